//! One description of a spinning Velodyne sensor (issue 31): lasers, firing timing,
//! packet layout, return modes and rotation, with the HDL-32E, VLP-16, Puck LITE, Puck
//! Hi-Res, VLP-32C, HDL-64E S2/S3 and VLS-128 (Alpha Prime) as instances.
//!
//! Sources:
//! - HDL-32E: the constants of [`packet`] and the built-in table of
//!   [`calibration`] (HDL-32E user manual, appendices B and E; notes in
//!   `../shared/docs/hdl32e.md`). A test holds this description to those constants.
//! - VLP-16, Puck LITE, Puck Hi-Res: VLP-16 user manual 63-9243 Rev D, section 9.2
//!   (Table 9-1, laser id to vertical angle and vertical correction for the VLP-16, Puck
//!   LITE and Puck Hi-Res), 9.3.1 (firing sequence: "It takes 55.296 us to fire all 16
//!   lasers"; data point: 2 mm granularity; data block: two firing sequences of 16
//!   lasers, 24 firing sequences in 12 blocks), 9.3.1.7 (Table 9-2 factory bytes: return
//!   mode 0x37/0x38/0x39 at 0x04DE, product id at 0x04DF: HDL-32E 0x21, VLP-16 and Puck
//!   LITE 0x22, Puck Hi-Res 0x24), 9.5 (firing sequence timing: 16 firings 2.304 us apart
//!   then an 18.43 us recharge; "the timestamp in the packet indicates the time of the
//!   first data point in the packet"; TimeOffset = 55.296 us * SequenceIndex + 2.304 us *
//!   DataPointIndex, with SequenceIndex = 2 * block + channel / 16 in single return mode
//!   and (block - block % 2) + channel / 16 in dual return mode, from the manual's
//!   `make_table`). The 110.592 us block duration and the azimuth interpolation across
//!   both sequences of a block (azimuth + gap * (2.304 * k + 55.296 * s) / 110.592) are
//!   those of the ROS velodyne driver (`rawdata.cc`, `VLP16_BLOCK_TDURATION`,
//!   `VLP16_DSR_TOFFSET`, `VLP16_FIRING_TOFFSET`) and Tier IV's nebula (`vlp16.hpp`).
//! - VLP-32C: VLP-32C user manual 63-9325, Table 9-1 (elevation and azimuth offset by
//!   laser id; the same numbers as velodyne_decoder's `calib_db.cpp` and bundled
//!   `VLP-32C.yml`), 9.5 (lasers fired in pairs every 2.304 us, 55.296 us a sequence,
//!   one sequence per block), 4 mm distance units (`distance_resolution: 0.004` in the
//!   ROS and velodyne_decoder tables).
//! - HDL-64E S2/S3: packet layout of the HDL-64E S2 and S3 manuals (upper block 0xEEFF,
//!   lower block 0xDDFF, status type and value bytes after the timestamp); firing timing
//!   from their "laser firing time table" as velodyne_decoder 3 (`buildTimings`,
//!   `unpack_hdl64e`) applies it, with its dual-mode block order and mode detection;
//!   default angles from VeloView's `HDL-64.xml` (the manuals print no table).
//! - VLS-128 (Alpha Prime): no manual page was at hand; the description is that of
//!   velodyne_decoder 3.1 (`packet_decoder.cpp`: `buildTimings` AlphaPrime,
//!   `unpack_vls128`, `correctVls128Timings`; `types.h`: bank flags 0xEEFF, 0xDDFF, 0xCCFF,
//!   0xBBFF, product id 0xA1; `calib_db.cpp`: the 128 elevations and azimuth offsets,
//!   0.004 m units), which cites VeloView's `vtkVelodyneLegacyPacketInterpreter` for the
//!   timing, and of the ROS velodyne driver (`rawdata.h`: `VLS128_BANK_1..4`,
//!   `VLS128_DISTANCE_RESOLUTION 0.004`, `VLS128_MODEL_ID 161`, "VLS-128 fires 8 lasers
//!   at a time"; `rawdata.cc` `unpack_vls128`: dual mode leaves the last 4 blocks out).
//!   Packet: 12 blocks, block `b` carries bank `b % 4` (lasers `32 * bank ..`) of firing
//!   sequence `b / 4`; dual mode: one sequence in blocks 0-7, last then strongest return
//!   of each bank adjacent. Timing: 8 lasers a firing group, one group a channel (2.89 us
//!   from firmware 5.2.3, 8/3 us before: two models told apart by the packet period,
//!   173.4 us or 160 us), 20 channels a sequence (16 groups, 2 idle channels after the
//!   8th and 2 at the end), the timestamp 7 us after the first firing ("Top of the Hour
//!   is aligned with the fourth firing group", velodyne_decoder; the ROS driver uses
//!   8.7 us); on fw 5.1 velodyne_decoder scales the 7 us with the channel (6.46 us),
//!   and so does [`VLS128_FW51`], so that the two decoders agree.

pub mod calibration;
pub mod decode;
pub mod encode;
pub mod frames;
pub mod identify;
pub mod index;
pub mod packet;

pub use packet::ReturnMode;

/// The data packet layout of these sensors (1206-byte UDP payload: 12 blocks of flag,
/// azimuth and 32 channels; timestamp; two factory or status bytes).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PacketLayout {
    /// UDP payload size of a data packet.
    pub payload_bytes: usize,
    /// Data blocks per packet.
    pub blocks: usize,
    /// Bytes per data block.
    pub block_bytes: usize,
    /// Block flag read as a little-endian u16 (bytes FF EE); the flag of bank 0.
    pub block_flag: u16,
    /// Flag of each laser bank in block order (`[0xEEFF]` for the single-bank sensors;
    /// the HDL-64E alternates upper-bank blocks 0xEEFF, lasers 0-31, and lower-bank
    /// blocks 0xDDFF, lasers 32-63): block `b` carries bank `b % bank_flags.len()`.
    pub bank_flags: &'static [u16],
    /// Channels (distance u16 + intensity u8) per block.
    pub channels: usize,
    /// Byte offset of the little-endian u32 timestamp (us past the hour).
    pub timestamp_at: usize,
    /// Byte offset of the return mode byte (`None`: the HDL-64E writes a status cycle
    /// there; its mode shows in the block azimuths).
    pub return_mode_at: Option<usize>,
    /// Byte offset of the product id byte (`None` on the HDL-64E).
    pub product_at: Option<usize>,
    /// In dual return mode the two returns of a bank sit in adjacent blocks (the
    /// VLS-128: last bank 0, strongest bank 0, last bank 1, ...); otherwise the banks
    /// of one return group come first (the HDL-64E: strongest upper, strongest lower,
    /// last upper, last lower). The same for single-bank layouts.
    pub dual_pairs_adjacent: bool,
}

