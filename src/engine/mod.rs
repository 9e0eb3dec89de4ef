//! The streaming engine of `run`, beside the pipeline: it reads frames from any
//! [`FrameSource`] (a capture, a point-cloud scan, a dataset folder's scans), runs them
//! through the [`Pipeline`] on a pool of workers, and writes each frame's files and the
//! reports as frames complete, with memory bounded whatever the input's length.
//!
//! The `run` command only turns its arguments into a [`Plan`] and a [`RunRequest`] and
//! calls [`run`], which reports to an [`Observer`]. Data flows one way: source ->
//! pipeline -> per-frame files and report spool -> reports.

pub mod chunks;
pub mod dataset;
pub mod frame_files;
pub mod inputs;
pub mod reports;
pub mod spool;
pub mod stream;

use crate::cloud::frames::{CloudOptions, CloudReader};
use crate::config::Config;
use crate::frame::Frame;
use crate::observe::{Counter, Observer};
use crate::pipeline::Pipeline;
use crate::sensor::frames::ModelFrameReader;
use crate::sensor::frames::{DecoderOptions, FrameReader};
use crate::shard::Shard;
use crate::writers::scan::ScanPoint;
use crate::writers::staging::{self, OutputFolder};
use crate::writers::FrameOutput;
use anyhow::Result;
use frame_files::{frame_outputs, reported_times, scan_points, write_scan};
use inputs::{DEFAULT_CAPTURE, DEFAULT_CAPTURE_NAME};
use reports::{
    check_target, cluster_document, documents, is_run_output, is_run_path, no_frame_error,
    report_line, run_settings, SourceSummary,
};
use spool::{ReportSpool, SpoolEntry};
use std::ops::RangeInclusive;
use std::path::{Path, PathBuf};
use std::sync::Arc;
pub use stream::stream_frames;

/// A scan's rows to write back, and the time each reports (empty unless a time field
/// placed its points).
type ScanRows = (Vec<ScanPoint>, Vec<f64>);

/// Validated settings of a run: what is computed and written for every frame.
#[derive(Clone)]
pub struct Plan {
    /// The experiment configuration.
    pub config: Config,
    /// The pipeline built from `config`.
    pub pipeline: Pipeline,
    /// How captures are decoded.
    pub decoder: DecoderOptions,
    /// Frames to process, by sweep index.
    pub frames: RangeInclusive<u32>,
    /// Also write the dropped returns in each point cloud.
    pub keep_dropped: bool,
    /// Write point clouds (false: reports only).
    pub ply: bool,
    /// Point-cloud format and PLY encoding.
    pub output: FrameOutput,
    /// Also write each frame's single-linkage merge tree.
    pub linkage: bool,
    /// Also write the capture re-encoded from the noisy returns (noisy.pcap).
    pub pcap_out: bool,
    /// Point-cloud scans are written back in their own format (no `--format` given).
    pub native: bool,
}

impl Plan {
    /// The plan for frames of `sensor` (its noise chain's firing slots hold its lasers);
    /// an error naming the stage and option when a stage's per-laser options do not fit
    /// it.
    pub fn for_sensor(&self, sensor: &crate::sensor::SensorModel) -> Result<Plan> {
        let pipeline = self
            .pipeline
            .for_sensor(sensor)
            .map_err(|e| anyhow::anyhow!("the {} ({} lasers): {e}", sensor.name, sensor.lasers))?;
        Ok(Plan {
            pipeline,
            ..self.clone()
        })
    }

    /// The settings `run` uses when no option is given: every frame, binary PLY point
    /// clouds, point-cloud scans written back in their own format.
    pub fn new(config: Config) -> Self {
        Plan {
            pipeline: Pipeline::new(&config),
            config,
            decoder: DecoderOptions::default(),
            frames: 0..=u32::MAX,
            keep_dropped: false,
            ply: true,
            output: FrameOutput::default(),
            linkage: false,
            pcap_out: false,
            native: true,
        }
    }
}

/// What a run reads and where it writes: the inputs and the output folder's handling.
#[derive(Clone, Debug, Default)]
pub struct RunRequest {
    /// Captures (pcap, pcapng; `-` standard input), point-cloud scans, or one dataset
    /// folder (KITTI sequence, nuScenes `samples/LIDAR_TOP`); empty runs the built-in
    /// capture.
    pub captures: Vec<PathBuf>,
    /// Output folder; each capture gets a subfolder named after it.
    pub output: PathBuf,
    /// Files that must never be written over (the configuration, a calibration file).
    pub protected: Vec<PathBuf>,
    /// Replace the results of another run.
    pub force: bool,
    /// Run only the inputs that fall to this shard.
    pub shard: Option<Shard>,
    /// Split captures into chunks of this many frames (`--chunk-frames`).
    pub chunk_frames: Option<u32>,
    /// Only join the parts of a chunked run (`--merge`).
    pub merge: bool,
    /// Sensor that recorded point-cloud scans (`--sensor`).
    pub sensor: Option<String>,
    /// Rotation rate of point-cloud scans in Hz (`--rotation-hz`).
    pub rotation_hz: Option<f64>,
    /// Per-point labels of a point-cloud scan (`--labels`); by default those found beside
    /// it.
    pub labels: Option<PathBuf>,
}

