//! Per-laser calibration of any described sensor (HDL-64E units above all: every unit
//! ships its own table), read from the ROS velodyne driver's YAML or VeloView's
//! `db.xml`, including the
//! corrections the HDL-32E's [`super::Calibration`] refuses: distance offset, two-point
//! distance correction, vertical and horizontal offsets. The YAML is parsed with
//! serde_norway and the XML with roxmltree as there (with its depth guard,
//! [`super::xml`]).
//!
//! Conventions: `azimuth_offset_deg` is the negated `rot_correction` (point azimuth =
//! block azimuth + offset), elevations in degrees, lengths in metres. How the corrections
//! apply is [`LaserCorrection::position`]: the HDL-64E S3 manual's formulas as the ROS
//! driver (`rawdata.cc`) and velodyne_decoder 3 apply them (two-point correction between
//! 2.40 m / 1.93 m and 25.04 m, the horizontal offset across the beam, z corrected by the
//! mean of the x and y corrections as velodyne_decoder does).

use crate::error::{Error, Result};
use crate::sensor::SensorModel;
use serde::Deserialize;
use std::path::Path;

/// Calibration of one laser.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LaserCorrection {
    /// Elevation in degrees (ROS `vert_correction` in degrees).
    pub elevation_deg: f64,
    /// Azimuth offset in degrees, the negated ROS `rot_correction`.
    pub azimuth_offset_deg: f64,
    /// Distance added to every measurement in metres (ROS `dist_correction`).
    pub dist_correction_m: f64,
    /// Two-point correction of x at the near point (ROS `dist_correction_x`), metres.
    pub dist_correction_x_m: f64,
    /// Two-point correction of y at the near point (ROS `dist_correction_y`), metres.
    pub dist_correction_y_m: f64,
    /// Height of the laser's origin above the sensor's, metres (`vert_offset_correction`).
    pub vert_offset_m: f64,
    /// Horizontal offset of the laser's origin, metres (`horiz_offset_correction`).
    pub horiz_offset_m: f64,
}

impl LaserCorrection {
    /// True when any correction beyond the two angles and the vertical offset is set
    /// (velodyne_decoder's "advanced" calibration).
    pub fn is_advanced(&self) -> bool {
        self.dist_correction_m != 0.0
            || self.dist_correction_x_m != 0.0
            || self.dist_correction_y_m != 0.0
            || self.horiz_offset_m != 0.0
    }

    /// Range and x, y, z (ROS axes) of a measured distance at azimuth `azimuth_deg` (the
    /// block's interpolated azimuth plus this laser's offset).
    pub fn position(&self, distance_m: f64, azimuth_deg: f64) -> (f64, [f64; 3]) {
        let (sin_w, cos_w) = self.elevation_deg.to_radians().sin_cos();
        let (sin_a, cos_a) = azimuth_deg.to_radians().sin_cos();
        if !self.is_advanced() {
            let xy = distance_m * cos_w;
            return (
                distance_m,
                [
                    xy * cos_a,
                    -xy * sin_a,
                    distance_m * sin_w + self.vert_offset_m,
                ],
            );
        }
        let corrected = distance_m + self.dist_correction_m;
        let (mut cx, mut cy, mut cz) = (
            self.dist_correction_m,
            self.dist_correction_m,
            self.dist_correction_m,
        );
        // Two-point correction (manual: near point x 2.40 m, y 1.93 m; far 25.04 m).
        if self.dist_correction_x_m != 0.0 && self.dist_correction_y_m != 0.0 && distance_m < 25.04
        {
            let xy = corrected * cos_w;
            let xx = (xy * sin_a).abs();
            let yy = (xy * cos_a).abs();
            let kx = (xx - 2.40) / (25.04 - 2.40);
            let ky = (yy - 1.93) / (25.04 - 1.93);
            cx = kx * self.dist_correction_m + (1.0 - kx) * self.dist_correction_x_m;
            cy = ky * self.dist_correction_m + (1.0 - ky) * self.dist_correction_y_m;
            cz = (cx + cy) / 2.0;
        }
        // The manual's frame (x right, y forward), then ROS axes (x forward, y left).
        let mx = (distance_m + cx) * cos_w * sin_a - self.horiz_offset_m * cos_a;
        let my = (distance_m + cy) * cos_w * cos_a + self.horiz_offset_m * sin_a;
        let mz = (distance_m + cz) * sin_w + self.vert_offset_m;
        (corrected, [my, -mx, mz])
    }
}

