//! `run --chunk-frames M`: frame ranges of captures as units of a sharded run.
//!
//! The units are (capture, chunk j), chunk j being the capture's frames at positions
//! [j*M, (j+1)*M) of those in `--frames`, numbered over the captures in the order given;
//! `--shard K/N` takes the units `i` with `i % N == K`. Captures of any described sensor:
//! a unit resumes the decoder where its chunk starts (the HDL-32E's from its frame index,
//! [`crate::sensor::index`], which reads no returns; another sensor's from a scan of the
//! capture, [`ModelFrameReader::scan`]), writes its frames' own files (point
//! clouds, linkage) straight into the capture's folder `DIR/<name>/`, and last a part,
//! `DIR/<name>/.run.chunk<M>-<j>.json`: the chunk's report pieces as the text one run
//! writes them, its exact totals, the files it wrote and the run's settings, behind a
//! checksum, written under a temporary name and renamed. A shard killed mid-unit leaves
//! at most frame files (rewritten with the same bytes by the rerun) and a `.*.tmp`, never
//! a part; a part cut or changed fails its checksum.
//!
//! `--merge` (or the same run without `--shard`, which computes every unit first) takes
//! the folder's exclusive lock, checks that every part is there with this run's settings
//! (else fails listing the missing ones and writes nothing), decodes each capture once
//! without processing it for the capture summary (the numbers a run reports cover every
//! packet read, which the parts alone do not), joins the parts into summary.json,
//! clusters.json and clusters.csv, writes the manifest and deletes the parts: the folder is
//! then the one a run on one machine writes, byte for byte.
//!
//! Shards write side by side under a shared lock and never delete anything: a capture
//! folder holding another run's results is refused (delete it or choose another folder).

use super::{Plan, RunRequest};
use crate::noise::summary::{
    DropCounts, DropsByLaser, NoiseSummary, RangeChange, RangeChangeState, SpuriousCounts,
};
use crate::observe::Observer;
use crate::pipeline::report::Totals;
use crate::pipeline::StageCounts;
use crate::sensor::frames::FrameReader;
use crate::sensor::frames::{CaptureFrames, CaptureSeek};
use crate::sensor::index::FrameScan;
use crate::shard::{self, Batch};
use crate::writers::staging::{self, OutputFolder, Refused};
use anyhow::{bail, Result};
use serde::{Deserialize, Serialize};
use std::ops::RangeInclusive;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// First bytes of a part file; the checksum of the rest follows (see
/// [`shard::write_checked`]).
const PART_MAGIC: &str = "lidar-noise run part xxh3 ";

/// A capture of the run.
struct Job {
    /// How outputs name it.
    source: String,
    /// Its folder name.
    name: String,
    /// The file (None: the built-in capture).
    path: Option<PathBuf>,
    /// The plan for its sensor.
    plan: Plan,
}

impl Job {
    /// How messages name it: the path as given (as `convert`'s do), else its label.
    fn shown(&self) -> String {
        self.path
            .as_deref()
            .map_or_else(|| self.source.clone(), super::inputs::capture_shown)
    }

    /// The job of the capture at `path` (None: the built-in one) and its chunks of `m`
    /// frames, with the number of frames.
    fn plan(
        source: String,
        name: String,
        path: Option<PathBuf>,
        plan: &Plan,
        m: u32,
    ) -> Result<(Job, Chunks, usize)> {
        let decoder = &plan.decoder;
        let (sensor, found) = match &path {
            // The scan also tells the sensor (and refuses a FIFO before opening it).
            Some(p) => crate::sensor::frames::scan_capture(p, decoder)?,
            None => {
                let scan = FrameScan::from_bytes(
                    Arc::from(super::inputs::DEFAULT_CAPTURE),
                    Path::new(super::inputs::DEFAULT_CAPTURE_NAME),
                    decoder,
                )?;
                let found = crate::sensor::frames::hdl32e_scanned(scan);
                (&crate::sensor::HDL32E, found)
            }
        };
        let job_plan = plan.for_sensor(sensor).map_err(|e| match &path {
            Some(p) => anyhow::anyhow!("{}: {e:#}; nothing was written", p.display()),
            None => e,
        })?;
        let keep = decoder.keep_partial;
        let (ranges, seeks, n) = shard::chunks_of(found, &plan.frames, keep, m)?;
        let job = Job {
            source,
            name,
            path,
            plan: job_plan,
        };
        Ok((job, Chunks { ranges, seeks }, n))
    }

