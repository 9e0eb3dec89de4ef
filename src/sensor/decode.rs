//! Data packet decoding: payload to returns with xyz and firing time, strongest, last
//! and dual (ROS velodyne axes: x forward, y left, z up; azimuth clockwise seen from
//! above; ring 0 lowest).
//!
//! Two kernels share the conventions below. [`PacketDecoder`] decodes the HDL-32E's
//! packets firing by firing into the frame being filled (the frame reader's hot path):
//! laser `j` fires `j * 1.152 us` into the `46.08 us` firing, so its azimuth is the
//! firing's plus `j / 40` of the step to the next firing's azimuth:
//! `a_j = a_f + (a_{f+1} - a_f) * j / 40` (mod 360); the last firing of a packet uses
//! the step before it, and steps larger than [`MAX_STEP_CENTIDEG`] (a gap or a corrupt
//! azimuth) interpolate nothing. [`ModelDecoder`] decodes a whole packet of any
//! [`SensorModel`] with the same rule written for its timing:
//!
//! Per channel `c` of block `b`: firing sequence `s = c / n`, laser id
//! `k = bank * n + c % n`, where `n` is the lasers of a bank and `bank = b % banks`
//! (VLP-16 manual 9.3.1.5 and 9.5; the HDL-64E's lower-bank blocks carry lasers 32-63).
//! A laser fires `SensorModel::laser_offset_us` into its sequence (in pairs on the
//! VLP-32C, in groups of 4 on the HDL-64E). Azimuth interpolation (on by
//! default, as velodyne_decoder, VeloView and the ROS VLP-16 path do): the laser fires
//! `s * sequence_us + k * laser_us` into its block, so its azimuth is the block's plus
//! that fraction of the block duration times the step to the next block's azimuth (next
//! pair in dual mode); the last block uses the step before it, and a step over
//! [`MAX_STEP_CENTIDEG`] (a gap) interpolates nothing. For the HDL-32E this is
//! `j / 40` of the step, as above; for the VLP-16 it is the ROS
//! driver's `gap * (2.304 k + 55.296 s) / 110.592`. Positions:
//! `x = r cos(w) cos(a)`, `y = -r cos(w) sin(a)`, `z = r sin(w) + v`, where `v` is the
//! laser's vertical correction of VLP-16 manual Table 9-1 ("After computing X,Y,Z, apply
//! the vertical correction ... for greatest accuracy"; 0 for the HDL-32E, whose manual
//! gives none). velodyne_decoder 3 applies the same offsets (measured on
//! vlp16_mrpt.pcap: its z minus r sin(w) is 11.23 mm for laser 0 down to -11.23 mm for
//! laser 15, the table's 11.2 to 0.03 mm); [`ModelDecoder::with_vertical_offsets`] turns
//! them off (the ROS driver's VLP-16 path has none).
//!
//! `Return::block` is [`SensorModel::return_block`]: the firing sequence in firing order
//! (0..23 for the VLP-16 in single mode), dual returns adjacent, so each (block, laser)
//! pair of a packet is one firing slot of the spurious-return rules.
//!
//! The VLS-128 ([`super::VLS128`]): block `b` carries bank `b % 4` (dual mode: bank
//! `b / 2`, blocks 8-11 empty and not read), laser `32 * bank + channel`; its banks fire
//! one after the other, so the interpolation fraction is the laser's time into the
//! whole sequence (`SensorModel::laser_offset_us`). A dual-mode VLS-128 packet holds a
//! single firing: [`ModelDecoder::decode_packet_after`] takes the step from the packet
//! before, as velodyne_decoder does.

use super::calibration::{Calibration, ModelCalibration};
use super::packet::{self, BLOCKS, BLOCK_BYTES, LASERS};
use super::{ReturnMode, SensorModel};
use crate::frame::{Return, ReturnKind};

/// Largest azimuth step between firings (hundredths of a degree) used for interpolation.
/// The HDL-32E turns at most 0.33 degrees per firing (20 Hz).
pub const MAX_STEP_CENTIDEG: u32 = 500;

/// Which returns of a dual-return capture to keep.
#[derive(
    Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize, clap::ValueEnum,
)]
#[serde(rename_all = "lowercase")]
pub enum DualSelect {
    /// Keep both returns of each firing.
    Both,
    /// Keep only the last return (even blocks).
    Last,
    /// Keep only the strongest return (odd blocks).
    Strongest,
}

