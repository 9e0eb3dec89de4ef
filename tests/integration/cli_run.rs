//! The `run`, `info`, `convert` and `validate` commands as a shell script sees them.

use crate::common;

use crate::common::bin;
use std::collections::BTreeMap;
use std::path::Path;

fn run_with(threads: &str, seed: &str, out: &Path, extra: &[&str]) {
    let fixture = common::fixtures().join("crossroad.pcap");
    bin()
        .env("RAYON_NUM_THREADS", threads)
        .args(["--quiet", "run"])
        .arg(&fixture)
        .args(["--seed", seed, "-o"])
        .arg(out)
        .args(if extra.contains(&"--no-ply") {
            &[][..]
        } else {
            &["--keep-dropped"][..]
        })
        .args(extra)
        .assert()
        .success();
}

#[test]
fn outputs_are_byte_identical_for_any_thread_count_and_change_with_the_seed() {
    let tmp = tempfile::tempdir().unwrap();
    let (a, b, c) = (
        tmp.path().join("a"),
        tmp.path().join("b"),
        tmp.path().join("c"),
    );
    run_with("1", "7", &a, &[]);
    run_with("2", "7", &b, &[]);
    run_with("2", "8", &c, &[]);
    let (fa, fb, fc) = (common::files(&a), common::files(&b), common::files(&c));
    assert!(fa.len() >= 5, "{:?}", fa.keys());
    assert_eq!(fa.keys().collect::<Vec<_>>(), fb.keys().collect::<Vec<_>>());
    for (name, bytes) in &fa {
        assert!(
            bytes == &fb[name],
            "{} differs between 1 and 2 threads",
            name.display()
        );
    }
    let ply = Path::new("crossroad/frame_00000.ply");
    assert!(fa[ply] != fc[ply], "another seed must give other noise");
}

#[test]
fn keep_dropped_ply_lists_fate_codes_and_every_return() {
    let tmp = tempfile::tempdir().unwrap();
    run_with("2", "1", tmp.path(), &["--frames", "0", "--ascii"]);
    let text = std::fs::read_to_string(tmp.path().join("crossroad/frame_00000.ply")).unwrap();
    let header: Vec<&str> = text.lines().take_while(|l| *l != "end_header").collect();
    assert!(header
        .iter()
        .any(|l| l.contains("fate codes: 0 kept, 1 occluded, 2 below_power, 3 below_min_range")));
    for prop in ["range_clean", "power", "fate", "ground", "cluster"] {
        assert!(
            header
                .iter()
                .any(|l| l.starts_with("property") && l.ends_with(&format!(" {prop}"))),
            "{prop}"
        );
    }
    let summary: serde_json::Value =
        serde_json::from_slice(&std::fs::read(tmp.path().join("crossroad/summary.json")).unwrap())
            .unwrap();
    let returns_in = summary["totals"]["noise"]["returns_in"].as_u64().unwrap();
    let vertices: u64 = header
        .iter()
        .find_map(|l| l.strip_prefix("element vertex "))
        .unwrap()
        .parse()
        .unwrap();
    assert_eq!(
        vertices, returns_in,
        "with --keep-dropped every return is in the PLY"
    );
    assert!(!std::fs::exists(tmp.path().join("crossroad/frame_00001.ply")).unwrap());
    assert_eq!(summary["settings"]["seed"], 1);
    assert_eq!(summary["version"], env!("CARGO_PKG_VERSION"));
}

#[test]
fn bad_config_fails_naming_key_and_line_and_writes_nothing() {
    let tmp = tempfile::tempdir().unwrap();
    let cfg = tmp.path().join("bad.toml");
    std::fs::write(
        &cfg,
        "seed = 1\n[[noise]]\ntype = \"rain\"\nrate_mm_h = -3\n",
    )
    .unwrap();
    let out = tmp.path().join("out");
    let assert = bin()
        .args(["run", "-c"])
        .arg(&cfg)
        .arg("-o")
        .arg(&out)
        .assert()
        .code(1);
    let err = String::from_utf8_lossy(&assert.get_output().stderr).to_string();
    assert!(
        err.contains("bad.toml") && err.contains("rate_mm_h") && err.contains("line 4"),
        "{err}"
    );
    assert!(!out.exists(), "no partial output");
    let assert = bin().arg("validate").arg(&cfg).assert().code(1);
    let err = String::from_utf8_lossy(&assert.get_output().stderr).to_string();
    assert!(err.contains("line 4"), "{err}");
    bin()
        .args(["validate", "configs/paper.toml"])
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .assert()
        .success();
}

