//! The final outputs of a sweep, rebuilt from the rows every time: tables, plots, the
//! bird's-eye figure and `index.html`. Nothing here depends on timing or thread count.

use super::birdseye::Panel;
use super::plan::{Vary, VaryKind};
use super::run::{Row, Rows};
use super::tables::{self, Group};
use crate::error::{Error, Result};
use crate::writers::figure::{self, BirdsEyePanel, FigureFormat, LinePlot, Series};
use crate::writers::html::{Figure, Link, LinkGroup, Page, Section};
use std::path::{Path, PathBuf};

/// The bird's-eye figure to draw.
#[derive(Clone, Debug)]
pub struct BirdsEye {
    /// Capture name.
    pub capture: String,
    /// Frame index.
    pub frame: u32,
    /// Seed used.
    pub seed: u64,
    /// The panels.
    pub panels: Vec<Panel>,
    /// Half-width of the view in metres.
    pub extent_m: f64,
}

/// Files written, relative to the output folder.
pub const TIDY_CSV: &str = "sweep.csv";
/// The tidy table as JSON.
pub const TIDY_JSON: &str = "sweep.json";
/// The aggregate table.
pub const AGGREGATE_CSV: &str = "aggregate.csv";
/// What each column of the aggregate table holds.
pub const AGGREGATE_COLUMNS_CSV: &str = "aggregate_columns.csv";
/// The page.
pub const INDEX_HTML: &str = "index.html";

/// Index of the varied key used as the plots' x axis: a rain rate if varied, else the
/// first numeric key.
pub fn x_axis(varies: &[Vary]) -> Option<usize> {
    varies
        .iter()
        .position(|v| v.key.ends_with("rate_mm_h") && v.is_numeric())
        .or_else(|| varies.iter().position(|v| v.is_numeric()))
}

fn x_label(v: &Vary) -> String {
    if v.key.ends_with("rate_mm_h") {
        "rain rate (mm/h)".into()
    } else {
        v.key.clone()
    }
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

/// What a metric measures, for its axis and its number format.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kind {
    /// A share in [0, 1]: three decimals, y axis 0 to 1.
    Share,
    /// A count (per frame): whole numbers as integers, other means with one decimal;
    /// integer axis ticks.
    Count,
    /// A length in metres, with the given decimals.
    Metres(usize),
}

/// How a metric is shown: title with its unit, kind, and how to read its plot.
#[derive(Clone, Debug, PartialEq)]
pub struct Presentation {
    /// Human title with the unit, e.g. "Objects detected (share)".
    pub title: String,
    /// Share, count or length.
    pub kind: Kind,
    /// One sentence on how to read the plot.
    pub read: String,
}

fn capitalised(s: &str) -> String {
    let mut c = s.chars();
    match c.next() {
        Some(f) => f.to_uppercase().chain(c).collect(),
        None => String::new(),
    }
}

/// The presentation of metric `name` whose table label (with unit) is `label`: fixed
/// titles and reading notes for the known metrics, the capitalised label otherwise (per
/// band and per class metrics carry their band or class in the label).
pub fn presentation(name: &str, label: &str) -> Presentation {
    let kind = if label.ends_with("(count)") {
        Kind::Count
    } else if label.ends_with("(m)") {
        Kind::Metres(if name.starts_with("range_change") {
            3
        } else {
            1
        })
    } else {
        Kind::Share
    };
    let fixed: Option<(&str, &str)> = match name {
        "detected_share" => Some(("Objects detected (share)", "Share of the objects that one noisy cluster still holds (half of the returns that reach clustering, purity >= 0.5); higher is better.")),
        "retained_share" => Some(("Objects retained (share)", "Like detected, but against all of the object's clean returns, so returns dropped by noise count against it; higher is better.")),
        "split_share" => Some(("Objects split (share)", "Share of the objects broken over two or more noisy clusters; lower is better.")),
        "merged_share" => Some(("Objects merged (share)", "Share of the objects that are the minority of a cluster made mostly of other returns; lower is better.")),
        "merged_into_ground_share" => Some(("Objects merged into ground (share)", "Share of the objects whose reaching returns are mostly labelled ground; lower is better.")),
        "lost_share" => Some(("Objects lost (share)", "Share of the objects with no outcome above, e.g. none of their returns reach clustering; lower is better.")),
        "objects" => Some(("Objects per frame (count)", "Objects counted per frame; the same in every cell of a capture, so a check rather than a result.")),
        "object_survival" => Some(("Object survival (share, IoU >= 0.5)", "Share of the clean object clusters that a noisy cluster matches with IoU >= 0.5 (the older rule); higher is better.")),
        "kept" => Some(("Returns kept per frame (count)", "Returns that pass every noise stage and the detection filters; falls as noise removes returns.")),
        "occluded" => Some(("Returns occluded per frame (count)", "Returns blocked by the occlusion stage.")),
        "below_power" => Some(("Returns below the power threshold per frame (count)", "Returns whose power after the noise stages is under detection.min_power; rain's extinction raises it.")),
        "below_min_range" => Some(("Returns below the minimum range per frame (count)", "Returns closer than detection.min_range_m, e.g. rain drops at the window.")),
        "range_change_mean_m" => Some(("Mean range change of kept returns (m)", "Noisy minus clean range, averaged over kept returns; 0 means no bias.")),
        "range_change_rms_m" => Some(("RMS range change of kept returns (m)", "Root mean square of noisy minus clean range; grows with the range noise.")),
        "range_change_p95_m" => Some(("95th percentile of the range change (m)", "95 % of the kept returns moved less than this.")),
        "clusters" => Some(("Clusters per frame (count)", "Every cluster with at least min_points returns; noise can add or remove clusters.")),
        "object_clusters" => Some(("Object clusters per frame (count)", "Clusters that pass the object rule (height and footprint)." )),
        "matched" => Some(("Clean object clusters matched per frame (count)", "Clean object clusters that a noisy cluster matches with IoU >= 0.5; higher is better.")),
        "false_clusters" => Some(("False object clusters per frame (count)", "Noisy clusters made mostly of returns that belong to no clean object cluster; lower is better.")),
        "farthest_matched_m" => Some(("Farthest matched object cluster (m)", "Horizontal distance of the farthest matched clean object cluster; falls when far objects are lost.")),
        "ground_precision" => Some(("Ground precision (share)", "Share of the returns labelled ground that are ground, over the returns that reach ground removal; higher is better.")),
        "ground_recall" => Some(("Ground recall (share)", "Share of the ground returns reaching ground removal that are labelled ground; higher is better.")),
        "ground_lost_before_share" => Some(("Ground returns dropped before ground removal (share)", "Share of the ground returns removed by the noise stages or the detection filters before ground removal.")),
        _ => None,
    };
    if let Some((title, read)) = fixed {
        return Presentation {
            title: title.into(),
            kind,
            read: read.into(),
        };
    }
    let read = if name.starts_with("objects_") {
        "Objects per frame whose clean centroid lies in this distance band."
    } else if name.contains("_share_") && label.contains(" at ") {
        "Share of the objects in this distance band (horizontal distance of the clean centroid) with this outcome."
    } else if name.starts_with("detected_share_") {
        "Share of the labelled objects of this kind that are detected; higher is better."
    } else {
        match kind {
            Kind::Share => "A share between 0 and 1.",
            Kind::Count => "A count per frame.",
            Kind::Metres(_) => "A length in metres.",
        }
    };
    Presentation {
        title: capitalised(label),
        kind,
        read: read.into(),
    }
}

