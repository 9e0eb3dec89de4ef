//! Tests of the sensor noise stages (p-diagram part 1) against the formulas of
//! pdiagram-models.md, computed here independently of the code under test.

use crate::common;

use common::{config, err, ply_payload, run, stage};

use assert_cmd::Command;
use lidar_noise::config::Config;
use lidar_noise::frame::{Frame, Return, ReturnKind};
use lidar_noise::noise::{Fate, NoiseChain, NoisyFrame};
use std::path::Path;

const C: f64 = 299_792_458.0;

/// A return of `laser` at `range` m, `azimuth` deg, firing `firing` (12 per packet),
/// time `time` s.
fn ret(laser: u8, range: f32, azimuth: f32, intensity: u8, firing: u32, time: f64) -> Return {
    common::beam_return(
        laser,
        range,
        azimuth,
        intensity,
        firing,
        time,
        ReturnKind::Strongest,
    )
}

/// A 10 Hz rotation: 2000 firings of 32 lasers, ranges 2..60 m, varied intensities.
fn turn(index: u32) -> Frame {
    common::rotation(index, 2000, |f, l| {
        let az = f as f32 * 0.18;
        let k = f * 32 + u32::from(l);
        let range = 2.0 + (k.wrapping_mul(2_654_435_761) % 5800) as f32 / 100.0;
        let t = 100.0 + f64::from(f) * 46.08e-6 + f64::from(l) * 1.152e-6;
        Some(ret(l, range, az, (k % 101) as u8, f, t))
    })
}

/// (clean, noisy) pairs of the surviving returns.
fn kept(f: &Frame, out: &NoisyFrame) -> Vec<(Return, Return)> {
    out.kept_indices()
        .into_iter()
        .zip(out.survivors())
        .map(|(i, o)| (f.returns[i as usize], o))
        .collect()
}

/// Every stage at zero magnitude.
const ZERO: &[(&str, &str)] = &[
    (
        "laser_diode",
        "sigma_power = 0\nsigma_range_m = 0\nsigma_elevation_deg = 0\nsigma_azimuth_deg = 0",
    ),
    ("mounting", "sigma_rot_deg = 0\nsigma_t_m = 0"),
    ("emitter", "power_factor = 1"),
    (
        "mechanics",
        "eccentricity_deg = 0\njitter_deg = 0\nwobble_deg = 0\nspin_rate_sigma = 0",
    ),
    (
        "receiver",
        "sigma_gain = 0\nsigma_noise = 0\nrange_noise_m = 0",
    ),
    ("motion", "vibration_deg = 0"),
    ("clock", "jitter_ps = 0\ndrift_ppm = 0"),
    ("ambient", "range_mm_per_c = 0"),
];

fn all_zero() -> String {
    let mut s = String::from("seed = 5\n");
    for (k, body) in ZERO {
        s.push_str(&format!("[[noise]]\ntype = \"{k}\"\n{body}\n"));
    }
    s
}

#[test]
fn a_1_ns_clock_bias_shifts_every_range_by_c_ns_over_2() {
    let f = turn(0);
    let out = run(
        &stage("clock", "bias_ns = 1\njitter_ps = 0\ndrift_ppm = 0"),
        &f,
    );
    let shift = C * 1e-9 / 2.0; // 0.149896 m
    assert!((shift - 0.1499).abs() < 1e-4);
    for (r, &rn) in f.returns.iter().zip(&out.range) {
        assert!(
            (f64::from(rn) - f64::from(r.range) - shift).abs() < 1e-5,
            "{rn} vs {}",
            r.range
        );
    }
}