/// Calibration of a whole sensor: one [`LaserCorrection`] per laser id.
#[derive(Clone, Debug, PartialEq)]
pub struct ModelCalibration {
    /// Per-laser corrections, indexed by laser id.
    pub lasers: Vec<LaserCorrection>,
    /// Size of one raw distance unit in metres.
    pub distance_resolution_m: f64,
    /// Where it came from ("built-in" or the file).
    pub source: String,
}

/// One `lasers:` entry of a ROS calibration YAML.
#[derive(Debug, Deserialize)]
struct RosLaser {
    laser_id: i64,
    rot_correction: f64,
    vert_correction: f64,
    #[serde(default)]
    dist_correction: f64,
    #[serde(default)]
    dist_correction_x: f64,
    #[serde(default)]
    dist_correction_y: f64,
    #[serde(default)]
    vert_offset_correction: f64,
    #[serde(default)]
    horiz_offset_correction: f64,
}

/// A ROS calibration YAML.
#[derive(Debug, Deserialize)]
struct RosFile {
    lasers: Vec<RosLaser>,
    #[serde(default)]
    num_lasers: Option<i64>,
    #[serde(default)]
    distance_resolution: Option<f64>,
}

impl ModelCalibration {
    /// The model's default table (angles and the manual's vertical offsets).
    pub fn builtin(model: &SensorModel) -> Self {
        ModelCalibration {
            lasers: (0..model.lasers)
                .map(|k| LaserCorrection {
                    elevation_deg: model.elevation_deg[k],
                    azimuth_offset_deg: model.azimuth_offset_deg[k],
                    dist_correction_m: 0.0,
                    dist_correction_x_m: 0.0,
                    dist_correction_y_m: 0.0,
                    vert_offset_m: model.vertical_offset_mm.get(k).map_or(0.0, |mm| mm * 1e-3),
                    horiz_offset_m: 0.0,
                })
                .collect(),
            distance_resolution_m: model.distance_resolution_m,
            source: "built-in".to_string(),
        }
    }

    /// Reads a ROS velodyne calibration YAML for `model` (bounded read).
    pub fn from_ros_yaml_file(path: &Path, model: &SensorModel) -> Result<Self> {
        let text = crate::error::read_text_bounded(path)?;
        Self::from_ros_yaml(&text, path, model)
    }

    /// Reads a ROS velodyne calibration YAML or a VeloView `db.xml` for `model`, told
    /// apart by content (a file whose first non-blank character is `<` is XML).
    pub fn from_file(path: &Path, model: &SensorModel) -> Result<Self> {
        let text = crate::error::read_text_bounded(path)?;
        if text
            .trim_start_matches('\u{feff}')
            .trim_start()
            .starts_with('<')
        {
            Self::from_veloview_xml(&text, path, model)
        } else {
            Self::from_ros_yaml(&text, path, model)
        }
    }

    /// Parses a ROS velodyne calibration YAML for `model`: every laser id from 0 to
    /// `model.lasers - 1` exactly once, finite values, angles in radians within +-90
    /// degrees; `path` names the file in errors.
    pub fn from_ros_yaml(text: &str, path: &Path, model: &SensorModel) -> Result<Self> {
        let file: RosFile = serde_norway::from_str(text).map_err(|e| Error::Config {
            path: path.to_path_buf(),
            message: format!("not a ROS velodyne calibration YAML: {e}"),
        })?;
        let lasers: Vec<(String, RosLaser)> = file
            .lasers
            .into_iter()
            .enumerate()
            .map(|(i, l)| (format!("lasers[{i}]"), l))
            .collect();
        assemble(
            &lasers,
            file.num_lasers,
            file.distance_resolution,
            path,
            model,
        )
    }

