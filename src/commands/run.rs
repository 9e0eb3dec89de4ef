//! `lidar-noise run`: parses its arguments into the engine's plain options and calls
//! [`lidar_noise::engine::run`], which streams every input through the pipeline.

use crate::cli::Global;
use crate::options::{DecoderArgs, FrameOutputArgs};
use anyhow::Result;
use lidar_noise::config::Config;
use lidar_noise::engine::{Plan, RunRequest};
use lidar_noise::pipeline::Pipeline;
use lidar_noise::range::parse_range;
use std::path::PathBuf;

/// Output folder when `-o` is not given.
pub const DEFAULT_OUTPUT: &str = "lidar-noise-out";

/// Arguments of `run`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Capture files (pcap or pcapng), `-` for standard input, or point-cloud scans
    /// (nuScenes .pcd.bin, KITTI .bin, PCD, CSV: one frame each), or one dataset folder (a
    /// KITTI sequence with velodyne/*.bin, a nuScenes samples/LIDAR_TOP with *.pcd.bin:
    /// written back in its own layout); none runs the built-in crossroad fixture.
    #[arg(value_name = "CAPTURE")]
    pub captures: Vec<PathBuf>,
    /// Sensor that recorded the point-cloud scans given (captures are told by their
    /// packets): hdl32e, vlp16, puck-hi-res, vlp32c, hdl64e, hdl64e-s3, hdl64e-kitti,
    /// vls128. Default: hdl64e-kitti (KITTI's unit) for KITTI .bin scans, hdl32e for
    /// every other format.
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
    /// captures in the order given; over a dataset folder's scans sorted by name), e.g.
    /// --shard $SLURM_ARRAY_TASK_ID/$SLURM_ARRAY_TASK_COUNT.
    #[arg(long, value_name = "K/N", value_parser = lidar_noise::shard::Shard::parse)]
    pub shard: Option<lidar_noise::shard::Shard>,
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
    let request = RunRequest {
        protected: args
            .config
            .iter()
            .chain(&args.decoder.calibration)
            .cloned()
            .collect(),
        captures: args.captures,
        output: args.output,
        force: args.force,
        shard: args.shard,
        chunk_frames: args.chunk_frames,
        merge: args.merge,
        sensor: args.sensor,
        rotation_hz: args.rotation_hz,
        labels: args.labels,
    };
    lidar_noise::engine::run(&plan, &request, &crate::cli::Console::new(global))
}