/// Formats a count: whole numbers without decimals, other means with one.
fn format_count(v: f64) -> String {
    if (v - v.round()).abs() < 1e-9 {
        figure::format_number(v.round(), 0)
    } else {
        figure::format_number(v, 1)
    }
}

/// Formats a value of a metric of kind `kind`.
pub fn format_value(kind: Kind, v: f64) -> String {
    match kind {
        Kind::Share => figure::format_number(v, 3),
        Kind::Count => format_count(v),
        Kind::Metres(d) => figure::format_number(v, d),
    }
}

/// Formats a mean and its interval; the interval is left out when it has no width at
/// the printed precision (every seed gave the same value) or there is none (one seed).
pub fn format_interval(kind: Kind, i: &tables::Interval) -> String {
    let mean = format_value(kind, i.mean);
    match (i.lo, i.hi) {
        (Some(lo), Some(hi)) => {
            let (lo, hi) = (format_value(kind, lo), format_value(kind, hi));
            if lo == mean && hi == mean {
                mean
            } else {
                format!("{mean} [{lo}, {hi}]")
            }
        }
        _ => mean,
    }
}

/// What a file of the sweep folder holds, for the page's list of files.
fn file_note(rel: &str, titles: &[(String, String)]) -> String {
    if let Some((_, t)) = titles.iter().find(|(p, _)| p == rel) {
        return t.clone();
    }
    match rel {
        TIDY_CSV => "one row per capture, frame, varied values and seed".into(),
        TIDY_JSON => "the same rows as JSON, with the metrics nested".into(),
        AGGREGATE_CSV => {
            "per capture and varied values: mean, lower and upper 95 % bound of every metric".into()
        }
        AGGREGATE_COLUMNS_CSV => {
            "what each column of the aggregate table holds, the interval method included".into()
        }
        _ if rel.starts_with("cells/") => "one cell's per-frame metrics and settings".into(),
        super::interactions::INTERACTIONS_CSV => {
            "per capture, stage pair and distance band: each alone, both, their product and the \
             verdict"
                .into()
        }
        super::interactions::INTERACTIONS_JSON => "the interaction table as JSON".into(),
        _ if rel.starts_with("plots/interactions_") => {
            "verdict of each stage pair in each distance band".into()
        }
        _ => String::new(),
    }
}

/// Every file under `dir` except hidden ones (temporaries, the lock) and `skip`, as
/// sorted relative paths with `/` separators.
fn folder_files(dir: &Path, skip: &str) -> Result<Vec<String>> {
    fn walk(root: &Path, d: &Path, out: &mut Vec<String>) -> std::io::Result<()> {
        for entry in std::fs::read_dir(d)? {
            let entry = entry?;
            let name = entry.file_name().to_string_lossy().into_owned();
            if name.starts_with('.') {
                continue;
            }
            let path = entry.path();
            if entry.file_type()?.is_dir() {
                walk(root, &path, out)?;
            } else if let Ok(rel) = path.strip_prefix(root) {
                let parts: Vec<String> = rel
                    .components()
                    .map(|c| c.as_os_str().to_string_lossy().into_owned())
                    .collect();
                out.push(parts.join("/"));
            }
        }
        Ok(())
    }
    let mut out = Vec::new();
    walk(dir, dir, &mut out).map_err(|e| Error::io(dir, e))?;
    out.retain(|f| f != skip);
    out.sort();
    Ok(out)
}

