//! Tests of the geometry world stages (p-diagram part 2): `multipath` (07, mixed pixels
//! and second echoes) and `lens_damage` (10, transmission and deflected beams), against
//! the formulas of pdiagram-models.md computed here independently of the code under test.

use crate::common;

use common::{config, ply_payload, run, stage};

use lidar_noise::config::Config;
use lidar_noise::frame::{Frame, Return, ReturnKind};
use lidar_noise::noise::{Fate, NoiseChain, NoisyFrame};
use std::path::Path;

/// A return of `laser` at `range` m in firing `firing` (0.18 degree per firing).
fn ret(laser: u8, range: f32, intensity: u8, firing: u32, kind: ReturnKind) -> Return {
    common::firing_return(laser, range, intensity, firing, 0.18, kind)
}

/// Bands of 10 firings alternately on a foreground at `near` m and a background at `far`
/// m (every laser), 600 firings: each laser has 59 depth edges, 118 edge returns.
fn bands(near: f32, far: f32, dual: bool) -> Frame {
    let mut v = Vec::new();
    for f in 0..600u32 {
        let range = if (f / 10) % 2 == 0 { near } else { far };
        for l in 0..32u8 {
            if dual {
                v.push(ret(l, range, 80, f, ReturnKind::DualLast));
                v.push(ret(l, range, 80, f, ReturnKind::DualStrongest));
            } else {
                v.push(ret(l, range, 80, f, ReturnKind::Strongest));
            }
        }
    }
    Frame {
        index: 0,
        partial: false,
        returns: v,
    }
}

/// A 10 Hz rotation: 2000 firings of 32 lasers, ranges 2..30 m, intensities 40..140.
fn turn(index: u32) -> Frame {
    common::rotation(index, 2000, |f, l| {
        let k = f * 32 + u32::from(l);
        let range = 2.0 + (k.wrapping_mul(2_654_435_761) % 2800) as f32 / 100.0;
        Some(ret(
            l,
            range,
            40 + (k % 101) as u8,
            f,
            ReturnKind::Strongest,
        ))
    })
}

/// Is return `i` of a `bands` frame next to a depth edge (neighbour firing in the other
/// band)? Returns the neighbour's range.
fn edge_neighbour(f: &Frame, i: usize, per_firing: usize) -> Option<f32> {
    let firing = i / per_firing;
    if firing.is_multiple_of(10) && firing > 0 {
        Some(f.returns[i - per_firing].range)
    } else if firing % 10 == 9 && firing + 1 < 600 {
        Some(f.returns[i + per_firing].range)
    } else {
        None
    }
}

/// The footprint share g on the other surface implied by a merged range `rm` between the
/// own surface (`r1`, full power `p1`) and the other (`r2`, `p2`): from
/// (rm - r1) / (r2 - r1) = g p2 / ((1 - g) p1 + g p2).
fn implied_g(rm: f64, r1: f64, r2: f64, p1: f64, p2: f64) -> f64 {
    let w = (rm - r1) / (r2 - r1);
    w * p1 / (p2 * (1.0 - w) + w * p1)
}

/// 3-sigma check of a binomial count.
fn within_3_sigma(count: usize, n: usize, p: f64) {
    let mean = n as f64 * p;
    let sd = (n as f64 * p * (1.0 - p)).sqrt();
    assert!(
        (count as f64 - mean).abs() <= 3.0 * sd,
        "{count} of {n}, expected {mean} +- {sd}"
    );
}

fn same_survivors(a: &NoisyFrame, b: &NoisyFrame) -> bool {
    let (x, y) = (a.survivors(), b.survivors());
    a.fate == b.fate
        && x.len() == y.len()
        && x.iter().zip(&y).all(|(p, q)| {
            p.x.to_bits() == q.x.to_bits()
                && p.y.to_bits() == q.y.to_bits()
                && p.z.to_bits() == q.z.to_bits()
                && p.range.to_bits() == q.range.to_bits()
                && p.intensity == q.intensity
                && p.time.to_bits() == q.time.to_bits()
        })
}

