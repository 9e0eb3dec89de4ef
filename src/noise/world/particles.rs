//! Echoes of particles in the beam (rain drops, snow flakes) by LISA's Monte Carlo
//! (Kilic et al., "Lidar Light Scattering Augmentation (LISA)", arXiv 2107.07004, 2021;
//! pdiagram-models.md, "11 Weather: rain backscatter (LISA)"). Shared by the `rain`
//! backscatter option and the `snow` stage; not a stage itself.
//!
//! Per beam: the beam is a cone of full divergence theta (diameter D_b(r) = r tan theta);
//! the number of particles above `d_min` in it is the cone volume
//! (pi/3) R (D_b(R)/2)^2 times their number density, randomly rounded; each particle
//! lies at r = R u^(1/3) (uniform in the cone's volume) and has an exponential diameter
//! (density N0 exp(-Lambda D)) truncated to [d_min, d_max]. Its echo, in this tool's
//! power units (kappa and the threshold in place of LISA's 1 and P_min), is
//! P_j = kappa rho_F exp(-2 alpha r) min(1, (D / D_b(r))^2) / r^2 with the Fresnel
//! reflectance rho_F = ((n - 1)/(n + 1))^2. Particles nearer than 1.5 m are ignored
//! (as in LISA). Only echoes the sensor could detect are returned.
//!
//! Deviation, for speed and stated: the cone is cut at the range beyond which no
//! particle up to `d_max` could be detected (a few metres: echoes are a short-range
//! effect), so the particles behind it, which could never be reported, are not drawn.
//! The cut depends on kappa and the threshold only, so the draws do not depend on the
//! other stages.

use super::mie::{Dsd, MieTable};
use crate::noise::{DetectionRule, Echo, Fate, NoisyFrame, SlotId};
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use std::sync::Arc;

/// LISA ignores particles nearer than this (m).
pub const MIN_RANGE_M: f64 = 1.5;

/// Smallest particle drawn (mm), as in LISA.
pub const D_MIN_MM: f64 = 0.05;

/// A population of particles with exponential sizes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Particles {
    /// Number density of particles with d_min <= D <= d_max (1/m^3).
    pub per_m3: f64,
    /// Slope Lambda of the size distribution (1/mm).
    pub lambda_per_mm: f64,
    /// Largest diameter drawn (mm).
    pub d_max_mm: f64,
    /// Fresnel reflectance rho_F of one particle.
    pub fresnel: f64,
    /// tan of the full beam divergence.
    pub tan_divergence: f64,
}

/// Fresnel reflectance at normal incidence of a medium of refractive index `n`.
pub fn fresnel(n: f64) -> f64 {
    ((n - 1.0) / (n + 1.0)).powi(2)
}

impl Particles {
    /// Particles of size density `n0 exp(-lambda D)` (1/(m^3 mm)) between `D_MIN_MM` and
    /// `d_max_mm`, refractive index `index`, beam divergence `divergence_rad`.
    pub fn new(
        n0: f64,
        lambda_per_mm: f64,
        d_max_mm: f64,
        index: f64,
        divergence_rad: f64,
    ) -> Self {
        let per_m3 = if n0 > 0.0 && lambda_per_mm.is_finite() && lambda_per_mm > 0.0 {
            n0 / lambda_per_mm
                * ((-lambda_per_mm * D_MIN_MM).exp() - (-lambda_per_mm * d_max_mm).exp())
        } else {
            0.0
        };
        Particles {
            per_m3,
            lambda_per_mm,
            d_max_mm,
            fresnel: fresnel(index),
            tan_divergence: divergence_rad.tan(),
        }
    }

    /// True when no particle is ever drawn.
    pub fn is_empty(&self) -> bool {
        self.per_m3 <= 0.0
    }

    /// Range (m) beyond which no particle up to `d_max` reaches `threshold` (kappa in
    /// m^2): the bound kappa rho_F min(1, (D/D_b)^2) / r^2 falls with r.
    pub fn cutoff_m(&self, kappa_m2: f64, threshold: f64) -> f64 {
        let k = kappa_m2 * self.fresnel / threshold;
        let near = k.sqrt();
        let d = self.d_max_mm * 1e-3;
        if near * self.tan_divergence <= d {
            near
        } else {
            (k * d * d / (self.tan_divergence * self.tan_divergence))
                .sqrt()
                .sqrt()
        }
    }

    /// Power of the echo of a particle of `d_mm` at `r` m.
    pub fn power(&self, r: f64, d_mm: f64, alpha: f64, kappa_m2: f64) -> f64 {
        let db = r * self.tan_divergence;
        let share = ((d_mm * 1e-3) / db).powi(2).min(1.0);
        kappa_m2 * self.fresnel * (-2.0 * alpha * r).exp() * share / (r * r)
    }

