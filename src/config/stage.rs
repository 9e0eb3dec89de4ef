//! `[[noise]]` entries as plain data: the stage `type`, its options as written (after
//! `--set`) and where they came from, for the noise registry to build and validate.
//! This module knows no stage; `crate::noise::registry` does.

use super::reader::Locator;
use std::sync::Arc;
use toml::{Table, Value};

/// Every stage `type` the registry builds, in registry order. Plain data so that the
/// `--set`/`--vary` shorthand can recognise stage names without importing `noise`; a
/// test in `noise::registry` checks it equals the registry's names.
pub const STAGE_TYPES: &[&str] = &[
    "occlusion",
    "rain",
    "laser_diode",
    "mounting",
    "emitter",
    "mechanics",
    "receiver",
    "motion",
    "clock",
    "ambient",
    "spoofing",
    "crosstalk",
    "emi",
    "multipath",
    "lens_damage",
    "fog",
    "snow",
];

/// One `[[noise]]` entry, not yet built into a stage.
#[derive(Clone, Debug)]
pub struct StageSpec {
    /// The dotted path of the entry (`noise[1]`), for errors.
    pub path: String,
    /// The whole entry as written, `type` included.
    pub options: Table,
    /// Where each key came from (line or `--set`), shared by the entries of one file.
    pub locator: Arc<Locator>,
    /// The effective options in documented order with defaults filled in; set by the
    /// registry when it validates the entry.
    pub settings: Vec<(String, Value)>,
    /// One line for humans; set by the registry when it validates the entry.
    pub description: String,
}

impl StageSpec {
    /// The `type` of the entry ("" when missing; the registry reports that).
    pub fn kind(&self) -> &str {
        self.options
            .get("type")
            .and_then(Value::as_str)
            .unwrap_or("")
    }

    /// One line for humans: what the stage does with which settings.
    pub fn describe(&self) -> &str {
        &self.description
    }
}
