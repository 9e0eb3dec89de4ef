//! Frame index: where each frame of a capture starts, found without decoding returns.
//!
//! A chunk of a sharded run or sweep starts mid-capture. Decoding from the start up to
//! the chunk makes a capture cut into C chunks cost C²/2 chunk decodes; the scan here
//! reads only record headers and the twelve block azimuths of each data packet (the
//! returns are never decoded), applies the frame cut of [`super::frames`] to them, and
//! yields each frame with a [`FrameSeek`]: the byte offset of the packet where the frame
//! begins and the frame state just before it. [`FrameReader::open_at`] resumes there and
//! yields the same frames as a reader from the start. The scan streams: it holds one
//! packet and one frame's seek point, whatever the capture's length.
//!
//! The frame cut is the few lines of `FrameReader::on_firing` and `decode_packet` that
//! decide boundaries, repeated here rather than shared so that the decoding loop stays
//! as it is; tests/frame_index.rs checks, frame by frame, that both agree.
//!
//! [`FrameReader::open_at`]: super::frames::FrameReader::open_at

use super::decode::{first_firing_us, PacketDecoder};
use super::frames::{identify_in, ArcBytes, DecoderOptions};
use super::packet::{self, ReturnMode};
use crate::capture::{CapturePoint, CaptureReader};
use crate::error::Result;
use std::collections::VecDeque;
use std::path::Path;
use std::sync::Arc;

/// Where a frame starts: the packet to resume at and the reader's frame state before it.
#[derive(Clone, Debug)]
pub struct FrameSeek {
    /// The frame resumed at.
    pub frame: u32,
    pub(super) capture: CapturePoint,
    pub(super) next_index: u32,
    pub(super) open: bool,
    pub(super) prev_rel: Option<u32>,
    pub(super) prev_azimuth: Option<u16>,
    pub(super) prev_ts: Option<u32>,
    pub(super) hour_offset_us: f64,
    pub(super) first_time_us: Option<f64>,
    pub(super) unwrapped_centideg: u64,
}

/// One frame found by the scan.
#[derive(Clone, Debug)]
pub struct ScannedFrame {
    /// Sweep index, as the frame reader numbers it.
    pub index: u32,
    /// Partial first or last sweep (see [`super::frames`]).
    pub partial: bool,
    /// Where to resume to read this frame first.
    pub seek: FrameSeek,
}

/// A frame being scanned.
struct Open {
    index: u32,
    first_rel: u32,
    first_step: u32,
    last_rel: u32,
    last_step: u32,
    seek: FrameSeek,
}

/// Frame state before a packet, kept until a frame starts in it.
#[derive(Clone, Copy)]
struct Before {
    next_index: u32,
    open: bool,
    prev_rel: Option<u32>,
    prev_azimuth: Option<u16>,
    prev_ts: Option<u32>,
    hour_offset_us: f64,
    first_time_us: Option<f64>,
    unwrapped_centideg: u64,
}

/// Iterator over the frames of a capture with their seek points, in frame order (every
/// frame, partial ones included, flagged).
pub struct FrameScan {
    capture: CaptureReader,
    decoder: PacketDecoder,
    cut: u32,
    next_index: u32,
    prev_rel: Option<u32>,
    prev_azimuth: Option<u16>,
    prev_ts: Option<u32>,
    hour_offset_us: f64,
    first_time_us: Option<f64>,
    unwrapped_centideg: u64,
    building: Option<Open>,
    ready: VecDeque<ScannedFrame>,
    done: bool,
}

impl FrameScan {
    /// Scans a capture file, refusing it unless it is an HDL-32E capture (as the reader).
    pub fn open(path: &Path, options: &DecoderOptions) -> Result<Self> {
        identify_in(CaptureReader::open(path)?)?;
        Ok(Self::new(CaptureReader::open(path)?, options))
    }

    /// Scans a capture held in memory; `name` stands for it in messages.
    pub fn from_bytes(bytes: Arc<[u8]>, name: &Path, options: &DecoderOptions) -> Result<Self> {
        let open =
            || CaptureReader::from_reader(std::io::Cursor::new(ArcBytes(bytes.clone())), name);
        identify_in(open()?)?;
        Ok(Self::new(open()?, options))
    }

