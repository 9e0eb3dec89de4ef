//! Scene synthesizer: ray-casts an HDL-32E (or, with `--sensor`, any sensor of
//! `src/sensor/`: [`synthesize_model`]) in a simple scene and writes a capture with
//! ground-truth labels (`lidar-noise synth`).
//!
//! Timing and geometry follow `docs/hdl32e.md`: block n (counting data packets only)
//! fires at `t0 + n * 46.08 µs`; the head turns at the scene's rate and the capture
//! starts with a block at azimuth exactly 0.00°. Block azimuths are quantised to
//! 0.01° as the packet stores them, and laser j's beam azimuth lies j/40 of the way
//! from its block's azimuth to the next block's (interpolated mode, the default; the
//! next block is the true next firing, also across packets), so a decoder that
//! interpolates reproduces the cast geometry. Rotation k is made of the blocks whose
//! unwrapped quantised azimuth lies in [k*360°, (k+1)*360°); the capture ends with
//! the packet holding the last block of the last rotation, and any blocks of that
//! packet past it carry no returns. One position packet follows every 9th data
//! packet (about every 5 ms).

pub mod labels;
pub mod raycast;
pub mod scene;

pub use scene::Scene;

use crate::sensor::calibration::Calibration;
use crate::sensor::encode::{
    encode_data_packet_into, encode_position_packet, FiringBlock, PACKET_DURATION_US, US_PER_HOUR,
};
use crate::sensor::encode::{encode_packet, PacketHeader};
use crate::sensor::packet::{
    BLOCKS as BLOCKS_PER_PACKET, DATA_PACKET_BYTES as DATA_PAYLOAD_LEN, DATA_PORT,
    FIRING_US as BLOCK_DURATION_US, LASERS as LASERS_PER_BLOCK,
    POSITION_PACKET_BYTES as POSITION_PAYLOAD_LEN, POSITION_PORT,
};
use crate::sensor::{ReturnMode, SensorModel, TimestampMark};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use raycast::{intensity, Caster, DISTANCE_UNIT_M};
use std::io::{self, Write};

/// Timestamp (µs past the hour) of the first data packet.
pub const FIRST_TIMESTAMP_US: f64 = 1000.0;
/// Capture (pcap) time of the top of the sensor's hour: 2024-01-01T00:00:00Z in µs.
pub const CAPTURE_EPOCH_US: u64 = 1_704_067_200_000_000;
/// A position packet follows every this many data packets.
pub const POSITION_EVERY: u32 = 9;
/// Delay of a position packet after the data packet it follows, µs.
pub const POSITION_DELAY_US: u64 = 100;

/// Synthesis settings that are not part of the scene.
#[derive(Clone, Debug)]
pub struct SynthOptions {
    /// Interpolate each laser's azimuth towards the next block (true, default) or
    /// cast every laser of a block at the block azimuth (false).
    pub interpolate: bool,
    /// Calibration giving the lasers' elevations and azimuth offsets (HDL-32E).
    pub calibration: Calibration,
    /// Sensor to synthesize: the HDL-32E (default: the path above, its bytes as
    /// before) or any other described model ([`synthesize_model`]).
    pub sensor: &'static SensorModel,
}

impl Default for SynthOptions {
    fn default() -> Self {
        SynthOptions {
            interpolate: true,
            calibration: Calibration::builtin(),
            sensor: &crate::sensor::HDL32E,
        }
    }
}

/// One emitted return as cast, in capture order.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CastReturn {
    /// Zero-based rotation index.
    pub frame: u32,
    /// Zero-based capture record index (position packets counted).
    pub packet: u32,
    /// Block within the packet, 0..11.
    pub block: u8,
    /// Laser id, 0..31.
    pub laser: u8,
    /// Raw distance in 2 mm units (never 0).
    pub raw_distance: u16,
    /// Intensity byte.
    pub intensity: u8,
    /// 0 = ground, k = object id.
    pub label: u16,
}

/// The labels-file rows of returns given in capture order (firings numbered per frame).
pub fn label_rows<'a>(returns: impl IntoIterator<Item = &'a CastReturn>) -> Vec<labels::LabelRow> {
    let mut firings = labels::Firings::default();
    returns
        .into_iter()
        .map(|r| labels::LabelRow {
            frame: r.frame,
            firing: firings.firing(r.frame, r.packet, r.block),
            laser: r.laser,
            label: r.label,
        })
        .collect()
}

