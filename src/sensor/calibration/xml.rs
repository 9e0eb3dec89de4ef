//! VeloView calibration XML (boost serialization, e.g. VeloView's `share/HDL-32.xml`).
//!
//! Layout: `<boost_serialization><DB>` holding `<distLSB_>` (centimetres) and
//! `<points_>`, a list of `<item><px>` with `<id_>`, `<rotCorrection_>` and
//! `<vertCorrection_>` (degrees), `<distCorrection_>`, `<vertOffsetCorrection_>` and
//! `<horizOffsetCorrection_>` (centimetres) and intensity keys. Units follow VeloView's
//! `vtkVelodynePacketInterpreter::LoadCalibration`, which divides distances and
//! `distLSB_` by 100 and keeps angles in degrees. `distCorrectionX_`/`Y_`,
//! `focalDistance_`, `focalSlope_`, `enabled_`, colours and intensity limits are ignored
//! (VeloView applies neither two-point nor intensity correction to the HDL-32E).

use super::{Assembler, Calibration, RawLaser};
use crate::error::{Error, Result};
use roxmltree::{Document, Node};
use std::path::Path;

/// VeloView's default distance unit, in centimetres (2 mm).
const DEFAULT_DIST_LSB_CM: f64 = 0.2;

/// Deepest element nesting accepted. VeloView files nest five levels; roxmltree builds
/// and drops its tree recursively, so a file nested tens of thousands of levels deep
/// overflowed the stack and aborted the process.
pub const MAX_DEPTH: usize = 64;

/// The line of the first element nested deeper than `max` levels, by a linear scan of the
/// tags (comments, CDATA, declarations and processing instructions skipped, quoted
/// attribute values read past): `None` when the nesting stays within `max`.
pub(crate) fn too_deep(text: &str, max: usize) -> Option<usize> {
    let b = text.as_bytes();
    let (mut i, mut depth, mut line) = (0usize, 0usize, 1usize);
    // Skips to just past `end`, counting lines; false when the text ends first.
    let skip = |i: &mut usize, line: &mut usize, end: &[u8]| -> bool {
        while *i < b.len() {
            if b[*i..].starts_with(end) {
                *i += end.len();
                return true;
            }
            *line += usize::from(b[*i] == b'\n');
            *i += 1;
        }
        false
    };
    while i < b.len() {
        match b[i] {
            b'\n' => {
                line += 1;
                i += 1;
            }
            b'<' if b[i..].starts_with(b"<!--") => {
                if !skip(&mut i, &mut line, b"-->") {
                    break;
                }
            }
            b'<' if b[i..].starts_with(b"<![CDATA[") => {
                if !skip(&mut i, &mut line, b"]]>") {
                    break;
                }
            }
            b'<' if b[i..].starts_with(b"<?") => {
                if !skip(&mut i, &mut line, b"?>") {
                    break;
                }
            }
            b'<' if b[i..].starts_with(b"<!") || b[i..].starts_with(b"</") => {
                let closing = b[i + 1] == b'/';
                if !skip(&mut i, &mut line, b">") {
                    break;
                }
                if closing {
                    depth = depth.saturating_sub(1);
                }
            }
            b'<' => {
                // A start tag: read to its `>` past quoted values; `/>` closes it at once.
                let mut quote = None;
                let mut last = 0u8;
                i += 1;
                while i < b.len() {
                    let c = b[i];
                    line += usize::from(c == b'\n');
                    match quote {
                        Some(q) if c == q => quote = None,
                        Some(_) => {}
                        None if c == b'"' || c == b'\'' => quote = Some(c),
                        None if c == b'>' => break,
                        None => {}
                    }
                    last = c;
                    i += 1;
                }
                i += 1;
                if last != b'/' {
                    depth += 1;
                    if depth > max {
                        return Some(line);
                    }
                }
            }
            _ => i += 1,
        }
    }
    None
}

