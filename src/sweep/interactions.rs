//! Interaction verdicts between noise stages (`sweep --interactions`).
//!
//! Inputs are object counts per seed for one distance band: no stage (the clean run),
//! stage `a` alone, stage `b` alone and both together, each run with common random
//! numbers. Each seed's frames are pooled first (detected share = detected / objects over
//! the seed's frames: frames of one capture are not independent samples). Shares are then
//! taken relative to the clean run's share, `a = share(a) / share(none)`: with labelled
//! objects the clean pipeline itself misses some (e.g. far objects split ring by ring), and
//! independence multiplies the chances of surviving each stage, not the clean misses
//! twice. Seeds whose clean run detects nothing in the band are left out. Two per-seed
//! differences are summarised by their mean and 95 % t interval over seeds
//! ([`super::tables::interval`]):
//!
//! - `vs_independence = both - a * b` (the product is the independence prediction);
//! - `vs_worse = both - min(a, b)` (the worse of the two alone).
//!
//! The verdict, with tolerance [`TOLERANCE`] (absolute, in detected share):
//!
//! 1. **masking** when `vs_worse` has mean above the tolerance and (with two or more
//!    seeds) its interval lies above 0: the pair detects more than the worse stage alone;
//! 2. **compounding** when `vs_independence` has mean below minus the tolerance and (with
//!    two or more seeds) its interval lies below 0: worse than independence predicts;
//! 3. **independent** when the mean of `vs_independence` is within the tolerance of 0 or
//!    (with two or more seeds) its interval contains 0;
//! 4. **unclear** otherwise (e.g. better than independence but not better than the worse
//!    stage alone).

use super::plan::{Vary, VaryKind};
use super::run::Row;
use super::tables::{band_title, interval, Interval};
use serde::Serialize;
use std::collections::BTreeMap;

/// Tolerance of the verdicts, in detected share (5 percentage points).
pub const TOLERANCE: f64 = 0.05;

/// Objects and detected objects of one seed (frames pooled) in one band.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Counts {
    /// Objects present.
    pub objects: u64,
    /// Objects detected.
    pub detected: u64,
}

impl Counts {
    /// Detected share, `None` without objects.
    pub fn share(&self) -> Option<f64> {
        (self.objects > 0).then(|| self.detected as f64 / self.objects as f64)
    }
}

/// Plain-language verdict on one stage pair in one band.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Verdict {
    /// Together clearly worse than the product of each alone.
    Compounding,
    /// Together within the tolerance (or the interval) of the product.
    Independent,
    /// Together better than the worse of the two alone.
    Masking,
    /// None of the above holds clearly.
    Unclear,
}

impl Verdict {
    /// The verdict's word as written in tables.
    pub fn word(self) -> &'static str {
        match self {
            Verdict::Compounding => "compounding",
            Verdict::Independent => "independent",
            Verdict::Masking => "masking",
            Verdict::Unclear => "unclear",
        }
    }
}

/// Summary of one pair in one band over seeds.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PairResult {
    /// Seeds with objects in all four runs and a clean detection.
    pub seeds: usize,
    /// Mean detected share of the clean run (absolute).
    pub clean: f64,
    /// Mean detected share of stage `a` alone, relative to the clean run.
    pub a: f64,
    /// Mean detected share of stage `b` alone, relative to the clean run.
    pub b: f64,
    /// Mean detected share with both, relative to the clean run.
    pub both: f64,
    /// `both - a * b` over seeds.
    pub vs_independence: Interval,
    /// `both - min(a, b)` over seeds.
    pub vs_worse: Interval,
    /// The verdict.
    pub verdict: Verdict,
}

