//! Point clouds as delimited text: a header row naming the columns, then one point a row.
//! The delimiter is the first of `,` `;` tab found in the header row (CloudCompare and
//! spreadsheets write `;` in some locales), else runs of spaces.
//!
//! Columns, matched case-insensitively: `x` `y` `z` (required; also `//x`, CloudCompare's
//! header), intensity (`intensity`, `i`, `reflectance`, `remission`, `scalar_intensity`),
//! ring (`ring`, `ring_index`, `ring_id`), time (`time`, `t`, `timestamp`). Others are
//! skipped. Source: RFC 4180 for the quoting, read by the `csv` crate.

use super::{invalid, ring_from_f64, CloudPoint, Fields};
use crate::error::Result;
use std::path::Path;

/// Whether `head` (a file's first bytes) is text whose first line names x, y and z.
pub fn looks_like(head: &[u8]) -> bool {
    let line = head.split(|&b| b == b'\n').next().unwrap_or(b"");
    let Ok(line) = std::str::from_utf8(line) else {
        return false;
    };
    let names = split_header(line, delimiter(line));
    ["x", "y", "z"]
        .iter()
        .all(|w| names.iter().any(|n| column_is(n, &[w])))
}

fn delimiter(header: &str) -> Option<u8> {
    [b',', b';', b'\t']
        .into_iter()
        .find(|d| header.as_bytes().contains(d))
}

fn split_header(line: &str, delim: Option<u8>) -> Vec<String> {
    match delim {
        Some(d) => line.split(d as char).map(|s| s.to_string()).collect(),
        None => line.split_whitespace().map(|s| s.to_string()).collect(),
    }
}

/// Whether header cell `name` is one of `names` (case, quotes, spaces and a leading `//`
/// ignored).
fn column_is(name: &str, names: &[&str]) -> bool {
    let n = name.trim().trim_matches('"').trim();
    let n = n.strip_prefix("//").unwrap_or(n).trim();
    names.iter().any(|w| n.eq_ignore_ascii_case(w))
}

/// Parses a CSV point cloud (`path` is named in errors, with line and column).
pub fn parse(bytes: &[u8], path: &Path) -> Result<(Vec<CloudPoint>, Fields)> {
    let first = bytes.split(|&b| b == b'\n').next().unwrap_or(b"");
    let first = String::from_utf8_lossy(first);
    let delim = delimiter(&first);
    // Whitespace-separated text: collapse runs of blanks into one separator for the reader.
    let owned;
    let input: &[u8] = match delim {
        Some(_) => bytes,
        None => {
            let text = std::str::from_utf8(bytes).map_err(|e| {
                invalid(
                    path,
                    format!("not text (invalid UTF-8 at byte {})", e.valid_up_to()),
                )
            })?;
            owned = text
                .lines()
                .map(|l| l.split_whitespace().collect::<Vec<_>>().join(","))
                .collect::<Vec<_>>()
                .join("\n");
            owned.as_bytes()
        }
    };
    let mut reader = ::csv::ReaderBuilder::new()
        .delimiter(delim.unwrap_or(b','))
        .has_headers(true)
        .flexible(true)
        .from_reader(input);
    let headers = reader
        .headers()
        .map_err(|e| invalid(path, format!("CSV header (line 1): {e}")))?
        .clone();
    let find = |names: &[&str]| headers.iter().position(|h| column_is(h, names));
    let need = |name: &str| {
        find(&[name]).ok_or_else(|| {
            invalid(
                path,
                format!(
                    "CSV header (line 1): no {name} column (columns: {})",
                    headers.iter().collect::<Vec<_>>().join(", ")
                ),
            )
        })
    };
    let cols = [need("x")?, need("y")?, need("z")?];
    let intensity = find(&[
        "intensity",
        "i",
        "reflectance",
        "remission",
        "scalar_intensity",
    ]);
    let ring = find(&["ring", "ring_index", "ring_id"]);
    let time = find(&["time", "t", "timestamp"]);
    let fields = Fields {
        intensity: intensity.is_some(),
        ring: ring.is_some(),
        time: time.is_some(),
    };
    let mut points = Vec::new();
    let mut record = ::csv::StringRecord::new();
    loop {
        let more = reader.read_record(&mut record).map_err(|e| {
            let line = e.position().map_or(0, |p| p.line());
            invalid(path, format!("CSV line {line}: {e}"))
        })?;
        if !more {
            break;
        }
        let line = record.position().map_or(0, |p| p.line());
        if record.len() == 1 && record[0].trim().is_empty() {
            continue;
        }
        let i = points.len();
        let get = |c: usize| -> Result<f64> {
            let name = headers.get(c).unwrap_or("").trim();
            let at = format!("CSV line {line}, column {} ({name}), point {i}", c + 1);
            match record.get(c).map(str::trim) {
                None | Some("") => Err(invalid(path, format!("{at}: missing value"))),
                Some(v) => v
                    .parse::<f64>()
                    .map_err(|_| invalid(path, format!("{at}: {v:?} is not a number"))),
            }
        };
        points.push(CloudPoint {
            x: get(cols[0])? as f32,
            y: get(cols[1])? as f32,
            z: get(cols[2])? as f32,
            intensity: match intensity {
                Some(c) => get(c)? as f32,
                None => 0.0,
            },
            ring: match ring {
                Some(c) => Some(ring_from_f64(get(c)?, i, path)?),
                None => None,
            },
            time: match time {
                Some(c) => Some(get(c)?),
                None => None,
            },
        });
    }
    Ok((points, fields))
}
