//! ROS velodyne driver calibration YAML (`velodyne_pointcloud/params/32db.yaml`).
//!
//! Layout: a top-level `lasers:` list of maps with `laser_id`, `rot_correction` and
//! `vert_correction` (radians), `dist_correction` (metres) and the other per-laser
//! keys; optional top-level `num_lasers` and `distance_resolution` (metres, default
//! 0.002). Intensity keys (`focal_distance`, `focal_slope`, `min_intensity`,
//! `max_intensity`) are read and ignored: the tool reports the raw intensity byte.
//! The two-point distance correction (`dist_correction_x`/`_y`) is only used by the
//! ROS driver when `two_pt_correction_available` is true, which is refused here.

use super::{Assembler, Calibration, RawLaser, LASERS};
use crate::error::{Error, Result};
use serde::Deserialize;
use std::path::Path;

/// Default size of one raw distance unit, as in the ROS driver.
const DEFAULT_DISTANCE_RESOLUTION_M: f64 = 0.002;

/// The whole file.
#[derive(Debug, Deserialize)]
struct RosFile {
    /// Per-laser entries.
    lasers: Vec<RosLaser>,
    /// Number of lasers the driver reads from the list (32 for the HDL-32E).
    #[serde(default)]
    num_lasers: Option<i64>,
    /// Size of one raw distance unit in metres.
    #[serde(default)]
    distance_resolution: Option<f64>,
}

/// One `lasers:` entry.
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
    two_pt_correction_available: bool,
    #[serde(default)]
    horiz_offset_correction: f64,
    #[serde(default)]
    vert_offset_correction: f64,
    // Intensity corrections: accepted for completeness, not applied.
    #[serde(default)]
    #[allow(dead_code)]
    focal_distance: f64,
    #[serde(default)]
    #[allow(dead_code)]
    focal_slope: f64,
    #[serde(default)]
    #[allow(dead_code)]
    min_intensity: Option<f64>,
    #[serde(default)]
    #[allow(dead_code)]
    max_intensity: Option<f64>,
}

/// Deepest collection nesting accepted. ROS files nest two levels (a list of maps); the
/// YAML parser takes time quadratic in the nesting (16,000 nested `[` took 3.9 s).
pub const MAX_DEPTH: usize = 64;

/// The line of the first collection nested deeper than `max` levels, by one scan of the
/// text: flow collections (`[`, `{`) that open a node and block sequence entries written
/// on one line (`- - - x`) count; quoted scalars and comments are skipped. `None` when
/// the nesting stays within `max`.
fn too_deep(text: &str, max: usize) -> Option<usize> {
    let mut depth = 0usize;
    // Inside a quoted scalar (which may span lines): its quote character.
    let mut quote: Option<u8> = None;
    for (n, line) in text.lines().enumerate() {
        let b = line.as_bytes();
        // Block sequence entries opening this line.
        let mut block = 0usize;
        // The last character that was not a blank: a `[`, `{` or quote after one of
        // these (or at the start) opens a node.
        let mut prev: Option<u8> = None;
        // Inside a plain scalar (`x[[`): brackets there are text, up to the `,`, `]`, `}`
        // or `: ` that ends it in a flow collection, or the end of the line.
        let mut plain = false;
        let mut i = 0;
        while i < b.len() {
            let c = b[i];
            let blank_before = i == 0 || matches!(b[i - 1], b' ' | b'\t');
            let blank_after = matches!(b.get(i + 1), None | Some(b' ' | b'\t'));
            match quote {
                Some(b'"') if c == b'\\' => i += 1,
                Some(q) if c == q => {
                    // `''` inside a single-quoted scalar is an escaped quote.
                    if q == b'\'' && b.get(i + 1) == Some(&b'\'') {
                        i += 1;
                    } else {
                        quote = None;
                        prev = Some(c);
                    }
                }
                Some(_) => {}
                None if c == b'#' && blank_before => break,
                None if plain => {
                    let ends = match c {
                        b',' => true,
                        b':' => blank_after,
                        b']' | b'}' => {
                            depth = depth.saturating_sub(1);
                            true
                        }
                        _ => false,
                    };
                    if ends {
                        plain = false;
                        prev = Some(c);
                    }
                }
                None => {
                    let opens =
                        matches!(prev, None | Some(b':' | b'-' | b',' | b'[' | b'{' | b'?'));
                    match c {
                        b' ' | b'\t' => {}
                        b'"' | b'\'' if opens => quote = Some(c),
                        b'[' | b'{' if opens => depth += 1,
                        b']' | b'}' => depth = depth.saturating_sub(1),
                        b'-' if (prev.is_none() || prev == Some(b'-')) && blank_after => block += 1,
                        b',' | b':' | b'?' => {}
                        _ => plain = true,
                    }
                    if !matches!(c, b' ' | b'\t') {
                        prev = Some(c);
                    }
                }
            }
            if depth + block > max {
                return Some(n + 1);
            }
            i += 1;
        }
    }
    None
}

