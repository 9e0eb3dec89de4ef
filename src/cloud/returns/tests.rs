//! Unit tests of `returns`.

use super::*;
use crate::sensor::HDL32E;

/// Each build of the geometry loop this processor runs (AVX2, AVX-512) gives the
/// baseline build's bits, on points all around the sensor and at every scale, with
/// zeros, signed zeros and values that are not finite.
#[test]
fn every_geometry_build_gives_the_plain_loops_bits() {
    use rand::{Rng, SeedableRng};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(17);
    let special = [
        0.0f32,
        -0.0,
        f32::NAN,
        f32::INFINITY,
        -f32::INFINITY,
        1e-30,
        3e38,
    ];
    let chunk: Vec<CloudPoint> = (0..CHUNK)
        .map(|i| {
            let mut c = [0, 1, 2, 3].map(|_| {
                let scale = 10f32.powi(rng.random_range(-3..4));
                rng.random_range(-1.0f32..1.0) * scale
            });
            if i % 13 == 0 {
                c[i / 13 % 4] = special[i / 52 % special.len()];
            }
            CloudPoint {
                x: c[0],
                y: c[1],
                z: c[2],
                intensity: c[3].abs(),
                ring: None,
                time: None,
            }
        })
        .collect();
    let rows = |g: &Geometry| {
        let f = |v: &[f64; CHUNK]| v.map(f64::to_bits);
        (
            [g.range, g.horizontal, g.azimuth, g.elevation, g.steps].map(|v| f(&v)),
            g.raw,
            g.intensity,
            g.finite,
        )
    };
    let (steps, unit, scale) = (2083.0 / 360.0, 0.002, 255.0);
    let mut plain = Box::<Geometry>::default();
    plain.of_any(&chunk, steps, unit, scale);
    let want = rows(&plain);
    // A point that is not finite is flagged; the rest are.
    assert!(want.3.iter().any(|&f| !f) && want.3.iter().filter(|&&f| f).count() > CHUNK / 2);
    let mut g = Box::<Geometry>::default();
    g.of(&chunk, steps, unit, scale);
    assert!(rows(&g) == want, "picked");
    #[cfg(target_arch = "x86_64")]
    {
        if std::arch::is_x86_feature_detected!("avx2") {
            let mut g = Box::<Geometry>::default();
            // SAFETY: the processor has AVX2 (checked on the line above).
            unsafe { g.of_avx2(&chunk, steps, unit, scale) };
            assert!(rows(&g) == want, "avx2");
        }
        if crate::numeric::avx512() {
            let mut g = Box::<Geometry>::default();
            // SAFETY: the processor has AVX-512 F and DQ (checked on the line above).
            unsafe { g.of_avx512(&chunk, steps, unit, scale) };
            assert!(rows(&g) == want, "avx512");
        }
    }
}

fn point(x: f32, y: f32, z: f32, intensity: f32, ring: Option<u16>) -> CloudPoint {
    CloudPoint {
        x,
        y,
        z,
        intensity,
        ring,
        time: None,
    }
}

/// The point laser `laser` would measure at `range` in firing `k` of a 10 Hz turn,
/// written from the sensor's description (not from the code under test).
fn on_grid(k: u32, laser: usize, range: f64) -> CloudPoint {
    // 46.08 us a firing, 1.152 us a laser; 10 Hz is 3.6e-3 degrees a microsecond.
    let az = (f64::from(k) * 46.08 + laser as f64 * 1.152) * 3.6e-3;
    let el = crate::sensor::calibration::BUILTIN_ELEVATION_DEG[laser];
    let (sa, ca) = az.to_radians().sin_cos();
    let (se, ce) = el.to_radians().sin_cos();
    point(
        (range * ce * ca) as f32,
        (-range * ce * sa) as f32,
        (range * se) as f32,
        100.0,
        None,
    )
}

