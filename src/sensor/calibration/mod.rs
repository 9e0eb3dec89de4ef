//! Per-laser calibration of the described sensors, read from the two formats users have:
//! the ROS velodyne driver's YAML ([`yaml`]) and VeloView's XML ([`xml`]).
//!
//! [`Calibration`] is the HDL-32E's (32 lasers: elevation, azimuth offset, distance
//! offset; the decoder's HDL-32E kernel); [`ModelCalibration`] any model's, with every
//! correction of the HDL-64E's formulas, also read from an HDL-64E's status bytes.

mod model;
pub mod xml;
pub mod yaml;

pub use model::{LaserCorrection, ModelCalibration};

use crate::error::{Error, Result};
use std::path::Path;

/// Number of lasers in an HDL-32E.
pub const LASERS: usize = 32;

/// Calibration of one laser.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LaserCal {
    /// Elevation angle in degrees (positive up).
    pub elevation_deg: f64,
    /// Azimuth offset in degrees: point azimuth = block azimuth + `azimuth_offset_deg`
    /// (both clockwise seen from above, as in the packet).
    ///
    /// Note the sign: the ROS driver (`rawdata.cc`, `cos(a - rot)` via
    /// `cos_rot_table_ * cos_rot_correction + sin_rot_table_ * sin_rot_correction`) and
    /// VeloView (`realAzimuth = azimuth/100 - rotationalCorrection`) both compute the
    /// point azimuth as block azimuth MINUS the rotational correction, so this field is
    /// the NEGATED ROS `rot_correction` (radians, converted to degrees) or VeloView
    /// `rotCorrection_` (degrees).
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

    /// Reads a ROS YAML or VeloView XML calibration file, telling them apart by content.
    ///
    /// A file whose first non-blank character is `<` is XML, anything else is YAML; the
    /// extension is not trusted because users rename these files freely.
    pub fn from_file(path: &Path) -> Result<Self> {
        let bytes = crate::error::read_bounded(path)?;
        let text = String::from_utf8(bytes).map_err(|e| Error::Config {
            path: path.to_path_buf(),
            message: format!(
                "not a text file (invalid UTF-8 at byte {})",
                e.utf8_error().valid_up_to()
            ),
        })?;
        if looks_like_xml(&text) {
            xml::parse_str(&text, path)
        } else {
            yaml::parse_str(&text, path)
        }
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

/// True when the first non-blank character (after an optional BOM) is `<`.
fn looks_like_xml(text: &str) -> bool {
    text.trim_start_matches('\u{feff}')
        .trim_start()
        .starts_with('<')
}

/// One laser entry as read from a file, before validation.
#[derive(Clone, Debug)]
struct RawLaser {
    /// Laser id as written in the file.
    id: i64,
    /// Where the entry is, for messages ("lasers[3] (line 12)").
    place: String,
    /// Elevation in degrees.
    elevation_deg: f64,
    /// Azimuth offset in degrees, already in the `azimuth_offset_deg` sign convention.
    azimuth_offset_deg: f64,
    /// Distance offset in metres.
    distance_offset_m: f64,
    /// Corrections we do not model, by file key, with their values (must be zero).
    unsupported: Vec<(&'static str, f64)>,
}

impl RawLaser {
    /// True for an all-zero entry (the unused upper-block slots of HDL-32E files).
    fn is_placeholder(&self) -> bool {
        self.elevation_deg == 0.0
            && self.azimuth_offset_deg == 0.0
            && self.distance_offset_m == 0.0
            && self.unsupported.iter().all(|&(_, v)| v == 0.0)
    }
}

/// Smallest distance unit accepted (m).
pub const MIN_DISTANCE_RESOLUTION_M: f64 = 1e-4;
/// Largest distance unit accepted (m).
pub const MAX_DISTANCE_RESOLUTION_M: f64 = 0.1;
/// Largest per-laser distance correction accepted (m).
pub const MAX_DISTANCE_OFFSET_M: f64 = 10.0;

/// Checks the entries of a file and builds the calibration.
///
/// Real HDL-32E files (ROS `32db.yaml`, VeloView `HDL-32.xml`) carry 64 entries of
/// which ids 32..63 are all-zero placeholders; those are skipped. Any non-zero entry
/// outside 0..31 is an error, as is a missing or repeated id in 0..31.
///
/// Entries are checked one at a time as a reader meets them, so a reader stops at the
/// first bad entry instead of reading the rest of a long file first; each check is a
/// constant-time lookup in the 32 slots, whatever the number of entries.
struct Assembler<'p> {
    path: &'p Path,
    distance_resolution_m: f64,
    slots: [Option<LaserCal>; LASERS],
    places: [Option<String>; LASERS],
}

impl<'p> Assembler<'p> {
    /// Checks the distance unit (read before the entries in both formats).
    fn new(path: &'p Path, distance_resolution_m: f64) -> Result<Self> {
        let lasers = Assembler {
            path,
            distance_resolution_m,
            slots: [None; LASERS],
            places: std::array::from_fn(|_| None),
        };
        // Velodyne sensors count distance in 2 mm (HDL-32E, VLP-16, HDL-64E) or 4 mm
        // (VLS-128) units: a unit outside 0.1 mm..10 cm is a unit mistake, and would drop
        // or scatter every return.
        if !(distance_resolution_m.is_finite()
            && (MIN_DISTANCE_RESOLUTION_M..=MAX_DISTANCE_RESOLUTION_M)
                .contains(&distance_resolution_m))
        {
            return Err(lasers.err(format!(
                "distance resolution (ROS `distance_resolution`, VeloView `distLSB_` in cm) is \
                 {distance_resolution_m} m, outside the physically possible {MIN_DISTANCE_RESOLUTION_M} \
                 to {MAX_DISTANCE_RESOLUTION_M} m (the HDL-32E's is 0.002 m)"
            )));
        }
        Ok(lasers)
    }

    fn err(&self, message: String) -> Error {
        Error::Config {
            path: self.path.to_path_buf(),
            message,
        }
    }

    /// Checks one entry and files it under its id; the error names the entry's place.
    fn push(&mut self, laser: RawLaser) -> Result<()> {
        let id = laser.id;
        let in_range = (0..LASERS as i64).contains(&id);
        if !in_range {
            if id >= LASERS as i64 && laser.is_placeholder() {
                return Ok(());
            }
            return Err(self.err(format!(
                "{}: laser id {id} is outside 0..{} (an HDL-32E has {LASERS} lasers; only \
                 all-zero placeholder entries may use other ids)",
                laser.place,
                LASERS - 1
            )));
        }
        let idx = id as usize;
        if let Some(first) = &self.places[idx] {
            return Err(self.err(format!(
                "{}: duplicate laser id {id} (first defined at {first})",
                laser.place
            )));
        }
        for &(key, value) in &laser.unsupported {
            if value != 0.0 {
                return Err(self.err(format!(
                    "{}: laser {id}: `{key}` = {value} is not supported (only zero \
                     horizontal/vertical offset corrections can be used)",
                    laser.place
                )));
            }
        }
        for (what, value) in [
            ("elevation", laser.elevation_deg),
            ("rotational correction", laser.azimuth_offset_deg),
            ("distance correction", laser.distance_offset_m),
        ] {
            if !value.is_finite() {
                return Err(self.err(format!(
                    "{}: laser {id}: {what} is not a finite number",
                    laser.place
                )));
            }
        }
        if laser.azimuth_offset_deg.abs() > 180.0 {
            return Err(self.err(format!(
                "{}: laser {id}: rotational correction {} degrees is outside [-180, 180] \
                 (real corrections are a few degrees)",
                laser.place, laser.azimuth_offset_deg
            )));
        }
        if laser.distance_offset_m.abs() > MAX_DISTANCE_OFFSET_M {
            return Err(self.err(format!(
                "{}: laser {id}: distance correction {} m is outside +-{MAX_DISTANCE_OFFSET_M} m \
                 (real corrections are under 2 m; centimetres and metres mixed up?)",
                laser.place, laser.distance_offset_m
            )));
        }
        if laser.elevation_deg.abs() > 90.0 {
            return Err(self.err(format!(
                "{}: laser {id}: elevation {} degrees is outside [-90, 90] (radians and degrees mixed up?)",
                laser.place, laser.elevation_deg
            )));
        }
        self.slots[idx] = Some(LaserCal {
            elevation_deg: laser.elevation_deg,
            azimuth_offset_deg: laser.azimuth_offset_deg,
            distance_offset_m: laser.distance_offset_m,
        });
        self.places[idx] = Some(laser.place);
        Ok(())
    }

    /// The calibration, once every id 0..31 was given.
    fn finish(self) -> Result<Calibration> {
        let missing: Vec<String> = (0..LASERS)
            .filter(|&i| self.slots[i].is_none())
            .map(|i| i.to_string())
            .collect();
        if !missing.is_empty() {
            return Err(self.err(format!(
                "missing laser id(s) {}: an HDL-32E calibration needs ids 0..{} exactly once",
                missing.join(", "),
                LASERS - 1
            )));
        }
        let lasers = self
            .slots
            .map(|s| s.expect("checked above: every slot is filled"));
        Ok(Calibration {
            lasers,
            distance_resolution_m: self.distance_resolution_m,
            source: self.path.display().to_string(),
        })
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    #[test]
    fn builtin_rings_follow_the_ros_convention() {
        let cal = Calibration::builtin();
        let rings = cal.rings();
        assert_eq!(rings[0], 0, "laser 0 is the lowest");
        assert_eq!(rings[31], 31, "laser 31 is the highest");
        // Laser 30 (-10.67) is the highest of the 16 even (lower) lasers; laser 7
        // (-5.33) is the fourth odd one above it.
        assert_eq!(rings[30], 15);
        assert_eq!(rings[7], 19);
        let mut seen = rings.to_vec();
        seen.sort();
        assert_eq!(seen, (0..32).collect::<Vec<u8>>());
    }

    #[test]
    fn builtin_table_matches_the_formula() {
        for (id, &table) in BUILTIN_ELEVATION_DEG.iter().enumerate() {
            let formula = if id % 2 == 0 {
                -30.67 + (id / 2) as f64 * 1.333
            } else {
                -9.33 + ((id - 1) / 2) as f64 * 1.333
            };
            assert!(
                // The manual's steps are 4/3 degree rounded to 0.01, the formula's 1.333.
                (table - formula).abs() < 0.015,
                "laser {id}: table {table} formula {formula}"
            );
        }
    }

    fn fixture(name: &str) -> std::path::PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("tests/data/calibration")
            .join(name)
    }

    pub(crate) fn assert_matches_builtin(cal: &Calibration) {
        let builtin = Calibration::builtin();
        for id in 0..LASERS {
            let (a, b) = (cal.lasers[id], builtin.lasers[id]);
            assert!(
                (a.elevation_deg - b.elevation_deg).abs() < 1e-9,
                "laser {id}"
            );
            assert!((a.azimuth_offset_deg - b.azimuth_offset_deg).abs() < 1e-9);
            assert!((a.distance_offset_m - b.distance_offset_m).abs() < 1e-9);
        }
        assert!((cal.distance_resolution_m - builtin.distance_resolution_m).abs() < 1e-15);
    }

    #[test]
    fn fixture_files_match_the_builtin_table() {
        for name in ["hdl32e_ros.yaml", "hdl32e_veloview.xml"] {
            let path = fixture(name);
            let cal = Calibration::from_file(&path).unwrap();
            assert_matches_builtin(&cal);
            assert_eq!(cal.source, path.display().to_string());
        }
    }

    #[test]
    fn format_is_detected_by_content_not_extension() {
        let dir = tempfile::tempdir().unwrap();
        let yaml_as_xml = dir.path().join("calib.xml");
        std::fs::copy(fixture("hdl32e_ros.yaml"), &yaml_as_xml).unwrap();
        assert_matches_builtin(&Calibration::from_file(&yaml_as_xml).unwrap());
        let xml_as_yaml = dir.path().join("calib.yaml");
        std::fs::copy(fixture("hdl32e_veloview.xml"), &xml_as_yaml).unwrap();
        assert_matches_builtin(&Calibration::from_file(&xml_as_yaml).unwrap());
    }

    #[test]
    fn malformed_fixtures_name_file_and_line() {
        let path = fixture("duplicate_id.yaml");
        let m = Calibration::from_file(&path).unwrap_err().to_string();
        assert!(m.starts_with(&path.display().to_string()), "{m}");
        assert!(
            m.contains("lasers[9] (line 12): duplicate laser id 8"),
            "{m}"
        );

        let path = fixture("wrong_type.xml");
        let m = Calibration::from_file(&path).unwrap_err().to_string();
        assert!(m.starts_with(&path.display().to_string()), "{m}");
        assert!(
            m.contains("line 40: <rotCorrection_> holds \"zero\""),
            "{m}"
        );
    }

    #[test]
    fn missing_and_binary_files_are_errors() {
        let m = Calibration::from_file(Path::new("/nonexistent/calib.yaml"))
            .unwrap_err()
            .to_string();
        assert!(m.contains("/nonexistent/calib.yaml"), "{m}");
        let dir = tempfile::tempdir().unwrap();
        let bin = dir.path().join("calib.bin");
        std::fs::write(&bin, [0xffu8, 0xfe, 0x00, 0x80]).unwrap();
        let m = Calibration::from_file(&bin).unwrap_err().to_string();
        assert!(m.contains("invalid UTF-8"), "{m}");
    }
}