/// Parses ROS YAML calibration text; `path` is only used in messages and as the source.
pub fn parse_str(text: &str, path: &Path) -> Result<Calibration> {
    let err = |message: String| Error::Config {
        path: path.to_path_buf(),
        message,
    };
    if let Some(line) = too_deep(text, MAX_DEPTH) {
        return Err(err(format!(
            "collections nested more than {MAX_DEPTH} levels deep at line {line}: not a ROS \
             velodyne calibration file (they nest two levels)"
        )));
    }
    // serde_norway's message already carries "at line L column C" where it knows it.
    let file: RosFile = serde_norway::from_str(text)
        .map_err(|e| err(format!("not a ROS velodyne calibration YAML: {e}")))?;
    if let Some(n) = file.num_lasers {
        if n != LASERS as i64 {
            return Err(err(format!(
                "num_lasers is {n}, but an HDL-32E calibration has {LASERS}"
            )));
        }
    }
    let lines = laser_id_lines(text, file.lasers.len());
    let mut lasers = Assembler::new(
        path,
        file.distance_resolution
            .unwrap_or(DEFAULT_DISTANCE_RESOLUTION_M),
    )?;
    for (i, l) in file.lasers.iter().enumerate() {
        let place = match lines.as_ref().map(|v| v[i]) {
            Some(line) => format!("lasers[{i}] (line {line})"),
            None => format!("lasers[{i}]"),
        };
        if l.two_pt_correction_available
            && (l.dist_correction_x != 0.0 || l.dist_correction_y != 0.0)
        {
            return Err(err(format!(
                "{place}: laser {}: `two_pt_correction_available` with non-zero \
                 dist_correction_x/dist_correction_y is not supported",
                l.laser_id
            )));
        }
        // Checked at once: the first bad entry ends the read.
        lasers.push(RawLaser {
            id: l.laser_id,
            place,
            elevation_deg: l.vert_correction.to_degrees(),
            // Both ROS and VeloView compute point azimuth = block azimuth - rot_correction.
            azimuth_offset_deg: -l.rot_correction.to_degrees(),
            distance_offset_m: l.dist_correction,
            unsupported: vec![
                ("horiz_offset_correction", l.horiz_offset_correction),
                ("vert_offset_correction", l.vert_offset_correction),
            ],
        })?;
    }
    lasers.finish()
}

