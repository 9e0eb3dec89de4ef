//! Mechanics (p-diagram 04): encoder offset, eccentricity and jitter shift the reported
//! azimuth of a firing; a wobbling spin axis tilts the beams once per turn; spin-rate
//! variation stretches the azimuth spacing within a rotation.
//!
//! Model (pdiagram-models.md, 04), per firing (the 32 returns of one data block share
//! one draw and one encoder angle a_f, the azimuth of the firing's first return):
//! a' = a + a0 + A1 sin(a_f + phi1) + N(0, s_a^2) + e (a - a_start);
//! w' = w + W sin(a_f + phi_w). phi1 and phi_w are drawn uniform once per seed (unit
//! stream); e ~ N(0, s_e^2) once per frame (the doc's slow random walk of the rate,
//! frozen over one 0.1 s rotation), then one normal per firing when s_a > 0 (drawn
//! together, see `fill_normals`), from the frame stream. `a_start` is the azimuth of the
//! frame's first return; the swept angle is taken modulo 360. Source: Glennie and
//! Lichti, Remote Sensing 3(3), 2011 (encoder misalignment found only marginally
//! significant); magnitudes are engineering assumptions below the 0.01 deg reporting step
//! and the 0.166 deg firing step.
//!
//! Defaults: the spread between units (encoder, bearing and spin-control tolerances of
//! another unit), to add to a recording; they move angles, not ranges (`sensor`, "What
//! the defaults stand for").