/// Per-laser constants precomputed from the calibration.
#[derive(Clone, Debug)]
struct LaserTable {
    cos_elev: [f32; LASERS],
    sin_elev: [f32; LASERS],
    elevation: [f32; LASERS],
    cos_off: [f32; LASERS],
    sin_off: [f32; LASERS],
    offset_deg: [f32; LASERS],
    dist_off: [f32; LASERS],
    ring: [u8; LASERS],
    /// `j as f32` for laser `j` (interpolation factor).
    index_f32: [f32; LASERS],
    /// `j as f64 * LASER_US`: laser `j`'s delay in its firing, in microseconds.
    laser_us: [f64; LASERS],
    has_offsets: bool,
}

/// Decodes data packets into returns.
#[derive(Clone, Debug)]
pub struct PacketDecoder {
    table: LaserTable,
    /// `(sin, cos)` of the per-laser azimuth step for each firing step in hundredths of
    /// a degree up to [`MAX_STEP_CENTIDEG`] (the same computation as for one block).
    step_sin_cos: Vec<(f64, f64)>,
    resolution: f32,
    interpolate: bool,
    dual: DualSelect,
}

/// Azimuth of one firing and the packet block(s) that carry it.
#[derive(Clone, Copy, Debug)]
pub struct Firing {
    /// Azimuth in hundredths of a degree.
    pub azimuth: u16,
    /// Step to the next firing in hundredths of a degree (0 across a gap).
    pub step: u32,
    /// Index of the firing within the packet.
    pub index: usize,
}

/// Counters of the decoder.
#[derive(Clone, Copy, Debug, Default, serde::Serialize)]
pub struct DecodeCounts {
    /// Return slots with distance 0 (no return).
    pub zero_distance: u64,
    /// Blocks whose azimuth was 36000 or more (real sensors send 36000 for 0 degrees),
    /// decoded modulo 360 degrees.
    pub azimuth_over_360_blocks: u64,
}

impl PacketDecoder {
    /// Creates a decoder for a calibration.
    pub fn new(calibration: &Calibration, interpolate: bool, dual: DualSelect) -> Self {
        let rings = calibration.rings();
        let mut t = LaserTable {
            cos_elev: [0.0; LASERS],
            sin_elev: [0.0; LASERS],
            elevation: [0.0; LASERS],
            cos_off: [1.0; LASERS],
            sin_off: [0.0; LASERS],
            offset_deg: [0.0; LASERS],
            dist_off: [0.0; LASERS],
            ring: rings,
            index_f32: std::array::from_fn(|j| j as f32),
            laser_us: std::array::from_fn(|j| j as f64 * packet::LASER_US),
            has_offsets: false,
        };
        for (j, cal) in calibration.lasers.iter().enumerate() {
            let w = cal.elevation_deg.to_radians();
            t.cos_elev[j] = w.cos() as f32;
            t.sin_elev[j] = w.sin() as f32;
            t.elevation[j] = cal.elevation_deg as f32;
            let o = cal.azimuth_offset_deg.to_radians();
            t.cos_off[j] = o.cos() as f32;
            t.sin_off[j] = o.sin() as f32;
            t.offset_deg[j] = cal.azimuth_offset_deg as f32;
            t.dist_off[j] = cal.distance_offset_m as f32;
            t.has_offsets |= cal.azimuth_offset_deg != 0.0;
        }
        let step_sin_cos = (0..=MAX_STEP_CENTIDEG)
            .map(|step| Self::step_deg(interpolate, step).to_radians().sin_cos())
            .collect();
        PacketDecoder {
            table: t,
            step_sin_cos,
            resolution: calibration.distance_resolution_m as f32,
            interpolate,
            dual,
        }
    }

    /// Azimuth step in degrees from one laser to the next in a firing.
    #[inline]
    fn step_deg(interpolate: bool, step_centideg: u32) -> f64 {
        if interpolate {
            f64::from(step_centideg) * 0.01 / 40.0
        } else {
            0.0
        }
    }

    /// Firings of a packet in order, with the step to the next firing.
    ///
    /// In dual mode two blocks share one firing; the firing's azimuth is the even block's.
    pub fn firings(&self, payload: &[u8], mode: ReturnMode) -> ([Firing; BLOCKS], usize) {
        let per = if mode == ReturnMode::Dual { 2 } else { 1 };
        let n = BLOCKS / per;
        let mut out = [Firing {
            azimuth: 0,
            step: 0,
            index: 0,
        }; BLOCKS];
        for (f, firing) in out.iter_mut().enumerate().take(n) {
            // Real sensors write 36000 for 0 degrees now and then; reduce modulo a turn.
            firing.azimuth = packet::block_azimuth(payload, f * per) % 36000;
            firing.index = f;
        }
        {
            let step = |a: u16, b: u16| -> u32 {
                let s = (u32::from(b) + 36000 - u32::from(a)) % 36000;
                if s > MAX_STEP_CENTIDEG {
                    0
                } else {
                    s
                }
            };
            for f in 0..n - 1 {
                out[f].step = step(out[f].azimuth, out[f + 1].azimuth);
            }
            out[n - 1].step = if n >= 2 { out[n - 2].step } else { 0 };
        }
        (out, n)
    }

