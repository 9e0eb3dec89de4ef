//! Range-image ground on a real HDL-32E frame (the shared reference decode of monterey
//! frame 1). No labels exist, so the checks are physical: the sensor sits on a vehicle
//! on a road, so road-level returns near it are ground and returns above it are not.

use lidar_noise::frame::{Return, ReturnKind};
use lidar_noise::ground::{segment, GroundOptions};
use lidar_noise::sensor::calibration::Calibration;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

const CSV: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../shared/data/hdl32e/monterey.frame1.reference.csv"
);

/// Returns of the reference frame in file (capture) order, or None if the data is absent.
fn load() -> Option<Vec<Return>> {
    let text = match std::fs::read_to_string(CSV) {
        Ok(t) => t,
        Err(e) => {
            eprintln!("skipping: {CSV} not readable ({e})");
            return None;
        }
    };
    let cal = Calibration::builtin();
    let lasers = cal.lasers_by_ring();
    let mut out = Vec::new();
    for (line_no, line) in text.lines().enumerate().skip(1) {
        let f: Vec<f64> = line
            .split(',')
            .map(|v| {
                v.parse()
                    .unwrap_or_else(|_| panic!("line {}: {line}", line_no + 1))
            })
            .collect();
        let (x, y, z, ring) = (f[0], f[1], f[2], f[5] as u8);
        let range = (x * x + y * y + z * z).sqrt();
        let laser = lasers[ring as usize];
        out.push(Return {
            x: x as f32,
            y: y as f32,
            z: z as f32,
            range: range as f32,
            azimuth: (-y).atan2(x).to_degrees().rem_euclid(360.0) as f32,
            elevation: cal.lasers[laser as usize].elevation_deg as f32,
            time: f[4],
            packet: 0,
            raw_distance: (range / 0.002) as u16,
            intensity: f[3] as u8,
            laser,
            ring,
            block: 0,
            kind: ReturnKind::Strongest,
        });
    }
    Some(out)
}

#[test]
fn real_frame_ground_lies_on_the_road() {
    let Some(returns) = load() else { return };
    assert!(returns.len() > 40_000, "{} returns", returns.len());
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let labels = segment(&returns, &GroundOptions::default(), &mut rng);
    assert_eq!(labels.len(), returns.len());
    let horiz = |r: &Return| r.x.hypot(r.y);
    let share = |pick: &dyn Fn(&Return) -> bool| {
        let (mut n, mut g) = (0usize, 0usize);
        for (r, &l) in returns.iter().zip(&labels) {
            if pick(r) {
                n += 1;
                g += l as usize;
            }
        }
        assert!(n > 1000, "too few returns to judge: {n}");
        g as f64 / n as f64
    };

    let all = share(&|_| true);
    // The sensor is about 2.2 m above the road: returns at road level 3 to 10 m away
    // (outside the recording vehicle) are mostly road.
    let road = share(&|r| (3.0..10.0).contains(&horiz(r)) && r.z < -2.1);
    // Returns above the sensor within 30 m are walls, trees and vehicles, not ground.
    let above = share(&|r| horiz(r) < 30.0 && r.z > 0.0);
    eprintln!("ground share: all {all:.3}, road level {road:.3}, above the sensor {above:.4}");
    assert!((0.2..0.9).contains(&all), "ground share {all}");
    assert!(road >= 0.8, "road-level returns found as ground: {road}");
    assert!(
        above <= 0.02,
        "returns above the sensor taken for ground: {above}"
    );
}