#[test]
fn mixed_pixels_lie_between_the_surfaces_with_the_power_weighted_range() {
    // Foreground 10 m, background 11 m: 1 m apart, under c tau_p / 2 = 1.5 m, so every
    // mixed edge return is one merged echo.
    let f = bands(10.0, 11.0, false);
    let base = run("seed = 5\n", &f);
    let out = run(&stage("multipath", "probability = 1"), &f);
    let mut mixed = 0;
    let mut edges = 0;
    for i in 0..f.returns.len() {
        let r0 = f.returns[i].range;
        match edge_neighbour(&f, i, 32) {
            None => {
                assert_eq!(out.fate[i], Fate::Kept, "{i}");
                assert_eq!(out.range[i], r0);
                assert_eq!(out.power[i], base.power[i]);
            }
            Some(r_other) => {
                edges += 1;
                assert_eq!(out.fate[i], Fate::Replaced, "{i}");
                assert_eq!(out.cause[i], 0);
                mixed += 1;
                let rm = f64::from(out.range[i]);
                let (r1, r2) = (f64::from(r0), f64::from(r_other));
                assert!(
                    rm > r1.min(r2) && rm < r1.max(r2),
                    "{rm} not in ({r1}, {r2})"
                );
                // Recover g from the range, then the power must be (1-g) P1 + g P2.
                let j = if i % (32 * 10) < 32 { i - 32 } else { i + 32 };
                let (p1, p2) = (base.power[i], base.power[j]);
                let g = implied_g(rm, r1, r2, p1, p2);
                let expect = (1.0 - g) * p1 + g * p2;
                assert!(
                    (out.power[i] / expect - 1.0).abs() < 1e-4,
                    "power {} vs {expect}",
                    out.power[i]
                );
                // The point stays on its beam.
                let s = out.noisy_return(i);
                let d = f64::from(s.x).hypot(f64::from(s.y)).hypot(f64::from(s.z));
                assert!((d - rm).abs() < 1e-4);
            }
        }
    }
    assert_eq!(edges, 32 * 118);
    assert_eq!(mixed, edges);
    // p_mix = 0.5: the mixed count is binomial(edges, 0.5).
    let out = run(&stage("multipath", "probability = 0.5"), &f);
    let mixed = out.fate.iter().filter(|&&x| x == Fate::Replaced).count();
    within_3_sigma(mixed, edges, 0.5);
}

#[test]
fn a_jump_of_exactly_edge_m_is_no_edge_however_the_ranges_round() {
    // A capture's ranges are whole 2 mm units: 6,007 and 6,157 units are 0.300 m apart,
    // 0.29999924 m between the two f32 ranges; the same points' ranges recomputed from
    // x y z (a dataset's copy of the capture) may lie a unit in the last place either
    // side, 0.3000002 m apart. None is more than edge_m = 0.3 m.
    let cases = [
        (6007.0f32 * 0.002, 6157.0f32 * 0.002),
        (12.014_001, 12.313_999),
        (12.013_999, 12.314_001),
        (2.0, 2.3),
    ];
    for (near, far) in cases {
        let out = run(
            &stage("multipath", "probability = 1"),
            &bands(near, far, false),
        );
        assert!(out.fate.iter().all(|&x| x == Fate::Kept), "{near} {far}");
    }
    // One unit more is an edge: every edge return mixed.
    let out = run(
        &stage("multipath", "probability = 1"),
        &bands(12.014, 12.316, false),
    );
    let mixed = out.fate.iter().filter(|&&x| x != Fate::Kept).count();
    assert_eq!(mixed, 32 * 118);
}

#[test]
fn separate_echoes_follow_the_strongest_rule() {
    // 5 m and 8 m: 3 m apart, two echoes. The neighbour's echo g P_other beats the own
    // echo (1 - g) P_own when g > P_own / (P_own + P_other): with g uniform that happens
    // with probability P_other / (P_own + P_other).
    let f = bands(5.0, 8.0, false);
    let base = run("seed = 5\n", &f);
    assert!(base.fate.iter().all(|&x| x == Fate::Kept));
    let mut total = 0;
    for seed in [5, 6, 7] {
        let out = run(
            &format!("seed = {seed}\n[[noise]]\ntype = \"multipath\"\nprobability = 1\n"),
            &f,
        );
        let (mut near_won, mut far_won, mut n_near, mut n_far) = (0, 0, 0, 0);
        let (mut p_near_win, mut p_far_win) = (0.0, 0.0);
        for i in 0..f.returns.len() {
            let Some(r_other) = edge_neighbour(&f, i, 32) else {
                assert_eq!(out.fate[i], Fate::Kept);
                continue;
            };
            let j = if i % (32 * 10) < 32 { i - 32 } else { i + 32 };
            let (po, px) = (base.power[i], base.power[j]);
            let won = out.fate[i] == Fate::Replaced;
            if won {
                assert_eq!(out.range[i], r_other);
                assert_eq!(out.cause[i], 0);
            } else {
                assert_eq!(out.range[i], f.returns[i].range);
                assert!(out.power[i] < po, "own echo weakened");
            }
            if f.returns[i].range < r_other {
                n_near += 1;
                near_won += usize::from(won);
                p_near_win = px / (po + px);
            } else {
                n_far += 1;
                far_won += usize::from(won);
                p_far_win = px / (po + px);
            }
        }
        within_3_sigma(near_won, n_near, p_near_win);
        within_3_sigma(far_won, n_far, p_far_win);
        total += near_won + far_won;
    }
    assert!(total > 0);
}

