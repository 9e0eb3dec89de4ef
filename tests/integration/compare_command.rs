//! `lidar-noise compare`: exit codes, the named field, tolerances, JUnit XML, missing and
//! extra files, and identical reports for the same capture run from another folder.

use crate::common;

use crate::common::bin;
use std::path::Path;

/// One run of the crossroad fixture (frame 0, PLY and LAS) into `out`, from `cwd`.
fn run_into(cwd: &Path, capture: &Path, out: &Path, format: &str) {
    bin()
        .current_dir(cwd)
        .args(["--quiet", "run"])
        .arg(capture)
        .args(["--seed", "5", "--frames", "0", "--format", format, "-o"])
        .arg(out)
        .assert()
        .success();
}

fn compare(expected: &Path, actual: &Path, extra: &[&str]) -> (i32, String) {
    let out = bin()
        .arg("compare")
        .arg(expected)
        .arg(actual)
        .args(extra)
        .output()
        .unwrap();
    (
        out.status.code().unwrap(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
    )
}

#[test]
fn same_capture_from_another_folder_compares_equal_and_changes_are_named() {
    let tmp = tempfile::tempdir().unwrap();
    // The same capture reached through two different paths as typed.
    let fixture = common::fixtures().join("crossroad.pcap");
    let sub = tmp.path().join("data/sub");
    std::fs::create_dir_all(&sub).unwrap();
    std::fs::copy(&fixture, sub.join("crossroad.pcap")).unwrap();
    let (a, b) = (tmp.path().join("a"), tmp.path().join("b"));
    run_into(tmp.path(), Path::new("data/sub/crossroad.pcap"), &a, "ply");
    run_into(&sub, Path::new("crossroad.pcap"), &b, "ply");
    for f in ["crossroad/summary.json", "crossroad/clusters.json"] {
        assert_eq!(
            std::fs::read(a.join(f)).unwrap(),
            std::fs::read(b.join(f)).unwrap(),
            "{f} names the capture by file name"
        );
    }
    let (code, stdout) = compare(&a, &b, &[]);
    assert_eq!(code, 0, "{stdout}");
    assert!(stdout.contains("same: 4 files"), "{stdout}");

    // A changed number: exit 1 and the field named.
    let summary = b.join("crossroad/summary.json");
    let text = std::fs::read_to_string(&summary).unwrap();
    let changed = text.replacen("\"ground_fraction\": 0.", "\"ground_fraction\": 0.0001", 1);
    assert_ne!(text, changed);
    std::fs::write(&summary, &changed).unwrap();
    let (code, stdout) = compare(&a, &b, &[]);
    assert_eq!(code, 1, "{stdout}");
    assert!(
        stdout.contains("crossroad/summary.json: 1 difference"),
        "{stdout}"
    );
    assert!(stdout.contains("ground_fraction: expected"), "{stdout}");

    // Within tolerance: the same.
    let (code, stdout) = compare(&a, &b, &["--tolerance", "ground_fraction=1"]);
    assert_eq!(code, 0, "{stdout}");
    let (code, _) = compare(&a, &b, &["--tolerance", "ground_fraction=1e-12"]);
    assert_eq!(code, 1);

    // JUnit XML: well-formed, one test case per file, the failure on the changed one.
    let junit = tmp.path().join("junit.xml");
    let (code, _) = compare(&a, &b, &["--junit", junit.to_str().unwrap()]);
    assert_eq!(code, 1);
    let xml = std::fs::read_to_string(&junit).unwrap();
    let doc = roxmltree::Document::parse(&xml).expect("well-formed JUnit XML");
    let cases: Vec<_> = doc
        .descendants()
        .filter(|n| n.has_tag_name("testcase"))
        .collect();
    assert_eq!(cases.len(), 4);
    let failed: Vec<&str> = cases
        .iter()
        .filter(|c| c.children().any(|n| n.has_tag_name("failure")))
        .map(|c| c.attribute("name").unwrap())
        .collect();
    assert_eq!(failed, ["crossroad/summary.json"]);
    let suite = doc
        .descendants()
        .find(|n| n.has_tag_name("testsuite"))
        .unwrap();
    assert_eq!(suite.attribute("failures"), Some("1"));
    assert_eq!(suite.attribute("tests"), Some("4"));

    // Missing and extra files.
    std::fs::write(&summary, &text).unwrap();
    std::fs::rename(
        b.join("crossroad/clusters.csv"),
        b.join("crossroad/other.csv"),
    )
    .unwrap();
    let (code, stdout) = compare(&a, &b, &[]);
    assert_eq!(code, 1, "{stdout}");
    assert!(
        stdout.contains("crossroad/clusters.csv: missing"),
        "{stdout}"
    );
    assert!(stdout.contains("crossroad/other.csv: extra"), "{stdout}");
}

#[test]
fn point_cloud_values_are_compared_and_usage_errors_exit_2() {
    let tmp = tempfile::tempdir().unwrap();
    let fixture = common::fixtures().join("crossroad.pcap");
    let (a, b) = (tmp.path().join("a"), tmp.path().join("b"));
    run_into(tmp.path(), &fixture, &a, "las");
    run_into(tmp.path(), &fixture, &b, "las");
    assert_eq!(compare(&a, &b, &[]).0, 0);
    // Another seed moves the rain-scattered points: the LAS dimensions differ.
    bin()
        .args(["--quiet", "run"])
        .arg(&fixture)
        .args([
            "--seed", "6", "--frames", "0", "--format", "las", "--force", "-o",
        ])
        .arg(&b)
        .assert()
        .success();
    let (code, stdout) = compare(&a, &b, &[]);
    assert_eq!(code, 1);
    assert!(stdout.contains("crossroad/frame_00000.las:"), "{stdout}");
    assert!(stdout.contains("\n  range: "), "{stdout}");
    assert!(stdout.contains("points differ"), "{stdout}");

    let (code, _) = compare(&a, &tmp.path().join("nope"), &[]);
    assert_eq!(code, 2);
    let (code, _) = compare(&a, &b, &["--tolerance", "range"]);
    assert_eq!(code, 2);
    assert_eq!(
        bin().arg("compare").arg(&a).output().unwrap().status.code(),
        Some(2)
    );
}
