//! `lidar-noise run`: the whole pipeline on one or more captures.

use crate::cli::Global;
use crate::cloud::frames::{CloudOptions, CloudReader, CloudSummary};
use crate::config::Config;
use crate::frame::{Frame, FrameSource};
use crate::hdl32e::frames::{CaptureSummary, DecoderOptions, FrameReader};
use crate::options::{parse_range, DecoderArgs, FrameOutputArgs};
use crate::pipeline::report::{
    write_cluster_csv, write_frame_clusters_json, write_pretty_nested, FrameClusters, FrameReport,
    Totals, FATE_CODES,
};
use crate::pipeline::{FrameResult, Pipeline};
use crate::writers::ply::{PlyColumns, PlyFrame};
use crate::writers::scan::ScanPoint;
use crate::writers::staging::{self, OutputFolder};
use crate::writers::{write_file, FrameOutput};
use anyhow::{Context, Result};
use serde::Serialize;
use std::ops::RangeInclusive;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// The capture the main command runs on when none is given.
pub const DEFAULT_CAPTURE: &[u8] = include_bytes!("../../fixtures/crossroad.pcap");
/// How the built-in capture is named in outputs.
pub const DEFAULT_CAPTURE_NAME: &str = "crossroad (built-in fixtures/crossroad.pcap)";
/// Output folder when `-o` is not given.
pub const DEFAULT_OUTPUT: &str = "lidar-noise-out";

/// Arguments of `run`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Capture files (pcap or pcapng), `-` for standard input, or point-cloud scans
    /// (nuScenes .pcd.bin, KITTI .bin, PCD, CSV: one frame each); none runs the built-in
    /// crossroad fixture.
    #[arg(value_name = "CAPTURE")]
    pub captures: Vec<PathBuf>,
    /// Sensor that recorded the point-cloud scans given (captures name their sensor
    /// themselves). Point clouds are placed on the HDL-32E's firings (`hdl32e`, the default
    /// except for KITTI scans, which come from an HDL-64E and need it said).
    #[arg(long, value_name = "NAME")]
    pub sensor: Option<String>,
    /// Rotation rate of the point-cloud scans in Hz: the firing grid their points are
    /// placed on (default 20 for nuScenes .pcd.bin, 10 otherwise).
    #[arg(long, value_name = "HZ")]
    pub rotation_hz: Option<f64>,
    /// Per-point labels of the point-cloud scan (SemanticKITTI .label, nuScenes-lidarseg
    /// _lidarseg.bin or -panoptic .npz): ground and object scores go to truth.json. By
    /// default a KITTI scan's ../labels/NNNNNN.label, or ../label_2 and ../calib boxes.
    #[arg(long, value_name = "FILE")]
    pub labels: Option<PathBuf>,
    /// Experiment configuration (default: the built-in configs/paper.toml).
    #[arg(short, long, value_name = "FILE")]
    pub config: Option<PathBuf>,
    /// Override a configuration key, e.g. --set noise[1].rate_mm_h=3 (repeatable).
    #[arg(long = "set", value_name = "KEY=VALUE")]
    pub sets: Vec<String>,
    /// Override the seed of every random stream.
    #[arg(long, value_name = "N")]
    pub seed: Option<u64>,
    /// Output folder; each capture gets a subfolder named after it.
    #[arg(short, long, value_name = "DIR", default_value = DEFAULT_OUTPUT)]
    pub output: PathBuf,
    /// Frames to process, by sweep index: N, A..B (both included), A.. or ..B.
    #[arg(long, value_name = "RANGE")]
    pub frames: Option<String>,
    /// Also write the dropped returns in each point cloud, with a `fate` field.
    #[arg(long)]
    pub keep_dropped: bool,
    /// Write no point clouds (reports only).
    #[arg(long, conflicts_with = "keep_dropped")]
    pub no_ply: bool,
    /// Point-cloud format (PLY, LAS, LAZ) and PLY encoding.
    #[command(flatten)]
    pub output_format: FrameOutputArgs,
    /// Also write each frame's single-linkage merge tree (SciPy linkage layout, CSV).
    ///
    /// Cost: one CSV row per merge (at most one per point, about 30 bytes: 1.5 MB per 50,000
    /// points) and memory linear in the frame's points (a few MB per thread).
    #[arg(long)]
    pub linkage_out: bool,
    /// Replace the results of another run in a capture's folder (as a whole); files
    /// lidar-noise did not write are never deleted (the run is refused instead).
    #[arg(long)]
    pub force: bool,
    /// Run only the captures that fall to shard K of N (K from 0, round-robin over the
    /// captures in the order given), e.g. --shard $SLURM_ARRAY_TASK_ID/$SLURM_ARRAY_TASK_COUNT.
    #[arg(long, value_name = "K/N", value_parser = crate::options::Shard::parse)]
    pub shard: Option<crate::options::Shard>,
    /// Split each capture into chunks of M frames, so that the units shards deal are
    /// (capture, chunk) rather than captures: for long captures and more nodes than
    /// captures. Each unit writes its frames' files and a part; `--merge` (or the same run
    /// without --shard) writes the reports. Give the same value to every shard and the
    /// merge (a different one is refused). Not with --pcap-out or standard input.
    #[arg(long, value_name = "M", value_parser = clap::value_parser!(u32).range(1..))]
    pub chunk_frames: Option<u32>,
    /// Compute nothing: join the parts the shards of `--chunk-frames` wrote into the
    /// reports of each capture (as one run writes them) and delete the parts, or fail
    /// listing the parts that are missing.
    #[arg(long, requires = "chunk_frames", conflicts_with = "shard")]
    pub merge: bool,
    /// Also write the capture re-encoded from the noisy returns as DIR/<name>/noisy.pcap
    /// (see the manual, "Noisy capture out").
    #[arg(long)]
    pub pcap_out: bool,
    /// Decoder settings shared by the commands that read captures.
    #[command(flatten)]
    pub decoder: DecoderArgs,
}

