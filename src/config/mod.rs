//! Experiment configuration: the TOML file, `--set` overrides and validation.
//!
//! Reading goes: text -> `toml` document (plus the position of every key) -> `--set`
//! overrides -> typed [`Config`]. Every error names the dotted key (`noise[1].rate_mm_h`)
//! and where it came from: a line and column of the file, or the `--set` argument.
//! Unknown keys are errors everywhere.
//!
//! Defaults when a key is absent (the reference study's settings): `seed = 42`,
//! `sensor.intensity = "reflectivity"`, `power.model = "lidar-equation"`,
//! `power.reference_reflectance = 0.10`, `power.reference_range_m = 100`,
//! `power.reflectance_floor = 0.005`, no noise stages, `detection.min_power = 0.001`,
//! `detection.min_range_m = 0.9`, `ground.method = "patchwork"` (its `patchwork_*`
//! settings are listed in `crate::ground::patchwork::Params`; the range-image keys
//! `max_angle_delta_deg = 5`, `initial_angle_deg = 30` and the RANSAC keys keep their
//! defaults too), `cluster.cut = "distance"` with `cutoff_m = 0.5`, `cutoff_per_m = 0`,
//! `min_points = 10`, `max_edge_m = 2`. The built-in configuration
//! (`configs/paper.toml`) sets `ground.method = "range-image"`, the reference study's
//! method.

pub mod overrides;
pub mod reader;
pub mod stage;

use crate::cluster::{ClusterOptions, CutRule, ObjectRule};
use crate::error::{Error, Result};
use crate::ground::{GroundMethod, GroundOptions};
use reader::{Locator, ReadContext, Section};
use serde::ser::SerializeMap;
use serde::{Serialize, Serializer};
pub use stage::{StageSpec, STAGE_TYPES};
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
    /// How detection is decided.
    pub model: DetectionModel,
    /// k: the threshold over the thermal and ambient noise's standard deviation.
    pub threshold_snr: f64,
    /// g: shot-noise variance per unit signal, in threshold units (F / N_T).
    pub shot_noise: f64,
}

/// `[detection] model`: how the receiver decides what it reports (`noise::detection`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum DetectionModel {
    /// Power at or above `min_power` (the reference study's deterministic threshold).
    Threshold,
    /// A probability of the signal-to-noise ratio (receiver noise model).
    Probabilistic,
}

impl DetectionModel {
    /// The name used in configurations.
    pub fn name(self) -> &'static str {
        match self {
            DetectionModel::Threshold => "threshold",
            DetectionModel::Probabilistic => "probabilistic",
        }
    }
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
            model: DetectionModel::Probabilistic,
            threshold_snr: 6.0,
            shot_noise: 0.05,
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
    /// `[[noise]]` stages in file order, as validated plain data (see [`StageSpec`]).
    pub noise: Vec<StageSpec>,
    /// `[detection]`.
    pub detection: DetectionConfig,
    /// `[ground]`.
    pub ground: GroundOptions,
    /// `[cluster]`.
    pub cluster: ClusterOptions,
    /// `[cluster]` `object_*` keys: which clusters are objects.
    pub objects: ObjectRule,
    /// Where the configuration came from (file path or the built-in label).
    pub source: PathBuf,
    /// The command-line overrides applied on top of the file, as given
    /// (`--set KEY=VALUE`, then `--seed N`), for provenance.
    pub overrides: Vec<String>,
}

impl Config {
    /// Loads `path` (or the built-in `configs/paper.toml`), applies `--set key=value`
    /// overrides in order and `--seed`, validates everything but the `[[noise]]` options
    /// (see `crate::loader` for [`Config::load`], which also builds the stages).
    pub fn parse_file(
        path: Option<&Path>,
        sets: &[String],
        seed: Option<u64>,
    ) -> Result<(Config, Vec<String>)> {
        let (text, file) = match path {
            Some(p) => (crate::error::read_text_bounded(p)?, p.to_path_buf()),
            None => (DEFAULT_TOML.to_string(), PathBuf::from(DEFAULT_LABEL)),
        };
        Self::parse_str(&text, &file, sets, seed)
    }

