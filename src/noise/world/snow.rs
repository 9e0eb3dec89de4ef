//! Snowfall (p-diagram 11): extinction of the hard-target power and echoes of flakes in
//! the beam, by a Marshall-Gunn particle model with LISA's Monte Carlo (LISA in snow mode;
//! pdiagram-models.md, "11 Weather: snow", its "simpler particle alternative").
//!
//! Units: `rate_mm_h` is the water-equivalent (melted) precipitation rate R that the
//! Gunn-Marshall law takes. Hahner et al. (CVPR 2022, "LiDAR Snowfall Simulation",
//! their released code `snowfall_rate_to_rainfall_rate`) give snowfall as a snowfall
//! rate S (mm/h, categories light 0-1, moderate 1-2.5, heavy > 2.5) with a terminal
//! velocity v_t and convert it to R = (S / (487 rho_s D_s v_t))^(3/2) with flake density
//! rho_s = 0.1 g/cm^3 and diameter D_s = 0.003 m. `preset` names their settings: light
//! (S 0.5 mm/h, v_t 2.0 m/s) R = 2.24 mm/h; moderate (1.0, 1.6) R = 8.85 mm/h; heavy
//! (2.5, 1.6) R = 34.97 mm/h. Before issue 29 a "moderate 1 mm/h" was fed as R = 1.
//!
//! Model, at water-equivalent rate R (mm/h):
//! - flake sizes (Gunn and Marshall 1958, as in LISA's snow mode): N(D) = N0 exp(-Lambda D),
//!   N0 = 7.6e3 R^-0.87 per m^3 per mm, Lambda = 2.55 R^-0.48 per mm, D in mm, drawn
//!   between 0.05 and 10 mm; ice, refractive index 1.3031 (Fresnel rho_F = 0.0173);
//! - extinction alpha = int (pi/4) D^2 Q_ext N(D) dD with Q_ext = 2 (flakes are thousands
//!   of wavelengths across: the geometric-optics limit of Mie theory) = pi N0 / Lambda^3
//!   x 1e-6 (1/m); hard target P exp(-2 alpha R);
//! - flake echoes per beam (cone of full divergence 3 mrad, flakes nearer than 1.5 m
//!   ignored), sampled only where detectable ([`super::particles::Population`]), each
//!   proposed to the beam's firing slot, where the sensor's return logic chooses once
//!   (strongest mode: a flake echo stronger than the target replaces it);
//! - flake backscatter by geometric optics: LISA's rule, the Fresnel reflectance of ice
//!   at normal incidence over the flake's cross-section (Lambertian disc), P_j =
//!   kappa rho_F exp(-2 alpha r) min(1, A_p/A_beam) / r^2. Flakes are not spheres; the
//!   Mie backscatter of a sphere at these sizes is dominated by the glory, an axial
//!   focusing that needs a perfect sphere (van de Hulst 1957, Ch. 17.4; Bohren & Huffman
//!   1983, Sec. 13.7), and irregular ice shows no glory; an ice sphere of the melted
//!   diameter would give Q_back/4 ~ 1 instead of rho_F = 0.017 (the rain stage does use
//!   Mie for drops, which are spheres). Unchanged from before issue 29 but for the
//!   sampling (only detectable flakes drawn), so the flake echoes keep their distribution
//!   and change their draws.
//!
//! Why not Hahner et al. (CVPR 2022): its flake sampling in per-channel planes, waveform
//! sums and HDL-64E intensity corrections need the sensor's waveform and noise-floor
//! curves, which are unknown for the HDL-32E; the particle model needs only the rate and
//! shares its machinery with the rain backscatter (LISA). Wet ground is not modelled.

use super::mie::Dsd;
use super::particles::{Particles, Population, Reflectance};
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

/// Hahner et al.'s snowfall presets: (name, snowfall rate S mm/h, terminal velocity m/s).
pub const PRESETS: [(&str, f64, f64); 3] = [
    ("light", 0.5, 2.0),
    ("moderate", 1.0, 1.6),
    ("heavy", 2.5, 1.6),
];