/// Validated settings of a run.
pub(super) struct Plan {
    pub(super) config: Config,
    pub(super) pipeline: Pipeline,
    pub(super) decoder: DecoderOptions,
    pub(super) frames: RangeInclusive<u32>,
    pub(super) keep_dropped: bool,
    pub(super) ply: bool,
    pub(super) output: FrameOutput,
    pub(super) linkage: bool,
    pub(super) pcap_out: bool,
    /// Point-cloud scans are written back in their own format (no `--format` given).
    pub(super) native: bool,
}

/// The per-capture summary written as summary.json.
#[derive(Serialize)]
pub(super) struct Summary<'a> {
    tool: &'static str,
    version: &'static str,
    capture: String,
    config: String,
    settings: crate::config::EffectiveConfig<'a>,
    power_constants: &'a crate::noise::PowerConstants,
    decoder: DecoderSettings,
    fate_codes: [&'static str; 6],
    capture_summary: SourceSummary<'a>,
    pub(super) totals: Totals,
    frames: &'a [FrameReport],
}

/// What the source held: a capture's packets and frames, or a point-cloud file's points.
#[derive(Serialize)]
#[serde(untagged)]
pub(super) enum SourceSummary<'a> {
    /// A decoded capture.
    Capture(&'a CaptureSummary),
    /// A point-cloud scan.
    Cloud(&'a CloudSummary),
}

/// Where a run's frames come from.
enum Source {
    /// A capture, decoded (boxed: its reader is large, and jobs are moved around).
    Capture(Box<FrameReader>),
    /// A point-cloud scan, placed on the sensor's firings.
    Cloud(CloudReader),
}

/// The point-cloud format of `path`, or `None` for a capture: files that start like a
/// pcap or pcapng file, standard input and streams (read only once, never probed) are
/// captures; so is anything no point-cloud reader recognises (the capture reader then
/// says what is wrong).
fn cloud_format(path: &Path) -> Option<crate::cloud::Format> {
    use std::io::Read;
    if super::is_stdin(path) || crate::capture::is_stream(path) {
        return None;
    }
    let mut head = Vec::with_capacity(4096);
    let file = std::fs::File::open(path).ok()?;
    file.take(4096).read_to_end(&mut head).ok()?;
    if crate::capture::starts_like_capture(&head) {
        return None;
    }
    crate::cloud::detect(path, &head).ok()
}

/// How a point-cloud file of `format` is read, from `--sensor` and `--rotation-hz`.
fn cloud_options(args: &Args, path: &Path, format: crate::cloud::Format) -> Result<CloudOptions> {
    use crate::cloud::guess::{guess_sensor, sensor_by_name, SENSOR_NAMES};
    use crate::cloud::Format;
    let sensor = match args.sensor.as_deref() {
        Some(name) => sensor_by_name(name).ok_or_else(|| {
            anyhow::anyhow!("--sensor {name}: not a sensor modelled here ({SENSOR_NAMES})")
        })?,
        None if format == Format::Kitti => {
            // KITTI's sensor is an HDL-64E: the default once the stages run 64 lasers. The
            // data's own evidence is shown beside it.
            let cloud = crate::cloud::read_file(path, &Default::default())?;
            let data = match guess_sensor(&cloud.points) {
                Ok(g) => g.reason,
                Err(e) => format!("the sensor cannot be told from the data: {e}"),
            };
            anyhow::bail!(
                "{}: a KITTI scan comes from an HDL-64E, whose 64 lasers the noise stages do \
                 not model yet (they model 32): nothing was written; the data: {data}; pass \
                 --sensor hdl32e only if an HDL-32E recorded this scan",
                path.display()
            )
        }
        None => &crate::sensor::HDL32E,
    };
    if sensor.name != crate::sensor::HDL32E.name {
        anyhow::bail!(
            "--sensor {}: {} scans are converted by the library (cloud::returns), but the noise \
             stages' firing slots are those of the HDL-32E's 32 lasers so far: run takes \
             --sensor hdl32e only; nothing was written",
            args.sensor.as_deref().unwrap_or_default(),
            sensor.name
        );
    }
    let rotation_hz = args.rotation_hz.unwrap_or(if format == Format::NuScenes {
        20.0
    } else {
        10.0
    });
    Ok(CloudOptions {
        sensor,
        format: Some(format),
        rotation_hz,
        labels: args.labels.clone(),
    })
}

/// The cluster report written as clusters.json.
#[derive(Serialize)]
pub(super) struct ClusterReport<'a> {
    tool: &'static str,
    version: &'static str,
    capture: String,
    frames: &'a [FrameClusters],
}

#[derive(Serialize)]
struct DecoderSettings {
    calibration: String,
    interpolate_azimuth: bool,
    dual: crate::hdl32e::decode::DualSelect,
    cut_angle_deg: f64,
    keep_partial: bool,
}

