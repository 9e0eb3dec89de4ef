//! Point-cloud files in: readers that turn dataset scans into [`CloudPoint`]s, one file
//! per format behind the [`Format`] enum (the PDAL idea: one reader per format, one
//! interface), ready to become sensor returns later (issue 31, "Point clouds in and out").
//!
//! Formats and their sources:
//! - KITTI / SemanticKITTI `velodyne/*.bin` ([`kitti`]): float32 little-endian
//!   x y z reflectance, 16 bytes a point (KITTI raw data devkit, `readme.txt`, "Velodyne
//!   3D laser scan data"; Geiger et al., IJRR 2013, section 3.2).
//! - nuScenes `samples/LIDAR_TOP/*.pcd.bin` ([`nuscenes`]): float32 little-endian
//!   x y z intensity ring_index, 20 bytes a point (nuscenes-devkit
//!   `LidarPointCloud.from_file`, `nuscenes/utils/data_classes.py`).
//! - PCD 0.7 ([`pcd`]): ascii, binary and binary_compressed (Point Cloud Library,
//!   "The PCD (Point Cloud Data) file format", pointclouds.org documentation).
//! - CSV with a header naming the columns ([`csv`]).
//!
//! Every reader works on the file's bytes, read whole and bounded by [`MAX_CLOUD_BYTES`],
//! so a header claiming 2^40 points is checked against the real size and refused, never
//! allocated. Every error names the file and the place (byte offset, point index, line
//! and column), and no input makes a reader panic (tests/integration/fuzz.rs, targets `cloud-*`).

pub(crate) mod atan;
pub mod boxes;
pub mod csv;
pub mod frames;
pub mod guess;
pub mod kitti;
pub mod labels;
pub mod nuscenes;
pub mod pcd;
pub mod returns;

use crate::error::{Error, Result};
use std::path::{Path, PathBuf};

/// Largest point-cloud file read (bytes). A KITTI scan is about 2 MB, a nuScenes sweep
/// under 1 MB; 1 GiB leaves room for dense PCD maps while `/dev/zero` or a wrong file is
/// refused after that many bytes instead of filling memory.
pub const MAX_CLOUD_BYTES: u64 = 1 << 30;

/// One point as the file stores it (no unit or scale conversion).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CloudPoint {
    /// x in metres, sensor or dataset frame as stored.
    pub x: f32,
    /// y in metres.
    pub y: f32,
    /// z in metres.
    pub z: f32,
    /// Intensity as stored; its scale is [`CloudInfo::intensity_scale`] (0 when absent).
    pub intensity: f32,
    /// Ring (laser row, 0 = lowest or as the dataset numbers it) when the file has one.
    pub ring: Option<u16>,
    /// Time stamp as stored (seconds or a dataset's own unit) when the file has one.
    pub time: Option<f64>,
}

impl CloudPoint {
    /// Whether x, y, z and intensity are all finite numbers.
    #[inline]
    pub(crate) fn values_finite(&self) -> bool {
        // `&`, not `&&`: no branch a value in the loops over a scan that call it.
        self.x.is_finite() & self.y.is_finite() & self.z.is_finite() & self.intensity.is_finite()
    }

    /// The first of x, y, z and intensity that is not a finite number, with its value.
    pub fn non_finite(&self) -> Option<(&'static str, f32)> {
        // One test for the common case: all finite.
        if self.values_finite() {
            return None;
        }
        [
            ("x", self.x),
            ("y", self.y),
            ("z", self.z),
            ("intensity", self.intensity),
        ]
        .into_iter()
        .find(|(_, v)| !v.is_finite())
    }
}

/// The point-cloud formats read.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Format {
    /// KITTI / SemanticKITTI `velodyne/*.bin`: 4 float32 a point.
    Kitti,
    /// nuScenes `LIDAR_TOP/*.pcd.bin`: 5 float32 a point.
    NuScenes,
    /// Point Cloud Library PCD 0.7 (ascii, binary, binary_compressed).
    Pcd,
    /// Comma-, semicolon- or tab-separated text with a header row.
    Csv,
}

/// How the stored intensity is scaled, per format.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum IntensityScale {
    /// 0 to 1 (KITTI reflectance).
    Unit,
    /// 0 to 255 (nuScenes, the Velodyne byte).
    Byte,
    /// The format does not say (PCD, CSV): as the writer stored it.
    Unstated,
}

