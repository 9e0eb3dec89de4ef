//! Scores of what perception found: a noisy frame against its clean baseline or a
//! dataset's labels, per object and by distance band.
//!
//! - [`metrics`]: the metric functions on plain arrays (object outcomes, matching, bands);
//! - [`truth`]: a labelled scan's ground and object scores, with the same functions.

pub mod metrics;
pub mod truth;