/// Runs the pipeline on every capture.
pub fn run(args: Args, global: Global) -> Result<()> {
    let (config, warnings) = Config::load(args.config.as_deref(), &args.sets, args.seed)?;
    for w in &warnings {
        global.warn(w);
    }
    if config.noise.is_empty() {
        global.warn(&format!(
            "{}: the configuration has no noise stage; the run measures the clean pipeline",
            config.source.display()
        ));
    }
    let plan = Plan {
        pipeline: Pipeline::new(&config),
        config,
        decoder: args.decoder.to_options()?,
        frames: match &args.frames {
            Some(text) => parse_range("--frames", text)?,
            None => 0..=u32::MAX,
        },
        keep_dropped: args.keep_dropped,
        ply: !args.no_ply,
        output: args.output_format.to_output()?,
        linkage: args.linkage_out,
        pcap_out: args.pcap_out,
        native: args.output_format.format.is_none(),
    };
    super::check_stdin_once(&args.captures)?;
    if plan.pcap_out {
        crate::writers::pcap::check_encodable(plan.pipeline.chain(), plan.config.seed)?;
        if args.captures.iter().any(|p| super::is_stdin(p)) {
            anyhow::bail!("--pcap-out needs capture files: standard input (`-`) is not kept");
        }
        // The noisy capture is a copy of the input read again: a FIFO would wait for ever.
        if let Some(p) = args.captures.iter().find(|p| crate::capture::is_stream(p)) {
            anyhow::bail!(
                "--pcap-out needs capture files: {} is a FIFO or a device, which can be read \
                 only once; save the capture to a file first",
                p.display()
            );
        }
    }
    let mut inputs: Vec<&Path> = args.captures.iter().map(PathBuf::as_path).collect();
    if let Some(c) = &args.config {
        inputs.push(c);
    }
    // A calibration file inside the output folder would be replaced by a report.
    inputs.extend(args.decoder.calibration.as_deref());
    let clouds: Vec<Option<crate::cloud::Format>> =
        args.captures.iter().map(|p| cloud_format(p)).collect();
    if let Some((p, _)) = args.captures.iter().zip(&clouds).find(|(_, c)| c.is_some()) {
        if args.chunk_frames.is_some() {
            anyhow::bail!(
                "--chunk-frames splits captures into frame ranges: {} is a point-cloud scan, \
                 one frame; share many scans among nodes with --shard alone",
                p.display()
            );
        }
        if plan.pcap_out {
            anyhow::bail!(
                "--pcap-out re-encodes a capture's packets: {} is a point-cloud scan, which has \
                 none; leave --pcap-out out (the noisy points are in the point clouds written)",
                p.display()
            );
        }
    }
    if let Some(m) = args.chunk_frames {
        return super::run_chunks::run(&args, &plan, m, &inputs, global);
    }
    // Every input and target is checked before anything is written.
    let mut jobs: Vec<(Source, String, String, Option<&Path>)> = Vec::new();
    if args.captures.is_empty() {
        let reader = FrameReader::from_bytes(
            Arc::from(DEFAULT_CAPTURE),
            Path::new(DEFAULT_CAPTURE_NAME),
            &plan.decoder,
        )?;
        jobs.push((
            Source::Capture(Box::new(reader)),
            DEFAULT_CAPTURE_NAME.into(),
            "crossroad".into(),
            None,
        ));
    }
    for ((path, name), cloud) in args
        .captures
        .iter()
        .zip(super::output_names(&args.captures))
        .zip(&clouds)
    {
        let reader = match cloud {
            Some(format) => Source::Cloud(CloudReader::open(
                path,
                &cloud_options(&args, path, *format)?,
            )?),
            None => Source::Capture(Box::new(super::open_capture(path, &plan.decoder)?)),
        };
        jobs.push((reader, super::capture_label(path), name, Some(path)));
    }
    if let Some(shard) = args.shard {
        let total = jobs.len();
        jobs = jobs
            .into_iter()
            .enumerate()
            .filter(|(i, _)| shard.owns(*i))
            .map(|(_, j)| j)
            .collect();
        if !global.quiet {
            eprintln!(
                "run --shard {shard}: {} of {total} capture{} fall to this shard",
                jobs.len(),
                if total == 1 { "" } else { "s" }
            );
        }
        if jobs.is_empty() {
            return Ok(());
        }
    }
    let check = || -> Result<()> {
        for (reader, source, name, capture) in &jobs {
            if let (true, Source::Capture(reader)) = (plan.pcap_out, reader) {
                let mode = reader.summary().return_mode;
                // Named by the path as given, as in every message of `run`.
                let shown = capture.map_or_else(|| source.clone(), super::capture_shown);
                crate::writers::pcap::check_capture(&shown, mode, plan.decoder.dual)?;
            }
            let target = args.output.join(name);
            check_target(&target, &inputs)?;
            staging::check_replace(
                &target,
                "run",
                &run_settings(&plan, source),
                &is_run_output,
                &|_| false,
                args.force,
                &inputs,
            )?;
        }
        Ok(())
    };
    check()?;
    // Shards of one batch write distinct capture folders side by side.
    let folder = if args.shard.is_some() {
        OutputFolder::lock_shared(&args.output)?
    } else {
        OutputFolder::lock(&args.output)?
    };
    if folder.repaired() {
        // The lock finished a killed run's commit: the folders checked may have changed.
        if let Err(e) = check() {
            folder.abandon();
            return Err(e);
        }
    }
    // Only now, the checks passed: what killed runs of this tool left.
    folder.remove_leftovers(&is_run_path);
    let mut staged = Vec::new();
    let mut reports = Vec::new();
    for (reader, source, name, capture) in jobs {
        let stage = match folder.stage(&name) {
            Ok(s) => s,
            Err(e) => {
                drop(staged);
                folder.abandon();
                return Err(e.into());
            }
        };
        let settings = run_settings(&plan, &source);
        let result = run_capture(
            &plan,
            reader,
            (&source, capture),
            stage.path(),
            &inputs,
            global,
        )
        .and_then(|report| {
            let files = staging::result_files(stage.path());
            staging::write_manifest(stage.path(), "run", &settings, files)?;
            Ok(report)
        });
        match result {
            Ok(report) => {
                staged.push(stage);
                reports.push(report);
            }
            Err(e) => {
                // Staging folders go first, so that a folder this run created is empty.
                drop(stage);
                drop(staged);
                folder.abandon();
                return Err(e);
            }
        }
    }
    let targets: Vec<PathBuf> = staged.iter().map(|s| s.target().to_path_buf()).collect();
    staging::commit(staged)?;
    if !global.quiet {
        for (line, dir) in reports.iter().zip(&targets) {
            eprintln!("{line}; results in {}", dir.display());
        }
    }
    Ok(())
}

