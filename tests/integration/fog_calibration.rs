//! Calibration of the fog stage for the HDL-32E (issue 29): the biaxial overlap against
//! a count of the beam's area by hand, no fog echo in clear air (V >= 10 km) on the
//! fixtures and on the shared capture, more echoes as the visibility falls, and the
//! visibility at which echoes start against an independent quadrature of the echo.

use crate::common;

use lidar_noise::frame::Frame;
use lidar_noise::noise::world::fog::{self, Biaxial, Droplets, Fog, Overlap};
use lidar_noise::noise::{Fate, NoiseChain};
use lidar_noise::sensor::frames::{DecoderOptions, FrameReader};
use std::path::Path;

const PI: f64 = std::f64::consts::PI;

/// configs/clear.toml (the clear-weather setting the numbers use) plus `extra`.
fn clear_plus(extra: &str) -> String {
    let clear =
        std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("configs/clear.toml"))
            .unwrap();
    format!("{clear}\n{extra}")
}

fn fog_stage(v: &str, body: &str) -> String {
    format!("[[noise]]\ntype = \"fog\"\nvisibility_m = {v}\n{body}\n")
}

/// The frames of `path` whose sweep index lies in `wanted` (as `--frames` picks them).
fn frames_of(path: &Path, wanted: std::ops::Range<u32>) -> Vec<Frame> {
    let mut reader = FrameReader::open(path, &DecoderOptions::default()).expect("open capture");
    reader
        .by_ref()
        .map(|f| f.expect("decode"))
        .filter(|f| wanted.contains(&f.index))
        .collect()
}

/// Returns of `frames` that the detection settings of configs/clear.toml keep.
fn detected(frames: &[Frame]) -> usize {
    let chain = NoiseChain::new(&common::config(&clear_plus("")));
    frames
        .iter()
        .map(|f| chain.process(f).survivors().len())
        .sum()
}

/// Fog echoes reported (returns replaced or added by the fog stage) over `frames`.
fn fog_echoes(text: &str, frames: &[Frame]) -> usize {
    let chain = NoiseChain::new(&common::config(text));
    frames
        .iter()
        .map(|f| {
            let out = chain.process(f);
            out.fate
                .iter()
                .filter(|x| matches!(x, Fate::Replaced | Fate::Added))
                .count()
        })
        .sum()
}

/// The HDL-32E default geometry, as the module states it.
fn hdl32e() -> Biaxial {
    match fog::hdl32e_overlap() {
        Overlap::Biaxial(b) => b,
        Overlap::Linear { .. } => panic!("the default overlap is biaxial"),
    }
}

/// Share of the beam's disk inside the receiver's field at range `r`, counted on a
/// 400 x 400 grid over the beam (independent of the lens-area formula).
fn overlap_by_count(b: &Biaxial, r: f64) -> f64 {
    let wt = b.tx_radius_m + r * (b.divergence_rad / 2.0).tan();
    let wr = b.rx_radius_m + r * (b.fov_rad / 2.0).tan();
    let n = 400;
    let (mut inside, mut total) = (0u64, 0u64);
    for i in 0..n {
        for j in 0..n {
            let x = -wt + (2.0 * f64::from(i) + 1.0) * wt / f64::from(n);
            let y = -wt + (2.0 * f64::from(j) + 1.0) * wt / f64::from(n);
            if x * x + y * y > wt * wt {
                continue;
            }
            total += 1;
            let dx = x - b.separation_m;
            if dx * dx + y * y <= wr * wr {
                inside += 1;
            }
        }
    }
    inside as f64 / total as f64
}

#[test]
fn biaxial_overlap_is_the_share_of_the_beam_the_receiver_sees() {
    let b = hdl32e();
    for r in [0.5, 2.0, 2.8, 4.0, 7.0, 12.0, 20.0, 40.0, 70.0, 74.0, 100.0] {
        let want = overlap_by_count(&b, r);
        let got = b.overlap(r);
        assert!((got - want).abs() < 2e-3, "r {r}: {got} vs {want}");
    }
    // R1 and R2 by hand: the field touches the beam when w_t + w_r = d and contains it
    // when w_r - w_t = d: with d = 30 mm, apertures 20 mm, divergence 3.3 mrad and FOV
    // 4.1 mrad, R1 = 10 mm / (1.65 + 2.05) mrad = 2.70 m, R2 = 30 mm / 0.4 mrad = 75 m.
    let (r1, r2) = (0.010 / (0.00165 + 0.00205), 0.030 / (0.00205 - 0.00165));
    assert!((b.start_m() / r1 - 1.0).abs() < 1e-5, "{}", b.start_m());
    assert!((b.full_m() / r2 - 1.0).abs() < 1e-5, "{}", b.full_m());
    assert_eq!(b.overlap(r1 * 0.999), 0.0);
    assert!(b.overlap(r1 * 1.01) > 0.0);
    assert!(b.overlap(r2 * 0.99) < 1.0);
    assert_eq!(b.overlap(r2 * 1.001), 1.0);
}