/// The section listing every file of the sweep folder, grouped: tables and other files
/// at the top level, plots, and the cells of each capture (folded, they can be many).
fn files_section(dir: &Path, titles: &[(String, String)], cells: &[String]) -> Result<Section> {
    let mut files = folder_files(dir, INDEX_HTML)?;
    files.extend(cells.iter().cloned());
    files.sort();
    files.dedup();
    let link = |f: &String| Link {
        href: f.clone(),
        note: file_note(f, titles),
    };
    let mut section = Section {
        heading: "Files".into(),
        paragraphs: vec![format!(
            "Everything in this folder, linked from here ({INDEX_HTML} is this page). The \
             page is rebuilt from the cells on every run; hidden files are temporaries and \
             the folder lock."
        )],
        ..Section::default()
    };
    let top: Vec<Link> = files
        .iter()
        .filter(|f| !f.contains('/'))
        .map(link)
        .collect();
    if !top.is_empty() {
        section.links.push(LinkGroup {
            title: "Tables and reports".into(),
            links: top,
            folded: false,
        });
    }
    let plots: Vec<Link> = files
        .iter()
        .filter(|f| f.starts_with("plots/"))
        .map(link)
        .collect();
    if !plots.is_empty() {
        section.links.push(LinkGroup {
            title: "Plots".into(),
            links: plots,
            folded: true,
        });
    }
    let mut groups: Vec<(String, Vec<Link>)> = Vec::new();
    for f in files
        .iter()
        .filter(|f| f.contains('/') && !f.starts_with("plots/"))
    {
        // Group by folder: cells/<capture>/..., or any other folder.
        let folder = f.rsplit_once('/').map_or("", |(d, _)| d).to_string();
        match groups.iter_mut().find(|(d, _)| *d == folder) {
            Some((_, l)) => l.push(link(f)),
            None => groups.push((folder, vec![link(f)])),
        }
    }
    for (folder, links) in groups {
        let title = match folder.strip_prefix("cells/") {
            Some(capture) => {
                format!("Cells of {capture} (one JSON file per cell: varied values and seed)")
            }
            None => format!("{folder}/"),
        };
        section.links.push(LinkGroup {
            title,
            links,
            folded: true,
        });
    }
    Ok(section)
}

/// Labels of the lines of one plot: the varied values other than the x axis's.
fn series_label(varies: &[Vary], values: &[String], xi: usize) -> String {
    let label: Vec<String> = varies
        .iter()
        .zip(values)
        .enumerate()
        .filter(|(k, _)| *k != xi)
        .map(|(_, (v, x))| match v.kind {
            VaryKind::Toggle { .. } => format!("{} {x}", v.key),
            _ => format!("{}={x}", v.key),
        })
        .collect();
    if label.is_empty() {
        "all".to_string()
    } else {
        label.join(", ")
    }
}

/// The lines of metric `mi` over the groups of one capture, x from varied key `xi`.
fn metric_series(varies: &[Vary], groups: &[&Group], mi: usize, xi: usize) -> Vec<Series> {
    let mut series: Vec<Series> = Vec::new();
    for g in groups {
        let Some(i) = g.metrics[mi] else { continue };
        let Ok(x) = g.values[xi].parse::<f64>() else {
            continue;
        };
        let label = series_label(varies, &g.values, xi);
        let point = (x, i.mean, i.lo.unwrap_or(i.mean), i.hi.unwrap_or(i.mean));
        match series.iter_mut().find(|s| s.label == label) {
            Some(s) => s.points.push(point),
            None => series.push(Series {
                label,
                points: vec![point],
            }),
        }
    }
    for s in &mut series {
        s.points.sort_by(|a, b| a.0.total_cmp(&b.0));
    }
    series
}

/// A line plot of a metric of kind `kind`.
fn line_plot(
    title: String,
    x: &Vary,
    kind: Kind,
    series: Vec<Series>,
    legend_title: &str,
) -> LinePlot {
    LinePlot {
        title,
        x_label: x_label(x),
        y_label: y_label(kind).into(),
        x_integer: x
            .values
            .iter()
            .all(|v| v.parse::<f64>().is_ok_and(|f| f.fract() == 0.0)),
        y_integer: kind == Kind::Count,
        y_range: (kind == Kind::Share).then_some((0.0, 1.0)),
        y_domain: match kind {
            Kind::Share => Some((0.0, 1.0)),
            Kind::Count => Some((0.0, f64::INFINITY)),
            Kind::Metres(_) => None,
        },
        legend_title: legend_title.into(),
        series,
    }
}

fn y_label(kind: Kind) -> &'static str {
    match kind {
        Kind::Share => "share (0 to 1)",
        Kind::Count => "count per frame (mean)",
        Kind::Metres(_) => "metres",
    }
}

