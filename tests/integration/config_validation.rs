//! Configuration loading: errors name key and line, overrides, warnings, shipped files.

use lidar_noise::config::Config;
use std::path::{Path, PathBuf};

fn load(text: &str, sets: &[&str]) -> Result<(Config, Vec<String>), String> {
    let sets: Vec<String> = sets.iter().map(|s| s.to_string()).collect();
    Config::from_toml_str(text, Path::new("exp.toml"), &sets, None).map_err(|e| e.to_string())
}

fn err(text: &str) -> String {
    match load(text, &[]) {
        Ok(_) => panic!("should fail:\n{text}"),
        Err(e) => e,
    }
}

fn assert_names(msg: &str, key: &str, line: usize) {
    assert!(msg.starts_with("exp.toml: "), "{msg}");
    assert!(msg.contains(key), "message should name {key}: {msg}");
    assert!(
        msg.contains(&format!("line {line},")),
        "message should name line {line}: {msg}"
    );
}

const GOOD: &str = r#"seed = 42
[sensor]
intensity = "reflectivity"
[power]
model = "lidar-equation"
reference_reflectance = 0.10
reference_range_m = 100.0
reflectance_floor = 0.005
[[noise]]
type = "occlusion"
lasers = [7, 5, 3, 1, 30]
[[noise]]
type = "rain"
rate_mm_h = 7.0
range_noise = "goodin"
[detection]
min_power = 0.001
min_range_m = 0.9
"#;

fn crate_path(rel: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(rel)
}

#[test]
fn the_contract_example_loads() {
    let (c, warnings) = load(GOOD, &[]).unwrap();
    assert!(warnings.is_empty(), "{warnings:?}");
    assert_eq!(c.seed, 42);
    assert_eq!(c.noise.len(), 2);
    assert_eq!(c.noise[0].kind(), "occlusion");
    assert_eq!(c.noise[1].kind(), "rain");
    assert_eq!(c.detection.min_power, 0.001);
    assert_eq!(c.detection.min_range_m, 0.9);
}

#[test]
fn unknown_keys_are_named_with_their_line() {
    let bad = GOOD.replace("min_range_m = 0.9", "min_range_m = 0.9\nmin_rnage = 1");
    assert_names(&err(&bad), "detection.min_rnage", 19);
    let bad = GOOD.replace(
        "range_noise = \"goodin\"",
        "range_noise = \"goodin\"\ndrop = 0.1",
    );
    assert_names(&err(&bad), "noise[1].drop", 16);
    let bad = format!("colour = 1\n{GOOD}");
    assert_names(&err(&bad), "colour", 1);
    let bad = GOOD.replace("[sensor]", "[sensor]\nfirmware = 2");
    assert_names(&err(&bad), "sensor.firmware", 3);
}

#[test]
fn wrong_types_and_impossible_values_are_named() {
    let e = err(&GOOD.replace("rate_mm_h = 7.0", "rate_mm_h = \"seven\""));
    assert_names(&e, "noise[1].rate_mm_h", 14);
    assert!(e.contains("expected a number"), "{e}");
    assert_names(
        &err(&GOOD.replace("rate_mm_h = 7.0", "rate_mm_h = -2")),
        "noise[1].rate_mm_h",
        14,
    );
    assert_names(
        &err(&GOOD.replace("[7, 5, 3, 1, 30]", "[7, 5, 128]")),
        "noise[0].lasers[2]",
        11,
    );
    assert_names(
        &err(&GOOD.replace("[7, 5, 3, 1, 30]", "[]")),
        "noise[0].lasers",
        11,
    );
    assert_names(
        &err(&GOOD.replace(
            "reference_reflectance = 0.10",
            "reference_reflectance = 1.5",
        )),
        "power.reference_reflectance",
        6,
    );
    // (An unknown type; "fog" served here until it became a stage.)
    let e = err(&GOOD.replace("type = \"rain\"", "type = \"hail\""));
    assert_names(&e, "noise[1].type", 13);
    assert!(e.contains("hail"), "{e}");
    assert_names(
        &err(&GOOD.replace("reference_range_m = 100.0", "reference_range_m = 0")),
        "power.reference_range_m",
        7,
    );
    assert_names(
        &err(&GOOD.replace("intensity = \"reflectivity\"", "intensity = \"percent\"")),
        "sensor.intensity",
        3,
    );
    assert_names(&err(&GOOD.replace("seed = 42", "seed = -1")), "seed", 1);
    assert_names(
        &err(&GOOD.replace("lasers = [7, 5, 3, 1, 30]", "rings = [15, 140]")),
        "noise[0].rings[1]",
        11,
    );
    assert_names(
        &err(&GOOD.replace("lasers = [7, 5, 3, 1, 30]", "elevation_deg = [-5, -10]")),
        "noise[0].elevation_deg",
        11,
    );
    assert_names(
        &err(&GOOD.replace(
            "lasers = [7, 5, 3, 1, 30]",
            "lasers = [7]\ntransmission = 1.0",
        )),
        "noise[0].transmission",
        12,
    );
    assert_names(
        &err(&GOOD.replace("lasers = [7, 5, 3, 1, 30]", "lasers = [7]\nrings = [3]")),
        "noise[0].rings",
        12,
    );
    assert_names(
        &err(&GOOD.replace("min_power = 0.001", "min_power = 0")),
        "detection.min_power",
        17,
    );
}