    /// Same as [`Config::parse_file`] on text already read; `file` names it in errors.
    pub fn parse_str(
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
        let locator = Arc::new(ctx.locator);
        for spec in &mut config.noise {
            spec.locator = locator.clone();
        }
        if let Some(s) = seed {
            config.seed = s;
        }
        config.overrides = sets
            .iter()
            .map(|s| format!("--set {s}"))
            .chain(seed.map(|s| format!("--seed {s}")))
            .collect();
        let warnings = ctx.warnings.into_inner();
        Ok((config, warnings))
    }

    /// The effective settings after overrides as TOML, with the same key names.
    pub fn effective_toml(&self) -> String {
        // Serialising plain numbers, strings and tables cannot fail.
        toml::to_string(&self.effective()).unwrap_or_default()
    }

    /// Where the configuration came from with its command-line overrides, e.g.
    /// `<built-in configs/paper.toml> --set rain.rate_mm_h=1 --seed 7`. A file is named
    /// by its file name, like captures, so that the same run from another folder writes
    /// the same reports (the effective settings are recorded beside it anyway).
    pub fn provenance(&self) -> String {
        let mut text = match self.source.file_name() {
            Some(name) if self.source != Path::new(DEFAULT_LABEL) => {
                name.to_string_lossy().into_owned()
            }
            _ => self.source.display().to_string(),
        };
        for o in &self.overrides {
            text.push(' ');
            text.push_str(o);
        }
        text
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
                    options: &s.settings,
                })
                .collect(),
            detection: &self.detection,
            ground: &self.ground,
            cluster: ClusterSettings::of(&self.cluster, &self.objects),
        }
    }
}

/// The serialised form of a configuration (key names as in the file).
#[derive(Serialize)]
pub struct EffectiveConfig<'a> {
    seed: u64,
    sensor: &'a SensorConfig,
    power: &'a PowerConfig,
    noise: Vec<StageSettings<'a>>,
    detection: &'a DetectionConfig,
    ground: &'a GroundOptions,
    cluster: ClusterSettings,
}

/// `[cluster]` as written in the file: the cut rule's parameter sits in `cutoff_m`.
#[derive(Serialize)]
struct ClusterSettings {
    cut: &'static str,
    cutoff_m: f64,
    cutoff_per_m: f64,
    min_points: usize,
    max_edge_m: f64,
    object_min_height_m: f64,
    object_max_height_m: f64,
    object_min_extent_m: f64,
    object_max_extent_m: f64,
}

impl ClusterSettings {
    fn of(o: &ClusterOptions, objects: &ObjectRule) -> Self {
        let (cut, cutoff_m) = match o.cut {
            CutRule::Distance => ("distance", o.cutoff_m),
            CutRule::Inconsistent { threshold } => ("inconsistent", threshold),
            CutRule::MaxClust { k } => ("maxclust", k as f64),
        };
        ClusterSettings {
            cut,
            cutoff_m,
            cutoff_per_m: o.cutoff_per_m,
            min_points: o.min_points,
            max_edge_m: o.max_edge_m,
            object_min_height_m: objects.min_height_m,
            object_max_height_m: objects.max_height_m,
            object_min_extent_m: objects.min_extent_m,
            object_max_extent_m: objects.max_extent_m,
        }
    }
}