/// One capture record produced by the synthesizer.
#[derive(Clone, Copy, Debug)]
pub enum Record<'a> {
    /// A data packet.
    Data {
        /// Capture (pcap) time, µs since the Unix epoch.
        capture_time_us: u64,
        /// The 1206-byte payload.
        payload: &'a [u8; DATA_PAYLOAD_LEN],
    },
    /// A position packet.
    Position {
        /// Capture (pcap) time, µs since the Unix epoch.
        capture_time_us: u64,
        /// The 512-byte payload.
        payload: &'a [u8; POSITION_PAYLOAD_LEN],
    },
}

impl Record<'_> {
    /// Capture time, µs since the Unix epoch.
    pub fn capture_time_us(&self) -> u64 {
        match self {
            Record::Data {
                capture_time_us, ..
            }
            | Record::Position {
                capture_time_us, ..
            } => *capture_time_us,
        }
    }

    /// UDP destination (and source) port of the record.
    pub fn port(&self) -> u16 {
        match self {
            Record::Data { .. } => DATA_PORT,
            Record::Position { .. } => POSITION_PORT,
        }
    }

    /// UDP payload.
    pub fn payload(&self) -> &[u8] {
        match self {
            Record::Data { payload, .. } => &payload[..],
            Record::Position { payload, .. } => &payload[..],
        }
    }
}

/// Counts of what a synthesis produced.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Summary {
    /// Capture records (data + position).
    pub records: u32,
    /// Data packets.
    pub data_packets: u32,
    /// Position packets.
    pub position_packets: u32,
    /// Emitted returns (non-zero distance).
    pub returns: u64,
    /// Full rotations.
    pub frames: u32,
}

/// Unwrapped block azimuths in hundredths of a degree, as the packets store them.
struct Spin {
    per_block: f64,
}

impl Spin {
    fn new(rotation_hz: f64) -> Spin {
        Spin {
            per_block: 36_000.0 * rotation_hz * BLOCK_DURATION_US * 1e-6,
        }
    }

    fn azimuth(&self, n: u64) -> u64 {
        (n as f64 * self.per_block).round() as u64
    }

    /// Index of the first block of rotation `frames` (one past the last cast block).
    fn end_block(&self, frames: u32) -> u64 {
        let target = u64::from(frames) * 36_000;
        let mut n = (target as f64 / self.per_block).floor() as u64;
        n = n.saturating_sub(2);
        while self.azimuth(n) < target {
            n += 1;
        }
        n
    }
}

