//! Tables of a sweep: the tidy CSV and JSON (one row per capture, frame, values, seed)
//! and the aggregate CSV (mean and 95 % interval over seeds and frames).
//!
//! The interval is the Student-t 95 % confidence interval of the mean,
//! `mean +- t(0.975, n-1) * sd / sqrt(n)` over the rows that have the metric; with a
//! single row both bounds equal the mean.

use super::metrics::FrameMetrics;
use super::run::Row;
use serde::Serialize;

/// One metric column: name, axis label with unit, and how to read it from a row.
pub struct Metric {
    /// Column name (snake_case).
    pub name: &'static str,
    /// Axis label with its unit.
    pub label: &'static str,
    /// The value of a row, if defined.
    pub get: fn(&FrameMetrics) -> Option<f64>,
    /// True when it needs ground-truth labels.
    pub needs_labels: bool,
}

macro_rules! metric {
    ($name:ident, $label:expr, int) => {
        Metric {
            name: stringify!($name),
            label: $label,
            get: |m| Some(m.$name as f64),
            needs_labels: false,
        }
    };
    ($name:ident, $label:expr, float) => {
        Metric {
            name: stringify!($name),
            label: $label,
            get: |m| Some(m.$name),
            needs_labels: false,
        }
    };
    ($name:ident, $label:expr, opt) => {
        Metric {
            name: stringify!($name),
            label: $label,
            get: |m| m.$name,
            needs_labels: false,
        }
    };
    ($name:ident, $label:expr, truth) => {
        Metric {
            name: stringify!($name),
            label: $label,
            get: |m| m.$name,
            needs_labels: true,
        }
    };
}

/// Every aggregated metric, in column order.
pub const METRICS: &[Metric] = &[
    metric!(
        object_survival,
        "object survival (share of clean clusters matched)",
        opt
    ),
    metric!(kept, "returns kept (count)", int),
    metric!(occluded, "returns dropped by occlusion (count)", int),
    metric!(
        below_power,
        "returns dropped below power threshold (count)",
        int
    ),
    metric!(
        below_min_range,
        "returns dropped below minimum range (count)",
        int
    ),
    metric!(
        range_change_mean_m,
        "mean range change of kept returns (m)",
        float
    ),
    metric!(
        range_change_rms_m,
        "RMS range change of kept returns (m)",
        float
    ),
    metric!(
        range_change_p95_m,
        "95th percentile |range change| (m)",
        float
    ),
    metric!(clusters, "clusters (count)", int),
    metric!(matched, "clean clusters matched (count)", int),
    metric!(split, "clean clusters split (count)", int),
    metric!(merged, "merged clusters (count)", int),
    metric!(lost, "clean clusters lost (count)", int),
    metric!(false_clusters, "false clusters (count)", int),
    metric!(farthest_matched_m, "farthest matched object (m)", opt),
    metric!(ground_precision, "ground precision (share)", truth),
    metric!(ground_recall, "ground recall (share)", truth),
    metric!(
        object_precision,
        "object detection precision (share)",
        truth
    ),
    metric!(object_recall, "object detection recall (share)", truth),
];

fn fmt_opt(v: Option<f64>) -> String {
    v.map_or_else(String::new, |x| x.to_string())
}

fn csv_bytes(header: Vec<String>, rows: Vec<Vec<String>>) -> Vec<u8> {
    let mut w = csv::Writer::from_writer(Vec::new());
    // Writing into memory cannot fail.
    let _ = w.write_record(&header);
    for r in rows {
        let _ = w.write_record(&r);
    }
    w.into_inner().unwrap_or_default()
}

/// Every per-frame column of the tidy table, in order.
pub const FRAME_COLUMNS: &[&str] = &[
    "returns",
    "kept",
    "baseline_kept",
    "occluded",
    "below_power",
    "below_min_range",
    "range_change_mean_m",
    "range_change_rms_m",
    "range_change_p95_m",
    "clusters",
    "baseline_clusters",
    "matched",
    "object_survival",
    "split",
    "merged",
    "lost",
    "false_clusters",
    "farthest_matched_m",
    "baseline_farthest_m",
    "ground_precision",
    "ground_recall",
    "object_precision",
    "object_recall",
];

fn frame_values(m: &FrameMetrics) -> Vec<String> {
    let i = |x: u64| x.to_string();
    let f = |x: f64| x.to_string();
    vec![
        i(m.returns),
        i(m.kept),
        i(m.baseline_kept),
        i(m.occluded),
        i(m.below_power),
        i(m.below_min_range),
        f(m.range_change_mean_m),
        f(m.range_change_rms_m),
        f(m.range_change_p95_m),
        i(m.clusters),
        i(m.baseline_clusters),
        i(m.matched),
        fmt_opt(m.object_survival),
        i(m.split),
        i(m.merged),
        i(m.lost),
        i(m.false_clusters),
        fmt_opt(m.farthest_matched_m),
        fmt_opt(m.baseline_farthest_m),
        fmt_opt(m.ground_precision),
        fmt_opt(m.ground_recall),
        fmt_opt(m.object_precision),
        fmt_opt(m.object_recall),
    ]
}

/// The tidy CSV: capture, frame, one column per varied key, seed, then the metrics.
pub fn tidy_csv(keys: &[String], rows: &[Row]) -> Vec<u8> {
    let mut header = vec!["capture".to_string(), "frame".to_string()];
    header.extend(keys.iter().cloned());
    header.push("seed".into());
    header.extend(FRAME_COLUMNS.iter().map(|s| s.to_string()));
    let body = rows
        .iter()
        .map(|r| {
            let mut v = vec![r.capture.clone(), r.metrics.frame.to_string()];
            v.extend(r.values.iter().cloned());
            v.push(r.seed.to_string());
            v.extend(frame_values(&r.metrics));
            v
        })
        .collect();
    csv_bytes(header, body)
}

