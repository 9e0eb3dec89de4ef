//! Frames of a capture of any described sensor but the HDL-32E (VLP-16, Puck Hi-Res,
//! VLP-32C, HDL-64E S2/S3, VLS-128), for `run` (issue 31).
//!
//! The sensor is identified by structure ([`crate::sensor::identify`]) from the first data
//! packets; each data packet is decoded by [`ModelDecoder`] (the model's built-in
//! table), and its returns go to frames firing by firing: a firing sequence's azimuth is
//! its block's, plus its share of the step to the next block for the second sequence of
//! a VLP-16 block, and a frame ends where that azimuth crosses the cut angle, as the
//! HDL-32E reader cuts ([`super::FrameReader`], whose sweep, partial-frame and
//! repeated-packet rules this follows). The first and last sweeps are partial unless they
//! start and end at the cut.
//!
//! Why a reader of its own beside the HDL-32E's: that one decodes firing by firing with
//! the HDL-32E's kernel ([`crate::sensor::decode::PacketDecoder`]); this one decodes a
//! whole packet of any layout ([`ModelDecoder`]) and then distributes its returns.
//!
//! `run --chunk-frames` starts a chunk mid-capture: [`ModelFrameReader::scan`] reads the
//! capture once and gives each frame a [`ModelSeek`] (the packet its first firing is in
//! and the reader's state just before that packet), and
//! [`ModelFrameReader::resume_at`] goes on from there, yielding the same frames as a
//! reader from the start (`tests/model_chunks.rs`). Unlike the HDL-32E's index, the scan
//! decodes the returns (once, for the plan; each chunk then reads only its own packets).

use super::{is_zero, Building, RecentPackets};
use crate::capture::CaptureReader;
use crate::error::{Error, Result};
use crate::frame::{Frame, Return};
use crate::sensor::decode::ModelDecoder;
use crate::sensor::identify::SAMPLE_PACKETS;
use crate::sensor::identify::{identify, Identified};
use crate::sensor::packet::POSITION_PACKET_BYTES;
use crate::sensor::{ReturnMode, SensorModel};
use serde::Serialize;
use std::collections::VecDeque;
use std::ops::RangeInclusive;
use std::path::Path;

/// The frame reader of a capture: the HDL-32E's, or another described sensor's.
pub enum CaptureFrames {
    /// An HDL-32E capture (boxed: the reader is large).
    Hdl32e(Box<crate::sensor::frames::FrameReader>),
    /// A capture of another described sensor.
    Model(Box<ModelFrameReader>),
}

/// The frame reader of the capture at `path`: the HDL-32E reader, or, where that refuses
/// the capture and another described sensor's structure fits it, that sensor's reader
/// (files only: a FIFO is read once); else the HDL-32E reader's error.
pub fn open_capture(
    path: &Path,
    options: &crate::sensor::frames::DecoderOptions,
) -> Result<CaptureFrames> {
    let e = match crate::sensor::frames::FrameReader::open(path, options) {
        Ok(r) => return Ok(CaptureFrames::Hdl32e(Box::new(r))),
        Err(e) => e,
    };
    if crate::capture::is_stream(path) {
        return Err(e);
    }
    model_or(e, options, ModelFrameReader::open(path, options))
}

/// Where a frame of a capture of any described sensor starts (see [`scan_capture`]).
#[derive(Clone, Debug)]
pub enum CaptureSeek {
    /// In an HDL-32E capture, from its frame index.
    Hdl32e(crate::sensor::index::FrameSeek),
    /// In a capture of another sensor, from [`ModelFrameReader::scan`].
    Model(ModelSeek),
}

/// A frame found by [`scan_capture`]: its index, whether it is a partial sweep, and where
/// it starts.
pub type ScannedFrame = (u32, bool, CaptureSeek);

/// The frames [`scan_capture`] finds, in order.
pub type ScannedFrames = Box<dyn Iterator<Item = Result<ScannedFrame>>>;