/// Verdict of one pair in one band from per-seed counts (same seed order in all four);
/// `None` when no seed has objects in all four runs and a clean detection.
pub fn pair_result(
    clean: &[Counts],
    a: &[Counts],
    b: &[Counts],
    both: &[Counts],
) -> Option<PairResult> {
    let mut sc = Vec::new();
    let mut sa = Vec::new();
    let mut sb = Vec::new();
    let mut sab = Vec::new();
    for (((c, x), y), z) in clean.iter().zip(a).zip(b).zip(both) {
        if let (Some(c), Some(x), Some(y), Some(z)) = (c.share(), x.share(), y.share(), z.share()) {
            if c > 0.0 {
                sc.push(c);
                sa.push(x / c);
                sb.push(y / c);
                sab.push(z / c);
            }
        }
    }
    let indep: Vec<f64> = (0..sab.len()).map(|i| sab[i] - sa[i] * sb[i]).collect();
    let worse: Vec<f64> = (0..sab.len()).map(|i| sab[i] - sa[i].min(sb[i])).collect();
    let vs_independence = interval(&indep)?;
    let vs_worse = interval(&worse)?;
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
    Some(PairResult {
        seeds: sab.len(),
        clean: mean(&sc),
        a: mean(&sa),
        b: mean(&sb),
        both: mean(&sab),
        vs_independence,
        vs_worse,
        verdict: verdict(&vs_independence, &vs_worse),
    })
}

/// The rule of the module docs applied to the two summarised differences.
pub fn verdict(vs_independence: &Interval, vs_worse: &Interval) -> Verdict {
    if vs_worse.mean > TOLERANCE && vs_worse.lo.is_none_or(|lo| lo > 0.0) {
        return Verdict::Masking;
    }
    if vs_independence.mean < -TOLERANCE && vs_independence.hi.is_none_or(|hi| hi < 0.0) {
        return Verdict::Compounding;
    }
    let contains_zero = matches!(
        (vs_independence.lo, vs_independence.hi),
        (Some(lo), Some(hi)) if lo <= 0.0 && hi >= 0.0
    );
    if vs_independence.mean.abs() <= TOLERANCE || contains_zero {
        return Verdict::Independent;
    }
    Verdict::Unclear
}

/// The stage pairs of an `--interactions` vary: (pair value, value of `a` alone, value of
/// `b` alone), by index into the vary's values.
fn pairs(vary: &Vary) -> Vec<(usize, usize, usize)> {
    let VaryKind::Stages { subsets } = &vary.kind else {
        return Vec::new();
    };
    let find = |set: &[usize]| subsets.iter().position(|s| s == set);
    subsets
        .iter()
        .enumerate()
        .filter(|(_, s)| s.len() == 2)
        .filter_map(|(k, s)| Some((k, find(&s[..1])?, find(&s[1..])?)))
        .collect()
}

/// One row of the interaction table: a stage pair in one distance band of one capture.
#[derive(Clone, Debug, PartialEq)]
pub struct InteractionRow {
    /// Capture name.
    pub capture: String,
    /// Distance band (`[5, 10) m`) or `all distances`.
    pub band: String,
    /// First stage of the pair (its `--interactions` value).
    pub a: String,
    /// Second stage of the pair.
    pub b: String,
    /// Objects times frames in the band per seed (frames pooled), mean over seeds.
    pub objects: f64,
    /// The pair's summary; `None` when no seed has objects and a clean detection.
    pub result: Option<PairResult>,
}

/// The capture name of the rows that pool every capture of the sweep.
pub const ALL_CAPTURES: &str = "all captures";

/// The name of the band row that pools every distance.
pub const ALL_DISTANCES: &str = "all distances";

/// What the interaction table needs of the rows, gathered a row at a time: objects and
/// detected objects summed over frames per capture, value and seed, per band of the
/// first row's layout and over all distances (last).
#[derive(Clone, Debug, Default)]
pub struct Pooled {
    bands: Option<Vec<String>>,
    counts: BTreeMap<(String, usize, u64), Vec<Counts>>,
}

