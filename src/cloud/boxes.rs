//! KITTI object `label_2` boxes as per-point ground truth (issue 31: "KITTI `label_2`
//! boxes (camera frame, with the calibration file) map points to objects").
//!
//! Formats (KITTI object development kit, `readme.txt`):
//! - `label_2/NNNNNN.txt`: one object a line, 15 space-separated values: type, truncated,
//!   occluded, alpha, the 2-D box (4 values), then the 3-D box: height, width, length
//!   (metres), location x y z of the box's bottom centre in the rectified camera frame
//!   (x right, y down, z forward), and rotation_y around the camera's y axis. `DontCare`
//!   lines mark regions without labels and are no object.
//! - `calib/NNNNNN.txt`: `KEY: values` lines; `R0_rect` (3x3, row-major) and
//!   `Tr_velo_to_cam` (3x4, row-major) take a Velodyne point to the rectified camera
//!   frame: p_rect = R0_rect (Tr_velo_to_cam [x y z 1]).
//!
//! A point belongs to the first box (file order) that holds it: rotated into the box's
//! frame (R_y(ry) as the devkit's `computeBox3D` builds the corners: length along x,
//! width along z), |x| <= l/2, |z| <= w/2 and -h <= y <= 0 from the bottom centre. The
//! boxes say nothing of ground: box truth has objects only.

use super::labels::GroundTruth;
use super::{invalid, CloudPoint};
use crate::error::Result;
use std::collections::BTreeMap;
use std::path::Path;

/// One 3-D box of a `label_2` file.
#[derive(Clone, Debug, PartialEq)]
pub struct Box3d {
    /// Object type (`Car`, `Pedestrian`, ...).
    pub kind: String,
    /// Height, width, length in metres.
    pub hwl: [f64; 3],
    /// Bottom centre in the rectified camera frame, metres.
    pub location: [f64; 3],
    /// Rotation around the camera's y axis, radians.
    pub rotation_y: f64,
}

/// Largest `label_2` or calibration file read (bytes); real ones are under 4 KB.
const MAX_TEXT_BYTES: u64 = 1 << 20;

/// Reads the boxes of a `label_2` file (`DontCare` lines skipped).
pub fn read_label2(path: &Path) -> Result<Vec<Box3d>> {
    let bytes = super::read_at_most(path, MAX_TEXT_BYTES, "not a KITTI label_2 file")?;
    parse_label2(&String::from_utf8_lossy(&bytes), path)
}

/// Parses `label_2` text (the content of `path`, named in errors with the line).
pub fn parse_label2(text: &str, path: &Path) -> Result<Vec<Box3d>> {
    let mut out = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let fields: Vec<&str> = line.split_whitespace().collect();
        if fields.is_empty() {
            continue;
        }
        if fields.len() < 15 {
            return Err(invalid(
                path,
                format!(
                    "line {}: {} values where a KITTI label_2 line has 15 (type, truncated, \
                     occluded, alpha, 2-D box, h w l, x y z, rotation_y)",
                    n + 1,
                    fields.len()
                ),
            ));
        }
        let mut v = [0.0f64; 7];
        for (k, slot) in v.iter_mut().enumerate() {
            let s = fields[8 + k];
            *slot = s
                .parse()
                .ok()
                .filter(|x: &f64| x.is_finite())
                .ok_or_else(|| {
                    invalid(
                        path,
                        format!(
                            "line {}, value {}: {s:?} is not a finite number",
                            n + 1,
                            9 + k
                        ),
                    )
                })?;
        }
        if fields[0] == "DontCare" {
            continue;
        }
        out.push(Box3d {
            kind: fields[0].to_string(),
            hwl: [v[0], v[1], v[2]],
            location: [v[3], v[4], v[5]],
            rotation_y: v[6],
        });
    }
    Ok(out)
}

/// Velodyne to rectified camera frame: R0_rect times Tr_velo_to_cam, 3x4 row-major.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VeloToRect(pub [[f64; 4]; 3]);

