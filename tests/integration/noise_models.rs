//! Tests of the noise chain against the formulas of docs/noise-models.md, computed here
//! independently of the code under test.

use crate::common;

use lidar_noise::config::Config;
use lidar_noise::frame::{Frame, Return, ReturnKind};
use lidar_noise::noise::{Fate, NoiseChain, NoisyFrame};
use std::path::Path;

/// A return of `laser` at `range` metres and `azimuth` degrees with the built-in table.
fn ret(laser: u8, range: f32, azimuth: f32, intensity: u8) -> Return {
    // Firing 0 at time 0: packet 0, block 0.
    common::beam_return(
        laser,
        range,
        azimuth,
        intensity,
        0,
        0.0,
        ReturnKind::Strongest,
    )
}

fn frame(index: u32, returns: Vec<Return>) -> Frame {
    Frame {
        index,
        partial: false,
        returns,
    }
}

/// The configuration of `text` with the reference study's deterministic detection
/// threshold (as configs/paper.toml has it), which the models tested here are stated
/// against, unless `text` says how to detect.
fn config(text: &str) -> Config {
    let text = if text.contains("[detection]") {
        text.to_string()
    } else {
        format!("{text}\n[detection]\nmodel = \"threshold\"\n")
    };
    Config::from_toml_str(&text, Path::new("test.toml"), &[], None)
        .unwrap_or_else(|e| panic!("config should load: {e}"))
        .0
}

fn run(text: &str, f: &Frame) -> NoisyFrame {
    NoiseChain::new(&config(text)).process(f)
}

fn rain_cfg(rate: f64, noise: &str, seed: u64) -> String {
    format!("seed = {seed}\n[[noise]]\ntype = \"rain\"\nmodel = \"goodin\"\nrate_mm_h = {rate}\nrange_noise = \"{noise}\"\n")
}

/// Every laser at every 10 degrees of azimuth, 10 m, intensity 50.
fn full_turn() -> Frame {
    let mut v = Vec::new();
    for az in (0..36).map(|i| i as f32 * 10.0) {
        for laser in 0..32u8 {
            v.push(ret(laser, 10.0, az, 50));
        }
    }
    frame(0, v)
}

#[test]
fn extinction_attenuates_power_by_two_way_beer_lambert() {
    // alpha = 0.01 R^0.6, written out by hand for the four rates.
    let cases = [
        (1.0, 0.01),
        (2.5, 0.017_328_621),
        (7.0, 0.032_140_958),
        (25.0, 0.068_986_483),
    ];
    let f = frame(0, vec![ret(0, 50.0, 0.0, 100), ret(0, 10.0, 0.0, 100)]);
    let clear = run("", &f);
    for (rate, alpha_hand) in cases {
        let alpha_formula = 0.01 * f64::powf(rate, 0.6);
        assert!((alpha_formula - alpha_hand).abs() < 1e-8, "rate {rate}");
        let wet = run(&rain_cfg(rate, "goodin", 1), &f);
        for (i, range) in [50.0, 10.0].into_iter().enumerate() {
            let ratio = wet.power[i] / clear.power[i];
            let expect = (-2.0 * alpha_hand * range).exp();
            assert!(
                (ratio / expect - 1.0).abs() < 1e-6,
                "rate {rate} range {range}: ratio {ratio} expected {expect}"
            );
        }
    }
    // At 7 mm/h and 50 m: exp(-3.2141) = 0.04019.
    let wet = run(&rain_cfg(7.0, "goodin", 1), &f);
    assert!((wet.power[0] / clear.power[0] - 0.040_191_66).abs() < 1e-6);
}

#[test]
fn sigma_follows_eq9_at_10_and_50_m() {
    use lidar_noise::noise::rain::range_sigma_m;
    // sigma = 0.02 R (1 - exp(-7))^2 = 0.19964 m at 10 m, 0.99818 m at 50 m.
    assert!((range_sigma_m(10.0, 7.0) - 0.199_635_41).abs() < 1e-7);
    assert!((range_sigma_m(50.0, 7.0) - 0.998_177_07).abs() < 1e-7);
    assert!((range_sigma_m(50.0, 3.0) - 0.902_904_62).abs() < 1e-7);
}

