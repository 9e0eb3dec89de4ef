//! KITTI and SemanticKITTI `velodyne/*.bin` scans: a bare array of points, each four
//! float32 little-endian values x y z reflectance (16 bytes, no header), x forward, y left,
//! z up in metres, reflectance 0 to 1.
//!
//! Source: KITTI raw data development kit, `readme.txt`, "Velodyne 3D laser scan data"
//! (and its `readVelodynePoints` / `fread(fid,[4 inf],'single')`); Geiger, Lenz, Stiller,
//! Urtasun, "Vision meets Robotics: The KITTI Dataset", IJRR 2013, section 3.2.
//! SemanticKITTI (Behley et al., ICCV 2019) keeps the same `.bin` files.

use super::{check_record_size, CloudPoint, Fields, Format};
use crate::error::Result;
use std::path::Path;

/// Bytes a point: 4 float32.
pub const POINT_BYTES: usize = 16;

/// Parses a KITTI `.bin` (`path` is named in errors).
///
/// One pass over the bytes with fixed-size chunks and `from_le_bytes`: no per-point
/// allocation, so the conversion runs at memory speed (about 6.5 GB/s of input on the
/// 2-core build machine; read and checks included, 2.7 GB/s: notes/h-cloud.md).
pub fn parse(bytes: &[u8], path: &Path) -> Result<(Vec<CloudPoint>, Fields)> {
    check_record_size(bytes, POINT_BYTES, Format::Kitti, path)?;
    let f = |b: &[u8]| f32::from_le_bytes([b[0], b[1], b[2], b[3]]);
    // Checked as they are read (the scan has no rings or times, so finite values are all
    // `check_points` asks of it; its own pass read the points back, a seventieth of a
    // dataset run), and by `check_points` only to name the first offending point.
    let mut sound = true;
    let points: Vec<CloudPoint> = bytes
        .chunks_exact(POINT_BYTES)
        .map(|c| {
            let p = CloudPoint {
                x: f(&c[0..4]),
                y: f(&c[4..8]),
                z: f(&c[8..12]),
                intensity: f(&c[12..16]),
                ring: None,
                time: None,
            };
            sound &= p.values_finite();
            p
        })
        .collect();
    if !sound {
        super::check_points(&points, path, None)?;
    }
    Ok((
        points,
        Fields {
            intensity: true,
            ring: false,
            time: false,
        },
    ))
}
