//! Emitter degradation and drift (p-diagram 03): laser output falls with age and drifts
//! over operating time.
//!
//! Model (pdiagram-models.md, 03): P' = P * f(h), f(h) = power_factor * (1 -
//! drift_per_hour * h), clamped at 0, with h the hours of capture time, taken as the
//! return's firing time since the top of the hour in which the capture starts
//! (`Return::time`/3600: the capture's own clock, no wall clock). The doc's
//! (1 - d_age h/h_life) becomes `power_factor` (age at the start of the capture) and its
//! temperature terms are left to `ambient` (factor 13), which owns the temperature.
//! The byte follows the power through the chain's intensity rule (`noise`, "Intensity"):
//! this stage changes power only. Deterministic (no draws). Source:
//! engineering assumption (no ageing data for HDL-32E emitters was found); the default
//! 0.9 is half of the doc's 20 % end-of-life loss.
//! The default is the ageing of a unit relative to the recorded one (spread between
//! units, `sensor`, "What the defaults stand for").

use super::{float, number, CHUNK};
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
    fn uses_layout(&self) -> bool {
        true
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
        // Times from the frame's compact columns (not the 48-byte returns).
        let lay = frame.layout();
        let factor = |t: f64| {
            // A product with the rounded 1/3600, not the quotient: h is within about an
            // ulp of it (2e-16 relative, so the factor moves by drift x that at most),
            // and the division was a third of the stage's time on real firing times.
            let h = t * (1.0 / 3600.0);
            (self.power_factor * (1.0 - self.drift_per_hour * h)).max(0.0)
        };
        // f is monotone in t (a product with a positive constant, a product with a
        // constant, a subtraction from 1, a product with power_factor >= 0 and max(0),
        // each monotone), so the factor of every time in the frame's range lies between
        // the factors of its two ends.
        let [t0, t1] = lay.time_range;
        let (f0, f1) = (factor(t0), factor(t1));
        let NoisyFrame { power, fate, .. } = frame;
        if !lay.time_nan && f0.to_bits() == f1.to_bits() && f0 != 0.0 && f0.is_finite() {
            // One factor for the frame: every time lies between the two ends and f is
            // monotone, so every factor equals theirs (a non-zero value: zero could come
            // as +0 or -0). So no time is read: as when the drift is 0, or every return
            // of the frame has the same time.
            for (p, fate) in power.iter_mut().zip(fate.iter()) {
                *p = if fate.is_alive() { *p * f0 } else { *p };
            }
            return;
        }
        let mut f = [0.0f64; CHUNK];
        for ((times, power), fate) in lay
            .time
            .chunks(CHUNK)
            .zip(power.chunks_mut(CHUNK))
            .zip(fate.chunks(CHUNK))
        {
            // The factors of a chunk first, free of branches (the divisions vectorise).
            let f = &mut f[..times.len()];
            for (f, &t) in f.iter_mut().zip(times) {
                *f = factor(t);
            }
            // Branch free, so it vectorises: dead returns keep their power.
            for ((p, fate), &f) in power.iter_mut().zip(fate).zip(f.iter()) {
                *p = if fate.is_alive() { *p * f } else { *p };
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
    model: "P' = P power_factor (1 - drift_per_hour h), h = firing time / 3600 s (the byte follows by the intensity rule)",
    source: "engineering assumption (pdiagram-models.md 03: 20 % loss at end of life; a 20 % loss shortens the detectable range by 11 %)",
    options: &[
        OptionSpec { name: "power_factor", unit: "-", default: "0.9", doc: "emitted power relative to new, in [0, 1]" },
        OptionSpec { name: "drift_per_hour", unit: "1/h", default: "0", doc: "relative power loss per hour of capture time" },
    ],
    build,
};

#[cfg(test)]
mod tests {
    use super::*;
    use crate::frame::{Return, ReturnKind};
    use crate::noise::Fate;
    use crate::noise::IdealPower;

    /// Powers of `e` applied to returns of the given times (every third one
    /// dead), with those of the model's formula per return.
    fn against_formula(e: &Emitter, times: &[f64]) {
        let clean: Vec<Return> = times
            .iter()
            .enumerate()
            .map(|(i, &time)| Return {
                x: 1.0,
                y: 0.0,
                z: 0.0,
                range: 2.0 + i as f32 * 0.01,
                azimuth: 0.0,
                elevation: 0.0,
                time,
                packet: i as u32 / 384,
                raw_distance: 0,
                intensity: (i * 7 % 256) as u8,
                laser: (i % 32) as u8,
                ring: 0,
                block: (i / 32 % 12) as u8,
                kind: ReturnKind::Strongest,
            })
            .collect();
        let ideal = IdealPower::new(
            &Default::default(),
            &Default::default(),
            &Default::default(),
        );
        let mut frame = NoisyFrame::with_layout(0, clean.clone(), &ideal);
        for k in (0..frame.len()).step_by(3) {
            frame.fate[k] = Fate::BelowPower;
        }
        let before = frame.power.clone();
        e.apply(&mut frame, &mut crate::noise::stage_rng(1, 0, 0));
        // Power only: the byte is the intensity rule's.
        assert!(frame.moved.intensity.is_none());
        for (i, r) in clean.iter().enumerate() {
            let f =
                (e.power_factor * (1.0 - e.drift_per_hour * (r.time * (1.0 / 3600.0)))).max(0.0);
            let p = if frame.fate[i].is_alive() {
                before[i] * f
            } else {
                before[i]
            };
            assert_eq!(frame.power[i].to_bits(), p.to_bits(), "{i} {}", r.time);
        }
    }

    #[test]
    fn one_factor_frames_and_the_others_give_the_formula_s_values() {
        let drift = Emitter {
            power_factor: 0.9,
            drift_per_hour: 0.01,
        };
        let flat = Emitter {
            power_factor: 0.77,
            drift_per_hour: 0.0,
        };
        let off = Emitter {
            power_factor: 0.0,
            drift_per_hour: 0.5,
        };
        let same = vec![1234.5; 700];
        let varied: Vec<f64> = (0..700).map(|i| 100.0 + f64::from(i) * 1.152e-6).collect();
        let mut with_nan = same.clone();
        with_nan[333] = f64::NAN;
        let late: Vec<f64> = (0..700).map(|i| 7000.0 + f64::from(i) * 0.5).collect();
        for e in [&drift, &flat, &off] {
            for times in [&same, &varied, &with_nan, &late, &vec![0.0; 3], &vec![]] {
                against_formula(e, times);
            }
        }
    }
}