/// Independent quadrature of the fog echo's peak power for no target: composite
/// Simpson over the pulse window [R - c tau_H, R] with 3,000 intervals, maximised over
/// R on a 2 cm scan refined by a 1 mm scan; P = pi kappa beta int sin^2 xi e^-2ar / r^2.
fn reference_peak_power(v: f64, beta_r: f64, b: &Biaxial, kappa: f64) -> f64 {
    let alpha = 20f64.ln() / v;
    let l = 299_792_458.0 * 20e-9;
    let p = |big_r: f64| {
        let n = 3_000;
        let lo = (big_r - l).max(1e-3);
        let h = (big_r - lo) / f64::from(n);
        let g = |r: f64| {
            (PI * (big_r - r) / l).sin().powi(2) * (-2.0 * alpha * r).exp() * b.overlap(r) / (r * r)
        };
        let mut s = g(lo) + g(big_r);
        for k in 1..n {
            s += g(lo + f64::from(k) * h) * if k % 2 == 1 { 4.0 } else { 2.0 };
        }
        PI * kappa * beta_r / v * s * h / 3.0
    };
    let mut best = (0.0, 0.0);
    let mut r = 0.5;
    while r < 45.0 {
        let q = p(r);
        if q > best.1 {
            best = (r, q);
        }
        r += 0.02;
    }
    let at = best.0;
    let mut r = at - 0.02;
    while r < at + 0.02 {
        best.1 = best.1.max(p(r));
        r += 0.001;
    }
    best.1
}

#[test]
fn echoes_start_below_10_km_visibility_and_the_onset_matches_the_quadrature() {
    let kappa = 100.0; // p_th 1e-3, a 10 % target at 100 m on the threshold.
    let p_th = 1e-3;
    let b = hdl32e();
    let f = Fog::new(1000.0, 0.046, 20.0, Overlap::Biaxial(b), 0.0, true);
    let onset = f.echo_onset_visibility_m(kappa, p_th);
    // At the onset the independent quadrature gives the threshold (within 1 %), and the
    // onset lies well below 10 km.
    let p = reference_peak_power(onset, 0.046, &b, kappa);
    assert!((p / p_th - 1.0).abs() < 0.01, "onset {onset} m: {p}");
    assert!(onset > 100.0 && onset < 10_000.0, "{onset}");
    eprintln!("onset, droplets hahner: {onset:.0} m");
    for d in [Droplets::Advection, Droplets::Radiation] {
        let v = f
            .clone()
            .with_droplets(d)
            .echo_onset_visibility_m(kappa, p_th);
        eprintln!("onset, droplets {d:?}: {v:.0} m");
        assert!(v > onset && v < 10_000.0, "{d:?}: {v}");
    }
    // Over the stated bounds of the unknown optics (apertures 20-30 mm, gap between
    // them 2-10 mm, receiver FOV 1.25-3 x the divergence) and beta_r up to the paper's
    // 0.092, the onset stays below 10 km: no fog echo in clear air whatever the
    // geometry within its bounds. With Mie droplets (beta 3.5 x the paper's) it does
    // not hold at every corner (reported, see the notes): the worst corner is printed.
    let mut worst_mie = (0.0f64, None);
    for aperture in [0.020, 0.030] {
        for gap in [0.002, 0.010] {
            for fov in [1.25, 3.0] {
                let g = Biaxial {
                    separation_m: aperture + gap,
                    tx_radius_m: aperture / 2.0,
                    rx_radius_m: aperture / 2.0,
                    divergence_rad: 3.3e-3,
                    fov_rad: 3.3e-3 * fov,
                };
                let f = Fog::new(1000.0, 0.092, 20.0, Overlap::Biaxial(g), 0.0, true);
                let v = f.echo_onset_visibility_m(kappa, p_th);
                let mie = f
                    .with_droplets(Droplets::Advection)
                    .echo_onset_visibility_m(kappa, p_th);
                eprintln!("bounds {g:?}: onset {v:.0} m (beta_r 0.092), {mie:.0} m (advection)");
                assert!(v < 10_000.0, "{g:?}: onset {v}");
                if mie > worst_mie.0 {
                    worst_mie = (mie, Some(g));
                }
            }
        }
    }
    eprintln!("worst corner with advection droplets: {worst_mie:?}");
    // Hahner's linear 0.9..1.0 m overlap puts the onset far beyond 10 km (the ring of
    // the issue): the overlap is what removes it.
    let hahner = Fog::new(
        1000.0,
        0.046,
        20.0,
        Overlap::Linear {
            start_m: 0.9,
            full_m: 1.0,
        },
        0.0,
        true,
    );
    let lin = hahner.echo_onset_visibility_m(kappa, p_th);
    eprintln!("onset, linear 0.9-1.0 m: {lin:.0} m");
    // Issue 29 measured 28,377 fog echoes at V = 10 km with it: the onset lies above.
    assert!(lin > 10_000.0, "{lin}");
}