#[test]
fn each_models_shared_table_is_built_once_and_is_its_own() {
    for model in crate::sensor::MODELS {
        let shared = BeamTable::of(model);
        assert!(
            Arc::ptr_eq(&shared, &BeamTable::of(model)),
            "{}",
            model.name
        );
        let fresh = BeamTable::new(model);
        assert_eq!(shared.by_elevation, fresh.by_elevation, "{}", model.name);
        assert_eq!(shared.direct, fresh.direct, "{}", model.name);
        assert_eq!(shared.bounds, fresh.bounds, "{}", model.name);
    }
    // Same lasers, another table: a model that differs only in its elevations gets
    // its own entry.
    let a = &crate::sensor::HDL64E_S2;
    let b = &crate::sensor::HDL64E_KITTI;
    assert!(!Arc::ptr_eq(&BeamTable::of(a), &BeamTable::of(b)));
}

#[test]
fn the_binned_search_is_the_partition_point() {
    use rand::{Rng, SeedableRng};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
    for model in crate::sensor::MODELS {
        let beams = BeamTable::new(model);
        let want = |e: f64| beams.bounds.partition_point(|&b| b < e);
        let mut elevations = vec![-90.0, 90.0, -1e9, 1e9, 0.0, -0.0];
        for &b in &beams.bounds {
            elevations.extend([b, b.next_down(), b.next_up()]);
        }
        for bin in 0..=2880 {
            let start = -90.0 + f64::from(bin) / BINS_PER_DEG;
            elevations.extend([start, start.next_down(), start.next_up()]);
        }
        elevations.extend((0..20_000).map(|_| rng.random_range(-95.0..95.0)));
        for e in elevations {
            assert_eq!(beams.first_at_or_above(e), want(e), "{} at {e}", model.name);
        }
    }
}

#[test]
fn the_direct_table_gives_the_search_answer() {
    use rand::{Rng, SeedableRng};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(12);
    for model in crate::sensor::MODELS {
        let beams = BeamTable::new(model);
        let looked_up = beams.direct.iter().filter(|&&d| d != DIRECT_SEARCH).count();
        assert!(
            looked_up * 100 > beams.direct.len() * 95,
            "{}: {looked_up} of {} bins looked up",
            model.name,
            beams.direct.len()
        );
        let mut elevations = vec![-90.0, 90.0, -1e9, 1e9, 0.0, -0.0];
        // Every bin's edges and middle, and the places the answer changes, each with
        // its neighbouring floats.
        for b in 0..=beams.direct.len() {
            let start = -90.0 + b as f64 / DIRECT_BINS_PER_DEG;
            elevations.extend([start, start + 0.5 / DIRECT_BINS_PER_DEG]);
        }
        let n = beams.elevation.len();
        for i in 0..n {
            let e = beams.elevation[i];
            for j in [i.saturating_sub(1), (i + 1).min(n - 1)] {
                let q = 0.25 * (beams.elevation[j] - e).abs();
                elevations.extend([e, e + q, e - q]);
            }
        }
        elevations.extend(beams.bounds.iter().copied());
        let mut around = Vec::new();
        for &e in &elevations {
            let (mut up, mut down) = (e, e);
            for _ in 0..3 {
                (up, down) = (up.next_up(), down.next_down());
                around.extend([up, down]);
            }
        }
        elevations.extend(around);
        elevations.extend((0..200_000).map(|_| rng.random_range(-91.0..91.0)));
        for e in elevations {
            assert_eq!(beams.nearest(e), beams.searched(e), "{} at {e}", model.name);
        }
    }
}

#[test]
fn a_point_on_the_grid_gets_its_firing_laser_and_time() {
    let opts = ReturnsOptions::default();
    for (k, laser) in [(0u32, 0usize), (1, 31), (100, 15), (1085, 7), (2169, 30)] {
        let out = to_returns(&[on_grid(k, laser, 20.0)], &HDL32E, &opts, "t").unwrap();
        let r = out.returns[0];
        assert_eq!(out.firings, 2170);
        assert_eq!(usize::from(r.laser), laser, "firing {k}");
        assert_eq!(r.packet, k / 12, "firing {k}");
        assert_eq!(u32::from(r.block), k % 12, "firing {k}");
        let t = (f64::from(k) * 46.08 + laser as f64 * 1.152) * 1e-6;
        assert!((r.time - t).abs() < 1e-12, "firing {k}: {} vs {t}", r.time);
        assert!((r.range - 20.0).abs() < 1e-4);
        assert!(
            (f64::from(r.elevation) - crate::sensor::calibration::BUILTIN_ELEVATION_DEG[laser])
                .abs()
                < 1e-3
        );
        assert_eq!(r.raw_distance, 10_000);
        assert_eq!(r.ring, HDL32E.rings()[laser]);
    }
}

