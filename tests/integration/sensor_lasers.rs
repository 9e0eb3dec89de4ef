//! The noise stages on sensors of 16, 64 and 128 lasers (issue 31, "A sensor model, not
//! an HDL-32E special case"): firing slots hold every laser of the sensor, per-laser
//! values and selections reach lasers past 31, and per-laser options that do not fit the
//! sensor are refused before anything is written. Frames are built from points on each
//! model's beams (its own elevation table, a ring field), through `cloud::returns`.

use crate::common;

use common::{bin2, config, refused_scan, stage};
use lidar_noise::cloud::returns::{to_returns, ReturnsOptions};
use lidar_noise::cloud::CloudPoint;
use lidar_noise::frame::Frame;
use lidar_noise::noise::{Fate, NoiseChain, Slots};
use lidar_noise::sensor::{SensorModel, HDL32E, HDL64E_S2, VLP16};

/// A turn of `model` at 10 Hz with every laser returning in firings `0..firings` (each
/// point in the middle of its laser's step), laser
/// l at range 10 + l / 8 m (so lasers l and l + 32 differ), intensity 60.
fn frame_of(model: &SensorModel, firings: u32) -> Frame {
    let n = (1.0 / (10.0 * model.sequence_us * 1e-6)).round();
    let rings = model.rings();
    let mut points = Vec::new();
    for k in 0..firings {
        for (l, &ring) in rings.iter().enumerate() {
            // Mid-firing, laser l's own firing time and azimuth offset added: a point on
            // the block azimuth (a laser's lead cut off) would sit on a firing's edge,
            // where float noise decides which of two firings it is in.
            let az = (f64::from(k) + 0.5) * 360.0 / n
                + model.laser_offset_us(l) * 360.0 * 10.0 * 1e-6
                + model.azimuth_offset_deg.get(l).copied().unwrap_or(0.0);
            let el = model.elevation_deg[l];
            let r = 10.0 + l as f64 / 8.0;
            let (sa, ca) = az.to_radians().sin_cos();
            let (se, ce) = el.to_radians().sin_cos();
            points.push(CloudPoint {
                x: (r * ce * ca) as f32,
                y: (-r * ce * sa) as f32,
                z: (r * se) as f32,
                intensity: 60.0,
                ring: Some(u16::from(ring)),
                time: None,
            });
        }
    }
    let placed = to_returns(&points, model, &ReturnsOptions::default(), "test").unwrap();
    assert_eq!(
        placed.shared, 0,
        "{}: every point has a slot of its own",
        model.name
    );
    Frame {
        index: 0,
        partial: false,
        returns: placed.returns,
    }
}

fn chain(text: &str, lasers: usize) -> NoiseChain {
    NoiseChain::new(&config(text)).for_lasers(lasers).unwrap()
}

#[test]
fn the_slots_of_a_64_laser_frame_hold_each_laser_apart() {
    let f = frame_of(&HDL64E_S2, 40);
    let slots = Slots::of(&f.returns, 64);
    assert_eq!(slots.lasers(), 64);
    let mut seen = std::collections::HashSet::new();
    for (i, r) in f.returns.iter().enumerate() {
        let s = slots.slot_of(i);
        assert!(seen.insert(s), "return {i} shares slot {s}");
        let (firing, laser) = slots.split(s);
        assert_eq!(laser, r.laser);
        assert_eq!(slots.slot(firing, laser), s);
    }
    // The same frame on 32-lasers slots folds lasers 32-63 onto laser 31: the reason the
    // stride is the sensor's.
    let folded = Slots::of(&f.returns, 32);
    let distinct: std::collections::HashSet<_> =
        (0..f.returns.len()).map(|i| folded.slot_of(i)).collect();
    assert!(distinct.len() < f.returns.len());
}

#[test]
fn lasers_past_31_get_their_own_per_laser_values() {
    let f = frame_of(&HDL64E_S2, 30);
    let text = stage(
        "laser_diode",
        "sigma_power = 0.0\nsigma_range_m = 0.05\nsigma_elevation_deg = 0.0\nsigma_azimuth_deg = 0.0",
    );
    let noisy = chain(&text, 64).process(&f);
    // The range bias of each laser (every return of a laser has the same).
    let mut bias = [f64::NAN; 64];
    for (i, r) in f.returns.iter().enumerate() {
        let b = f64::from(noisy.range[i]) - f64::from(r.range);
        let l = usize::from(r.laser);
        if bias[l].is_nan() {
            bias[l] = b;
        }
        assert!((bias[l] - b).abs() < 1e-5, "laser {l}: {} vs {b}", bias[l]);
    }
    assert!(bias.iter().all(|b| !b.is_nan()));
    // Laser l + 32 is not laser l (an id taken modulo 32 would give it the same bias).
    let same = (0..32)
        .filter(|&l| (bias[l] - bias[l + 32]).abs() < 1e-6)
        .count();
    assert_eq!(same, 0, "{bias:?}");
    // The first 32 lasers' draws do not depend on how many the sensor has.
    let f32_ = frame_of(&HDL32E, 30);
    let noisy32 = chain(&text, 32).process(&f32_);
    for (i, r) in f32_.returns.iter().enumerate() {
        let b = f64::from(noisy32.range[i]) - f64::from(r.range);
        assert!(
            (b - bias[usize::from(r.laser)]).abs() < 1e-5,
            "laser {}",
            r.laser
        );
    }
}

