//! Rain (factor 11) after Goodin et al. 2019.
//!
//! With rain rate R in mm/h: extinction alpha = 0.01 R^0.6 (1/m, their Eq. 5); power
//! P_n = P * exp(-2 alpha R_i) with the range before the noise (Eq. 7); range
//! R_n = R_i + sigma z with sigma = 0.02 R_i (1 - exp(-R))^2 and z standard normal
//! (Eq. 9, `range_noise = "goodin"`), or R_n = R_i + u with u uniform in +-1.5 cm
//! (`range_noise = "mavs"`, Goodin's MAVS simulator). There is no random drop: a return
//! is lost only when its power falls under the detection threshold.
//!
//! Exactly one draw is made per return, in return order, for every return — including
//! returns already occluded — so the stream stays aligned whatever the other stages do,
//! and the same seed at another rain rate reuses the same z (common random numbers).
//! The fits were made up to about 7 mm/h; higher rates run with a warning.

use crate::config::reader::Section;
use crate::error::Result;
use crate::noise::{NoiseStage, NoisyFrame};
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use serde::Serialize;
use std::sync::Arc;
use toml::Value;

/// The `type` name of this stage.
pub const NAME: &str = "rain";

/// Highest rain rate of the data the model was fitted on, in mm/h.
pub const FITTED_MAX_RATE_MM_H: f64 = 7.0;

/// Half-width of the MAVS uniform range jitter in metres.
pub const MAVS_JITTER_M: f64 = 0.015;

/// Which range noise to add.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum RangeNoise {
    /// Gaussian of Eq. 9, growing with range and rate.
    Goodin,
    /// Uniform +-1.5 cm as in MAVS.
    Mavs,
}

/// The rain stage.
#[derive(Clone, Debug)]
pub struct Rain {
    /// Rain rate in mm/h.
    pub rate_mm_h: f64,
    /// Range noise model.
    pub range_noise: RangeNoise,
    /// Extinction coefficient alpha in 1/m.
    alpha: f64,
    /// sigma / R_i.
    sigma_per_m: f64,
}

/// Extinction coefficient alpha (1/m) at `rate` mm/h (Goodin Eq. 5).
pub fn extinction_per_m(rate_mm_h: f64) -> f64 {
    0.01 * rate_mm_h.powf(0.6)
}

/// Standard deviation (m) of the range noise at `range` metres and `rate` mm/h (Eq. 9).
pub fn range_sigma_m(range_m: f64, rate_mm_h: f64) -> f64 {
    let g = 1.0 - (-rate_mm_h).exp();
    0.02 * range_m * g * g
}

impl Rain {
    /// Builds the stage for a valid (non-negative, finite) rate.
    pub fn new(rate_mm_h: f64, range_noise: RangeNoise) -> Self {
        Rain {
            rate_mm_h,
            range_noise,
            alpha: extinction_per_m(rate_mm_h),
            sigma_per_m: range_sigma_m(1.0, rate_mm_h),
        }
    }
}

impl NoiseStage for Rain {
    fn kind(&self) -> &'static str {
        NAME
    }

    fn describe(&self) -> String {
        let noise = match self.range_noise {
            RangeNoise::Goodin => format!(
                "Gaussian range noise sigma = {:.4} x range",
                self.sigma_per_m
            ),
            RangeNoise::Mavs => "uniform range noise +-1.5 cm (MAVS)".into(),
        };
        format!(
            "{} mm/h, alpha = {:.5} 1/m, {noise}",
            self.rate_mm_h, self.alpha
        )
    }

    fn settings(&self) -> Vec<(&'static str, Value)> {
        let noise = match self.range_noise {
            RangeNoise::Goodin => "goodin",
            RangeNoise::Mavs => "mavs",
        };
        vec![
            ("rate_mm_h", Value::Float(self.rate_mm_h)),
            ("range_noise", Value::String(noise.into())),
        ]
    }

    fn apply(&self, frame: &mut NoisyFrame, rng: &mut ChaCha8Rng) {
        let two_alpha = 2.0 * self.alpha;
        for ((range, power), fate) in frame
            .range
            .iter_mut()
            .zip(frame.power.iter_mut())
            .zip(frame.fate.iter())
        {
            // Draw before looking at the fate: one draw per return keeps streams aligned.
            let draw = match self.range_noise {
                RangeNoise::Goodin => rng.sample::<f64, _>(StandardNormal),
                RangeNoise::Mavs => MAVS_JITTER_M * (2.0 * rng.random::<f64>() - 1.0),
            };
            if !fate.is_alive() {
                continue;
            }
            let r_i = f64::from(*range);
            *power *= (-two_alpha * r_i).exp();
            let delta = match self.range_noise {
                RangeNoise::Goodin => self.sigma_per_m * r_i * draw,
                RangeNoise::Mavs => draw,
            };
            *range = (r_i + delta) as f32;
        }
    }
}

/// Reads the options of a `rain` entry.
pub fn build(opts: &Section<'_>) -> Result<Arc<dyn NoiseStage>> {
    let Some(rate) = opts.f64("rate_mm_h")? else {
        return Err(opts.missing("rate_mm_h"));
    };
    if rate < 0.0 {
        return Err(opts.error("rate_mm_h", format!("{rate} is negative")));
    }
    if rate > FITTED_MAX_RATE_MM_H {
        opts.warn(
            "rate_mm_h",
            format!(
                "{rate} mm/h is above the {FITTED_MAX_RATE_MM_H} mm/h the Goodin fit was made on; \
                 the model extrapolates"
            ),
        );
    }
    let range_noise = match opts.choice("range_noise", &["goodin", "mavs"])? {
        Some("mavs") => RangeNoise::Mavs,
        _ => RangeNoise::Goodin,
    };
    Ok(Arc::new(Rain::new(rate, range_noise)))
}

/// The registry entry of this stage.
pub const KIND: crate::noise::StageKind = crate::noise::StageKind {
    name: NAME,
    factor: "11 weather (rain)",
    model: "two-way extinction exp(-2 alpha R) on power and Gaussian range noise (Goodin Eq. 9) or MAVS uniform noise",
    source: "Goodin et al., Electronics 2019; noise-models.md",
    options: &[
        crate::noise::registry::OptionSpec { name: "rate_mm_h", unit: "mm/h", default: "required", doc: "rain rate" },
        crate::noise::registry::OptionSpec { name: "range_noise", unit: "-", default: "\"goodin\"", doc: "\"goodin\" (Eq. 9 Gaussian) or \"mavs\" (uniform +-1.5 cm)" },
    ],
    build,
};
