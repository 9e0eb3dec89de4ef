//! Ground removal: labels each surviving return of one frame as ground or not.
//!
//! Three methods, chosen by [`GroundOptions::method`]:
//! - [`GroundMethod::RangeImage`] (default): the angle-image segmentation of MATLAB's
//!   `segmentGroundFromLidarData` after Bogoslavskyi and Stachniss, see [`range_image`].
//! - [`GroundMethod::Ransac`]: a plane fit with a caller-seeded random stream, see [`ransac`].
//! - [`GroundMethod::None`]: nothing is ground.
//!
//! Every method is stateless and works on one frame at a time, so results never depend
//! on which frames came before (or on the thread count).

pub mod range_image;
pub mod ransac;

use crate::frame::Return;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

/// Which ground segmentation runs.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum GroundMethod {
    /// Angle image over the organised ring x azimuth grid (MATLAB / Bogoslavskyi).
    #[default]
    RangeImage,
    /// RANSAC plane fit refined by least squares.
    Ransac,
    /// No ground removal: every return is kept as non-ground.
    None,
}

/// Settings of the ground stage; the `[ground]` table of the configuration file.
#[derive(Clone, Debug, PartialEq, Deserialize, Serialize)]
#[serde(default, deny_unknown_fields)]
pub struct GroundOptions {
    /// Segmentation method ("range-image", "ransac" or "none").
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
}

impl Default for GroundOptions {
    fn default() -> Self {
        GroundOptions {
            method: GroundMethod::RangeImage,
            max_angle_delta_deg: 5.0,
            initial_angle_deg: 30.0,
            ransac_threshold_m: 0.2,
            ransac_iterations: 100,
            ransac_max_tilt_deg: 15.0,
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
        assert!(toml::from_str::<GroundOptions>("method = \"patchwork\"").is_err());
    }

    #[test]
    fn defaults_match_the_reference_and_validate() {
        let d = GroundOptions::default();
        assert_eq!(d.method, GroundMethod::RangeImage);
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
