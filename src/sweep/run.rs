//! Execution of a sweep: cells x frames in parallel, one result file per cell, resumable.
//!
//! Each capture is decoded in batches of frames; a batch is shared by every cell being
//! computed, and the clean baseline of each frame is computed once per distinct baseline
//! configuration (the cell configuration without noise stages, seed included, since
//! ground RANSAC draws from the seed) and reused by every cell. Each cell's per-frame
//! metrics go to `DIR/cells/<capture>/<cell>.json`, written atomically with the settings
//! that produced them; a later run loads a cell whose file records the same settings
//! instead of computing it again. The tables are always rebuilt from the cell files.

use super::cells::{cell_settings, content_key, join_parts, read_cell, CellWriter};
use super::labels::{truth_of, Labels, Truth};
use super::plan::{BaseConfig, Cell, Vary};
use super::progress::Progress;
use super::reference::{frame_metrics, reference_of, Reference};
use super::stream;
use crate::config::Config;
use crate::error::{Error, Result};
use crate::frame::FrameSource;
use crate::observe::Observer;
use crate::pipeline::Pipeline;
use crate::score::metrics::FrameMetrics;
use crate::sensor::frames::CaptureFrames;
use crate::sensor::frames::CaptureSeek;
use crate::sensor::frames::DecoderOptions;
use crate::sensor::SensorModel;
use crate::shard::{self, Batch, Shard};
use rayon::prelude::*;
use std::collections::BTreeMap;
use std::ops::RangeInclusive;
use std::path::{Path, PathBuf};

/// Version of the metric definitions; a change makes old cell files stale.
pub const METRICS_VERSION: u32 = 2;

/// One capture of a sweep.
#[derive(Clone, Debug)]
pub struct CaptureInput {
    /// Name in outputs (unique within the sweep; the file stem by default).
    pub name: String,
    /// The pcap or pcapng file.
    pub path: PathBuf,
    /// Ground-truth labels of a synthesized capture, if any.
    pub labels: Option<PathBuf>,
}

/// Everything a sweep needs.
#[derive(Clone, Debug)]
pub struct SweepSettings {
    /// The base configuration.
    pub base: BaseConfig,
    /// The varied keys.
    pub varies: Vec<Vary>,
    /// The seeds.
    pub seeds: Vec<u64>,
    /// Decoder settings.
    pub decoder: DecoderOptions,
    /// Frames to process, by index.
    pub frames: RangeInclusive<u32>,
    /// Output folder.
    pub output: PathBuf,
    /// Distance band edges in metres, ascending (see [`metrics::band_index`]).
    pub bands: Vec<f64>,
    /// Frames per chunk (`--chunk-frames`): units become (cell, chunk), see
    /// [`crate::shard`].
    pub chunk_frames: Option<u32>,
}

/// One row of the tidy table: a frame of a cell of a capture.
#[derive(Clone, Debug, PartialEq)]
pub struct Row {
    /// Capture name.
    pub capture: String,
    /// Varied values, in `--vary` order.
    pub values: Vec<String>,
    /// Seed.
    pub seed: u64,
    /// The metrics.
    pub metrics: FrameMetrics,
}

/// What a sweep did.
#[derive(Clone, Debug, Default)]
pub struct Outcome {
    /// Cells computed in this run.
    pub computed: usize,
    /// Cells loaded from earlier runs.
    pub loaded: usize,
    /// Every row, read back from the cell files (a frame at a time) in canonical order.
    pub rows: CellRows,
    /// Units (cells, or cells x chunks) of the whole sweep.
    pub total: usize,
    /// Units that fall to this call (all but for a shard, none for a merge).
    pub owned: usize,
}

/// The rows of a sweep, each time they are asked for read again from its cell files a
/// frame at a time: memory does not grow with the frames (issue 30).
#[derive(Clone, Debug, Default)]
pub struct CellRows {
    /// Capture name, varied values, seed and file of each cell, in canonical order.
    cells: Vec<(String, Vec<String>, u64, PathBuf)>,
    /// Rows (frames) of all the cells.
    rows: usize,
}

