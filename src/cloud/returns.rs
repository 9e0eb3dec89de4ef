//! Point-cloud points as returns of a spinning sensor model (issue 31, "Point clouds in
//! and out"; the Python package's `Chain.apply` on plain arrays, issue 32). Any
//! [`SensorModel`] works: HDL-32E, VLP-16, Puck Hi-Res, VLP-32C, HDL-64E S2/S3.
//!
//! Each point becomes the [`Return`] the sensor would have reported:
//! - range, azimuth and elevation from x y z (azimuth clockwise seen from above, as the
//!   decoder gives it: x = r cos(el) cos(az), y = -r cos(el) sin(az)); x y z are kept as
//!   stored. Mounting and per-laser offsets: the points are taken in the sensor frame as
//!   the dataset stores them (its mounting already removed or never applied); a laser's
//!   vertical offset (VLP-16 and Puck Hi-Res: at most 11.2 mm) is not subtracted, which
//!   moves a point's elevation by under 0.13 deg at 5 m, far less than the 2 deg between
//!   their beams. KITTI's HDL-64E ([`crate::sensor::HDL64E_KITTI`], measured on KITTI
//!   scans) is the exception: its points carry offsets of 0.12 and 0.2 m, so its beams are
//!   lines from the lasers' own origins and a point's laser is the beam whose line passes
//!   nearest in height at its horizontal distance ([`BeamTable::nearest_at`]). A laser's
//!   azimuth offset (VLP-32C: +-1.4 or +-4.2 deg; HDL-64E: up to 9.8 deg) is taken off
//!   the point's azimuth before its firing is found, as the decoder adds it (point
//!   azimuth = firing azimuth + offset).
//! - the laser from the ring (0 = lowest beam, the sensor's rings) where the point has
//!   one, else from the elevation: the laser whose table elevation is nearest (the
//!   model's built-in table; a unit's own calibration differs, by up to 2.5 deg a laser
//!   on the HDL-64E, which [`CloudReturns::ambiguous`] and `notes` measure).
//! - the firing slot from the azimuth on the sensor's firing grid: at `rotation_hz` a turn
//!   holds n = round(1 / (rotation_hz * sequence_us)) firing sequences (2170 for the
//!   HDL-32E at 10 Hz, 1808 for the VLP-16, 2083 for the HDL-64E S2), firing k starting
//!   at azimuth 360 k / n, and laser l of a firing fires `laser_offset_us(l)` after its
//!   start (its group's time on the VLP-32C and HDL-64E, whose two banks fire together).
//!   A point goes to the firing in whose step its own firing started (its azimuth less
//!   laser l's lead), the turn cut at 0 as a capture's sweeps are: a firing started just
//!   before 0 (its lasers interpolated past the cut) is the turn's last, one past 360 (a
//!   laser's offset) the next turn's first; so a capture's frame written as a scan keeps
//!   its firings' order (`tests/integration/cloud_equivalence.rs`). When two points claim one slot
//!   (a dataset's motion compensation, a merged sweep, or KITTI's lines, whose points
//!   come a little faster than the grid's firings), the later in file order moves to the
//!   nearest firing within two on either side that no point claims, and shares the slot
//!   only when those are all claimed (counted in [`CloudReturns::moved`] and
//!   [`CloudReturns::shared`]); a point is never pushed out of its own firing, so a
//!   collision moves one point, not the rest of its line. Slots no point claims are the
//!   sensor's empty slots (sky, no echo), which the spurious-return rules of
//!   `noise::spurious` need.
//! - by time instead, where every point has a time whose span fits one turn at the
//!   sensor's slowest rate in seconds, milliseconds, microseconds or nanoseconds (the
//!   first that fits is the unit): the sensor fires at a fixed rate whatever its motor's
//!   speed, so a point's firing is its time since the earliest point's, less its laser's
//!   offset, in firing periods (rounded), counted from the earliest firing; its return's
//!   time is its own; two points of one slot share it (a dual return, a merged sweep),
//!   none moves. A real capture's frame written with its times keeps every firing
//!   (`tests/integration/cloud_equivalence.rs`), where on the azimuth grid a turn whose speed varies
//!   moves some points. [`CloudReturns::time`] says which placed them.
//! - packet and block from the firing (firings numbered from 0 at the turn's start,
//!   `sequences_per_packet` firings a packet in single return mode: 12 on the HDL-32E and
//!   VLP-32C, 24 on the VLP-16, 6 on the HDL-64E), time = `start_time` + the firing's and
//!   laser's offsets, so time follows the azimuth as in a capture.
//! - the intensity byte from the stored value by the format's scale (KITTI 0-1 times 255,
//!   nuScenes and unstated as stored), rounded and clamped to 0-255.
//!
//! The returns come out in firing order (capture order), which the noise stages and the
//! slots expect; [`CloudReturns::order`] gives each return's point index, so results can
//! be put back in file order.

use crate::cloud::{CloudPoint, IntensityScale};
use crate::error::{Error, Result};
use crate::frame::{Return, ReturnKind};
use crate::sensor::{ReturnMode, SensorModel};
use std::sync::{Arc, Mutex};