#[test]
fn dual_captures_report_the_second_surface_as_a_second_echo() {
    let f = bands(5.0, 8.0, true);
    // The threshold detection: a mixed pixel's shares are reported when at or above it
    // (under the receiver's noise a weakened share is kept with a probability).
    let out = run(
        &format!(
            "{}[detection]\nmodel = \"threshold\"\n",
            stage("multipath", "probability = 1")
        ),
        &f,
    );
    let thr = out.threshold;
    let (mut two, mut edges) = (0, 0);
    for i in (0..f.returns.len()).step_by(2) {
        // i: DualLast, i + 1: DualStrongest of the same slot.
        assert_eq!(f.returns[i].kind, ReturnKind::DualLast);
        let Some(r_other) = edge_neighbour(&f, i, 64) else {
            assert_eq!(out.fate[i], Fate::Kept);
            assert_eq!(out.fate[i + 1], Fate::Kept);
            continue;
        };
        edges += 1;
        let r_own = f.returns[i].range;
        let (a, b) = (out.range[i], out.range[i + 1]);
        assert!(out.fate[i].is_alive() && out.fate[i + 1].is_alive());
        if a != b {
            two += 1;
            // The farther surface is the last return, the other one the strongest.
            assert_eq!(a, r_own.max(r_other));
            assert_eq!(b, r_own.min(r_other));
        } else {
            // One echo only: the neighbour's share was under the threshold, or the own
            // echo's was.
            assert!(out.power[i] >= thr);
        }
    }
    assert_eq!(edges, 32 * 118);
    // g is uniform: the neighbour's echo g P is detectable for all but a tiny g.
    assert!(two as f64 > 0.95 * edges as f64, "{two} of {edges}");
    // Single mode keeps one return per slot.
    let single = run(
        &stage("multipath", "probability = 1"),
        &bands(5.0, 8.0, false),
    );
    assert_eq!(single.len(), single.clean_len);
}

#[test]
fn footprint_rule_mixes_fewer_and_smaller_shares() {
    // Footprint of 3 mrad, firings 0.18 deg (3.1 mrad) apart: a beam reaches across
    // the edge only if the edge is within theta/2 of its centre (probability
    // (theta/2) / (step cos w) about 0.5), and then by a share under one half.
    let f = bands(10.0, 11.0, false);
    let base = run("seed = 5\n", &f);
    let out = run(
        &stage("multipath", "probability = 1\nfraction = \"footprint\""),
        &f,
    );
    let mut mixed = 0;
    let mut edges = 0;
    let mut expect = 0.0;
    let step = 0.18f64.to_radians();
    for i in 0..f.returns.len() {
        let Some(r_other) = edge_neighbour(&f, i, 32) else {
            continue;
        };
        edges += 1;
        let sep = step * f64::from(f.returns[i].elevation).to_radians().cos();
        expect += (1.5e-3 / sep).min(1.0);
        if out.fate[i] == Fate::Replaced {
            mixed += 1;
            // At most half the footprint on the neighbour.
            let j = if i % (32 * 10) < 32 { i - 32 } else { i + 32 };
            let g = implied_g(
                f64::from(out.range[i]),
                f64::from(f.returns[i].range),
                f64::from(r_other),
                base.power[i],
                base.power[j],
            );
            assert!(g > 0.0 && g <= 0.5 + 1e-4, "g = {g}");
        }
    }
    let p = expect / edges as f64;
    within_3_sigma(mixed, edges, p);
}

