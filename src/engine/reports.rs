//! What a run reports and how it recognises its own results: the summary.json and
//! clusters.json documents, the line printed per capture, the settings a rerun compares
//! and the names of the files `run` writes.

use super::Plan;
use crate::cloud::frames::CloudSummary;
use crate::pipeline::report::{FrameClusters, FrameReport, Totals, FATE_CODES};
use crate::sensor::frames::{CaptureSummary, FrameReader};
use anyhow::Result;
use serde::Serialize;
use std::ops::RangeInclusive;
use std::path::Path;

/// The per-capture summary written as summary.json.
#[derive(Serialize)]
pub struct Summary<'a> {
    tool: &'static str,
    version: &'static str,
    capture: String,
    config: String,
    settings: crate::config::EffectiveConfig<'a>,
    power_constants: &'a crate::noise::PowerConstants,
    decoder: DecoderSettings,
    fate_codes: [&'static str; 6],
    capture_summary: SourceSummary<'a>,
    /// Totals over the frames.
    pub totals: Totals,
    frames: &'a [FrameReport],
}

/// What the source held: a capture's packets and frames, or a point-cloud file's points.
#[derive(Serialize)]
#[serde(untagged)]
pub enum SourceSummary<'a> {
    /// A decoded capture.
    Capture(&'a CaptureSummary),
    /// A point-cloud scan.
    Cloud(&'a CloudSummary),
    /// A capture of another described sensor.
    Model(&'a crate::sensor::frames::ModelCaptureSummary),
}

/// The cluster report written as clusters.json.
#[derive(Serialize)]
pub struct ClusterReport<'a> {
    tool: &'static str,
    version: &'static str,
    capture: String,
    frames: &'a [FrameClusters],
}

#[derive(Serialize)]
struct DecoderSettings {
    calibration: String,
    interpolate_azimuth: bool,
    dual: crate::sensor::decode::DualSelect,
    cut_angle_deg: f64,
    keep_partial: bool,
}

/// What decides a capture folder's results: a rerun with the same settings replaces it
/// with the same bytes, other settings are another run (see `staging::check_replace`).
pub fn run_settings(plan: &Plan, source: &str) -> serde_json::Value {
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
pub fn is_run_output(name: &str) -> bool {
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
pub fn is_run_path(rel: &str) -> bool {
    rel.split_once('/').is_some_and(|(_, f)| {
        !f.contains('/')
            && (is_run_output(f)
                || f == "noisy.pcap"
                || (f.starts_with(".run.chunk") && f.ends_with(".json")))
    })
}

/// True for `<prefix>NNNNN<ext>` with five or more digits and one of `exts`.
pub fn numbered(name: &str, prefix: &str, exts: &[&str]) -> bool {
    let Some(rest) = name.strip_prefix(prefix) else {
        return false;
    };
    exts.iter().any(|ext| {
        rest.strip_suffix(ext)
            .is_some_and(|d| d.len() >= 5 && d.bytes().all(|b| b.is_ascii_digit()))
    })
}

/// Refuses a target folder that is an input, holds an input or is a file.
pub fn check_target(dir: &Path, inputs: &[&Path]) -> Result<()> {
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

/// The capture's summary.json and clusters.json, with empty `frames` arrays (the frames
/// are spooled and joined in, see [`super::spool`]).
pub fn documents<'a>(
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
pub(crate) fn cluster_document(source: &str) -> ClusterReport<'static> {
    ClusterReport {
        tool: "lidar-noise",
        version: env!("CARGO_PKG_VERSION"),
        capture: source.to_string(),
        frames: &[],
    }
}

/// The line a run prints for a capture.
pub fn report_line(source: &str, frames: usize, t: &Totals) -> String {
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
/// The error for a capture of another sensor that yielded no frame in `frames`, read to
/// its end.
pub fn no_model_frame_error(
    source: &str,
    frames: &RangeInclusive<u32>,
    reader: &crate::sensor::frames::ModelFrameReader,
) -> anyhow::Error {
    anyhow::anyhow!(
        "{source}: no frame to process in {} of this {} capture ({} full and {} partial \
         sweeps; --keep-partial keeps the partial ones)",
        crate::range::frames_phrase(frames),
        reader.model().name,
        reader.summary().full_frames,
        reader.summary().partial_frames
    )
}

/// The error for an HDL-32E capture that yielded no frame in `frames`.
pub fn no_frame_error(
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
    // Full sweeps follow each other: from the first one (after a partial first sweep, or
    // frame 0 when the capture starts on a full turn).
    let first = s.first_full_frame.unwrap_or(0);
    let last = first + full.saturating_sub(1);
    let partial_note = if *frames.start() == 0 && *frames.end() == 0 {
        "frame 0 is the partial first sweep (add --keep-partial to process it); "
    } else {
        ""
    };
    anyhow::anyhow!(
        "{source}: no frame to process in {}: {partial_note}the capture has {} \
         full frame{} ({}); pick others with --frames or add --keep-partial",
        crate::range::frames_phrase(frames),
        full,
        if full == 1 { "" } else { "s" },
        if full == 0 {
            "none".to_string()
        } else {
            format!("indexes {first}..{last}")
        }
    )
}
