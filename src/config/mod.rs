//! Experiment configuration: the TOML file, `--set` overrides and validation.
//!
//! Reading goes: text -> `toml` document (plus the position of every key) -> `--set`
//! overrides -> typed [`Config`]. Every error names the dotted key (`noise[1].rate_mm_h`)
//! and where it came from: a line and column of the file, or the `--set` argument.
//! Unknown keys are errors everywhere except inside `[ground]` and `[cluster]`, which are
//! kept as opaque tables until their typed readers land.
//!
//! Defaults when a key is absent (the reference study's settings): `seed = 42`,
//! `sensor.intensity = "reflectivity"`, `power.model = "lidar-equation"`,
//! `power.reference_reflectance = 0.10`, `power.reference_range_m = 100`,
//! `power.reflectance_floor = 0.005`, no noise stages, `detection.min_power = 0.001`,
//! `detection.min_range_m = 0.9`.

pub mod overrides;
pub mod reader;

use crate::error::{Error, Result};
use crate::noise::{self, NoiseStage};
use reader::{Locator, ReadContext, Section};
use serde::ser::SerializeMap;
use serde::{Serialize, Serializer};
use std::cell::RefCell;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// The built-in configuration used when no file is given: `configs/paper.toml`.
pub const DEFAULT_TOML: &str = include_str!("../../configs/paper.toml");

/// Label used in errors about the built-in configuration.
pub const DEFAULT_LABEL: &str = "<built-in configs/paper.toml>";

/// How to read the intensity byte of a return.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum IntensityMode {
    /// Firmware 2 calibrated reflectivity: 0..100 % diffuse reflectance, 101..255
    /// retro-reflectors; rho = intensity / 100 clamped to [floor, 1].
    Reflectivity,
    /// Older firmware raw level 0..255; assumed proportional to reflectance,
    /// rho = intensity / 255 clamped to [floor, 1].
    Raw,
}

/// `[sensor]`: how the recording is to be interpreted.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SensorConfig {
    /// Meaning of the intensity byte.
    pub intensity: IntensityMode,
}

/// Which formula gives the ideal power of a return.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum PowerModel {
    /// P = kappa * rho / R^2, kappa from the reference target (the doc's default).
    LidarEquation,
    /// MAVS: P = rho / R^2 against P_min = 0.9 / (pi * z_max^2), z_max =
    /// `reference_range_m`; rescaled so that P_min maps onto `detection.min_power`.
    Mavs,
}

/// `[power]`: ideal power as a fraction of emitted power.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct PowerConfig {
    /// The power formula.
    pub model: PowerModel,
    /// Reflectance of the reference target that returns exactly the threshold.
    pub reference_reflectance: f64,
    /// Range of the reference target in metres (z_max in the MAVS model).
    pub reference_range_m: f64,
    /// Lowest reflectance given to a return (an intensity of 0 is still a detection).
    pub reflectance_floor: f64,
}

/// `[detection]`: what a real sensor could not have detected.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct DetectionConfig {
    /// Detection threshold as a fraction of emitted power.
    pub min_power: f64,
    /// Minimum range in metres (0 disables the filter).
    pub min_range_m: f64,
}

impl Default for SensorConfig {
    fn default() -> Self {
        SensorConfig {
            intensity: IntensityMode::Reflectivity,
        }
    }
}

impl Default for PowerConfig {
    fn default() -> Self {
        PowerConfig {
            model: PowerModel::LidarEquation,
            reference_reflectance: 0.10,
            reference_range_m: 100.0,
            reflectance_floor: 0.005,
        }
    }
}

impl Default for DetectionConfig {
    fn default() -> Self {
        DetectionConfig {
            min_power: 0.001,
            min_range_m: 0.9,
        }
    }
}