    /// The capture's reader, from the start or from `at`.
    fn open(&self, at: Option<&CaptureSeek>) -> Result<CaptureFrames> {
        let decoder = &self.plan.decoder;
        let bytes = || Arc::from(super::inputs::DEFAULT_CAPTURE);
        let name = Path::new(super::inputs::DEFAULT_CAPTURE_NAME);
        Ok(match (&self.path, at) {
            (Some(p), Some(at)) => crate::sensor::frames::open_capture_at(p, decoder, at)?,
            (Some(p), None) => crate::sensor::frames::open_capture(p, decoder)?,
            (None, Some(CaptureSeek::Hdl32e(at))) => CaptureFrames::Hdl32e(Box::new(
                FrameReader::from_bytes_at(bytes(), name, decoder, at)?,
            )),
            (None, _) => {
                CaptureFrames::Hdl32e(Box::new(FrameReader::from_bytes(bytes(), name, decoder)?))
            }
        })
    }
}

/// A capture's chunks and where each starts.
struct Chunks {
    ranges: Vec<RangeInclusive<u32>>,
    seeks: Vec<CaptureSeek>,
}

/// The exact totals of a part (see [`RangeChangeState`]).
#[derive(Serialize, Deserialize)]
struct ExactTotals {
    frames: u64,
    returns_in: u64,
    returns_out: u64,
    dropped: DropCounts,
    dropped_by_laser: DropsByLaser,
    range_change: RangeChangeState,
    spurious: SpuriousCounts,
    stages: StageCounts,
}

impl ExactTotals {
    fn of(t: &Totals) -> Self {
        let n = &t.noise;
        ExactTotals {
            frames: n.frames,
            returns_in: n.returns_in,
            returns_out: n.returns_out,
            dropped: n.dropped,
            dropped_by_laser: n.dropped_by_laser.clone(),
            range_change: n.range_change.state(),
            spurious: n.spurious,
            stages: t.stages.clone(),
        }
    }

    fn noise(&self) -> Option<NoiseSummary> {
        Some(NoiseSummary {
            frames: self.frames,
            returns_in: self.returns_in,
            returns_out: self.returns_out,
            dropped: self.dropped,
            dropped_by_laser: self.dropped_by_laser.clone(),
            range_change: RangeChange::from_state(&self.range_change)?,
            spurious: self.spurious,
        })
    }
}

/// What a unit leaves for the merge.
#[derive(Serialize, Deserialize)]
struct Part {
    /// The run's settings plus the chunk's (size, index, count, frame range).
    settings: serde_json::Value,
    /// Frames in the chunk.
    frames: usize,
    /// Files the unit wrote in the capture folder.
    files: Vec<String>,
    totals: ExactTotals,
    /// summary.json's frame elements, as one run writes them, comma-separated.
    summary_frames: String,
    /// clusters.json's frame elements.
    cluster_frames: String,
    /// clusters.csv for the chunk, header line included.
    csv: String,
}

/// File name of part `j` with chunks of `m` frames.
fn part_name(m: u32, j: usize) -> String {
    shard::part_name("run", m, j)
}

/// Chunk size of a part file name (None for other names).
fn part_chunk_size(name: &str) -> Option<u32> {
    shard::run_part_chunk_size(name)
}

fn write_part(path: &Path, part: &Part, inputs: &[&Path]) -> Result<()> {
    Ok(shard::write_checked(path, PART_MAGIC, part, inputs)?)
}

/// Reads a part: None when absent, Err(why) when it cannot be trusted.
fn read_part(path: &Path) -> Option<std::result::Result<Part, String>> {
    shard::read_checked(path, PART_MAGIC)
}

