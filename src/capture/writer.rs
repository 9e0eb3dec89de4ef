//! Capture writers: classic libpcap (either byte order, micro- or nanosecond
//! timestamps) and pcapng, carrying UDP datagrams in Ethernet + IPv4 frames as an
//! HDL-32E puts them on the wire.

use std::io::{self, Write};

/// Source IPv4 address of the sensor (factory default).
pub const SENSOR_IP: [u8; 4] = [192, 168, 1, 201];
/// Destination IPv4 address (broadcast, as the sensor sends by default).
pub const BROADCAST_IP: [u8; 4] = [255, 255, 255, 255];
/// Source MAC address used in written frames (Velodyne OUI 60:76:88).
pub const SENSOR_MAC: [u8; 6] = [0x60, 0x76, 0x88, 0x00, 0x00, 0x01];
/// Link type of written captures: Ethernet.
pub const LINKTYPE_ETHERNET: u32 = 1;
/// Length of the Ethernet + IPv4 + UDP headers in front of each payload.
pub const HEADERS_LEN: usize = 14 + 20 + 8;
/// Largest UDP payload a frame can carry (IPv4 total length is a u16).
pub const MAX_UDP_PAYLOAD: usize = 65_535 - 28;

/// Byte order of a classic pcap file.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum ByteOrder {
    /// Little-endian (what x86 machines write).
    #[default]
    Little,
    /// Big-endian.
    Big,
}

/// Timestamp resolution of a classic pcap file.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum TimeResolution {
    /// Microseconds (magic a1b2c3d4).
    #[default]
    Micro,
    /// Nanoseconds (magic a1b23c4d).
    Nano,
}

/// Options of a classic pcap file.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct PcapOptions {
    /// Byte order of headers.
    pub byte_order: ByteOrder,
    /// Timestamp resolution.
    pub resolution: TimeResolution,
}

/// Builds an Ethernet + IPv4 + UDP frame around `payload` into `frame` (cleared first).
///
/// The IPv4 header checksum is valid; the UDP checksum is 0 ("not computed"), which
/// IPv4 allows and which is what many capture tools see for sensor traffic. The IPv4
/// identification field counts frames so that consecutive frames differ.
pub fn build_udp_frame(
    frame: &mut Vec<u8>,
    ident: u16,
    src_port: u16,
    dst_port: u16,
    payload: &[u8],
) -> io::Result<()> {
    if payload.len() > MAX_UDP_PAYLOAD {
        return Err(io::Error::new(
            io::ErrorKind::InvalidInput,
            format!("UDP payload of {} bytes is too large", payload.len()),
        ));
    }
    frame.clear();
    // Ethernet: broadcast destination, sensor source, EtherType IPv4.
    frame.extend_from_slice(&[0xFF; 6]);
    frame.extend_from_slice(&SENSOR_MAC);
    frame.extend_from_slice(&[0x08, 0x00]);
    // IPv4 header, 20 bytes, no options.
    let total_len = (20 + 8 + payload.len()) as u16;
    let mut ip = [0u8; 20];
    ip[0] = 0x45;
    ip[2..4].copy_from_slice(&total_len.to_be_bytes());
    ip[4..6].copy_from_slice(&ident.to_be_bytes());
    ip[6] = 0x40; // don't fragment
    ip[8] = 64; // TTL
    ip[9] = 17; // UDP
    ip[12..16].copy_from_slice(&SENSOR_IP);
    ip[16..20].copy_from_slice(&BROADCAST_IP);
    let checksum = ipv4_checksum(&ip);
    ip[10..12].copy_from_slice(&checksum.to_be_bytes());
    frame.extend_from_slice(&ip);
    // UDP header.
    frame.extend_from_slice(&src_port.to_be_bytes());
    frame.extend_from_slice(&dst_port.to_be_bytes());
    frame.extend_from_slice(&((8 + payload.len()) as u16).to_be_bytes());
    frame.extend_from_slice(&[0, 0]);
    frame.extend_from_slice(payload);
    Ok(())
}

/// Internet checksum of an IPv4 header whose checksum field is zero.
pub fn ipv4_checksum(header: &[u8]) -> u16 {
    let mut sum: u32 = header
        .chunks(2)
        .map(|c| u32::from(u16::from_be_bytes([c[0], *c.get(1).unwrap_or(&0)])))
        .sum();
    while sum > 0xFFFF {
        sum = (sum & 0xFFFF) + (sum >> 16);
    }
    !(sum as u16)
}

