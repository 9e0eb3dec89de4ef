//! The final outputs of a sweep, rebuilt from the rows every time: tables, plots, the
//! bird's-eye figure and `index.html`. Nothing here depends on timing or thread count.

use super::plan::{Vary, VaryKind};
use super::run::{Panel, Row};
use super::tables::{self, Group};
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
    let metrics = tables::metrics(rows);
    let groups = tables::aggregate(rows, &metrics);
    put(
        AGGREGATE_CSV,
        &tables::aggregate_csv(&keys, &groups, &metrics),
    )?;

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
         frames), then the 95 % Student-t interval of the mean is taken over seeds; frames \
         of one capture are not independent samples. With one seed there is no interval."
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
            for (mi, metric) in metrics.iter().enumerate() {
                // Per band only the detected share gets a plot (the rest is in the tables).
                if metric.name.starts_with("objects_")
                    || metric.name.starts_with("retained_share_")
                    || metric.name.starts_with("lost_share_")
                {
                    continue;
                }
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
                    let point = (x, i.mean, i.lo.unwrap_or(i.mean), i.hi.unwrap_or(i.mean));
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
                    // The label without its unit: "objects detected at [5, 10) m".
                    title: format!(
                        "{capture}: {}",
                        metric
                            .label
                            .rsplit_once(" (")
                            .map_or(&*metric.label, |t| t.0)
                    ),
                    x_label: x_label(&varies[xi]),
                    y_label: metric.label.clone(),
                    series,
                };
                let rel = format!("{sub}/{}.png", metric.name);
                let path = dir.join(&rel);
                png::line_plot(&plot, &path, protected)?;
                written.push(path);
                section.figures.push(Figure {
                    src: rel,
                    caption: metric.label.clone(),
                });
            }
            page.sections.push(section);
        }
    }

    let table = |names: &[String]| {
        let cols: Vec<usize> = names
            .iter()
            .filter_map(|n| metrics.iter().position(|m| &m.name == n))
            .filter(|&i| groups.iter().any(|g| g.metrics[i].is_some()))
            .collect();
        let mut header = vec!["capture".to_string()];
        header.extend(keys.iter().cloned());
        header.push("seeds".into());
        header.extend(cols.iter().map(|&i| metrics[i].name.clone()));
        let body = groups
            .iter()
            .map(|g| {
                let mut r = vec![g.capture.clone()];
                r.extend(g.values.iter().cloned());
                r.push(g.seeds.to_string());
                r.extend(cols.iter().map(|&i| match g.metrics[i] {
                    Some(v) => match (v.lo, v.hi) {
                        (Some(lo), Some(hi)) => format!("{:.3} [{lo:.3}, {hi:.3}]", v.mean),
                        _ => format!("{:.3}", v.mean),
                    },
                    None => String::new(),
                }));
                r
            })
            .collect();
        (header, body)
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
    page.sections.push(Section {
        heading: "Table (mean [95 % interval over seeds])".into(),
        paragraphs: vec![format!("All metrics: {AGGREGATE_CSV}.")],
        figures: Vec::new(),
        table: Some(table(&shown)),
    });
    if let Some(first) = rows.first() {
        let mut by_band = Vec::new();
        for b in &first.metrics.bands {
            let name = tables::band_name(b);
            by_band.push(format!("objects_{name}"));
            by_band.push(format!("detected_share_{name}"));
        }
        if !by_band.is_empty() {
            page.sections.push(Section {
                heading: "Objects by distance band (mean [95 % interval over seeds])".into(),
                paragraphs: vec![
                    "objects_<band>: objects in the band per frame; detected_share_<band>: \
                     detected objects over objects in the band. Bands are [lo, hi) on the \
                     horizontal distance of the object's clean centroid; the last is open."
                        .into(),
                ],
                figures: Vec::new(),
                table: Some(table(&by_band)),
            });
        }
    }
    if let [vary] = varies {
        if let Some((files, section)) =
            super::interactions::write_outputs(dir, vary, captures, rows, protected)?
        {
            written.extend(files);
            page.sections.insert(1, section);
        }
    }
    let path = dir.join(INDEX_HTML);
    crate::writers::write_file(&page, &path, protected)?;
    written.push(path);
    Ok(written)
}