    /// Parses a VeloView calibration XML (`db.xml`, boost serialization: `<DB>` with
    /// `<distLSB_>` in cm and `<points_>` items whose `<px>` holds `<id_>`,
    /// `<rotCorrection_>` and `<vertCorrection_>` in degrees and `<distCorrection_>`,
    /// `<distCorrectionX_>`, `<distCorrectionY_>`, `<vertOffsetCorrection_>`,
    /// `<horizOffsetCorrection_>` in cm: the units of the ROS driver's
    /// `gen_calibration.py`, which converts these files to its YAML). Same checks as
    /// the YAML; places are named by item and line.
    pub fn from_veloview_xml(text: &str, path: &Path, model: &SensorModel) -> Result<Self> {
        let err = |message: String| Error::Config {
            path: path.to_path_buf(),
            message,
        };
        let max = crate::sensor::calibration::xml::MAX_DEPTH;
        if let Some(line) = crate::sensor::calibration::xml::too_deep(text, max) {
            return Err(err(format!(
                "elements nested more than {max} levels deep at line {line}: not a VeloView \
                 calibration file"
            )));
        }
        let options = roxmltree::ParsingOptions {
            allow_dtd: true,
            ..Default::default()
        };
        let doc = roxmltree::Document::parse_with_options(text, options)
            .map_err(|e| err(format!("not a well-formed XML file: {e}")))?;
        let line_of = |n: roxmltree::Node| doc.text_pos_at(n.range().start).row;
        let number = |n: roxmltree::Node| -> Result<f64> {
            let t = n.text().unwrap_or("").trim();
            t.parse::<f64>().map_err(|_| {
                err(format!(
                    "line {}: <{}> holds {t:?}, expected a number",
                    line_of(n),
                    n.tag_name().name()
                ))
            })
        };
        let db = doc
            .descendants()
            .find(|n| n.has_tag_name("DB"))
            .ok_or_else(|| err("no <DB> element: not a VeloView calibration file".into()))?;
        let resolution = match child(db, "distLSB_") {
            Some(n) => Some(number(n)? / 100.0),
            None => None,
        };
        let points = child(db, "points_")
            .ok_or_else(|| err(format!("<DB> at line {} has no <points_>", line_of(db))))?;
        let mut lasers = Vec::new();
        for (i, item) in points
            .children()
            .filter(|n| n.has_tag_name("item"))
            .enumerate()
        {
            // A few more items than lasers is a wrong file, not one to scan to its end
            // (each place's line number is a scan of the text).
            if i >= 2 * model.lasers {
                return Err(err(format!(
                    "points_ item {i} at line {}: more than {} items for the {} lasers of a {}",
                    line_of(item),
                    2 * model.lasers,
                    model.lasers,
                    model.name
                )));
            }
            let px = child(item, "px").ok_or_else(|| {
                err(format!(
                    "points_ item {i} at line {} has no <px>",
                    line_of(item)
                ))
            })?;
            let place = format!("points_ item {i} (line {})", line_of(px));
            let get = |name: &str, required: bool| -> Result<f64> {
                match child(px, name) {
                    Some(n) => number(n),
                    None if required => Err(err(format!("{place}: missing <{name}>"))),
                    None => Ok(0.0),
                }
            };
            let id = get("id_", true)?;
            if id.fract() != 0.0 || id.abs() > 1e9 {
                return Err(err(format!("{place}: <id_> {id} is not an integer")));
            }
            let laser = RosLaser {
                laser_id: id as i64,
                rot_correction: get("rotCorrection_", true)?.to_radians(),
                vert_correction: get("vertCorrection_", true)?.to_radians(),
                dist_correction: get("distCorrection_", false)? / 100.0,
                dist_correction_x: get("distCorrectionX_", false)? / 100.0,
                dist_correction_y: get("distCorrectionY_", false)? / 100.0,
                vert_offset_correction: get("vertOffsetCorrection_", false)? / 100.0,
                horiz_offset_correction: get("horizOffsetCorrection_", false)? / 100.0,
            };
            lasers.push((place, laser));
        }
        assemble(&lasers, None, resolution, path, model)
    }

