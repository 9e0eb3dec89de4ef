//! Regression: the reports of the paper configuration on the crossroad fixture are the
//! reviewed goldens in tests/golden/. After a deliberate change, rewrite them with
//! `LIDAR_NOISE_BLESS=1 cargo test` and review the diff; never edit a golden to pass a test.

use crate::common;

use assert_cmd::Command;
use lidar_noise::compare::{compare_file, Status, Tolerances};
use std::path::Path;

#[test]
fn paper_reports_on_the_crossroad_fixture_match_the_goldens() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let tmp = tempfile::tempdir().unwrap();
    Command::cargo_bin("lidar-noise")
        .unwrap()
        .current_dir(root)
        .args([
            "--quiet",
            "run",
            "fixtures/crossroad.pcap",
            "-c",
            "configs/paper.toml",
        ])
        .args(["--seed", "42", "--no-ply", "-o"])
        .arg(tmp.path())
        .assert()
        .success();
    // Field by field with `compare`'s rules: provenance (tool version) is not a regression.
    let tolerances = Tolerances::default();
    for file in ["summary.json", "clusters.csv"] {
        let golden = root
            .join("tests/golden")
            .join(format!("crossroad_paper_{file}"));
        let fresh = tmp.path().join("crossroad").join(file);
        let rel = format!("tests/golden/crossroad_paper_{file}");
        if common::bless_golden(&rel, &std::fs::read(&fresh).unwrap()) {
            continue;
        }
        if let Status::Different { count, listed } = compare_file(&golden, &fresh, &tolerances) {
            panic!(
                "{file} differs from tests/golden/crossroad_paper_{file} in {count} fields:\n  {}\n\
                 If the change is deliberate, run `LIDAR_NOISE_BLESS=1 cargo test` and review the diff.",
                listed.join("\n  ")
            );
        }
    }
}