/// The 1206-byte layout of the HDL-32E and VLP-16 data packets.
pub const LAYOUT_1206: PacketLayout = PacketLayout {
    payload_bytes: 1206,
    blocks: 12,
    block_bytes: 100,
    block_flag: 0xEEFF,
    bank_flags: &[0xEEFF],
    channels: 32,
    timestamp_at: 1200,
    return_mode_at: Some(1204),
    product_at: Some(1205),
    dual_pairs_adjacent: false,
};

/// The 1206-byte layout of the HDL-64E S2 and S3: blocks alternate upper bank (bytes
/// FF EE) and lower bank (bytes FF DD); bytes 1204-1205 are the status type and value
/// of the status cycle, not a return mode or product id.
pub const LAYOUT_HDL64E: PacketLayout = PacketLayout {
    bank_flags: &[0xEEFF, 0xDDFF],
    return_mode_at: None,
    product_at: None,
    ..LAYOUT_1206
};

/// The 1206-byte layout of the VLS-128 (Alpha Prime): four banks of 32 lasers, blocks
/// flagged FF EE (lasers 0-31), FF DD (32-63), FF CC (64-95), FF BB (96-127), one firing
/// sequence per 4 blocks (3 a packet); in dual return mode one sequence a packet in
/// blocks 0-7, the last and strongest return of each bank adjacent, blocks 8-11 empty.
pub const LAYOUT_VLS128: PacketLayout = PacketLayout {
    bank_flags: &[0xEEFF, 0xDDFF, 0xCCFF, 0xBBFF],
    dual_pairs_adjacent: true,
    ..LAYOUT_1206
};

impl PacketLayout {
    /// True when a payload has the size and every block flag of this layout.
    pub fn is_data_packet(&self, payload: &[u8]) -> bool {
        payload.len() == self.payload_bytes && self.bad_flag(payload).is_none()
    }

    /// Number of laser banks (blocks of one firing with different lasers).
    pub fn banks(&self) -> usize {
        self.bank_flags.len()
    }

    /// The first block whose flag is not its bank's (the payload must be long enough).
    /// Blocks a dual-mode packet leaves empty (the VLS-128's last four) are not checked;
    /// a packet whose mode byte no firmware writes is checked as a single-mode one.
    pub fn bad_flag(&self, payload: &[u8]) -> Option<usize> {
        let mode = self.return_mode(payload).unwrap_or(ReturnMode::Strongest);
        (0..self.used_blocks(mode)).find(|&b| {
            let at = b * self.block_bytes;
            u16::from_le_bytes([payload[at], payload[at + 1]]) != self.expected_flag(mode, b)
        })
    }

    /// Blocks of one firing: one per bank, twice that in dual mode.
    pub fn blocks_per_firing(&self, mode: ReturnMode) -> usize {
        if mode == ReturnMode::Dual {
            2 * self.banks()
        } else {
            self.banks()
        }
    }

    /// Blocks that carry returns in a mode: every block but those left over after the
    /// last whole firing (the VLS-128's dual mode fills 8 of 12).
    pub fn used_blocks(&self, mode: ReturnMode) -> usize {
        let per = self.blocks_per_firing(mode);
        self.blocks / per * per
    }

    /// Laser bank of packet block `block` in a mode.
    pub fn block_bank(&self, mode: ReturnMode, block: usize) -> usize {
        if mode == ReturnMode::Dual && self.dual_pairs_adjacent {
            (block / 2) % self.banks()
        } else {
            block % self.banks()
        }
    }

    /// Return group (0 first, 1 second) of a dual-mode packet block.
    pub fn dual_group(&self, block: usize) -> usize {
        if self.dual_pairs_adjacent {
            block % 2
        } else {
            (block / self.banks()) % 2
        }
    }

    /// Packet block of firing `firing`, return group `group` (0 in single mode) and bank
    /// `bank` (the inverse of [`PacketLayout::block_bank`] and [`PacketLayout::dual_group`]).
    pub fn block_of(&self, mode: ReturnMode, firing: usize, group: usize, bank: usize) -> usize {
        let within = if mode == ReturnMode::Dual && self.dual_pairs_adjacent {
            2 * bank + group
        } else {
            group * self.banks() + bank
        };
        firing * self.blocks_per_firing(mode) + within
    }

    /// Flag block `block` must carry in a mode (little-endian u16).
    pub fn expected_flag(&self, mode: ReturnMode, block: usize) -> u16 {
        self.bank_flags[self.block_bank(mode, block)]
    }

    /// Return mode of a data packet: its mode byte, or for layouts without one (the
    /// HDL-64E) dual when the first block of the second bank group repeats the first
    /// block's azimuth (velodyne_decoder's rule: in dual mode the blocks run strongest
    /// upper, strongest lower, last upper, last lower of one firing). `Err` carries the
    /// unknown byte.
    pub fn return_mode(&self, payload: &[u8]) -> Result<ReturnMode, u8> {
        match self.return_mode_at {
            Some(at) => ReturnMode::from_byte(payload[at]).ok_or(payload[at]),
            None => {
                let banks = self.banks();
                if self.block_azimuth(payload, 0) == self.block_azimuth(payload, banks) {
                    Ok(ReturnMode::Dual)
                } else {
                    Ok(ReturnMode::Strongest)
                }
            }
        }
    }

    /// Azimuth of a block in hundredths of a degree, as written (may be 36000 or more).
    pub fn block_azimuth(&self, payload: &[u8], block: usize) -> u16 {
        let at = block * self.block_bytes + 2;
        u16::from_le_bytes([payload[at], payload[at + 1]])
    }

    /// Byte offset of one channel's distance in the payload.
    pub fn channel_at(&self, block: usize, channel: usize) -> usize {
        block * self.block_bytes + 4 + 3 * channel
    }

    /// Packet timestamp in microseconds past the hour.
    pub fn timestamp_us(&self, payload: &[u8]) -> u32 {
        let t = self.timestamp_at;
        u32::from_le_bytes([payload[t], payload[t + 1], payload[t + 2], payload[t + 3]])
    }
}

/// What instant of the packet the packet timestamp marks.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TimestampMark {
    /// The last laser of the last firing (HDL-32E manual: fire time = timestamp -
    /// 542.592 us + block * 46.08 us + laser * 1.152 us).
    LastFiring,
    /// The first data point of the packet (VLP-16 manual 9.5).
    FirstFiring,
}

