//! The inputs of a run: captures given by path or on standard input, the built-in
//! capture, how outputs and messages name them, the warnings about what a capture held,
//! and the progress shown while frames are processed.

use crate::observe::{Counter, Observer};
use crate::sensor::frames::CaptureSummary;
use std::path::Path;

/// The capture the main command runs on when none is given.
pub const DEFAULT_CAPTURE: &[u8] = include_bytes!("../../fixtures/crossroad.pcap");
/// How the built-in capture is named in outputs.
pub const DEFAULT_CAPTURE_NAME: &str = "crossroad (built-in fixtures/crossroad.pcap)";

/// Warns about a capture cut mid-record.
pub fn warn_truncation(observer: &dyn Observer, path: &Path, summary: &CaptureSummary) {
    if let Some(offset) = summary.capture.truncated_at {
        observer.warn(&format!(
            "{}: the capture ends inside a record at byte offset {offset}; \
             every whole packet before it was decoded",
            path.display()
        ));
    }
}

/// Warns about what the decoder skipped and about suspicious data: malformed packets,
/// lasers that never returned, and (when `check_intensity`) an intensity distribution
/// that looks like old firmware's raw levels read as calibrated reflectivity.
pub fn warn_capture(
    observer: &dyn Observer,
    path: &Path,
    s: &CaptureSummary,
    check_intensity: bool,
) {
    let skipped = s.capture.malformed + s.bad_data_packets;
    if skipped > 0 {
        observer.warn(&format!(
            "{}: skipped {} malformed packet{} ({} with malformed headers, {} data packets \
             with an invalid return mode byte)",
            path.display(),
            skipped,
            if skipped == 1 { "" } else { "s" },
            s.capture.malformed,
            s.bad_data_packets
        ));
    }
    warn_duplicates(observer, path, s.duplicate_packets);
    if s.clock_backward_steps > 0 {
        observer.warn(&format!(
            "{}: the sensor clock runs backwards {} time{} between data packets: the capture \
             holds reordered or duplicated packets (or the sensor's clock was reset), so \
             frames may repeat or mix returns; sort and deduplicate the packets (e.g. by \
             timestamp) if that was not intended",
            path.display(),
            s.clock_backward_steps,
            if s.clock_backward_steps == 1 { "" } else { "s" }
        ));
    }
    if s.short_frames > 0 {
        observer.warn(&format!(
            "{}: {} frame{} between the first and the last cover less than nine tenths of a \
             turn: the azimuths jump back within the capture (interleaved or reordered \
             packets, or two sensors in one capture), and every jump cuts a frame; sort the \
             packets by time, or split the capture by sensor, if that was not intended",
            path.display(),
            s.short_frames,
            if s.short_frames == 1 { "" } else { "s" }
        ));
    }
    let dead = s.dead_lasers();
    if !dead.is_empty() {
        observer.warn(&format!(
            "{}: dead laser{} (no return over the whole capture): {}",
            path.display(),
            if dead.len() == 1 { "" } else { "s" },
            join_ids(&dead)
        ));
    }
    if check_intensity {
        if let Some(hint) = raw_intensity_hint(s) {
            observer.warn(&format!("{}: {hint}", path.display()));
        }
    }
}

/// Warns about the data packets dropped as exact copies of one before them, if any.
pub fn warn_duplicates(observer: &dyn Observer, path: &Path, duplicates: u64) {
    if duplicates > 0 {
        observer.warn(&format!(
            "{}: dropped {} duplicate data packet{} (exact copies, same timestamp and bytes, \
             of one of the {} data packets before; the capture was recorded or merged twice?): \
             frames are decoded from the first copies only",
            path.display(),
            duplicates,
            if duplicates == 1 { "" } else { "s" },
            crate::sensor::frames::DUPLICATE_WINDOW
        ));
    }
}

/// The advice printed when the intensities look like raw levels, if they do.
pub fn raw_intensity_hint(s: &CaptureSummary) -> Option<String> {
    s.raw_intensity_suspected().map(|(share, median)| {
        format!(
            "{:.1} % of the intensities are above 100 (median {median}): this looks like old \
             firmware's raw 0-255 levels, which reflectivity mode reads as retro-reflectors; \
             if so, add --set sensor.intensity=\"raw\"",
            100.0 * share
        )
    })
}

/// Laser ids as "3, 7, 30".
pub fn join_ids(ids: &[u8]) -> String {
    ids.iter().map(u8::to_string).collect::<Vec<_>>().join(", ")
}

