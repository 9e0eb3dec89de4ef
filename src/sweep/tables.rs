//! Tables of a sweep: the tidy CSV and JSON (one row per capture, frame, values, seed)
//! and the aggregate CSV (mean and 95 % interval over seeds).
//!
//! Frames of one capture are not independent samples (the same scene, the same objects,
//! correlated noise), so the aggregate first reduces each seed to one value: the mean of
//! the metric over the seed's frames (for shares such as the detected share, the pooled
//! ratio: detected objects over objects, summed over the frames). The interval over seeds
//! then depends on what the metric is:
//!
//! - **Shares** (values in [0, 1]: the object shares, object survival, ground precision,
//!   recall and loss): the 95 % **percentile bootstrap over seeds**. The seeds' values
//!   are resampled with replacement [`BOOTSTRAP_RESAMPLES`] times (fixed random stream,
//!   so the same values give the same bounds on every machine and thread count), the
//!   mean taken of each resample, and the bounds are the 2.5th and 97.5th percentiles of
//!   those means (order statistics 50 and 1950 of 2000, 1-based). The bounds lie
//!   between the smallest and the largest seed's value, so a share's interval stays in
//!   [0, 1]: the Student t interval gave "0.984 [0.943, 1.024]" and
//!   "0.001 [-0.001, 0.002]". With few seeds it is narrower than the t interval (it cannot
//!   be wider than the seeds' range): read it as the spread over seeds, not as a
//!   guaranteed 95 % coverage.
//! - **Counts and lengths**: the Student t 95 % confidence interval of the mean,
//!   `mean +- t(0.975, n-1) * sd / sqrt(n)` with the exact t quantile.
//!
//! `n` is the number of seeds that have the metric. With a single seed there is no
//! interval: the bounds are left empty. [`aggregate_columns_csv`] writes what every
//! column of the aggregate table holds, method included.

use super::run::Row;
use crate::score::metrics::{BandMetrics, FrameMetrics};
use serde::Serialize;

/// How a column is read from a row.
pub type Getter = Box<dyn Fn(&FrameMetrics) -> Option<f64> + Send + Sync>;

/// One metric column: name, axis label with unit, and how to read it from a row.
pub struct Metric {
    /// Column name (snake_case).
    pub name: String,
    /// Axis label with its unit.
    pub label: String,
    /// The value of a row, if defined.
    pub get: Getter,
    /// For shares: the row's weight (its denominator); a seed's value is then the
    /// weighted mean of its frames, i.e. the pooled ratio. `None`: plain mean.
    pub weight: Option<Getter>,
    /// True when it needs ground-truth labels.
    pub needs_labels: bool,
    /// A share in [0, 1]: its interval is the percentile bootstrap over seeds, which
    /// stays in [0, 1]; otherwise the Student t interval.
    pub share: bool,
}

impl Metric {
    /// How the bounds of this metric's interval are computed.
    pub fn method(&self) -> IntervalMethod {
        if self.share {
            IntervalMethod::Bootstrap
        } else {
            IntervalMethod::StudentT
        }
    }
}

/// How the 95 % interval of a metric over seeds is computed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum IntervalMethod {
    /// Percentile bootstrap of the mean over seeds (shares: stays in [0, 1]).
    Bootstrap,
    /// Student t interval of the mean over seeds (counts and lengths).
    StudentT,
}

impl IntervalMethod {
    /// One phrase naming the method, for the column notes and the page.
    pub fn describe(self) -> &'static str {
        match self {
            IntervalMethod::Bootstrap => {
                "95 % percentile bootstrap over seeds (2000 resamples of the seeds' values, \
                    2.5th and 97.5th percentile of their means; stays within the seeds' range)"
            }
            IntervalMethod::StudentT => {
                "95 % Student t interval of the mean over seeds (mean +- t(0.975, n-1) sd / \
                    sqrt(n))"
            }
        }
    }
}