    /// Draws the particles in a beam whose target (or cut) lies at `range` m and calls
    /// `out` with each detectable echo (power at or above `threshold`, range at or
    /// above `min_range`), nearest-first not guaranteed. `cutoff` is
    /// [`Particles::cutoff_m`]; `alpha` the extinction of the medium (1/m).
    #[allow(clippy::too_many_arguments)]
    pub fn beam(
        &self,
        rng: &mut ChaCha8Rng,
        range: f64,
        cutoff: f64,
        alpha: f64,
        kappa_m2: f64,
        threshold: f64,
        min_range: f64,
        mut out: impl FnMut(Echo),
    ) {
        let r_cone = range.min(cutoff);
        if r_cone.is_nan() || r_cone <= 0.0 {
            return;
        }
        let radius = r_cone * self.tan_divergence / 2.0;
        let expected = self.per_m3 * std::f64::consts::PI / 3.0 * r_cone * radius * radius;
        // LISA's random rounding of the expected count.
        let whole = expected.floor();
        let u: f64 = rng.random();
        let count = whole as u64 + u64::from(u < expected - whole);
        let tail = 1.0 - (-self.lambda_per_mm * (self.d_max_mm - D_MIN_MM)).exp();
        let lo = MIN_RANGE_M.max(min_range);
        // Cheap rejections first (they only skip particles the exact test would reject
        // too): u below (lo / R)^3 (with a margin for rounding) puts the particle nearer
        // than lo; the power without extinction bounds the power with it.
        let a_lo = (lo / r_cone).powi(3) * (1.0 - 1e-9);
        let k = kappa_m2 * self.fresnel;
        let t2 = self.tan_divergence * self.tan_divergence;
        // Farthest range at which a particle of diameter d_m could reach the threshold
        // (the bound below, solved for r); beyond it, no cube root is needed.
        let near = (k / threshold).sqrt();
        let r3 = r_cone * r_cone * r_cone;
        for _ in 0..count {
            let (a, b): (f64, f64) = (rng.random(), rng.random());
            if a < a_lo {
                continue;
            }
            let d = D_MIN_MM - (1.0 - b * tail).ln() / self.lambda_per_mm;
            let d_m = d * 1e-3;
            let r_max = if near * self.tan_divergence <= d_m {
                near
            } else {
                (k * d_m * d_m / (t2 * threshold)).sqrt().sqrt()
            };
            if a * r3 > r_max * r_max * r_max * (1.0 + 1e-9) {
                continue;
            }
            let r = r_cone * a.cbrt();
            if r < lo {
                continue;
            }
            let r2 = r * r;
            if k * (d_m * d_m / (t2 * r2)).min(1.0) < threshold * r2 {
                continue;
            }
            let p = self.power(r, d, alpha, kappa_m2);
            if p >= threshold {
                out(Echo {
                    range: r as f32,
                    power: p,
                });
            }
        }
    }
}

/// Backscatter of one particle as the reflectance rho(D) of a Lambertian disc of the
/// particle's cross-section: P = kappa rho(D) exp(-2 alpha r) min(1, A_p / A_beam) / r^2.
#[derive(Clone, Copy, Debug)]
pub enum Reflectance {
    /// Constant rho (LISA: the Fresnel reflectance at normal incidence).
    Fresnel(f64),
    /// Mie: rho(D) = pi (dsigma/dOmega) / (pi a^2) = Q_back(x) / 4, x = pi D / lambda.
    Mie {
        /// Q_ext/Q_back of the particle's material.
        table: &'static MieTable,
        /// Wavelength (m).
        wavelength_m: f64,
    },
}

impl Reflectance {
    /// rho at diameter `d_mm`.
    #[inline]
    pub fn at(&self, d_mm: f64) -> f64 {
        match *self {
            Reflectance::Fresnel(rho) => rho,
            Reflectance::Mie {
                table,
                wavelength_m,
            } => {
                table
                    .at(super::mie::size_parameter(d_mm * 1e-3, wavelength_m))
                    .1
                    / 4.0
            }
        }
    }

    /// Largest rho on [`lo`, `hi`] mm: the ends and every table node between (the table
    /// is linear between nodes, so this is the exact maximum of what [`Self::at`] gives).
    fn max_on(&self, lo: f64, hi: f64) -> f64 {
        match *self {
            Reflectance::Fresnel(rho) => rho,
            Reflectance::Mie {
                table,
                wavelength_m,
            } => {
                let x = |d: f64| super::mie::size_parameter(d * 1e-3, wavelength_m);
                table.max_between(x(lo), x(hi)) / 4.0
            }
        }
    }
}

/// Size bins of [`Population`].
pub const POPULATION_BINS: usize = 64;

/// One size bin: its particles per m^3 and the local exponential slope of N(D).
#[derive(Clone, Copy, Debug)]
struct SizeBin {
    lo: f64,
    hi: f64,
    per_m3: f64,
    slope: f64,
    /// 1 - exp(-slope (hi - lo)): the truncated exponential's mass on the bin.
    span: f64,
    rho_max: f64,
}