#[test]
fn no_fog_echo_in_clear_air_on_the_fixtures_and_more_as_visibility_falls() {
    let dir = common::fixtures();
    let mut frames = frames_of(&dir.join("crossroad.pcap"), 0..2);
    frames.extend(frames_of(&dir.join("parking.pcap"), 0..2));
    assert!(frames.iter().map(|f| f.returns.len()).sum::<usize>() > 1000);
    for v in ["inf", "10000", "20000"] {
        let n = fog_echoes(&clear_plus(&fog_stage(v, "")), &frames);
        assert_eq!(n, 0, "V {v}");
    }
    // Denser fog, more echoes: non-decreasing as V falls, and some at 100 m.
    let mut last = 0;
    for v in ["10000", "1000", "600", "300", "150", "100", "50"] {
        let n = fog_echoes(&clear_plus(&fog_stage(v, "")), &frames);
        assert!(n >= last, "V {v}: {n} < {last}");
        last = n;
    }
    assert!(last > 0);
    let at_100 = fog_echoes(&clear_plus(&fog_stage("100", "")), &frames);
    let at_300 = fog_echoes(&clear_plus(&fog_stage("300", "")), &frames);
    assert!(at_100 > at_300, "{at_100} vs {at_300}");
}

#[test]
fn no_fog_echo_in_clear_air_on_the_shared_capture() {
    let Some(path) = common::shared("hdl32e/monterey.pcap") else {
        return;
    };
    // Frames 2-4 (148,551 recorded returns), as in the issue: clear air keeps every one
    // but those under the minimum range (issue 50).
    let frames = frames_of(&path, 2..5);
    assert_eq!(frames.len(), 3);
    let recorded: usize = frames.iter().map(|f| f.returns.len()).sum();
    let near: usize = frames
        .iter()
        .map(|f| f.returns.iter().filter(|r| r.range < 0.9).count())
        .sum();
    assert_eq!(recorded, 148_551);
    assert_eq!(detected(&frames), recorded - near);
    for v in ["inf", "10000"] {
        assert_eq!(
            fog_echoes(&clear_plus(&fog_stage(v, "")), &frames),
            0,
            "V {v}"
        );
    }
}

