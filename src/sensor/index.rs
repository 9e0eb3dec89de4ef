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
//! The frame cut and the capture clock are [`super::frames::SweepState`], the same piece
//! the reader steps; what each frame keeps (first and last azimuth, for the partial
//! flag) mirrors `FrameReader::finish_frame`, and tests/frame_index.rs checks, frame by
//! frame, that both agree.
//!
//! [`FrameReader::open_at`]: super::frames::FrameReader::open_at

use super::decode::{first_firing_us, PacketDecoder};
use super::frames::{identify_in, ArcBytes, DecoderOptions, SweepState};
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
    pub(super) sweep: SweepState,
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
    sweep: SweepState,
}

/// Iterator over the frames of a capture with their seek points, in frame order (every
/// frame, partial ones included, flagged).
pub struct FrameScan {
    capture: CaptureReader,
    decoder: PacketDecoder,
    cut: u32,
    next_index: u32,
    sweep: SweepState,
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
            sweep: SweepState::default(),
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
                sweep: self.sweep,
            };
            // Its state before the duplicate check: a reader resumed here checks again.
            if self.sweep.is_duplicate(d.payload) {
                continue;
            }
            let offset = d.offset;
            let (firings, n) = self.decoder.firings(d.payload, mode);
            self.sweep.on_packet(
                packet::timestamp_us(d.payload),
                first_firing_us(d.payload, n),
            );
            for firing in &firings[..n] {
                self.on_firing(firing.azimuth, firing.step, &before, offset);
            }
        }
        Ok(())
    }

    fn on_firing(&mut self, azimuth: u16, step: u32, before: &Before, offset: u64) {
        let (rel, wrapped) = self.sweep.on_firing(azimuth, self.cut);
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
                sweep: before.sweep,
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