/// Checks a capture folder a shard or merge writes into: no other run's results, no
/// files this tool did not write, no parts of another chunk size.
fn check_folder(
    target: &Path,
    settings: &serde_json::Value,
    m: u32,
    inputs: &[&Path],
) -> Result<()> {
    super::reports::check_target(target, inputs)?;
    shard::check_parts(target, Some(m), Batch::Run)?;
    if let Some(manifest) = staging::read_manifest(target) {
        if manifest.command != "run" || manifest.settings != *settings {
            return Err(anyhow::Error::new(Refused(format!(
                "{}: holds the results of another run; a sharded run never deletes results \
                 (its shards run at once): delete the folder, or choose another output folder",
                target.display()
            ))));
        }
    }
    // Only refuses files this tool did not write (and inputs): with `force` set, results
    // of an earlier run pass, and the manifest was compared above.
    let ours = |f: &str| super::reports::is_run_output(f) || part_chunk_size(f).is_some();
    // Parts are written in place by shards and never listed in a manifest.
    let parts = |f: &str| part_chunk_size(f).is_some();
    staging::check_replace(target, "run", settings, &ours, &parts, true, inputs)?;
    Ok(())
}

/// True when `dir` holds the complete results of this run (merged, or written by one
/// run): its manifest has these settings and every file it lists is there. Its units are
/// then done, for shards run again after the merge as for the merge.
fn merged(dir: &Path, settings: &serde_json::Value) -> bool {
    staging::read_manifest(dir).is_some_and(|m| {
        m.command == "run"
            && m.settings == *settings
            && m.files.iter().all(|f| dir.join(f).is_file())
    })
}

/// Runs `run --chunk-frames m` (as a shard, a merge, or both in one process).
pub(crate) fn run(
    request: &RunRequest,
    plan: &Plan,
    m: u32,
    inputs: &[&Path],
    observer: &dyn Observer,
) -> Result<()> {
    if plan.pcap_out {
        bail!(
            "--pcap-out cannot be split into --chunk-frames: the noisy capture is one file \
             written in frame order; run it without --chunk-frames"
        );
    }
    if request.captures.iter().any(|p| super::inputs::is_stdin(p)) {
        bail!(
            "--chunk-frames needs capture files: standard input (`-`) cannot be read by \
             several shards, nor resumed mid-capture"
        );
    }
    if request.force && request.shard.is_some() {
        bail!(
            "--force cannot be given to a shard of --chunk-frames: shards run at once and \
             never delete results; give it to --merge (stale frame files), or delete the \
             folder to replace another run"
        );
    }
    let mut named = Vec::new();
    if request.captures.is_empty() {
        named.push((
            super::inputs::DEFAULT_CAPTURE_NAME.to_string(),
            "crossroad".to_string(),
            None,
        ));
    }
    for (path, name) in request
        .captures
        .iter()
        .zip(super::inputs::output_names(&request.captures))
    {
        named.push((super::inputs::capture_label(path), name, Some(path.clone())));
    }
    // The units, and so the deal, are known before any work: each capture is scanned
    // (an HDL-32E's frame starts only, no returns decoded).
    let (mut jobs, mut plans) = (Vec::new(), Vec::new());
    for (source, name, path) in named {
        let (job, chunks, n) = Job::plan(source, name, path, plan, m)?;
        if n == 0 {
            bail!(
                "{}: no frame to process in {}; pick others with --frames or add \
                 --keep-partial",
                job.shown(),
                crate::range::frames_phrase(&plan.frames)
            );
        }
        jobs.push(job);
        plans.push(chunks);
    }
    let total: usize = plans.iter().map(|c| c.ranges.len()).sum();
    let folder = if request.shard.is_some() {
        OutputFolder::lock_shared(&request.output)?
    } else {
        OutputFolder::lock(&request.output)?
    };
    let result = units(request, plan, m, &jobs, &plans, total, inputs, observer);
    if result.is_ok() {
        // The checks passed and the merge is done: what killed runs of this tool left.
        folder.remove_leftovers(&super::reports::is_run_path);
    }
    if result.is_err() {
        // A folder this (exclusive) run created, with nothing in it, goes again.
        folder.abandon();
    }
    result
}

