//! Execution of a sweep: cells x frames in parallel, one result file per cell, resumable.
//!
//! Each capture is decoded in batches of frames; a batch is shared by every cell being
//! computed, and the clean baseline of each frame is computed once per distinct baseline
//! configuration (the cell configuration without noise stages, seed included, since
//! ground RANSAC draws from the seed) and reused by every cell. Each cell's per-frame
//! metrics go to `DIR/cells/<capture>/<cell>.json`, written atomically with the settings
//! that produced them; a later run loads a cell whose file records the same settings
//! instead of computing it again. The tables are always rebuilt from the cell files.

use super::plan::{BaseConfig, Cell, Vary};
use super::progress::Progress;
use crate::config::Config;
use crate::error::{Error, Result};
use crate::frame::Frame;
use crate::frame::FrameSource;
use crate::observe::Observer;
use crate::pipeline::{FrameResult, Pipeline};
use crate::score::metrics::{self, ClassMetrics, FrameMetrics, MatchRule, ReturnState, Tally};
use crate::sensor::frames::CaptureFrames;
use crate::sensor::frames::CaptureSeek;
use crate::sensor::frames::DecoderOptions;
use crate::sensor::SensorModel;
use crate::shard::{self, Batch, Shard};
use crate::synth::labels::{check_frame, read_labels_file, LabelRow, LabelRows};
use rayon::prelude::*;
use serde::Serialize;
use std::collections::{BTreeMap, HashMap};
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

use super::stream::{self, CHECKSUM_PLACEHOLDER};

/// The baseline of one frame, reduced to what the metrics need.
struct Reference {
    /// Cluster id per clean return (-1 for none).
    labels: Vec<i32>,
    /// Object cluster id per clean return (-1 for none and for non-object clusters).
    objects: Vec<i32>,
    kept: u64,
    clusters: u64,
    object_clusters: u64,
    /// Horizontal centroid distance of each object cluster.
    distance: BTreeMap<i32, f64>,
}

/// Ground truth of one frame, per clean return.
struct Truth {
    ground: Vec<bool>,
    objects: Vec<i32>,
}

/// Ground-truth labels of a capture: where its rows come from and object classes by id.
struct Labels {
    rows: LabelSource,
    classes: BTreeMap<i32, String>,
}

/// The label rows of a capture's frames.
enum LabelSource {
    /// A file in frame order (as the synthesizer writes it: capture order), read again
    /// a frame at a time by every pass over the capture: memory does not grow with it.
    InOrder(PathBuf),
    /// Rows of a file not in frame order, grouped by frame (held whole).
    Grouped(HashMap<u32, Vec<LabelRow>>),
}

impl Labels {
    /// Reads (checks) the labels file `path`; its rows are held only when they are not
    /// in frame order.
    fn open(path: &Path) -> Result<Labels> {
        let file = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
        let mut last = 0u32;
        let mut in_order = true;
        for row in LabelRows::new(file, path)? {
            let row = row?;
            in_order &= row.frame >= last;
            last = row.frame;
        }
        let rows = if in_order {
            LabelSource::InOrder(path.to_path_buf())
        } else {
            LabelSource::Grouped(group_labels(read_labels_file(path)?))
        };
        Ok(Labels {
            rows,
            classes: read_classes(path)?,
        })
    }

    /// A reader of the rows of frames asked for in increasing order.
    fn cursor(&self) -> Result<LabelCursor<'_>> {
        Ok(match &self.rows {
            LabelSource::InOrder(path) => {
                let file = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
                LabelCursor::Stream {
                    rows: LabelRows::new(file, path)?,
                    next: None,
                }
            }
            LabelSource::Grouped(frames) => LabelCursor::Grouped(frames),
        })
    }
}

/// The label rows of one frame after another (see [`Labels::cursor`]).
enum LabelCursor<'a> {
    Stream {
        rows: LabelRows<'static>,
        /// The first row of a later frame, read ahead.
        next: Option<LabelRow>,
    },
    Grouped(&'a HashMap<u32, Vec<LabelRow>>),
}

