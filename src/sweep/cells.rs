//! A sweep's cell files: one per cell and capture, `cells/<capture>/<cell>.json`, with the
//! settings and input content that produced it and a checksum, written a frame at a time
//! and reused by later sweeps of the same settings; the parts of chunked cells joined
//! into one.

use super::plan::Cell;
use super::run::{CaptureInput, SweepSettings, METRICS_VERSION};
use super::stream::{self, CHECKSUM_PLACEHOLDER};
use crate::config::Config;
use crate::error::{Error, Result};
use crate::score::metrics::FrameMetrics;
use serde::Serialize;
use std::path::{Path, PathBuf};

/// A cell result file (written by [`CellWriter`], read by [`stream::scan_cell`]).
#[derive(Serialize)]
struct CellFile {
    tool: String,
    settings: serde_json::Value,
    frames: Vec<FrameMetrics>,
    /// xxh3-64 (hex) of the file's bytes with this value written as 16 zeros: an edited
    /// or cut file does not verify and is recomputed.
    #[serde(default)]
    checksum: String,
}

/// Joins a cell's parts (which must all verify) in frame order into the cell file a sweep
/// without chunks writes, then deletes the parts (only exclusive runs join: no shard is
/// writing them). The frames are joined as text: parsing and writing the metrics again
/// could change the last digit of a float (serde_json's default parser is not exact).
pub(super) fn join_parts(
    path: &Path,
    settings: serde_json::Value,
    parts: &[PathBuf],
    protected: &[&Path],
) -> Result<()> {
    const OPEN: &str = "\n  \"frames\": [\n";
    const CLOSE: &str = "\n  ],\n  \"checksum\"";
    let mut out = CellWriter::create(path, &settings, protected)?;
    for part in parts {
        let bad = || Error::Invalid(format!("{}: part missing or unreadable", part.display()));
        // A part holds one chunk's frames: read whole, it is bounded by --chunk-frames.
        let Some(Ok(head)) = read_cell(part) else {
            return Err(bad());
        };
        let text = std::fs::read_to_string(part).map_err(|_| bad())?;
        let start = text.find(OPEN).ok_or_else(bad)? + OPEN.len();
        let end = text.rfind(CLOSE).filter(|&e| e >= start).ok_or_else(bad)?;
        out.push_indented(&text[start..end], head.frames as u64)?;
    }
    out.commit()?;
    for part in parts {
        let _ = std::fs::remove_file(part);
    }
    Ok(())
}

/// True when the file at `path` names this tool as its writer as the cell files (and
/// parts) a sweep writes do (`"tool": "lidar-noise ..."`), even edited or cut since:
/// proof enough that a sweep wrote it, for the cells no manifest lists.
pub fn written_by_sweep(path: &Path) -> bool {
    const TOOL: &[u8] = b"\"tool\": \"lidar-noise ";
    // Cells hold a few kB per frame; anything far larger is not one of them.
    const MAX_CELL_BYTES: u64 = 1 << 30;
    if std::fs::metadata(path).map_or(true, |m| !m.is_file() || m.len() > MAX_CELL_BYTES) {
        return false;
    }
    let holds = |bytes: &[u8]| bytes.windows(TOOL.len()).any(|w| w == TOOL);
    // As written, the file starts with it; only a file rewritten with other key order
    // is read whole.
    let mut head = Vec::with_capacity(256);
    let Ok(file) = std::fs::File::open(path) else {
        return false;
    };
    use std::io::Read;
    if file.take(256).read_to_end(&mut head).is_ok() && holds(&head) {
        return true;
    }
    std::fs::read(path).is_ok_and(|bytes| holds(&bytes))
}

/// Hashes of the capture's, labels' and calibration's content and the tool version: a
/// cell computed from other data (same name and size included) is not reused.
pub(super) fn content_key(s: &SweepSettings, capture: &CaptureInput) -> Result<serde_json::Value> {
    let labels = match &capture.labels {
        Some(p) => Some(hash_file(p)?),
        None => None,
    };
    Ok(serde_json::json!({
        "tool_version": env!("CARGO_PKG_VERSION"),
        "capture_xxh3": hash_file(&capture.path)?,
        "labels_xxh3": labels,
        "calibration_xxh3": format!(
            "{:016x}",
            xxhash_rust::xxh3::xxh3_64(format!("{:?}", s.decoder.calibration).as_bytes())
        ),
    }))
}

