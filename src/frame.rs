//! Decoded returns and frames: the one data type every stage after the decoder sees.

use serde::{Deserialize, Serialize};

/// Which return of a firing a point is.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[repr(u8)]
pub enum ReturnKind {
    /// Single-return mode 0x37: the strongest return.
    Strongest = 0,
    /// Single-return mode 0x38: the last return.
    Last = 1,
    /// Dual mode 0x39, even block of a pair: the last return.
    DualLast = 2,
    /// Dual mode 0x39, odd block of a pair: the strongest return, or the second
    /// strongest where the strongest is also the last.
    DualStrongest = 3,
}

/// One decoded laser return.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Return {
    /// Forward coordinate in metres (ROS velodyne convention).
    pub x: f32,
    /// Leftward coordinate in metres.
    pub y: f32,
    /// Upward coordinate in metres.
    pub z: f32,
    /// Range in metres (raw distance times the distance resolution).
    pub range: f32,
    /// Azimuth in degrees, clockwise seen from above, in [0, 360).
    pub azimuth: f32,
    /// Elevation in degrees.
    pub elevation: f32,
    /// Firing time in seconds (sensor clock) since the top of the hour in which the
    /// capture starts; later hours continue past 3600.
    pub time: f64,
    /// Zero-based index of the capture record that carried the return.
    pub packet: u32,
    /// Raw distance in the packet's distance units (2 mm on the HDL-32E and VLP-16, 4 mm
    /// on the VLP-32C and VLS-128; the sensor model's `distance_resolution_m`).
    pub raw_distance: u16,
    /// Intensity byte as reported by the sensor.
    pub intensity: u8,
    /// Laser id: the channel's index in the sensor model's laser table (0 to lasers - 1).
    pub laser: u8,
    /// Ring (lasers sorted by elevation, 0 = lowest).
    pub ring: u8,
    /// Data block index within the packet (0 to 11).
    pub block: u8,
    /// Which return of the firing this is.
    pub kind: ReturnKind,
}

impl Return {
    /// A return with every field zero (the strongest return of laser 0 in block 0): the
    /// filler of decoder slots before they are decoded, and the base of returns built
    /// field by field.
    pub const BLANK: Return = Return {
        x: 0.0,
        y: 0.0,
        z: 0.0,
        range: 0.0,
        azimuth: 0.0,
        elevation: 0.0,
        time: 0.0,
        packet: 0,
        raw_distance: 0,
        intensity: 0,
        laser: 0,
        ring: 0,
        block: 0,
        kind: ReturnKind::Strongest,
    };
}

/// One rotation of the sensor.
#[derive(Clone, Debug, Default)]
pub struct Frame {
    /// Zero-based sweep index within the capture, partial first sweep included.
    pub index: u32,
    /// True for a sweep that does not cover a full turn (first or last of a capture).
    pub partial: bool,
    /// Returns in capture order.
    pub returns: Vec<Return>,
}

/// A source of frames in capture order: a decoded capture or a point-cloud file.
pub trait FrameSource {
    /// Up to `max` next frames whose index lies in `frames`; empty once the source (or the
    /// range) is exhausted.
    fn next_batch(
        &mut self,
        max: usize,
        frames: &std::ops::RangeInclusive<u32>,
    ) -> crate::error::Result<Vec<Frame>>;

    /// Hands a finished frame's buffer back for reuse.
    fn recycle(&mut self, frame: Frame);

    /// Every remaining frame whose index lies in `frames`, in order.
    fn read_rest(
        &mut self,
        frames: &std::ops::RangeInclusive<u32>,
    ) -> crate::error::Result<Vec<Frame>> {
        let mut all = Vec::new();
        loop {
            let batch = self.next_batch(16, frames)?;
            if batch.is_empty() {
                return Ok(all);
            }
            all.extend(batch);
        }
    }

    /// Reads the source to its end (or past `frames`), counting the frames in `frames`
    /// and keeping none (their buffers recycled).
    fn count_rest(
        &mut self,
        frames: &std::ops::RangeInclusive<u32>,
    ) -> crate::error::Result<usize> {
        let mut n = 0;
        loop {
            let batch = self.next_batch(16, frames)?;
            if batch.is_empty() {
                return Ok(n);
            }
            n += batch.len();
            batch.into_iter().for_each(|f| self.recycle(f));
        }
    }
}

impl Frame {
    /// Time of the first return in the frame, in seconds past the hour.
    pub fn start_time(&self) -> f64 {
        self.returns.first().map_or(0.0, |r| r.time)
    }
}

/// What happened to a return; the first cause in pipeline order wins.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize)]
#[serde(rename_all = "snake_case")]
#[repr(u8)]
pub enum Fate {
    /// Survives the chain and the filters.
    Kept = 0,
    /// Removed by an occlusion stage (the beam was never emitted).
    Occluded = 1,
    /// Noisy power under the detection threshold.
    BelowPower = 2,
    /// Noisy range under the minimum range.
    BelowMinRange = 3,
    /// Replaced by a spurious echo that won its firing slot: the position and range are
    /// the echo's, `clean` keeps the return that was recorded.
    Replaced = 4,
    /// Added by a stage in a firing slot that had no return (no clean origin).
    Added = 5,
}

/// `cause` of returns whose fate no stage decided: kept returns, and returns dropped by
/// the detection filters.
pub const NO_CAUSE: u8 = u8::MAX;

impl Fate {
    /// The causes of removal, in pipeline order.
    pub const DROPS: [Fate; 3] = [Fate::Occluded, Fate::BelowPower, Fate::BelowMinRange];

    /// True while the sensor still reports the return (kept, or a spurious echo in its place).
    #[inline]
    pub fn is_alive(self) -> bool {
        matches!(self, Fate::Kept | Fate::Replaced | Fate::Added)
    }

    /// True for returns that are echoes of no recorded return.
    #[inline]
    pub fn is_spurious(self) -> bool {
        matches!(self, Fate::Replaced | Fate::Added)
    }

    /// Short snake_case name (as in reports).
    pub fn name(self) -> &'static str {
        match self {
            Fate::Kept => "kept",
            Fate::Occluded => "occluded",
            Fate::BelowPower => "below_power",
            Fate::BelowMinRange => "below_min_range",
            Fate::Replaced => "replaced",
            Fate::Added => "added",
        }
    }
}
