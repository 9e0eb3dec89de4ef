//! Tests of the weather stages (p-diagram 11, part 2: fog, snow, rain backscatter) against
//! the formulas of pdiagram-models.md, computed here independently of the code under
//! test, and of how their echoes compete in the firing slots.

use crate::common;

use common::{config, err, run, stage};

use crate::common::ideal;
use lidar_noise::config::Config;
use lidar_noise::frame::{Frame, Return, ReturnKind};
use lidar_noise::noise::{Fate, NoiseChain, NoisyFrame, NO_CAUSE};
use std::path::Path;
use std::sync::Arc;

const C: f64 = 299_792_458.0;

/// A return of `laser` at `range` m in firing `firing` (0.2 deg per firing, 12 firings
/// per packet) with `intensity` (reflectivity, %).
fn ret(laser: u8, range: f32, intensity: u8, firing: u32, kind: ReturnKind) -> Return {
    common::firing_return(laser, range, intensity, firing, 0.2, kind)
}

/// 1800 firings of 32 lasers, ranges 2..60 m, varied intensities; every 7th slot is
/// empty (sky), so echoes are also added.
fn turn(index: u32) -> Frame {
    common::rotation(index, 1800, |f, l| {
        let k = f * 32 + u32::from(l);
        if k % 7 == 3 {
            return None;
        }
        let range = 2.0 + (k.wrapping_mul(2_654_435_761) % 5800) as f32 / 100.0;
        Some(ret(l, range, (k % 101) as u8, f, ReturnKind::Strongest))
    })
}

/// Independent reference for the fog echo: the paper's integral in its own variable t,
/// P_s(R) = pi kappa beta (c/2) int_0^{2 tau_H} s(t) exp(-2 alpha r) xi(r) / r^2 dt,
/// r = R - c t / 2, r <= R0, by composite Simpson on 4,000 intervals, maximised over R
/// by a 1 cm scan refined by a 0.5 mm scan. Returns (R at the maximum - c tau_H / 2,
/// maximum).
fn reference_echo(v: f64, r0: f64, r1: f64, r2: f64, tau_h: f64, kappa: f64) -> (f64, f64) {
    let alpha = -(0.05f64.ln()) / v;
    let beta = 0.046 / v;
    let xi = |r: f64| {
        if r <= r1 {
            0.0
        } else if r >= r2 {
            1.0
        } else {
            (r - r1) / (r2 - r1)
        }
    };
    let p = |big_r: f64| {
        let n = 4_000;
        let h = 2.0 * tau_h / f64::from(n);
        let g = |t: f64| {
            let r = big_r - C * t / 2.0;
            if r <= r1 || r > r0 {
                return 0.0;
            }
            (std::f64::consts::PI * t / (2.0 * tau_h)).sin().powi(2)
                * (-2.0 * alpha * r).exp()
                * xi(r)
                / (r * r)
        };
        let mut s = g(0.0) + g(2.0 * tau_h);
        for k in 1..n {
            s += g(f64::from(k) * h) * if k % 2 == 1 { 4.0 } else { 2.0 };
        }
        std::f64::consts::PI * kappa * beta * (C / 2.0) * s * h / 3.0
    };
    let scan = |from: f64, to: f64, step: f64, best: &mut (f64, f64)| {
        let mut big_r = from;
        while big_r <= to {
            let v = p(big_r);
            if v > best.1 {
                *best = (big_r, v);
            }
            big_r += step;
        }
    };
    let mut best = (0.0, 0.0);
    scan(r1, r0.min(30.0) + C * tau_h, 0.01, &mut best);
    let at = best.0;
    scan(at - 0.02, at + 0.02, 0.0005, &mut best);
    (best.0 - C * tau_h / 2.0, best.1)
}

/// The fog optics before issue 50: a pulse of 20 ns (Hahner's), 25 mm apertures and a
/// 5 mrad receiver field (the central estimates; the calibrated defaults are 4 ns, 20 mm
/// and 4.1 mrad), for tests of the noiseless echo (`[detection] model = "threshold"`).
const OLD_OPTICS: &str =
    "tau_h_ns = 20\ntx_aperture_mm = 25\nrx_aperture_mm = 25\nrx_fov_mrad = 5\n";