/// What decides a capture folder's results: a rerun with the same settings replaces it
/// with the same bytes, other settings are another run (see `staging::check_replace`).
pub(super) fn run_settings(plan: &Plan, source: &str) -> serde_json::Value {
    serde_json::json!({
        "capture": source,
        "config": plan.config.provenance(),
        "effective": plan.config.to_json(),
        "decoder": {
            "calibration": plan.decoder.calibration.source,
            "interpolate_azimuth": plan.decoder.interpolate_azimuth,
            "dual": format!("{:?}", plan.decoder.dual),
            "cut_angle_deg": plan.decoder.cut_angle_deg,
            "keep_partial": plan.decoder.keep_partial,
        },
        "frames": [plan.frames.start(), plan.frames.end()],
        "keep_dropped": plan.keep_dropped,
        "ply": plan.ply,
        "output": format!("{:?}", plan.output),
        "linkage": plan.linkage,
    })
}

/// True for the names `run` writes in a capture folder (for folders without a manifest).
pub(super) fn is_run_output(name: &str) -> bool {
    matches!(
        name,
        "summary.json" | "clusters.json" | "clusters.csv" | "truth.json"
    ) || numbered(
        name,
        "frame_",
        &[
            ".ply",
            ".las",
            ".laz",
            ".pcd.bin",
            ".bin",
            ".pcd",
            ".csv",
            ".fate.csv",
        ],
    ) || numbered(name, "linkage_", &[".csv"])
}

/// True for the paths, relative to a run's output folder, of the files `run` writes
/// (`<capture>/<file>`, parts of `--chunk-frames` included): the clean-up of what killed
/// runs left removes their temporary files only.
pub(super) fn is_run_path(rel: &str) -> bool {
    rel.split_once('/').is_some_and(|(_, f)| {
        !f.contains('/')
            && (is_run_output(f)
                || f == "noisy.pcap"
                || (f.starts_with(".run.chunk") && f.ends_with(".json")))
    })
}

/// True for `<prefix>NNNNN<ext>` with five or more digits and one of `exts`.
pub(crate) fn numbered(name: &str, prefix: &str, exts: &[&str]) -> bool {
    let Some(rest) = name.strip_prefix(prefix) else {
        return false;
    };
    exts.iter().any(|ext| {
        rest.strip_suffix(ext)
            .is_some_and(|d| d.len() >= 5 && d.bytes().all(|b| b.is_ascii_digit()))
    })
}

/// Refuses a target folder that is an input, holds an input or is a file.
pub(super) fn check_target(dir: &Path, inputs: &[&Path]) -> Result<()> {
    crate::writers::atomic::refuse_inputs(dir, inputs)?;
    if dir.exists() && !dir.is_dir() {
        anyhow::bail!("{}: the output is a file, not a folder", dir.display());
    }
    // Replacing the folder would delete an input kept inside it.
    if let Ok(target) = std::fs::canonicalize(dir) {
        for input in inputs {
            if std::fs::canonicalize(input).is_ok_and(|i| i.starts_with(&target)) {
                anyhow::bail!(
                    "{}: refusing to replace a folder that holds an input ({})",
                    dir.display(),
                    input.display()
                );
            }
        }
    }
    Ok(())
}

