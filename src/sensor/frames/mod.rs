//! Streaming frame reader: capture file to frames of decoded returns, one rotation each.
//!
//! A frame starts where the firing azimuth, measured from the cut angle, wraps
//! (falls by more than half a turn). The first sweep counts as full when it starts
//! within one firing step of the cut angle, the last when it ends within one step of
//! it; partial sweeps are numbered like the others but left out unless asked for.

mod model;

pub use model::*;

use super::decode::{first_firing_us, DecodeCounts, DualSelect, PacketDecoder, ReturnTally};
use super::identify::{self, Identity, Sample};
use super::index::FrameSeek;
use super::packet::{self, ReturnMode};
use crate::capture::{CaptureReader, CaptureStats, Format};
use crate::error::{Error, Result};
use crate::frame::Frame;
use crate::sensor::calibration::Calibration;
use serde::Serialize;
use std::collections::VecDeque;
use std::ops::RangeInclusive;
use std::path::Path;
use std::sync::Arc;

/// Returns reserved for a new frame: one 10 Hz turn of an HDL-32E has at most 69,120.
const FRAME_CAPACITY: usize = 72_000;

/// How to decode a capture.
#[derive(Clone, Debug)]
pub struct DecoderOptions {
    /// Per-laser calibration.
    pub calibration: Calibration,
    /// Interpolate each laser's azimuth by its firing time (see [`super::decode`]).
    pub interpolate_azimuth: bool,
    /// Returns kept from dual-return captures.
    pub dual: DualSelect,
    /// Azimuth in degrees where frames are cut (0 = the azimuth wrap).
    pub cut_angle_deg: f64,
    /// Emit the partial first and last sweeps too.
    pub keep_partial: bool,
    /// The `--calibration` file as given (None: built-in tables), for captures of the
    /// other described sensors, which read it for their own model.
    pub calibration_file: Option<CalibrationFile>,
}

/// A calibration file given for the captures to decode.
#[derive(Clone, Debug)]
pub struct CalibrationFile {
    /// Its path.
    pub path: std::path::PathBuf,
    /// Why it is not an HDL-32E calibration, when it is another sensor's: an HDL-32E
    /// capture is then refused with this.
    pub not_hdl32e: Option<String>,
}

impl Default for DecoderOptions {
    fn default() -> Self {
        DecoderOptions {
            calibration: Calibration::builtin(),
            interpolate_azimuth: true,
            dual: DualSelect::Both,
            cut_angle_deg: 0.0,
            keep_partial: false,
            calibration_file: None,
        }
    }
}

impl DecoderOptions {
    /// Refuses, for an HDL-32E capture, a calibration file of another sensor.
    fn check_calibration(&self) -> Result<()> {
        match self
            .calibration_file
            .as_ref()
            .and_then(|f| f.not_hdl32e.as_ref())
        {
            Some(why) => Err(Error::Invalid(format!(
                "{why} (this is an HDL-32E capture: give it an HDL-32E calibration, or \
                 leave --calibration out)"
            ))),
            None => Ok(()),
        }
    }
}