fn plain(name: &str, label: &str, get: fn(&FrameMetrics) -> Option<f64>) -> Metric {
    Metric {
        name: name.into(),
        label: label.into(),
        get: Box::new(get),
        weight: None,
        needs_labels: false,
        share: false,
    }
}

/// A share `part / whole` of a count group, pooled over frames.
fn share(
    name: String,
    label: String,
    part: impl Fn(&FrameMetrics) -> Option<u64> + Send + Sync + 'static,
    whole: impl Fn(&FrameMetrics) -> Option<u64> + Send + Sync + 'static,
) -> Metric {
    let whole = std::sync::Arc::new(whole);
    let w2 = whole.clone();
    Metric {
        name,
        label,
        get: Box::new(move |m| {
            let w = whole(m)?;
            (w > 0).then(|| part(m).unwrap_or(0) as f64 / w as f64)
        }),
        weight: Some(Box::new(move |m| w2(m).map(|w| w as f64))),
        needs_labels: false,
        share: true,
    }
}

/// Short name of a band for column names: `5_10m`, `40m_plus`.
pub fn band_name(b: &BandMetrics) -> String {
    match b.hi_m {
        Some(hi) => format!("{}_{}m", b.lo_m, hi),
        None => format!("{}m_plus", b.lo_m),
    }
}

/// Human name of a band: `[5, 10) m`, `>= 40 m`.
pub fn band_title(b: &BandMetrics) -> String {
    match b.hi_m {
        Some(hi) => format!("[{}, {}) m", b.lo_m, hi),
        None => format!(">= {} m", b.lo_m),
    }
}

/// Every aggregated metric of `rows`, in column order: the fixed ones, then per distance
/// band (layout of the first row) and per object class (every class seen).
pub fn metrics(rows: &[Row]) -> Vec<Metric> {
    let mut set = MetricSet::new(rows.first());
    for r in rows {
        set.see(r);
    }
    set.finish().0
}

/// The metrics of rows seen one at a time: the fixed ones and those of the first row's
/// bands from the start, one per object class as classes appear (appended: rows before
/// had none, so their sums stay right); [`MetricSet::finish`] puts the classes in name
/// order, as [`metrics`] lists them.
pub struct MetricSet {
    /// The metrics so far, classes in the order they appeared.
    pub metrics: Vec<Metric>,
    fixed: usize,
    kinds: Vec<String>,
}

impl MetricSet {
    /// The fixed metrics and those of the bands of `first` (the first row).
    pub fn new(first: Option<&Row>) -> MetricSet {
        let metrics = fixed_metrics(first);
        MetricSet {
            fixed: metrics.len(),
            metrics,
            kinds: Vec::new(),
        }
    }

    /// Adds a metric for each object class of `r` not seen before.
    pub fn see(&mut self, r: &Row) {
        for c in &r.metrics.classes {
            if !self.kinds.contains(&c.kind) {
                self.kinds.push(c.kind.clone());
                self.metrics.push(class_metric(&c.kind));
            }
        }
    }

    /// The metrics in column order (classes by name) and, for each, its index in
    /// [`MetricSet::metrics`] (where sums gathered with it hold it).
    pub fn finish(self) -> (Vec<Metric>, Vec<usize>) {
        let mut order: Vec<usize> = (0..self.fixed).collect();
        let mut classes: Vec<usize> = (0..self.kinds.len()).collect();
        classes.sort_by(|&a, &b| self.kinds[a].cmp(&self.kinds[b]));
        order.extend(classes.iter().map(|&k| self.fixed + k));
        let mut slots: Vec<Option<Metric>> = self.metrics.into_iter().map(Some).collect();
        let metrics = order.iter().filter_map(|&i| slots[i].take()).collect();
        (metrics, order)
    }
}