/// Description of one spinning Velodyne sensor model.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SensorModel {
    /// Model name as users write it ("HDL-32E", "VLP-16").
    pub name: &'static str,
    /// Product id byte the sensor writes (byte 1205; 0 where the layout has none).
    pub product_id: u8,
    /// Number of lasers (16, 32 or 64).
    pub lasers: usize,
    /// Default elevation of each laser id in degrees (the manual's table).
    pub elevation_deg: &'static [f64],
    /// Default azimuth offset of each laser id in degrees (0 for these models).
    pub azimuth_offset_deg: &'static [f64],
    /// Vertical offset of each laser's origin in millimetres (VLP-16 manual Table 9-1;
    /// empty where the manual gives none); added to z by [`decode::ModelDecoder`] unless
    /// turned off, as the manual and velodyne_decoder do.
    pub vertical_offset_mm: &'static [f64],
    /// Size of one raw distance unit in metres.
    pub distance_resolution_m: f64,
    /// Time between two consecutive firing groups of a sequence in microseconds (one
    /// laser a group on the HDL-32E and VLP-16, a pair on the VLP-32C, four on the
    /// HDL-64E).
    pub laser_us: f64,
    /// Lasers fired in one group (1, 2 on the VLP-32C, 4 on the HDL-64E).
    pub lasers_per_group: usize,
    /// Firing time of each laser of a group after the group's first, in microseconds
    /// (`lasers_per_group` values: all 0 except on the HDL-64E).
    pub group_pattern_us: &'static [f64],
    /// Lasers of different banks with the same index fire together (the HDL-64E's upper
    /// and lower banks); false where the banks fire one after the other within a
    /// sequence (the VLS-128: laser `k` is in firing group `k / 8` of all 128).
    pub banks_fire_together: bool,
    /// Lasers from this id on fire this many microseconds later than the group grid
    /// says (the VLS-128's two idle channels after its 8th firing group); `(usize::MAX,
    /// 0.0)` where there is none.
    pub firing_pause: (usize, f64),
    /// Time from the first firing of a packet to the instant its timestamp marks, in
    /// microseconds, with [`TimestampMark::FirstFiring`] (7 us on the VLS-128, 0 else).
    pub timestamp_after_first_us: f64,
    /// In dual return mode the strongest return's blocks come first (HDL-64E); else the
    /// last return's (HDL-32E, VLP-16, VLP-32C: even blocks last, odd strongest).
    pub dual_strongest_first: bool,
    /// Duration of one firing sequence (all lasers fired and recharged) in microseconds.
    pub sequence_us: f64,
    /// Firing sequences per block in single return mode (1 for the HDL-32E, 2 for the
    /// VLP-16, whose block carries two 16-laser sequences in its 32 channels).
    pub sequences_per_block: usize,
    /// What the packet timestamp marks.
    pub timestamp_mark: TimestampMark,
    /// Packet layout.
    pub layout: PacketLayout,
    /// Return modes the sensor writes (byte 1204).
    pub return_modes: &'static [ReturnMode],
    /// Slowest and fastest rotation rate in Hz.
    pub rotation_hz: (f64, f64),
}

/// Return modes of the 1206-byte sensors (manual Table 9-2).
const MODES: [ReturnMode; 3] = [ReturnMode::Strongest, ReturnMode::Last, ReturnMode::Dual];

/// Elevations of the HDL-32E by laser id (the built-in calibration table).
const HDL32E_ELEVATION_DEG: [f64; 32] = crate::sensor::calibration::BUILTIN_ELEVATION_DEG;

/// Elevations of the VLP-16 and Puck LITE by laser id (VLP-16 manual, Table 9-1).
const VLP16_ELEVATION_DEG: [f64; 16] = [
    -15.0, 1.0, -13.0, 3.0, -11.0, 5.0, -9.0, 7.0, -7.0, 9.0, -5.0, 11.0, -3.0, 13.0, -1.0, 15.0,
];

/// Vertical corrections of the VLP-16 and Puck LITE in mm (VLP-16 manual, Table 9-1).
const VLP16_VERTICAL_MM: [f64; 16] = [
    11.2, -0.7, 9.7, -2.2, 8.1, -3.7, 6.6, -5.1, 5.1, -6.6, 3.7, -8.1, 2.2, -9.7, 0.7, -11.2,
];

/// Elevations of the Puck Hi-Res by laser id (VLP-16 manual, Table 9-1).
const HIRES_ELEVATION_DEG: [f64; 16] = [
    -10.0, 0.67, -8.67, 2.0, -7.33, 3.33, -6.0, 4.67, -4.67, 6.0, -3.33, 7.33, -2.0, 8.67, -0.67,
    10.0,
];

/// Vertical corrections of the Puck Hi-Res in mm (VLP-16 manual, Table 9-1).
const HIRES_VERTICAL_MM: [f64; 16] = [
    7.4, -0.9, 6.5, -1.8, 5.5, -2.7, 4.6, -3.7, 3.7, -4.6, 2.7, -5.5, 1.8, -6.5, 0.9, -7.4,
];

const ZERO_32: [f64; 32] = [0.0; 32];

/// Velodyne HDL-32E: 32 lasers fired one every 1.152 us, one 46.08 us firing per block.
pub const HDL32E: SensorModel = SensorModel {
    name: "HDL-32E",
    product_id: 0x21,
    lasers: 32,
    elevation_deg: &HDL32E_ELEVATION_DEG,
    azimuth_offset_deg: &ZERO_32,
    vertical_offset_mm: &[],
    distance_resolution_m: 0.002,
    laser_us: 1.152,
    lasers_per_group: 1,
    group_pattern_us: &[0.0],
    banks_fire_together: true,
    firing_pause: (usize::MAX, 0.0),
    timestamp_after_first_us: 0.0,
    dual_strongest_first: false,
    sequence_us: 46.08,
    sequences_per_block: 1,
    timestamp_mark: TimestampMark::LastFiring,
    layout: LAYOUT_1206,
    return_modes: &MODES,
    rotation_hz: (5.0, 20.0),
};

/// Velodyne VLP-16: 16 lasers 2.304 us apart, two 55.296 us sequences per block.
pub const VLP16: SensorModel = SensorModel {
    name: "VLP-16",
    product_id: 0x22,
    lasers: 16,
    elevation_deg: &VLP16_ELEVATION_DEG,
    azimuth_offset_deg: &[0.0; 16],
    vertical_offset_mm: &VLP16_VERTICAL_MM,
    distance_resolution_m: 0.002,
    laser_us: 2.304,
    lasers_per_group: 1,
    group_pattern_us: &[0.0],
    banks_fire_together: true,
    firing_pause: (usize::MAX, 0.0),
    timestamp_after_first_us: 0.0,
    dual_strongest_first: false,
    sequence_us: 55.296,
    sequences_per_block: 2,
    timestamp_mark: TimestampMark::FirstFiring,
    layout: LAYOUT_1206,
    return_modes: &MODES,
    rotation_hz: (5.0, 20.0),
};

