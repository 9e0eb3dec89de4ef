//! Per-point ground truth of labelled datasets: which points are ground and which belong
//! to which object, for ground precision/recall and per-object detection on real scans
//! (issue 31, "Ground truth from datasets").
//!
//! Formats and their sources:
//! - SemanticKITTI `labels/*.label`: one little-endian uint32 a point, in the order of the
//!   scan's `velodyne/*.bin`; the lower 16 bits are the semantic class, the upper 16 bits
//!   the instance id (Behley et al., ICCV 2019; the dataset's `semantic-kitti.yaml` names
//!   the classes).
//! - nuScenes-lidarseg `lidarseg/<version>/<token>_lidarseg.bin`: one uint8 class index a
//!   point, in the order of the sweep's `.pcd.bin` (nuscenes-devkit, `lidarseg` tutorial
//!   and `category.json`: 32 classes, 0 = noise).
//! - nuScenes-panoptic `panoptic/<version>/<token>_panoptic.npz`: a NumPy archive holding
//!   one uint16 array (`data`), class index x 1000 + instance index a point (nuscenes-devkit,
//!   panoptic tutorial; classes 24 and up are "stuff" with no instances).
//!
//! The class mapping (stated in the manual and in [`SEMANTIC_KITTI`] / [`NUSCENES`]):
//! ground is what a ground-removal method should remove (road, parking, sidewalk, other
//! ground, lane marking, terrain; nuScenes: the four `flat.*` classes); objects are the
//! "thing" classes that carry instances (vehicles, people, riders; nuScenes also animals,
//! barriers, traffic cones, debris, pushable objects and bicycle racks); everything else
//! (buildings, vegetation, poles, unlabelled, noise) is neither. nuScenes-lidarseg has no
//! instance ids, so it gives ground and classes but no objects; the panoptic file gives both.
//!
//! The `.npy` member is parsed here by hand: only a one-dimensional little-endian uint16
//! array is valid, which a header check of a few lines settles; the crates that parse any
//! `.npy` (npyz) bring zip 0.6 with zstd, bzip2 and AES built from C. The archive itself is
//! read with the `zip` crate.

use crate::error::Result;
use std::collections::BTreeMap;
use std::io::Read;
use std::path::Path;

use super::invalid;

/// The label file formats read.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LabelFormat {
    /// SemanticKITTI `.label`: uint32 a point, class in the low 16 bits, instance above.
    SemanticKitti,
    /// nuScenes-lidarseg `_lidarseg.bin`: uint8 class index a point.
    NuScenesLidarseg,
    /// nuScenes-panoptic `_panoptic.npz`: uint16 class x 1000 + instance a point.
    NuScenesPanoptic,
}

impl LabelFormat {
    /// The format of a label file from its name (`.label`, `_lidarseg.bin`, `.npz`).
    pub fn detect(path: &Path) -> Option<Self> {
        let name = path.file_name()?.to_string_lossy().to_ascii_lowercase();
        if name.ends_with(".label") {
            Some(Self::SemanticKitti)
        } else if name.ends_with("_lidarseg.bin") {
            Some(Self::NuScenesLidarseg)
        } else if name.ends_with(".npz") {
            Some(Self::NuScenesPanoptic)
        } else {
            None
        }
    }

    /// The format's name in messages.
    pub fn name(self) -> &'static str {
        match self {
            Self::SemanticKitti => "SemanticKITTI .label",
            Self::NuScenesLidarseg => "nuScenes-lidarseg",
            Self::NuScenesPanoptic => "nuScenes-panoptic",
        }
    }
}

/// What a class is to the pipeline's metrics.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Role {
    /// Ground: what ground removal should remove.
    Ground,
    /// A "thing": its instances are objects.
    Object,
    /// Neither (structures, vegetation, unlabelled, noise).
    Other,
}

/// One class of a dataset.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Class {
    /// The dataset's class id.
    pub id: u16,
    /// The dataset's class name.
    pub name: &'static str,
    /// Its role in the metrics.
    pub role: Role,
}

const fn class(id: u16, name: &'static str, role: Role) -> Class {
    Class { id, name, role }
}

