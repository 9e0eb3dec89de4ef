//! The README and the mdBook manual under docs/: the README stays a short entry point, the
//! configuration reference is what the binary prints, every link of the README and the
//! manual stays inside the repository and resolves, and the CI recipes name a Rust new
//! enough for Cargo.toml. (`mdbook build` and the check of the built HTML's links and
//! anchors run in .ci/run; these checks need no mdbook.)

use std::path::{Component, Path, PathBuf};
use std::process::Command;

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

fn read(rel: &str) -> String {
    let path = root().join(rel);
    std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// Every Markdown file of the manual (docs/, recursively), relative to the repository.
fn manual_pages() -> Vec<PathBuf> {
    fn walk(dir: &Path, out: &mut Vec<PathBuf>) {
        for entry in std::fs::read_dir(dir).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                walk(&path, out);
            } else if path.extension().is_some_and(|e| e == "md") {
                out.push(path);
            }
        }
    }
    let mut out = Vec::new();
    walk(&root().join("docs"), &mut out);
    out.sort();
    out
}

/// The Markdown text outside fenced code blocks and inline code spans, where links live.
fn prose(markdown: &str) -> String {
    let mut out = String::new();
    let mut fenced = false;
    for line in markdown.lines() {
        if line.trim_start().starts_with("```") {
            fenced = !fenced;
            continue;
        }
        if fenced {
            continue;
        }
        // Inline code spans: drop what lies between pairs of backticks.
        for (i, part) in line.split('`').enumerate() {
            if i % 2 == 0 {
                out.push_str(part);
            }
        }
        out.push('\n');
    }
    out
}

/// Targets of the Markdown links and images `[text](target)` / `![alt](target)` of a text.
fn link_targets(markdown: &str) -> Vec<String> {
    let text = prose(markdown);
    let mut out = Vec::new();
    let mut rest = text.as_str();
    while let Some(i) = rest.find("](") {
        let after = &rest[i + 2..];
        let end = after.find(')').unwrap_or(after.len());
        out.push(after[..end].trim().to_string());
        rest = &after[end..];
    }
    out
}

/// A path joined without touching the file system, `..` taken lexically.
fn normalise(path: &Path) -> PathBuf {
    let mut out = PathBuf::new();
    for c in path.components() {
        match c {
            Component::ParentDir => {
                out.pop();
            }
            Component::CurDir => {}
            other => out.push(other),
        }
    }
    out
}

/// Checks the relative links of one Markdown file: each names a file of the repository
/// that exists. Returns the problems found.
fn check_links(file: &Path) -> Vec<String> {
    let text = std::fs::read_to_string(file).unwrap();
    let dir = file.parent().unwrap();
    let mut bad = Vec::new();
    for target in link_targets(&text) {
        if target.starts_with('#') || target.contains("://") || target.starts_with("mailto:") {
            continue;
        }
        let path_part = target.split('#').next().unwrap();
        let resolved = normalise(&dir.join(path_part));
        if !resolved.starts_with(root()) {
            bad.push(format!(
                "{}: {target} leaves the repository",
                file.display()
            ));
        } else if !resolved.exists() {
            bad.push(format!("{}: {target} does not exist", file.display()));
        }
    }
    bad
}

#[test]
fn readme_is_a_short_entry_point() {
    let readme = read("README.md");
    let lines = readme.lines().count();
    // Was a 2,605-line lab notebook; the manual holds the rest.
    assert!(lines <= 420, "README.md has {lines} lines");
    for word in ["issue 9", "issue 14", "issue 31", "not met", "Not met"] {
        assert!(!readme.contains(word), "README.md still says {word:?}");
    }
    // The install section and the pointers a new user looks for.
    assert!(readme.contains("cargo install --locked --path ."));
    assert!(readme.contains("## Python"));
    assert!(readme.contains("docs/SUMMARY.md"));
    // It opens with every kind of noise, not only rain and a dirty lens.
    let opening: String = readme.lines().take(40).collect::<Vec<_>>().join("\n");
    for stage in [
        "fog",
        "snow",
        "crosstalk",
        "spoofing",
        "mounting",
        "multipath",
    ] {
        assert!(opening.contains(stage), "the opening does not name {stage}");
    }
}

