//! Provenance: outputs record the effective configuration with `--set` and `--seed`, and
//! `validate --print` writes a configuration that reruns to the same results.

use crate::common;

use crate::common::bin;
use lidar_noise::compare::{compare_dirs, Tolerances};
use std::path::Path;

fn run(out: &Path, config: Option<&Path>, extra: &[&str]) {
    let mut cmd = bin();
    cmd.env("RAYON_NUM_THREADS", "2")
        .args(["--quiet", "run"])
        .arg(common::fixtures().join("crossroad.pcap"))
        .args(["--frames", "0", "--ascii", "-o"])
        .arg(out);
    if let Some(c) = config {
        cmd.arg("-c").arg(c);
    }
    cmd.args(extra).assert().success();
}

/// `validate --print` output without its leading comment lines.
fn printed(args: &[&str]) -> String {
    let out = bin()
        .args(["validate", "--print"])
        .args(args)
        .output()
        .unwrap();
    assert!(out.status.success());
    let text = String::from_utf8(out.stdout).unwrap();
    text.lines()
        .filter(|l| !l.starts_with('#'))
        .collect::<Vec<_>>()
        .join("\n")
}

#[test]
fn ply_and_summary_record_set_overrides_and_seed() {
    let tmp = tempfile::tempdir().unwrap();
    run(
        tmp.path(),
        None,
        &["--set", "noise[1].rate_mm_h=1", "--seed", "11"],
    );
    let ply = std::fs::read_to_string(tmp.path().join("crossroad/frame_00000.ply")).unwrap();
    let header = &ply[..ply.find("end_header").unwrap()];
    assert!(
        header.contains(
            "comment config <built-in configs/paper.toml> --set noise[1].rate_mm_h=1 --seed 11\n"
        ),
        "{header}"
    );
    assert!(
        header.contains("comment effective-config seed = 11\n"),
        "{header}"
    );
    assert!(
        header.contains("comment effective-config rate_mm_h = 1.0\n"),
        "{header}"
    );
    let summary: serde_json::Value =
        serde_json::from_slice(&std::fs::read(tmp.path().join("crossroad/summary.json")).unwrap())
            .unwrap();
    assert_eq!(
        summary["config"],
        "<built-in configs/paper.toml> --set noise[1].rate_mm_h=1 --seed 11"
    );
    assert_eq!(summary["settings"]["noise"][1]["rate_mm_h"], 1.0);
    assert_eq!(summary["settings"]["seed"], 11);
}

#[test]
fn printed_configuration_reruns_to_the_same_results() {
    let tmp = tempfile::tempdir().unwrap();
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut checked = 0;
    for entry in std::fs::read_dir(root.join("configs")).unwrap() {
        let config = entry.unwrap().path();
        if config.extension().and_then(|e| e.to_str()) != Some("toml") {
            continue;
        }
        let name = config.file_stem().unwrap().to_string_lossy().into_owned();
        let overrides = ["--set", "detection.min_power=0.002", "--seed", "5"];
        let mut args = vec![config.to_str().unwrap()];
        args.extend(overrides);
        let first = printed(&args);
        let saved = tmp.path().join(format!("{name}.effective.toml"));
        std::fs::write(&saved, &first).unwrap();
        // Printing the saved file again gives the same configuration.
        assert_eq!(printed(&[saved.to_str().unwrap()]), first, "{name}");
        assert!(first.contains("min_power = 0.002"), "{first}");
        // And running it gives the same results as the original with the overrides.
        let (a, b) = (
            tmp.path().join(format!("{name}-a")),
            tmp.path().join(format!("{name}-b")),
        );
        run(&a, Some(&config), &overrides);
        run(&b, Some(&saved), &[]);
        let report = compare_dirs(&a, &b, &Tolerances::default()).unwrap();
        assert!(report.same(), "{name}:\n{}", report.human());
        checked += 1;
    }
    assert!(checked >= 2, "configs/*.toml");
}
