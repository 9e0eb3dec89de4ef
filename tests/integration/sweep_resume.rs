//! A sweep interrupted and restarted writes the same files as an uninterrupted one.

use crate::common;

use crate::common::fixture;
use assert_cmd::Command;
use lidar_noise::sweep::run::METRICS_VERSION;
use std::path::{Path, PathBuf};

fn sweep(out: &Path) -> String {
    let o = Command::cargo_bin("lidar-noise")
        .unwrap()
        .arg("sweep")
        .arg(fixture("crossroad.pcap"))
        .args([
            "--vary",
            "rain.rate_mm_h=0,3",
            "--vary",
            "occlusion=on,off",
            "--seeds",
            "1..2",
            "--frames",
            "0",
            "-o",
        ])
        .arg(out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    String::from_utf8_lossy(&o.stderr).into_owned()
}

#[test]
fn interrupted_and_restarted_equals_uninterrupted() {
    let tmp = tempfile::tempdir().unwrap();
    let a = tmp.path().join("a");
    let b = tmp.path().join("b");
    let msg = sweep(&a);
    assert!(msg.contains("8 cells computed, 0 loaded"), "{msg}");
    sweep(&b);
    // Simulate an interruption: half the cells and every final output are missing.
    let cells = b.join("cells").join("crossroad");
    let mut names: Vec<PathBuf> = std::fs::read_dir(&cells)
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    names.sort();
    assert_eq!(names.len(), 8);
    for p in names.iter().step_by(2) {
        std::fs::remove_file(p).unwrap();
    }
    for f in ["sweep.csv", "sweep.json", "aggregate.csv", "index.html"] {
        std::fs::remove_file(b.join(f)).unwrap();
    }
    std::fs::remove_dir_all(b.join("plots")).unwrap();
    let msg = sweep(&b);
    assert!(msg.contains("4 cells computed, 4 loaded"), "{msg}");
    let fa = common::files(&a);
    let fb = common::files(&b);
    assert_eq!(fa.keys().collect::<Vec<_>>(), fb.keys().collect::<Vec<_>>());
    assert!(fa.len() > 8 + 4 + 10, "{} files", fa.len());
    for (k, v) in &fa {
        assert!(v == &fb[k], "{} differs", k.display());
    }
    // A third run computes nothing.
    let msg = sweep(&b);
    assert!(msg.contains("0 cells computed, 8 loaded"), "{msg}");
    assert!(common::files(&b) == fa);
}

#[test]
fn a_cell_with_other_settings_is_recomputed() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("o");
    sweep(&out);
    // Tamper with the recorded settings of one cell: it must be computed again.
    let cells = out.join("cells").join("crossroad");
    let p = std::fs::read_dir(&cells)
        .unwrap()
        .next()
        .unwrap()
        .unwrap()
        .path();
    let text = std::fs::read_to_string(&p).unwrap();
    std::fs::write(
        &p,
        text.replace(
            &format!("\"metrics_version\": {METRICS_VERSION}"),
            "\"metrics_version\": 0",
        ),
    )
    .unwrap();
    assert_ne!(
        std::fs::read_to_string(&p).unwrap(),
        text,
        "tampering failed"
    );
    let msg = sweep(&out);
    assert!(msg.contains("1 cells computed, 7 loaded"), "{msg}");
    assert_eq!(std::fs::read_to_string(&p).unwrap(), text);
}
