//! Laser diode piece to piece (p-diagram 01): each emitter/receiver pair has its own
//! power, range offset and pointing error, fixed for the unit.
//!
//! Model (pdiagram-models.md, 01): per laser l, P' = g_l P with g_l = exp(N(0, s_g^2)),
//! R' = R + b_l with b_l ~ N(0, s_b^2), I' = clamp(round(g_l I), 0, 255); plus (this
//! issue) elevation and azimuth offsets ~ N(0, s^2) in degrees: the point is reported
//! along the turned direction at its range (the scene is not re-ray-cast: the range the
//! turned beam would have measured is unknown). All draws are made once per seed from
//! the stage's unit stream, four per laser in a fixed order, so a value given per laser
//! replaces its draw without moving the others. Source: Levinson and Thrun, ISER 2010
//! (per-beam intensity response and range offsets); defaults are engineering
//! assumptions under the HDL-32E's 2 cm accuracy.

use super::{float, normal, per_laser, scale_byte, sigma};
use crate::config::reader::Section;
use crate::error::Result;
use crate::noise::registry::OptionSpec;
use crate::noise::{NoiseStage, NoisyFrame, StageKind};
use rand_chacha::ChaCha8Rng;
use std::sync::Arc;
use toml::Value;

/// The `type` name of this stage.
pub const NAME: &str = "laser_diode";

/// The laser-diode stage.
#[derive(Clone, Debug)]
pub struct LaserDiode {
    /// SD of the log power factor.
    pub sigma_power: f64,
    /// SD of the range bias, metres.
    pub sigma_range_m: f64,
    /// SD of the elevation offset, degrees.
    pub sigma_elevation_deg: f64,
    /// SD of the azimuth offset, degrees.
    pub sigma_azimuth_deg: f64,
    /// Given per-laser values (power factor, range bias, elevation, azimuth offset).
    pub given: [Option<Vec<f64>>; 4],
    /// Values in use per laser: power factor, range bias m, elevation deg, azimuth deg.
    pub values: [[f64; 32]; 4],
}

impl NoiseStage for LaserDiode {
    fn kind(&self) -> &'static str {
        NAME
    }
    fn describe(&self) -> String {
        format!(
            "per-laser power lognormal SD {}, range bias SD {} m, elevation SD {} deg, azimuth SD {} deg (once per seed)",
            self.sigma_power, self.sigma_range_m, self.sigma_elevation_deg, self.sigma_azimuth_deg
        )
    }
    fn settings(&self) -> Vec<(&'static str, Value)> {
        let mut v = vec![
            ("sigma_power", float(self.sigma_power)),
            ("sigma_range_m", float(self.sigma_range_m)),
            ("sigma_elevation_deg", float(self.sigma_elevation_deg)),
            ("sigma_azimuth_deg", float(self.sigma_azimuth_deg)),
        ];
        for (name, g) in GIVEN_KEYS.iter().zip(&self.given) {
            if let Some(g) = g {
                v.push((name, Value::Array(g.iter().map(|&x| float(x)).collect())));
            }
        }
        v
    }
    fn with_unit_draws(&self, rng: &mut ChaCha8Rng) -> Option<Arc<dyn NoiseStage>> {
        let mut s = self.clone();
        for l in 0..32 {
            let d = [normal(rng), normal(rng), normal(rng), normal(rng)];
            s.values[0][l] = (self.sigma_power * d[0]).exp();
            s.values[1][l] = self.sigma_range_m * d[1];
            s.values[2][l] = self.sigma_elevation_deg * d[2];
            s.values[3][l] = self.sigma_azimuth_deg * d[3];
            for (k, g) in self.given.iter().enumerate() {
                if let Some(g) = g {
                    s.values[k][l] = g[l];
                }
            }
        }
        Some(Arc::new(s))
    }
    fn apply(&self, frame: &mut NoisyFrame, _rng: &mut ChaCha8Rng) {
        let [gain, bias, elev, azim] = &self.values;
        let n = frame.len();
        let gains = gain.iter().any(|&g| g != 1.0);
        let biases = bias.iter().any(|&b| b != 0.0);
        if gains || biases {
            let clean = &frame.clean;
            let mut inten = if gains {
                Some(
                    frame
                        .moved
                        .intensity
                        .get_or_insert_with(|| clean.iter().map(|r| r.intensity).collect()),
                )
            } else {
                None
            };
            // One pass over the returns; the laser's values are looked up once.
            for i in 0..n {
                if !frame.fate[i].is_alive() {
                    continue;
                }
                let l = usize::from(clean[i].laser) % 32;
                if let Some(inten) = inten.as_deref_mut() {
                    let g = gain[l];
                    frame.power[i] *= g;
                    inten[i] = scale_byte(inten[i], g);
                }
                if biases {
                    frame.range[i] = (f64::from(frame.range[i]) + bias[l]) as f32;
                }
            }
        }
        for (values, is_azimuth) in [(elev, false), (azim, true)] {
            if values.iter().all(|&v| v == 0.0) {
                continue;
            }
            let offsets = values.map(|v| v as f32);
            let clean = &frame.clean;
            let target = if is_azimuth {
                frame.moved.azimuth_mut(n)
            } else {
                frame.moved.elevation_mut(n)
            };
            for (t, r) in target.iter_mut().zip(clean) {
                *t += offsets[usize::from(r.laser) % 32];
            }
        }
    }
}

