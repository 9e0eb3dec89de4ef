//! A sweep into an output folder, as one library call: the folder's lock, the checks of
//! what it holds, the manifest and the plans it grew from, the cells (see [`super::run`]),
//! the tables, plots and page (see [`super::outputs`]) committed as a whole, and the
//! clean-up of a failed first sweep. The command line and Python build a
//! [`SweepRequest`] and call [`sweep`].

use super::birdseye::{birdseye_panels, read_frame};
use super::outputs::{write_outputs, BirdsEye};
use super::plan::{BaseConfig, Vary};
use super::run::{run_mode, CaptureInput, Mode, SweepSettings};
use crate::observe::Observer;
use crate::sensor::frames::DecoderOptions;
use crate::shard::Shard;
use crate::writers::figure::FigureFormat;
use crate::writers::staging;
use anyhow::Result;
use std::collections::HashSet;
use std::ops::RangeInclusive;
use std::path::{Path, PathBuf};

/// Everything a sweep into a folder is asked to do, checked by [`sweep`].
#[derive(Clone, Debug)]
pub struct SweepRequest {
    /// Capture files (pcap or pcapng).
    pub captures: Vec<PathBuf>,
    /// Base experiment configuration (None: the built-in configs/paper.toml).
    pub config: Option<PathBuf>,
    /// Overrides of base configuration keys, `KEY=VALUE`.
    pub sets: Vec<String>,
    /// The varied keys and their values.
    pub varies: Vec<Vary>,
    /// Run every noise stage alone, every pair and all together (not with `varies`).
    pub interactions: bool,
    /// Seeds (None: the configuration's seed).
    pub seeds: Option<Vec<u64>>,
    /// Ground-truth labels, one per capture in order (empty: `X.labels.csv.gz` beside a
    /// capture `X.pcap` when it exists).
    pub labels: Vec<PathBuf>,
    /// Output folder.
    pub output: PathBuf,
    /// Frames to process, by sweep index.
    pub frames: RangeInclusive<u32>,
    /// Frame of the first capture shown in the bird's-eye figure (None: the first).
    pub figure_frame: Option<u32>,
    /// Distance band edges in metres, ascending.
    pub bands: Vec<f64>,
    /// Half-width of the bird's-eye view in metres.
    pub figure_extent: f64,
    /// File format of the plots and heatmaps.
    pub figure_format: FigureFormat,
    /// Replace the results of another sweep in the folder as a whole.
    pub force: bool,
    /// Compute only the units that fall to this shard; no tables, plots or page.
    pub shard: Option<Shard>,
    /// Compute nothing: build the outputs from the cells the shards wrote.
    pub merge: bool,
    /// Split each capture into chunks of this many frames (units become cell x chunk).
    pub chunk_frames: Option<u32>,
    /// How captures are decoded.
    pub decoder: DecoderOptions,
    /// Other files never written over (a calibration file).
    pub protected: Vec<PathBuf>,
}

impl SweepRequest {
    /// A sweep of `captures` into `output` with the settings `sweep` takes when no option
    /// is given: the built-in configuration, nothing varied, the configuration's seed,
    /// every frame, the default bands and figure.
    pub fn new(captures: Vec<PathBuf>, output: PathBuf) -> Self {
        SweepRequest {
            captures,
            config: None,
            sets: Vec::new(),
            varies: Vec::new(),
            interactions: false,
            seeds: None,
            labels: Vec::new(),
            output,
            frames: crate::range::ALL_FRAMES,
            figure_frame: None,
            bands: crate::score::metrics::DEFAULT_BANDS.to_vec(),
            figure_extent: 40.0,
            figure_format: FigureFormat::Png,
            force: false,
            shard: None,
            merge: false,
            chunk_frames: None,
            decoder: DecoderOptions::default(),
            protected: Vec::new(),
        }
    }
}

