//! Per-frame reports spooled to disk as frames complete and joined into summary.json,
//! clusters.json and clusters.csv at the end, so that a run's memory does not grow with
//! the capture's length.

use crate::pipeline::report::{
    write_cluster_csv, write_frame_clusters_json, write_pretty_nested, FrameClusters, FrameReport,
    Totals,
};
use anyhow::{Context, Result};
use serde::Serialize;
use std::path::Path;

/// Per-frame reports written to disk as they come (summary frames, cluster frames and
/// cluster CSV rows), with the totals kept as a running sum.
pub(crate) struct ReportSpool {
    summary_frames: std::io::BufWriter<std::fs::File>,
    /// clusters.json itself: its head needs nothing the frames decide, so the frames go
    /// straight into the final file instead of a spool that is copied at the end.
    clusters: crate::writers::atomic::AtomicFile,
    csv_rows: std::io::BufWriter<std::fs::File>,
    pub(crate) totals: Totals,
    pub(crate) frames: usize,
}

/// One frame's report pieces, serialised by the worker that processed the frame so that
/// only the writing is left to the thread that keeps frame order.
pub(crate) struct SpoolEntry {
    pub(crate) report: FrameReport,
    pub(crate) summary: Vec<u8>,
    pub(crate) clusters: Vec<u8>,
    pub(crate) csv: Vec<u8>,
}

impl SpoolEntry {
    pub(crate) fn of(report: FrameReport, clusters: &FrameClusters) -> Result<Self> {
        // Sized from the shared capture's reports (a frame's summary about 2 kB, a
        // cluster's CSV row about 190 bytes, its JSON about 1.2 kB), so that the buffers
        // seldom grow, each growth copying what they hold.
        let mut summary = Vec::with_capacity(4096);
        write_element(&mut summary, "", &report)?;
        let mut cluster_bytes = Vec::with_capacity(64 + 1280 * clusters.clusters.len());
        cluster_bytes.extend_from_slice(b"    ");
        write_frame_clusters_json(&mut cluster_bytes, 2, clusters);
        let mut csv = Vec::with_capacity(512 + 256 * clusters.clusters.len());
        write_cluster_csv(&mut csv, std::slice::from_ref(clusters));
        Ok(SpoolEntry {
            report,
            summary,
            clusters: cluster_bytes,
            csv,
        })
    }
}

const SPOOL_SUMMARY: &str = ".summary-frames.part";
const SPOOL_CSV: &str = ".clusters-csv.part";

impl ReportSpool {
    pub(crate) fn new<C: Serialize>(dir: &Path, clusters: &C, inputs: &[&Path]) -> Result<Self> {
        let open = |name: &str| -> Result<std::io::BufWriter<std::fs::File>> {
            let path = dir.join(name);
            let f = std::fs::File::create(&path).map_err(|e| crate::error::Error::io(&path, e))?;
            Ok(std::io::BufWriter::new(f))
        };
        let mut cluster_file =
            crate::writers::atomic::AtomicFile::create(&dir.join("clusters.json"), inputs)?;
        cluster_file.write_all(document_stem(clusters)?.as_bytes())?;
        cluster_file.write_all(b"[\n")?;
        Ok(ReportSpool {
            summary_frames: open(SPOOL_SUMMARY)?,
            clusters: cluster_file,
            csv_rows: open(SPOOL_CSV)?,
            totals: Totals::default(),
            frames: 0,
        })
    }

    pub(crate) fn add(&mut self, entry: SpoolEntry) -> Result<()> {
        use std::io::Write;
        let sep: &[u8] = if self.frames == 0 { b"" } else { b",\n" };
        self.summary_frames.write_all(sep)?;
        self.summary_frames.write_all(&entry.summary)?;
        self.clusters.write_all(sep)?;
        self.clusters.write_all(&entry.clusters)?;
        // Every table starts with the header line; the final file has it once.
        let csv = &entry.csv;
        let start = if self.frames == 0 {
            0
        } else {
            csv.iter()
                .position(|&b| b == b'\n')
                .map_or(csv.len(), |i| i + 1)
        };
        self.csv_rows.write_all(&csv[start..])?;
        self.totals.add(&entry.report);
        self.frames += 1;
        Ok(())
    }

