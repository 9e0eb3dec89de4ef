//! `run DATASET_DIR`: every scan of a KITTI sequence folder (`velodyne/*.bin`) or of a
//! nuScenes `samples/LIDAR_TOP` folder (`*.pcd.bin`) through the pipeline, written back in
//! the dataset's own layout (issue 31, "Dataset folders"):
//!
//! - KITTI `SEQ/velodyne/NNNNNN.bin` -> `OUT/velodyne/NNNNNN.bin` + `NNNNNN.fate.csv`;
//! - nuScenes `.../samples/LIDAR_TOP/NAME.pcd.bin` -> `OUT/samples/LIDAR_TOP/NAME.pcd.bin`
//!   + `NAME.fate.csv`.
//!
//! The scans are sorted by file name; scan `i` of that order is processed as frame `i`, so
//! its random streams derive from (seed, i, stage) whoever processes it: the bytes of a
//! file are the same for any thread count and whether the run is whole or a shard
//! (`--shard K/N` takes the files `i` with `i % N == K`). Files are processed in parallel
//! (one scan per worker at a time: memory does not grow with the dataset's length).
//!
//! Resumable: `OUT/dataset-run.json` holds the settings; a rerun with the same settings
//! skips every file whose scan is there (the sidecar is written first and each file is
//! written under a temporary name and renamed, so a scan file is there only when both are
//! complete); other settings are refused unless `--force`, which recomputes every file.
//! A file that fails writes nothing; the others are written, and the run fails naming the
//! first failed file in sorted order.

use super::{cloud_options, Plan, RunRequest};
use crate::cloud::frames::read_frame;
use crate::cloud::Format;
use crate::observe::{Counter, Observer};
use anyhow::{bail, Result};
use rayon::prelude::*;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};

/// The layouts of dataset folders `run` walks.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Layout {
    /// A KITTI (or SemanticKITTI) sequence: `velodyne/*.bin`.
    Kitti,
    /// nuScenes lidar samples: `samples/LIDAR_TOP/*.pcd.bin`.
    NuScenes,
}

impl Layout {
    /// The folder of scans under the output folder, mirroring the input's.
    pub fn scan_folder(self) -> &'static str {
        match self {
            Layout::Kitti => "velodyne",
            Layout::NuScenes => "samples/LIDAR_TOP",
        }
    }

    /// The file name ending of a scan.
    pub fn extension(self) -> &'static str {
        match self {
            Layout::Kitti => ".bin",
            Layout::NuScenes => ".pcd.bin",
        }
    }

    fn format(self) -> Format {
        match self {
            Layout::Kitti => Format::Kitti,
            Layout::NuScenes => Format::NuScenes,
        }
    }

    fn name(self) -> &'static str {
        match self {
            Layout::Kitti => "KITTI sequence",
            Layout::NuScenes => "nuScenes LIDAR_TOP",
        }
    }
}

/// A dataset folder's scans.
#[derive(Clone, Debug)]
pub struct Dataset {
    /// Its layout.
    pub layout: Layout,
    /// The folder holding the scans.
    pub scan_dir: PathBuf,
    /// The scans, sorted by file name: scan `i` is frame `i` of the run.
    pub scans: Vec<PathBuf>,
}

/// Files of `dir` whose names end with `ext` (and are more than that), sorted by name.
fn files_ending(dir: &Path, ext: &str) -> Result<Vec<PathBuf>> {
    let entries = std::fs::read_dir(dir).map_err(|e| crate::error::Error::io(dir, e))?;
    let mut names = Vec::new();
    for entry in entries {
        let entry = entry.map_err(|e| crate::error::Error::io(dir, e))?;
        let name = entry.file_name();
        let Some(name) = name.to_str() else { continue };
        if name.len() > ext.len() && name.ends_with(ext) && !name.starts_with('.') {
            // Through symbolic links too (datasets are often linked into place).
            if entry.path().is_file() {
                names.push(name.to_string());
            }
        }
    }
    names.sort();
    Ok(names.into_iter().map(|n| dir.join(n)).collect())
}

