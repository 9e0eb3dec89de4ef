//! `lidar-noise compare`: two result folders field by field, for CI regression checks.

use crate::cli::{Global, EXIT_ERROR, EXIT_OK, EXIT_USAGE};
use lidar_noise::compare::{compare_dirs, Tolerances};
use std::path::PathBuf;

/// Arguments of `compare`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Folder of the expected results (e.g. committed to the repository).
    #[arg(value_name = "EXPECTED_DIR")]
    pub expected: PathBuf,
    /// Folder of the results to check.
    #[arg(value_name = "ACTUAL_DIR")]
    pub actual: PathBuf,
    /// Numeric tolerance of a field: KEY=ABS or KEY=REL% (repeatable); KEY is a field
    /// name (JSON key, CSV column, PLY property, LAS dimension), a full JSON path, or `*`.
    #[arg(long = "tolerance", value_name = "KEY=VALUE")]
    pub tolerances: Vec<String>,
    /// Also write the result as JUnit XML (one test case per file).
    #[arg(long, value_name = "FILE")]
    pub junit: Option<PathBuf>,
}

/// Compares the folders and returns the exit code: 0 same, 1 different, 2 unusable
/// arguments (a folder that is not one, a malformed tolerance, an unwritable JUnit file).
pub fn run(args: Args, global: Global) -> i32 {
    let usage = |m: String| {
        eprintln!("lidar-noise: error: {m}");
        EXIT_USAGE
    };
    let tolerances = match Tolerances::parse(&args.tolerances) {
        Ok(t) => t,
        Err(e) => return usage(e.to_string()),
    };
    let report = match compare_dirs(&args.expected, &args.actual, &tolerances) {
        Ok(r) => r,
        Err(e) => return usage(e.to_string()),
    };
    if let Some(path) = &args.junit {
        let xml = report.junit();
        if let Err(e) = lidar_noise::writers::atomic::write_atomically(path, &[], |out| {
            out.write_all(xml.as_bytes())
        }) {
            return usage(e.to_string());
        }
    }
    let text = report.human();
    let printed = if report.same() && global.quiet {
        Ok(())
    } else {
        super::write_stdout(&text)
    };
    match printed {
        Err(e) if !crate::cli::is_broken_pipe(&e) => {
            eprintln!("lidar-noise: error: {e:#}");
            EXIT_ERROR
        }
        _ if report.same() => EXIT_OK,
        _ => EXIT_ERROR,
    }
}