/// Sample mean and standard deviation of range changes of kept returns.
fn change_stats(out: &NoisyFrame) -> (f64, f64, f64, usize) {
    let d: Vec<f64> = (0..out.len())
        .filter(|&i| out.fate[i] == Fate::Kept)
        .map(|i| f64::from(out.range[i]) - f64::from(out.clean[i].range))
        .collect();
    let n = d.len() as f64;
    let mean = d.iter().sum::<f64>() / n;
    let var = d.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0);
    let max_abs = d.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    (mean, var.sqrt(), max_abs, d.len())
}

#[test]
fn goodin_range_noise_has_the_eq9_spread() {
    let n = 100_000;
    for range in [20.0f32, 50.0] {
        let f = frame(
            3,
            (0..n)
                .map(|i| ret((i % 32) as u8, range, 0.0, 100))
                .collect(),
        );
        let out = run(&rain_cfg(7.0, "goodin", 42), &f);
        let (mean, std, _, kept) = change_stats(&out);
        assert_eq!(kept, n, "all returns at {range} m are detectable");
        let sigma = 0.02 * f64::from(range) * (1.0 - (-7.0f64).exp()).powi(2);
        assert!(
            (std / sigma - 1.0).abs() < 0.02,
            "range {range}: std {std} sigma {sigma}"
        );
        assert!(
            mean.abs() < 4.0 * sigma / (n as f64).sqrt(),
            "range {range}: mean {mean}"
        );
    }
}

#[test]
fn mavs_range_noise_is_uniform_within_1_5_cm() {
    let n = 100_000;
    let f = frame(
        0,
        (0..n)
            .map(|i| ret((i % 32) as u8, 20.0, 0.0, 100))
            .collect(),
    );
    let out = run(&rain_cfg(7.0, "mavs", 42), &f);
    let (mean, std, max_abs, kept) = change_stats(&out);
    assert_eq!(kept, n);
    // f32 storage of a 20 m range rounds to about 1e-6 m.
    assert!(max_abs <= 0.015 + 2e-6, "max {max_abs}");
    assert!(
        max_abs > 0.0149,
        "the jitter uses its full width: max {max_abs}"
    );
    let uniform_std = 0.015 / 3f64.sqrt();
    assert!((std / uniform_std - 1.0).abs() < 0.02, "std {std}");
    assert!(mean.abs() < 4.0 * uniform_std / (n as f64).sqrt());
    // p95 of |change| of a uniform +-1.5 cm is 0.95 * 1.5 cm; the summary's 0.1 mm bins
    // hold it to within one bin of the sample value.
    let mut abs: Vec<f64> = (0..out.len())
        .map(|i| (f64::from(out.range[i]) - f64::from(out.clean[i].range)).abs())
        .collect();
    abs.sort_by(f64::total_cmp);
    let p95 = abs[(0.95 * n as f64).ceil() as usize - 1];
    assert!((p95 - 0.01425).abs() < 2e-4, "sample p95 {p95}");
    let got = out.summary().range_change.p95_abs_m();
    assert!(
        got >= p95 - 1e-9 && got <= p95 + 1e-4 + 1e-9,
        "{got} vs {p95}"
    );
}

#[test]
fn rain_never_drops_at_random() {
    // Close, bright returns keep far more than the threshold even after attenuation:
    // nothing may be lost.
    let f = frame(
        0,
        (0..5000)
            .map(|i| ret((i % 32) as u8, 5.0, 0.0, 100))
            .collect(),
    );
    let out = run(&rain_cfg(25.0, "goodin", 9), &f);
    assert!(out.fate.iter().all(|&f| f == Fate::Kept));
}

/// The set of laser ids that occlusion `selection` removes from the full turn.
fn occluded(out: &NoisyFrame) -> Vec<(u8, u32)> {
    (0..out.len())
        .filter(|&i| out.fate[i] == Fate::Occluded)
        .map(|i| (out.clean[i].laser, out.clean[i].azimuth as u32))
        .collect()
}

