//! `lidar-noise sweep`: every combination of varied settings and seeds over captures.

use crate::cli::Global;
use crate::options::{parse_range, DecoderArgs};
use crate::sweep::outputs::{write_outputs, BirdsEye};
use crate::sweep::plan::{parse_seeds, BaseConfig, Vary};
use crate::sweep::run::{
    birdseye_panels, read_frame, run_mode as run_sweep, CaptureInput, Mode, Observer, SweepSettings,
};
use crate::writers::staging;
use anyhow::Result;
use indicatif::{MultiProgress, ProgressBar, ProgressDrawTarget, ProgressStyle};
use std::collections::HashSet;
use std::path::{Path, PathBuf};

/// Arguments of `sweep`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Capture files (pcap or pcapng).
    #[arg(value_name = "CAPTURE", required = true)]
    pub captures: Vec<PathBuf>,
    /// Base experiment configuration (default: the built-in configs/paper.toml).
    #[arg(short, long, value_name = "FILE")]
    pub config: Option<PathBuf>,
    /// Override a base configuration key, e.g. --set detection.min_power=0.002 (repeatable).
    #[arg(long = "set", value_name = "KEY=VALUE")]
    pub sets: Vec<String>,
    /// Vary a key over values: rain.rate_mm_h=0,1,3 or a range rain.rate_mm_h=0..10:2.5
    /// (A..B[:STEP], B included, step 1 by default) (first stage of that type),
    /// noise[1].rate_mm_h=..., any --set path, or occlusion=on,off (repeatable).
    #[arg(long = "vary", value_name = "KEY=V1,V2,...")]
    pub varies: Vec<String>,
    /// Run every noise stage of the configuration alone, every pair and all together, and
    /// write the interaction table and heatmap (not with --vary).
    #[arg(long, conflicts_with = "varies")]
    pub interactions: bool,
    /// Seeds: N, A..B (both included) or a,b,c (default: the configuration's seed).
    #[arg(long, value_name = "SEEDS")]
    pub seeds: Option<String>,
    /// Ground-truth labels (one per capture, in order); by default CAPTURE with .pcap
    /// replaced by .labels.csv.gz is used when it exists.
    #[arg(long = "labels", value_name = "FILE")]
    pub labels: Vec<PathBuf>,
    /// Output folder.
    #[arg(short, long, value_name = "DIR", default_value = "lidar-noise-sweep")]
    pub output: PathBuf,
    /// Frames to process, by sweep index: N, A..B (both included), A.. or ..B.
    #[arg(long, value_name = "RANGE")]
    pub frames: Option<String>,
    /// Frame of the first capture shown in the bird's-eye figure (default: the first).
    #[arg(long, value_name = "N")]
    pub figure_frame: Option<u32>,
    /// Distance band edges in metres, ascending: bands [e0, e1), ..., [ek, inf) on the
    /// horizontal distance of each object's clean centroid.
    #[arg(long, value_name = "M,M,...", default_value = "0,5,10,20,40")]
    pub bands: String,
    /// Half-width of the bird's-eye view in metres.
    #[arg(long, value_name = "M", default_value_t = 40.0)]
    pub figure_extent: f64,
    /// File format of the plots and heatmaps: png, or svg (vector, for print; text stays
    /// text). The bird's-eye figure is always PNG: its tens of thousands of points would
    /// make an SVG of tens of megabytes.
    #[arg(long, value_enum, value_name = "FORMAT", default_value = "png")]
    pub figure_format: crate::writers::figure::FigureFormat,
    /// Replace the results of another sweep (other captures, configuration, --vary keys,
    /// fewer values or seeds, frames, bands or figure) in the folder as a whole; cells of
    /// this sweep are kept. Not needed to grow a sweep by new --vary values or seeds: its
    /// finished cells are reused. Files lidar-noise did not write are never deleted (the
    /// sweep is refused).
    #[arg(long, conflicts_with_all = ["shard", "merge"])]
    pub force: bool,
    /// Compute only the cells that fall to shard K of N (K from 0, round-robin over the
    /// cells of every capture) into DIR/cells/; writes no tables, plots or page. Shards
    /// may run at the same time, on other machines sharing DIR, in any order, repeatedly.
    #[arg(long, value_name = "K/N", value_parser = crate::options::Shard::parse, conflicts_with = "merge")]
    pub shard: Option<crate::options::Shard>,
    /// Compute no cell: build the tables, plots and page from the cells the shards wrote,
    /// or fail listing the cells that are missing.
    #[arg(long)]
    pub merge: bool,
    /// Split each capture into chunks of M frames, so that the units shards deal are
    /// (cell, chunk) rather than cells: for long captures and more nodes than cells. Give
    /// the same value to every shard, the merge and reruns (a different one is refused).
    #[arg(long, value_name = "M", value_parser = clap::value_parser!(u32).range(1..))]
    pub chunk_frames: Option<u32>,
    /// Decoder settings shared by the commands that read captures.
    #[command(flatten)]
    pub decoder: DecoderArgs,
}