/// Computes the units that fall to this process and merges (unless a shard).
#[allow(clippy::too_many_arguments)]
fn units(
    request: &RunRequest,
    plan: &Plan,
    m: u32,
    jobs: &[Job],
    plans: &[Chunks],
    total: usize,
    inputs: &[&Path],
    observer: &dyn Observer,
) -> Result<()> {
    let mut settings = Vec::new();
    for job in jobs {
        let s = super::reports::run_settings(plan, &job.source);
        check_folder(&request.output.join(&job.name), &s, m, inputs)?;
        settings.push(s);
    }
    if !request.merge {
        let mut offset = 0usize;
        let (mut owned, mut computed) = (0usize, 0usize);
        for ((job, chunks), settings) in jobs.iter().zip(plans).zip(&settings) {
            let n = chunks.ranges.len();
            let dir = request.output.join(&job.name);
            let done = merged(&dir, settings);
            for j in 0..n {
                if request.shard.is_some_and(|s| !s.owns(offset + j)) {
                    continue;
                }
                owned += 1;
                if done {
                    continue;
                }
                std::fs::create_dir_all(&dir).map_err(|e| crate::error::Error::io(&dir, e))?;
                let path = dir.join(part_name(m, j));
                let want = shard::part_settings(settings, m, j, n, &chunks.ranges[j]);
                // A part already there for these settings is kept (shards may run twice).
                if let Some(Ok(p)) = read_part(&path) {
                    if p.settings == want && p.files.iter().all(|f| dir.join(f).is_file()) {
                        continue;
                    }
                }
                let part =
                    compute_unit(job, &chunks.ranges[j], &chunks.seeks[j], &dir, inputs, want)?;
                write_part(&path, &part, inputs)?;
                computed += 1;
            }
            offset += n;
        }
        if let Some(shard) = request.shard {
            observer.note(&format!(
                "run --shard {shard}: {owned} of {total} capture chunks fall to this shard \
                 ({computed} computed, {} already done); a shard writes no reports: run \
                 `lidar-noise run ... --chunk-frames {m} --merge` once every shard is done",
                owned - computed
            ));
            return Ok(());
        }
    }
    merge(request, m, jobs, plans, &settings, inputs, observer)
}

/// Processes one chunk: its frames' files into `dir`, its report pieces into the part.
fn compute_unit(
    job: &Job,
    range: &RangeInclusive<u32>,
    seek: &CaptureSeek,
    dir: &Path,
    inputs: &[&Path],
    settings: serde_json::Value,
) -> Result<Part> {
    let plan = &job.plan;
    let mut reader = job.open(Some(seek))?.into_source();
    let mut part = Part {
        settings,
        frames: 0,
        files: Vec::new(),
        totals: ExactTotals::of(&Totals::default()),
        summary_frames: String::new(),
        cluster_frames: String::new(),
        csv: String::new(),
    };
    let mut totals = Totals::default();
    let (mut summary, mut clusters, mut csv) = (Vec::new(), Vec::new(), Vec::new());
    let work = |f: crate::frame::Frame| {
        let result = plan.pipeline.process(f)?;
        super::frame_files::frame_outputs(plan, result, &job.source, dir, inputs, true)
    };
    let warmup = crate::memory::worker_warmup_bytes();
    super::stream::stream_frames(
        &mut *reader,
        range,
        warmup,
        work,
        |(entry, returns), reader| {
            reader.recycle(crate::frame::Frame {
                returns,
                ..crate::frame::Frame::default()
            });
            // As the run's report spool: elements comma-separated, one CSV header.
            let sep: &[u8] = if part.frames == 0 { b"" } else { b",\n" };
            summary.extend_from_slice(sep);
            summary.extend_from_slice(&entry.summary);
            clusters.extend_from_slice(sep);
            clusters.extend_from_slice(&entry.clusters);
            let start = if part.frames == 0 {
                0
            } else {
                entry
                    .csv
                    .iter()
                    .position(|&b| b == b'\n')
                    .map_or(entry.csv.len(), |i| i + 1)
            };
            csv.extend_from_slice(&entry.csv[start..]);
            totals.add(&entry.report);
            let index = entry.report.index;
            if plan.ply {
                part.files.push(plan.output.file_name(index));
            }
            if plan.linkage {
                part.files.push(format!("linkage_{index:05}.csv"));
            }
            part.frames += 1;
            Ok(())
        },
    )?;
    part.totals = ExactTotals::of(&totals);
    let text = |b: Vec<u8>| String::from_utf8(b).map_err(|e| anyhow::anyhow!("internal: {e}"));
    part.summary_frames = text(summary)?;
    part.cluster_frames = text(clusters)?;
    part.csv = text(csv)?;
    Ok(part)
}

