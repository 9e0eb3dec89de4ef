//! One module per subcommand: each parses nothing itself and calls the library.

pub mod convert;
pub mod info;

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
