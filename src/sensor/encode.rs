//! Data packet encoding for any [`SensorModel`]: the inverse of [`super::decode`], for
//! writing noisy returns back into a capture (`--pcap-out`) and for synthesizing
//! captures of any described sensor.
//!
//! A return's place in the packet is [`SensorModel::packet_position`] of its
//! `Return::block` and laser id (the inverse of the decoder's
//! [`SensorModel::return_block`]); only its 3-byte slot (distance u16 LE, intensity u8)
//! is written. Re-encoding a packet ([`reencode_packet`]) clears every slot of the
//! blocks its mode uses, then writes each return: block flags, azimuths, timestamp,
//! mode, product and status bytes, and the blocks a dual-mode VLS-128 packet leaves
//! empty stay as they were, so decode -> re-encode -> decode gives the same returns
//! (tests: every model, every mode). [`encode_packet`] builds a packet from nothing:
//! the model's flags, one azimuth per firing on every block of that firing, the
//! timestamp and the mode and product bytes (status bytes on the HDL-64E).
//!
//! The HDL-32E's packets from firings ([`encode_data_packet`]), for the scene
//! synthesizer and tests that need captures with known content, follow the HDL-32E
//! manual (appendix B).

use super::packet::{
    BLOCKS, BLOCK_BYTES, BLOCK_FLAG, DATA_PACKET_BYTES, LASERS, POSITION_PACKET_BYTES,
    PRODUCT_HDL32E,
};
use super::{ReturnMode, SensorModel};
use crate::frame::Return;

/// The mode byte a sensor writes for a return mode (0x37, 0x38, 0x39; 0x00 for the old
/// firmware's unknown mode).
pub fn mode_byte(mode: ReturnMode) -> u8 {
    match mode {
        ReturnMode::Strongest => 0x37,
        ReturnMode::Last => 0x38,
        ReturnMode::Dual => 0x39,
        ReturnMode::Unknown => 0x00,
    }
}

/// Clears every return slot (distance and intensity) of the blocks a data packet's mode
/// uses and returns the mode. The payload must be a data packet of the model's layout.
pub fn clear_returns(model: &SensorModel, payload: &mut [u8]) -> Result<ReturnMode, String> {
    let lay = &model.layout;
    if payload.len() != lay.payload_bytes {
        return Err(format!(
            "data packet of {} bytes where the {} sends {}",
            payload.len(),
            model.name,
            lay.payload_bytes
        ));
    }
    if let Some(b) = lay.bad_flag(payload) {
        return Err(format!(
            "block {b} has not the {}'s flag (payload byte offset {})",
            model.name,
            b * lay.block_bytes
        ));
    }
    let mode = lay
        .return_mode(payload)
        .map_err(|byte| format!("unknown return mode byte 0x{byte:02x}"))?;
    for block in 0..lay.used_blocks(mode) {
        let at = lay.channel_at(block, 0);
        payload[at..at + 3 * lay.channels].fill(0);
    }
    Ok(mode)
}

/// Writes one slot: raw distance `raw` and intensity of laser `laser` in the firing
/// slot `return_block` (a `Return::block` value) of a packet in mode `mode`. An
/// out-of-range laser or block is an error naming it, never a write elsewhere.
pub fn write_slot(
    model: &SensorModel,
    mode: ReturnMode,
    payload: &mut [u8],
    return_block: usize,
    laser: usize,
    raw: u16,
    intensity: u8,
) -> Result<(), String> {
    if laser >= model.lasers {
        return Err(format!(
            "laser {laser}: the {} has {}",
            model.name, model.lasers
        ));
    }
    let (block, channel) = model.packet_position(mode, return_block, laser);
    if block >= model.layout.used_blocks(mode) {
        return Err(format!(
            "firing slot {return_block} is past the {}'s packet in {mode:?} mode",
            model.name
        ));
    }
    let at = model.layout.channel_at(block, channel);
    payload[at..at + 2].copy_from_slice(&raw.to_le_bytes());
    payload[at + 2] = intensity;
    Ok(())
}

/// Writes a decoded (or noisy) return's raw distance and intensity into its slot.
pub fn write_return(
    model: &SensorModel,
    mode: ReturnMode,
    payload: &mut [u8],
    r: &Return,
) -> Result<(), String> {
    write_slot(
        model,
        mode,
        payload,
        usize::from(r.block),
        usize::from(r.laser),
        r.raw_distance,
        r.intensity,
    )
}