impl CellRows {
    /// Number of rows.
    pub fn len(&self) -> usize {
        self.rows
    }

    /// True without rows.
    pub fn is_empty(&self) -> bool {
        self.rows == 0
    }
}

/// Rows given one at a time, in canonical order: read from the cell files
/// ([`CellRows`]) or held in memory (a slice of rows, for tests).
pub trait Rows {
    /// Calls `f` with every row in order.
    fn each(&self, f: &mut dyn FnMut(&Row)) -> Result<()>;
}

impl Rows for CellRows {
    fn each(&self, f: &mut dyn FnMut(&Row)) -> Result<()> {
        for (capture, values, seed, path) in &self.cells {
            let mut row = Row {
                capture: capture.clone(),
                values: values.clone(),
                seed: *seed,
                metrics: FrameMetrics::default(),
            };
            let read = stream::scan_cell(path, &mut |m| {
                row.metrics = m;
                f(&row);
            });
            if !matches!(read, Some(Ok(_))) {
                return Err(Error::Invalid(format!(
                    "{}: cell result missing or unreadable",
                    path.display()
                )));
            }
        }
        Ok(())
    }
}

impl Rows for [Row] {
    fn each(&self, f: &mut dyn FnMut(&Row)) -> Result<()> {
        self.iter().for_each(f);
        Ok(())
    }
}

impl Rows for Vec<Row> {
    fn each(&self, f: &mut dyn FnMut(&Row)) -> Result<()> {
        self.as_slice().each(f)
    }
}

/// Which cells a call computes and whether it reads the rows back.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Mode {
    /// Every cell not done yet; every row is read back.
    All,
    /// Only the cells (or cell parts, see [`crate::shard`]) that fall to this shard (see
    /// [`crate::shard::unit_index`]); no rows.
    Shard(Shard),
    /// No cell is computed: every cell must be done (else an error lists the missing).
    Merge,
}

/// Index of cell `cell` (in [`super::plan::cells`] order) of capture `capture` in the
/// sweep's list of cells, which `--shard K/N` deals round-robin.
pub fn shard_index(capture: usize, cell: usize, cells_per_capture: usize) -> usize {
    capture * cells_per_capture + cell
}

/// Runs (or resumes) the sweep and returns every row; progress and warnings go to
/// `observer`.
pub fn run(
    s: &SweepSettings,
    captures: &[CaptureInput],
    observer: &dyn Observer,
) -> Result<Outcome> {
    run_mode(s, captures, observer, Mode::All)
}

/// [`run`] restricted to a shard's cells (no rows), or a merge that computes nothing.
pub fn run_mode(
    s: &SweepSettings,
    captures: &[CaptureInput],
    observer: &dyn Observer,
    mode: Mode,
) -> Result<Outcome> {
    let total = super::plan::cells(&s.varies, &s.seeds).len() * captures.len();
    let own = match mode {
        Mode::Shard(shard) => (0..total).filter(|&i| shard.owns(i)).count(),
        Mode::All | Mode::Merge => total,
    };
    let progress = Progress::start(observer, s.chunk_frames.is_some(), own as u64);
    let outcome = compute(s, captures, &progress, mode);
    progress.finish();
    outcome
}

