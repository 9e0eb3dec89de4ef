//! Streaming reader of pcap and pcapng captures: yields UDP datagrams one at a time.
//!
//! Memory stays bounded by the read buffer whatever the capture's length.

pub mod link;
pub mod writer;

use crate::error::{Error, Result};
use pcap_parser::pcapng::Block;
use pcap_parser::traits::PcapReaderIterator;
use pcap_parser::{PcapBlockOwned, PcapError};
use serde::Serialize;
use std::fs::File;
use std::io::{Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use link::Parsed;

/// Read buffer size; a record larger than this is treated as corrupt (a UDP
/// datagram is at most 64 KiB plus headers).
const BUFFER_BYTES: usize = 1 << 18;

/// Container format of a capture.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Format {
    /// Classic libpcap.
    Pcap,
    /// pcapng.
    Pcapng,
}

/// Counters of what the reader met, for `info` and diagnostics.
#[derive(Clone, Debug, Default, Serialize)]
pub struct CaptureStats {
    /// Packet records read (pcap records, pcapng enhanced and simple packet blocks).
    pub records: u64,
    /// Whole IPv4/UDP datagrams handed on.
    pub udp: u64,
    /// IPv4 fragments skipped.
    pub fragments: u64,
    /// IPv4 packets of other protocols skipped.
    pub not_udp: u64,
    /// Frames that are not IPv4 (or of an unsupported link type) skipped.
    pub not_ipv4: u64,
    /// Frames cut short by the snapshot length or with malformed headers.
    pub malformed: u64,
    /// Byte offset where the capture ends mid-record, if it does.
    pub truncated_at: Option<u64>,
}

/// One UDP datagram from the capture.
#[derive(Clone, Copy, Debug)]
pub struct Datagram<'a> {
    /// Zero-based index of the packet record in the capture.
    pub record: u32,
    /// Byte offset of the record in the file.
    pub offset: u64,
    /// Capture timestamp in nanoseconds since the Unix epoch.
    pub ts_ns: u64,
    /// UDP source port.
    pub src_port: u16,
    /// UDP destination port.
    pub dst_port: u16,
    /// Byte offset of the UDP payload in the file (where `payload` starts), so that a
    /// writer can patch the payload in a byte-for-byte copy of the capture.
    pub payload_offset: u64,
    /// UDP payload.
    pub payload: &'a [u8],
}

/// First four bytes of the file headers the reader knows: classic pcap in either byte
/// order with microsecond or nanosecond timestamps, and the pcapng section header block.
const MAGICS: [[u8; 4]; 5] = [
    [0xd4, 0xc3, 0xb2, 0xa1],
    [0xa1, 0xb2, 0xc3, 0xd4],
    [0x4d, 0x3c, 0xb2, 0xa1],
    [0xa1, 0xb2, 0x3c, 0x4d],
    [0x0a, 0x0d, 0x0d, 0x0a],
];

/// True when `head` starts like a pcap or pcapng file.
pub fn starts_like_capture(head: &[u8]) -> bool {
    head.get(..4).is_some_and(|h| MAGICS.iter().any(|m| h == m))
}

/// The message for a stream that does not start like a capture.
const NOT_A_CAPTURE: &str = "not a pcap or pcapng capture (unknown file header); \
                             record the sensor with tcpdump, Wireshark or VeloView";

/// Checks the first bytes of a capture (at most 4 are looked at): the file header
/// decides pcap or pcapng, so anything else is refused before the rest is read.
pub fn check_file_header(first: &[u8], path: &Path) -> Result<()> {
    let fail = |message: &str| {
        Err(Error::Capture {
            path: path.to_path_buf(),
            message: message.into(),
        })
    };
    match first.get(..4) {
        _ if first.is_empty() => fail("the file is empty, not a pcap or pcapng capture"),
        Some(magic) if MAGICS.iter().any(|m| m == magic) => Ok(()),
        Some(_) => fail(NOT_A_CAPTURE),
        // A short stream that could still be a header's start ends inside it.
        None if MAGICS.iter().any(|m| m.starts_with(first)) => {
            fail("the file ends inside the capture's file header")
        }
        None => fail(NOT_A_CAPTURE),
    }
}

/// Reads a stream (standard input, a FIFO) that can be read only once into memory, after
/// checking its file header: a stream that is no capture (`/dev/zero`, a text) is refused
/// after its first four bytes instead of being read to its end.
pub fn read_stream(mut stream: impl Read, path: &Path) -> Result<Vec<u8>> {
    let mut bytes = vec![0u8; 4];
    let mut got = 0;
    while got < bytes.len() {
        match stream.read(&mut bytes[got..]) {
            Ok(0) => break,
            Ok(n) => got += n,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => return Err(Error::io(path, e)),
        }
    }
    bytes.truncate(got);
    check_file_header(&bytes, path)?;
    stream
        .read_to_end(&mut bytes)
        .map_err(|e| Error::io(path, e))?;
    Ok(bytes)
}

