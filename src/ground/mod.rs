//! Ground removal: labels each surviving return of one frame as ground or not.
//!
//! Four methods, chosen by [`GroundOptions::method`]:
//! - [`GroundMethod::Patchwork`] (default): region-wise plane fitting after Patchwork++
//!   (Lee et al., RA-L 2022) with a per-point height test of our own, see [`patchwork`].
//!   It is the method that keeps ground precision and recall at 0.97 or more under the
//!   Goodin rain of `configs/rain.toml` (`tests/integration/ground_targets.rs`).
//! - [`GroundMethod::RangeImage`]: the angle-image segmentation of MATLAB's
//!   `segmentGroundFromLidarData` after Bogoslavskyi and Stachniss, see [`range_image`];
//!   the reference study's method (`configs/paper.toml` selects it).
//! - [`GroundMethod::Ransac`]: a plane fit with a caller-seeded random stream, see [`ransac`].
//! - [`GroundMethod::None`]: nothing is ground.
//!
//! Every method is stateless and works on one frame at a time, so results never depend
//! on which frames came before (or on the thread count).

pub mod patchwork;
pub mod range_image;
pub mod ransac;

use crate::frame::Return;
use rand_chacha::ChaCha8Rng;
use serde::ser::SerializeMap;
use serde::{Deserialize, Serialize, Serializer};

/// Which ground segmentation runs.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum GroundMethod {
    /// Region-wise plane fitting after Patchwork++ with a per-point height test.
    #[default]
    Patchwork,
    /// Angle image over the organised ring x azimuth grid (MATLAB / Bogoslavskyi).
    RangeImage,
    /// RANSAC plane fit refined by least squares.
    Ransac,
    /// No ground removal: every return is kept as non-ground.
    None,
}

/// Settings of the ground stage; the `[ground]` table of the configuration file.
///
/// Serialised (in `summary.json`), the `patchwork_*` keys appear only when the method is
/// patchwork, so reports of the other methods keep the keys they always had.
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct GroundOptions {
    /// Segmentation method ("patchwork", "range-image", "ransac" or "none").
    pub method: GroundMethod,
    /// Range image: largest angle difference (degrees, exclusive) between neighbouring
    /// ground cells (MATLAB `ElevationAngleDelta`).
    pub max_angle_delta_deg: f64,
    /// Range image: largest angle (degrees, inclusive) of a column's lowest cell for it to
    /// seed the ground (MATLAB `InitialElevationAngle`).
    pub initial_angle_deg: f64,
    /// RANSAC: largest point-to-plane distance of an inlier, in metres.
    pub ransac_threshold_m: f64,
    /// RANSAC: number of three-point hypotheses drawn.
    pub ransac_iterations: u32,
    /// RANSAC: largest tilt of the plane from horizontal, in degrees.
    pub ransac_max_tilt_deg: f64,
    /// Patchwork: sensor height above the road, metres.
    pub patchwork_sensor_height_m: f64,
    /// Patchwork: returns nearer than this horizontal distance are not ground, metres.
    pub patchwork_min_range_m: f64,
    /// Patchwork: outer edge of the concentric zone model, metres.
    pub patchwork_max_range_m: f64,
    /// Patchwork: seed band above the lowest-point representative, metres.
    pub patchwork_seed_m: f64,
    /// Patchwork: inlier distance of the plane fit and largest height tolerance, metres.
    pub patchwork_distance_m: f64,
    /// Patchwork: largest angle of a ground plane's normal from vertical, degrees.
    pub patchwork_uprightness_deg: f64,
    /// Patchwork: largest elevation of a non-flat inner ground plane above the road, metres.
    pub patchwork_elevation_m: f64,
    /// Patchwork: variance along the normal below which an elevated plane is flat, m^2.
    pub patchwork_flatness_m2: f64,
    /// Patchwork: steepest road the global elevation bound allows, degrees.
    pub patchwork_max_slope_deg: f64,
    /// Patchwork: depth below the road beyond which a weak inner return is a reflection, metres.
    pub patchwork_rnr_depth_m: f64,
    /// Patchwork: intensity at or below which a deep inner return is a reflection.
    pub patchwork_rnr_max_intensity: u8,
    /// Patchwork: seed band of the vertical plane fit (R-VPF), metres.
    pub patchwork_vpf_seed_m: f64,
    /// Patchwork: inlier distance of the vertical plane fit (R-VPF), metres.
    pub patchwork_vpf_distance_m: f64,
    /// Patchwork: height tolerance above the plane in multiples of its RMS residual.
    pub patchwork_height_sigmas: f64,
    /// Patchwork: smallest height tolerance above the plane, metres.
    pub patchwork_height_min_m: f64,
    /// Patchwork: depth tolerance below the plane, metres.
    pub patchwork_below_m: f64,
    /// Patchwork: rise to the next ring that marks the foot of a vertical structure
    /// (0 turns the test off), metres.
    pub patchwork_foot_rise_m: f64,
    /// Patchwork: largest height step between a ground plane and the nearer one in its
    /// direction, metres.
    pub patchwork_continuity_m: f64,
}