/// Reads `[ground]`; every key is optional.
fn read_ground(root: &Section<'_>) -> Result<GroundOptions> {
    let mut g = GroundOptions::default();
    let Some(t) = root.table("ground")? else {
        return Ok(g);
    };
    if let Some(m) = t.choice("method", &["patchwork", "range-image", "ransac", "none"])? {
        g.method = match m {
            "range-image" => GroundMethod::RangeImage,
            "ransac" => GroundMethod::Ransac,
            "none" => GroundMethod::None,
            _ => GroundMethod::Patchwork,
        };
    }
    let angle = |key: &str, into: &mut f64| -> Result<()> {
        if let Some(v) = t.f64(key)? {
            if !(0.0..=90.0).contains(&v) {
                return Err(t.error(key, format!("{v} is not an angle in [0, 90] degrees")));
            }
            *into = v;
        }
        Ok(())
    };
    angle("max_angle_delta_deg", &mut g.max_angle_delta_deg)?;
    angle("initial_angle_deg", &mut g.initial_angle_deg)?;
    angle("ransac_max_tilt_deg", &mut g.ransac_max_tilt_deg)?;
    if let Some(v) = t.f64("ransac_threshold_m")? {
        if !(v > 0.0 && v.is_finite()) {
            return Err(t.error(
                "ransac_threshold_m",
                format!("{v} must be a positive distance"),
            ));
        }
        g.ransac_threshold_m = v;
    }
    if let Some(v) = t.i64("ransac_iterations")? {
        if !(1..=1_000_000).contains(&v) {
            return Err(t.error("ransac_iterations", format!("{v} is outside 1..=1000000")));
        }
        g.ransac_iterations = v as u32;
    }
    let keys: Vec<&str> = g.patchwork_f64().iter().map(|(k, _)| *k).collect();
    for key in keys {
        if let Some(v) = t.f64(key)? {
            GroundOptions::check_patchwork(key, v).map_err(|m| t.error(key, m))?;
            let slot = match key {
                "patchwork_sensor_height_m" => &mut g.patchwork_sensor_height_m,
                "patchwork_min_range_m" => &mut g.patchwork_min_range_m,
                "patchwork_max_range_m" => &mut g.patchwork_max_range_m,
                "patchwork_seed_m" => &mut g.patchwork_seed_m,
                "patchwork_distance_m" => &mut g.patchwork_distance_m,
                "patchwork_uprightness_deg" => &mut g.patchwork_uprightness_deg,
                "patchwork_elevation_m" => &mut g.patchwork_elevation_m,
                "patchwork_flatness_m2" => &mut g.patchwork_flatness_m2,
                "patchwork_max_slope_deg" => &mut g.patchwork_max_slope_deg,
                "patchwork_rnr_depth_m" => &mut g.patchwork_rnr_depth_m,
                "patchwork_vpf_seed_m" => &mut g.patchwork_vpf_seed_m,
                "patchwork_vpf_distance_m" => &mut g.patchwork_vpf_distance_m,
                "patchwork_height_sigmas" => &mut g.patchwork_height_sigmas,
                "patchwork_height_min_m" => &mut g.patchwork_height_min_m,
                "patchwork_below_m" => &mut g.patchwork_below_m,
                "patchwork_foot_rise_m" => &mut g.patchwork_foot_rise_m,
                _ => &mut g.patchwork_continuity_m,
            };
            *slot = v;
        }
    }
    if let Some(v) = t.i64("patchwork_rnr_max_intensity")? {
        if !(0..=255).contains(&v) {
            return Err(t.error(
                "patchwork_rnr_max_intensity",
                format!("{v} is outside 0..=255 (an intensity byte)"),
            ));
        }
        g.patchwork_rnr_max_intensity = v as u8;
    }
    if g.patchwork_max_range_m <= g.patchwork_min_range_m {
        let key = if t.has("patchwork_max_range_m") {
            "patchwork_max_range_m"
        } else {
            "patchwork_min_range_m"
        };
        return Err(t.error(
            key,
            format!(
                "patchwork_max_range_m ({}) must exceed patchwork_min_range_m ({})",
                g.patchwork_max_range_m, g.patchwork_min_range_m
            ),
        ));
    }
    t.finish()?;
    Ok(g)
}

