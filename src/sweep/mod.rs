//! Parameter sweeps: every combination of varied configuration values and seeds, run over
//! captures and compared frame by frame with the clean baseline.
//!
//! - [`plan`]: cells from `--vary` and `--seeds`, and each cell's configuration;
//! - [`metrics`]: pure metric functions (the object matching rule is documented there);
//! - [`run`]: parallel, resumable execution writing one result file per cell;
//! - [`chunks`]: frame ranges of long captures as units of sharded sweeps;
//! - [`stream`]: cell files and the tidy JSON written and read a frame at a time;
//! - [`tables`]: tidy CSV/JSON and the aggregate CSV;
//! - [`outputs`]: every final file (tables, plots, bird's-eye figure, `index.html`).
//!
//! Common random numbers: each stage draws from a stream keyed by seed, frame and stage
//! type + occurrence (see [`crate::noise`]), so cells differing only in a rain rate or in
//! the presence of the occlusion reuse the same draws.

pub mod chunks;
pub mod interactions;
pub mod metrics;
pub mod outputs;
pub mod plan;
pub mod run;
pub mod stream;
pub mod tables;