/// The point laser `laser` of `model` would measure at `range` in firing `k` of a
/// 10 Hz turn, from the manuals' numbers written out here: `fire_us` is the laser's
/// time in its firing sequence, `az_offset` its azimuth offset, `el` its elevation.
fn model_point(seq_us: f64, k: u32, fire_us: f64, az_offset: f64, el: f64) -> CloudPoint {
    let az = (f64::from(k) * seq_us + fire_us) * 3.6e-3 + az_offset;
    let (sa, ca) = az.to_radians().sin_cos();
    let (se, ce) = el.to_radians().sin_cos();
    let range = 15.0;
    point(
        (range * ce * ca) as f32,
        (-range * ce * sa) as f32,
        (range * se) as f32,
        10.0,
        None,
    )
}

#[test]
fn every_model_places_a_grid_point_on_its_firing_laser_and_time() {
    use crate::sensor::{HDL64E_S2, HDL64E_S3, PUCK_HI_RES, VLP16, VLP32C};
    let opts = ReturnsOptions::default();
    // (model, sequence us, firings a turn at 10 Hz, firings a packet, firing k,
    // laser, its firing time in the sequence, azimuth offset, elevation)
    let cases = [
        // VLP-16 manual 9.5: laser 9 fires 9 * 2.304 us into its 55.296 us sequence;
        // Table 9-1: +9 deg. 24 sequences a packet.
        (
            &VLP16,
            55.296,
            1808,
            24,
            700u32,
            9usize,
            9.0 * 2.304,
            0.0,
            9.0,
        ),
        (&PUCK_HI_RES, 55.296, 1808, 24, 1807, 0, 0.0, 0.0, -10.0),
        // VLP-32C: lasers in pairs every 2.304 us, laser 29 is pair 14: 32.256 us;
        // Table 9-1: +15 deg, azimuth offset -1.4 deg.
        (&VLP32C, 55.296, 1808, 12, 100, 29, 14.0 * 2.304, -1.4, 15.0),
        // HDL-64E S2: 48 us firings, groups of four 6 us apart, 0/1.26/2.46/3.66 us
        // in a group; laser 37 (lower bank, lane 5: group 1, second) fires at 7.26 us;
        // VeloView's HDL-64.xml: -20.34 deg, azimuth offset -2.96 deg.
        (
            &HDL64E_S2,
            48.0,
            2083,
            6,
            1000,
            37,
            6.0 + 1.26,
            -2.96,
            -20.34,
        ),
        // Laser 2 (upper bank, lane 2): 2.46 us; +1.15 deg, azimuth offset -3.3 deg:
        // firing 0's direction is 356.7 deg, on the circle's far side.
        (&HDL64E_S2, 48.0, 2083, 6, 0, 2, 2.46, -3.3, 1.15),
        // HDL-64E S3: 57.6 us firings, groups 7.2 us apart, 0/1.3/2.5/3.7 us; laser 63
        // (lower bank, lane 31: group 7, fourth): 7 * 7.2 + 3.7 us; -11.12 deg, -1.54.
        (
            &HDL64E_S3,
            57.6,
            1736,
            6,
            1735,
            63,
            7.0 * 7.2 + 3.7,
            -1.54,
            -11.12,
        ),
    ];
    for (model, seq, n, per_packet, k, laser, fire_us, az_offset, el) in cases {
        let p = model_point(seq, k, fire_us, az_offset, el);
        let out = to_returns(&[p], model, &opts, "t").unwrap();
        let r = out.returns[0];
        let what = format!("{} firing {k} laser {laser}", model.name);
        assert_eq!(out.firings, n, "{what}");
        assert_eq!(usize::from(r.laser), laser, "{what}");
        assert_eq!(r.packet, k / per_packet, "{what}");
        assert_eq!(u32::from(r.block), k % per_packet, "{what}");
        let t = (f64::from(k) * seq + fire_us) * 1e-6;
        assert!((r.time - t).abs() < 1e-9, "{what}: {} vs {t}", r.time);
        assert_eq!(out.from_elevation, 1);
    }
}