    /// Blocks of a firing to decode, with the kind of return each carries.
    pub fn blocks_of(&self, mode: ReturnMode, firing: usize) -> ([(usize, ReturnKind); 2], usize) {
        match mode {
            ReturnMode::Dual => {
                let last = (firing * 2, ReturnKind::DualLast);
                let strongest = (firing * 2 + 1, ReturnKind::DualStrongest);
                match self.dual {
                    DualSelect::Both => ([last, strongest], 2),
                    DualSelect::Last => ([last, last], 1),
                    DualSelect::Strongest => ([strongest, strongest], 1),
                }
            }
            ReturnMode::Last => ([(firing, ReturnKind::Last); 2], 1),
            ReturnMode::Strongest | ReturnMode::Unknown => {
                ([(firing, ReturnKind::Strongest); 2], 1)
            }
        }
    }

    /// Decodes the 32 returns of one block into `out`; distance 0 is counted, not emitted.
    ///
    /// `time0_us` is the first firing's time in microseconds past the hour. Each emitted
    /// return is also tallied in `tally` (per laser id and per intensity byte).
    #[allow(clippy::too_many_arguments)]
    #[inline]
    pub fn decode_block(
        &self,
        payload: &[u8],
        block: usize,
        kind: ReturnKind,
        firing: &Firing,
        time0_us: f64,
        record: u32,
        counts: &mut DecodeCounts,
        tally: &mut ReturnTally<'_>,
        out: &mut Vec<Return>,
    ) {
        // One loop per calibration kind, so the per-return test is decided once.
        if self.table.has_offsets {
            self.decode_block_with::<true>(
                payload, block, kind, firing, time0_us, record, counts, tally, out,
            );
        } else {
            self.decode_block_with::<false>(
                payload, block, kind, firing, time0_us, record, counts, tally, out,
            );
        }
    }

    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn decode_block_with<const OFFSETS: bool>(
        &self,
        payload: &[u8],
        block: usize,
        kind: ReturnKind,
        firing: &Firing,
        time0_us: f64,
        record: u32,
        counts: &mut DecodeCounts,
        tally: &mut ReturnTally<'_>,
        out: &mut Vec<Return>,
    ) {
        if packet::block_azimuth(payload, block) >= 36000 {
            counts.azimuth_over_360_blocks += 1;
        }
        let t = &self.table;
        let base = block * BLOCK_BYTES + 4;
        let Ok(data) = <&[u8; LASERS * 3]>::try_from(&payload[base..base + LASERS * 3]) else {
            return;
        };
        let az_deg = f64::from(firing.azimuth) * 0.01;
        let step_deg = Self::step_deg(self.interpolate, firing.step);
        // Rotate (cos, sin) laser by laser instead of calling sin_cos 32 times.
        let (s0, c0) = az_deg.to_radians().sin_cos();
        let (sd, cd) = match self.step_sin_cos.get(firing.step as usize) {
            Some(&sc) => sc,
            None => step_deg.to_radians().sin_cos(),
        };
        let (mut c, mut s) = (c0, s0);
        let (az0, step) = (az_deg as f32, step_deg as f32);
        let fire_us = time0_us + firing.index as f64 * packet::FIRING_US;
        // Every slot is written in place and kept only when its distance is non-zero, so
        // the loop has no branch on the data (a zero return is overwritten or cut off).
        let start = out.len();
        out.resize(start + LASERS, Return::BLANK);
        let Ok(slots) = <&mut [Return; LASERS]>::try_from(&mut out[start..]) else {
            return;
        };
        // Per-laser quantities in passes without stores into the frame (the rotation is
        // sequential, the rest vectorises); the last pass assembles the returns.
        let mut dir = [[0f32; 2]; LASERS];
        for d in &mut dir {
            *d = [c as f32, s as f32];
            // Advance to the next laser's firing azimuth.
            let next_c = c * cd - s * sd;
            s = s * cd + c * sd;
            c = next_c;
        }
        let mut azimuth = [0f32; LASERS];
        for (j, a) in azimuth.iter_mut().enumerate() {
            let mut az = az0 + step * t.index_f32[j];
            if OFFSETS {
                az += t.offset_deg[j];
            }
            // Offsets and interpolation move an azimuth at most a few degrees past a turn.
            if az >= 360.0 {
                az -= 360.0;
            } else if az < 0.0 {
                az += 360.0;
            }
            *a = az;
        }
        let mut kept = 0usize;
        for j in 0..LASERS {
            let raw = u16::from_le_bytes([data[j * 3], data[j * 3 + 1]]);
            let intensity = data[j * 3 + 2];
            let [cj, sj] = dir[j];
            let (ca, sa) = if OFFSETS {
                (
                    cj * t.cos_off[j] - sj * t.sin_off[j],
                    sj * t.cos_off[j] + cj * t.sin_off[j],
                )
            } else {
                (cj, sj)
            };
            let range = f32::from(raw) * self.resolution + t.dist_off[j];
            let xy = range * t.cos_elev[j];
            // `kept <= j < LASERS`, so the mask never changes the index.
            slots[kept & (LASERS - 1)] = Return {
                x: xy * ca,
                y: -xy * sa,
                z: range * t.sin_elev[j],
                range,
                azimuth: azimuth[j],
                elevation: t.elevation[j],
                time: (fire_us + t.laser_us[j]) * 1e-6,
                packet: record,
                raw_distance: raw,
                intensity,
                laser: j as u8,
                ring: t.ring[j],
                block: block as u8,
                kind,
            };
            let hit = u64::from(raw != 0);
            kept += hit as usize;
            tally.per_laser[j] += hit;
            tally.intensity[usize::from(intensity)] += hit;
        }
        counts.zero_distance += (LASERS - kept) as u64;
        out.truncate(start + kept);
    }
}

