//! Per-laser calibration: elevation, azimuth offset and ring of each HDL-32E laser.

use crate::error::Result;
use std::path::Path;

/// Number of lasers in an HDL-32E.
pub const LASERS: usize = 32;

/// Calibration of one laser.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LaserCal {
    /// Elevation angle in degrees (positive up).
    pub elevation_deg: f64,
    /// Azimuth offset in degrees added to the block azimuth (ROS `rot_correction`,
    /// converted to degrees, same sign).
    pub azimuth_offset_deg: f64,
    /// Additive distance correction in metres (ROS `dist_correction`).
    pub distance_offset_m: f64,
}

/// Calibration of a whole sensor.
#[derive(Clone, Debug, PartialEq)]
pub struct Calibration {
    /// Per-laser calibration, indexed by laser id.
    pub lasers: [LaserCal; LASERS],
    /// Size of one raw distance unit in metres (0.002 for the HDL-32E).
    pub distance_resolution_m: f64,
    /// Where the calibration came from ("built-in" or a file path).
    pub source: String,
}

/// Elevations of the built-in table (HDL-32E manual), indexed by laser id.
pub const BUILTIN_ELEVATION_DEG: [f64; LASERS] = [
    -30.67, -9.33, -29.33, -8.00, -28.00, -6.67, -26.67, -5.33, -25.33, -4.00, -24.00, -2.67,
    -22.67, -1.33, -21.33, 0.00, -20.00, 1.33, -18.67, 2.67, -17.33, 4.00, -16.00, 5.33, -14.67,
    6.67, -13.33, 8.00, -12.00, 9.33, -10.67, 10.67,
];

impl Calibration {
    /// The manual's table: no azimuth or distance offsets, 2 mm distance units.
    pub fn builtin() -> Self {
        let mut lasers = [LaserCal {
            elevation_deg: 0.0,
            azimuth_offset_deg: 0.0,
            distance_offset_m: 0.0,
        }; LASERS];
        for (cal, &elevation_deg) in lasers.iter_mut().zip(BUILTIN_ELEVATION_DEG.iter()) {
            cal.elevation_deg = elevation_deg;
        }
        Calibration {
            lasers,
            distance_resolution_m: 0.002,
            source: "built-in".to_string(),
        }
    }

    /// Reads a ROS YAML or VeloView XML calibration file.
    pub fn from_file(path: &Path) -> Result<Self> {
        Err(crate::error::Error::Config {
            path: path.to_path_buf(),
            message: "calibration files are not supported yet".into(),
        })
    }

    /// Ring of each laser: laser ids sorted by elevation, 0 = lowest.
    pub fn rings(&self) -> [u8; LASERS] {
        let mut ids: Vec<usize> = (0..LASERS).collect();
        // Stable sort keeps equal elevations in id order, so rings are deterministic.
        ids.sort_by(|&a, &b| {
            self.lasers[a]
                .elevation_deg
                .total_cmp(&self.lasers[b].elevation_deg)
        });
        let mut rings = [0u8; LASERS];
        for (ring, &id) in ids.iter().enumerate() {
            rings[id] = ring as u8;
        }
        rings
    }

    /// Laser id of each ring (inverse of [`Calibration::rings`]).
    pub fn lasers_by_ring(&self) -> [u8; LASERS] {
        let rings = self.rings();
        let mut ids = [0u8; LASERS];
        for (id, &ring) in rings.iter().enumerate() {
            ids[ring as usize] = id as u8;
        }
        ids
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn builtin_rings_follow_the_ros_convention() {
        let cal = Calibration::builtin();
        let rings = cal.rings();
        assert_eq!(rings[0], 0, "laser 0 is the lowest");
        assert_eq!(rings[31], 31, "laser 31 is the highest");
        assert_eq!(rings[30], 19);
        assert_eq!(rings[7], 15);
        let mut seen = rings.to_vec();
        seen.sort();
        assert_eq!(seen, (0..32).collect::<Vec<u8>>());
    }

    #[test]
    fn builtin_table_matches_the_formula() {
        for id in 0..LASERS {
            let formula = if id % 2 == 0 {
                -30.67 + (id / 2) as f64 * 1.333
            } else {
                -9.33 + ((id - 1) / 2) as f64 * 1.333
            };
            assert!(
                (BUILTIN_ELEVATION_DEG[id] - formula).abs() < 0.01,
                "laser {id}: table {} formula {formula}",
                BUILTIN_ELEVATION_DEG[id]
            );
        }
    }
}
