//! Validation of command-line values into the plain types the library takes.

use crate::error::{Error, Result};
use crate::sensor::calibration::Calibration;
use crate::sensor::decode::DualSelect;
use crate::sensor::frames::{CalibrationFile, DecoderOptions};
use crate::writers::ply::{PlyEncoding, PlyStyle};
use crate::writers::{FrameFormat, FrameOutput};
use std::ops::RangeInclusive;
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
    crate::sensor::MODELS
        .iter()
        .filter(|m| m.name != crate::sensor::HDL32E.name)
        .any(|m| crate::sensor::calibration::ModelCalibration::from_file(path, m).is_ok())
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

/// Shard `k` of `n` (0-based, like Slurm's array task ids): the items whose index is `k`
/// modulo `n` (a round-robin deal, so shards differ by at most one item).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Shard {
    /// This shard, 0..n.
    pub k: u32,
    /// Number of shards.
    pub n: u32,
}

impl Shard {
    /// Parses `K/N` with 0 <= K < N.
    pub fn parse(text: &str) -> std::result::Result<Shard, String> {
        let bad = || {
            format!(
                "{text}: expected K/N with 0 <= K < N, e.g. 0/4 (K counts from 0, like \
                 $SLURM_ARRAY_TASK_ID with --array=0-3)"
            )
        };
        let (k, n) = text.split_once('/').ok_or_else(bad)?;
        let k: u32 = k.trim().parse().map_err(|_| bad())?;
        let n: u32 = n.trim().parse().map_err(|_| bad())?;
        if n == 0 || k >= n {
            return Err(bad());
        }
        Ok(Shard { k, n })
    }

    /// True when item `index` (in the batch's canonical order) falls to this shard.
    pub fn owns(&self, index: usize) -> bool {
        index % self.n as usize == self.k as usize
    }
}

impl std::fmt::Display for Shard {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}/{}", self.k, self.n)
    }
}

/// Parses an inclusive index range: `N`, `A..B`, `A..` or `..B`.
pub fn parse_range(flag: &str, text: &str) -> Result<RangeInclusive<u32>> {
    let bad = || {
        Error::Invalid(format!(
            "{flag} {text}: expected N, A..B, A.. or ..B with whole numbers (both ends included)"
        ))
    };
    let num = |s: &str| s.trim().parse::<u32>().map_err(|_| bad());
    let range = match text.split_once("..") {
        None => {
            let n = num(text)?;
            n..=n
        }
        Some((a, b)) => {
            let lo = if a.trim().is_empty() { 0 } else { num(a)? };
            let hi = if b.trim().is_empty() {
                u32::MAX
            } else {
                num(b.trim_start_matches('='))?
            };
            lo..=hi
        }
    };
    if range.start() > range.end() {
        return Err(Error::Invalid(format!(
            "{flag} {text}: the range is reversed ({} is after {}); write {}..{}",
            range.start(),
            range.end(),
            range.end(),
            range.start()
        )));
    }
    Ok(range)
}

/// Worker threads set by `--threads`, if given (see [`worker_threads`]).
static THREADS: std::sync::OnceLock<usize> = std::sync::OnceLock::new();

/// Records `--threads N` for [`worker_threads`]; the first call wins.
pub fn set_worker_threads(n: usize) {
    let _ = THREADS.set(n.max(1));
}

/// Worker threads to use: `--threads`, else `RAYON_NUM_THREADS` (when a positive number),
/// else one per core, as rayon decides. Unlike `rayon::current_num_threads` it does not
/// start rayon's global pool, whose idle threads would spin beside the streaming workers
/// of `run` and `convert` (a pool of their own, of this size).
pub fn worker_threads() -> usize {
    if let Some(&n) = THREADS.get() {
        return n;
    }
    std::env::var("RAYON_NUM_THREADS")
        .ok()
        .and_then(|v| v.trim().parse::<usize>().ok())
        .filter(|&n| n > 0)
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()))
}

/// How a frame range reads in messages: `--frames A..B`, `--frames A..` when open-ended,
/// or "the whole capture" when no `--frames` narrowed it.
pub fn frames_phrase(frames: &std::ops::RangeInclusive<u32>) -> String {
    match (*frames.start(), *frames.end()) {
        (0, u32::MAX) => "the whole capture".to_string(),
        (a, u32::MAX) => format!("--frames {a}.."),
        (a, b) => format!("--frames {a}..{b}"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ranges_are_inclusive_and_checked() {
        assert_eq!(parse_range("--frames", "3").unwrap(), 3..=3);
        assert_eq!(parse_range("--frames", "1..10").unwrap(), 1..=10);
        assert_eq!(parse_range("--frames", "1..=10").unwrap(), 1..=10);
        assert_eq!(parse_range("--frames", "5..").unwrap(), 5..=u32::MAX);
        assert_eq!(parse_range("--frames", "..4").unwrap(), 0..=4);
        assert!(parse_range("--frames", "4..2").is_err());
        assert!(parse_range("--frames", "x").is_err());
        assert!(parse_range("--frames", "-1..2").is_err());
    }

    #[test]
    fn shards_parse_and_deal_round_robin() {
        assert_eq!(Shard::parse("2/5").unwrap(), Shard { k: 2, n: 5 });
        for bad in ["5/5", "1/0", "x/2", "1", "-1/3", "1/2/3"] {
            assert!(Shard::parse(bad).is_err(), "{bad}");
        }
        for n in 1..=7u32 {
            for index in 0..50 {
                let owners: Vec<u32> = (0..n).filter(|&k| Shard { k, n }.owns(index)).collect();
                assert_eq!(owners.len(), 1, "item {index} of {n} shards: {owners:?}");
            }
        }
    }
}
