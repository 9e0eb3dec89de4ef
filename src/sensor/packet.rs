//! Layout of HDL-32E data and position packets (see the manual, appendix B).

/// UDP payload size of a data packet.
pub const DATA_PACKET_BYTES: usize = 1206;
/// UDP payload size of a position (telemetry) packet.
pub const POSITION_PACKET_BYTES: usize = 512;
/// Default UDP port of data packets.
pub const DATA_PORT: u16 = 2368;
/// Default UDP port of position packets.
pub const POSITION_PORT: u16 = 8308;
/// Blocks (firings, or half firings in dual mode) per data packet.
pub const BLOCKS: usize = 12;
/// Bytes per block.
pub const BLOCK_BYTES: usize = 100;
/// Lasers per block.
pub const LASERS: usize = 32;
/// Block flag, read as a little-endian u16 (bytes FF EE).
pub const BLOCK_FLAG: u16 = 0xEEFF;
/// Duration of one firing cycle in microseconds.
pub const FIRING_US: f64 = 46.08;
/// Time between two lasers of one firing in microseconds.
pub const LASER_US: f64 = 1.152;
/// Offset from the packet timestamp (end of packet) to the first firing, in microseconds.
pub const FIRST_FIRING_OFFSET_US: f64 = -542.592;
/// Product id byte of the HDL-32E.
pub const PRODUCT_HDL32E: u8 = 0x21;

/// Return mode byte of a data packet.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum ReturnMode {
    /// 0x37: strongest return.
    Strongest,
    /// 0x38: last return.
    Last,
    /// 0x39: dual return, blocks in pairs.
    Dual,
    /// 0x00 (old firmware): treated as strongest.
    Unknown,
}

impl ReturnMode {
    /// Parses the return mode byte; `None` for values no firmware writes.
    pub fn from_byte(byte: u8) -> Option<Self> {
        match byte {
            0x37 => Some(ReturnMode::Strongest),
            0x38 => Some(ReturnMode::Last),
            0x39 => Some(ReturnMode::Dual),
            0x00 => Some(ReturnMode::Unknown),
            _ => None,
        }
    }
}

/// Name of a Velodyne product id byte.
pub fn product_name(id: u8) -> &'static str {
    match id {
        0x00 => "unknown (old firmware)",
        0x21 => "HDL-32E",
        0x22 => "VLP-16",
        0x24 => "Puck Hi-Res",
        0x28 => "VLP-32C",
        0x31 => "Velarray",
        0xA1 => "VLS-128",
        _ => "unknown product",
    }
}

/// True when a UDP payload has the size and block flags of a data packet.
#[inline]
pub fn is_data_packet(payload: &[u8]) -> bool {
    payload.len() == DATA_PACKET_BYTES
        && (0..BLOCKS).all(|b| {
            let at = b * BLOCK_BYTES;
            u16::from_le_bytes([payload[at], payload[at + 1]]) == BLOCK_FLAG
        })
}

/// Azimuth of a block in hundredths of a degree.
#[inline]
pub fn block_azimuth(payload: &[u8], block: usize) -> u16 {
    let at = block * BLOCK_BYTES + 2;
    u16::from_le_bytes([payload[at], payload[at + 1]])
}

/// Packet timestamp in microseconds past the hour (marks the end of the packet).
#[inline]
pub fn timestamp_us(payload: &[u8]) -> u32 {
    u32::from_le_bytes([payload[1200], payload[1201], payload[1202], payload[1203]])
}

/// Return mode byte.
#[inline]
pub fn return_mode_byte(payload: &[u8]) -> u8 {
    payload[1204]
}

/// Product id byte.
#[inline]
pub fn product_byte(payload: &[u8]) -> u8 {
    payload[1205]
}
