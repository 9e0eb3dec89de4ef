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
        let da = azimuth_moves.then(|| moved.azimuth_deg.get_or_insert_with(|| vec![0.0; n]));
        let de = wobbles.then(|| moved.elevation_deg.get_or_insert_with(|| vec![0.0; n]));
        if let Some(da) = da {
            for &[start, end] in &lay.firings {
                let idx = start as usize..end as usize;
                let jitter = if self.jitter_deg > 0.0 {
                    self.jitter_deg * normal(rng)
                } else {
                    0.0
                };
                // The first return of a firing always evaluates (as a new firing did).
                let mut last: Option<(u32, f32)> = None;
                for (d, &az) in da[idx.clone()].iter_mut().zip(&lay.azimuth[idx]) {
                    if last.is_none_or(|(bits, _)| bits != az.to_bits()) {
                        let a = f64::from(az);
                        let swept = (a - a_start).rem_euclid(360.0);
                        last = Some((
                            az.to_bits(),
                            (self.azimuth_offset_deg
                                + self.eccentricity_deg * (a.to_radians() + self.phases[0]).sin()
                                + jitter
                                + spin * swept) as f32,
                        ));
                    }
                    *d += last.map_or(0.0, |(_, s)| s);
                }
            }
        }
        if let Some(de) = de {
            let mut last = (f32::NAN, 0.0f32);
            for (d, &az) in de.iter_mut().zip(&lay.azimuth) {
                if az.to_bits() != last.0.to_bits() {
                    let a = f64::from(az).to_radians();
                    last = (az, (self.wobble_deg * (a + self.phases[1]).sin()) as f32);
                }
                *d += last.1;
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