/// A chain's stages applied to a frame without resolving: the proposed echoes.
fn proposals(text: &str, returns: Vec<Return>) -> NoisyFrame {
    let chain = NoiseChain::new(&config(text));
    let p = ideal();
    let mut f = NoisyFrame::new(0, returns, &p);
    f.power_model = Some(Arc::new(p));
    let mut rng = lidar_noise::noise::stage_rng(5, 0, 0);
    for s in chain.stages() {
        s.apply(&mut f, &mut rng);
    }
    f
}

#[test]
fn fog_extinction_at_mor_is_minus_ln_005_over_mor() {
    for v in [50.0f64, 150.0, 600.0, 1000.0] {
        let alpha = lidar_noise::noise::world::fog::extinction_per_m(v);
        assert!((alpha - (-(0.05f64).ln() / v)).abs() < 1e-15 * alpha.max(1.0));
        // One-way transmission over V is the 5 % contrast that defines the MOR.
        assert!(((-alpha * v).exp() - 0.05).abs() < 1e-12);
    }
    // On a frame: the hard-target power falls by exp(-2 alpha R) (no echoes: beta_r 0).
    let f = turn(1);
    let base = run("seed = 5\n", &f);
    let out = run(&stage("fog", "visibility_m = 200\nbeta_r = 0"), &f);
    let alpha = 20f64.ln() / 200.0;
    for i in (0..f.returns.len()).step_by(97) {
        let want = base.power[i] * (-2.0 * alpha * f64::from(f.returns[i].range)).exp();
        assert!((out.power[i] / want - 1.0).abs() < 1e-12, "{i}");
    }
}

#[test]
fn fog_echo_power_follows_the_paper_integral_within_1_percent() {
    let kappa = ideal().constants().kappa_m2;
    for (v, r0, r1, r2, tau) in [
        (100.0, 60.0, 0.9, 1.0, 20.0),
        (50.0, 30.0, 0.9, 1.0, 20.0),
        (600.0, 80.0, 0.9, 1.0, 20.0),
        (150.0, 3.3, 0.9, 1.0, 20.0),
        (150.0, 40.0, 1.5, 5.0, 20.0),
        (300.0, 25.0, 0.9, 2.0, 10.0),
    ] {
        let body = format!(
            "visibility_m = {v}\noverlap = \"linear\"\noverlap_start_m = {r1}\noverlap_full_m = {r2}\ntau_h_ns = {tau}\nempty_slots = false"
        );
        // A dark target, far: the echo is proposed in its slot.
        let f = proposals(
            &stage("fog", &body),
            vec![ret(0, r0 as f32, 0, 0, ReturnKind::Strongest)],
        );
        assert_eq!(f.proposals().len(), 1, "V {v} R0 {r0}");
        let echo = f.proposals()[0].echo;
        let (want_r, want_p) = reference_echo(v, r0, r1, r2, tau * 1e-9, kappa);
        assert!(
            (echo.power / want_p - 1.0).abs() < 0.01,
            "V {v} R0 {r0}: {} vs {want_p}",
            echo.power
        );
        assert!(
            (f64::from(echo.range) - want_r).abs() < 0.02,
            "{} vs {want_r}",
            echo.range
        );
    }
    // The echo power is proportional to beta = beta_r / V.
    // The optics before issue 50 (pulse of 20 ns, 25 mm apertures, a 5 mrad field),
    // whose noiseless peak reaches the threshold at 100 m (the calibrated ones never do:
    // their echoes are the receiver's noise's, tests/integration/fog_calibration.rs).
    let one = proposals(
        &stage("fog", &format!("visibility_m = 100\n{OLD_OPTICS}")),
        vec![ret(0, 50.0, 0, 0, ReturnKind::Strongest)],
    );
    let three = proposals(
        &stage(
            "fog",
            &format!("visibility_m = 100\nbeta_r = 0.138\n{OLD_OPTICS}"),
        ),
        vec![ret(0, 50.0, 0, 0, ReturnKind::Strongest)],
    );
    assert!((three.proposals()[0].echo.power / one.proposals()[0].echo.power - 3.0).abs() < 1e-12);
}