/// What a capture contained, accumulated while reading it.
#[derive(Clone, Debug, Serialize)]
pub struct CaptureSummary {
    /// Container format.
    pub format: Format,
    /// pcap link type of the (first) interface.
    pub linktype: i32,
    /// Name of the link type.
    pub linktype_name: &'static str,
    /// Product id byte of the data packets.
    pub product_id: u8,
    /// Product name.
    pub product: &'static str,
    /// Return mode of the capture.
    pub return_mode: ReturnMode,
    /// HDL-32E data packets.
    pub data_packets: u64,
    /// Position (telemetry) packets, skipped.
    pub position_packets: u64,
    /// Other UDP datagrams, skipped.
    pub other_udp: u64,
    /// Data packets whose return mode byte was invalid, skipped.
    pub bad_data_packets: u64,
    /// Distinct (source, destination) UDP ports of data packets (at most 8 listed).
    pub data_ports: Vec<(u16, u16)>,
    /// Median time between data packets in microseconds.
    pub packet_period_us: Option<f64>,
    /// Rotation rate in Hz, from the azimuth advance over sensor time.
    pub rotation_hz: Option<f64>,
    /// Sweeps covering a full turn.
    pub full_frames: u32,
    /// Partial sweeps (first and last of the capture).
    pub partial_frames: u32,
    /// Index of the first full sweep, for messages (not in reports).
    #[serde(skip)]
    pub first_full_frame: Option<u32>,
    /// Non-zero returns in the whole capture, partial sweeps included.
    pub returns: u64,
    /// Non-zero returns in full frames.
    pub returns_in_full_frames: u64,
    /// Sensor time spanned by the firings, in seconds: from the first to the last firing,
    /// or, when the sensor clock ran backwards between data packets
    /// (`clock_backward_steps` > 0), from the earliest to the latest firing. Never negative.
    pub duration_s: f64,
    /// Data packets whose first firing is earlier than the previous packet's: the sensor
    /// clock is not monotonic (reordered or duplicated packets, a reset clock). Left out
    /// of reports when 0.
    #[serde(skip_serializing_if = "is_zero")]
    pub clock_backward_steps: u64,
    /// Data packets dropped as exact copies of one of the few data packets before them
    /// (same timestamp and payload): a capture recorded or merged twice. Left out of
    /// reports when 0.
    #[serde(skip_serializing_if = "is_zero")]
    pub duplicate_packets: u64,
    /// Frames between the first and the last that cover less than nine tenths of a turn:
    /// the azimuths jumped back within the capture (interleaved or reordered packets, two
    /// sensors in one capture), so each jump cut a frame. Left out of reports when 0.
    #[serde(skip_serializing_if = "is_zero")]
    pub short_frames: u64,
    /// Decoder counters.
    pub decode: DecodeCounts,
    /// Container-level counters (records, fragments, truncation).
    pub capture: CaptureStats,
    /// Returns per laser id over the whole capture (not in reports: see `dead_lasers`).
    #[serde(skip)]
    pub returns_per_laser: Vec<u64>,
    /// Returns per intensity byte value over the whole capture (256 bins, not in reports).
    #[serde(skip)]
    pub intensity_histogram: Vec<u64>,
}

/// True for 0 (serde: counters left out of reports when nothing happened).
fn is_zero(n: &u64) -> bool {
    *n == 0
}

/// Returns below this count say too little about the intensity distribution.
const MIN_RETURNS_FOR_INTENSITY_CHECK: u64 = 1000;

/// Laser ids with no return among `per_laser` counts, when there are `returns` at all (a
/// capture without any says nothing about its lasers).
pub(crate) fn dead_lasers(returns: u64, per_laser: &[u64]) -> Vec<u8> {
    if returns == 0 {
        return Vec::new();
    }
    (0..per_laser.len())
        .filter(|&l| per_laser[l] == 0)
        .map(|l| l as u8)
        .collect()
}

impl CaptureSummary {
    /// Lasers (by id) that returned nothing over the whole capture, when it has returns.
    pub fn dead_lasers(&self) -> Vec<u8> {
        dead_lasers(self.returns, &self.returns_per_laser)
    }

    /// Share of returns with an intensity above 100 and the median intensity, when the
    /// distribution looks like old firmware's raw 0-255 levels rather than calibrated
    /// reflectivity (0-100 %, only retro-reflectors above 100): more than 90 % of the
    /// returns above 100 or a median above 150.
    pub fn raw_intensity_suspected(&self) -> Option<(f64, u8)> {
        let total: u64 = self.intensity_histogram.iter().sum();
        if total < MIN_RETURNS_FOR_INTENSITY_CHECK {
            return None;
        }
        let above: u64 = self.intensity_histogram.iter().skip(101).sum();
        let mut seen = 0;
        let mut median = 0u8;
        for (v, &n) in self.intensity_histogram.iter().enumerate() {
            seen += n;
            if 2 * seen >= total {
                median = v as u8;
                break;
            }
        }
        let share = above as f64 / total as f64;
        (share > 0.9 || median > 150).then_some((share, median))
    }
}

/// A frame being filled, with the azimuths (relative to the cut, centidegrees) and steps
/// of its first and last firings; shared with the other sensors' reader
/// (`sensor::frames`), which cuts sweeps by the same rules.
pub(crate) struct Building {
    pub(crate) frame: Frame,
    first_rel: u32,
    first_step: u32,
    last_rel: u32,
    last_step: u32,
}