/// What to conclude from the bird's-eye panels: each panel's clusters against the clean
/// one's.
fn birdseye_conclusion(panels: &[Panel]) -> String {
    let Some((clean, rest)) = panels.split_first() else {
        return String::new();
    };
    if rest.is_empty() {
        return String::new();
    }
    let each: Vec<String> = rest
        .iter()
        .map(|p| format!("{} {}", p.title, p.clusters))
        .collect();
    format!(
        "Conclusion: against {} clusters without noise ({}), {}; more clusters than clean \
         means noise split objects or added clutter clusters, fewer means objects were lost \
         or merged (with each other or with the ground): the sweep's tables and plots say \
         which.",
        clean.clusters,
        clean.title,
        each.join(", ")
    )
}

/// "at 7 mm/h" or "at KEY = 7": where on the x axis a value lies, for a sentence.
fn x_at(x: &Vary, v: f64) -> String {
    if x.key.ends_with("rate_mm_h") {
        format!("at {v} mm/h")
    } else {
        format!("at {} = {v}", x.key)
    }
}

/// A point of a line: x, mean, lower and upper bound.
type Point = (f64, f64, f64, f64);

/// True when two intervals (lo, hi) overlap; `None` when either has no width (one seed
/// or every seed equal): nothing can be said about the spread.
fn overlap(a: Point, b: Point) -> Option<bool> {
    let width = |p: Point| p.3 > p.2;
    (width(a) || width(b)).then_some(a.3 >= b.2 && b.3 >= a.2)
}

/// One sentence on what to conclude from line plot `plot`, from the values it draws:
/// how a single line changes from the smallest x to the largest, and whether that is
/// more than the spread over seeds; with several lines, how they compare at the largest
/// x. `better`: higher values are better (`Some(true)`), lower (`Some(false)`), or
/// neither.
fn conclusion(plot: &LinePlot, kind: Kind, x: &Vary, better: Option<bool>) -> String {
    let f = |v: f64| format_value(kind, v);
    let ends = |s: &Series| Some((*s.points.first()?, *s.points.last()?));
    let lines: Vec<(&Series, _)> = plot
        .series
        .iter()
        .filter_map(|s| ends(s).map(|e| (s, e)))
        .collect();
    let Some(&(_, (first, last))) = lines.first() else {
        return String::new();
    };
    if lines.len() == 1 || first.0 == last.0 {
        if first.0 == last.0 || f(first.1) == f(last.1) {
            return format!(
                "Conclusion: the mean stays at {} over the {} shown; this setting does not \
                    move it.",
                f(last.1),
                x_label(x)
            );
        }
        let verb = if last.1 > first.1 { "rises" } else { "falls" };
        let judged = match better {
            Some(b) if b == (last.1 > first.1) => " (better)",
            Some(_) => " (worse)",
            None => "",
        };
        let spread = match overlap(first, last) {
            Some(false) => {
                ", more than the spread over seeds (the intervals at the two ends \
                do not overlap)"
            }
            Some(true) => {
                ", but the intervals at the two ends overlap: with these seeds the \
                change is within the spread over seeds"
            }
            None => "",
        };
        return format!(
            "Conclusion: from {} to {} the mean {verb}{judged} from {} to {}{spread}.",
            x_at(x, first.0).trim_start_matches("at "),
            x_at(x, last.0).trim_start_matches("at "),
            f(first.1),
            f(last.1)
        );
    }
    // Several lines: how they compare at the largest x.
    let xmax = lines
        .iter()
        .map(|(_, (_, l))| l.0)
        .fold(f64::NEG_INFINITY, f64::max);
    let mut at_end: Vec<(&str, Point)> = lines
        .iter()
        .filter(|(_, (_, l))| l.0 == xmax)
        .map(|(s, (_, l))| (s.label.as_str(), *l))
        .collect();
    at_end.sort_by(|a, b| b.1 .1.total_cmp(&a.1 .1));
    let (top, bottom) = (at_end[0], at_end[at_end.len() - 1]);
    if f(top.1 .1) == f(bottom.1 .1) {
        return format!(
            "Conclusion: {} every line gives {}: the other varied values do not change this \
                metric there (lines drawn over each other; the markers tell them apart).",
            x_at(x, xmax),
            f(top.1 .1)
        );
    }
    let listed: Vec<String> = at_end
        .iter()
        .take(4)
        .map(|(l, p)| format!("{l} {}", f(p.1)))
        .collect();
    let more = if at_end.len() > 4 {
        format!(
            " and {} more lines down to {}",
            at_end.len() - 4,
            f(bottom.1 .1)
        )
    } else {
        String::new()
    };
    let best = match better {
        Some(true) => format!("; {} is best there", top.0),
        Some(false) => format!("; {} is best there", bottom.0),
        None => String::new(),
    };
    let spread = match overlap(top.1, bottom.1) {
        Some(false) => ", a gap larger than the spread over seeds",
        Some(true) => ", though the highest and lowest intervals overlap",
        None => "",
    };
    format!(
        "Conclusion: {} the lines give {}{more}{best}{spread}.",
        x_at(x, xmax),
        listed.join(", ")
    )
}