/// Runs one capture into `dir` (its staging folder); returns the line to print.
fn run_capture(
    plan: &Plan,
    mut reader: Source,
    (source, capture): (&str, Option<&Path>),
    dir: &Path,
    inputs: &[&Path],
    global: Global,
) -> Result<String> {
    let progress = match capture {
        Some(path) => super::frames_progress(global, path, &plan.decoder, &plan.frames),
        None => super::progress(global, "frames"),
    };
    progress.set_message(source.to_string());
    // Per-frame reports are streamed to spool files and joined at the end, so memory
    // does not grow with the capture's length.
    let mut spool = ReportSpool::new(dir, &cluster_document(source), inputs)?;
    // --pcap-out: workers patch the return slots, frames are written as they complete.
    let pcap = if plan.pcap_out {
        use crate::writers::pcap::{NoisyCapture, Source};
        let path = capture.unwrap_or(Path::new(DEFAULT_CAPTURE_NAME));
        let source = capture.map_or(Source::Bytes(Arc::from(DEFAULT_CAPTURE)), |p| {
            Source::File(p.to_path_buf())
        });
        let calibration = &plan.decoder.calibration;
        Some(NoisyCapture::create(
            source,
            path,
            calibration,
            dir,
            inputs,
        )?)
    } else {
        None
    };
    // A scan written back in its own format replaces the frame file.
    let native = plan.native && plan.ply && matches!(reader, Source::Cloud(_));
    // A labelled scan's ground and object scores (one frame), for truth.json.
    let truth = match &mut reader {
        Source::Cloud(r) => r.take_truth(),
        Source::Capture(_) => None,
    };
    let scored = std::sync::Mutex::new(None);
    let work = |f: Frame| -> Result<(SpoolEntry, Vec<crate::frame::Return>, Vec<ScanPoint>)> {
        let result = plan.pipeline.process(f)?;
        if let Some(t) = &truth {
            let bands = &crate::sweep::metrics::DEFAULT_BANDS;
            *scored.lock().expect("no panic holds it") =
                Some(t.score(&result, plan.config.cluster.min_points, bands));
        }
        if let Some(p) = &pcap {
            p.encode_frame(&result.noisy);
        }
        let rows = if native {
            scan_points(&result)
        } else {
            Vec::new()
        };
        let (entry, returns) = frame_outputs(plan, result, source, dir, inputs, !native)?;
        Ok((entry, returns, rows))
    };
    // Frames arrive here in order: the noisy capture can be written up to this one.
    let mut done = |entry: SpoolEntry| -> Result<()> {
        if let Some(p) = &pcap {
            p.frame_done(entry.report.index)?;
        }
        spool.add(entry)?;
        progress.inc(1);
        Ok(())
    };
    let warmup = crate::memory::worker_warmup_bytes();
    match &mut reader {
        Source::Capture(r) => stream_frames(
            &mut **r,
            &plan.frames,
            warmup,
            work,
            |(e, returns, _), r| {
                r.recycle(Frame {
                    returns,
                    ..Frame::default()
                });
                done(e)
            },
        )?,
        Source::Cloud(r) => {
            stream_frames(r, &plan.frames, warmup, work, |(e, _, rows), r| {
                if native {
                    write_scan(r, rows, e.report.index, dir, inputs)?;
                }
                done(e)
            })?;
        }
    }
    progress.finish_and_clear();
    // Messages name the capture by the path as given, as `convert`'s do; the outputs name
    // it by `source`, its file name, so that they do not depend on the working folder.
    let shown = capture.map_or_else(|| source.to_string(), super::capture_shown);
    let capture_summary;
    let source_summary = match &mut reader {
        Source::Capture(r) => {
            capture_summary = r.summary();
            super::warn_truncation(global, Path::new(&shown), &capture_summary);
            super::warn_capture(
                global,
                Path::new(&shown),
                &capture_summary,
                plan.config.sensor.intensity == crate::config::IntensityMode::Reflectivity,
            );
            if spool.frames == 0 {
                return Err(no_frame_error(&shown, &plan.frames, r));
            }
            SourceSummary::Capture(&capture_summary)
        }
        Source::Cloud(r) => {
            if spool.frames == 0 {
                anyhow::bail!(
                    "{shown}: no frame to process in {}: a point-cloud scan is one frame, 0",
                    crate::options::frames_phrase(&plan.frames)
                );
            }
            SourceSummary::Cloud(r.summary())
        }
    };
    let (summary, _) = documents(plan, source, source_summary, spool.totals.clone());
    let frames = spool.frames;
    if let Some(p) = pcap {
        let name = p.file_name();
        let lost = p.finish()?;
        if lost > 0 {
            global.warn(&format!(
                "{shown}: {lost} kept returns lie outside the range a packet can hold \
                 (0 to 131.07 m) and are written as no return in {name}"
            ));
        }
    }
    if let Some(s) = scored.into_inner().expect("no panic holds it") {
        let path = dir.join("truth.json");
        crate::writers::atomic::write_atomically(&path, inputs, |out| {
            serde_json::to_writer_pretty(&mut *out, &s).map_err(std::io::Error::other)
        })?;
    }
    spool.finish(&summary, dir, inputs)?;
    Ok(report_line(&shown, frames, &summary.totals))
}

/// The capture's summary.json and clusters.json, with empty `frames` arrays (the frames
/// are spooled and joined in, see [`join_document`]).
pub(super) fn documents<'a>(
    plan: &'a Plan,
    source: &str,
    capture_summary: SourceSummary<'a>,
    totals: Totals,
) -> (Summary<'a>, ClusterReport<'a>) {
    let summary = Summary {
        tool: "lidar-noise",
        version: env!("CARGO_PKG_VERSION"),
        capture: source.to_string(),
        config: plan.config.provenance(),
        settings: plan.config.effective(),
        power_constants: plan.pipeline.chain().ideal_power().constants(),
        decoder: DecoderSettings {
            calibration: plan.decoder.calibration.source.clone(),
            interpolate_azimuth: plan.decoder.interpolate_azimuth,
            dual: plan.decoder.dual,
            cut_angle_deg: plan.decoder.cut_angle_deg,
            keep_partial: plan.decoder.keep_partial,
        },
        fate_codes: FATE_CODES,
        capture_summary,
        totals,
        frames: &[],
    };
    (summary, cluster_document(source))
}

/// The capture's clusters.json with an empty `frames` array: it depends on nothing but
/// the capture's name, so a run writes its head first and streams the frames after it.
fn cluster_document(source: &str) -> ClusterReport<'static> {
    ClusterReport {
        tool: "lidar-noise",
        version: env!("CARGO_PKG_VERSION"),
        capture: source.to_string(),
        frames: &[],
    }
}

/// The line a run prints for a capture.
pub(super) fn report_line(source: &str, frames: usize, t: &Totals) -> String {
    let sp = t.noise.spurious;
    // Spurious echoes are reported apart, so "kept" never exceeds the recorded returns.
    let echoes = if sp.is_empty() {
        String::new()
    } else {
        format!(
            ", plus {} replaced by and {} added as spurious echoes",
            sp.replaced, sp.added
        )
    };
    format!(
        "{source}: {} frame{}, {} of {} returns kept ({} occluded, {} below power, {} below \
         min range){echoes}, {:.1} % ground, {} clusters",
        frames,
        if frames == 1 { "" } else { "s" },
        t.noise.returns_out - sp.replaced - sp.added,
        t.noise.returns_in,
        t.noise.dropped.occluded,
        t.noise.dropped.below_power,
        t.noise.dropped.below_min_range,
        100.0 * t.ground_fraction,
        t.stages.clusters,
    )
}

/// The error for a `--frames` range with no frame to process, naming the capture's full
/// frames (the reader stopped at the end of the range, so it reads on to count them).
pub(super) fn no_frame_error(
    source: &str,
    frames: &RangeInclusive<u32>,
    reader: &mut FrameReader,
) -> anyhow::Error {
    for frame in reader.by_ref() {
        if let Err(e) = frame {
            return e.into();
        }
    }
    let s = reader.summary();
    let full = s.full_frames;
    let (first, last) = if s.partial_frames > 0 {
        (1, full)
    } else {
        (0, full.saturating_sub(1))
    };
    let partial_note = if *frames.start() == 0 && *frames.end() == 0 {
        "frame 0 is the partial first sweep (add --keep-partial to process it); "
    } else {
        ""
    };
    anyhow::anyhow!(
        "{source}: no frame to process in {}: {partial_note}the capture has {} \
         full frame{} ({}); pick others with --frames or add --keep-partial",
        crate::options::frames_phrase(frames),
        full,
        if full == 1 { "" } else { "s" },
        if full == 0 {
            "none".to_string()
        } else {
            format!("indexes {first}..{last}")
        }
    )
}