/// Streaming classic libpcap writer of UDP datagrams in Ethernet frames.
pub struct PcapWriter<W: Write> {
    out: W,
    options: PcapOptions,
    frame: Vec<u8>,
    ident: u16,
    records: u64,
}

impl<W: Write> PcapWriter<W> {
    /// Writes the global header (little-endian, microseconds, Ethernet) and returns the writer.
    pub fn new(out: W) -> io::Result<Self> {
        Self::with_options(out, PcapOptions::default())
    }

    /// Writes the global header with the given byte order and resolution.
    pub fn with_options(mut out: W, options: PcapOptions) -> io::Result<Self> {
        let magic: u32 = match options.resolution {
            TimeResolution::Micro => 0xa1b2_c3d4,
            TimeResolution::Nano => 0xa1b2_3c4d,
        };
        let mut header = Vec::with_capacity(24);
        put_u32(&mut header, options.byte_order, magic);
        put_u16(&mut header, options.byte_order, 2);
        put_u16(&mut header, options.byte_order, 4);
        put_u32(&mut header, options.byte_order, 0); // thiszone
        put_u32(&mut header, options.byte_order, 0); // sigfigs
        put_u32(&mut header, options.byte_order, 65_535); // snaplen
        put_u32(&mut header, options.byte_order, LINKTYPE_ETHERNET);
        out.write_all(&header)?;
        Ok(PcapWriter {
            out,
            options,
            frame: Vec::with_capacity(HEADERS_LEN + 1206),
            ident: 0,
            records: 0,
        })
    }

    /// Appends one record: a UDP datagram captured at `ts_us` microseconds since the epoch.
    pub fn write_udp(
        &mut self,
        ts_us: u64,
        src_port: u16,
        dst_port: u16,
        payload: &[u8],
    ) -> io::Result<()> {
        build_udp_frame(&mut self.frame, self.ident, src_port, dst_port, payload)?;
        self.ident = self.ident.wrapping_add(1);
        let secs = ts_us / 1_000_000;
        let frac = match self.options.resolution {
            TimeResolution::Micro => ts_us % 1_000_000,
            TimeResolution::Nano => (ts_us % 1_000_000) * 1000,
        };
        let secs = u32::try_from(secs).map_err(|_| {
            io::Error::new(
                io::ErrorKind::InvalidInput,
                "timestamp past 2106 does not fit classic pcap",
            )
        })?;
        let order = self.options.byte_order;
        let mut header = Vec::with_capacity(16);
        put_u32(&mut header, order, secs);
        put_u32(&mut header, order, frac as u32);
        put_u32(&mut header, order, self.frame.len() as u32);
        put_u32(&mut header, order, self.frame.len() as u32);
        self.out.write_all(&header)?;
        self.out.write_all(&self.frame)?;
        self.records += 1;
        Ok(())
    }

    /// Number of records written so far.
    pub fn records(&self) -> u64 {
        self.records
    }

    /// Flushes and returns the underlying writer.
    pub fn into_inner(mut self) -> io::Result<W> {
        self.out.flush()?;
        Ok(self.out)
    }
}

/// Streaming pcapng writer: one Section Header Block, one Interface Description Block
/// (Ethernet, microsecond timestamps), then one Enhanced Packet Block per datagram.
/// Written in little-endian byte order.
pub struct PcapNgWriter<W: Write> {
    out: W,
    frame: Vec<u8>,
    ident: u16,
    records: u64,
}

impl<W: Write> PcapNgWriter<W> {
    /// Writes the section header and interface description and returns the writer.
    pub fn new(mut out: W) -> io::Result<Self> {
        let mut shb = Vec::with_capacity(28);
        put_u32(&mut shb, ByteOrder::Little, 0x0A0D_0D0A);
        put_u32(&mut shb, ByteOrder::Little, 28);
        put_u32(&mut shb, ByteOrder::Little, 0x1A2B_3C4D);
        put_u16(&mut shb, ByteOrder::Little, 1);
        put_u16(&mut shb, ByteOrder::Little, 0);
        shb.extend_from_slice(&(-1i64).to_le_bytes()); // section length unknown
        put_u32(&mut shb, ByteOrder::Little, 28);
        out.write_all(&shb)?;
        // Interface Description Block without options: the default resolution is µs.
        let mut idb = Vec::with_capacity(20);
        put_u32(&mut idb, ByteOrder::Little, 1);
        put_u32(&mut idb, ByteOrder::Little, 20);
        put_u16(&mut idb, ByteOrder::Little, LINKTYPE_ETHERNET as u16);
        put_u16(&mut idb, ByteOrder::Little, 0);
        put_u32(&mut idb, ByteOrder::Little, 65_535);
        put_u32(&mut idb, ByteOrder::Little, 20);
        out.write_all(&idb)?;
        Ok(PcapNgWriter {
            out,
            frame: Vec::with_capacity(HEADERS_LEN + 1206),
            ident: 0,
            records: 0,
        })
    }

