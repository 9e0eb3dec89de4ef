//! Rain (factor 11): `model = "mie"` (default; physical) or `model = "goodin"` (the
//! reference study's).
//!
//! ## model = "mie"
//!
//! Drops of a size distribution (Marshall-Palmer N(D) = 8000 exp(-4.1 R^-0.21 D) per m^3
//! per mm, Marshall & Palmer 1948; or, with `dsd = "gamma"`, N0 D^mu exp(-Lambda D),
//! Ulbrich 1983, from its three parameters) between 0.05 and 6 mm; water at 905 nm (Hale &
//! Querry 1973); efficiencies by the Mie series of [`super::mie`]:
//! - extinction alpha = int (pi D^2/4) Q_ext(D) N(D) dD (1.3e-3 /m at 7.29 mm/h, against
//!   Goodin's 0.0329: the drops are thousands of wavelengths across, Q_ext ~ 2);
//!   hard targets P exp(-2 alpha R) (Beer-Lambert, two ways);
//! - range noise that grows as the echo weakens, LISA's model (Kilic et al. 2021, their
//!   range-noise equation and code): sigma_R = dR / sqrt(2 SNR), SNR = P / p_th with P
//!   the power, p_th the detection threshold and dR = 0.09 m. A recorded return already
//!   carries the sensor's noise at its clear-air power P0, so the stage adds only the
//!   difference of variances, sigma^2 = dR^2 (p_th / 2) (1/P - 1/P0) with P the attenuated
//!   power (0 at 0 mm/h; LISA, which simulates the sensor, adds the whole sigma)
//!   (`range_noise = "lisa"`, the default with mie; "goodin" and "mavs" also accepted);
//! - drop echoes (`backscatter = true`): P_j = kappa pi (dsigma/dOmega)(D) /
//!   (A_beam(r) r^2) exp(-2 alpha r), capped at the full-beam case (a drop larger than the
//!   beam intercepts only the beam). Derivation: this tool's hard-target law
//!   P = kappa rho / r^2 is a Lambertian target filling the beam, whose differential
//!   backscatter cross-section is rho A_beam / pi; received power scales as irradiance
//!   (1/A_beam) x dsigma/dOmega / r^2, so a particle gives kappa pi (dsigma/dOmega) /
//!   (A_beam r^2), which is kappa rho / r^2 for the Lambertian disc (tested). The beam and
//!   receiver are the HDL-32E's (the fog stage's biaxial optics): A_beam grows from the
//!   exit aperture, drops fill the lit volume, and a drop is seen only inside the
//!   receiver's field (probability xi(r)). dsigma/dOmega: the receiver, 30 mm beside the
//!   beam, sees the drops at pi - d/r, 2.5 mrad or more from exact backscatter for every
//!   drop within the ~12 m where one can be detected, several widths (~1/x) away from the
//!   glory that makes the exact-180 degree Mie Q_back large (Q_back/4 ~ 1.2: a drop echoing
//!   like a white disc, which put a drop echo in 77 % of the sky beams at 7.29 mm/h); there
//!   a large sphere's backscatter is its front-surface reflection rho_F a^2 / 4 (van de
//!   Hulst 1957, geometric optics), rho_F of water = 0.0199: LISA's rule. Averaging the Mie
//!   intensity functions over the receiver's aperture would refine it for the smallest
//!   drops (not done). Sampled only where detectable ([`super::particles::Population`]).
//!   Drop echoes are attenuated by the same Mie alpha (one extinction per medium).
//!
//! The Mie series still gives the extinction (Q_ext) and the volume backscatter that
//! [`super::mie::volume_optics`] reports (lidar ratio ~4.7 sr at 7.29 mm/h, exact
//! 180 degrees: what a coaxial lidar would see).
//!
//! The rate warning above 7 mm/h belongs to Goodin's fit and is not given for mie.
//!
//! ## model = "goodin"
//!
//! As before issue 29 (ranges, powers, fates, causes and draws; tested by a digest,
//! tests/golden/rain_goodin_digest.txt), but for its arithmetic, which since 2026-11-28
//! gives the same bits on every machine: the attenuation and the range noise's
//! 1 - exp(-R) by the project's own exp ([`exp_nonpositive`], within 2 ulp), R^0.6 by
//! the libm crate's pow. The platform's exp and pow had been kept for the study's bits,
//! but glibc picks them by processor (with or without FMA) and their last bits differ:
//! with glibc's non-FMA builds (forced by `GLIBC_TUNABLES`), 20 of a nuScenes sweep's
//! 34,688 powers moved by an ulp and the digest test failed.
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
//! the range noise unchanged (common random numbers). The same holds for mie: one normal
//! draw per return first, then the drop-echo draws (one uniform per lit beam, three per
//! drop drawn).

