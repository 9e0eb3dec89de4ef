//! Per-laser calibration of any described sensor (HDL-64E units above all: every unit
//! ships its own table), read from the ROS velodyne driver's YAML, including the
//! corrections `src/calibration/` refuses for the HDL-32E: distance offset, two-point
//! distance correction, vertical and horizontal offsets.
//!
//! Written here rather than by extending `src/calibration/`, whose readers and
//! `Calibration` type are fixed at the HDL-32E's 32 lasers and refuse the offsets; the
//! YAML is parsed with serde_norway as there.
//!
//! Conventions: `azimuth_offset_deg` is the negated `rot_correction` (point azimuth =
//! block azimuth + offset), elevations in degrees, lengths in metres. How the corrections
//! apply is [`LaserCorrection::position`]: the HDL-64E S3 manual's formulas as the ROS
//! driver (`rawdata.cc`) and velodyne_decoder 3 apply them (two-point correction between
//! 2.40 m / 1.93 m and 25.04 m, the horizontal offset across the beam, z corrected by the
//! mean of the x and y corrections as velodyne_decoder does).

use super::SensorModel;
use crate::error::{Error, Result};
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

    /// Parses a ROS velodyne calibration YAML for `model`: every laser id from 0 to
    /// `model.lasers - 1` exactly once, finite values, angles in radians within +-90
    /// degrees; `path` names the file in errors.
    pub fn from_ros_yaml(text: &str, path: &Path, model: &SensorModel) -> Result<Self> {
        let err = |message: String| Error::Config {
            path: path.to_path_buf(),
            message,
        };
        let file: RosFile = serde_norway::from_str(text)
            .map_err(|e| err(format!("not a ROS velodyne calibration YAML: {e}")))?;
        let n = model.lasers;
        if let Some(k) = file.num_lasers {
            if k != n as i64 {
                return Err(err(format!(
                    "num_lasers is {k}, but a {} has {n} lasers",
                    model.name
                )));
            }
        }
        let resolution = file
            .distance_resolution
            .unwrap_or(model.distance_resolution_m);
        if !(resolution.is_finite() && resolution > 0.0 && resolution < 1.0) {
            return Err(err(format!(
                "distance_resolution {resolution} is not a size in metres"
            )));
        }
        let mut lasers: Vec<Option<LaserCorrection>> = vec![None; n];
        for (i, l) in file.lasers.iter().enumerate() {
            let id = usize::try_from(l.laser_id)
                .ok()
                .filter(|&id| id < n)
                .ok_or_else(|| {
                    err(format!(
                        "lasers[{i}]: laser_id {} is not one of the {n} lasers of a {}",
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
                return Err(err(format!("lasers[{i}] (laser {id}): {key} is {v}")));
            }
            for (key, v) in &values[..2] {
                if v.abs() > std::f64::consts::FRAC_PI_2 {
                    return Err(err(format!(
                        "lasers[{i}] (laser {id}): {key} {v} is beyond 90 degrees: \
                         radians are expected"
                    )));
                }
            }
            if lasers[id].is_some() {
                return Err(err(format!("lasers[{i}]: laser_id {id} appears twice")));
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
            .map(|(id, l)| l.ok_or_else(|| err(format!("laser {id} is missing from lasers"))))
            .collect::<Result<Vec<_>>>()?;
        Ok(ModelCalibration {
            lasers,
            distance_resolution_m: resolution,
            source: path.display().to_string(),
        })
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
