//! Noisy capture out (`run --pcap-out`): the input capture with every HDL-32E data packet
//! re-encoded from the noisy returns, written as `noisy.pcap` (`noisy.pcapng` for a
//! pcapng input).
//!
//! The output is a byte-for-byte copy of the input in which only return slots (distance
//! and intensity, 3 bytes each) of data packets change, plus the UDP checksum of a data
//! packet that had one (set to 0, "no checksum", which IPv4 allows: the old sum no longer
//! matches the payload, and a receiving kernel drops datagrams with a wrong one). File
//! and record headers, link/IP/UDP headers, timestamps, block flags and azimuths, the
//! packet's timestamp, return mode and product bytes, position packets and every other
//! record stay as they were.
//!
//! Rules:
//! - Every return slot of a data packet is first cleared (distance and intensity 0, "no
//!   return"), then each return of a processed frame is written back: kept returns with
//!   their noisy range `round((range - distance offset) / resolution)` and noisy
//!   intensity, dropped returns as zero distance. Returns in no processed frame (the
//!   partial first and last sweeps without `--keep-partial`, frames outside `--frames`)
//!   stay cleared, so the noisy capture holds exactly the processed frames' returns.
//! - A kept return whose range the wire cannot hold (rounds to 0 or less, or above
//!   65535 units = 131.07 m) is written as no return and counted (`unencodable`): the
//!   sensor reports nothing there either. Clamping would invent a range.
//! - Stages that change what a packet cannot carry (azimuth, elevation, pose, firing
//!   time: `mounting`, `motion`, `mechanics` azimuth terms, `laser_diode` angle offsets,
//!   `clock` drift or time offset) are refused before anything is written, by name (see
//!   [`check_encodable`]). Range and intensity changes (clock bias/jitter, ambient,
//!   rain, receiver, ...) are what the packet holds and are written.

use crate::calibration::Calibration;
use crate::capture::CaptureReader;
use crate::frame::{Return, ReturnKind};
use crate::hdl32e::decode::DualSelect;
use crate::hdl32e::encode::{raw_distance, write_return_slot, BLOCKS_PER_PACKET, BLOCK_LEN};
use crate::hdl32e::packet::{self, ReturnMode};
use crate::noise::{stage_rng, NoiseChain, NoisyFrame};
use crate::writers::Output;
use anyhow::{bail, Result};
use std::io::Write;
use std::path::Path;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Mutex;

/// Marks a record that carries no data packet.
const NOT_DATA: u64 = u64::MAX;

/// The capture being re-encoded: a copy of its bytes, patched frame by frame.
pub struct NoisyCapture {
    bytes: Mutex<Vec<u8>>,
    /// File offset of each record's data-packet payload ([`NOT_DATA`] for other records).
    payloads: Vec<u64>,
    pcapng: bool,
    offsets: [f32; 32],
    resolution: f32,
    unencodable: AtomicU64,
}

/// The patched bytes as a document for [`crate::writers::write_file`].
struct CaptureBytes<'a> {
    bytes: &'a [u8],
    extension: &'static str,
}

impl Output for CaptureBytes<'_> {
    fn extension(&self) -> &'static str {
        self.extension
    }
    fn write_to(&self, out: &mut dyn Write) -> std::io::Result<()> {
        out.write_all(self.bytes)
    }
}