    /// Writes summary.json from its spool file, closes clusters.json and renames
    /// clusters.csv into place, with the same bytes as serialising the whole documents at
    /// once.
    pub(crate) fn finish<S: Serialize>(
        self,
        summary: &S,
        dir: &Path,
        inputs: &[&Path],
    ) -> Result<()> {
        let ReportSpool {
            summary_frames,
            mut clusters,
            csv_rows,
            ..
        } = self;
        // Flushed, not synced: the spool files are read back by this process (through the
        // page cache) and the results are renamed into place only after; an fsync here
        // cost more wall time than the whole report.
        for w in [summary_frames, csv_rows] {
            w.into_inner().map_err(|e| e.into_error())?;
        }
        join_document(
            summary,
            &dir.join(SPOOL_SUMMARY),
            &dir.join("summary.json"),
            inputs,
        )?;
        clusters.write_all(DOCUMENT_END)?;
        clusters.commit()?;
        std::fs::rename(dir.join(SPOOL_CSV), dir.join("clusters.csv"))
            .with_context(|| format!("{}: cannot write", dir.join("clusters.csv").display()))?;
        Ok(())
    }
}

/// One array element as `to_writer_pretty` lays it out two levels deep.
fn write_element<T: Serialize>(out: &mut impl std::io::Write, sep: &str, value: &T) -> Result<()> {
    out.write_all(sep.as_bytes())?;
    out.write_all(b"    ")?;
    write_pretty_nested(out, 2, value)?;
    Ok(())
}

/// Writes `doc` (whose last field is an empty `frames` array) with the spooled elements
/// put into that array, then deletes the spool file.
fn join_document<T: Serialize>(doc: &T, spool: &Path, path: &Path, inputs: &[&Path]) -> Result<()> {
    join_with(doc, path, inputs, |out| {
        // Large chunks: few read and write calls (the writer passes them by its buffer).
        let mut spooled = std::fs::File::open(spool)?;
        let mut chunk = vec![0u8; 256 << 10];
        loop {
            match std::io::Read::read(&mut spooled, &mut chunk) {
                Ok(0) => return Ok(()),
                Ok(n) => out.write_all(&chunk[..n])?,
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                Err(e) => return Err(e),
            }
        }
    })?;
    std::fs::remove_file(spool).ok();
    Ok(())
}

/// Writes `doc` (whose last field is an empty `frames` array) with the elements `body`
/// writes put into that array.
pub(crate) fn join_with<T: Serialize>(
    doc: &T,
    path: &Path,
    inputs: &[&Path],
    body: impl FnOnce(&mut dyn std::io::Write) -> std::io::Result<()>,
) -> Result<()> {
    let stem = document_stem(doc)?;
    crate::writers::atomic::write_atomically(path, inputs, |out| {
        out.write_all(stem.as_bytes())?;
        out.write_all(b"[\n")?;
        body(out)?;
        out.write_all(DOCUMENT_END)
    })?;
    Ok(())
}

/// `doc` (whose last field is an empty `frames` array) pretty-printed up to that array's
/// opening bracket, exclusive.
fn document_stem<T: Serialize>(doc: &T) -> Result<String> {
    let mut head = serde_json::to_string_pretty(doc)?;
    let Some(len) = head.strip_suffix("[]\n}").map(str::len) else {
        anyhow::bail!("internal: the report does not end with its frames array");
    };
    head.truncate(len);
    Ok(head)
}

/// What follows a document's last frame: the frames array and the document closed.
const DOCUMENT_END: &[u8] = b"\n  ]\n}\n";