/// Velodyne Puck Hi-Res: the VLP-16's packets and timing, elevations within +-10 deg.
pub const PUCK_HI_RES: SensorModel = SensorModel {
    name: "Puck Hi-Res",
    product_id: 0x24,
    elevation_deg: &HIRES_ELEVATION_DEG,
    vertical_offset_mm: &HIRES_VERTICAL_MM,
    ..VLP16
};

/// Elevations of the VLP-32C by laser id (VLP-32C user manual 63-9325, Table 9-1).
const VLP32C_ELEVATION_DEG: [f64; 32] = [
    -25.0, -1.0, -1.667, -15.639, -11.31, 0.0, -0.667, -8.843, -7.254, 0.333, -0.333, -6.148,
    -5.333, 1.333, 0.667, -4.0, -4.667, 1.667, 1.0, -3.667, -3.333, 3.333, 2.333, -2.667, -3.0,
    7.0, 4.667, -2.333, -2.0, 15.0, 10.333, -1.333,
];

/// Azimuth offsets of the VLP-32C by laser id in degrees (VLP-32C user manual, Table
/// 9-1: added to the block azimuth).
const VLP32C_AZIMUTH_OFFSET_DEG: [f64; 32] = [
    1.4, -4.2, 1.4, -1.4, 1.4, -1.4, 4.2, -1.4, 1.4, -4.2, 1.4, -1.4, 4.2, -1.4, 4.2, -1.4, 1.4,
    -4.2, 1.4, -4.2, 4.2, -1.4, 1.4, -1.4, 1.4, -1.4, 1.4, -4.2, 4.2, -1.4, 1.4, -1.4,
];

/// Velodyne VLP-32C: 32 lasers fired in 16 pairs 2.304 us apart, one 55.296 us firing
/// sequence per block, 4 mm distance units (VLP-32C user manual 63-9325: 9.3 packet
/// format, 9.5 firing timing: time offset = 55.296 us * sequence + 2.304 us *
/// floor(channel / 2), as velodyne_decoder's `buildTimings` cites it; timestamp = first
/// firing of the packet; product id 0x28).
pub const VLP32C: SensorModel = SensorModel {
    name: "VLP-32C",
    product_id: 0x28,
    lasers: 32,
    elevation_deg: &VLP32C_ELEVATION_DEG,
    azimuth_offset_deg: &VLP32C_AZIMUTH_OFFSET_DEG,
    vertical_offset_mm: &[],
    distance_resolution_m: 0.004,
    laser_us: 2.304,
    lasers_per_group: 2,
    group_pattern_us: &[0.0, 0.0],
    banks_fire_together: true,
    firing_pause: (usize::MAX, 0.0),
    timestamp_after_first_us: 0.0,
    dual_strongest_first: false,
    sequence_us: 55.296,
    sequences_per_block: 1,
    timestamp_mark: TimestampMark::FirstFiring,
    layout: LAYOUT_1206,
    return_modes: &MODES,
    rotation_hz: (5.0, 20.0),
};

/// Default elevations of the HDL-64E by laser id (0-31 upper bank, 32-63 lower bank).
/// The HDL-64E manuals print no beam table (each unit ships its own `db.xml`); these are
/// the angles of VeloView's default `HDL-64.xml` (Kitware LidarView, as bundled in
/// velodyne_decoder's `HDL-64E_S3-VeloView.yml`), to two decimals. Other units differ by
/// up to about 2.5 deg per laser: read the unit's calibration where it matters.
const HDL64E_ELEVATION_DEG: [f64; 64] = [
    -6.29, -5.89, 1.15, 1.52, -5.61, -5.29, -7.63, -7.26, -4.96, -4.57, -7.0, -6.64, -2.22, -1.84,
    -4.26, -3.84, -1.55, -1.18, -3.58, -3.2, -0.88, -0.52, -2.91, -2.53, 1.86, 2.19, -0.15, 0.23,
    2.51, 2.81, 0.48, 0.89, -21.77, -21.28, -10.67, -9.99, -20.91, -20.34, -23.95, -23.44, -19.74,
    -19.14, -22.82, -22.27, -15.58, -15.15, -18.72, -18.19, -14.72, -14.16, -17.77, -17.3, -13.73,
    -13.13, -16.71, -16.2, -9.37, -9.15, -12.37, -12.05, -8.65, -8.11, -11.59, -11.12,
];

/// Default azimuth offsets of the HDL-64E in degrees (same source as the elevations; the
/// negated `rotCorrection_`, so point azimuth = block azimuth + offset).
const HDL64E_AZIMUTH_OFFSET_DEG: [f64; 64] = [
    4.55, 2.46, -3.3, -5.52, 0.23, -2.05, 1.01, -1.22, -4.05, -6.29, -3.26, -5.54, 4.55, 2.28,
    5.31, 3.09, 0.26, -2.01, 1.04, -1.21, -4.01, -6.23, -3.23, -5.46, 4.58, 2.32, 5.35, 3.09, 0.28,
    -1.95, 1.1, -1.18, 7.45, 3.99, -5.01, -8.21, 0.51, -2.96, 1.82, -1.69, -6.43, -9.79, -5.23,
    -8.7, 7.27, 3.8, 8.63, 5.1, 0.46, -2.86, 1.75, -1.69, -6.13, -9.49, -5.01, -8.43, 7.0, 3.76,
    8.3, 4.98, 0.45, -2.65, 1.71, -1.54,
];

/// Velodyne HDL-64E S2: upper and lower bank fire together, one firing per block pair
/// every 48 us, lasers in groups of 4 (6 us apart, 0/1.26/2.46/3.66 us within a group):
/// the "laser firing time table" of the HDL-64E S2 manual as velodyne_decoder 3 applies
/// it; timestamp = first firing of the packet (velodyne_decoder); 6 firings a packet in
/// single return mode (288 us), 3 in dual.
pub const HDL64E_S2: SensorModel = SensorModel {
    name: "HDL-64E S2",
    product_id: 0,
    lasers: 64,
    elevation_deg: &HDL64E_ELEVATION_DEG,
    azimuth_offset_deg: &HDL64E_AZIMUTH_OFFSET_DEG,
    vertical_offset_mm: &[],
    distance_resolution_m: 0.002,
    laser_us: 6.0,
    lasers_per_group: 4,
    group_pattern_us: &[0.0, 1.26, 2.46, 3.66],
    banks_fire_together: true,
    firing_pause: (usize::MAX, 0.0),
    timestamp_after_first_us: 0.0,
    dual_strongest_first: true,
    sequence_us: 48.0,
    sequences_per_block: 1,
    timestamp_mark: TimestampMark::FirstFiring,
    layout: LAYOUT_HDL64E,
    return_modes: &[ReturnMode::Strongest, ReturnMode::Dual],
    rotation_hz: (5.0, 15.0),
};

