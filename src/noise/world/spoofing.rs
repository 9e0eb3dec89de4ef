//! Malicious attacks (p-diagram 14): an injected fake object and a relay (delay) attack.
//!
//! Injection (pdiagram-models.md 14): the attacker fires 905 nm pulses timed to the
//! victim's firings so that a fake object appears. The object is a box standing on the
//! sensor's line of sight: centre at azimuth `azimuth_deg` (the sensor's clockwise
//! azimuth) and horizontal range `range_m`, `size_m = [length, width]` (length along the
//! line of sight, width across it), from `base_z_m` up to `base_z_m + height_m` (sensor
//! frame, z up). For every firing slot whose beam meets the box (slab ray-box
//! intersection along the slot's beam direction), an echo at the entry distance is
//! proposed with the attacker's power P_s (`power`, a fraction of emitted power as
//! received). The points therefore lie on the box's visible surface and carry the
//! slot's firing time; occupied slots use the return's beam, empty ones (sky) the beam
//! of the laser turned to the firing (`Slots::vacant_return`). The slot rule decides
//! what the sensor reports: in strongest mode the echo replaces the return when P_s is
//! higher, in last mode only when the box is farther, in dual mode it can be added as the
//! second return. `max_points` (N_s) limits the attacker's budget: that many of the hit
//! slots, drawn uniformly without replacement per frame (0 = every hit slot, which is
//! about 250 points for the default box on the shared capture: more than any published
//! attack shows).
//!
//! Relay/delay: an attacker re-emitting the victim's pulse with delay tau makes an echo at
//! R' = d_a + c tau / 2. We take the attacker at the target itself (d_a = R of each return
//! in the sector), so every alive return in `relay_azimuth_deg` moves farther along its
//! beam by exactly c tau / 2, keeping its power (the attacker re-emits at the level it
//! received: engineering assumption). The moved return is no longer an echo of the
//! target, so it is marked `Replaced` with this stage as cause (`range_clean` keeps the
//! recorded range) rather than competing with it as a proposed echo: the relay removes the
//! true echo from the victim's view in the sector by construction of the attack. Negative
//! delays (pulses sent before the echo, which need the firing schedule predicted) are not
//! modelled.
//!
//! Not modelled: blinding/saturation (use `occlusion` on the sector), attack windows over
//! frames and lasers (the box and the sector select the beams). Defaults: a car-sized box
//! (4.5 x 1.8 x 1.5 m on the road 1.8 m below a roof-mounted sensor) 15 m ahead, power 1
//! (receiver saturation), no relay: engineering assumptions. Budget: `max_points = 100`
//! per frame, the attack capability Cao et al. demonstrated ("Adversarial Sensor Attack
//! on LiDAR-based Perception in Autonomous Driving", CCS 2019: about 100 spoofed points
//! within about 10 degrees of azimuth, building on Shin et al., "Illusion and Dazzle",
//! CHES 2017); Sun et al. ("Towards Robust LiDAR-based Perception in Autonomous
//! Driving", USENIX Security 2020) assume a stronger attacker with up to 200 points
//! (`max_points = 200`). These figures are taken from the papers' summaries (abstracts
//! and the issue), not re-read from their tables.

use super::crosstalk::{read_sector, Sector};
use crate::config::reader::Section;
use crate::error::Result;
use crate::noise::registry::OptionSpec;
use crate::noise::sensor::{float, number, C_M_PER_S};
use crate::noise::{Echo, Fate, NoiseStage, NoisyFrame, StageKind};
use rand_chacha::ChaCha8Rng;
use std::sync::Arc;
use toml::Value;

/// The `type` name of this stage.
pub const NAME: &str = "spoofing";

/// Default budget of injected points per frame: the ~100 points in ~10 degrees Cao et
/// al. (CCS 2019) spoofed.
pub const DEFAULT_MAX_POINTS: u32 = 100;

/// Azimuth margin (degrees) around the box's span when choosing firings to test: covers
/// calibration azimuth offsets and the spread of a firing's lasers.
const SPAN_MARGIN_DEG: f64 = 2.0;

/// The fake object: an axis-aligned box in the frame turned to its centre azimuth.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FakeBox {
    /// Centre azimuth, degrees (sensor azimuth, clockwise from +x).
    pub azimuth_deg: f64,
    /// Horizontal range of the box centre, metres.
    pub range_m: f64,
    /// Length along the line of sight and width across it, metres.
    pub size_m: [f64; 2],
    /// Height, metres.
    pub height_m: f64,
    /// z of the bottom face in the sensor frame, metres.
    pub base_z_m: f64,
}

