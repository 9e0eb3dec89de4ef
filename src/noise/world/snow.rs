//! Snowfall (p-diagram 11): extinction of the hard-target power and echoes of flakes in
//! the beam, by a Marshall-Gunn particle model with LISA's Monte Carlo (LISA in snow mode;
//! pdiagram-models.md, "11 Weather: snow", its "simpler particle alternative").
//!
//! Model, at snowfall rate R (mm/h, water equivalent):
//! - flake sizes (Gunn and Marshall 1958, as in LISA's snow mode): N(D) = N0 exp(-Lambda D),
//!   N0 = 7.6e3 R^-0.87 per m^3 per mm, Lambda = 2.55 R^-0.48 per mm, D in mm, drawn
//!   between 0.05 and 10 mm; ice, refractive index 1.3031 (Fresnel rho_F = 0.0173);
//! - extinction alpha = int (pi/4) D^2 Q_ext N(D) dD with Q_ext = 2 (flakes are thousands
//!   of wavelengths across: the geometric-optics limit of Mie theory) = pi N0 / Lambda^3
//!   x 1e-6 (1/m); hard target P exp(-2 alpha R);
//! - flake echoes per beam by the Monte Carlo of [`super::particles`] (cone of full
//!   divergence 3 mrad, flakes nearer than 1.5 m ignored), each proposed to the beam's
//!   firing slot, where the sensor's return logic chooses once (strongest mode: a flake
//!   echo stronger than the target replaces it).
//!
//! Why not Hahner et al. (CVPR 2022): its flake sampling in per-channel planes, waveform
//! sums and HDL-64E intensity corrections need the sensor's waveform and noise-floor
//! curves, which are unknown for the HDL-32E; the particle model needs only the rate and
//! shares its machinery with the rain backscatter (LISA). Wet ground is not modelled.

use super::particles::{Particles, DEFAULT_KAPPA_M2};
use crate::config::reader::Section;
use crate::error::Result;
use crate::noise::registry::OptionSpec;
use crate::noise::sensor::{float, number};
use crate::noise::{Fate, NoiseStage, NoisyFrame, StageKind};
use rand_chacha::ChaCha8Rng;
use std::sync::Arc;
use toml::Value;

/// The `type` name of this stage.
pub const NAME: &str = "snow";

/// Refractive index of ice at 905 nm (LISA).
pub const ICE_INDEX: f64 = 1.3031;

/// Largest flake drawn (mm water equivalent).
pub const D_MAX_MM: f64 = 10.0;

/// N0 (1/(m^3 mm)) and Lambda (1/mm) of the Gunn-Marshall size law at `rate` mm/h.
pub fn size_law(rate_mm_h: f64) -> (f64, f64) {
    (7.6e3 * rate_mm_h.powf(-0.87), 2.55 * rate_mm_h.powf(-0.48))
}

/// Extinction alpha (1/m) at `rate` mm/h: pi N0 / Lambda^3 x 1e-6 (0 without snow).
pub fn extinction_per_m(rate_mm_h: f64) -> f64 {
    if rate_mm_h <= 0.0 {
        return 0.0;
    }
    let (n0, l) = size_law(rate_mm_h);
    std::f64::consts::PI * n0 / (l * l * l) * 1e-6
}

/// The snow stage.
#[derive(Clone, Debug)]
pub struct Snow {
    /// Snowfall rate in mm/h (water equivalent).
    pub rate_mm_h: f64,
    /// Full beam divergence in mrad.
    pub divergence_mrad: f64,
    /// Flake echoes also in slots without a return.
    pub empty_slots: bool,
    alpha: f64,
    particles: Particles,
}

impl Snow {
    /// The stage with these options (valid values assumed).
    pub fn new(rate_mm_h: f64, divergence_mrad: f64, empty_slots: bool) -> Snow {
        let (n0, lambda) = if rate_mm_h > 0.0 {
            size_law(rate_mm_h)
        } else {
            (0.0, f64::INFINITY)
        };
        Snow {
            rate_mm_h,
            divergence_mrad,
            empty_slots,
            alpha: extinction_per_m(rate_mm_h),
            particles: Particles::new(n0, lambda, D_MAX_MM, ICE_INDEX, divergence_mrad * 1e-3),
        }
    }

    /// Extinction alpha in 1/m.
    pub fn alpha(&self) -> f64 {
        self.alpha
    }

    /// The flake population.
    pub fn particles(&self) -> &Particles {
        &self.particles
    }
}