/// The sensor of the capture file at `path` and every frame of it (partial ones too,
/// flagged) with where it starts, in order: an HDL-32E capture's from its frame index
/// (streamed, no returns decoded), another sensor's from a scan that decodes it once; the
/// capture reader's error when no described sensor fits.
pub fn scan_capture(
    path: &Path,
    options: &crate::sensor::frames::DecoderOptions,
) -> Result<(&'static SensorModel, ScannedFrames)> {
    let e = match crate::sensor::index::FrameScan::open(path, options) {
        Ok(scan) => return Ok((&crate::sensor::HDL32E, hdl32e_scanned(scan))),
        Err(e) => e,
    };
    // A FIFO is refused by the scan before it is opened (an open waits for a writer).
    if crate::capture::is_stream(path) {
        return Err(e);
    }
    let reader = match open_capture(path, options) {
        Ok(CaptureFrames::Model(r)) => r,
        Ok(CaptureFrames::Hdl32e(_)) => return Err(e),
        Err(e) => return Err(e),
    };
    let sensor = reader.model();
    let frames = reader
        .scan()
        .map(|f| f.map(|f| (f.index, f.partial, CaptureSeek::Model(f.seek))));
    Ok((sensor, Box::new(frames)))
}

/// The frames of an HDL-32E capture's frame index, as [`scan_capture`] gives them.
pub fn hdl32e_scanned(scan: crate::sensor::index::FrameScan) -> ScannedFrames {
    Box::new(scan.map(|f| f.map(|f| (f.index, f.partial, CaptureSeek::Hdl32e(f.seek)))))
}

/// The frame reader of the capture file at `path` going on from `at` (found by
/// [`scan_capture`] on the same file): the frames from `at`'s on are those a reader from
/// the start yields.
pub fn open_capture_at(
    path: &Path,
    options: &crate::sensor::frames::DecoderOptions,
    at: &CaptureSeek,
) -> Result<CaptureFrames> {
    match at {
        CaptureSeek::Hdl32e(at) => Ok(CaptureFrames::Hdl32e(Box::new(
            crate::sensor::frames::FrameReader::open_at(path, options, at)?,
        ))),
        CaptureSeek::Model(at) => match open_capture(path, options)? {
            CaptureFrames::Model(mut r) => {
                r.resume_at(path, at)?;
                Ok(CaptureFrames::Model(r))
            }
            CaptureFrames::Hdl32e(_) => Err(Error::Invalid(format!(
                "{}: now an HDL-32E capture, not the one scanned: was it replaced during \
                 the run?",
                path.display()
            ))),
        },
    }
}

impl CaptureFrames {
    /// The reader as a frame source.
    pub fn into_source(self) -> Box<dyn crate::frame::FrameSource> {
        match self {
            CaptureFrames::Hdl32e(r) => r,
            CaptureFrames::Model(r) => r,
        }
    }

    /// The reader as a frame source, kept for its summary afterwards.
    pub fn source_mut(&mut self) -> &mut dyn crate::frame::FrameSource {
        match self {
            CaptureFrames::Hdl32e(r) => r.as_mut(),
            CaptureFrames::Model(r) => r.as_mut(),
        }
    }
}

/// The other sensor's reader, or the error to show when neither reader takes the
/// capture: where the HDL-32E reader saw another product's packets, the other readers'
/// (it names what was measured and every sensor described); else the HDL-32E reader's.
fn model_or(
    hdl32e: Error,
    options: &crate::sensor::frames::DecoderOptions,
    model: Result<Option<ModelFrameReader>>,
) -> Result<CaptureFrames> {
    match model {
        Ok(Some(r)) => Ok(CaptureFrames::Model(Box::new(
            match &options.calibration_file {
                Some(file) => r.with_calibration_file(&file.path)?,
                None => r,
            },
        ))),
        Err(m) if matches!(hdl32e, Error::OtherSensor { .. }) => Err(m),
        _ => Err(hdl32e),
    }
}

/// [`open_capture`] of a capture held in memory (standard input, read to its end), named
/// `name` in messages.
pub fn open_capture_bytes(
    bytes: std::sync::Arc<[u8]>,
    name: &Path,
    options: &crate::sensor::frames::DecoderOptions,
) -> Result<CaptureFrames> {
    use crate::capture::ArcBytes;
    let e = match crate::sensor::frames::FrameReader::from_bytes(bytes.clone(), name, options) {
        Ok(r) => return Ok(CaptureFrames::Hdl32e(Box::new(r))),
        Err(e) => e,
    };
    let open = || CaptureReader::from_reader(std::io::Cursor::new(ArcBytes(bytes.clone())), name);
    model_or(e, options, ModelFrameReader::open_with(open, options))
}