/// Writes a processed frame's own files (point cloud, linkage) into `dir` and returns its
/// report pieces and the frame's return buffer (for the reader to reuse).
pub(super) fn frame_outputs(
    plan: &Plan,
    mut result: FrameResult,
    source: &str,
    dir: &Path,
    inputs: &[&Path],
    frame_file: bool,
) -> Result<(SpoolEntry, Vec<crate::frame::Return>)> {
    let clusters = FrameClusters {
        index: result.noisy.index,
        clusters: std::mem::take(&mut result.clusters),
    };
    let r = &result;
    // The frame file and the reports are a fork an idle worker may take (see
    // `crate::par::join`); the frame file's error comes first, as when they run in turn.
    let (ply, reports) = crate::par::join(
        || {
            if plan.ply && frame_file {
                write_ply(plan, r, source, dir, inputs)?;
            }
            Ok::<(), anyhow::Error>(())
        },
        || {
            if plan.linkage {
                write_linkage(plan, r, dir, inputs)?;
            }
            SpoolEntry::of(FrameReport::of(r), &clusters)
        },
    );
    ply?;
    let entry = reports?;
    // The frame's buffer goes back to the reader for the next frame.
    Ok((entry, result.noisy.clean))
}

/// Runs `work` on every frame in `frames` as a bounded pipeline: the calling thread
/// decodes frames and hands them to `options::worker_threads()` workers, and hands
/// each result to `done` (with the reader, to recycle buffers) in frame order as soon as
/// every earlier frame's is in. Decoding, processing (with each frame's own files) and the
/// ordered report append overlap, with no barrier between groups of frames: a slow frame
/// holds back only the report append, never the workers. At most `workers + 2` frames
/// are in flight (decoded, queued, processed or waiting for an earlier one), so memory
/// stays bounded whatever the capture's length. Errors come in frame order: a frame's
/// processing error before a decoding error further on; after the first error no new
/// frame is started.
///
/// The workers are the threads of one rayon pool, one frame loop each, so that `work`'s
/// forks ([`crate::par::join`]) can be taken by a worker that has no frame left: at the
/// end of a capture the last frames then use every core, not one frame per core.
pub(crate) fn stream_frames<T: Send, R: FrameSource>(
    reader: &mut R,
    frames: &RangeInclusive<u32>,
    warmup: usize,
    work: impl Fn(Frame) -> Result<T> + Sync,
    mut done: impl FnMut(T, &mut R) -> Result<()>,
) -> Result<()> {
    use std::collections::BTreeMap;
    use std::panic::AssertUnwindSafe;
    use std::sync::atomic::{AtomicBool, Ordering};
    use std::sync::{mpsc, Mutex};
    let workers = crate::options::worker_threads();
    // A worker that finishes needs one decoded frame ready, and one more lets a frame
    // finish before an earlier one without idling a worker; frames decoded further ahead
    // only hold memory (3.3 MB each), whose first-touched pages cost CPU time: on the
    // shared capture `2 x workers + 1` (5 at 2 workers) peaked at 68-71 MB and took 1-4 %
    // more CPU than this (66 MB) in four interleaved comparisons.
    let window = workers + 2;
    // A pool of its own, of exactly `workers` threads: the global pool may have another
    // size (set before `--threads` was read) and would also take other rayon work.
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(workers)
        .build()
        .with_context(|| format!("cannot start {workers} worker threads"))?;
    let (frame_tx, frame_rx) = mpsc::sync_channel::<(usize, Frame)>(workers);
    let frame_rx = Mutex::new(frame_rx);
    // A worker's panic travels to the calling thread and resumes there.
    type Outcome<T> = std::thread::Result<Result<T>>;
    let (result_tx, result_rx) = mpsc::channel::<(usize, Outcome<T>)>();
    // Set on the first error: queued frames are then skipped, not processed.
    let stop = AtomicBool::new(false);
    // The calling thread is no thread of the pool: it decodes and keeps frame order while
    // the pool's threads run the frames (and, when idle, the forks of other frames).
    pool.in_place_scope(|scope| -> Result<()> {
        let (frame_rx, result_tx, work, stop) = (&frame_rx, &result_tx, &work, &stop);
        // One frame loop on each thread of the pool (a broadcast, so that no thread can
        // run a second loop inside a fork it waits for).
        scope.spawn_broadcast(move |_, ctx| {
            let result_tx = result_tx.clone();
            // Until its first frame, the worker faults in `warmup` bytes of its heap (see
            // `HeapWarmer`); only the first `WARMED_WORKERS` do.
            let bytes = if ctx.index() < WARMED_WORKERS {
                warmup
            } else {
                0
            };
            let mut warmer = crate::memory::HeapWarmer::new(bytes);
            loop {
                let next = next_frame(frame_rx, &mut warmer);
                let Ok((seq, frame)) = next else {
                    return;
                };
                if stop.load(Ordering::Relaxed) {
                    continue;
                }
                let outcome = std::panic::catch_unwind(AssertUnwindSafe(|| work(frame)));
                if result_tx.send((seq, outcome)).is_err() {
                    return;
                }
            }
        });
        let mut frame_tx = Some(frame_tx);
        // Results that arrived before an earlier frame's, by sequence number.
        let mut pending: BTreeMap<usize, Outcome<T>> = BTreeMap::new();
        let (mut sent, mut finished) = (0usize, 0usize);
        let mut decode_error: Option<anyhow::Error> = None;
        // Hands over every result whose predecessors are all in.
        let mut drain =
            |pending: &mut BTreeMap<usize, Outcome<T>>, finished: &mut usize, reader: &mut R| {
                while let Some(outcome) = pending.remove(finished) {
                    *finished += 1;
                    let result = outcome.unwrap_or_else(|panic| std::panic::resume_unwind(panic));
                    if let Err(e) = result.and_then(|r| done(r, reader)) {
                        stop.store(true, Ordering::Relaxed);
                        return Err(e);
                    }
                }
                Ok::<(), anyhow::Error>(())
            };
        loop {
            // Decode ahead while the window has room.
            while frame_tx.is_some() && sent - finished < window {
                match reader.next_batch(1, frames) {
                    Ok(mut batch) => match batch.pop() {
                        Some(frame) => {
                            let tx = frame_tx.as_ref().expect("checked above");
                            // The workers only leave once the queue is closed.
                            tx.send((sent, frame)).expect("workers are running");
                            sent += 1;
                        }
                        None => {
                            frame_tx = None;
                        }
                    },
                    Err(e) => {
                        decode_error = Some(e.into());
                        frame_tx = None;
                    }
                }
                // Reports go out between decodes, not only when the window is full.
                while let Ok((seq, result)) = result_rx.try_recv() {
                    pending.insert(seq, result);
                }
                if let Err(e) = drain(&mut pending, &mut finished, reader) {
                    drop(frame_tx.take());
                    return Err(e);
                }
            }
            if finished == sent {
                break;
            }
            let (seq, result) = result_rx
                .recv()
                .expect("a worker holds every unfinished frame");
            pending.insert(seq, result);
            if let Err(e) = drain(&mut pending, &mut finished, reader) {
                drop(frame_tx.take());
                return Err(e);
            }
        }
        decode_error.map_or(Ok(()), Err)
    })
}

