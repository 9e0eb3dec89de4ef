//! Mechanics (p-diagram 04): encoder offset, eccentricity and jitter shift the reported
//! azimuth of a firing; a wobbling spin axis tilts the beams once per turn; spin-rate
//! variation stretches the azimuth spacing within a rotation.
//!
//! Model (pdiagram-models.md, 04), per firing (the 32 returns of one data block share
//! one draw): a' = a + a0 + A1 sin(a + phi1) + N(0, s_a^2) + e (a - a_start);
//! w' = w + W sin(a + phi_w). phi1 and phi_w are drawn uniform once per seed (unit
//! stream); e ~ N(0, s_e^2) once per frame (the doc's slow random walk of the rate,
//! frozen over one 0.1 s rotation), then one normal per firing when s_a > 0, from the
//! frame stream. `a_start` is the azimuth of the frame's first return; the swept angle
//! is taken modulo 360. Source: Glennie and Lichti, Remote Sensing 3(3), 2011 (encoder
//! misalignment found only marginally significant); magnitudes are engineering
//! assumptions below the 0.01 deg reporting step and the 0.166 deg firing step.

use super::{float, normal, number, sigma};
use crate::config::reader::Section;
use crate::error::Result;
use crate::noise::registry::OptionSpec;
use crate::noise::{NoiseStage, NoisyFrame, StageKind};
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use std::sync::Arc;
use toml::Value;

/// The `type` name of this stage.
pub const NAME: &str = "mechanics";

/// The mechanics stage.
#[derive(Clone, Debug)]
pub struct Mechanics {
    /// Encoder offset a0, degrees.
    pub azimuth_offset_deg: f64,
    /// Eccentricity amplitude A1, degrees.
    pub eccentricity_deg: f64,
    /// Per-firing azimuth jitter SD, degrees.
    pub jitter_deg: f64,
    /// Spin-axis wobble amplitude W on elevation, degrees.
    pub wobble_deg: f64,
    /// SD of the relative spin-rate error per frame.
    pub spin_rate_sigma: f64,
    /// Phases phi1, phi_w in radians (drawn once per seed).
    pub phases: [f64; 2],
}