/// [`run_mode`] reporting to `observer`.
fn compute(
    s: &SweepSettings,
    captures: &[CaptureInput],
    observer: &Progress,
    mode: Mode,
) -> Result<Outcome> {
    let mut outcome = Outcome::default();
    let canonical = canonical_cells(s);
    let mut missing = Vec::new();
    // Units (cells, or cells x chunks) of the captures before this one.
    let mut offset = 0usize;
    for capture in captures {
        let dir = s.output.join("cells").join(&capture.name);
        std::fs::create_dir_all(&dir).map_err(|e| Error::io(&dir, e))?;
        shard::check_parts(&dir, s.chunk_frames, Batch::Sweep)?;
        let protected = protected_paths(capture);
        let protected: Vec<&Path> = protected.iter().map(PathBuf::as_path).collect();
        // With --chunk-frames, the frames are counted first (decoding only) so that the
        // list of units, and so the deal of the shards, is known before any work; the
        // scan tells the sensor too.
        let mut expected_frames = None;
        let mut seeks = Vec::new();
        let (sensor, ranges) = match s.chunk_frames {
            Some(m) => {
                let (sensor, (ranges, at, n)) = chunk_ranges(s, &capture.path, m)?;
                expected_frames = Some(n);
                seeks = at;
                (sensor, Some(ranges))
            }
            None => (capture_sensor(s, capture)?, None),
        };
        // Cells are keyed on the content of every input, not on names and sizes.
        let content = content_key(s, capture)?;
        let n_chunks = ranges.as_ref().map_or(1, Vec::len);
        // Execution order: seeds outermost so cells sharing a baseline run together.
        // Pending units by chunk (one group without chunks), each group sharing decoding.
        let mut pending: BTreeMap<usize, Vec<Pending>> = BTreeMap::new();
        // Cells whose parts are all there and verify, to be joined.
        let mut joins: Vec<(PathBuf, serde_json::Value, Vec<PathBuf>)> = Vec::new();
        let mut loaded = 0usize;
        let all_cells = super::plan::cells(&s.varies, &s.seeds);
        let per_capture = all_cells.len();
        for (cell_index, cell) in all_cells.into_iter().enumerate() {
            let owned: Vec<usize> = (0..n_chunks)
                .filter(|&j| {
                    let i = shard::unit_index(offset, cell_index, j, n_chunks);
                    outcome.total += 1;
                    match mode {
                        Mode::Shard(shard) => shard.owns(i),
                        Mode::All => true,
                        Mode::Merge => false,
                    }
                })
                .collect();
            outcome.owned += owned.len();
            if owned.is_empty() && mode != Mode::Merge {
                continue;
            }
            let config = s.base.cell_config(&s.varies, &cell)?;
            // Per-laser options must fit the capture's sensor (`occlusion` lasers = [40]
            // would select nothing on an HDL-32E).
            let pipeline = Pipeline::new(&config).for_sensor(sensor).map_err(|e| {
                Error::Invalid(format!(
                    "{}: {}: the {} ({} lasers): {e}",
                    capture.path.display(),
                    cell.file_name(&s.varies),
                    sensor.name,
                    sensor.lasers
                ))
            })?;
            let mut baseline = config.clone();
            baseline.noise.clear();
            // Without noise stages only RANSAC ground draws random numbers: otherwise the
            // baseline is the same for every seed and is computed once.
            let baseline_key = if baseline.ground.method == crate::ground::GroundMethod::Ransac {
                baseline.effective_toml()
            } else {
                let mut unseeded = baseline.clone();
                unseeded.seed = 0;
                unseeded.effective_toml()
            };
            let settings = cell_settings(s, capture, &content, &cell, &config, &baseline);
            let file_name = cell.file_name(&s.varies);
            let path = dir.join(&file_name);
            match read_cell(&path) {
                Some(Ok(f)) if f.settings == settings => {
                    let expected = match expected_frames {
                        Some(n) => n,
                        None => {
                            let n = count_frames(s, capture)?;
                            expected_frames = Some(n);
                            n
                        }
                    };
                    if f.frames == expected {
                        loaded += 1;
                        continue;
                    }
                    observer.warn(&format!(
                        "{}: the cell has {} frames where its settings give {expected}; \
                         recomputing it",
                        path.display(),
                        f.frames
                    ));
                }
                Some(Err(why)) => {
                    observer.warn(&format!("{}: {why}; recomputing the cell", path.display()))
                }
                _ => {}
            }
            let (Some(m), Some(ranges)) = (s.chunk_frames, &ranges) else {
                if mode == Mode::Merge {
                    missing.push(path.display().to_string());
                    continue;
                }
                pending.entry(0).or_default().push(Pending {
                    path,
                    settings,
                    pipeline,
                    baseline_key,
                    baseline,
                    lasers: sensor.lasers,
                    min_points: config.cluster.min_points,
                });
                continue;
            };
            let parts = shard::part_paths(&dir, &file_name, m, n_chunks);
            let mut complete = true;
            for (j, part) in parts.iter().enumerate() {
                let part_settings = shard::part_settings(&settings, m, j, n_chunks, &ranges[j]);
                let want = (ranges[j].clone(), part_settings);
                let done = match read_cell(part) {
                    Some(Ok(f)) if f.settings == want.1 => {
                        // The part holds exactly its chunk's frames, in order.
                        f.frames <= m as usize
                            && f.first == Some(*want.0.start())
                            && f.last == Some(*want.0.end())
                    }
                    Some(Err(why)) => {
                        observer.warn(&format!("{}: {why}; recomputing it", part.display()));
                        false
                    }
                    _ => false,
                };
                if done {
                    continue;
                }
                complete = false;
                if mode == Mode::Merge {
                    missing.push(part.display().to_string());
                } else if owned.contains(&j) {
                    pending.entry(j).or_default().push(Pending {
                        path: part.clone(),
                        settings: want.1,
                        pipeline: pipeline.clone(),
                        baseline_key: baseline_key.clone(),
                        baseline: baseline.clone(),
                        lasers: sensor.lasers,
                        min_points: config.cluster.min_points,
                    });
                }
            }
            if complete || mode == Mode::All {
                joins.push((path, settings, parts));
            }
        }
        offset += per_capture * n_chunks;
        if mode == Mode::Merge && !missing.is_empty() {
            continue;
        }
        let n_pending: usize = pending.values().map(Vec::len).sum();
        observer.capture(&capture.name, n_pending as u64);
        for _ in 0..loaded {
            observer.cell_done();
        }
        outcome.loaded += loaded;
        if n_pending > 0 {
            let truth = match &capture.labels {
                Some(p) => Some(Labels::open(p)?),
                None => None,
            };
            let chunk = (4 * rayon::current_num_threads()).max(8);
            let mut first = true;
            if ranges.is_none() {
                // The frames every pending cell will run are counted from the frame index
                // (no decoding) before any work, so a progress bar knows its total from
                // the start instead of after the first batch of cells.
                let n = match expected_frames {
                    Some(n) => n,
                    None => count_frames(s, capture)?,
                };
                if n > 0 {
                    observer.frames_total(n as u64);
                    first = false;
                }
            }
            for (j, units) in &pending {
                // A chunk's units read only the chunk's frames, from where the chunk starts.
                let mut range = s.clone();
                if let Some(r) = &ranges {
                    range.frames = r[*j].clone();
                }
                for cells in units.chunks(chunk) {
                    compute_chunk(
                        &range,
                        capture,
                        seeks.get(*j),
                        cells,
                        truth.as_ref(),
                        &protected,
                        observer,
                        &mut first,
                    )?;
                }
            }
        }
        outcome.computed += n_pending;
        if matches!(mode, Mode::Shard(_)) {
            continue;
        }
        for (path, settings, parts) in joins {
            join_parts(&path, settings, &parts, &protected)?;
        }
        for cell in &canonical {
            let path = dir.join(cell.file_name(&s.varies));
            // Checked here, read again a frame at a time when the tables are written.
            let Some(Ok(head)) = read_cell(&path) else {
                return Err(Error::Invalid(format!(
                    "{}: cell result missing or unreadable",
                    path.display()
                )));
            };
            outcome.rows.rows += head.frames;
            outcome
                .rows
                .cells
                .push((capture.name.clone(), cell.values.clone(), cell.seed, path));
        }
    }
    if !missing.is_empty() {
        let n = missing.len();
        let what = if s.chunk_frames.is_some() {
            "cell part"
        } else {
            "cell"
        };
        return Err(Error::Invalid(format!(
            "sweep --merge: {n} {what}{} missing, unfinished or computed with other settings \
             (run the shards that own them, or rerun without --merge to compute them here): \
             {}",
            if n == 1 { " is" } else { "s are" },
            crate::error::first_ten(&missing),
        )));
    }
    Ok(outcome)
}

