//! TODO

pub mod writer;