/// Per-return counts of a capture, kept by [`PacketDecoder::decode_block`].
#[derive(Debug)]
pub struct ReturnTally<'a> {
    /// Returns per laser id.
    pub per_laser: &'a mut [u64; LASERS],
    /// Returns per intensity byte value.
    pub intensity: &'a mut [u64; 256],
}

/// Time of a packet's first firing in microseconds past the hour.
///
/// The timestamp marks the last laser of the last firing, so the first firing lies
/// `(firings - 1) * 46.08 + 31 * 1.152` us before it (542.592 us in single-return mode,
/// as the manual gives).
pub fn first_firing_us(payload: &[u8], firings: usize) -> f64 {
    f64::from(packet::timestamp_us(payload))
        - ((firings as f64 - 1.0) * packet::FIRING_US + 31.0 * packet::LASER_US)
}

/// Counters of one decoded packet.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PacketCounts {
    /// Return mode read from the packet.
    pub mode: Option<ReturnMode>,
    /// Channels with distance 0 (no return), in the blocks decoded.
    pub zero_distance: u64,
    /// Returns emitted.
    pub returns: u64,
}

/// Decodes the data packets of one sensor model.
#[derive(Clone, Debug)]
pub struct ModelDecoder {
    model: SensorModel,
    /// Per-laser corrections (the model's table unless a file was given).
    cal: ModelCalibration,
    /// Any laser has distance or horizontal corrections (the manual's full formulas).
    advanced: bool,
    cos_elev: Vec<f64>,
    sin_elev: Vec<f64>,
    rings: Vec<u8>,
    /// Vertical correction of each laser in metres (zeros when off).
    z_offset: Vec<f64>,
    vertical_offsets: bool,
    interpolate: bool,
    dual: DualSelect,
}

impl ModelDecoder {
    /// A decoder with the model's default calibration.
    pub fn new(model: &SensorModel, interpolate: bool, dual: DualSelect) -> Self {
        let mut dec = ModelDecoder {
            model: *model,
            cal: ModelCalibration::builtin(model),
            advanced: false,
            cos_elev: Vec::new(),
            sin_elev: Vec::new(),
            rings: Vec::new(),
            z_offset: Vec::new(),
            vertical_offsets: true,
            interpolate,
            dual,
        };
        dec.cache();
        dec
    }

    /// Uses a calibration (a unit's own table, e.g. read by
    /// [`ModelCalibration::from_ros_yaml_file`]) in place of the model's default; its
    /// laser count must be the model's.
    pub fn with_calibration(mut self, cal: ModelCalibration) -> Result<Self, String> {
        if cal.lasers.len() != self.model.lasers {
            return Err(format!(
                "calibration {} has {} lasers, the {} has {}",
                cal.source,
                cal.lasers.len(),
                self.model.name,
                self.model.lasers
            ));
        }
        self.cal = cal;
        self.cache();
        Ok(self)
    }

