//! lidar-noise: replays Velodyne captures and point-cloud scans through modelled LiDAR
//! noise, then measures what perception still detects.
//!
//! Data flows one way: source (capture, scan, dataset folder) -> sensor model -> frames of
//! returns -> noise stages -> detection -> ground -> clusters -> scores and writers. The
//! command line (`src/cli.rs`, `src/commands/`, `src/options.rs`) is compiled into the
//! binary only; the layers and the rule each keeps are in `docs/project/design.md`.

#![warn(missing_docs)]

pub mod capture;
pub mod cloud;
pub mod cluster;
pub mod compare;
pub mod config;
pub mod engine;
pub mod error;
pub mod frame;
pub mod ground;
pub mod loader;
pub mod memory;
pub mod noise;
pub(crate) mod numeric;
pub mod observe;
pub mod par;
pub mod pipeline;
pub(crate) mod radix;
pub mod range;
pub mod score;
pub mod sensor;
pub mod shard;
pub mod signals;
pub mod sweep;
pub mod synth;
pub mod writers;

/// Helpers shared by unit tests.
#[cfg(test)]
pub(crate) mod test_util {
    /// Next state of a 64-bit LCG (unit tests need no RNG crate); its high bits are the
    /// random ones.
    pub(crate) fn lcg(state: &mut u64) -> u64 {
        *state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        *state
    }

    /// Next uniform number in [0, 1) of [`lcg`].
    pub(crate) fn lcg_unit(state: &mut u64) -> f64 {
        (lcg(state) >> 11) as f64 / (1u64 << 53) as f64
    }
}
