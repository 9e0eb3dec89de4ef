//! HDL-32E packet encoder: the inverse of the decoder, used by the scene synthesizer
//! and by tests that need captures with known content.
//!
//! Layouts follow the HDL-32E manual (appendix B) and `docs/hdl32e.md`.

/// Length of a data packet's UDP payload.
pub const DATA_PAYLOAD_LEN: usize = 1206;
/// Length of a position (telemetry) packet's UDP payload.
pub const POSITION_PAYLOAD_LEN: usize = 512;
/// UDP port the sensor sends data packets to.
pub const DATA_PORT: u16 = 2368;
/// UDP port the sensor sends position packets to.
pub const POSITION_PORT: u16 = 8308;
/// Blocks (firings) in one data packet.
pub const BLOCKS_PER_PACKET: usize = 12;
/// Lasers in one block.
pub const LASERS_PER_BLOCK: usize = 32;
/// Bytes in one block: flag, azimuth and 32 three-byte returns.
pub const BLOCK_LEN: usize = 100;
/// Block flag bytes as they appear in the packet (0xEEFF little-endian).
pub const BLOCK_FLAG: [u8; 2] = [0xFF, 0xEE];
/// Return mode byte for single strongest return.
pub const RETURN_MODE_STRONGEST: u8 = 0x37;
/// Product id byte of the HDL-32E.
pub const PRODUCT_ID_HDL32E: u8 = 0x21;
/// Duration of one firing cycle (block) in microseconds.
pub const BLOCK_DURATION_US: f64 = 46.08;
/// Time between two lasers of a block in microseconds.
pub const LASER_SPACING_US: f64 = 1.152;
/// Time from the first firing of a packet to its timestamp, in microseconds.
pub const FIRST_FIRING_OFFSET_US: f64 = 542.592;
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
    pub distances: [u16; LASERS_PER_BLOCK],
    /// Intensity byte per laser id.
    pub intensities: [u8; LASERS_PER_BLOCK],
}

impl Default for FiringBlock {
    fn default() -> Self {
        FiringBlock {
            azimuth: 0,
            distances: [0; LASERS_PER_BLOCK],
            intensities: [0; LASERS_PER_BLOCK],
        }
    }
}

/// Writes one 1206-byte data packet payload into `out`.
///
/// `timestamp_us` is microseconds past the top of the hour and marks the end of the
/// packet (the first firing happened [`FIRST_FIRING_OFFSET_US`] earlier). Azimuths
/// above 35999 are written as given: the encoder is also used to build malformed
/// packets for tests.
pub fn encode_data_packet_into(
    blocks: &[FiringBlock; BLOCKS_PER_PACKET],
    timestamp_us: u32,
    return_mode: u8,
    out: &mut [u8; DATA_PAYLOAD_LEN],
) {
    for (b, block) in blocks.iter().enumerate() {
        let base = b * BLOCK_LEN;
        out[base..base + 2].copy_from_slice(&BLOCK_FLAG);
        out[base + 2..base + 4].copy_from_slice(&block.azimuth.to_le_bytes());
        for j in 0..LASERS_PER_BLOCK {
            let at = base + 4 + 3 * j;
            out[at..at + 2].copy_from_slice(&block.distances[j].to_le_bytes());
            out[at + 2] = block.intensities[j];
        }
    }
    out[1200..1204].copy_from_slice(&timestamp_us.to_le_bytes());
    out[1204] = return_mode;
    out[1205] = PRODUCT_ID_HDL32E;
}

/// Returns one 1206-byte data packet payload (see [`encode_data_packet_into`]).
pub fn encode_data_packet(
    blocks: &[FiringBlock; BLOCKS_PER_PACKET],
    timestamp_us: u32,
    return_mode: u8,
) -> [u8; DATA_PAYLOAD_LEN] {
    let mut out = [0u8; DATA_PAYLOAD_LEN];
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
    let at = block * BLOCK_LEN + 4 + 3 * laser;
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
pub fn encode_position_packet(timestamp_us: u32) -> [u8; POSITION_PAYLOAD_LEN] {
    let mut out = [0u8; POSITION_PAYLOAD_LEN];
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
mod tests {
    use super::*;

    #[test]
    fn data_packet_layout_matches_the_manual() {
        let mut blocks = [FiringBlock::default(); BLOCKS_PER_PACKET];
        blocks[0].azimuth = 35999;
        blocks[0].distances[0] = 0x1234;
        blocks[0].intensities[0] = 7;
        blocks[11].azimuth = 258;
        blocks[11].distances[31] = 0xBEEF;
        blocks[11].intensities[31] = 255;
        let p = encode_data_packet(&blocks, 0x0102_0304, RETURN_MODE_STRONGEST);
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
        let mut p = encode_data_packet(&[FiringBlock::default(); BLOCKS_PER_PACKET], 0, 0x37);
        write_return_slot(&mut p, 11, 31, 0xBEEF, 9);
        assert_eq!(&p[1197..1200], &[0xEF, 0xBE, 9]);
        write_return_slot(&mut p, 0, 0, 0x0102, 3);
        assert_eq!(&p[4..7], &[0x02, 0x01, 3]);
    }
}