fn occ_cfg(body: &str) -> String {
    format!("[[noise]]\ntype = \"occlusion\"\n{body}\n")
}

#[test]
fn occlusion_by_laser_removes_exactly_those_lasers() {
    let f = full_turn();
    let out = run(&occ_cfg("lasers = [7, 5, 3, 1, 30]"), &f);
    let set = [7u8, 5, 3, 1, 30];
    for i in 0..out.len() {
        let r = &out.clean[i];
        let expect = if set.contains(&r.laser) {
            Fate::Occluded
        } else {
            Fate::Kept
        };
        assert_eq!(out.fate[i], expect, "laser {} az {}", r.laser, r.azimuth);
        // Untouched power and range even when occluded.
        assert_eq!(out.range[i], r.range);
    }
    assert_eq!(occluded(&out).len(), 5 * 36);
    let s = out.summary();
    assert_eq!(s.dropped.occluded, 180);
    assert_eq!(s.returns_out as usize, out.len() - 180);
    for l in 0..32 {
        let want = if set.contains(&(l as u8)) { 36 } else { 0 };
        assert_eq!(s.dropped_by_laser.occluded[l], want, "laser {l}");
    }
    assert_eq!(out.survivors().len(), out.len() - 180);
}

#[test]
fn occlusion_sector_limits_the_azimuths_and_may_wrap() {
    let f = full_turn();
    for (sector, inside) in [
        (
            [90.0, 180.0],
            (|a: u32| (90..180).contains(&a)) as fn(u32) -> bool,
        ),
        ([300.0, 60.0], |a: u32| !(60..300).contains(&a)),
    ] {
        let out = run(
            &occ_cfg(&format!(
                "lasers = [7, 5]\nazimuth_deg = [{}, {}]",
                sector[0], sector[1]
            )),
            &f,
        );
        let mut want: Vec<(u8, u32)> = Vec::new();
        for r in &f.returns {
            if (r.laser == 7 || r.laser == 5) && inside(r.azimuth as u32) {
                want.push((r.laser, r.azimuth as u32));
            }
        }
        assert!(!want.is_empty());
        assert_eq!(occluded(&out), want, "sector {sector:?}");
    }
}

#[test]
fn rings_and_elevations_select_the_right_lasers() {
    let f = full_turn();
    let by_laser = occluded(&run(&occ_cfg("lasers = [7, 5, 3, 1, 30]"), &f));
    // The doc: those ids are rings 15..19 and elevations -10.67..-5.33.
    let by_ring = occluded(&run(&occ_cfg("rings = [15, 16, 17, 18, 19]"), &f));
    let by_elev = occluded(&run(&occ_cfg("elevation_deg = [-10.67, -5.33]"), &f));
    assert_eq!(by_ring, by_laser);
    assert_eq!(by_elev, by_laser);
    // The two lowest beams: -30.67 (laser 0) and -29.33 (laser 2).
    let low = occluded(&run(&occ_cfg("elevation_deg = [-31, -29]"), &f));
    let mut lasers: Vec<u8> = low.iter().map(|x| x.0).collect();
    lasers.dedup();
    lasers.sort();
    lasers.dedup();
    assert_eq!(lasers, vec![0, 2]);
    // Ring 0 is laser 0, ring 31 laser 31.
    let top = occluded(&run(&occ_cfg("rings = [0, 31]"), &f));
    assert!(top.iter().all(|x| x.0 == 0 || x.0 == 31));
    assert_eq!(top.len(), 72);
}

#[test]
fn partial_transmission_scales_power_only() {
    let f = full_turn();
    let clear = run("", &f);
    let out = run(&occ_cfg("lasers = [3]\ntransmission = 0.25"), &f);
    for i in 0..out.len() {
        assert_eq!(out.fate[i], Fate::Kept);
        assert_eq!(out.range[i], clear.range[i]);
        // One-way transmission T crossed out and back: P' = T^2 P (issue 29).
        let want = if out.clean[i].laser == 3 {
            clear.power[i] * (0.25 * 0.25)
        } else {
            clear.power[i]
        };
        assert_eq!(out.power[i], want);
    }
}