const GIVEN_KEYS: [&str; 4] = [
    "power_factors",
    "range_bias_m",
    "elevation_offsets_deg",
    "azimuth_offsets_deg",
];

/// Reads the options of a `laser_diode` entry.
pub fn build(opts: &Section<'_>) -> Result<Arc<dyn NoiseStage>> {
    let given = [
        per_laser(opts, GIVEN_KEYS[0], 0.0, 10.0)?,
        per_laser(opts, GIVEN_KEYS[1], -1.0, 1.0)?,
        per_laser(opts, GIVEN_KEYS[2], -5.0, 5.0)?,
        per_laser(opts, GIVEN_KEYS[3], -5.0, 5.0)?,
    ];
    Ok(Arc::new(LaserDiode {
        sigma_power: sigma(opts, "sigma_power", 0.10, 2.0)?,
        sigma_range_m: sigma(opts, "sigma_range_m", 0.01, 1.0)?,
        sigma_elevation_deg: sigma(opts, "sigma_elevation_deg", 0.01, 5.0)?,
        sigma_azimuth_deg: sigma(opts, "sigma_azimuth_deg", 0.01, 5.0)?,
        given,
        values: [[1.0; 32], [0.0; 32], [0.0; 32], [0.0; 32]],
    }))
}

/// The registry entry of this stage.
pub const KIND: StageKind = StageKind {
    name: NAME,
    factor: "01 laser diode (piece to piece)",
    model: "per laser, once per seed: P' = g_l P, g_l = exp(N(0, s_g^2)); R' = R + N(0, s_b^2); elevation and azimuth offsets N(0, s^2); I' = g_l I",
    source: "Levinson and Thrun, ISER 2010 (per-beam response and range offsets); defaults engineering assumption within the 2 cm spec",
    options: &[
        OptionSpec { name: "sigma_power", unit: "-", default: "0.10", doc: "SD of the per-laser log power factor" },
        OptionSpec { name: "sigma_range_m", unit: "m", default: "0.01", doc: "SD of the per-laser range bias b_l" },
        OptionSpec { name: "sigma_elevation_deg", unit: "deg", default: "0.01", doc: "SD of the per-laser elevation offset" },
        OptionSpec { name: "sigma_azimuth_deg", unit: "deg", default: "0.01", doc: "SD of the per-laser azimuth offset" },
        OptionSpec { name: "power_factors", unit: "-", default: "drawn", doc: "32 given power factors (replace the draws)" },
        OptionSpec { name: "range_bias_m", unit: "m", default: "drawn", doc: "32 given range biases" },
        OptionSpec { name: "elevation_offsets_deg", unit: "deg", default: "drawn", doc: "32 given elevation offsets" },
        OptionSpec { name: "azimuth_offsets_deg", unit: "deg", default: "drawn", doc: "32 given azimuth offsets" },
    ],
    build,
};
