//! Validation of command-line values into the plain types the library takes (decoder
//! and point-cloud output settings; shards and frame ranges parse with
//! [`lidar_noise::shard`] and [`lidar_noise::range`]).

use lidar_noise::error::{Error, Result};
use lidar_noise::sensor::calibration::Calibration;
use lidar_noise::sensor::decode::DualSelect;
use lidar_noise::sensor::frames::{CalibrationFile, DecoderOptions};
use lidar_noise::writers::ply::{PlyEncoding, PlyStyle};
use lidar_noise::writers::{FrameFormat, FrameOutput};
use std::path::PathBuf;

/// Decoder settings as given on the command line.
#[derive(Clone, Debug, clap::Args)]
pub struct DecoderArgs {
    /// Per-laser calibration: ROS YAML or VeloView XML of the capture's sensor (default:
    /// the manual's table; an HDL-64E's own from its status bytes).
    #[arg(long, value_name = "FILE")]
    pub calibration: Option<PathBuf>,
    /// Use the block azimuth for every laser instead of interpolating by firing time.
    #[arg(long)]
    pub no_interpolate: bool,
    /// Returns to keep from dual-return captures.
    #[arg(long, value_enum, default_value_t = DualSelect::Both)]
    pub dual: DualSelect,
    /// Azimuth in degrees where frames are cut.
    #[arg(
        long,
        value_name = "DEG",
        default_value_t = 0.0,
        allow_negative_numbers = true
    )]
    pub cut_angle: f64,
    /// Also output the partial first and last sweeps of the capture.
    #[arg(long)]
    pub keep_partial: bool,
}

impl DecoderArgs {
    /// Checks the values and loads the calibration.
    pub fn to_options(&self) -> Result<DecoderOptions> {
        if !self.cut_angle.is_finite() {
            return Err(Error::Invalid(format!(
                "--cut-angle {}: give an angle in degrees, e.g. --cut-angle 90",
                self.cut_angle
            )));
        }
        let (calibration, calibration_file) = match &self.calibration {
            Some(path) => match Calibration::from_file(path) {
                Ok(c) => (
                    c,
                    Some(CalibrationFile {
                        path: path.clone(),
                        not_hdl32e: None,
                    }),
                ),
                // Another described sensor's file (an HDL-64E's 64 lasers) is read for the
                // captures of that sensor; a file no sensor reads is refused now.
                Err(e) if other_sensor_reads(path) => (
                    Calibration::builtin(),
                    Some(CalibrationFile {
                        path: path.clone(),
                        not_hdl32e: Some(e.to_string()),
                    }),
                ),
                Err(e) => return Err(e),
            },
            None => (Calibration::builtin(), None),
        };
        Ok(DecoderOptions {
            calibration,
            calibration_file,
            interpolate_azimuth: !self.no_interpolate,
            dual: self.dual,
            cut_angle_deg: self.cut_angle,
            keep_partial: self.keep_partial,
        })
    }
}

/// Whether a described sensor other than the HDL-32E reads the calibration file `path`.
fn other_sensor_reads(path: &std::path::Path) -> bool {
    lidar_noise::sensor::MODELS
        .iter()
        .filter(|m| m.name != lidar_noise::sensor::HDL32E.name)
        .any(|m| lidar_noise::sensor::calibration::ModelCalibration::from_file(path, m).is_ok())
}

/// Point-cloud output settings shared by `run` and `convert`.
#[derive(Clone, Debug, clap::Args)]
pub struct FrameOutputArgs {
    /// Point-cloud file format of each frame [default: ply; `run` writes a point-cloud
    /// scan back in its own format unless this is given].
    #[arg(long, value_enum)]
    pub format: Option<FrameFormat>,
    /// Write ASCII PLY instead of binary little-endian (PLY only).
    #[arg(long)]
    pub ascii: bool,
    /// PLY property names: plain, or cloudcompare (`scalar_<name>`, which CloudCompare
    /// loads as scalar fields).
    #[arg(long, value_enum, value_name = "STYLE", default_value_t = PlyStyle::Plain)]
    pub ply_style: PlyStyle,
}

impl FrameOutputArgs {
    /// Checks the combination and returns the writer settings.
    pub fn to_output(&self) -> Result<FrameOutput> {
        let format = self.format.unwrap_or(FrameFormat::Ply);
        if format != FrameFormat::Ply {
            if self.ascii {
                return Err(Error::Invalid(
                    "--ascii applies to --format ply only".to_string(),
                ));
            }
            if self.ply_style != PlyStyle::Plain {
                return Err(Error::Invalid(
                    "--ply-style applies to --format ply only".to_string(),
                ));
            }
        }
        Ok(FrameOutput {
            format,
            encoding: if self.ascii {
                PlyEncoding::Ascii
            } else {
                PlyEncoding::BinaryLittleEndian
            },
            ply_style: self.ply_style,
        })
    }
}
