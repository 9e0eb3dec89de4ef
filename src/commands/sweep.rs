//! `lidar-noise sweep`: every combination of varied settings and seeds over captures.

use crate::cli::{Console, Global};
use crate::options::DecoderArgs;
use anyhow::Result;
use lidar_noise::range::{parse_range, ALL_FRAMES};
use lidar_noise::sweep::folder::SweepRequest;
use lidar_noise::sweep::plan::{parse_bands, parse_seeds, Vary};
use std::path::PathBuf;

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
    pub figure_format: lidar_noise::writers::figure::FigureFormat,
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
    #[arg(long, value_name = "K/N", value_parser = lidar_noise::shard::Shard::parse, conflicts_with = "merge")]
    pub shard: Option<lidar_noise::shard::Shard>,
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

/// Runs the sweep and writes every output.
pub fn run(args: Args, global: Global) -> Result<()> {
    let request = SweepRequest {
        varies: args
            .varies
            .iter()
            .map(|v| Vary::parse(v))
            .collect::<lidar_noise::error::Result<_>>()?,
        interactions: args.interactions,
        seeds: args.seeds.as_deref().map(parse_seeds).transpose()?,
        frames: match &args.frames {
            Some(text) => parse_range("--frames", text)?,
            None => ALL_FRAMES,
        },
        bands: parse_bands(&args.bands)?,
        decoder: args.decoder.to_options()?,
        protected: args.decoder.calibration.iter().cloned().collect(),
        figure_frame: args.figure_frame,
        figure_extent: args.figure_extent,
        figure_format: args.figure_format,
        force: args.force,
        shard: args.shard,
        merge: args.merge,
        chunk_frames: args.chunk_frames,
        labels: args.labels,
        sets: args.sets,
        config: args.config,
        ..SweepRequest::new(args.captures, args.output)
    };
    lidar_noise::sweep::folder::sweep(&request, &Console::new(global))
}
