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
//!
//! Backscatter (option `backscatter = true`, off by default so the reference study is
//! unchanged): echoes of drops at short range by LISA's Monte Carlo (Kilic et al. 2021;
//! see [`super::particles`]): Marshall-Palmer drops N(D) = 8000 exp(-4.1 R^-0.21 D) per
//! m^3 per mm between 0.05 and 6 mm (larger drops break up), water (index 1.328,
//! Fresnel rho_F = 0.0199), a cone of full divergence `divergence_mrad`; each detectable
//! drop echo is proposed to the beam's firing slot and competes there once with the
//! target (strongest mode: a drop echo stronger than the target replaces it). The drop
//! echoes are attenuated with Goodin's alpha, not LISA's Mie alpha: one extinction per
//! medium (pdiagram-models.md, "Interactions"). The backscatter draws come after the
//! range-noise draws of every return, from the same stream, so switching it on leaves
//! the range noise unchanged (common random numbers).

use super::particles::Particles;
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
    /// Drop echoes (LISA), when on: the drop population.
    pub backscatter: Option<Backscatter>,
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

/// The drop echoes of the `backscatter` option.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Backscatter {
    /// Full beam divergence in mrad.
    pub divergence_mrad: f64,
    /// Drop echoes also in slots without a return.
    pub empty_slots: bool,
    /// The drops.
    pub drops: Particles,
}

/// Refractive index of water at 905 nm (LISA).
pub const WATER_INDEX: f64 = 1.328;

/// Largest drop drawn (mm): larger drops break up.
pub const DROP_MAX_MM: f64 = 6.0;

/// N0 (1/(m^3 mm)) and Lambda (1/mm) of the Marshall-Palmer law at `rate` mm/h (LISA).
pub fn marshall_palmer(rate_mm_h: f64) -> (f64, f64) {
    (8000.0, 4.1 * rate_mm_h.powf(-0.21))
}

impl Backscatter {
    /// Drops at `rate_mm_h` in a beam of `divergence_mrad`.
    pub fn new(rate_mm_h: f64, divergence_mrad: f64, empty_slots: bool) -> Self {
        let (n0, lambda) = if rate_mm_h > 0.0 {
            marshall_palmer(rate_mm_h)
        } else {
            (0.0, f64::INFINITY)
        };
        Backscatter {
            divergence_mrad,
            empty_slots,
            drops: Particles::new(n0, lambda, DROP_MAX_MM, WATER_INDEX, divergence_mrad * 1e-3),
        }
    }
}

impl Rain {
    /// Builds the stage for a valid (non-negative, finite) rate.
    pub fn new(rate_mm_h: f64, range_noise: RangeNoise) -> Self {
        Rain {
            rate_mm_h,
            range_noise,
            backscatter: None,
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
        let drops = match &self.backscatter {
            Some(b) => format!(
                ", drop echoes ({:.0} drops/m^3 above 0.05 mm, {} mrad beam)",
                b.drops.per_m3, b.divergence_mrad
            ),
            None => String::new(),
        };
        format!(
            "{} mm/h, alpha = {:.5} 1/m, {noise}{drops}",
            self.rate_mm_h, self.alpha
        )
    }

    fn settings(&self) -> Vec<(&'static str, Value)> {
        let noise = match self.range_noise {
            RangeNoise::Goodin => "goodin",
            RangeNoise::Mavs => "mavs",
        };
        let mut v = vec![
            ("rate_mm_h", Value::Float(self.rate_mm_h)),
            ("range_noise", Value::String(noise.into())),
        ];
        // Listed only when on, so the reference study's reports stay byte-identical.
        if let Some(b) = &self.backscatter {
            v.push(("backscatter", Value::Boolean(true)));
            v.push(("divergence_mrad", Value::Float(b.divergence_mrad)));
            v.push(("empty_slots", Value::Boolean(b.empty_slots)));
        }
        v
    }

    fn proposes_echoes(&self) -> bool {
        self.backscatter.is_some_and(|b| !b.drops.is_empty())
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
        if let Some(b) = &self.backscatter {
            super::snow::propose_particle_echoes(frame, rng, &b.drops, self.alpha, b.empty_slots);
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
    let mut rain = Rain::new(rate, range_noise);
    if super::bool_option(opts, "backscatter", false)? {
        let divergence = crate::noise::sensor::number(opts, "divergence_mrad", 3.0, 0.01, 100.0)?;
        let empty_slots = super::bool_option(opts, "empty_slots", true)?;
        rain.backscatter = Some(Backscatter::new(rate, divergence, empty_slots));
    } else {
        for key in ["divergence_mrad", "empty_slots"] {
            if opts.has(key) {
                return Err(opts.error(key, "only used with backscatter = true"));
            }
        }
    }
    Ok(Arc::new(rain))
}

/// The registry entry of this stage.
pub const KIND: crate::noise::StageKind = crate::noise::StageKind {
    name: NAME,
    factor: "11 weather (rain)",
    model: "two-way extinction exp(-2 alpha R) on power and Gaussian range noise (Goodin Eq. 9) or MAVS uniform noise; optional drop echoes (LISA Monte Carlo)",
    source: "Goodin et al., Electronics 2019; noise-models.md; backscatter: Kilic et al. 2021 (LISA)",
    options: &[
        crate::noise::registry::OptionSpec { name: "rate_mm_h", unit: "mm/h", default: "required", doc: "rain rate" },
        crate::noise::registry::OptionSpec { name: "range_noise", unit: "-", default: "\"goodin\"", doc: "\"goodin\" (Eq. 9 Gaussian) or \"mavs\" (uniform +-1.5 cm)" },
        crate::noise::registry::OptionSpec { name: "backscatter", unit: "-", default: "false", doc: "drop echoes at short range (LISA Monte Carlo, Marshall-Palmer drops), proposed to the firing slot" },
        crate::noise::registry::OptionSpec { name: "divergence_mrad", unit: "mrad", default: "3", doc: "with backscatter: full beam divergence of the Monte Carlo cone" },
        crate::noise::registry::OptionSpec { name: "empty_slots", unit: "-", default: "true", doc: "with backscatter: drop echoes also in firing slots without a return" },
    ],
    build,
};