/// Joins the parts of every capture into its reports, or fails listing missing parts.
#[allow(clippy::too_many_arguments)]
fn merge(
    request: &RunRequest,
    m: u32,
    jobs: &[Job],
    plans: &[Chunks],
    settings: &[serde_json::Value],
    inputs: &[&Path],
    observer: &dyn Observer,
) -> Result<()> {
    // Every part of every capture is checked before anything is written.
    let mut missing = Vec::new();
    for ((job, chunks), settings) in jobs.iter().zip(plans).zip(settings) {
        let dir = request.output.join(&job.name);
        let n = chunks.ranges.len();
        if merged(&dir, settings) {
            continue;
        }
        for j in 0..n {
            let path = dir.join(part_name(m, j));
            let want = shard::part_settings(settings, m, j, n, &chunks.ranges[j]);
            match read_part(&path) {
                Some(Ok(p)) if p.settings == want && p.frames <= m as usize => {
                    // A frame file deleted since: the unit is to be computed again.
                    if let Some(f) = p.files.iter().find(|f| !dir.join(f).is_file()) {
                        observer.warn(&format!(
                            "{}: {} it wrote is gone",
                            path.display(),
                            dir.join(f).display()
                        ));
                        missing.push(path.display().to_string());
                    }
                }
                Some(Err(why)) => {
                    observer.warn(&format!("{}: {why}", path.display()));
                    missing.push(path.display().to_string());
                }
                _ => missing.push(path.display().to_string()),
            }
        }
    }
    if !missing.is_empty() {
        let n = missing.len();
        bail!(
            "run --merge: {n} capture chunk part{} missing, unfinished or computed with other \
             settings (run the shards that own them, or rerun without --merge to compute them \
             here): {}",
            if n == 1 { " is" } else { "s are" },
            crate::error::first_ten(&missing),
        );
    }
    let mut lines = Vec::new();
    for ((job, chunks), settings) in jobs.iter().zip(plans).zip(settings) {
        let dir = request.output.join(&job.name);
        let names: Vec<String> = (0..chunks.ranges.len()).map(|j| part_name(m, j)).collect();
        if merged(&dir, settings) {
            lines.push(format!("{}: already merged", job.shown()));
            continue;
        }
        lines.push(join_capture(
            request, job, &dir, &names, settings, inputs, observer,
        )?);
    }
    for (line, job) in lines.iter().zip(jobs) {
        observer.note(&format!(
            "{line}; results in {}",
            request.output.join(&job.name).display()
        ));
    }
    Ok(())
}