impl Pooled {
    /// Adds a row of a sweep over `vary`.
    pub fn add(&mut self, r: &Row, vary: &Vary) {
        let bands = self
            .bands
            .get_or_insert_with(|| r.metrics.bands.iter().map(band_title).collect())
            .len();
        let Some(v) = r
            .values
            .first()
            .and_then(|x| vary.values.iter().position(|y| y == x))
        else {
            return;
        };
        let c = self
            .counts
            .entry((r.capture.clone(), v, r.seed))
            .or_insert_with(|| vec![Counts::default(); bands + 1]);
        for (i, b) in r.metrics.bands.iter().enumerate().take(bands) {
            c[i].objects += b.objects;
            c[i].detected += b.detected;
        }
        c[bands].objects += r.metrics.objects;
        c[bands].detected += r.metrics.detected;
    }
}

/// The interaction table of an `--interactions` sweep: per capture (then, with several,
/// all captures pooled per seed), pair and band (the sweep's bands, then all distances
/// pooled). Empty when `vary` is not `--interactions`.
pub fn table(rows: &[Row], vary: &Vary, captures: &[String]) -> Vec<InteractionRow> {
    let mut pooled = Pooled::default();
    for r in rows {
        pooled.add(r, vary);
    }
    table_of(&pooled, vary, captures)
}

/// [`table`] of rows gathered in `pooled`.
pub fn table_of(pooled: &Pooled, vary: &Vary, captures: &[String]) -> Vec<InteractionRow> {
    let pairs = pairs(vary);
    let mut out = Vec::new();
    let Some(none) = vary.values.iter().position(|v| v == super::plan::NO_STAGES) else {
        return out;
    };
    let bands: Vec<String> = pooled.bands.clone().unwrap_or_default();
    // Each capture, then (with several) all captures pooled per seed.
    let mut groups: Vec<(String, Vec<&String>)> =
        captures.iter().map(|c| (c.clone(), vec![c])).collect();
    if captures.len() > 1 {
        groups.push((ALL_CAPTURES.to_string(), captures.iter().collect()));
    }
    for (capture, members) in &groups {
        // (value, seed) -> counts per band, then all distances last.
        let mut counts: BTreeMap<(usize, u64), Vec<Counts>> = BTreeMap::new();
        for ((c, v, seed), per_band) in &pooled.counts {
            if !members.contains(&c) {
                continue;
            }
            let sum = counts
                .entry((*v, *seed))
                .or_insert_with(|| vec![Counts::default(); bands.len() + 1]);
            for (s, p) in sum.iter_mut().zip(per_band) {
                s.objects += p.objects;
                s.detected += p.detected;
            }
        }
        let mut seeds: Vec<u64> = counts.keys().map(|k| k.1).collect();
        seeds.sort_unstable();
        seeds.dedup();
        let series = |v: usize, band: usize| -> Vec<Counts> {
            seeds
                .iter()
                .map(|s| counts.get(&(v, *s)).map(|c| c[band]).unwrap_or_default())
                .collect()
        };
        for &(both, a, b) in &pairs {
            for (band, name) in bands
                .iter()
                .map(String::as_str)
                .chain([ALL_DISTANCES])
                .enumerate()
            {
                let clean = series(none, band);
                let objects = if seeds.is_empty() {
                    0.0
                } else {
                    clean.iter().map(|c| c.objects as f64).sum::<f64>() / seeds.len() as f64
                };
                out.push(InteractionRow {
                    capture: capture.clone(),
                    band: name.to_string(),
                    a: vary.values[a].clone(),
                    b: vary.values[b].clone(),
                    objects,
                    result: pair_result(
                        &clean,
                        &series(a, band),
                        &series(b, band),
                        &series(both, band),
                    ),
                });
            }
        }
    }
    out
}

/// Column names of the interaction CSV.
pub const CSV_HEADER: [&str; 17] = [
    "capture",
    "band",
    "stage_a",
    "stage_b",
    "seeds",
    "object_frames",
    "clean_detected_share",
    "a_alone",
    "b_alone",
    "both",
    "independence_product",
    "both_minus_product",
    "both_minus_product_lo",
    "both_minus_product_hi",
    "both_minus_worse",
    "both_minus_worse_lo",
    "both_minus_worse_hi",
];

