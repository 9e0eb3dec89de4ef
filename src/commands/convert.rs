//! `lidar-noise convert`: one PLY per frame.

use crate::cli::Global;
use crate::hdl32e::frames::FrameReader;
use crate::options::{parse_range, DecoderArgs};
use crate::writers::ply::{PlyEncoding, PlyFrame};
use crate::writers::staging::{self, OutputFolder};
use crate::writers::write_file;
use anyhow::Result;
use std::path::{Path, PathBuf};

/// Arguments of `convert`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Capture file (pcap or pcapng).
    #[arg(value_name = "CAPTURE")]
    pub capture: PathBuf,
    /// Output folder (created if missing); frames are written as frame_NNNNN.ply.
    #[arg(short, long, value_name = "DIR")]
    pub output: PathBuf,
    /// Frames to write, by sweep index: N, A..B (both included), A.. or ..B.
    #[arg(long, value_name = "RANGE")]
    pub frames: Option<String>,
    /// Write ASCII PLY instead of binary little-endian.
    #[arg(long)]
    pub ascii: bool,
    /// Decoder settings shared by the commands that read captures.
    #[command(flatten)]
    pub decoder: DecoderArgs,
}

/// File name of a frame's PLY.
pub fn frame_file_name(index: u32) -> String {
    format!("frame_{index:05}.ply")
}

/// Decodes the capture and writes the selected frames.
pub fn run(args: Args, global: Global) -> Result<()> {
    let options = args.decoder.to_options()?;
    let range = match &args.frames {
        Some(text) => parse_range("--frames", text)?,
        None => 0..=u32::MAX,
    };
    let reader = FrameReader::open(&args.capture, &options)?;
    // Frames are written into a staging folder and moved into place only when all are
    // written: a failed or interrupted convert leaves no frame behind.
    let folder = OutputFolder::lock(&args.output)?;
    let stage = match folder.stage("convert") {
        Ok(s) => s,
        Err(e) => {
            folder.abandon();
            return Err(e.into());
        }
    };
    match convert(&args, global, reader, &range, stage.path()) {
        Ok(written) => {
            staging::commit_files(stage, &args.output)?;
            if !global.quiet {
                eprintln!(
                    "{}: wrote {written} frame{} to {}",
                    args.capture.display(),
                    if written == 1 { "" } else { "s" },
                    display(&args.output)
                );
            }
            Ok(())
        }
        Err(e) => {
            drop(stage);
            folder.abandon();
            Err(e)
        }
    }
}

/// Writes the frames in `range` into `dir`; returns how many.
fn convert(
    args: &Args,
    global: Global,
    mut reader: FrameReader,
    range: &std::ops::RangeInclusive<u32>,
    dir: &Path,
) -> Result<u32> {
    let source = args.capture.display().to_string();
    let progress = super::progress(global, "frames");
    let mut written = 0u32;
    while let Some(frame) = reader.next() {
        let frame = frame?;
        if frame.index > *range.end() {
            break;
        }
        if range.contains(&frame.index) {
            let name = frame_file_name(frame.index);
            crate::writers::atomic::refuse_inputs(
                &args.output.join(&name),
                &[args.capture.as_path()],
            )?;
            let path = dir.join(name);
            let ply = PlyFrame {
                encoding: if args.ascii {
                    PlyEncoding::Ascii
                } else {
                    PlyEncoding::BinaryLittleEndian
                },
                ..PlyFrame::new(&frame.returns, &source, frame.index, frame.start_time())
            };
            write_file(&ply, &path, &[args.capture.as_path()])?;
            written += 1;
            progress.inc(1);
        }
        reader.recycle(frame);
    }
    progress.finish_and_clear();
    let summary = reader.summary();
    super::warn_truncation(global, &args.capture, &summary);
    super::warn_capture(global, &args.capture, &summary, false);
    if written == 0 {
        anyhow::bail!(
            "{}: no frame in {} (the capture has {} full frames{}); pick others with --frames \
             or add --keep-partial",
            args.capture.display(),
            args.frames.as_deref().unwrap_or("the capture"),
            summary.full_frames,
            if summary.partial_frames > 0 {
                ", partial sweeps left out"
            } else {
                ""
            }
        );
    }
    Ok(written)
}

fn display(path: &Path) -> String {
    path.display().to_string()
}