/// Runs the sweep of `args` and writes every output into its folder; warnings, progress
/// and what was done go to `observer`.
pub fn sweep(args: &SweepRequest, observer: &dyn Observer) -> Result<()> {
    let (base, warnings) = BaseConfig::load(args.config.as_deref(), &args.sets)?;
    for w in &warnings {
        observer.warn(w);
    }
    let varies = if args.interactions {
        vec![Vary::interactions(&base)?]
    } else {
        args.varies.clone()
    };
    let mut seen = HashSet::new();
    if let Some(v) = varies.iter().find(|v| !seen.insert(v.key.clone())) {
        anyhow::bail!("--vary {}: the key is varied twice", v.key);
    }
    let seeds = match &args.seeds {
        Some(s) => s.clone(),
        None => vec![base.seed()],
    };
    if !args.labels.is_empty() && args.labels.len() != args.captures.len() {
        anyhow::bail!(
            "--labels: give one labels file per capture ({} captures, {} labels files)",
            args.captures.len(),
            args.labels.len()
        );
    }
    if !(args.figure_extent.is_finite() && args.figure_extent > 0.0) {
        anyhow::bail!(
            "--figure-extent {}: give a positive distance in metres",
            args.figure_extent
        );
    }
    let mut captures = Vec::new();
    let names = crate::engine::inputs::output_names(&args.captures);
    for (i, (path, name)) in args.captures.iter().zip(names).enumerate() {
        let labels = match args.labels.get(i) {
            Some(l) => Some(l.clone()),
            None => {
                let stem = path.file_stem().unwrap_or_default().to_string_lossy();
                let guess = path.with_file_name(format!("{stem}.labels.csv.gz"));
                guess.is_file().then_some(guess)
            }
        };
        captures.push(CaptureInput {
            name,
            path: path.clone(),
            labels,
        });
    }
    let settings = SweepSettings {
        base,
        varies,
        seeds,
        decoder: args.decoder.clone(),
        frames: args.frames.clone(),
        output: args.output.clone(),
        bands: args.bands.clone(),
        chunk_frames: args.chunk_frames,
    };
    // Every cell configuration is built (and so checked) before any work starts.
    for cell in super::plan::cells(&settings.varies, &settings.seeds) {
        settings.base.cell_config(&settings.varies, &cell)?;
    }
    // One sweep per folder at a time (its shards excepted: they share the lock and write
    // distinct cells).
    let folder = if args.shard.is_some() {
        staging::OutputFolder::lock_shared(&args.output)?
    } else {
        staging::OutputFolder::lock(&args.output)?
    };
    let plan = plan_settings(args, &settings, &captures)?;
    let mut inputs: Vec<&Path> = Vec::new();
    for c in &captures {
        inputs.push(&c.path);
        inputs.extend(c.labels.as_deref());
    }
    inputs.extend(args.config.as_deref());
    inputs.extend(args.protected.iter().map(PathBuf::as_path));
    let is_cell = |f: &str| is_cell_file(&args.output, f);
    // A sweep given new values or seeds grows the folder's sweep without --force: its
    // finished cells are reused, the manifest records the earlier plan.
    let grown_from = staging::read_manifest(&args.output)
        .filter(|m| m.command == "sweep" && m.settings != plan && grows(&m.settings, &plan));
    let old = match staging::check_replace(
        &args.output,
        "sweep",
        &plan,
        &is_sweep_output,
        &is_cell,
        args.force || grown_from.is_some(),
        &inputs,
    ) {
        Ok(old) => old,
        Err(e) => {
            folder.abandon();
            return Err(e);
        }
    };
    // Only now, the checks passed: what killed runs of this tool left.
    folder.remove_leftovers(&|f| is_sweep_output(f) || f.starts_with("cells/"));
    let earlier = staging::read_manifest(&args.output);
    // A new folder records the plan before any cell, so that a sweep of another plan is
    // refused while its cells accumulate (shards, an interrupted sweep). A folder holding
    // results keeps their record until the new results replace them whole.
    let fresh = old.is_empty() && earlier.is_none();
    if fresh {
        staging::write_manifest(&args.output, "sweep", &plan, Vec::new())?;
    }
    // The plans the results grew from: kept over reruns of the same plan, one more
    // when this one grows, none when --force replaces another plan.
    let growth = match (&earlier, &grown_from) {
        (Some(m), Some(_)) => {
            let mut g = m.growth.clone();
            g.push(growth_entry(&m.settings));
            g
        }
        (Some(m), None) if m.command == "sweep" && m.settings == plan => m.growth.clone(),
        _ => Vec::new(),
    };
    if let Some(m) = &grown_from {
        observer.note(&format!(
            "sweep: the plan grows (new values or seeds; before: {}); finished cells are \
             reused",
            growth_entry(&m.settings)
        ));
    }
    let result = sweep_into(
        args,
        &settings,
        &captures,
        &folder,
        (&plan, &old, earlier.as_ref(), growth),
        observer,
    );
    if result.is_err() && args.shard.is_none() && fresh {
        // A failed first sweep leaves no folder, no record and no empty cell folder;
        // cells it finished stay (with their record), a rerun loads them.
        for c in &captures {
            let _ = std::fs::remove_dir(args.output.join("cells").join(&c.name));
        }
        let _ = std::fs::remove_dir(args.output.join("cells"));
        if staging::result_files(&args.output).is_empty() {
            let _ = std::fs::remove_file(args.output.join(staging::MANIFEST));
        }
        folder.abandon();
    }
    result
}