/// Velodyne HDL-64E S3: as the S2 with a 57.6 us firing, groups 7.2 us apart and
/// 0/1.3/2.5/3.7 us within a group (HDL-64E S3 manual's firing time table, as
/// velodyne_decoder 3 applies it); 345.6 us per packet in single return mode.
pub const HDL64E_S3: SensorModel = SensorModel {
    name: "HDL-64E S3",
    laser_us: 7.2,
    group_pattern_us: &[0.0, 1.3, 2.5, 3.7],
    sequence_us: 57.6,
    ..HDL64E_S2
};

/// Elevations of KITTI's HDL-64E by laser id, in degrees from each laser's own origin
/// (which lies [`HDL64E_KITTI_VERTICAL_MM`] above the scan's origin), measured on real
/// scans by `examples/kitti_beams.rs tune` (docs/guide/datasets.md, "KITTI's beams"):
/// KITTI stores each laser's sweep in turn, so the scan lines recovered from the point
/// order name each point's laser (line `k` from the top is ring `63 - k`; a ring is
/// mapped to the laser id the default table puts at that ring, so both tables order the
/// lasers alike). Tuning scans: KITTI object 000000, 000001 and 000002 (cut to the
/// camera's view: rings 17 to 63) and SemanticKITTI 000964 (all 64 rings).
/// - Rings 25-63: a least-squares line z = h tan(el) + dz through the ring's points (h
///   the horizontal distance) beyond 2 m, from the scans where the points lie on one line
///   (median residual under 5 mm; the object scans' is 0.2-0.3 mm, as for points computed
///   from the unit's calibration) over at least 1 m of h.
/// - Rings 17-24 (ground near the car, under 1 m of h): the median of atan2(z - dz, h)
///   with the lower bank's median offset; 10-90 % spread 0.01 deg.
/// - Rings 0-16, only in the SemanticKITTI scan, whose points lie off one line by 1-10 mm
///   (a moved or noisier scan): the same median, with a 10-90 % spread of about 0.9 deg
///   against 0.5 deg between beams: the least sure part of the table.
///
/// The default table ([`HDL64E_S2`]) lies 0.87 to 1.33 deg above these (+2.81 to -23.95
/// deg against +1.94 to -25.16); seen from the scan's origin at 10 m, where the offsets
/// lift KITTI's beams, they differ from it by -0.73 to +0.32 deg.
const HDL64E_KITTI_ELEVATION_DEG: [f64; 64] = [
    -7.287, -6.999, 0.181, 0.579, -6.676, -6.329, -8.711, -8.311, -5.958, -5.611, -8.058, -7.679,
    -3.236, -2.874, -5.251, -4.914, -2.547, -2.210, -4.588, -4.216, -1.836, -1.497, -3.937, -3.540,
    0.872, 1.305, -1.204, -0.803, 1.574, 1.937, -0.452, -0.089, -23.083, -22.566, -11.599, -10.957,
    -22.087, -21.417, -25.163, -24.648, -20.884, -20.328, -24.152, -23.554, -16.621, -16.211,
    -19.852, -19.411, -15.686, -15.215, -18.903, -18.414, -14.620, -14.067, -17.807, -17.272,
    -10.471, -10.063, -13.500, -13.054, -9.573, -9.026, -12.572, -12.116,
];

/// Vertical offsets of KITTI's HDL-64E lasers by laser id in millimetres: the height of
/// each laser's origin above the scan's origin, which KITTI's points carry (the line fits
/// of [`HDL64E_KITTI_ELEVATION_DEG`]; upper bank 197.8 to 209.2 mm, lower bank 123.7 to
/// 125.9 mm; rings without a fit take the lower bank's median, 124.7 mm).
const HDL64E_KITTI_VERTICAL_MM: [f64; 64] = [
    198.9, 199.2, 206.8, 207.3, 199.5, 199.8, 197.8, 198.2, 200.1, 200.5, 198.4, 198.6, 203.2,
    203.7, 200.8, 201.2, 203.5, 205.3, 201.5, 201.8, 205.8, 205.8, 202.3, 202.7, 207.7, 208.2,
    206.0, 205.5, 208.7, 209.2, 206.0, 206.4, 124.7, 124.7, 124.0, 124.4, 124.7, 124.7, 124.7,
    124.7, 124.7, 124.7, 124.7, 124.7, 124.7, 124.7, 124.7, 124.7, 124.7, 124.7, 124.7, 124.7,
    124.7, 124.7, 124.7, 124.7, 124.7, 125.1, 124.7, 124.7, 125.2, 125.9, 124.7, 123.7,
];

/// KITTI's HDL-64E S2: the S2's timing and packets with the unit's own beams, measured on
/// KITTI scans (elevation and vertical offset per laser); `--sensor hdl64e-kitti`.
pub const HDL64E_KITTI: SensorModel = SensorModel {
    name: "HDL-64E S2 (KITTI)",
    elevation_deg: &HDL64E_KITTI_ELEVATION_DEG,
    vertical_offset_mm: &HDL64E_KITTI_VERTICAL_MM,
    ..HDL64E_S2
};

/// Elevations of the VLS-128 (Alpha Prime) by laser id in degrees: the manual's beam
/// table as velodyne_decoder's `calib_db.cpp` (AlphaPrime) and the ROS driver's
/// `VLS128.yaml` (VeloView's calibration) carry it.
#[allow(clippy::approx_constant)] // -6.28 deg is laser 26's elevation, not tau
const VLS128_ELEVATION_DEG: [f64; 128] = [
    -11.742, -1.99, 3.4, -5.29, -0.78, 4.61, -4.08, 1.31, -6.5, -1.11, 4.28, -4.41, 0.1, 6.48,
    -3.2, 2.19, -3.86, 1.53, -9.244, -1.77, 2.74, -5.95, -0.56, 4.83, -2.98, 2.41, -6.28, -0.89,
    3.62, -5.07, 0.32, 7.58, -0.34, 5.18, -3.64, 1.75, -25.0, -2.43, 2.96, -5.73, 0.54, 9.7, -2.76,
    2.63, -7.65, -1.55, 3.84, -4.85, 3.18, -5.51, -0.12, 5.73, -4.3, 1.09, -16.042, -2.21, 4.06,
    -4.63, 0.76, 15.0, -3.42, 1.97, -6.85, -1.33, -5.62, -0.23, 5.43, -3.53, 0.98, -19.582, -2.32,
    3.07, -4.74, 0.65, 11.75, -2.65, 1.86, -7.15, -1.44, 3.95, -2.1, 3.29, -5.4, -0.01, 4.5, -4.19,
    1.2, -13.565, -1.22, 4.17, -4.52, 0.87, 6.08, -3.31, 2.08, -6.65, 1.42, -10.346, -1.88, 3.51,
    -6.06, -0.67, 4.72, -3.97, 2.3, -6.39, -1.0, 4.39, -5.18, 0.21, 6.98, -3.09, 4.98, -3.75, 1.64,
    -8.352, -2.54, 2.85, -5.84, -0.45, 8.43, -2.87, 2.52, -6.17, -1.66, 3.73, -4.96, 0.43,
];