/// A particle population sampled only where it can be detected.
///
/// Particles form a Poisson process in the lit beam (cross-section A_beam(r) = pi w(r)^2,
/// w(r) = a + r t: LISA's cone has a = 0 and t = tan(theta) / 2; with the sensor's
/// [`Population::optics`], a is the exit aperture's radius and t = tan(theta / 2)) with
/// size density N(D). Per beam whose target lies at R, the
/// detectable particles are those with r in [lo, R] (lo = max(1.5 m, minimum range); the
/// target hides what lies behind it) and P(r, D) >= threshold. P falls with r, so for a
/// size bin [D1, D2] every detectable particle lies nearer than r_b, the range where the
/// bound kappa rho_max(bin) min(1, (D2 / 2 w(r))^2) / r^2 (no extinction) meets the
/// threshold. The superset {r in [lo, r_b], D in bin}, over all bins, holds a Poisson
/// number of particles with mean Lambda = sum_b n_b (pi / 3t) (w(r_b)^3 - w(lo)^3)+ (the
/// lit volume), n_b the bin's particles per m^3: one Poisson count per beam (inversion of one
/// uniform), then per particle a bin (weight of its term), r with w(r)^3 uniform (a
/// particle behind the target, r > R, is hidden and dropped), D from the bin's N(D) (an
/// exponential through N at both bin ends: exact for Marshall-Palmer and Gunn-Marshall,
/// an approximation within a bin for gamma with mu > 0), and the exact power test (with
/// extinction and rho(D)) keeps the detectable ones. Thinning a Poisson process keeps it
/// Poisson (so do the target's shadow and the thinning of each bin by the receiver's
/// overlap at its r_b, the largest it reaches there, with the rest of xi(r) decided per
/// particle), so the echoes have exactly the distribution of
/// drawing every particle in the cone and keeping the detectable ones (tested against
/// that brute force), at a cost of two uniforms per beam that holds a particle.
///
/// Draw pattern ([`Population::beams`]): for each beam that holds a particle, one uniform
/// for the geometric gap from the previous such beam and one for its count; three per
/// particle drawn, and with [`Population::optics`] one more per particle bright enough to
/// be detected. A sweep of the rate reuses the same stream (common random numbers), but
/// the beams holding particles at a lower rate are not always among those at a higher
/// one: the coupling is in distribution, not beam by beam.
#[derive(Clone, Debug)]
pub struct Population {
    /// tan of the full beam divergence.
    pub tan_divergence: f64,
    /// The sensor's transmitter/receiver optics, when set: the beam starts at the exit
    /// aperture's width (not at a point, as in LISA's cone), and a particle's echo is
    /// seen only where the particle lies in the receiver's field of view, which at range
    /// r covers the share xi(r) of the beam (the overlap of the fog stage). `None` keeps
    /// LISA's cone and a receiver that sees every particle.
    pub optics: Option<super::fog::Biaxial>,
    /// Particles per m^3 between the size limits.
    pub per_m3: f64,
    reflectance: Reflectance,
    bins: Vec<SizeBin>,
    /// xi(r) of `optics` on a fine grid (see [`OverlapTable`]).
    overlap: Option<Arc<OverlapTable>>,
}

/// The overlap xi(r) of a sensor's optics sampled every few millimetres from R1 to R2 and
/// interpolated linearly: two arc cosines a particle were a sixth of a snow frame's
/// particle sampling. Interpolation between samples of a function that never falls
/// never falls either, so the per-bin bound of the thinning (xi at the bin's farthest
/// range, from the same table) still holds exactly; the table is within 1e-6 of xi (the
/// most just past R1, where xi starts as (r - R1)^1.5).
#[derive(Debug)]
struct OverlapTable {
    start: f64,
    per_step: f64,
    xi: Vec<f64>,
}

impl OverlapTable {
    // 65,536 steps: about 1 mm over the HDL-32E's 2.7-75 m, where xi rises as (r - R1)^(3/2)
    // from R1 (linear interpolation within 1e-6 of it there).
    const STEPS: usize = 65_536;

    /// `None` when the overlap never becomes full (no finite R2): the exact xi then.
    fn new(o: &super::fog::Biaxial) -> Option<OverlapTable> {
        let (r1, r2) = (o.start_m(), o.full_m());
        if !(r2.is_finite() && r2 > r1) {
            return None;
        }
        let step = (r2 - r1) / Self::STEPS as f64;
        let xi = (0..=Self::STEPS)
            .map(|k| o.overlap(r1 + k as f64 * step))
            .collect();
        Some(OverlapTable {
            start: r1,
            per_step: 1.0 / step,
            xi,
        })
    }

    fn at(&self, r: f64) -> f64 {
        let u = (r - self.start) * self.per_step;
        // Also a NaN range.
        if u.is_nan() || u <= 0.0 {
            return self.xi[0];
        }
        if u >= Self::STEPS as f64 {
            return self.xi[Self::STEPS];
        }
        let k = u as usize;
        let t = u - k as f64;
        self.xi[k] + t * (self.xi[k + 1] - self.xi[k])
    }
}

/// A [`Population`] prepared for one frame's kappa, threshold and minimum range.
#[derive(Clone, Debug)]
pub struct Prepared {
    lo: f64,
    /// Per bin: w(r_b)^3, the cube of the lit beam's radius at r_b.
    w3_b: Vec<f64>,
    lambda_max: f64,
    p0_max: f64,
    /// Cumulative bin weights of the superset region (every bin to its r_b).
    cum_max: Vec<f64>,
    kappa: f64,
    threshold: f64,
    /// pi / 3t: the lit volume between two ranges is c (w(r2)^3 - w(r1)^3).
    c: f64,
    /// a: the beam's radius at the sensor (m).
    a: f64,
    /// Per bin: the overlap xi at r_b, a bound of xi over the bin's region (xi grows with
    /// r), by which its particles are thinned before the draw (1 without optics).
    xi_b: Vec<f64>,
    /// t: the growth of the beam's radius per metre.
    t: f64,
    /// The probabilistic detection rule and the threshold it is relative to (`None`:
    /// the threshold `threshold` decides, as in the reference study).
    detection: Option<(Arc<DetectionRule>, f64)>,
}

