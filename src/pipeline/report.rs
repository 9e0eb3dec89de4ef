//! Reports of a run: the per-capture summary and the cluster report (JSON and CSV).

use super::{FrameResult, StageCounts};
use crate::cluster::ClusterInfo;
use crate::noise::NoiseSummary;
use crate::writers::csv::CsvTable;
use serde::Serialize;

/// Meaning of the PLY `fate` codes, in code order.
pub const FATE_CODES: [&str; 6] = [
    "kept",
    "occluded",
    "below_power",
    "below_min_range",
    "replaced",
    "added",
];

/// One frame's line in the summary.
#[derive(Clone, Debug, Serialize)]
pub struct FrameReport {
    /// Sweep index in the capture.
    pub index: u32,
    /// What the noise chain and the filters did.
    pub noise: NoiseSummary,
    /// Counts after ground removal and clustering.
    pub stages: StageCounts,
    /// Share of kept returns labelled ground.
    pub ground_fraction: f64,
}

impl FrameReport {
    /// Summarises a processed frame.
    pub fn of(result: &FrameResult) -> Self {
        FrameReport {
            index: result.noisy.index,
            noise: result.noise.clone(),
            stages: result.counts.clone(),
            ground_fraction: result.counts.ground_fraction(),
        }
    }
}

/// Totals over the frames of a capture.
#[derive(Clone, Debug, Default, Serialize)]
pub struct Totals {
    /// Merged noise summaries.
    pub noise: NoiseSummary,
    /// Summed stage counts.
    pub stages: StageCounts,
    /// Share of kept returns labelled ground.
    pub ground_fraction: f64,
}

impl Totals {
    /// Adds up frame reports.
    pub fn of(frames: &[FrameReport]) -> Self {
        let mut t = Totals::default();
        for f in frames {
            t.add(f);
        }
        t
    }

    /// Adds one frame report (the running form of `of`, for streamed reports).
    pub fn add(&mut self, f: &FrameReport) {
        self.noise.merge(&f.noise);
        self.stages.merge(&f.stages);
        self.ground_fraction = self.stages.ground_fraction();
    }
}

/// One frame's clusters in the cluster report.
#[derive(Clone, Debug, Serialize)]
pub struct FrameClusters {
    /// Sweep index in the capture.
    pub index: u32,
    /// Objects, sorted by id.
    pub clusters: Vec<ClusterInfo>,
}

/// Columns of the cluster CSV.
pub const CLUSTER_COLUMNS: [&str; 27] = [
    "frame",
    "cluster",
    "object",
    "points",
    "centroid_x",
    "centroid_y",
    "centroid_z",
    "min_x",
    "min_y",
    "min_z",
    "max_x",
    "max_y",
    "max_z",
    "extent_x",
    "extent_y",
    "extent_z",
    "box_center_x",
    "box_center_y",
    "box_length",
    "box_width",
    "box_yaw_deg",
    "box_z_min",
    "box_z_max",
    "min_range",
    "mean_range",
    "mean_intensity",
    "lasers",
];

/// The cluster report as one CSV table, one row per cluster.
pub fn cluster_table(frames: &[FrameClusters]) -> CsvTable {
    let mut t = CsvTable::new(&CLUSTER_COLUMNS);
    let f = |v: f64| format!("{v:.4}");
    for frame in frames {
        for c in &frame.clusters {
            let b = &c.oriented_box;
            let lasers: Vec<String> = c.lasers.iter().map(|l| l.to_string()).collect();
            t.rows.push(vec![
                frame.index.to_string(),
                c.id.to_string(),
                u8::from(c.object).to_string(),
                c.n_points.to_string(),
                f(c.centroid[0]),
                f(c.centroid[1]),
                f(c.centroid[2]),
                f(c.aabb_min[0]),
                f(c.aabb_min[1]),
                f(c.aabb_min[2]),
                f(c.aabb_max[0]),
                f(c.aabb_max[1]),
                f(c.aabb_max[2]),
                f(c.extent[0]),
                f(c.extent[1]),
                f(c.extent[2]),
                f(b.center[0]),
                f(b.center[1]),
                f(b.length),
                f(b.width),
                f(b.yaw_deg),
                f(b.z_min),
                f(b.z_max),
                f(c.min_range),
                f(c.mean_range),
                f(c.mean_intensity),
                lasers.join(" "),
            ]);
        }
    }
    t
}