impl NoiseStage for Mechanics {
    fn kind(&self) -> &'static str {
        NAME
    }
    fn uses_layout(&self) -> bool {
        true
    }
    fn describe(&self) -> String {
        format!(
            "encoder offset {} deg, eccentricity {} deg, firing jitter SD {} deg, axis wobble {} deg, spin-rate SD {}",
            self.azimuth_offset_deg, self.eccentricity_deg, self.jitter_deg, self.wobble_deg, self.spin_rate_sigma
        )
    }
    fn settings(&self) -> Vec<(&'static str, Value)> {
        vec![
            ("azimuth_offset_deg", float(self.azimuth_offset_deg)),
            ("eccentricity_deg", float(self.eccentricity_deg)),
            ("jitter_deg", float(self.jitter_deg)),
            ("wobble_deg", float(self.wobble_deg)),
            ("spin_rate_sigma", float(self.spin_rate_sigma)),
        ]
    }
    fn with_unit_draws(&self, rng: &mut ChaCha8Rng) -> Option<Arc<dyn NoiseStage>> {
        let mut s = self.clone();
        s.phases = [
            rng.random::<f64>() * std::f64::consts::TAU,
            rng.random::<f64>() * std::f64::consts::TAU,
        ];
        Some(Arc::new(s))
    }
    fn apply(&self, frame: &mut NoisyFrame, rng: &mut ChaCha8Rng) {
        let n = frame.len();
        let spin = if self.spin_rate_sigma > 0.0 {
            self.spin_rate_sigma * normal(rng)
        } else {
            0.0
        };
        let azimuth_moves = self.azimuth_offset_deg != 0.0
            || self.eccentricity_deg != 0.0
            || self.jitter_deg != 0.0
            || spin != 0.0;
        let wobbles = self.wobble_deg != 0.0;
        if !(azimuth_moves || wobbles) {
            return;
        }
        let a_start = frame.clean.first().map_or(0.0, |r| f64::from(r.azimuth));
        // The frame's firings and azimuths from its layout (not the 48-byte returns).
        // The jitter is drawn per firing (packet, block); the shift and the wobble are
        // functions of the azimuth, evaluated again only where it changes.
        let lay = frame.layout();
        let moved = &mut frame.moved;
        let mut da = azimuth_moves.then(|| moved.azimuth_deg.get_or_insert_with(|| vec![0.0; n]));
        let mut de = wobbles.then(|| moved.elevation_deg.get_or_insert_with(|| vec![0.0; n]));
        // Both values are `f32` roundings of expressions that do not decrease as the
        // sine grows (the amplitudes are >= 0). Within a firing of several azimuths the
        // sine is first bracketed from the firing's anchor ([`Anchor::bracket`]); where
        // the expression rounds to one `f32` at both ends of the bracket, so does it at
        // libm's sine between them, and libm `sin` (two per return on real captures,
        // most of this stage's time) is called only where it does not.
        let shift_with = |sine: f64, swept: f64, jitter: f64| {
            (self.azimuth_offset_deg + self.eccentricity_deg * sine + jitter + spin * swept) as f32
        };
        // `rem_euclid(360)` without its `fmod` call where |v| < 360: there `v % 360` is
        // `v` exactly, and `rem_euclid` adds 360 to a negative remainder.
        let swept_of = |v: f64| {
            if v.abs() < 360.0 {
                if v < 0.0 {
                    v + 360.0
                } else {
                    v
                }
            } else {
                v.rem_euclid(360.0)
            }
        };
        let shift_of = |az: f32, jitter: f64, anchor: Option<&Anchor>| {
            let a = f64::from(az);
            let swept = swept_of(a - a_start);
            let x = a.to_radians() + self.phases[0];
            of_sine(x, anchor, |sine| shift_with(sine, swept, jitter))
        };
        let wobble_of = |az: f32, anchor: Option<&Anchor>| {
            let x = f64::from(az).to_radians() + self.phases[1];
            of_sine(x, anchor, |sine| (self.wobble_deg * sine) as f32)
        };
        // The shift is evaluated again at the first return of every firing (the jitter
        // changes there) and where the azimuth changes; the wobble where the azimuth
        // changes from the last return's (from NaN bits, with 0 as its value, before
        // the first). One pass over the azimuths does both (they were two passes).
        let mut wobble = (f32::NAN.to_bits(), 0.0f32);
        for &[start, end] in &lay.firings {
            let idx = start as usize..end as usize;
            let jitter = if da.is_some() && self.jitter_deg > 0.0 {
                self.jitter_deg * normal(rng)
            } else {
                0.0
            };
            let az = &lay.azimuth[idx.clone()];
            // Anchors at the firing's first azimuth, for firings of several azimuths
            // (one azimuth: one evaluation, libm's directly).
            let uniform = az.iter().all(|a| a.to_bits() == az[0].to_bits());
            let anchor_at =
                |phase: f64| (!uniform).then(|| Anchor::new(f64::from(az[0]).to_radians() + phase));
            let shift_anchor = if da.is_some() {
                anchor_at(self.phases[0])
            } else {
                None
            };
            let wobble_anchor = if de.is_some() {
                anchor_at(self.phases[1])
            } else {
                None
            };
            let mut shift = (az.first().map_or(0, |a| !a.to_bits()), 0.0f32);
            let mut shift_at = |az: f32| {
                if az.to_bits() != shift.0 {
                    shift = (az.to_bits(), shift_of(az, jitter, shift_anchor.as_ref()));
                }
                shift.1
            };
            let mut wobble_at = |az: f32| {
                if az.to_bits() != wobble.0 {
                    wobble = (az.to_bits(), wobble_of(az, wobble_anchor.as_ref()));
                }
                wobble.1
            };
            // A firing whose returns share one azimuth (no azimuth interpolation, or a
            // synthetic frame) gets one shift and one wobble, evaluated at its first
            // return exactly as the loops below would, and added in a loop free of
            // tests (the loops below would add the same values).
            if let Some(&first) = az.first() {
                if uniform {
                    if let Some(da) = da.as_deref_mut() {
                        let s = shift_at(first);
                        da[idx.clone()].iter_mut().for_each(|d| *d += s);
                    }
                    if let Some(de) = de.as_deref_mut() {
                        let w = wobble_at(first);
                        de[idx].iter_mut().for_each(|e| *e += w);
                    }
                    continue;
                }
            }
            match (da.as_deref_mut(), de.as_deref_mut()) {
                (Some(da), Some(de)) => {
                    for ((d, e), &a) in da[idx.clone()].iter_mut().zip(&mut de[idx]).zip(az) {
                        *d += shift_at(a);
                        *e += wobble_at(a);
                    }
                }
                (Some(da), None) => {
                    for (d, &a) in da[idx].iter_mut().zip(az) {
                        *d += shift_at(a);
                    }
                }
                (None, Some(de)) => {
                    for (e, &a) in de[idx].iter_mut().zip(az) {
                        *e += wobble_at(a);
                    }
                }
                (None, None) => {}
            }
        }
    }
}

