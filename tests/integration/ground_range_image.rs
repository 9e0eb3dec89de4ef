//! Range-image ground segmentation against ray-cast HDL-32E frames with exact labels.

use crate::common;
use crate::common::ground_scene;

use ground_scene::{make_return, precision_recall, precision_recall_where, Scene};
use lidar_noise::ground::{range_image, segment, GroundMethod, GroundOptions};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

/// The occlusion band of the reference study: rings 15..19.
const BAND: [u8; 5] = [7, 5, 3, 1, 30];

/// The range-image method (no longer the default, so named explicitly).
fn run(returns: &[lidar_noise::frame::Return]) -> Vec<bool> {
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let opts = GroundOptions {
        method: GroundMethod::RangeImage,
        ..GroundOptions::default()
    };
    segment(returns, &opts, &mut rng)
}

#[test]
fn flat_street_ground_is_found() {
    let (returns, truth) = Scene::street(0.0).frame(0.2, &[]);
    assert!(returns.len() > 30_000, "scene too small: {}", returns.len());
    let labels = run(&returns);
    assert_eq!(labels.len(), returns.len());
    let (p, r) = precision_recall(&labels, &truth);
    eprintln!("flat: precision {p:.4} recall {r:.4}");
    assert!(p >= 0.97 && r >= 0.97, "precision {p} recall {r}");
    // Obstacles must stay: most car, wall and pole returns are not ground.
    let objects: Vec<bool> = truth.iter().map(|t| !t).collect();
    let kept = labels
        .iter()
        .zip(&objects)
        .filter(|(&l, &o)| o && !l)
        .count();
    let total = objects.iter().filter(|&&o| o).count();
    assert!(total > 1000, "scene has {total} object returns");
    assert!(kept as f64 / total as f64 >= 0.97, "{kept} of {total} kept");
}

#[test]
fn occluded_band_of_lasers_is_bridged() {
    let (returns, truth) = Scene::street(0.0).frame(0.2, &BAND);
    assert!(returns.iter().all(|r| !(15..=19).contains(&r.ring)));
    let labels = run(&returns);
    let (p, r) = precision_recall(&labels, &truth);
    eprintln!("band: precision {p:.4} recall {r:.4}");
    assert!(p >= 0.95 && r >= 0.95, "precision {p} recall {r}");
    // The ground beyond the band (rings 20 and up) is reachable only across it.
    let above: Vec<bool> = returns.iter().map(|r| r.ring >= 20).collect();
    let (pa, ra) = precision_recall_where(&labels, &truth, &above);
    eprintln!("band, rings >= 20: precision {pa:.4} recall {ra:.4}");
    assert!(ra >= 0.9, "ground beyond the band: recall {ra}");
}

#[test]
fn band_occluded_in_a_sector_only_is_bridged() {
    // A mud spot: the band is missing only between 90 and 200 degrees.
    let (returns, truth) = Scene::street(0.0).frame_filtered(0.2, |laser, az| {
        !(BAND.contains(&laser) && (90.0..200.0).contains(&az))
    });
    let labels = run(&returns);
    let (p, r) = precision_recall(&labels, &truth);
    eprintln!("sector band: precision {p:.4} recall {r:.4}");
    assert!(p >= 0.95 && r >= 0.95, "precision {p} recall {r}");
}

#[test]
fn sloped_ground_is_found() {
    let (returns, truth) = Scene::street(5.0).frame(0.2, &[]);
    let labels = run(&returns);
    let (p, r) = precision_recall(&labels, &truth);
    eprintln!("slope 5: precision {p:.4} recall {r:.4}");
    assert!(p >= 0.95 && r >= 0.95, "precision {p} recall {r}");
}

#[test]
fn real_azimuth_step_is_measured() {
    // 11.8 Hz like the shared capture: 0.19 degrees per firing, not the 0.2 default.
    let (returns, truth) = Scene::street(0.0).frame(0.19, &[]);
    let cols = range_image::column_count(&returns);
    assert!((1890..=1900).contains(&cols), "{cols} columns");
    let labels = run(&returns);
    let (p, r) = precision_recall(&labels, &truth);
    eprintln!("0.19 step: precision {p:.4} recall {r:.4}");
    assert!(p >= 0.97 && r >= 0.97, "precision {p} recall {r}");
}

#[test]
fn small_range_noise_is_tolerated() {
    // Rain-like jitter: 1 cm standard deviation, drawn from a seeded stream.
    let (mut returns, truth) = Scene::street(0.0).frame(0.2, &[]);
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let noise = Normal::new(0.0, 0.01).unwrap();
    for r in &mut returns {
        let range = f64::from(r.range) + noise.sample(&mut rng);
        *r = make_return(
            range,
            f64::from(r.azimuth),
            f64::from(r.elevation),
            r.laser,
            r.ring,
        );
    }
    let labels = run(&returns);
    let (p, r) = precision_recall(&labels, &truth);
    eprintln!("1 cm noise: precision {p:.4} recall {r:.4}");
    assert!(p >= 0.95 && r >= 0.9, "precision {p} recall {r}");
}