impl FakeBox {
    /// The point `[x, y, z]` (sensor frame) in the box's frame: x' along the line of sight.
    pub fn to_local(&self, p: [f64; 3]) -> [f64; 3] {
        let (s, c) = self.azimuth_deg.to_radians().sin_cos();
        // The sensor's azimuth a points along (cos a, -sin a): turn it onto +x'.
        [p[0] * c - p[1] * s, p[0] * s + p[1] * c, p[2]]
    }

    /// Lower and upper corners in the box's frame.
    pub fn bounds(&self) -> ([f64; 3], [f64; 3]) {
        let [l, w] = self.size_m;
        (
            [self.range_m - l / 2.0, -w / 2.0, self.base_z_m],
            [
                self.range_m + l / 2.0,
                w / 2.0,
                self.base_z_m + self.height_m,
            ],
        )
    }

    /// Distance along `dir` (sensor frame, from the origin; in units of `dir`) at which the
    /// ray enters the box, if it meets it in front of the sensor.
    pub fn entry(&self, dir: [f64; 3]) -> Option<f64> {
        let d = self.to_local(dir);
        let (lo, hi) = self.bounds();
        let (mut t0, mut t1) = (0.0f64, f64::INFINITY);
        for k in 0..3 {
            if d[k] == 0.0 {
                // Parallel to the slab: inside it (the origin) or never.
                if lo[k] > 0.0 || hi[k] < 0.0 {
                    return None;
                }
                continue;
            }
            let (a, b) = (lo[k] / d[k], hi[k] / d[k]);
            let (near, far) = if a < b { (a, b) } else { (b, a) };
            t0 = t0.max(near);
            t1 = t1.min(far);
            if t0 > t1 {
                return None;
            }
        }
        (t0 > 0.0).then_some(t0)
    }

    /// Half the azimuth span of the footprint as seen from the sensor, degrees.
    pub fn half_span_deg(&self) -> f64 {
        let (lo, hi) = self.bounds();
        [lo[0], hi[0]]
            .iter()
            .flat_map(|&x| [lo[1], hi[1]].map(|y| y.atan2(x).abs().to_degrees()))
            .fold(0.0, f64::max)
    }
}

/// The spoofing stage.
#[derive(Clone, Debug)]
pub struct Spoofing {
    /// The injected object.
    pub object: FakeBox,
    /// Attacker's received power P_s (fraction of emitted power); 0 disables injection.
    pub power: f64,
    /// Budget N_s of injected points per frame; 0 = every slot the box covers.
    pub max_points: u32,
    /// Sector of the relay attack.
    pub relay_sector: Sector,
    /// Relay delay tau in nanoseconds; 0 disables the relay.
    pub relay_delay_ns: f64,
}

impl Spoofing {
    /// The range shift of the relay, c tau / 2, metres.
    pub fn relay_shift_m(&self) -> f64 {
        C_M_PER_S * self.relay_delay_ns * 1e-9 / 2.0
    }

    /// The slots whose beams meet the box, with the entry range: (slot, range).
    pub fn hits(&self, frame: &mut NoisyFrame) -> Vec<(crate::noise::SlotId, f32)> {
        let slots = frame.slots();
        let reach = self.object.half_span_deg() + SPAN_MARGIN_DEG;
        let mut out = Vec::new();
        for f in 0..slots.firings.len() {
            // The firing's azimuth from any of its returns.
            let Some(first) = slots.any_of_firing(f) else {
                continue;
            };
            let mut d = f64::from(frame.clean[first].azimuth) - self.object.azimuth_deg;
            d = (d + 180.0).rem_euclid(360.0) - 180.0;
            if d.abs() > reach {
                continue;
            }
            for l in 0..slots.lasers() as u8 {
                let slot = slots.slot(f, l);
                let unit = match slots.occupants(slot).next() {
                    Some(i) => {
                        let r = &frame.clean[i];
                        if r.range > 0.0 {
                            let k = 1.0 / f64::from(r.range);
                            [f64::from(r.x) * k, f64::from(r.y) * k, f64::from(r.z) * k]
                        } else {
                            continue;
                        }
                    }
                    None => match slots.vacant_return(&frame.clean, slot, 1.0) {
                        Some((r, _)) => [f64::from(r.x), f64::from(r.y), f64::from(r.z)],
                        None => continue,
                    },
                };
                if let Some(t) = self.object.entry(unit) {
                    out.push((slot, t as f32));
                }
            }
        }
        out
    }
}