/// How points are placed on the sensor's firing grid.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ReturnsOptions {
    /// Rotation rate in Hz (HDL-32E default 10; nuScenes records at 20).
    pub rotation_hz: f64,
    /// How the stored intensity is scaled.
    pub intensity_scale: IntensityScale,
    /// Time of the turn's first firing in seconds (the returns' time base).
    pub start_time: f64,
}

impl Default for ReturnsOptions {
    fn default() -> Self {
        ReturnsOptions {
            rotation_hz: 10.0,
            intensity_scale: IntensityScale::Byte,
            start_time: 0.0,
        }
    }
}

/// Points turned into returns.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct CloudReturns {
    /// The returns, in firing order.
    pub returns: Vec<Return>,
    /// Index in the input of each return's point.
    pub order: Vec<u32>,
    /// Firings in the turn (the grid's size).
    pub firings: u32,
    /// Points moved to a neighbouring firing because their own slot was taken.
    pub moved: usize,
    /// Points left sharing a slot with an earlier point (no free slot within reach).
    pub shared: usize,
    /// Points whose laser came from their elevation (no ring field).
    pub from_elevation: usize,
    /// Of those, points in the middle half between two neighbouring beams of the table
    /// (or more than half a spacing beyond the outermost): their laser is a guess.
    pub ambiguous: usize,
    /// The time field that placed the points, with how its values map to the returns'
    /// times and back; `None` when they were placed by azimuth (no time field, or one
    /// whose span fits one turn in no unit).
    pub time: Option<TimeField>,
}

/// A time field that placed points by time: its unit and how a point's time (as stored)
/// becomes its return's time (seconds from the turn's earliest firing start, plus
/// `start_time`), and back.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TimeField {
    /// "s", "ms", "us" or "ns".
    pub unit: &'static str,
    /// The unit in seconds.
    pub unit_s: f64,
    /// The earliest time, as stored.
    pub t0: f64,
    /// The returns' time base (`ReturnsOptions::start_time`).
    pub start_time: f64,
    /// Microseconds from the earliest firing's start to `t0`'s (a multiple of the firing
    /// period, at most 0: the earliest point's laser may fire after its firing starts).
    pub lead_us: f64,
}

impl TimeField {
    /// The return's time of a point stored with time `t`.
    #[inline]
    pub fn to_return(&self, t: f64) -> f64 {
        self.start_time + ((t - self.t0) * self.unit_s * 1e6 - self.lead_us) * 1e-6
    }

    /// The time to store for a return of time `time` (the inverse of
    /// [`TimeField::to_return`], to rounding).
    pub fn to_file(&self, time: f64) -> f64 {
        self.t0 + ((time - self.start_time) * 1e6 + self.lead_us) * 1e-6 / self.unit_s
    }
}

/// Units a time field is tried in, with their length in seconds: the first in which the
/// field's span fits one turn at the sensor's slowest rate is taken (tools store it in
/// seconds, as ROS's velodyne driver, or in nanoseconds, as Ouster's `t`).
const TIME_UNITS: [(&str, f64); 4] = [("s", 1.0), ("ms", 1e-3), ("us", 1e-6), ("ns", 1e-9)];

/// What places points by time: the time field's unit, its length in seconds, and the
/// earliest time.
type TimeBase = (&'static str, f64, f64);

/// The unit of the points' time field when it can place them: every point has a time,
/// they are not all equal, and their span fits one turn (at the sensor's slowest rate)
/// in that unit. A time that is not a finite number is an error naming its point.
fn time_unit(points: &[CloudPoint], slowest_hz: f64, source: &str) -> Result<Option<TimeBase>> {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for (i, p) in points.iter().enumerate() {
        let Some(t) = p.time else {
            return Ok(None);
        };
        if !t.is_finite() {
            return Err(Error::Invalid(format!(
                "{source}: point {i} (0-based): time is {t}, not a finite number"
            )));
        }
        lo = lo.min(t);
        hi = hi.max(t);
    }
    let span = hi - lo;
    if span.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
        return Ok(None);
    }
    let turn_s = 1.0 / slowest_hz;
    Ok(TIME_UNITS
        .iter()
        .find(|&&(_, s)| span * s <= turn_s)
        .map(|&(u, s)| (u, s, lo)))
}

/// Firings on either side searched for a free slot when a point's own is taken.
const REACH: i64 = 2;

