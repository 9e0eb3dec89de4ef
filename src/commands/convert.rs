//! `lidar-noise convert`: one PLY per frame.

use crate::cli::Global;
use crate::options::DecoderArgs;
use anyhow::Result;
use std::path::PathBuf;

/// Arguments of `convert`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Capture file (pcap or pcapng).
    #[arg(value_name = "CAPTURE")]
    pub capture: PathBuf,
    /// Output folder (created if missing).
    #[arg(short, long, value_name = "DIR")]
    pub output: PathBuf,
    /// Frames to write, by sweep index: N, A..B (inclusive), A.. or ..B.
    #[arg(long, value_name = "RANGE")]
    pub frames: Option<String>,
    /// Write ASCII PLY instead of binary little-endian.
    #[arg(long)]
    pub ascii: bool,
    #[command(flatten)]
    pub decoder: DecoderArgs,
}

/// Decodes the capture and writes the selected frames.
pub fn run(_args: Args, _global: Global) -> Result<()> {
    anyhow::bail!("convert is not implemented yet")
}