#[test]
fn strongest_return_keeps_a_strong_near_target_and_replaces_a_weak_far_one() {
    // Hahner's overlap (linear, 0.9..1.0 m), V = 300 m: the fog echo (about 0.03 of
    // emitted power at 1.6 m) beats a 10 % target at 25 m (0.016 x exp(-2 alpha 25) =
    // 0.0097, detectable without fog echo) but not a 100 % target at 8 m.
    let weak = ret(3, 25.0, 10, 0, ReturnKind::Strongest);
    let strong = ret(4, 8.0, 100, 0, ReturnKind::Strongest);
    let f = Frame {
        index: 0,
        partial: false,
        returns: vec![weak, strong],
    };
    let body = "visibility_m = 300\nempty_slots = false\noverlap = \"linear\"";
    let out = run(&stage("fog", body), &f);
    assert_eq!(out.fate, vec![Fate::Replaced, Fate::Kept]);
    assert_eq!(out.cause, vec![0, NO_CAUSE]);
    // The replaced return reports the echo's range; its clean range is the target's.
    assert!(out.range[0] > 1.3 && out.range[0] < 1.9, "{}", out.range[0]);
    assert_eq!(out.clean[0].range, 25.0);
    let alpha = 20f64.ln() / 300.0;
    let p_h = 0.001 * (0.1 / 0.1) * (100.0f64 / 25.0).powi(2) * (-2.0 * alpha * 25.0).exp();
    assert!(out.power[0] > p_h, "echo {} vs target {p_h}", out.power[0]);
    // Without the echo the weak target was detectable: the fog echo hid it.
    let no_echo = run(&stage("fog", "visibility_m = 300\nbeta_r = 0"), &f);
    assert_eq!(no_echo.fate, vec![Fate::Kept, Fate::Kept]);
    assert!((no_echo.power[0] / p_h - 1.0).abs() < 1e-12);
    // Last-return mode reports the farthest echo: the target stays.
    let last: Vec<Return> = f
        .returns
        .iter()
        .map(|r| Return {
            kind: ReturnKind::Last,
            ..*r
        })
        .collect();
    let out = run(
        &stage("fog", body),
        &Frame {
            index: 0,
            partial: false,
            returns: last,
        },
    );
    assert_eq!(out.fate, vec![Fate::Kept, Fate::Kept]);
}

#[test]
fn fog_fills_empty_slots_and_occluded_beams_get_no_echo() {
    // The threshold detection (noiseless): the echo is detectable in every free slot.
    // Under the receiver's noise it is a chance per beam (tests/integration/fog_calibration.rs).
    // With the optics before issue 50 (`OLD_OPTICS`) the noiseless peak is detectable.
    let threshold = "[detection]\nmodel = \"threshold\"\n";
    let fog = format!("visibility_m = 100\n{OLD_OPTICS}");
    let f = turn(3);
    let out = run(&format!("{}{threshold}", stage("fog", &fog)), &f);
    let added = out.fate.iter().filter(|x| **x == Fate::Added).count();
    // Every 7th slot of 1800 x 32 is empty.
    let empty = (0..1800 * 32u32).filter(|k| k % 7 == 3).count();
    assert_eq!(added, empty);
    assert_eq!(out.len(), f.returns.len() + added);
    let off = run(
        &format!(
            "{}{threshold}",
            stage("fog", &format!("{fog}empty_slots = false"))
        ),
        &f,
    );
    assert_eq!(off.len(), f.returns.len());
    // Occlusion removes the beams of laser 5: none of its slots reports fog.
    let occ = run(
        &format!("seed = 5\n[[noise]]\ntype = \"occlusion\"\nlasers = [5]\n[[noise]]\ntype = \"fog\"\n{fog}{threshold}"),
        &f,
    );
    for i in 0..occ.len() {
        if occ.clean[i].laser == 5 {
            assert!(!occ.fate[i].is_spurious(), "{i}");
        }
    }
}