/// The numbers of the fidelity report (not a check): on frames 2-4 of the shared capture
/// with configs/clear.toml plus one fog stage (`FOG_EXTRA` adds option lines), the share
/// of returns replaced and added, and where the echoes sit in range and by ring, as JSON
/// on stdout. Run: `cargo test --release --test integration -- --ignored --nocapture fog_calibration::`.
#[test]
#[ignore]
fn measure_the_shared_capture() {
    let Some(path) = common::shared("hdl32e/monterey.pcap") else {
        return;
    };
    let frames = frames_of(&path, 2..5);
    let recorded: usize = frames.iter().map(|f| f.returns.len()).sum();
    let returns = detected(&frames);
    let extra = std::env::var("FOG_EXTRA").unwrap_or_default();
    let edges = [
        0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 7.5, 10.0, 15.0, 20.0, 30.0, 50.0, 100.0, 1e9,
    ];
    let mut rows = Vec::new();
    for v in [50.0, 100.0, 150.0, 300.0, 600.0, 1000.0, 10000.0] {
        let chain = NoiseChain::new(&common::config(&clear_plus(&fog_stage(
            &format!("{v}"),
            &extra,
        ))));
        let (mut replaced, mut added) = (0usize, 0usize);
        let mut hist = vec![0usize; edges.len() - 1];
        let mut by_ring = [0usize; 32];
        let mut ranges = Vec::new();
        // The echo table is built on first use (once per stage): time it apart.
        let t = std::time::Instant::now();
        chain.process(&frames[0]);
        let first = t.elapsed().as_secs_f64();
        let t = std::time::Instant::now();
        let outs: Vec<_> = frames.iter().map(|f| chain.process(f)).collect();
        let secs = t.elapsed().as_secs_f64();
        for out in &outs {
            for i in 0..out.len() {
                match out.fate[i] {
                    Fate::Replaced => replaced += 1,
                    Fate::Added => added += 1,
                    _ => continue,
                }
                let r = f64::from(out.range[i]);
                ranges.push(r);
                let b = edges
                    .windows(2)
                    .position(|w| r >= w[0] && r < w[1])
                    .unwrap_or(0);
                hist[b] += 1;
                by_ring[usize::from(out.clean[i].ring) % 32] += 1;
            }
        }
        ranges.sort_by(f64::total_cmp);
        let q = |p: f64| {
            if ranges.is_empty() {
                serde_json::Value::Null
            } else {
                serde_json::json!(ranges[((ranges.len() - 1) as f64 * p) as usize])
            }
        };
        rows.push(serde_json::json!({
            "visibility_m": v,
            "replaced": replaced,
            "replaced_share": replaced as f64 / returns as f64,
            "added": added,
            "added_share": added as f64 / returns as f64,
            "echo_range_m": {"min": q(0.0), "median": q(0.5), "max": q(1.0)},
            "echo_range_histogram": {"edges_m": edges, "counts": hist},
            "echoes_by_ring": by_ring.to_vec(),
            "seconds_first_frame_with_table": first,
            "seconds_3_frames_whole_chain": secs,
        }));
    }
    let doc = serde_json::json!({"recorded": recorded, "returns": returns, "fog_extra_options": extra, "runs": rows});
    println!("{}", serde_json::to_string_pretty(&doc).unwrap());
}

/// What the fog echoes of `frames` under `text` look like: (echoes a frame, their ranges
/// sorted, their intensity bytes sorted, kept returns at 20-30 and 30-40 m).
fn fog_profile(text: &str, frames: &[Frame]) -> (f64, Vec<f32>, Vec<u8>, [usize; 2]) {
    let chain = NoiseChain::new(&common::config(text));
    let (mut ranges, mut bytes, mut bands) = (Vec::new(), Vec::new(), [0usize; 2]);
    for f in frames {
        let out = chain.process(f);
        for i in 0..out.len() {
            let fate = out.fate[i];
            if matches!(fate, Fate::Replaced | Fate::Added) {
                ranges.push(out.range[i]);
                bytes.push(out.noisy_return(i).intensity);
            } else if fate == Fate::Kept {
                let r = out.range[i];
                if (20.0..30.0).contains(&r) {
                    bands[0] += 1;
                } else if (30.0..40.0).contains(&r) {
                    bands[1] += 1;
                }
            }
        }
    }
    ranges.sort_by(f32::total_cmp);
    bytes.sort_unstable();
    (
        ranges.len() as f64 / frames.len() as f64,
        ranges,
        bytes,
        bands,
    )
}

fn quantile<T: Copy>(v: &[T], q: f64) -> T {
    v[((v.len() - 1) as f64 * q).round() as usize]
}

/// Issue 50: at V = 90 m a fog echo is a chance per beam, not every free slot: a few
/// dozen to a few hundred echoes a frame, spread in range beyond the overlap's start
/// (none within 3 m, as a real HDL-32E in fog shows in its open sectors), with small
/// non-zero intensity bytes. On the fixtures within a factor of 2 of the band
/// (20-600 a frame on the shared capture).
#[test]
fn fog_at_90_m_is_a_chance_per_beam_on_the_fixtures() {
    let dir = common::fixtures();
    let mut frames = frames_of(&dir.join("crossroad.pcap"), 0..2);
    frames.extend(frames_of(&dir.join("parking.pcap"), 0..2));
    let (per_frame, ranges, bytes, _) = fog_profile(&clear_plus(&fog_stage("90", "")), &frames);
    assert!((10.0..=1200.0).contains(&per_frame), "{per_frame} a frame");
    let (q1, med, q3) = (
        quantile(&ranges, 0.25),
        quantile(&ranges, 0.5),
        quantile(&ranges, 0.75),
    );
    assert!(q3 - q1 >= 0.3, "interquartile range {q1}..{q3}");
    assert!(ranges[0] >= 3.0, "nearest fog echo at {} m", ranges[0]);
    assert!((3.0..10.0).contains(&med), "median range {med}");
    let b = quantile(&bytes, 0.5);
    assert!((1..=6).contains(&b), "median byte {b}");
    assert!(bytes[0] >= 1, "a reported echo has a non-zero byte");
}

