//! RANSAC ground plane and the "none" method against ray-cast HDL-32E frames.

use crate::common::ground_scene;

use ground_scene::{make_return, precision_recall, Scene};
use lidar_noise::ground::{segment, GroundMethod, GroundOptions};
use rand::{RngCore, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn ransac() -> GroundOptions {
    GroundOptions {
        method: GroundMethod::Ransac,
        ..Default::default()
    }
}

#[test]
fn ransac_finds_the_flat_ground() {
    let (returns, truth) = Scene::street(0.0).frame(0.2, &[]);
    let mut rng = ChaCha8Rng::seed_from_u64(42);
    let labels = segment(&returns, &ransac(), &mut rng);
    let (p, r) = precision_recall(&labels, &truth);
    eprintln!("ransac flat: precision {p:.4} recall {r:.4}");
    assert!(r >= 0.95, "recall {r}");
    assert!(p >= 0.9, "precision {p}");
}

#[test]
fn ransac_finds_a_sloped_ground_within_the_tilt_limit() {
    let (returns, truth) = Scene::street(5.0).frame(0.2, &[]);
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let labels = segment(&returns, &ransac(), &mut rng);
    let (p, r) = precision_recall(&labels, &truth);
    eprintln!("ransac slope 5: precision {p:.4} recall {r:.4}");
    assert!(r >= 0.95 && p >= 0.9, "precision {p} recall {r}");

    // With a 2 degree tilt limit the 5 degree ground is not an admissible plane.
    let strict = GroundOptions {
        ransac_max_tilt_deg: 2.0,
        ..ransac()
    };
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let labels = segment(&returns, &strict, &mut rng);
    let (_, r) = precision_recall(&labels, &truth);
    assert!(r < 0.5, "tilt limit ignored: recall {r}");
}

#[test]
fn ransac_is_deterministic_for_a_seed() {
    let (returns, _) = Scene::street(0.0).frame(0.2, &[7, 5, 3, 1, 30]);
    let run = |seed| {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let labels = segment(&returns, &ransac(), &mut rng);
        (labels, rng.next_u64())
    };
    let (a, after_a) = run(9);
    let (b, after_b) = run(9);
    assert_eq!(a, b);
    assert_eq!(after_a, after_b, "the stream must advance identically");
}

#[test]
fn ransac_threshold_is_used() {
    // Ground points 0.5 m off the plane are not inliers at 0.2 m but are at 1 m.
    let mut returns = Vec::new();
    for k in 0..2000 {
        let az = k as f64 * 0.18;
        let el = -20.0 + (k % 10) as f64;
        let range = 1.8 / (-el).to_radians().sin();
        let mut r = make_return(range, az, el, 0, 0);
        if k % 4 == 0 {
            r.z += 0.5;
        }
        returns.push(r);
    }
    let count = |threshold| {
        let opts = GroundOptions {
            ransac_threshold_m: threshold,
            ..ransac()
        };
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        segment(&returns, &opts, &mut rng)
            .iter()
            .filter(|&&g| g)
            .count()
    };
    assert_eq!(count(0.2), 1500);
    assert_eq!(count(1.0), 2000);
}

#[test]
fn ransac_tiny_frames_do_not_panic() {
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    assert!(segment(&[], &ransac(), &mut rng).is_empty());
    let one = [make_return(5.0, 10.0, -20.0, 16, 8)];
    assert_eq!(segment(&one, &ransac(), &mut rng), vec![false]);
    // Three identical points: every triple is degenerate.
    let same = [one[0]; 3];
    assert_eq!(segment(&same, &ransac(), &mut rng), vec![false; 3]);
}

#[test]
fn none_labels_nothing_and_leaves_the_stream_alone() {
    let (returns, _) = Scene::street(0.0).frame(0.2, &[]);
    let opts = GroundOptions {
        method: GroundMethod::None,
        ..Default::default()
    };
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let labels = segment(&returns, &opts, &mut rng);
    assert_eq!(labels.len(), returns.len());
    assert!(labels.iter().all(|&g| !g));
    assert_eq!(rng.next_u64(), ChaCha8Rng::seed_from_u64(11).next_u64());
    assert!(segment(&[], &opts, &mut rng).is_empty());
}