/// Water-equivalent rate (mm/h) of snowfall rate `s_mm_h` at terminal velocity `v_m_s`
/// (Hahner et al. 2022: R = (S / (487 rho_s D_s v_t))^(3/2), rho_s = 0.1, D_s = 0.003).
pub fn water_equivalent_mm_h(s_mm_h: f64, v_m_s: f64) -> f64 {
    (s_mm_h / (487.0 * 0.1 * 0.003 * v_m_s)).powf(1.5)
}

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
    /// Hahner's preset the rate came from, if any.
    pub preset: Option<&'static str>,
    alpha: f64,
    particles: Particles,
    population: Arc<Population>,
}

impl Snow {
    /// The stage with these options (valid values assumed).
    pub fn new(rate_mm_h: f64, divergence_mrad: f64, empty_slots: bool) -> Snow {
        let (n0, lambda) = if rate_mm_h > 0.0 {
            size_law(rate_mm_h)
        } else {
            (0.0, f64::INFINITY)
        };
        let dsd = Dsd::Gamma {
            n0,
            mu: 0.0,
            lambda_per_mm: lambda,
        };
        let population = Population::new(
            &dsd,
            super::particles::D_MIN_MM,
            D_MAX_MM,
            Reflectance::Fresnel(super::particles::fresnel(ICE_INDEX)),
            divergence_mrad * 1e-3,
        )
        // The HDL-32E's exit aperture and receiver field, as for rain drops.
        .with_optics(super::fog::hdl32e_optics());
        Snow {
            rate_mm_h,
            divergence_mrad,
            empty_slots,
            preset: None,
            alpha: extinction_per_m(rate_mm_h),
            particles: Particles::new(n0, lambda, D_MAX_MM, ICE_INDEX, divergence_mrad * 1e-3),
            population: Arc::new(population),
        }
    }

    /// Extinction alpha in 1/m.
    pub fn alpha(&self) -> f64 {
        self.alpha
    }

    /// The flake population (size law; LISA's Fresnel echo rule).
    pub fn particles(&self) -> &Particles {
        &self.particles
    }

    /// The flake population as sampled (detectable flakes only).
    pub fn population(&self) -> &Population {
        &self.population
    }
}