/// Re-encodes a data packet in place from its returns: every slot of the used blocks
/// cleared, then each return written (decode with `DualSelect::Both`, then this, gives
/// back the packet up to the intensity bytes of empty slots).
pub fn reencode_packet(
    model: &SensorModel,
    payload: &mut [u8],
    returns: &[Return],
) -> Result<(), String> {
    let mode = clear_returns(model, payload)?;
    for r in returns {
        write_return(model, mode, payload, r)?;
    }
    Ok(())
}

/// The header of a packet built by [`encode_packet`].
#[derive(Clone, Debug, PartialEq)]
pub struct PacketHeader {
    /// Return mode (the mode byte; on the HDL-64E only the block order and azimuths
    /// show it, and Last cannot be told from Strongest).
    pub mode: ReturnMode,
    /// Azimuth of each firing of the packet in hundredths of a degree (0..35999),
    /// written on every block of that firing.
    pub firing_azimuths: Vec<u16>,
    /// Timestamp, microseconds past the hour.
    pub timestamp_us: u32,
    /// Bytes 1204-1205 on layouts without mode and product bytes (the HDL-64E's status
    /// type and value); ignored elsewhere.
    pub status: (u8, u8),
}

/// A data packet of the model from a header and its slots `(return_block, laser, raw
/// distance, intensity)`; slots not given are empty (distance 0).
pub fn encode_packet(
    model: &SensorModel,
    header: &PacketHeader,
    slots: impl IntoIterator<Item = (usize, usize, u16, u8)>,
) -> Result<Vec<u8>, String> {
    let lay = &model.layout;
    let mode = header.mode;
    if !model.return_modes.contains(&mode) {
        return Err(format!("the {} has no {mode:?} return mode", model.name));
    }
    let firings = lay.blocks / lay.blocks_per_firing(mode);
    if header.firing_azimuths.len() != firings {
        return Err(format!(
            "{} firing azimuths where a {} packet in {mode:?} mode has {firings}",
            header.firing_azimuths.len(),
            model.name
        ));
    }
    let mut p = vec![0u8; lay.payload_bytes];
    let per = lay.blocks_per_firing(mode);
    for block in 0..lay.used_blocks(mode) {
        let at = block * lay.block_bytes;
        let az = header.firing_azimuths[block / per] % 36000;
        p[at..at + 2].copy_from_slice(&lay.expected_flag(mode, block).to_le_bytes());
        p[at + 2..at + 4].copy_from_slice(&az.to_le_bytes());
    }
    // Empty blocks (the VLS-128's last four in dual mode): no flag, the firing's
    // azimuth, as velodyne_decoder's mock dual capture writes them.
    for block in lay.used_blocks(mode)..lay.blocks {
        let at = block * lay.block_bytes + 2;
        p[at..at + 2].copy_from_slice(&(header.firing_azimuths[0] % 36000).to_le_bytes());
    }
    let t = lay.timestamp_at;
    p[t..t + 4].copy_from_slice(&header.timestamp_us.to_le_bytes());
    match (lay.return_mode_at, lay.product_at) {
        (Some(m), Some(id)) => {
            p[m] = mode_byte(mode);
            p[id] = model.product_id;
        }
        _ => {
            p[t + 4] = header.status.0;
            p[t + 5] = header.status.1;
        }
    }
    for (rb, laser, raw, intensity) in slots {
        write_slot(model, mode, &mut p, rb, laser, raw, intensity)?;
    }
    Ok(p)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sensor::decode::{DualSelect, ModelDecoder};
    use crate::sensor::MODELS;

    /// A data packet of `model` in `mode` from the layout (not from [`encode_packet`]):
    /// flags per the manuals' block order, azimuths of a 10 Hz turn, pseudo-random
    /// distances with about a tenth empty (intensity 0 there).
    fn packet(model: &SensorModel, mode: ReturnMode, seed: u32) -> Vec<u8> {
        let lay = &model.layout;
        let banks = lay.banks();
        let dual = mode == ReturnMode::Dual;
        let per = banks * if dual { 2 } else { 1 };
        let used = 12 / per * per;
        let mut p = vec![0u8; 1206];
        let mut x = seed.wrapping_mul(2_654_435_761).wrapping_add(12345);
        for b in 0..12 {
            let bank = if dual && lay.dual_pairs_adjacent {
                (b / 2) % banks
            } else {
                b % banks
            };
            let flag: u16 = [0xEEFF, 0xDDFF, 0xCCFF, 0xBBFF][bank];
            let az = ((35_900 + 20 * (b / per)) % 36_000) as u16;
            p[b * 100..b * 100 + 2].copy_from_slice(&flag.to_le_bytes());
            p[b * 100 + 2..b * 100 + 4].copy_from_slice(&az.to_le_bytes());
            for c in 0..32 {
                x ^= x << 13;
                x ^= x >> 17;
                x ^= x << 5;
                let at = b * 100 + 4 + 3 * c;
                if b < used && !x.is_multiple_of(10) {
                    p[at..at + 2].copy_from_slice(&((x >> 8) as u16 | 1).to_le_bytes());
                    p[at + 2] = (x >> 3) as u8;
                } else if b >= used {
                    // The VLS-128's empty blocks: whatever is there must survive.
                    p[at] = 0x5A;
                }
            }
        }
        p[1200..1204].copy_from_slice(&(1_000_000 + seed).to_le_bytes());
        if lay.return_mode_at.is_some() {
            p[1204] = mode_byte(mode);
            p[1205] = model.product_id;
        } else {
            p[1204] = b'H';
            p[1205] = 7;
            if dual {
                // HDL-64E dual: the second return group repeats the azimuths.
                for b in 0..12 {
                    let az = ((35_900 + 20 * (b / 4)) % 36_000) as u16;
                    p[b * 100 + 2..b * 100 + 4].copy_from_slice(&az.to_le_bytes());
                }
            }
        }
        p
    }

    #[test]
    fn decode_reencode_decode_is_exact_for_every_model_and_mode() {
        for model in MODELS {
            for &mode in model.return_modes {
                for seed in 0..3 {
                    let original = packet(model, mode, seed);
                    let dec = ModelDecoder::new(model, true, DualSelect::Both);
                    let mut first = Vec::new();
                    dec.decode_packet(&original, 0, 0.0, &mut first).unwrap();
                    assert!(
                        first.len() > 200,
                        "{} {mode:?}: {}",
                        model.name,
                        first.len()
                    );
                    let mut again = original.clone();
                    // Scribble over every slot first: re-encoding must clear them.
                    for b in 0..model.layout.used_blocks(mode) {
                        again[b * 100 + 4..b * 100 + 100].fill(0xAB);
                    }
                    reencode_packet(model, &mut again, &first).unwrap();
                    assert!(again == original, "{} {mode:?} seed {seed}", model.name);
                    let mut second = Vec::new();
                    dec.decode_packet(&again, 0, 0.0, &mut second).unwrap();
                    assert_eq!(first, second, "{} {mode:?}", model.name);
                    // From nothing: the header and the slots give the same packet.
                    let per = model.layout.blocks_per_firing(mode);
                    let header = PacketHeader {
                        mode,
                        firing_azimuths: (0..12 / per)
                            .map(|f| model.layout.block_azimuth(&original, f * per))
                            .collect(),
                        timestamp_us: model.layout.timestamp_us(&original),
                        status: (original[1204], original[1205]),
                    };
                    let slots = first.iter().map(|r| {
                        let (b, l) = (usize::from(r.block), usize::from(r.laser));
                        (b, l, r.raw_distance, r.intensity)
                    });
                    let built = encode_packet(model, &header, slots).unwrap();
                    let used = model.layout.used_blocks(mode) * 100;
                    assert!(built[..used] == original[..used], "{} {mode:?}", model.name);
                    assert!(built[1200..] == original[1200..], "{} {mode:?}", model.name);
                    let mut third = Vec::new();
                    dec.decode_packet(&built, 0, 0.0, &mut third).unwrap();
                    assert_eq!(first, third, "{} {mode:?}", model.name);
                }
            }
        }
    }

    #[test]
    fn bad_slots_and_packets_are_refused() {
        let m = &crate::sensor::VLS128;
        let mut p = packet(m, ReturnMode::Dual, 1);
        let e = write_slot(m, ReturnMode::Dual, &mut p, 2, 5, 1, 1).unwrap_err();
        assert!(e.contains("firing slot 2"), "{e}");
        let e = write_slot(m, ReturnMode::Dual, &mut p, 0, 128, 1, 1).unwrap_err();
        assert!(e.contains("laser 128"), "{e}");
        p[200] = 0;
        let e = clear_returns(m, &mut p).unwrap_err();
        assert!(e.contains("block 2") && e.contains("200"), "{e}");
        let e = clear_returns(m, &mut p[..1000]).unwrap_err();
        assert!(e.contains("1000 bytes"), "{e}");
        let header = PacketHeader {
            mode: ReturnMode::Strongest,
            firing_azimuths: vec![0; 2],
            timestamp_us: 0,
            status: (0, 0),
        };
        let e = encode_packet(m, &header, []).unwrap_err();
        assert!(
            e.contains("2 firing azimuths") && e.contains("has 3"),
            "{e}"
        );
    }
}