/// The masking sentence: when a line with an occlusion on detects more objects than
/// the same line with it off at 2 mm/h of rain or more, say why (it is the ground
/// method's artifact, not a better sensor). `None` when the plot shows no such case.
fn masking(plot: &LinePlot, x: &Vary) -> Option<String> {
    if !x.key.ends_with("rate_mm_h") {
        return None;
    }
    for on in &plot.series {
        if !on.label.contains("occlusion on") {
            continue;
        }
        let off_label = on.label.replace("occlusion on", "occlusion off");
        let Some(off) = plot.series.iter().find(|s| s.label == off_label) else {
            continue;
        };
        let above: Vec<(f64, f64, f64)> = on
            .points
            .iter()
            .filter(|p| p.0 >= 2.0)
            .filter_map(|p| {
                let q = off.points.iter().find(|q| q.0 == p.0)?;
                (p.1 > q.1 + 0.005).then_some((p.0, p.1, q.1))
            })
            .collect();
        let Some(&(r, a, b)) = above
            .iter()
            .max_by(|u, v| (u.1 - u.2).total_cmp(&(v.1 - v.2)))
        else {
            continue;
        };
        return Some(format!(
            "Masking: with the occlusion on more objects are detected than with it off at \
                rain of 2 mm/h or more ({} against {} at {r} mm/h). This is not a better \
                sensor: the occluded lasers are the noisiest near-ground rings, and with \
             range-image ground removal (paper.toml's) rain's range noise breaks its \
             ring-to-ring test, so their ground returns stay in the cloud as clutter that \
             merges with nearby objects; blocking those lasers removes that clutter along \
             with a few object returns.",
            format_value(Kind::Share, a),
            format_value(Kind::Share, b)
        ));
    }
    None
}

/// Which plot group a metric belongs to.
#[derive(Clone, Copy, PartialEq, Eq)]
enum PlotGroup {
    Main,
    Band,
    Class,
}

/// A plot to draw (or to report as all zero) and its place on the page.
struct Planned {
    name: String,
    plot: LinePlot,
    caption: String,
    read: String,
    kind: Kind,
}