/// Frames of `capture` in `range` that `run` and `convert` process, counted from the
/// frame index without decoding returns (as `sweep` counts its frames): the total of
/// their progress bars. None for standard input and other files that are not regular
/// (a FIFO can be read only once), and when the count fails (the run then reports why).
pub fn frames_total(
    capture: &Path,
    options: &crate::sensor::frames::DecoderOptions,
    range: &std::ops::RangeInclusive<u32>,
) -> Option<u64> {
    if is_stdin(capture) || !std::fs::metadata(capture).is_ok_and(|m| m.is_file()) {
        return None;
    }
    let scan = crate::sensor::index::FrameScan::open(capture, options).ok()?;
    let (_, _, n) = crate::shard::chunk_plan(scan, range, options.keep_partial, u32::MAX).ok()?;
    Some(n as u64)
}

/// Starts the observer's count of the frames of `capture` (None: the built-in one) in
/// `range`, with [`frames_total`] as its total when progress is shown.
pub fn start_frames(
    observer: &dyn Observer,
    capture: Option<&Path>,
    options: &crate::sensor::frames::DecoderOptions,
    range: &std::ops::RangeInclusive<u32>,
) {
    let total = match capture {
        Some(path) if observer.shows_progress() => frames_total(path, options, range),
        _ => None,
    };
    observer.start(Counter::Frames, total);
}

/// The capture path that stands for standard input.
pub const STDIN: &str = "-";

/// True when `path` is `-`, standard input.
pub fn is_stdin(path: &Path) -> bool {
    path.as_os_str() == STDIN
}

/// How outputs name a capture: its file name, not the path as typed, so the same capture
/// run from another folder gives identical reports; `stdin` for `-`.
pub fn capture_label(path: &Path) -> String {
    if is_stdin(path) {
        return "stdin".into();
    }
    path.file_name().map_or_else(
        || path.display().to_string(),
        |n| n.to_string_lossy().into_owned(),
    )
}

/// The frame reader of a capture file or of standard input (`-`, read to its end and held
/// in memory, as each reader reads a capture twice: to identify the sensor, then to
/// decode): the HDL-32E's, or another described sensor's where that refuses the capture
/// and the sensor's structure fits it (a FIFO is read once: only the HDL-32E's).
pub fn open_any_capture(
    path: &Path,
    options: &crate::sensor::frames::DecoderOptions,
) -> anyhow::Result<crate::sensor::frames::CaptureFrames> {
    if !is_stdin(path) {
        return Ok(crate::sensor::frames::open_capture(path, options)?);
    }
    let name = Path::new(STDIN_NAME);
    let bytes = crate::capture::read_stream(std::io::stdin().lock(), name)?;
    Ok(crate::sensor::frames::open_capture_bytes(
        std::sync::Arc::from(bytes),
        name,
        options,
    )?)
}

/// How messages name standard input.
pub const STDIN_NAME: &str = "<stdin>";

/// How messages name a capture: the path as given, `<stdin>` for `-` (outputs name it by
/// [`capture_label`]).
pub fn capture_shown(path: &Path) -> String {
    if is_stdin(path) {
        STDIN_NAME.to_string()
    } else {
        path.display().to_string()
    }
}

/// Refuses `-` given more than once (standard input can be read only once).
pub fn check_stdin_once(paths: &[std::path::PathBuf]) -> anyhow::Result<()> {
    if paths.iter().filter(|p| is_stdin(p)).count() > 1 {
        anyhow::bail!("`-` (standard input) can be given only once");
    }
    Ok(())
}

/// Output names of captures: each file's stem, with `-2`, `-3`, ... added where two
/// captures share a stem, so every capture gets its own folder. A stem that is no usable
/// folder name (``, `.`, `..`, or one starting with `.`, which would be hidden and could
/// match the tool's own temporary names) gets a `capture` prefix.
pub fn output_names(paths: &[std::path::PathBuf]) -> Vec<String> {
    let mut used = std::collections::HashSet::new();
    paths
        .iter()
        .map(|path| {
            if is_stdin(path) {
                used.insert("stdin".to_string());
                return "stdin".to_string();
            }
            let stem = path.file_stem().map_or_else(
                || "capture".to_string(),
                |s| s.to_string_lossy().into_owned(),
            );
            // A nuScenes scan `X.pcd.bin` is named X, as its token.
            let stem = match stem.strip_suffix(".pcd") {
                Some(s) if path.extension().is_some_and(|e| e == "bin") => s.to_string(),
                _ => stem,
            };
            let stem = if stem.is_empty() || stem.starts_with('.') {
                format!("capture{stem}")
            } else {
                stem
            };
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
