//! TODO
pub mod validate;