/// Time covered by one data packet (12 blocks) in microseconds.
pub const PACKET_DURATION_US: f64 = 552.96;
/// Microseconds in one hour: the sensor timestamp wraps at this value.
pub const US_PER_HOUR: u64 = 3_600_000_000;

/// One firing (block) of a data packet, in packet units.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FiringBlock {
    /// Azimuth in hundredths of a degree, 0..35999.
    pub azimuth: u16,
    /// Raw distance per laser id, in 2 mm units (0 = no return).
    pub distances: [u16; LASERS],
    /// Intensity byte per laser id.
    pub intensities: [u8; LASERS],
}

impl Default for FiringBlock {
    fn default() -> Self {
        FiringBlock {
            azimuth: 0,
            distances: [0; LASERS],
            intensities: [0; LASERS],
        }
    }
}

/// Writes one 1206-byte data packet payload into `out`.
///
/// `timestamp_us` is microseconds past the top of the hour and marks the end of the
/// packet (the first firing happened 542.592 us earlier). Azimuths
/// above 35999 are written as given: the encoder is also used to build malformed
/// packets for tests.
pub fn encode_data_packet_into(
    blocks: &[FiringBlock; BLOCKS],
    timestamp_us: u32,
    return_mode: u8,
    out: &mut [u8; DATA_PACKET_BYTES],
) {
    for (b, block) in blocks.iter().enumerate() {
        let base = b * BLOCK_BYTES;
        out[base..base + 2].copy_from_slice(&BLOCK_FLAG.to_le_bytes());
        out[base + 2..base + 4].copy_from_slice(&block.azimuth.to_le_bytes());
        for j in 0..LASERS {
            let at = base + 4 + 3 * j;
            out[at..at + 2].copy_from_slice(&block.distances[j].to_le_bytes());
            out[at + 2] = block.intensities[j];
        }
    }
    out[1200..1204].copy_from_slice(&timestamp_us.to_le_bytes());
    out[1204] = return_mode;
    out[1205] = PRODUCT_HDL32E;
}

