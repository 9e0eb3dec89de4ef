//! The sweep's page and plots as a reader meets them: every file of the folder linked,
//! numbers with sensible precision (no "16.000" counts, no "-0.0"), all-zero metrics not
//! drawn but listed, human plot titles, and bird's-eye panels that say what they show.
//!
//! Each test runs one small sweep (crossroad fixture, two frames, rain 0/1/7 mm/h x
//! occlusion on/off, two seeds).

use crate::common::fixture;
use assert_cmd::Command;
use lidar_noise::sweep::tables;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// A sweep folder of its own for each test (the sweep takes well under a second).
struct Sweep {
    _tmp: tempfile::TempDir,
    dir: PathBuf,
}

fn sweep() -> Sweep {
    sweep_with(&[])
}

fn sweep_with(extra: &[&str]) -> Sweep {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("sweep");
    let o = Command::cargo_bin("lidar-noise")
        .unwrap()
        .arg("sweep")
        .arg(fixture("crossroad.pcap"))
        .arg("-c")
        .arg(PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("configs/paper.toml"))
        .args([
            "--vary",
            "rain.rate_mm_h=0,1,7",
            "--vary",
            "occlusion=on,off",
            "--seeds",
            "1..2",
            "--frames",
            "0..1",
            "--quiet",
        ])
        .args(extra)
        .arg("-o")
        .arg(&dir)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    Sweep { _tmp: tmp, dir }
}

fn page(s: &Sweep) -> String {
    std::fs::read_to_string(s.dir.join("index.html")).unwrap()
}

/// Every non-hidden file under `dir`, relative, with `/` separators.
fn files(dir: &Path) -> Vec<String> {
    fn walk(root: &Path, d: &Path, out: &mut Vec<String>) {
        for e in std::fs::read_dir(d).unwrap() {
            let e = e.unwrap();
            if e.file_name().to_string_lossy().starts_with('.') {
                continue;
            }
            if e.file_type().unwrap().is_dir() {
                walk(root, &e.path(), out);
            } else {
                let rel = e.path().strip_prefix(root).unwrap().to_path_buf();
                let parts: Vec<String> = rel
                    .components()
                    .map(|c| c.as_os_str().to_string_lossy().into_owned())
                    .collect();
                out.push(parts.join("/"));
            }
        }
    }
    let mut out = Vec::new();
    walk(dir, dir, &mut out);
    out.sort();
    out
}

/// Values of `attr="..."` attributes in `html`.
fn attributes(html: &str, attr: &str) -> Vec<String> {
    let key = format!(" {attr}=\"");
    html.match_indices(&key)
        .map(|(i, _)| {
            let rest = &html[i + key.len()..];
            rest[..rest.find('"').unwrap()].to_string()
        })
        .collect()
}

/// Undoes the page's HTML escaping.
fn unescape(s: &str) -> String {
    s.replace("&lt;", "<")
        .replace("&gt;", ">")
        .replace("&quot;", "\"")
        .replace("&#39;", "'")
        .replace("&amp;", "&")
}

/// The page's tables: header cells and rows of cell texts.
fn tables_of(html: &str) -> Vec<(Vec<String>, Vec<Vec<String>>)> {
    let cells = |row: &str, tag: &str| -> Vec<String> {
        let open = format!("<{tag}");
        let close = format!("</{tag}>");
        row.split(&open)
            .skip(1)
            .map(|c| {
                let c = &c[c.find('>').unwrap() + 1..];
                c[..c.find(&close).unwrap()].to_string()
            })
            .collect()
    };
    html.split("<table>")
        .skip(1)
        .map(|t| {
            let t = &t[..t.find("</table>").unwrap()];
            let rows: Vec<&str> = t.split("<tr>").skip(1).collect();
            let header = cells(rows[0], "th");
            let body = rows[1..].iter().map(|r| cells(r, "td")).collect();
            (header, body)
        })
        .collect()
}

/// Numbers in a table cell ("0.896 [0.851, 0.941]" -> three).
fn numbers(cell: &str) -> Vec<&str> {
    cell.split([' ', '[', ']', ','])
        .filter(|t| !t.is_empty())
        .collect()
}

#[test]
fn page_links_every_file_of_the_folder() {
    let s = sweep();
    let html = page(&s);
    let mut refs = attributes(&html, "href");
    refs.extend(attributes(&html, "src"));
    let all = files(&s.dir);
    assert!(
        all.iter().any(|f| f.starts_with("cells/")),
        "no cell files: {all:?}"
    );
    assert!(all.iter().any(|f| f.ends_with(".png")), "{all:?}");
    for f in &all {
        if f == "index.html" {
            continue;
        }
        assert!(refs.contains(f), "the page does not link {f}");
    }
    // And every link points at a file that exists.
    for r in refs.iter().filter(|r| !r.starts_with('#')) {
        assert!(s.dir.join(r).is_file(), "the page links a missing file {r}");
    }
}