#[test]
fn readme_and_manual_links_stay_in_the_repository_and_resolve() {
    let mut bad = check_links(&root().join("README.md"));
    for page in manual_pages() {
        bad.extend(check_links(&page));
    }
    for text in [read("README.md")].into_iter().chain(
        manual_pages()
            .into_iter()
            .map(|p| std::fs::read_to_string(p).unwrap()),
    ) {
        // The model notes beside the repository were named and linked as ../shared/docs/*.md;
        // the manual says in its own words what the project takes from them.
        assert!(!text.contains("](../shared"), "a link points at ../shared");
        assert!(
            !text.contains("shared/docs"),
            "a page points at ../shared/docs"
        );
    }
    assert!(bad.is_empty(), "{}", bad.join("\n"));
}

#[test]
fn every_chapter_of_the_summary_exists_and_every_page_is_listed() {
    let summary = read("docs/SUMMARY.md");
    let listed: Vec<String> = link_targets(&summary);
    assert!(listed.len() >= 20, "{listed:?}");
    for target in &listed {
        assert!(
            root().join("docs").join(target).is_file(),
            "SUMMARY.md lists {target}, which is missing"
        );
    }
    // Pages written for the book but not listed would silently not be built. Generated
    // tables included into pages (docs/figures/*.md) are not chapters.
    for page in manual_pages() {
        let rel = page.strip_prefix(root().join("docs")).unwrap();
        let rel = rel.to_string_lossy().replace('\\', "/");
        if rel == "SUMMARY.md" || rel.starts_with("figures/") {
            continue;
        }
        assert!(listed.contains(&rel), "docs/{rel} is not in SUMMARY.md");
    }
}

#[test]
fn the_stage_reference_is_what_the_binary_prints() {
    let out = Command::new(env!("CARGO_BIN_EXE_lidar-noise"))
        .args(["stages", "--markdown"])
        .output()
        .unwrap();
    assert!(out.status.success());
    let printed = String::from_utf8(out.stdout).unwrap();
    let page = read("docs/reference/stages.md");
    assert!(
        page.contains("Generated by scripts/dev/make-manual.sh"),
        "docs/reference/stages.md is not the generated page"
    );
    assert!(
        page.ends_with(&printed),
        "docs/reference/stages.md differs from `lidar-noise stages --markdown`: run scripts/dev/make-manual.sh"
    );
}

#[test]
fn ci_recipes_name_a_rust_new_enough_for_cargo_toml() {
    let cargo = read("Cargo.toml");
    let needed = cargo
        .lines()
        .find_map(|l| l.strip_prefix("rust-version = \""))
        .and_then(|v| v.strip_suffix('"'))
        .expect("rust-version in Cargo.toml");
    let version = |v: &str| -> (u32, u32) {
        let mut parts = v.split('.').map(|p| p.parse::<u32>().unwrap());
        (parts.next().unwrap(), parts.next().unwrap_or(0))
    };
    let mut images = 0;
    let texts = [read("README.md")].into_iter().chain(
        manual_pages()
            .into_iter()
            .map(|p| std::fs::read_to_string(p).unwrap()),
    );
    for text in texts {
        for (i, _) in text.match_indices("image: rust:") {
            let tag: String = text[i + "image: rust:".len()..]
                .chars()
                .take_while(|c| c.is_ascii_digit() || *c == '.')
                .collect();
            images += 1;
            assert!(
                version(&tag) >= version(needed),
                "a CI recipe uses rust:{tag}, Cargo.toml needs {needed}"
            );
        }
    }
    assert!(images >= 1, "the GitLab recipe is gone");
    assert!(read("README.md").contains(&format!("Rust {needed} or newer")));
}