impl NoiseStage for Spoofing {
    fn kind(&self) -> &'static str {
        NAME
    }

    fn describe(&self) -> String {
        let o = &self.object;
        let inject = if self.power > 0.0 {
            format!(
                "fake {} x {} x {} m box at {} m, azimuth {} deg, power {}{}",
                o.size_m[0],
                o.size_m[1],
                o.height_m,
                o.range_m,
                o.azimuth_deg,
                self.power,
                if self.max_points > 0 {
                    format!(", at most {} points", self.max_points)
                } else {
                    String::new()
                }
            )
        } else {
            "no injection".into()
        };
        let relay = if self.relay_delay_ns > 0.0 {
            format!(
                "relay {} ns (+{:.3} m) in {}+{} deg",
                self.relay_delay_ns,
                self.relay_shift_m(),
                self.relay_sector.from,
                self.relay_sector.width
            )
        } else {
            "no relay".into()
        };
        format!("{inject}; {relay}")
    }

    fn settings(&self) -> Vec<(&'static str, Value)> {
        let o = &self.object;
        vec![
            ("azimuth_deg", float(o.azimuth_deg)),
            ("range_m", float(o.range_m)),
            (
                "size_m",
                Value::Array(vec![float(o.size_m[0]), float(o.size_m[1])]),
            ),
            ("height_m", float(o.height_m)),
            ("base_z_m", float(o.base_z_m)),
            ("power", float(self.power)),
            ("max_points", Value::Integer(i64::from(self.max_points))),
            ("relay_azimuth_deg", self.relay_sector.to_value()),
            ("relay_delay_ns", float(self.relay_delay_ns)),
        ]
    }

    fn proposes_echoes(&self) -> bool {
        self.power > 0.0 || self.relay_delay_ns > 0.0
    }

    fn apply(&self, frame: &mut NoisyFrame, rng: &mut ChaCha8Rng) {
        if self.relay_delay_ns > 0.0 {
            let shift = self.relay_shift_m();
            for i in 0..frame.len() {
                if frame.fate[i].is_alive()
                    && self
                        .relay_sector
                        .contains(f64::from(frame.clean[i].azimuth))
                {
                    frame.range[i] = (f64::from(frame.range[i]) + shift) as f32;
                    frame.set_fate(i, Fate::Replaced);
                }
            }
        }
        if self.power <= 0.0 || frame.clean_len == 0 {
            return;
        }
        let mut hits = self.hits(frame);
        let budget = self.max_points as usize;
        if budget > 0 && hits.len() > budget {
            let mut keep = rand::seq::index::sample(rng, hits.len(), budget).into_vec();
            keep.sort_unstable();
            hits = keep.into_iter().map(|k| hits[k]).collect();
        }
        for (slot, range) in hits {
            frame.propose_slot(
                slot,
                Echo {
                    range,
                    power: self.power,
                },
            );
        }
    }
}

/// Reads the options of a `spoofing` entry.
pub fn build(opts: &Section<'_>) -> Result<Arc<dyn NoiseStage>> {
    let azimuth_deg = number(opts, "azimuth_deg", 0.0, 0.0, 360.0)?;
    let range_m = number(opts, "range_m", 15.0, 0.0, 130.0)?;
    let size_m = match opts.pair("size_m")? {
        None => [4.5, 1.8],
        Some(s) => {
            for (i, v) in s.iter().enumerate() {
                if !(v.is_finite() && *v > 0.0 && *v <= 100.0) {
                    return Err(opts.error(
                        &format!("size_m[{i}]"),
                        format!("{v} is outside (0, 100] m"),
                    ));
                }
            }
            s
        }
    };
    let height_m = number(opts, "height_m", 1.5, 0.0, 100.0)?;
    let base_z_m = number(opts, "base_z_m", -1.8, -100.0, 100.0)?;
    let power = number(opts, "power", 1.0, 0.0, 1.0)?;
    let max_points = match opts.i64("max_points")? {
        None => DEFAULT_MAX_POINTS,
        Some(n) if (0..=1_000_000).contains(&n) => n as u32,
        Some(n) => {
            return Err(opts.error(
                "max_points",
                format!("{n} is outside [0, 1000000] (0 = every slot the box covers)"),
            ))
        }
    };
    let relay_sector = read_sector(opts, "relay_azimuth_deg")?.unwrap_or(Sector::FULL);
    let relay_delay_ns = number(opts, "relay_delay_ns", 0.0, 0.0, 1e4)?;
    if range_m - size_m[0] / 2.0 <= 0.0 {
        return Err(opts.error(
            "range_m",
            format!(
                "the box ({range_m} m away, {} m long) would hold the sensor: its near face \
                 must be in front of it",
                size_m[0]
            ),
        ));
    }
    Ok(Arc::new(Spoofing {
        object: FakeBox {
            azimuth_deg,
            range_m,
            size_m,
            height_m,
            base_z_m,
        },
        power,
        max_points,
        relay_sector,
        relay_delay_ns,
    }))
}