#[test]
fn dual_returns_share_the_cell_label() {
    let (returns, _) = Scene::street(0.0).frame(0.2, &[]);
    let single = run(&returns);
    // Every firing also reports a farther second return, as in dual mode.
    let mut dual = Vec::with_capacity(2 * returns.len());
    for r in &returns {
        dual.push(*r);
        let far = make_return(
            f64::from(r.range) + 3.0,
            f64::from(r.azimuth),
            f64::from(r.elevation),
            r.laser,
            r.ring,
        );
        dual.push(far);
    }
    let labels = run(&dual);
    assert_eq!(labels.len(), dual.len());
    for (i, pair) in labels.chunks(2).enumerate() {
        assert_eq!(pair[0], pair[1], "pair {i} split");
        assert_eq!(pair[0], single[i], "return {i} changed label");
    }
}

#[test]
fn same_input_same_labels() {
    let (returns, _) = Scene::street(5.0).frame(0.2, &BAND);
    assert_eq!(run(&returns), run(&returns));
}

#[test]
fn tiny_frames_do_not_panic() {
    assert!(run(&[]).is_empty());
    let one = [make_return(5.0, 10.0, -20.0, 16, 8)];
    assert_eq!(run(&one), vec![false], "a lone return has no slope");
    let two = [
        make_return(5.0, 10.0, -20.0, 16, 8),
        make_return(6.0, 10.0, -18.67, 18, 9),
    ];
    assert_eq!(run(&two).len(), 2);
    let mut nan = make_return(5.0, 10.0, -20.0, 16, 8);
    nan.x = f32::NAN;
    nan.azimuth = f32::NAN;
    assert_eq!(run(&[nan]), vec![false]);
}

#[test]
fn strict_settings_lose_a_slope() {
    // On a 5 degree slope only columns along the contour are flatter than 1 degree, and a
    // 0.01 degree delta lets almost nothing grow: most of the ground must be lost, which
    // shows both settings reach the algorithm.
    let (returns, truth) = Scene::street(5.0).frame(0.2, &[]);
    let opts = GroundOptions {
        method: GroundMethod::RangeImage,
        initial_angle_deg: 1.0,
        max_angle_delta_deg: 0.01,
        ..Default::default()
    };
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let labels = segment(&returns, &opts, &mut rng);
    let (_, r) = precision_recall(&labels, &truth);
    assert!(r < 0.5, "settings ignored: recall {r}");
}

/// `segment` decides on approximate angles where they are decided by more than a margin
/// and on the exact `atan2` angles otherwise: its labels must be those of the exact
/// angles everywhere (margin infinite), and so must a very wide margin's (most
/// comparisons then take the exact path), on noisy synthetic streets (several seeds,
/// slopes, noise levels and settings, with and without the occluded band) and on the
/// shared capture's frames through the paper chain.
#[test]
fn approximate_angles_decide_like_exact_ones() {
    let check = |returns: &[lidar_noise::frame::Return], what: &str| {
        for (initial, delta) in [(30.0, 5.0), (10.0, 1.0), (45.0, 0.5)] {
            let exact = range_image::segment_with_margin(returns, initial, delta, f64::INFINITY);
            let fast = range_image::segment(returns, initial, delta);
            assert_eq!(fast, exact, "{what}, initial {initial}, delta {delta}");
            let wide = range_image::segment_with_margin(returns, initial, delta, 30.0);
            assert_eq!(
                wide, exact,
                "{what}, margin 30, initial {initial}, delta {delta}"
            );
            // Margins below the safe one (and NaN) are raised to it, not taken.
            for small in [0.0, -1.0, f64::NAN] {
                let got = range_image::segment_with_margin(returns, initial, delta, small);
                assert_eq!(got, exact, "{what}, margin {small}");
            }
            assert!(exact.iter().any(|&g| g), "{what}: some ground");
        }
    };
    for seed in 0..6u64 {
        let slope = [0.0, 5.0, -3.0][seed as usize % 3];
        let band: &[u8] = if seed % 2 == 0 { &[] } else { &BAND };
        let (mut returns, _) = Scene::street(slope).frame(0.2, band);
        // Range noise from none to Goodin's 0.02 R at heavy rain.
        let mut rng = ChaCha8Rng::seed_from_u64(100 + seed);
        let per_m = [0.0, 0.001, 0.005, 0.02, 0.0005, 0.01][seed as usize];
        let z = Normal::new(0.0, 1.0).unwrap();
        for r in &mut returns {
            let range = f64::from(r.range) * (1.0 + per_m * z.sample(&mut rng));
            *r = make_return(
                range,
                f64::from(r.azimuth),
                f64::from(r.elevation),
                r.laser,
                r.ring,
            );
        }
        check(&returns, &format!("street seed {seed}"));
    }
    let Some(capture) = common::shared("hdl32e/monterey.pcap") else {
        return;
    };
    let (cfg, _) = lidar_noise::config::Config::load(
        Some(&std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("configs/paper.toml")),
        &[],
        None,
    )
    .expect("paper.toml");
    let chain = lidar_noise::noise::NoiseChain::new(&cfg);
    let options = lidar_noise::sensor::frames::DecoderOptions::default();
    let reader = lidar_noise::sensor::frames::FrameReader::open(&capture, &options).unwrap();
    for frame in reader.take(6) {
        let frame = frame.unwrap();
        let survivors = chain.process(&frame).survivors();
        check(&survivors, &format!("monterey frame {}", frame.index));
    }
}
