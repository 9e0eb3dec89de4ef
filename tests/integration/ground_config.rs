//! The `[ground]` keys of the patchwork method: read, typed, checked, named in errors.

use lidar_noise::config::Config;
use lidar_noise::ground::GroundMethod;
use std::path::Path;

fn load(text: &str) -> Result<Config, String> {
    Config::from_toml_str(text, Path::new("exp.toml"), &[], None)
        .map(|(c, _)| c)
        .map_err(|e| e.to_string())
}

#[test]
fn patchwork_is_the_default_and_its_keys_are_read() {
    let c = load("seed = 1\n").unwrap();
    assert_eq!(c.ground.method, GroundMethod::Patchwork);
    let c = load(
        "[ground]\nmethod = \"patchwork\"\npatchwork_sensor_height_m = 2.2\npatchwork_continuity_m = 0.4\npatchwork_rnr_max_intensity = 5\n",
    )
    .unwrap();
    assert_eq!(c.ground.patchwork_sensor_height_m, 2.2);
    assert_eq!(c.ground.patchwork_continuity_m, 0.4);
    assert_eq!(c.ground.patchwork_rnr_max_intensity, 5);
    let json = c.to_json().to_string();
    assert!(json.contains("\"patchwork_sensor_height_m\":2.2"), "{json}");
    // Other methods' reports keep only their own keys.
    let c = load("[ground]\nmethod = \"range-image\"\n").unwrap();
    assert!(!c.to_json().to_string().contains("patchwork_"));
}

#[test]
fn bad_patchwork_values_name_the_key_and_line() {
    for (text, key) in [
        (
            "[ground]\npatchwork_sensor_height_m = -1.0\n",
            "patchwork_sensor_height_m",
        ),
        (
            "[ground]\npatchwork_uprightness_deg = 95\n",
            "patchwork_uprightness_deg",
        ),
        (
            "[ground]\npatchwork_distance_m = \"far\"\n",
            "patchwork_distance_m",
        ),
        (
            "[ground]\npatchwork_rnr_max_intensity = 300\n",
            "patchwork_rnr_max_intensity",
        ),
        (
            "[ground]\npatchwork_max_range_m = 2.0\n",
            "patchwork_max_range_m",
        ),
        ("[ground]\npatchwork_zones = 3\n", "patchwork_zones"),
    ] {
        let e = load(text).unwrap_err();
        assert!(e.contains(key) && e.contains("line 2"), "{text}: {e}");
    }
}
