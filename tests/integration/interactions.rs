//! `sweep --interactions` on constructed stage pairs, through the real pipeline.
//!
//! The scene: flat ground and four 3 m walls 8 m from the sensor, straight ahead
//! (azimuth 0), to the right (90), behind (180) and to the left (270); each wall faces
//! the sensor and is hit by rings 13..=28 (elevations -13.3 to +6.7 degrees). Each test
//! pairs two occlusion stages restricted to azimuth sectors, so the designed outcome of
//! every object is known:
//!
//! - compounding: two stages each drop a disjoint half of the front wall's rings (even
//!   and odd ones); each alone leaves a wall with 0.37 m between its rings (cut 0.5 m),
//!   together they remove it.
//! - masking: one stage cuts two gaps into the right wall, which splits it into three
//!   pieces (no piece holds half its returns); the other removes the top and bottom
//!   pieces, so with both the middle piece is a whole object again.
//! - independent: one stage removes the front and right walls, the other the front and
//!   left walls: each alone keeps half of the walls, both keep a quarter, the product.

use crate::common::bin;
use serde_json::Value;
use std::path::{Path, PathBuf};

const SCENE: &str = r#"
name = "walls"
frames = 1
seed = 1

[sensor]
height_m = 1.9
rotation_hz = 10.0

[ground]
reflectance = 0.2

[[objects]]
kind = "wall"
x = 8.15
y = 0.0
length_m = 0.3
width_m = 2.0
height_m = 3.0
reflectance = 0.5

[[objects]]
kind = "wall"
x = 0.0
y = -8.15
length_m = 2.0
width_m = 0.3
height_m = 3.0
reflectance = 0.5

[[objects]]
kind = "wall"
x = -8.15
y = 0.0
length_m = 0.3
width_m = 2.0
height_m = 3.0
reflectance = 0.5

[[objects]]
kind = "wall"
x = 0.0
y = 8.15
length_m = 2.0
width_m = 0.3
height_m = 3.0
reflectance = 0.5
"#;

/// Synthesizes the scene once per test into `dir`; returns the capture.
fn capture(dir: &Path) -> PathBuf {
    let scene = dir.join("walls.toml");
    std::fs::write(&scene, SCENE).unwrap();
    bin()
        .args(["synth", "-q", "-o"])
        .arg(dir)
        .arg(&scene)
        .assert()
        .success();
    let pcap = dir.join("walls.pcap");
    assert!(pcap.is_file() && dir.join("walls.labels.csv.gz").is_file());
    pcap
}

fn rings(r: impl IntoIterator<Item = u32>) -> String {
    let v: Vec<String> = r.into_iter().map(|k| k.to_string()).collect();
    format!("[{}]", v.join(", "))
}

/// A config with two occlusion stages: (rings, azimuth sector) each.
fn config(dir: &Path, a: (String, [f64; 2]), b: (String, [f64; 2])) -> PathBuf {
    let stage = |(r, s): &(String, [f64; 2])| {
        format!(
            "[[noise]]\ntype = \"occlusion\"\nrings = {r}\nazimuth_deg = [{}, {}]\n\n",
            s[0], s[1]
        )
    };
    let text = format!(
        "seed = 1\n\n{}{}[detection]\nmin_power = 0.001\nmin_range_m = 0.9\n",
        stage(&a),
        stage(&b)
    );
    let path = dir.join("pair.toml");
    std::fs::write(&path, text).unwrap();
    path
}

/// Runs `sweep --interactions` and returns the interaction rows of all distances and of
/// the [5, 10) m band, plus the output folder.
fn sweep(dir: &Path, pcap: &Path, config: &Path) -> (Value, Value, PathBuf) {
    let out = dir.join("out");
    bin()
        .args(["sweep", "-q", "--interactions", "--seeds", "1..2", "-c"])
        .arg(config)
        .arg(pcap)
        .arg("-o")
        .arg(&out)
        .assert()
        .success();
    let json: Value =
        serde_json::from_slice(&std::fs::read(out.join("interactions.json")).unwrap()).unwrap();
    let rows = json["rows"].as_array().unwrap();
    assert_eq!(rows.len(), 6, "one pair, five bands and all distances");
    let find = |band: &str| {
        rows.iter()
            .find(|r| r["band"] == band)
            .unwrap_or_else(|| panic!("no {band} row in {json}"))
            .clone()
    };
    (find("all distances"), find("[5, 10) m"), out)
}

fn share(row: &Value, key: &str) -> f64 {
    row[key]
        .as_f64()
        .unwrap_or_else(|| panic!("{key} in {row}"))
}