/// The metrics every sweep has, and those of the bands of `first`.
fn fixed_metrics(first: Option<&Row>) -> Vec<Metric> {
    macro_rules! int {
        ($f:ident, $l:expr) => {
            plain(stringify!($f), $l, |m| Some(m.$f as f64))
        };
    }
    macro_rules! opt {
        ($f:ident, $l:expr) => {
            plain(stringify!($f), $l, |m| m.$f)
        };
    }
    macro_rules! object_share {
        ($f:ident, $what:expr) => {
            share(
                concat!(stringify!($f), "_share").into(),
                format!("objects {} (share)", $what),
                |m| Some(m.$f),
                |m| Some(m.objects),
            )
        };
    }
    let mut out = vec![
        object_share!(detected, "detected"),
        object_share!(retained, "retained"),
        object_share!(split, "split"),
        object_share!(merged, "merged"),
        object_share!(merged_into_ground, "merged into ground"),
        object_share!(lost, "lost"),
        int!(objects, "objects (count)"),
        Metric {
            share: true,
            ..opt!(
                object_survival,
                "object survival (share of clean object clusters matched, IoU >= 0.5)"
            )
        },
        int!(kept, "returns kept (count)"),
        int!(occluded, "returns dropped by occlusion (count)"),
        int!(below_power, "returns dropped below power threshold (count)"),
        int!(
            below_min_range,
            "returns dropped below minimum range (count)"
        ),
        plain(
            "range_change_mean_m",
            "mean range change of kept returns (m)",
            |m| Some(m.range_change_mean_m),
        ),
        plain(
            "range_change_rms_m",
            "RMS range change of kept returns (m)",
            |m| Some(m.range_change_rms_m),
        ),
        plain(
            "range_change_p95_m",
            "95th percentile |range change| (m)",
            |m| Some(m.range_change_p95_m),
        ),
        int!(clusters, "clusters (count)"),
        int!(object_clusters, "object clusters (count)"),
        int!(matched, "clean object clusters matched (count)"),
        int!(false_clusters, "false object clusters (count)"),
        opt!(farthest_matched_m, "farthest matched object cluster (m)"),
    ];
    for (name, label, get) in [
        (
            "ground_precision",
            "ground precision over reaching returns (share)",
            (|m: &FrameMetrics| m.ground_precision) as fn(&FrameMetrics) -> Option<f64>,
        ),
        (
            "ground_recall",
            "ground recall over reaching returns (share)",
            |m: &FrameMetrics| m.ground_recall,
        ),
        (
            "ground_lost_before_share",
            "ground returns dropped before ground removal (share)",
            |m: &FrameMetrics| m.ground_lost_before_share,
        ),
    ] {
        let mut m = plain(name, label, get);
        m.needs_labels = true;
        m.share = true;
        out.push(m);
    }
    if let Some(first) = first {
        for (k, b) in first.metrics.bands.iter().enumerate() {
            let (name, title) = (band_name(b), band_title(b));
            out.push(plain(
                &format!("objects_{name}"),
                &format!("objects at {title} (count)"),
                |_| None,
            ));
            let last = out.len() - 1;
            out[last].get = Box::new(move |m| m.bands.get(k).map(|b| b.objects as f64));
            for (what, part) in [
                (
                    "detected",
                    (|b: &BandMetrics| b.detected) as fn(&BandMetrics) -> u64,
                ),
                ("retained", |b: &BandMetrics| b.retained),
                ("lost", |b: &BandMetrics| b.lost),
            ] {
                out.push(share(
                    format!("{what}_share_{name}"),
                    format!("objects {what} at {title} (share)"),
                    move |m| m.bands.get(k).map(part),
                    move |m| m.bands.get(k).map(|b| b.objects),
                ));
            }
        }
    }
    out
}

/// The detected share of the labelled objects of class `kind`.
fn class_metric(kind: &str) -> Metric {
    let (k1, k2) = (kind.to_string(), kind.to_string());
    let mut m = share(
        format!("detected_share_{}", safe_name(kind)),
        format!("{kind} objects detected (share)"),
        move |m| {
            m.classes
                .iter()
                .find(|c| c.kind == k1)
                .map(|c| c.counts.detected)
        },
        move |m| {
            m.classes
                .iter()
                .find(|c| c.kind == k2)
                .map(|c| c.counts.objects)
        },
    );
    m.needs_labels = true;
    m
}