    fn new(capture: CaptureReader, options: &DecoderOptions) -> Self {
        FrameScan {
            capture,
            // Only `firings` is used: block azimuths and steps, no returns.
            decoder: PacketDecoder::new(&options.calibration, false, options.dual),
            cut: ((options.cut_angle_deg.rem_euclid(360.0) * 100.0).round() as u32) % 36000,
            next_index: 0,
            prev_rel: None,
            prev_azimuth: None,
            prev_ts: None,
            hour_offset_us: 0.0,
            first_time_us: None,
            unwrapped_centideg: 0,
            building: None,
            ready: VecDeque::new(),
            done: false,
        }
    }

    fn finish(&mut self, b: Open, last: bool) {
        // As `FrameReader::finish_frame`.
        let first_ok = b.index > 0 || b.first_rel <= b.first_step.max(1);
        let last_ok = !last || b.last_rel + b.last_step.max(1) >= 36000;
        self.ready.push_back(ScannedFrame {
            index: b.index,
            partial: !(first_ok && last_ok),
            seek: b.seek,
        });
    }

    fn pump(&mut self) -> Result<()> {
        while self.ready.is_empty() && !self.done {
            let Some(d) = self.capture.next_datagram()? else {
                self.done = true;
                if let Some(b) = self.building.take() {
                    self.finish(b, true);
                }
                break;
            };
            // As `FrameReader::pump` and `decode_packet`, up to the firings.
            if d.payload.len() == packet::POSITION_PACKET_BYTES
                || !packet::is_data_packet(d.payload)
            {
                continue;
            }
            let Some(mode) = ReturnMode::from_byte(packet::return_mode_byte(d.payload)) else {
                continue;
            };
            let before = Before {
                next_index: self.next_index,
                open: self.building.is_some(),
                prev_rel: self.prev_rel,
                prev_azimuth: self.prev_azimuth,
                prev_ts: self.prev_ts,
                hour_offset_us: self.hour_offset_us,
                first_time_us: self.first_time_us,
                unwrapped_centideg: self.unwrapped_centideg,
            };
            let offset = d.offset;
            let ts = packet::timestamp_us(d.payload);
            if let Some(prev) = self.prev_ts {
                if u64::from(ts) + 1_800_000_000 < u64::from(prev) {
                    self.hour_offset_us += 3_600_000_000.0;
                }
            }
            self.prev_ts = Some(ts);
            let (firings, n) = self.decoder.firings(d.payload, mode);
            let time0 = first_firing_us(d.payload, n) + self.hour_offset_us;
            self.first_time_us.get_or_insert(time0);
            for firing in &firings[..n] {
                self.on_firing(firing.azimuth, firing.step, &before, offset);
            }
        }
        Ok(())
    }

    fn on_firing(&mut self, azimuth: u16, step: u32, before: &Before, offset: u64) {
        if let Some(prev) = self.prev_azimuth {
            let d = (u32::from(azimuth) + 36000 - u32::from(prev)) % 36000;
            if d < 18000 {
                self.unwrapped_centideg += u64::from(d);
            }
        }
        self.prev_azimuth = Some(azimuth);
        let rel = (u32::from(azimuth) + 36000 - self.cut) % 36000;
        let wrapped = self.prev_rel.is_some_and(|p| rel + 18000 < p);
        self.prev_rel = Some(rel);
        if wrapped {
            if let Some(b) = self.building.take() {
                self.finish(b, false);
            }
        }
        if self.building.is_none() {
            let index = self.next_index;
            self.next_index += 1;
            let seek = FrameSeek {
                frame: index,
                capture: self.capture.point_before_last(offset),
                next_index: before.next_index,
                open: before.open,
                prev_rel: before.prev_rel,
                prev_azimuth: before.prev_azimuth,
                prev_ts: before.prev_ts,
                hour_offset_us: before.hour_offset_us,
                first_time_us: before.first_time_us,
                unwrapped_centideg: before.unwrapped_centideg,
            };
            self.building = Some(Open {
                index,
                first_rel: rel,
                first_step: step,
                last_rel: rel,
                last_step: step,
                seek,
            });
        }
        if let Some(b) = self.building.as_mut() {
            b.last_rel = rel;
            b.last_step = step;
        }
    }
}

impl Iterator for FrameScan {
    type Item = Result<ScannedFrame>;

    fn next(&mut self) -> Option<Self::Item> {
        if let Err(e) = self.pump() {
            self.done = true;
            self.ready.clear();
            return Some(Err(e));
        }
        self.ready.pop_front().map(Ok)
    }
}