/// Which optional fields a file holds.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Fields {
    /// An intensity (reflectance, remission) field.
    pub intensity: bool,
    /// A ring (laser row) field.
    pub ring: bool,
    /// A per-point time field.
    pub time: bool,
}

/// What a file is: format, size, fields.
#[derive(Clone, Debug, PartialEq)]
pub struct CloudInfo {
    /// The file read.
    pub path: PathBuf,
    /// Its format.
    pub format: Format,
    /// Number of points.
    pub points: usize,
    /// Optional fields present.
    pub fields: Fields,
    /// How its intensity is scaled.
    pub intensity_scale: IntensityScale,
}

/// A file's points and description.
#[derive(Clone, Debug, PartialEq)]
pub struct Cloud {
    /// What the file is.
    pub info: CloudInfo,
    /// Its points, in file order.
    pub points: Vec<CloudPoint>,
}

/// What the caller knows beyond the file.
#[derive(Clone, Copy, Debug, Default)]
pub struct ReadOptions {
    /// The format, when not to be detected.
    pub format: Option<Format>,
    /// The sensor's number of lasers: a ring at or above it is refused.
    pub lasers: Option<u16>,
}

impl Format {
    /// Short name for messages.
    pub fn name(self) -> &'static str {
        match self {
            Format::Kitti => "KITTI .bin",
            Format::NuScenes => "nuScenes .pcd.bin",
            Format::Pcd => "PCD",
            Format::Csv => "CSV",
        }
    }

    /// The intensity scale the format defines.
    pub fn intensity_scale(self) -> IntensityScale {
        match self {
            Format::Kitti => IntensityScale::Unit,
            Format::NuScenes => IntensityScale::Byte,
            Format::Pcd | Format::Csv => IntensityScale::Unstated,
        }
    }

    /// Parses `bytes` (the whole file `path`, named in errors) in this format.
    pub fn parse(self, bytes: &[u8], path: &Path) -> Result<(Vec<CloudPoint>, Fields)> {
        match self {
            Format::Kitti => kitti::parse(bytes, path),
            Format::NuScenes => nuscenes::parse(bytes, path),
            Format::Pcd => pcd::parse(bytes, path),
            Format::Csv => csv::parse(bytes, path),
        }
    }
}

/// The error every reader returns: the file, then what is wrong and where.
pub(crate) fn invalid(path: &Path, message: impl Into<String>) -> Error {
    Error::Capture {
        path: path.to_path_buf(),
        message: message.into(),
    }
}

/// The format of `path` from its name and first bytes: content first where it is
/// unambiguous (a PCD header, text whose first line names x y z), then the extension
/// (`.pcd.bin` before `.bin`, since both end in `.bin`).
pub fn detect(path: &Path, head: &[u8]) -> Result<Format> {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default();
    if pcd::looks_like(head) {
        return Ok(Format::Pcd);
    }
    if name.ends_with(".pcd.bin") {
        return Ok(Format::NuScenes);
    }
    if name.ends_with(".bin") {
        return Ok(Format::Kitti);
    }
    if name.ends_with(".pcd") {
        return Ok(Format::Pcd);
    }
    if name.ends_with(".csv") || csv::looks_like(head) {
        return Ok(Format::Csv);
    }
    Err(invalid(
        path,
        "not a point-cloud format read here (expected KITTI .bin, nuScenes .pcd.bin, PCD, \
         or CSV with an x,y,z header)",
    ))
}

/// Reads the whole of `path`, refusing more than [`MAX_CLOUD_BYTES`].
pub fn read_cloud_bytes(path: &Path) -> Result<Vec<u8>> {
    read_at_most(
        path,
        MAX_CLOUD_BYTES,
        "more than a point-cloud file read here may be",
    )
}

/// The bytes of `path`, refused (naming the file, the bound and `what` it means) when it
/// holds more than `max` bytes, which are never read past.
pub(crate) fn read_at_most(path: &Path, max: u64, what: &str) -> Result<Vec<u8>> {
    use std::io::Read;
    let file = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
    // The real size (when the file has one) sizes the buffer once: a 2 MB scan is read in
    // one allocation and one copy.
    let hint = file.metadata().map(|m| m.len()).unwrap_or(0);
    let mut bytes = Vec::with_capacity(hint.min(max) as usize + 1);
    file.take(max + 1)
        .read_to_end(&mut bytes)
        .map_err(|e| Error::io(path, e))?;
    if bytes.len() as u64 > max {
        return Err(invalid(
            path,
            format!("larger than {} MiB, {what}", max >> 20),
        ));
    }
    Ok(bytes)
}