#[test]
fn clock_jitter_spread_matches_its_sigma() {
    // 64,000 draws; (n-1) s^2 / sigma^2 is chi-square(n-1): its 99.9 % interval is
    // within +-2.1 % of n, so the sample SD lies within +-1.1 % of sigma; we allow 2 %
    // (f32 ranges add a negligible 1e-6 m).
    let f = turn(3);
    let out = run(&stage("clock", "jitter_ps = 70\ndrift_ppm = 0"), &f);
    let d: Vec<f64> = f
        .returns
        .iter()
        .zip(&out.range)
        .map(|(r, &rn)| f64::from(rn) - f64::from(r.range))
        .collect();
    let n = d.len() as f64;
    let mean = d.iter().sum::<f64>() / n;
    let sd = (d.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
    let sigma = C * 70e-12 / 2.0;
    assert!((sd / sigma - 1.0).abs() < 0.02, "sd {sd} sigma {sigma}");
    assert!(mean.abs() < 4.0 * sigma / n.sqrt(), "mean {mean}");
}

#[test]
fn clock_drift_scales_range_and_stretches_frame_time() {
    let f = turn(0);
    let out = run(
        &stage(
            "clock",
            "jitter_ps = 0\ndrift_ppm = 100\ntime_offset_us = 5",
        ),
        &f,
    );
    let t0 = f.returns[0].time;
    for (r, o) in kept(&f, &out) {
        assert!((f64::from(o.range) - f64::from(r.range) * 1.0001).abs() < 1e-5);
        assert!((o.time - (t0 + (r.time - t0) * 1.0001 + 5e-6)).abs() < 1e-9);
    }
}

#[test]
fn a_mounting_yaw_of_2_degrees_rotates_every_point_by_2_degrees_about_z() {
    let f = turn(0);
    let out = run(
        &stage("mounting", "yaw_deg = 2\nsigma_rot_deg = 0\nsigma_t_m = 0"),
        &f,
    );
    for (r, o) in kept(&f, &out) {
        let a0 = f64::from(r.y).atan2(f64::from(r.x));
        let a1 = f64::from(o.y).atan2(f64::from(o.x));
        let d = (a1 - a0).to_degrees().rem_euclid(360.0);
        assert!((d - 2.0).abs() < 1e-3, "turned by {d}");
        assert!((o.z - r.z).abs() < 1e-5);
        let h0 = f64::from(r.x).hypot(f64::from(r.y));
        let h1 = f64::from(o.x).hypot(f64::from(o.y));
        assert!((h0 - h1).abs() < 1e-4);
        // The sensor frame stays the reported one.
        assert_eq!(o.range, r.range);
        assert_eq!(o.azimuth, r.azimuth);
    }
}

#[test]
fn mounting_translation_and_per_seed_draws() {
    let f = turn(0);
    let out = run(
        &stage(
            "mounting",
            "x_m = 0.5\nz_m = -0.25\nsigma_rot_deg = 0\nsigma_t_m = 0",
        ),
        &f,
    );
    for (r, o) in kept(&f, &out).into_iter() {
        assert!((o.x - r.x - 0.5).abs() < 1e-5 && (o.z - r.z + 0.25).abs() < 1e-5);
    }
    // Drawn per seed: the same pose in every frame.
    let chain = NoiseChain::new(&config(&stage("mounting", "")));
    let (a, b) = (
        chain.process(&turn(0)).survivors(),
        chain.process(&turn(9)).survivors(),
    );
    assert!(common::same_returns(&a, &b));
    assert!(!common::same_returns(&a, &turn(0).returns));
}

#[test]
fn a_receiver_noise_floor_of_k_thresholds_drops_exactly_the_formula_s_returns() {
    let f = turn(0);
    let base = run("seed = 5\n", &f);
    for k in [0.5, 2.0, 10.0] {
        let out = run(
            &stage(
                "receiver",
                &format!("noise_floor = {k}\nsigma_gain = 0\nsigma_noise = 0\nrange_noise_m = 0"),
            ),
            &f,
        );
        let cut = 0.001 * (1.0 + k);
        let mut dropped = 0;
        for i in 0..f.returns.len() {
            let expect = if base.fate[i] != Fate::Kept || base.power[i] < cut {
                if base.fate[i] == Fate::Kept {
                    Fate::BelowPower
                } else {
                    base.fate[i]
                }
            } else {
                Fate::Kept
            };
            assert_eq!(out.fate[i], expect, "return {i}, power {}", base.power[i]);
            dropped += usize::from(expect == Fate::BelowPower);
        }
        assert!(dropped > 0);
    }
}

#[test]
fn receiver_gain_error_scales_intensity_and_range_noise_follows_snr() {
    let f = turn(0);
    let out = run(
        &stage(
            "receiver",
            "gain_error = 0.5\nsigma_gain = 0\nsigma_noise = 0\nrange_noise_m = 0",
        ),
        &f,
    );
    for (r, o) in kept(&f, &out).into_iter() {
        assert_eq!(o.intensity, (f64::from(r.intensity) * 0.5).round() as u8);
    }
    // Range noise: standardised by dR / sqrt(2 SNR), the changes have SD 1 (+-3 %).
    let base = run("seed = 5\n", &f);
    let out = run(
        &stage(
            "receiver",
            "sigma_gain = 0\nsigma_noise = 0\nrange_noise_m = 0.09",
        ),
        &f,
    );
    let z: Vec<f64> = (0..f.returns.len())
        .filter(|&i| out.fate[i] == Fate::Kept)
        .map(|i| {
            let s = 0.09 / (2.0 * base.power[i] / 0.001).sqrt();
            (f64::from(out.range[i]) - f64::from(f.returns[i].range)) / s
        })
        .collect();
    let n = z.len() as f64;
    let sd = (z.iter().map(|x| x * x).sum::<f64>() / n).sqrt();
    assert!(n > 10_000.0 && (sd - 1.0).abs() < 0.03, "sd {sd} over {n}");
}

#[test]
fn motion_displaces_a_return_by_v_times_its_time_offset() {
    let f = turn(0);
    let v = 13.9;
    let out = run(
        &stage("motion", &format!("speed_mps = {v}\nvibration_deg = 0")),
        &f,
    );
    let t0 = f.returns[0].time;
    for (r, o) in kept(&f, &out).into_iter() {
        let dt = r.time - t0;
        assert!(
            (f64::from(r.x - o.x) - v * dt).abs() < 1e-4,
            "dx {} vs {}",
            r.x - o.x,
            v * dt
        );
        assert_eq!((o.y, o.z), (r.y, r.z));
    }
    // t_ref = "middle": displacement relative to the middle of the frame.
    let out = run(
        &stage(
            "motion",
            &format!("speed_mps = {v}\nvibration_deg = 0\nt_ref = \"middle\""),
        ),
        &f,
    );
    let tm = 0.5 * (t0 + f.returns.last().unwrap().time);
    for (r, o) in kept(&f, &out).into_iter() {
        assert!((f64::from(r.x - o.x) - v * (r.time - tm)).abs() < 1e-4);
    }
}

#[test]
fn motion_yaw_rate_turns_points_by_omega_dt() {
    let f = turn(0);
    let out = run(
        &stage("motion", "yaw_rate_deg_s = 30\nvibration_deg = 0"),
        &f,
    );
    let t0 = f.returns[0].time;
    for (r, o) in kept(&f, &out).into_iter().step_by(97) {
        let fire_t = r.time - f64::from(r.laser) * 1.152e-6;
        let d = (f64::from(o.y).atan2(f64::from(o.x)) - f64::from(r.y).atan2(f64::from(r.x)))
            .to_degrees();
        let d = (d + 180.0).rem_euclid(360.0) - 180.0;
        assert!((d + 30.0 * (fire_t - t0)).abs() < 1e-3, "{d}");
    }
}

#[test]
fn laser_diode_given_values_act_per_laser() {
    let f = turn(0);
    let bias: Vec<String> = (0..32).map(|l| format!("{}", l as f64 * 0.001)).collect();
    let pf: Vec<String> = (0..32)
        .map(|l| if l == 3 { "0.5".into() } else { "1.0".into() })
        .collect();
    let body = format!(
        "sigma_elevation_deg = 0\nsigma_azimuth_deg = 0\nrange_bias_m = [{}]\npower_factors = [{}]",
        bias.join(", "),
        pf.join(", ")
    );
    let base = run("seed = 5\n", &f);
    let out = run(&stage("laser_diode", &body), &f);
    for (i, r) in f.returns.iter().enumerate() {
        let expect = f64::from(r.range) + f64::from(r.laser) * 0.001;
        assert!((f64::from(out.range[i]) - expect).abs() < 1e-5);
        let g = if r.laser == 3 { 0.5 } else { 1.0 };
        assert!((out.power[i] - g * base.power[i]).abs() <= 1e-12 * base.power[i].max(1.0));
    }
}

#[test]
fn laser_diode_draws_match_their_sigma_and_are_fixed_per_seed() {
    // The per-laser azimuth offsets are drawn once per seed: 32 values. Their SD over
    // 32 lasers has a chi-square(31) spread: the 99.9 % interval of s/sigma is
    // [0.58, 1.46]; we check within it at the fixed seed.
    let f = turn(0);
    let out = run(
        &stage(
            "laser_diode",
            "sigma_power = 0\nsigma_range_m = 0\nsigma_elevation_deg = 0\nsigma_azimuth_deg = 0.1",
        ),
        &f,
    );
    let da = out.moved.azimuth_deg.as_ref().expect("offsets");
    let mut per = [f32::NAN; 32];
    for (r, &d) in f.returns.iter().zip(da) {
        let l = r.laser as usize;
        assert!(per[l].is_nan() || per[l] == d, "one offset per laser");
        per[l] = d;
    }
    let sd = (per.iter().map(|&x| f64::from(x).powi(2)).sum::<f64>() / 32.0).sqrt();
    assert!((0.058..0.146).contains(&sd), "sd {sd}");
    let other = run(
        &stage(
            "laser_diode",
            "sigma_power = 0\nsigma_range_m = 0\nsigma_elevation_deg = 0\nsigma_azimuth_deg = 0.1",
        ),
        &turn(7),
    );
    assert_eq!(other.moved.azimuth_deg.as_ref().unwrap()[..32], da[..32]);
}

#[test]
fn emitter_scales_power_and_intensity_with_capture_hours() {
    let f = turn(0);
    let base = run("seed = 5\n", &f);
    let out = run(
        &stage("emitter", "power_factor = 0.8\ndrift_per_hour = 0.1"),
        &f,
    );
    for (i, r) in f.returns.iter().enumerate() {
        let g = 0.8 * (1.0 - 0.1 * r.time / 3600.0);
        if out.fate[i] == Fate::Kept {
            assert!((out.power[i] / base.power[i] - g).abs() < 1e-12);
        }
    }
    for (r, o) in kept(&f, &out).into_iter() {
        let g = 0.8 * (1.0 - 0.1 * r.time / 3600.0);
        assert_eq!(o.intensity, (f64::from(r.intensity) * g).round() as u8);
    }
}

#[test]
fn mechanics_offset_moves_azimuth_and_jitter_matches_sigma() {
    let f = turn(0);
    let out = run(&stage("mechanics", "azimuth_offset_deg = 1.5\neccentricity_deg = 0\njitter_deg = 0\nwobble_deg = 0\nspin_rate_sigma = 0"), &f);
    for (r, o) in kept(&f, &out).into_iter() {
        let d = (f64::from(o.azimuth) - f64::from(r.azimuth)).rem_euclid(360.0);
        assert!((d - 1.5).abs() < 1e-3);
        let turned = (f64::from(r.y).atan2(f64::from(r.x)) - f64::from(o.y).atan2(f64::from(o.x)))
            .to_degrees()
            .rem_euclid(360.0);
        assert!((turned - 1.5).abs() < 1e-3, "clockwise by {turned}");
    }
    // One jitter draw per firing: 2000 values; s/sigma within +-8 % (99.9 % chi-square
    // interval for 1999 degrees of freedom is +-5.2 %).
    let out = run(
        &stage(
            "mechanics",
            "eccentricity_deg = 0\njitter_deg = 0.005\nwobble_deg = 0\nspin_rate_sigma = 0",
        ),
        &f,
    );
    let da = out.moved.azimuth_deg.as_ref().unwrap();
    let firings: Vec<f64> = da
        .chunks(32)
        .map(|c| {
            assert!(c.iter().all(|&x| x == c[0]), "one draw per firing");
            f64::from(c[0])
        })
        .collect();
    let sd = (firings.iter().map(|x| x * x).sum::<f64>() / firings.len() as f64).sqrt();
    assert!((sd / 0.005 - 1.0).abs() < 0.08, "sd {sd}");
}

#[test]
fn ambient_sun_raises_the_threshold_and_temperature_offsets_range() {
    let f = turn(0);
    let base = run("seed = 5\n", &f);
    let out = run(
        &stage("ambient", "irradiance = 1\nk_sun = 2\nrange_mm_per_c = 0"),
        &f,
    );
    for i in 0..f.returns.len() {
        let keep = base.fate[i] == Fate::Kept && base.power[i] >= 0.003;
        assert_eq!(out.fate[i] == Fate::Kept, keep);
    }
    let out = run(
        &stage("ambient", "temperature_c = 45\nrange_mm_per_c = 0.5"),
        &f,
    );
    for (r, &rn) in f.returns.iter().zip(&out.range) {
        assert!((f64::from(rn) - f64::from(r.range) - 0.01).abs() < 1e-5);
    }
}

#[test]
fn every_stage_at_zero_magnitude_is_the_identity() {
    let f = turn(2);
    let base = run("seed = 5\n", &f);
    for (k, body) in ZERO {
        let out = run(&stage(k, body), &f);
        assert_eq!(out.fate, base.fate, "{k}");
        assert!(
            common::same_returns(&out.survivors(), &base.survivors()),
            "{k}"
        );
    }
    let out = run(&all_zero(), &f);
    assert!(common::same_returns(&out.survivors(), &base.survivors()));
}

#[test]
fn adding_a_stage_leaves_the_other_stages_draws_unchanged() {
    // Clock jitter alone and clock jitter after every other random stage: the clock's
    // range changes are the same (its stream is keyed by type, not position).
    let f = turn(4);
    let clock = "[[noise]]\ntype = \"clock\"\njitter_ps = 70\ndrift_ppm = 0\n";
    let alone = run(&format!("seed = 5\n{clock}"), &f);
    let others = "[[noise]]\ntype = \"mechanics\"\n[[noise]]\ntype = \"laser_diode\"\nsigma_range_m = 0\nsigma_power = 0\n[[noise]]\ntype = \"motion\"\n";
    let with = run(&format!("seed = 5\n{others}{clock}"), &f);
    for i in 0..f.returns.len() {
        assert_eq!(alone.range[i].to_bits(), with.range[i].to_bits());
    }
}

#[test]
fn sensor_chain_is_deterministic_and_thread_independent() {
    let text = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("configs/pdiagram-sensor.toml"),
    )
    .unwrap();
    let chain = NoiseChain::new(&config(&text));
    let frames: Vec<Frame> = (0..4).map(turn).collect();
    let one = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap()
        .install(|| chain.process_all(frames.clone()));
    let two = rayon::ThreadPoolBuilder::new()
        .num_threads(2)
        .build()
        .unwrap()
        .install(|| chain.process_all(frames.clone()));
    for (a, b) in one.iter().zip(&two) {
        assert_eq!(a.fate, b.fate);
        assert!(common::same_returns(&a.survivors(), &b.survivors()));
    }
    let again = NoiseChain::new(&config(&text)).process(&frames[0]);
    assert!(common::same_returns(
        &again.survivors(),
        &one[0].survivors()
    ));
}