/// Azimuth offsets of the VLS-128 by laser id in degrees (point azimuth = block
/// azimuth + offset, the negated `rot_correction` of the same tables): eight columns
/// of lasers, laser `k` in column `k % 8`.
const VLS128_AZIMUTH_OFFSET_DEG: [f64; 128] = {
    const COLUMNS: [f64; 8] = [6.354, 4.548, 2.732, 0.911, -0.911, -2.732, -4.548, -6.354];
    let mut t = [0.0; 128];
    let mut k = 0;
    while k < 128 {
        t[k] = COLUMNS[k % 8];
        k += 1;
    }
    t
};

/// Velodyne VLS-128 (Alpha Prime), firmware 5.2.3 and later: 128 lasers in 4 banks of
/// 32 ([`LAYOUT_VLS128`]), fired 8 at a time every 2.89 us channel, 16 groups and 4
/// idle channels (two after the 8th group, two at the end) a 57.8 us sequence: laser
/// `k` fires `(k / 8 + 2 * (k / 64)) * 2.89` us into its sequence; 3 sequences a
/// packet in single return mode (173.4 us), 1 in dual (57.8 us); the timestamp marks
/// 7 us after the packet's first firing (velodyne_decoder's `buildTimings`, after
/// VeloView); 4 mm distance units; product id 0xA1.
pub const VLS128: SensorModel = SensorModel {
    name: "VLS-128",
    product_id: 0xA1,
    lasers: 128,
    elevation_deg: &VLS128_ELEVATION_DEG,
    azimuth_offset_deg: &VLS128_AZIMUTH_OFFSET_DEG,
    vertical_offset_mm: &[],
    distance_resolution_m: 0.004,
    laser_us: 2.89,
    lasers_per_group: 8,
    group_pattern_us: &[0.0; 8],
    banks_fire_together: false,
    firing_pause: (64, 2.0 * 2.89),
    timestamp_after_first_us: 7.0,
    dual_strongest_first: false,
    sequence_us: 20.0 * 2.89,
    sequences_per_block: 1,
    timestamp_mark: TimestampMark::FirstFiring,
    layout: LAYOUT_VLS128,
    return_modes: &MODES,
    rotation_hz: (5.0, 20.0),
};

/// Velodyne VLS-128 with firmware 5.1 (manual Rev 3): the same packets with an 8/3 us
/// channel, 53.33 us a sequence, 160 us a packet in single return mode
/// (velodyne_decoder's `correctVls128Timings`, after VeloView; the ROS driver's
/// 2.665 us and 53.3 us), the timestamp 6.46 us after the first firing (velodyne_decoder's
/// 7 us scaled by 8/3 / 2.89). Told from the current firmware by the packet period.
pub const VLS128_FW51: SensorModel = SensorModel {
    name: "VLS-128 fw5.1",
    laser_us: 8.0 / 3.0,
    firing_pause: (64, 2.0 * 8.0 / 3.0),
    sequence_us: 20.0 * 8.0 / 3.0,
    // velodyne_decoder scales its whole timing table, the 7 us included, by the channel
    // ratio; no source gives this firmware's own value (the ROS driver's is 8.7 us).
    timestamp_after_first_us: 7.0 * (8.0 / 3.0) / 2.89,
    ..VLS128
};

/// Every described sensor; the Puck LITE is the VLP-16 (same product id, same angles:
/// manual 9.3.1.7).
pub const MODELS: [&SensorModel; 8] = [
    &HDL32E,
    &VLP16,
    &PUCK_HI_RES,
    &VLP32C,
    &HDL64E_S2,
    &HDL64E_S3,
    &VLS128,
    &VLS128_FW51,
];

impl SensorModel {
    /// Duration of one block in microseconds (all its firing sequences).
    pub fn block_us(&self) -> f64 {
        self.sequence_us * self.sequences_per_block as f64
    }

    /// Packet blocks of one firing: one per bank, twice that in dual mode.
    pub fn blocks_per_firing(&self, mode: ReturnMode) -> usize {
        self.layout.blocks_per_firing(mode)
    }

    /// Lasers of one bank (the lasers a block carries per firing sequence).
    pub fn lasers_per_bank(&self) -> usize {
        self.lasers / self.layout.banks()
    }

    /// Firing sequences per packet in a return mode (dual mode repeats each block).
    pub fn sequences_per_packet(&self, mode: ReturnMode) -> usize {
        self.layout.blocks / self.blocks_per_firing(mode) * self.sequences_per_block
    }

    /// Nominal time between data packets in microseconds (553 us for the HDL-32E,
    /// 1327 us for the VLP-16, 664 us for the VLP-32C, 288 and 346 us for the HDL-64E
    /// S2 and S3 in single return mode, half in dual mode).
    pub fn packet_period_us(&self, mode: ReturnMode) -> f64 {
        self.sequences_per_packet(mode) as f64 * self.sequence_us
    }

    /// Firing sequence and laser id of channel `channel` of a bank-0 block.
    pub fn channel_laser(&self, channel: usize) -> (usize, usize) {
        self.block_laser(0, channel)
    }

    /// Firing sequence and laser id of channel `channel` of packet block `block` in
    /// single return mode (the HDL-64E's lower-bank blocks carry lasers 32-63); see
    /// [`SensorModel::block_laser_in`] for dual-mode packets.
    pub fn block_laser(&self, block: usize, channel: usize) -> (usize, usize) {
        self.block_laser_in(ReturnMode::Strongest, block, channel)
    }

    /// Firing sequence and laser id of channel `channel` of packet block `block` in a
    /// return mode (the VLS-128's dual-mode blocks pair up per bank).
    pub fn block_laser_in(&self, mode: ReturnMode, block: usize, channel: usize) -> (usize, usize) {
        let per = self.lasers_per_bank();
        let bank = self.layout.block_bank(mode, block);
        (channel / per, bank * per + channel % per)
    }

