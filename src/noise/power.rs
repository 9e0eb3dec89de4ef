//! Ideal power of a recorded return, as a fraction of emitted power.
//!
//! LiDAR equation for a Lambertian target: P_i = kappa * rho / R^2, clamped at 1
//! (receiver saturation). rho comes from the intensity byte (`/100` for firmware-2
//! reflectivity, `/255` for raw levels — an assumption: raw level proportional to
//! reflectance) clamped to `[reflectance_floor, 1]`, so retro-reflectors (reflectivity
//! over 100) get rho = 1 and an intensity of 0 is still a detectable return.
//!
//! kappa is fixed by a reference target: rho_ref at z_ref returns exactly the threshold
//! p_th = `detection.min_power`, so kappa = p_th * z_ref^2 / rho_ref.
//!
//! The MAVS model (P = rho / z^2 against P_min = 0.9 / (pi z_max^2)) is the same formula
//! rescaled so that its threshold lands on `detection.min_power`: kappa = p_th * pi *
//! z_max^2 / 0.9 with z_max = `reference_range_m`, i.e. an effective rho_ref = 0.9 / pi.
//! A return is then kept exactly when rho / z^2 >= P_min, whatever `min_power` is;
//! `reference_reflectance` is not used.

use crate::config::{DetectionConfig, IntensityMode, PowerConfig, PowerModel, SensorConfig};
use serde::Serialize;

/// kappa (m^2) of the default power model (a 10 % target at 100 m on the 1e-3
/// threshold), for frames built without one.
pub const DEFAULT_KAPPA_M2: f64 = 100.0;

/// Every constant of the ideal-power model, for reports.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct PowerConstants {
    /// "lidar-equation" or "mavs".
    pub model: PowerModel,
    /// How intensities were read.
    pub intensity: IntensityMode,
    /// Intensity giving rho = 1 (100 for reflectivity, 255 for raw).
    pub intensity_full_scale: f64,
    /// Lowest reflectance given to a return.
    pub reflectance_floor: f64,
    /// Reference reflectance used for kappa (0.9 / pi in the MAVS model).
    pub reference_reflectance: f64,
    /// Reference range in metres (z_max in the MAVS model).
    pub reference_range_m: f64,
    /// Detection threshold as a fraction of emitted power.
    pub threshold: f64,
    /// kappa in P = kappa * rho / R^2, in square metres.
    pub kappa_m2: f64,
    /// Powers are clamped at this value (receiver saturation).
    pub saturation: f64,
    /// MAVS only: its unscaled threshold 0.9 / (pi * z_max^2) in 1/m^2.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mavs_min_power_per_m2: Option<f64>,
}

/// The ideal-power model with a per-intensity reflectance table.
#[derive(Clone, Debug)]
pub struct IdealPower {
    constants: PowerConstants,
    /// rho of each intensity byte.
    rho: [f64; 256],
    /// p_th * (rho / rho_ref) of each intensity byte: the first two factors of
    /// [`IdealPower::power`], so a return costs one division instead of two (same value:
    /// the product is evaluated left to right).
    scaled: [f64; 256],
}

impl IdealPower {
    /// Builds the model from the configuration tables.
    pub fn new(power: &PowerConfig, sensor: &SensorConfig, detection: &DetectionConfig) -> Self {
        let full_scale = match sensor.intensity {
            IntensityMode::Reflectivity => 100.0,
            IntensityMode::Raw => 255.0,
        };
        let (rho_ref, mavs) = match power.model {
            PowerModel::LidarEquation => (power.reference_reflectance, None),
            PowerModel::Mavs => (
                0.9 / std::f64::consts::PI,
                Some(0.9 / (std::f64::consts::PI * power.reference_range_m.powi(2))),
            ),
        };
        let floor = power.reflectance_floor;
        let mut rho = [0.0; 256];
        for (i, r) in rho.iter_mut().enumerate() {
            *r = (i as f64 / full_scale).clamp(floor, 1.0);
        }
        let scaled = rho.map(|r| detection.min_power * (r / rho_ref));
        IdealPower {
            constants: PowerConstants {
                model: power.model,
                intensity: sensor.intensity,
                intensity_full_scale: full_scale,
                reflectance_floor: floor,
                reference_reflectance: rho_ref,
                reference_range_m: power.reference_range_m,
                threshold: detection.min_power,
                kappa_m2: detection.min_power * power.reference_range_m.powi(2) / rho_ref,
                saturation: 1.0,
                mavs_min_power_per_m2: mavs,
            },
            rho,
            scaled,
        }
    }

    /// The constants in use.
    pub fn constants(&self) -> &PowerConstants {
        &self.constants
    }

    /// Reflectance given to an intensity byte.
    pub fn reflectance(&self, intensity: u8) -> f64 {
        self.rho[intensity as usize]
    }

    /// Ideal power of a return of `intensity` at `range` metres.
    #[inline]
    pub fn power(&self, intensity: u8, range: f32) -> f64 {
        let c = &self.constants;
        let range = f64::from(range);
        if range <= 0.0 {
            return c.saturation;
        }
        // Written as p_th * (rho / rho_ref) * (z_ref / R)^2 — the same value as
        // kappa * rho / R^2 — so the reference target lands exactly on the threshold.
        // `scaled` holds p_th * (rho / rho_ref) (threshold and reflectances are fixed).
        let q = c.reference_range_m / range;
        (self.scaled[usize::from(intensity)] * q * q).min(c.saturation)
    }

    /// Intensity byte the sensor would report for a return of `power` at `range` metres:
    /// the inverse of [`IdealPower::power`], rounded and clamped to the byte's full scale
    /// (spurious echoes get their intensity from it).
    pub fn intensity_of(&self, power: f64, range: f32) -> u8 {
        let c = &self.constants;
        let q = f64::from(range) / c.reference_range_m;
        let rho = power / c.threshold * c.reference_reflectance * q * q;
        // Non-negative after the clamp (NaN gives 0), so adding one half and truncating
        // rounds half up without the libm call `round` is here.
        (rho.clamp(0.0, 1.0) * c.intensity_full_scale + 0.5) as u8
    }

    /// Intensity byte the sensor reports for a spurious echo of `power` at `range`
    /// metres (fog, drops, flakes, crosstalk, mixtures): the byte of
    /// [`IdealPower::intensity_of`], but at least 1. Why: a reported echo crossed the
    /// threshold, so its raw level is not zero, while the firmware's range compensation
    /// (calibrated on hard targets in full overlap) takes a weak echo at a few metres
    /// down to 0; a real sensor reports its particle clutter with small non-zero bytes
    /// (a real HDL-32E in fog: median 1, 95th percentile 4; `docs/fidelity.md`). How the
    /// firmware maps near, weak echoes above that is not known, so nothing more is added.
    pub fn echo_intensity(&self, power: f64, range: f32) -> u8 {
        self.intensity_of(power, range).max(1)
    }
}