/// The registry entry of this stage.
pub const KIND: StageKind = StageKind {
    name: NAME,
    factor: "14 malicious attacks (spoofing, relay)",
    model: "echoes of power P_s on the surface of a fake box in every firing slot whose beam meets it (ray-box entry), competing by the slot rule; relay moves returns in a sector by c tau / 2",
    source: "Cao et al. CCS 2019; Petit et al. Black Hat Europe 2015; Shin et al. CHES 2017; box, power and delay engineering assumptions",
    options: &[
        OptionSpec { name: "azimuth_deg", unit: "deg", default: "0", doc: "azimuth of the fake box's centre (sensor azimuth, clockwise)" },
        OptionSpec { name: "range_m", unit: "m", default: "15", doc: "horizontal range of the box's centre" },
        OptionSpec { name: "size_m", unit: "m", default: "[4.5, 1.8]", doc: "box length along the line of sight and width across it" },
        OptionSpec { name: "height_m", unit: "m", default: "1.5", doc: "box height" },
        OptionSpec { name: "base_z_m", unit: "m", default: "-1.8", doc: "z of the box's bottom in the sensor frame" },
        OptionSpec { name: "power", unit: "-", default: "1", doc: "attacker's received power P_s (fraction of emitted power, 1 = saturation); 0 = no injection" },
        OptionSpec { name: "max_points", unit: "points", default: "100", doc: "budget N_s of injected points per frame, drawn among the hit slots (100: Cao et al. CCS 2019; 200: Sun et al. USENIX Security 2020); 0 = all" },
        OptionSpec { name: "relay_azimuth_deg", unit: "deg", default: "[0, 360]", doc: "sector [from, to) of the relay attack, clockwise, may wrap" },
        OptionSpec { name: "relay_delay_ns", unit: "ns", default: "0", doc: "relay delay tau: returns in the sector move by c tau / 2; 0 = no relay" },
    ],
    build,
};

#[cfg(test)]
mod tests {
    use super::*;

    fn car() -> FakeBox {
        FakeBox {
            azimuth_deg: 90.0,
            range_m: 10.0,
            size_m: [4.0, 2.0],
            height_m: 1.5,
            base_z_m: -1.0,
        }
    }

    #[test]
    fn a_level_ray_at_the_centre_azimuth_enters_the_near_face() {
        let b = car();
        // Azimuth 90 deg (clockwise) points along -y.
        let t = b.entry([0.0, -1.0, 0.0]).unwrap();
        assert!((t - 8.0).abs() < 1e-12, "{t}");
        // Pointing the other way, or above the box, misses.
        assert_eq!(b.entry([0.0, 1.0, 0.0]), None);
        assert_eq!(b.entry([0.0, -0.8, 0.6]), None);
    }

    #[test]
    fn a_steep_ray_enters_through_the_top_or_not_at_all() {
        let mut b = car();
        b.base_z_m = -3.0;
        b.height_m = 2.0; // top at z = -1
        let n = 82f64.sqrt();
        let dir = [0.0, -9.0 / n, -1.0 / n];
        let t = b.entry(dir).unwrap();
        let p = [dir[0] * t, dir[1] * t, dir[2] * t];
        // Passes over the near face (z = -8/9 at 8 m) and enters through the top face
        // (z = -1) at horizontal distance 9 m.
        assert!((p[2] + 1.0).abs() < 1e-9, "{p:?}");
        assert!((p[1] + 9.0).abs() < 1e-9, "{p:?}");
        // Steeper, it hits the ground in front of the box: no entry.
        assert_eq!(b.entry([0.0, -0.5, -0.5]), None);
    }

    #[test]
    fn half_span_is_that_of_the_near_corners() {
        let b = car();
        let expect = (1.0f64).atan2(8.0).to_degrees();
        assert!((b.half_span_deg() - expect).abs() < 1e-12);
    }
}
