//! `lidar-noise run`: the whole pipeline on one or more captures.

use crate::cli::Global;
use crate::config::Config;
use crate::hdl32e::frames::{CaptureSummary, DecoderOptions, FrameReader};
use crate::options::{parse_range, DecoderArgs, FrameOutputArgs};
use crate::pipeline::report::{cluster_table, FrameClusters, FrameReport, Totals, FATE_CODES};
use crate::pipeline::{FrameResult, Pipeline};
use crate::writers::json::JsonDoc;
use crate::writers::ply::{PlyColumns, PlyFrame};
use crate::writers::{write_file, FrameOutput};
use anyhow::{Context, Result};
use rayon::prelude::*;
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
    /// Capture files (pcap or pcapng), `-` for standard input; none runs the built-in
    /// crossroad fixture.
    #[arg(value_name = "CAPTURE")]
    pub captures: Vec<PathBuf>,
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
    #[arg(long)]
    pub linkage_out: bool,
    /// Decoder settings shared by the commands that read captures.
    #[command(flatten)]
    pub decoder: DecoderArgs,
}

/// Validated settings of a run.
struct Plan {
    config: Config,
    pipeline: Pipeline,
    decoder: DecoderOptions,
    frames: RangeInclusive<u32>,
    keep_dropped: bool,
    ply: bool,
    output: FrameOutput,
    linkage: bool,
}

/// The per-capture summary written as summary.json.
#[derive(Serialize)]
struct Summary<'a> {
    tool: &'static str,
    version: &'static str,
    capture: String,
    config: String,
    settings: crate::config::EffectiveConfig<'a>,
    power_constants: &'a crate::noise::PowerConstants,
    decoder: DecoderSettings,
    fate_codes: [&'static str; 4],
    capture_summary: &'a CaptureSummary,
    totals: Totals,
    frames: &'a [FrameReport],
}

/// The cluster report written as clusters.json.
#[derive(Serialize)]
struct ClusterReport<'a> {
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
    };
    super::check_stdin_once(&args.captures)?;
    let mut inputs: Vec<&Path> = args.captures.iter().map(PathBuf::as_path).collect();
    if let Some(c) = &args.config {
        inputs.push(c);
    }
    if args.captures.is_empty() {
        let dir = args.output.join("crossroad");
        let reader = FrameReader::from_bytes(
            Arc::from(DEFAULT_CAPTURE),
            Path::new(DEFAULT_CAPTURE_NAME),
            &plan.decoder,
        )?;
        run_capture(&plan, reader, DEFAULT_CAPTURE_NAME, &dir, &inputs, global)?;
    }
    for (path, name) in args
        .captures
        .iter()
        .zip(super::output_names(&args.captures))
    {
        let reader = super::open_capture(path, &plan.decoder)?;
        let dir = args.output.join(&name);
        run_capture(
            &plan,
            reader,
            &super::capture_label(path),
            &dir,
            &inputs,
            global,
        )?;
    }
    Ok(())
}

fn run_capture(
    plan: &Plan,
    mut reader: FrameReader,
    source: &str,
    dir: &Path,
    inputs: &[&Path],
    global: Global,
) -> Result<()> {
    std::fs::create_dir_all(dir)
        .with_context(|| format!("cannot create the output folder {}", dir.display()))?;
    let progress = super::progress(global, "frames");
    progress.set_message(source.to_string());
    // Frames are processed in batches in parallel; results are written in frame order,
    // and memory stays bounded by one batch whatever the capture's length.
    let batch_size = 2 * rayon::current_num_threads().max(1);
    let mut frame_reports = Vec::new();
    let mut frame_clusters = Vec::new();
    loop {
        let batch = reader.next_batch(batch_size, &plan.frames)?;
        if batch.is_empty() {
            break;
        }
        let results: Vec<crate::error::Result<FrameResult>> = batch
            .into_par_iter()
            .map(|f| plan.pipeline.process(f))
            .collect();
        for result in results {
            let result = result?;
            if plan.ply {
                write_ply(plan, &result, source, dir, inputs)?;
            }
            if plan.linkage {
                write_linkage(plan, &result, dir, inputs)?;
            }
            frame_reports.push(FrameReport::of(&result));
            frame_clusters.push(FrameClusters {
                index: result.noisy.index,
                clusters: result.clusters,
            });
            progress.inc(1);
        }
    }
    progress.finish_and_clear();
    let capture_summary = reader.summary();
    super::warn_truncation(global, Path::new(source), &capture_summary);
    if frame_reports.is_empty() {
        anyhow::bail!(
            "{source}: no frame to process (the capture has {} full frames); pick others with \
             --frames or add --keep-partial",
            capture_summary.full_frames
        );
    }
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
        capture_summary: &capture_summary,
        totals: Totals::of(&frame_reports),
        frames: &frame_reports,
    };
    write_file(&JsonDoc(&summary), &dir.join("summary.json"), inputs)?;
    let clusters = ClusterReport {
        tool: "lidar-noise",
        version: env!("CARGO_PKG_VERSION"),
        capture: source.to_string(),
        frames: &frame_clusters,
    };
    write_file(&JsonDoc(&clusters), &dir.join("clusters.json"), inputs)?;
    write_file(
        &cluster_table(&frame_clusters),
        &dir.join("clusters.csv"),
        inputs,
    )?;
    if !global.quiet {
        let t = &summary.totals;
        eprintln!(
            "{source}: {} frames, {} of {} returns kept ({} occluded, {} below power, {} below \
             min range), {:.1} % ground, {} clusters; results in {}",
            frame_reports.len(),
            t.noise.returns_out,
            t.noise.returns_in,
            t.noise.dropped.occluded,
            t.noise.dropped.below_power,
            t.noise.dropped.below_min_range,
            100.0 * t.ground_fraction,
            t.stages.clusters,
            dir.display()
        );
    }
    Ok(())
}

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
            "fate codes: 0 {}, 1 {}, 2 {}, 3 {}",
            FATE_CODES[0], FATE_CODES[1], FATE_CODES[2], FATE_CODES[3]
        ),
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
        let range_clean: Vec<f32> = r.noisy.clean.iter().map(|c| c.range).collect();
        let power: Vec<f32> = r.noisy.power.iter().map(|&p| p as f32).collect();
        let fate: Vec<u8> = r.noisy.fate.iter().map(|&f| f as u8).collect();
        let ply = PlyFrame {
            columns: PlyColumns {
                range_clean: Some(&range_clean),
                power: Some(&power),
                fate: Some(&fate),
                ground: Some(&ground_all),
                cluster: Some(&cluster_all),
            },
            comments: &comments,
            ..PlyFrame::new(&returns, source, r.noisy.index, start)
        };
        write_file(&*plan.output.document(ply), &path, inputs)?;
    } else {
        let range_clean: Vec<f32> = r
            .kept
            .iter()
            .map(|&k| r.noisy.clean[k as usize].range)
            .collect();
        let power: Vec<f32> = r
            .kept
            .iter()
            .map(|&k| r.noisy.power[k as usize] as f32)
            .collect();
        let ply = PlyFrame {
            columns: PlyColumns {
                range_clean: Some(&range_clean),
                power: Some(&power),
                fate: None,
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
