//! Synthetic HDL-32E frames for the ground tests and bench: the 32 beams of the built-in
//! calibration ray-cast against a ground plane and a few boxes, with exact labels.
#![allow(dead_code)]

use lidar_noise::frame::{Return, ReturnKind};
use lidar_noise::sensor::calibration::Calibration;

/// An axis-aligned box standing on the ground.
#[derive(Clone, Copy, Debug)]
pub struct Block {
    /// Lower corner (x, y) of the footprint, metres.
    pub min: [f64; 2],
    /// Upper corner (x, y) of the footprint, metres.
    pub max: [f64; 2],
    /// Top of the box above the ground at the footprint's centre, metres.
    pub height: f64,
}

/// A scene: ground plane z = -sensor_height + tan(slope) * x, plus boxes.
#[derive(Clone, Debug)]
pub struct Scene {
    /// Sensor height above the ground at the origin, metres.
    pub sensor_height: f64,
    /// Ground slope along x, degrees (positive: rising ahead).
    pub slope_deg: f64,
    /// Obstacles.
    pub blocks: Vec<Block>,
    /// Largest range that returns, metres.
    pub max_range: f64,
    /// Smallest range that returns, metres.
    pub min_range: f64,
}

impl Scene {
    /// Flat ground 1.8 m below the sensor with a car (4 x 1.8 x 1.5 m) 8 m ahead, a second
    /// car behind on the right, a wall on the left and a pole.
    pub fn street(slope_deg: f64) -> Scene {
        Scene {
            sensor_height: 1.8,
            slope_deg,
            blocks: vec![
                Block {
                    min: [8.0, -0.9],
                    max: [12.0, 0.9],
                    height: 1.5,
                },
                Block {
                    min: [-10.0, -5.0],
                    max: [-6.0, -3.2],
                    height: 1.5,
                },
                Block {
                    min: [-5.0, 10.0],
                    max: [25.0, 10.3],
                    height: 3.0,
                },
                Block {
                    min: [3.0, -4.3],
                    max: [3.3, -4.0],
                    height: 4.0,
                },
            ],
            max_range: 100.0,
            min_range: 0.9,
        }
    }

    fn ground_z(&self, x: f64) -> f64 {
        -self.sensor_height + self.slope_deg.to_radians().tan() * x
    }

    /// Distance along unit direction `d` to the nearest surface, and whether it is ground.
    pub fn cast(&self, d: [f64; 3]) -> Option<(f64, bool)> {
        let mut best: Option<(f64, bool)> = None;
        // Ground: z - s x + h = 0 along t * d.
        let s = self.slope_deg.to_radians().tan();
        let denom = d[2] - s * d[0];
        if denom < -1e-12 {
            let t = -self.sensor_height / denom;
            best = Some((t, true));
        }
        for b in &self.blocks {
            let cx = 0.5 * (b.min[0] + b.max[0]);
            // Boxes reach well below the ground so sloped ground meets them without a gap.
            let lo = [b.min[0], b.min[1], self.ground_z(cx) - 10.0];
            let hi = [b.max[0], b.max[1], self.ground_z(cx) + b.height];
            let (mut t0, mut t1) = (0.0f64, f64::INFINITY);
            for k in 0..3 {
                if d[k].abs() < 1e-12 {
                    if 0.0 < lo[k] || 0.0 > hi[k] {
                        t0 = f64::INFINITY;
                    }
                    continue;
                }
                let (a, c) = ((lo[k]) / d[k], (hi[k]) / d[k]);
                t0 = t0.max(a.min(c));
                t1 = t1.min(a.max(c));
            }
            if t0 <= t1 && t0 > 0.0 && best.is_none_or(|(t, _)| t0 < t) {
                best = Some((t0, false));
            }
        }
        best.filter(|&(t, _)| t >= self.min_range && t <= self.max_range)
    }

    /// Ray-casts every laser not in `skip_lasers` at every azimuth step, in capture
    /// order (azimuth-major, laser id order). Returns the returns and their true labels.
    pub fn frame(&self, azimuth_step_deg: f64, skip_lasers: &[u8]) -> (Vec<Return>, Vec<bool>) {
        self.frame_filtered(azimuth_step_deg, |laser, _| !skip_lasers.contains(&laser))
    }

    /// Like [`Scene::frame`], keeping only beams for which `keep(laser, azimuth_deg)` holds.
    pub fn frame_filtered(
        &self,
        azimuth_step_deg: f64,
        keep: impl Fn(u8, f64) -> bool,
    ) -> (Vec<Return>, Vec<bool>) {
        let cal = Calibration::builtin();
        let rings = cal.rings();
        let steps = (360.0 / azimuth_step_deg).round() as usize;
        let mut returns = Vec::new();
        let mut labels = Vec::new();
        for k in 0..steps {
            let az = k as f64 * azimuth_step_deg;
            for laser in 0..32u8 {
                if !keep(laser, az) {
                    continue;
                }
                let el = cal.lasers[laser as usize].elevation_deg;
                let (a, w) = (az.to_radians(), el.to_radians());
                let d = [w.cos() * a.cos(), -w.cos() * a.sin(), w.sin()];
                let Some((t, ground)) = self.cast(d) else {
                    continue;
                };
                returns.push(make_return(t, az, el, laser, rings[laser as usize]));
                labels.push(ground);
            }
        }
        (returns, labels)
    }
}

/// A return at range `range` along (azimuth, elevation), with the other fields filled.
pub fn make_return(range: f64, azimuth: f64, elevation: f64, laser: u8, ring: u8) -> Return {
    let (a, w) = (azimuth.to_radians(), elevation.to_radians());
    Return {
        x: (range * w.cos() * a.cos()) as f32,
        y: (-range * w.cos() * a.sin()) as f32,
        z: (range * w.sin()) as f32,
        range: range as f32,
        azimuth: azimuth as f32,
        elevation: elevation as f32,
        time: 0.0,
        packet: 0,
        raw_distance: (range / 0.002).min(65535.0) as u16,
        intensity: 50,
        laser,
        ring,
        block: 0,
        kind: ReturnKind::Strongest,
    }
}

/// Precision and recall of `predicted` against `truth`, restricted to `mask`.
pub fn precision_recall_where(predicted: &[bool], truth: &[bool], mask: &[bool]) -> (f64, f64) {
    assert_eq!(predicted.len(), truth.len());
    let (mut tp, mut fp, mut fneg) = (0usize, 0usize, 0usize);
    for ((&p, &t), _) in predicted.iter().zip(truth).zip(mask).filter(|(_, &m)| m) {
        match (p, t) {
            (true, true) => tp += 1,
            (true, false) => fp += 1,
            (false, true) => fneg += 1,
            _ => {}
        }
    }
    assert!(tp + fneg > 0, "the scene has no ground to find");
    let precision = if tp + fp == 0 {
        0.0
    } else {
        tp as f64 / (tp + fp) as f64
    };
    (precision, tp as f64 / (tp + fneg) as f64)
}

/// Precision and recall of `predicted` against `truth`.
pub fn precision_recall(predicted: &[bool], truth: &[bool]) -> (f64, f64) {
    precision_recall_where(predicted, truth, &vec![true; truth.len()])
}