impl Building {
    /// The frame a resumed reader finds open before its first packet (frame
    /// `next_index - 1`, when `open`): only its tail is seen, and it is dropped (its index
    /// is below the frame resumed at).
    pub(crate) fn tail_before(open: bool, next_index: u32) -> Option<Self> {
        open.then(|| {
            let frame = Frame {
                index: next_index.wrapping_sub(1),
                partial: false,
                returns: Vec::new(),
            };
            Building::new(frame, 0, 0)
        })
    }

    /// A frame whose first firing is at `rel` with azimuth step `step`.
    pub(crate) fn new(frame: Frame, rel: u32, step: u32) -> Self {
        Building {
            frame,
            first_rel: rel,
            first_step: step,
            last_rel: rel,
            last_step: step,
        }
    }

    /// Takes the next firing.
    pub(crate) fn extend(&mut self, rel: u32, step: u32) {
        self.last_rel = rel;
        self.last_step = step;
    }

    /// True when the sweep is whole: not the capture's first unless it starts at the cut,
    /// not its `last` unless it reaches the cut.
    pub(crate) fn is_whole(&self, last: bool) -> bool {
        let first_ok = self.frame.index > 0 || self.first_rel <= self.first_step.max(1);
        let last_ok = !last || self.last_rel + self.last_step.max(1) >= 36000;
        first_ok && last_ok
    }
}

/// What decides frame boundaries and capture timing, carried from packet to packet:
/// one piece for the reader and the frame index (so both cut frames alike), copied whole
/// into a seek point to resume.
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct SweepState {
    /// Last firing's azimuth relative to the cut angle, centidegrees.
    prev_rel: Option<u32>,
    /// Last firing's azimuth, centidegrees.
    prev_azimuth: Option<u16>,
    /// Last data packet's timestamp, microseconds past the hour.
    prev_ts: Option<u32>,
    /// Hours the sensor clock has restarted, as microseconds.
    hour_offset_us: f64,
    /// First firing's time in the capture.
    first_time_us: Option<f64>,
    /// Rotation so far (forward steps only), centidegrees.
    unwrapped_centideg: u64,
    /// The last data packets kept (see [`SweepState::is_duplicate`]).
    recent: RecentPackets,
}

/// Data packets compared with each new one to find exact duplicates.
pub const DUPLICATE_WINDOW: usize = 8;

/// Timestamp and xxh3 hash of the payload of each of the last [`DUPLICATE_WINDOW`] data
/// packets kept, in a ring: a fixed size whatever the capture's length, and small enough
/// to be copied into every seek point, so that a resumed reader drops the same packets.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct RecentPackets {
    entries: [(u32, u64); DUPLICATE_WINDOW],
    /// Entries filled so far (up to the window).
    len: usize,
    /// Where the next entry goes.
    next: usize,
}

impl RecentPackets {
    /// True when a data packet is an exact copy (same timestamp, same payload hash) of one
    /// of the last [`DUPLICATE_WINDOW`] data packets kept; a kept packet joins the window.
    /// A capture recorded twice over the same interface, or merged with itself, repeats
    /// every packet: decoding the copies doubled every return and cut extra frames where a
    /// copy straddles the cut angle.
    #[inline]
    pub(crate) fn is_duplicate(&mut self, payload: &[u8]) -> bool {
        let ts = packet::timestamp_us(payload);
        let hash = xxhash_rust::xxh3::xxh3_64(payload);
        if self.entries[..self.len].contains(&(ts, hash)) {
            return true;
        }
        self.entries[self.next] = (ts, hash);
        self.next = (self.next + 1) % DUPLICATE_WINDOW;
        self.len = (self.len + 1).min(DUPLICATE_WINDOW);
        false
    }
}

impl SweepState {
    /// [`RecentPackets::is_duplicate`] of this reader's window.
    #[inline]
    pub(super) fn is_duplicate(&mut self, payload: &[u8]) -> bool {
        self.recent.is_duplicate(payload)
    }

    /// Takes a data packet's timestamp and its first firing's time past the hour; returns
    /// that firing's time in the capture.
    #[inline]
    pub(super) fn on_packet(&mut self, ts: u32, first_firing_us: f64) -> f64 {
        if let Some(prev) = self.prev_ts {
            // The sensor clock restarts every hour: keep time increasing. Compared in u64:
            // in u32 `ts + 1_800_000_000` overflows once the clock passes 41 min 35 s.
            if u64::from(ts) + 1_800_000_000 < u64::from(prev) {
                self.hour_offset_us += 3_600_000_000.0;
            }
        }
        self.prev_ts = Some(ts);
        let time0 = first_firing_us + self.hour_offset_us;
        self.first_time_us.get_or_insert(time0);
        time0
    }