/// Data packets searched for an HDL-64E's calibration in their status bytes: three
/// cycles of the status block (4,160 packets each), so one that starts anywhere in the
/// first is whole within them, while a capture without one is not read to its end.
const STATUS_PACKETS: usize = 3 * 4160;

/// The unit's calibration from the status bytes of an HDL-64E capture (bytes 1204 and
/// 1205 of its first [`STATUS_PACKETS`] data packets), as velodyne_decoder reads it;
/// None for other sensors and where no block's check holds (the built-in table is then
/// used).
fn status_calibration(
    open: &impl Fn() -> Result<CaptureReader>,
    model: &'static SensorModel,
) -> Result<Option<crate::sensor::calibration::ModelCalibration>> {
    if model.lasers != 64 || model.layout.product_at.is_some() {
        return Ok(None);
    }
    let mut reader = open()?;
    let mut status = Vec::new();
    while let Some(d) = reader.next_datagram()? {
        if model.layout.is_data_packet(d.payload) {
            status.push((d.payload[1204], d.payload[1205]));
            if status.len() >= STATUS_PACKETS {
                break;
            }
        }
    }
    Ok(crate::sensor::calibration::ModelCalibration::from_status_bytes(status, model).ok())
}

/// What was read from a capture of another sensor, for `summary.json`.
#[derive(Clone, Debug, Default, Serialize)]
pub struct ModelCaptureSummary {
    /// The sensor identified.
    pub sensor: &'static str,
    /// Product byte the packets carry (0 for the HDL-64E, whose packets have none).
    pub product_id: u8,
    /// False when the product byte names another model than the structure says.
    pub product_byte_agrees: bool,
    /// Return mode of the first data packet.
    pub return_mode: Option<ReturnMode>,
    /// Median time between data packets, microseconds.
    pub packet_period_us: f64,
    /// Rotation rate measured from the azimuth steps, Hz.
    pub rotation_hz: f64,
    /// Data packets decoded.
    pub data_packets: u64,
    /// Position packets seen.
    pub position_packets: u64,
    /// Other UDP payloads (not data packets of the sensor).
    pub other_udp: u64,
    /// Data packets that could not be decoded (named in a warning).
    pub bad_data_packets: u64,
    /// Complete sweeps.
    pub full_frames: u64,
    /// Partial sweeps (first and last).
    pub partial_frames: u64,
    /// Returns decoded.
    pub returns: u64,
    /// Returns per laser id.
    pub returns_per_laser: Vec<u64>,
    /// Why the product byte was overruled, empty when it was not.
    pub note: String,
    /// The calibration decoded with: "built-in" (the model's table), or the unit's own
    /// read from an HDL-64E's status bytes.
    pub calibration: String,
    /// Data packets dropped as exact copies of one of the few before them, as the
    /// HDL-32E reader drops them (left out of reports when 0).
    #[serde(skip_serializing_if = "is_zero")]
    pub duplicate_packets: u64,
}

impl ModelCaptureSummary {
    /// Laser ids without a single return in a capture that has returns (empty when it has
    /// none), as [`crate::sensor::frames::CaptureSummary::dead_lasers`] gives them.
    pub fn dead_lasers(&self) -> Vec<u8> {
        crate::sensor::frames::dead_lasers(self.returns, &self.returns_per_laser)
    }
}

/// Where a frame of a capture of another sensor starts: the packet to resume at and the
/// reader's state just before it.
#[derive(Clone, Debug)]
pub struct ModelSeek {
    /// The frame resumed at.
    pub frame: u32,
    capture: crate::capture::CapturePoint,
    next_index: u32,
    open: bool,
    prev_ts: Option<u32>,
    hour_offset_us: f64,
    prev_rel: Option<u32>,
    previous: Vec<u8>,
    recent: RecentPackets,
}