/// Writes the plots of every capture and returns their page sections; `titles` gets
/// (relative path, title) of every plot written.
#[allow(clippy::too_many_arguments)]
fn plot_sections(
    dir: &Path,
    varies: &[Vary],
    captures: &[String],
    first: Option<&Row>,
    metrics: &[tables::Metric],
    groups: &[Group],
    protected: &[&Path],
    written: &mut Vec<PathBuf>,
    titles: &mut Vec<(String, String)>,
    format: FigureFormat,
) -> Result<Vec<Section>> {
    let Some(xi) = x_axis(varies) else {
        return Ok(Vec::new());
    };
    let xv = &varies[xi];
    let bands: Vec<(String, String)> = first.map_or_else(Vec::new, |r| {
        r.metrics
            .bands
            .iter()
            .map(|b| (tables::band_name(b), tables::band_title(b)))
            .collect()
    });
    let group_of = |name: &str| {
        if let Some(b) = name.strip_prefix("detected_share_") {
            if bands.iter().any(|(n, _)| n == b) {
                return Some(PlotGroup::Band);
            }
            return Some(PlotGroup::Class);
        }
        // Per band only the detected share gets a plot (the rest is in the tables).
        let per_band = ["objects_", "retained_share_", "lost_share_"];
        (!per_band.iter().any(|p| name.starts_with(p))).then_some(PlotGroup::Main)
    };
    let others = if varies.len() > 1 {
        "other varied values"
    } else {
        ""
    };
    let mut sections = Vec::new();
    for capture in captures {
        let cg: Vec<&Group> = groups.iter().filter(|g| &g.capture == capture).collect();
        let sub = format!("plots/{}", safe(capture));
        let mut planned: [Vec<Planned>; 3] = [Vec::new(), Vec::new(), Vec::new()];
        let mut empty = Vec::new();
        // Lines of the combined per-band and per-kind plots (one line per band or kind).
        let mut combined: [Vec<Series>; 3] = [Vec::new(), Vec::new(), Vec::new()];
        for (mi, metric) in metrics.iter().enumerate() {
            let Some(pg) = group_of(&metric.name) else {
                continue;
            };
            let pres = presentation(&metric.name, &metric.label);
            let series = metric_series(varies, &cg, mi, xi);
            if series.is_empty() {
                empty.push(pres.title);
                continue;
            }
            if pg != PlotGroup::Main && series.len() == 1 {
                let label = match pg {
                    PlotGroup::Band => bands
                        .iter()
                        .find(|(n, _)| metric.name.ends_with(n.as_str()))
                        .map_or_else(String::new, |(_, t)| t.clone()),
                    _ => metric
                        .label
                        .split_once(" objects")
                        .map_or_else(|| metric.name.clone(), |(k, _)| k.to_string()),
                };
                combined[pg as usize].push(Series {
                    label,
                    points: series[0].points.clone(),
                });
            }
            planned[pg as usize].push(Planned {
                name: metric.name.clone(),
                plot: line_plot(
                    format!("{} - {capture}", pres.title),
                    xv,
                    pres.kind,
                    series,
                    others,
                ),
                caption: pres.title,
                read: pres.read,
                kind: pres.kind,
            });
        }
        // With one line per plot, the bands (and the kinds) share one plot: one line
        // each, easier to compare than a plot each.
        for (pg, name, what, legend, read) in [
            (
                PlotGroup::Band,
                "detected_share_by_band",
                "Objects detected by distance band (share)",
                "distance band",
                "One line per band (horizontal distance of the object's clean centroid): \
                 where in distance the noise costs objects; higher is better.",
            ),
            (
                PlotGroup::Class,
                "detected_share_by_kind",
                "Objects detected by kind (share)",
                "object kind",
                "One line per labelled object kind: which kinds the noise costs; higher \
                 is better.",
            ),
        ] {
            let lines = std::mem::take(&mut combined[pg as usize]);
            let slot = &mut planned[pg as usize];
            if lines.len() >= 2 && lines.len() == slot.len() {
                *slot = vec![Planned {
                    name: name.into(),
                    plot: line_plot(
                        format!("{what} - {capture}"),
                        xv,
                        Kind::Share,
                        lines,
                        legend,
                    ),
                    caption: what.into(),
                    read: read.into(),
                    kind: Kind::Share,
                }];
            }
        }
        let mut figures: [Vec<Figure>; 3] = [Vec::new(), Vec::new(), Vec::new()];
        let mut zero: [Vec<String>; 3] = [Vec::new(), Vec::new(), Vec::new()];
        for (slot, plans) in planned.into_iter().enumerate() {
            for p in plans {
                if p.plot.all_zero() {
                    zero[slot].push(p.caption);
                    continue;
                }
                std::fs::create_dir_all(dir.join(&sub)).map_err(|e| Error::io(dir, e))?;
                let rel = format!("{sub}/{}.{}", p.name, format.extension());
                let path = dir.join(&rel);
                figure::line_plot(&p.plot, &path, protected, format)?;
                written.push(path);
                titles.push((rel.clone(), p.plot.title.clone()));
                let better = if p.read.contains("higher is better") {
                    Some(true)
                } else if p.read.contains("lower is better") {
                    Some(false)
                } else {
                    None
                };
                let mut conclusion = conclusion(&p.plot, p.kind, xv, better);
                if p.name.starts_with("detected_share") {
                    if let Some(m) = masking(&p.plot, xv) {
                        conclusion.push(' ');
                        conclusion.push_str(&m);
                    }
                }
                figures[slot].push(Figure {
                    src: rel,
                    caption: p.caption,
                    read: p.read,
                    conclusion,
                    wide: false,
                });
            }
        }
        let note = |z: &Vec<String>| {
            (!z.is_empty()).then(|| format!("All zero, not drawn: {}.", z.join("; ")))
        };
        let [main, band, class] = figures;
        let [zmain, zband, zclass] = zero;
        let mut notes: Vec<String> = note(&zmain).into_iter().collect();
        if !empty.is_empty() {
            notes.push(format!(
                "No values (they need ground-truth labels or objects), not drawn: {}.",
                empty.join("; ")
            ));
        }
        sections.push(Section {
            heading: format!("Plots: {capture}"),
            paragraphs: vec![format!(
                "Each point is the mean over seeds (each seed first reduced to its mean \
                 over frames), the shaded band its 95 % interval (shares: percentile \
                 bootstrap over seeds, within 0 to 1; counts: Student t, drawn from 0 up, \
                 the tables give it unclipped). The x axis is the {}. {}",
                x_label(xv),
                if varies.len() > 1 {
                    "One line per combination of the other varied values (legend on the right)."
                } else {
                    "One line: nothing else is varied."
                }
            )],
            figures: main,
            notes,
            ..Section::default()
        });
        for (heading, figures, z) in [
            (
                format!("{capture}: objects detected by distance band"),
                band,
                zband,
            ),
            (
                format!("{capture}: objects detected by kind"),
                class,
                zclass,
            ),
        ] {
            if figures.is_empty() && z.is_empty() {
                continue;
            }
            sections.push(Section {
                heading,
                sub: true,
                figures,
                notes: note(&z).into_iter().collect(),
                ..Section::default()
            });
        }
    }
    Ok(sections)
}