impl Dataset {
    /// Finds the layout of `dir`: a KITTI sequence (it holds `velodyne/`, or is it), a nuScenes root
    /// or `samples` folder (it holds `samples/LIDAR_TOP/` or `LIDAR_TOP/`), or the
    /// `LIDAR_TOP` folder itself (it holds `*.pcd.bin`); anything else is refused naming
    /// the folder and what was expected.
    pub fn find(dir: &Path) -> Result<Dataset> {
        let of = |layout: Layout, scan_dir: PathBuf| -> Result<Dataset> {
            let scans = files_ending(&scan_dir, layout.extension())?;
            if scans.is_empty() {
                bail!(
                    "{}: a {} folder with no scan (*{}) in it",
                    scan_dir.display(),
                    layout.name(),
                    layout.extension()
                );
            }
            Ok(Dataset {
                layout,
                scan_dir,
                scans,
            })
        };
        if !dir.is_dir() {
            bail!("{}: not a folder", dir.display());
        }
        if dir.join("velodyne").is_dir() {
            return of(Layout::Kitti, dir.join("velodyne"));
        }
        // The sequence's velodyne folder itself.
        if dir.file_name().is_some_and(|n| n == "velodyne") {
            return of(Layout::Kitti, dir.to_path_buf());
        }
        for sub in ["samples/LIDAR_TOP", "LIDAR_TOP"] {
            if dir.join(sub).is_dir() {
                return of(Layout::NuScenes, dir.join(sub));
            }
        }
        if !files_ending(dir, ".pcd.bin")?.is_empty() {
            return of(Layout::NuScenes, dir.to_path_buf());
        }
        bail!(
            "{}: not a dataset folder: expected a KITTI sequence folder (holding velodyne/*.bin) \
             or a nuScenes samples/LIDAR_TOP folder (holding *.pcd.bin), or a nuScenes root \
             holding samples/LIDAR_TOP",
            dir.display()
        )
    }

    /// The output stem of scan `path` (its file name without the layout's extension).
    fn stem(&self, path: &Path) -> String {
        let name = path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        name.strip_suffix(self.layout.extension())
            .unwrap_or(&name)
            .to_string()
    }
}

/// Name of the settings file in the output folder.
pub const SETTINGS_FILE: &str = "dataset-run.json";

/// What one file gave: points in, points kept.
struct FileDone {
    points: usize,
    kept: usize,
}

/// Refuses the options that have no meaning for a dataset folder.
fn check_options(plan: &Plan, request: &RunRequest) -> Result<()> {
    let refused = |what: &str| -> Result<()> {
        bail!(
            "{what}: a dataset folder is written back in its own layout, one scan file and \
             its .fate.csv per input scan; run single scans for other outputs"
        )
    };
    if plan.pcap_out {
        return refused("--pcap-out");
    }
    if request.chunk_frames.is_some() || request.merge {
        bail!(
            "--chunk-frames and --merge split captures into frame ranges: a dataset folder's \
             scans are one frame each; share them among nodes with --shard alone"
        );
    }
    if !plan.native {
        return refused("--format");
    }
    if !plan.ply {
        return refused("--no-ply");
    }
    if plan.keep_dropped {
        return refused("--keep-dropped");
    }
    if plan.linkage {
        return refused("--linkage-out");
    }
    if plan.frames != (0..=u32::MAX) {
        bail!(
            "--frames selects a capture's frames: a dataset folder's scans are one frame each; \
             share them among nodes with --shard"
        );
    }
    Ok(())
}

