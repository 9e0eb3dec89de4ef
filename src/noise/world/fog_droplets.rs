//! Fog droplet size distributions and their backscatter-to-extinction ratio at 905 nm
//! from Mie theory, for the `droplets` option of the fog stage.
//!
//! Distributions: the modified gamma n(r) = a r^alpha exp(-b r^gamma) (r the droplet
//! radius in um) with the parameters of Shettle & Fenn (1979) as tabulated by Al Naboulsi
//! et al., "Fog attenuation prediction for optical and infrared waves", Opt. Eng. 43(2),
//! 2004, Table 1 (after Tampieri & Tomasi 1976):
//! - advection fog: alpha = 3, gamma = 1, b = 0.3 /um (mode radius alpha / b = 10 um);
//! - radiation fog: alpha = 6, gamma = 1, b = 1.5 /um (mode radius 4 um).
//!
//! With gamma = 1 this is the gamma distribution of [`mie::Dsd::Gamma`] in the diameter
//! D = 2 r: N(D) ~ D^alpha exp(-(b / 2) D), so mu = alpha and Lambda = b / 2 per um of
//! diameter (150 /mm advection, 750 /mm radiation). The number density `a` drops out:
//! the stage normalises the extinction to the visibility (alpha_ext = -ln(0.05) / V) and
//! takes beta = alpha_ext * (beta / alpha)_Mie, so only the shape matters.
//!
//! Efficiencies: the Bohren-Huffman series of [`mie`] for water at 905 nm
//! ([`mie::WATER_905`], Hale & Querry 1973), tabulated on 6,000 log-spaced size
//! parameters over the droplets' range (0.2-250 um diameter), integrated by Simpson's
//! rule ([`mie::volume_optics`]) over 16 sub-ranges (32,000 diameters, a step of 8 nm,
//! far finer than the ripple of Q_back in x), so the ratio is converged to well under
//! 1 % (test).

use super::mie::{self, Dsd, MieTable, VolumeOptics};
use std::sync::OnceLock;

/// Smallest and largest droplet diameter integrated (mm).
const D_MIN_MM: f64 = 0.0002;
const D_MAX_MM: f64 = 0.25;
/// Sub-ranges of the diameter integral (each one Simpson rule of `mie`).
const SUB_RANGES: usize = 16;
/// Size parameters of the droplet Mie table.
const TABLE_POINTS: usize = 6000;

/// Where the fog backscatter comes from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Droplets {
    /// Hahner et al.'s beta = beta_r / V (beta_r an option).
    Hahner,
    /// Mie backscatter of advection fog (Shettle & Fenn, mode radius 10 um).
    Advection,
    /// Mie backscatter of radiation fog (Shettle & Fenn, mode radius 4 um).
    Radiation,
}

impl Droplets {
    /// The option value naming this choice.
    pub fn name(&self) -> &'static str {
        match self {
            Droplets::Hahner => "hahner",
            Droplets::Advection => "advection",
            Droplets::Radiation => "radiation",
        }
    }

    /// The modified-gamma parameters (alpha, b in 1/um) of a Mie distribution.
    pub fn shettle_fenn(&self) -> Option<(f64, f64)> {
        match self {
            Droplets::Hahner => None,
            Droplets::Advection => Some((3.0, 0.3)),
            Droplets::Radiation => Some((6.0, 1.5)),
        }
    }

    /// The distribution as N(D) over the diameter in mm (unit number density scale).
    pub fn dsd(&self) -> Option<Dsd> {
        self.shettle_fenn().map(|(alpha, b)| Dsd::Gamma {
            n0: 1.0,
            mu: alpha,
            // b / 2 per um of diameter, in 1/mm.
            lambda_per_mm: b / 2.0 * 1e3,
        })
    }

    /// Mie extinction and backscatter of the distribution at unit scale (their ratio is
    /// what the stage uses), computed once per kind.
    pub fn optics(&self) -> Option<VolumeOptics> {
        static ADVECTION: OnceLock<VolumeOptics> = OnceLock::new();
        static RADIATION: OnceLock<VolumeOptics> = OnceLock::new();
        let cell = match self {
            Droplets::Hahner => return None,
            Droplets::Advection => &ADVECTION,
            Droplets::Radiation => &RADIATION,
        };
        let dsd = self.dsd()?;
        Some(*cell.get_or_init(|| integrate(&dsd, table())))
    }

    /// beta / alpha_ext (1/sr) of the distribution.
    pub fn backscatter_ratio(&self) -> Option<f64> {
        self.optics().map(|o| o.beta_per_m_sr / o.alpha_per_m)
    }
}

