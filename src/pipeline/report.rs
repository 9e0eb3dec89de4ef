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

/// `format!("{v:.4}")`, byte for byte, without the exact big-number formatting for
/// ordinary values. `{:.4}` rounds the exact binary value to 4 decimals; for `|v| < 1e6`,
/// `v * 1e4` is within 1e-6 of the exact scaled value, so rounding it gives the same
/// digits unless its fraction lies within 1e-3 of one half (ties and near-ties, including
/// exact ties such as 1/32, go to `format!`, which decides them exactly). Negative values
/// that round to zero (printed `-0.0000`), NaN, infinities and large values also go to
/// `format!`. Profiling showed `{:.4}` (Grisu with Dragon fallback) at about 4 % of a run.
pub(crate) fn fixed4(v: f64) -> String {
    let a = v.abs();
    if a < 1e6 {
        let s = a * 1e4;
        let whole = s as u64;
        let frac = s - whole as f64;
        if (frac - 0.5).abs() > 1e-3 {
            let n = whole + u64::from(frac > 0.5);
            if n > 0 || !v.is_sign_negative() {
                let sign = if v.is_sign_negative() { "-" } else { "" };
                return format!("{sign}{}.{:04}", n / 10_000, n % 10_000);
            }
        }
    }
    format!("{v:.4}")
}

/// The cluster report as one CSV table, one row per cluster.
pub fn cluster_table(frames: &[FrameClusters]) -> CsvTable {
    let mut t = CsvTable::new(&CLUSTER_COLUMNS);
    let f = fixed4;
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

#[cfg(test)]
mod tests {
    use super::fixed4;
    use rand::{Rng, SeedableRng};

    fn check(v: f64) {
        assert_eq!(fixed4(v), format!("{v:.4}"), "{v:e} ({:#x})", v.to_bits());
    }

    #[test]
    fn fixed4_matches_format_on_ties_and_edges() {
        for v in [
            0.0,
            -0.0,
            f64::NAN,
            f64::INFINITY,
            f64::NEG_INFINITY,
            1e6,
            -1e6,
            999_999.999_95,
            1e300,
            -0.00004,
            -0.00005,
            -0.00006,
            0.00005,
            0.00015,
            1.00005,
            2.5e-5,
            f64::MIN_POSITIVE,
            -f64::MIN_POSITIVE,
        ] {
            check(v);
        }
        // Exact ties of the scaled value (dyadic fractions) and their neighbours.
        for k in -4096i64..4096 {
            for e in [5, 6, 7, 8, 10] {
                let v = k as f64 / f64::from(1u32 << e);
                check(v);
                check(f64::from_bits(v.to_bits() + 1));
                check(f64::from_bits(v.to_bits().wrapping_sub(1)));
            }
        }
    }

    #[test]
    fn fixed4_matches_format_on_random_values() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(14);
        for _ in 0..200_000 {
            let mag = 10f64.powi(rng.random_range(-6..8));
            let v = rng.random_range(-1.0..1.0) * mag;
            check(v);
            check(v as f32 as f64);
            // Values one 1e-4 step apart land on every fraction of the scaled value.
            check((v * 1e4).round() / 1e4 + 5e-5);
        }
    }
}