#[test]
fn missing_required_keys_point_at_their_table() {
    let e = err(&GOOD.replace("rate_mm_h = 7.0\n", ""));
    assert_names(&e, "noise[1].rate_mm_h", 12);
    assert!(e.contains("missing"), "{e}");
    let e = err(&GOOD.replace("lasers = [7, 5, 3, 1, 30]\n", ""));
    assert_names(&e, "noise[0]", 9);
}

#[test]
fn syntax_errors_give_the_line() {
    let e = err(&GOOD.replace("min_power = 0.001", "min_power = = 0.001"));
    assert!(e.contains("line 17"), "{e}");
}

#[test]
fn high_rain_rates_warn_about_the_fit() {
    // The warning belongs to Goodin's fit (issue 29): the mie model (default) has none.
    let (_, warnings) = load(&GOOD.replace("rate_mm_h = 7.0", "rate_mm_h = 12"), &[]).unwrap();
    assert!(warnings.is_empty(), "{warnings:?}");
    let (c, warnings) = load(
        &GOOD.replace("rate_mm_h = 7.0", "rate_mm_h = 12\nmodel = \"goodin\""),
        &[],
    )
    .unwrap();
    assert_eq!(c.noise.len(), 2);
    assert_eq!(warnings.len(), 1, "{warnings:?}");
    assert!(warnings[0].contains("noise[1].rate_mm_h"), "{warnings:?}");
    assert!(warnings[0].contains("7 mm/h"), "{warnings:?}");
    assert!(warnings[0].contains("line 14"), "{warnings:?}");
}

#[test]
fn set_overrides_keys_before_validation() {
    let (c, _) = load(
        GOOD,
        &[
            "noise[1].rate_mm_h=3",
            "detection.min_power=0.002",
            "sensor.intensity=raw",
        ],
    )
    .unwrap();
    let json = c.to_json();
    assert_eq!(json["noise"][1]["rate_mm_h"], 3.0);
    assert_eq!(json["noise"][1]["type"], "rain");
    assert_eq!(json["detection"]["min_power"], 0.002);
    assert_eq!(json["sensor"]["intensity"], "raw");
    // Appending a stage through --set.
    let (c, _) = load(
        GOOD,
        &[
            "noise[2].type=occlusion",
            "noise[2].rings=[0]",
            "ground.max_angle_delta_deg=7",
            "cluster.cutoff_m=0.3",
        ],
    )
    .unwrap();
    assert_eq!(c.noise.len(), 3);
    assert_eq!(c.ground.max_angle_delta_deg, 7.0);
    assert_eq!(c.cluster.cutoff_m, 0.3);
    // [ground] and [cluster] know their keys too.
    let e = load(GOOD, &["ground.max_angle=5"]).unwrap_err();
    assert!(e.contains("ground.max_angle"), "{e}");
    let e = load(GOOD, &["cluster.cut=\"fuzzy\""]).unwrap_err();
    assert!(e.contains("cluster.cut"), "{e}");
}

#[test]
fn a_bad_set_names_itself() {
    for (arg, key) in [
        ("noise[1].rate_mm_h=-3", "noise[1].rate_mm_h"),
        ("detection.min_powr=0.1", "detection.min_powr"),
        ("noise[1].rate_mm_h=fast", "noise[1].rate_mm_h"),
    ] {
        let e = load(GOOD, &[arg]).unwrap_err();
        assert!(e.contains(&format!("--set {arg}")), "{e}");
        assert!(e.contains(key), "{e}");
    }
    for arg in ["noise[7].rate_mm_h=1", "noise=", "seed.x=1", "nokeyvalue"] {
        let e = load(GOOD, &[arg]).unwrap_err();
        assert!(e.contains(&format!("--set {arg}")), "{arg}: {e}");
    }
}

#[test]
fn seed_override_and_defaults() {
    let (c, _) = Config::from_toml_str(GOOD, Path::new("x"), &[], Some(7)).unwrap();
    assert_eq!(c.seed, 7);
    let (c, _) = load("", &[]).unwrap();
    assert_eq!(c.seed, 42);
    assert!(c.noise.is_empty());
    assert_eq!(c.detection.min_power, 0.001);
    assert!(Config::from_toml_str(GOOD, Path::new("x"), &[], Some(u64::MAX)).is_err());
}