    /// Recomputes the per-laser caches from the calibration.
    fn cache(&mut self) {
        let rad: Vec<f64> = self
            .cal
            .lasers
            .iter()
            .map(|l| l.elevation_deg.to_radians())
            .collect();
        self.cos_elev = rad.iter().map(|w| w.cos()).collect();
        self.sin_elev = rad.iter().map(|w| w.sin()).collect();
        self.rings = self.cal.rings();
        self.advanced = self.cal.lasers.iter().any(|l| l.is_advanced());
        let on = self.vertical_offsets;
        self.z_offset = self
            .cal
            .lasers
            .iter()
            .map(|l| if on { l.vert_offset_m } else { 0.0 })
            .collect();
    }

    /// Applies the per-laser vertical corrections (the default) or not.
    pub fn with_vertical_offsets(mut self, on: bool) -> Self {
        self.vertical_offsets = on;
        self.cache();
        self
    }

    /// The calibration in use.
    pub fn calibration(&self) -> &ModelCalibration {
        &self.cal
    }

    /// The model decoded.
    pub fn model(&self) -> &SensorModel {
        &self.model
    }

    /// Decodes one data packet payload, appending its non-zero returns to `out`.
    ///
    /// `record` is the capture record (`Return::packet`); `hour_offset_us` is added to
    /// the packet timestamp (whole hours the capture has run, kept by the caller). A
    /// payload that is not a data packet of the model's layout, or carries a return mode
    /// byte no firmware writes, is an error naming the byte offset.
    pub fn decode_packet(
        &self,
        payload: &[u8],
        record: u32,
        hour_offset_us: f64,
        out: &mut Vec<Return>,
    ) -> Result<PacketCounts, String> {
        self.decode_packet_after(payload, None, record, hour_offset_us, out)
    }