/// Workers of [`stream_frames`] that warm their heaps. Why a bound: a worker with no
/// frame to come (a capture of fewer frames than workers) warms its whole block, so on a
/// machine of many cores the warm-up would add that much memory per core; four bound it
/// at four blocks (48 MB at 12 MB a worker) and cover the machines it was measured on.
const WARMED_WORKERS: usize = 4;

/// The next item off the workers' queue. While `warmer` has pages left and no item is
/// ready, it warms one slice between polls; it is dropped (its pages handed back to the
/// heap) before an item is returned. The lock is held only while taking one item.
fn next_frame<T>(
    rx: &std::sync::Mutex<std::sync::mpsc::Receiver<T>>,
    warmer: &mut Option<crate::memory::HeapWarmer>,
) -> Result<T, std::sync::mpsc::RecvError> {
    use std::sync::mpsc::{RecvError, TryRecvError};
    use std::sync::TryLockError;
    while let Some(w) = warmer.as_mut() {
        let polled = match rx.try_lock() {
            Ok(rx) => rx.try_recv(),
            Err(TryLockError::Poisoned(e)) => e.into_inner().try_recv(),
            // The other worker waits on the queue: nothing for this one yet.
            Err(TryLockError::WouldBlock) => Err(TryRecvError::Empty),
        };
        if let Err(TryRecvError::Empty) = polled {
            if !w.step() {
                *warmer = None;
            }
        } else {
            // An item, or the queue closed: either way the warm-up is over.
            *warmer = None;
            return polled.map_err(|_| RecvError);
        }
    }
    rx.lock().unwrap_or_else(|e| e.into_inner()).recv()
}

/// Per-frame reports written to disk as they come (summary frames, cluster frames and
/// cluster CSV rows), with the totals kept as a running sum.
struct ReportSpool {
    summary_frames: std::io::BufWriter<std::fs::File>,
    /// clusters.json itself: its head needs nothing the frames decide, so the frames go
    /// straight into the final file instead of a spool that is copied at the end.
    clusters: crate::writers::atomic::AtomicFile,
    csv_rows: std::io::BufWriter<std::fs::File>,
    totals: Totals,
    frames: usize,
}

/// One frame's report pieces, serialised by the worker that processed the frame so that
/// only the writing is left to the thread that keeps frame order.
pub(super) struct SpoolEntry {
    pub(super) report: FrameReport,
    pub(super) summary: Vec<u8>,
    pub(super) clusters: Vec<u8>,
    pub(super) csv: Vec<u8>,
}