#[test]
fn the_elevation_says_when_the_laser_is_a_guess() {
    use crate::sensor::{HDL64E_S2, VLP16};
    let beams = BeamTable::new(&VLP16);
    // VLP-16 beams every 2 deg: +1.2 deg is laser 1 (+1), sure; +1.6 and +2.4 are in
    // the middle half between +1 and +3 (laser 3).
    assert_eq!(beams.nearest(1.2), (1, false));
    assert_eq!(beams.nearest(1.6), (1, true));
    assert_eq!(beams.nearest(2.4), (3, true));
    assert_eq!(beams.nearest(2.6), (3, false));
    // Beyond the top beam (+15, laser 15) by more than half a spacing.
    assert_eq!(beams.nearest(15.4), (15, false));
    assert_eq!(beams.nearest(16.0), (15, true));
    // HDL-64E: -9.37 (laser 56) and -9.15 (laser 57) are 0.22 deg apart.
    let beams = BeamTable::new(&HDL64E_S2);
    assert_eq!(beams.nearest(-9.36), (56, false));
    assert_eq!(beams.nearest(-9.2), (57, false));
    assert_eq!(beams.nearest(-9.29), (56, true));
}

#[test]
fn kittis_table_orders_its_64_lasers_as_the_default_within_the_hdl64e_span() {
    use crate::sensor::{HDL64E_KITTI, HDL64E_S2};
    let (el, dz) = (HDL64E_KITTI.elevation_deg, HDL64E_KITTI.vertical_offset_mm);
    assert_eq!((el.len(), dz.len(), HDL64E_KITTI.lasers), (64, 64, 64));
    // The lasers in the same order by elevation as the default table's, so a ring
    // means the same laser with either.
    assert_eq!(HDL64E_KITTI.rings(), HDL64E_S2.rings());
    // Within the default span widened by 1.5 deg (+2.81 to -23.95); the HDL-64E
    // manuals give +2 to -24.8 deg.
    for (l, &e) in el.iter().enumerate() {
        assert!((-25.45..=4.31).contains(&e), "laser {l}: {e} deg");
    }
    // Beams at least 0.2 deg apart, from the lowest up (the KITTI beams are 0.25 to
    // 0.67 deg apart).
    let beams = BeamTable::new(&HDL64E_KITTI);
    for w in beams.elevation.windows(2) {
        assert!(w[1] - w[0] >= 0.2, "{w:?}");
    }
    // Upper bank (lasers 0-31) about 0.2 m above the origin, lower bank about 0.12 m.
    for (l, &mm) in dz.iter().enumerate() {
        let want = if l < 32 { 190.0..=215.0 } else { 115.0..=130.0 };
        assert!(want.contains(&mm), "laser {l}: {mm} mm");
    }
    // The beams' heights rise with the ring at every distance beyond 0.2 m, which the
    // search of `nearest_at` needs.
    for h in [0.2, 0.5, 1.0, 5.0, 30.0, 120.0] {
        let at: Vec<f64> = (0..64)
            .map(|k| h * beams.slope[k] + beams.origin_m[k])
            .collect();
        assert!(at.windows(2).all(|w| w[1] > w[0]), "at {h} m");
    }
}

#[test]
fn only_kittis_beams_are_matched_in_height() {
    use crate::sensor::{HDL64E_KITTI, MODELS};
    // Every other model: `nearest_at` is `nearest` on the elevation, whatever h and z.
    for m in MODELS {
        let beams = BeamTable::new(m);
        for i in 0..2000 {
            let h = 0.5 + f64::from(i % 97) * 0.7;
            let z = -3.0 + f64::from(i % 89) * 0.05;
            let e = z.atan2(h).to_degrees();
            assert_eq!(beams.nearest_at(h, z, e), beams.nearest(e), "{}", m.name);
        }
    }
    // KITTI's: a point of laser 29 (the top beam, +1.937 deg from 209.2 mm up) at 5 m
    // is seen at +4.3 deg from the origin, above every beam of the elevation table.
    let beams = BeamTable::new(&HDL64E_KITTI);
    let (h, el, dz) = (5.0, 1.937_f64, 0.2092);
    let z = h * el.to_radians().tan() + dz;
    let e = z.atan2(h).to_degrees();
    assert!(e > 4.2, "{e}");
    assert_eq!(beams.nearest_at(h, z, e), (29, false));
    // Laser 38 (the bottom beam, -25.163 deg, 124.7 mm) at 3 m, and halfway between
    // laser 38 and the next beam up (laser 39, -24.648 deg): ambiguous.
    let low = |el: f64| 3.0 * el.to_radians().tan() + 0.1247;
    let z = low(-25.163);
    assert_eq!(
        beams.nearest_at(3.0, z, z.atan2(3.0).to_degrees()),
        (38, false)
    );
    let z = 0.5 * (low(-25.163) + low(-24.648)) - 1e-4;
    assert_eq!(
        beams.nearest_at(3.0, z, z.atan2(3.0).to_degrees()),
        (38, true)
    );
}

