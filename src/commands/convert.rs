//! `lidar-noise convert`: one point cloud per frame, no noise.

use crate::cli::{Console, Global};
use crate::options::{DecoderArgs, FrameOutputArgs};
use anyhow::Result;
use lidar_noise::frame::{Frame, FrameSource};
use lidar_noise::observe::{Counter, Observer};
use lidar_noise::range::parse_range;
use lidar_noise::sensor::frames::CaptureFrames;
use lidar_noise::sensor::frames::DecoderOptions;
use lidar_noise::writers::ply::PlyFrame;
use lidar_noise::writers::staging::{self, OutputFolder, Staged};
use lidar_noise::writers::{write_file, FrameOutput};
use std::ops::RangeInclusive;
use std::path::{Path, PathBuf};

/// Arguments of `convert`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Capture files (pcap or pcapng), `-` for standard input.
    #[arg(value_name = "CAPTURE", required = true)]
    pub captures: Vec<PathBuf>,
    /// Output folder (created if missing); frames are written as frame_NNNNN.<format>,
    /// in a subfolder named after each capture when several are given.
    #[arg(short, long, value_name = "DIR")]
    pub output: PathBuf,
    /// Frames to write, by sweep index: N, A..B (both included), A.. or ..B.
    #[arg(long, value_name = "RANGE")]
    pub frames: Option<String>,
    /// Point-cloud format (PLY, LAS, LAZ) and PLY encoding.
    #[command(flatten)]
    pub output_format: FrameOutputArgs,
    /// Replace the frames of another convert in the target folder (as a whole); files
    /// lidar-noise did not write are never deleted (the command is refused instead).
    #[arg(long)]
    pub force: bool,
    /// Decoder settings shared by the commands that read captures.
    #[command(flatten)]
    pub decoder: DecoderArgs,
}

/// Decodes each capture and writes the selected frames.
///
/// Frames are written into staging folders beside their targets and moved into place only
/// when every capture is written: a failed or interrupted convert leaves no frame behind.
pub fn run(args: Args, global: Global) -> Result<()> {
    super::check_stdin_once(&args.captures)?;
    let console = Console::new(global);
    let options = args.decoder.to_options()?;
    let output = args.output_format.to_output()?;
    let range = match &args.frames {
        Some(text) => parse_range("--frames", text)?,
        None => 0..=u32::MAX,
    };
    let several = args.captures.len() > 1;
    let names = super::output_names(&args.captures);
    // One capture keeps the historical layout (frames directly in DIR).
    let targets: Vec<(&str, PathBuf)> = names
        .iter()
        .map(|name| {
            if several {
                (name.as_str(), args.output.join(name))
            } else {
                ("convert", args.output.clone())
            }
        })
        .collect();
    let mut inputs: Vec<&Path> = args.captures.iter().map(PathBuf::as_path).collect();
    // A calibration file inside the output folder would be replaced by a frame.
    inputs.extend(args.decoder.calibration.as_deref());
    let check = || -> Result<Vec<String>> {
        let mut old = Vec::new();
        for (capture, (_, target)) in args.captures.iter().zip(&targets) {
            let settings = convert_settings(&args, capture, output);
            old = staging::check_replace(
                target,
                "convert",
                &settings,
                &is_convert_output,
                &|_| false,
                args.force,
                &inputs,
            )?;
        }
        Ok(old)
    };
    let mut old = check()?;
    let folder = OutputFolder::lock(&args.output)?;
    if folder.repaired() {
        // The lock finished a killed run's commit: the folders checked may have changed.
        match check() {
            Ok(o) => old = o,
            Err(e) => {
                folder.abandon();
                return Err(e);
            }
        }
    }
    // Only now, the checks passed: what killed runs of this tool left.
    folder.remove_leftovers(&|rel| is_convert_output(rel.rsplit('/').next().unwrap_or(rel)));
    let mut staged: Vec<(Staged, PathBuf, u32, &Path)> = Vec::new();
    for (capture, (stage_name, target)) in args.captures.iter().zip(targets) {
        let settings = convert_settings(&args, capture, output);
        let result = folder
            .stage(stage_name)
            .map_err(anyhow::Error::from)
            .and_then(|s| {
                let written = convert_one(
                    capture,
                    &target,
                    s.path(),
                    &options,
                    output,
                    &range,
                    &console,
                )?;
                let files = staging::result_files(s.path());
                staging::write_manifest(s.path(), "convert", &settings, files)?;
                Ok((s, written))
            });
        match result {
            Ok((s, written)) => staged.push((s, target, written, capture.as_path())),
            Err(e) => {
                drop(staged);
                folder.abandon();
                return Err(e);
            }
        }
    }
    let mut done = Vec::new();
    if several {
        let mut stages = Vec::new();
        for (s, target, written, capture) in staged {
            stages.push(s);
            done.push((target, written, capture));
        }
        staging::commit(stages)?;
    } else if let Some((s, target, written, capture)) = staged.pop() {
        // The frames go into the output folder itself: replaced as a sweep's results are,
        // in one commit a kill cannot leave half done (the earlier frames the new ones do
        // not replace go last).
        let new = staging::result_files(s.path());
        let replaces: Vec<String> = old.into_iter().filter(|f| !new.contains(f)).collect();
        staging::commit_into(s, &replaces)?;
        done.push((target, written, capture));
    }
    if !global.quiet {
        for (target, written, capture) in done {
            eprintln!(
                "{}: wrote {written} frame{} to {}",
                super::capture_shown(capture),
                if written == 1 { "" } else { "s" },
                target.display()
            );
        }
    }
    Ok(())
}