    /// Takes a firing's azimuth; returns it relative to the cut angle `cut` and whether it
    /// starts a new sweep (it crossed the cut).
    #[inline]
    pub(super) fn on_firing(&mut self, azimuth: u16, cut: u32) -> (u32, bool) {
        if let Some(prev) = self.prev_azimuth {
            let d = (u32::from(azimuth) + 36000 - u32::from(prev)) % 36000;
            if d < 18000 {
                self.unwrapped_centideg += u64::from(d);
            }
        }
        self.prev_azimuth = Some(azimuth);
        let rel = (u32::from(azimuth) + 36000 - cut) % 36000;
        let wrapped = self.prev_rel.is_some_and(|p| rel + 18000 < p);
        self.prev_rel = Some(rel);
        (rel, wrapped)
    }
}

/// Iterator over the frames of a capture.
pub struct FrameReader {
    capture: CaptureReader,
    decoder: PacketDecoder,
    keep_partial: bool,
    cut: u32,
    building: Option<Building>,
    ready: VecDeque<Frame>,
    next_index: u32,
    sweep: SweepState,
    last_time_us: f64,
    /// Earliest and latest firing time seen, microseconds (`[inf, -inf]` before any).
    time_span_us: [f64; 2],
    summary: CaptureSummary,
    done: bool,
    /// Copy of the current data packet (the datagram borrows the reader).
    packet: Vec<u8>,
    /// Buffers of frames handed back through [`FrameReader::recycle`].
    spare: Vec<Vec<crate::frame::Return>>,
    /// Returns in the largest frame finished so far: how much of a fresh buffer to fault in.
    largest: usize,
    /// Set by [`FrameReader::next_batch`] once a frame beyond its range was seen.
    past_range: bool,
    /// Frames below this index are dropped uncounted: a reader resumed at a frame (see
    /// [`super::index`]) decodes the tail of the frame before it in the resume packet.
    skip_before: u32,
}

/// Reads up to [`identify::SAMPLE_PACKETS`] data packets and identifies the sensor.
pub fn identify_capture(path: &Path) -> Result<Identity> {
    identify_in(CaptureReader::open(path)?)
}

pub(super) fn identify_in(mut capture: CaptureReader) -> Result<Identity> {
    let path = capture.path().to_path_buf();
    let mut sample = Sample::default();
    while let Some(d) = capture.next_datagram()? {
        if packet::is_data_packet(d.payload) {
            sample.push(d.payload, d.ts_ns, d.record, d.offset);
            if sample.is_full() {
                break;
            }
        }
    }
    identify::hdl32e_identity(&sample).map_err(|refusal| {
        if refusal.other_sensor {
            return Error::OtherSensor {
                path: path.clone(),
                message: refusal.message,
            };
        }
        let message = refusal.message;
        let linktype = capture.linktype().unwrap_or(-1);
        let message = if sample.products.is_empty() && capture.linktype().is_none() {
            // pcapng packets refer to an interface description block for their link type.
            format!(
                "{message} (the pcapng capture has no interface description block, so no                  packet has a link type)"
            )
        } else if sample.products.is_empty() && !crate::capture::link::is_supported(linktype)
        {
            format!("link type {linktype} is not supported (Ethernet, Linux cooked v1/v2, raw IPv4 and BSD loopback are)")
        } else {
            message
        };
        Error::Capture { path, message }
    })
}

pub(super) use crate::capture::ArcBytes;

impl FrameReader {
    /// Opens a capture, refusing it unless it is an HDL-32E capture. A FIFO (or device)
    /// is read once into memory, its file header checked first, as standard input is.
    pub fn open(path: &Path, options: &DecoderOptions) -> Result<Self> {
        if crate::capture::is_stream(path) {
            let stream = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
            let bytes = crate::capture::read_stream(stream, path)?;
            return Self::from_bytes(Arc::from(bytes), path, options);
        }
        Self::with_source(|| CaptureReader::open(path), options)
    }