/// Returns one 1206-byte data packet payload (see [`encode_data_packet_into`]).
pub fn encode_data_packet(
    blocks: &[FiringBlock; BLOCKS],
    timestamp_us: u32,
    return_mode: u8,
) -> [u8; DATA_PACKET_BYTES] {
    let mut out = [0u8; DATA_PACKET_BYTES];
    encode_data_packet_into(blocks, timestamp_us, return_mode, &mut out);
    out
}

/// Largest raw distance a packet can hold (2 mm units: 131.07 m at the default resolution).
pub const MAX_RAW_DISTANCE: u16 = u16::MAX;

/// Raw packet distance of a range in metres: `round((range - offset) / resolution)`, the
/// inverse of the decoder's `raw * resolution + offset`.
///
/// `None` when the sensor could not report the range: the quotient rounds to zero or
/// less (0 means "no return" on the wire) or above [`MAX_RAW_DISTANCE`], or is not finite.
#[inline]
pub fn raw_distance(range_m: f32, offset_m: f32, resolution_m: f32) -> Option<u16> {
    let q = ((range_m - offset_m) / resolution_m).round();
    if q.is_finite() && q >= 1.0 && q <= f32::from(MAX_RAW_DISTANCE) {
        Some(q as u16)
    } else {
        None
    }
}

/// Writes one return slot (distance and intensity) of block `block`, laser `laser` into
/// a data packet payload; the block flag and azimuth are left as they are.
#[inline]
pub fn write_return_slot(payload: &mut [u8], block: usize, laser: usize, raw: u16, intensity: u8) {
    let at = block * BLOCK_BYTES + 4 + 3 * laser;
    payload[at..at + 2].copy_from_slice(&raw.to_le_bytes());
    payload[at + 2] = intensity;
}