#[test]
fn lens_transmission_scales_power_by_t_squared_on_the_chosen_lasers() {
    let f = turn(0);
    let base = run("seed = 5\n", &f);
    let out = run(
        &stage(
            "lens_damage",
            "lasers = [3, 17]\ntransmission = 0.8\nscatter_probability = 0",
        ),
        &f,
    );
    let kept: Vec<u32> = out.kept_indices();
    let survivors = out.survivors();
    for (k, &i) in kept.iter().enumerate() {
        let i = i as usize;
        let r = &f.returns[i];
        let g = if r.laser == 3 || r.laser == 17 {
            0.64
        } else {
            1.0
        };
        assert!((out.power[i] / base.power[i] - g).abs() < 1e-12);
        assert_eq!(
            survivors[k].intensity,
            (f64::from(r.intensity) * g).round() as u8
        );
        assert_eq!(out.range[i], r.range);
    }
}

#[test]
fn deflected_beams_report_the_neighbouring_surface_at_the_nominal_angles() {
    let f = turn(1);
    let base = run("seed = 5\n", &f);
    assert!(base.fate.iter().all(|&x| x == Fate::Kept));
    let p = 0.05;
    let out = run(
        &stage(
            "lens_damage",
            &format!(
                "transmission = 1\nscatter_probability = {p}\nscatter_sigma_deg = 0.5\nscatter_fraction = 1"
            ),
        ),
        &f,
    );
    let n = f.returns.len();
    let deflected: Vec<usize> = (0..n).filter(|&i| out.cause[i] == 0).collect();
    // Every return of the full frame has a surface in any direction: none is lost.
    assert!(deflected.iter().all(|&i| out.fate[i] == Fate::Replaced));
    within_3_sigma(deflected.len(), n, p);
    let mut moved = 0;
    for &i in &deflected {
        let (r, o) = (&f.returns[i], out.noisy_return(i));
        // The range of a surface within a few sigma of the aim...
        let firing = i / 32;
        let near = (firing.saturating_sub(20)..(firing + 21).min(2000))
            .flat_map(|g| (0..32).map(move |l| g * 32 + l))
            .any(|j| f.returns[j].range == out.range[i] && base.power[j] == out.power[i]);
        assert!(near, "return {i}: range {} from nowhere near", out.range[i]);
        // ...reported along the aimed direction.
        let s = f64::from(out.range[i]) / f64::from(r.range);
        assert!((f64::from(o.x) - f64::from(r.x) * s).abs() < 1e-4);
        assert!((f64::from(o.z) - f64::from(r.z) * s).abs() < 1e-4);
        assert_eq!(o.azimuth, r.azimuth);
        moved += usize::from(out.range[i] != r.range);
    }
    // sigma 0.5 deg spans about 3 firings and one laser: most deflected beams hit
    // another cell.
    assert!(moved as f64 > 0.8 * deflected.len() as f64);
    // Everything else is untouched.
    for i in (0..n).filter(|&i| out.cause[i] != 0) {
        assert_eq!(out.range[i], f.returns[i].range);
        assert_eq!(out.fate[i], Fate::Kept);
    }
}

#[test]
fn an_undeflected_scatter_scales_power_by_t_squared_q() {
    let f = turn(2);
    let base = run("seed = 5\n", &f);
    let out = run(
        &stage(
            "lens_damage",
            "lasers = [0]\ntransmission = 0.9\nscatter_probability = 1\nscatter_sigma_deg = 0\nscatter_fraction = 0.5",
        ),
        &f,
    );
    for (i, r) in f.returns.iter().enumerate() {
        if r.laser == 0 {
            assert_eq!(out.range[i], r.range);
            let want = 0.81 * 0.5 * base.power[i];
            if want >= 0.001 {
                assert_eq!(out.fate[i], Fate::Replaced);
                assert!((out.power[i] / want - 1.0).abs() < 1e-12);
            } else {
                assert_eq!(out.fate[i], Fate::BelowPower);
            }
        } else {
            assert_eq!(out.fate[i], Fate::Kept);
            assert_eq!(out.power[i], base.power[i]);
        }
    }
}

const ZERO: &[(&str, &str)] = &[
    ("multipath", "probability = 0"),
    ("lens_damage", "transmission = 1\nscatter_probability = 0"),
];

