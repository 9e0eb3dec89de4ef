//! Stages of the world's noise factors (p-diagram 11, 12, ...): what lies between the
//! sensor and its targets.

pub mod crosstalk;
pub mod emi;
pub mod lens_damage;
pub mod multipath;
pub mod occlusion;
pub mod rain;
pub mod spoofing;