impl NoiseStage for Snow {
    fn kind(&self) -> &'static str {
        NAME
    }

    fn describe(&self) -> String {
        format!(
            "snowfall {} mm/h: alpha = {:.5} 1/m, {:.0} flakes/m^3 above 0.05 mm, echoes in a {} mrad beam",
            self.rate_mm_h, self.alpha, self.particles.per_m3, self.divergence_mrad
        )
    }

    fn settings(&self) -> Vec<(&'static str, Value)> {
        vec![
            ("rate_mm_h", float(self.rate_mm_h)),
            ("divergence_mrad", float(self.divergence_mrad)),
            ("empty_slots", Value::Boolean(self.empty_slots)),
        ]
    }

    fn proposes_echoes(&self) -> bool {
        !self.particles.is_empty()
    }

    fn apply(&self, frame: &mut NoisyFrame, rng: &mut ChaCha8Rng) {
        if self.rate_mm_h <= 0.0 {
            return;
        }
        let two_alpha = 2.0 * self.alpha;
        for ((power, &range), fate) in frame.power.iter_mut().zip(&frame.range).zip(&frame.fate) {
            if fate.is_alive() {
                *power *= (-two_alpha * f64::from(range)).exp();
            }
        }
        propose_particle_echoes(frame, rng, &self.particles, self.alpha, self.empty_slots);
    }
}

/// Proposes the particle echoes of every beam of `frame` (recorded returns, whatever their
/// fate except occluded, then empty slots when `empty_slots`), drawing from `rng` in that
/// order. Shared by `snow` and the `rain` backscatter.
pub fn propose_particle_echoes(
    frame: &mut NoisyFrame,
    rng: &mut ChaCha8Rng,
    particles: &Particles,
    alpha: f64,
    empty_slots: bool,
) {
    if particles.is_empty() {
        return;
    }
    let kappa = frame
        .power_model
        .as_ref()
        .map_or(DEFAULT_KAPPA_M2, |m| m.constants().kappa_m2);
    let (threshold, min_range) = (frame.threshold, frame.min_range);
    let cutoff = particles.cutoff_m(kappa, threshold);
    let slots = frame.slots();
    for i in 0..frame.clean_len {
        // Occlusion removes the beam: no particle is lit (and no draw is made).
        if frame.fate[i] == Fate::Occluded {
            continue;
        }
        let slot = slots.slot_of(i);
        particles.beam(
            rng,
            f64::from(frame.range[i]),
            cutoff,
            alpha,
            kappa,
            threshold,
            min_range,
            |e| frame.propose_slot(slot, e),
        );
    }
    if empty_slots {
        for slot in 0..slots.len() as u32 {
            if slots.is_vacant(slot) {
                particles.beam(
                    rng,
                    f64::INFINITY,
                    cutoff,
                    alpha,
                    kappa,
                    threshold,
                    min_range,
                    |e| frame.propose_slot(slot, e),
                );
            }
        }
    }
}

/// Reads the options of a `snow` entry.
pub fn build(opts: &Section<'_>) -> Result<Arc<dyn NoiseStage>> {
    if !opts.has("rate_mm_h") {
        return Err(opts.missing("rate_mm_h"));
    }
    let rate = number(opts, "rate_mm_h", 0.0, 0.0, 100.0)?;
    if rate > 10.0 {
        opts.warn(
            "rate_mm_h",
            format!(
                "{rate} mm/h of water-equivalent snowfall is far beyond heavy snow (> 2.5 mm/h)"
            ),
        );
    }
    let divergence_mrad = number(opts, "divergence_mrad", 3.0, 0.01, 100.0)?;
    let empty_slots = super::bool_option(opts, "empty_slots", true)?;
    Ok(Arc::new(Snow::new(rate, divergence_mrad, empty_slots)))
}

/// The registry entry of this stage.
pub const KIND: StageKind = StageKind {
    name: NAME,
    factor: "11 weather (snow)",
    model: "Gunn-Marshall flakes N0 = 7.6e3 R^-0.87, Lambda = 2.55 R^-0.48 /mm; alpha = pi N0/Lambda^3 (Q_ext = 2), P exp(-2 alpha R); flake echoes by LISA's Monte Carlo in a 3 mrad cone, proposed to the firing slot",
    source: "Kilic et al. 2021 (LISA, snow mode); Gunn and Marshall 1958; pdiagram-models.md 11 snow",
    options: &[
        OptionSpec { name: "rate_mm_h", unit: "mm/h", default: "required", doc: "snowfall rate, water equivalent (light < 1, moderate 1-2.5, heavy > 2.5)" },
        OptionSpec { name: "divergence_mrad", unit: "mrad", default: "3", doc: "full beam divergence of the Monte Carlo cone" },
        OptionSpec { name: "empty_slots", unit: "-", default: "true", doc: "flake echoes also in firing slots without a return" },
    ],
    build,
};

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn extinction_is_the_geometric_optics_integral() {
        // Numerical integral of (pi/4) D^2 2 N(D) dD (D in mm -> m^2 via 1e-6).
        let rate = 1.5;
        let (n0, l) = size_law(rate);
        let mut sum = 0.0;
        let h = 1e-4;
        let mut d = h / 2.0;
        while d < 40.0 {
            sum += std::f64::consts::FRAC_PI_4 * d * d * 2.0 * n0 * (-l * d).exp() * h;
            d += h;
        }
        let want = sum * 1e-6;
        assert!((extinction_per_m(rate) / want - 1.0).abs() < 1e-6);
        assert_eq!(extinction_per_m(0.0), 0.0);
    }
}