/// True when `path` names something other than a regular file or a folder (a FIFO, a
/// device, a socket), which can be read only once and not at an offset.
pub fn is_stream(path: &Path) -> bool {
    std::fs::metadata(path).is_ok_and(|m| !m.is_file() && !m.is_dir())
}

/// A streaming capture reader.
pub struct CaptureReader {
    inner: Box<dyn PcapReaderIterator + Send>,
    path: PathBuf,
    format: Format,
    /// Link type of each pcapng interface (one entry for classic pcap).
    linktypes: Vec<i32>,
    /// Timestamp resolution (units per second) and offset (s) of each interface.
    ts_units: Vec<(u64, u64)>,
    nanosecond: bool,
    pending_consume: usize,
    position: u64,
    finished: bool,
    stats: CaptureStats,
    /// Byte offset and size of the blocks that set up the records after them (the pcap
    /// file header; pcapng section headers and interface descriptions of the current
    /// section), so that a reader can resume mid-capture (see [`CapturePoint`]).
    headers: Vec<(u64, usize)>,
    /// Blocks before this offset are a resumed reader's replayed header blocks: they are
    /// already in `headers`.
    resumed_at: u64,
}

/// Where a reader can resume: just before a packet record, with the header blocks that
/// set up its decoding and the counters of everything before it. A reader resumed here
/// numbers records and byte offsets (in messages too) as one that read from the start.
#[derive(Clone, Debug)]
pub struct CapturePoint {
    /// Byte offset of the record.
    pub offset: u64,
    /// Header blocks (offset, size) replayed before the record.
    headers: Vec<(u64, usize)>,
    /// Counters of the records before it.
    stats: CaptureStats,
}

/// Where a datagram sits in the reader's buffer, found before the buffer is re-borrowed.
struct Found {
    record: u32,
    offset: u64,
    ts_ns: u64,
    src_port: u16,
    dst_port: u16,
    start: usize,
    len: usize,
}

/// Shared capture bytes as a `Cursor`'s buffer (a capture held in memory, read more
/// than once).
pub struct ArcBytes(pub Arc<[u8]>);

impl AsRef<[u8]> for ArcBytes {
    fn as_ref(&self) -> &[u8] {
        &self.0
    }
}

impl CaptureReader {
    /// Opens a capture file.
    pub fn open(path: &Path) -> Result<Self> {
        // A FIFO read a second time starts wherever the first read stopped, which came out
        // as "unknown file header". The frame reader reads one into memory once (see
        // `FrameReader::open`); the readers that open a capture several times or resume
        // it at an offset refuse it, before opening it (which waits for a writer).
        if is_stream(path) {
            return Err(Error::Capture {
                path: path.to_path_buf(),
                message: "is a FIFO or a device, not a regular file: it can be read only once \
                          and not at an offset; save the capture to a file, or give `-` and \
                          redirect it to standard input"
                    .into(),
            });
        }
        let file = File::open(path).map_err(|e| Error::io(path, e))?;
        // Reading a folder fails only at the first read, as "could not be read": say why.
        if file.metadata().is_ok_and(|m| m.is_dir()) {
            return Err(Error::Capture {
                path: path.to_path_buf(),
                message: "is a directory, not a capture file".into(),
            });
        }
        Self::from_reader(file, path)
    }

    /// Reads a capture from any byte stream; `path` names it in messages.
    pub fn from_reader(reader: impl Read + Send + 'static, path: &Path) -> Result<Self> {
        let fail = |message: String| Error::Capture {
            path: path.to_path_buf(),
            message,
        };
        let inner = pcap_parser::create_reader(BUFFER_BYTES, reader).map_err(|e| match e {
            PcapError::Eof => fail("the file is empty, not a pcap or pcapng capture".into()),
            PcapError::ReadError => fail("the file could not be read".into()),
            PcapError::Incomplete(_) | PcapError::UnexpectedEof => {
                fail("the file ends inside the capture's file header".into())
            }
            _ => fail(NOT_A_CAPTURE.into()),
        })?;
        Ok(CaptureReader {
            inner,
            path: path.to_path_buf(),
            format: Format::Pcap,
            linktypes: Vec::new(),
            ts_units: Vec::new(),
            nanosecond: false,
            pending_consume: 0,
            position: 0,
            finished: false,
            stats: CaptureStats::default(),
            headers: Vec::new(),
            resumed_at: 0,
        })
    }