    /// Reads a capture held in memory; `name` stands for it in messages.
    pub fn from_bytes(bytes: Arc<[u8]>, name: &Path, options: &DecoderOptions) -> Result<Self> {
        Self::with_source(
            || CaptureReader::from_reader(std::io::Cursor::new(ArcBytes(bytes.clone())), name),
            options,
        )
    }

    /// Identifies the sensor on a first reader, then decodes from a second one.
    fn with_source(
        open: impl Fn() -> Result<CaptureReader>,
        options: &DecoderOptions,
    ) -> Result<Self> {
        let identity = identify_in(open()?)?;
        options.check_calibration()?;
        Ok(Self::from_parts(identity, open()?, options))
    }

    /// A reader of `capture`, a capture identified as `identity`.
    fn from_parts(identity: Identity, capture: CaptureReader, options: &DecoderOptions) -> Self {
        let cut = ((options.cut_angle_deg.rem_euclid(360.0) * 100.0).round() as u32) % 36000;
        FrameReader {
            capture,
            decoder: PacketDecoder::new(
                &options.calibration,
                options.interpolate_azimuth,
                options.dual,
            ),
            keep_partial: options.keep_partial,
            cut,
            building: None,
            ready: VecDeque::new(),
            next_index: 0,
            sweep: SweepState::default(),
            last_time_us: 0.0,
            time_span_us: [f64::INFINITY, f64::NEG_INFINITY],
            summary: CaptureSummary {
                format: Format::Pcap,
                linktype: -1,
                linktype_name: "",
                product_id: identity.product,
                product: packet::product_name(identity.product),
                return_mode: identity.mode,
                data_packets: 0,
                position_packets: 0,
                other_udp: 0,
                bad_data_packets: 0,
                data_ports: Vec::new(),
                packet_period_us: identity.packet_period_us,
                rotation_hz: None,
                full_frames: 0,
                partial_frames: 0,
                first_full_frame: None,
                returns: 0,
                returns_in_full_frames: 0,
                duration_s: 0.0,
                clock_backward_steps: 0,
                duplicate_packets: 0,
                short_frames: 0,
                decode: DecodeCounts::default(),
                capture: CaptureStats::default(),
                returns_per_laser: vec![0; packet::LASERS],
                intensity_histogram: vec![0; 256],
            },
            done: false,
            packet: Vec::with_capacity(packet::DATA_PACKET_BYTES),
            spare: Vec::new(),
            largest: 0,
            past_range: false,
            skip_before: 0,
        }
    }

    /// Opens a capture at a frame found by [`super::index::FrameScan`]: the frames it
    /// yields (numbering, boundaries, returns, partial flags) and its errors are those a
    /// reader from the start yields from that frame on, without decoding what lies before.
    /// Its [`Self::summary`] counts only the packets read from there (the record numbers
    /// and container counters in it are the whole capture's).
    pub fn open_at(path: &Path, options: &DecoderOptions, at: &FrameSeek) -> Result<Self> {
        let identity = identify_in(CaptureReader::open(path)?)?;
        options.check_calibration()?;
        let capture = CaptureReader::open_at(path, &at.capture)?;
        let mut reader = Self::from_parts(identity, capture, options);
        reader.resume(at);
        Ok(reader)
    }

    /// [`Self::open_at`] for a capture held in memory.
    pub fn from_bytes_at(
        bytes: Arc<[u8]>,
        name: &Path,
        options: &DecoderOptions,
        at: &FrameSeek,
    ) -> Result<Self> {
        let mut reader = Self::from_bytes(bytes.clone(), name, options)?;
        reader.capture = CaptureReader::from_reader_at(
            std::io::Cursor::new(ArcBytes(bytes)),
            name,
            &at.capture,
        )?;
        reader.resume(at);
        Ok(reader)
    }

    /// Sets the frame state a reader from the start has just before the resume packet.
    fn resume(&mut self, at: &FrameSeek) {
        self.next_index = at.next_index;
        self.sweep = at.sweep;
        self.skip_before = at.frame;
        self.building = Building::tail_before(at.open, at.next_index);
    }