/// Writes one capture's reports and manifest from its parts, then deletes the parts.
#[allow(clippy::too_many_arguments)]
fn join_capture(
    request: &RunRequest,
    job: &Job,
    dir: &Path,
    names: &[String],
    settings: &serde_json::Value,
    inputs: &[&Path],
    observer: &dyn Observer,
) -> Result<String> {
    // Parts are read one at a time (memory bounded by a chunk), first for the totals and
    // the files, then for each report.
    let read = |name: &String| -> Result<Part> {
        match read_part(&dir.join(name)) {
            Some(Ok(p)) => Ok(p),
            _ => bail!(
                "{}: the part changed during the merge",
                dir.join(name).display()
            ),
        }
    };
    let mut noise = NoiseSummary::default();
    let mut stages = StageCounts::default();
    let mut frames = 0usize;
    let mut listed = std::collections::BTreeSet::new();
    for name in names {
        let p = read(name)?;
        let n = p
            .totals
            .noise()
            .ok_or_else(|| anyhow::anyhow!("{}: malformed totals", dir.join(name).display()))?;
        noise.merge(&n);
        stages.merge(&p.totals.stages);
        frames += p.frames;
        listed.extend(p.files);
    }
    // Frame files of other runs (another --frames, say) would end up in the manifest.
    let reports = ["summary.json", "clusters.json", "clusters.csv"];
    let stale: Vec<String> = staging::result_files(dir)
        .into_iter()
        .filter(|f| {
            !listed.contains(f) && part_chunk_size(f).is_none() && !reports.contains(&f.as_str())
        })
        .collect();
    if !stale.is_empty() {
        if !request.force {
            let shown: Vec<&str> = stale.iter().take(5).map(String::as_str).collect();
            return Err(anyhow::Error::new(Refused(format!(
                "{}: holds {} file{} no part of this run wrote ({}{}); rerun the merge with \
                 --force to delete them, or choose another output folder",
                dir.display(),
                stale.len(),
                if stale.len() == 1 { "" } else { "s" },
                shown.join(", "),
                if stale.len() > 5 { ", ..." } else { "" }
            ))));
        }
        staging::remove_results(dir, &stale, &|_| false);
    }
    // The capture summary covers every packet a run reads: decode without processing.
    let plan = &job.plan;
    let mut reader = job.open(None)?;
    reader.source_mut().count_rest(&plan.frames)?;
    let capture_summary;
    let source_summary = match &reader {
        CaptureFrames::Hdl32e(r) => {
            capture_summary = r.summary();
            super::inputs::warn_truncation(observer, Path::new(&job.shown()), &capture_summary);
            super::inputs::warn_capture(
                observer,
                Path::new(&job.shown()),
                &capture_summary,
                plan.config.sensor.intensity == crate::config::IntensityMode::Reflectivity,
            );
            super::reports::SourceSummary::Capture(&capture_summary)
        }
        CaptureFrames::Model(r) => {
            let duplicates = r.summary().duplicate_packets;
            super::inputs::warn_duplicates(observer, Path::new(&job.shown()), duplicates);
            super::reports::SourceSummary::Model(r.summary())
        }
    };
    let totals = Totals {
        ground_fraction: stages.ground_fraction(),
        noise,
        stages,
    };
    let (summary, clusters) = super::reports::documents(plan, &job.source, source_summary, totals);
    let pieces = |field: fn(&Part) -> &str, out: &mut dyn std::io::Write| -> std::io::Result<()> {
        for (j, name) in names.iter().enumerate() {
            let p = read(name).map_err(std::io::Error::other)?;
            if j > 0 {
                out.write_all(b",\n")?;
            }
            out.write_all(field(&p).as_bytes())?;
        }
        Ok(())
    };
    super::spool::join_with(&summary, &dir.join("summary.json"), inputs, |out| {
        pieces(|p| &p.summary_frames, out)
    })?;
    super::spool::join_with(&clusters, &dir.join("clusters.json"), inputs, |out| {
        pieces(|p| &p.cluster_frames, out)
    })?;
    crate::writers::atomic::write_atomically(&dir.join("clusters.csv"), inputs, |out| {
        for (j, name) in names.iter().enumerate() {
            let p = read(name).map_err(std::io::Error::other)?;
            let csv = p.csv.as_bytes();
            // One header line for the whole table.
            let start = if j == 0 {
                0
            } else {
                csv.iter()
                    .position(|&b| b == b'\n')
                    .map_or(csv.len(), |i| i + 1)
            };
            out.write_all(&csv[start..])?;
        }
        Ok(())
    })?;
    // The manifest lists the results as one run's; the parts go only after it is written
    // (a merge killed in between is redone from them).
    let files: Vec<String> = staging::result_files(dir)
        .into_iter()
        .filter(|f| part_chunk_size(f).is_none())
        .collect();
    staging::write_manifest(dir, "run", settings, files)?;
    for name in names {
        std::fs::remove_file(dir.join(name)).ok();
    }
    Ok(super::reports::report_line(
        &job.shown(),
        frames,
        &summary.totals,
    ))
}
