//! TODO

pub mod synth;
