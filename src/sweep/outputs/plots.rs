//! The sweep's line plots and the conclusions written under them.

use super::*;

/// Labels of the lines of one plot: the varied values other than the x axis's.
pub(super) fn series_label(varies: &[Vary], values: &[String], xi: usize) -> String {
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
pub(super) fn metric_series(
    varies: &[Vary],
    groups: &[&Group],
    mi: usize,
    xi: usize,
) -> Vec<Series> {
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
pub(super) fn line_plot(
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

pub(super) fn y_label(kind: Kind) -> &'static str {
    match kind {
        Kind::Share => "share (0 to 1)",
        Kind::Count => "count per frame (mean)",
        Kind::Metres(_) => "metres",
    }
}

/// What to conclude from the bird's-eye panels: each panel's clusters against the clean
/// one's.
pub(super) fn birdseye_conclusion(panels: &[Panel]) -> String {
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
pub(super) fn x_at(x: &Vary, v: f64) -> String {
    if x.key.ends_with("rate_mm_h") {
        format!("at {v} mm/h")
    } else {
        format!("at {} = {v}", x.key)
    }
}

/// A point of a line: x, mean, lower and upper bound.
pub(super) type Point = (f64, f64, f64, f64);

/// True when two intervals (lo, hi) overlap; `None` when either has no width (one seed
/// or every seed equal): nothing can be said about the spread.
pub(super) fn overlap(a: Point, b: Point) -> Option<bool> {
    let width = |p: Point| p.3 > p.2;
    (width(a) || width(b)).then_some(a.3 >= b.2 && b.3 >= a.2)
}

/// One sentence on what to conclude from line plot `plot`, from the values it draws:
/// how a single line changes from the smallest x to the largest, and whether that is
/// more than the spread over seeds; with several lines, how they compare at the largest
/// x. `better`: higher values are better (`Some(true)`), lower (`Some(false)`), or
/// neither.
pub(super) fn conclusion(plot: &LinePlot, kind: Kind, x: &Vary, better: Option<bool>) -> String {
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
pub(super) fn masking(plot: &LinePlot, x: &Vary) -> Option<String> {
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
pub(super) enum PlotGroup {
    Main,
    Band,
    Class,
}

/// A plot to draw (or to report as all zero) and its place on the page.
pub(super) struct Planned {
    name: String,
    plot: LinePlot,
    caption: String,
    read: String,
    kind: Kind,
}

/// Writes the plots of every capture and returns their page sections; `titles` gets
/// (relative path, title) of every plot written.
#[allow(clippy::too_many_arguments)]
pub(super) fn plot_sections(
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