    /// As [`ModelDecoder::decode_packet`], given the data packet before this one: a
    /// packet holding a single firing (the VLS-128 in dual return mode) has no next
    /// block to interpolate towards, so its azimuth step is the one from `previous`'s
    /// first block to its own, per firing of `previous` (velodyne_decoder's rule). Without
    /// `previous` (or when it is not a data packet of the model) such a packet is not
    /// interpolated. Packets with two or more firings ignore `previous`.
    pub fn decode_packet_after(
        &self,
        payload: &[u8],
        previous: Option<&[u8]>,
        record: u32,
        hour_offset_us: f64,
        out: &mut Vec<Return>,
    ) -> Result<PacketCounts, String> {
        let m = &self.model;
        let lay = &m.layout;
        if payload.len() != lay.payload_bytes {
            return Err(format!(
                "data packet of {} bytes where the {} sends {}",
                payload.len(),
                m.name,
                lay.payload_bytes
            ));
        }
        if let Some(b) = lay.bad_flag(payload) {
            let mode = lay.return_mode(payload).unwrap_or(ReturnMode::Strongest);
            let want = lay.expected_flag(mode, b).to_be_bytes();
            return Err(format!(
                "block {b} has no 0x{:02X}{:02X} flag (payload byte offset {})",
                want[1],
                want[0],
                b * lay.block_bytes
            ));
        }
        let mode = lay.return_mode(payload).map_err(|byte| {
            format!(
                "unknown return mode byte 0x{byte:02x} (payload byte offset {})",
                lay.return_mode_at.unwrap_or(0)
            )
        })?;
        let banks = lay.banks();
        let per = m.blocks_per_firing(mode);
        let n = lay.blocks / per;
        // Azimuth of each firing and bank: the first block of the firing with that bank
        // (dual mode: the pair's first block, as velodyne_decoder and ROS read it).
        let azimuth: Vec<u32> = (0..n * banks)
            .map(|fb| {
                u32::from(lay.block_azimuth(payload, lay.block_of(mode, fb / banks, 0, fb % banks)))
                    % 36000
            })
            .collect();
        let mut step: Vec<f64> = (0..n * banks)
            .map(|fb| match azimuth.get(fb + banks) {
                Some(&next) => {
                    let s = (next + 36000 - azimuth[fb]) % 36000;
                    if s > MAX_STEP_CENTIDEG {
                        0.0
                    } else {
                        f64::from(s)
                    }
                }
                None => 0.0,
            })
            .collect();
        if n >= 2 {
            for k in 0..banks {
                step[(n - 1) * banks + k] = step[(n - 2) * banks + k];
            }
        } else if let Some(prev) = previous.filter(|p| lay.is_data_packet(p)) {
            let prev_mode = lay.return_mode(prev).unwrap_or(mode);
            let prev_firings = lay.blocks / m.blocks_per_firing(prev_mode);
            let a = u32::from(lay.block_azimuth(prev, 0)) % 36000;
            let s = (azimuth[0] + 36000 - a) % 36000;
            let per_firing = f64::from(s) / prev_firings as f64;
            if per_firing <= f64::from(MAX_STEP_CENTIDEG) {
                step.iter_mut().for_each(|x| *x = per_firing);
            }
        }
        let ts = f64::from(lay.timestamp_us(payload)) + hour_offset_us;
        let block_us = m.block_us();
        let mut counts = PacketCounts {
            mode: Some(mode),
            ..PacketCounts::default()
        };
        for block in 0..lay.used_blocks(mode) {
            let Some(kind) = self.kind(mode, block) else {
                continue;
            };
            let fb = (block / per) * banks + lay.block_bank(mode, block);
            let az0 = f64::from(azimuth[fb]) * 0.01;
            let gap = if self.interpolate {
                step[fb] * 0.01
            } else {
                0.0
            };
            for channel in 0..lay.channels {
                let at = lay.channel_at(block, channel);
                let raw = u16::from_le_bytes([payload[at], payload[at + 1]]);
                if raw == 0 {
                    counts.zero_distance += 1;
                    continue;
                }
                let (sequence, laser) = m.block_laser_in(mode, block, channel);
                let into_block = sequence as f64 * m.sequence_us + m.laser_offset_us(laser);
                let cal = &self.cal.lasers[laser];
                let mut az = az0 + gap * into_block / block_us + cal.azimuth_offset_deg;
                az = az.rem_euclid(360.0);
                let distance = f64::from(raw) * self.cal.distance_resolution_m;
                let (range, [x, y, z]) = if self.advanced {
                    let (range, mut p) = cal.position(distance, az);
                    p[2] += self.z_offset[laser] - cal.vert_offset_m;
                    (range, p)
                } else {
                    let (sa, ca) = az.to_radians().sin_cos();
                    let xy = distance * self.cos_elev[laser];
                    (
                        distance,
                        [
                            xy * ca,
                            -xy * sa,
                            distance * self.sin_elev[laser] + self.z_offset[laser],
                        ],
                    )
                };
                let seq = m.sequence_index(mode, block, sequence);
                out.push(Return {
                    x: x as f32,
                    y: y as f32,
                    z: z as f32,
                    range: range as f32,
                    azimuth: (az as f32) % 360.0,
                    elevation: cal.elevation_deg as f32,
                    time: (ts + m.firing_offset_us(mode, seq, laser)) * 1e-6,
                    packet: record,
                    raw_distance: raw,
                    intensity: payload[at + 2],
                    laser: laser as u8,
                    ring: self.rings[laser],
                    block: m.return_block(mode, block, sequence) as u8,
                    kind,
                });
                counts.returns += 1;
            }
        }
        Ok(counts)
    }

    /// Kind of the returns of a packet block, or `None` when the dual selection drops it.
    fn kind(&self, mode: ReturnMode, block: usize) -> Option<ReturnKind> {
        match mode {
            ReturnMode::Dual => {
                let last = !self.model.dual_block_is_strongest(block);
                match (self.dual, last) {
                    (DualSelect::Both, true) | (DualSelect::Last, true) => {
                        Some(ReturnKind::DualLast)
                    }
                    (DualSelect::Both, false) | (DualSelect::Strongest, false) => {
                        Some(ReturnKind::DualStrongest)
                    }
                    _ => None,
                }
            }
            ReturnMode::Last => Some(ReturnKind::Last),
            ReturnMode::Strongest | ReturnMode::Unknown => Some(ReturnKind::Strongest),
        }
    }
}

#[cfg(test)]
#[allow(clippy::needless_range_loop)] // packets are indexed by block and channel as in the manual
mod tests {
    use super::*;
    use crate::sensor::VLP16;