    /// Reads an HDL-64E's own calibration from the status bytes of its data packets
    /// (bytes 1204 and 1205: status type and value). Types `H M S D N Y G T V` carry the
    /// clock and unit status; every other byte (the S3's `W` included) is the next byte
    /// of a 1,820-byte calibration block starting "UNIT#": two noise thresholds, 64
    /// laser records of 28 bytes (id u8; vertical and rotational correction i16 in
    /// 0.01 deg; far distance, x and y two-point, vertical and horizontal offset
    /// corrections, focal distance i16 in mm; focal slope i16; min and max intensity u8)
    /// and a 21-byte tail ending in a u16 check: the CRC-16 (polynomial 0x8005) of bytes
    /// 1-20 of each record on the S3 (which writes `W`), the block length on the S2.
    /// The layout and check are those velodyne_decoder's `hdl64e.read_status_info`
    /// reads (the S2/S3 manuals' status cycle: 7 calibration bytes in each 16 packets,
    /// 4,160 packets a block). The first block whose check holds is used.
    pub fn from_status_bytes(
        status: impl IntoIterator<Item = (u8, u8)>,
        model: &SensorModel,
    ) -> std::result::Result<Self, String> {
        const BLOCK: usize = 1820;
        if model.lasers != 64 {
            return Err(format!("{} packets carry no calibration", model.name));
        }
        let mut values = Vec::with_capacity(BLOCK);
        let (mut s3, mut blocks, mut seen) = (false, 0usize, 0usize);
        for (kind, value) in status {
            seen += 1;
            if b"HMSDNYGTV".contains(&kind) {
                continue;
            }
            s3 |= kind == b'W';
            values.push(value);
            if values.len() < BLOCK {
                continue;
            }
            blocks += 1;
            let Some(start) = values.windows(5).position(|w| w == b"UNIT#") else {
                values.clear();
                continue;
            };
            values.rotate_left(start);
            let expected = u16::from_le_bytes([values[BLOCK - 2], values[BLOCK - 1]]);
            let records = &values[7..BLOCK - 21];
            let check = if s3 {
                crc16(records.chunks(28).flat_map(|r| r[1..21].iter().copied()))
            } else {
                BLOCK as u16
            };
            if expected == check {
                return decode_records(records, model);
            }
            // Keep the bytes after the start token: the next block may complete them.
            values.truncate(BLOCK - start);
            if start == 0 {
                values.clear();
            }
        }
        Err(format!(
            "no HDL-64E calibration block with a valid check in the status bytes of {seen} \
             data packets ({blocks} blocks of {BLOCK} bytes tried; a whole block takes \
             4,160 packets)"
        ))
    }

    /// Ring of each laser id: ids sorted by elevation, 0 lowest (ties in id order).
    pub fn rings(&self) -> Vec<u8> {
        let mut ids: Vec<usize> = (0..self.lasers.len()).collect();
        ids.sort_by(|&a, &b| {
            self.lasers[a]
                .elevation_deg
                .total_cmp(&self.lasers[b].elevation_deg)
        });
        let mut rings = vec![0u8; self.lasers.len()];
        for (ring, &id) in ids.iter().enumerate() {
            rings[id] = ring as u8;
        }
        rings
    }
}