fn safe_name(s: &str) -> String {
    s.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() {
                c.to_ascii_lowercase()
            } else {
                '_'
            }
        })
        .collect()
}

fn fmt_opt(v: Option<f64>) -> String {
    v.map_or_else(String::new, |x| x.to_string())
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
    "object_clusters",
    "baseline_clusters",
    "baseline_object_clusters",
    "matched",
    "object_survival",
    "false_clusters",
    "farthest_matched_m",
    "baseline_farthest_m",
    "labelled",
    "objects",
    "detected",
    "retained",
    "split",
    "merged",
    "merged_into_ground",
    "lost",
    "ground_precision",
    "ground_recall",
    "ground_lost_before_share",
];

/// Per-band columns of the tidy table, each followed by `_<band>` (see [`band_name`]).
pub const BAND_COLUMNS: &[&str] = &[
    "objects",
    "detected",
    "retained",
    "split",
    "merged",
    "merged_into_ground",
    "lost",
];

fn frame_values(m: &FrameMetrics) -> Vec<String> {
    let i = |x: u64| x.to_string();
    let f = |x: f64| x.to_string();
    let mut v = vec![
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
        i(m.object_clusters),
        i(m.baseline_clusters),
        i(m.baseline_object_clusters),
        i(m.matched),
        fmt_opt(m.object_survival),
        i(m.false_clusters),
        fmt_opt(m.farthest_matched_m),
        fmt_opt(m.baseline_farthest_m),
        m.labelled.to_string(),
        i(m.objects),
        i(m.detected),
        i(m.retained),
        i(m.split),
        i(m.merged),
        i(m.merged_into_ground),
        i(m.lost),
        fmt_opt(m.ground_precision),
        fmt_opt(m.ground_recall),
        fmt_opt(m.ground_lost_before_share),
    ];
    for b in &m.bands {
        v.extend(
            [
                b.objects,
                b.detected,
                b.retained,
                b.split,
                b.merged,
                b.merged_into_ground,
                b.lost,
            ]
            .map(i),
        );
    }
    v
}

/// The tidy CSV: capture, frame, one column per varied key, seed, then the metrics and
/// the per-band counts (`objects_0_5m`, `detected_0_5m`, ...; band layout of the first row).
pub fn tidy_csv(keys: &[String], rows: &[Row]) -> Vec<u8> {
    let mut t = TidyCsv::new(Vec::new(), keys);
    // Writing into memory cannot fail.
    for r in rows {
        let _ = t.row(r);
    }
    t.finish().unwrap_or_default()
}

/// The tidy CSV written a row at a time (see [`tidy_csv`]); the header, which takes the
/// band layout of the first row, goes out with it.
pub struct TidyCsv<W: std::io::Write> {
    out: csv::Writer<W>,
    keys: Vec<String>,
    header: bool,
}

impl<W: std::io::Write> TidyCsv<W> {
    /// A table of the varied `keys` into `out`.
    pub fn new(out: W, keys: &[String]) -> Self {
        TidyCsv {
            out: csv::Writer::from_writer(out),
            keys: keys.to_vec(),
            header: false,
        }
    }

    fn header(&mut self, first: Option<&Row>) -> std::io::Result<()> {
        let mut header = vec!["capture".to_string(), "frame".to_string()];
        header.extend(self.keys.iter().cloned());
        header.push("seed".into());
        header.extend(FRAME_COLUMNS.iter().map(|s| s.to_string()));
        if let Some(first) = first {
            for b in &first.metrics.bands {
                let name = band_name(b);
                header.extend(BAND_COLUMNS.iter().map(|c| format!("{c}_{name}")));
            }
        }
        self.header = true;
        Ok(self.out.write_record(&header)?)
    }