#[test]
fn the_ring_decides_the_laser_when_given() {
    // Ring 31 is the top beam (+10.67 deg, laser 31) even for a point at -30 deg.
    let p = point(10.0, 0.0, -5.0, 1.0, Some(31));
    let out = to_returns(&[p], &HDL32E, &ReturnsOptions::default(), "t").unwrap();
    assert_eq!(out.returns[0].laser, 31);
    assert_eq!(out.returns[0].ring, 31);
    // Without a ring, the nearest elevation: atan(-5/10) = -26.57 deg, laser 6 (-26.67).
    let p = point(10.0, 0.0, -5.0, 1.0, None);
    let out = to_returns(&[p], &HDL32E, &ReturnsOptions::default(), "t").unwrap();
    assert_eq!(out.returns[0].laser, 6);
}

#[test]
fn returns_come_in_firing_order_with_the_input_index() {
    // Input in reverse firing order; a taken slot moves the later point to the firing
    // before (the nearer side searched first is the earlier one).
    let pts = vec![
        on_grid(500, 3, 10.0),
        on_grid(20, 9, 10.0),
        on_grid(20, 4, 10.0),
        on_grid(20, 4, 11.0),
    ];
    let out = to_returns(&pts, &HDL32E, &ReturnsOptions::default(), "t").unwrap();
    assert_eq!(out.order, vec![3, 2, 1, 0]);
    let firing = |r: &Return| r.packet * 12 + u32::from(r.block);
    let f: Vec<u32> = out.returns.iter().map(firing).collect();
    assert_eq!(f, vec![19, 20, 20, 500]);
    assert_eq!(out.returns[0].range, 11.0);
    assert_eq!((out.moved, out.shared), (1, 0));
}

#[test]
fn a_collision_moves_one_point_not_the_rest_of_its_line() {
    // One laser's line in file order running down the firings, as KITTI stores it,
    // with a second point in firing 8 (a half step) and firing 3 left empty.
    let ks = [10, 9, 8, 8, 7, 6, 5, 4, 2];
    let pts: Vec<CloudPoint> = ks.iter().map(|&k| on_grid(k, 5, 10.0)).collect();
    let out = to_returns(&pts, &HDL32E, &ReturnsOptions::default(), "t").unwrap();
    let firing = |r: &Return| r.packet * 12 + u32::from(r.block);
    let mut by_point = vec![0; ks.len()];
    for (r, &i) in out.returns.iter().zip(&out.order) {
        by_point[i as usize] = firing(r);
    }
    // Every other point keeps its own firing; the second of firing 8 takes the only
    // firing within two that no point claims (3 is too far; 6 and 7 are claimed).
    assert_eq!(by_point, vec![10, 9, 8, 8, 7, 6, 5, 4, 2]);
    assert_eq!((out.moved, out.shared), (0, 1));
    let pts: Vec<CloudPoint> = [10, 9, 8, 8, 6, 5]
        .iter()
        .map(|&k| on_grid(k, 5, 10.0))
        .collect();
    let out = to_returns(&pts, &HDL32E, &ReturnsOptions::default(), "t").unwrap();
    let mut by_point = vec![0; pts.len()];
    for (r, &i) in out.returns.iter().zip(&out.order) {
        by_point[i as usize] = firing(r);
    }
    assert_eq!(by_point, vec![10, 9, 8, 7, 6, 5]);
    assert_eq!((out.moved, out.shared), (1, 0));
}

