//! Stages of the world's noise factors (p-diagram 11, 12, ...): what lies between the
//! sensor and its targets.

pub mod crosstalk;
pub mod emi;
pub mod fog;
pub mod lens_damage;
pub mod mie;
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

/// A uniform number in [0, 1) from the top 53 bits of a word.
#[inline]
pub fn unit(w: u64) -> f64 {
    (w >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
}

/// SplitMix64 finaliser: a second, independent-looking word from one draw, so a return
/// spends one word of its stream whatever it needs.
#[inline]
pub fn splitmix(w: u64) -> u64 {
    let mut z = w.wrapping_add(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}