/// Cells in table order: `--vary` values (first key slowest), then seed.
pub fn canonical_cells(s: &SweepSettings) -> Vec<Cell> {
    let mut cells = super::plan::cells(&s.varies, &s.seeds);
    let rank = |c: &Cell| -> Vec<usize> {
        s.varies
            .iter()
            .zip(&c.values)
            .map(|(v, x)| v.values.iter().position(|y| y == x).unwrap_or(0))
            .chain(s.seeds.iter().position(|&x| x == c.seed))
            .collect()
    };
    cells.sort_by_key(rank);
    cells
}

struct Pending {
    path: PathBuf,
    settings: serde_json::Value,
    pipeline: Pipeline,
    baseline: Config,
    /// The capture's sensor's lasers (the baseline's chain is built for them).
    lasers: usize,
    baseline_key: String,
    min_points: usize,
}

fn protected_paths(capture: &CaptureInput) -> Vec<PathBuf> {
    let mut p = vec![capture.path.clone()];
    p.extend(capture.labels.clone());
    p
}

/// The capture's sensor, the chunks of `M` frames of it within `s.frames` and where each
/// starts (see [`shard::capture_chunks`]), and the number of frames; errors when the
/// capture has no frame in range.
fn chunk_ranges(
    s: &SweepSettings,
    path: &Path,
    frames_per_chunk: u32,
) -> Result<(&'static SensorModel, shard::ChunkRanges)> {
    let (sensor, found) = shard::capture_chunks(path, &s.decoder, &s.frames, frames_per_chunk)?;
    if found.2 == 0 {
        return Err(Error::Invalid(format!(
            "{}: no frame to process in {} (partial sweeps need --keep-partial)",
            path.display(),
            crate::range::frames_phrase(&s.frames)
        )));
    }
    Ok((sensor, found))
}