    /// Appends a row (after the header, on the first).
    pub fn row(&mut self, r: &Row) -> std::io::Result<()> {
        if !self.header {
            self.header(Some(r))?;
        }
        let mut v = vec![r.capture.clone(), r.metrics.frame.to_string()];
        v.extend(r.values.iter().cloned());
        v.push(r.seed.to_string());
        v.extend(frame_values(&r.metrics));
        Ok(self.out.write_record(&v)?)
    }

    /// Writes what is left (the header of a table without rows) and returns the output.
    pub fn finish(mut self) -> std::io::Result<W> {
        if !self.header {
            self.header(None)?;
        }
        self.out.into_inner().map_err(|e| e.into_error())
    }
}

#[derive(Serialize)]
struct JsonRow<'a> {
    capture: &'a str,
    frame: u32,
    parameters: serde_json::Map<String, serde_json::Value>,
    seed: u64,
    metrics: &'a FrameMetrics,
}

/// A row of the tidy JSON.
fn json_row(keys: &[String], r: &Row) -> serde_json::Value {
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
}

/// The tidy JSON document without its rows.
fn tidy_json_head(keys: &[String], rows: Vec<serde_json::Value>) -> serde_json::Value {
    serde_json::json!({
        "tool": format!("lidar-noise {}", env!("CARGO_PKG_VERSION")),
        "keys": keys,
        "rows": rows,
    })
}

/// The tidy table as JSON: `{"tool", "keys", "rows": [...]}`.
pub fn tidy_json(keys: &[String], rows: &[Row]) -> serde_json::Value {
    tidy_json_head(keys, rows.iter().map(|r| json_row(keys, r)).collect())
}

/// The tidy JSON written a row at a time, as `serde_json::to_vec_pretty` of
/// [`tidy_json`] would write it.
pub struct TidyJson<W: std::io::Write> {
    array: super::stream::ArrayWriter<W>,
    keys: Vec<String>,
}

impl<W: std::io::Write> TidyJson<W> {
    /// Starts the document of the varied `keys` in `out`.
    pub fn new(out: W, keys: &[String]) -> std::io::Result<Self> {
        Ok(TidyJson {
            array: super::stream::ArrayWriter::start(
                out,
                &tidy_json_head(keys, Vec::new()),
                "rows",
            )?,
            keys: keys.to_vec(),
        })
    }

    /// Appends a row.
    pub fn row(&mut self, r: &Row) -> std::io::Result<()> {
        self.array.push(&json_row(&self.keys, r))
    }

    /// Closes the document; returns the output.
    pub fn finish(self) -> std::io::Result<W> {
        self.array.finish()
    }
}

/// Mean and 95 % interval of one metric over a group's seeds.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Interval {
    /// Seeds with a value.
    pub n: usize,
    /// Mean over seeds.
    pub mean: f64,
    /// Lower bound; `None` with a single seed (no interval).
    pub lo: Option<f64>,
    /// Upper bound; `None` with a single seed.
    pub hi: Option<f64>,
}

/// Student t quantile `p` for `df` degrees of freedom (exact, via `statrs`).
pub fn t_quantile(p: f64, df: usize) -> Option<f64> {
    use statrs::distribution::{ContinuousCDF, StudentsT};
    let t = StudentsT::new(0.0, 1.0, df as f64).ok()?;
    Some(t.inverse_cdf(p))
}

/// Mean and t interval of `values` (one per seed); `None` when empty, no bounds for one.
pub fn interval(values: &[f64]) -> Option<Interval> {
    let n = values.len();
    if n == 0 {
        return None;
    }
    let mean = values.iter().sum::<f64>() / n as f64;
    let half = (n > 1)
        .then(|| {
            let var = values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1) as f64;
            t_quantile(0.975, n - 1).map(|t| t * (var / n as f64).sqrt())
        })
        .flatten();
    Some(Interval {
        n,
        mean,
        lo: half.map(|h| mean - h),
        hi: half.map(|h| mean + h),
    })
}