/// One frame found by [`ModelFrameReader::scan`].
#[derive(Clone, Debug)]
pub struct ScannedModelFrame {
    /// Sweep index, as the reader numbers it.
    pub index: u32,
    /// Partial first or last sweep.
    pub partial: bool,
    /// Where to resume to read this frame first.
    pub seek: ModelSeek,
}

/// The frames of a capture with where each starts ([`ModelFrameReader::scan`]).
pub struct ModelScan {
    reader: ModelFrameReader,
}

impl Iterator for ModelScan {
    type Item = Result<ScannedModelFrame>;

    fn next(&mut self) -> Option<Self::Item> {
        let r = &mut self.reader;
        let frame = match r.next_frame() {
            Ok(Some(f)) => f,
            Ok(None) => return None,
            Err(e) => {
                // No frame after an error.
                r.done = true;
                r.ready.clear();
                return Some(Err(e));
            }
        };
        let seek = r
            .seeks
            .as_mut()
            .and_then(VecDeque::pop_front)
            .filter(|s| s.frame == frame.index);
        let index = frame.index;
        let partial = frame.partial;
        r.recycle(frame);
        Some(seek.map_or_else(
            || {
                Err(Error::Invalid(format!(
                    "{}: internal: frame {index} has no start recorded",
                    r.capture.path().display()
                )))
            },
            |seek| {
                Ok(ScannedModelFrame {
                    index,
                    partial,
                    seek,
                })
            },
        ))
    }
}

/// Iterator over the frames of a capture of a described sensor other than the HDL-32E.
pub struct ModelFrameReader {
    capture: CaptureReader,
    decoder: ModelDecoder,
    model: &'static SensorModel,
    keep_partial: bool,
    cut: u32,
    building: Option<Building>,
    ready: VecDeque<Frame>,
    next_index: u32,
    prev_ts: Option<u32>,
    hour_offset_us: f64,
    prev_rel: Option<u32>,
    /// The data packet before the current one (the VLS-128's dual-mode step).
    previous: Vec<u8>,
    /// The last data packets kept, to drop exact copies.
    recent: RecentPackets,
    packet: Vec<u8>,
    scratch: Vec<Return>,
    spare: Vec<Vec<Return>>,
    done: bool,
    past_range: bool,
    summary: ModelCaptureSummary,
    /// While scanning: the seek of each frame started and not yet finished, in order.
    seeks: Option<VecDeque<ModelSeek>>,
}

impl ModelFrameReader {
    /// Identifies the sensor of the capture `open` reads (twice: a first reader for the
    /// sample, a second to decode; a third for an HDL-64E's status bytes, unless
    /// `options` name a calibration file); `None` when it is an HDL-32E (its own reader
    /// takes it), an error when no described sensor fits. Of `options`, the HDL-32E's
    /// calibration is not used, nor the calibration file: the caller applies it
    /// ([`ModelFrameReader::with_calibration_file`]), whose errors then are its own.
    pub fn open_with(
        open: impl Fn() -> Result<CaptureReader>,
        options: &crate::sensor::frames::DecoderOptions,
    ) -> Result<Option<Self>> {
        let mut sample_reader = open()?;
        let path = sample_reader.path().to_path_buf();
        let mut sample: Vec<(Vec<u8>, u64)> = Vec::new();
        while let Some(d) = sample_reader.next_datagram()? {
            if d.payload.len() == crate::sensor::LAYOUT_1206.payload_bytes {
                sample.push((d.payload.to_vec(), d.ts_ns));
                if sample.len() >= SAMPLE_PACKETS {
                    break;
                }
            }
        }
        let refs: Vec<(&[u8], u64)> = sample.iter().map(|(p, t)| (p.as_slice(), *t)).collect();
        let found: Identified = identify(&refs).map_err(|message| Error::Capture {
            path: path.clone(),
            message,
        })?;
        if found.model.name == crate::sensor::HDL32E.name {
            return Ok(None);
        }
        let model = found.model;
        let cut = ((options.cut_angle_deg.rem_euclid(360.0) * 100.0).round() as u32) % 36000;
        let mut decoder = ModelDecoder::new(model, options.interpolate_azimuth, options.dual);
        let mut calibration = "built-in".to_string();
        // A calibration file, applied once the sensor is known
        // ([`ModelFrameReader::with_calibration_file`]), wins over the status bytes: they
        // are not read then (a third pass over up to 12,480 data packets).
        let status = match options.calibration_file {
            Some(_) => None,
            None => status_calibration(&open, model)?,
        };
        if let Some(cal) = status {
            calibration = cal.source.clone();
            decoder = decoder
                .with_calibration(cal)
                .map_err(|message| Error::Capture {
                    path: path.clone(),
                    message,
                })?;
        }
        Ok(Some(ModelFrameReader {
            capture: open()?,
            decoder,
            model,
            keep_partial: options.keep_partial,
            cut,
            building: None,
            ready: VecDeque::new(),
            next_index: 0,
            prev_ts: None,
            hour_offset_us: 0.0,
            prev_rel: None,
            previous: Vec::new(),
            recent: RecentPackets::default(),
            packet: Vec::new(),
            scratch: Vec::new(),
            spare: Vec::new(),
            done: false,
            past_range: false,
            summary: ModelCaptureSummary {
                sensor: model.name,
                product_id: found.product_byte,
                product_byte_agrees: found.product_byte_agrees,
                return_mode: Some(found.mode),
                packet_period_us: found.packet_period_us,
                rotation_hz: found.rotation_hz,
                returns_per_laser: vec![0; model.lasers],
                note: found.note,
                calibration,
                ..Default::default()
            },
            seeks: None,
        }))
    }