/// Frames of the capture in the sweep's range: the number every cell file must hold
/// (counted from the frame index, without decoding returns).
fn count_frames(s: &SweepSettings, capture: &CaptureInput) -> Result<usize> {
    match crate::sensor::frames::open_capture(&capture.path, &s.decoder)? {
        CaptureFrames::Hdl32e(_) => {
            let scan = crate::sensor::index::FrameScan::open(&capture.path, &s.decoder)?;
            Ok(shard::chunk_plan(scan, &s.frames, s.decoder.keep_partial, u32::MAX)?.2)
        }
        // Another sensor's capture has no frame index: its frames are decoded and counted.
        CaptureFrames::Model(mut r) => r.count_rest(&s.frames),
    }
}

/// The sensor of a sweep's capture: the HDL-32E, or another described sensor told by its
/// packets' structure.
fn capture_sensor(s: &SweepSettings, capture: &CaptureInput) -> Result<&'static SensorModel> {
    Ok(
        match crate::sensor::frames::open_capture(&capture.path, &s.decoder)? {
            CaptureFrames::Hdl32e(_) => &crate::sensor::HDL32E,
            CaptureFrames::Model(r) => r.model(),
        },
    )
}

/// The frames of a capture from the start, with its sensor's reader.
fn open_frames(path: &Path, decoder: &DecoderOptions) -> Result<Box<dyn FrameSource>> {
    Ok(crate::sensor::frames::open_capture(path, decoder)?.into_source())
}