/// Issue 50 on the shared capture (frames 0-9): fog echoes at V = 90 m within the
/// issue's band of 20-600 a frame, spread in range (interquartile at least 0.3 m), bytes
/// of 1-6, none within 3 m; the far tail falls smoothly (kept returns at 30-40 m over
/// those at 20-30 m at least half the real recording's 0.15).
#[test]
fn fog_at_90_m_on_the_shared_capture() {
    let Some(path) = common::shared("hdl32e/monterey.pcap") else {
        eprintln!("SKIPPED: ../shared/data is absent");
        return;
    };
    let frames = frames_of(&path, 0..10);
    let (per_frame, ranges, bytes, bands) = fog_profile(&clear_plus(&fog_stage("90", "")), &frames);
    eprintln!(
        "V = 90 m: {per_frame} fog echoes a frame, ranges {:.2}/{:.2}/{:.2} m, bytes median {}, bands {bands:?}",
        quantile(&ranges, 0.25),
        quantile(&ranges, 0.5),
        quantile(&ranges, 0.75),
        quantile(&bytes, 0.5)
    );
    assert!((20.0..=600.0).contains(&per_frame), "{per_frame} a frame");
    assert!(quantile(&ranges, 0.75) - quantile(&ranges, 0.25) >= 0.3);
    assert!(ranges[0] >= 3.0, "nearest fog echo at {} m", ranges[0]);
    assert!((1..=6).contains(&quantile(&bytes, 0.5)));
    let ratio = bands[1] as f64 / bands[0] as f64;
    assert!(ratio >= 0.075, "30-40 m over 20-30 m: {ratio} ({bands:?})");
    // Thinner fog, fewer echoes; none at 10 km.
    let (at_300, ..) = fog_profile(&clear_plus(&fog_stage("300", "")), &frames);
    assert!(at_300 < per_frame / 10.0, "{at_300} at 300 m");
    let (at_10k, ..) = fog_profile(&clear_plus(&fog_stage("10000", "")), &frames);
    assert_eq!(at_10k, 0.0);
}

/// Issue 50: the fog's draws are one uniform per recorded return and one per vacant slot,
/// so a beam that reports an echo at V keeps reporting one as the fog thickens (common
/// random numbers across a sweep of V): the set of beams with an echo grows.
#[test]
fn a_sweep_of_visibility_keeps_each_beam_s_draw() {
    let dir = common::fixtures();
    let frames = frames_of(&dir.join("crossroad.pcap"), 0..1);
    let added = |v: &str| -> Vec<(u32, u8, u32)> {
        let chain = NoiseChain::new(&common::config(&clear_plus(&fog_stage(
            v,
            "empty_slots = true",
        ))));
        let out = chain.process(&frames[0]);
        let mut keys: Vec<_> = (out.clean_len..out.len())
            .filter(|&i| out.fate[i] == Fate::Added)
            .map(|i| {
                let r = &out.clean[i];
                (r.packet, r.laser, u32::from(r.block))
            })
            .collect();
        keys.sort_unstable();
        keys
    };
    let (thin, thick) = (added("120"), added("70"));
    assert!(
        !thin.is_empty() && thick.len() > thin.len(),
        "{} {}",
        thin.len(),
        thick.len()
    );
    let missing = thin
        .iter()
        .filter(|k| thick.binary_search(k).is_err())
        .count();
    assert_eq!(missing, 0, "beams with an echo at 120 m lost it at 70 m");
}

/// Issue 50: with the calibrated optics and the 4 ns pulse the fog's noiseless peak never
/// reaches the threshold at any visibility (0.58 of it at most, near V = 27 m): under the
/// threshold model fog only attenuates, and its echoes are the receiver's noise's.
#[test]
fn the_calibrated_noiseless_peak_never_reaches_the_threshold() {
    let f = Fog::new(
        1000.0,
        0.046,
        fog::TAU_H_NS,
        fog::hdl32e_overlap(),
        0.0,
        true,
    );
    assert_eq!(f.echo_onset_visibility_m(100.0, 1e-3), 0.0);
    let best = [10.0, 20.0, 25.0, 27.0, 30.0, 40.0, 60.0, 90.0]
        .iter()
        .map(|&v| {
            Fog::new(v, 0.046, fog::TAU_H_NS, fog::hdl32e_overlap(), 0.0, true).peak_power(100.0)
        })
        .fold(0.0f64, f64::max);
    assert!(best > 0.5e-3 && best < 0.65e-3, "{best}");
}