#[test]
fn two_stages_dropping_disjoint_halves_of_an_object_compound() {
    let dir = tempfile::tempdir().unwrap();
    let pcap = capture(dir.path());
    let front = [340.0, 20.0];
    let cfg = config(
        dir.path(),
        (rings((13..=28).step_by(2)), front),
        (rings((14..=28).step_by(2)), front),
    );
    let (all, band, out) = sweep(dir.path(), &pcap, &cfg);
    assert_eq!(all["stage_a"], "occlusion[0]");
    assert_eq!(all["stage_b"], "occlusion[1]");
    // All four walls are found without noise; each stage alone keeps every wall.
    assert_eq!(share(&all, "clean_detected_share"), 1.0, "{all}");
    assert_eq!(share(&all, "a_alone"), 1.0, "{all}");
    assert_eq!(share(&all, "b_alone"), 1.0, "{all}");
    // Together the front wall is gone: 3 of 4, where independence predicts 4 of 4.
    assert_eq!(share(&all, "both"), 0.75, "{all}");
    assert_eq!(all["verdict"], "compounding", "{all}");
    assert_eq!(band["verdict"], "compounding", "{band}");
    // The run without stages and each stage alone are cells of the sweep.
    let tidy = std::fs::read_to_string(out.join("sweep.csv")).unwrap();
    for v in [
        "none",
        "occlusion[0]",
        "occlusion[1]",
        "occlusion[0]+occlusion[1]",
    ] {
        assert!(tidy.contains(&format!(",{v},")), "{v} missing in sweep.csv");
    }
    assert!(out.join("plots/interactions_walls.png").is_file());
    let page = std::fs::read_to_string(out.join("index.html")).unwrap();
    assert!(page.contains("plots/interactions_walls.png") && page.contains("compounding"));
}

#[test]
fn a_stage_removing_what_another_splits_off_masks_it() {
    let dir = tempfile::tempdir().unwrap();
    let pcap = capture(dir.path());
    let right = [70.0, 110.0];
    let cfg = config(
        dir.path(),
        // a: the top and bottom pieces that b would leave.
        (rings((13..=16).chain(26..=28)), right),
        // b: two gaps of three rings (0.75 m at 8 m) split the wall in three.
        (rings((17..=19).chain(23..=25)), right),
    );
    let (all, band, _) = sweep(dir.path(), &pcap, &cfg);
    assert_eq!(share(&all, "a_alone"), 1.0, "{all}");
    assert_eq!(share(&all, "b_alone"), 0.75, "{all}");
    assert_eq!(share(&all, "both"), 1.0, "{all}");
    assert_eq!(all["verdict"], "masking", "{all}");
    assert_eq!(band["verdict"], "masking", "{band}");
}

#[test]
fn stages_on_different_objects_are_independent() {
    let dir = tempfile::tempdir().unwrap();
    let pcap = capture(dir.path());
    let every = rings(0..=31);
    let cfg = config(
        dir.path(),
        // a: front and right walls; b: front and left walls.
        (every.clone(), [340.0, 110.0]),
        (every, [250.0, 20.0]),
    );
    let (all, band, _) = sweep(dir.path(), &pcap, &cfg);
    assert_eq!(share(&all, "a_alone"), 0.5, "{all}");
    assert_eq!(share(&all, "b_alone"), 0.5, "{all}");
    assert_eq!(share(&all, "both"), 0.25, "{all}");
    assert_eq!(share(&all, "independence_product"), 0.25, "{all}");
    assert_eq!(all["verdict"], "independent", "{all}");
    assert_eq!(band["verdict"], "independent", "{band}");
}

#[test]
fn interactions_need_two_stages_and_no_vary() {
    let dir = tempfile::tempdir().unwrap();
    let pcap = dir.path().join("missing.pcap");
    let one = dir.path().join("one.toml");
    std::fs::write(&one, "[[noise]]\ntype = \"rain\"\nrate_mm_h = 3.0\n").unwrap();
    let out = dir.path().join("out");
    let assert = bin()
        .args(["sweep", "--interactions", "-c"])
        .arg(&one)
        .arg(&pcap)
        .arg("-o")
        .arg(&out)
        .assert()
        .failure();
    let err = String::from_utf8_lossy(&assert.get_output().stderr).into_owned();
    assert!(err.contains("at least two"), "{err}");
    assert!(!out.exists());
    let assert = bin()
        .args(["sweep", "--interactions", "--vary", "rain.rate_mm_h=1,2"])
        .arg(&pcap)
        .assert()
        .failure();
    let err = String::from_utf8_lossy(&assert.get_output().stderr).into_owned();
    assert!(
        err.contains("--interactions") && err.contains("--vary"),
        "{err}"
    );
}