    /// Every frame of the capture (partial ones too, flagged) with where it starts, in
    /// order, read to the capture's end; the frames' returns are decoded and dropped, and
    /// a frame's start is held only until the frame ends (memory does not grow with the
    /// capture).
    pub fn scan(mut self) -> ModelScan {
        self.keep_partial = true;
        self.seeks = Some(VecDeque::new());
        ModelScan { reader: self }
    }

    /// Goes on from `at` (of a scan of the same capture, read again from `path`): the
    /// frames from `at.frame` on are those a reader from the start yields; the tail of
    /// the frame before is dropped. The summary then covers only what is read from here.
    pub fn resume_at(&mut self, path: &Path, at: &ModelSeek) -> Result<()> {
        self.capture = CaptureReader::open_at(path, &at.capture)?;
        self.next_index = at.next_index;
        self.prev_ts = at.prev_ts;
        self.hour_offset_us = at.hour_offset_us;
        self.prev_rel = at.prev_rel;
        self.previous.clone_from(&at.previous);
        self.recent = at.recent;
        self.ready.clear();
        self.done = false;
        self.past_range = false;
        self.building = Building::tail_before(at.open, at.next_index);
        Ok(())
    }

    /// The reader decoding with the calibration file `path` (a `db.xml` or ROS YAML of
    /// the identified sensor: its unit's angles and corrections) instead of the built-in
    /// table or the status bytes' calibration.
    pub fn with_calibration_file(mut self, path: &Path) -> Result<Self> {
        let cal = crate::sensor::calibration::ModelCalibration::from_file(path, self.model)?;
        self.summary.calibration = path.display().to_string();
        self.decoder = self
            .decoder
            .with_calibration(cal)
            .map_err(|message| Error::Config {
                path: path.to_path_buf(),
                message,
            })?;
        Ok(self)
    }

    /// [`ModelFrameReader::open_with`] of a capture file.
    pub fn open(
        path: &Path,
        options: &crate::sensor::frames::DecoderOptions,
    ) -> Result<Option<Self>> {
        Self::open_with(|| CaptureReader::open(path), options)
    }