impl LabelCursor<'_> {
    /// The rows of frame `index` (frames asked for in increasing order).
    fn frame(&mut self, index: u32) -> Result<Vec<LabelRow>> {
        match self {
            LabelCursor::Grouped(frames) => Ok(frames.get(&index).cloned().unwrap_or_default()),
            LabelCursor::Stream { rows, next } => {
                let mut out = Vec::new();
                loop {
                    let row = match next.take() {
                        Some(r) => r,
                        None => match rows.next() {
                            Some(r) => r?,
                            None => return Ok(out),
                        },
                    };
                    if row.frame > index {
                        *next = Some(row);
                        return Ok(out);
                    }
                    if row.frame == index {
                        out.push(row);
                    }
                }
            }
        }
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

/// Joins a cell's parts (which must all verify) in frame order into the cell file a sweep
/// without chunks writes, then deletes the parts (only exclusive runs join: no shard is
/// writing them). The frames are joined as text: parsing and writing the metrics again
/// could change the last digit of a float (serde_json's default parser is not exact).
fn join_parts(
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

/// Hashes of the capture's, labels' and calibration's content and the tool version: a
/// cell computed from other data (same name and size included) is not reused.
fn content_key(s: &SweepSettings, capture: &CaptureInput) -> Result<serde_json::Value> {
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

fn cell_settings(
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
fn read_cell(path: &Path) -> Option<std::result::Result<stream::CellHead, String>> {
    stream::scan_cell(path, &mut |_| ())
}

/// A cell file written a frame at a time, in the layout of `serde_json::to_vec_pretty`
/// of a [`CellFile`] and a line break, its checksum computed as the bytes go; it appears
/// at its path only once committed.
struct CellWriter {
    array: stream::ArrayWriter<crate::writers::atomic::AtomicFile>,
    path: PathBuf,
}

impl CellWriter {
    /// Buffer of each cell file: the cells of a batch are written side by side.
    const BUFFER_BYTES: usize = 64 << 10;

    fn create(path: &Path, settings: &serde_json::Value, protected: &[&Path]) -> Result<Self> {
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

    fn push(&mut self, m: &FrameMetrics) -> Result<()> {
        self.array.push(m).map_err(|e| Error::io(&self.path, e))
    }

    fn push_indented(&mut self, text: &str, n: u64) -> Result<()> {
        self.array
            .push_indented(text, n)
            .map_err(|e| Error::io(&self.path, e))
    }

    /// Writes the checksum (of the bytes with it written as zeros) and renames the file
    /// into place.
    fn commit(self) -> Result<()> {
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

fn group_labels(rows: Vec<LabelRow>) -> HashMap<u32, Vec<LabelRow>> {
    let mut out: HashMap<u32, Vec<LabelRow>> = HashMap::new();
    for r in rows {
        out.entry(r.frame).or_default().push(r);
    }
    out
}

/// Object classes (`kind` by `id`) of `<name>.objects.json` beside `<name>.labels.csv.gz`;
/// empty when there is no such file.
fn read_classes(labels: &Path) -> Result<BTreeMap<i32, String>> {
    let name = labels.file_name().unwrap_or_default().to_string_lossy();
    let Some(stem) = name.split(".labels.").next().filter(|s| *s != name) else {
        return Ok(BTreeMap::new());
    };
    let path = labels.with_file_name(format!("{stem}.objects.json"));
    let Ok(text) = std::fs::read(&path) else {
        return Ok(BTreeMap::new());
    };
    let value: serde_json::Value = serde_json::from_slice(&text)
        .map_err(|e| Error::Invalid(format!("{}: {e}", path.display())))?;
    let mut out = BTreeMap::new();
    for o in value["objects"].as_array().map_or(&[][..], Vec::as_slice) {
        if let (Some(id), Some(kind)) = (o["id"].as_i64(), o["kind"].as_str()) {
            out.insert(id as i32, kind.to_string());
        }
    }
    Ok(out)
}

fn truth_of(frame: &Frame, rows: &[LabelRow], origin: &Path) -> Result<Truth> {
    check_frame(rows, frame, origin)?;
    Ok(Truth {
        ground: rows.iter().map(|l| l.label == 0).collect(),
        objects: rows
            .iter()
            .map(|l| if l.label == 0 { -1 } else { i32::from(l.label) })
            .collect(),
    })
}

/// Cluster id of every clean return (-1 when dropped, ground or noise).
/// Cluster id per recorded return (-1: none). A spurious echo (replaced or added) is no
/// recorded return: it gets no label, so it never counts for an object.
fn labels_per_clean(r: &FrameResult) -> Vec<i32> {
    let mut out = vec![-1; r.noisy.clean_len];
    for (&k, &l) in r.kept.iter().zip(&r.labels) {
        if r.noisy.fate[k as usize] == crate::noise::Fate::Kept {
            out[k as usize] = l;
        }
    }
    out
}

/// Object clusters made of spurious echoes only: false clusters no recorded return shows.
fn spurious_object_clusters(r: &FrameResult) -> u64 {
    let mut real = std::collections::BTreeSet::new();
    let mut any = std::collections::BTreeSet::new();
    for (&k, &l) in r.kept.iter().zip(&r.labels) {
        if l >= 0 {
            any.insert(l);
            if r.noisy.fate[k as usize] == crate::noise::Fate::Kept {
                real.insert(l);
            }
        }
    }
    r.clusters
        .iter()
        .filter(|c| c.object && any.contains(&c.id) && !real.contains(&c.id))
        .count() as u64
}

/// `labels` (cluster id per clean return) with every cluster that is not an object set
/// to -1.
fn object_labels(r: &FrameResult, labels: &[i32]) -> Vec<i32> {
    // Cluster ids are 0..n in id order, so a dense lookup is enough.
    let len = r
        .clusters
        .iter()
        .map(|c| c.id + 1)
        .max()
        .unwrap_or(0)
        .max(0) as usize;
    let mut object = vec![false; len];
    for c in r.clusters.iter().filter(|c| c.object && c.id >= 0) {
        object[c.id as usize] = true;
    }
    labels
        .iter()
        .map(|&l| {
            if l >= 0 && object.get(l as usize).copied().unwrap_or(false) {
                l
            } else {
                -1
            }
        })
        .collect()
}

fn reference_of(r: &FrameResult) -> Reference {
    let labels = labels_per_clean(r);
    let objects = object_labels(r, &labels);
    Reference {
        labels,
        objects,
        kept: r.counts.kept,
        clusters: r.clusters.len() as u64,
        object_clusters: r.counts.objects,
        distance: r
            .clusters
            .iter()
            .filter(|c| c.object)
            .map(|c| (c.id, c.centroid[0].hypot(c.centroid[1])))
            .collect(),
    }
}

fn frame_metrics(
    r: &FrameResult,
    reference: &Reference,
    truth: Option<&Truth>,
    classes: &BTreeMap<i32, String>,
    min_points: usize,
    bands: &[f64],
) -> FrameMetrics {
    use crate::noise::Fate;
    let count = |f: Fate| r.noisy.fate.iter().filter(|&&x| x == f).count() as u64;
    let change = metrics::range_change(
        r.kept
            .iter()
            .filter(|&&k| r.noisy.fate[k as usize] == Fate::Kept)
            .map(|&k| (r.noisy.clean[k as usize].range, r.noisy.range[k as usize])),
    );
    let noisy = labels_per_clean(r);
    let rule = MatchRule::default();
    // IoU survival of the baseline's object clusters.
    let m = metrics::match_objects(&reference.objects, &noisy, rule);
    // Clutter: noisy object clusters that come from no baseline cluster at all.
    let noisy_objects = object_labels(r, &noisy);
    let clutter = metrics::match_objects(&reference.labels, &noisy_objects, rule);
    let farthest = |ids: &mut dyn Iterator<Item = i32>| {
        ids.filter_map(|id| reference.distance.get(&id).copied())
            .max_by(f64::total_cmp)
    };
    // Per clean return: reached, method ground, noisy cluster, clean position.
    let mut states: Vec<ReturnState> = r
        .noisy
        .clean
        .iter()
        .zip(&noisy)
        .map(|(c, &n)| ReturnState {
            object: -1,
            reached: false,
            ground: false,
            cluster: n,
            xy: [c.x, c.y],
        })
        .collect();
    for (&k, &g) in r.kept.iter().zip(&r.ground) {
        // Only recorded returns the sensor still reports reach an object; echoes do not.
        if r.noisy.fate[k as usize] == Fate::Kept {
            states[k as usize].reached = true;
            states[k as usize].ground = g;
        }
    }
    let object_ids = truth.map_or(&reference.objects, |t| &t.objects);
    for (s, &o) in states.iter_mut().zip(object_ids) {
        s.object = o;
    }
    let results = metrics::object_outcomes(&states, min_points);
    let whole = Tally::of(&results);
    let mut out = FrameMetrics {
        frame: r.noisy.index,
        returns: r.noisy.len() as u64,
        kept: r.counts.kept,
        baseline_kept: reference.kept,
        occluded: count(Fate::Occluded),
        below_power: count(Fate::BelowPower),
        below_min_range: count(Fate::BelowMinRange),
        range_change_mean_m: change.mean,
        range_change_rms_m: change.rms,
        range_change_p95_m: change.p95_abs,
        clusters: r.clusters.len() as u64,
        object_clusters: r.counts.objects,
        baseline_clusters: reference.clusters,
        baseline_object_clusters: reference.object_clusters,
        matched: m.matched() as u64,
        object_survival: m.survival(),
        false_clusters: clutter.false_clusters as u64 + spurious_object_clusters(r),
        farthest_matched_m: farthest(&mut m.pairs.iter().map(|p| p.0)),
        baseline_farthest_m: farthest(&mut reference.distance.keys().copied()),
        labelled: truth.is_some(),
        objects: whole.objects,
        detected: whole.detected,
        retained: whole.retained,
        split: whole.split,
        merged: whole.merged,
        merged_into_ground: whole.merged_into_ground,
        lost: whole.lost,
        bands: metrics::band_metrics(&results, bands),
        ..FrameMetrics::default()
    };
    if let Some(t) = truth {
        // Ground precision and recall over the returns that reach ground removal; the
        // ground returns dropped before it are reported on their own.
        // A spurious echo is never ground in truth (it is no recorded return).
        let truth_reached: Vec<bool> = r
            .kept
            .iter()
            .map(|&k| r.noisy.fate[k as usize] == Fate::Kept && t.ground[k as usize])
            .collect();
        (out.ground_precision, out.ground_recall) =
            metrics::precision_recall(&truth_reached, &r.ground);
        let ground_total = t.ground.iter().filter(|&&g| g).count();
        let ground_reached = truth_reached.iter().filter(|&&g| g).count();
        out.ground_lost_before_share = (ground_total > 0)
            .then(|| (ground_total - ground_reached) as f64 / ground_total as f64);
        let mut by_class: BTreeMap<&str, Tally> = BTreeMap::new();
        for o in &results {
            if let Some(kind) = classes.get(&o.id) {
                by_class.entry(kind).or_default().add(o);
            }
        }
        out.classes = by_class
            .into_iter()
            .map(|(kind, counts)| ClassMetrics {
                kind: kind.to_string(),
                counts,
            })
            .collect();
    }
    out
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

/// One panel of the bird's-eye figure: a configuration's result on one frame.
#[derive(Clone, Debug)]
pub struct Panel {
    /// Title, e.g. "rain only".
    pub title: String,
    /// Survivor x, y (metres) and class: -2 ground, -1 noise, k cluster id.
    pub points: Vec<(f32, f32, i32)>,
    /// Clusters found.
    pub clusters: usize,
    /// The noise stages applied, one "type: settings" line each, in chain order.
    pub stages: Vec<String>,
}

/// Runs one frame through the clean configuration, each stage type of the base alone, and
/// all of them (the reference study's figure 3 for occlusion and rain).
pub fn birdseye_panels(
    base: &BaseConfig,
    seed: u64,
    frame: &Frame,
    lasers: usize,
) -> Result<Vec<Panel>> {
    let mut types: Vec<&str> = Vec::new();
    for s in &base.config.noise {
        if !types.contains(&s.kind()) {
            types.push(s.kind());
        }
    }
    let mut variants: Vec<(String, Vec<&str>)> = vec![("clean".into(), Vec::new())];
    for t in &types {
        variants.push((format!("{t} only"), vec![t]));
    }
    if types.len() >= 2 {
        variants.push((types.join(" + "), types.clone()));
    }
    variants
        .par_iter()
        .map(|(title, kinds)| {
            let config = base.only_stages(kinds, seed)?;
            let pipeline = Pipeline::new(&config)
                .for_lasers(lasers)
                .map_err(Error::Invalid)?;
            let r = pipeline.process(frame.clone())?;
            let points = r
                .survivors
                .iter()
                .zip(&r.ground)
                .zip(&r.labels)
                .map(|((p, &g), &l)| (p.x, p.y, if g { -2 } else { l }))
                .collect();
            Ok(Panel {
                title: title.clone(),
                points,
                clusters: r.clusters.len(),
                stages: config
                    .noise
                    .iter()
                    .map(|s| format!("{}: {}", s.kind(), s.describe()))
                    .collect(),
            })
        })
        .collect()
}

/// Decodes the frame with index `index` of a capture (the first in `frames` when `None`),
/// with its sensor's number of lasers.
pub fn read_frame(
    path: &Path,
    decoder: &DecoderOptions,
    frames: &RangeInclusive<u32>,
    index: Option<u32>,
) -> Result<Option<(Frame, usize)>> {
    let (mut reader, lasers): (Box<dyn FrameSource>, usize) =
        match crate::sensor::frames::open_capture(path, decoder)? {
            CaptureFrames::Hdl32e(r) => (r, crate::sensor::HDL32E.lasers),
            CaptureFrames::Model(r) => {
                let lasers = r.model().lasers;
                (r, lasers)
            }
        };
    let everything = 0..=u32::MAX;
    loop {
        let batch = reader.next_batch(16, &everything)?;
        if batch.is_empty() {
            return Ok(None);
        }
        for frame in batch {
            let wanted = match index {
                Some(i) => frame.index == i,
                None => frames.contains(&frame.index),
            };
            if wanted {
                return Ok(Some((frame, lasers)));
            }
        }
    }
}
