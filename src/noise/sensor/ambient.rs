//! Ambient conditions (p-diagram 13): sunlight raises the receiver's noise floor so weak
//! returns drop; temperature shifts the range.
//!
//! Model (pdiagram-models.md, 13): background power P_bg = k_sun * E/E_ref in units of
//! p_th. The doc raises the receiver's noise SD to s_n sqrt(1 + P_bg); this stage keeps
//! the detection deterministic and raises the threshold by the background instead: a
//! return is dropped (`below_power`) when P < p_th (1 + P_bg) (a stated simplification;
//! use `receiver.sigma_noise` for the random part). Temperature: R' = R + k_R (T - T0),
//! T0 = 25 C, k_R in mm per degree C, default 0.5 mm/C: an engineering assumption (the
//! doc suggests 0.0005 m/K to try; Glennie and Lichti 2011 report warm-up drift of an
//! HDL-64E without a coefficient we could verify). False sun returns are part 2 (they add
//! returns). Deterministic (no draws).
//!
//! Defaults: a scenario's conditions, not the unit's: no sun and the calibration
//! temperature, so no change (`sensor`, "What the defaults stand for").

use super::{float, number};
use crate::config::reader::Section;
use crate::error::Result;
use crate::noise::registry::OptionSpec;
use crate::noise::{Fate, NoiseStage, NoisyFrame, StageKind};
use rand_chacha::ChaCha8Rng;
use std::sync::Arc;
use toml::Value;

/// The `type` name of this stage.
pub const NAME: &str = "ambient";

/// Reference temperature of the range offset, degrees C.
pub const T0_C: f64 = 25.0;

/// The ambient stage.
#[derive(Clone, Debug)]
pub struct Ambient {
    /// Irradiance relative to full sun, E/E_ref.
    pub irradiance: f64,
    /// Background power per unit irradiance, in units of p_th.
    pub k_sun: f64,
    /// Temperature in degrees C.
    pub temperature_c: f64,
    /// Range offset per degree C from 25 C, mm.
    pub range_mm_per_c: f64,
}

impl NoiseStage for Ambient {
    fn kind(&self) -> &'static str {
        NAME
    }
    fn describe(&self) -> String {
        format!(
            "irradiance {} of full sun (threshold x {}), {} C ({:+.4} m range offset)",
            self.irradiance,
            1.0 + self.k_sun * self.irradiance,
            self.temperature_c,
            self.offset_m()
        )
    }
    fn settings(&self) -> Vec<(&'static str, Value)> {
        vec![
            ("irradiance", float(self.irradiance)),
            ("k_sun", float(self.k_sun)),
            ("temperature_c", float(self.temperature_c)),
            ("range_mm_per_c", float(self.range_mm_per_c)),
        ]
    }
    fn apply(&self, frame: &mut NoisyFrame, _rng: &mut ChaCha8Rng) {
        let p_bg = self.k_sun * self.irradiance;
        let cut = frame.threshold * (1.0 + p_bg);
        let offset = self.offset_m();
        if p_bg == 0.0 && offset == 0.0 {
            return;
        }
        let stage = frame.stage;
        let NoisyFrame {
            fate,
            cause,
            power,
            range,
            ..
        } = frame;
        for (((f, c), &p), r) in fate
            .iter_mut()
            .zip(cause.iter_mut())
            .zip(power.iter())
            .zip(range.iter_mut())
        {
            if !f.is_alive() {
                continue;
            }
            if p_bg > 0.0 && p < cut {
                // As `NoisyFrame::set_fate` (the frame is borrowed field by field).
                *f = Fate::BelowPower;
                *c = stage;
            } else if offset != 0.0 {
                *r = (f64::from(*r) + offset) as f32;
            }
        }
    }
}

impl Ambient {
    /// The temperature range offset in metres.
    pub fn offset_m(&self) -> f64 {
        self.range_mm_per_c * 1e-3 * (self.temperature_c - T0_C)
    }
}

/// Reads the options of an `ambient` entry.
pub fn build(opts: &Section<'_>) -> Result<Arc<dyn NoiseStage>> {
    Ok(Arc::new(Ambient {
        irradiance: number(opts, "irradiance", 0.0, 0.0, 10.0)?,
        k_sun: number(opts, "k_sun", 1.0, 0.0, 1e3)?,
        temperature_c: number(opts, "temperature_c", T0_C, -40.0, 85.0)?,
        range_mm_per_c: number(opts, "range_mm_per_c", 0.5, -100.0, 100.0)?,
    }))
}

/// The registry entry of this stage.
pub const KIND: StageKind = StageKind {
    name: NAME,
    factor: "13 ambient (sunlight, temperature)",
    model: "dropped if P < p_th (1 + k_sun E/E_ref); R' = R + k_R (T - 25 C)",
    source: "pdiagram-models.md 13 (k_sun = 1); k_R engineering assumption (doc: try 0.5 mm/K); datasheet operating range -10 to 60 C",
    options: &[
        OptionSpec { name: "irradiance", unit: "E/E_ref", default: "0", doc: "background irradiance, 1 = full sun" },
        OptionSpec { name: "k_sun", unit: "x p_th", default: "1", doc: "background power at full sun, in units of the threshold" },
        OptionSpec { name: "temperature_c", unit: "C", default: "25", doc: "sensor temperature, in [-40, 85]" },
        OptionSpec { name: "range_mm_per_c", unit: "mm/C", default: "0.5", doc: "range offset per degree from 25 C" },
    ],
    build,
};
