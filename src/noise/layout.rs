//! Compact columns of a frame's clean returns that sensor stages read, and laser sets.

use super::spurious;
use crate::frame::Return;

/// Compact copies of the clean returns' fields that sensor stages read, and the frame's
/// firings, built in one pass over the returns.
///
/// Why: a 50k-return frame's `clean` is 2.4 MB, more than the L2 cache, and every stage
/// that read one byte (laser id) or one time per return streamed all of it again; these
/// columns are 50-400 kB.
#[derive(Clone, Debug, Default)]
pub struct Layout {
    /// Laser id of each return (modulo [`spurious::MAX_LASERS`], so per-laser tables of
    /// that size need no bounds check).
    pub laser: Vec<u8>,
    /// Clean intensity byte of each return.
    pub intensity: Vec<u8>,
    /// Clean firing time of each return (seconds, as `Return::time`).
    pub time: Vec<f64>,
    /// Clean azimuth of each return (degrees).
    pub azimuth: Vec<f32>,
    /// Maximal runs of consecutive returns with the same packet and block (firings), as
    /// ranges of return indices `[start, end)`, in order.
    pub firings: Vec<[u32; 2]>,
    /// Smallest and largest clean firing time, NaN ignored (`[inf, -inf]` when there is
    /// none): lets stages whose factor is monotone in time table it for the frame.
    pub time_range: [f64; 2],
    /// Some clean firing time is NaN (outside `time_range`).
    pub time_nan: bool,
}

impl Layout {
    /// The columns and firings of `clean`.
    pub fn of(clean: &[Return]) -> Layout {
        Layout::build(clean, |_| {})
    }

    /// The columns and firings of `clean`, with `also` called on every chunk of at most
    /// [`LAYOUT_CHUNK`] returns, in order, in the same pass.
    ///
    /// Why chunks: each chunk's columns are written to small buffers (in L1 cache) and
    /// appended to the columns, which are therefore never zeroed first (`vec![0; n]`
    /// wrote them all once more); `also` reads the chunk's returns while they are in
    /// cache; and the loop over one chunk keeps its few pointers in registers (the
    /// iterator over every column and the return spilled them to the stack).
    #[inline(always)]
    pub(super) fn build(clean: &[Return], mut also: impl FnMut(&[Return])) -> Layout {
        const B: usize = LAYOUT_CHUNK;
        let n = clean.len();
        let mut l = Layout {
            laser: Vec::with_capacity(n),
            intensity: Vec::with_capacity(n),
            time: Vec::with_capacity(n),
            azimuth: Vec::with_capacity(n),
            firings: Vec::with_capacity(n / 32 + 1),
            time_range: [f64::INFINITY, f64::NEG_INFINITY],
            time_nan: false,
        };
        let (mut laser, mut intensity) = ([0u8; B], [0u8; B]);
        let (mut time, mut azimuth) = ([0f64; B], [0f32; B]);
        // The running extremes of the times, as four pairs (see `TimeExtremes`).
        let mut extremes = TimeExtremes::new();
        // A firing starts where packet or block changes (its end is set below).
        let mut key = None;
        for (c, chunk) in clean.chunks(B).enumerate() {
            also(chunk);
            let m = chunk.len();
            for (j, r) in chunk.iter().enumerate() {
                laser[j] = r.laser & LASER_MASK;
                intensity[j] = r.intensity;
                time[j] = r.time;
                azimuth[j] = r.azimuth;
                let k = (r.packet, r.block);
                if key != Some(k) {
                    key = Some(k);
                    l.firings.push([(c * B + j) as u32, n as u32]);
                }
            }
            extremes.add(&time[..m]);
            l.laser.extend_from_slice(&laser[..m]);
            l.intensity.extend_from_slice(&intensity[..m]);
            l.time.extend_from_slice(&time[..m]);
            l.azimuth.extend_from_slice(&azimuth[..m]);
        }
        // Each firing ends where the next starts (the last at `n`, as pushed).
        for k in 1..l.firings.len() {
            l.firings[k - 1][1] = l.firings[k][0];
        }
        l.time_range = extremes.range();
        l.time_nan = extremes.nan;
        l
    }

