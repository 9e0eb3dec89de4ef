//! nuScenes `samples/LIDAR_TOP/*.pcd.bin` and `sweeps/LIDAR_TOP/*.pcd.bin` (HDL-32E): a
//! bare array of points, each five float32 little-endian values x y z intensity ring_index
//! (20 bytes, no header, despite the `.pcd` in the name), metres in the sensor frame,
//! intensity 0 to 255, ring index 0 to 31.
//!
//! Source: nuscenes-devkit, `python-sdk/nuscenes/utils/data_classes.py`,
//! `LidarPointCloud.from_file` (`np.fromfile(..., dtype=np.float32).reshape((-1, 5))`),
//! and the nuScenes data format page ("lidar: x y z intensity ring index").

use super::{check_record_size, ring_from_f64, CloudPoint, Fields, Format};
use crate::error::Result;
use std::path::Path;

/// Bytes a point: 5 float32.
pub const POINT_BYTES: usize = 20;

/// Parses a nuScenes `.pcd.bin` (`path` is named in errors); a ring index that is not a
/// whole number from 0 to 65535 is refused with its point index.
pub fn parse(bytes: &[u8], path: &Path) -> Result<(Vec<CloudPoint>, Fields)> {
    let n = check_record_size(bytes, POINT_BYTES, Format::NuScenes, path)?;
    let f = |b: &[u8]| f32::from_le_bytes([b[0], b[1], b[2], b[3]]);
    let mut points = Vec::with_capacity(n);
    for (i, c) in bytes.chunks_exact(POINT_BYTES).enumerate() {
        let ring = ring_from_f64(f64::from(f(&c[16..20])), i, path)?;
        points.push(CloudPoint {
            x: f(&c[0..4]),
            y: f(&c[4..8]),
            z: f(&c[8..12]),
            intensity: f(&c[12..16]),
            ring: Some(ring),
            time: None,
        });
    }
    Ok((
        points,
        Fields {
            intensity: true,
            ring: true,
            time: false,
        },
    ))
}