fn fmt(v: Option<f64>) -> String {
    // Six decimals keep the file stable and exact enough; "-0" never appears.
    v.map_or_else(String::new, |v| {
        let t = format!("{v:.6}");
        if t.trim_start_matches('-')
            .chars()
            .all(|c| c == '0' || c == '.')
        {
            t.trim_start_matches('-').to_string()
        } else {
            t
        }
    })
}

/// The table as CSV: [`CSV_HEADER`] plus `verdict`; shares relative to the clean run.
pub fn to_csv(rows: &[InteractionRow]) -> Vec<u8> {
    let mut w = csv::Writer::from_writer(Vec::new());
    let mut header: Vec<&str> = CSV_HEADER.to_vec();
    header.push("verdict");
    // Writing to a Vec cannot fail.
    let _ = w.write_record(&header);
    for r in rows {
        let p = r.result.as_ref();
        let _ = w.write_record([
            r.capture.clone(),
            r.band.clone(),
            r.a.clone(),
            r.b.clone(),
            p.map_or(0, |p| p.seeds).to_string(),
            fmt(Some(r.objects)),
            fmt(p.map(|p| p.clean)),
            fmt(p.map(|p| p.a)),
            fmt(p.map(|p| p.b)),
            fmt(p.map(|p| p.both)),
            fmt(p.map(|p| p.a * p.b)),
            fmt(p.map(|p| p.vs_independence.mean)),
            fmt(p.and_then(|p| p.vs_independence.lo)),
            fmt(p.and_then(|p| p.vs_independence.hi)),
            fmt(p.map(|p| p.vs_worse.mean)),
            fmt(p.and_then(|p| p.vs_worse.lo)),
            fmt(p.and_then(|p| p.vs_worse.hi)),
            p.map_or("no objects", |p| p.verdict.word()).to_string(),
        ]);
    }
    w.into_inner().unwrap_or_default()
}

/// The table as JSON (the same fields as the CSV, numbers as numbers).
pub fn to_json(rows: &[InteractionRow]) -> serde_json::Value {
    let iv = |i: &Interval| serde_json::json!({"mean": i.mean, "lo": i.lo, "hi": i.hi});
    let rows: Vec<serde_json::Value> = rows
        .iter()
        .map(|r| {
            let p = r.result.as_ref();
            serde_json::json!({
                "capture": r.capture,
                "band": r.band,
                "stage_a": r.a,
                "stage_b": r.b,
                "seeds": p.map_or(0, |p| p.seeds),
                "object_frames": r.objects,
                "clean_detected_share": p.map(|p| p.clean),
                "a_alone": p.map(|p| p.a),
                "b_alone": p.map(|p| p.b),
                "both": p.map(|p| p.both),
                "independence_product": p.map(|p| p.a * p.b),
                "both_minus_product": p.map(|p| iv(&p.vs_independence)),
                "both_minus_worse": p.map(|p| iv(&p.vs_worse)),
                "verdict": p.map_or("no objects", |p| p.verdict.word()),
            })
        })
        .collect();
    serde_json::json!({
        "tool": format!("lidar-noise {}", env!("CARGO_PKG_VERSION")),
        "tolerance": TOLERANCE,
        "shares": "detected share relative to the run without noise stages, seeds' frames pooled",
        "rows": rows,
    })
}

/// The interaction CSV file.
pub const INTERACTIONS_CSV: &str = "interactions.csv";
/// The interaction JSON file.
pub const INTERACTIONS_JSON: &str = "interactions.json";

/// What to conclude from one capture's heatmap: how many cells have each verdict, and
/// what masking means where it occurs.
fn verdict_conclusion(rows: &[&InteractionRow]) -> String {
    let verdicts: Vec<Verdict> = rows
        .iter()
        .filter_map(|r| r.result.as_ref().map(|p| p.verdict))
        .collect();
    if verdicts.is_empty() {
        return String::new();
    }
    let count: Vec<String> = [
        Verdict::Compounding,
        Verdict::Independent,
        Verdict::Masking,
        Verdict::Unclear,
    ]
    .iter()
    .map(|v| (v, verdicts.iter().filter(|w| *w == v).count()))
    .filter(|(_, n)| *n > 0)
    .map(|(v, n)| format!("{n} {}", v.word()))
    .collect();
    let mut s = format!(
        "Conclusion: of {} pair and band cells with objects, {}.",
        verdicts.len(),
        count.join(", ")
    );
    if verdicts.contains(&Verdict::Masking) {
        s.push_str(
            " Masking cells are where the pair detects more than its worse stage alone: \
             one stage removes returns that would hurt the other (an occlusion blocking \
             the lasers whose rain-noised ground returns would merge with objects), not a \
             gain in the sensor.",
        );
    } else if verdicts.contains(&Verdict::Compounding) {
        s.push_str(" Compounding cells are where the two stages together cost more objects than independent stages would.");
    }
    s
}