impl Serialize for GroundOptions {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let mut m = s.serialize_map(None)?;
        m.serialize_entry("method", &self.method)?;
        m.serialize_entry("max_angle_delta_deg", &self.max_angle_delta_deg)?;
        m.serialize_entry("initial_angle_deg", &self.initial_angle_deg)?;
        m.serialize_entry("ransac_threshold_m", &self.ransac_threshold_m)?;
        m.serialize_entry("ransac_iterations", &self.ransac_iterations)?;
        m.serialize_entry("ransac_max_tilt_deg", &self.ransac_max_tilt_deg)?;
        if self.method == GroundMethod::Patchwork {
            for (key, value) in self.patchwork_f64() {
                m.serialize_entry(key, &value)?;
            }
            m.serialize_entry(
                "patchwork_rnr_max_intensity",
                &self.patchwork_rnr_max_intensity,
            )?;
        }
        m.end()
    }
}

impl Default for GroundOptions {
    fn default() -> Self {
        let p = patchwork::Params::default();
        GroundOptions {
            method: GroundMethod::Patchwork,
            max_angle_delta_deg: 5.0,
            initial_angle_deg: 30.0,
            ransac_threshold_m: 0.2,
            ransac_iterations: 100,
            ransac_max_tilt_deg: 15.0,
            patchwork_sensor_height_m: p.sensor_height_m,
            patchwork_min_range_m: p.min_range_m,
            patchwork_max_range_m: p.max_range_m,
            patchwork_seed_m: p.seed_m,
            patchwork_distance_m: p.distance_m,
            patchwork_uprightness_deg: p.uprightness_deg,
            patchwork_elevation_m: p.elevation_m,
            patchwork_flatness_m2: p.flatness_m2,
            patchwork_max_slope_deg: p.max_slope_deg,
            patchwork_rnr_depth_m: p.rnr_depth_m,
            patchwork_rnr_max_intensity: p.rnr_max_intensity,
            patchwork_vpf_seed_m: p.vpf_seed_m,
            patchwork_vpf_distance_m: p.vpf_distance_m,
            patchwork_height_sigmas: p.height_sigmas,
            patchwork_height_min_m: p.height_min_m,
            patchwork_below_m: p.below_m,
            patchwork_foot_rise_m: p.foot_rise_m,
            patchwork_continuity_m: p.continuity_m,
        }
    }
}

impl GroundOptions {
    /// The patchwork method's settings.
    pub fn patchwork_params(&self) -> patchwork::Params {
        patchwork::Params {
            sensor_height_m: self.patchwork_sensor_height_m,
            min_range_m: self.patchwork_min_range_m,
            max_range_m: self.patchwork_max_range_m,
            seed_m: self.patchwork_seed_m,
            distance_m: self.patchwork_distance_m,
            uprightness_deg: self.patchwork_uprightness_deg,
            elevation_m: self.patchwork_elevation_m,
            flatness_m2: self.patchwork_flatness_m2,
            max_slope_deg: self.patchwork_max_slope_deg,
            rnr_depth_m: self.patchwork_rnr_depth_m,
            rnr_max_intensity: self.patchwork_rnr_max_intensity,
            vpf_seed_m: self.patchwork_vpf_seed_m,
            vpf_distance_m: self.patchwork_vpf_distance_m,
            height_sigmas: self.patchwork_height_sigmas,
            height_min_m: self.patchwork_height_min_m,
            below_m: self.patchwork_below_m,
            foot_rise_m: self.patchwork_foot_rise_m,
            continuity_m: self.patchwork_continuity_m,
        }
    }