/// Reads `[cluster]`; every key is optional.
fn read_cluster(root: &Section<'_>) -> Result<(ClusterOptions, ObjectRule)> {
    let mut c = ClusterOptions {
        min_points: 10,
        ..ClusterOptions::default()
    };
    let mut o = ObjectRule::default();
    let Some(t) = root.table("cluster")? else {
        return Ok((c, o));
    };
    let cut = t
        .choice("cut", &["distance", "inconsistent", "maxclust"])?
        .unwrap_or("distance");
    let value = t.f64("cutoff_m")?;
    c.cut = match cut {
        "inconsistent" => {
            let v = value.unwrap_or(1.0);
            if !(v >= 0.0 && v.is_finite()) {
                return Err(t.error(
                    "cutoff_m",
                    format!("{v}: the inconsistency threshold must be 0 or more"),
                ));
            }
            CutRule::Inconsistent { threshold: v }
        }
        "maxclust" => {
            let Some(v) = value else {
                return Err(t.missing("cutoff_m"));
            };
            if !(v >= 1.0 && v.fract() == 0.0 && v <= 1e9) {
                return Err(t.error("cutoff_m", format!("{v}: with cut = \"maxclust\" give the largest number of clusters, a whole number of at least 1")));
            }
            CutRule::MaxClust { k: v as usize }
        }
        _ => {
            if let Some(v) = value {
                if !(v > 0.0 && v.is_finite()) {
                    return Err(t.error(
                        "cutoff_m",
                        format!("{v} must be a positive distance in metres"),
                    ));
                }
                c.cutoff_m = v;
            }
            CutRule::Distance
        }
    };
    if let Some(v) = t.f64("cutoff_per_m")? {
        if !(v >= 0.0 && v.is_finite()) {
            return Err(t.error("cutoff_per_m", format!("{v} must be 0 or more")));
        }
        c.cutoff_per_m = v;
    }
    if let Some(v) = t.i64("min_points")? {
        if v < 1 {
            return Err(t.error("min_points", format!("{v} must be at least 1")));
        }
        c.min_points = v as usize;
    }
    if let Some(v) = t.f64("max_edge_m")? {
        if v.is_nan() || v <= 0.0 {
            return Err(t.error(
                "max_edge_m",
                format!("{v} must be a positive distance (inf allowed)"),
            ));
        }
        c.max_edge_m = v;
    }
    let mut given: Vec<&str> = Vec::new();
    for (key, into) in [
        ("object_min_height_m", &mut o.min_height_m),
        ("object_max_height_m", &mut o.max_height_m),
        ("object_min_extent_m", &mut o.min_extent_m),
        ("object_max_extent_m", &mut o.max_extent_m),
    ] {
        if let Some(v) = t.f64(key)? {
            if v.is_nan() || v < 0.0 {
                return Err(t.error(key, format!("{v} must be 0 or more metres (inf allowed)")));
            }
            *into = v;
            given.push(key);
        }
    }
    for (what, lo, hi, lo_key, hi_key) in [
        (
            "height",
            o.min_height_m,
            o.max_height_m,
            "object_min_height_m",
            "object_max_height_m",
        ),
        (
            "extent",
            o.min_extent_m,
            o.max_extent_m,
            "object_min_extent_m",
            "object_max_extent_m",
        ),
    ] {
        if lo > hi {
            // Name the key the file sets (the other may be a default).
            let key = if given.contains(&hi_key) {
                hi_key
            } else {
                lo_key
            };
            return Err(t.error(
                key,
                format!("the object {what} range is empty: {lo_key} = {lo} > {hi_key} = {hi}"),
            ));
        }
    }
    t.finish()?;
    Ok((c, o))
}

/// A stage's `type` followed by its options in their documented order.
pub struct StageSettings<'a> {
    kind: &'a str,
    options: &'a [(String, toml::Value)],
}

impl Serialize for StageSettings<'_> {
    fn serialize<S: Serializer>(&self, serializer: S) -> std::result::Result<S::Ok, S::Error> {
        let mut map = serializer.serialize_map(Some(self.options.len() + 1))?;
        map.serialize_entry("type", self.kind)?;
        for (k, v) in self.options {
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

    // Stage options are validated by the noise registry (crate::loader); here they are
    // only recorded as data.
    let mut stages: Vec<StageSpec> = Vec::new();
    let entries = root.table_array("noise")?;
    // PLY and LAS store the deciding stage's index in one byte, 255 meaning none.
    if entries.len() > 254 {
        return Err(root.error(
            "noise",
            format!(
                "{} [[noise]] stages; at most 254 are supported",
                entries.len()
            ),
        ));
    }
    for entry in entries {
        stages.push(StageSpec {
            path: entry.path().to_string(),
            options: entry.raw().clone(),
            locator: Arc::default(),
            settings: Vec::new(),
            description: String::new(),
        });
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
        if let Some(m) = d.choice("model", &["threshold", "probabilistic"])? {
            detection.model = if m == "threshold" {
                DetectionModel::Threshold
            } else {
                DetectionModel::Probabilistic
            };
        }
        if let Some(v) = d.f64("threshold_snr")? {
            if !(1.0..=100.0).contains(&v) {
                return Err(d.error("threshold_snr", format!("{v} is outside [1, 100]")));
            }
            detection.threshold_snr = v;
        }
        if let Some(v) = d.f64("shot_noise")? {
            if !(0.0..=10.0).contains(&v) {
                return Err(d.error("shot_noise", format!("{v} is outside [0, 10]")));
            }
            detection.shot_noise = v;
        }
        d.finish()?;
    }

    let ground = read_ground(root)?;
    let (cluster, objects) = read_cluster(root)?;
    root.finish()?;

    Ok(Config {
        seed,
        sensor,
        power,
        noise: stages,
        detection,
        ground,
        cluster,
        objects,
        source: file.to_path_buf(),
        overrides: Vec::new(),
    })
}