#[test]
fn a_full_slot_neighbourhood_is_shared_and_counted() {
    let pts: Vec<CloudPoint> = (0..7).map(|_| on_grid(40, 0, 10.0)).collect();
    let out = to_returns(&pts, &HDL32E, &ReturnsOptions::default(), "t").unwrap();
    assert_eq!((out.moved, out.shared), (4, 2));
}

#[test]
fn points_sharing_slots_follow_their_slots_own_point_in_file_order() {
    // Crowded slots in file order against slot order (a later firing first, lasers
    // interleaved), ranges telling the points apart: each of the crowded slots keeps
    // its first point, the neighbours within reach take four more, the rest share.
    let crowds = [(300, 7), (40, 0), (40, 1), (41, 0), (12, 31)];
    let pts: Vec<CloudPoint> = (0..9)
        .flat_map(|n| {
            crowds
                .iter()
                .map(move |&(k, l)| on_grid(k, l, 10.0 + f64::from(n) * 0.01))
        })
        .collect();
    let out = to_returns(&pts, &HDL32E, &ReturnsOptions::default(), "t").unwrap();
    assert!(out.shared >= 8, "{}", out.shared);
    assert_eq!(out.order.len(), pts.len());
    // Returns in firing order, then laser, then file order: strictly ascending.
    let key = |r: &Return, i: u32| (r.packet * 12 + u32::from(r.block), r.laser, i);
    let keys: Vec<_> = out
        .returns
        .iter()
        .zip(&out.order)
        .map(|(r, &i)| key(r, i))
        .collect();
    assert!(keys.windows(2).all(|w| w[0] < w[1]), "{keys:?}");
    // Each point once, at its own range.
    let mut seen = out.order.clone();
    seen.sort_unstable();
    assert!(seen.iter().copied().eq(0..pts.len() as u32));
    for (r, &i) in out.returns.iter().zip(&out.order) {
        let p = &pts[i as usize];
        let (x, y, z) = (f64::from(p.x), f64::from(p.y), f64::from(p.z));
        assert_eq!(r.range, (x * x + y * y + z * z).sqrt() as f32, "point {i}");
    }
}

#[test]
fn intensity_scales_by_format() {
    let p = point(5.0, 1.0, 0.0, 0.5, None);
    let unit = ReturnsOptions {
        intensity_scale: IntensityScale::Unit,
        ..ReturnsOptions::default()
    };
    let out = to_returns(&[p], &HDL32E, &unit, "t").unwrap();
    assert_eq!(out.returns[0].intensity, 128);
    let p = point(5.0, 1.0, 0.0, 300.0, None);
    let out = to_returns(&[p], &HDL32E, &ReturnsOptions::default(), "t").unwrap();
    assert_eq!(out.returns[0].intensity, 255);
}

#[test]
fn bad_points_are_refused_with_their_index() {
    let opts = ReturnsOptions::default();
    let mut pts = vec![point(1.0, 2.0, 3.0, 4.0, None); 5];
    pts[3].y = f32::NAN;
    let e = to_returns(&pts, &HDL32E, &opts, "scan.bin")
        .unwrap_err()
        .to_string();
    assert!(e.contains("scan.bin: point 3 (0-based): y is NaN"), "{e}");
    pts[3].y = 0.0;
    pts[4].ring = Some(32);
    let e = to_returns(&pts, &HDL32E, &opts, "scan.bin")
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("point 4 (0-based): ring 32 is out of range"),
        "{e}"
    );
    let slow = ReturnsOptions {
        rotation_hz: 1.0,
        ..opts
    };
    let e = to_returns(&pts[..1], &HDL32E, &slow, "t")
        .unwrap_err()
        .to_string();
    assert!(e.contains("rotation_hz 1"), "{e}");
}

#[test]
fn the_origin_is_a_return_at_zero_range_not_a_nan() {
    let out = to_returns(
        &[point(0.0, 0.0, 0.0, 0.0, None)],
        &HDL32E,
        &ReturnsOptions::default(),
        "t",
    )
    .unwrap();
    let r = out.returns[0];
    assert_eq!((r.range, r.azimuth, r.elevation), (0.0, 0.0, 0.0));
}

