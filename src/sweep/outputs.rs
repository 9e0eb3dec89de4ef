//! The final outputs of a sweep, rebuilt from the rows every time: tables, plots, the
//! bird's-eye figure and `index.html`. Nothing here depends on timing or thread count.

use super::plan::{Vary, VaryKind};
use super::run::{Panel, Row};
use super::tables::{self, Group, METRICS};
use crate::error::{Error, Result};
use crate::writers::html::{Figure, Page, Section};
use crate::writers::png::{self, BirdsEyePanel, LinePlot, Series};
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

/// Writes every output file into `dir` and returns the paths written.
pub fn write_outputs(
    dir: &Path,
    varies: &[Vary],
    captures: &[String],
    rows: &[Row],
    figure: Option<&BirdsEye>,
    protected: &[&Path],
) -> Result<Vec<PathBuf>> {
    let keys: Vec<String> = varies.iter().map(|v| v.key.clone()).collect();
    let mut written = Vec::new();
    let mut put = |name: &str, bytes: &[u8]| -> Result<()> {
        let path = dir.join(name);
        crate::writers::atomic::write_atomically(&path, protected, |o| o.write_all(bytes))?;
        written.push(path);
        Ok(())
    };
    put(TIDY_CSV, &tables::tidy_csv(&keys, rows))?;
    let json = serde_json::to_vec_pretty(&tables::tidy_json(&keys, rows))
        .map_err(|e| Error::Invalid(format!("sweep.json: {e}")))?;
    put(TIDY_JSON, &json)?;
    let groups = tables::aggregate(rows);
    put(AGGREGATE_CSV, &tables::aggregate_csv(&keys, &groups))?;

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
        "Metrics compare each frame with the same frame without noise stages (same filters, \
         ground and clustering). A clean cluster survives when a noisy cluster has \
         point-membership IoU >= 0.5 with it (greedy one-to-one); split, merged, lost and \
         false clusters use a 20 % share rule (see the sweep module documentation). Bands and \
         intervals: 95 % Student-t confidence interval of the mean over seeds and frames."
            .into(),
    );
    intro.paragraphs.push(format!(
        "Files: {TIDY_CSV} (one row per capture, frame, values, seed), {TIDY_JSON}, \
         {AGGREGATE_CSV}, cells/ (one result file per cell)."
    ));
    page.sections.push(intro);

    if let Some(f) = figure {
        std::fs::create_dir_all(dir.join("plots")).map_err(|e| Error::io(dir, e))?;
        let rel = format!("plots/birdseye_{}_frame{}.png", safe(&f.capture), f.frame);
        let panels: Vec<BirdsEyePanel> = f
            .panels
            .iter()
            .map(|p| BirdsEyePanel {
                title: format!("{} ({} clusters)", p.title, p.clusters),
                points: p.points.clone(),
            })
            .collect();
        let title = format!("{} frame {} (seed {})", f.capture, f.frame, f.seed);
        let path = dir.join(&rel);
        png::birdseye(&title, &panels, f.extent_m, &path, protected)?;
        written.push(path);
        page.sections.push(Section {
            heading: "Bird's-eye view".into(),
            paragraphs: vec![
                "The base configuration on one frame: without noise, with each noise type \
                 alone, and with all of them. Clusters in colour, ground light grey, \
                 unclustered returns dark grey."
                    .into(),
            ],
            figures: vec![Figure {
                src: rel,
                caption: title,
            }],
            table: None,
        });
    }

    if let Some(xi) = x_axis(varies) {
        for capture in captures {
            let cg: Vec<&Group> = groups.iter().filter(|g| &g.capture == capture).collect();
            let sub = format!("plots/{}", safe(capture));
            std::fs::create_dir_all(dir.join(&sub)).map_err(|e| Error::io(dir, e))?;
            let mut section = Section {
                heading: format!("Plots: {capture}"),
                ..Section::default()
            };
            for (mi, metric) in METRICS.iter().enumerate() {
                let mut series: Vec<Series> = Vec::new();
                for g in &cg {
                    let Some(i) = g.metrics[mi] else { continue };
                    let Ok(x) = g.values[xi].parse::<f64>() else {
                        continue;
                    };
                    let label: Vec<String> = varies
                        .iter()
                        .zip(&g.values)
                        .enumerate()
                        .filter(|(k, _)| *k != xi)
                        .map(|(_, (v, x))| match v.kind {
                            VaryKind::Toggle { .. } => format!("{} {x}", v.key),
                            _ => format!("{}={x}", v.key),
                        })
                        .collect();
                    let label = if label.is_empty() {
                        "all".to_string()
                    } else {
                        label.join(", ")
                    };
                    let point = (x, i.mean, i.lo, i.hi);
                    match series.iter_mut().find(|s| s.label == label) {
                        Some(s) => s.points.push(point),
                        None => series.push(Series {
                            label,
                            points: vec![point],
                        }),
                    }
                }
                if series.is_empty() {
                    continue;
                }
                for s in &mut series {
                    s.points.sort_by(|a, b| a.0.total_cmp(&b.0));
                }
                let plot = LinePlot {
                    title: format!("{capture}: {}", metric.name.replace('_', " ")),
                    x_label: x_label(&varies[xi]),
                    y_label: metric.label.into(),
                    series,
                };
                let rel = format!("{sub}/{}.png", metric.name);
                let path = dir.join(&rel);
                png::line_plot(&plot, &path, protected)?;
                written.push(path);
                section.figures.push(Figure {
                    src: rel,
                    caption: metric.label.into(),
                });
            }
            page.sections.push(section);
        }
    }

    let shown = [
        "object_survival",
        "clusters",
        "lost",
        "split",
        "merged",
        "false_clusters",
        "farthest_matched_m",
        "kept",
        "range_change_rms_m",
        "object_recall",
        "ground_recall",
    ];
    let cols: Vec<usize> = shown
        .iter()
        .filter_map(|n| METRICS.iter().position(|m| m.name == *n))
        .filter(|&i| groups.iter().any(|g| g.metrics[i].is_some()))
        .collect();
    let mut header = vec!["capture".to_string()];
    header.extend(keys.iter().cloned());
    header.push("rows".into());
    header.extend(cols.iter().map(|&i| METRICS[i].name.to_string()));
    let body = groups
        .iter()
        .map(|g| {
            let mut r = vec![g.capture.clone()];
            r.extend(g.values.iter().cloned());
            r.push(g.rows.to_string());
            r.extend(cols.iter().map(|&i| match g.metrics[i] {
                Some(v) => format!("{:.3} [{:.3}, {:.3}]", v.mean, v.lo, v.hi),
                None => String::new(),
            }));
            r
        })
        .collect();
    page.sections.push(Section {
        heading: "Table (mean [95 % interval])".into(),
        paragraphs: vec![format!("All metrics: {AGGREGATE_CSV}.")],
        figures: Vec::new(),
        table: Some((header, body)),
    });
    let path = dir.join(INDEX_HTML);
    crate::writers::write_file(&page, &path, protected)?;
    written.push(path);
    Ok(written)
}
