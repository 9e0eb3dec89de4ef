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

use crate::noise::Echo;
use rand::Rng;
use rand_chacha::ChaCha8Rng;

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