/// A sensor model's beams sorted by elevation, for the laser nearest an elevation.
#[derive(Clone, Debug)]
pub struct BeamTable {
    /// Laser ids from the lowest beam up (the rings' order).
    by_elevation: Vec<u8>,
    /// Their elevations, degrees, ascending.
    elevation: Vec<f64>,
    /// Midpoints between neighbouring beams.
    bounds: Vec<f64>,
    /// Per beam (same order), tan of its elevation, where the beams are lines from their
    /// lasers' own origins ([`beams_from_offset_origins`]); empty else.
    slope: Vec<f64>,
    /// Per beam, the height of its laser's origin above the points' origin in metres.
    origin_m: Vec<f64>,
    /// Per 1/16 degree of elevation from -90: the index of the first bound at or above
    /// the bin's start, where the search for an elevation in the bin begins (a binary
    /// search's mispredicted branches were a twentieth of a KITTI scan's run).
    first_bound: Vec<u8>,
    /// Per 1/[`DIRECT_BINS_PER_DEG`] degree of elevation from -90: the answer of
    /// [`BeamTable::nearest`] for every elevation of the bin (laser id in the low byte,
    /// [`DIRECT_AMBIGUOUS`] where ambiguous), or [`DIRECT_SEARCH`] where the answer
    /// changes within the bin (a bound between beams or an ambiguity threshold lies in
    /// it, or near it), which then is searched: the search alone was a fifth of a KITTI
    /// scan's conversion to returns.
    direct: Vec<u16>,
}

/// Bins of [`BeamTable`]'s `direct` per degree: a fine grid (64 to a degree, 23 KB), so
/// that few bins hold a point where the answer changes (at most three a beam).
const DIRECT_BINS_PER_DEG: f64 = 64.0;

/// Flag of a `direct` entry: the elevations of the bin are ambiguous.
const DIRECT_AMBIGUOUS: u16 = 1 << 8;

/// A `direct` entry whose bin is searched.
const DIRECT_SEARCH: u16 = u16::MAX;

/// Room around a bin within which no change of answer may lie for the bin to be looked
/// up, degrees: far above the rounding of the bin index (`(e + 90) * 64` errs by less
/// than 1e-12 of a degree) and of the thresholds' own arithmetic (a few ulps of 90).
const DIRECT_MARGIN_DEG: f64 = 1e-9;

/// Bins of [`BeamTable`]'s `first_bound` per degree.
const BINS_PER_DEG: f64 = 16.0;

/// Whether `model`'s points carry its lasers' vertical offsets and its table gives the
/// elevations from those offset origins, so that a beam is the line z = h tan(el) + dz
/// (h the horizontal distance): KITTI's HDL-64E, whose offsets (0.12 and 0.2 m) lift a
/// point at 10 m by 0.7 to 1.2 deg, more than two beam spacings. The other models' offsets
/// (the VLP-16's at most 11.2 mm, under 0.13 deg at 5 m) are left in, as they were.
fn beams_from_offset_origins(model: &SensorModel) -> bool {
    model.name == crate::sensor::HDL64E_KITTI.name
}