/// Computes the cells and writes the tables, plots and page into a staging folder, then
/// replaces the folder's earlier results with them as a whole (`staging::commit_into`):
/// a failure or an interruption before that leaves the earlier results as they were.
/// `earlier`: the plan, the files `check_replace` returned and the folder's manifest.
fn sweep_into(
    args: &SweepRequest,
    settings: &SweepSettings,
    captures: &[CaptureInput],
    folder: &staging::OutputFolder,
    (plan, old, earlier, growth): (
        &serde_json::Value,
        &[String],
        Option<&staging::Manifest>,
        Vec<serde_json::Value>,
    ),
    observer: &dyn Observer,
) -> Result<()> {
    // The cells of this plan (and their parts) are kept: the old plan's go at the end.
    let cells = super::run::canonical_cells(settings);
    let mut keep = HashSet::new();
    for c in captures {
        for cell in &cells {
            keep.insert(format!(
                "cells/{}/{}",
                c.name,
                cell.file_name(&settings.varies)
            ));
        }
    }
    let part_of_kept = |f: &str| {
        f.rsplit_once('/').is_some_and(|(folder, name)| {
            crate::shard::part_chunk_size(name).is_some()
                && keep.iter().any(|k| k.starts_with(&format!("{folder}/")))
        })
    };
    let mode = match (args.shard, args.merge) {
        (Some(shard), _) => Mode::Shard(shard),
        (None, true) => Mode::Merge,
        (None, false) => Mode::All,
    };
    let outcome = run_mode(settings, captures, observer, mode)?;
    if let Some(shard) = args.shard {
        let units = if args.chunk_frames.is_some() {
            "cell parts"
        } else {
            "cells"
        };
        observer.note(&format!(
            "sweep --shard {shard}: {} of {} {units} fall to this shard ({} computed, \
             {} already done); a shard writes no tables, plots or page: run \
             `lidar-noise sweep ... --merge` (or the same sweep without --shard) once \
             every shard is done",
            outcome.owned, outcome.total, outcome.computed, outcome.loaded
        ));
        return Ok(());
    }

    let first = &captures[0];
    let seed = settings.seeds[0];
    let figure = match read_frame(
        &first.path,
        &settings.decoder,
        &settings.frames,
        args.figure_frame,
    )? {
        Some((frame, lasers)) => Some(BirdsEye {
            capture: first.name.clone(),
            frame: frame.index,
            seed,
            panels: birdseye_panels(&settings.base, seed, &frame, lasers)?,
            extent_m: args.figure_extent,
        }),
        None => {
            observer.warn(&format!(
                "{}: no frame {} for the bird's-eye figure",
                first.path.display(),
                args.figure_frame
                    .map_or("in range".into(), |f| f.to_string())
            ));
            None
        }
    };
    let mut protected: Vec<&Path> = Vec::new();
    for c in captures {
        protected.push(&c.path);
        if let Some(l) = &c.labels {
            protected.push(l);
        }
    }
    if let Some(c) = &args.config {
        protected.push(c);
    }
    let names: Vec<String> = captures.iter().map(|c| c.name.clone()).collect();
    let mut cell_files: Vec<String> = keep.iter().cloned().collect();
    cell_files.sort();
    let stage = folder.stage("sweep")?;
    let written = write_outputs(
        stage.path(),
        &settings.varies,
        &names,
        &outcome.rows,
        figure.as_ref(),
        &protected,
        &cell_files,
        args.figure_format,
    )?;
    let files: Vec<String> = written
        .iter()
        .filter_map(|p| p.strip_prefix(stage.path()).ok())
        .map(|p| p.to_string_lossy().replace('\\', "/"))
        .collect();
    staging::write_manifest_grown(stage.path(), "sweep", plan, files.clone(), growth)?;
    // Of the earlier results: the files of its record that the new ones do not replace
    // and, with --force, the cells of another plan. Cells of this plan stay.
    let listed = |f: &String| earlier.is_some_and(|m| m.files.contains(f));
    let replaces: Vec<String> = old
        .iter()
        .filter(|f| !files.contains(f) && !keep.contains(*f) && !part_of_kept(f))
        .filter(|f| args.force || listed(f))
        .cloned()
        .collect();
    staging::commit_into(stage, &replaces)?;
    observer.note(&format!(
        "sweep: {} cells computed, {} loaded from earlier runs, {} rows; open {}",
        outcome.computed,
        outcome.loaded,
        outcome.rows.len(),
        args.output.join("index.html").display()
    ));
    Ok(())
}

