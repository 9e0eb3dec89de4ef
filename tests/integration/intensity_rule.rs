//! Tests of the intensity rule (src/noise/mod.rs, "Intensity"): the intensity byte of a
//! return's own echo is the clean byte times the ratio of its final to its ideal power
//! (and any receiver `gain_error`), rounded once and clamped to the byte, in
//! reflectivity and raw captures alike; spurious echoes keep the intensity of their own
//! power; at zero strength nothing changes. Expected bytes are computed here from the
//! ideal-power formula P = kappa rho / R^2, not read from the code under test.

use crate::common;

use common::{run, stage};

use lidar_noise::frame::{Frame, Return, ReturnKind};
use lidar_noise::noise::{Fate, NoisyFrame};

/// kappa of the default power model, p_th z_ref^2 / rho_ref = 1e-3 * 100^2 / 0.1 (m^2).
const KAPPA: f64 = 100.0;

fn ret(laser: u8, range: f32, intensity: u8, firing: u32) -> Return {
    common::firing_return(laser, range, intensity, firing, 0.18, ReturnKind::Strongest)
}

/// A 10 Hz rotation: ranges 1..70 m, intensities 0..120 (some retro-reflectors, some
/// returns saturated at short range).
fn turn() -> Frame {
    common::rotation(0, 2000, |f, l| {
        let k = f * 32 + u32::from(l);
        let range = 1.0 + (k.wrapping_mul(2_654_435_761) % 6900) as f32 / 100.0;
        let intensity = (k.wrapping_mul(40_503) % 121) as u8;
        Some(ret(l, range, intensity, f))
    })
}

/// Ideal power of byte `i` at `r` m for a reflectivity (`full` = 100) or raw (255)
/// capture: kappa rho / R^2 with rho = i / full clamped to [0.005, 1], clamped at 1.
fn ideal(i: u8, r: f32, full: f64) -> f64 {
    let rho = (f64::from(i) / full).clamp(0.005, 1.0);
    (KAPPA * rho / f64::from(r).powi(2)).min(1.0)
}

/// round(v f) clamped to the byte, rounding halves up.
fn scaled(v: u8, f: f64) -> u8 {
    (f64::from(v) * f).round().clamp(0.0, 255.0) as u8
}

/// Checks the rule on every kept return of `out` and returns how many bytes changed.
fn check_rule(f: &Frame, out: &NoisyFrame, full: f64, gain: f64, what: &str) -> usize {
    let mut changed = 0;
    let mut kept = 0;
    for (i, r) in f.returns.iter().enumerate() {
        if out.fate[i] != Fate::Kept {
            continue;
        }
        kept += 1;
        let ratio = out.power[i] / ideal(r.intensity, r.range, full);
        let want = scaled(r.intensity, gain * ratio);
        let got = out.noisy_return(i).intensity;
        // Within one of the hand value (the ratio of two rounded powers may sit on the
        // other side of a half), and exactly it away from halves.
        let x = f64::from(r.intensity) * gain * ratio;
        let near_half = (x - x.floor() - 0.5).abs() < 1e-9;
        assert!(
            got == want || (near_half && got.abs_diff(want) <= 1),
            "{what}: return {i} (byte {}, {} m): {got} against {want}",
            r.intensity,
            r.range
        );
        changed += usize::from(got != r.intensity);
    }
    assert!(kept > 1000, "{what}: {kept} kept");
    changed
}

#[test]
fn rain_and_fog_lower_the_intensity_of_kept_returns_by_their_power_loss() {
    let f = turn();
    for cfg in [
        stage("rain", "rate_mm_h = 7.29"),
        stage("rain", "rate_mm_h = 25"),
        stage("fog", "visibility_m = 100"),
    ] {
        let out = run(&cfg, &f);
        let changed = check_rule(&f, &out, 100.0, 1.0, &cfg);
        assert!(changed > 0, "{cfg}: no intensity changed");
        // Attenuation only: no kept byte rises.
        for (i, r) in f.returns.iter().enumerate() {
            if out.fate[i] == Fate::Kept {
                assert!(out.noisy_return(i).intensity <= r.intensity, "{cfg}: {i}");
            }
        }
    }
}

