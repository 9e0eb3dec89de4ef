//! The page's section listing the sweep's files, each with what it holds.

use super::*;

/// What a file of the sweep folder holds, for the page's list of files.
pub(super) fn file_note(rel: &str, titles: &[(String, String)]) -> String {
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
        crate::sweep::interactions::INTERACTIONS_CSV => {
            "per capture, stage pair and distance band: each alone, both, their product and the \
             verdict"
                .into()
        }
        crate::sweep::interactions::INTERACTIONS_JSON => "the interaction table as JSON".into(),
        _ if rel.starts_with("plots/interactions_") => {
            "verdict of each stage pair in each distance band".into()
        }
        _ => String::new(),
    }
}

/// Every file under `dir` except hidden ones (temporaries, the lock) and `skip`, as
/// sorted relative paths with `/` separators.
pub(super) fn folder_files(dir: &Path, skip: &str) -> Result<Vec<String>> {
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
pub(super) fn files_section(
    dir: &Path,
    titles: &[(String, String)],
    cells: &[String],
) -> Result<Section> {
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