/// True for a file under `DIR/cells/` that says by its content that a sweep wrote it (a
/// cell or a part of one, even edited or cut): cells accumulate over runs and shards, so
/// no one manifest lists them.
fn is_cell_file(dir: &Path, rel: &str) -> bool {
    rel.starts_with("cells/") && super::cells::written_by_sweep(&dir.join(rel))
}

/// What decides a sweep folder's tables, plots and page: a sweep with other settings is
/// another sweep (refused without --force); the same plan resumes (see
/// `staging::check_replace`). Capture content is not in it: cells are keyed on it and
/// recomputed when it changes, and the tables are always rebuilt whole.
fn plan_settings(
    args: &SweepRequest,
    settings: &SweepSettings,
    captures: &[CaptureInput],
) -> Result<serde_json::Value> {
    let d = &settings.decoder;
    Ok(serde_json::json!({
        "captures": captures.iter().map(|c| serde_json::json!({
            "name": c.name,
            "file": crate::engine::inputs::capture_label(&c.path),
            "labels": c.labels.as_ref().map(|l| crate::engine::inputs::capture_label(l)),
        })).collect::<Vec<_>>(),
        "base": serde_json::to_value(&settings.base.table)?,
        "varies": settings.varies.iter().map(|v| serde_json::json!({
            "key": v.key,
            "values": v.values,
        })).collect::<Vec<_>>(),
        "seeds": settings.seeds,
        "frames": [settings.frames.start(), settings.frames.end()],
        "bands": settings.bands,
        "decoder": {
            "calibration": d.calibration.source,
            "interpolate_azimuth": d.interpolate_azimuth,
            "dual": format!("{:?}", d.dual),
            "cut_angle_deg": d.cut_angle_deg,
            "keep_partial": d.keep_partial,
        },
        "figure_frame": args.figure_frame,
        "figure_extent": args.figure_extent,
    }))
}

/// True when the sweep plan `new` grows `old`: everything equal but the values of each
/// varied key (same keys, in the same order) and the seeds, of which `new` holds all of
/// `old`'s and more. Its cells include all of `old`'s (a cell's file is named by its own
/// values and seed), so they are reused; a removed value, another key, base
/// configuration, capture, frame range, band or figure is another sweep.
fn grows(old: &serde_json::Value, new: &serde_json::Value) -> bool {
    use serde_json::Value;
    let (Value::Object(a), Value::Object(b)) = (old, new) else {
        return false;
    };
    let superset = |x: Option<&Value>, y: Option<&Value>| match (x, y) {
        (Some(Value::Array(x)), Some(Value::Array(y))) => x.iter().all(|v| y.contains(v)),
        _ => false,
    };
    let same_but = |k: &str| k == "varies" || k == "seeds";
    let keys_equal = a.len() == b.len()
        && a.iter()
            .all(|(k, v)| same_but(k) || b.get(k).is_some_and(|w| w == v));
    let varies_grow = match (a.get("varies"), b.get("varies")) {
        (Some(Value::Array(x)), Some(Value::Array(y))) => {
            x.len() == y.len()
                && x.iter().zip(y).all(|(p, q)| {
                    p.get("key") == q.get("key") && superset(p.get("values"), q.get("values"))
                })
        }
        _ => false,
    };
    keys_equal && varies_grow && superset(a.get("seeds"), b.get("seeds"))
}

/// What the manifest records of a plan a sweep grew from: its varied values and seeds.
fn growth_entry(plan: &serde_json::Value) -> serde_json::Value {
    serde_json::json!({ "varies": plan["varies"], "seeds": plan["seeds"] })
}

/// True for the files `sweep` writes (for folders without a manifest): tables, page,
/// plots and cells.
fn is_sweep_output(name: &str) -> bool {
    let parts: Vec<&str> = name.split('/').collect();
    match parts.as_slice() {
        [super::outputs::TIDY_CSV]
        | [super::outputs::TIDY_JSON]
        | [super::outputs::AGGREGATE_CSV]
        | [super::outputs::INDEX_HTML]
        | [super::interactions::INTERACTIONS_CSV]
        | [super::interactions::INTERACTIONS_JSON] => true,
        ["cells", _, cell] => cell.ends_with(".json"),
        ["plots", .., png] => png.ends_with(".png"),
        _ => false,
    }
}