/// Colour of a verdict in the heatmap (and its key).
fn verdict_color(v: Option<Verdict>) -> plotters::style::RGBColor {
    use plotters::style::RGBColor;
    match v {
        Some(Verdict::Compounding) => RGBColor(239, 138, 98),
        Some(Verdict::Independent) => RGBColor(224, 224, 224),
        Some(Verdict::Masking) => RGBColor(103, 169, 207),
        Some(Verdict::Unclear) => RGBColor(253, 219, 127),
        None => RGBColor(255, 255, 255),
    }
}

/// Writes the interaction table (CSV, JSON) and one heatmap per capture into `dir`;
/// returns the files written and the page section. Nothing when `vary` is not the
/// `--interactions` key.
pub fn write_outputs(
    dir: &std::path::Path,
    vary: &Vary,
    captures: &[String],
    pooled: &Pooled,
    protected: &[&std::path::Path],
    format: crate::writers::figure::FigureFormat,
) -> crate::error::Result<Option<(Vec<std::path::PathBuf>, crate::writers::html::Section)>> {
    use crate::writers::figure::heatmap::{heatmap, HeatCell, Heatmap};
    use crate::writers::html::{Figure, Section};
    if !matches!(vary.kind, VaryKind::Stages { .. }) {
        return Ok(None);
    }
    let table = table_of(pooled, vary, captures);
    let mut written = Vec::new();
    let mut put = |name: &str, bytes: &[u8]| -> crate::error::Result<()> {
        let path = dir.join(name);
        crate::writers::atomic::write_atomically(&path, protected, |o| o.write_all(bytes))?;
        written.push(path);
        Ok(())
    };
    put(INTERACTIONS_CSV, &to_csv(&table))?;
    let json = serde_json::to_vec_pretty(&to_json(&table))
        .map_err(|e| crate::error::Error::Invalid(format!("{INTERACTIONS_JSON}: {e}")))?;
    put(INTERACTIONS_JSON, &json)?;
    let mut section = Section {
        heading: "Interactions between noise stages".into(),
        paragraphs: vec![
            format!(
                "Each stage of the configuration alone, each pair and all together, with \
                 the same seeds (common random numbers). Detected shares are relative to \
                 the run without noise stages. For each pair: both together against the \
                 product of each alone (what independent stages would give) and against \
                 the worse of the two alone. Verdicts (tolerance {TOLERANCE} in share, and \
                 with two or more seeds the 95 % interval over seeds must exclude 0): \
                 masking when the pair detects more than the worse stage alone; \
                 compounding when it detects less than the product; independent when it \
                 is within the tolerance of the product or its interval contains it; \
                 unclear otherwise."
            ),
            format!("Files: {INTERACTIONS_CSV}, {INTERACTIONS_JSON}."),
        ],
        ..Section::default()
    };
    let share = |v: f64| format!("{v:.2}");
    let mut names: Vec<&String> = captures.iter().collect();
    let pooled = ALL_CAPTURES.to_string();
    if captures.len() > 1 {
        names.push(&pooled);
    }
    for capture in names {
        let rows: Vec<&InteractionRow> = table.iter().filter(|r| &r.capture == capture).collect();
        let mut columns: Vec<String> = Vec::new();
        let mut pair_names: Vec<String> = Vec::new();
        for r in &rows {
            if !columns.contains(&r.band) {
                columns.push(r.band.clone());
            }
            let name = format!("{} + {}", r.a, r.b);
            if !pair_names.contains(&name) {
                pair_names.push(name);
            }
        }
        if pair_names.is_empty() {
            continue;
        }
        let cells = pair_names
            .iter()
            .map(|name| {
                columns
                    .iter()
                    .map(|band| {
                        let r = rows
                            .iter()
                            .find(|r| &r.band == band && &format!("{} + {}", r.a, r.b) == name);
                        match r.and_then(|r| r.result.as_ref()) {
                            Some(p) => HeatCell {
                                color: verdict_color(Some(p.verdict)),
                                lines: vec![
                                    p.verdict.word().to_string(),
                                    format!("both {} vs {}", share(p.both), share(p.a * p.b)),
                                    format!("alone {} / {}", share(p.a), share(p.b)),
                                ],
                            },
                            None => HeatCell {
                                color: verdict_color(None),
                                lines: vec!["no objects".into()],
                            },
                        }
                    })
                    .collect()
            })
            .collect();
        let map = Heatmap {
            title: format!("{capture}: stage pairs by distance band (objects detected)"),
            rows: pair_names,
            columns,
            cells,
            key: [
                Verdict::Compounding,
                Verdict::Independent,
                Verdict::Masking,
                Verdict::Unclear,
            ]
            .iter()
            .map(|v| (verdict_color(Some(*v)), v.word().to_string()))
            .chain([(verdict_color(None), "no objects in the band".to_string())])
            .collect(),
            notes: vec![
                "both X vs Y: detected share with both stages against the product of each \
                 alone (independence)"
                    .into(),
                "alone A / B: each stage alone; shares relative to the run without noise, \
                 mean over seeds"
                    .into(),
            ],
        };
        std::fs::create_dir_all(dir.join("plots")).map_err(|e| crate::error::Error::io(dir, e))?;
        let rel = format!(
            "plots/interactions_{}.{}",
            safe(capture),
            format.extension()
        );
        let path = dir.join(&rel);
        heatmap(&map, &path, protected, format)?;
        written.push(path);
        section.figures.push(Figure {
            src: rel,
            caption: format!("{capture}: stage pairs by distance band"),
            read: "Each cell is one pair in one band: its colour is the verdict, \"both X vs \
                   Y\" the detected share with both stages against the product of each alone. \
                   Read a row across to see at which distances two stages interact."
                .into(),
            conclusion: verdict_conclusion(&rows),
            wide: true,
        });
    }
    let header: Vec<String> = [
        "capture",
        "band",
        "pair",
        "seeds",
        "object-frames",
        "clean",
        "a alone",
        "b alone",
        "both",
        "a x b",
        "both - a x b",
        "both - worse",
        "verdict",
    ]
    .map(String::from)
    .to_vec();
    let iv = |i: &Interval| match (i.lo, i.hi) {
        (Some(lo), Some(hi)) => format!("{:.3} [{lo:.3}, {hi:.3}]", i.mean),
        _ => format!("{:.3}", i.mean),
    };
    let body = table
        .iter()
        .map(|r| {
            let mut v = vec![
                r.capture.clone(),
                r.band.clone(),
                format!("{} + {}", r.a, r.b),
            ];
            match &r.result {
                Some(p) => v.extend([
                    p.seeds.to_string(),
                    format!("{:.1}", r.objects),
                    format!("{:.3}", p.clean),
                    format!("{:.3}", p.a),
                    format!("{:.3}", p.b),
                    format!("{:.3}", p.both),
                    format!("{:.3}", p.a * p.b),
                    iv(&p.vs_independence),
                    iv(&p.vs_worse),
                    p.verdict.word().to_string(),
                ]),
                None => {
                    v.extend(["0".to_string(), format!("{:.1}", r.objects)]);
                    v.extend(std::iter::repeat_n(String::new(), 7));
                    v.push("no objects".into());
                }
            }
            v
        })
        .collect();
    section.table = Some((header, body));
    Ok(Some((written, section)))
}