use super::mie::{self, Dsd, VolumeOptics};
use super::particles::{Particles, Population, Reflectance};
use crate::config::reader::Section;
use crate::error::Result;
use crate::noise::transmission::exp_nonpositive;
use crate::noise::{Fate, NoiseStage, NoisyFrame};
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use serde::Serialize;
use std::sync::Arc;
use toml::Value;

/// The `type` name of this stage.
pub const NAME: &str = "rain";

/// Highest rain rate of the data the model was fitted on, in mm/h.
pub const FITTED_MAX_RATE_MM_H: f64 = 7.0;

/// Half-width of the MAVS uniform range jitter in metres.
pub const MAVS_JITTER_M: f64 = 0.015;

/// Range resolution dR (m) of LISA's range noise sigma = dR / sqrt(2 SNR).
pub const LISA_RANGE_RESOLUTION_M: f64 = 0.09;

/// Which range noise to add.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum RangeNoise {
    /// Gaussian of Eq. 9, growing with range and rate.
    Goodin,
    /// Uniform +-1.5 cm as in MAVS.
    Mavs,
    /// LISA: Gaussian, the variance of dR / sqrt(2 P / p_th) beyond the clear-air echo's.
    Lisa,
}

/// Which rain model.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Model {
    /// Goodin et al. 2019 (the reference study).
    Goodin,
    /// Mie extinction and backscatter of a drop size distribution.
    Mie,
}

/// Smallest drop of the mie model (mm; LISA's lower limit).
pub const MIE_D_MIN_MM: f64 = 0.05;

/// alpha and beta (Mie, water at 905 nm) of `dsd` between 0.05 and 6 mm.
pub fn mie_optics(dsd: &Dsd) -> VolumeOptics {
    mie::volume_optics(
        dsd,
        MIE_D_MIN_MM,
        DROP_MAX_MM,
        mie::water_905(),
        mie::WAVELENGTH_905_M,
    )
}

/// sigma (m) of LISA's range noise at power `p` and threshold `p_th`.
pub fn lisa_sigma_m(p: f64, p_th: f64) -> f64 {
    LISA_RANGE_RESOLUTION_M / (2.0 * p / p_th).sqrt()
}

/// sigma (m) of the range noise the rain adds to a recorded return whose power falls from
/// `before` to `after`: the recording already holds the sensor's own noise at `before`,
/// so only the extra variance, sigma(after)^2 - sigma(before)^2, is added (0 without
/// rain, so 0 mm/h is the identity).
pub fn lisa_added_sigma_m(after: f64, before: f64, p_th: f64) -> f64 {
    let var = |p: f64| if p > 0.0 { p_th / (2.0 * p) } else { 0.0 };
    LISA_RANGE_RESOLUTION_M * (var(after) - var(before)).max(0.0).sqrt()
}

/// The rain stage.
#[derive(Clone, Debug)]
pub struct Rain {
    /// Rain model.
    pub model: Model,
    /// Drop size distribution (mie).
    pub dsd: Dsd,
    /// Rain rate in mm/h.
    pub rate_mm_h: f64,
    /// Range noise model.
    pub range_noise: RangeNoise,
    /// Drop echoes (LISA), when on: the drop population.
    pub backscatter: Option<Backscatter>,
    /// Mie drop echoes, when on with model = "mie".
    pub mie_drops: Option<Arc<MieDrops>>,
    /// Extinction coefficient alpha in 1/m.
    alpha: f64,
    /// sigma / R_i.
    sigma_per_m: f64,
}

/// Extinction coefficient alpha (1/m) at `rate` mm/h (Goodin Eq. 5).
pub fn extinction_per_m(rate_mm_h: f64) -> f64 {
    // The libm crate's pow, not the platform's: the same bits on every machine (module
    // documentation).
    0.01 * libm::pow(rate_mm_h, 0.6)
}