    /// A VLP-16 packet: block azimuths `az[b]` (centidegrees), timestamp `ts`, and the
    /// distance and intensity of each channel from `fill(block, channel)`.
    fn vlp_packet(
        az: &[u16; 12],
        ts: u32,
        mode: u8,
        fill: impl Fn(usize, usize) -> (u16, u8),
    ) -> Vec<u8> {
        let mut p = vec![0u8; 1206];
        for b in 0..12 {
            let at = b * 100;
            p[at] = 0xFF;
            p[at + 1] = 0xEE;
            p[at + 2..at + 4].copy_from_slice(&az[b].to_le_bytes());
            for c in 0..32 {
                let (d, i) = fill(b, c);
                let o = at + 4 + 3 * c;
                p[o..o + 2].copy_from_slice(&d.to_le_bytes());
                p[o + 2] = i;
            }
        }
        p[1200..1204].copy_from_slice(&ts.to_le_bytes());
        p[1204] = mode;
        p[1205] = 0x22;
        p
    }

    /// Elevation of VLP-16 laser `k` (manual Table 9-1: even ids -15, -13, ..., -1; odd
    /// ids 1, 3, ..., 15), written from the table, not from the model.
    fn manual_elevation(k: usize) -> f64 {
        if k.is_multiple_of(2) {
            k as f64 - 15.0
        } else {
            k as f64
        }
    }

    /// Vertical correction of VLP-16 laser `k` in metres (manual Table 9-1).
    fn manual_vertical_m(k: usize) -> f64 {
        [
            11.2, -0.7, 9.7, -2.2, 8.1, -3.7, 6.6, -5.1, 5.1, -6.6, 3.7, -8.1, 2.2, -9.7, 0.7,
            -11.2,
        ][k] * 1e-3
    }

    fn close(a: f64, b: f64, tol: f64) -> bool {
        (a - b).abs() <= tol
    }

    #[test]
    fn vlp16_single_return_positions_and_times_follow_the_manual() {
        // 10 Hz: 0.398 deg per 110.592 us block, written as 40 centidegrees; the packet
        // crosses 360 degrees to check the wrap.
        let az: [u16; 12] = std::array::from_fn(|b| ((35_800 + 40 * b) % 36_000) as u16);
        let ts = 1_234_567u32;
        let dist = |b: usize, c: usize| (1000 + 37 * b as u16 + 101 * c as u16, (b * 32 + c) as u8);
        let p = vlp_packet(&az, ts, 0x37, |b, c| {
            if (b + c) % 7 == 3 {
                (0, 9)
            } else {
                dist(b, c)
            }
        });
        let dec = ModelDecoder::new(&VLP16, true, DualSelect::Both);
        let mut out = Vec::new();
        let counts = dec.decode_packet(&p, 5, 3.6e9, &mut out).unwrap();
        let zeros = (0..12)
            .flat_map(|b| (0..32).map(move |c| (b, c)))
            .filter(|(b, c)| (b + c) % 7 == 3)
            .count();
        assert_eq!(counts.zero_distance as usize, zeros);
        assert_eq!(out.len(), 384 - zeros);
        let mut it = out.iter();
        for b in 0..12 {
            for c in 0..32 {
                if (b + c) % 7 == 3 {
                    continue;
                }
                let r = it.next().unwrap();
                let (s, k) = (c / 16, c % 16);
                let (raw, intensity) = dist(b, c);
                let r_m = f64::from(raw) * 0.002;
                // Manual 9.5 and ROS: azimuth + 40 * (2.304 k + 55.296 s) / 110.592.
                let a_deg = (f64::from(az[b])
                    + 40.0 * (2.304 * k as f64 + 55.296 * s as f64) / 110.592)
                    / 100.0;
                let (a, w) = (a_deg.to_radians(), manual_elevation(k).to_radians());
                let (x, y, z) = (
                    r_m * w.cos() * a.cos(),
                    -r_m * w.cos() * a.sin(),
                    r_m * w.sin() + manual_vertical_m(k),
                );
                assert!(
                    close(f64::from(r.x), x, 1e-4)
                        && close(f64::from(r.y), y, 1e-4)
                        && close(f64::from(r.z), z, 1e-4),
                    "block {b} channel {c}: ({}, {}, {}) vs ({x}, {y}, {z})",
                    r.x,
                    r.y,
                    r.z
                );
                assert!(
                    close(f64::from(r.azimuth), a_deg % 360.0, 1e-4),
                    "{} {a_deg}",
                    r.azimuth
                );
                let t =
                    (3.6e9 + f64::from(ts) + 55.296 * (2 * b + s) as f64 + 2.304 * k as f64) * 1e-6;
                assert!(close(r.time, t, 1e-9), "time {} vs {t}", r.time);
                assert_eq!(
                    (
                        r.laser as usize,
                        r.block as usize,
                        r.raw_distance,
                        r.intensity
                    ),
                    (k, 2 * b + s, raw, intensity)
                );
                let ring = if k.is_multiple_of(2) {
                    k / 2
                } else {
                    8 + k / 2
                };
                assert_eq!(
                    (r.ring as usize, r.packet, r.kind),
                    (ring, 5, ReturnKind::Strongest)
                );
            }
        }
    }