#[test]
fn tables_print_counts_as_integers_shares_with_three_decimals_and_no_negative_zero() {
    let s = sweep();
    let html = page(&s);
    let tables = tables_of(&html);
    assert!(tables.len() >= 2, "expected the main and the band tables");
    let is_count = |h: &str| {
        [
            "seeds",
            "objects",
            "clusters",
            "object_clusters",
            "false_clusters",
            "kept",
        ]
        .contains(&h)
            || h.starts_with("objects_")
    };
    let is_share = |h: &str| h.contains("_share") || h == "object_survival" || h == "ground_recall";
    let (mut counts, mut shares) = (0, 0);
    for (header, rows) in &tables {
        for row in rows {
            assert_eq!(row.len(), header.len(), "{header:?} vs {row:?}");
            for (h, cell) in header.iter().zip(row) {
                for n in numbers(cell) {
                    assert!(
                        !(n.starts_with("-0") && n.trim_start_matches(['-', '0', '.']).is_empty()),
                        "negative zero {n} in column {h}: {cell}"
                    );
                    if is_count(h) {
                        counts += 1;
                        let v: f64 = n.parse().unwrap();
                        match n.split_once('.') {
                            None => assert_eq!(v.fract(), 0.0),
                            Some((_, d)) => {
                                assert!(
                                    d.len() == 1 && d != "0",
                                    "count {n} in column {h} printed with needless decimals"
                                );
                            }
                        }
                    } else if is_share(h) {
                        shares += 1;
                        let d = n.split_once('.').map_or(0, |(_, d)| d.len());
                        assert_eq!(d, 3, "share {n} in column {h}");
                    }
                }
            }
        }
    }
    assert!(
        counts > 20 && shares > 20,
        "{counts} counts, {shares} shares checked"
    );
    // Nowhere on the page (tables, notes) a negative zero.
    for pat in ["-0.0<", "-0.0 ", "-0.0,", "-0.00", ">-0<", " -0 "] {
        assert!(!html.contains(pat), "the page prints negative zero ({pat})");
    }
}

/// The aggregate table as columns: name -> every non-empty value.
fn aggregate_columns(s: &Sweep) -> BTreeMap<String, Vec<f64>> {
    let mut r = csv::Reader::from_path(s.dir.join("aggregate.csv")).unwrap();
    let header: Vec<String> = r.headers().unwrap().iter().map(String::from).collect();
    let mut cols: BTreeMap<String, Vec<f64>> = BTreeMap::new();
    for rec in r.records() {
        for (h, v) in header.iter().zip(rec.unwrap().iter()) {
            if let Ok(x) = v.parse::<f64>() {
                cols.entry(h.clone()).or_default().push(x);
            }
        }
    }
    cols
}

#[test]
fn all_zero_metrics_are_listed_not_drawn() {
    let s = sweep();
    let cols = aggregate_columns(&s);
    let html = page(&s);
    let plots = s.dir.join("plots").join("crossroad");
    let mut zero = 0;
    let mut drawn = 0;
    for m in tables::metrics(&[]) {
        let values: Vec<f64> = ["mean", "lo", "hi"]
            .iter()
            .flat_map(|s| {
                cols.get(&format!("{}_{s}", m.name))
                    .cloned()
                    .unwrap_or_default()
            })
            .collect();
        if values.is_empty() {
            continue;
        }
        let png = plots.join(format!("{}.png", m.name));
        let title = lidar_noise::sweep::outputs::presentation(&m.name, &m.label).title;
        if values.iter().all(|&v| v == 0.0) {
            zero += 1;
            assert!(!png.exists(), "{} is all zero but drawn", m.name);
            let note = html
                .split("All zero, not drawn: ")
                .nth(1)
                .expect("no all-zero note on the page");
            let note = unescape(&note[..note.find('<').unwrap()]);
            assert!(
                note.contains(&title),
                "{title} missing from the note: {note}"
            );
        } else {
            drawn += 1;
            assert!(png.exists(), "{} has values but no plot", m.name);
        }
    }
    // The fixture has all-zero metrics (e.g. returns below the minimum range) and
    // drawn ones, so both branches ran.
    assert!(zero >= 1 && drawn >= 10, "{zero} all-zero, {drawn} drawn");
}

/// The `key` text chunk of a PNG.
fn png_text(path: &Path, key: &str) -> Option<String> {
    let decoder = png::Decoder::new(std::fs::File::open(path).unwrap());
    let reader = decoder.read_info().unwrap();
    let info = reader.info();
    info.utf8_text
        .iter()
        .find(|t| t.keyword == key)
        .map(|t| t.get_text().unwrap())
        .or_else(|| {
            info.uncompressed_latin1_text
                .iter()
                .find(|t| t.keyword == key)
                .map(|t| t.text.clone())
        })
}

