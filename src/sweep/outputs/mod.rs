//! The final outputs of a sweep, rebuilt from the rows every time: tables, plots, the
//! bird's-eye figure and `index.html`. Nothing here depends on timing or thread count.

mod files;
mod plots;
mod present;

use files::*;
use plots::*;
use present::*;
pub use present::{format_interval, format_value, presentation, x_axis, Kind, Presentation};

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
mod tests;