    /// Time of a laser's firing after the start of its firing sequence, in microseconds
    /// (lasers of different banks with the same index fire together on the HDL-64E; the
    /// VLS-128's banks fire one after the other, with a pause mid-sequence).
    pub fn laser_offset_us(&self, laser: usize) -> f64 {
        let j = if self.banks_fire_together {
            laser % self.lasers_per_bank()
        } else {
            laser
        };
        let g = self.lasers_per_group;
        let pause = if laser >= self.firing_pause.0 {
            self.firing_pause.1
        } else {
            0.0
        };
        (j / g) as f64 * self.laser_us + self.group_pattern_us[j % g] + pause
    }

    /// Firing sequence index within the packet of sequence `sequence` of block `block`
    /// (VLP-16 manual 9.5: dual-return block pairs share their sequences).
    pub fn sequence_index(&self, mode: ReturnMode, block: usize, sequence: usize) -> usize {
        block / self.blocks_per_firing(mode) * self.sequences_per_block + sequence
    }

    /// True when packet block `block` of a dual-mode packet holds strongest returns.
    pub fn dual_block_is_strongest(&self, block: usize) -> bool {
        let second = self.layout.dual_group(block) == 1;
        second != self.dual_strongest_first
    }

    /// Time of one laser's firing relative to the packet timestamp, in microseconds.
    pub fn firing_offset_us(&self, mode: ReturnMode, sequence_index: usize, laser: usize) -> f64 {
        let from_first = sequence_index as f64 * self.sequence_us + self.laser_offset_us(laser);
        match self.timestamp_mark {
            TimestampMark::FirstFiring => from_first - self.timestamp_after_first_us,
            TimestampMark::LastFiring => {
                let last = (self.sequences_per_packet(mode) - 1) as f64 * self.sequence_us
                    + self.laser_offset_us(self.lasers - 1);
                from_first - last
            }
        }
    }

    /// The `Return::block` value of a return: the index of its 1-sequence half block in
    /// firing order, with dual returns adjacent. Single mode: `sequence_index` (0..11 on
    /// the HDL-32E, 0..23 on the VLP-16, 0..5 on the HDL-64E, whose laser ids tell the
    /// banks apart). Dual mode: `2 * sequence_index + strongest`, so `block & !1` names
    /// the firing as the spurious-return slots expect and the even value is the last
    /// return. For the HDL-32E this is the packet block, as before.
    pub fn return_block(&self, mode: ReturnMode, block: usize, sequence: usize) -> usize {
        let s = self.sequence_index(mode, block, sequence);
        if mode == ReturnMode::Dual {
            2 * s + usize::from(self.dual_block_is_strongest(block))
        } else {
            s
        }
    }

    /// Packet block and channel of a return from its `Return::block` and laser id (the
    /// inverse of [`SensorModel::return_block`]), for encoders.
    pub fn packet_position(
        &self,
        mode: ReturnMode,
        return_block: usize,
        laser: usize,
    ) -> (usize, usize) {
        let per = self.sequences_per_block;
        let lanes = self.lasers_per_bank();
        let (bank, lane) = (laser / lanes, laser % lanes);
        let (s, group) = if mode == ReturnMode::Dual {
            let strongest = return_block & 1 == 1;
            (
                return_block / 2,
                usize::from(strongest != self.dual_strongest_first),
            )
        } else {
            (return_block, 0)
        };
        let block = self.layout.block_of(mode, s / per, group, bank);
        (block, (s % per) * lanes + lane)
    }

    /// Ring of each laser id: ids sorted by elevation, 0 lowest (ties in id order).
    pub fn rings(&self) -> Vec<u8> {
        let mut ids: Vec<usize> = (0..self.lasers).collect();
        ids.sort_by(|&a, &b| self.elevation_deg[a].total_cmp(&self.elevation_deg[b]));
        let mut rings = vec![0u8; self.lasers];
        for (ring, &id) in ids.iter().enumerate() {
            rings[id] = ring as u8;
        }
        rings
    }
}

/// The described model a user names: its name in any case, spaces, dashes, dots and
/// underscores ignored ("vlp16", "HDL-64E S3", "hdl64e_s3", "vls128", "VLS-128 fw5.1");
/// "puck lite" is the VLP-16. `Err` lists the names.
pub fn by_name(name: &str) -> Result<&'static SensorModel, String> {
    let key = |s: &str| -> String {
        s.chars()
            .filter(|c| c.is_ascii_alphanumeric())
            .map(|c| c.to_ascii_lowercase())
            .collect()
    };
    let want = key(name);
    if want == "pucklite" {
        return Ok(&VLP16);
    }
    MODELS
        .iter()
        .copied()
        .find(|m| key(m.name) == want)
        .ok_or_else(|| {
            let names: Vec<&str> = MODELS.iter().map(|m| m.name).collect();
            format!("unknown sensor '{name}': one of {}", names.join(", "))
        })
}