/// SemanticKITTI's classes (`semantic-kitti.yaml`, `labels`) and their roles.
pub const SEMANTIC_KITTI: [Class; 34] = [
    class(0, "unlabeled", Role::Other),
    class(1, "outlier", Role::Other),
    class(10, "car", Role::Object),
    class(11, "bicycle", Role::Object),
    class(13, "bus", Role::Object),
    class(15, "motorcycle", Role::Object),
    class(16, "on-rails", Role::Object),
    class(18, "truck", Role::Object),
    class(20, "other-vehicle", Role::Object),
    class(30, "person", Role::Object),
    class(31, "bicyclist", Role::Object),
    class(32, "motorcyclist", Role::Object),
    class(40, "road", Role::Ground),
    class(44, "parking", Role::Ground),
    class(48, "sidewalk", Role::Ground),
    class(49, "other-ground", Role::Ground),
    class(50, "building", Role::Other),
    class(51, "fence", Role::Other),
    class(52, "other-structure", Role::Other),
    class(60, "lane-marking", Role::Ground),
    class(70, "vegetation", Role::Other),
    class(71, "trunk", Role::Other),
    class(72, "terrain", Role::Ground),
    class(80, "pole", Role::Other),
    class(81, "traffic-sign", Role::Other),
    class(99, "other-object", Role::Other),
    class(252, "moving-car", Role::Object),
    class(253, "moving-bicyclist", Role::Object),
    class(254, "moving-person", Role::Object),
    class(255, "moving-motorcyclist", Role::Object),
    class(256, "moving-on-rails", Role::Object),
    class(257, "moving-bus", Role::Object),
    class(258, "moving-truck", Role::Object),
    class(259, "moving-other-vehicle", Role::Object),
];

/// nuScenes' 32 lidarseg classes (`category.json`, index order) and their roles.
pub const NUSCENES: [Class; 32] = [
    class(0, "noise", Role::Other),
    class(1, "animal", Role::Object),
    class(2, "human.pedestrian.adult", Role::Object),
    class(3, "human.pedestrian.child", Role::Object),
    class(4, "human.pedestrian.construction_worker", Role::Object),
    class(5, "human.pedestrian.personal_mobility", Role::Object),
    class(6, "human.pedestrian.police_officer", Role::Object),
    class(7, "human.pedestrian.stroller", Role::Object),
    class(8, "human.pedestrian.wheelchair", Role::Object),
    class(9, "movable_object.barrier", Role::Object),
    class(10, "movable_object.debris", Role::Object),
    class(11, "movable_object.pushable_pullable", Role::Object),
    class(12, "movable_object.trafficcone", Role::Object),
    class(13, "static_object.bicycle_rack", Role::Object),
    class(14, "vehicle.bicycle", Role::Object),
    class(15, "vehicle.bus.bendy", Role::Object),
    class(16, "vehicle.bus.rigid", Role::Object),
    class(17, "vehicle.car", Role::Object),
    class(18, "vehicle.construction", Role::Object),
    class(19, "vehicle.emergency.ambulance", Role::Object),
    class(20, "vehicle.emergency.police", Role::Object),
    class(21, "vehicle.motorcycle", Role::Object),
    class(22, "vehicle.trailer", Role::Object),
    class(23, "vehicle.truck", Role::Object),
    class(24, "flat.driveable_surface", Role::Ground),
    class(25, "flat.other", Role::Ground),
    class(26, "flat.sidewalk", Role::Ground),
    class(27, "flat.terrain", Role::Ground),
    class(28, "static.manmade", Role::Other),
    class(29, "static.other", Role::Other),
    class(30, "static.vegetation", Role::Other),
    class(31, "vehicle.ego", Role::Other),
];

/// The labels of one scan as the file stores them.
#[derive(Clone, Debug, PartialEq)]
pub struct PointLabels {
    /// The file's format.
    pub format: LabelFormat,
    /// Class id of every point, in the scan's point order.
    pub class: Vec<u16>,
    /// Instance id of every point (0: none; always 0 for nuScenes-lidarseg).
    pub instance: Vec<u16>,
}

/// Ground truth for the metrics, per point of the scan.
#[derive(Clone, Debug, PartialEq)]
pub struct GroundTruth {
    /// True for points of a ground class.
    pub ground: Vec<bool>,
    /// Object id of every point (1, 2, ... in order of first appearance; -1: no object).
    pub objects: Vec<i32>,
    /// The class name of every object id.
    pub classes: BTreeMap<i32, String>,
    /// Points of an object class that carry no instance id (counted, not objects).
    pub without_instance: usize,
}

/// The dataset's class of `id` in `format`.
pub fn class_of(format: LabelFormat, id: u16) -> Option<&'static Class> {
    let table: &[Class] = match format {
        LabelFormat::SemanticKitti => &SEMANTIC_KITTI,
        _ => &NUSCENES,
    };
    table.iter().find(|c| c.id == id)
}