#[derive(Serialize)]
struct JsonRow<'a> {
    capture: &'a str,
    frame: u32,
    parameters: serde_json::Map<String, serde_json::Value>,
    seed: u64,
    metrics: &'a FrameMetrics,
}

/// The tidy table as JSON: `{"tool", "keys", "rows": [...]}`.
pub fn tidy_json(keys: &[String], rows: &[Row]) -> serde_json::Value {
    let rows: Vec<serde_json::Value> = rows
        .iter()
        .map(|r| {
            let parameters = keys
                .iter()
                .zip(&r.values)
                .map(|(k, v)| (k.clone(), serde_json::Value::String(v.clone())))
                .collect();
            serde_json::to_value(JsonRow {
                capture: &r.capture,
                frame: r.metrics.frame,
                parameters,
                seed: r.seed,
                metrics: &r.metrics,
            })
            .unwrap_or(serde_json::Value::Null)
        })
        .collect();
    serde_json::json!({
        "tool": format!("lidar-noise {}", env!("CARGO_PKG_VERSION")),
        "keys": keys,
        "rows": rows,
    })
}

/// Mean and 95 % interval of one metric over a group.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Interval {
    /// Rows with a value.
    pub n: usize,
    /// Mean.
    pub mean: f64,
    /// Lower bound.
    pub lo: f64,
    /// Upper bound.
    pub hi: f64,
}

/// Student t quantile 0.975 for `df` degrees of freedom (1.96 past 30).
fn t975(df: usize) -> f64 {
    const T: [f64; 30] = [
        12.706, 4.303, 3.182, 2.776, 2.571, 2.447, 2.365, 2.306, 2.262, 2.228, 2.201, 2.179, 2.160,
        2.145, 2.131, 2.120, 2.110, 2.101, 2.093, 2.086, 2.080, 2.074, 2.069, 2.064, 2.060, 2.056,
        2.052, 2.048, 2.045, 2.042,
    ];
    match df {
        0 => 0.0,
        d if d <= 30 => T[d - 1],
        d if d <= 60 => 2.0,
        _ => 1.96,
    }
}

/// Mean and t interval of `values`; `None` when empty.
pub fn interval(values: &[f64]) -> Option<Interval> {
    let n = values.len();
    if n == 0 {
        return None;
    }
    let mean = values.iter().sum::<f64>() / n as f64;
    let half = if n > 1 {
        let var = values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1) as f64;
        t975(n - 1) * (var / n as f64).sqrt()
    } else {
        0.0
    };
    Some(Interval {
        n,
        mean,
        lo: mean - half,
        hi: mean + half,
    })
}

/// One group of the aggregate table: a capture and a combination of varied values.
#[derive(Clone, Debug, PartialEq)]
pub struct Group {
    /// Capture name.
    pub capture: String,
    /// Varied values, in `--vary` order.
    pub values: Vec<String>,
    /// Rows (seeds x frames) in the group.
    pub rows: usize,
    /// Interval of each metric of [`METRICS`], in order.
    pub metrics: Vec<Option<Interval>>,
}

/// Aggregates rows over seeds and frames, keeping the rows' order of first appearance.
pub fn aggregate(rows: &[Row]) -> Vec<Group> {
    let mut order: Vec<(String, Vec<String>)> = Vec::new();
    let mut members: Vec<Vec<&FrameMetrics>> = Vec::new();
    for r in rows {
        let key = (r.capture.clone(), r.values.clone());
        match order.iter().position(|k| *k == key) {
            Some(i) => members[i].push(&r.metrics),
            None => {
                order.push(key);
                members.push(vec![&r.metrics]);
            }
        }
    }
    order
        .into_iter()
        .zip(members)
        .map(|((capture, values), ms)| Group {
            capture,
            values,
            rows: ms.len(),
            metrics: METRICS
                .iter()
                .map(|m| {
                    let v: Vec<f64> = ms.iter().filter_map(|x| (m.get)(x)).collect();
                    interval(&v)
                })
                .collect(),
        })
        .collect()
}

/// The aggregate CSV: capture, varied keys, rows, then `<metric>_mean,_lo,_hi` each.
pub fn aggregate_csv(keys: &[String], groups: &[Group]) -> Vec<u8> {
    let mut header = vec!["capture".to_string()];
    header.extend(keys.iter().cloned());
    header.push("rows".into());
    for m in METRICS {
        for s in ["mean", "lo", "hi"] {
            header.push(format!("{}_{s}", m.name));
        }
    }
    let body = groups
        .iter()
        .map(|g| {
            let mut v = vec![g.capture.clone()];
            v.extend(g.values.iter().cloned());
            v.push(g.rows.to_string());
            for i in &g.metrics {
                v.push(fmt_opt(i.map(|i| i.mean)));
                v.push(fmt_opt(i.map(|i| i.lo)));
                v.push(fmt_opt(i.map(|i| i.hi)));
            }
            v
        })
        .collect();
    csv_bytes(header, body)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn interval_of_known_values() {
        let i = interval(&[1.0, 2.0, 3.0]).unwrap();
        assert_eq!(i.mean, 2.0);
        // sd = 1, n = 3, t(2) = 4.303.
        assert!((i.hi - (2.0 + 4.303 / 3f64.sqrt())).abs() < 1e-9);
        assert!(interval(&[]).is_none());
    }
}
