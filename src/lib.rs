//! lidar-noise: replays Velodyne HDL-32E captures through modelled LiDAR noise.
//!
//! Data flows one way: capture -> decoder -> frame -> noise stages -> detection
//! filters -> ground -> clusters -> writers.

#![warn(missing_docs)]

pub mod capture;
pub mod cli;
pub mod cloud;
pub mod cluster;
pub mod commands;
pub mod compare;
pub mod config;
pub mod engine;
pub mod error;
pub mod frame;
pub mod ground;
pub mod loader;
pub mod memory;
pub mod noise;
pub mod options;
pub mod par;
pub mod pipeline;
pub(crate) mod radix;
pub mod sensor;
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