    /// Up to `max` next frames whose index lies in `frames`; empty once the capture (or
    /// the range) is exhausted. Lets callers process frames in bounded parallel batches.
    pub fn next_batch(&mut self, max: usize, frames: &RangeInclusive<u32>) -> Result<Vec<Frame>> {
        let mut batch = Vec::with_capacity(max);
        while batch.len() < max && !self.past_range {
            match self.next() {
                None => break,
                Some(frame) => {
                    let frame = frame?;
                    if frame.index > *frames.end() {
                        self.past_range = true;
                    } else if frames.contains(&frame.index) {
                        batch.push(frame);
                    } else {
                        self.recycle(frame);
                    }
                }
            }
        }
        Ok(batch)
    }

    /// Hands a finished frame's buffer back for reuse, sparing an allocation per frame.
    pub fn recycle(&mut self, frame: Frame) {
        let mut returns = frame.returns;
        returns.clear();
        if self.spare.len() < 2 {
            self.spare.push(returns);
        }
    }

    /// What the capture contained so far (complete once the iterator is exhausted).
    pub fn summary(&self) -> CaptureSummary {
        let mut s = self.summary.clone();
        s.format = self.capture.format();
        s.linktype = self.capture.linktype().unwrap_or(-1);
        s.linktype_name = crate::capture::link::link_name(s.linktype);
        s.capture = self.capture.stats().clone();
        if let Some(first) = self.sweep.first_time_us {
            s.duration_s = if s.clock_backward_steps == 0 {
                (self.last_time_us - first) * 1e-6
            } else {
                // A clock that ran backwards has no first-to-last duration: the span of
                // the firing times is the time the capture covers at least.
                (self.time_span_us[1] - self.time_span_us[0]) * 1e-6
            };
            // NaN-free and non-negative whatever the timestamps were.
            s.duration_s = s.duration_s.max(0.0);
            if s.duration_s > 0.0 {
                s.rotation_hz = Some(self.sweep.unwrapped_centideg as f64 / 36000.0 / s.duration_s);
            }
        }
        s
    }

    fn finish_frame(&mut self, mut b: Building, last: bool) {
        if b.frame.index < self.skip_before {
            return;
        }
        self.largest = self.largest.max(b.frame.returns.len());
        b.frame.partial = !b.is_whole(last);
        // A middle frame (its start came from a wrap, its end from the next) covers about a
        // turn; far less means the azimuths jumped back (see `short_frames`).
        let covered = (b.last_rel + b.last_step.max(1)).saturating_sub(b.first_rel);
        if b.frame.index > 0 && !last && covered < 36000 * 9 / 10 {
            self.summary.short_frames += 1;
        }
        if b.frame.partial {
            self.summary.partial_frames += 1;
        } else {
            self.summary.full_frames += 1;
            self.summary.returns_in_full_frames += b.frame.returns.len() as u64;
            self.summary.first_full_frame.get_or_insert(b.frame.index);
        }
        if !b.frame.partial || self.keep_partial {
            self.ready.push_back(b.frame);
        } else {
            // Its buffer serves the next frame: a fresh one costs page faults.
            self.recycle(b.frame);
        }
    }

    fn on_firing(&mut self, azimuth: u16, step: u32) {
        let (rel, wrapped) = self.sweep.on_firing(azimuth, self.cut);
        if wrapped {
            if let Some(b) = self.building.take() {
                self.finish_frame(b, false);
            }
        }
        let (next_index, spare, largest) = (&mut self.next_index, &mut self.spare, self.largest);
        let b = self.building.get_or_insert_with(|| {
            let index = *next_index;
            *next_index += 1;
            let frame = Frame {
                index,
                partial: false,
                returns: spare.pop().unwrap_or_else(|| {
                    // A fresh buffer (the first frames, before buffers come back): its
                    // pages faulted in by one call, sized by the frames so far.
                    let mut v = Vec::with_capacity(FRAME_CAPACITY);
                    crate::memory::prefault(&mut v, largest);
                    v
                }),
            };
            Building::new(frame, rel, step)
        });
        b.extend(rel, step);
    }