#[test]
fn usage_errors_exit_2_and_missing_files_exit_1() {
    bin().arg("frobnicate").assert().code(2);
    let assert = bin()
        .args(["info", "no/such/capture.pcap"])
        .assert()
        .code(1);
    let err = String::from_utf8_lossy(&assert.get_output().stderr).to_string();
    assert!(err.contains("no/such/capture.pcap"), "{err}");
}

#[test]
fn output_refuses_to_overwrite_an_input() {
    let tmp = tempfile::tempdir().unwrap();
    let capture = tmp.path().join("frame_00000.ply");
    std::fs::copy(common::fixtures().join("crossroad.pcap"), &capture).unwrap();
    let before = std::fs::read(&capture).unwrap();
    bin()
        .args(["--quiet", "convert"])
        .arg(&capture)
        .arg("-o")
        .arg(tmp.path())
        .assert()
        .code(1);
    assert_eq!(std::fs::read(&capture).unwrap(), before);
}

#[test]
fn info_json_reports_the_shared_capture() {
    let Some(path) = common::shared("hdl32e/monterey.pcap") else {
        return;
    };
    let assert = bin().args(["info", "--json"]).arg(&path).assert().success();
    let v: serde_json::Value = serde_json::from_slice(&assert.get_output().stdout).unwrap();
    assert_eq!(v["data_packets"], 2702);
    assert_eq!(v["position_packets"], 299);
    assert_eq!(v["full_frames"], 17);
    assert_eq!(v["returns"], 872_800);
    assert_eq!(v["product"], "HDL-32E");
}

fn totals(dir: &Path, name: &str) -> serde_json::Value {
    let s: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join(name).join("summary.json")).unwrap())
            .unwrap();
    s["totals"]["noise"].clone()
}

#[test]
fn shared_capture_clear_drops_under_1_percent_and_paper_drops_more_than_each_noise_alone() {
    let Some(path) = common::shared("hdl32e/monterey.pcap") else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut dropped = BTreeMap::new();
    for name in ["clear", "rain", "occlusion", "paper"] {
        let out = tmp.path().join(name);
        bin()
            .args(["--quiet", "run", "--no-ply", "-c"])
            .arg(root.join("configs").join(format!("{name}.toml")))
            .arg(&path)
            .arg("-o")
            .arg(&out)
            .assert()
            .success();
        let t = totals(&out, "monterey");
        let d = &t["dropped"];
        let total = d["occluded"].as_u64().unwrap()
            + d["below_power"].as_u64().unwrap()
            + d["below_min_range"].as_u64().unwrap();
        assert_eq!(
            total + t["returns_out"].as_u64().unwrap(),
            t["returns_in"].as_u64().unwrap()
        );
        eprintln!(
            "{name}: {total} of {} dropped, by cause {d}",
            t["returns_in"]
        );
        dropped.insert(name, (total, t["returns_in"].as_u64().unwrap(), d.clone()));
    }
    let (clear, n, _) = &dropped["clear"];
    assert!(
        (*clear as f64) < 0.01 * *n as f64,
        "clear drops {clear} of {n}"
    );
    let paper = dropped["paper"].0;
    assert!(paper > dropped["rain"].0 && paper > dropped["occlusion"].0);
    let split = &dropped["paper"].2;
    assert!(split["occluded"].as_u64().unwrap() > 0 && split["below_power"].as_u64().unwrap() > 0);
}

#[test]
fn linkage_out_writes_a_scipy_layout_merge_tree_per_frame() {
    let tmp = tempfile::tempdir().unwrap();
    run_with(
        "2",
        "3",
        tmp.path(),
        &["--frames", "1", "--linkage-out", "--no-ply"],
    );
    let text = std::fs::read_to_string(tmp.path().join("crossroad/linkage_00001.csv")).unwrap();
    let mut lines = text.lines();
    assert_eq!(lines.next(), Some("cluster_a,cluster_b,distance,count"));
    let rows: Vec<Vec<f64>> = lines
        .map(|l| l.split(',').map(|c| c.parse().unwrap()).collect())
        .collect();
    assert!(rows.len() > 1000, "{} merges", rows.len());
    let summary: serde_json::Value =
        serde_json::from_slice(&std::fs::read(tmp.path().join("crossroad/summary.json")).unwrap())
            .unwrap();
    let n = summary["frames"][0]["stages"]["non_ground"]
        .as_u64()
        .unwrap() as f64;
    for (k, row) in rows.iter().enumerate() {
        assert_eq!(row.len(), 4);
        assert!(
            row[0] < n + k as f64 && row[1] < n + k as f64,
            "ids refer to points or earlier merges"
        );
        assert!(row[2] <= 2.0, "no merge above max_edge_m");
        if k > 0 {
            assert!(row[2] >= rows[k - 1][2], "heights are sorted");
        }
    }
    assert!(!tmp.path().join("crossroad/frame_00001.ply").exists());
}