/// Standard deviation (m) of the range noise at `range` metres and `rate` mm/h (Eq. 9).
pub fn range_sigma_m(range_m: f64, rate_mm_h: f64) -> f64 {
    // A rate is not negative (checked when the stage is built).
    let g = 1.0 - exp_nonpositive(-rate_mm_h);
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

/// The Mie drop echoes of the `backscatter` option with model = "mie".
#[derive(Clone, Debug)]
pub struct MieDrops {
    /// Full beam divergence in mrad.
    pub divergence_mrad: f64,
    /// Drop echoes also in slots without a return.
    pub empty_slots: bool,
    /// The drops.
    pub drops: Population,
}

impl Rain {
    /// Builds the Goodin stage for a valid (non-negative, finite) rate.
    pub fn new(rate_mm_h: f64, range_noise: RangeNoise) -> Self {
        Rain {
            model: Model::Goodin,
            dsd: Dsd::MarshallPalmer { rate_mm_h },
            rate_mm_h,
            range_noise,
            backscatter: None,
            mie_drops: None,
            alpha: extinction_per_m(rate_mm_h),
            sigma_per_m: range_sigma_m(1.0, rate_mm_h),
        }
    }

    /// Builds the Mie stage for drops `dsd` at a rate (reported) of `rate_mm_h`.
    pub fn mie(rate_mm_h: f64, dsd: Dsd, range_noise: RangeNoise) -> Self {
        Rain {
            model: Model::Mie,
            dsd,
            rate_mm_h,
            range_noise,
            backscatter: None,
            mie_drops: None,
            alpha: mie_optics(&dsd).alpha_per_m,
            sigma_per_m: range_sigma_m(1.0, rate_mm_h),
        }
    }

    /// Adds Mie drop echoes (model = "mie").
    pub fn with_mie_drops(mut self, divergence_mrad: f64, empty_slots: bool) -> Self {
        let drops = Population::new(
            &self.dsd,
            MIE_D_MIN_MM,
            DROP_MAX_MM,
            // Seen by the HDL-32E's biaxial receiver, a drop scatters towards it at pi - d/r
            // (d = 30 mm between the axes: 2.5 mrad or more for every drop within the
            // 12 m where drops can be detected), several widths (~1/x, 0.3 mrad for a 1 mm
            // drop) away from the glory that makes the exact-180 degree Mie Q_back large;
            // there a large sphere's backscatter is its front-surface reflection,
            // dsigma/dOmega = rho_F a^2 / 4 (van de Hulst 1957, geometric optics). The
            // exact-180 degree value put a drop echo in 77 % of the sky beams at 7.29 mm/h.
            Reflectance::Fresnel(super::particles::fresnel(WATER_INDEX)),
            divergence_mrad * 1e-3,
        )
        // The HDL-32E's exit aperture and receiver field (the fog stage's overlap): the
        // near drops LISA's point cone lights brightly are mostly outside the field.
        .with_optics(super::fog::hdl32e_optics());
        self.mie_drops = Some(Arc::new(MieDrops {
            divergence_mrad,
            empty_slots,
            drops,
        }));
        self
    }

    /// Extinction coefficient alpha in 1/m.
    pub fn alpha(&self) -> f64 {
        self.alpha
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
            RangeNoise::Lisa => {
                "added range noise sigma^2 = (0.09 m)^2 p_th / 2 (1/P - 1/P_clear) (LISA's law, the extra over the recording's own)".into()
            }
        };
        let drops = match (&self.backscatter, &self.mie_drops) {
            (Some(b), _) => format!(
                ", drop echoes ({:.0} drops/m^3 above 0.05 mm, {} mrad beam)",
                b.drops.per_m3, b.divergence_mrad
            ),
            (None, Some(m)) => format!(
                ", Mie drop echoes ({:.0} drops/m^3 above 0.05 mm, {} mrad beam)",
                m.drops.per_m3, m.divergence_mrad
            ),
            _ => String::new(),
        };
        match self.model {
            Model::Goodin => format!(
                "{} mm/h, alpha = {:.5} 1/m, {noise}{drops}",
                self.rate_mm_h, self.alpha
            ),
            Model::Mie => {
                let dsd = match self.dsd {
                    Dsd::MarshallPalmer { .. } => "Marshall-Palmer drops".to_string(),
                    Dsd::Gamma {
                        n0,
                        mu,
                        lambda_per_mm,
                    } => format!("gamma drops N0 = {n0}, mu = {mu}, Lambda = {lambda_per_mm}/mm"),
                };
                format!(
                    "{} mm/h, Mie ({dsd}, water at 905 nm): alpha = {:.6} 1/m, {noise}{drops}",
                    self.rate_mm_h, self.alpha
                )
            }
        }
    }

    fn settings(&self) -> Vec<(&'static str, Value)> {
        let noise = match self.range_noise {
            RangeNoise::Goodin => "goodin",
            RangeNoise::Mavs => "mavs",
            RangeNoise::Lisa => "lisa",
        };
        // `model` is always listed: the default changed to mie with issue 29, so a
        // printed configuration of a Goodin run must say goodin to rerun the same.
        // Order as in the option specs.
        let mut v = vec![(
            "model",
            Value::String(
                match self.model {
                    Model::Goodin => "goodin",
                    Model::Mie => "mie",
                }
                .into(),
            ),
        )];
        v.push(("rate_mm_h", Value::Float(self.rate_mm_h)));
        v.push(("range_noise", Value::String(noise.into())));
        if let Dsd::Gamma {
            n0,
            mu,
            lambda_per_mm,
        } = self.dsd
        {
            v.push(("dsd", Value::String("gamma".into())));
            v.push(("gamma_n0", Value::Float(n0)));
            v.push(("gamma_mu", Value::Float(mu)));
            v.push(("gamma_lambda_per_mm", Value::Float(lambda_per_mm)));
        }
        // Listed only when on, so the reference study's reports stay byte-identical.
        if let Some(b) = &self.backscatter {
            v.push(("backscatter", Value::Boolean(true)));
            v.push(("divergence_mrad", Value::Float(b.divergence_mrad)));
            v.push(("empty_slots", Value::Boolean(b.empty_slots)));
        }
        if let Some(m) = &self.mie_drops {
            v.push(("backscatter", Value::Boolean(true)));
            v.push(("divergence_mrad", Value::Float(m.divergence_mrad)));
            v.push(("empty_slots", Value::Boolean(m.empty_slots)));
        }
        v
    }

    fn proposes_echoes(&self) -> bool {
        self.backscatter.is_some_and(|b| !b.drops.is_empty())
            || self.mie_drops.as_ref().is_some_and(|m| !m.drops.is_empty())
    }

    fn apply(&self, frame: &mut NoisyFrame, rng: &mut ChaCha8Rng) {
        // One pass for both models: goodin's build refuses `range_noise = "lisa"`, so for
        // goodin the draws, powers and ranges are exactly those of before the mie model.
        self.attenuate_and_draw(frame, rng);
        // Drop echoes after every range draw, from the same stream: goodin's LISA cone,
        // or mie's population through the sensor's optics.
        if let Some(b) = &self.backscatter {
            super::snow::propose_particle_echoes(frame, rng, &b.drops, self.alpha, b.empty_slots);
        }
        if let Some(m) = &self.mie_drops {
            super::particles::propose_population_echoes(
                frame,
                rng,
                &m.drops,
                self.alpha,
                m.empty_slots,
            );
        }
    }
}

