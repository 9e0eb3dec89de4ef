//! One module per subcommand: each parses nothing itself and calls the library.

pub mod compare;
pub mod convert;
pub mod info;
pub mod run;
pub mod stages;
pub mod sweep;
pub mod synth;
pub mod validate;

// The helpers every command shares live with the engine that runs the inputs.
pub use lidar_noise::engine::inputs::{
    capture_label, capture_shown, check_stdin_once, join_ids, output_names, raw_intensity_hint,
    warn_capture, warn_truncation,
};

/// Writes `text` to standard output, flushed; a failure (a full disk, a closed pipe) is an
/// error naming standard output instead of the panic of `print!`.
pub fn write_stdout(text: impl AsRef<[u8]>) -> anyhow::Result<()> {
    use std::io::Write;
    let mut out = std::io::stdout().lock();
    out.write_all(text.as_ref())
        .and_then(|()| out.flush())
        .map_err(|e| anyhow::Error::new(e).context("cannot write to standard output"))
}