/// Progress bars on stderr: cells and frames, with elapsed and remaining time.
struct Bars {
    cells: ProgressBar,
    frames: ProgressBar,
    _multi: MultiProgress,
    global: Global,
    chunked: bool,
    /// Cells still to compute in the current capture.
    pending_here: std::sync::atomic::AtomicU64,
}

impl Bars {
    fn new(global: Global, total_cells: u64, chunked: bool) -> Bars {
        use std::io::IsTerminal;
        let visible = !global.quiet && std::io::stderr().is_terminal();
        let multi = MultiProgress::with_draw_target(if visible {
            ProgressDrawTarget::stderr()
        } else {
            ProgressDrawTarget::hidden()
        });
        let style = |unit: &str| {
            ProgressStyle::with_template(&format!(
                "{{bar:30}} {{pos}}/{{len}} {unit} {{elapsed}} elapsed, {{eta}} left {{msg}}"
            ))
            .unwrap_or_else(|_| ProgressStyle::default_bar())
        };
        let cells = multi.add(ProgressBar::new(total_cells).with_style(style("cells")));
        let frames = multi.add(ProgressBar::new(0).with_style(style("frames")));
        Bars {
            cells,
            frames,
            _multi: multi,
            global,
            chunked,
            pending_here: std::sync::atomic::AtomicU64::new(0),
        }
    }
}

impl Observer for Bars {
    fn capture(&self, name: &str, cells: u64) {
        if self.chunked {
            // With chunks the units are known capture by capture (frames are counted).
            self.cells.inc_length(cells);
        }
        self.cells.set_message(name.to_string());
        self.frames.set_position(0);
        self.frames.set_length(0);
        self.pending_here
            .store(cells, std::sync::atomic::Ordering::Relaxed);
    }
    fn frames_total(&self, n: u64) {
        if self.chunked {
            // Known after the first chunk: n frames per unit, units still to run.
            let cells_left = self.cells.length().unwrap_or(0) - self.cells.position();
            self.frames
                .set_length(self.frames.position() + n * cells_left);
        } else {
            // Known before work starts: n frames for each pending cell of this capture.
            let here = self.pending_here.load(std::sync::atomic::Ordering::Relaxed);
            self.frames.set_length(self.frames.position() + n * here);
        }
    }
    fn frame_done(&self) {
        self.frames.inc(1);
    }
    fn cell_done(&self) {
        self.cells.inc(1);
    }
    fn warn(&self, message: &str) {
        self.cells.suspend(|| self.global.warn(message));
    }
}

