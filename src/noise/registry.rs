//! The one registry of stage types: builds stages from the plain `[[noise]]` data of a
//! configuration ([`StageSpec`]), with errors naming key and line, and lists every
//! type with its options for `lidar-noise stages`.

use super::{sensor, world, NoiseStage};
use crate::config::reader::{ReadContext, Section};
use crate::config::StageSpec;
use crate::error::Result;
use std::cell::RefCell;
use std::sync::Arc;

/// One option of a stage type, as `lidar-noise stages` lists it.
#[derive(Clone, Copy, Debug)]
pub struct OptionSpec {
    /// Key in `[[noise]]`.
    pub name: &'static str,
    /// Unit ("-" for none).
    pub unit: &'static str,
    /// Default as written in TOML ("required" when there is none).
    pub default: &'static str,
    /// What it does.
    pub doc: &'static str,
}

/// A stage type that `[[noise]]` entries can name.
pub struct StageKind {
    /// The `type` string.
    pub name: &'static str,
    /// P-diagram factor number(s) and name.
    pub factor: &'static str,
    /// The model in one or two sentences.
    pub model: &'static str,
    /// Where the model and its defaults come from.
    pub source: &'static str,
    /// Every option the stage reads.
    pub options: &'static [OptionSpec],
    /// Reads and validates the stage's options (all keys except `type`).
    pub build: fn(&Section<'_>) -> Result<Arc<dyn NoiseStage>>,
}

/// Every stage type, by `type` name. Adding a stage adds one line here (and its name
/// to `config::STAGE_TYPES`).
pub const REGISTRY: &[StageKind] = &[
    world::occlusion::KIND,
    world::rain::KIND,
    sensor::laser_diode::KIND,
    sensor::mounting::KIND,
    sensor::emitter::KIND,
    sensor::mechanics::KIND,
    sensor::receiver::KIND,
    sensor::motion::KIND,
    sensor::clock::KIND,
    sensor::ambient::KIND,
    world::spoofing::KIND,
    world::crosstalk::KIND,
    world::emi::KIND,
    world::multipath::KIND,
    world::lens_damage::KIND,
    world::fog::KIND,
    world::snow::KIND,
];

/// The option names of a stage type, as declared.
fn option_names(k: &StageKind) -> Vec<&'static str> {
    k.options.iter().map(|o| o.name).collect()
}

/// Builds the stage of one `[[noise]]` entry read through `entry`.
pub fn build_stage(entry: &Section<'_>) -> Result<Arc<dyn NoiseStage>> {
    let Some(kind) = entry.str("type")? else {
        return Err(entry.missing("type"));
    };
    match REGISTRY.iter().find(|k| k.name == kind) {
        Some(k) => (k.build)(entry).map_err(|e| {
            // A misspelt key often fails first as a missing required one (`rate_mmh` for
            // `rate_mm_h`): name the key the stage does not have instead.
            let mut options = option_names(k);
            options.insert(0, "type");
            let unknown = entry.unknown_keys(|key| options.contains(&key));
            match unknown.first() {
                Some(key) => entry.unknown_key_error(key, &options),
                None => e,
            }
        }),
        None => {
            let names: Vec<&str> = REGISTRY.iter().map(|k| k.name).collect();
            Err(entry.error(
                "type",
                format!(
                    "unknown noise stage \"{kind}\" (known: {})",
                    names.join(", ")
                ),
            ))
        }
    }
}

/// Builds the stage of a plain entry, checking for unknown keys; returns the stage and
/// the warnings its options raised (prefixed with key and origin).
pub fn build_spec(spec: &StageSpec) -> Result<(Arc<dyn NoiseStage>, Vec<String>)> {
    let ctx = ReadContext {
        locator: (*spec.locator).clone(),
        warnings: RefCell::new(Vec::new()),
    };
    let section = Section::new(&spec.options, spec.path.clone(), &ctx);
    let stage = build_stage(&section)?;
    // Unknown keys are named with the stage's own options (not only those this entry
    // set), as `lidar-noise stages` lists them.
    let kind = section.raw().get("type").and_then(|v| v.as_str());
    match REGISTRY.iter().find(|k| Some(k.name) == kind) {
        Some(k) => {
            let mut options = option_names(k);
            options.insert(0, "type");
            section.finish_listing(&options)?;
        }
        None => section.finish()?,
    }
    drop(section);
    Ok((stage, ctx.warnings.into_inner()))
}

/// Validates every entry of `specs` and fills in its effective settings and
/// description; returns the warnings in chain order.
pub fn resolve(specs: &mut [StageSpec]) -> Result<Vec<String>> {
    let mut warnings = Vec::new();
    for spec in specs.iter_mut() {
        let (stage, w) = build_spec(spec)?;
        spec.settings = stage
            .settings()
            .into_iter()
            .map(|(k, v)| (k.to_string(), v))
            .collect();
        spec.description = stage.describe();
        warnings.extend(w);
    }
    Ok(warnings)
}

/// The stages of validated entries, in chain order.
///
/// # Panics
/// Only if an entry was never validated by [`resolve`] (a programming error: every
/// `Config` from `Config::load`/`from_toml_str` is resolved).
pub fn build_all(specs: &[StageSpec]) -> Vec<Arc<dyn NoiseStage>> {
    specs
        .iter()
        .map(|s| match build_spec(s) {
            Ok((stage, _)) => stage,
            Err(e) => panic!("noise stage built from an unvalidated entry: {e}"),
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn config_knows_the_registry_names() {
        let names: Vec<&str> = REGISTRY.iter().map(|k| k.name).collect();
        assert_eq!(names, crate::config::STAGE_TYPES);
    }
}

#[cfg(test)]
mod listing_tests {
    use super::*;

    /// Every option a stage reports in its settings is declared in its option specs
    /// (and the other way round), so `lidar-noise stages` lists what the code reads.
    #[test]
    fn option_specs_match_the_settings_of_each_stage() {
        let spec_for = |kind: &str| -> &str {
            match kind {
                "occlusion" => "lasers = [1]",
                "rain" => "rate_mm_h = 1.0",
                "fog" => "visibility_m = 100.0",
                "snow" => "rate_mm_h = 1.0",
                _ => "",
            }
        };
        for k in REGISTRY {
            let text = format!("[[noise]]\ntype = \"{}\"\n{}\n", k.name, spec_for(k.name));
            let (config, _) =
                crate::config::Config::from_toml_str(&text, std::path::Path::new("t"), &[], None)
                    .unwrap();
            let declared: Vec<&str> = k.options.iter().map(|o| o.name).collect();
            for (name, _) in &config.noise[0].settings {
                assert!(
                    declared.contains(&name.as_str()),
                    "{}: {name} undeclared",
                    k.name
                );
            }
            if !matches!(
                k.name,
                "occlusion" | "laser_diode" | "lens_damage" | "rain" | "fog" | "crosstalk"
            ) {
                let set: Vec<&str> = config.noise[0]
                    .settings
                    .iter()
                    .map(|(n, _)| n.as_str())
                    .collect();
                assert_eq!(set, declared, "{}", k.name);
            }
        }
    }
}