/// Largest label file read (bytes): a SemanticKITTI scan's labels are about 500 KB.
pub const MAX_LABEL_BYTES: u64 = 256 << 20;

/// Reads the labels of a scan of `points` points from `path` (format from the name
/// unless given).
pub fn read_labels_file(
    path: &Path,
    format: Option<LabelFormat>,
    points: usize,
) -> Result<PointLabels> {
    let format =
        match format.or_else(|| LabelFormat::detect(path)) {
            Some(f) => f,
            None => return Err(invalid(
                path,
                "not a known label file: SemanticKITTI labels end in .label, nuScenes-lidarseg \
                 files in _lidarseg.bin, nuScenes-panoptic files in .npz",
            )),
        };
    let bytes = super::read_at_most(path, MAX_LABEL_BYTES, "not a label file of one scan")?;
    parse(&bytes, path, format, points)
}

/// Parses label file `bytes` (the content of `path`) for a scan of `points` points.
pub fn parse(bytes: &[u8], path: &Path, format: LabelFormat, points: usize) -> Result<PointLabels> {
    let (class, instance) = match format {
        LabelFormat::SemanticKitti => {
            whole(bytes.len(), 4, path, format)?;
            bytes
                .chunks_exact(4)
                .map(|c| {
                    let v = u32::from_le_bytes([c[0], c[1], c[2], c[3]]);
                    ((v & 0xffff) as u16, (v >> 16) as u16)
                })
                .unzip()
        }
        LabelFormat::NuScenesLidarseg => (
            bytes.iter().map(|&b| u16::from(b)).collect(),
            vec![0; bytes.len()],
        ),
        LabelFormat::NuScenesPanoptic => {
            let values = npz_u16(bytes, path)?;
            values.iter().map(|&v| (v / 1000, v % 1000)).unzip()
        }
    };
    let labels = PointLabels {
        format,
        class,
        instance,
    };
    if labels.class.len() != points {
        return Err(invalid(
            path,
            format!(
                "{} labels for a scan of {points} points: the label file belongs to another scan \
                 (or the scan was filtered after labelling)",
                labels.class.len()
            ),
        ));
    }
    if let Some((i, &c)) = labels
        .class
        .iter()
        .enumerate()
        .find(|&(_, &c)| class_of(format, c).is_none())
    {
        return Err(invalid(
            path,
            format!(
                "point {i} (0-based): class {c} is not a {} class ({})",
                format.name(),
                match format {
                    LabelFormat::SemanticKitti =>
                        "semantic-kitti.yaml lists 0, 1, 10-99 and 252-259",
                    _ => "nuScenes has classes 0 to 31",
                }
            ),
        ));
    }
    Ok(labels)
}

/// Refuses a size that is not a whole number of `size`-byte labels.
fn whole(len: usize, size: usize, path: &Path, format: LabelFormat) -> Result<()> {
    if !len.is_multiple_of(size) {
        return Err(invalid(
            path,
            format!(
                "{len} bytes is not a whole number of {size}-byte {} labels: {} bytes left over \
                 after {} whole labels (from byte offset {}): a truncated or different file",
                format.name(),
                len % size,
                len / size,
                len - len % size
            ),
        ));
    }
    Ok(())
}

impl PointLabels {
    /// The ground truth the metrics use (see the module documentation for the mapping).
    pub fn truth(&self) -> GroundTruth {
        let mut ids: BTreeMap<(u16, u16), i32> = BTreeMap::new();
        let mut classes = BTreeMap::new();
        let mut without_instance = 0;
        let mut ground = Vec::with_capacity(self.class.len());
        let mut objects = Vec::with_capacity(self.class.len());
        for (&c, &inst) in self.class.iter().zip(&self.instance) {
            let class = class_of(self.format, c);
            let role = class.map_or(Role::Other, |k| k.role);
            ground.push(role == Role::Ground);
            let object = if role == Role::Object && inst != 0 {
                let next = ids.len() as i32 + 1;
                let id = *ids.entry((c, inst)).or_insert(next);
                if id == next {
                    classes.insert(id, class.map_or("", |k| k.name).to_string());
                }
                id
            } else {
                if role == Role::Object {
                    without_instance += 1;
                }
                -1
            };
            objects.push(object);
        }
        GroundTruth {
            ground,
            objects,
            classes,
            without_instance,
        }
    }
}

