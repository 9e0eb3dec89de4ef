//! Emitter degradation and drift (p-diagram 03): laser output falls with age and drifts
//! over operating time.
//!
//! Model (pdiagram-models.md, 03): P' = P * f(h), f(h) = power_factor * (1 -
//! drift_per_hour * h), clamped at 0, with h the hours of capture time, taken as the
//! return's firing time since the top of the hour in which the capture starts
//! (`Return::time`/3600: the capture's own clock, no wall clock). The doc's
//! (1 - d_age h/h_life) becomes `power_factor` (age at the start of the capture) and its
//! temperature terms are left to `ambient` (factor 13), which owns the temperature.
//! Intensity follows power: I' = clamp(round(f I)). Deterministic (no draws). Source:
//! engineering assumption (no ageing data for HDL-32E emitters was found); the default
//! 0.9 is half of the doc's 20 % end-of-life loss.

use super::{float, number, scale_byte, CHUNK};
use crate::config::reader::Section;
use crate::error::Result;
use crate::noise::registry::OptionSpec;
use crate::noise::{NoiseStage, NoisyFrame, StageKind};
use rand_chacha::ChaCha8Rng;
use std::sync::Arc;
use toml::Value;

/// The `type` name of this stage.
pub const NAME: &str = "emitter";

/// The emitter stage.
#[derive(Clone, Debug)]
pub struct Emitter {
    /// Power factor at the start of the capture.
    pub power_factor: f64,
    /// Relative power loss per hour of capture time.
    pub drift_per_hour: f64,
}

impl NoiseStage for Emitter {
    fn kind(&self) -> &'static str {
        NAME
    }
    fn describe(&self) -> String {
        format!(
            "emitted power x {} minus {} per hour of capture time",
            self.power_factor, self.drift_per_hour
        )
    }
    fn settings(&self) -> Vec<(&'static str, Value)> {
        vec![
            ("power_factor", float(self.power_factor)),
            ("drift_per_hour", float(self.drift_per_hour)),
        ]
    }
    fn apply(&self, frame: &mut NoisyFrame, _rng: &mut ChaCha8Rng) {
        if self.power_factor == 1.0 && self.drift_per_hour == 0.0 {
            return;
        }
        // Times and intensities from the frame's compact columns (not the 48-byte returns).
        let lay = frame.layout();
        let NoisyFrame {
            power, fate, moved, ..
        } = frame;
        let inten = moved.intensity.get_or_insert_with(|| lay.intensity.clone());
        let mut f = [0.0f64; CHUNK];
        for (((times, power), inten), fate) in lay
            .time
            .chunks(CHUNK)
            .zip(power.chunks_mut(CHUNK))
            .zip(inten.chunks_mut(CHUNK))
            .zip(fate.chunks(CHUNK))
        {
            // The factors of a chunk first, free of branches (the divisions vectorise).
            let f = &mut f[..times.len()];
            for (f, &t) in f.iter_mut().zip(times) {
                let h = t / 3600.0;
                *f = (self.power_factor * (1.0 - self.drift_per_hour * h)).max(0.0);
            }
            for (((p, v), fate), &f) in power
                .iter_mut()
                .zip(inten.iter_mut())
                .zip(fate)
                .zip(f.iter())
            {
                if fate.is_alive() {
                    *p *= f;
                    *v = scale_byte(*v, f);
                }
            }
        }
    }
}

/// Reads the options of an `emitter` entry.
pub fn build(opts: &Section<'_>) -> Result<Arc<dyn NoiseStage>> {
    Ok(Arc::new(Emitter {
        power_factor: number(opts, "power_factor", 0.9, 0.0, 1.0)?,
        drift_per_hour: number(opts, "drift_per_hour", 0.0, -1.0, 1.0)?,
    }))
}

/// The registry entry of this stage.
pub const KIND: StageKind = StageKind {
    name: NAME,
    factor: "03 emitter (degradation, drift)",
    model: "P' = P power_factor (1 - drift_per_hour h), h = firing time / 3600 s; I' = f I",
    source: "engineering assumption (pdiagram-models.md 03: 20 % loss at end of life; a 20 % loss shortens the detectable range by 11 %)",
    options: &[
        OptionSpec { name: "power_factor", unit: "-", default: "0.9", doc: "emitted power relative to new, in [0, 1]" },
        OptionSpec { name: "drift_per_hour", unit: "1/h", default: "0", doc: "relative power loss per hour of capture time" },
    ],
    build,
};