#[test]
fn zero_weather_is_the_identity() {
    let f = turn(2);
    let base = run(
        "seed = 5\n[[noise]]\ntype = \"rain\"\nmodel = \"goodin\"\nrate_mm_h = 7\n",
        &f,
    );
    for extra in [
        "[[noise]]\ntype = \"fog\"\nvisibility_m = inf\n",
        "[[noise]]\ntype = \"snow\"\nrate_mm_h = 0\n",
        "[[noise]]\ntype = \"fog\"\nvisibility_m = 100\nbeta_r = 0\n",
    ] {
        let text = format!(
            "seed = 5\n[[noise]]\ntype = \"rain\"\nmodel = \"goodin\"\nrate_mm_h = 7\n{extra}"
        );
        let out = run(&text, &f);
        assert!(
            !NoiseChain::new(&config(&text)).proposes_echoes(),
            "{extra}"
        );
        if extra.contains("inf") || extra.contains("rate_mm_h = 0") {
            assert_eq!(out.fate, base.fate, "{extra}");
            assert_eq!(out.power, base.power, "{extra}");
            assert!(
                common::same_returns(&out.survivors(), &base.survivors()),
                "{extra}"
            );
        }
    }
    // backscatter = false written out is the default.
    let off = run(
        "seed = 5\n[[noise]]\ntype = \"rain\"\nmodel = \"goodin\"\nrate_mm_h = 7\nbackscatter = false\n",
        &f,
    );
    assert!(common::same_returns(&off.survivors(), &base.survivors()));
}

#[test]
fn zero_weather_writes_the_same_ply() {
    let tmp = tempfile::tempdir().unwrap();
    let rain = "seed = 5\n[[noise]]\ntype = \"rain\"\nmodel = \"goodin\"\nrate_mm_h = 7\n";
    let weather = format!(
        "{rain}[[noise]]\ntype = \"fog\"\nvisibility_m = inf\n[[noise]]\ntype = \"snow\"\nrate_mm_h = 0.0\n"
    );
    let ply = common::run_frame0(tmp.path(), &[rain, &weather], &["--keep-dropped"]);
    let payload = |i: usize| common::ply_payload(&ply[i]);
    let (pa, pb) = (payload(0), payload(1));
    assert!(!pa.is_empty());
    assert!(pa == pb, "PLY payloads differ");
}

#[test]
fn rain_backscatter_adds_near_drop_echoes_and_keeps_the_rain_draws() {
    let f = turn(4);
    let base = run(&stage("rain", "model = \"goodin\"\nrate_mm_h = 7"), &f);
    let bs = run(
        &stage(
            "rain",
            "model = \"goodin\"\nrate_mm_h = 7\nbackscatter = true",
        ),
        &f,
    );
    let mut spurious = 0;
    for i in 0..bs.len() {
        if bs.fate[i].is_spurious() {
            spurious += 1;
            // Drop echoes are a short-range effect: LISA's 1.5 m floor, and no drop beyond
            // the cut can be detected (a few metres).
            assert!(bs.range[i] >= 1.5 && bs.range[i] < 15.0, "{}", bs.range[i]);
            assert_eq!(bs.cause[i], 0);
        } else if i < f.returns.len() {
            // Common random numbers: the range noise of every other return is unchanged.
            assert_eq!(bs.range[i].to_bits(), base.range[i].to_bits(), "{i}");
            assert_eq!(bs.fate[i], base.fate[i]);
        }
    }
    assert!(spurious > 0);
    // More rain, more drop echoes (same seed).
    let heavy = run(
        &stage(
            "rain",
            "model = \"goodin\"\nrate_mm_h = 30\nbackscatter = true",
        ),
        &f,
    );
    let heavy_n = heavy.fate.iter().filter(|x| x.is_spurious()).count();
    assert!(heavy_n > spurious, "{heavy_n} vs {spurious}");
}