impl Prepared {
    /// The same bounds, with every drawn particle's echo reported by `rule` relative to
    /// the threshold `t` (one more draw per particle above the cut; the bounds must
    /// have been prepared with the cut, [`NoisyFrame::faintest_echo`], as threshold).
    pub fn with_detection(mut self, rule: Arc<DetectionRule>, t: f64) -> Self {
        self.detection = Some((rule, t));
        self
    }
}

impl Population {
    /// Particles of size density `dsd` between `d_min_mm` and `d_max_mm`, echoing with
    /// `reflectance`, in a beam of full divergence `divergence_rad`.
    pub fn new(
        dsd: &Dsd,
        d_min_mm: f64,
        d_max_mm: f64,
        reflectance: Reflectance,
        divergence_rad: f64,
    ) -> Self {
        let h = (d_max_mm - d_min_mm) / POPULATION_BINS as f64;
        let mut bins = Vec::with_capacity(POPULATION_BINS);
        for b in 0..POPULATION_BINS {
            let lo = d_min_mm + h * b as f64;
            let hi = lo + h;
            // Simpson on 16 intervals: N(D) is smooth within a bin.
            let k = 16;
            let g = h / f64::from(k);
            let mut sum = dsd.density(lo) + dsd.density(hi);
            for i in 1..k {
                sum += dsd.density(lo + g * f64::from(i)) * if i % 2 == 1 { 4.0 } else { 2.0 };
            }
            let per_m3 = (sum * g / 3.0).max(0.0);
            let (n_lo, n_hi) = (dsd.density(lo), dsd.density(hi));
            let slope = if n_lo > 0.0 && n_hi > 0.0 {
                (n_lo / n_hi).ln() / h
            } else {
                0.0
            };
            bins.push(SizeBin {
                lo,
                hi,
                per_m3,
                slope,
                span: 1.0 - (-slope * h).exp(),
                rho_max: reflectance.max_on(lo, hi),
            });
        }
        Population {
            tan_divergence: divergence_rad.tan(),
            optics: None,
            per_m3: bins.iter().map(|b| b.per_m3).sum(),
            reflectance,
            bins,
            overlap: None,
        }
    }

    /// xi(r) of the optics (1 without).
    fn overlap_at(&self, r: f64) -> f64 {
        match (&self.overlap, &self.optics) {
            (Some(t), _) => t.at(r),
            (None, Some(o)) => o.overlap(r),
            (None, None) => 1.0,
        }
    }

    /// The population seen through `optics` (see [`Population::optics`]); the beam's
    /// divergence stays the population's own.
    pub fn with_optics(mut self, optics: super::fog::Biaxial) -> Self {
        let o = super::fog::Biaxial {
            divergence_rad: 2.0 * (self.tan_divergence / 2.0).atan().max(0.0),
            ..optics
        };
        self.overlap = OverlapTable::new(&o).map(Arc::new);
        self.optics = Some(o);
        self
    }

    /// True when no particle is ever drawn.
    pub fn is_empty(&self) -> bool {
        self.per_m3 <= 0.0
    }

    /// (a, t): the lit beam's radius is w(r) = a + r t (LISA's cone: a = 0, t =
    /// tan(theta) / 2; with optics, the exit aperture and the half angle's tangent).
    pub fn lit_beam(&self) -> (f64, f64) {
        match &self.optics {
            Some(o) => (o.tx_radius_m, (o.divergence_rad / 2.0).tan()),
            None => (0.0, self.tan_divergence / 2.0),
        }
    }

    /// Power of the echo of a particle of `d_mm` at `r` m (see [`Reflectance`]), before
    /// the receiver's field of view is taken into account.
    #[inline]
    pub fn power(&self, r: f64, d_mm: f64, alpha: f64, kappa_m2: f64) -> f64 {
        // Beam diameter: from the exit aperture with the sensor's optics (never narrower
        // than the cone, so the bounds of `prepare` still hold), else LISA's cone.
        let db = match &self.optics {
            Some(o) => 2.0 * o.beam_radius(r),
            None => r * self.tan_divergence,
        };
        self.power_in(r, d_mm, alpha, kappa_m2, db)
    }

    /// [`Population::power`] in a beam of diameter `db` m at the particle.
    #[inline]
    fn power_in(&self, r: f64, d_mm: f64, alpha: f64, kappa_m2: f64, db: f64) -> f64 {
        let share = ((d_mm * 1e-3) / db).powi(2).min(1.0);
        kappa_m2
            * self.reflectance.at(d_mm)
            * crate::noise::transmission::exp_nonpositive(-2.0 * alpha * r)
            * share
            / (r * r)
    }