/// The one uint16 array of a nuScenes-panoptic `.npz` (member `data.npy`, or the only
/// member).
fn npz_u16(bytes: &[u8], path: &Path) -> Result<Vec<u16>> {
    let mut archive = zip::ZipArchive::new(std::io::Cursor::new(bytes))
        .map_err(|e| invalid(path, format!("not a NumPy .npz archive (zip): {e}")))?;
    let names = archive
        .file_names()
        .map(|n| n.map(|n| n.into_owned()))
        .collect::<std::result::Result<Vec<String>, _>>()
        .map_err(|e| invalid(path, format!("a member name of the .npz: {e}")))?;
    let name = if names.iter().any(|n| n == "data.npy") {
        "data.npy".to_string()
    } else if names.len() == 1 {
        names[0].clone()
    } else {
        return Err(invalid(
            path,
            format!(
                "no array `data` in the .npz (members: {}): nuScenes-panoptic files hold one",
                names.join(", ")
            ),
        ));
    };
    let mut member = archive
        .by_name(&name)
        .map_err(|e| invalid(path, format!("member {name}: {e}")))?;
    // The archive's claimed size is not trusted: the read is bounded by the file limit.
    let mut npy = Vec::new();
    (&mut member)
        .take(MAX_LABEL_BYTES + 1)
        .read_to_end(&mut npy)
        .map_err(|e| invalid(path, format!("member {name}: {e}")))?;
    if npy.len() as u64 > MAX_LABEL_BYTES {
        return Err(invalid(
            path,
            format!("member {name} holds more than {MAX_LABEL_BYTES} bytes"),
        ));
    }
    npy_u16(&npy, path, &name)
}

/// The values of a one-dimensional little-endian uint16 `.npy` image (NumPy's "format.py",
/// format versions 1.0 to 3.0).
fn npy_u16(npy: &[u8], path: &Path, member: &str) -> Result<Vec<u16>> {
    let bad = |what: String| invalid(path, format!("member {member}: {what}"));
    if npy.len() < 10 || &npy[..6] != b"\x93NUMPY" {
        return Err(bad("not a NumPy .npy array (no \\x93NUMPY magic)".into()));
    }
    let (len, start): (usize, usize) = match npy[6] {
        1 => (usize::from(u16::from_le_bytes([npy[8], npy[9]])), 10),
        2 | 3 if npy.len() >= 12 => (
            u32::from_le_bytes([npy[8], npy[9], npy[10], npy[11]]) as usize,
            12,
        ),
        v => return Err(bad(format!(".npy format version {v} is not read"))),
    };
    let header = npy
        .get(start..start.saturating_add(len))
        .ok_or_else(|| bad(format!("the header claims {len} bytes, past the end")))?;
    let header = String::from_utf8_lossy(header);
    let field = |key: &str| -> Option<String> {
        let at = header.find(&format!("'{key}'"))? + key.len() + 2;
        let rest = header[at..].trim_start().strip_prefix(':')?.trim_start();
        let end = if rest.starts_with('(') {
            rest.find(')')? + 1
        } else {
            rest.find([',', '}']).unwrap_or(rest.len())
        };
        Some(rest[..end].trim().to_string())
    };
    let descr = field("descr").unwrap_or_default();
    if !matches!(descr.as_str(), "'<u2'" | "'|u2'") {
        return Err(bad(format!(
            "dtype {descr} where nuScenes-panoptic stores uint16 ('<u2')"
        )));
    }
    if field("fortran_order").as_deref() == Some("True") {
        return Err(bad("Fortran-ordered arrays are not read".into()));
    }
    let shape = field("shape").unwrap_or_default();
    let dims: Vec<&str> = shape
        .trim_matches(|c| c == '(' || c == ')')
        .split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .collect();
    let n: usize = match dims.as_slice() {
        [n] => n
            .parse()
            .map_err(|_| bad(format!("shape {shape} is not one length")))?,
        _ => return Err(bad(format!("shape {shape}: one dimension expected"))),
    };
    let data = &npy[start + len..];
    if data.len() != n.saturating_mul(2) {
        return Err(bad(format!(
            "shape ({n},) needs {} data bytes, the member has {}",
            n.saturating_mul(2),
            data.len()
        )));
    }
    Ok(data
        .chunks_exact(2)
        .map(|c| u16::from_le_bytes([c[0], c[1]]))
        .collect())
}