#[allow(clippy::too_many_arguments)]
fn compute_chunk(
    s: &SweepSettings,
    capture: &CaptureInput,
    seek: Option<&CaptureSeek>,
    cells: &[Pending],
    labels: Option<&Labels>,
    protected: &[&Path],
    observer: &Progress,
    first: &mut bool,
) -> Result<()> {
    let mut keys: Vec<&str> = Vec::new();
    let mut baselines: Vec<Pipeline> = Vec::new();
    let mut which = Vec::with_capacity(cells.len());
    for c in cells {
        let i = match keys.iter().position(|k| *k == c.baseline_key) {
            Some(i) => i,
            None => {
                keys.push(&c.baseline_key);
                // A baseline has no noise stage: nothing in it can misfit the lasers.
                let p = Pipeline::new(&c.baseline);
                baselines.push(p.for_lasers(c.lasers).unwrap_or(p));
                keys.len() - 1
            }
        };
        which.push(i);
    }
    let empty = BTreeMap::new();
    let classes = labels.map_or(&empty, |l| &l.classes);
    let mut reader: Box<dyn FrameSource> = match seek {
        Some(at) => {
            crate::sensor::frames::open_capture_at(&capture.path, &s.decoder, at)?.into_source()
        }
        None => open_frames(&capture.path, &s.decoder)?,
    };
    let batch_size = (2 * rayon::current_num_threads()).max(4);
    // Each cell's frames go to its file as their batch is done (kept until then only):
    // memory does not grow with the capture. Dropped uncommitted (an error), the files
    // are deleted.
    let mut files: Vec<CellWriter> = cells
        .iter()
        .map(|c| CellWriter::create(&c.path, &c.settings, protected))
        .collect::<Result<_>>()?;
    let mut n_frames = 0u64;
    let mut cursor = labels.map(Labels::cursor).transpose()?;
    loop {
        let batch = reader.next_batch(batch_size, &s.frames)?;
        if batch.is_empty() {
            break;
        }
        n_frames += batch.len() as u64;
        let truths: Vec<Option<Truth>> = match &mut cursor {
            Some(c) => batch
                .iter()
                .map(|f| {
                    truth_of(
                        f,
                        &c.frame(f.index)?,
                        capture.labels.as_deref().unwrap_or(Path::new("")),
                    )
                    .map(Some)
                })
                .collect::<Result<_>>()?,
            None => batch.iter().map(|_| None).collect(),
        };
        let refs: Vec<Reference> = (0..baselines.len() * batch.len())
            .into_par_iter()
            .map(|i| {
                let (b, f) = (i / batch.len(), i % batch.len());
                baselines[b]
                    .process(batch[f].clone())
                    .map(|r| reference_of(&r))
            })
            .collect::<Result<_>>()?;
        let rows: Vec<FrameMetrics> = (0..cells.len() * batch.len())
            .into_par_iter()
            .map(|i| {
                let (c, f) = (i / batch.len(), i % batch.len());
                let r = cells[c].pipeline.process(batch[f].clone())?;
                let reference = &refs[which[c] * batch.len() + f];
                let m = frame_metrics(
                    &r,
                    reference,
                    truths[f].as_ref(),
                    classes,
                    cells[c].min_points,
                    &s.bands,
                );
                observer.frame_done();
                Ok(m)
            })
            .collect::<Result<_>>()?;
        for (i, m) in rows.iter().enumerate() {
            files[i / batch.len()].push(m)?;
        }
    }
    if n_frames == 0 {
        return Err(Error::Invalid(format!(
            "{}: no frame to process in {} (partial sweeps need --keep-partial)",
            capture.path.display(),
            crate::range::frames_phrase(&s.frames)
        )));
    }
    if *first {
        observer.frames_total(n_frames);
        *first = false;
    }
    for file in files {
        file.commit()?;
        observer.cell_done();
    }
    Ok(())
}