#[test]
fn snow_attenuates_by_its_extinction_and_flake_echoes_grow_with_the_rate() {
    let f = turn(5);
    let base = run("seed = 5\n", &f);
    // Gunn-Marshall: alpha = int (pi/4) D^2 2 N0 exp(-Lambda D) dD = pi N0 / Lambda^3 (mm -> m).
    let rate = 2.0f64;
    let (n0, lam) = (7.6e3 * rate.powf(-0.87), 2.55 * rate.powf(-0.48));
    let alpha = std::f64::consts::PI * n0 / lam.powi(3) * 1e-6;
    let out = run(&stage("snow", "rate_mm_h = 2.0\nempty_slots = false"), &f);
    for i in (0..f.returns.len()).step_by(89) {
        if out.fate[i] == Fate::Kept {
            let want = base.power[i] * (-2.0 * alpha * f64::from(f.returns[i].range)).exp();
            assert!((out.power[i] / want - 1.0).abs() < 1e-9, "{i}");
        }
    }
    let count = |rate: f64| {
        let o = run(&stage("snow", &format!("rate_mm_h = {rate}")), &f);
        o.fate.iter().filter(|x| x.is_spurious()).count()
    };
    // Through the HDL-32E's exit aperture and field of view flake echoes are rare at low
    // rates: moderate and heavy water-equivalent rates.
    let (light, heavy) = (count(5.0), count(30.0));
    assert!(light > 0 && heavy > light, "{light} {heavy}");
}

#[test]
fn weather_chain_is_deterministic_and_thread_independent() {
    let text = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("configs/adverse-weather.toml"),
    )
    .unwrap();
    let chain = NoiseChain::new(&config(&text));
    assert!(chain.proposes_echoes());
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
        assert_eq!(a.cause, b.cause);
        assert!(common::same_returns(&a.survivors(), &b.survivors()));
    }
    let again = NoiseChain::new(&config(&text)).process(&frames[0]);
    assert!(common::same_returns(
        &again.survivors(),
        &one[0].survivors()
    ));
    // Another seed gives other flake and drop echoes.
    let other =
        NoiseChain::new(&config(&text.replace("seed = 42", "seed = 43"))).process(&frames[0]);
    assert_ne!(other.fate, one[0].fate);
}

#[test]
fn bad_weather_options_name_key_and_line() {
    let cases = [
        ("fog", "visibility_m = -5", "visibility_m", "outside"),
        ("fog", "visibility_m = 100\nbeta_r = nan", "beta_r", "nan"),
        (
            "fog",
            "visibility_m = 100\nrx_fov_mrad = 4\noverlap = \"linear\"",
            "rx_fov_mrad",
            "not an option of overlap = \"linear\"",
        ),
        (
            "fog",
            "visibility_m = 100\noverlap_full_m = 2",
            "overlap_full_m",
            "not an option of overlap = \"biaxial\"",
        ),
        ("fog", "visibility_m = 100\ngain = 1", "gain", "unknown"),
        (
            "fog",
            "visibility_m = 100\noverlap = \"linear\"\noverlap_start_m = 2.0\noverlap_full_m = 1.0",
            "overlap_full_m",
            "below",
        ),
        (
            "fog",
            "visibility_m = 100\nempty_slots = 1",
            "empty_slots",
            "true or false",
        ),
        ("fog", "visibility_m = \"thick\"", "visibility_m", "number"),
        ("snow", "rate_mm_h = -1", "rate_mm_h", "outside"),
        (
            "snow",
            "rate_mm_h = 1\ndivergence_mrad = 0",
            "divergence_mrad",
            "outside",
        ),
        (
            "rain",
            "rate_mm_h = 1\ndivergence_mrad = 2",
            "divergence_mrad",
            "backscatter",
        ),
        (
            "rain",
            "rate_mm_h = 1\nbackscatter = \"yes\"",
            "backscatter",
            "true or false",
        ),
    ];
    for (kind, body, key, word) in cases {
        let e = err(&stage(kind, body));
        let line = 4 + body.lines().position(|l| l.starts_with(key)).unwrap();
        assert!(e.contains(&format!("noise[0].{key} (line {line}")), "{e}");
        assert!(e.contains(word), "{e}");
    }
    assert!(err(&stage("fog", "")).contains("visibility_m"));
    assert!(err(&stage("snow", "")).contains("rate_mm_h"));
}