impl NoiseStage for Snow {
    fn kind(&self) -> &'static str {
        NAME
    }

    fn describe(&self) -> String {
        let preset = match self.preset {
            Some(p) => format!(" (Hahner's {p} preset)"),
            None => String::new(),
        };
        // A preset's rate is converted (2.2383844962893775 mm/h): three decimals are
        // what a reader needs; the settings keep the exact value.
        let rate = if self.preset.is_some() {
            format!("{:.3}", self.rate_mm_h)
                .trim_end_matches('0')
                .trim_end_matches('.')
                .to_string()
        } else {
            self.rate_mm_h.to_string()
        };
        format!(
            "snowfall {rate} mm/h water equivalent{preset}: alpha = {:.5} 1/m, {:.0} flakes/m^3 above 0.05 mm, echoes in a {} mrad beam",
            self.alpha, self.population.per_m3, self.divergence_mrad
        )
    }

    fn settings(&self) -> Vec<(&'static str, Value)> {
        // The preset is printed with its converted rate; the two agree, which build
        // accepts, so a printed configuration reruns the same.
        let mut v = Vec::new();
        v.extend([
            ("rate_mm_h", float(self.rate_mm_h)),
            (
                "preset",
                Value::String(self.preset.unwrap_or("none").into()),
            ),
            ("divergence_mrad", float(self.divergence_mrad)),
            ("empty_slots", Value::Boolean(self.empty_slots)),
        ]);
        v
    }

    fn proposes_echoes(&self) -> bool {
        !self.particles.is_empty()
    }

    fn apply(&self, frame: &mut NoisyFrame, rng: &mut ChaCha8Rng) {
        if self.rate_mm_h <= 0.0 {
            return;
        }
        crate::noise::transmission::attenuate(
            &mut frame.power,
            &frame.range,
            &frame.fate,
            2.0 * self.alpha,
        );
        super::particles::propose_population_echoes(
            frame,
            rng,
            &self.population,
            self.alpha,
            self.empty_slots,
        );
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
    let kappa = frame.kappa_m2();
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
    let preset = match opts.choice("preset", &["none", "light", "moderate", "heavy"])? {
        Some(name) if name != "none" => {
            let p = PRESETS.iter().find(|p| p.0 == name);
            if let (Some(&(_, s, v)), Some(rate)) = (p, opts.f64("rate_mm_h")?) {
                // Both only as a printed configuration writes them: the same rate.
                let want = water_equivalent_mm_h(s, v);
                if (rate - want).abs() > 1e-9 * want {
                    return Err(opts.error(
                        "preset",
                        format!(
                            "give either preset or rate_mm_h ({name} is {want} mm/h), not both"
                        ),
                    ));
                }
            }
            p
        }
        _ => {
            if !opts.has("rate_mm_h") {
                return Err(opts.missing("rate_mm_h"));
            }
            None
        }
    };
    let rate = match preset {
        Some(&(_, s, v)) => water_equivalent_mm_h(s, v),
        None => number(opts, "rate_mm_h", 0.0, 0.0, 100.0)?,
    };
    if preset.is_none() && rate > 40.0 {
        opts.warn(
            "rate_mm_h",
            format!("{rate} mm/h water equivalent is beyond Hahner's heavy preset (35 mm/h)"),
        );
    }
    let divergence_mrad = number(opts, "divergence_mrad", 3.0, 0.01, 100.0)?;
    let empty_slots = super::bool_option(opts, "empty_slots", true)?;
    let mut snow = Snow::new(rate, divergence_mrad, empty_slots);
    snow.preset = preset.map(|p| p.0);
    Ok(Arc::new(snow))
}

/// The registry entry of this stage.
pub const KIND: StageKind = StageKind {
    name: NAME,
    factor: "11 weather (snow)",
    model: "Gunn-Marshall flakes N0 = 7.6e3 R^-0.87, Lambda = 2.55 R^-0.48 /mm (R water equivalent); alpha = pi N0/Lambda^3 (Q_ext = 2), P exp(-2 alpha R); flake echoes with Fresnel reflectance x area (geometric optics, LISA), detectable flakes only, in a 3 mrad cone, proposed to the firing slot",
    source: "Gunn and Marshall 1958; Kilic et al. 2021 (LISA, snow mode); Hahner et al. CVPR 2022 (presets, snowfall-rate conversion); pdiagram-models.md 11 snow",
    options: &[
        OptionSpec { name: "rate_mm_h", unit: "mm/h", default: "required (or preset)", doc: "water-equivalent (melted) precipitation rate R of the Gunn-Marshall law; not Hahner's snowfall rate (see preset)" },
        OptionSpec { name: "preset", unit: "-", default: "\"none\"", doc: "Hahner et al. 2022: \"light\" (snowfall 0.5 mm/h at 2.0 m/s: R = 2.24), \"moderate\" (1.0 at 1.6: R = 8.85), \"heavy\" (2.5 at 1.6: R = 34.97); R = (S/(487 0.1 0.003 v_t))^1.5; instead of rate_mm_h; \"none\" (default): rate_mm_h" },
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

    #[test]
    fn a_preset_is_described_with_its_rate_rounded() {
        let text = "[[noise]]\ntype = \"snow\"\npreset = \"light\"\n";
        let (cfg, _) =
            crate::config::Config::from_toml_str(text, std::path::Path::new("t"), &[], None)
                .unwrap();
        let d = &cfg.noise[0].description;
        assert!(
            d.starts_with("snowfall 2.238 mm/h water equivalent (Hahner's light preset)"),
            "{d}"
        );
    }
}
