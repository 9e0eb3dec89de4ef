//! Noisy capture out (`run --pcap-out`): the input capture with every data packet
//! re-encoded from the noisy returns, written as `noisy.pcap` (`noisy.pcapng` for a
//! pcapng input). The packets are the HDL-32E's, or those of another described sensor
//! ([`Wire::Model`]: slots placed by the model's layout, `crate::sensor::encode`).
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
//!   intensity, dropped returns as zero distance (for another sensor, the slots of the
//!   blocks the packet's return mode uses, and the range over the model's resolution). Returns in no processed frame (the
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
//! - Spurious returns (issue 12) are written where the sensor would report them: a
//!   replaced return (fate 4) carries the echo's range and intensity in its own slot, an
//!   added return (fate 5) fills the vacant slot (packet, block, laser) it was resolved
//!   into; a dual capture keeps both entries of a slot (the even block the last return,
//!   the odd block the strongest).
//!
//! Streaming: memory does not grow with the capture's length. Workers turn a processed
//! frame into compact patches (record, slot, raw distance, intensity: 12 bytes per
//! reported return); the output is written front to back by a second sequential reading
//! of the input, which copies every record's bytes and writes each data payload with its
//! return slots cleared and its patches applied. [`NoisyCapture::frame_done`], called in
//! frame order, writes every record before the frame's last packet (the only record a
//! later frame may still share), and [`NoisyCapture::finish`] the rest. Only the patches
//! of frames in flight and one payload are held, never the capture.

use crate::capture::{ArcBytes, CaptureReader};
use crate::error::Error;
use crate::noise::{NoiseChain, NoisyFrame};
use crate::sensor::calibration::Calibration;
use crate::sensor::decode::DualSelect;
use crate::sensor::encode::raw_distance;
use crate::sensor::packet::{self, ReturnMode};
use crate::sensor::packet::{BLOCKS as BLOCKS_PER_PACKET, BLOCK_BYTES as BLOCK_LEN};
use crate::sensor::SensorModel;
use crate::writers::atomic::AtomicFile;
use anyhow::{bail, Context, Result};
use std::io::{BufReader, Read};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};

/// Bytes of a data packet payload.
const PAYLOAD: usize = packet::DATA_PACKET_BYTES;

/// Where the input capture's bytes come from (it is read twice more, front to back).
#[derive(Clone, Debug)]
pub enum Source {
    /// A capture file.
    File(PathBuf),
    /// A capture held in memory.
    Bytes(Arc<[u8]>),
}

impl Source {
    /// A new sequential reader from the first byte; errors name `name`.
    fn open(&self, name: &Path) -> Result<Box<dyn Read + Send>> {
        Ok(match self {
            Source::File(path) => Box::new(BufReader::with_capacity(
                1 << 18,
                std::fs::File::open(path).map_err(|e| Error::io(name, e))?,
            )),
            Source::Bytes(bytes) => Box::new(std::io::Cursor::new(ArcBytes(Arc::clone(bytes)))),
        })
    }
}