/// Checks the entries of a calibration file against `model` and builds the calibration:
/// each laser id once, finite values, angles within +-90 degrees (radians expected).
fn assemble(
    entries: &[(String, RosLaser)],
    num_lasers: Option<i64>,
    resolution: Option<f64>,
    path: &Path,
    model: &SensorModel,
) -> Result<ModelCalibration> {
    let err = |message: String| Error::Config {
        path: path.to_path_buf(),
        message,
    };
    let n = model.lasers;
    if let Some(k) = num_lasers {
        if k != n as i64 {
            return Err(err(format!(
                "num_lasers is {k}, but a {} has {n} lasers",
                model.name
            )));
        }
    }
    let resolution = resolution.unwrap_or(model.distance_resolution_m);
    if !(resolution.is_finite() && resolution > 0.0 && resolution < 1.0) {
        return Err(err(format!(
            "distance resolution {resolution} m is not a size in metres"
        )));
    }
    let mut lasers: Vec<Option<LaserCorrection>> = vec![None; n];
    for (place, l) in entries {
        let id = usize::try_from(l.laser_id)
            .ok()
            .filter(|&id| id < n)
            .ok_or_else(|| {
                err(format!(
                    "{place}: laser_id {} is not one of the {n} lasers of a {}",
                    l.laser_id, model.name
                ))
            })?;
        let values = [
            ("rot_correction", l.rot_correction),
            ("vert_correction", l.vert_correction),
            ("dist_correction", l.dist_correction),
            ("dist_correction_x", l.dist_correction_x),
            ("dist_correction_y", l.dist_correction_y),
            ("vert_offset_correction", l.vert_offset_correction),
            ("horiz_offset_correction", l.horiz_offset_correction),
        ];
        if let Some((key, v)) = values.iter().find(|(_, v)| !v.is_finite()) {
            return Err(err(format!("{place} (laser {id}): {key} is {v}")));
        }
        for (key, v) in &values[..2] {
            if v.abs() > std::f64::consts::FRAC_PI_2 {
                return Err(err(format!(
                    "{place} (laser {id}): {key} {v} rad is beyond 90 degrees: radians are \
                     expected"
                )));
            }
        }
        if lasers[id].is_some() {
            return Err(err(format!("{place}: laser_id {id} appears twice")));
        }
        lasers[id] = Some(LaserCorrection {
            elevation_deg: l.vert_correction.to_degrees(),
            azimuth_offset_deg: -l.rot_correction.to_degrees(),
            dist_correction_m: l.dist_correction,
            dist_correction_x_m: l.dist_correction_x,
            dist_correction_y_m: l.dist_correction_y,
            vert_offset_m: l.vert_offset_correction,
            horiz_offset_m: l.horiz_offset_correction,
        });
    }
    let lasers = lasers
        .into_iter()
        .enumerate()
        .map(|(id, l)| l.ok_or_else(|| err(format!("laser {id} is missing from the file"))))
        .collect::<Result<Vec<_>>>()?;
    Ok(ModelCalibration {
        lasers,
        distance_resolution_m: resolution,
        source: path.display().to_string(),
    })
}

/// The first child element of `node` named `name`.
fn child<'a, 'i>(node: roxmltree::Node<'a, 'i>, name: &str) -> Option<roxmltree::Node<'a, 'i>> {
    node.children().find(|n| n.has_tag_name(name))
}

/// CRC-16 with polynomial 0x8005, initial value 0, no reflection (the HDL-64E S3's
/// calibration check).
fn crc16(bytes: impl Iterator<Item = u8>) -> u16 {
    let mut reg: u16 = 0;
    for octet in bytes {
        for i in 0..8 {
            let mut top = reg & 0x8000;
            if octet & (0x80 >> i) != 0 {
                top ^= 0x8000;
            }
            reg <<= 1;
            if top != 0 {
                reg ^= 0x8005;
            }
        }
    }
    reg
}

/// The 64 laser records of a status calibration block (28 bytes each).
fn decode_records(
    records: &[u8],
    model: &SensorModel,
) -> std::result::Result<ModelCalibration, String> {
    let mut lasers: Vec<Option<LaserCorrection>> = vec![None; model.lasers];
    for (i, r) in records.chunks(28).enumerate() {
        let v = |k: usize| f64::from(i16::from_le_bytes([r[1 + 2 * k], r[2 + 2 * k]]));
        let id = usize::from(r[0]);
        if id >= model.lasers || lasers[id].is_some() {
            return Err(format!(
                "status calibration record {i} names laser {id}: not a new laser of 0..{}",
                model.lasers - 1
            ));
        }
        lasers[id] = Some(LaserCorrection {
            elevation_deg: v(0) * 0.01,
            azimuth_offset_deg: -v(1) * 0.01,
            dist_correction_m: v(2) * 0.001,
            dist_correction_x_m: v(3) * 0.001,
            dist_correction_y_m: v(4) * 0.001,
            vert_offset_m: v(5) * 0.001,
            horiz_offset_m: v(6) * 0.001,
        });
    }
    Ok(ModelCalibration {
        lasers: lasers
            .into_iter()
            .map(|l| l.expect("64 records, each id once"))
            .collect(),
        distance_resolution_m: model.distance_resolution_m,
        source: "the packets' status bytes".to_string(),
    })
}