/// `value(x.sin())` with libm's sine, for a `value` that does not decrease as the sine
/// grows: taken at both ends of the anchor's bracket of the sine where they give the same
/// `f32` (so does every sine between them), from libm `sin` otherwise.
#[inline(always)]
fn of_sine(x: f64, anchor: Option<&Anchor>, value: impl Fn(f64) -> f32) -> f32 {
    if let Some((lo, hi)) = anchor.and_then(|an| an.bracket(x)) {
        let l = value(lo);
        if l.to_bits() == value(hi).to_bits() {
            return l;
        }
    }
    value(x.sin())
}

/// sin and cos at one argument (a firing's first azimuth plus a phase), from which the
/// sine at nearby arguments is bracketed.
struct Anchor {
    x: f64,
    sin: f64,
    cos: f64,
}

impl Anchor {
    /// Bound of |bracket centre - libm sine|. The centre sin(x0) cos(d) + cos(x0) sin(d),
    /// d = x - x0, |d| <= 0.02, is within about 3e-15 of the true sine: libm's sin and
    /// cos of x0 (1 ulp each), d itself (one rounding of x - x0, 1.4e-15 at most for
    /// |x| < 13), the series of sin(d) and cos(d) cut after d^5 and d^6 (below 3e-16) and
    /// a few roundings; libm's sine of x is within 1 ulp (1.1e-16). 1e-13 is 30 times
    /// their sum.
    const BOUND: f64 = 1e-13;

    fn new(x: f64) -> Anchor {
        Anchor {
            x,
            sin: x.sin(),
            cos: x.cos(),
        }
    }

    /// An interval holding libm's `x.sin()`; `None` when `x` is more than 0.02 from the
    /// anchor or not finite (a firing's azimuths span about 0.003 rad).
    fn bracket(&self, x: f64) -> Option<(f64, f64)> {
        let d = x - self.x;
        if d.is_nan() || d.abs() > 0.02 {
            return None;
        }
        const S3: f64 = -1.0 / 6.0;
        const S5: f64 = 1.0 / 120.0;
        const C2: f64 = -1.0 / 2.0;
        const C4: f64 = 1.0 / 24.0;
        const C6: f64 = -1.0 / 720.0;
        let d2 = d * d;
        let sin_d = d + d * d2 * (S3 + d2 * S5);
        let cos_d = 1.0 + d2 * (C2 + d2 * (C4 + d2 * C6));
        let s = self.sin * cos_d + self.cos * sin_d;
        Some((s - Self::BOUND, s + Self::BOUND))
    }
}