/// The packets a capture carries: how slots are found and ranges written.
#[derive(Clone, Copy, Debug)]
pub enum Wire<'a> {
    /// HDL-32E packets, ranges less the calibration's distance offsets.
    Hdl32e(&'a Calibration),
    /// Packets of another described sensor, with its built-in table (no offsets).
    Model(&'static SensorModel),
}

/// One return slot to write: 12 bytes, whatever the slot held before.
#[derive(Clone, Copy, Debug)]
struct Patch {
    /// Capture record of the data packet.
    record: u32,
    /// The return's firing slot in the packet (`Return::block`).
    block: u8,
    /// Its laser id.
    laser: u8,
    /// Raw distance (never 0: cleared slots need no patch).
    raw: u16,
    /// Intensity byte.
    intensity: u8,
}

/// The patches of one processed frame, sorted by record.
struct FramePatches {
    index: u32,
    /// The frame's last record: later frames touch no record before it.
    last: Option<u32>,
    patches: Vec<Patch>,
}

/// Where the re-encoded bytes go.
enum Sink {
    Memory(Vec<u8>),
    File(AtomicFile),
}

impl Sink {
    fn write_all(&mut self, bytes: &[u8]) -> Result<()> {
        match self {
            Sink::Memory(v) => v.extend_from_slice(bytes),
            Sink::File(f) => f.write_all(bytes)?,
        }
        Ok(())
    }
}

/// The sequential writer: a datagram scanner and a raw reader over the same input.
struct Writer {
    name: PathBuf,
    /// Finds each data packet's record and payload offset.
    scanner: CaptureReader,
    /// Copies the bytes (a second reader over the same input, kept behind the scanner).
    raw: Box<dyn Read + Send>,
    /// Input bytes consumed from `raw` (and written to the sink) so far.
    copied: u64,
    /// A data packet found by the scanner but not written yet (record, payload offset).
    held: Option<(u32, u64)>,
    /// The scanner has reached the end of the capture.
    scanned: bool,
    sink: Sink,
    payload: Vec<u8>,
    chunk: Vec<u8>,
    /// Another sensor's packets (None: the HDL-32E's).
    model: Option<&'static SensorModel>,
}

impl Writer {
    /// Copies `n` input bytes to the sink unchanged.
    fn copy(&mut self, mut n: u64) -> Result<()> {
        while n > 0 {
            let take = n.min(self.chunk.len() as u64) as usize;
            let chunk = &mut self.chunk[..take];
            self.raw.read_exact(chunk).with_context(|| {
                format!("{}: cannot read the capture again", self.name.display())
            })?;
            self.sink.write_all(chunk)?;
            self.copied += take as u64;
            n -= take as u64;
        }
        Ok(())
    }

    /// Skips `n` input bytes, writing `n` zeros instead.
    fn zeros(&mut self, n: u64) -> Result<()> {
        let n = n as usize;
        let chunk = &mut self.chunk[..n];
        self.raw
            .read_exact(chunk)
            .with_context(|| format!("{}: cannot read the capture again", self.name.display()))?;
        chunk.fill(0);
        self.sink.write_all(chunk)?;
        self.copied += n as u64;
        Ok(())
    }

    /// Whether a payload is a data packet of the sensor (`None`: the HDL-32E).
    fn is_data(model: Option<&SensorModel>, payload: &[u8]) -> bool {
        match model {
            Some(m) => m.layout.is_data_packet(payload),
            None => packet::is_data_packet(payload),
        }
    }

    /// Clears every return slot of a data packet (another sensor's: of the blocks its
    /// mode uses, the mode returned); the HDL-32E's: all twelve blocks.
    fn clear(&self, payload: &mut [u8]) -> Option<crate::sensor::ReturnMode> {
        if let Some(m) = self.model {
            if let Ok(mode) = crate::sensor::encode::clear_returns(m, payload) {
                return Some(mode);
            }
        }
        for b in 0..BLOCKS_PER_PACKET {
            payload[b * BLOCK_LEN + 4..(b + 1) * BLOCK_LEN].fill(0);
        }
        None
    }

    /// The next data packet (record, payload offset), or `None` at the end.
    fn next_data(&mut self) -> Result<Option<(u32, u64)>> {
        if let Some(h) = self.held.take() {
            return Ok(Some(h));
        }
        while !self.scanned {
            match self.scanner.next_datagram()? {
                Some(d) if Self::is_data(self.model, d.payload) => {
                    return Ok(Some((d.record, d.payload_offset)))
                }
                Some(_) => {}
                None => self.scanned = true,
            }
        }
        Ok(None)
    }

    /// Writes every record before `bound` (all of them for `u32::MAX`), applying `ready`
    /// (sorted by record; those of records before `bound`).
    fn write_until(&mut self, bound: u32, ready: &[Patch]) -> Result<()> {
        let mut next = 0;
        while let Some((record, at)) = self.next_data()? {
            if record >= bound {
                self.held = Some((record, at));
                break;
            }
            // UDP header: the checksum is its last two bytes, just before the payload.
            let checksum = at.saturating_sub(2).max(self.copied);
            self.copy(checksum - self.copied)?;
            self.zeros(at - checksum)?;
            let mut payload = std::mem::take(&mut self.payload);
            self.raw.read_exact(&mut payload).with_context(|| {
                format!("{}: cannot read the capture again", self.name.display())
            })?;
            self.copied += payload.len() as u64;
            let mode = self.clear(&mut payload);
            while next < ready.len() && ready[next].record < record {
                next += 1;
            }
            while next < ready.len() && ready[next].record == record {
                let p = ready[next];
                let (block, laser) = (usize::from(p.block), usize::from(p.laser));
                match (self.model, mode) {
                    (Some(m), Some(mode)) => {
                        // Slots come from this packet's own returns: always in it.
                        let _ = crate::sensor::encode::write_slot(
                            m,
                            mode,
                            &mut payload,
                            block,
                            laser,
                            p.raw,
                            p.intensity,
                        );
                    }
                    _ => {
                        let at = block * BLOCK_LEN + 4 + 3 * (laser & 31);
                        payload[at..at + 2].copy_from_slice(&p.raw.to_le_bytes());
                        payload[at + 2] = p.intensity;
                    }
                }
                next += 1;
            }
            let written = self.sink.write_all(&payload);
            self.payload = payload;
            written?;
        }
        if bound == u32::MAX {
            // Whatever follows the last data packet (other records, a cut record).
            let mut rest = Vec::new();
            self.raw.read_to_end(&mut rest).with_context(|| {
                format!("{}: cannot read the capture again", self.name.display())
            })?;
            self.sink.write_all(&rest)?;
            self.copied += rest.len() as u64;
        }
        Ok(())
    }
}

/// The capture being re-encoded, streamed to its output as frames complete.
pub struct NoisyCapture {
    pcapng: bool,
    offsets: [f32; 32],
    resolution: f32,
    /// Another sensor's packets (None: the HDL-32E's).
    model: Option<&'static SensorModel>,
    unencodable: AtomicU64,
    /// Patches of frames encoded but not yet written.
    pending: Mutex<Vec<FramePatches>>,
    writer: Mutex<Writer>,
}

impl NoisyCapture {
    /// Re-encodes the capture `bytes` (named `name` in messages) in memory: the result
    /// is [`NoisyCapture::into_bytes`]. For library use and tests; `run --pcap-out`
    /// streams to a file with [`NoisyCapture::create`].
    pub fn new(bytes: Vec<u8>, name: &Path, calibration: &Calibration) -> Result<Self> {
        Self::new_for(bytes, name, Wire::Hdl32e(calibration))
    }

    /// [`NoisyCapture::new`] for a capture whose packets are `wire`'s.
    pub fn new_for(bytes: Vec<u8>, name: &Path, wire: Wire) -> Result<Self> {
        Self::with_sink(Source::Bytes(Arc::from(bytes)), name, wire, |_| {
            Ok(Sink::Memory(Vec::new()))
        })
    }

    /// Re-encodes the capture from `source` (named `name` in messages) into
    /// `dir/noisy.pcap` (`noisy.pcapng`), streamed into a temporary file there that
    /// [`NoisyCapture::finish`] renames into place; refuses to overwrite any of `inputs`.
    pub fn create(
        source: Source,
        name: &Path,
        wire: Wire,
        dir: &Path,
        inputs: &[&Path],
    ) -> Result<Self> {
        Self::with_sink(source, name, wire, |file_name| {
            Ok(Sink::File(AtomicFile::create(
                &dir.join(file_name),
                inputs,
            )?))
        })
    }

    fn with_sink(
        source: Source,
        name: &Path,
        wire: Wire,
        sink: impl FnOnce(&str) -> Result<Sink>,
    ) -> Result<Self> {
        let mut magic = [0u8; 4];
        let mut head = source.open(name)?;
        let pcapng = head.read_exact(&mut magic).is_ok() && magic == [0x0A, 0x0D, 0x0D, 0x0A];
        drop(head);
        let scanner = CaptureReader::from_reader(source.open(name)?, name)?;
        let mut offsets = [0.0f32; 32];
        let (model, resolution) = match wire {
            Wire::Hdl32e(calibration) => {
                for (o, l) in offsets.iter_mut().zip(&calibration.lasers) {
                    *o = l.distance_offset_m as f32;
                }
                (None, calibration.distance_resolution_m as f32)
            }
            Wire::Model(m) => (Some(m), m.distance_resolution_m as f32),
        };
        let writer = Writer {
            name: name.to_path_buf(),
            scanner,
            raw: source.open(name)?,
            copied: 0,
            held: None,
            scanned: false,
            sink: sink(Self::name_for(pcapng))?,
            payload: vec![0; model.map_or(PAYLOAD, |m| m.layout.payload_bytes)],
            chunk: vec![0; 1 << 16],
            model,
        };
        Ok(NoisyCapture {
            pcapng,
            offsets,
            resolution,
            model,
            unencodable: AtomicU64::new(0),
            pending: Mutex::new(Vec::new()),
            writer: Mutex::new(writer),
        })
    }

    fn name_for(pcapng: bool) -> &'static str {
        if pcapng {
            "noisy.pcapng"
        } else {
            "noisy.pcap"
        }
    }

    /// File name of the output: `noisy.pcap`, or `noisy.pcapng` for a pcapng input.
    pub fn file_name(&self) -> &'static str {
        Self::name_for(self.pcapng)
    }

    /// Kept returns whose range the wire cannot hold, written as no return so far.
    pub fn unencodable(&self) -> u64 {
        self.unencodable.load(Ordering::Relaxed)
    }

    /// Turns the returns of one processed frame into patches of their packet slots:
    /// alive returns (kept, replaced, added) with their noisy range and intensity;
    /// dropped ones stay cleared (zero distance, as the sensor reports no return).
    ///
    /// Frames touch disjoint slots, so the order in which workers call this does not
    /// change the bytes.
    pub fn encode_frame(&self, frame: &NoisyFrame) {
        let reported = frame.reported();
        let mut lost = 0u64;
        let mut patches = Vec::with_capacity(reported.len());
        // The last packet of the recorded returns (dropped ones included): its records
        // are complete once this frame is.
        let mut last = None;
        for i in 0..reported.len() {
            let r = reported.of(i);
            if i < frame.clean_len {
                last = last.max(Some(r.packet));
            }
            if !reported.is_alive(i) {
                continue;
            }
            let fits = match self.model {
                Some(m) => usize::from(r.laser) < m.lasers,
                None => usize::from(r.block) < BLOCKS_PER_PACKET,
            };
            if !fits {
                continue;
            }
            let laser = if self.model.is_some() {
                r.laser
            } else {
                r.laser & 31
            };
            let offset = self.offsets.get(usize::from(laser)).copied().unwrap_or(0.0);
            match raw_distance(r.range, offset, self.resolution) {
                Some(raw) => patches.push(Patch {
                    record: r.packet,
                    block: r.block,
                    laser,
                    raw,
                    intensity: r.intensity,
                }),
                None => lost += 1,
            }
        }
        // Recorded returns come in capture order; added ones (appended) may not.
        if !patches.is_sorted_by_key(|p| p.record) {
            patches.sort_by_key(|p| p.record);
        }
        self.pending
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .push(FramePatches {
                index: frame.index,
                last,
                patches,
            });
        if lost > 0 {
            self.unencodable.fetch_add(lost, Ordering::Relaxed);
        }
    }

    /// Frame `index` and every frame before it are encoded: writes every record before
    /// its last packet. Call in frame order (`run` does, where it appends the reports).
    pub fn frame_done(&self, index: u32) -> Result<()> {
        let bound = {
            let pending = self.pending.lock().unwrap_or_else(|e| e.into_inner());
            pending
                .iter()
                .find(|f| f.index == index)
                .and_then(|f| f.last)
        };
        match bound {
            Some(bound) => self.write_until(bound, Some(index)),
            None => Ok(()),
        }
    }

    /// Writes the records before `bound` with the patches that fall there; forgets the
    /// frames up to `done` once they have no patch left.
    fn write_until(&self, bound: u32, done: Option<u32>) -> Result<()> {
        let mut ready = Vec::new();
        {
            let mut pending = self.pending.lock().unwrap_or_else(|e| e.into_inner());
            for f in pending.iter_mut() {
                let k = f.patches.partition_point(|p| p.record < bound);
                ready.extend(f.patches.drain(..k));
            }
            pending.retain(|f| !f.patches.is_empty() || done.is_none_or(|d| f.index > d));
        }
        // Several frames' runs (a shared packet); stable, so nearly linear on runs.
        if !ready.is_sorted_by_key(|p| p.record) {
            ready.sort_by_key(|p| p.record);
        }
        let mut writer = self.writer.lock().unwrap_or_else(|e| e.into_inner());
        writer.write_until(bound, &ready)
    }

    /// Writes every remaining record and returns the output (for [`NoisyCapture::new`]).
    pub fn try_into_bytes(self) -> Result<Vec<u8>> {
        self.write_until(u32::MAX, None)?;
        match self
            .writer
            .into_inner()
            .unwrap_or_else(|e| e.into_inner())
            .sink
        {
            Sink::Memory(bytes) => Ok(bytes),
            Sink::File(f) => bail!(
                "internal: {} is streamed to a file; use finish",
                f.path().display()
            ),
        }
    }

    /// The re-encoded capture bytes (for [`NoisyCapture::new`]).
    ///
    /// # Panics
    /// When the capture cannot be read again (it was already read whole by the decoder
    /// that produced the frames) or was made with [`NoisyCapture::create`]; see
    /// [`NoisyCapture::try_into_bytes`].
    pub fn into_bytes(self) -> Vec<u8> {
        self.try_into_bytes()
            .unwrap_or_else(|e| panic!("noisy capture: {e:#}"))
    }

    /// Writes every remaining record and renames the output into place; returns the
    /// number of unencodable returns (see [`NoisyCapture::unencodable`]).
    pub fn finish(self) -> Result<u64> {
        self.write_until(u32::MAX, None)?;
        let unencodable = self.unencodable();
        match self
            .writer
            .into_inner()
            .unwrap_or_else(|e| e.into_inner())
            .sink
        {
            Sink::File(f) => f.commit()?,
            Sink::Memory(_) => bail!("internal: an in-memory noisy capture; use into_bytes"),
        }
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

/// Refuses a noise chain with a stage that changes what a data packet cannot carry
/// (see [`NoiseChain::geometry_changes`]): per return a packet holds only a distance and
/// an intensity.
pub fn check_encodable(chain: &NoiseChain, seed: u64) -> Result<()> {
    let refused: Vec<String> = chain
        .geometry_changes(seed)
        .iter()
        .map(|c| {
            format!(
                "noise[{}] ({}) changes the {}",
                c.stage,
                c.kind,
                c.what.join(", ")
            )
        })
        .collect();
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
