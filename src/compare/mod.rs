//! Field-by-field comparison of two result folders of `run` or `sweep` (for CI regression).
//!
//! Every file of either folder is paired by its relative path. JSON reports, CSV tables,
//! PLY and LAS/LAZ point clouds are compared field by field (one module per format);
//! provenance (tool version, paths, comments, VLRs) is ignored; any other file is compared
//! byte for byte, except the sweep's `index.html` and PNG plots, which are drawn from the
//! compared tables. Numbers are equal when identical or within the tolerance of their field.

pub mod csv;
pub mod json;
pub mod las;
pub mod ply;

use crate::error::{Error, Result};
use std::collections::BTreeSet;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// Differences listed per file; the rest are counted.
pub const MAX_LISTED: usize = 20;

/// JSON keys that are provenance, not results: never compared.
pub const PROVENANCE_KEYS: [&str; 5] = ["tool", "version", "calibration", "config", "source"];

/// A numeric tolerance: absolute, or relative to the expected value.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Tolerance {
    /// |actual - expected| <= value.
    Absolute(f64),
    /// |actual - expected| <= value * |expected|.
    Relative(f64),
}

/// Tolerances by field, from `--tolerance KEY=VALUE`.
///
/// A key matches a field by its full path (`totals.ground_fraction`,
/// `frames[0].noise.returns_out`), its own name (`ground_fraction`, a CSV column, a PLY
/// property or LAS dimension), or `*` for every numeric field; the most specific wins.
#[derive(Clone, Debug, Default)]
pub struct Tolerances {
    entries: Vec<(String, Tolerance)>,
}

impl Tolerances {
    /// Parses `KEY=VALUE` options: VALUE a non-negative number, or a percentage (`1%`).
    pub fn parse(args: &[String]) -> Result<Tolerances> {
        let mut entries = Vec::new();
        for arg in args {
            let bad = |m: &str| Error::Invalid(format!("--tolerance {arg}: {m}"));
            let (key, value) = arg
                .split_once('=')
                .ok_or_else(|| bad("expected KEY=VALUE, e.g. ground_fraction=1e-6 or power=1%"))?;
            let key = key.trim();
            if key.is_empty() {
                return Err(bad("empty key"));
            }
            let value = value.trim();
            let (number, relative) = match value.strip_suffix('%') {
                Some(v) => (v, true),
                None => (value, false),
            };
            let v: f64 = number
                .parse()
                .ok()
                .filter(|v: &f64| v.is_finite() && *v >= 0.0)
                .ok_or_else(|| bad("the tolerance must be a number of 0 or more (or N%)"))?;
            let tol = if relative {
                Tolerance::Relative(v / 100.0)
            } else {
                Tolerance::Absolute(v)
            };
            entries.push((key.to_string(), tol));
        }
        Ok(Tolerances { entries })
    }

    /// The tolerance of a field with this full path and name, if any.
    pub fn find(&self, path: &str, name: &str) -> Option<Tolerance> {
        let by = |k: &str| self.entries.iter().rev().find(|(e, _)| e == k).map(|e| e.1);
        by(path).or_else(|| by(name)).or_else(|| by("*"))
    }

    /// True when `actual` equals `expected` within the field's tolerance (NaN equals NaN).
    pub fn allows(&self, path: &str, name: &str, expected: f64, actual: f64) -> bool {
        if expected == actual || (expected.is_nan() && actual.is_nan()) {
            return true;
        }
        let delta = (actual - expected).abs();
        match self.find(path, name) {
            Some(Tolerance::Absolute(t)) => delta <= t,
            Some(Tolerance::Relative(r)) => delta <= r * expected.abs(),
            None => false,
        }
    }
}

/// The differences found in one file.
#[derive(Debug)]
pub struct Diffs<'t> {
    tolerances: &'t Tolerances,
    /// The first [`MAX_LISTED`] differences, as human-readable lines.
    pub listed: Vec<String>,
    /// How many differences in all.
    pub count: usize,
}

impl<'t> Diffs<'t> {
    /// An empty list using these tolerances.
    pub fn new(tolerances: &'t Tolerances) -> Self {
        Diffs {
            tolerances,
            listed: Vec::new(),
            count: 0,
        }
    }

    /// Records a difference.
    pub fn push(&mut self, line: String) {
        self.count += 1;
        if self.listed.len() < MAX_LISTED {
            self.listed.push(line);
        }
    }

    /// Compares two numbers of the field `path` (named `name`), recording a difference.
    pub fn number(&mut self, path: &str, name: &str, expected: f64, actual: f64) {
        if !self.tolerances.allows(path, name, expected, actual) {
            self.push(format!("{path}: expected {expected}, actual {actual}"));
        }
    }