impl BeamTable {
    /// The beams of `model`, built once a process for each model.
    ///
    /// Why: the table takes about 0.2 ms to build (11,521 bins, each searched), a tenth
    /// of a nuScenes sweep's conversion in the Python package and 1 % of a KITTI scan's
    /// run, and a run or a data loader asks for the same model's table every scan.
    pub fn of(model: &SensorModel) -> Arc<BeamTable> {
        // Keyed by what the table reads, compared bit for bit (so that a NaN still finds
        // its entry and the list cannot grow): a model is a `'static` description, so a
        // few entries at most.
        type Key = (&'static str, usize, &'static [f64], &'static [f64]);
        static BUILT: Mutex<Vec<(Key, Arc<BeamTable>)>> = Mutex::new(Vec::new());
        let key: Key = (
            model.name,
            model.lasers,
            model.elevation_deg,
            model.vertical_offset_mm,
        );
        let bits = |a: &[f64], b: &[f64]| {
            a.iter()
                .map(|x| x.to_bits())
                .eq(b.iter().map(|x| x.to_bits()))
        };
        let same = |k: &Key| k.0 == key.0 && k.1 == key.1 && bits(k.2, key.2) && bits(k.3, key.3);
        // A panic elsewhere while the lock was held leaves the list whole (entries are
        // pushed complete), so a poisoned lock is still read.
        let mut built = BUILT.lock().unwrap_or_else(|p| p.into_inner());
        if let Some((_, t)) = built.iter().find(|(k, _)| same(k)) {
            return Arc::clone(t);
        }
        let table = Arc::new(BeamTable::new(model));
        built.push((key, Arc::clone(&table)));
        table
    }

    /// The beams of `model` (its built-in elevation table).
    pub fn new(model: &SensorModel) -> Self {
        let rings = model.rings();
        let mut by_elevation = vec![0u8; model.lasers];
        for (laser, &ring) in rings.iter().enumerate() {
            by_elevation[usize::from(ring)] = laser as u8;
        }
        let elevation: Vec<f64> = by_elevation
            .iter()
            .map(|&l| model.elevation_deg[usize::from(l)])
            .collect();
        let bounds = elevation.windows(2).map(|w| 0.5 * (w[0] + w[1])).collect();
        let (slope, origin_m) = if beams_from_offset_origins(model) {
            by_elevation
                .iter()
                .zip(&elevation)
                .map(|(&l, e)| {
                    let mm = model.vertical_offset_mm.get(usize::from(l)).copied();
                    (e.to_radians().tan(), mm.unwrap_or(0.0) * 1e-3)
                })
                .unzip()
        } else {
            (Vec::new(), Vec::new())
        };
        let bounds: Vec<f64> = bounds;
        let first_bound = (0..=(180.0 * BINS_PER_DEG) as usize)
            .map(|b| {
                let start = -90.0 + b as f64 / BINS_PER_DEG;
                bounds.partition_point(|&x| x < start) as u8
            })
            .collect();
        let mut table = BeamTable {
            by_elevation,
            elevation,
            bounds,
            slope,
            origin_m,
            first_bound,
            direct: Vec::new(),
        };
        table.direct = table.direct_answers();
        table
    }

    /// The `direct` table: each bin's answer where no elevation within the bin (and
    /// [`DIRECT_MARGIN_DEG`] around it) changes it, else [`DIRECT_SEARCH`]. The answer
    /// changes only at a bound between beams (the nearest beam changes) and at a beam's
    /// ambiguity thresholds, a quarter of the gap to its neighbour on each side; between
    /// them it is constant, so the search's answer anywhere in such a bin is the bin's.
    fn direct_answers(&self) -> Vec<u16> {
        let n = self.elevation.len();
        let mut changes: Vec<f64> = self.bounds.clone();
        for i in 0..n {
            let e = self.elevation[i];
            let (above, below) = self.neighbours(i);
            for (side, j) in [(1.0, above), (-1.0, below)] {
                let gap = (self.elevation[j] - e).abs();
                changes.push(e + side * 0.25 * gap);
            }
        }
        changes.sort_by(f64::total_cmp);
        let bins = (180.0 * DIRECT_BINS_PER_DEG) as usize + 1;
        (0..bins)
            .map(|b| {
                let lo = -90.0 + b as f64 / DIRECT_BINS_PER_DEG - DIRECT_MARGIN_DEG;
                let hi = -90.0 + (b + 1) as f64 / DIRECT_BINS_PER_DEG + DIRECT_MARGIN_DEG;
                // The first change at or above lo: the bin is clear when it lies above hi.
                let k = changes.partition_point(|&c| c < lo);
                if changes.get(k).is_some_and(|&c| c <= hi) {
                    return DIRECT_SEARCH;
                }
                let (laser, ambiguous) = self.searched(0.5 * (lo + hi));
                u16::from(laser) | if ambiguous { DIRECT_AMBIGUOUS } else { 0 }
            })
            .collect()
    }

    /// The laser whose beam is nearest `elevation_deg`, and whether the choice is
    /// ambiguous: the elevation lies more than a quarter of the spacing to the next beam
    /// on its side away from the nearest beam (the middle half between two beams), or
    /// beyond the outermost beams by more than half their spacing.
    #[inline]
    pub fn nearest(&self, elevation_deg: f64) -> (u8, bool) {
        // Truncation as in `first_at_or_above`; anything below -90 (or a NaN) takes the
        // search.
        let bin = (elevation_deg + 90.0) * DIRECT_BINS_PER_DEG;
        if bin >= 0.0 {
            if let Some(&d) = self.direct.get(bin as usize) {
                if d != DIRECT_SEARCH {
                    return (d as u8, d & DIRECT_AMBIGUOUS != 0);
                }
            }
        }
        self.searched(elevation_deg)
    }

    /// [`BeamTable::nearest`] by the search of the bounds.
    #[inline]
    fn searched(&self, elevation_deg: f64) -> (u8, bool) {
        let i = self.first_at_or_above(elevation_deg);
        self.judged(i, elevation_deg, |k| self.elevation[k])
    }

    /// The index of the first bound at or above `elevation_deg` (the bounds' partition
    /// point): from the bin's start, a step or two up (bins are narrower than the beam
    /// spacing), and down where rounding put the bin's start above the elevation, so the
    /// index is the partition point's whatever the table.
    #[inline]
    fn first_at_or_above(&self, elevation_deg: f64) -> usize {
        let last = self.first_bound.len() - 1;
        // Truncation, not `floor` (a libm call on the x86-64 baseline): the same bin for
        // every value at or above 0, and anything below (or a NaN, refused before)
        // starts at bin 0, where the steps below find the partition point all the same.
        let bin = (elevation_deg + 90.0) * BINS_PER_DEG;
        let bin = if bin >= 0.0 {
            (bin as usize).min(last)
        } else {
            0
        };
        let mut i = usize::from(self.first_bound[bin]);
        while i < self.bounds.len() && self.bounds[i] < elevation_deg {
            i += 1;
        }
        while i > 0 && self.bounds[i - 1] >= elevation_deg {
            i -= 1;
        }
        i
    }

    /// The laser of a point at horizontal distance `horizontal` and height `z` (metres)
    /// whose elevation from the origin is `elevation_deg`: [`BeamTable::nearest`], except
    /// where the beams are lines from offset origins (KITTI's HDL-64E), where it is the
    /// beam whose line passes nearest in height at that distance, ambiguous by the same
    /// rule in height.
    #[inline]
    pub fn nearest_at(&self, horizontal: f64, z: f64, elevation_deg: f64) -> (u8, bool) {
        if self.origin_m.is_empty() {
            return self.nearest(elevation_deg);
        }
        // The beams' heights at this distance rise with the ring beyond 0.12 m on KITTI's
        // table (neighbouring beams 0.25 deg or more apart, their offsets by 2 mm at
        // most), so the midpoints can be searched as `nearest` searches its bounds.
        let at = |k: usize| horizontal * self.slope[k] + self.origin_m[k];
        let (mut lo, mut hi) = (0, self.elevation.len() - 1);
        while lo < hi {
            let mid = (lo + hi) / 2;
            if 0.5 * (at(mid) + at(mid + 1)) < z {
                lo = mid + 1;
            } else {
                hi = mid;
            }
        }
        self.judged(lo, z, at)
    }

    /// The beams whose gap to beam `i` judges a point above it and below it: its
    /// neighbours, or at the outermost beams the one neighbour on either side.
    #[inline]
    fn neighbours(&self, i: usize) -> (usize, usize) {
        let n = self.elevation.len();
        let above = if i + 1 < n {
            i + 1
        } else {
            i.saturating_sub(1)
        };
        let below = if i > 0 { i - 1 } else { (i + 1).min(n - 1) };
        (above, below)
    }

    /// The laser of beam `i`, nearest to `value` (the point's elevation or height; `at`
    /// gives each beam's), and whether the choice is ambiguous.
    #[inline]
    fn judged(&self, i: usize, value: f64, at: impl Fn(usize) -> f64) -> (u8, bool) {
        let e = at(i);
        // The neighbour on the point's side of the nearest beam. Both candidates first,
        // then one select: which side a point lies is a coin toss, and as a branch it
        // mispredicted on every other point.
        let (above, below) = self.neighbours(i);
        let j = if value >= e { above } else { below };
        let gap = (at(j) - e).abs();
        let ambiguous = gap > 0.0 && (value - e).abs() > 0.25 * gap;
        (self.by_elevation[i], ambiguous)
    }
}

/// Points whose geometry is computed at a time: a vectorised pass over a chunk, then the
/// sequential placing over the same chunk while its values are in the first-level cache.
const CHUNK: usize = 256;

/// What a chunk of points' returns take from their coordinates and intensity, computed
/// in one vectorised pass: range, horizontal distance, azimuth, elevation, firing steps,
/// raw distance, intensity byte, and whether the point's values are finite.
struct Geometry {
    range: [f64; CHUNK],
    horizontal: [f64; CHUNK],
    azimuth: [f64; CHUNK],
    elevation: [f64; CHUNK],
    /// Azimuth in firing steps from 0.
    steps: [f64; CHUNK],
    /// Range in the sensor's distance units, rounded and clamped (the raw distance).
    raw: [u16; CHUNK],
    /// Intensity byte.
    intensity: [u8; CHUNK],
    /// Whether x, y, z and intensity are all finite.
    finite: [bool; CHUNK],
}

impl Default for Geometry {
    fn default() -> Self {
        Geometry {
            range: [0.0; CHUNK],
            horizontal: [0.0; CHUNK],
            azimuth: [0.0; CHUNK],
            elevation: [0.0; CHUNK],
            steps: [0.0; CHUNK],
            raw: [0; CHUNK],
            intensity: [0; CHUNK],
            finite: [true; CHUNK],
        }
    }
}

impl Geometry {
    /// The geometry of `chunk` (at most [`CHUNK`] points) in its first rows; a point with
    /// a non-finite value gets `finite` false (its other rows are meaningless).
    fn of(&mut self, chunk: &[CloudPoint], steps_per_deg: f64, unit_m: f64, scale: f64) {
        #[cfg(target_arch = "x86_64")]
        {
            if crate::numeric::avx512() {
                // SAFETY: the processor has AVX-512 F and DQ (checked on the line above).
                unsafe { self.of_avx512(chunk, steps_per_deg, unit_m, scale) };
                return;
            }
            if std::arch::is_x86_feature_detected!("avx2") {
                // SAFETY: the processor has AVX2 (checked on the line above).
                unsafe { self.of_avx2(chunk, steps_per_deg, unit_m, scale) };
                return;
            }
        }
        self.of_any(chunk, steps_per_deg, unit_m, scale);
    }