fn safe(name: &str) -> String {
    name.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || "._-".contains(c) {
                c
            } else {
                '_'
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn c(objects: u64, detected: u64) -> Counts {
        Counts { objects, detected }
    }

    fn clean(n: usize) -> Vec<Counts> {
        vec![c(10, 10); n]
    }

    #[test]
    fn shares_are_relative_to_the_clean_run() {
        // The clean run detects 8 of 10; each stage alone keeps 6 of those 8 (0.75), both
        // keep 4.5 of 8 on average: exactly the product of the relative shares.
        let clean = [c(10, 8), c(10, 8)];
        let a = [c(10, 6), c(10, 6)];
        let b = [c(10, 6), c(10, 6)];
        let both = [c(10, 4), c(10, 5)];
        let r = pair_result(&clean, &a, &b, &both).unwrap();
        assert!((r.a - 0.75).abs() < 1e-12 && (r.clean - 0.8).abs() < 1e-12);
        assert!((r.vs_independence.mean - (4.5 / 8.0 - 0.5625)).abs() < 1e-12);
        assert_eq!(r.verdict, Verdict::Independent, "{r:?}");
        // Taken absolutely, the product 0.36 against 0.45 would not read as independence.
        assert!((0.45f64 - 0.36).abs() > TOLERANCE);
    }

    #[test]
    fn each_alone_keeps_both_lose_is_compounding() {
        // Each stage alone keeps 9 of 10 objects, together only 2: product predicts 0.81.
        let a = [c(10, 9), c(10, 9), c(10, 8)];
        let b = [c(10, 9), c(10, 10), c(10, 9)];
        let both = [c(10, 2), c(10, 3), c(10, 2)];
        let r = pair_result(&clean(a.len()), &a, &b, &both).unwrap();
        assert_eq!(r.verdict, Verdict::Compounding, "{r:?}");
    }

    #[test]
    fn pair_better_than_worse_alone_is_masking() {
        // b alone is bad (0.3), but with a it recovers to 0.8.
        let a = [c(10, 9), c(10, 9), c(10, 9)];
        let b = [c(10, 3), c(10, 3), c(10, 4)];
        let both = [c(10, 8), c(10, 8), c(10, 8)];
        let r = pair_result(&clean(a.len()), &a, &b, &both).unwrap();
        assert_eq!(r.verdict, Verdict::Masking, "{r:?}");
    }

    #[test]
    fn product_is_independent() {
        let a = [c(10, 5), c(10, 5)];
        let b = [c(10, 8), c(10, 8)];
        let both = [c(10, 4), c(10, 4)];
        let r = pair_result(&clean(a.len()), &a, &b, &both).unwrap();
        assert!((r.vs_independence.mean).abs() < 1e-12);
        assert_eq!(r.verdict, Verdict::Independent, "{r:?}");
    }

    #[test]
    fn single_seed_uses_the_tolerance_only() {
        let r = pair_result(&[c(4, 4)], &[c(4, 4)], &[c(4, 4)], &[c(4, 3)]).unwrap();
        assert_eq!(r.vs_independence.lo, None);
        assert_eq!(r.verdict, Verdict::Compounding);
        let r = pair_result(
            &[c(100, 100)],
            &[c(100, 100)],
            &[c(100, 100)],
            &[c(100, 96)],
        )
        .unwrap();
        assert_eq!(r.verdict, Verdict::Independent);
    }

    #[test]
    fn seeds_without_objects_are_skipped() {
        assert!(pair_result(&[c(3, 3)], &[c(0, 0)], &[c(3, 3)], &[c(3, 3)]).is_none());
        // A seed whose clean run detects nothing is left out as well.
        assert!(pair_result(&[c(3, 0)], &[c(3, 3)], &[c(3, 3)], &[c(3, 3)]).is_none());
        let r = pair_result(
            &[c(3, 3), c(2, 2)],
            &[c(0, 0), c(2, 2)],
            &[c(3, 3), c(2, 2)],
            &[c(3, 3), c(2, 2)],
        );
        assert_eq!(r.unwrap().seeds, 1);
    }
}
