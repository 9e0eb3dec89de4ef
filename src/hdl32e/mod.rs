//! Velodyne HDL-32E: packet layout, sensor identification, decoding and frames.

pub mod decode;
pub mod encode;
pub mod frames;
pub mod identify;
pub mod index;
pub mod packet;