    /// Opens a capture file at `point` (taken from a reader of the same file).
    pub fn open_at(path: &Path, point: &CapturePoint) -> Result<Self> {
        let file = File::open(path).map_err(|e| Error::io(path, e))?;
        Self::from_reader_at(file, path, point)
    }

    /// Reads a capture from a seekable byte stream at `point`: the header blocks are
    /// replayed, then reading goes on at the point's record, without reading what lies
    /// between.
    pub fn from_reader_at(
        mut reader: impl Read + Seek + Send + 'static,
        path: &Path,
        point: &CapturePoint,
    ) -> Result<Self> {
        let mut prefix = Vec::new();
        for &(offset, size) in &point.headers {
            let start = prefix.len();
            prefix.resize(start + size, 0);
            reader
                .seek(SeekFrom::Start(offset))
                .and_then(|_| reader.read_exact(&mut prefix[start..]))
                .map_err(|e| Error::io(path, e))?;
        }
        reader
            .seek(SeekFrom::Start(point.offset))
            .map_err(|e| Error::io(path, e))?;
        let replayed = prefix.len() as u64;
        let mut capture = Self::from_reader(std::io::Cursor::new(prefix).chain(reader), path)?;
        // The replayed blocks count as lying just before the record, so that offsets
        // from the record on are the file's.
        capture.position = point.offset.saturating_sub(replayed);
        capture.stats = point.stats.clone();
        capture.headers = point.headers.clone();
        capture.resumed_at = point.offset;
        Ok(capture)
    }

    /// Where to resume to read the record of the datagram just returned by
    /// [`Self::next_datagram`] (at byte `offset`) again.
    pub fn point_before_last(&self, offset: u64) -> CapturePoint {
        let mut stats = self.stats.clone();
        // The datagram's own record: one record, one UDP datagram.
        stats.records -= 1;
        stats.udp -= 1;
        CapturePoint {
            offset,
            headers: self.headers.clone(),
            stats,
        }
    }

    /// The capture's path as given.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Container format (known once the first block has been read).
    pub fn format(&self) -> Format {
        self.format
    }

    /// Link type of the first interface, once known.
    pub fn linktype(&self) -> Option<i32> {
        self.linktypes.first().copied()
    }

    /// Counters so far.
    pub fn stats(&self) -> &CaptureStats {
        &self.stats
    }

    fn error(&self, message: String) -> Error {
        Error::Capture {
            path: self.path.clone(),
            message,
        }
    }