#[test]
fn weather_stages_are_sweepable_and_toggleable() {
    use lidar_noise::sweep::plan::Vary;
    for (k, key) in [
        ("fog", "visibility_m"),
        ("snow", "rate_mm_h"),
        ("fog", "beta_r"),
    ] {
        assert!(
            Vary::parse(&format!("{k}.{key}=50,100")).is_ok(),
            "{k}.{key}"
        );
        assert!(Vary::parse(&format!("{k}=on,off")).is_ok(), "{k}");
    }
    let (c, _) = Config::from_toml_str(
        "",
        Path::new("x"),
        &["fog.visibility_m=80".to_string()],
        None,
    )
    .unwrap();
    assert_eq!(c.noise[0].kind(), "fog");
}

#[test]
fn dual_mode_reports_the_fog_echo_and_the_target() {
    // A dual slot holding one target (both entries, as the sensor reports a single echo
    // twice): a stronger fog echo becomes the strongest return, the target stays the last.
    let mut last = ret(3, 25.0, 10, 0, ReturnKind::DualLast);
    let mut strongest = last;
    strongest.kind = ReturnKind::DualStrongest;
    last.block = 0;
    strongest.block = 1;
    let f = Frame {
        index: 0,
        partial: false,
        returns: vec![last, strongest],
    };
    let out = run(
        &stage(
            "fog",
            "visibility_m = 300\nempty_slots = false\noverlap = \"linear\"",
        ),
        &f,
    );
    assert_eq!(out.fate, vec![Fate::Kept, Fate::Replaced]);
    assert_eq!(out.range[0], 25.0);
    assert!(out.range[1] < 2.0, "{}", out.range[1]);
}

#[test]
fn fog_range_noise_follows_hahner_v1() {
    // Echo range x R0 / U(R0 - n, R0 + n): within the bounds, both sides, mean near
    // E[R0 / U] (about 1 for n << R0).
    let r0 = 40.0f64;
    let n = 5.0f64;
    let returns: Vec<Return> = (0..3000u32)
        .map(|k| ret((k % 32) as u8, r0 as f32, 0, k / 32, ReturnKind::Strongest))
        .collect();
    // The optics before issue 50, whose noiseless peak is detectable at 100 m.
    let plain = proposals(
        &stage(
            "fog",
            &format!("visibility_m = 100\nempty_slots = false\n{OLD_OPTICS}"),
        ),
        returns.clone(),
    );
    let noisy = proposals(
        &stage(
            "fog",
            &format!("visibility_m = 100\nempty_slots = false\nrange_noise_m = {n}\n{OLD_OPTICS}"),
        ),
        returns,
    );
    let base = f64::from(plain.proposals()[0].echo.range);
    assert!(plain
        .proposals()
        .iter()
        .all(|c| f64::from(c.echo.range) == base));
    let (lo, hi) = (base * r0 / (r0 + n), base * r0 / (r0 - n));
    let mut below = 0;
    let mut sum = 0.0;
    for c in &noisy.proposals() {
        let r = f64::from(c.echo.range);
        assert!(r >= lo - 1e-5 && r <= hi + 1e-5, "{r} not in [{lo}, {hi}]");
        below += usize::from(r < base);
        sum += r / base;
    }
    let m = noisy.proposals().len();
    assert_eq!(m, 3000);
    // E[R0/U] for U uniform on [R0 - n, R0 + n] = R0 / (2 n) ln((R0 + n)/(R0 - n)).
    let want = r0 / (2.0 * n) * ((r0 + n) / (r0 - n)).ln();
    assert!(
        (sum / m as f64 - want).abs() < 0.003,
        "{} vs {want}",
        sum / m as f64
    );
    assert!(below > 1300 && below < 1700, "{below}");
}