#[test]
fn optical_and_sensor_losses_follow_the_same_rule_rounded_once() {
    let f = turn();
    let all: Vec<String> = (0..32).map(|l| l.to_string()).collect();
    for (cfg, gain) in [
        (
            stage(
                "occlusion",
                &format!("lasers = [{}]\ntransmission = 0.7", all.join(", ")),
            ),
            1.0,
        ),
        (
            stage(
                "lens_damage",
                "transmission = 0.8\nscatter_probability = 0",
            ),
            1.0,
        ),
        (
            stage("emitter", "power_factor = 0.9\ndrift_per_hour = 0.05"),
            1.0,
        ),
        (
            stage("laser_diode", "sigma_range_m = 0\nsigma_elevation_deg = 0\nsigma_azimuth_deg = 0"),
            1.0,
        ),
        // Receiver: per-laser gains scale power (so intensity), `gain_error` scales the
        // byte alone; with the emitter's 0.9 the byte is rounded once: 45 x 0.5 x 0.9 =
        // 20.25 gives 20, where rounding after each stage gave round(22.5) = 23, then
        // round(20.7) = 21.
        (
            "seed = 5\n[[noise]]\ntype = \"emitter\"\npower_factor = 0.9\n\
             [[noise]]\ntype = \"receiver\"\ngain_error = 0.5\nsigma_noise = 0\nrange_noise_m = 0\n"
                .to_string(),
            0.5,
        ),
    ] {
        let out = run(&cfg, &f);
        let changed = check_rule(&f, &out, 100.0, gain, &cfg);
        assert!(changed > 0, "{cfg}");
    }
    // The worked example above, on one return at 30 m.
    let one = Frame {
        index: 0,
        partial: false,
        returns: vec![ret(0, 30.0, 45, 0)],
    };
    let out = run(
        "seed = 5\n[[noise]]\ntype = \"emitter\"\npower_factor = 0.9\n\
         [[noise]]\ntype = \"receiver\"\ngain_error = 0.5\nsigma_gain = 0\nsigma_noise = 0\nrange_noise_m = 0\n",
        &one,
    );
    assert_eq!(out.survivors()[0].intensity, 20);
}

#[test]
fn raw_captures_scale_by_the_same_power_ratio() {
    let f = turn();
    let cfg =
        "seed = 5\n[sensor]\nintensity = \"raw\"\n[[noise]]\ntype = \"rain\"\nrate_mm_h = 7.29\n\
               [[noise]]\ntype = \"emitter\"\npower_factor = 0.8\n";
    let out = run(cfg, &f);
    let changed = check_rule(&f, &out, 255.0, 1.0, "raw");
    assert!(changed > 0);
}

/// A saturated ideal power (clamped at 1, returns of high reflectance within about
/// 10 m) still loses its byte by the stages' loss factor: the byte reports reflectance
/// and the clamp bounds the power model, not the sensor's linear reflectivity.
#[test]
fn saturated_returns_lose_intensity_by_the_loss_factor() {
    let f = Frame {
        index: 0,
        partial: false,
        returns: vec![ret(0, 2.0, 100, 0), ret(1, 3.0, 200, 0)],
    };
    assert_eq!(ideal(100, 2.0, 100.0), 1.0);
    let out = run(&stage("emitter", "power_factor = 0.5"), &f);
    let s = out.survivors();
    assert_eq!((s[0].intensity, s[1].intensity), (50, 100));
}

#[test]
fn spurious_echoes_keep_the_intensity_of_their_own_power() {
    // Spoofed points (attacker power 1 at the box) over returns at 20..60 m, with an
    // emitter loss that must not touch them.
    let mut v = Vec::new();
    for fi in 0..2000u32 {
        for l in 0..32u8 {
            v.push(ret(l, 20.0 + (fi % 40) as f32, 30, fi));
        }
    }
    let f = Frame {
        index: 0,
        partial: false,
        returns: v,
    };
    let cfg = "seed = 5\n[[noise]]\ntype = \"emitter\"\npower_factor = 0.5\n\
               [[noise]]\ntype = \"spoofing\"\nmax_points = 0\n";
    let out = run(cfg, &f);
    let mut seen = 0;
    for i in 0..out.len() {
        if !out.fate[i].is_spurious() {
            continue;
        }
        seen += 1;
        // intensity_of(1, R), as the default power model gives it.
        assert_eq!(
            out.noisy_return(i).intensity,
            common::echo_byte(1.0, out.range[i]),
            "{i}"
        );
    }
    assert!(seen > 50);
    check_rule(&f, &out, 100.0, 1.0, "spoofing + emitter");
}

#[test]
fn at_zero_strength_every_byte_is_unchanged() {
    let f = turn();
    let base = run("seed = 5\n", &f);
    let zero = "seed = 5\n\
        [[noise]]\ntype = \"rain\"\nrate_mm_h = 0\n\
        [[noise]]\ntype = \"lens_damage\"\ntransmission = 1\nscatter_probability = 0\n\
        [[noise]]\ntype = \"emitter\"\npower_factor = 1\n\
        [[noise]]\ntype = \"laser_diode\"\nsigma_power = 0\nsigma_range_m = 0\nsigma_elevation_deg = 0\nsigma_azimuth_deg = 0\n\
        [[noise]]\ntype = \"receiver\"\nsigma_gain = 0\nsigma_noise = 0\nrange_noise_m = 0\n";
    let out = run(zero, &f);
    assert_eq!(out.fate, base.fate);
    assert!(common::same_returns(&out.survivors(), &base.survivors()));
    assert!(
        out.moved.intensity.is_none(),
        "no intensity column at zero strength"
    );
}