/// The described model writing a product id byte, if any.
pub fn by_product(product: u8) -> Option<&'static SensorModel> {
    MODELS
        .iter()
        .copied()
        .find(|m| m.layout.product_at.is_some() && m.product_id == product)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn vlp16_timing_matches_the_manual() {
        // Manual 9.5: 16 x 2.304 us + 18.43 us recharge = 55.296 us; 24 sequences per
        // packet; the last point of a packet fires 23 * 55.296 + 15 * 2.304 us in.
        assert!((16.0 * VLP16.laser_us + 18.432 - VLP16.sequence_us).abs() < 1e-9);
        assert!((VLP16.packet_period_us(ReturnMode::Strongest) - 1327.104).abs() < 1e-9);
        assert!((VLP16.packet_period_us(ReturnMode::Dual) - 663.552).abs() < 1e-9);
        assert!((HDL32E.packet_period_us(ReturnMode::Strongest) - 552.96).abs() < 1e-9);
        let last = VLP16.firing_offset_us(ReturnMode::Strongest, 23, 15);
        assert!((last - (23.0 * 55.296 + 15.0 * 2.304)).abs() < 1e-9);
        // Manual's dual-mode table: block 3, channel 20 is sequence (3 - 1) + 1 = 3.
        assert_eq!(VLP16.sequence_index(ReturnMode::Dual, 3, 1), 3);
        assert_eq!(VLP16.sequence_index(ReturnMode::Strongest, 3, 1), 7);
    }

    #[test]
    fn vlp16_rings_interleave_as_in_the_manual() {
        let rings = VLP16.rings();
        for (id, &ring) in rings.iter().enumerate() {
            let want = if id % 2 == 0 { id / 2 } else { 8 + id / 2 };
            assert_eq!(usize::from(ring), want, "laser {id}");
        }
        assert_eq!(PUCK_HI_RES.rings(), rings);
    }

    #[test]
    fn vls128_layout_and_timing_follow_velodyne_decoder() {
        // velodyne_decoder's buildTimings (AlphaPrime): block i, channel j fires
        // (i / 4) * 20 ch + (dsr / 8 + dsr / 64 * 2) * ch - 7 us, dsr = 32 * (i % 4) + j,
        // the whole table scaled by ch / 2.89 once it has seen the 160 us packet spacing
        // of firmware 5.1 (correctVls128Timings).
        for (model, ch) in [(&VLS128, 2.89), (&VLS128_FW51, 8.0 / 3.0)] {
            let mode = ReturnMode::Strongest;
            for i in 0..12 {
                for j in 0..32 {
                    let dsr = 32 * (i % 4) + j;
                    let want = (i / 4) as f64 * 20.0 * ch + (dsr / 8 + dsr / 64 * 2) as f64 * ch
                        - 7.0 * ch / 2.89;
                    let (seq, laser) = model.block_laser_in(mode, i, j);
                    assert_eq!(laser, dsr, "block {i} channel {j}");
                    let s = model.sequence_index(mode, i, seq);
                    let got = model.firing_offset_us(mode, s, laser);
                    assert!(
                        (got - want).abs() < 1e-9,
                        "block {i} channel {j}: {got} {want}"
                    );
                }
            }
            // Dual: blocks 2b (last) and 2b + 1 (strongest) carry bank b; blocks 8-11
            // are empty; one sequence a packet.
            let dual = ReturnMode::Dual;
            assert_eq!(model.layout.used_blocks(dual), 8);
            for b in 0..8 {
                let (seq, laser) = model.block_laser_in(dual, b, 5);
                assert_eq!((seq, laser), (0, 32 * (b / 2) + 5), "dual block {b}");
                assert_eq!(
                    model.dual_block_is_strongest(b),
                    b % 2 == 1,
                    "dual block {b}"
                );
                assert_eq!(
                    model.layout.expected_flag(dual, b),
                    [0xEEFF, 0xDDFF, 0xCCFF, 0xBBFF][b / 2]
                );
            }
            assert!(
                (model.packet_period_us(dual) * 3.0 - model.packet_period_us(mode)).abs() < 1e-9
            );
        }
        assert!((VLS128.packet_period_us(ReturnMode::Strongest) - 173.4).abs() < 1e-9);
        assert!((VLS128_FW51.packet_period_us(ReturnMode::Strongest) - 160.0).abs() < 1e-9);
        assert_eq!(by_product(0xA1).map(|m| m.name), Some("VLS-128"));
        for (name, want) in [
            ("vls128", "VLS-128"),
            ("VLS-128 FW5.1", "VLS-128 fw5.1"),
            ("hdl64e_s3", "HDL-64E S3"),
            ("Puck LITE", "VLP-16"),
            ("hdl-32e", "HDL-32E"),
        ] {
            assert_eq!(by_name(name).map(|m| m.name), Ok(want));
        }
        let e = by_name("hdl64e").unwrap_err();
        assert!(
            e.contains("'hdl64e'") && e.contains("HDL-64E S2, HDL-64E S3"),
            "{e}"
        );
        // Rings: laser 36 (-25 deg) lowest, laser 59 (15 deg) highest.
        let rings = VLS128.rings();
        assert_eq!((rings[36], rings[59]), (0, 127));
    }

    #[test]
    fn return_block_and_packet_position_are_inverse() {
        for model in MODELS {
            for mode in MODES {
                let mut seen = std::collections::HashSet::new();
                if !model.return_modes.contains(&mode) {
                    continue;
                }
                for block in 0..model.layout.used_blocks(mode) {
                    for channel in 0..32 {
                        let (sequence, laser) = model.block_laser_in(mode, block, channel);
                        let rb = model.return_block(mode, block, sequence);
                        assert!(seen.insert((rb, laser)), "{} {mode:?}", model.name);
                        assert_eq!(model.packet_position(mode, rb, laser), (block, channel));
                    }
                }
            }
        }
    }
}

/// The HDL-32E description holds the constants the HDL-32E kernel of the decoder uses
/// (its packet layout, timing, product byte, built-in calibration).
#[cfg(test)]
mod hdl32e_constants {
    use super::*;
    use crate::sensor::calibration::Calibration;
    use crate::sensor::packet as p;

    #[test]
    fn hdl32e_description_holds_the_decoder_constants() {
        let m = &HDL32E;
        let l = &m.layout;
        assert_eq!(l.payload_bytes, p::DATA_PACKET_BYTES);
        assert_eq!(l.blocks, p::BLOCKS);
        assert_eq!(l.block_bytes, p::BLOCK_BYTES);
        assert_eq!(l.block_flag, p::BLOCK_FLAG);
        assert_eq!(l.channels, p::LASERS);
        assert_eq!(m.lasers, p::LASERS);
        assert_eq!(m.product_id, p::PRODUCT_HDL32E);
        assert_eq!(m.laser_us, p::LASER_US);
        assert_eq!(m.sequence_us, p::FIRING_US);
        assert_eq!(m.sequences_per_block, 1);
        let first = m.firing_offset_us(ReturnMode::Strongest, 0, 0);
        assert!((first - p::FIRST_FIRING_OFFSET_US).abs() < 1e-9, "{first}");
        let cal = Calibration::builtin();
        assert_eq!(m.distance_resolution_m, cal.distance_resolution_m);
        for (k, laser) in cal.lasers.iter().enumerate() {
            assert_eq!(m.elevation_deg[k], laser.elevation_deg, "laser {k}");
            assert_eq!(
                m.azimuth_offset_deg[k], laser.azimuth_offset_deg,
                "laser {k}"
            );
        }
        assert_eq!(m.rings(), cal.rings().to_vec());
        // The accessors read the bytes the HDL-32E packet functions read.
        let mut payload = vec![0u8; 1206];
        for (i, b) in payload.iter_mut().enumerate() {
            *b = (i * 7 % 251) as u8;
        }
        assert_eq!(l.timestamp_us(&payload), p::timestamp_us(&payload));
        assert_eq!(
            payload[l.return_mode_at.unwrap()],
            p::return_mode_byte(&payload)
        );
        assert_eq!(payload[l.product_at.unwrap()], p::product_byte(&payload));
        for b in 0..12 {
            assert_eq!(l.block_azimuth(&payload, b), p::block_azimuth(&payload, b));
        }
        for (id, name) in [(0x21, "HDL-32E"), (0x22, "VLP-16"), (0x24, "Puck Hi-Res")] {
            assert_eq!(by_product(id).map(|m| m.name), Some(name));
            assert_eq!(p::product_name(id), name);
        }
    }
}
