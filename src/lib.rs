//! lidar-noise: replays Velodyne HDL-32E captures through modelled LiDAR noise.
//!
//! Data flows one way: capture -> decoder -> frame -> noise stages -> detection
//! filters -> ground -> clusters -> writers.

#![warn(missing_docs)]

pub mod calibration;
pub mod capture;
pub mod cli;
pub mod cluster;
pub mod commands;
pub mod compare;
pub mod config;
pub mod error;
pub mod frame;
pub mod ground;
pub mod hdl32e;
pub mod loader;
pub mod noise;
pub mod options;
pub mod pipeline;
pub mod signals;
pub mod sweep;
pub mod synth;
pub mod writers;