    /// The real-valued `patchwork_*` keys with their values, in documentation order.
    pub fn patchwork_f64(&self) -> [(&'static str, f64); 17] {
        [
            ("patchwork_sensor_height_m", self.patchwork_sensor_height_m),
            ("patchwork_min_range_m", self.patchwork_min_range_m),
            ("patchwork_max_range_m", self.patchwork_max_range_m),
            ("patchwork_seed_m", self.patchwork_seed_m),
            ("patchwork_distance_m", self.patchwork_distance_m),
            ("patchwork_uprightness_deg", self.patchwork_uprightness_deg),
            ("patchwork_elevation_m", self.patchwork_elevation_m),
            ("patchwork_flatness_m2", self.patchwork_flatness_m2),
            ("patchwork_max_slope_deg", self.patchwork_max_slope_deg),
            ("patchwork_rnr_depth_m", self.patchwork_rnr_depth_m),
            ("patchwork_vpf_seed_m", self.patchwork_vpf_seed_m),
            ("patchwork_vpf_distance_m", self.patchwork_vpf_distance_m),
            ("patchwork_height_sigmas", self.patchwork_height_sigmas),
            ("patchwork_height_min_m", self.patchwork_height_min_m),
            ("patchwork_below_m", self.patchwork_below_m),
            ("patchwork_foot_rise_m", self.patchwork_foot_rise_m),
            ("patchwork_continuity_m", self.patchwork_continuity_m),
        ]
    }

    /// Checks one `patchwork_*` value; the error names the key. Sizes must be finite and
    /// non-negative (those that scale a test, positive), angles within 0..90 degrees.
    pub fn check_patchwork(key: &str, value: f64) -> Result<(), String> {
        let ok = value.is_finite()
            && match key {
                "patchwork_uprightness_deg" | "patchwork_max_slope_deg" => {
                    (0.0..=90.0).contains(&value)
                }
                "patchwork_foot_rise_m"
                | "patchwork_flatness_m2"
                | "patchwork_rnr_depth_m"
                | "patchwork_below_m"
                | "patchwork_min_range_m" => value >= 0.0,
                _ => value > 0.0,
            };
        if ok {
            Ok(())
        } else {
            Err(format!(
                "ground.{key}: {value} is not allowed ({})",
                match key {
                    "patchwork_uprightness_deg" | "patchwork_max_slope_deg" =>
                        "an angle between 0 and 90 degrees",
                    "patchwork_foot_rise_m"
                    | "patchwork_flatness_m2"
                    | "patchwork_rnr_depth_m"
                    | "patchwork_below_m"
                    | "patchwork_min_range_m" => "a finite value of 0 or more",
                    _ => "a finite value above 0",
                }
            ))
        }
    }
}

impl GroundOptions {
    /// Checks every value; the error names the offending key of the `[ground]` table.
    pub fn validate(&self) -> Result<(), String> {
        fn angle(key: &str, value: f64) -> Result<(), String> {
            if value.is_finite() && (0.0..=90.0).contains(&value) {
                Ok(())
            } else {
                Err(format!(
                    "ground.{key} must be an angle between 0 and 90 degrees, got {value}"
                ))
            }
        }
        angle("max_angle_delta_deg", self.max_angle_delta_deg)?;
        angle("initial_angle_deg", self.initial_angle_deg)?;
        angle("ransac_max_tilt_deg", self.ransac_max_tilt_deg)?;
        if !(self.ransac_threshold_m.is_finite() && self.ransac_threshold_m > 0.0) {
            return Err(format!(
                "ground.ransac_threshold_m must be a positive distance in metres, got {}",
                self.ransac_threshold_m
            ));
        }
        if self.ransac_iterations == 0 {
            return Err("ground.ransac_iterations must be at least 1, got 0".to_string());
        }
        for (key, value) in self.patchwork_f64() {
            Self::check_patchwork(key, value)?;
        }
        if self.patchwork_max_range_m <= self.patchwork_min_range_m {
            return Err(format!(
                "ground.patchwork_max_range_m ({}) must exceed ground.patchwork_min_range_m ({})",
                self.patchwork_max_range_m, self.patchwork_min_range_m
            ));
        }
        Ok(())
    }
}

/// Labels each return as ground (true) or not, in input order.
///
/// `rng` is only drawn from by [`GroundMethod::Ransac`]; the other methods leave it
/// untouched, so switching method does not shift later stages' streams unless RANSAC
/// is chosen.
pub fn segment(returns: &[Return], opts: &GroundOptions, rng: &mut ChaCha8Rng) -> Vec<bool> {
    match opts.method {
        GroundMethod::RangeImage => {
            range_image::segment(returns, opts.initial_angle_deg, opts.max_angle_delta_deg)
        }
        GroundMethod::Ransac => ransac::segment(
            returns,
            opts.ransac_threshold_m,
            opts.ransac_iterations,
            opts.ransac_max_tilt_deg,
            rng,
        ),
        GroundMethod::Patchwork => patchwork::segment(returns, &opts.patchwork_params()),
        GroundMethod::None => vec![false; returns.len()],
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn toml_table_parses_with_kebab_case_methods() {
        let opts: GroundOptions = toml::from_str(
            "method = \"ransac\"\nmax_angle_delta_deg = 4.0\nransac_iterations = 7\n",
        )
        .unwrap();
        assert_eq!(opts.method, GroundMethod::Ransac);
        assert_eq!(opts.max_angle_delta_deg, 4.0);
        assert_eq!(opts.ransac_iterations, 7);
        assert_eq!(
            opts.initial_angle_deg, 30.0,
            "missing keys take the default"
        );
        let opts: GroundOptions = toml::from_str("method = \"range-image\"").unwrap();
        assert_eq!(opts.method, GroundMethod::RangeImage);
        let opts: GroundOptions = toml::from_str("method = \"none\"").unwrap();
        assert_eq!(opts.method, GroundMethod::None);
    }

    #[test]
    fn toml_rejects_unknown_keys_and_methods() {
        let err = toml::from_str::<GroundOptions>("max_angle_delta = 4.0").unwrap_err();
        assert!(err.to_string().contains("max_angle_delta"), "{err}");
        assert!(toml::from_str::<GroundOptions>("method = \"RangeImage\"").is_err());
        assert!(toml::from_str::<GroundOptions>("method = \"Patchwork\"").is_err());
        let opts: GroundOptions =
            toml::from_str("method = \"patchwork\"\npatchwork_sensor_height_m = 2.2").unwrap();
        assert_eq!(opts.method, GroundMethod::Patchwork);
        assert_eq!(opts.patchwork_sensor_height_m, 2.2);
    }

    #[test]
    fn defaults_match_the_reference_and_validate() {
        let d = GroundOptions::default();
        assert_eq!(d.method, GroundMethod::Patchwork);
        assert_eq!(d.max_angle_delta_deg, 5.0);
        assert_eq!(d.initial_angle_deg, 30.0);
        assert!(d.validate().is_ok());
    }

    #[test]
    fn validate_names_the_key() {
        let cases: [(&str, GroundOptions); 6] = [
            (
                "max_angle_delta_deg",
                GroundOptions {
                    max_angle_delta_deg: -1.0,
                    ..Default::default()
                },
            ),
            (
                "initial_angle_deg",
                GroundOptions {
                    initial_angle_deg: 91.0,
                    ..Default::default()
                },
            ),
            (
                "initial_angle_deg",
                GroundOptions {
                    initial_angle_deg: f64::NAN,
                    ..Default::default()
                },
            ),
            (
                "ransac_max_tilt_deg",
                GroundOptions {
                    ransac_max_tilt_deg: -0.5,
                    ..Default::default()
                },
            ),
            (
                "ransac_threshold_m",
                GroundOptions {
                    ransac_threshold_m: 0.0,
                    ..Default::default()
                },
            ),
            (
                "ransac_iterations",
                GroundOptions {
                    ransac_iterations: 0,
                    ..Default::default()
                },
            ),
        ];
        for (key, opts) in cases {
            let err = opts.validate().unwrap_err();
            assert!(err.contains(key), "{key}: {err}");
        }
    }
}