fn deltas(out: &NoisyFrame) -> Vec<f64> {
    (0..out.len())
        .map(|i| f64::from(out.range[i]) - f64::from(out.clean[i].range))
        .collect()
}

/// A varied frame: every laser, ranges 2..60 m.
fn varied(index: u32) -> Frame {
    frame(
        index,
        (0..3000)
            .map(|i| ret((i % 32) as u8, 2.0 + (i % 59) as f32, (i % 360) as f32, 60))
            .collect(),
    )
}

#[test]
fn seeds_reproduce_and_rates_share_draws() {
    let f = varied(5);
    let a = run(&rain_cfg(7.0, "goodin", 11), &f);
    let b = run(&rain_cfg(7.0, "goodin", 11), &f);
    assert_eq!(a.range, b.range);
    assert_eq!(a.power, b.power);
    assert_eq!(a.fate, b.fate);
    let c = run(&rain_cfg(7.0, "goodin", 12), &f);
    assert_ne!(a.range, c.range, "another seed gives other draws");
    // Another frame index gives other draws too.
    let other = run(&rain_cfg(7.0, "goodin", 11), &varied(6));
    assert_ne!(deltas(&a), deltas(&other));

    // Rate 3 vs 7 with one seed: the same z, so changes scale by the sigma ratio.
    let d3 = deltas(&run(&rain_cfg(3.0, "goodin", 11), &f));
    let d7 = deltas(&a);
    let g = |r: f64| (1.0 - (-r).exp()).powi(2);
    let ratio = g(3.0) / g(7.0);
    for i in 0..f.returns.len() {
        // f32 range storage: about 4e-6 m at 60 m.
        assert!(
            (d3[i] - ratio * d7[i]).abs() < 1e-5,
            "return {i}: {} vs {}",
            d3[i],
            ratio * d7[i]
        );
    }
    assert!(d7.iter().any(|d| d.abs() > 0.1), "the noise is not trivial");
}

#[test]
fn occlusion_does_not_shift_the_rain_draws() {
    let f = varied(2);
    let rain_only = run(&rain_cfg(7.0, "goodin", 4), &f);
    let both = run(
        &format!(
            "seed = 4\n{}\n[[noise]]\ntype = \"rain\"\nmodel = \"goodin\"\nrate_mm_h = 7.0\n",
            occ_cfg("lasers = [7, 5, 3, 1, 30]")
        ),
        &f,
    );
    let mut compared = 0;
    for i in 0..f.returns.len() {
        if both.fate[i] == Fate::Occluded {
            continue;
        }
        assert_eq!(both.range[i], rain_only.range[i], "return {i}");
        compared += 1;
    }
    assert!(compared > 2000);
}

#[test]
fn thread_count_does_not_change_results() {
    let chain = NoiseChain::new(&config(&format!(
        "{}\n[[noise]]\ntype = \"rain\"\nmodel = \"goodin\"\nrate_mm_h = 7.0\n",
        occ_cfg("lasers = [1]")
    )));
    let frames: Vec<Frame> = (0..8).map(varied).collect();
    let pool = |n| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build()
            .unwrap()
    };
    let one = pool(1).install(|| chain.process_all(frames.clone()));
    let two = pool(2).install(|| chain.process_all(frames.clone()));
    let serial: Vec<NoisyFrame> = frames.iter().map(|f| chain.process(f)).collect();
    for ((a, b), c) in one.iter().zip(&two).zip(&serial) {
        assert_eq!(a.range, b.range);
        assert_eq!(a.range, c.range);
        assert_eq!(a.fate, c.fate);
        assert_eq!(a.power, c.power);
    }
}