impl NoisyCapture {
    /// Copies the capture `bytes` (named `name` in messages), clears every return slot of
    /// its data packets and zeroes their UDP checksums.
    pub fn new(bytes: Vec<u8>, name: &Path, calibration: &Calibration) -> Result<Self> {
        let mut bytes = bytes;
        let pcapng = bytes.len() >= 4 && bytes[0..4] == [0x0A, 0x0D, 0x0D, 0x0A];
        let mut payloads = Vec::new();
        let mut reader = CaptureReader::from_reader(std::io::Cursor::new(bytes.clone()), name)?;
        let mut data = Vec::new();
        while let Some(d) = reader.next_datagram()? {
            let record = d.record as usize;
            if payloads.len() <= record {
                payloads.resize(record + 1, NOT_DATA);
            }
            if packet::is_data_packet(d.payload) {
                payloads[record] = d.payload_offset;
                data.push(d.payload_offset);
            }
        }
        for at in data {
            let at = at as usize;
            // UDP header: the checksum is its last two bytes, just before the payload.
            if at >= 2 {
                bytes[at - 2..at].fill(0);
            }
            let payload = &mut bytes[at..at + packet::DATA_PACKET_BYTES];
            for b in 0..BLOCKS_PER_PACKET {
                payload[b * BLOCK_LEN + 4..(b + 1) * BLOCK_LEN].fill(0);
            }
        }
        let mut offsets = [0.0f32; 32];
        for (o, l) in offsets.iter_mut().zip(&calibration.lasers) {
            *o = l.distance_offset_m as f32;
        }
        Ok(NoisyCapture {
            bytes: Mutex::new(bytes),
            payloads,
            pcapng,
            offsets,
            resolution: calibration.distance_resolution_m as f32,
            unencodable: AtomicU64::new(0),
        })
    }

    /// File name of the output: `noisy.pcap`, or `noisy.pcapng` for a pcapng input.
    pub fn file_name(&self) -> &'static str {
        if self.pcapng {
            "noisy.pcapng"
        } else {
            "noisy.pcap"
        }
    }

    /// Kept returns whose range the wire cannot hold, written as no return so far.
    pub fn unencodable(&self) -> u64 {
        self.unencodable.load(Ordering::Relaxed)
    }

    /// Writes the returns of one processed frame into their packet slots.
    ///
    /// Frames touch disjoint slots, so the order in which workers call this does not
    /// change the bytes.
    pub fn encode_frame(&self, frame: &NoisyFrame) {
        let intensity = frame.moved.intensity.as_deref();
        let mut lost = 0u64;
        let mut bytes = self.bytes.lock().unwrap_or_else(|e| e.into_inner());
        for (i, r) in frame.clean.iter().enumerate() {
            let Some(&at) = self.payloads.get(r.packet as usize) else {
                continue;
            };
            if at == NOT_DATA {
                continue;
            }
            let laser = usize::from(r.laser) & 31;
            let (raw, value) = if frame.fate[i].is_alive() {
                match raw_distance(frame.range[i], self.offsets[laser], self.resolution) {
                    Some(raw) => (raw, intensity.map_or(r.intensity, |v| v[i])),
                    None => {
                        lost += 1;
                        (0, 0)
                    }
                }
            } else {
                (0, 0)
            };
            let at = at as usize;
            let payload = &mut bytes[at..at + packet::DATA_PACKET_BYTES];
            write_return_slot(payload, usize::from(r.block), laser, raw, value);
        }
        drop(bytes);
        if lost > 0 {
            self.unencodable.fetch_add(lost, Ordering::Relaxed);
        }
    }

    /// The patched capture bytes.
    pub fn into_bytes(self) -> Vec<u8> {
        self.bytes.into_inner().unwrap_or_else(|e| e.into_inner())
    }

    /// Writes the patched capture into `dir` atomically, refusing to overwrite an input.
    pub fn finish(self, dir: &Path, inputs: &[&Path]) -> Result<u64> {
        let name = self.file_name();
        let unencodable = self.unencodable();
        let bytes = self.into_bytes();
        let doc = CaptureBytes {
            bytes: &bytes,
            extension: if name.ends_with("pcapng") {
                "pcapng"
            } else {
                "pcap"
            },
        };
        crate::writers::write_file(&doc, &dir.join(name), inputs)?;
        Ok(unencodable)
    }
}