    /// Number of returns covered.
    pub fn len(&self) -> usize {
        self.laser.len()
    }

    /// True when it covers no return.
    pub fn is_empty(&self) -> bool {
        self.laser.is_empty()
    }
}

/// Why laser ids (or rings) given at `key` do not all exist on a sensor of `lasers`
/// lasers, if they do not.
pub fn check_ids(key: &str, ids: Option<&[u8]>, lasers: usize) -> Result<(), String> {
    match ids.and_then(|ids| ids.iter().find(|&&i| usize::from(i) >= lasers)) {
        Some(i) => Err(format!(
            "{key} names {i}, but the sensor has {lasers} lasers (0 to {})",
            lasers - 1
        )),
        None => Ok(()),
    }
}

/// A set of laser ids (or rings) below [`spurious::MAX_LASERS`]: the lasers a stage
/// acts on, tested per return with one shift.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LaserSet(u128);

impl LaserSet {
    /// Every id.
    pub const ALL: LaserSet = LaserSet(u128::MAX);
    /// No id.
    pub const NONE: LaserSet = LaserSet(0);

    /// The set of `ids` (ids from [`spurious::MAX_LASERS`] up are taken modulo it).
    pub fn of(ids: &[u8]) -> Self {
        LaserSet(ids.iter().fold(0, |m, &i| m | (1u128 << (i & LASER_MASK))))
    }

    /// True when `id` is in the set (never for an id from [`spurious::MAX_LASERS`] up).
    #[inline]
    pub fn contains(self, id: u8) -> bool {
        id <= LASER_MASK && self.0 & (1u128 << id) != 0
    }
}

/// Keeps a laser id within a per-laser table of [`spurious::MAX_LASERS`] entries.
pub const LASER_MASK: u8 = (spurious::MAX_LASERS - 1) as u8;

/// Returns per chunk of [`Layout`]'s pass (a multiple of 4, see [`TimeExtremes`]).
pub(super) const LAYOUT_CHUNK: usize = 256;

/// The smallest and largest time of a column fed in order, NaN ignored: four running
/// pairs, so successive comparisons do not wait on each other (a NaN compares false and
/// is left out; the selects are single min/max instructions). Times go to pair `i % 4`
/// by their index `i` in the column, and the last `len % 4` to pair 0, as long as every
/// piece fed but the last has a length that is a multiple of 4.
struct TimeExtremes {
    lo: [f64; 4],
    hi: [f64; 4],
    /// Some time was NaN.
    nan: bool,
}

impl TimeExtremes {
    fn new() -> Self {
        TimeExtremes {
            lo: [f64::INFINITY; 4],
            hi: [f64::NEG_INFINITY; 4],
            nan: false,
        }
    }

    #[inline(always)]
    fn add(&mut self, times: &[f64]) {
        let (lo, hi) = (&mut self.lo, &mut self.hi);
        let mut quads = times.chunks_exact(4);
        for q in &mut quads {
            for k in 0..4 {
                lo[k] = if q[k] < lo[k] { q[k] } else { lo[k] };
                hi[k] = if q[k] > hi[k] { q[k] } else { hi[k] };
            }
        }
        for &t in quads.remainder() {
            lo[0] = if t < lo[0] { t } else { lo[0] };
            hi[0] = if t > hi[0] { t } else { hi[0] };
        }
        self.nan |= times.iter().fold(false, |any, t| any | t.is_nan());
    }

    /// `[smallest, largest]` (`[inf, -inf]` when no time was a number).
    fn range(&self) -> [f64; 2] {
        [
            self.lo.into_iter().fold(f64::INFINITY, f64::min),
            self.hi.into_iter().fold(f64::NEG_INFINITY, f64::max),
        ]
    }
}
