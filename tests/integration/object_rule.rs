//! Which clusters are objects: the `[cluster]` object keys and the rule itself.

use lidar_noise::cluster::{describe, ObjectRule};
use lidar_noise::config::Config;
use lidar_noise::frame::{Return, ReturnKind};
use std::path::Path;

fn load(text: &str) -> Result<Config, String> {
    Config::from_toml_str(text, Path::new("exp.toml"), &[], None)
        .map(|c| c.0)
        .map_err(|e| e.to_string())
}

#[test]
fn object_keys_are_read_and_validated_with_key_and_line() {
    let c =
        load("[cluster]\nmin_points = 5\nobject_min_height_m = 0.3\nobject_max_extent_m = 20\n")
            .unwrap();
    assert_eq!(c.objects.min_height_m, 0.3);
    assert_eq!(c.objects.max_extent_m, 20.0);
    assert_eq!(c.objects.max_height_m, ObjectRule::default().max_height_m);
    let defaults = load("seed = 1\n").unwrap().objects;
    assert_eq!(defaults, ObjectRule::default());
    // The effective settings repeat the keys.
    assert!(c.effective_toml().contains("object_min_height_m = 0.3"));

    let e = load("[cluster]\nmin_points = 5\nobject_min_height_m = -1.0\n").unwrap_err();
    assert!(
        e.contains("cluster.object_min_height_m") && e.contains("line 3,"),
        "{e}"
    );
    let e = load("[cluster]\nobject_min_extent_m = 5.0\nobject_max_extent_m = 2.0\n").unwrap_err();
    assert!(
        e.contains("cluster.object_max_extent_m") && e.contains("line 3,"),
        "{e}"
    );
    // Only the minimum is given: it is the key named.
    let e = load("[cluster]\nobject_min_height_m = 7.0\n").unwrap_err();
    assert!(
        e.contains("cluster.object_min_height_m") && e.contains("line 2,") && e.contains("empty"),
        "{e}"
    );
    let e = load("[cluster]\nobject_max_height_m = \"tall\"\n").unwrap_err();
    assert!(e.contains("cluster.object_max_height_m"), "{e}");
}

fn at(x: f32, y: f32, z: f32) -> Return {
    Return {
        x,
        y,
        z,
        range: (x * x + y * y + z * z).sqrt(),
        azimuth: 0.0,
        elevation: 0.0,
        time: 0.0,
        packet: 0,
        raw_distance: 1,
        intensity: 0,
        laser: 0,
        ring: 0,
        block: 0,
        kind: ReturnKind::Strongest,
    }
}

/// A column of `n` returns from z = 0 to `height`, spread over `length` along x.
fn cluster_of(n: usize, height: f32, length: f32) -> Vec<Return> {
    (0..n)
        .map(|i| {
            let t = i as f32 / (n - 1) as f32;
            at(10.0 + t * length, (i % 2) as f32 * 0.2, t * height)
        })
        .collect()
}

fn is_object(returns: &[Return], min_points: usize) -> bool {
    let info = describe(returns, &vec![0; returns.len()]).unwrap();
    ObjectRule::default().is_object(&info[0], min_points)
}

#[test]
fn the_default_rule_keeps_road_users_and_rejects_clutter() {
    // A cone (0.6 m), a pedestrian (1.8 m), a car (4.5 x 1.5 m), an 18 m truck: objects.
    assert!(is_object(&cluster_of(20, 0.6, 0.3), 10));
    assert!(is_object(&cluster_of(20, 1.8, 0.5), 10));
    assert!(is_object(&cluster_of(20, 1.5, 4.5), 10));
    assert!(is_object(&cluster_of(20, 4.0, 17.9), 10));
    // A flat ground remnant (0.2 m), a 25 m wall, a 10 m tall mast: not objects.
    assert!(!is_object(&cluster_of(20, 0.2, 3.0), 10));
    assert!(!is_object(&cluster_of(20, 2.5, 25.0), 10));
    assert!(!is_object(&cluster_of(20, 10.0, 0.3), 10));
    // Too few returns.
    assert!(!is_object(&cluster_of(9, 1.8, 0.5), 10));
}