    /// The bounds of every bin for `kappa_m2`, `threshold` and `min_range` (m).
    pub fn prepare(&self, kappa_m2: f64, threshold: f64, min_range: f64) -> Prepared {
        let (a, t) = self.lit_beam();
        let lo = MIN_RANGE_M.max(min_range);
        let r_b: Vec<f64> = self
            .bins
            .iter()
            .map(|b| {
                let k = kappa_m2 * b.rho_max / threshold;
                // A particle filling the beam is detectable to sqrt(k); a smaller one while
                // k (D / 2 w(r))^2 / r^2 >= 1, i.e. w(r) r <= (D/2) sqrt(k): the positive
                // root of t r^2 + a r - (D/2) sqrt(k) (for a = 0: (k D^2 / 4t^2)^(1/4)).
                let near = k.sqrt();
                let half = b.hi * 0.5e-3 * near;
                let root = 2.0 * half / (a + (a * a + 4.0 * t * half).sqrt());
                // 1e-9 margin: the bound must not cut a particle on its edge by rounding.
                near.min(root) * (1.0 + 1e-9)
            })
            .collect();
        let xi_b = r_b.iter().map(|&r| self.overlap_at(r)).collect();
        let c = std::f64::consts::PI / (3.0 * t);
        let w3_b = r_b
            .iter()
            .map(|&r| {
                let w = a + r * t;
                w * w * w
            })
            .collect();
        let mut p = Prepared {
            a,
            t,
            xi_b,
            w3_b,
            lo,
            lambda_max: 0.0,
            p0_max: 1.0,
            cum_max: Vec::new(),
            kappa: kappa_m2,
            threshold,
            c,
            detection: None,
        };
        p.lambda_max = self.expected(&p);
        p.p0_max = (-p.lambda_max).exp();
        let mut acc = 0.0;
        p.cum_max = (0..self.bins.len())
            .map(|b| {
                acc += self.weight(&p, b);
                acc
            })
            .collect();
        p
    }

    /// Weight of bin `b`: its particles in the superset region, over pi / 3t.
    #[inline]
    fn weight(&self, p: &Prepared, b: usize) -> f64 {
        let w = p.a + p.lo * p.t;
        self.bins[b].per_m3 * p.xi_b[b] * (p.w3_b[b] - w * w * w).max(0.0)
    }

    /// Expected number of particles in a beam's superset region (every bin to its r_b).
    pub fn expected(&self, p: &Prepared) -> f64 {
        p.c * (0..self.bins.len()).map(|b| self.weight(p, b)).sum::<f64>()
    }

    /// Draws the detectable particles of `n` beams in order and calls `out(k, echo)` with
    /// each echo of beam k; `range(k)` is beam k's target range in metres (infinite for an
    /// empty slot, `None` for a beam that lights nothing, such as an occluded one) and
    /// `alpha` the extinction of the medium (1/m).
    ///
    /// Each beam's superset region holds Poisson(lambda_max) particles, so whether a beam
    /// holds any is a Bernoulli trial of probability 1 - p0 and the gap to the next beam
    /// that does is geometric: one draw per lit beam, G = floor(-ln U / lambda_max),
    /// instead of one per beam (a 32-bit draw and its test for each of a frame's 50,000
    /// beams were a quarter of a weather chain's time, while rain lights about 0.2 % of
    /// them and moderate snow 8 %). A lit beam then draws its count from Poisson
    /// conditioned on at least one, by inversion, and its particles.
    pub fn beams(
        &self,
        p: &Prepared,
        rng: &mut ChaCha8Rng,
        n: usize,
        mut range: impl FnMut(usize) -> Option<f64>,
        alpha: f64,
        mut out: impl FnMut(usize, Echo),
    ) {
        let lambda = p.lambda_max;
        if !(lambda > 0.0 && lambda.is_finite()) {
            return;
        }
        let mut k = 0usize;
        loop {
            // U in (0, 1]: -ln U in [0, inf); `as` saturates a huge gap.
            let u: f64 = 1.0 - rng.random::<f64>();
            let gap = (-u.ln() / lambda).floor() as usize;
            k = k.saturating_add(gap);
            if k >= n {
                return;
            }
            // Also false for a NaN range.
            if let Some(r) = range(k).filter(|&r| r > p.lo) {
                // The count given at least one: inversion of a uniform on [p0, 1).
                let v: f64 = rng.random();
                let u = p.p0_max + v * (1.0 - p.p0_max);
                let (mut count, mut term, mut cdf) =
                    (1u32, p.p0_max * lambda, p.p0_max * (1.0 + lambda));
                while u >= cdf && count < 100_000 {
                    count += 1;
                    term *= lambda / f64::from(count);
                    cdf += term;
                }
                self.particles(p, rng, count, r, alpha, |e| out(k, e));
            }
            k += 1;
        }
    }

