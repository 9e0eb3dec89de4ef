//! A sweep grows by new values or seeds without `--force` (issue 33, Messages: adding
//! one value was refused, "replaced as a whole", though with `--force` the finished
//! cells were reused): the finished cells are reused, the results equal a sweep of the
//! grown plan from scratch, and the manifest records the plan it grew from. Another base
//! configuration, capture, key or a removed value is still another sweep, refused.

use crate::common;

use assert_cmd::Command;
use std::path::Path;

/// Runs `lidar-noise sweep` over a frame of the crossroad fixture (or `capture`) into
/// `out`; returns the exit code and stderr.
fn sweep(out: &Path, capture: &str, args: &[&str]) -> (i32, String) {
    let o = Command::cargo_bin("lidar-noise")
        .unwrap()
        .arg("sweep")
        .arg(common::fixtures().join(capture))
        .args(["--frames", "0", "-o"])
        .arg(out)
        .args(args)
        .output()
        .unwrap();
    (
        o.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&o.stderr).into_owned(),
    )
}

fn manifest(out: &Path) -> serde_json::Value {
    serde_json::from_slice(&std::fs::read(out.join(".lidar-noise.json")).unwrap()).unwrap()
}

#[test]
fn a_sweep_grows_by_new_values_and_seeds_without_force() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("grown");
    let c = "crossroad.pcap";
    let (code, err) = sweep(&out, c, &["--vary", "rain.rate_mm_h=0,3", "--seeds", "1"]);
    assert_eq!(code, 0, "{err}");
    assert!(manifest(&out).get("growth").is_none());

    // One value more: the two finished cells are loaded, one is computed.
    let (code, err) = sweep(&out, c, &["--vary", "rain.rate_mm_h=0,1,3", "--seeds", "1"]);
    assert_eq!(code, 0, "{err}");
    assert!(err.contains("1 cells computed, 2 loaded"), "{err}");
    assert!(err.contains("the plan grows"), "{err}");
    // And a seed more: three loaded, three computed.
    let (code, err) = sweep(
        &out,
        c,
        &["--vary", "rain.rate_mm_h=0,1,3", "--seeds", "1,2"],
    );
    assert_eq!(code, 0, "{err}");
    assert!(err.contains("3 cells computed, 3 loaded"), "{err}");
    // The record: the grown plan, and the plans it grew from, oldest first.
    let m = manifest(&out);
    assert_eq!(m["settings"]["seeds"], serde_json::json!([1, 2]));
    let values = |v: &serde_json::Value| v["varies"][0]["values"].clone();
    let growth = m["growth"].as_array().expect("growth recorded");
    assert_eq!(growth.len(), 2, "{m}");
    assert_eq!(values(&growth[0]), serde_json::json!(["0", "3"]));
    assert_eq!(growth[0]["seeds"], serde_json::json!([1]));
    assert_eq!(values(&growth[1]), serde_json::json!(["0", "1", "3"]));
    assert_eq!(growth[1]["seeds"], serde_json::json!([1]));
    // A rerun of the same plan keeps the record.
    let (code, err) = sweep(
        &out,
        c,
        &["--vary", "rain.rate_mm_h=0,1,3", "--seeds", "1,2"],
    );
    assert_eq!(code, 0, "{err}");
    assert_eq!(manifest(&out)["growth"].as_array().map(Vec::len), Some(2));

    // The results equal the grown plan's from scratch.
    let fresh = tmp.path().join("fresh");
    let (code, err) = sweep(
        &fresh,
        c,
        &["--vary", "rain.rate_mm_h=0,1,3", "--seeds", "1,2"],
    );
    assert_eq!(code, 0, "{err}");
    let (a, b) = (common::files(&out), common::files(&fresh));
    assert_eq!(a.keys().collect::<Vec<_>>(), b.keys().collect::<Vec<_>>());
    for (name, bytes) in &a {
        if name.to_string_lossy() != ".lidar-noise.json" {
            assert!(bytes == &b[name], "{} differs", name.display());
        }
    }

    // Not growth: still refused without --force (exit 3), results untouched.
    let before = common::files(&out);
    for (capture, args) in [
        // A value removed.
        (
            "crossroad.pcap",
            vec!["--vary", "rain.rate_mm_h=0,1", "--seeds", "1,2"],
        ),
        // A seed removed.
        (
            "crossroad.pcap",
            vec!["--vary", "rain.rate_mm_h=0,1,3", "--seeds", "2"],
        ),
        // Another base configuration.
        (
            "crossroad.pcap",
            vec![
                "--vary",
                "rain.rate_mm_h=0,1,3,5",
                "--seeds",
                "1,2",
                "--set",
                "detection.min_power=0.002",
            ],
        ),
        // Another key varied as well.
        (
            "crossroad.pcap",
            vec![
                "--vary",
                "rain.rate_mm_h=0,1,3",
                "--vary",
                "occlusion=on,off",
                "--seeds",
                "1,2",
            ],
        ),
        // Another capture.
        (
            "parking.pcap",
            vec!["--vary", "rain.rate_mm_h=0,1,3,5", "--seeds", "1,2"],
        ),
    ] {
        let (code, err) = sweep(&out, capture, &args);
        assert_eq!(code, 3, "{capture} {args:?}: {err}");
        assert!(err.contains("--force"), "{err}");
        assert_eq!(common::files(&out), before, "{capture} {args:?}");
    }
}