    /// Compares two columns of per-point values (same length) of the field `name`,
    /// recording one summary line when any point differs beyond the tolerance.
    pub fn column(&mut self, what: &str, name: &str, expected: &[f64], actual: &[f64]) {
        let mut differing = 0usize;
        let mut first = None;
        let mut max_delta = 0.0f64;
        for (i, (&x, &y)) in expected.iter().zip(actual).enumerate() {
            if !self.tolerances.allows(name, name, x, y) {
                differing += 1;
                first.get_or_insert((i, x, y));
                max_delta = max_delta.max((y - x).abs());
            }
        }
        if let Some((i, x, y)) = first {
            self.push(format!(
                "{name}: {differing} of {} {what} differ, largest by {max_delta}; first {what} {i}: \
                 expected {x}, actual {y}",
                expected.len()
            ));
        }
    }

    /// Compares two texts of the field `path`, recording a difference.
    pub fn text(&mut self, path: &str, expected: &str, actual: &str) {
        if expected != actual {
            self.push(format!("{path}: expected {expected:?}, actual {actual:?}"));
        }
    }
}

/// How one file of the two folders compares.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Status {
    /// Equal within the tolerances.
    Same,
    /// Present in both, different: the count and the first differences.
    Different {
        /// Number of differences.
        count: usize,
        /// The first [`MAX_LISTED`] differences.
        listed: Vec<String>,
    },
    /// In the expected folder only.
    Missing,
    /// In the actual folder only.
    Extra,
}

/// The comparison of one file.
#[derive(Debug, Clone)]
pub struct FileResult {
    /// Path relative to the compared folders.
    pub path: PathBuf,
    /// The outcome.
    pub status: Status,
}

/// The comparison of two folders.
#[derive(Debug, Clone, Default)]
pub struct Report {
    /// One entry per file of either folder, sorted by path.
    pub files: Vec<FileResult>,
}

impl Report {
    /// True when every file is the same.
    pub fn same(&self) -> bool {
        self.files.iter().all(|f| f.status == Status::Same)
    }

    /// A short human diff: one block per differing file, then a one-line verdict.
    pub fn human(&self) -> String {
        let mut out = String::new();
        for f in &self.files {
            let p = f.path.display();
            match &f.status {
                Status::Same => {}
                Status::Missing => {
                    let _ = writeln!(out, "{p}: missing (expected, not in the actual folder)");
                }
                Status::Extra => {
                    let _ = writeln!(out, "{p}: extra (in the actual folder, not expected)");
                }
                Status::Different { count, listed } => {
                    let s = if *count == 1 { "" } else { "s" };
                    let _ = writeln!(out, "{p}: {count} difference{s}");
                    for line in listed {
                        let _ = writeln!(out, "  {line}");
                    }
                    if *count > listed.len() {
                        let _ = writeln!(out, "  ... and {} more", count - listed.len());
                    }
                }
            }
        }
        let bad = self
            .files
            .iter()
            .filter(|f| f.status != Status::Same)
            .count();
        if bad == 0 {
            let _ = writeln!(out, "same: {} files", self.files.len());
        } else {
            let _ = writeln!(out, "different: {bad} of {} files", self.files.len());
        }
        out
    }

    /// The report as JUnit XML: one test case per file, a failure per differing file.
    pub fn junit(&self) -> String {
        let failures = self
            .files
            .iter()
            .filter(|f| f.status != Status::Same)
            .count();
        let mut x = String::from("<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n");
        let _ = writeln!(
            x,
            "<testsuites name=\"lidar-noise compare\" tests=\"{}\" failures=\"{failures}\">",
            self.files.len()
        );
        let _ = writeln!(
            x,
            "  <testsuite name=\"lidar-noise compare\" tests=\"{}\" failures=\"{failures}\" errors=\"0\">",
            self.files.len()
        );
        for f in &self.files {
            let name = xml_escape(&f.path.display().to_string());
            let open = format!("    <testcase classname=\"compare\" name=\"{name}\"");
            let (message, body) = match &f.status {
                Status::Same => {
                    let _ = writeln!(x, "{open}/>");
                    continue;
                }
                Status::Missing => ("missing from the actual folder".to_string(), String::new()),
                Status::Extra => ("not in the expected folder".to_string(), String::new()),
                Status::Different { count, listed } => {
                    let mut body = listed.join("\n");
                    if *count > listed.len() {
                        let _ = write!(body, "\n... and {} more", count - listed.len());
                    }
                    (format!("{count} differences"), body)
                }
            };
            let _ = writeln!(
                x,
                "{open}>\n      <failure message=\"{}\">{}</failure>\n    </testcase>",
                xml_escape(&message),
                xml_escape(&body)
            );
        }
        x.push_str("  </testsuite>\n</testsuites>\n");
        x
    }
}