    /// The `count` particles of a lit beam's superset region (every bin to its r_b,
    /// whatever the target's range): those behind the target at `range` and those below
    /// the threshold are dropped (thinning a Poisson process keeps it Poisson, so this is
    /// exact, and it spares the per-beam sum over the bins a nearer target would need).
    fn particles(
        &self,
        p: &Prepared,
        rng: &mut ChaCha8Rng,
        count: u32,
        range: f64,
        alpha: f64,
        mut out: impl FnMut(Echo),
    ) {
        let total = p.lambda_max / p.c;
        let w3 = |r: f64| {
            let w = p.a + r * p.t;
            w * w * w
        };
        let lo3 = w3(p.lo);
        for _ in 0..count {
            let (a, b, c): (f64, f64, f64) = (rng.random(), rng.random(), rng.random());
            // The bin, by the cumulative weights.
            let bin = p
                .cum_max
                .partition_point(|&w| w <= a * total)
                .min(self.bins.len() - 1);
            let r = ((lo3 + c * (p.w3_b[bin] - lo3)).cbrt() - p.a) / p.t;
            // The target hides what lies behind it.
            if r > range {
                continue;
            }
            let sb = &self.bins[bin];
            let width = sb.hi - sb.lo;
            let d = if sb.slope.abs() * width < 1e-9 {
                sb.lo + b * width
            } else {
                sb.lo - (1.0 - b * sb.span).ln() / sb.slope
            };
            // `power` with the beam's radius a + r t of `prepare` (the tangent once a
            // frame, not per particle).
            let pw = self.power_in(r, d, alpha, p.kappa, 2.0 * (p.a + r * p.t));
            if pw < p.threshold {
                continue;
            }
            // In the receiver's field with probability xi(r) (one more draw, made only for
            // a particle bright enough to be detected).
            if self.optics.is_some() {
                let v: f64 = rng.random();
                // The bin's particles were thinned by xi(r_b) >= xi(r) already.
                if v * p.xi_b[bin] >= self.overlap_at(r) {
                    continue;
                }
            }
            let echo = Echo {
                range: r as f32,
                power: pw,
            };
            match &p.detection {
                // The receiver's noise decides (one draw per particle above the cut).
                Some((rule, t)) => {
                    let w: f64 = rng.random();
                    if let Some(a) = rule.echo_amplitude(pw / t, w) {
                        out(Echo {
                            range: echo.range,
                            power: a * t,
                        });
                    }
                }
                None => out(echo),
            }
        }
    }
}