impl SpoolEntry {
    fn of(report: FrameReport, clusters: &FrameClusters) -> Result<Self> {
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
    fn new(dir: &Path, clusters: &ClusterReport, inputs: &[&Path]) -> Result<Self> {
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

    fn add(&mut self, entry: SpoolEntry) -> Result<()> {
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
    fn finish<S: Serialize>(self, summary: &S, dir: &Path, inputs: &[&Path]) -> Result<()> {
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
pub(super) fn join_with<T: Serialize>(
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

fn write_ply(
    plan: &Plan,
    r: &FrameResult,
    source: &str,
    dir: &Path,
    inputs: &[&Path],
) -> Result<()> {
    let ground: Vec<u8> = r.ground.iter().map(|&g| u8::from(g)).collect();
    let path = dir.join(plan.output.file_name(r.noisy.index));
    let mut comments = vec![
        format!("config {}", plan.config.provenance()),
        format!("seed {}", plan.config.seed),
        format!(
            "fate codes: {}",
            FATE_CODES
                .iter()
                .enumerate()
                .map(|(i, c)| format!("{i} {c}"))
                .collect::<Vec<_>>()
                .join(", ")
        ),
        "cause: index of the stage in the noise chain that decided the fate, 255 none or the \
         detection filters; range_clean 0 for added returns"
            .into(),
        "range is after noise, range_clean before; power is a fraction of emitted power".into(),
        "cluster -1 is ground or noise".into(),
    ];
    // The whole effective configuration, so that it can be rebuilt from the file alone.
    comments.extend(
        plan.config
            .effective_toml()
            .lines()
            .filter(|l| !l.trim().is_empty())
            .map(|l| format!("effective-config {l}")),
    );
    let start = r.noisy.clean.first().map_or(0.0, |c| c.time);
    if plan.keep_dropped {
        // Every return: kept ones at their noisy position, dropped ones where they were.
        let mut returns = r.noisy.clean.clone();
        let mut ground_all = vec![0u8; returns.len()];
        let mut cluster_all = vec![-1i32; returns.len()];
        for (s, &k) in r.kept.iter().enumerate() {
            returns[k as usize] = r.survivors[s];
            ground_all[k as usize] = ground[s];
            cluster_all[k as usize] = r.labels[s];
        }
        let range_clean: Vec<f32> = (0..r.noisy.len()).map(|i| clean_range(r, i)).collect();
        let power: Vec<f32> = r.noisy.power.iter().map(|&p| p as f32).collect();
        let fate: Vec<u8> = r.noisy.fate.iter().map(|&f| f as u8).collect();
        let ply = PlyFrame {
            columns: PlyColumns {
                range_clean: Some(&range_clean),
                power: Some(&power),
                fate: Some(&fate),
                cause: Some(&r.noisy.cause),
                ground: Some(&ground_all),
                cluster: Some(&cluster_all),
            },
            comments: &comments,
            ..PlyFrame::new(&returns, source, r.noisy.index, start)
        };
        write_file(&*plan.output.document(ply), &path, inputs)?;
    } else {
        let range_clean: Vec<f32> = r.kept.iter().map(|&k| clean_range(r, k as usize)).collect();
        let power: Vec<f32> = r
            .kept
            .iter()
            .map(|&k| r.noisy.power[k as usize] as f32)
            .collect();
        // Chains that can report spurious echoes say which points are echoes; the
        // columns depend on the configuration only, never on the data.
        let echoes = plan.pipeline.chain().proposes_echoes();
        let (fate, cause): (Vec<u8>, Vec<u8>) = if echoes {
            r.kept
                .iter()
                .map(|&k| (r.noisy.fate[k as usize] as u8, r.noisy.cause[k as usize]))
                .unzip()
        } else {
            (Vec::new(), Vec::new())
        };
        let ply = PlyFrame {
            columns: PlyColumns {
                range_clean: Some(&range_clean),
                power: Some(&power),
                fate: echoes.then_some(&fate[..]),
                cause: echoes.then_some(&cause[..]),
                ground: Some(&ground),
                cluster: Some(&r.labels),
            },
            comments: &comments,
            ..PlyFrame::new(&r.survivors, source, r.noisy.index, start)
        };
        write_file(&*plan.output.document(ply), &path, inputs)?;
    }
    Ok(())
}

/// Range of return `i` before noise: 0 for a return a stage added (it has no clean origin).
/// The kept returns of a processed scan as points to write back (`point` is the return's
/// index in the frame until [`write_scan`] maps it to the input's).
fn scan_points(r: &FrameResult) -> Vec<ScanPoint> {
    r.kept
        .iter()
        .zip(&r.survivors)
        .zip(r.ground.iter().zip(&r.labels))
        .map(|((&k, s), (&g, &cluster))| {
            let k = k as usize;
            ScanPoint {
                x: s.x,
                y: s.y,
                z: s.z,
                intensity: s.intensity,
                ring: u16::from(s.ring),
                point: (k < r.noisy.clean_len).then_some(k as u32),
                fate: r.noisy.fate[k] as u8,
                cause: r.noisy.cause[k],
                range_clean: clean_range(r, k),
                ground: u8::from(g),
                cluster,
            }
        })
        .collect()
}

/// Writes frame `index` of a scan back in the scan's own format, in the input's point
/// order (echoes the noise added after the recorded points), with its sidecar of fates.
fn write_scan(
    reader: &CloudReader,
    mut rows: Vec<ScanPoint>,
    index: u32,
    dir: &Path,
    inputs: &[&Path],
) -> Result<()> {
    use crate::writers::scan::{extension, Fates, Scan};
    let order = reader.order();
    for p in &mut rows {
        p.point = p.point.and_then(|k| order.get(k as usize).copied());
    }
    // Recorded points in input order, then added echoes in return order (stable).
    rows.sort_by_key(|p| p.point.map_or((1, 0), |i| (0, i)));
    let format = reader.format();
    let stem = format!("frame_{index:05}");
    let scan = Scan {
        format,
        points: &rows,
    };
    write_file(
        &scan,
        &dir.join(format!("{stem}.{}", extension(format))),
        inputs,
    )?;
    write_file(
        &Fates { points: &rows },
        &dir.join(format!("{stem}.fate.csv")),
        inputs,
    )?;
    Ok(())
}

fn clean_range(r: &FrameResult, i: usize) -> f32 {
    if i < r.noisy.clean_len {
        r.noisy.clean[i].range
    } else {
        0.0
    }
}

fn write_linkage(plan: &Plan, r: &FrameResult, dir: &Path, inputs: &[&Path]) -> Result<()> {
    let points: Vec<[f32; 3]> = r
        .survivors
        .iter()
        .zip(&r.ground)
        .filter(|(_, &g)| !g)
        .map(|(s, _)| [s.x, s.y, s.z])
        .collect();
    let z = crate::cluster::linkage(&points, plan.config.cluster.max_edge_m)?;
    let path = dir.join(format!("linkage_{:05}.csv", r.noisy.index));
    crate::writers::atomic::write_atomically(&path, inputs, |out| {
        crate::cluster::write_linkage_csv(out, &z)
    })?;
    Ok(())
}