#[test]
fn reference_target_sits_exactly_on_the_threshold() {
    // kappa = p_th z_ref^2 / rho_ref: intensity 10 (rho 0.10) at 100 m gives p_th.
    let f = frame(
        0,
        vec![
            ret(0, 100.0, 0.0, 10),
            ret(0, 100.0, 0.0, 9),
            ret(0, 5.0, 0.0, 0),
            ret(0, 50.0, 0.0, 200),
            ret(0, 50.0, 0.0, 100),
            ret(0, 0.5, 0.0, 100),
        ],
    );
    let out = run("", &f);
    assert_eq!(out.power[0], 0.001);
    assert_eq!(out.fate[0], Fate::Kept, "P = min_power is detected");
    assert_eq!(out.fate[1], Fate::BelowPower);
    // Intensity 0 at 5 m: floor 0.005 -> P = 100 * 0.005 / 25 = 0.02, kept.
    assert!((out.power[2] - 100.0 * 0.005 / 25.0).abs() < 1e-15);
    assert_eq!(out.fate[2], Fate::Kept);
    // Retro-reflector clamps to rho = 1.
    assert_eq!(out.power[3], out.power[4]);
    assert!((out.power[4] - 100.0 / 2500.0).abs() < 1e-15);
    // 0.5 m: saturated power, removed by the minimum range.
    assert_eq!(out.power[5], 1.0);
    assert_eq!(out.fate[5], Fate::BelowMinRange);

    // Without the floor an intensity-0 return is lost.
    let nofloor = run("[power]\nreflectance_floor = 0.0\n", &f);
    assert_eq!(nofloor.fate[2], Fate::BelowPower);
    let k = NoiseChain::new(&config(""))
        .ideal_power()
        .constants()
        .kappa_m2;
    assert!((k - 100.0).abs() < 1e-9, "kappa {k}");
}

#[test]
fn raw_intensity_and_mavs_power_models() {
    // Raw: rho = level / 255; level 51 = 0.2 -> P = 0.001 * 2 * (100 / 40)^2.
    let f = frame(0, vec![ret(0, 40.0, 0.0, 51)]);
    let raw = run("[sensor]\nintensity = \"raw\"\n", &f);
    assert!((raw.power[0] - 0.001 * (0.2 / 0.1) * 6.25).abs() < 1e-15);

    // MAVS: kept iff rho / z^2 >= 0.9 / (pi 100^2), i.e. z <= 186.8 m for rho = 1.
    let z_lim = (std::f64::consts::PI * 1e4 / 0.9).sqrt();
    let f = frame(
        0,
        vec![
            ret(0, (z_lim - 0.5) as f32, 0.0, 100),
            ret(0, (z_lim + 0.5) as f32, 0.0, 100),
        ],
    );
    let mavs = run("[power]\nmodel = \"mavs\"\n", &f);
    assert_eq!(mavs.fate, vec![Fate::Kept, Fate::BelowPower]);
    let lidar_eq = run("", &f);
    // The lidar equation with rho_ref = 0.1 at 100 m keeps rho = 1 to 316 m.
    assert_eq!(lidar_eq.fate, vec![Fate::Kept, Fate::Kept]);
}

#[test]
fn first_cause_wins_and_survivors_move_along_the_beam() {
    let f = frame(
        0,
        vec![
            ret(7, 0.5, 0.0, 100), // occluded and too close: occluded
            ret(8, 0.5, 0.0, 0),   // too weak (no floor) and too close: power
            ret(8, 0.5, 0.0, 100), // too close
            ret(9, 30.0, 0.0, 100),
            ret(9, 45.0, 100.0, 30),
        ],
    );
    let text = format!(
        "seed = 3\n[power]\nreflectance_floor = 0.0\n{}\n[[noise]]\ntype = \"rain\"\nmodel = \"goodin\"\nrate_mm_h = 5\n",
        occ_cfg("lasers = [7]")
    );
    let out = run(&text, &f);
    assert_eq!(
        out.fate,
        vec![
            Fate::Occluded,
            Fate::BelowPower,
            Fate::BelowMinRange,
            Fate::Kept,
            Fate::Kept
        ]
    );
    assert_eq!(out.kept_indices(), vec![3, 4]);
    let surv = out.survivors();
    for (s, &i) in surv.iter().zip(&out.kept_indices()) {
        let c = &f.returns[i as usize];
        assert_eq!(s.range, out.range[i as usize]);
        assert_ne!(s.range, c.range, "rain moved the point");
        let norm = (s.x * s.x + s.y * s.y + s.z * s.z).sqrt();
        assert!((norm - s.range).abs() < 1e-4, "|xyz| {norm} vs {}", s.range);
        // Same direction as the clean point.
        let dot = (s.x * c.x + s.y * c.y + s.z * c.z) / (norm * c.range);
        assert!((dot - 1.0).abs() < 1e-5);
        assert_eq!(s.laser, c.laser);
    }
}