/// What decides a convert's frames (see `staging::check_replace`).
fn convert_settings(args: &Args, capture: &Path, output: FrameOutput) -> serde_json::Value {
    let d = &args.decoder;
    serde_json::json!({
        "capture": super::capture_label(capture),
        "frames": args.frames,
        "output": format!("{output:?}"),
        "decoder": {
            "calibration": d.calibration.as_ref().and_then(|p| p.file_name()).map(|n| n.to_string_lossy()),
            "no_interpolate": d.no_interpolate,
            "dual": format!("{:?}", d.dual),
            "cut_angle_deg": d.cut_angle,
            "keep_partial": d.keep_partial,
        },
    })
}

/// True for the frame files `convert` writes (for folders without a manifest).
fn is_convert_output(name: &str) -> bool {
    lidar_noise::engine::reports::numbered(name, "frame_", &[".ply", ".las", ".laz"])
}

/// Writes the frames of `capture` in `range` into `dir` (the staging folder of `target`);
/// returns how many.
fn convert_one(
    capture: &Path,
    target: &Path,
    dir: &Path,
    options: &DecoderOptions,
    output: FrameOutput,
    range: &RangeInclusive<u32>,
    observer: &dyn Observer,
) -> Result<u32> {
    let mut frames = lidar_noise::engine::inputs::open_any_capture(capture, options)?;
    let reader: &mut dyn FrameSource = match &mut frames {
        CaptureFrames::Hdl32e(r) => &mut **r,
        CaptureFrames::Model(r) => &mut **r,
    };
    let source = super::capture_label(capture);
    lidar_noise::engine::inputs::start_frames(observer, Some(capture), options, range);
    let mut written = 0u32;
    // Decoding on this thread, PLY encoding and writing on the workers, overlapped
    // (see `engine::stream_frames`); the frame's buffer comes back for the decoder to reuse.
    let work = |frame: Frame| -> Result<Frame> {
        let name = output.file_name(frame.index);
        lidar_noise::writers::atomic::refuse_inputs(&target.join(&name), &[capture])?;
        let path = dir.join(name);
        let ply = PlyFrame::new(&frame.returns, &source, frame.index, frame.start_time());
        write_file(&*output.document(ply), &path, &[capture])?;
        Ok(frame)
    };
    // No heap warm-up: a frame's decoding and PLY need little heap, and warming 12 MB a
    // worker made `convert` slower, not faster.
    lidar_noise::engine::stream_frames(reader, range, 0, work, |frame, reader| {
        written += 1;
        observer.advance(Counter::Frames, 1);
        reader.recycle(frame);
        Ok(())
    })?;
    observer.finish(Counter::Frames);
    // Named as `run` names it: the path as given, `<stdin>` for `-`.
    let shown = super::capture_shown(capture);
    match &mut frames {
        CaptureFrames::Hdl32e(reader) => {
            let summary = reader.summary();
            super::warn_truncation(observer, Path::new(&shown), &summary);
            super::warn_capture(observer, Path::new(&shown), &summary, false);
            if written == 0 {
                // Same message as `run`'s: the capture's full frames counted to its end.
                return Err(lidar_noise::engine::reports::no_frame_error(
                    &shown, range, reader,
                ));
            }
        }
        CaptureFrames::Model(reader) => {
            let duplicates = reader.summary().duplicate_packets;
            lidar_noise::engine::inputs::warn_duplicates(observer, Path::new(&shown), duplicates);
            if written == 0 {
                return Err(lidar_noise::engine::reports::no_model_frame_error(
                    &shown, range, reader,
                ));
            }
        }
    }
    Ok(written)
}
