//! One module per subcommand: each parses nothing itself and calls the library.

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