    /// [`Geometry::of`] compiled for AVX-512: eight points a vector.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx512f,avx512dq")]
    unsafe fn of_avx512(
        &mut self,
        chunk: &[CloudPoint],
        steps_per_deg: f64,
        unit_m: f64,
        scale: f64,
    ) {
        self.of_any(chunk, steps_per_deg, unit_m, scale);
    }

    /// [`Geometry::of`] compiled for AVX2: four points a vector instead of SSE2's two
    /// (the same bits: no fused multiply-adds either way). Its own function, because a
    /// closure passed to `numeric::wide` was not inlined into it and ran as SSE2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn of_avx2(
        &mut self,
        chunk: &[CloudPoint],
        steps_per_deg: f64,
        unit_m: f64,
        scale: f64,
    ) {
        self.of_any(chunk, steps_per_deg, unit_m, scale);
    }

    /// [`Geometry::of`]'s loop: branch-free arithmetic (`atan`'s selects, no libm call),
    /// so that it vectorises.
    #[inline(always)]
    fn of_any(&mut self, chunk: &[CloudPoint], steps_per_deg: f64, unit_m: f64, scale: f64) {
        let n = chunk.len();
        let (range, horizontal) = (&mut self.range[..n], &mut self.horizontal[..n]);
        let (azimuth, elevation) = (&mut self.azimuth[..n], &mut self.elevation[..n]);
        let steps = &mut self.steps[..n];
        let (raw, finite) = (&mut self.raw[..n], &mut self.finite[..n]);
        let bytes = &mut self.intensity[..n];
        for (k, p) in chunk.iter().enumerate() {
            let (x, y, z) = (f64::from(p.x), f64::from(p.y), f64::from(p.z));
            // sqrt of the sums, not hypot: libm's hypot (overflow-safe, not needed for
            // coordinates in metres) was an eighth of the conversion's time.
            let h2 = x * x + y * y;
            horizontal[k] = h2.sqrt();
            range[k] = (h2 + z * z).sqrt();
            // atan2 gives [-180, 180] degrees: one add wraps it.
            let a = crate::cloud::atan::atan2(-y, x).to_degrees();
            azimuth[k] = if a < 0.0 { a + 360.0 } else { a };
            steps[k] = azimuth[k] * steps_per_deg;
            elevation[k] = crate::cloud::atan::atan2(z, horizontal[k]).to_degrees();
            raw[k] = crate::numeric::round_clamped(range[k] / unit_m, u16::MAX);
            let i = f64::from(p.intensity);
            bytes[k] = crate::numeric::round_clamped(i * scale, 255) as u8;
            // Zero times a value is 0 unless the value is infinite or NaN.
            finite[k] = (x * 0.0 + y * 0.0) + (z * 0.0 + i * 0.0) == 0.0;
        }
    }
}