/// The settings that decide a dataset run's bytes: a rerun with the same ones resumes.
fn settings(plan: &Plan, request: &RunRequest, data: &Dataset) -> Result<serde_json::Value> {
    let cloud = cloud_options(request, data.layout.format())?;
    Ok(serde_json::json!({
        "tool": "lidar-noise",
        "version": env!("CARGO_PKG_VERSION"),
        "layout": data.layout.name(),
        "scans": data.scans.len(),
        "config": plan.config.provenance(),
        "effective": plan.config.to_json(),
        "sensor": cloud.sensor.name,
        "rotation_hz": cloud.rotation_hz,
    }))
}

/// Runs every scan of the dataset folder `dir` that falls to this shard.
pub fn run(plan: &Plan, request: &RunRequest, dir: &Path, observer: &dyn Observer) -> Result<()> {
    check_options(plan, request)?;
    let data = Dataset::find(dir)?;
    // The noise chain for the dataset's sensor, checked before anything is written.
    let plan = &plan.for_sensor(cloud_options(request, data.layout.format())?.sensor)?;
    let out_dir = request.output.join(data.layout.scan_folder());
    // Written into the input folder, the noisy scans would replace the clean ones.
    if let (Ok(a), Ok(b)) = (
        std::fs::canonicalize(&out_dir),
        std::fs::canonicalize(&data.scan_dir),
    ) {
        if a == b {
            bail!(
                "{}: the output folder is the dataset's own: choose another -o",
                out_dir.display()
            );
        }
    }
    let settings = settings(plan, request, &data)?;
    let settings_path = request.output.join(SETTINGS_FILE);
    // Each file's writes are checked against its own scan and the protected files (the
    // output folder is not the scans' folder, checked above): against every scan, each
    // write would cost a stat per scan of the dataset.
    let mut inputs: Vec<&Path> = request.protected.iter().map(PathBuf::as_path).collect();
    inputs.extend(data.scans.first().map(PathBuf::as_path));
    let mut resume = true;
    if let Ok(bytes) = std::fs::read(&settings_path) {
        let found: Option<serde_json::Value> = serde_json::from_slice(&bytes).ok();
        if found.as_ref() != Some(&settings) {
            if !request.force {
                bail!(
                    "{}: the output folder holds a dataset run with other settings (or another \
                     dataset); rerun with --force to recompute every scan, or choose another \
                     output folder",
                    settings_path.display()
                );
            }
            resume = false;
        }
    } else if request.output.exists() && !request.output.is_dir() {
        bail!(
            "{}: the output is a file, not a folder",
            request.output.display()
        );
    }
    if request.force {
        resume = false;
    }
    std::fs::create_dir_all(&out_dir).map_err(|e| crate::error::Error::io(&out_dir, e))?;
    crate::writers::atomic::write_atomically(&settings_path, &inputs, |out| {
        out.write_all(serde_json::to_string_pretty(&settings)?.as_bytes())?;
        out.write_all(b"\n")
    })?;
    let total = data.scans.len();
    let owned: Vec<usize> = (0..total)
        .filter(|&i| request.shard.is_none_or(|s| s.owns(i)))
        .collect();
    observer.start(Counter::Scans, Some(owned.len() as u64));
    let skipped = AtomicUsize::new(0);
    let one = |i: usize| -> Result<Option<FileDone>> {
        let path = &data.scans[i];
        let stem = data.stem(path);
        let scan_out = out_dir.join(format!("{stem}{}", data.layout.extension()));
        let fate_out = out_dir.join(format!("{stem}.fate.csv"));
        // A labelled scan's scores: written before the scan, so a scan file on disk means
        // all of its outputs are.
        let truth_out = crate::score::truth::labels_beside(path)
            .map(|_| out_dir.join(format!("{stem}.truth.json")));
        if resume
            && scan_out.is_file()
            && fate_out.is_file()
            && truth_out.as_ref().is_none_or(|t| t.is_file())
        {
            skipped.fetch_add(1, Ordering::Relaxed);
            observer.advance(Counter::Scans, 1);
            return Ok(None);
        }
        let mut own = inputs.clone();
        own[inputs.len() - 1] = path;
        let outs = (scan_out.as_path(), fate_out.as_path(), truth_out.as_deref());
        let done = run_file(plan, request, &data, i, outs, &own);
        observer.advance(Counter::Scans, 1);
        done.map(Some)
    };
    let workers = crate::par::worker_threads();
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(workers)
        .build()
        .map_err(|e| anyhow::anyhow!("cannot start {workers} worker threads: {e}"))?;
    // One file per task, in order of index: results come back in the files' order.
    let results: Vec<Result<Option<FileDone>>> =
        pool.install(|| owned.par_iter().with_max_len(1).map(|&i| one(i)).collect());
    observer.finish(Counter::Scans);
    let failed = results.iter().filter(|r| r.is_err()).count();
    let (mut points, mut kept, mut computed) = (0usize, 0usize, 0usize);
    let mut first_error = None;
    for r in results {
        match r {
            Ok(Some(d)) => {
                points += d.points;
                kept += d.kept;
                computed += 1;
            }
            Ok(None) => {}
            Err(e) if first_error.is_none() => first_error = Some(e),
            Err(_) => {}
        }
    }
    if let Some(e) = first_error {
        bail!(
            "{e:#} ({failed} of {} scan{} failed and wrote nothing; the others are written: \
             fix or remove the failed scans and rerun to finish)",
            owned.len(),
            if owned.len() == 1 { "" } else { "s" }
        );
    }
    let shard = request.shard.map_or_else(String::new, |s| {
        format!(" (shard {s}: {} of {total})", owned.len())
    });
    observer.note(&format!(
        "{}: {} {} scan{}{shard}, {computed} computed ({kept} points written from {points}), {} \
         already done; results in {}",
        dir.display(),
        total,
        data.layout.name(),
        if total == 1 { "" } else { "s" },
        skipped.load(Ordering::Relaxed),
        out_dir.display()
    ));
    Ok(())
}