#[test]
fn plot_titles_are_human_with_units_and_match_the_page() {
    let s = sweep();
    let html = page(&s);
    let names: Vec<String> = tables::metrics(&[]).into_iter().map(|m| m.name).collect();
    let captions: Vec<String> = attributes(&html, "alt")
        .iter()
        .map(|a| unescape(a))
        .collect();
    let mut n = 0;
    for f in files(&s.dir).iter().filter(|f| f.ends_with(".png")) {
        let title = png_text(&s.dir.join(f), "Title").unwrap_or_else(|| panic!("{f}: no title"));
        n += 1;
        assert!(
            !title.contains('_'),
            "{f}: raw field name in title {title:?}"
        );
        for name in &names {
            assert_ne!(&title, name, "{f}");
        }
        if f.contains("birdseye") {
            assert!(title.contains("seed 1"), "{title}");
            continue;
        }
        assert!(title.contains(" - crossroad"), "{f}: {title}");
        assert!(
            title.contains("(share") || title.contains("(count)") || title.contains("(m)"),
            "{f}: no unit in {title:?}"
        );
        let caption = title.trim_end_matches(" - crossroad");
        assert!(
            captions.iter().any(|c| c == caption),
            "{f}: the page has no figure captioned {caption:?}"
        );
    }
    assert!(n >= 10, "{n} plots");
}

#[test]
fn birdseye_panels_name_their_stages_and_seed() {
    let s = sweep();
    let dir = s.dir.join("plots");
    let png = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .find(|p| p.to_string_lossy().contains("birdseye"))
        .expect("no bird's-eye figure");
    let d = png_text(&png, "Description").expect("no panel description");
    let panels: Vec<&str> = d.split("\n\n").collect();
    assert_eq!(panels.len(), 4, "{d}");
    assert!(panels[0].starts_with("clean, seed 1") && panels[0].contains("no noise stage"));
    // The rain panel says which rate it shows (paper.toml: 7 mm/h).
    let rain = panels.iter().find(|p| p.starts_with("rain only")).unwrap();
    assert!(rain.contains("rain: 7 mm/h"), "{rain}");
    assert!(rain.contains("seed 1"), "{rain}");
    let both = panels[3];
    assert!(
        both.contains("occlusion:") && both.contains("rain:"),
        "{both}"
    );
}

#[test]
fn plots_with_several_lines_are_wider_for_the_legend() {
    // The legend is drawn right of the plot area: a plot with one line per occlusion
    // setting is wider than the 900 px plot area.
    let s = sweep();
    let png = s.dir.join("plots/crossroad/detected_share.png");
    let decoder = png::Decoder::new(std::fs::File::open(&png).unwrap());
    let info = decoder.read_info().unwrap();
    let (w, h) = (info.info().width, info.info().height);
    assert!(w > 900 && h == 560, "{w}x{h}");
}

/// `--figure-format svg` writes the plots and heatmaps as SVG (vector, with their title),
/// and the page shows those files; the bird's-eye figure stays PNG.
#[test]
fn svg_figure_format_writes_svgs_the_page_links() {
    let s = sweep_with(&["--figure-format", "svg"]);
    let html = page(&s);
    let srcs = attributes(&html, "src");
    let svgs: Vec<&String> = srcs.iter().filter(|p| p.ends_with(".svg")).collect();
    assert!(svgs.len() >= 10, "{srcs:?}");
    assert!(
        srcs.iter()
            .all(|p| p.ends_with(".svg") || p.contains("birdseye")),
        "{srcs:?}"
    );
    for f in &svgs {
        let text = std::fs::read_to_string(s.dir.join(f)).unwrap();
        let doc = roxmltree::Document::parse(&text).unwrap();
        assert!(doc.root_element().has_tag_name("svg"), "{f}");
        let title = doc
            .descendants()
            .find(|n| n.has_tag_name("title"))
            .and_then(|n| n.text())
            .unwrap_or_default();
        assert!(title.contains("crossroad"), "{f}: title {title:?}");
    }
    // No PNG line plots are left behind.
    let plots = files(&s.dir.join("plots"));
    assert!(
        plots
            .iter()
            .all(|p| p.ends_with(".svg") || p.contains("birdseye")),
        "{plots:?}"
    );
    // The default stays PNG.
    let png = sweep();
    assert!(png.dir.join("plots/crossroad/detected_share.png").is_file());
}

/// Every figure on the page says in one sentence what to conclude, from its values; the
/// detected-share plot explains the masking (occlusion on detects more than off at 7
/// mm/h with paper.toml's range-image ground removal).
#[test]
fn every_figure_says_what_to_conclude_and_explains_masking() {
    let s = sweep();
    let html = page(&s);
    let figures: Vec<&str> = html.split("<figure").skip(1).collect();
    assert!(figures.len() >= 10, "{} figures", figures.len());
    for f in &figures {
        let f = &f[..f.find("</figure>").unwrap()];
        assert!(
            f.contains("<p class=\"conclusion\">Conclusion: "),
            "a figure without a conclusion: {f}"
        );
    }
    let detected = figures
        .iter()
        .find(|f| f.contains("plots/crossroad/detected_share.png"))
        .unwrap();
    assert!(detected.contains("at 7 mm/h"), "{detected}");
    assert!(detected.contains("Masking:"), "{detected}");
    assert!(
        detected.contains("noisiest near-ground rings") && detected.contains("clutter"),
        "{detected}"
    );
    // Where occlusion on does not detect more, no masking is claimed.
    let merged = figures
        .iter()
        .find(|f| f.contains("plots/crossroad/merged_share.png"))
        .unwrap();
    assert!(!merged.contains("Masking:"), "{merged}");
}