/// Parses VeloView XML calibration text; `path` is only used in messages and as the source.
pub fn parse_str(text: &str, path: &Path) -> Result<Calibration> {
    let err = |message: String| Error::Config {
        path: path.to_path_buf(),
        message,
    };
    // VeloView files start with `<!DOCTYPE boost_serialization>`, which roxmltree
    // refuses unless DTDs are allowed (it still expands no external entities).
    let options = roxmltree::ParsingOptions {
        allow_dtd: true,
        ..Default::default()
    };
    if let Some(line) = too_deep(text, MAX_DEPTH) {
        return Err(err(format!(
            "elements nested more than {MAX_DEPTH} levels deep at line {line}: not a VeloView \
             calibration file (they nest five levels)"
        )));
    }
    // roxmltree's message already ends with "at L:C".
    let doc = Document::parse_with_options(text, options)
        .map_err(|e| err(format!("not a well-formed XML file: {e}")))?;
    // roxmltree's `text_pos_at` counts lines from the start of the text at every call:
    // once per item made a one-line file of 20,000 items take minutes. The line starts
    // are found once; each lookup is a binary search.
    let lines = LineIndex::new(text);
    let line_of = |node: Node| lines.line(node.range().start);

    let db = doc
        .descendants()
        .find(|n| n.has_tag_name("DB"))
        .ok_or_else(|| {
            err("no <DB> element: not a VeloView calibration file (expected <boost_serialization><DB>)".into())
        })?;
    let dist_lsb_cm = match child(db, "distLSB_") {
        Some(node) => number(node, &line_of).map_err(err)?,
        None => DEFAULT_DIST_LSB_CM,
    };
    let points = child(db, "points_").ok_or_else(|| {
        err(format!(
            "<DB> at line {} has no <points_> list",
            line_of(db)
        ))
    })?;

    let mut lasers = Assembler::new(path, dist_lsb_cm / 100.0)?;
    for (i, item) in points
        .children()
        .filter(|n| n.has_tag_name("item"))
        .enumerate()
    {
        let px = child(item, "px").ok_or_else(|| {
            err(format!(
                "points_ item {i} at line {} has no <px>",
                line_of(item)
            ))
        })?;
        let place = format!("points_ item {i} (line {})", line_of(px));
        let required = |name: &str| -> Result<f64> {
            let node = child(px, name).ok_or_else(|| err(format!("{place}: missing <{name}>")))?;
            number(node, &line_of).map_err(err)
        };
        let optional = |name: &str| -> Result<f64> {
            match child(px, name) {
                Some(node) => number(node, &line_of).map_err(err),
                None => Ok(0.0),
            }
        };
        let id_value = required("id_")?;
        if id_value.fract() != 0.0 || id_value.abs() > 1e9 {
            return Err(err(format!("{place}: <id_> {id_value} is not an integer")));
        }
        let rot_deg = required("rotCorrection_")?;
        let vert_deg = required("vertCorrection_")?;
        let dist_cm = optional("distCorrection_")?;
        // Checked at once: the first bad entry ends the read.
        lasers.push(RawLaser {
            id: id_value as i64,
            place,
            elevation_deg: vert_deg,
            // VeloView: realAzimuth = azimuth/100 - rotationalCorrection.
            azimuth_offset_deg: -rot_deg,
            distance_offset_m: dist_cm / 100.0,
            unsupported: vec![
                (
                    "horizOffsetCorrection_",
                    optional("horizOffsetCorrection_")?,
                ),
                ("vertOffsetCorrection_", optional("vertOffsetCorrection_")?),
            ],
        })?;
    }
    lasers.finish()
}

/// Byte offsets where the lines of a text start, to turn an offset into a line number
/// by binary search.
struct LineIndex {
    starts: Vec<usize>,
}

impl LineIndex {
    /// Scans the text once.
    fn new(text: &str) -> Self {
        let starts = std::iter::once(0)
            .chain(text.match_indices('\n').map(|(i, _)| i + 1))
            .collect();
        LineIndex { starts }
    }

    /// The 1-based line of byte offset `pos`.
    fn line(&self, pos: usize) -> u32 {
        let line = self.starts.partition_point(|&start| start <= pos);
        u32::try_from(line).unwrap_or(u32::MAX)
    }
}

/// First child element called `name`.
fn child<'a, 'i>(node: Node<'a, 'i>, name: &str) -> Option<Node<'a, 'i>> {
    node.children().find(|n| n.has_tag_name(name))
}