/// A whole validated experiment configuration.
#[derive(Clone, Debug)]
pub struct Config {
    /// Seed of every random stream.
    pub seed: u64,
    /// `[sensor]`.
    pub sensor: SensorConfig,
    /// `[power]`.
    pub power: PowerConfig,
    /// `[[noise]]` stages in file order, built and validated.
    pub noise: Vec<Arc<dyn NoiseStage>>,
    /// `[detection]`.
    pub detection: DetectionConfig,
    /// `[ground]`, not validated here yet (opaque).
    pub ground: Option<toml::Table>,
    /// `[cluster]`, not validated here yet (opaque).
    pub cluster: Option<toml::Table>,
    /// Where the configuration came from (file path or the built-in label).
    pub source: PathBuf,
}

impl Config {
    /// Loads `path` (or the built-in `configs/paper.toml`), applies `--set key=value`
    /// overrides in order and `--seed`, validates, and returns the configuration with
    /// its warnings (for the caller to print).
    pub fn load(
        path: Option<&Path>,
        sets: &[String],
        seed: Option<u64>,
    ) -> Result<(Config, Vec<String>)> {
        let (text, file) = match path {
            Some(p) => (
                std::fs::read_to_string(p).map_err(|e| Error::io(p, e))?,
                p.to_path_buf(),
            ),
            None => (DEFAULT_TOML.to_string(), PathBuf::from(DEFAULT_LABEL)),
        };
        Self::from_toml_str(&text, &file, sets, seed)
    }

    /// Same as [`Config::load`] on text already read; `file` names it in errors.
    pub fn from_toml_str(
        text: &str,
        file: &Path,
        sets: &[String],
        seed: Option<u64>,
    ) -> Result<(Config, Vec<String>)> {
        let syntax = |e: toml::de::Error| Error::Config {
            path: file.to_path_buf(),
            message: e.to_string().trim_end().to_string(),
        };
        let spanned = toml::de::DeTable::parse(text).map_err(syntax)?;
        let mut locator = Locator {
            file: file.to_path_buf(),
            spans: overrides::key_positions(text, &spanned),
            sets: Vec::new(),
        };
        let mut root: toml::Table = toml::from_str(text).map_err(syntax)?;
        for arg in sets {
            overrides::apply_set(&mut root, arg, &mut locator).map_err(|m| Error::Config {
                path: file.to_path_buf(),
                message: format!("--set {arg}: {m}"),
            })?;
        }
        if let Some(s) = seed {
            if i64::try_from(s).is_err() {
                return Err(Error::Invalid(format!(
                    "--seed {s}: must be at most {} (TOML integers are 64-bit signed)",
                    i64::MAX
                )));
            }
        }
        let ctx = ReadContext {
            locator,
            warnings: RefCell::new(Vec::new()),
        };
        let mut config = read_config(&Section::new(&root, "", &ctx), file)?;
        if let Some(s) = seed {
            config.seed = s;
        }
        let warnings = ctx.warnings.into_inner();
        Ok((config, warnings))
    }

    /// The effective settings after overrides as TOML, with the same key names.
    pub fn effective_toml(&self) -> String {
        // Serialising plain numbers, strings and tables cannot fail.
        toml::to_string(&self.effective()).unwrap_or_default()
    }

    /// The effective settings after overrides as JSON, with the same key names.
    pub fn to_json(&self) -> serde_json::Value {
        serde_json::to_value(self.effective()).unwrap_or(serde_json::Value::Null)
    }

    /// One line per noise stage, in chain order, for humans.
    pub fn stage_lines(&self) -> Vec<String> {
        self.noise
            .iter()
            .enumerate()
            .map(|(i, s)| format!("noise[{i}] {}: {}", s.kind(), s.describe()))
            .collect()
    }

    /// The effective settings as a serialisable value whose fields keep the file's
    /// order (for embedding in a report next to the tool version).
    pub fn effective(&self) -> EffectiveConfig<'_> {
        EffectiveConfig {
            seed: self.seed,
            sensor: &self.sensor,
            power: &self.power,
            noise: self
                .noise
                .iter()
                .map(|s| StageSettings {
                    kind: s.kind(),
                    options: s.settings(),
                })
                .collect(),
            detection: &self.detection,
            ground: self.ground.as_ref(),
            cluster: self.cluster.as_ref(),
        }
    }
}