    /// Appends one Enhanced Packet Block carrying a UDP datagram captured at `ts_us` µs.
    pub fn write_udp(
        &mut self,
        ts_us: u64,
        src_port: u16,
        dst_port: u16,
        payload: &[u8],
    ) -> io::Result<()> {
        build_udp_frame(&mut self.frame, self.ident, src_port, dst_port, payload)?;
        self.ident = self.ident.wrapping_add(1);
        let padded = self.frame.len().div_ceil(4) * 4;
        let block_len = (32 + padded) as u32;
        let mut head = Vec::with_capacity(28);
        put_u32(&mut head, ByteOrder::Little, 6);
        put_u32(&mut head, ByteOrder::Little, block_len);
        put_u32(&mut head, ByteOrder::Little, 0); // interface id
        put_u32(&mut head, ByteOrder::Little, (ts_us >> 32) as u32);
        put_u32(&mut head, ByteOrder::Little, ts_us as u32);
        put_u32(&mut head, ByteOrder::Little, self.frame.len() as u32);
        put_u32(&mut head, ByteOrder::Little, self.frame.len() as u32);
        self.out.write_all(&head)?;
        self.out.write_all(&self.frame)?;
        self.out.write_all(&[0u8; 3][..padded - self.frame.len()])?;
        self.out.write_all(&block_len.to_le_bytes())?;
        self.records += 1;
        Ok(())
    }

    /// Number of packet blocks written so far.
    pub fn records(&self) -> u64 {
        self.records
    }

    /// Flushes and returns the underlying writer.
    pub fn into_inner(mut self) -> io::Result<W> {
        self.out.flush()?;
        Ok(self.out)
    }
}

fn put_u16(buf: &mut Vec<u8>, order: ByteOrder, v: u16) {
    match order {
        ByteOrder::Little => buf.extend_from_slice(&v.to_le_bytes()),
        ByteOrder::Big => buf.extend_from_slice(&v.to_be_bytes()),
    }
}

fn put_u32(buf: &mut Vec<u8>, order: ByteOrder, v: u32) {
    match order {
        ByteOrder::Little => buf.extend_from_slice(&v.to_le_bytes()),
        ByteOrder::Big => buf.extend_from_slice(&v.to_be_bytes()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ipv4_checksum_of_a_known_header() {
        // Worked example from RFC 1071 style references (wikipedia IPv4 header checksum).
        let mut h = [
            0x45, 0x00, 0x00, 0x73, 0x00, 0x00, 0x40, 0x00, 0x40, 0x11, 0x00, 0x00, 0xc0, 0xa8,
            0x00, 0x01, 0xc0, 0xa8, 0x00, 0xc7,
        ];
        assert_eq!(ipv4_checksum(&h), 0xb861);
        h[10..12].copy_from_slice(&0xb861u16.to_be_bytes());
        // A header with a valid checksum sums to zero.
        assert_eq!(ipv4_checksum(&h), 0);
    }

    #[test]
    fn frame_layout() {
        let mut f = Vec::new();
        build_udp_frame(&mut f, 7, 2368, 2368, &[1, 2, 3]).unwrap();
        assert_eq!(f.len(), HEADERS_LEN + 3);
        assert_eq!(&f[12..14], &[0x08, 0x00]);
        assert_eq!(&f[26..30], &SENSOR_IP);
        assert_eq!(ipv4_checksum(&f[14..34]), 0);
        assert_eq!(u16::from_be_bytes([f[34], f[35]]), 2368);
        assert_eq!(u16::from_be_bytes([f[38], f[39]]), 11);
        assert_eq!(&f[42..], &[1, 2, 3]);
    }
}