/// Proposes the echoes of `pop` for every beam of `frame` (recorded returns, whatever
/// their fate except occluded, then vacant slots when `empty_slots`), drawing from `rng`
/// only for the beams that light a particle ([`Population::beams`]).
pub fn propose_population_echoes(
    frame: &mut NoisyFrame,
    rng: &mut ChaCha8Rng,
    pop: &Population,
    alpha: f64,
    empty_slots: bool,
) {
    if pop.is_empty() {
        return;
    }
    let kappa = frame.kappa_m2();
    // With probabilistic detection the particles are drawn down to the faintest echo
    // that can be reported, and each one's detection drawn.
    let prep = match frame.detection.clone().filter(|r| r.is_probabilistic()) {
        Some(rule) => pop
            .prepare(kappa, frame.faintest_echo(), frame.min_range)
            .with_detection(rule, frame.threshold),
        None => pop.prepare(kappa, frame.threshold, frame.min_range),
    };
    let slots = frame.slots();
    let vacant: Vec<SlotId> = if empty_slots {
        (0..slots.len() as u32)
            .filter(|&s| slots.is_vacant(s))
            .collect()
    } else {
        Vec::new()
    };
    let n = frame.clean_len;
    // Beams 0..n are the recorded returns, then the vacant slots.
    let mut lit: Vec<(SlotId, Echo)> = Vec::new();
    pop.beams(
        &prep,
        rng,
        n + vacant.len(),
        |k| match k.checked_sub(n) {
            // Occlusion removes the beam: no particle is lit.
            None if frame.fate[k] == Fate::Occluded => None,
            None => Some(f64::from(frame.range[k])),
            Some(_) => Some(f64::INFINITY),
        },
        alpha,
        |k, e| {
            let slot = match k.checked_sub(n) {
                None => slots.slot_of(k),
                Some(v) => vacant[v],
            };
            lit.push((slot, e));
        },
    );
    for (slot, e) in lit {
        frame.propose_slot(slot, e);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    fn rain() -> Particles {
        // Marshall-Palmer at 7 mm/h.
        Particles::new(8000.0, 4.1 * 7f64.powf(-0.21), 6.0, 1.328, 3e-3)
    }

    #[test]
    fn nothing_is_detectable_beyond_the_cutoff() {
        let p = rain();
        let c = p.cutoff_m(100.0, 0.001);
        assert!(c > 2.0 && c < 20.0, "{c}");
        assert!(p.power(c * 1.001, p.d_max_mm, 0.0, 100.0) < 0.001);
        assert!(p.power(c * 0.999, p.d_max_mm, 0.0, 100.0) >= 0.001);
        assert!((fresnel(1.328) - 0.01985).abs() < 1e-4);
    }

    #[test]
    fn counts_and_sizes_follow_the_distribution() {
        let p = rain();
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        // No threshold: every particle beyond 1.5 m is reported; count and mean range.
        let (mut n, mut sum_r) = (0u64, 0.0);
        let beams = 20_000;
        for _ in 0..beams {
            p.beam(&mut rng, 8.0, 8.0, 0.0, 100.0, 0.0, 0.0, |e| {
                n += 1;
                sum_r += f64::from(e.range);
            });
        }
        let cone = std::f64::consts::PI / 3.0 * 8.0 * (8.0 * p.tan_divergence / 2.0).powi(2);
        // Share of the cone's volume beyond 1.5 m: 1 - (1.5/8)^3.
        let want = p.per_m3 * cone * (1.0 - (1.5f64 / 8.0).powi(3)) * f64::from(beams);
        let sd = want.sqrt();
        assert!(
            (n as f64 - want).abs() < 4.0 * sd + 0.01 * want,
            "{n} vs {want}"
        );
        // Mean of r = 8 u^(1/3) given r > 1.5: (3/4) 8 (1 - q^4) / (1 - q^3), q = 1.5/8.
        let q = 1.5f64 / 8.0;
        let mean = 0.75 * 8.0 * (1.0 - q.powi(4)) / (1.0 - q.powi(3));
        assert!(
            (sum_r / n as f64 - mean).abs() < 0.05,
            "{}",
            sum_r / n as f64
        );
    }
}

#[cfg(test)]
mod population_tests {
    use super::*;
    use crate::noise::world::mie;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Poisson};

    /// Brute force: every particle of the cone to `range` (Poisson count, r^3 uniform,
    /// D by inversion of the truncated exponential), kept when r >= 1.5 m and P >= th.
    /// Returns (count, sum r, sum r^2, sum ln P, sum (ln P)^2).
    fn brute(pop: &Population, n0: f64, l: f64, range: f64, th: f64, beams: u32) -> [f64; 5] {
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let (d0, d1) = (D_MIN_MM, 6.0);
        let per = n0 / l * ((-l * d0).exp() - (-l * d1).exp());
        // The lit volume to `range`: a cone from the sensor (LISA), or with the optics a
        // frustum from the exit aperture, radius a_t + r tan(theta/2) (pi h (R1^2 + R1 R2
        // + R2^2) / 3), with r drawn by rejection from the density ~ radius(r)^2.
        let (a0, grow) = match &pop.optics {
            Some(o) => (o.tx_radius_m, (o.divergence_rad / 2.0).tan()),
            None => (0.0, pop.tan_divergence / 2.0),
        };
        let (r1, r2) = (a0, a0 + range * grow);
        let mean = per * std::f64::consts::PI * range * (r1 * r1 + r1 * r2 + r2 * r2) / 3.0;
        let pois = Poisson::new(mean).unwrap();
        let tail = 1.0 - (-l * (d1 - d0)).exp();
        let mut s = [0.0; 5];
        for _ in 0..beams {
            let n = pois.sample(&mut rng) as u64;
            for _ in 0..n {
                let (mut a, b): (f64, f64) = (rng.random(), rng.random());
                let r = loop {
                    let r = range * a;
                    let keep: f64 = rng.random();
                    if keep * r2 * r2 <= (a0 + r * grow).powi(2) {
                        break r;
                    }
                    a = rng.random();
                };
                let d = d0 - (1.0 - b * tail).ln() / l;
                let p = pop.power(r, d, 0.0, 100.0);
                if r >= MIN_RANGE_M && p >= th {
                    // Through the optics: in the receiver's field with probability xi(r).
                    if let Some(o) = &pop.optics {
                        let v: f64 = rng.random();
                        if v >= o.overlap(r) {
                            continue;
                        }
                    }
                    add(&mut s, r, p);
                }
            }
        }
        s
    }

    fn add(s: &mut [f64; 5], r: f64, p: f64) {
        let lp = p.ln();
        s[0] += 1.0;
        s[1] += r;
        s[2] += r * r;
        s[3] += lp;
        s[4] += lp * lp;
    }

    fn fast(pop: &Population, range: f64, th: f64, beams: u32) -> [f64; 5] {
        let mut rng = ChaCha8Rng::seed_from_u64(12);
        let prep = pop.prepare(100.0, th, 0.0);
        let mut s = [0.0; 5];
        pop.beams(
            &prep,
            &mut rng,
            beams as usize,
            |_| Some(range),
            0.0,
            |_, e| add(&mut s, f64::from(e.range), e.power),
        );
        s
    }

    /// Counts, and mean and SD of the range and of ln power (which carries the size) of
    /// detectable echoes: fast sampler vs brute force, within 4 standard errors.
    fn compare(pop: &Population, n0: f64, l: f64, th: f64) {
        let beams = 200_000;
        let range = 8.0;
        let b = brute(pop, n0, l, range, th, beams);
        let f = fast(pop, range, th, beams);
        assert!(
            b[0] > 500.0,
            "too few brute-force echoes for the test: {}",
            b[0]
        );
        let se = (b[0] + f[0]).sqrt();
        assert!(
            (b[0] - f[0]).abs() < 4.0 * se,
            "counts {} vs {}",
            b[0],
            f[0]
        );
        for (i, what) in [(1, "r"), (3, "ln P")] {
            let (mb, mf) = (b[i] / b[0], f[i] / f[0]);
            let sd = (b[i + 1] / b[0] - mb * mb).sqrt();
            let se_m = sd * (1.0 / b[0] + 1.0 / f[0]).sqrt();
            assert!(
                (mb - mf).abs() < 4.0 * se_m,
                "mean {what} {mb} vs {mf} (se {se_m})"
            );
            let sdf = (f[i + 1] / f[0] - mf * mf).sqrt();
            assert!((sd / sdf - 1.0).abs() < 0.1, "sd {what} {sd} vs {sdf}");
        }
    }

    /// Marshall-Palmer drops (0.05-6 mm) at `rate` mm/h in a 3 mrad beam, and Lambda.
    fn marshall_palmer(rate: f64, reflectance: Reflectance) -> (Population, f64) {
        let dsd = Dsd::MarshallPalmer { rate_mm_h: rate };
        let pop = Population::new(&dsd, D_MIN_MM, 6.0, reflectance, 3e-3);
        (pop, 4.1 * rate.powf(-0.21))
    }

    /// Exact-180 degree Mie backscatter of water at 905 nm.
    fn water_mie() -> Reflectance {
        Reflectance::Mie {
            table: mie::water_905(),
            wavelength_m: mie::WAVELENGTH_905_M,
        }
    }

    #[test]
    fn detectable_sampling_matches_brute_force_fresnel() {
        let (pop, l) = marshall_palmer(7.0, Reflectance::Fresnel(fresnel(1.328)));
        compare(&pop, 8000.0, l, 1e-5);
    }

    #[test]
    fn detectable_sampling_matches_brute_force_mie() {
        let (pop, l) = marshall_palmer(7.0, water_mie());
        compare(&pop, 8000.0, l, 1e-4);
    }

    #[test]
    fn the_hdl32e_overlap_never_falls_with_range() {
        // The sampler thins each size bin by xi(r_b) as a bound of xi on [lo, r_b]: xi must
        // not fall with r.
        let o = super::super::fog::hdl32e_optics();
        let mut last = 0.0;
        for k in 0..=200_000 {
            let x = o.overlap(f64::from(k) * 1e-3);
            assert!(x >= last - 1e-12, "{k} mm: {x} < {last}");
            last = x;
        }
        assert!(last > 0.999);
    }

    #[test]
    fn the_overlap_table_is_within_1e_6_of_xi_and_never_falls() {
        let o = super::super::fog::hdl32e_optics();
        let t = OverlapTable::new(&o).expect("the HDL-32E's field grows around its beam");
        let (r1, r2) = (o.start_m(), o.full_m());
        let mut last = 0.0;
        for k in 0..=400_000 {
            let r = f64::from(k) * 1e-4;
            let (got, want) = (t.at(r), o.overlap(r));
            assert!((got - want).abs() < 1e-6, "{r} m: {got} vs {want}");
            assert!(got >= last, "{r} m falls");
            last = got;
        }
        assert_eq!(t.at(r1 * 0.5), 0.0);
        assert_eq!(t.at(r2 + 1.0), 1.0);
        assert_eq!(t.at(f64::NAN), 0.0);
    }

    #[test]
    fn detectable_sampling_matches_brute_force_through_the_hdl32e_optics() {
        // A heavier rain, so that enough drops pass the exit aperture's wider beam and the
        // receiver's field for the comparison.
        let (pop, l) = marshall_palmer(50.0, water_mie());
        let pop = pop.with_optics(super::super::fog::hdl32e_optics());
        compare(&pop, 8000.0, l, 1e-5);
    }

    #[test]
    fn lambertian_full_beam_target_gives_kappa_rho_over_r2() {
        // A Lambertian disc of reflectance rho filling the beam has dsigma/dOmega =
        // rho A_beam / pi; the particle rule P = kappa pi (dsigma/dOmega) / (A_beam r^2)
        // must give the hard-target law kappa rho / r^2 exactly.
        let (kappa, rho, r, t): (f64, f64, f64, f64) = (100.0, 0.3, 5.0, 3e-3);
        let a_beam = std::f64::consts::PI * (r * t / 2.0).powi(2);
        let dsdo = rho * a_beam / std::f64::consts::PI;
        let p_rule = kappa * std::f64::consts::PI * dsdo / (a_beam * r * r);
        assert!((p_rule / (kappa * rho / (r * r)) - 1.0).abs() < 1e-12);
        // And the code's form: a sphere filling the beam (D = r tan theta) with
        // rho(D) = Q_back/4 is the same as that disc with rho = Q_back / 4.
        let pop = Population::new(
            &Dsd::MarshallPalmer { rate_mm_h: 1.0 },
            D_MIN_MM,
            6.0,
            Reflectance::Fresnel(rho),
            t.atan(),
        );
        let d_mm = r * t * 1e3;
        let p = pop.power(r, d_mm, 0.0, kappa);
        assert!((p / (kappa * rho / (r * r)) - 1.0).abs() < 1e-9, "{p}");
        // A drop of cross-section A_p < A_beam: the rule kappa pi (Q_back a^2/4) /
        // (A_beam r^2) with Q_back = 4 rho.
        let d_mm = 0.5 * r * t * 1e3;
        let a = d_mm * 1e-3 / 2.0;
        let want = kappa * std::f64::consts::PI * mie::diff_backscatter_m2_sr(4.0 * rho, a)
            / (a_beam * r * r);
        let p = pop.power(r, d_mm, 0.0, kappa);
        assert!((p / want - 1.0).abs() < 1e-9, "{p} vs {want}");
    }
}
