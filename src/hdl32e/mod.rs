//! TODO

pub mod encode;