    #[test]
    fn vertical_offsets_can_be_turned_off() {
        let p = vlp_packet(&[0; 12], 0, 0x37, |_, _| (5000, 1));
        let (mut on, mut off) = (Vec::new(), Vec::new());
        let dec = ModelDecoder::new(&VLP16, true, DualSelect::Both);
        dec.decode_packet(&p, 0, 0.0, &mut on).unwrap();
        dec.with_vertical_offsets(false)
            .decode_packet(&p, 0, 0.0, &mut off)
            .unwrap();
        for (a, b) in on.iter().zip(&off) {
            let k = usize::from(a.laser);
            assert!(close(
                f64::from(b.z),
                10.0 * manual_elevation(k).to_radians().sin(),
                1e-5
            ));
            assert!(close(f64::from(a.z - b.z), manual_vertical_m(k), 1e-5));
        }
    }

    #[test]
    fn vlp16_dual_return_pairs_share_sequences() {
        // Blocks 2p (last) and 2p+1 (strongest) share azimuth and firing times.
        let az: [u16; 12] = std::array::from_fn(|b| (1000 + 40 * (b / 2)) as u16);
        let p = vlp_packet(&az, 0, 0x39, |b, c| {
            (2000 + (b % 2) as u16 * 500 + c as u16, 7)
        });
        let mut out = Vec::new();
        ModelDecoder::new(&VLP16, true, DualSelect::Both)
            .decode_packet(&p, 0, 0.0, &mut out)
            .unwrap();
        assert_eq!(out.len(), 384);
        for (i, r) in out.iter().enumerate() {
            let (b, c) = (i / 32, i % 32);
            let (s, k) = (c / 16, c % 16);
            let seq = (b - b % 2) + s;
            let kind = if b % 2 == 0 {
                ReturnKind::DualLast
            } else {
                ReturnKind::DualStrongest
            };
            assert_eq!(
                (r.kind, r.block as usize, r.laser as usize),
                (kind, 2 * seq + b % 2, k),
                "block {b} channel {c}"
            );
            assert!(close(
                r.time,
                (55.296 * seq as f64 + 2.304 * k as f64) * 1e-6,
                1e-12
            ));
            let a_deg = (f64::from(az[b])
                + 40.0 * (2.304 * k as f64 + 55.296 * s as f64) / 110.592)
                / 100.0;
            assert!(
                close(f64::from(r.azimuth), a_deg, 1e-4),
                "{} {a_deg}",
                r.azimuth
            );
        }
        for (select, kind) in [
            (DualSelect::Last, ReturnKind::DualLast),
            (DualSelect::Strongest, ReturnKind::DualStrongest),
        ] {
            let mut one = Vec::new();
            ModelDecoder::new(&VLP16, true, select)
                .decode_packet(&p, 0, 0.0, &mut one)
                .unwrap();
            assert_eq!(one.len(), 192);
            assert!(one.iter().all(|r| r.kind == kind));
        }
        let mut p_last = p.clone();
        p_last[1204] = 0x38;
        let mut last = Vec::new();
        ModelDecoder::new(&VLP16, true, DualSelect::Both)
            .decode_packet(&p_last, 0, 0.0, &mut last)
            .unwrap();
        assert!(last.iter().all(|r| r.kind == ReturnKind::Last) && last.len() == 384);
    }

    #[test]
    fn bad_packets_are_refused_with_the_place() {
        let dec = ModelDecoder::new(&VLP16, true, DualSelect::Both);
        let mut p = vlp_packet(&[0; 12], 0, 0x37, |_, _| (1, 1));
        p[1204] = 0x41;
        let e = dec.decode_packet(&p, 0, 0.0, &mut Vec::new()).unwrap_err();
        assert!(e.contains("0x41") && e.contains("1204"), "{e}");
        p[1204] = 0x37;
        p[500] = 0;
        let e = dec.decode_packet(&p, 0, 0.0, &mut Vec::new()).unwrap_err();
        assert!(e.contains("block 5") && e.contains("500"), "{e}");
        let e = dec
            .decode_packet(&p[..1000], 0, 0.0, &mut Vec::new())
            .unwrap_err();
        assert!(e.contains("1000 bytes"), "{e}");
    }
}
