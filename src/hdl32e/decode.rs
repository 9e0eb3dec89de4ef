//! Data packet decoding: raw blocks to per-laser returns with xyz and firing time.
//!
//! Azimuth interpolation (on by default): laser `j` fires `j * 1.152 us` into the
//! `46.08 us` firing, so its azimuth is the firing's azimuth plus `j / 40` of the step
//! to the next firing's azimuth: `a_j = a_f + (a_{f+1} - a_f) * j / 40` (mod 360). The
//! last firing of a packet has no successor in the packet and uses the step before it.
//! Steps larger than [`MAX_STEP_CENTIDEG`] (a gap or a corrupt azimuth) interpolate
//! nothing.

use super::packet::{self, ReturnMode, BLOCKS, BLOCK_BYTES, LASERS};
use crate::calibration::Calibration;
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
        out.resize(start + LASERS, BLANK);
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

/// Filler for the slots of a block before they are decoded (every field is overwritten).
pub(crate) const BLANK: Return = Return {
    x: 0.0,
    y: 0.0,
    z: 0.0,
    range: 0.0,
    azimuth: 0.0,
    elevation: 0.0,
    time: 0.0,
    packet: 0,
    raw_distance: 0,
    intensity: 0,
    laser: 0,
    ring: 0,
    block: 0,
    kind: ReturnKind::Strongest,
};

/// Time of a packet's first firing in microseconds past the hour.
///
/// The timestamp marks the last laser of the last firing, so the first firing lies
/// `(firings - 1) * 46.08 + 31 * 1.152` us before it (542.592 us in single-return mode,
/// as the manual gives).
pub fn first_firing_us(payload: &[u8], firings: usize) -> f64 {
    f64::from(packet::timestamp_us(payload))
        - ((firings as f64 - 1.0) * packet::FIRING_US + 31.0 * packet::LASER_US)
}