/// Reads the options of a `mechanics` entry.
pub fn build(opts: &Section<'_>) -> Result<Arc<dyn NoiseStage>> {
    Ok(Arc::new(Mechanics {
        azimuth_offset_deg: number(opts, "azimuth_offset_deg", 0.0, -180.0, 180.0)?,
        eccentricity_deg: number(opts, "eccentricity_deg", 0.01, 0.0, 10.0)?,
        jitter_deg: sigma(opts, "jitter_deg", 0.005, 10.0)?,
        wobble_deg: number(opts, "wobble_deg", 0.02, 0.0, 10.0)?,
        spin_rate_sigma: sigma(opts, "spin_rate_sigma", 0.001, 0.5)?,
        phases: [0.0; 2],
    }))
}

/// The registry entry of this stage.
pub const KIND: StageKind = StageKind {
    name: NAME,
    factor: "04 mechanics (encoder, spin)",
    model: "per firing a' = a + a0 + A1 sin(a + phi1) + N(0, s_a^2) + e (a - a_start); w' = w + W sin(a + phi_w); e ~ N(0, s_e^2) per frame",
    source: "Glennie and Lichti, Remote Sensing 3(3) 2011; magnitudes engineering assumption (pdiagram-models.md 04)",
    options: &[
        OptionSpec { name: "azimuth_offset_deg", unit: "deg", default: "0", doc: "encoder offset a0, in [-180, 180]" },
        OptionSpec { name: "eccentricity_deg", unit: "deg", default: "0.01", doc: "once-per-turn encoder eccentricity A1" },
        OptionSpec { name: "jitter_deg", unit: "deg", default: "0.005", doc: "per-firing azimuth jitter SD" },
        OptionSpec { name: "wobble_deg", unit: "deg", default: "0.02", doc: "spin-axis wobble W on elevation, once per turn" },
        OptionSpec { name: "spin_rate_sigma", unit: "-", default: "0.001", doc: "SD of the relative spin-rate error per frame" },
    ],
    build,
};

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn anchored_brackets_hold_libm_sine_with_room() {
        let mut state = 9u64;
        let mut unit = || crate::test_util::lcg_unit(&mut state);
        let mut worst = 0.0f64;
        for _ in 0..100_000 {
            // Azimuths as the stage makes them (f32 degrees, radians, a phase < 2 pi),
            // and offsets up to and beyond the 0.02 limit.
            let phase = unit() * std::f64::consts::TAU;
            let a0 = f64::from((unit() * 360.0) as f32).to_radians() + phase;
            let anchor = Anchor::new(a0);
            let x = a0 + (unit() - 0.5) * 0.05;
            match anchor.bracket(x) {
                Some((lo, hi)) => {
                    let libm = x.sin();
                    assert!(lo <= libm && libm <= hi, "{a0} {x}");
                    worst = worst.max((0.5 * (lo + hi) - libm).abs());
                }
                None => assert!((x - a0).abs() > 0.02),
            }
        }
        assert!(worst < Anchor::BOUND / 30.0, "worst {worst}");
        assert!(Anchor::new(1.0).bracket(f64::NAN).is_none());
    }

    /// A return of zeros (the decoder's filler).
    fn blank() -> Return {
        crate::hdl32e::decode::BLANK
    }
    use crate::frame::Return;
    use crate::noise::{stage_rng, IdealPower};

    /// The stage as it was written before the one-pass loop and the uniform firings:
    /// two passes, memos reset as described there.
    fn reference(m: &Mechanics, clean: &[Return], rng: &mut ChaCha8Rng) -> [Vec<f32>; 2] {
        let n = clean.len();
        let spin = if m.spin_rate_sigma > 0.0 {
            m.spin_rate_sigma * normal(rng)
        } else {
            0.0
        };
        let a_start = clean.first().map_or(0.0, |r| f64::from(r.azimuth));
        let (mut da, mut de) = (vec![0.0f32; n], vec![0.0f32; n]);
        let mut start = 0;
        while start < n {
            let key = (clean[start].packet, clean[start].block);
            let mut end = start;
            while end < n && (clean[end].packet, clean[end].block) == key {
                end += 1;
            }
            let jitter = if m.jitter_deg > 0.0 {
                m.jitter_deg * normal(rng)
            } else {
                0.0
            };
            let mut last: Option<(u32, f32)> = None;
            for i in start..end {
                let az = clean[i].azimuth;
                if last.is_none_or(|(bits, _)| bits != az.to_bits()) {
                    let a = f64::from(az);
                    let swept = (a - a_start).rem_euclid(360.0);
                    last = Some((
                        az.to_bits(),
                        (m.azimuth_offset_deg
                            + m.eccentricity_deg * (a.to_radians() + m.phases[0]).sin()
                            + jitter
                            + spin * swept) as f32,
                    ));
                }
                da[i] += last.map_or(0.0, |(_, s)| s);
            }
            start = end;
        }
        let mut last = (f32::NAN, 0.0f32);
        for (d, r) in de.iter_mut().zip(clean) {
            if r.azimuth.to_bits() != last.0.to_bits() {
                let a = f64::from(r.azimuth).to_radians();
                last = (r.azimuth, (m.wobble_deg * (a + m.phases[1]).sin()) as f32);
            }
            *d += last.1;
        }
        [da, de]
    }

    #[test]
    fn one_pass_and_uniform_firings_give_the_two_pass_values() {
        // Firings of one azimuth, of interpolated azimuths, of a repeated azimuth
        // across firings, and of one return.
        let mut clean = Vec::new();
        for f in 0..120u32 {
            let len = if f % 17 == 3 { 1 } else { 32 - (f % 4) };
            for j in 0..len {
                let base = (f / 3) as f32 * 0.5;
                let azimuth = match f % 3 {
                    0 => base,
                    1 => base + j as f32 * 0.004,
                    _ => base + if j < 16 { 0.0 } else { 0.1 },
                };
                clean.push(Return {
                    azimuth,
                    range: 5.0,
                    packet: f / 12,
                    block: (f % 12) as u8,
                    laser: j as u8,
                    ..blank()
                });
            }
        }
        let ideal = IdealPower::new(
            &Default::default(),
            &Default::default(),
            &Default::default(),
        );
        let m = Mechanics {
            azimuth_offset_deg: 0.3,
            eccentricity_deg: 0.01,
            jitter_deg: 0.005,
            wobble_deg: 0.02,
            spin_rate_sigma: 0.001,
            phases: [0.7, 4.1],
        };
        let wobble_only = Mechanics {
            azimuth_offset_deg: 0.0,
            eccentricity_deg: 0.0,
            jitter_deg: 0.0,
            spin_rate_sigma: 0.0,
            ..m.clone()
        };
        let shift_only = Mechanics {
            wobble_deg: 0.0,
            ..m.clone()
        };
        for (k, m) in [m, wobble_only, shift_only].iter().enumerate() {
            let mut frame = NoisyFrame::with_layout(2, clean.clone(), &ideal);
            m.apply(&mut frame, &mut stage_rng(9, 2, 5));
            let [da, de] = reference(m, &clean, &mut stage_rng(9, 2, 5));
            for (got, want) in [
                (&frame.moved.azimuth_deg, da),
                (&frame.moved.elevation_deg, de),
            ] {
                if let Some(got) = got {
                    assert!(
                        got.iter()
                            .zip(&want)
                            .all(|(a, b)| a.to_bits() == b.to_bits()),
                        "{k}"
                    );
                } else {
                    assert!(want.iter().all(|&x| x == 0.0), "{k}");
                }
            }
        }
    }
}