    /// Decodes datagrams until a frame is ready or the capture ends.
    fn pump(&mut self) -> Result<()> {
        while self.ready.is_empty() && !self.done {
            let Some(d) = self.capture.next_datagram()? else {
                self.done = true;
                if let Some(b) = self.building.take() {
                    self.finish_frame(b, true);
                }
                break;
            };
            if d.payload.len() == packet::POSITION_PACKET_BYTES {
                self.summary.position_packets += 1;
                continue;
            }
            if !packet::is_data_packet(d.payload) {
                self.summary.other_udp += 1;
                continue;
            }
            // The sensor was identified from the first data packets; a later packet of
            // another product (a second sensor on the wire, or captures concatenated)
            // would decode as garbage returns. One byte per packet checks it.
            let product = packet::product_byte(d.payload);
            let expected = self.summary.product_id;
            if product != expected && product != 0 {
                let (record, offset) = (d.record, d.offset);
                return Err(Error::Capture {
                    path: self.capture.path().to_path_buf(),
                    message: format!(
                        "data packet in record {} at byte offset {} has product id 0x{product:02x} \
                         ({}) where the capture's first data packets have 0x{expected:02x} ({}): \
                         the capture mixes sensors; keep one sensor's packets (e.g. filter by \
                         UDP port) and rerun",
                        record,
                        offset,
                        packet::product_name(product),
                        packet::product_name(expected)
                    ),
                });
            }
            let record = d.record;
            let ports = (d.src_port, d.dst_port);
            // The datagram borrows the reader; copy the 1206 bytes so frame state can change.
            let mut payload = std::mem::take(&mut self.packet);
            payload.clear();
            payload.extend_from_slice(d.payload);
            self.decode_packet(&payload, record, ports);
            self.packet = payload;
        }
        Ok(())
    }

    fn decode_packet(&mut self, payload: &[u8], record: u32, ports: (u16, u16)) {
        let Some(mode) = ReturnMode::from_byte(packet::return_mode_byte(payload)) else {
            self.summary.bad_data_packets += 1;
            return;
        };
        // The frame index drops the same packets (see `index::FrameScan`), so that both
        // cut the same frames.
        if self.sweep.is_duplicate(payload) {
            self.summary.duplicate_packets += 1;
            return;
        }
        self.summary.data_packets += 1;
        if self.summary.data_ports.len() < 8 && !self.summary.data_ports.contains(&ports) {
            self.summary.data_ports.push(ports);
        }
        let (firings, n) = self.decoder.firings(payload, mode);
        let time0 = self
            .sweep
            .on_packet(packet::timestamp_us(payload), first_firing_us(payload, n));
        if self.time_span_us[1] >= self.time_span_us[0] && time0 < self.last_time_us {
            self.summary.clock_backward_steps += 1;
        }
        self.last_time_us = time0 + (n as f64 - 1.0) * packet::FIRING_US;
        self.time_span_us[0] = self.time_span_us[0].min(time0);
        self.time_span_us[1] = self.time_span_us[1].max(self.last_time_us);
        for firing in &firings[..n] {
            self.on_firing(firing.azimuth, firing.step);
            let (blocks, count) = self.decoder.blocks_of(mode, firing.index);
            // on_firing always leaves a frame open.
            let Some(b) = self.building.as_mut() else {
                continue;
            };
            let before = b.frame.returns.len();
            let s = &mut self.summary;
            let mut tally = ReturnTally {
                per_laser: s
                    .returns_per_laser
                    .as_mut_slice()
                    .try_into()
                    .expect("one count per laser"),
                intensity: s
                    .intensity_histogram
                    .as_mut_slice()
                    .try_into()
                    .expect("one count per intensity byte"),
            };
            for &(block, kind) in &blocks[..count] {
                self.decoder.decode_block(
                    payload,
                    block,
                    kind,
                    firing,
                    time0,
                    record,
                    &mut s.decode,
                    &mut tally,
                    &mut b.frame.returns,
                );
            }
            s.returns += (b.frame.returns.len() - before) as u64;
        }
    }
}

impl crate::frame::FrameSource for FrameReader {
    fn next_batch(&mut self, max: usize, frames: &RangeInclusive<u32>) -> Result<Vec<Frame>> {
        FrameReader::next_batch(self, max, frames)
    }

    fn recycle(&mut self, frame: Frame) {
        FrameReader::recycle(self, frame)
    }
}

impl Iterator for FrameReader {
    type Item = Result<Frame>;

    fn next(&mut self) -> Option<Self::Item> {
        if let Err(e) = self.pump() {
            self.done = true;
            self.ready.clear();
            return Some(Err(e));
        }
        self.ready.pop_front().map(Ok)
    }
}