/// Refuses a capture whose noisy returns could not be written back whole: a dual-return
/// capture decoded with `--dual last|strongest` would lose the other return of each
/// firing (the output stays dual, so both must be decoded).
pub fn check_capture(source: &str, mode: ReturnMode, dual: DualSelect) -> Result<()> {
    if mode == ReturnMode::Dual && dual != DualSelect::Both {
        bail!(
            "{source}: --pcap-out needs --dual both on a dual-return capture: the noisy \
             capture stays dual, and the returns the decoder skips would be lost"
        );
    }
    Ok(())
}

/// Refuses a noise chain with a stage that changes what a data packet cannot carry.
///
/// A packet holds per return only a distance and an intensity; azimuths are per firing
/// and shared by the 32 lasers, elevations are the calibration's, times are the packet's
/// timestamp. Each stage is applied alone to a probe rotation (180 firings of 32 returns
/// at 10 m); a stage that then reports an azimuth, elevation, pose or time change is
/// named in the error. Probing rather than listing types keeps this right when a stage
/// is configured at zero magnitude (no change, accepted) or new stages are added.
pub fn check_encodable(chain: &NoiseChain, seed: u64) -> Result<()> {
    let probe = probe_returns();
    let mut refused = Vec::new();
    for (i, stage) in chain.stages().iter().enumerate() {
        let mut frame = NoisyFrame::new(0, probe.clone(), chain.ideal_power());
        frame.threshold = 0.0;
        let mut rng = stage_rng(seed, 0, i as u32);
        stage.apply(&mut frame, &mut rng);
        let m = &frame.moved;
        let mut what = Vec::new();
        if m.azimuth_deg
            .as_ref()
            .is_some_and(|v| v.iter().any(|&a| a != 0.0))
        {
            what.push("azimuth");
        }
        if m.elevation_deg
            .as_ref()
            .is_some_and(|v| v.iter().any(|&a| a != 0.0))
        {
            what.push("elevation");
        }
        if m.pose.as_ref().is_some_and(|poses| {
            probe.iter().enumerate().any(|(i, r)| {
                poses.of(i).apply([r.x, r.y, r.z], r.time - poses.t_ref) != [r.x, r.y, r.z]
            })
        }) {
            what.push("position (pose)");
        }
        if m.time
            .as_ref()
            .is_some_and(|v| v.iter().zip(&probe).any(|(&t, r)| t != r.time))
        {
            what.push("firing time");
        }
        if !what.is_empty() {
            refused.push(format!(
                "noise[{i}] ({}) changes the {}",
                stage.kind(),
                what.join(", ")
            ));
        }
    }
    if !refused.is_empty() {
        bail!(
            "--pcap-out cannot write this configuration: {}; a data packet holds only a \
             distance and an intensity per return (azimuths per firing, elevations from the \
             calibration, times from the packet timestamp, all kept as recorded). Remove \
             these stages or set them to zero for --pcap-out",
            refused.join("; ")
        );
    }
    Ok(())
}

/// A synthetic rotation in the default calibration's geometry, for [`check_encodable`].
fn probe_returns() -> Vec<Return> {
    let cal = Calibration::builtin();
    let rings = cal.rings();
    let mut out = Vec::with_capacity(180 * 32);
    for f in 0..180u32 {
        let az = f as f32 * 2.0;
        for (j, l) in cal.lasers.iter().enumerate() {
            let range = 10.0f32;
            let (w, a) = (l.elevation_deg.to_radians() as f32, az.to_radians());
            out.push(Return {
                x: range * w.cos() * a.cos(),
                y: -range * w.cos() * a.sin(),
                z: range * w.sin(),
                range,
                azimuth: az,
                elevation: l.elevation_deg as f32,
                time: 1.0 + f64::from(f) * 46.08e-6 + j as f64 * 1.152e-6,
                packet: f / 12,
                raw_distance: 5000,
                intensity: 40,
                laser: j as u8,
                ring: rings[j],
                block: (f % 12) as u8,
                kind: ReturnKind::Strongest,
            });
        }
    }
    out
}
