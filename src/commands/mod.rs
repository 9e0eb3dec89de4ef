//! One module per subcommand: each parses nothing itself and calls the library.

pub mod compare;
pub mod convert;
pub mod info;
pub mod run;
pub mod sweep;
pub mod synth;
pub mod validate;

use crate::cli::Global;
use crate::hdl32e::frames::CaptureSummary;
use std::path::Path;

/// Warns about a capture cut mid-record.
pub fn warn_truncation(global: Global, path: &Path, summary: &CaptureSummary) {
    if let Some(offset) = summary.capture.truncated_at {
        global.warn(&format!(
            "{}: the capture ends inside a record at byte offset {offset}; \
             every whole packet before it was decoded",
            path.display()
        ));
    }
}

/// A progress spinner on stderr, hidden when quiet or when stderr is not a terminal.
pub fn progress(global: Global, unit: &'static str) -> indicatif::ProgressBar {
    use std::io::IsTerminal;
    if global.quiet || !std::io::stderr().is_terminal() {
        return indicatif::ProgressBar::hidden();
    }
    let bar = indicatif::ProgressBar::new_spinner();
    if let Ok(style) = indicatif::ProgressStyle::with_template(&format!(
        "{{spinner}} {{pos}} {unit} {{elapsed}} {{msg}}"
    )) {
        bar.set_style(style);
    }
    bar.enable_steady_tick(std::time::Duration::from_millis(200));
    bar
}

/// How outputs name a capture: its file name, not the path as typed, so the same capture
/// run from another folder gives identical reports.
pub fn capture_label(path: &Path) -> String {
    path.file_name().map_or_else(
        || path.display().to_string(),
        |n| n.to_string_lossy().into_owned(),
    )
}

/// Output names of captures: each file's stem, with `-2`, `-3`, ... added where two
/// captures share a stem, so every capture gets its own folder.
pub fn output_names(paths: &[std::path::PathBuf]) -> Vec<String> {
    let mut used = std::collections::HashSet::new();
    paths
        .iter()
        .map(|path| {
            let stem = path.file_stem().map_or_else(
                || "capture".to_string(),
                |s| s.to_string_lossy().into_owned(),
            );
            let mut name = stem.clone();
            let mut n = 2;
            while !used.insert(name.clone()) {
                name = format!("{stem}-{n}");
                n += 1;
            }
            name
        })
        .collect()
}