impl Rain {
    /// The range draw of every return (alive or not: one draw per return keeps streams
    /// aligned), in return order.
    fn draw(&self, rng: &mut ChaCha8Rng) -> f64 {
        match self.range_noise {
            RangeNoise::Mavs => MAVS_JITTER_M * (2.0 * rng.random::<f64>() - 1.0),
            RangeNoise::Goodin | RangeNoise::Lisa => rng.sample::<f64, _>(StandardNormal),
        }
    }

    /// Attenuation and range noise of the recorded returns (either model's extinction):
    /// the draws first (the stream is sequential), then one branch-free pass the compiler
    /// vectorises (the same arithmetic, in the same order, as a return-by-return loop;
    /// goodin's own loop, a return at a time with a draw among the arithmetic, did not
    /// vectorise and was a third slower on the paper chain's bench).
    fn attenuate_and_draw(&self, frame: &mut NoisyFrame, rng: &mut ChaCha8Rng) {
        let (two_alpha, p_th) = (2.0 * self.alpha, frame.threshold);
        DRAWS.with_borrow_mut(|draws| {
            draws.clear();
            // The model's draw in its own loop (one match a frame, not one a return).
            let n = frame.range.len();
            match self.range_noise {
                RangeNoise::Mavs => draws.extend((0..n).map(|_| self.draw(rng))),
                RangeNoise::Goodin | RangeNoise::Lisa => {
                    draws.extend((0..n).map(|_| Distribution::<f64>::sample(&StandardNormal, rng)))
                }
            }
            let columns = (&mut frame.range[..], &mut frame.power[..], &frame.fate[..]);
            let sigma_per_m = self.sigma_per_m;
            // One loop per noise model, so each is branch-free.
            match self.range_noise {
                RangeNoise::Goodin => {
                    attenuate_and_move(columns, draws, two_alpha, |r_i, _, _, draw| {
                        sigma_per_m * r_i * draw
                    })
                }
                RangeNoise::Mavs => {
                    attenuate_and_move(columns, draws, two_alpha, |_, _, _, draw| draw)
                }
                RangeNoise::Lisa => {
                    attenuate_and_move(columns, draws, two_alpha, |_, after, before, draw| {
                        // A return at or under zero power is dropped by the filters anyway.
                        let sigma = lisa_added_sigma_m(after, before, p_th);
                        if after > 0.0 {
                            sigma * draw
                        } else {
                            0.0
                        }
                    })
                }
            }
        });
    }
}