/// Writes every output file into `dir` (a staging folder: it holds only what this call
/// writes) and returns the paths written; `cells` are the cell files of the sweep
/// (relative paths, in the final folder), which the page lists too. The rows are read
/// once, a row at a time: the tidy tables are written as they come and only sums per
/// group and seed are kept, so memory does not grow with the frames.
#[allow(clippy::too_many_arguments)]
pub fn write_outputs(
    dir: &Path,
    varies: &[Vary],
    captures: &[String],
    rows: &dyn Rows,
    figure: Option<&BirdsEye>,
    protected: &[&Path],
    cells: &[String],
    format: FigureFormat,
) -> Result<Vec<PathBuf>> {
    use crate::writers::atomic::AtomicFile;
    let keys: Vec<String> = varies.iter().map(|v| v.key.clone()).collect();
    let mut written = Vec::new();
    let (csv_path, json_path) = (dir.join(TIDY_CSV), dir.join(TIDY_JSON));
    let mut csv = tables::TidyCsv::new(AtomicFile::create(&csv_path, protected)?, &keys);
    let mut json = tables::TidyJson::new(AtomicFile::create(&json_path, protected)?, &keys)
        .map_err(|e| Error::io(&json_path, e))?;
    let interactions = match varies {
        [vary] if matches!(vary.kind, VaryKind::Stages { .. }) => Some(vary),
        _ => None,
    };
    let mut set: Option<tables::MetricSet> = None;
    let mut first: Option<Row> = None;
    let mut aggregate = tables::Aggregate::default();
    let mut pooled = super::interactions::Pooled::default();
    let mut failed: Option<Error> = None;
    rows.each(&mut |r| {
        if failed.is_some() {
            return;
        }
        first.get_or_insert_with(|| r.clone());
        let set = set.get_or_insert_with(|| tables::MetricSet::new(Some(r)));
        set.see(r);
        aggregate.add(r, &set.metrics);
        if let Some(vary) = interactions {
            pooled.add(r, vary);
        }
        if let Err(e) = csv.row(r) {
            failed = Some(Error::io(&csv_path, e));
        } else if let Err(e) = json.row(r) {
            failed = Some(Error::io(&json_path, e));
        }
    })?;
    if let Some(e) = failed {
        return Err(e);
    }
    csv.finish()
        .map_err(|e| Error::io(&csv_path, e))?
        .commit()?;
    written.push(csv_path);
    json.finish()
        .map_err(|e| Error::io(&json_path, e))?
        .commit()?;
    written.push(json_path);
    let (metrics, order) = set.unwrap_or_else(|| tables::MetricSet::new(None)).finish();
    let groups = aggregate.groups(&order, &metrics);
    for (name, bytes) in [
        (
            AGGREGATE_CSV,
            tables::aggregate_csv(&keys, &groups, &metrics),
        ),
        (
            AGGREGATE_COLUMNS_CSV,
            tables::aggregate_columns_csv(&keys, &metrics),
        ),
    ] {
        let path = dir.join(name);
        crate::writers::atomic::write_atomically(&path, protected, |o| o.write_all(&bytes))?;
        written.push(path);
    }

    let mut page = Page {
        title: "lidar-noise sweep".into(),
        sections: Vec::new(),
    };
    let mut intro = Section {
        heading: "Settings".into(),
        ..Section::default()
    };
    for v in varies {
        intro
            .paragraphs
            .push(format!("varied: {} = {}", v.key, v.values.join(", ")));
    }
    intro.paragraphs.push(
        "Objects are the capture's labelled objects when it has labels, else the object \
         clusters of the same frame without noise stages (clusters 0.4-6 m tall with a \
         footprint up to 18 m by default: [cluster] object_* keys). An object is detected \
         when one noisy cluster holds at least half of its returns that reach clustering \
         with purity >= 0.5, retained when the same holds against all its clean returns \
         (dropped returns count as lost); otherwise it is merged into ground, merged, split \
         or lost (exclusive, in that order; see the sweep metrics module documentation). \
         Distance bands are [lo, hi) on the horizontal distance of the object's clean \
         centroid, the last one open. Object survival is the older IoU >= 0.5 match of \
         clean object clusters. Ground precision and recall count only the returns that \
         reach ground removal."
            .into(),
    );
    intro.paragraphs.push(
        "Intervals: each seed is first reduced to its mean over frames (shares pooled over \
         frames; frames of one capture are not independent samples), then the 95 % interval \
         is taken over seeds. Shares get the percentile bootstrap over seeds (2000 \
         resamples of the seeds' values; the 2.5th and 97.5th percentiles of their means), \
         which stays in [0, 1] and within the seeds' range: with few seeds it shows the \
         spread over seeds rather than a guaranteed coverage. Counts and lengths get the \
         Student t interval of the mean. With one seed there is no interval."
            .into(),
    );
    intro.paragraphs.push(format!(
        "Files: {TIDY_CSV} (one row per capture, frame, values, seed), {TIDY_JSON}, \
         {AGGREGATE_CSV} (its columns explained in {AGGREGATE_COLUMNS_CSV}), cells/ (one \
         result file per cell); every file is linked under Files at the end."
    ));
    page.sections.push(intro);

    let mut titles: Vec<(String, String)> = Vec::new();
    if let Some(f) = figure {
        std::fs::create_dir_all(dir.join("plots")).map_err(|e| Error::io(dir, e))?;
        let rel = format!("plots/birdseye_{}_frame{}.png", safe(&f.capture), f.frame);
        let panels: Vec<BirdsEyePanel> = f
            .panels
            .iter()
            .map(|p| BirdsEyePanel {
                title: format!("{}, seed {}: {} clusters", p.title, f.seed, p.clusters),
                details: if p.stages.is_empty() {
                    vec!["no noise stage".into()]
                } else {
                    p.stages.clone()
                },
                points: p.points.clone(),
            })
            .collect();
        let title = format!(
            "{} frame {}: base configuration, seed {}",
            f.capture, f.frame, f.seed
        );
        let path = dir.join(&rel);
        figure::birdseye(
            &title,
            &panels,
            f.extent_m,
            &path,
            protected,
            FigureFormat::Png,
        )?;
        written.push(path);
        titles.push((rel.clone(), title.clone()));
        let varied: Vec<&str> = varies.iter().map(|v| v.key.as_str()).collect();
        page.sections.push(Section {
            heading: "Bird's-eye view".into(),
            paragraphs: vec![format!(
                "The base configuration on one frame and seed: without noise, with each \
                 noise type alone, and with all of them. This is not one of the sweep's \
                 cells: the varied keys ({}) keep their base values, which each panel's \
                 stage lines give (e.g. the rain rate).",
                varied.join(", ")
            )],
            figures: vec![Figure {
                src: rel,
                caption: title,
                read: "Seen from above, x forward, the sensor at the centre. Each cluster \
                       has its own colour (colours repeat), ground is light grey, returns in \
                       no cluster dark grey; dropped returns are not drawn."
                    .into(),
                conclusion: birdseye_conclusion(&f.panels),
                wide: true,
            }],
            ..Section::default()
        });
    }

    page.sections.extend(plot_sections(
        dir,
        varies,
        captures,
        first.as_ref(),
        &metrics,
        &groups,
        protected,
        &mut written,
        &mut titles,
        format,
    )?);

    let table = |names: &[String]| {
        let cols: Vec<usize> = names
            .iter()
            .filter_map(|n| metrics.iter().position(|m| &m.name == n))
            .filter(|&i| groups.iter().any(|g| g.metrics[i].is_some()))
            .collect();
        let pres: Vec<Presentation> = cols
            .iter()
            .map(|&i| presentation(&metrics[i].name, &metrics[i].label))
            .collect();
        let mut header = vec!["capture".to_string()];
        header.extend(keys.iter().cloned());
        header.push("seeds".into());
        header.extend(cols.iter().map(|&i| metrics[i].name.clone()));
        let mut notes = vec![String::new(); 2 + keys.len()];
        notes.extend(pres.iter().map(|p| p.title.clone()));
        let body = groups
            .iter()
            .map(|g| {
                let mut r = vec![g.capture.clone()];
                r.extend(g.values.iter().cloned());
                r.push(g.seeds.to_string());
                r.extend(cols.iter().zip(&pres).map(|(&i, p)| {
                    g.metrics[i]
                        .as_ref()
                        .map_or_else(String::new, |v| format_interval(p.kind, v))
                }));
                r
            })
            .collect();
        ((header, body), notes)
    };
    let shown: Vec<String> = [
        "detected_share",
        "retained_share",
        "merged_share",
        "merged_into_ground_share",
        "split_share",
        "lost_share",
        "objects",
        "object_survival",
        "clusters",
        "object_clusters",
        "false_clusters",
        "kept",
        "range_change_rms_m",
        "ground_recall",
        "ground_lost_before_share",
    ]
    .map(String::from)
    .to_vec();
    let precision = "Shares with 3 decimals, counts per frame as whole numbers (means that \
                     are not whole with 1 decimal), range changes in metres with 3. The \
                     interval is left out where every seed gave the same value. Hover a \
                     column name for its meaning.";
    let (t, notes) = table(&shown);
    page.sections.push(Section {
        heading: "Table (mean [95 % interval over seeds])".into(),
        paragraphs: vec![format!("All metrics: {AGGREGATE_CSV}."), precision.into()],
        table: Some(t),
        column_notes: notes,
        ..Section::default()
    });
    if let Some(first) = &first {
        let mut by_band = Vec::new();
        for b in &first.metrics.bands {
            let name = tables::band_name(b);
            by_band.push(format!("objects_{name}"));
            by_band.push(format!("detected_share_{name}"));
        }
        if !by_band.is_empty() {
            let (t, notes) = table(&by_band);
            page.sections.push(Section {
                heading: "Objects by distance band (mean [95 % interval over seeds])".into(),
                paragraphs: vec![
                    "objects_<band>: objects in the band per frame; detected_share_<band>: \
                     detected objects over objects in the band. Bands are [lo, hi) on the \
                     horizontal distance of the object's clean centroid; the last is open."
                        .into(),
                ],
                table: Some(t),
                column_notes: notes,
                ..Section::default()
            });
        }
    }
    if let [vary] = varies {
        if let Some((files, section)) =
            super::interactions::write_outputs(dir, vary, captures, &pooled, protected, format)?
        {
            written.extend(files);
            page.sections.insert(1, section);
        }
    }
    page.sections.push(files_section(dir, &titles, cells)?);
    let path = dir.join(INDEX_HTML);
    crate::writers::write_file(&page, &path, protected)?;
    written.push(path);
    Ok(written)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counts_print_as_integers_and_shares_with_three_decimals() {
        assert_eq!(format_value(Kind::Count, 16.0), "16");
        assert_eq!(format_value(Kind::Count, 41185.294), "41185.3");
        assert_eq!(format_value(Kind::Share, 1.0), "1.000");
        assert_eq!(format_value(Kind::Share, -0.0), "0.000");
        let same = tables::Interval {
            n: 3,
            mean: 16.0,
            lo: Some(16.0),
            hi: Some(16.0),
        };
        assert_eq!(format_interval(Kind::Count, &same), "16");
        let wide = tables::Interval {
            n: 3,
            mean: 0.5,
            lo: Some(-0.0001),
            hi: Some(1.0),
        };
        assert_eq!(format_interval(Kind::Share, &wide), "0.500 [0.000, 1.000]");
    }

    #[test]
    fn every_metric_has_a_human_title() {
        for m in tables::metrics(&[]) {
            let p = presentation(&m.name, &m.label);
            assert!(!p.title.contains('_'), "{}: {}", m.name, p.title);
            assert!(p.title.ends_with(')'), "{}: no unit in {}", m.name, p.title);
            assert!(!p.title.starts_with(char::is_lowercase), "{}", p.title);
            assert!(!p.read.is_empty());
        }
    }
}
