//! KITTI's HDL-64E beam table (`sensor::HDL64E_KITTI`, `--sensor hdl64e-kitti`) on a
//! synthetic KITTI-like scan written here from the table: each laser's points on its line
//! z = h tan(el) + dz, with jitter, stored laser by laser from the top beam down as KITTI
//! stores them. No real KITTI file is read (the real scans' numbers come from
//! `examples/kitti_beams.rs`, docs/guide/datasets.md).

use lidar_noise::cloud::guess::{sensor_by_name, SENSOR_NAMES};
use lidar_noise::cloud::returns::{to_returns, ReturnsOptions};
use lidar_noise::cloud::CloudPoint;
use lidar_noise::sensor::{SensorModel, HDL64E_KITTI, HDL64E_S2};

/// A deterministic jitter in [-1, 1) from an index (no random crate needed).
fn jitter(i: u64) -> f64 {
    let x = i
        .wrapping_mul(6364136223846793005)
        .wrapping_add(1442695040888963407);
    (x >> 11) as f64 / (1u64 << 52) as f64 - 1.0
}

/// The scan: per laser (top beam first), 180 azimuths at horizontal distances from 3 to
/// 60 m, elevation jittered by up to `jitter_deg` and offset by up to 2 mm; returns the
/// points and each point's laser id.
fn kitti_like(model: &SensorModel, jitter_deg: f64) -> (Vec<CloudPoint>, Vec<u8>) {
    let mut lasers: Vec<usize> = (0..64).collect();
    lasers.sort_by(|&a, &b| model.elevation_deg[b].total_cmp(&model.elevation_deg[a]));
    let (mut points, mut truth) = (Vec::new(), Vec::new());
    let mut n = 0u64;
    for &l in &lasers {
        for a in 0..180 {
            n += 1;
            let az = f64::from(a) * 2.0 + 0.3 * jitter(n);
            let h = 3.0 + 57.0 * (0.5 + 0.5 * jitter(n + 7_000_000));
            let el = model.elevation_deg[l] + jitter_deg * jitter(n + 14_000_000);
            let dz = model.vertical_offset_mm[l] * 1e-3 + 0.002 * jitter(n + 21_000_000);
            let (s, c) = az.to_radians().sin_cos();
            points.push(CloudPoint {
                x: (h * c) as f32,
                y: (h * s) as f32,
                z: (h * el.to_radians().tan() + dz) as f32,
                intensity: 0.3,
                ring: None,
                time: None,
            });
            truth.push(l as u8);
        }
    }
    (points, truth)
}

/// Share of points given their laser, and the share ambiguous, with `model`'s table.
fn agreement(points: &[CloudPoint], truth: &[u8], model: &SensorModel) -> (f64, f64) {
    let out = to_returns(points, model, &ReturnsOptions::default(), "kitti-like").unwrap();
    assert_eq!(out.from_elevation, points.len());
    let same = out
        .returns
        .iter()
        .zip(&out.order)
        .filter(|(r, &i)| r.laser == truth[i as usize])
        .count();
    let n = points.len() as f64;
    (same as f64 / n, out.ambiguous as f64 / n)
}

#[test]
fn every_point_of_a_kitti_like_scan_gets_its_laser_from_kittis_table() {
    // Jitter of 0.03 deg: a tenth of the closest beams' spacing (0.25 deg).
    let (points, truth) = kitti_like(&HDL64E_KITTI, 0.03);
    assert_eq!(points.len(), 64 * 180);
    let (same, ambiguous) = agreement(&points, &truth, &HDL64E_KITTI);
    assert_eq!((same, ambiguous), (1.0, 0.0));
    // The ring of each return is the laser's ring, rings 63 (top) to 0.
    let out = to_returns(&points, &HDL64E_KITTI, &ReturnsOptions::default(), "k").unwrap();
    let rings = HDL64E_KITTI.rings();
    for (r, &i) in out.returns.iter().zip(&out.order) {
        assert_eq!(r.ring, rings[usize::from(truth[i as usize])]);
        assert_eq!(usize::from(r.ring), 63 - i as usize / 180);
    }
}

#[test]
fn the_default_table_does_not_fit_kittis_unit() {
    // The same scan with the built-in HDL-64E table: most points fall to another laser
    // (the default beams lie 0.9 to 1.3 deg above KITTI's, and the offsets lift near
    // points further), which is why KITTI scans need their own table.
    let (points, truth) = kitti_like(&HDL64E_KITTI, 0.03);
    let (same, ambiguous) = agreement(&points, &truth, &HDL64E_S2);
    assert!(same < 0.3, "{same}");
    assert!(ambiguous > 0.3, "{ambiguous}");
}

#[test]
fn jitter_of_half_a_spacing_is_counted_ambiguous() {
    // Elevations jittered by up to 0.2 deg (beams 0.25 to 0.67 deg apart): some points
    // lie in the middle half between two beams, and are counted so.
    let (points, truth) = kitti_like(&HDL64E_KITTI, 0.2);
    let (same, ambiguous) = agreement(&points, &truth, &HDL64E_KITTI);
    assert!(ambiguous > 0.05 && ambiguous < 0.5, "{ambiguous}");
    assert!(same > 0.9 && same < 1.0, "{same}");
}

#[test]
fn kittis_unit_is_a_sensor_name() {
    for name in ["hdl64e-kitti", "HDL-64E_KITTI", "kitti"] {
        assert_eq!(sensor_by_name(name).unwrap().name, "HDL-64E S2 (KITTI)");
    }
    assert!(SENSOR_NAMES.contains("hdl64e-kitti"), "{SENSOR_NAMES}");
    // Its timing and packets are the S2's; only the beams differ.
    let k = sensor_by_name("hdl64e-kitti").unwrap();
    assert_eq!(
        (k.sequence_us, k.lasers, k.azimuth_offset_deg),
        (HDL64E_S2.sequence_us, 64, HDL64E_S2.azimuth_offset_deg)
    );
    assert_ne!(k.elevation_deg, HDL64E_S2.elevation_deg);
    // `hdl64e` stays the S2 with the default beams.
    assert_eq!(sensor_by_name("hdl64e").unwrap().name, "HDL-64E S2");
}