#[test]
fn zero_magnitude_is_the_identity() {
    for f in [turn(3), bands(10.0, 11.0, false), bands(5.0, 8.0, true)] {
        let base = run("seed = 5\n", &f);
        for (k, body) in ZERO {
            let out = run(&stage(k, body), &f);
            assert!(same_survivors(&out, &base), "{k}");
        }
    }
}

#[test]
fn deterministic_for_a_seed_and_any_thread_count() {
    let text = "seed = 9\n[[noise]]\ntype = \"multipath\"\n[[noise]]\ntype = \"lens_damage\"\nscatter_probability = 0.05\n";
    let chain = NoiseChain::new(&config(text));
    let frames: Vec<Frame> = (0..4).map(turn).collect();
    let pool = |n| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build()
            .unwrap()
    };
    let one = pool(1).install(|| chain.process_all(frames.clone()));
    let two = pool(2).install(|| chain.process_all(frames.clone()));
    for (a, b) in one.iter().zip(&two) {
        assert!(same_survivors(a, b));
        assert_eq!(a.cause, b.cause);
    }
    let again = NoiseChain::new(&config(text)).process(&frames[0]);
    assert!(same_survivors(&again, &one[0]));
    // Another seed changes the result; another frame draws its own numbers.
    let other =
        NoiseChain::new(&config(&text.replace("seed = 9", "seed = 10"))).process(&frames[0]);
    assert!(!same_survivors(&other, &one[0]));
    assert!(one.iter().all(|o| o.fate.contains(&Fate::Replaced)));
}

#[test]
fn bad_options_name_key_and_line() {
    let cases = [
        ("multipath", "probability = 1.5", "probability", "outside"),
        ("multipath", "pulse_ns = nan", "pulse_ns", "nan"),
        ("multipath", "fraction = \"gauss\"", "fraction", "gauss"),
        ("multipath", "edge_m = -1", "edge_m", "outside"),
        ("lens_damage", "lasers = [140]", "lasers[0]", "140"),
        (
            "lens_damage",
            "transmission = 1.2",
            "transmission",
            "outside",
        ),
        (
            "lens_damage",
            "scatter_sigma_deg = -0.5",
            "scatter_sigma_deg",
            "negative",
        ),
        ("lens_damage", "scatter = 0.1", "scatter", "unknown"),
    ];
    for (kind, body, key, word) in cases {
        let e = match Config::from_toml_str(&stage(kind, body), Path::new("bad.toml"), &[], None) {
            Ok(_) => panic!("should fail: {kind} {body}"),
            Err(e) => e.to_string(),
        };
        assert!(e.contains(&format!("noise[0].{key} (line 4")), "{e}");
        assert!(e.contains(word), "{e}");
    }
}

#[test]
fn zero_magnitude_writes_the_same_ply_and_bad_options_write_nothing() {
    let tmp = tempfile::tempdir().unwrap();
    let mut zero = String::from("seed = 5\n");
    for (k, body) in ZERO {
        zero.push_str(&format!("[[noise]]\ntype = \"{k}\"\n{body}\n"));
    }
    let ply = common::run_frame0(tmp.path(), &[&zero, "seed = 5\n"], &["--keep-dropped"]);
    // The header records the configuration; the data must be byte-identical.
    let a = ply_payload(&ply[0]);
    let b = ply_payload(&ply[1]);
    assert!(!a.is_empty());
    assert!(a == b, "PLY payloads differ");
    let msg = common::refused_run(tmp.path(), &stage("lens_damage", "scatter_probability = 2"));
    assert!(
        msg.contains("noise[0].scatter_probability (line 4"),
        "{msg}"
    );
}

#[test]
fn both_stages_are_sweepable_and_toggleable() {
    use lidar_noise::sweep::plan::Vary;
    for (k, key) in [
        ("multipath", "probability"),
        ("lens_damage", "transmission"),
    ] {
        assert!(Vary::parse(&format!("{k}.{key}=0,1")).is_ok(), "{k}.{key}");
        assert!(Vary::parse(&format!("{k}=on,off")).is_ok(), "{k}");
        let (c, _) =
            Config::from_toml_str("", Path::new("x"), &[format!("{k}.{key}=1")], None).unwrap();
        assert_eq!(c.noise[0].kind(), k);
    }
}