use super::{fill_normals, float, normal, number, sigma, sin_plus, SineTrack};
use crate::config::reader::Section;
use crate::error::Result;
use crate::noise::registry::OptionSpec;
use crate::noise::{NoiseStage, NoisyFrame, StageKind};
use crate::numeric::wrap_360;
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
        let lay = frame.layout();
        let moved = &mut frame.moved;
        let mut da = azimuth_moves.then(|| moved.azimuth_deg.get_or_insert_with(|| vec![0.0; n]));
        let mut de = wobbles.then(|| moved.elevation_deg.get_or_insert_with(|| vec![0.0; n]));
        let phases = self.phases.map(f64::sin_cos);
        let mut track = SineTrack::default();
        // One jitter draw per firing, in firing order, whatever the firing holds: all of
        // them at once (the ziggurat of `fill_normals`; one at a time cost a tenth of
        // the stage's time on real captures).
        let mut jitters = Vec::new();
        if da.is_some() && self.jitter_deg > 0.0 {
            jitters.resize(lay.firings.len(), 0.0);
            fill_normals(rng, &mut jitters);
        }
        for (f, &[start, end]) in lay.firings.iter().enumerate() {
            let idx = start as usize..end as usize;
            let jitter = jitters.get(f).map_or(0.0, |&n| self.jitter_deg * n);
            let az = &lay.azimuth[idx.clone()];
            let Some(&first) = az.first() else {
                continue;
            };
            // The encoder reads one angle per firing and the doc's model is per firing
            // (pdiagram-models.md 04: the errors "shift a for all 32 returns of a
            // firing"), so the once-per-turn sines are taken at the firing's azimuth,
            // that of its first return. The decoder's interpolated azimuths within a
            // firing span about 0.003 rad, so taking the sines at each of them instead
            // would move the shift by at most A1 * 0.003 (3e-5 deg at the default A1),
            // far below the 0.01 deg reporting step; it cost two libm sines per return
            // on real captures, most of the sensor chain's time. sin and cos of a_f are
            // carried from firing to firing ([`SineTrack`], within 1e-13 of libm's), the
            // phases added by angle addition.
            let sc = track.at(f64::from(first).to_radians());
            if let Some(da) = da.as_deref_mut() {
                let base = self.azimuth_offset_deg
                    + self.eccentricity_deg * sin_plus(sc, phases[0])
                    + jitter;
                let da = &mut da[idx.clone()];
                // The spin-rate error stretches the azimuth swept since the frame's first
                // return, `wrap_360(a - a_start)`: per return, as the decoder
                // interpolates per return. For azimuths within a turn of `a_start`
                // (every decoded one) that is a select the loop vectorises.
                let within = || {
                    az.iter()
                        .fold(true, |w, &a| w & ((f64::from(a) - a_start).abs() < 360.0))
                };
                if spin == 0.0 {
                    let s = base as f32;
                    da.iter_mut().for_each(|d| *d += s);
                } else if within() {
                    for (d, &a) in da.iter_mut().zip(az) {
                        let v = f64::from(a) - a_start;
                        let v = if v < 0.0 { v + 360.0 } else { v };
                        *d += (base + spin * v) as f32;
                    }
                } else {
                    for (d, &a) in da.iter_mut().zip(az) {
                        *d += (base + spin * wrap_360(f64::from(a) - a_start)) as f32;
                    }
                }
            }
            if let Some(de) = de.as_deref_mut() {
                let w = (self.wobble_deg * sin_plus(sc, phases[1])) as f32;
                de[idx].iter_mut().for_each(|e| *e += w);
            }
        }
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
    model: "per firing (encoder angle a_f, its first return's azimuth) a' = a + a0 + A1 sin(a_f + phi1) + N(0, s_a^2) + e (a - a_start); w' = w + W sin(a_f + phi_w); e ~ N(0, s_e^2) per frame",
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
    use crate::frame::Return;
    use crate::noise::{stage_rng, IdealPower};

    /// The model written out from the returns themselves (firings as runs of one
    /// packet and block): per firing, sines at its first return's azimuth, the jitter
    /// drawn in firing order; the spin term per return.
    fn reference(m: &Mechanics, clean: &[Return], rng: &mut ChaCha8Rng) -> [Vec<f32>; 2] {
        let n = clean.len();
        let spin = if m.spin_rate_sigma > 0.0 {
            m.spin_rate_sigma * normal(rng)
        } else {
            0.0
        };
        let a_start = clean.first().map_or(0.0, |r| f64::from(r.azimuth));
        let (mut da, mut de) = (vec![0.0f32; n], vec![0.0f32; n]);
        // One jitter per firing, drawn together after the spin-rate error.
        let firings = clean
            .windows(2)
            .filter(|w| (w[0].packet, w[0].block) != (w[1].packet, w[1].block))
            .count()
            + usize::from(n > 0);
        let mut drawn = vec![0.0; if m.jitter_deg > 0.0 { firings } else { 0 }];
        fill_normals(rng, &mut drawn);
        let mut jitters = drawn.into_iter();
        let mut start = 0;
        while start < n {
            let key = (clean[start].packet, clean[start].block);
            let mut end = start;
            while end < n && (clean[end].packet, clean[end].block) == key {
                end += 1;
            }
            let jitter = jitters.next().map_or(0.0, |n| m.jitter_deg * n);
            let a_f = f64::from(clean[start].azimuth).to_radians();
            for i in start..end {
                let swept = (f64::from(clean[i].azimuth) - a_start).rem_euclid(360.0);
                da[i] = (m.azimuth_offset_deg
                    + m.eccentricity_deg * (a_f + m.phases[0]).sin()
                    + jitter
                    + spin * swept) as f32;
                de[i] = (m.wobble_deg * (a_f + m.phases[1]).sin()) as f32;
            }
            start = end;
        }
        [da, de]
    }

    #[test]
    fn the_stage_gives_the_per_firing_model() {
        // Firings of one azimuth, of interpolated azimuths, of a repeated azimuth
        // across firings, and of one return.
        let mut clean = Vec::new();
        for f in 0..120u32 {
            let len = if f % 17 == 3 { 1 } else { 32 - (f % 4) };
            for j in 0..len {
                // From 355 degrees across north, so the swept angle wraps.
                let base = (355.0 + (f / 3) as f32 * 0.5) % 360.0;
                let azimuth = match f % 3 {
                    // One firing two turns beyond the others (no decoder makes it), so the
                    // swept angle also takes its general path.
                    _ if f == 50 => base + 720.0 + j as f32 * 0.004,
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
                    ..Return::BLANK
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
        let steady = Mechanics {
            spin_rate_sigma: 0.0,
            ..m.clone()
        };
        for (k, m) in [m, wobble_only, shift_only, steady].iter().enumerate() {
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
            // Without the spin term every return of a firing moves alike, interpolated
            // azimuths or not.
            if m.spin_rate_sigma == 0.0 {
                let lay = frame.layout();
                for &[a, b] in &lay.firings {
                    for c in [&frame.moved.azimuth_deg, &frame.moved.elevation_deg]
                        .into_iter()
                        .flatten()
                    {
                        let c = &c[a as usize..b as usize];
                        assert!(c.iter().all(|x| x.to_bits() == c[0].to_bits()), "{k}");
                    }
                }
            }
        }
    }
}