#[test]
fn occluding_laser_40_of_an_hdl64e_drops_that_laser_only_and_is_counted_there() {
    let f = frame_of(&HDL64E_S2, 25);
    let noisy = chain(&stage("occlusion", "lasers = [40]"), 64).process(&f);
    let mut dropped = 0;
    for (i, r) in f.returns.iter().enumerate() {
        let occluded = noisy.fate[i] == Fate::Occluded;
        assert_eq!(occluded, r.laser == 40, "return {i} of laser {}", r.laser);
        dropped += usize::from(occluded);
    }
    assert_eq!(dropped, 25);
    let s = noisy.summary();
    assert_eq!(s.dropped_by_laser.occluded.len(), 64);
    assert_eq!(s.dropped_by_laser.occluded[40], 25);
}

#[test]
fn per_laser_options_that_do_not_fit_the_sensor_are_refused_naming_them() {
    let c = config(&stage("occlusion", "lasers = [3, 20]"));
    let e = NoiseChain::new(&c).for_lasers(VLP16.lasers).unwrap_err();
    assert!(
        e.contains("lasers names 20") && e.contains("16 lasers"),
        "{e}"
    );
    assert!(NoiseChain::new(&c).for_lasers(32).is_ok());
    let list = vec!["1.0"; 32].join(", ");
    let c = config(&stage("laser_diode", &format!("power_factors = [{list}]")));
    let e = NoiseChain::new(&c).for_lasers(64).unwrap_err();
    assert!(
        e.contains("power_factors has 32 entries") && e.contains("64"),
        "{e}"
    );
    assert!(NoiseChain::new(&c).for_lasers(32).is_ok());
    let c = config(&stage("lens_damage", "lasers = [70]"));
    assert!(NoiseChain::new(&c).for_lasers(64).is_err());
    assert!(NoiseChain::new(&c).for_lasers(128).is_ok());
}

#[test]
fn vacant_slots_of_a_vlp16_take_echoes_of_its_own_lasers_only() {
    // Fog proposes an echo in every empty slot: on a 16-laser sensor none may carry a
    // laser id the sensor does not have.
    let mut f = frame_of(&VLP16, 60);
    // Empty slots: drop every third return.
    let mut k = 0;
    f.returns.retain(|_| {
        k += 1;
        k % 3 != 0
    });
    let text =
        "seed = 3\n[detection]\nmin_power = 1e-9\n[[noise]]\ntype = \"fog\"\nvisibility_m = 30\n";
    let noisy = chain(text, 16).process(&f);
    let added: Vec<_> = (noisy.clean_len..noisy.len())
        .filter(|&i| noisy.fate[i] == Fate::Added)
        .collect();
    assert!(!added.is_empty(), "dense fog fills empty slots");
    assert!(added.iter().all(|&i| noisy.clean[i].laser < 16));
}

#[test]
fn a_kitti_scan_runs_as_an_hdl64e_and_misfit_options_write_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let scan = dir.path().join("000000.bin");
    std::fs::write(&scan, common::kitti_bytes(&frame_of(&HDL64E_S2, 200))).unwrap();
    let out = dir.path().join("out");
    let cfg = dir.path().join("occ.toml");
    std::fs::write(&cfg, stage("occlusion", "lasers = [40]")).unwrap();
    let run = |out: &std::path::Path, sensor: &[&str]| -> serde_json::Value {
        bin2()
            .args(["--quiet", "run"])
            .arg(&scan)
            .args(sensor)
            .arg("-c")
            .arg(&cfg)
            .arg("-o")
            .arg(out)
            .assert()
            .success();
        serde_json::from_slice(&std::fs::read(out.join("000000/summary.json")).unwrap()).unwrap()
    };
    // By default a KITTI scan is KITTI's HDL-64E (its unit's beams).
    let v = run(&dir.path().join("default"), &[]);
    assert_eq!(v["capture_summary"]["sensor"], "HDL-64E S2 (KITTI)");
    // The points lie on the default S2 beams: said, every laser is found.
    let v = run(&out, &["--sensor", "hdl64e"]);
    assert_eq!(v["capture_summary"]["sensor"], "HDL-64E S2");
    let occluded = &v["totals"]["noise"]["dropped_by_laser"]["occluded"];
    assert_eq!(occluded.as_array().unwrap().len(), 64);
    assert_eq!(occluded[40], 200);
    assert!(out.join("000000/frame_00000.bin").exists());
    // The same options on an HDL-32E (said): refused, naming the sensor, nothing written.
    let cfg = cfg.to_str().unwrap();
    refused_scan(
        &scan,
        &["--sensor", "hdl32e", "-c", cfg],
        "000000.bin: the HDL-32E (32 lasers): [[noise]] #1 (occlusion): lasers names 40",
    );
}