#[test]
fn summaries_count_and_merge_exactly() {
    let text = format!(
        "seed = 8\n{}\n[[noise]]\ntype = \"rain\"\nmodel = \"goodin\"\nrate_mm_h = 7\n",
        occ_cfg("lasers = [7, 5, 3, 1, 30]")
    );
    let chain = NoiseChain::new(&config(&text));
    let frames: Vec<NoisyFrame> = (0..3).map(|i| chain.process(&varied(i))).collect();
    let mut total = frames[0].summary();
    total.merge(&frames[1].summary());
    total.merge(&frames[2].summary());
    // Merging in another order gives the same summary.
    let mut rev = frames[2].summary();
    rev.merge(&frames[0].summary());
    rev.merge(&frames[1].summary());
    assert_eq!(total, rev);

    let mut all_d = Vec::new();
    let (mut occ, mut pow, mut rng) = (0u64, 0u64, 0u64);
    let mut pow_by_laser = [0u64; 32];
    for fr in &frames {
        for i in 0..fr.len() {
            match fr.fate[i] {
                Fate::Kept => all_d.push(f64::from(fr.range[i]) - f64::from(fr.clean[i].range)),
                Fate::Occluded => occ += 1,
                Fate::BelowPower => {
                    pow += 1;
                    pow_by_laser[fr.clean[i].laser as usize] += 1;
                }
                Fate::BelowMinRange => rng += 1,
                Fate::Replaced | Fate::Added => panic!("occlusion and rain propose no echoes"),
            }
        }
    }
    assert_eq!(total.frames, 3);
    assert_eq!(total.returns_in, 9000);
    assert_eq!(total.returns_out as usize, all_d.len());
    assert_eq!(total.dropped.occluded, occ);
    assert_eq!(total.dropped.below_power, pow);
    assert!(pow > 0, "7 mm/h drops far, dim returns");
    assert_eq!(total.dropped.below_min_range, rng);
    assert_eq!(total.dropped_by_laser.below_power, pow_by_laser);
    let n = all_d.len() as f64;
    let mean = all_d.iter().sum::<f64>() / n;
    let rms = (all_d.iter().map(|d| d * d).sum::<f64>() / n).sqrt();
    let rc = &total.range_change;
    assert!((rc.mean_m() - mean).abs() < 1e-8);
    assert!((rc.rms_m() - rms).abs() < 1e-8);
    let mut abs: Vec<f64> = all_d.iter().map(|d| d.abs()).collect();
    abs.sort_by(f64::total_cmp);
    let p95 = abs[(0.95 * n).ceil() as usize - 1];
    // Bin widths of the documented histogram: 0.1 mm to 0.1 m, 1 mm to 1 m, 1 cm to 10 m.
    let width = if p95 < 0.1 {
        1e-4
    } else if p95 < 1.0 {
        1e-3
    } else {
        1e-2
    };
    assert!(
        rc.p95_abs_m() >= p95 - 1e-9 && rc.p95_abs_m() <= p95 + width + 1e-9,
        "p95 {} vs exact {p95}",
        rc.p95_abs_m()
    );
    assert!(p95 > 0.1, "the test exercises the coarser bins: {p95}");
    let json = serde_json::to_value(&total).unwrap();
    assert_eq!(json["range_change"]["count"], all_d.len() as u64);
}