/// Line number (1-based) of each `laser_id` key, in file order, for messages.
///
/// serde gives no positions for values that parsed fine, so a laser's line is found by
/// scanning for its `laser_id` key. Returns `None` when the count does not match the
/// number of entries (the key hidden in an unusual layout); messages then omit the line.
fn laser_id_lines(text: &str, expected: usize) -> Option<Vec<usize>> {
    let mut lines = Vec::with_capacity(expected);
    for (n, line) in text.lines().enumerate() {
        // Drop comments so a commented-out entry does not count.
        let code = line.split('#').next().unwrap_or("");
        let mut rest = code;
        while let Some(pos) = rest.find("laser_id") {
            let after = rest[pos + "laser_id".len()..].trim_start();
            if after.starts_with(':') {
                lines.push(n + 1);
            }
            rest = &rest[pos + "laser_id".len()..];
        }
    }
    (lines.len() == expected).then_some(lines)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sensor::calibration::BUILTIN_ELEVATION_DEG;
    use std::path::PathBuf;

    fn fake_path() -> PathBuf {
        PathBuf::from("/calib/test.yaml")
    }

    /// ROS-style YAML (block style, one key per line) with the given vertical
    /// corrections in radians and the given per-laser rot_correction.
    fn ros_yaml(ids: &[i64], vert_rad: &[f64], rot_rad: f64) -> String {
        let mut s = String::from("# test calibration\nlasers:\n");
        for (&id, &v) in ids.iter().zip(vert_rad) {
            s.push_str(&format!(
                "- laser_id: {id}\n  rot_correction: {rot_rad:?}\n  vert_correction: {v:?}\n  \
                 dist_correction: 0.0\n  dist_correction_x: 0.0\n  dist_correction_y: 0.0\n  \
                 focal_distance: 0.0\n  focal_slope: 0.0\n  horiz_offset_correction: 0.0\n  \
                 vert_offset_correction: 0.0\n  min_intensity: 0.0\n  max_intensity: 255.0\n"
            ));
        }
        s.push_str("num_lasers: 32\ndistance_resolution: 0.002\n");
        s
    }

    fn builtin_rad() -> Vec<f64> {
        // Radians computed here with the textbook factor, independently of the parser.
        BUILTIN_ELEVATION_DEG
            .iter()
            .map(|d| d * std::f64::consts::PI / 180.0)
            .collect()
    }

    fn ids() -> Vec<i64> {
        (0..32).collect()
    }

    fn message(e: Error) -> String {
        e.to_string()
    }

    #[test]
    fn builtin_angles_round_trip() {
        let text = ros_yaml(&ids(), &builtin_rad(), 0.0);
        let cal = parse_str(&text, &fake_path()).unwrap();
        // Angles, offsets and the 2 mm distance unit (distLSB_ 0.2 cm in XML).
        crate::sensor::calibration::tests::assert_matches_builtin(&cal);
        assert_eq!(cal.rings(), Calibration::builtin().rings());
        assert_eq!(cal.source, "/calib/test.yaml");
    }

    #[test]
    fn rot_correction_is_negated_into_azimuth_offset() {
        // rot_correction 0.01 rad: ROS puts the point at block azimuth - 0.5729578 deg.
        let text = ros_yaml(&ids(), &builtin_rad(), 0.01);
        let cal = parse_str(&text, &fake_path()).unwrap();
        for l in cal.lasers {
            assert!((l.azimuth_offset_deg - (-0.572_957_795_130_823_2)).abs() < 1e-12);
        }
    }

    #[test]
    fn upper_block_placeholders_are_skipped_like_32db_yaml() {
        let mut all_ids = ids();
        let mut vert = builtin_rad();
        all_ids.extend(32..64);
        vert.extend(std::iter::repeat_n(0.0, 32));
        let text = ros_yaml(&all_ids, &vert, 0.0);
        let cal = parse_str(&text, &fake_path()).unwrap();
        assert_eq!(
            cal.lasers[31].elevation_deg,
            Calibration::builtin().lasers[31].elevation_deg
        );
    }

    #[test]
    fn flow_style_and_default_resolution() {
        let mut s = String::from("lasers:\n");
        for (id, v) in builtin_rad().iter().enumerate() {
            s.push_str(&format!(
                "- {{laser_id: {id}, rot_correction: 0.0, vert_correction: {v:?}, dist_correction: 0.01}}\n"
            ));
        }
        let cal = parse_str(&s, &fake_path()).unwrap();
        assert_eq!(cal.distance_resolution_m, 0.002);
        assert_eq!(cal.lasers[3].distance_offset_m, 0.01);
    }

    #[test]
    fn missing_laser_is_named() {
        let ids: Vec<i64> = (0..32).filter(|&i| i != 17).collect();
        let text = ros_yaml(&ids, &builtin_rad(), 0.0);
        let m = message(parse_str(&text, &fake_path()).unwrap_err());
        assert!(m.contains("/calib/test.yaml"), "{m}");
        assert!(m.contains("missing laser id(s) 17"), "{m}");
    }

    #[test]
    fn duplicate_id_names_file_line_and_laser() {
        let mut ids = ids();
        ids[5] = 4;
        let text = ros_yaml(&ids, &builtin_rad(), 0.0);
        let m = message(parse_str(&text, &fake_path()).unwrap_err());
        // Entry i starts at line 3 + 12 * i (2 header lines, 12 lines per entry).
        assert!(m.contains("/calib/test.yaml"), "{m}");
        assert!(m.contains("lasers[5] (line 63)"), "{m}");
        assert!(m.contains("duplicate laser id 4"), "{m}");
        assert!(m.contains("lasers[4] (line 51)"), "{m}");
    }

    #[test]
    fn wrong_type_names_line() {
        let text = ros_yaml(&ids(), &builtin_rad(), 0.0).replacen(
            "vert_correction: -0.5352924815866609",
            "vert_correction: steep",
            1,
        );
        assert!(
            text.contains("steep"),
            "test setup: laser 0 line must be replaced"
        );
        let m = message(parse_str(&text, &fake_path()).unwrap_err());
        assert!(m.contains("/calib/test.yaml"), "{m}");
        assert!(m.contains("line 5"), "{m}");
        assert!(m.contains("vert_correction"), "{m}");
    }

    #[test]
    fn offsets_are_refused_with_laser_and_key() {
        let text = ros_yaml(&ids(), &builtin_rad(), 0.0);
        // Give laser 2 a horizontal offset.
        let pos = text.find("- laser_id: 2\n").unwrap();
        let (head, tail) = text.split_at(pos);
        let tail = tail.replacen(
            "horiz_offset_correction: 0.0",
            "horiz_offset_correction: 0.026",
            1,
        );
        let m = message(parse_str(&format!("{head}{tail}"), &fake_path()).unwrap_err());
        assert!(m.contains("laser 2"), "{m}");
        assert!(m.contains("horiz_offset_correction"), "{m}");
        assert!(m.contains("not supported"), "{m}");
        assert!(m.contains("lasers[2] (line 27)"), "{m}");
    }

    #[test]
    fn wrong_num_lasers_and_non_mapping_are_errors() {
        let text =
            ros_yaml(&ids(), &builtin_rad(), 0.0).replace("num_lasers: 32", "num_lasers: 64");
        assert!(message(parse_str(&text, &fake_path()).unwrap_err()).contains("num_lasers is 64"));
        let m = message(parse_str("just a string", &fake_path()).unwrap_err());
        assert!(m.contains("/calib/test.yaml"), "{m}");
    }

    #[test]
    fn deep_nesting_is_refused_before_parsing_naming_the_line() {
        // Issue 30, defect 7: 16,000 nested `[` took 3.9 s to parse (quadratic).
        let n = 16_000;
        for text in [
            format!("lasers:\n  {}{}\n", "[".repeat(n), "]".repeat(n)),
            format!("lasers:\n  {}x{}\n", "{a: ".repeat(n), "}".repeat(n)),
            format!("# comment\nlasers:\n{}x\n", "- ".repeat(n)),
        ] {
            let m = message(parse_str(&text, &fake_path()).unwrap_err());
            assert!(
                m.contains("/calib/test.yaml")
                    && m.contains("nested more than 64 levels deep at line"),
                "{m}"
            );
        }
        assert_eq!(
            too_deep(&format!("a:\n  {}\n", "[".repeat(65)), 64),
            Some(2)
        );
        // Brackets in quotes, comments and plain scalars open nothing; the real layouts
        // nest two levels.
        let quiet = format!(
            "a: \"{0}\"\nb: '{0}'' {0}'\nc: x{0}\nd: 1 # {0}\n",
            "[".repeat(100)
        );
        assert_eq!(too_deep(&quiet, 64), None);
        assert_eq!(too_deep(&ros_yaml(&ids(), &builtin_rad(), 0.0), 2), None);
        assert_eq!(too_deep("a: [[[x]]]\n", 2), Some(1));
    }

    #[test]
    fn degrees_in_place_of_radians_are_caught() {
        let deg: Vec<f64> = BUILTIN_ELEVATION_DEG.to_vec();
        let text = ros_yaml(&ids(), &deg, 0.0);
        let m = message(parse_str(&text, &fake_path()).unwrap_err());
        assert!(m.contains("outside [-90, 90]"), "{m}");
    }
}