/// Returns a 512-byte position packet payload with a `$GPRMC` sentence.
///
/// Layout (HDL-32E manual, checked against a real capture): bytes 0..13 unused,
/// 14..37 gyro/temperature/acceleration (left zero: no IMU data), 198..201 GPS
/// timestamp (little-endian u32, µs past the hour), 206.. the NMEA sentence
/// terminated by CR LF, the rest zero. The sentence carries the UTC time derived from
/// `timestamp_us` on a fixed date and position, status `A`.
pub fn encode_position_packet(timestamp_us: u32) -> [u8; POSITION_PACKET_BYTES] {
    let mut out = [0u8; POSITION_PACKET_BYTES];
    out[198..202].copy_from_slice(&timestamp_us.to_le_bytes());
    let secs = timestamp_us / 1_000_000;
    let body = format!(
        "GPRMC,00{:02}{:02},A,3707.8324,N,12139.2864,W,000.0,000.0,010124,013.8,E,D",
        secs / 60,
        secs % 60
    );
    let checksum = body.bytes().fold(0u8, |acc, b| acc ^ b);
    let sentence = format!("${body}*{checksum:02X}\r\n");
    // The sentence is at most 82 bytes (NMEA limit), far inside the packet.
    out[206..206 + sentence.len()].copy_from_slice(sentence.as_bytes());
    out
}

#[cfg(test)]
mod hdl32e_tests {
    use super::*;

    #[test]
    fn data_packet_layout_matches_the_manual() {
        let mut blocks = [FiringBlock::default(); BLOCKS];
        blocks[0].azimuth = 35999;
        blocks[0].distances[0] = 0x1234;
        blocks[0].intensities[0] = 7;
        blocks[11].azimuth = 258;
        blocks[11].distances[31] = 0xBEEF;
        blocks[11].intensities[31] = 255;
        let p = encode_data_packet(&blocks, 0x0102_0304, 0x37);
        assert_eq!(&p[0..2], &[0xFF, 0xEE]);
        assert_eq!(u16::from_le_bytes([p[2], p[3]]), 35999);
        assert_eq!(&p[4..7], &[0x34, 0x12, 7]);
        assert_eq!(&p[1100..1102], &[0xFF, 0xEE]);
        assert_eq!(u16::from_le_bytes([p[1102], p[1103]]), 258);
        assert_eq!(&p[1197..1200], &[0xEF, 0xBE, 255]);
        assert_eq!(&p[1200..1204], &[4, 3, 2, 1]);
        assert_eq!(p[1204], 0x37);
        assert_eq!(p[1205], 0x21);
    }

    #[test]
    fn position_packet_carries_timestamp_and_valid_nmea() {
        let p = encode_position_packet(125_000_000);
        assert_eq!(p.len(), 512);
        assert_eq!(
            u32::from_le_bytes([p[198], p[199], p[200], p[201]]),
            125_000_000
        );
        let end = p[206..].iter().position(|&b| b == b'\n').unwrap() + 206;
        let s = std::str::from_utf8(&p[206..=end]).unwrap();
        assert!(s.starts_with("$GPRMC,000205,A,"), "{s}");
        let (body, tail) = s[1..].split_once('*').unwrap();
        let sum = body.bytes().fold(0u8, |a, b| a ^ b);
        assert_eq!(tail.trim_end(), format!("{sum:02X}"));
        assert!(s.len() <= 82, "NMEA sentences are at most 82 bytes");
    }

    #[test]
    fn raw_distance_rounds_and_refuses_what_the_wire_cannot_hold() {
        assert_eq!(raw_distance(10.0, 0.0, 0.002), Some(5000));
        assert_eq!(raw_distance(10.0011, 0.0, 0.002), Some(5001));
        assert_eq!(raw_distance(10.1, 0.1, 0.002), Some(5000));
        assert_eq!(raw_distance(0.002, 0.0, 0.002), Some(1));
        assert_eq!(raw_distance(0.0009, 0.0, 0.002), None);
        assert_eq!(raw_distance(-1.0, 0.0, 0.002), None);
        assert_eq!(raw_distance(131.07, 0.0, 0.002), Some(65535));
        assert_eq!(raw_distance(131.072, 0.0, 0.002), None);
        assert_eq!(raw_distance(f32::NAN, 0.0, 0.002), None);
    }

    #[test]
    fn return_slot_lands_where_the_decoder_reads_it() {
        let mut p = encode_data_packet(&[FiringBlock::default(); BLOCKS], 0, 0x37);
        write_return_slot(&mut p, 11, 31, 0xBEEF, 9);
        assert_eq!(&p[1197..1200], &[0xEF, 0xBE, 9]);
        write_return_slot(&mut p, 0, 0, 0x0102, 3);
        assert_eq!(&p[4..7], &[0x02, 0x01, 3]);
    }
}