#[test]
fn effective_settings_round_trip() {
    let (c, _) = load(
        GOOD,
        &["noise[1].rate_mm_h=2.5", "noise[0].azimuth_deg=[300, 60]"],
    )
    .unwrap();
    let text = c.effective_toml();
    assert!(text.contains("rate_mm_h = 2.5"), "{text}");
    let (again, _) = load(&text, &[]).unwrap();
    assert_eq!(again.to_json(), c.to_json());
    assert_eq!(c.to_json()["seed"], 42);
    assert_eq!(c.to_json()["power"]["model"], "lidar-equation");
}

#[test]
fn shipped_configs_validate() {
    let expect = [
        ("configs/paper.toml", vec!["occlusion", "rain"]),
        ("configs/rain.toml", vec!["rain"]),
        ("configs/occlusion.toml", vec!["occlusion"]),
        ("configs/clear.toml", vec![]),
    ];
    for (file, kinds) in expect {
        let (c, w) = Config::load(Some(&crate_path(file)), &[], None)
            .unwrap_or_else(|e| panic!("{file}: {e}"));
        assert!(w.is_empty(), "{file}: {w:?}");
        let got: Vec<&str> = c.noise.iter().map(|s| s.kind()).collect();
        assert_eq!(got, kinds, "{file}");
        assert_eq!(c.detection.min_power, 0.001, "{file}");
        assert_eq!(c.detection.min_range_m, 0.9, "{file}");
    }
    // The built-in default is paper.toml.
    let (builtin, _) = Config::load(None, &[], None).unwrap();
    let (paper, _) = Config::load(Some(&crate_path("configs/paper.toml")), &[], None).unwrap();
    assert_eq!(builtin.to_json(), paper.to_json());
    assert_eq!(
        paper.to_json()["noise"][0]["lasers"],
        serde_json::json!([7, 5, 3, 1, 30])
    );
    assert_eq!(paper.to_json()["noise"][1]["rate_mm_h"], 7.0);
}

#[test]
fn validate_command_accepts_good_and_rejects_bad() {
    let dir = tempfile::tempdir().unwrap();
    let good = dir.path().join("good.toml");
    std::fs::write(&good, GOOD).unwrap();
    // `lidar-noise --quiet validate CONFIG --set ...`: its error message, or None.
    let validate = |p: &Path, set: &[&str]| -> Option<String> {
        let mut cmd = assert_cmd::Command::cargo_bin("lidar-noise").unwrap();
        cmd.args(["--quiet", "validate"]).arg(p);
        for s in set {
            cmd.args(["--set", s]);
        }
        let out = cmd.output().unwrap();
        (!out.status.success()).then(|| String::from_utf8_lossy(&out.stderr).into_owned())
    };
    assert_eq!(validate(&good, &[]), None);
    let e = validate(&good, &["noise[0].lasers=[199]"]).expect("refused");
    assert!(e.contains("--set noise[0].lasers=[199]"), "{e}");
    let bad = dir.path().join("bad.toml");
    std::fs::write(&bad, GOOD.replace("rate_mm_h = 7.0", "rate_mm_h = -7")).unwrap();
    let e = validate(&bad, &[]).expect("refused");
    assert!(e.contains("bad.toml") && e.contains("line 14"), "{e}");
    let missing = dir.path().join("nope.toml");
    assert!(validate(&missing, &[]).is_some());
}

/// An unknown stage key is named with the stage's own options (all of them, not only the
/// keys this entry sets) and the closest one; a misspelt required key is reported as the
/// misspelling, not as the required key missing (issue 33).
#[test]
fn unknown_stage_keys_name_the_stage_options_and_the_closest() {
    let e = err("[[noise]]\ntype = \"rain\"\nrate_mmh = 3.0\n");
    assert_names(&e, "noise[0].rate_mmh", 3);
    assert!(e.contains("did you mean `rate_mm_h`?"), "{e}");
    assert!(!e.contains("required key missing"), "{e}");
    let e = err("[[noise]]\ntype = \"rain\"\nrate_mm_h = 3.0\nbackscater = true\n");
    assert_names(&e, "noise[0].backscater", 4);
    assert!(e.contains("did you mean `backscatter`?"), "{e}");
    // The options this entry did not set are listed too.
    for option in ["divergence_mrad", "empty_slots", "model", "dsd"] {
        assert!(e.contains(option), "{option} missing from: {e}");
    }
    // From --set: a prefix of the one option it begins.
    let e = load(
        "[[noise]]\ntype = \"rain\"\nrate_mm_h = 3.0\n",
        &["rain.rate=3"],
    )
    .unwrap_err();
    assert!(e.contains("noise[0].rate (from --set rain.rate=3)"), "{e}");
    assert!(e.contains("did you mean `rate_mm_h`?"), "{e}");
    // Nothing near: no guess, the list alone.
    let e = err("[[noise]]\ntype = \"fog\"\nvisibility_m = 100.0\nzzz = 1\n");
    assert!(!e.contains("did you mean"), "{e}");
    assert!(e.contains("beta_r") && e.contains("overlap"), "{e}");
}