/// Text of an element as a number; the error names the element and its line.
fn number(node: Node, line_of: &dyn Fn(Node) -> u32) -> std::result::Result<f64, String> {
    let text = node.text().unwrap_or("").trim();
    text.parse::<f64>().map_err(|_| {
        format!(
            "line {}: <{}> holds {text:?}, expected a number",
            line_of(node),
            node.tag_name().name()
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn deep_nesting_is_an_error_naming_the_line_not_a_stack_overflow() {
        // Issue 30, defect 2: 50,000 nested elements aborted the process.
        let n = 50_000;
        let text = format!("<a>\n{}{}</a>", "<b>".repeat(n), "</b>".repeat(n));
        let e = parse_str(&text, Path::new("deep.xml"))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("deep.xml") && e.contains("nested more than 64"),
            "{e}"
        );
        assert!(e.contains("line 2"), "{e}");
        // The scan reads comments, CDATA, quoted '>' and empty elements as XML does.
        let ok = format!(
            "<?xml version='1.0'?><!DOCTYPE x><r a=\"x>y\">{}<e/><!-- <q><q> --><![CDATA[<z>]]>{}</r>",
            "<i>".repeat(60),
            "</i>".repeat(60)
        );
        assert_eq!(too_deep(&ok, 64), None);
        assert!(too_deep(&ok, 60).is_some());
    }

    #[test]
    fn a_long_one_line_file_stops_at_the_first_bad_item() {
        // Issue 30, defect 7: a one-line file of 20,000 items took 89 s to report the
        // duplicate id at item 32 (every item's line was counted from the start of the
        // text, and every item was read before any was checked). Item 40's value is
        // malformed too: the read ends at item 32, so that error is never reached.
        let items: String = (0..20_000)
            .map(|i| {
                let vert = if i == 40 { "low" } else { "0" };
                format!(
                    "<item><px><id_>{}</id_><rotCorrection_>0</rotCorrection_>\
                     <vertCorrection_>{vert}</vertCorrection_></px></item>",
                    i % 32
                )
            })
            .collect();
        let text = format!(
            "<boost_serialization><DB><points_>{items}</points_></DB></boost_serialization>"
        );
        let e = parse_str(&text, Path::new("wide.xml"))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("wide.xml")
                && e.contains("points_ item 32 (line 1): duplicate laser id 0 (first defined at points_ item 0 (line 1))"),
            "{e}"
        );
    }

    #[test]
    fn line_index_counts_lines_like_the_text() {
        let text = "a\nbb\n\nccc\n";
        let lines = LineIndex::new(text);
        for pos in 0..=text.len() {
            let expected = 1 + text[..pos].matches('\n').count();
            assert_eq!(lines.line(pos) as usize, expected, "offset {pos}");
        }
        // One start per line, found in one pass: a lookup never rescans the text.
        assert_eq!(lines.starts, vec![0, 2, 5, 6, 10]);
    }

    use crate::sensor::calibration::BUILTIN_ELEVATION_DEG;
    use std::path::PathBuf;

    fn fake_path() -> PathBuf {
        PathBuf::from("/calib/test.xml")
    }

    /// VeloView-style XML, one `<px>` field per line like VeloView writes it.
    fn veloview_xml(ids: &[i64], vert_deg: &[f64], rot_deg: f64, horiz_cm: f64) -> String {
        let mut s = String::from(
            "<?xml version=\"1.0\" encoding=\"UTF-8\" standalone=\"yes\" ?>\n\
             <!DOCTYPE boost_serialization>\n\
             <boost_serialization signature=\"serialization::archive\" version=\"4\">\n\
             <DB class_id=\"0\" tracking_level=\"1\" version=\"0\" object_id=\"_0\">\n\
             \t<distLSB_>0.2</distLSB_>\n\
             \t<points_ class_id=\"7\" tracking_level=\"0\" version=\"0\">\n\
             \t\t<count>32</count>\n\
             \t\t<item_version>1</item_version>\n",
        );
        for (&id, &v) in ids.iter().zip(vert_deg) {
            s.push_str(&format!(
                "\t\t<item>\n\t\t\t<px>\n\t\t\t\t<id_>{id}</id_>\n\
                 \t\t\t\t<rotCorrection_>{rot_deg:?}</rotCorrection_>\n\
                 \t\t\t\t<vertCorrection_>{v:?}</vertCorrection_>\n\
                 \t\t\t\t<distCorrection_>0</distCorrection_>\n\
                 \t\t\t\t<vertOffsetCorrection_>0</vertOffsetCorrection_>\n\
                 \t\t\t\t<horizOffsetCorrection_>{horiz_cm:?}</horizOffsetCorrection_>\n\
                 \t\t\t</px>\n\t\t</item>\n"
            ));
        }
        s.push_str("\t</points_>\n</DB>\n</boost_serialization>\n");
        s
    }

    fn ids() -> Vec<i64> {
        (0..32).collect()
    }

    #[test]
    fn builtin_angles_round_trip() {
        let text = veloview_xml(&ids(), &BUILTIN_ELEVATION_DEG, 0.0, 0.0);
        let cal = parse_str(&text, &fake_path()).unwrap();
        // Angles, offsets and the 2 mm distance unit (distLSB_ 0.2 cm in XML).
        crate::sensor::calibration::tests::assert_matches_builtin(&cal);
        assert_eq!(cal.rings(), Calibration::builtin().rings());
    }

    #[test]
    fn rot_correction_sign_and_units() {
        let text = veloview_xml(&ids(), &BUILTIN_ELEVATION_DEG, -1.5, 0.0)
            .replace("<distCorrection_>0<", "<distCorrection_>3.5<");
        let cal = parse_str(&text, &fake_path()).unwrap();
        assert_eq!(cal.lasers[7].azimuth_offset_deg, 1.5);
        assert!((cal.lasers[7].distance_offset_m - 0.035).abs() < 1e-15);
    }

    #[test]
    fn placeholders_above_31_are_skipped_like_hdl32_xml() {
        let mut all_ids = ids();
        let mut vert = BUILTIN_ELEVATION_DEG.to_vec();
        all_ids.extend(32..64);
        vert.extend(std::iter::repeat_n(0.0, 32));
        assert!(parse_str(&veloview_xml(&all_ids, &vert, 0.0, 0.0), &fake_path()).is_ok());
        // A non-zero entry at id 40 is not a placeholder.
        vert[40] = 3.0;
        let m = parse_str(&veloview_xml(&all_ids, &vert, 0.0, 0.0), &fake_path())
            .unwrap_err()
            .to_string();
        assert!(m.contains("laser id 40 is outside 0..31"), "{m}");
        assert!(m.contains("points_ item 40 (line"), "{m}");
    }

    #[test]
    fn missing_laser_is_named() {
        let ids: Vec<i64> = (0..32).filter(|&i| i != 0).collect();
        let m = parse_str(
            &veloview_xml(&ids, &BUILTIN_ELEVATION_DEG, 0.0, 0.0),
            &fake_path(),
        )
        .unwrap_err()
        .to_string();
        assert!(m.contains("/calib/test.xml"), "{m}");
        assert!(m.contains("missing laser id(s) 0"), "{m}");
    }

    #[test]
    fn duplicate_id_names_line() {
        let mut ids = ids();
        ids[1] = 0;
        let m = parse_str(
            &veloview_xml(&ids, &BUILTIN_ELEVATION_DEG, 0.0, 0.0),
            &fake_path(),
        )
        .unwrap_err()
        .to_string();
        // 8 header lines, 10 lines per item, <px> is the 2nd line of an item.
        assert!(m.contains("points_ item 1 (line 20)"), "{m}");
        assert!(
            m.contains("duplicate laser id 0 (first defined at points_ item 0 (line 10))"),
            "{m}"
        );
    }

    #[test]
    fn wrong_type_names_element_and_line() {
        let text = veloview_xml(&ids(), &BUILTIN_ELEVATION_DEG, 0.0, 0.0).replacen(
            "<vertCorrection_>-30.67<",
            "<vertCorrection_>low<",
            1,
        );
        let m = parse_str(&text, &fake_path()).unwrap_err().to_string();
        assert!(m.contains("/calib/test.xml"), "{m}");
        assert!(
            m.contains("line 13: <vertCorrection_> holds \"low\""),
            "{m}"
        );
    }

    #[test]
    fn offsets_are_refused_with_laser_and_key() {
        let m = parse_str(
            &veloview_xml(&ids(), &BUILTIN_ELEVATION_DEG, 0.0, 2.6),
            &fake_path(),
        )
        .unwrap_err()
        .to_string();
        assert!(m.contains("laser 0"), "{m}");
        assert!(m.contains("horizOffsetCorrection_"), "{m}");
        assert!(m.contains("not supported"), "{m}");
    }

    #[test]
    fn malformed_xml_and_wrong_root() {
        let m = parse_str("<DB><points_></DB>", &fake_path())
            .unwrap_err()
            .to_string();
        assert!(m.contains("/calib/test.xml") && m.contains("1:"), "{m}");
        let m = parse_str("<other/>", &fake_path()).unwrap_err().to_string();
        assert!(m.contains("no <DB> element"), "{m}");
    }
}