/// Runs the pipeline on every input of `request` with the settings of `plan`, writing
/// into `request.output`; reports a line per capture, warnings and progress to
/// `observer`.
pub fn run(plan: &Plan, request: &RunRequest, observer: &dyn Observer) -> Result<()> {
    if let Some(dir) = request.captures.iter().find(|p| p.is_dir()) {
        if request.captures.len() > 1 {
            anyhow::bail!(
                "{}: a dataset folder is run on its own: give it as the only input",
                dir.display()
            );
        }
        return dataset::run(plan, request, dir, observer);
    }
    inputs::check_stdin_once(&request.captures)?;
    if plan.pcap_out {
        crate::writers::pcap::check_encodable(plan.pipeline.chain(), plan.config.seed)?;
        if request.captures.iter().any(|p| inputs::is_stdin(p)) {
            anyhow::bail!("--pcap-out needs capture files: standard input (`-`) is not kept");
        }
        // The noisy capture is a copy of the input read again: a FIFO would wait for ever.
        if let Some(p) = request
            .captures
            .iter()
            .find(|p| crate::capture::is_stream(p))
        {
            anyhow::bail!(
                "--pcap-out needs capture files: {} is a FIFO or a device, which can be read \
                 only once; save the capture to a file first",
                p.display()
            );
        }
    }
    let mut inputs: Vec<&Path> = request.captures.iter().map(PathBuf::as_path).collect();
    // The configuration and a calibration file inside the output folder would be replaced
    // by a report.
    inputs.extend(request.protected.iter().map(PathBuf::as_path));
    let clouds: Vec<Option<crate::cloud::Format>> =
        request.captures.iter().map(|p| cloud_format(p)).collect();
    if let Some((p, _)) = request
        .captures
        .iter()
        .zip(&clouds)
        .find(|(_, c)| c.is_some())
    {
        if request.chunk_frames.is_some() {
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
    if let Some(m) = request.chunk_frames {
        // Chunked runs take captures of any described sensor, each with its plan.
        return chunks::run(request, plan, m, &inputs, observer);
    }
    // Every input and target is checked before anything is written.
    // Each job with the plan for its sensor (the noise chain's firing slots hold its
    // lasers).
    let mut jobs: Vec<(Source, String, String, Option<&Path>, Plan)> = Vec::new();
    if request.captures.is_empty() {
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
            plan.for_sensor(&crate::sensor::HDL32E)?,
        ));
    }
    for ((path, name), cloud) in request
        .captures
        .iter()
        .zip(inputs::output_names(&request.captures))
        .zip(&clouds)
    {
        let (reader, job_plan) = match cloud {
            Some(format) => {
                let options = cloud_options(request, *format)?;
                let job_plan = plan.for_sensor(options.sensor).map_err(|e| {
                    anyhow::anyhow!("{}: {e:#}; nothing was written", path.display())
                })?;
                (
                    Source::Cloud(Box::new(CloudReader::open(path, &options)?)),
                    job_plan,
                )
            }
            None => open_capture_source(path, plan)?,
        };
        jobs.push((
            reader,
            inputs::capture_label(path),
            name,
            Some(path),
            job_plan,
        ));
    }
    if let Some(shard) = request.shard {
        let total = jobs.len();
        jobs = jobs
            .into_iter()
            .enumerate()
            .filter(|(i, _)| shard.owns(*i))
            .map(|(_, j)| j)
            .collect();
        observer.note(&format!(
            "run --shard {shard}: {} of {total} capture{} fall to this shard",
            jobs.len(),
            if total == 1 { "" } else { "s" }
        ));
        if jobs.is_empty() {
            return Ok(());
        }
    }
    let check = || -> Result<()> {
        for (reader, source, name, capture, _) in &jobs {
            // Named by the path as given, as in every message of `run`.
            let shown = capture.map_or_else(|| source.clone(), inputs::capture_shown);
            match (plan.pcap_out, reader) {
                (true, Source::Capture(reader)) => {
                    let mode = reader.summary().return_mode;
                    crate::writers::pcap::check_capture(&shown, mode, plan.decoder.dual)?;
                }
                (true, Source::Model(reader)) => {
                    let mode = reader.summary().return_mode;
                    let mode = mode.unwrap_or(crate::sensor::ReturnMode::Strongest);
                    crate::writers::pcap::check_capture(&shown, mode, plan.decoder.dual)?;
                }
                _ => {}
            }
            let target = request.output.join(name);
            check_target(&target, &inputs)?;
            staging::check_replace(
                &target,
                "run",
                &run_settings(plan, source),
                &is_run_output,
                &|_| false,
                request.force,
                &inputs,
            )?;
        }
        Ok(())
    };
    check()?;
    // Shards of one batch write distinct capture folders side by side.
    let folder = if request.shard.is_some() {
        OutputFolder::lock_shared(&request.output)?
    } else {
        OutputFolder::lock(&request.output)?
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
    for (reader, source, name, capture, job_plan) in jobs {
        let stage = match folder.stage(&name) {
            Ok(s) => s,
            Err(e) => {
                drop(staged);
                folder.abandon();
                return Err(e.into());
            }
        };
        let settings = run_settings(plan, &source);
        let result = run_source(
            &job_plan,
            reader,
            (&source, capture),
            stage.path(),
            &inputs,
            observer,
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
    for (line, dir) in reports.iter().zip(&targets) {
        observer.note(&format!("{line}; results in {}", dir.display()));
    }
    Ok(())
}

/// Where a run's frames come from.
enum Source {
    /// A capture, decoded (boxed: its reader is large, and jobs are moved around).
    Capture(Box<FrameReader>),
    /// A capture of another described sensor (VLP-16, VLP-32C, HDL-64E, VLS-128).
    Model(Box<ModelFrameReader>),
    /// A point-cloud scan, placed on the sensor's firings (boxed, as the others).
    Cloud(Box<CloudReader>),
}

impl Source {
    /// The decoder of a capture (either sensor family's), `None` for a scan.
    fn decoder(&mut self) -> Option<&mut dyn crate::frame::FrameSource> {
        match self {
            Source::Capture(r) => Some(&mut **r),
            Source::Model(r) => Some(&mut **r),
            Source::Cloud(_) => None,
        }
    }
}

/// The frame source of the capture at `path` and the plan for its sensor: the HDL-32E
/// reader, or, where that refuses the capture and another described sensor's structure
/// fits it, that sensor's reader (files and standard input: a FIFO is read once).
fn open_capture_source(path: &Path, plan: &Plan) -> Result<(Source, Plan)> {
    use crate::sensor::frames::CaptureFrames;
    let nothing =
        |e: anyhow::Error| anyhow::anyhow!("{}: {e:#}; nothing was written", path.display());
    let hdl32e = |r| -> Result<(Source, Plan)> {
        let plan = plan.for_sensor(&crate::sensor::HDL32E).map_err(nothing)?;
        Ok((Source::Capture(r), plan))
    };
    let reader = match inputs::open_any_capture(path, &plan.decoder)? {
        CaptureFrames::Hdl32e(r) => return hdl32e(r),
        CaptureFrames::Model(r) => r,
    };
    let model = reader.model();
    let plan = plan.for_sensor(model).map_err(nothing)?;
    Ok((Source::Model(reader), plan))
}

/// The point-cloud format of `path`, or `None` for a capture: files that start like a
/// pcap or pcapng file, standard input and streams (read only once, never probed) are
/// captures; so is anything no point-cloud reader recognises (the capture reader then
/// says what is wrong).
pub(crate) fn cloud_format(path: &Path) -> Option<crate::cloud::Format> {
    use std::io::Read;
    if inputs::is_stdin(path) || crate::capture::is_stream(path) {
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
pub(crate) fn cloud_options(
    request: &RunRequest,
    format: crate::cloud::Format,
) -> Result<CloudOptions> {
    use crate::cloud::guess::{sensor_by_name, SENSOR_NAMES};
    use crate::cloud::Format;
    let sensor = match request.sensor.as_deref() {
        Some(name) => sensor_by_name(name).ok_or_else(|| {
            anyhow::anyhow!("--sensor {name}: not a sensor modelled here ({SENSOR_NAMES})")
        })?,
        // KITTI and SemanticKITTI were recorded with an HDL-64E S2 (its beams as KITTI's
        // unit has them: `sensor::HDL64E_KITTI`), nuScenes with an HDL-32E; other formats
        // say nothing of their sensor: the HDL-32E unless said.
        None if format == Format::Kitti => &crate::sensor::HDL64E_KITTI,
        None => &crate::sensor::HDL32E,
    };
    let rotation_hz = request
        .rotation_hz
        .unwrap_or(if format == Format::NuScenes {
            20.0
        } else {
            10.0
        });
    Ok(CloudOptions {
        sensor,
        format: Some(format),
        rotation_hz,
        labels: request.labels.clone(),
    })
}

/// Runs one capture into `dir` (its staging folder); returns the line to print.
fn run_source(
    plan: &Plan,
    mut reader: Source,
    (source, capture): (&str, Option<&Path>),
    dir: &Path,
    inputs: &[&Path],
    observer: &dyn Observer,
) -> Result<String> {
    inputs::start_frames(observer, capture, &plan.decoder, &plan.frames);
    observer.label(Counter::Frames, source);
    // Per-frame reports are streamed to spool files and joined at the end, so memory
    // does not grow with the capture's length.
    let mut spool = ReportSpool::new(dir, &cluster_document(source), inputs)?;
    // --pcap-out: workers patch the return slots, frames are written as they complete.
    let pcap = if plan.pcap_out {
        use crate::writers::pcap::{NoisyCapture, Source, Wire};
        let wire = match &reader {
            self::Source::Model(r) => Wire::Model(r.model()),
            _ => Wire::Hdl32e(&plan.decoder.calibration),
        };
        let path = capture.unwrap_or(Path::new(DEFAULT_CAPTURE_NAME));
        let source = capture.map_or(Source::Bytes(Arc::from(DEFAULT_CAPTURE)), |p| {
            Source::File(p.to_path_buf())
        });
        Some(NoisyCapture::create(source, path, wire, dir, inputs)?)
    } else {
        None
    };
    // A scan written back in its own format replaces the frame file.
    let native = plan.native && plan.ply && matches!(reader, Source::Cloud(_));
    // A labelled scan's ground and object scores (one frame), for truth.json.
    let truth = match &mut reader {
        Source::Cloud(r) => r.take_truth(),
        Source::Capture(_) | Source::Model(_) => None,
    };
    // A scan placed by its time field gets its times written back in it.
    let timed = native && matches!(&reader, Source::Cloud(r) if r.summary().time_field.is_some());
    let scored = std::sync::Mutex::new(None);
    let work = |f: Frame| -> Result<(SpoolEntry, Vec<crate::frame::Return>, ScanRows)> {
        let result = plan.pipeline.process(f)?;
        if let Some(t) = &truth {
            let bands = &crate::score::metrics::DEFAULT_BANDS;
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
        let times = if timed {
            reported_times(&result)
        } else {
            Vec::new()
        };
        let (entry, returns) = frame_outputs(plan, result, source, dir, inputs, !native)?;
        Ok((entry, returns, (rows, times)))
    };
    // Frames arrive here in order: the noisy capture can be written up to this one.
    let mut done = |entry: SpoolEntry| -> Result<()> {
        if let Some(p) = &pcap {
            p.frame_done(entry.report.index)?;
        }
        spool.add(entry)?;
        observer.advance(Counter::Frames, 1);
        Ok(())
    };
    let warmup = crate::memory::worker_warmup_bytes();
    match &mut reader {
        Source::Capture(_) | Source::Model(_) => stream_frames(
            reader.decoder().expect("a capture"),
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
            stream_frames(
                &mut **r,
                &plan.frames,
                warmup,
                work,
                |(e, _, (rows, times)), r| {
                    if native {
                        write_scan(r, rows, &times, e.report.index, dir, inputs)?;
                    }
                    done(e)
                },
            )?;
        }
    }
    observer.finish(Counter::Frames);
    // Messages name the capture by the path as given, as `convert`'s do; the outputs name
    // it by `source`, its file name, so that they do not depend on the working folder.
    let shown = capture.map_or_else(|| source.to_string(), inputs::capture_shown);
    let capture_summary;
    let source_summary = match &mut reader {
        Source::Capture(r) => {
            capture_summary = r.summary();
            inputs::warn_truncation(observer, Path::new(&shown), &capture_summary);
            inputs::warn_capture(
                observer,
                Path::new(&shown),
                &capture_summary,
                plan.config.sensor.intensity == crate::config::IntensityMode::Reflectivity,
            );
            if spool.frames == 0 {
                return Err(no_frame_error(&shown, &plan.frames, r));
            }
            SourceSummary::Capture(&capture_summary)
        }
        Source::Model(r) => {
            inputs::warn_duplicates(observer, Path::new(&shown), r.summary().duplicate_packets);
            if spool.frames == 0 {
                return Err(reports::no_model_frame_error(&shown, &plan.frames, r));
            }
            SourceSummary::Model(r.summary())
        }
        Source::Cloud(r) => {
            if spool.frames == 0 {
                anyhow::bail!(
                    "{shown}: no frame to process in {}: a point-cloud scan is one frame, 0",
                    crate::range::frames_phrase(&plan.frames)
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
            observer.warn(&format!(
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