#[test]
fn bad_options_name_key_and_line() {
    let cases = [
        ("clock", "jitter_ps = -1", "jitter_ps", "negative"),
        ("clock", "bias_ns = nan", "bias_ns", "nan"),
        ("mounting", "yaw_deg = 200", "yaw_deg", "outside"),
        ("mounting", "pitch_deg = 91", "pitch_deg", "outside"),
        ("receiver", "sigma_noise = -0.1", "sigma_noise", "negative"),
        (
            "laser_diode",
            "range_bias_m = [0.0, 0.1]",
            "range_bias_m",
            "32",
        ),
        ("mechanics", "jitter_deg = inf", "jitter_deg", "inf"),
        ("motion", "t_ref = \"end\"", "t_ref", ""),
        ("emitter", "power_factor = 1.5", "power_factor", "outside"),
        ("ambient", "temperature_c = 200", "temperature_c", "outside"),
        ("ambient", "sunlight = 1", "sunlight", "unknown"),
    ];
    for (kind, body, key, word) in cases {
        let e = err(&stage(kind, body));
        assert!(e.contains(&format!("noise[0].{key} (line 4")), "{e}");
        assert!(e.contains(word), "{e}");
    }
}

#[test]
fn zero_magnitude_chain_writes_the_same_ply_and_bad_options_write_nothing() {
    let tmp = tempfile::tempdir().unwrap();
    let ply = common::run_frame0(
        tmp.path(),
        &[&all_zero(), "seed = 5\n"],
        &["--keep-dropped"],
    );
    let a = ply_payload(&ply[0]);
    let b = ply_payload(&ply[1]);
    assert!(!a.is_empty());
    assert!(a == b, "PLY payloads differ");
    let msg = common::refused_run(tmp.path(), &stage("clock", "jitter_ps = -3"));
    assert!(msg.contains("noise[0].jitter_ps (line 4"), "{msg}");
}