    /// The sensor identified.
    pub fn model(&self) -> &'static SensorModel {
        self.model
    }

    /// What was read so far.
    pub fn summary(&self) -> &ModelCaptureSummary {
        &self.summary
    }

    /// Up to `max` next frames whose index lies in `frames`; empty once the capture (or
    /// the range) is exhausted.
    pub fn next_batch(&mut self, max: usize, frames: &RangeInclusive<u32>) -> Result<Vec<Frame>> {
        let mut out = Vec::new();
        while out.len() < max && !self.past_range {
            let Some(frame) = self.next_frame()? else {
                break;
            };
            if frame.index > *frames.end() {
                self.past_range = true;
            } else if frame.index >= *frames.start() {
                out.push(frame);
            } else {
                self.recycle(frame);
            }
        }
        Ok(out)
    }

    /// Hands a finished frame's buffer back for reuse.
    pub fn recycle(&mut self, mut frame: Frame) {
        frame.returns.clear();
        if self.spare.len() < 4 {
            self.spare.push(frame.returns);
        }
    }

    fn next_frame(&mut self) -> Result<Option<Frame>> {
        while self.ready.is_empty() && !self.done {
            self.pump()?;
        }
        Ok(self.ready.pop_front())
    }

    /// Reads one datagram (or ends the capture).
    fn pump(&mut self) -> Result<()> {
        let Some(d) = self.capture.next_datagram()? else {
            self.done = true;
            if let Some(b) = self.building.take() {
                self.finish_frame(b, true);
            }
            return Ok(());
        };
        if d.payload.len() == POSITION_PACKET_BYTES {
            self.summary.position_packets += 1;
            return Ok(());
        }
        if !self.model.layout.is_data_packet(d.payload) {
            self.summary.other_udp += 1;
            return Ok(());
        }
        let (record, offset) = (d.record, d.offset);
        // While scanning, the window a frame starting in this packet resumes with.
        let recent = self.recent;
        // Exact copies are dropped before they touch the frame state (the HDL-32E
        // reader's rule); a packet the decoder refuses does not join the window.
        let lay = &self.model.layout;
        if lay.return_mode(d.payload).is_ok() && self.recent.is_duplicate(d.payload) {
            self.summary.duplicate_packets += 1;
            return Ok(());
        }
        let mut payload = std::mem::take(&mut self.packet);
        payload.clear();
        payload.extend_from_slice(d.payload);
        // While scanning, the state a frame starting in this packet resumes from.
        let before = (
            self.next_index,
            self.building.is_some(),
            self.prev_ts,
            self.hour_offset_us,
            self.prev_rel,
        );
        self.decode_packet(&payload, record);
        if let Some(seeks) = &mut self.seeks {
            for frame in before.0..self.next_index {
                seeks.push_back(ModelSeek {
                    frame,
                    capture: self.capture.point_before_last(offset),
                    next_index: before.0,
                    open: before.1,
                    prev_ts: before.2,
                    hour_offset_us: before.3,
                    prev_rel: before.4,
                    previous: self.previous.clone(),
                    recent,
                });
            }
        }
        self.previous.clear();
        self.previous.extend_from_slice(&payload);
        self.packet = payload;
        Ok(())
    }

    fn decode_packet(&mut self, payload: &[u8], record: u32) {
        let lay = &self.model.layout;
        let ts = lay.timestamp_us(payload);
        if let Some(prev) = self.prev_ts {
            // The sensor clock restarts every hour: keep time increasing (as the HDL-32E
            // reader does).
            if u64::from(ts) + 1_800_000_000 < u64::from(prev) {
                self.hour_offset_us += 3_600_000_000.0;
            }
        }
        self.prev_ts = Some(ts);
        let mut scratch = std::mem::take(&mut self.scratch);
        scratch.clear();
        let previous = (!self.previous.is_empty()).then_some(self.previous.as_slice());
        let decoded = self.decoder.decode_packet_after(
            payload,
            previous,
            record,
            self.hour_offset_us,
            &mut scratch,
        );
        let mode = match decoded {
            Ok(c) => c.mode.unwrap_or(ReturnMode::Strongest),
            Err(_) => {
                self.summary.bad_data_packets += 1;
                self.scratch = scratch;
                return;
            }
        };
        self.summary.data_packets += 1;
        let dual = mode == ReturnMode::Dual;
        // Firing sequence of each return, and the returns in firing order (stable: each
        // firing's returns keep the decoder's order).
        let seq = |r: &Return| if dual { r.block / 2 } else { r.block };
        scratch.sort_by_key(seq);
        let firings = self.firing_azimuths(payload, mode);
        let mut start = 0;
        while start < scratch.len() {
            let s = seq(&scratch[start]);
            let end = start
                + scratch[start..]
                    .iter()
                    .position(|r| seq(r) != s)
                    .unwrap_or(scratch.len() - start);
            let (azimuth, within, step) = firings.get(usize::from(s)).copied().unwrap_or_default();
            self.on_firing(azimuth, within, step);
            let b = self
                .building
                .as_mut()
                .expect("on_firing leaves a frame open");
            for r in &scratch[start..end] {
                if let Some(n) = self.summary.returns_per_laser.get_mut(usize::from(r.laser)) {
                    *n += 1;
                }
            }
            self.summary.returns += (end - start) as u64;
            b.frame.returns.extend_from_slice(&scratch[start..end]);
            start = end;
        }
        self.scratch = scratch;
    }

    /// Every firing sequence of a packet, in order: its block's azimuth (centidegrees),
    /// how far past it the sequence fires, and the step to the next sequence.
    fn firing_azimuths(&self, payload: &[u8], mode: ReturnMode) -> Vec<(u16, u32, u32)> {
        let m = self.model;
        let lay = &m.layout;
        let n = lay.blocks / m.blocks_per_firing(mode);
        let az: Vec<u32> = (0..n)
            .map(|f| u32::from(lay.block_azimuth(payload, lay.block_of(mode, f, 0, 0))) % 36000)
            .collect();
        let step = |f: usize| -> u32 {
            let (a, b) = if f + 1 < n {
                (az[f], az[f + 1])
            } else if f > 0 {
                (az[f - 1], az[f])
            } else {
                return 0;
            };
            let s = (b + 36000 - a) % 36000;
            if s > crate::sensor::decode::MAX_STEP_CENTIDEG {
                0
            } else {
                s
            }
        };
        let per = m.sequences_per_block.max(1);
        let mut out = Vec::with_capacity(n * per);
        for (f, &a) in az.iter().enumerate() {
            let s = step(f);
            for k in 0..per {
                let within = (s as usize * k / per) as u32;
                out.push((a as u16, within, s / per as u32));
            }
        }
        out
    }

    /// A firing sequence of the block at `azimuth`, `within` past it. The block's azimuth
    /// decides the sweep, as the HDL-32E reader and the synthesizer's labels decide it:
    /// a VLP-16 block just before the cut is wholly the sweep's, though its second
    /// sequence fires past the cut.
    fn on_firing(&mut self, azimuth: u16, within: u32, step: u32) {
        let block_rel = (u32::from(azimuth) + 36000 - self.cut) % 36000;
        let wrapped = self.prev_rel.is_some_and(|p| block_rel + 18000 < p);
        self.prev_rel = Some(block_rel);
        let rel = block_rel + within;
        if wrapped {
            if let Some(b) = self.building.take() {
                self.finish_frame(b, false);
            }
        }
        let (next_index, spare) = (&mut self.next_index, &mut self.spare);
        let b = self.building.get_or_insert_with(|| {
            let index = *next_index;
            *next_index += 1;
            let frame = Frame {
                index,
                partial: false,
                returns: spare.pop().unwrap_or_default(),
            };
            Building::new(frame, rel, step)
        });
        b.extend(rel, step);
    }

    fn finish_frame(&mut self, mut b: Building, last: bool) {
        b.frame.partial = !b.is_whole(last);
        if b.frame.partial {
            self.summary.partial_frames += 1;
        } else {
            self.summary.full_frames += 1;
        }
        if !b.frame.partial || self.keep_partial {
            self.ready.push_back(b.frame);
        } else {
            self.recycle(b.frame);
        }
    }
}

impl crate::frame::FrameSource for ModelFrameReader {
    fn next_batch(&mut self, max: usize, frames: &RangeInclusive<u32>) -> Result<Vec<Frame>> {
        ModelFrameReader::next_batch(self, max, frames)
    }

    fn recycle(&mut self, frame: Frame) {
        ModelFrameReader::recycle(self, frame)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dead_lasers_are_those_without_a_return_in_a_capture_with_returns() {
        let mut s = ModelCaptureSummary {
            returns: 5,
            returns_per_laser: vec![3, 0, 2, 0],
            ..Default::default()
        };
        assert_eq!(s.dead_lasers(), vec![1, 3]);
        s.returns = 0;
        s.returns_per_laser = vec![0; 4];
        assert!(s.dead_lasers().is_empty());
    }
}