/// Reads scan `i`, runs it through the pipeline as frame `i` and writes it back with its
/// sidecar of fates. Nothing is written when reading or processing fails.
fn run_file(
    plan: &Plan,
    request: &RunRequest,
    data: &Dataset,
    i: usize,
    (scan_out, fate_out, truth_out): (&Path, &Path, Option<&Path>),
    inputs: &[&Path],
) -> Result<FileDone> {
    let path = &data.scans[i];
    let options = cloud_options(request, data.layout.format())?;
    let (mut frame, format, _, order, truth) = read_frame(path, &options)?;
    // The file's index in sorted order is its frame index: its random streams derive from
    // (seed, index, stage), the same whether it runs in a shard or in the whole run.
    frame.index = u32::try_from(i)
        .map_err(|_| anyhow::anyhow!("{}: more than 2^32 scans", data.scan_dir.display()))?;
    let points = frame.returns.len();
    let result = plan
        .pipeline
        .process_points(frame)
        .map_err(|e| anyhow::anyhow!("{}: {e:#}", path.display()))?;
    let (rows, rows_order) = super::frame_files::scan_points_in_input_order(&result, &order);
    let kept = rows.len();
    let written = (|| -> Result<()> {
        if let (Some(t), Some(out)) = (&truth, truth_out) {
            let bands = &crate::score::metrics::DEFAULT_BANDS;
            let score = t.score(&result, plan.config.cluster.min_points, bands);
            crate::writers::atomic::write_atomically(out, inputs, |w| {
                serde_json::to_writer_pretty(&mut *w, &score).map_err(std::io::Error::other)
            })?;
        }
        super::frame_files::write_scan_files_in_order(
            format,
            &rows,
            &rows_order,
            scan_out,
            fate_out,
            inputs,
        )
    })();
    if written.is_err() {
        // The sidecars went first: without their scan they are no output of this file.
        if !scan_out.exists() {
            std::fs::remove_file(fate_out).ok();
            if let Some(t) = truth_out {
                std::fs::remove_file(t).ok();
            }
        }
    }
    written?;
    Ok(FileDone { points, kept })
}