/// Resamples of the percentile bootstrap.
pub const BOOTSTRAP_RESAMPLES: usize = 2000;

/// Mean of `values` (one per seed) and its 95 % percentile bootstrap interval: the
/// 2.5th and 97.5th percentiles of the means of [`BOOTSTRAP_RESAMPLES`] resamples (with
/// replacement, from a fixed random stream). The bounds lie within the values' range.
/// `None` when empty, no bounds for one value.
pub fn bootstrap_interval(values: &[f64]) -> Option<Interval> {
    use rand::{Rng, SeedableRng};
    let n = values.len();
    if n == 0 {
        return None;
    }
    let mean = values.iter().sum::<f64>() / n as f64;
    if n == 1 {
        return Some(Interval {
            n,
            mean,
            lo: None,
            hi: None,
        });
    }
    // One fixed stream for every metric and group: the same values give the same
    // bounds whatever else the sweep holds.
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0x0b00_7577_a9b0_0757);
    let mut means: Vec<f64> = (0..BOOTSTRAP_RESAMPLES)
        .map(|_| {
            (0..n)
                .map(|_| values[rng.random_range(0..n as u32) as usize])
                .sum::<f64>()
                / n as f64
        })
        .collect();
    means.sort_by(f64::total_cmp);
    // Order statistics 50 and 1950 (1-based) of 2000: 2.5 % of the means lie at or
    // below the lower bound, 2.5 % at or above the upper one.
    let k = BOOTSTRAP_RESAMPLES / 40;
    // A resample's mean can differ from the values' bounds by rounding; the bounds are
    // kept within the values' range.
    let (min, max) = values
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
            (a.min(v), b.max(v))
        });
    Some(Interval {
        n,
        mean,
        lo: Some(means[k - 1].clamp(min, max)),
        hi: Some(means[BOOTSTRAP_RESAMPLES - k].clamp(min, max)),
    })
}

/// One value per seed: the metric's mean over the seed's frames (weighted for shares).
pub fn per_seed(metric: &Metric, rows: &[&Row]) -> Vec<f64> {
    let mut sums = SeedSums::default();
    for r in rows {
        sums.add(r, std::slice::from_ref(metric));
    }
    sums.values(0)
}

/// Per seed and metric, the weighted sum of the rows' values and the sum of their
/// weights (a seed's value is their ratio), gathered a row at a time.
#[derive(Clone, Debug, Default)]
pub struct SeedSums {
    seeds: std::collections::BTreeMap<u64, Vec<(f64, f64)>>,
}

impl SeedSums {
    /// Adds a row's value of each metric (metrics may have been appended since the
    /// last row: rows before had no value of them).
    pub fn add(&mut self, r: &Row, metrics: &[Metric]) {
        let sums = self.seeds.entry(r.seed).or_default();
        if sums.len() < metrics.len() {
            sums.resize(metrics.len(), (0.0, 0.0));
        }
        for (metric, (sum, weight)) in metrics.iter().zip(sums.iter_mut()) {
            let Some(v) = (metric.get)(&r.metrics) else {
                continue;
            };
            let w = metric.weight.as_ref().map_or(Some(1.0), |w| w(&r.metrics));
            if let Some(w) = w.filter(|&w| w > 0.0) {
                *sum += v * w;
                *weight += w;
            }
        }
    }

    /// The value of metric `i` of each seed with a weight, in seed order.
    pub fn values(&self, i: usize) -> Vec<f64> {
        self.seeds
            .values()
            .filter_map(|s| s.get(i).filter(|(_, w)| *w > 0.0).map(|(s, w)| s / w))
            .collect()
    }

    /// Seeds seen.
    pub fn seeds(&self) -> usize {
        self.seeds.len()
    }
}

