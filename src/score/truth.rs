//! Dataset ground truth against what the pipeline found in a scan (issue 31, "Ground truth
//! from datasets"): ground precision and recall and per-object detection by distance band,
//! scored with the same functions (`score::metrics`) the sweep uses for synthesized
//! captures with their labels, so the figures of a real labelled scan and of a fixture mean
//! the same thing.
//!
//! The labels are in the file's point order; the pipeline's returns are in firing order:
//! [`crate::cloud::returns::CloudReturns::order`] (kept by `CloudReader::order`) maps one to the
//! other. Where the labels are found: [`labels_beside`].

use crate::cloud::labels::{read_labels_file, GroundTruth};
use crate::error::Result;
use crate::noise::Fate;
use crate::pipeline::FrameResult;
use crate::score::metrics::{self, BandMetrics, ClassMetrics, ReturnState, Tally};
use serde::Serialize;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// The scores of one labelled scan.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct TruthScore {
    /// Where the truth came from.
    pub labels: String,
    /// Points labelled ground.
    pub ground_points: usize,
    /// Share of the returns the method called ground that are ground in truth (over the
    /// returns reaching ground removal); `None` without ground truth or prediction.
    pub ground_precision: Option<f64>,
    /// Share of the ground returns reaching ground removal that the method called ground.
    pub ground_recall: Option<f64>,
    /// Object outcomes over the whole scan.
    pub objects: Tally,
    /// By distance band (horizontal distance of an object's centroid).
    pub bands: Vec<BandMetrics>,
    /// By the dataset's class.
    pub classes: Vec<ClassMetrics>,
    /// Points of an object class without an instance id (no object).
    pub without_instance: usize,
}

/// Scores `r` (the pipeline's result on a scan) against `truth` (per point of the file,
/// `order[i]` the point of return `i`): objects with at least `min_points` points, bands
/// with `edges`.
pub fn score(
    r: &FrameResult,
    truth: &GroundTruth,
    order: &[u32],
    min_points: usize,
    edges: &[f64],
    labels: &str,
) -> TruthScore {
    let clean = &r.noisy.clean[..r.noisy.clean_len];
    let point = |i: usize| order.get(i).map(|&k| k as usize);
    // Per recorded return: its noisy cluster (-1: dropped, ground, noise).
    let mut cluster = vec![-1i32; clean.len()];
    let mut state: Vec<ReturnState> = clean
        .iter()
        .enumerate()
        .map(|(i, c)| ReturnState {
            object: point(i)
                .and_then(|k| truth.objects.get(k))
                .copied()
                .unwrap_or(-1),
            reached: false,
            ground: false,
            cluster: -1,
            xy: [c.x, c.y],
        })
        .collect();
    let mut truth_reached = Vec::with_capacity(r.kept.len());
    for ((&k, &g), &l) in r.kept.iter().zip(&r.ground).zip(&r.labels) {
        let k = k as usize;
        // Only recorded returns the sensor still reports count; an added echo is never
        // ground in truth and reaches no object.
        let recorded = k < clean.len() && r.noisy.fate[k] == Fate::Kept;
        if recorded {
            state[k].reached = true;
            state[k].ground = g;
            cluster[k] = l;
        }
        truth_reached.push(
            recorded
                && point(k)
                    .and_then(|p| truth.ground.get(p))
                    .copied()
                    .unwrap_or(false),
        );
    }
    for (s, &c) in state.iter_mut().zip(&cluster) {
        s.cluster = c;
    }
    let (ground_precision, ground_recall) = if truth.ground.iter().any(|&g| g) {
        metrics::precision_recall(&truth_reached, &r.ground)
    } else {
        (None, None)
    };
    let results = metrics::object_outcomes(&state, min_points);
    let mut by_class: BTreeMap<&str, Tally> = BTreeMap::new();
    for o in &results {
        if let Some(kind) = truth.classes.get(&o.id) {
            by_class.entry(kind).or_default().add(o);
        }
    }
    TruthScore {
        labels: labels.to_string(),
        ground_points: truth.ground.iter().filter(|&&g| g).count(),
        ground_precision,
        ground_recall,
        objects: Tally::of(&results),
        bands: metrics::band_metrics(&results, edges),
        classes: by_class
            .into_iter()
            .map(|(kind, counts)| ClassMetrics {
                kind: kind.to_string(),
                counts,
            })
            .collect(),
        without_instance: truth.without_instance,
    }
}

/// A scan's ground truth as a frame source keeps it: per point of the file, with the
/// input index of each return of its frame.
#[derive(Clone, Debug, PartialEq)]
pub struct CloudTruth {
    /// The label files, for messages and the report.
    pub labels: String,
    /// Per point of the file.
    pub truth: GroundTruth,
    /// Input index of each return of the scan's frame.
    pub order: Vec<u32>,
}

impl CloudTruth {
    /// Scores the pipeline's result on the scan's frame (see [`score`]).
    pub fn score(&self, r: &FrameResult, min_points: usize, edges: &[f64]) -> TruthScore {
        score(r, &self.truth, &self.order, min_points, edges, &self.labels)
    }
}

/// Where a scan's labels are, when the dataset's layout puts them beside it:
/// SemanticKITTI `SEQ/velodyne/NNNNNN.bin` -> `SEQ/labels/NNNNNN.label`; KITTI object
/// `velodyne/NNNNNN.bin` -> `label_2/NNNNNN.txt` with `calib/NNNNNN.txt`.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum LabelsBeside {
    /// A per-point label file.
    PerPoint(PathBuf),
    /// KITTI boxes and their calibration.
    Boxes {
        /// The `label_2` file.
        label: PathBuf,
        /// The `calib` file.
        calib: PathBuf,
    },
}

/// The labels found beside `scan` (see [`LabelsBeside`]), if any exist.
pub fn labels_beside(scan: &Path) -> Option<LabelsBeside> {
    let name = scan.file_name()?.to_string_lossy().into_owned();
    let stem = name.strip_suffix(".bin")?;
    let dir = scan.parent()?;
    if dir.file_name()?.to_string_lossy() != "velodyne" {
        return None;
    }
    let root = dir.parent()?;
    let per_point = root.join("labels").join(format!("{stem}.label"));
    if per_point.is_file() {
        return Some(LabelsBeside::PerPoint(per_point));
    }
    let label = root.join("label_2").join(format!("{stem}.txt"));
    let calib = root.join("calib").join(format!("{stem}.txt"));
    (label.is_file() && calib.is_file()).then_some(LabelsBeside::Boxes { label, calib })
}

/// The ground truth of a scan of `points` (its points, for boxes) from `labels`.
pub fn read_truth(
    labels: &LabelsBeside,
    points: &[crate::cloud::CloudPoint],
) -> Result<GroundTruth> {
    match labels {
        LabelsBeside::PerPoint(path) => Ok(read_labels_file(path, None, points.len())?.truth()),
        LabelsBeside::Boxes { label, calib } => {
            let boxes = crate::cloud::boxes::read_label2(label)?;
            let calib = crate::cloud::boxes::read_calib(calib)?;
            Ok(crate::cloud::boxes::box_truth(points, &boxes, &calib))
        }
    }
}

impl LabelsBeside {
    /// The files, for messages.
    pub fn shown(&self) -> String {
        match self {
            LabelsBeside::PerPoint(p) => p.display().to_string(),
            LabelsBeside::Boxes { label, calib } => {
                format!("{} with {}", label.display(), calib.display())
            }
        }
    }
}