/// A turn whose motor speeds up and slows down (the azimuth step of a firing from
/// 0.13 to 0.23 degree, a real sensor's rate varies less), every laser of every
/// firing, each point with its time in `unit_s` (the firing's start from `t0` plus
/// the laser's offset).
fn uneven_turn(firings: u32, unit_s: f64, t0: f64) -> Vec<CloudPoint> {
    let mut pts = Vec::new();
    let mut az = 0.0f64;
    for k in 0..firings {
        for laser in 0..32 {
            let el = crate::sensor::calibration::BUILTIN_ELEVATION_DEG[laser];
            let (sa, ca) = az.to_radians().sin_cos();
            let (se, ce) = el.to_radians().sin_cos();
            let t_us = f64::from(k) * 46.08 + HDL32E.laser_offset_us(laser);
            let mut p = point(
                (10.0 * ce * ca) as f32,
                (-10.0 * ce * sa) as f32,
                (10.0 * se) as f32,
                50.0,
                Some(u16::from(HDL32E.rings()[laser])),
            );
            p.time = Some(t0 + t_us * 1e-6 / unit_s);
            pts.push(p);
        }
        az += 0.18 + 0.05 * (f64::from(k) * 0.01).sin();
    }
    pts
}

#[test]
fn points_with_times_keep_their_own_firings() {
    let options = ReturnsOptions::default();
    for (unit, unit_s, t0) in [
        ("s", 1.0, 1.5e9),
        ("ms", 1e-3, 0.0),
        ("us", 1e-6, 7.0),
        ("ns", 1e-9, 0.0),
    ] {
        let pts = uneven_turn(1500, unit_s, t0);
        let out = to_returns(&pts, &HDL32E, &options, "t").unwrap();
        assert_eq!(out.time.map(|t| t.unit), Some(unit));
        assert_eq!((out.firings, out.moved, out.shared), (1500, 0, 0), "{unit}");
        for (j, r) in out.returns.iter().enumerate() {
            let i = out.order[j] as usize;
            assert_eq!(i, j, "{unit}: file order is firing order");
            let k = (i / 32) as u32;
            assert_eq!(r.packet * 12 + u32::from(r.block), k, "{unit}: point {i}");
            let want = pts[i].time.unwrap() - pts[0].time.unwrap();
            assert!((r.time - want * unit_s).abs() < 1e-6, "{unit}: point {i}");
        }
        // The same points by azimuth: the speeding turn puts some on other firings.
        let untimed: Vec<CloudPoint> = pts
            .iter()
            .map(|p| CloudPoint { time: None, ..*p })
            .collect();
        let out = to_returns(&untimed, &HDL32E, &options, "t").unwrap();
        assert_eq!(out.time, None);
        let off = out
            .returns
            .iter()
            .zip(&out.order)
            .filter(|(r, &i)| r.packet * 12 + u32::from(r.block) != i / 32)
            .count();
        assert!(off > 1000, "{unit}: {off}");
    }
}

#[test]
fn times_that_cannot_place_points_leave_them_to_the_azimuth() {
    let options = ReturnsOptions::default();
    // All equal (a scan's one stamp on every point), and several turns in seconds.
    let mut same = uneven_turn(100, 1.0, 0.0);
    same.iter_mut().for_each(|p| p.time = Some(3.0));
    let mut long = uneven_turn(100, 1.0, 0.0);
    long.last_mut().unwrap().time = Some(1e12);
    for pts in [same, long] {
        let out = to_returns(&pts, &HDL32E, &options, "t").unwrap();
        assert_eq!(out.time, None);
        assert_eq!(out.firings, 2170);
    }
    // Two points of one firing and laser (a dual return) share its slot.
    let mut pts = uneven_turn(10, 1.0, 0.0);
    let twin = pts[33];
    pts.push(twin);
    let out = to_returns(&pts, &HDL32E, &options, "t").unwrap();
    assert_eq!((out.moved, out.shared), (0, 1));
    assert_eq!(out.order[34], 320);
    // A time that is not a number is refused with its point.
    let mut pts = uneven_turn(10, 1.0, 0.0);
    pts[7].time = Some(f64::NAN);
    let e = to_returns(&pts, &HDL32E, &options, "t").unwrap_err();
    assert!(
        e.to_string().contains("point 7 (0-based): time is NaN"),
        "{e}"
    );
}