/// The aggregate table gathered a row at a time: groups (capture, varied values) in
/// the order of their first row, each with its rows and [`SeedSums`].
#[derive(Clone, Debug, Default)]
pub struct Aggregate {
    groups: Vec<(String, Vec<String>, usize, SeedSums)>,
    last: usize,
}

impl Aggregate {
    /// Adds a row, with the values of `metrics`.
    pub fn add(&mut self, r: &Row, metrics: &[Metric]) {
        let same = |g: &(String, Vec<String>, usize, SeedSums)| g.0 == r.capture && g.1 == r.values;
        // Rows come cell by cell: most often in the group of the row before.
        let i = match self.groups.get(self.last).filter(|g| same(g)) {
            Some(_) => self.last,
            None => match self.groups.iter().position(same) {
                Some(i) => i,
                None => {
                    self.groups
                        .push((r.capture.clone(), r.values.clone(), 0, SeedSums::default()));
                    self.groups.len() - 1
                }
            },
        };
        self.last = i;
        self.groups[i].2 += 1;
        self.groups[i].3.add(r, metrics);
    }

    /// The groups; metric `k` of each is the one gathered at index `order[k]`.
    pub fn groups(&self, order: &[usize], metrics: &[Metric]) -> Vec<Group> {
        self.groups
            .iter()
            .map(|(capture, values, rows, sums)| Group {
                capture: capture.clone(),
                values: values.clone(),
                rows: *rows,
                seeds: sums.seeds(),
                metrics: order
                    .iter()
                    .zip(metrics)
                    .map(|(&i, m)| {
                        let values = sums.values(i);
                        match m.method() {
                            IntervalMethod::Bootstrap => bootstrap_interval(&values),
                            IntervalMethod::StudentT => interval(&values),
                        }
                    })
                    .collect(),
            })
            .collect()
    }
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
    /// Seeds in the group.
    pub seeds: usize,
    /// Interval of each metric of `metrics`, in order.
    pub metrics: Vec<Option<Interval>>,
}

/// Aggregates rows per seed, then over seeds, keeping the rows' order of first appearance.
pub fn aggregate(rows: &[Row], metrics: &[Metric]) -> Vec<Group> {
    let mut a = Aggregate::default();
    for r in rows {
        a.add(r, metrics);
    }
    a.groups(&(0..metrics.len()).collect::<Vec<_>>(), metrics)
}

/// The aggregate CSV: capture, varied keys, rows, seeds, then `<metric>_mean,_lo,_hi` each
/// (what each holds: [`aggregate_columns_csv`]).
pub fn aggregate_csv(keys: &[String], groups: &[Group], metrics: &[Metric]) -> Vec<u8> {
    let mut header = vec!["capture".to_string()];
    header.extend(keys.iter().cloned());
    header.push("rows".into());
    header.push("seeds".into());
    for m in metrics {
        for s in ["mean", "lo", "hi"] {
            header.push(format!("{}_{s}", m.name));
        }
    }
    let body = groups.iter().map(|g| {
        let mut v = vec![g.capture.clone()];
        v.extend(g.values.iter().cloned());
        v.push(g.rows.to_string());
        v.push(g.seeds.to_string());
        for i in &g.metrics {
            v.push(fmt_opt(i.map(|i| i.mean)));
            v.push(fmt_opt(i.and_then(|i| i.lo)));
            v.push(fmt_opt(i.and_then(|i| i.hi)));
        }
        v
    });
    csv_bytes(header, body)
}

/// A CSV document in memory.
fn csv_bytes(header: Vec<String>, rows: impl IntoIterator<Item = Vec<String>>) -> Vec<u8> {
    let mut w = csv::Writer::from_writer(Vec::new());
    // Writing into memory cannot fail.
    let _ = w.write_record(&header);
    for r in rows {
        let _ = w.write_record(&r);
    }
    w.into_inner().unwrap_or_default()
}