/// Runs the sweep and writes every output.
pub fn run(args: Args, global: Global) -> Result<()> {
    let (base, warnings) = BaseConfig::load(args.config.as_deref(), &args.sets)?;
    for w in &warnings {
        global.warn(w);
    }
    let varies: Vec<Vary> = args
        .varies
        .iter()
        .map(|v| Vary::parse(v))
        .collect::<crate::error::Result<_>>()?;
    let varies = if args.interactions {
        vec![Vary::interactions(&base)?]
    } else {
        varies
    };
    let mut seen = HashSet::new();
    if let Some(v) = varies.iter().find(|v| !seen.insert(v.key.clone())) {
        anyhow::bail!("--vary {}: the key is varied twice", v.key);
    }
    let seeds = match &args.seeds {
        Some(s) => parse_seeds(s)?,
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
    let names = super::output_names(&args.captures);
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
        decoder: args.decoder.to_options()?,
        frames: match &args.frames {
            Some(text) => parse_range("--frames", text)?,
            None => 0..=u32::MAX,
        },
        output: args.output.clone(),
        bands: crate::sweep::plan::parse_bands(&args.bands)?,
        chunk_frames: args.chunk_frames,
    };
    // Every cell configuration is built (and so checked) before any work starts.
    for cell in crate::sweep::plan::cells(&settings.varies, &settings.seeds) {
        settings.base.cell_config(&settings.varies, &cell)?;
    }
    // One sweep per folder at a time (its shards excepted: they share the lock and write
    // distinct cells).
    let folder = if args.shard.is_some() {
        staging::OutputFolder::lock_shared(&args.output)?
    } else {
        staging::OutputFolder::lock(&args.output)?
    };
    let plan = plan_settings(&args, &settings, &captures)?;
    let mut inputs: Vec<&Path> = Vec::new();
    for c in &captures {
        inputs.push(&c.path);
        inputs.extend(c.labels.as_deref());
    }
    inputs.extend(args.config.as_deref());
    inputs.extend(args.decoder.calibration.as_deref());
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
    if let (Some(m), false) = (&grown_from, global.quiet) {
        eprintln!(
            "sweep: the plan grows (new values or seeds; before: {}); finished cells are \
             reused",
            growth_entry(&m.settings)
        );
    }
    let result = sweep_into(
        &args,
        &settings,
        &captures,
        &folder,
        (&plan, &old, earlier.as_ref(), growth),
        global,
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
    args: &Args,
    settings: &SweepSettings,
    captures: &[CaptureInput],
    folder: &staging::OutputFolder,
    (plan, old, earlier, growth): (
        &serde_json::Value,
        &[String],
        Option<&staging::Manifest>,
        Vec<serde_json::Value>,
    ),
    global: Global,
) -> Result<()> {
    let n_cells = crate::sweep::plan::cells(&settings.varies, &settings.seeds).len();
    // The cells of this plan (and their parts) are kept: the old plan's go at the end.
    let cells = crate::sweep::run::canonical_cells(settings);
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
            crate::sweep::chunks::part_chunk_size(name).is_some()
                && keep.iter().any(|k| k.starts_with(&format!("{folder}/")))
        })
    };
    let mode = match (args.shard, args.merge) {
        (Some(shard), _) => Mode::Shard(shard),
        (None, true) => Mode::Merge,
        (None, false) => Mode::All,
    };
    let total = n_cells * captures.len();
    let own = match args.shard {
        Some(shard) => (0..total).filter(|&i| shard.owns(i)).count(),
        None => total,
    };
    let chunked = args.chunk_frames.is_some();
    let bars = Bars::new(global, if chunked { 0 } else { own as u64 }, chunked);
    let outcome = run_sweep(settings, captures, &bars, mode)?;
    bars.frames.finish_and_clear();
    bars.cells.finish_and_clear();
    if let Some(shard) = args.shard {
        if !global.quiet {
            let units = if chunked { "cell parts" } else { "cells" };
            eprintln!(
                "sweep --shard {shard}: {} of {} {units} fall to this shard ({} computed, \
                 {} already done); a shard writes no tables, plots or page: run \
                 `lidar-noise sweep ... --merge` (or the same sweep without --shard) once \
                 every shard is done",
                outcome.owned, outcome.total, outcome.computed, outcome.loaded
            );
        }
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
            global.warn(&format!(
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
    if !global.quiet {
        eprintln!(
            "sweep: {} cells computed, {} loaded from earlier runs, {} rows; open {}",
            outcome.computed,
            outcome.loaded,
            outcome.rows.len(),
            args.output.join("index.html").display()
        );
    }
    Ok(())
}

/// True for a file under `DIR/cells/` that says by its content that a sweep wrote it (a
/// cell or a part of one, even edited or cut): cells accumulate over runs and shards, so
/// no one manifest lists them.
fn is_cell_file(dir: &Path, rel: &str) -> bool {
    rel.starts_with("cells/") && crate::sweep::run::written_by_sweep(&dir.join(rel))
}

/// What decides a sweep folder's tables, plots and page: a sweep with other settings is
/// another sweep (refused without --force); the same plan resumes (see
/// `staging::check_replace`). Capture content is not in it: cells are keyed on it and
/// recomputed when it changes, and the tables are always rebuilt whole.
fn plan_settings(
    args: &Args,
    settings: &SweepSettings,
    captures: &[CaptureInput],
) -> Result<serde_json::Value> {
    let d = &settings.decoder;
    Ok(serde_json::json!({
        "captures": captures.iter().map(|c| serde_json::json!({
            "name": c.name,
            "file": crate::commands::capture_label(&c.path),
            "labels": c.labels.as_ref().map(|l| crate::commands::capture_label(l)),
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
        [crate::sweep::outputs::TIDY_CSV]
        | [crate::sweep::outputs::TIDY_JSON]
        | [crate::sweep::outputs::AGGREGATE_CSV]
        | [crate::sweep::outputs::INDEX_HTML]
        | [crate::sweep::interactions::INTERACTIONS_CSV]
        | [crate::sweep::interactions::INTERACTIONS_JSON] => true,
        ["cells", _, cell] => cell.ends_with(".json"),
        ["plots", .., png] => png.ends_with(".png"),
        _ => false,
    }
}