/// Multiplies each alive return's power by exp(-`two_alpha` R) and moves its range by
/// `delta(R, power after, power before, draw)`, in one pass the compiler vectorises (the
/// same arithmetic, in the same order, as a return-by-return loop), with AVX-512 or AVX2
/// where the processor has it (see [`crate::numeric::wide`]).
fn attenuate_and_move(
    columns: (&mut [f32], &mut [f64], &[Fate]),
    draws: &[f64],
    two_alpha: f64,
    delta: impl Fn(f64, f64, f64, f64) -> f64,
) {
    #[cfg(target_arch = "x86_64")]
    {
        if crate::numeric::avx512() {
            // SAFETY: the processor has AVX-512 F and DQ (checked on the line above).
            unsafe { attenuate_and_move_avx512(columns, draws, two_alpha, delta) };
            return;
        }
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the processor has AVX2 (checked on the line above).
            unsafe { attenuate_and_move_avx2(columns, draws, two_alpha, delta) };
            return;
        }
    }
    attenuate_and_move_body(columns, draws, two_alpha, delta);
}

/// [`attenuate_and_move`] compiled with AVX-512.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx512dq")]
unsafe fn attenuate_and_move_avx512(
    columns: (&mut [f32], &mut [f64], &[Fate]),
    draws: &[f64],
    two_alpha: f64,
    delta: impl Fn(f64, f64, f64, f64) -> f64,
) {
    attenuate_and_move_body(columns, draws, two_alpha, delta);
}

/// [`attenuate_and_move`] compiled with AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn attenuate_and_move_avx2(
    columns: (&mut [f32], &mut [f64], &[Fate]),
    draws: &[f64],
    two_alpha: f64,
    delta: impl Fn(f64, f64, f64, f64) -> f64,
) {
    attenuate_and_move_body(columns, draws, two_alpha, delta);
}

/// The loop of [`attenuate_and_move`].
#[inline(always)]
fn attenuate_and_move_body(
    (range, power, fate): (&mut [f32], &mut [f64], &[Fate]),
    draws: &[f64],
    two_alpha: f64,
    delta: impl Fn(f64, f64, f64, f64) -> f64,
) {
    let n = range
        .len()
        .min(power.len())
        .min(fate.len())
        .min(draws.len());
    let (range, power, fate, draws) = (&mut range[..n], &mut power[..n], &fate[..n], &draws[..n]);
    for i in 0..n {
        let r_i = f64::from(range[i]);
        let before = power[i];
        let after = before * crate::noise::transmission::exp_nonpositive(-two_alpha * r_i);
        let moved = (r_i + delta(r_i, after, before, draws[i])) as f32;
        // Selects, not branches: dead returns keep their power and range.
        let alive = fate[i].is_alive();
        power[i] = if alive { after } else { before };
        range[i] = if alive { moved } else { range[i] };
    }
}

thread_local! {
    /// The range draws of a frame, kept between frames so the buffer is not reallocated.
    static DRAWS: std::cell::RefCell<Vec<f64>> = const { std::cell::RefCell::new(Vec::new()) };
}