    /// Next whole IPv4/UDP datagram, or `None` at the end of the capture.
    ///
    /// A capture cut mid-record ends cleanly with `stats().truncated_at` set.
    pub fn next_datagram(&mut self) -> Result<Option<Datagram<'_>>> {
        if self.finished {
            return Ok(None);
        }
        if self.pending_consume > 0 {
            self.inner.consume(self.pending_consume);
            self.position += self.pending_consume as u64;
            self.pending_consume = 0;
        }
        let found = loop {
            match self.step()? {
                Step::Again => continue,
                Step::End => {
                    self.finished = true;
                    return Ok(None);
                }
                Step::Found(found) => break found,
            }
        };
        let data = self.inner.data();
        let payload = data
            .get(found.start..found.start + found.len)
            .ok_or_else(|| {
                self.error(format!(
                    "internal: payload outside buffer at record {}",
                    found.record
                ))
            })?;
        Ok(Some(Datagram {
            record: found.record,
            offset: found.offset,
            ts_ns: found.ts_ns,
            src_port: found.src_port,
            dst_port: found.dst_port,
            payload_offset: found.offset + found.start as u64,
            payload,
        }))
    }

    /// Reads one block; leaves a found datagram's bytes in the buffer until the next call.
    fn step(&mut self) -> Result<Step> {
        let offset = self.position;
        let buffer_start = self.inner.data().as_ptr() as usize;
        let record = self.stats.records;
        let outcome = match self.inner.next() {
            Ok((size, block)) => {
                let mut packet: Option<(i32, u64, &[u8])> = None;
                let replayed = offset < self.resumed_at;
                match block {
                    PcapBlockOwned::LegacyHeader(header) => {
                        if !replayed {
                            self.headers = vec![(offset, size)];
                        }
                        self.format = Format::Pcap;
                        self.nanosecond = header.is_nanosecond_precision();
                        self.linktypes = vec![header.network.0];
                        let units = if self.nanosecond { 1_000_000_000 } else { 1_000_000 };
                        self.ts_units = vec![(units, 0)];
                    }
                    PcapBlockOwned::Legacy(b) => {
                        let frac = if self.nanosecond {
                            u64::from(b.ts_usec)
                        } else {
                            u64::from(b.ts_usec) * 1000
                        };
                        let ts = u64::from(b.ts_sec) * 1_000_000_000 + frac;
                        let lt = self.linktypes.first().copied().unwrap_or(-1);
                        packet = Some((lt, ts, b.data));
                    }
                    PcapBlockOwned::NG(Block::SectionHeader(_)) => {
                        self.format = Format::Pcapng;
                        if !replayed {
                            self.headers = vec![(offset, size)];
                        }
                        // Interface ids restart in each section.
                        self.linktypes.clear();
                        self.ts_units.clear();
                    }
                    PcapBlockOwned::NG(Block::InterfaceDescription(idb)) => {
                        self.format = Format::Pcapng;
                        if !replayed {
                            self.headers.push((offset, size));
                        }
                        self.linktypes.push(idb.linktype.0);
                        let units = idb.ts_resolution().unwrap_or(1_000_000);
                        self.ts_units.push((units, idb.ts_offset().max(0) as u64));
                    }
                    PcapBlockOwned::NG(Block::EnhancedPacket(epb)) => {
                        let iface = epb.if_id as usize;
                        let (units, ts_off) =
                            self.ts_units.get(iface).copied().unwrap_or((1_000_000, 0));
                        let raw = (u128::from(epb.ts_high) << 32) | u128::from(epb.ts_low);
                        let ns = raw * 1_000_000_000 / u128::from(units.max(1))
                            + u128::from(ts_off) * 1_000_000_000;
                        let lt = self.linktypes.get(iface).copied().unwrap_or(-1);
                        let caplen = (epb.caplen as usize).min(epb.data.len());
                        packet = Some((lt, u64::try_from(ns).unwrap_or(u64::MAX), &epb.data[..caplen]));
                    }
                    PcapBlockOwned::NG(Block::SimplePacket(spb)) => {
                        let lt = self.linktypes.first().copied().unwrap_or(-1);
                        let len = (spb.origlen as usize).min(spb.data.len());
                        packet = Some((lt, 0, &spb.data[..len]));
                    }
                    PcapBlockOwned::NG(_) => {}
                }
                let found = packet.and_then(|(lt, ts_ns, frame)| {
                    self.stats.records += 1;
                    match link::parse_frame(lt, frame) {
                        Parsed::Udp {
                            src_port,
                            dst_port,
                            start,
                            len,
                        } => {
                            self.stats.udp += 1;
                            let start_in_buffer = frame.as_ptr() as usize - buffer_start + start;
                            Some(Found {
                                record: record as u32,
                                offset,
                                ts_ns,
                                src_port,
                                dst_port,
                                start: start_in_buffer,
                                len,
                            })
                        }
                        Parsed::Fragment => {
                            self.stats.fragments += 1;
                            None
                        }
                        Parsed::NotUdp => {
                            self.stats.not_udp += 1;
                            None
                        }
                        Parsed::NotIpv4 => {
                            self.stats.not_ipv4 += 1;
                            None
                        }
                        Parsed::Malformed => {
                            self.stats.malformed += 1;
                            None
                        }
                    }
                });
                Ok((size, found))
            }
            Err(e) => Err(match e {
                PcapError::Eof => Stop::End,
                PcapError::Incomplete(_) => Stop::Refill,
                PcapError::UnexpectedEof => Stop::Truncated,
                PcapError::BufferTooSmall => Stop::Corrupt(format!(
                    "record {record} at byte offset {offset} claims more than {BUFFER_BYTES} bytes: \
                     the capture is corrupt from there on"
                )),
                PcapError::ReadError => Stop::Corrupt(format!("read error at byte offset {offset}")),
                _ => Stop::Corrupt(format!(
                    "malformed record {record} at byte offset {offset}: the capture is corrupt from there on"
                )),
            }),
        };
        match outcome {
            Ok((size, Some(mut found))) => {
                // Keep the bytes in the buffer until the caller is done with them.
                self.pending_consume = size;
                found.offset = offset;
                Ok(Step::Found(found))
            }
            Ok((size, None)) => {
                self.inner.consume(size);
                self.position += size as u64;
                Ok(Step::Again)
            }
            Err(Stop::End) => Ok(Step::End),
            Err(Stop::Refill) => {
                if self.inner.refill().is_err() {
                    return Err(self.error(format!("read error at byte offset {offset}")));
                }
                Ok(Step::Again)
            }
            Err(Stop::Truncated) => {
                self.stats.truncated_at = Some(offset);
                Ok(Step::End)
            }
            Err(Stop::Corrupt(message)) => Err(self.error(message)),
        }
    }
}

enum Step {
    Again,
    End,
    Found(Found),
}

enum Stop {
    End,
    Refill,
    Truncated,
    Corrupt(String),
}