/// A point placed on the grid: every value its return takes (32 bytes, two thirds of a
/// return: the rest follows from the firing and the laser).
#[derive(Clone, Copy)]
struct Placed {
    x: f32,
    y: f32,
    z: f32,
    range: f32,
    azimuth: f32,
    elevation: f32,
    firing: u32,
    raw_distance: u16,
    intensity: u8,
    laser: u8,
}

/// Turns `points` into returns of `model` (see the module's documentation). Errors name
/// `source` and the point index: a non-finite coordinate or intensity, a ring at or above
/// the model's number of lasers, a rotation rate outside the model's range.
pub fn to_returns(
    points: &[CloudPoint],
    model: &SensorModel,
    options: &ReturnsOptions,
    source: &str,
) -> Result<CloudReturns> {
    let (lo, hi) = model.rotation_hz;
    if !(options.rotation_hz >= lo && options.rotation_hz <= hi) {
        return Err(Error::Invalid(format!(
            "{source}: rotation_hz {}: the {} turns at {lo} to {hi} Hz",
            options.rotation_hz, model.name
        )));
    }
    if !options.start_time.is_finite() {
        return Err(Error::Invalid(format!(
            "{source}: start_time {} is not a finite number",
            options.start_time
        )));
    }
    if points.len() >= u32::MAX as usize {
        return Err(Error::Invalid(format!(
            "{source}: {} points, more than one turn can hold",
            points.len()
        )));
    }
    let lasers = model.lasers;
    let sequence_us = model.sequence_us;
    let n = (1e6 / (options.rotation_hz * sequence_us)).round().max(1.0) as i64;
    let us_per_deg = 1e6 / (360.0 * options.rotation_hz);
    let per_packet = model.sequences_per_packet(ReturnMode::Strongest) as i64;
    let rings = model.rings();
    let beams = BeamTable::of(model);
    // Per laser: its firing time in the sequence, and its lead (that time and its azimuth
    // offset in rotation) in firing steps, so a point's firing is a subtraction from its
    // azimuth in steps.
    let laser_us: Vec<f64> = (0..lasers).map(|l| model.laser_offset_us(l)).collect();
    let lead_steps: Vec<f64> = (0..lasers)
        .map(|l| {
            let offset_deg = model.azimuth_offset_deg.get(l).copied().unwrap_or(0.0);
            (laser_us[l] + offset_deg * us_per_deg) / sequence_us
        })
        .collect();
    let scale = match options.intensity_scale {
        IntensityScale::Unit => 255.0,
        IntensityScale::Byte | IntensityScale::Unstated => 1.0,
    };
    // Placed by time where the points carry it in a unit that fits one turn: a firing
    // then is the sensor's own (it fires at a fixed rate whatever its motor's speed), so
    // a real capture's frame keeps every firing, where the azimuth grid moves some points
    // of a turn whose speed varies.
    let by_time = time_unit(points, lo, source)?;
    let slots = if by_time.is_some() {
        0
    } else {
        n as usize * lasers
    };
    // The point in each slot (u32::MAX: none); a point that had to share a slot is listed
    // in `sharing` instead, as slot << 32 | point, in file order.
    let mut point_at = vec![u32::MAX; slots];
    let mut sharing: Vec<u64> = Vec::new();
    // Points whose own slot an earlier point had claimed, in file order.
    let mut lost: Vec<u32> = Vec::new();
    let (mut moved, mut from_elevation, mut ambiguous) = (0, 0, 0);
    // Per point, in input order: what its return needs beyond the point itself.
    let mut placed = Vec::with_capacity(points.len());
    let mut geometry = Geometry::default();
    let steps_per_deg = us_per_deg / sequence_us;
    // By time: each point's firing counted from the earliest time, less the laser's
    // offset in its firing; the slots are taken after the loop.
    let mut time_firings: Vec<i64> = Vec::new();
    for (c, chunk) in points.chunks(CHUNK).enumerate() {
        // A non-finite value flows through the chunk's arithmetic harmlessly and is
        // reported when its point's turn comes (after any earlier point's error).
        geometry.of(chunk, steps_per_deg, model.distance_resolution_m, scale);
        let mut lost_here = [0u32; CHUNK];
        let mut lost_n = 0;
        let bad = geometry.finite[..chunk.len()].iter().position(|&f| !f);
        for (j, p) in chunk.iter().enumerate() {
            let i = c * CHUNK + j;
            if bad == Some(j) {
                let (field, v) = p.non_finite().unwrap_or(("x", p.x));
                return Err(Error::Invalid(format!(
                    "{source}: point {i} (0-based): {field} is {v}, not a finite number"
                )));
            }
            let range = geometry.range[j];
            let laser = match p.ring {
                Some(ring) if usize::from(ring) < lasers => beams.by_elevation[usize::from(ring)],
                Some(ring) => {
                    return Err(Error::Invalid(format!(
                        "{source}: point {i} (0-based): ring {ring} is out of range for the \
                         {} ({lasers} lasers, rings 0 to {})",
                        model.name,
                        lasers - 1
                    )))
                }
                None => {
                    let (laser, unsure) = beams.nearest_at(
                        geometry.horizontal[j],
                        f64::from(p.z),
                        geometry.elevation[j],
                    );
                    from_elevation += 1;
                    ambiguous += usize::from(unsure);
                    laser
                }
            };
            let l = usize::from(laser);
            let firing = if let Some((_, unit_s, t0)) = by_time {
                // Every point has a finite time (`time_unit`). The firing is set below,
                // once the earliest is known.
                let t = p.time.unwrap_or(t0);
                let since_us = (t - t0) * unit_s * 1e6 - laser_us[l];
                time_firings.push((since_us / sequence_us).round() as i64);
                0
            } else {
                // The firing on the circle. The turn is cut where a firing starts at
                // azimuth 0, as a capture's sweeps are cut: a firing that started before
                // 0 (a laser of the turn's last firing, interpolated or offset past the
                // cut) is the turn's last, one that starts at or past 360 the next turn's
                // first (a laser fired ahead of its firing's azimuth by an offset); within
                // the turn, the grid firing whose step holds the firing's start (grid
                // firing k covers [k, k + 1) steps, as the turn covers [0, 360): the
                // firings of a capture's sweep, cut at 0, keep their order, one a step
                // while the sensor turns no slower than the grid). Float noise at a
                // step's start (a thousandth of a firing: float32 coordinates give
                // azimuths to about 3e-5 of one) counts as the start itself. Within one
                // turn of the grid either way (azimuths and offsets under one turn), so
                // one add or subtract wraps it (no float remainder).
                const AT_CUT: f64 = 1e-3;
                let turn = n as f64;
                let mut t = geometry.steps[j] - lead_steps[l];
                if t < -AT_CUT {
                    t += turn;
                } else if t >= turn - AT_CUT {
                    t -= turn;
                }
                // Truncation is the floor here: t + AT_CUT is at least 0 (or clamped to
                // 0 whichever way it rounds), and `floor` is a libm call on the x86-64
                // baseline (no SSE4.1 round), a twentieth of the conversion.
                let firing = ((t + AT_CUT) as i64).clamp(0, n - 1);
                let slot = firing as usize * lasers + l;
                // Claimed without a branch: on a real KITTI scan a tenth of the points
                // find their slot taken, scattered, and as a branch that mispredicted.
                // The point is written to the chunk's lost list either way and counted
                // only when its slot was taken.
                let held = point_at[slot];
                let free = held == u32::MAX;
                point_at[slot] = if free { i as u32 } else { held };
                lost_here[lost_n] = i as u32;
                lost_n += usize::from(!free);
                firing
            };
            placed.push(Placed {
                x: p.x,
                y: p.y,
                z: p.z,
                range: range as f32,
                azimuth: geometry.azimuth[j] as f32,
                elevation: geometry.elevation[j] as f32,
                firing: firing as u32,
                raw_distance: geometry.raw[j],
                intensity: geometry.intensity[j],
                laser,
            });
        }
        lost.extend_from_slice(&lost_here[..lost_n]);
    }
    // By time: the firings counted from the earliest, and the slots taken in file order.
    // A point whose slot an earlier point took shares it (its time says it is that
    // firing's: a dual return, or a merged sweep), rather than moving.
    let mut n = n;
    let mut lowest = 0i64;
    if by_time.is_some() && !placed.is_empty() {
        lowest = time_firings.iter().copied().min().unwrap_or(0);
        let last = time_firings.iter().copied().max().unwrap_or(0);
        // Within one turn of the slowest rate (`time_unit`): a few thousand firings.
        n = last - lowest + 1;
        point_at = vec![u32::MAX; n as usize * lasers];
        for (i, (q, &k)) in placed.iter_mut().zip(&time_firings).enumerate() {
            q.firing = (k - lowest) as u32;
            let slot = q.firing as usize * lasers + usize::from(q.laser);
            if point_at[slot] == u32::MAX {
                point_at[slot] = i as u32;
            } else {
                sharing.push((slot as u64) << 32 | i as u64);
            }
        }
    }
    // The points whose own slot an earlier point took, in file order: each moves to the
    // nearest slot of its laser within `REACH` firings that no point claims (the earlier
    // side first), or shares its own. Only unclaimed slots are taken, so a point never
    // displaces another from its own firing: on a real KITTI scan a tenth of the points
    // collide (two points of a line 0.09 deg apart, every 6 or 7 points), and a greedy
    // search in file order moved each following point of the line by one firing, four
    // fifths of the scan.
    for &i in &lost {
        let q = &mut placed[i as usize];
        let (k, l) = (i64::from(q.firing), usize::from(q.laser));
        let free = |f: i64| (0..n).contains(&f) && point_at[f as usize * lasers + l] == u32::MAX;
        // The nearer firings first, the earlier side first: k - 1, k + 1, k - 2, k + 2
        // (a plain loop, which the compiler keeps tighter than `flat_map` and `find`).
        let mut found = None;
        for d in 1..=REACH {
            if free(k - d) {
                found = Some(k - d);
                break;
            }
            if free(k + d) {
                found = Some(k + d);
                break;
            }
        }
        match found {
            Some(f) => {
                moved += 1;
                q.firing = f as u32;
                point_at[f as usize * lasers + l] = i;
            }
            None => sharing.push(((k as usize * lasers + l) as u64) << 32 | u64::from(i)),
        }
    }
    let shared = sharing.len();
    // Firing order, then laser, then file order (the same points always give the same
    // returns): the slots walked in order, a slot's own point before those sharing it
    // (pushed in file order, so a stable sort by slot keeps them so: a radix sort of the
    // slot bits alone, where a comparison sort of the pairs was a sixteenth of a real
    // KITTI scan's conversion, whose 120,000 points leave about 16,000 sharing).
    let slot_bits = u64::BITS - (point_at.len() as u64).leading_zeros();
    crate::radix::sort_packed(&mut sharing, 32, slot_bits);
    let mut order = Vec::with_capacity(points.len());
    let mut rest = sharing.iter().peekable();
    for (slot, &i) in point_at.iter().enumerate() {
        if i != u32::MAX {
            order.push(i);
            while let Some(&&k) = rest.peek() {
                if (k >> 32) as usize != slot {
                    break;
                }
                order.push(k as u32);
                rest.next();
            }
        }
    }
    // The returns built in firing order from the placings (a placing holds all its
    // return needs, so one record is read a return; building returns in input order and
    // then moving them was a fifth of the conversion, most of it the copy's pages),
    // with the room the noise chain keeps for added echoes (it would move them otherwise).
    let mut returns = Vec::with_capacity(order.len() + crate::noise::room_for_added(order.len()));
    let time_field = by_time.map(|(unit, unit_s, t0)| TimeField {
        unit,
        unit_s,
        t0,
        start_time: options.start_time,
        lead_us: lowest as f64 * sequence_us,
    });
    returns.extend(order.iter().map(|&i| {
        let q = &placed[i as usize];
        let l = usize::from(q.laser);
        let firing = i64::from(q.firing);
        // By time, the point's own, from the start of the earliest firing.
        let time = match &time_field {
            Some(f) => f.to_return(points[i as usize].time.unwrap_or(f.t0)),
            None => options.start_time + (firing as f64 * sequence_us + laser_us[l]) * 1e-6,
        };
        Return {
            x: q.x,
            y: q.y,
            z: q.z,
            range: q.range,
            azimuth: q.azimuth,
            elevation: q.elevation,
            time,
            packet: (firing / per_packet) as u32,
            raw_distance: q.raw_distance,
            intensity: q.intensity,
            laser: q.laser,
            ring: rings[l],
            block: (firing % per_packet) as u8,
            kind: ReturnKind::Strongest,
        }
    }));
    Ok(CloudReturns {
        returns,
        order,
        firings: n as u32,
        moved,
        shared,
        from_elevation,
        ambiguous,
        time: time_field,
    })
}

#[cfg(test)]
mod tests;