/// The serialised form of a configuration (key names as in the file).
#[derive(Serialize)]
pub struct EffectiveConfig<'a> {
    seed: u64,
    sensor: &'a SensorConfig,
    power: &'a PowerConfig,
    noise: Vec<StageSettings>,
    detection: &'a DetectionConfig,
    #[serde(skip_serializing_if = "Option::is_none")]
    ground: Option<&'a toml::Table>,
    #[serde(skip_serializing_if = "Option::is_none")]
    cluster: Option<&'a toml::Table>,
}

/// A stage's `type` followed by its options in their documented order.
pub struct StageSettings {
    kind: &'static str,
    options: Vec<(&'static str, toml::Value)>,
}

impl Serialize for StageSettings {
    fn serialize<S: Serializer>(&self, serializer: S) -> std::result::Result<S::Ok, S::Error> {
        let mut map = serializer.serialize_map(Some(self.options.len() + 1))?;
        map.serialize_entry("type", self.kind)?;
        for (k, v) in &self.options {
            map.serialize_entry(k, v)?;
        }
        map.end()
    }
}

fn read_config(root: &Section<'_>, file: &Path) -> Result<Config> {
    let seed = match root.i64("seed")? {
        None => 42,
        Some(s) => u64::try_from(s).map_err(|_| root.error("seed", "must not be negative"))?,
    };

    let mut sensor = SensorConfig::default();
    if let Some(s) = root.table("sensor")? {
        if let Some(v) = s.choice("intensity", &["reflectivity", "raw"])? {
            sensor.intensity = match v {
                "raw" => IntensityMode::Raw,
                _ => IntensityMode::Reflectivity,
            };
        }
        s.finish()?;
    }

    let mut power = PowerConfig::default();
    if let Some(p) = root.table("power")? {
        if let Some(v) = p.choice("model", &["lidar-equation", "mavs"])? {
            power.model = match v {
                "mavs" => PowerModel::Mavs,
                _ => PowerModel::LidarEquation,
            };
        }
        if let Some(v) = p.f64("reference_reflectance")? {
            if !(v > 0.0 && v <= 1.0) {
                return Err(p.error("reference_reflectance", format!("{v} is outside (0, 1]")));
            }
            power.reference_reflectance = v;
        }
        if let Some(v) = p.f64("reference_range_m")? {
            if v <= 0.0 {
                return Err(p.error("reference_range_m", format!("{v} must be positive")));
            }
            power.reference_range_m = v;
        }
        if let Some(v) = p.f64("reflectance_floor")? {
            if !(0.0..=1.0).contains(&v) {
                return Err(p.error("reflectance_floor", format!("{v} is outside [0, 1]")));
            }
            power.reflectance_floor = v;
        }
        p.finish()?;
    }

    let mut stages: Vec<Arc<dyn NoiseStage>> = Vec::new();
    for entry in root.table_array("noise")? {
        stages.push(noise::build_stage(&entry)?);
        entry.finish()?;
    }

    let mut detection = DetectionConfig::default();
    if let Some(d) = root.table("detection")? {
        if let Some(v) = d.f64("min_power")? {
            if !(v > 0.0 && v <= 1.0) {
                return Err(d.error("min_power", format!("{v} is outside (0, 1]")));
            }
            detection.min_power = v;
        }
        if let Some(v) = d.f64("min_range_m")? {
            if v < 0.0 {
                return Err(d.error("min_range_m", format!("{v} must not be negative")));
            }
            detection.min_range_m = v;
        }
        d.finish()?;
    }

    let ground = root.raw_table("ground")?;
    let cluster = root.raw_table("cluster")?;
    root.finish()?;

    Ok(Config {
        seed,
        sensor,
        power,
        noise: stages,
        detection,
        ground,
        cluster,
        source: file.to_path_buf(),
    })
}
