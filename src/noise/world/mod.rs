//! Stages of the world's noise factors (p-diagram 11, 12, ...): what lies between the
//! sensor and its targets.

pub mod crosstalk;
pub mod emi;
pub mod fog;
pub mod lens_damage;
pub mod multipath;
pub mod occlusion;
pub mod particles;
pub mod rain;
pub mod snow;
pub mod spoofing;

use crate::config::reader::Section;
use crate::error::Result;
use toml::Value;

/// A boolean option at `key`, or `default`; other types are an error naming key and line.
pub fn bool_option(opts: &Section<'_>, key: &str, default: bool) -> Result<bool> {
    match opts.value(key) {
        None => Ok(default),
        Some(Value::Boolean(b)) => Ok(*b),
        Some(v) => Err(opts.error(key, format!("expected true or false, found {v}"))),
    }
}