/// Reads the point-cloud file `path`.
pub fn read_file(path: &Path, options: &ReadOptions) -> Result<Cloud> {
    let bytes = read_cloud_bytes(path)?;
    read_bytes(&bytes, path, options)
}

/// Reads a point cloud from `bytes`, the content of `path` (its name detects the format
/// and is named in errors).
pub fn read_bytes(bytes: &[u8], path: &Path, options: &ReadOptions) -> Result<Cloud> {
    let format = match options.format {
        Some(f) => f,
        None => detect(path, &bytes[..bytes.len().min(4096)])?,
    };
    let (points, fields) = format.parse(bytes, path)?;
    // A KITTI scan's points are checked as they are parsed (`kitti::parse`).
    if format != Format::Kitti {
        check_points(&points, path, options.lasers)?;
    }
    Ok(Cloud {
        info: CloudInfo {
            path: path.to_path_buf(),
            format,
            points: points.len(),
            fields,
            intensity_scale: format.intensity_scale(),
        },
        points,
    })
}

/// Refuses non-finite coordinates, intensities and times, and (when the sensor's number of
/// lasers is known) rings at or above it, naming the point index (0-based, file order).
pub fn check_points(points: &[CloudPoint], path: &Path, lasers: Option<u16>) -> Result<()> {
    // The common case, every point sound, in one pass without a branch a value (the
    // per-point early exits below were a twentieth of a KITTI scan's run); the loop
    // below runs only to name the first offending point.
    let limit = lasers.unwrap_or(u16::MAX);
    let ring_ok = |p: &CloudPoint| lasers.is_none() || p.ring.is_none_or(|r| r < limit);
    let sound = points.iter().fold(true, |ok, p| {
        ok & p.values_finite() & p.time.is_none_or(f64::is_finite) & ring_ok(p)
    });
    if sound {
        return Ok(());
    }
    for (i, p) in points.iter().enumerate() {
        if let Some((field, v)) = p.non_finite() {
            return Err(invalid(
                path,
                format!("point {i} (0-based): {field} is {v}, not a finite number"),
            ));
        }
        if let Some(t) = p.time {
            if !t.is_finite() {
                return Err(invalid(
                    path,
                    format!("point {i} (0-based): time is {t}, not a finite number"),
                ));
            }
        }
        if let (Some(ring), Some(n)) = (p.ring, lasers) {
            if ring >= n {
                return Err(invalid(
                    path,
                    format!(
                        "point {i} (0-based): ring {ring} is out of range for a sensor of \
                         {n} lasers (0 to {})",
                        n.saturating_sub(1)
                    ),
                ));
            }
        }
    }
    Ok(())
}

/// The ring stored as a float (nuScenes, PCD F fields): a whole number from 0 to 65535,
/// else an error naming the point.
pub(crate) fn ring_from_f64(v: f64, index: usize, path: &Path) -> Result<u16> {
    if v.fract() == 0.0 && (0.0..=u16::MAX as f64).contains(&v) {
        Ok(v as u16)
    } else {
        Err(invalid(
            path,
            format!("point {index} (0-based): ring {v} is not a whole number from 0 to 65535"),
        ))
    }
}

/// Refuses a fixed-record file whose size is not a whole number of records, naming the
/// size and the remainder (and the other dataset layout when the size fits it).
pub(crate) fn check_record_size(
    bytes: &[u8],
    record: usize,
    format: Format,
    path: &Path,
) -> Result<usize> {
    let rem = bytes.len() % record;
    if rem == 0 {
        return Ok(bytes.len() / record);
    }
    let hint = match format {
        Format::Kitti if bytes.len().is_multiple_of(20) => {
            " (it is a multiple of 20: a nuScenes .pcd.bin under another name?)"
        }
        Format::NuScenes if bytes.len().is_multiple_of(16) => {
            " (it is a multiple of 16: a KITTI .bin under another name?)"
        }
        _ => "",
    };
    Err(invalid(
        path,
        format!(
            "{} bytes is not a whole number of {}-byte {} points: {} bytes left over after \
             {} whole points (from byte offset {}): a truncated or different file{hint}",
            bytes.len(),
            record,
            format.name(),
            rem,
            bytes.len() / record,
            bytes.len() - rem
        ),
    ))
}