/// Runs the synthesis, handing every record and its cast returns (empty for position
/// packets) to `sink` in capture order. Same scene and options give the same output.
pub fn synthesize<F>(scene: &Scene, options: &SynthOptions, mut sink: F) -> io::Result<Summary>
where
    F: FnMut(Record<'_>, &[CastReturn]) -> io::Result<()>,
{
    if options.sensor.name != crate::sensor::HDL32E.name {
        return synthesize_model(scene, options.sensor, options.interpolate, sink);
    }
    let caster = Caster::new(scene, &options.calibration);
    let spin = Spin::new(scene.sensor.rotation_hz);
    let end_block = spin.end_block(scene.frames);
    let data_packets = end_block.div_ceil(BLOCKS_PER_PACKET as u64);
    let noise = (scene.range_noise_m > 0.0)
        .then(|| Normal::new(0.0, scene.range_noise_m))
        .transpose()
        .map_err(|e| io::Error::new(io::ErrorKind::InvalidInput, e.to_string()))?;
    let mut rng_frame = u32::MAX;
    let mut rng = ChaCha8Rng::seed_from_u64(scene.seed);

    let mut summary = Summary {
        frames: scene.frames,
        ..Summary::default()
    };
    let mut blocks = [FiringBlock::default(); BLOCKS_PER_PACKET];
    let mut payload = [0u8; DATA_PAYLOAD_LEN];
    let mut returns: Vec<CastReturn> = Vec::with_capacity(BLOCKS_PER_PACKET * LASERS_PER_BLOCK);
    let mut record: u32 = 0;
    for p in 0..data_packets {
        returns.clear();
        let ts = (FIRST_TIMESTAMP_US + p as f64 * PACKET_DURATION_US).round() as u64;
        for (b, block) in blocks.iter_mut().enumerate() {
            let n = p * BLOCKS_PER_PACKET as u64 + b as u64;
            let q = spin.azimuth(n);
            block.azimuth = (q % 36_000) as u16;
            block.distances = [0; LASERS_PER_BLOCK];
            block.intensities = [0; LASERS_PER_BLOCK];
            if n >= end_block {
                continue;
            }
            let frame = (q / 36_000) as u32;
            if noise.is_some() && frame != rng_frame {
                // One stream per (seed, frame): frames are independent of each other.
                rng = ChaCha8Rng::seed_from_u64(scene.seed);
                rng.set_stream(u64::from(frame));
                rng_frame = frame;
            }
            let step = (spin.azimuth(n + 1) - q) as f64;
            for j in 0..LASERS_PER_BLOCK {
                let az = if options.interpolate {
                    (q as f64 + step * j as f64 / 40.0) / 100.0
                } else {
                    q as f64 / 100.0
                };
                let Some(hit) = caster.cast(az, j) else {
                    continue;
                };
                let mut range = hit.range;
                if let Some(normal) = &noise {
                    range += normal.sample(&mut rng);
                }
                let raw = (range / DISTANCE_UNIT_M).round().clamp(0.0, 65_535.0) as u16;
                if raw == 0 {
                    continue;
                }
                let inten = intensity(hit.reflectance, hit.retro, hit.cos_incidence);
                block.distances[j] = raw;
                block.intensities[j] = inten;
                returns.push(CastReturn {
                    frame,
                    packet: record,
                    block: b as u8,
                    laser: j as u8,
                    raw_distance: raw,
                    intensity: inten,
                    label: hit.label,
                });
            }
        }
        encode_data_packet_into(&blocks, (ts % US_PER_HOUR) as u32, 0x37, &mut payload);
        sink(
            Record::Data {
                capture_time_us: CAPTURE_EPOCH_US + ts,
                payload: &payload,
            },
            &returns,
        )?;
        record += 1;
        summary.data_packets += 1;
        summary.returns += returns.len() as u64;
        if (p + 1) % u64::from(POSITION_EVERY) == 0 {
            let pts = ts + POSITION_DELAY_US;
            let position = encode_position_packet((pts % US_PER_HOUR) as u32);
            sink(
                Record::Position {
                    capture_time_us: CAPTURE_EPOCH_US + pts,
                    payload: &position,
                },
                &[],
            )?;
            record += 1;
            summary.position_packets += 1;
        }
    }
    summary.records = record;
    Ok(summary)
}

/// Synthesizes a capture of any described sensor other than the HDL-32E (single
/// return, strongest): as [`synthesize`], with the model's packet layout, timing and
/// beam table. Firing `n` (one block per bank; a VLP-16 block holds two sequences)
/// starts at `n * block_us` after the first and carries the block azimuth
/// `round(n * step)` (hundredths of a degree, `step` = 36000 * rate * block_us); laser
/// `k` of sequence `s` fires `s * sequence_us + laser_offset_us(k)` into its firing and
/// is cast at that fraction of the way to the next firing's azimuth (interpolated mode),
/// as `sensor::decode` reads it back. Each packet's timestamp marks its first firing
/// (plus the model's `timestamp_after_first_us`; for a last-firing model the packet's
/// last firing). Rays start at the sensor origin: per-laser origin offsets (the VLP-16's
/// vertical corrections, up to 11.2 mm, which the decoder adds) are not modelled. No
/// position packets; HDL-64E status bytes are 'H' 0. `CastReturn::block` is the
/// return's `Return::block` (the firing sequence within the packet), so labels key on
/// (frame, firing sequence, laser id). A scene turning faster or slower than the model
/// can is refused (the HDL-64E turns at 5 to 15 Hz).
pub fn synthesize_model<F>(
    scene: &Scene,
    model: &'static SensorModel,
    interpolate: bool,
    mut sink: F,
) -> io::Result<Summary>
where
    F: FnMut(Record<'_>, &[CastReturn]) -> io::Result<()>,
{
    let mode = ReturnMode::Strongest;
    let hz = scene.sensor.rotation_hz;
    if !(model.rotation_hz.0..=model.rotation_hz.1).contains(&hz) {
        return Err(io::Error::new(
            io::ErrorKind::InvalidInput,
            format!(
                "the scene turns the sensor at {hz} Hz: the {} turns at {} to {} Hz",
                model.name, model.rotation_hz.0, model.rotation_hz.1
            ),
        ));
    }
    let caster = Caster::with_angles(scene, model.elevation_deg, model.azimuth_offset_deg);
    let block_us = model.block_us();
    let spin = Spin {
        per_block: 36_000.0 * hz * block_us * 1e-6,
    };
    let end_firing = spin.end_block(scene.frames);
    let firings = model.layout.blocks / model.blocks_per_firing(mode);
    let data_packets = end_firing.div_ceil(firings as u64);
    let noise = (scene.range_noise_m > 0.0)
        .then(|| Normal::new(0.0, scene.range_noise_m))
        .transpose()
        .map_err(|e| io::Error::new(io::ErrorKind::InvalidInput, e.to_string()))?;
    let mut rng_frame = u32::MAX;
    let mut rng = ChaCha8Rng::seed_from_u64(scene.seed);
    let period = model.packet_period_us(mode);
    let stamp_after_first = match model.timestamp_mark {
        TimestampMark::FirstFiring => model.timestamp_after_first_us,
        TimestampMark::LastFiring => -model.firing_offset_us(mode, 0, 0),
    };
    let mut summary = Summary {
        frames: scene.frames,
        ..Summary::default()
    };
    let mut returns: Vec<CastReturn> = Vec::new();
    let mut slots: Vec<(usize, usize, u16, u8)> = Vec::new();
    for p in 0..data_packets {
        returns.clear();
        slots.clear();
        let first_us = FIRST_TIMESTAMP_US + p as f64 * period;
        let ts = (first_us + stamp_after_first).round() as u64;
        let mut azimuths = Vec::with_capacity(firings);
        for f in 0..firings {
            let n = p * firings as u64 + f as u64;
            let q = spin.azimuth(n);
            azimuths.push((q % 36_000) as u16);
            if n >= end_firing {
                continue;
            }
            let frame = (q / 36_000) as u32;
            if noise.is_some() && frame != rng_frame {
                // One stream per (seed, frame), as the HDL-32E path draws.
                rng = ChaCha8Rng::seed_from_u64(scene.seed);
                rng.set_stream(u64::from(frame));
                rng_frame = frame;
            }
            let step = (spin.azimuth(n + 1) - q) as f64;
            for s in 0..model.sequences_per_block {
                let sequence = f * model.sequences_per_block + s;
                for k in 0..model.lasers {
                    let into = s as f64 * model.sequence_us + model.laser_offset_us(k);
                    let az = if interpolate {
                        (q as f64 + step * into / block_us) / 100.0
                    } else {
                        q as f64 / 100.0
                    };
                    let Some(hit) = caster.cast(az, k) else {
                        continue;
                    };
                    let mut range = hit.range;
                    if let Some(normal) = &noise {
                        range += normal.sample(&mut rng);
                    }
                    let raw = (range / model.distance_resolution_m)
                        .round()
                        .clamp(0.0, 65_535.0) as u16;
                    if raw == 0 {
                        continue;
                    }
                    let inten = intensity(hit.reflectance, hit.retro, hit.cos_incidence);
                    slots.push((sequence, k, raw, inten));
                    returns.push(CastReturn {
                        frame,
                        packet: summary.records,
                        block: sequence as u8,
                        laser: k as u8,
                        raw_distance: raw,
                        intensity: inten,
                        label: hit.label,
                    });
                }
            }
        }
        let header = PacketHeader {
            mode,
            firing_azimuths: azimuths,
            timestamp_us: (ts % US_PER_HOUR) as u32,
            status: (b'H', 0),
        };
        let payload = encode_packet(model, &header, slots.iter().copied())
            .map_err(|e| io::Error::new(io::ErrorKind::InvalidData, e))?;
        let payload: &[u8; DATA_PAYLOAD_LEN] = payload
            .as_slice()
            .try_into()
            .map_err(|_| io::Error::new(io::ErrorKind::InvalidData, "packet size"))?;
        sink(
            Record::Data {
                capture_time_us: CAPTURE_EPOCH_US + ts,
                payload,
            },
            &returns,
        )?;
        summary.records += 1;
        summary.data_packets += 1;
        summary.returns += returns.len() as u64;
    }
    Ok(summary)
}

/// The cast returns of every rotation, in capture order (index = frame).
pub fn cast_frames(scene: &Scene, options: &SynthOptions) -> Vec<Vec<CastReturn>> {
    let mut frames: Vec<Vec<CastReturn>> = vec![Vec::new(); scene.frames as usize];
    // The sink never fails, so neither does the synthesis.
    let _ = synthesize(scene, options, |_, returns| {
        for r in returns {
            frames[r.frame as usize].push(*r);
        }
        Ok(())
    });
    frames
}

/// Writes the capture (classic pcap) and the labels file of a scene.
pub fn write_capture<P: Write, L: Write>(
    scene: &Scene,
    options: &SynthOptions,
    pcap: P,
    labels_out: L,
) -> io::Result<(Summary, P, L)> {
    let mut pcap = crate::capture::writer::PcapWriter::new(pcap)?;
    let mut labels = labels::LabelWriter::new(labels_out)?;
    let summary = synthesize(scene, options, |record, returns| {
        pcap.write_udp(
            record.capture_time_us(),
            record.port(),
            record.port(),
            record.payload(),
        )?;
        for r in returns {
            labels.write_return(r.frame, r.packet, r.block, r.laser, r.label)?;
        }
        Ok(())
    })?;
    Ok((summary, pcap.into_inner()?, labels.finish()?))
}

/// The object list (and the scene it came from) as pretty JSON.
pub fn objects_json(scene: &Scene) -> String {
    // Serializing plain structs of numbers and strings cannot fail.
    serde_json::to_string_pretty(scene).unwrap_or_default()
}
