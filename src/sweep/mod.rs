//! Parameter sweeps: every combination of varied configuration values and seeds, run over
//! captures and compared frame by frame with the clean baseline.
//!
//! - [`plan`]: cells from `--vary` and `--seeds`, and each cell's configuration;
//! - [`crate::score::metrics`]: the metric functions (the object matching rule is documented there);
//! - [`folder`]: a sweep into an output folder as one call (lock, manifest, outputs);
//! - [`run`]: parallel, resumable execution of the cells;
//! - `cells`: the cell files (one per cell, reused when their settings match), `labels`:
//!   a capture's ground truth, `reference`: a frame's metrics against its baseline;
//! - [`birdseye`]: the bird's-eye figure's panels;
//! - [`progress`]: the counts an observer sees while cells are computed;
//! - [`stream`]: cell files and the tidy JSON written and read a frame at a time;
//! - [`tables`]: tidy CSV/JSON and the aggregate CSV;
//! - [`outputs`]: every final file (tables, plots, bird's-eye figure, `index.html`).
//!
//! Common random numbers: each stage draws from a stream keyed by seed, frame and stage
//! type + occurrence (see [`crate::noise`]), so cells differing only in a rain rate or in
//! the presence of the occlusion reuse the same draws.

pub mod birdseye;
pub(crate) mod cells;
pub mod folder;
pub mod interactions;
pub(crate) mod labels;
pub mod outputs;
pub mod plan;
pub(crate) mod progress;
pub(crate) mod reference;
pub mod run;
pub mod stream;
pub mod tables;