#[test]
fn stages_lists_every_registered_type_with_its_options() {
    let o = Command::cargo_bin("lidar-noise")
        .unwrap()
        .arg("stages")
        .assert()
        .success();
    let text = String::from_utf8_lossy(&o.get_output().stdout).to_string();
    for k in lidar_noise::noise::REGISTRY {
        assert!(
            text.contains(&format!("{} (p-diagram", k.name)),
            "{}",
            k.name
        );
        for opt in k.options {
            assert!(text.contains(opt.name), "{}.{}", k.name, opt.name);
        }
    }
    let help = Command::cargo_bin("lidar-noise")
        .unwrap()
        .args(["stages", "--help"])
        .assert()
        .success();
    assert!(String::from_utf8_lossy(&help.get_output().stdout).contains("Examples:"));
}

#[test]
fn every_sensor_stage_is_sweepable_and_toggleable() {
    // The --vary shorthand and on/off resolve for every stage type.
    use lidar_noise::sweep::plan::Vary;
    for (k, key) in [
        ("clock", "bias_ns"),
        ("mounting", "yaw_deg"),
        ("receiver", "noise_floor"),
        ("laser_diode", "sigma_power"),
        ("emitter", "power_factor"),
        ("motion", "speed_mps"),
        ("mechanics", "jitter_deg"),
        ("ambient", "irradiance"),
    ] {
        assert!(Vary::parse(&format!("{k}.{key}=0,1")).is_ok(), "{k}.{key}");
        assert!(Vary::parse(&format!("{k}=on,off")).is_ok(), "{k}");
        let (c, _) =
            Config::from_toml_str("", Path::new("x"), &[format!("{k}.{key}=1")], None).unwrap();
        assert_eq!(c.noise[0].kind(), k);
    }
}
