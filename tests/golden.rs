//! Regression: the reports of the paper configuration on the crossroad fixture are the
//! reviewed goldens in tests/golden/. After a deliberate change, run
//! scripts/update-goldens.sh and review the diff; never edit a golden to pass a test.

use assert_cmd::Command;
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
    for file in ["summary.json", "clusters.csv"] {
        let fresh = std::fs::read_to_string(tmp.path().join("crossroad").join(file)).unwrap();
        let golden = std::fs::read_to_string(
            root.join("tests/golden")
                .join(format!("crossroad_paper_{file}")),
        )
        .unwrap();
        if fresh != golden {
            let line = fresh
                .lines()
                .zip(golden.lines())
                .position(|(a, b)| a != b)
                .unwrap_or(0);
            panic!(
                "{file} differs from tests/golden/crossroad_paper_{file} from line {}:\n  now:    {}\n  golden: {}\n\
                 If the change is deliberate, run scripts/update-goldens.sh and review the diff.",
                line + 1,
                fresh.lines().nth(line).unwrap_or(""),
                golden.lines().nth(line).unwrap_or("")
            );
        }
    }
}