/// Escapes text for XML content and attribute values; drops characters XML 1.0 forbids.
fn xml_escape(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for c in text.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&apos;"),
            '\n' | '\t' | '\r' => out.push(c),
            c if (c as u32) < 0x20 => {}
            c => out.push(c),
        }
    }
    out
}

/// Files under `dir`, relative to it, sorted; hidden files (temporaries) are skipped.
fn list_files(dir: &Path) -> Result<BTreeSet<PathBuf>> {
    let mut out = BTreeSet::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        let entries = std::fs::read_dir(&d).map_err(|e| Error::io(&d, e))?;
        for entry in entries {
            let entry = entry.map_err(|e| Error::io(&d, e))?;
            let path = entry.path();
            if entry.file_name().to_string_lossy().starts_with('.') {
                continue;
            }
            let ty = entry.file_type().map_err(|e| Error::io(&path, e))?;
            if ty.is_dir() {
                stack.push(path);
            } else if let Ok(rel) = path.strip_prefix(dir) {
                out.insert(rel.to_path_buf());
            }
        }
    }
    Ok(out)
}

/// True for files that are drawn from compared data and not compared themselves.
fn is_presentation(path: &Path) -> bool {
    matches!(
        path.extension().and_then(|e| e.to_str()),
        Some("png" | "html")
    )
}

/// Compares every file of `expected` with the file of the same relative path in `actual`.
///
/// Errors only when a folder cannot be listed; a file that cannot be read or parsed is
/// reported as a difference.
pub fn compare_dirs(expected: &Path, actual: &Path, tolerances: &Tolerances) -> Result<Report> {
    for dir in [expected, actual] {
        if !dir.is_dir() {
            return Err(Error::Invalid(format!("{}: not a folder", dir.display())));
        }
    }
    let (e, a) = (list_files(expected)?, list_files(actual)?);
    let mut files = Vec::new();
    for path in e.union(&a) {
        if is_presentation(path) {
            continue;
        }
        let status = match (e.contains(path), a.contains(path)) {
            (true, false) => Status::Missing,
            (false, true) => Status::Extra,
            _ => compare_file(&expected.join(path), &actual.join(path), tolerances),
        };
        files.push(FileResult {
            path: path.clone(),
            status,
        });
    }
    Ok(Report { files })
}

/// Compares two files by the format their extension names.
pub fn compare_file(expected: &Path, actual: &Path, tolerances: &Tolerances) -> Status {
    let mut diffs = Diffs::new(tolerances);
    let read = |p: &Path| std::fs::read(p).map_err(|e| format!("cannot read {}: {e}", p.display()));
    match (read(expected), read(actual)) {
        (Ok(e), Ok(a)) => {
            let ext = expected
                .extension()
                .and_then(|e| e.to_str())
                .unwrap_or("")
                .to_ascii_lowercase();
            let outcome = match ext.as_str() {
                "json" => json::compare(&e, &a, &mut diffs),
                "csv" => csv::compare(&e, &a, &mut diffs),
                "ply" => ply::compare(&e, &a, &mut diffs),
                "las" | "laz" => las::compare((expected, &e), (actual, &a), &mut diffs),
                _ => {
                    if e != a {
                        diffs.push("the bytes differ".to_string());
                    }
                    Ok(())
                }
            };
            if let Err(m) = outcome {
                diffs.push(m);
            }
        }
        (e, a) => {
            for r in [e, a] {
                if let Err(m) = r {
                    diffs.push(m);
                }
            }
        }
    }
    if diffs.count == 0 {
        Status::Same
    } else {
        Status::Different {
            count: diffs.count,
            listed: diffs.listed,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tolerances_match_by_path_name_or_star() {
        let t = Tolerances::parse(&[
            "ground_fraction=0.01".into(),
            "totals.ground_fraction=0".into(),
            "power=1%".into(),
        ])
        .unwrap();
        assert!(t.allows("frames[0].ground_fraction", "ground_fraction", 0.5, 0.509));
        assert!(!t.allows("totals.ground_fraction", "ground_fraction", 0.5, 0.509));
        assert!(t.allows("power", "power", 2.0, 2.019));
        assert!(!t.allows("power", "power", 2.0, 2.03));
        assert!(!t.allows("range", "range", 1.0, 1.000001));
        assert!(t.allows("range", "range", f64::NAN, f64::NAN));
        let star = Tolerances::parse(&["*=0.5".into()]).unwrap();
        assert!(star.allows("a.b", "b", 1.0, 1.4));
        for bad in ["x", "=1", "x=-1", "x=abc", "x=inf"] {
            assert!(Tolerances::parse(&[bad.into()]).is_err(), "{bad}");
        }
    }

    #[test]
    fn xml_escape_handles_markup_and_control_characters() {
        assert_eq!(xml_escape("a<b & \"c\"\u{1}"), "a&lt;b &amp; &quot;c&quot;");
    }
}