/// Reads the options of a `rain` entry.
pub fn build(opts: &Section<'_>) -> Result<Arc<dyn NoiseStage>> {
    let Some(rate) = opts.f64("rate_mm_h")? else {
        return Err(opts.missing("rate_mm_h"));
    };
    if rate < 0.0 || !rate.is_finite() {
        return Err(opts.error("rate_mm_h", format!("{rate} is not a non-negative number")));
    }
    let model = match opts.choice("model", &["goodin", "mie"])? {
        Some("goodin") => Model::Goodin,
        _ => Model::Mie,
    };
    if model == Model::Mie {
        return build_mie(opts, rate);
    }
    for key in ["dsd", "gamma_n0", "gamma_mu", "gamma_lambda_per_mm"] {
        if opts.has(key) {
            return Err(opts.error(key, "only used with model = \"mie\""));
        }
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

/// The options of a `rain` entry with model = "mie".
fn build_mie(opts: &Section<'_>, rate: f64) -> Result<Arc<dyn NoiseStage>> {
    let range_noise = match opts.choice("range_noise", &["lisa", "goodin", "mavs"])? {
        Some("goodin") => RangeNoise::Goodin,
        Some("mavs") => RangeNoise::Mavs,
        _ => RangeNoise::Lisa,
    };
    let dsd = match opts.choice("dsd", &["marshall-palmer", "gamma"])? {
        Some("gamma") => {
            let get = |key: &str| -> Result<f64> {
                match opts.f64(key)? {
                    Some(v) if v.is_finite() => Ok(v),
                    Some(v) => Err(opts.error(key, format!("{v} is not a finite number"))),
                    None => Err(opts.missing(key)),
                }
            };
            let (n0, mu, lambda) = (
                get("gamma_n0")?,
                get("gamma_mu")?,
                get("gamma_lambda_per_mm")?,
            );
            if n0 < 0.0 {
                return Err(opts.error("gamma_n0", format!("{n0} is negative")));
            }
            if mu <= -1.0 {
                return Err(opts.error("gamma_mu", format!("{mu} must exceed -1")));
            }
            if lambda <= 0.0 {
                return Err(opts.error("gamma_lambda_per_mm", format!("{lambda} must be positive")));
            }
            Dsd::Gamma {
                n0,
                mu,
                lambda_per_mm: lambda,
            }
        }
        _ => {
            for key in ["gamma_n0", "gamma_mu", "gamma_lambda_per_mm"] {
                if opts.has(key) {
                    return Err(opts.error(key, "only used with dsd = \"gamma\""));
                }
            }
            Dsd::MarshallPalmer { rate_mm_h: rate }
        }
    };
    let mut rain = Rain::mie(rate, dsd, range_noise);
    if super::bool_option(opts, "backscatter", false)? {
        let divergence = crate::noise::sensor::number(opts, "divergence_mrad", 3.0, 0.01, 100.0)?;
        let empty_slots = super::bool_option(opts, "empty_slots", true)?;
        rain = rain.with_mie_drops(divergence, empty_slots);
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
    model: "mie: Mie extinction of Marshall-Palmer (or gamma) drops, water at 905 nm, exp(-2 alpha R), LISA range noise (the variance beyond the recording's), drop echoes through the HDL-32E's biaxial optics (front-surface reflection seen off the glory); goodin: alpha = 0.01 R^0.6, Gaussian range noise (Goodin Eq. 9) or MAVS uniform noise, drop echoes with Fresnel reflectance (LISA)",
    source: "Bohren & Huffman 1983; Hale & Querry 1973; Marshall & Palmer 1948; Ulbrich 1983; Kilic et al. 2021 (LISA); Goodin et al., Electronics 2019; noise-models.md",
    options: &[
        crate::noise::registry::OptionSpec { name: "model", unit: "-", default: "\"mie\"", doc: "\"mie\" (physical: Mie optics of a drop size distribution) or \"goodin\" (Goodin et al. 2019, the reference study's; alpha ~27x the Mie value)" },
        crate::noise::registry::OptionSpec { name: "rate_mm_h", unit: "mm/h", default: "required", doc: "rain rate" },
        crate::noise::registry::OptionSpec { name: "range_noise", unit: "-", default: "\"lisa\" (mie), \"goodin\" (goodin)", doc: "\"lisa\" (LISA's sigma = 0.09 m / sqrt(2 P/p_th), the extra variance over the clear-air echo's; mie only), \"goodin\" (Eq. 9 Gaussian) or \"mavs\" (uniform +-1.5 cm)" },
        crate::noise::registry::OptionSpec { name: "dsd", unit: "-", default: "\"marshall-palmer\"", doc: "mie: drop size distribution, \"marshall-palmer\" (from rate_mm_h) or \"gamma\" (N0 D^mu exp(-Lambda D), Ulbrich 1983)" },
        crate::noise::registry::OptionSpec { name: "gamma_n0", unit: "1/(m^3 mm^(1+mu))", default: "required with gamma", doc: "gamma DSD: N0" },
        crate::noise::registry::OptionSpec { name: "gamma_mu", unit: "-", default: "required with gamma", doc: "gamma DSD: shape mu (> -1)" },
        crate::noise::registry::OptionSpec { name: "gamma_lambda_per_mm", unit: "1/mm", default: "required with gamma", doc: "gamma DSD: slope Lambda" },
        crate::noise::registry::OptionSpec { name: "backscatter", unit: "-", default: "false", doc: "drop echoes at short range, proposed to the firing slot (mie: through the HDL-32E optics, detectable drops only; goodin: LISA Monte Carlo cone)" },
        crate::noise::registry::OptionSpec { name: "divergence_mrad", unit: "mrad", default: "3", doc: "with backscatter: full beam divergence of the Monte Carlo cone" },
        crate::noise::registry::OptionSpec { name: "empty_slots", unit: "-", default: "true", doc: "with backscatter: drop echoes also in firing slots without a return" },
    ],
    build,
};

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    #[test]
    fn the_wide_rain_pass_gives_the_plain_loops_bits() {
        // The AVX2 and AVX-512 builds (where this machine has them) against the loop
        // compiled for the baseline, for LISA's range noise with its zero-power case.
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        let fates = [
            Fate::Kept,
            Fate::Occluded,
            Fate::BelowPower,
            Fate::Replaced,
            Fate::Added,
        ];
        let n = 10_007;
        let range: Vec<f32> = (0..n).map(|_| rng.random::<f32>() * 120.0).collect();
        let power: Vec<f64> = (0..n)
            .map(|i| if i % 9 == 0 { 0.0 } else { rng.random::<f64>() })
            .collect();
        let fate: Vec<Fate> = (0..n).map(|_| fates[rng.random_range(0..5)]).collect();
        let draws: Vec<f64> = (0..n).map(|_| rng.sample(StandardNormal)).collect();
        let delta = |_: f64, after: f64, before: f64, draw: f64| {
            let sigma = lisa_added_sigma_m(after, before, 0.001);
            if after > 0.0 {
                sigma * draw
            } else {
                0.0
            }
        };
        let (mut r2, mut p2) = (range.clone(), power.clone());
        attenuate_and_move_body((&mut r2, &mut p2, &fate), &draws, 0.004, delta);
        // Each build this processor runs (the one `attenuate_and_move` picks among them).
        type Pass<'a> = dyn Fn(&mut [f32], &mut [f64]) + 'a;
        let mut builds: Vec<(&str, Box<Pass>)> = vec![(
            "picked",
            Box::new(|r, p| attenuate_and_move((r, p, &fate), &draws, 0.004, delta)),
        )];
        #[cfg(target_arch = "x86_64")]
        {
            if std::arch::is_x86_feature_detected!("avx2") {
                builds.push((
                    "avx2",
                    // SAFETY: the processor has AVX2 (checked on the line above).
                    Box::new(|r, p| unsafe {
                        attenuate_and_move_avx2((r, p, &fate), &draws, 0.004, delta)
                    }),
                ));
            }
            if crate::numeric::avx512() {
                builds.push((
                    "avx512",
                    // SAFETY: the processor has AVX-512 F and DQ (checked above).
                    Box::new(|r, p| unsafe {
                        attenuate_and_move_avx512((r, p, &fate), &draws, 0.004, delta)
                    }),
                ));
            }
        }
        for (name, pass) in &builds {
            let (mut r1, mut p1) = (range.clone(), power.clone());
            pass(&mut r1, &mut p1);
            assert!(
                r1.iter().zip(&r2).all(|(a, b)| a.to_bits() == b.to_bits()),
                "{name}"
            );
            assert!(
                p1.iter().zip(&p2).all(|(a, b)| a.to_bits() == b.to_bits()),
                "{name}"
            );
        }
        // And it did something: alive returns moved and lost power.
        assert!(p2.iter().zip(&power).filter(|(a, b)| a < b).count() > n / 3);
    }
}