/// The aggregate table's column dictionary: one row per column of [`aggregate_csv`]
/// saying what it holds (`column,metric,holds`), the interval method included, so the
/// table reads without the documentation.
pub fn aggregate_columns_csv(keys: &[String], metrics: &[Metric]) -> Vec<u8> {
    let header = vec!["column".to_string(), "metric".into(), "holds".into()];
    let mut body: Vec<Vec<String>> =
        vec![vec!["capture".into(), String::new(), "capture name".into()]];
    for k in keys {
        body.push(vec![k.clone(), String::new(), "varied value".into()]);
    }
    body.push(vec![
        "rows".into(),
        String::new(),
        "rows (frames x seeds) aggregated".into(),
    ]);
    body.push(vec![
        "seeds".into(),
        String::new(),
        "seeds aggregated; each seed is first reduced to one value (its mean over frames, \
            shares pooled over frames)"
            .into(),
    ]);
    for m in metrics {
        let how = m.method().describe();
        for (s, holds) in [
            ("mean", format!("{}: mean over seeds", m.label)),
            (
                "lo",
                format!("{}: lower bound of the {how}; empty with one seed", m.label),
            ),
            (
                "hi",
                format!("{}: upper bound of the {how}; empty with one seed", m.label),
            ),
        ] {
            body.push(vec![format!("{}_{s}", m.name), m.name.clone(), holds]);
        }
    }
    csv_bytes(header, body)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn interval_of_known_values() {
        let i = interval(&[1.0, 2.0, 3.0]).unwrap();
        assert_eq!(i.mean, 2.0);
        // sd = 1, n = 3, t(0.975, 2) = 4.302653.
        assert!((i.hi.unwrap() - (2.0 + 4.302653 / 3f64.sqrt())).abs() < 1e-6);
        assert!(interval(&[]).is_none());
        let one = interval(&[0.7]).unwrap();
        assert_eq!((one.mean, one.lo, one.hi), (0.7, None, None));
    }

    /// A share near 1 (or near 0) over few seeds: the Student t interval left [0, 1]
    /// ("0.984 [0.943, 1.024]", "0.001 [-0.001, 0.002]"); the bootstrap stays inside.
    #[test]
    fn share_intervals_stay_in_zero_one() {
        for values in [
            vec![1.0, 1.0, 0.952],
            vec![1.0, 0.968, 1.0, 0.968, 1.0],
            vec![0.0, 0.003, 0.0],
            vec![0.0, 1.0],
        ] {
            let t = interval(&values).unwrap();
            assert!(
                t.lo.unwrap() < 0.0 || t.hi.unwrap() > 1.0,
                "{values:?}: the t interval is the failing case"
            );
            let b = bootstrap_interval(&values).unwrap();
            assert_eq!(b.mean, t.mean);
            let (lo, hi) = (b.lo.unwrap(), b.hi.unwrap());
            assert!((0.0..=1.0).contains(&lo) && (0.0..=1.0).contains(&hi));
            assert!(lo <= b.mean && b.mean <= hi && lo < hi, "{values:?}: {b:?}");
        }
        let one = bootstrap_interval(&[0.7]).unwrap();
        assert_eq!((one.lo, one.hi), (None, None));
        let same = bootstrap_interval(&[0.5, 0.5, 0.5]).unwrap();
        assert_eq!((same.lo, same.hi), (Some(0.5), Some(0.5)));
        // Deterministic: the same values give the same bounds.
        assert_eq!(
            bootstrap_interval(&[0.2, 0.9, 0.4]),
            bootstrap_interval(&[0.2, 0.9, 0.4])
        );
    }

    #[test]
    fn t_quantiles_are_exact() {
        for (df, t) in [
            (1, 12.706205),
            (2, 4.302653),
            (9, 2.262157),
            (40, 2.021075),
            (100, 1.983972),
        ] {
            let q = t_quantile(0.975, df).unwrap();
            assert!((q - t).abs() < 1e-5, "df {df}: {q} vs {t}");
        }
    }
}