/// Reads `R0_rect` and `Tr_velo_to_cam` of a KITTI object `calib` file.
pub fn read_calib(path: &Path) -> Result<VeloToRect> {
    let bytes = super::read_at_most(path, MAX_TEXT_BYTES, "not a KITTI calibration file")?;
    parse_calib(&String::from_utf8_lossy(&bytes), path)
}

/// Parses calibration text (the content of `path`).
pub fn parse_calib(text: &str, path: &Path) -> Result<VeloToRect> {
    let key = |name: &str, n: usize| -> Result<Vec<f64>> {
        let (no, line) = text
            .lines()
            .enumerate()
            .find(|(_, l)| l.trim_start().starts_with(&format!("{name}:")))
            .ok_or_else(|| {
                invalid(
                    path,
                    format!("no {name} line (a KITTI object calib file has one)"),
                )
            })?;
        let values: Vec<f64> = line
            .split_once(':')
            .map_or("", |(_, v)| v)
            .split_whitespace()
            .map(|s| s.parse::<f64>().ok().filter(|x| x.is_finite()))
            .collect::<Option<_>>()
            .ok_or_else(|| {
                invalid(
                    path,
                    format!(
                        "line {}: {name} holds a value that is not a finite number",
                        no + 1
                    ),
                )
            })?;
        if values.len() != n {
            return Err(invalid(
                path,
                format!(
                    "line {}: {name} has {} values, not {n}",
                    no + 1,
                    values.len()
                ),
            ));
        }
        Ok(values)
    };
    let r = key("R0_rect", 9)?;
    let t = key("Tr_velo_to_cam", 12)?;
    let mut m = [[0.0; 4]; 3];
    for (i, row) in m.iter_mut().enumerate() {
        for (j, cell) in row.iter_mut().enumerate() {
            *cell = (0..3).map(|k| r[3 * i + k] * t[4 * k + j]).sum();
        }
    }
    Ok(VeloToRect(m))
}

impl VeloToRect {
    /// A Velodyne point in the rectified camera frame.
    pub fn apply(&self, p: [f64; 3]) -> [f64; 3] {
        let m = &self.0;
        [0, 1, 2].map(|i| m[i][0] * p[0] + m[i][1] * p[1] + m[i][2] * p[2] + m[i][3])
    }
}

impl Box3d {
    /// True when the rectified-camera point `p` is inside the box.
    pub fn contains(&self, p: [f64; 3]) -> bool {
        let [h, w, l] = self.hwl;
        let d = [
            p[0] - self.location[0],
            p[1] - self.location[1],
            p[2] - self.location[2],
        ];
        let (s, c) = self.rotation_y.sin_cos();
        // R_y(ry)^T d: the point in the box's own axes.
        let x = c * d[0] - s * d[2];
        let z = s * d[0] + c * d[2];
        x.abs() <= l / 2.0 && z.abs() <= w / 2.0 && d[1] <= 0.0 && d[1] >= -h
    }
}

/// Ground truth of `points` from `boxes`: object id k + 1 for points in box k (the first
/// box holding them), classes by id, no ground.
pub fn box_truth(points: &[CloudPoint], boxes: &[Box3d], calib: &VeloToRect) -> GroundTruth {
    let objects = points
        .iter()
        .map(|p| {
            let q = calib.apply([f64::from(p.x), f64::from(p.y), f64::from(p.z)]);
            boxes
                .iter()
                .position(|b| b.contains(q))
                .map_or(-1, |k| k as i32 + 1)
        })
        .collect();
    let classes: BTreeMap<i32, String> = boxes
        .iter()
        .enumerate()
        .map(|(k, b)| (k as i32 + 1, b.kind.clone()))
        .collect();
    GroundTruth {
        ground: vec![false; points.len()],
        objects,
        classes,
        without_instance: 0,
    }
}