/// Water at 905 nm over the droplets' size parameters.
fn table() -> &'static MieTable {
    static TABLE: OnceLock<MieTable> = OnceLock::new();
    TABLE.get_or_init(|| {
        let (n, k) = mie::WATER_905;
        MieTable::new(
            n,
            k,
            mie::size_parameter(D_MIN_MM * 1e-3, mie::WAVELENGTH_905_M),
            mie::size_parameter(D_MAX_MM * 1e-3, mie::WAVELENGTH_905_M),
            TABLE_POINTS,
        )
    })
}

/// alpha and beta of `dsd` over [D_MIN_MM, D_MAX_MM] in [`SUB_RANGES`] Simpson pieces.
fn integrate(dsd: &Dsd, table: &MieTable) -> VolumeOptics {
    let h = (D_MAX_MM - D_MIN_MM) / SUB_RANGES as f64;
    (0..SUB_RANGES).fold(
        VolumeOptics {
            alpha_per_m: 0.0,
            beta_per_m_sr: 0.0,
        },
        |acc, i| {
            let lo = D_MIN_MM + h * i as f64;
            let o = mie::volume_optics(dsd, lo, lo + h, table, mie::WAVELENGTH_905_M);
            VolumeOptics {
                alpha_per_m: acc.alpha_per_m + o.alpha_per_m,
                beta_per_m_sr: acc.beta_per_m_sr + o.beta_per_m_sr,
            }
        },
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn large_droplets_extinguish_twice_their_area() {
        // Extinction paradox: for droplets much larger than the wavelength Q_ext -> 2, so
        // alpha over the geometric cross-section of the distribution is close to 2
        // (slightly above: the mean Q_ext of a broad distribution at x ~ 30-70 is 2.0-2.1).
        for d in [Droplets::Advection, Droplets::Radiation] {
            let dsd = d.dsd().unwrap();
            let o = d.optics().unwrap();
            // Geometric cross-section by a plain midpoint rule on 200,000 diameters.
            let n = 200_000;
            let h = (D_MAX_MM - D_MIN_MM) / f64::from(n);
            let area: f64 = (0..n)
                .map(|i| {
                    let d_mm = D_MIN_MM + h * (f64::from(i) + 0.5);
                    let d_m = d_mm * 1e-3;
                    std::f64::consts::PI * d_m * d_m / 4.0 * dsd.density(d_mm) * h
                })
                .sum();
            let q = o.alpha_per_m / area;
            assert!((1.95..2.2).contains(&q), "{d:?}: mean Q_ext {q}");
        }
    }

    #[test]
    fn lidar_ratios_lie_in_the_range_of_liquid_water_clouds_and_converge() {
        // Liquid-water droplets of a few um and more have lidar ratios near 18-19 sr in the
        // near infrared (O'Connor, Illingworth & Hogan, J. Atmos. Oceanic Technol. 21,
        // 2004: 18.8 sr at 905 nm, used to calibrate ceilometers on liquid clouds); the
        // bounds here are loose, the exact values are reported, not asserted.
        for d in [Droplets::Advection, Droplets::Radiation] {
            let o = d.optics().unwrap();
            let s = o.lidar_ratio_sr();
            eprintln!(
                "{d:?}: lidar ratio {s:.3} sr, beta/alpha {:.5} 1/sr",
                1.0 / s
            );
            assert!((12.0..25.0).contains(&s), "{d:?}: {s} sr");
            // Half the sub-ranges: the ratio moves by far less than 1 %.
            let dsd = d.dsd().unwrap();
            let h = (D_MAX_MM - D_MIN_MM) / 8.0;
            let (mut a, mut b) = (0.0, 0.0);
            for i in 0..8 {
                let lo = D_MIN_MM + h * f64::from(i);
                let v = mie::volume_optics(&dsd, lo, lo + h, table(), mie::WAVELENGTH_905_M);
                a += v.alpha_per_m;
                b += v.beta_per_m_sr;
            }
            assert!(((a / b) / s - 1.0).abs() < 0.01, "{d:?}: {} vs {s}", a / b);
        }
        assert_eq!(Droplets::Hahner.optics(), None);
    }
}