/// xxh3-64 of a file's bytes in hex, read in blocks (memory stays flat).
pub fn hash_file(path: &Path) -> Result<String> {
    use std::io::Read;
    let mut file = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
    let mut hasher = xxhash_rust::xxh3::Xxh3::new();
    let mut buf = vec![0u8; 1 << 16];
    loop {
        let n = file.read(&mut buf).map_err(|e| Error::io(path, e))?;
        if n == 0 {
            break;
        }
        hasher.update(&buf[..n]);
    }
    Ok(format!("{:016x}", hasher.digest()))
}

pub(super) fn cell_settings(
    s: &SweepSettings,
    capture: &CaptureInput,
    content: &serde_json::Value,
    cell: &Cell,
    config: &Config,
    baseline: &Config,
) -> serde_json::Value {
    let values: Vec<serde_json::Value> = s
        .varies
        .iter()
        .zip(&cell.values)
        .map(|(v, x)| serde_json::json!({ "key": v.key, "value": x }))
        .collect();
    serde_json::json!({
        "metrics_version": METRICS_VERSION,
        "capture": capture.name,
        "content": content,
        "labels": capture.labels.as_ref().and_then(|p| p.file_name()).map(|n| n.to_string_lossy()),
        "frames": [s.frames.start(), s.frames.end()],
        "bands": s.bands,
        "decoder": {
            "calibration": s.decoder.calibration.source,
            "interpolate_azimuth": s.decoder.interpolate_azimuth,
            "dual": format!("{:?}", s.decoder.dual),
            "cut_angle_deg": s.decoder.cut_angle_deg,
            "keep_partial": s.decoder.keep_partial,
        },
        "cell": values,
        "seed": cell.seed,
        "config": config.to_json(),
        "baseline": baseline.to_json(),
    })
}

/// The cell file at `path`, its frames read and dropped: None when there is none,
/// Err(why) when it does not verify.
pub(super) fn read_cell(path: &Path) -> Option<std::result::Result<stream::CellHead, String>> {
    stream::scan_cell(path, &mut |_| ())
}

/// A cell file written a frame at a time, in the layout of `serde_json::to_vec_pretty`
/// of a [`CellFile`] and a line break, its checksum computed as the bytes go; it appears
/// at its path only once committed.
pub(super) struct CellWriter {
    array: stream::ArrayWriter<crate::writers::atomic::AtomicFile>,
    path: PathBuf,
}

impl CellWriter {
    /// Buffer of each cell file: the cells of a batch are written side by side.
    const BUFFER_BYTES: usize = 64 << 10;

    pub(super) fn create(
        path: &Path,
        settings: &serde_json::Value,
        protected: &[&Path],
    ) -> Result<Self> {
        let file =
            crate::writers::atomic::AtomicFile::with_buffer(path, protected, Self::BUFFER_BYTES)?;
        let doc = CellFile {
            tool: format!("lidar-noise {}", env!("CARGO_PKG_VERSION")),
            settings: settings.clone(),
            frames: Vec::new(),
            checksum: CHECKSUM_PLACEHOLDER.into(),
        };
        let mut array =
            stream::ArrayWriter::start(file, &doc, "frames").map_err(|e| Error::io(path, e))?;
        // The head on disk at once: a kill leaves a temporary file that says by its
        // content that a sweep wrote it, which the next run cleans up.
        array.flush().map_err(|e| Error::io(path, e))?;
        Ok(CellWriter {
            array,
            path: path.to_path_buf(),
        })
    }

    pub(super) fn push(&mut self, m: &FrameMetrics) -> Result<()> {
        self.array.push(m).map_err(|e| Error::io(&self.path, e))
    }

    fn push_indented(&mut self, text: &str, n: u64) -> Result<()> {
        self.array
            .push_indented(text, n)
            .map_err(|e| Error::io(&self.path, e))
    }

    /// Writes the checksum (of the bytes with it written as zeros) and renames the file
    /// into place.
    pub(super) fn commit(self) -> Result<()> {
        let (mut file, mut tail, mut hasher) = self.array.into_tail();
        tail.push('\n');
        hasher.update(tail.as_bytes());
        let sum = format!("{:016x}", hasher.digest());
        let field = format!("\"checksum\": \"{CHECKSUM_PLACEHOLDER}\"");
        let at = tail.rfind(&field).ok_or_else(|| {
            Error::Invalid("internal: the cell file has no checksum field".into())
        })? + field.len()
            - 1
            - CHECKSUM_PLACEHOLDER.len();
        tail.replace_range(at..at + sum.len(), &sum);
        file.write_all(tail.as_bytes())?;
        file.commit()
    }
}
