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
//!   its firings' order (`tests/cloud_equivalence.rs`). When two points claim one slot
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
//!   (`tests/cloud_equivalence.rs`), where on the azimuth grid a turn whose speed varies
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
    /// it, or near it), which then is searched. On a KITTI scan the search took 0.9 ms
    /// of the 5 ms its points take to become returns, the table 0.55 ms.
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
            if crate::noise::transmission::avx512() {
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
    /// closure passed to `transmission::wide` was not inlined into it and ran as SSE2.
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
            raw[k] = crate::noise::round_clamped(range[k] / unit_m, u16::MAX);
            let i = f64::from(p.intensity);
            bytes[k] = crate::noise::round_clamped(i * scale, 255) as u8;
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
        // (a loop: `flat_map` and `find` made a real KITTI scan's conversion 4.54 ms,
        // this 4.36).
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
mod tests {
    use super::*;
    use crate::sensor::HDL32E;

    /// Each build of the geometry loop this processor runs (AVX2, AVX-512) gives the
    /// baseline build's bits, on points all around the sensor and at every scale, with
    /// zeros, signed zeros and values that are not finite.
    #[test]
    fn every_geometry_build_gives_the_plain_loops_bits() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(17);
        let special = [
            0.0f32,
            -0.0,
            f32::NAN,
            f32::INFINITY,
            -f32::INFINITY,
            1e-30,
            3e38,
        ];
        let chunk: Vec<CloudPoint> = (0..CHUNK)
            .map(|i| {
                let mut c = [0, 1, 2, 3].map(|_| {
                    let scale = 10f32.powi(rng.random_range(-3..4));
                    rng.random_range(-1.0f32..1.0) * scale
                });
                if i % 13 == 0 {
                    c[i / 13 % 4] = special[i / 52 % special.len()];
                }
                CloudPoint {
                    x: c[0],
                    y: c[1],
                    z: c[2],
                    intensity: c[3].abs(),
                    ring: None,
                    time: None,
                }
            })
            .collect();
        let rows = |g: &Geometry| {
            let f = |v: &[f64; CHUNK]| v.map(f64::to_bits);
            (
                [g.range, g.horizontal, g.azimuth, g.elevation, g.steps].map(|v| f(&v)),
                g.raw,
                g.intensity,
                g.finite,
            )
        };
        let (steps, unit, scale) = (2083.0 / 360.0, 0.002, 255.0);
        let mut plain = Box::<Geometry>::default();
        plain.of_any(&chunk, steps, unit, scale);
        let want = rows(&plain);
        // A point that is not finite is flagged; the rest are.
        assert!(want.3.iter().any(|&f| !f) && want.3.iter().filter(|&&f| f).count() > CHUNK / 2);
        let mut g = Box::<Geometry>::default();
        g.of(&chunk, steps, unit, scale);
        assert!(rows(&g) == want, "picked");
        #[cfg(target_arch = "x86_64")]
        {
            if std::arch::is_x86_feature_detected!("avx2") {
                let mut g = Box::<Geometry>::default();
                // SAFETY: the processor has AVX2 (checked on the line above).
                unsafe { g.of_avx2(&chunk, steps, unit, scale) };
                assert!(rows(&g) == want, "avx2");
            }
            if crate::noise::transmission::avx512() {
                let mut g = Box::<Geometry>::default();
                // SAFETY: the processor has AVX-512 F and DQ (checked on the line above).
                unsafe { g.of_avx512(&chunk, steps, unit, scale) };
                assert!(rows(&g) == want, "avx512");
            }
        }
    }

    fn point(x: f32, y: f32, z: f32, intensity: f32, ring: Option<u16>) -> CloudPoint {
        CloudPoint {
            x,
            y,
            z,
            intensity,
            ring,
            time: None,
        }
    }

    /// The point laser `laser` would measure at `range` in firing `k` of a 10 Hz turn,
    /// written from the sensor's description (not from the code under test).
    fn on_grid(k: u32, laser: usize, range: f64) -> CloudPoint {
        // 46.08 us a firing, 1.152 us a laser; 10 Hz is 3.6e-3 degrees a microsecond.
        let az = (f64::from(k) * 46.08 + laser as f64 * 1.152) * 3.6e-3;
        let el = crate::sensor::calibration::BUILTIN_ELEVATION_DEG[laser];
        let (sa, ca) = az.to_radians().sin_cos();
        let (se, ce) = el.to_radians().sin_cos();
        point(
            (range * ce * ca) as f32,
            (-range * ce * sa) as f32,
            (range * se) as f32,
            100.0,
            None,
        )
    }

    #[test]
    fn each_models_shared_table_is_built_once_and_is_its_own() {
        for model in crate::sensor::MODELS {
            let shared = BeamTable::of(model);
            assert!(
                Arc::ptr_eq(&shared, &BeamTable::of(model)),
                "{}",
                model.name
            );
            let fresh = BeamTable::new(model);
            assert_eq!(shared.by_elevation, fresh.by_elevation, "{}", model.name);
            assert_eq!(shared.direct, fresh.direct, "{}", model.name);
            assert_eq!(shared.bounds, fresh.bounds, "{}", model.name);
        }
        // Same lasers, another table: a model that differs only in its elevations gets
        // its own entry.
        let a = &crate::sensor::HDL64E_S2;
        let b = &crate::sensor::HDL64E_KITTI;
        assert!(!Arc::ptr_eq(&BeamTable::of(a), &BeamTable::of(b)));
    }

    #[test]
    fn the_binned_search_is_the_partition_point() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        for model in crate::sensor::MODELS {
            let beams = BeamTable::new(model);
            let want = |e: f64| beams.bounds.partition_point(|&b| b < e);
            let mut elevations = vec![-90.0, 90.0, -1e9, 1e9, 0.0, -0.0];
            for &b in &beams.bounds {
                elevations.extend([b, b.next_down(), b.next_up()]);
            }
            for bin in 0..=2880 {
                let start = -90.0 + f64::from(bin) / BINS_PER_DEG;
                elevations.extend([start, start.next_down(), start.next_up()]);
            }
            elevations.extend((0..20_000).map(|_| rng.random_range(-95.0..95.0)));
            for e in elevations {
                assert_eq!(beams.first_at_or_above(e), want(e), "{} at {e}", model.name);
            }
        }
    }

    #[test]
    fn the_direct_table_gives_the_search_answer() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(12);
        for model in crate::sensor::MODELS {
            let beams = BeamTable::new(model);
            let looked_up = beams.direct.iter().filter(|&&d| d != DIRECT_SEARCH).count();
            assert!(
                looked_up * 100 > beams.direct.len() * 95,
                "{}: {looked_up} of {} bins looked up",
                model.name,
                beams.direct.len()
            );
            let mut elevations = vec![-90.0, 90.0, -1e9, 1e9, 0.0, -0.0];
            // Every bin's edges and middle, and the places the answer changes, each with
            // its neighbouring floats.
            for b in 0..=beams.direct.len() {
                let start = -90.0 + b as f64 / DIRECT_BINS_PER_DEG;
                elevations.extend([start, start + 0.5 / DIRECT_BINS_PER_DEG]);
            }
            let n = beams.elevation.len();
            for i in 0..n {
                let e = beams.elevation[i];
                for j in [i.saturating_sub(1), (i + 1).min(n - 1)] {
                    let q = 0.25 * (beams.elevation[j] - e).abs();
                    elevations.extend([e, e + q, e - q]);
                }
            }
            elevations.extend(beams.bounds.iter().copied());
            let mut around = Vec::new();
            for &e in &elevations {
                let (mut up, mut down) = (e, e);
                for _ in 0..3 {
                    (up, down) = (up.next_up(), down.next_down());
                    around.extend([up, down]);
                }
            }
            elevations.extend(around);
            elevations.extend((0..200_000).map(|_| rng.random_range(-91.0..91.0)));
            for e in elevations {
                assert_eq!(beams.nearest(e), beams.searched(e), "{} at {e}", model.name);
            }
        }
    }

    #[test]
    fn a_point_on_the_grid_gets_its_firing_laser_and_time() {
        let opts = ReturnsOptions::default();
        for (k, laser) in [(0u32, 0usize), (1, 31), (100, 15), (1085, 7), (2169, 30)] {
            let out = to_returns(&[on_grid(k, laser, 20.0)], &HDL32E, &opts, "t").unwrap();
            let r = out.returns[0];
            assert_eq!(out.firings, 2170);
            assert_eq!(usize::from(r.laser), laser, "firing {k}");
            assert_eq!(r.packet, k / 12, "firing {k}");
            assert_eq!(u32::from(r.block), k % 12, "firing {k}");
            let t = (f64::from(k) * 46.08 + laser as f64 * 1.152) * 1e-6;
            assert!((r.time - t).abs() < 1e-12, "firing {k}: {} vs {t}", r.time);
            assert!((r.range - 20.0).abs() < 1e-4);
            assert!(
                (f64::from(r.elevation) - crate::sensor::calibration::BUILTIN_ELEVATION_DEG[laser])
                    .abs()
                    < 1e-3
            );
            assert_eq!(r.raw_distance, 10_000);
            assert_eq!(r.ring, HDL32E.rings()[laser]);
        }
    }

    /// The point laser `laser` of `model` would measure at `range` in firing `k` of a
    /// 10 Hz turn, from the manuals' numbers written out here: `fire_us` is the laser's
    /// time in its firing sequence, `az_offset` its azimuth offset, `el` its elevation.
    fn model_point(seq_us: f64, k: u32, fire_us: f64, az_offset: f64, el: f64) -> CloudPoint {
        let az = (f64::from(k) * seq_us + fire_us) * 3.6e-3 + az_offset;
        let (sa, ca) = az.to_radians().sin_cos();
        let (se, ce) = el.to_radians().sin_cos();
        let range = 15.0;
        point(
            (range * ce * ca) as f32,
            (-range * ce * sa) as f32,
            (range * se) as f32,
            10.0,
            None,
        )
    }

    #[test]
    fn every_model_places_a_grid_point_on_its_firing_laser_and_time() {
        use crate::sensor::{HDL64E_S2, HDL64E_S3, PUCK_HI_RES, VLP16, VLP32C};
        let opts = ReturnsOptions::default();
        // (model, sequence us, firings a turn at 10 Hz, firings a packet, firing k,
        // laser, its firing time in the sequence, azimuth offset, elevation)
        let cases = [
            // VLP-16 manual 9.5: laser 9 fires 9 * 2.304 us into its 55.296 us sequence;
            // Table 9-1: +9 deg. 24 sequences a packet.
            (
                &VLP16,
                55.296,
                1808,
                24,
                700u32,
                9usize,
                9.0 * 2.304,
                0.0,
                9.0,
            ),
            (&PUCK_HI_RES, 55.296, 1808, 24, 1807, 0, 0.0, 0.0, -10.0),
            // VLP-32C: lasers in pairs every 2.304 us, laser 29 is pair 14: 32.256 us;
            // Table 9-1: +15 deg, azimuth offset -1.4 deg.
            (&VLP32C, 55.296, 1808, 12, 100, 29, 14.0 * 2.304, -1.4, 15.0),
            // HDL-64E S2: 48 us firings, groups of four 6 us apart, 0/1.26/2.46/3.66 us
            // in a group; laser 37 (lower bank, lane 5: group 1, second) fires at 7.26 us;
            // VeloView's HDL-64.xml: -20.34 deg, azimuth offset -2.96 deg.
            (
                &HDL64E_S2,
                48.0,
                2083,
                6,
                1000,
                37,
                6.0 + 1.26,
                -2.96,
                -20.34,
            ),
            // Laser 2 (upper bank, lane 2): 2.46 us; +1.15 deg, azimuth offset -3.3 deg:
            // firing 0's direction is 356.7 deg, on the circle's far side.
            (&HDL64E_S2, 48.0, 2083, 6, 0, 2, 2.46, -3.3, 1.15),
            // HDL-64E S3: 57.6 us firings, groups 7.2 us apart, 0/1.3/2.5/3.7 us; laser 63
            // (lower bank, lane 31: group 7, fourth): 7 * 7.2 + 3.7 us; -11.12 deg, -1.54.
            (
                &HDL64E_S3,
                57.6,
                1736,
                6,
                1735,
                63,
                7.0 * 7.2 + 3.7,
                -1.54,
                -11.12,
            ),
        ];
        for (model, seq, n, per_packet, k, laser, fire_us, az_offset, el) in cases {
            let p = model_point(seq, k, fire_us, az_offset, el);
            let out = to_returns(&[p], model, &opts, "t").unwrap();
            let r = out.returns[0];
            let what = format!("{} firing {k} laser {laser}", model.name);
            assert_eq!(out.firings, n, "{what}");
            assert_eq!(usize::from(r.laser), laser, "{what}");
            assert_eq!(r.packet, k / per_packet, "{what}");
            assert_eq!(u32::from(r.block), k % per_packet, "{what}");
            let t = (f64::from(k) * seq + fire_us) * 1e-6;
            assert!((r.time - t).abs() < 1e-9, "{what}: {} vs {t}", r.time);
            assert_eq!(out.from_elevation, 1);
        }
    }

    #[test]
    fn the_elevation_says_when_the_laser_is_a_guess() {
        use crate::sensor::{HDL64E_S2, VLP16};
        let beams = BeamTable::new(&VLP16);
        // VLP-16 beams every 2 deg: +1.2 deg is laser 1 (+1), sure; +1.6 and +2.4 are in
        // the middle half between +1 and +3 (laser 3).
        assert_eq!(beams.nearest(1.2), (1, false));
        assert_eq!(beams.nearest(1.6), (1, true));
        assert_eq!(beams.nearest(2.4), (3, true));
        assert_eq!(beams.nearest(2.6), (3, false));
        // Beyond the top beam (+15, laser 15) by more than half a spacing.
        assert_eq!(beams.nearest(15.4), (15, false));
        assert_eq!(beams.nearest(16.0), (15, true));
        // HDL-64E: -9.37 (laser 56) and -9.15 (laser 57) are 0.22 deg apart.
        let beams = BeamTable::new(&HDL64E_S2);
        assert_eq!(beams.nearest(-9.36), (56, false));
        assert_eq!(beams.nearest(-9.2), (57, false));
        assert_eq!(beams.nearest(-9.29), (56, true));
    }

    #[test]
    fn kittis_table_orders_its_64_lasers_as_the_default_within_the_hdl64e_span() {
        use crate::sensor::{HDL64E_KITTI, HDL64E_S2};
        let (el, dz) = (HDL64E_KITTI.elevation_deg, HDL64E_KITTI.vertical_offset_mm);
        assert_eq!((el.len(), dz.len(), HDL64E_KITTI.lasers), (64, 64, 64));
        // The lasers in the same order by elevation as the default table's, so a ring
        // means the same laser with either.
        assert_eq!(HDL64E_KITTI.rings(), HDL64E_S2.rings());
        // Within the default span widened by 1.5 deg (+2.81 to -23.95); the HDL-64E
        // manuals give +2 to -24.8 deg.
        for (l, &e) in el.iter().enumerate() {
            assert!((-25.45..=4.31).contains(&e), "laser {l}: {e} deg");
        }
        // Beams at least 0.2 deg apart, from the lowest up (the KITTI beams are 0.25 to
        // 0.67 deg apart).
        let beams = BeamTable::new(&HDL64E_KITTI);
        for w in beams.elevation.windows(2) {
            assert!(w[1] - w[0] >= 0.2, "{w:?}");
        }
        // Upper bank (lasers 0-31) about 0.2 m above the origin, lower bank about 0.12 m.
        for (l, &mm) in dz.iter().enumerate() {
            let want = if l < 32 { 190.0..=215.0 } else { 115.0..=130.0 };
            assert!(want.contains(&mm), "laser {l}: {mm} mm");
        }
        // The beams' heights rise with the ring at every distance beyond 0.2 m, which the
        // search of `nearest_at` needs.
        for h in [0.2, 0.5, 1.0, 5.0, 30.0, 120.0] {
            let at: Vec<f64> = (0..64)
                .map(|k| h * beams.slope[k] + beams.origin_m[k])
                .collect();
            assert!(at.windows(2).all(|w| w[1] > w[0]), "at {h} m");
        }
    }

    #[test]
    fn only_kittis_beams_are_matched_in_height() {
        use crate::sensor::{HDL64E_KITTI, MODELS};
        // Every other model: `nearest_at` is `nearest` on the elevation, whatever h and z.
        for m in MODELS {
            let beams = BeamTable::new(m);
            for i in 0..2000 {
                let h = 0.5 + f64::from(i % 97) * 0.7;
                let z = -3.0 + f64::from(i % 89) * 0.05;
                let e = z.atan2(h).to_degrees();
                assert_eq!(beams.nearest_at(h, z, e), beams.nearest(e), "{}", m.name);
            }
        }
        // KITTI's: a point of laser 29 (the top beam, +1.937 deg from 209.2 mm up) at 5 m
        // is seen at +4.3 deg from the origin, above every beam of the elevation table.
        let beams = BeamTable::new(&HDL64E_KITTI);
        let (h, el, dz) = (5.0, 1.937_f64, 0.2092);
        let z = h * el.to_radians().tan() + dz;
        let e = z.atan2(h).to_degrees();
        assert!(e > 4.2, "{e}");
        assert_eq!(beams.nearest_at(h, z, e), (29, false));
        // Laser 38 (the bottom beam, -25.163 deg, 124.7 mm) at 3 m, and halfway between
        // laser 38 and the next beam up (laser 39, -24.648 deg): ambiguous.
        let low = |el: f64| 3.0 * el.to_radians().tan() + 0.1247;
        let z = low(-25.163);
        assert_eq!(
            beams.nearest_at(3.0, z, z.atan2(3.0).to_degrees()),
            (38, false)
        );
        let z = 0.5 * (low(-25.163) + low(-24.648)) - 1e-4;
        assert_eq!(
            beams.nearest_at(3.0, z, z.atan2(3.0).to_degrees()),
            (38, true)
        );
    }

    #[test]
    fn the_ring_decides_the_laser_when_given() {
        // Ring 31 is the top beam (+10.67 deg, laser 31) even for a point at -30 deg.
        let p = point(10.0, 0.0, -5.0, 1.0, Some(31));
        let out = to_returns(&[p], &HDL32E, &ReturnsOptions::default(), "t").unwrap();
        assert_eq!(out.returns[0].laser, 31);
        assert_eq!(out.returns[0].ring, 31);
        // Without a ring, the nearest elevation: atan(-5/10) = -26.57 deg, laser 6 (-26.67).
        let p = point(10.0, 0.0, -5.0, 1.0, None);
        let out = to_returns(&[p], &HDL32E, &ReturnsOptions::default(), "t").unwrap();
        assert_eq!(out.returns[0].laser, 6);
    }

    #[test]
    fn returns_come_in_firing_order_with_the_input_index() {
        // Input in reverse firing order; a taken slot moves the later point to the firing
        // before (the nearer side searched first is the earlier one).
        let pts = vec![
            on_grid(500, 3, 10.0),
            on_grid(20, 9, 10.0),
            on_grid(20, 4, 10.0),
            on_grid(20, 4, 11.0),
        ];
        let out = to_returns(&pts, &HDL32E, &ReturnsOptions::default(), "t").unwrap();
        assert_eq!(out.order, vec![3, 2, 1, 0]);
        let firing = |r: &Return| r.packet * 12 + u32::from(r.block);
        let f: Vec<u32> = out.returns.iter().map(firing).collect();
        assert_eq!(f, vec![19, 20, 20, 500]);
        assert_eq!(out.returns[0].range, 11.0);
        assert_eq!((out.moved, out.shared), (1, 0));
    }

    #[test]
    fn a_collision_moves_one_point_not_the_rest_of_its_line() {
        // One laser's line in file order running down the firings, as KITTI stores it,
        // with a second point in firing 8 (a half step) and firing 3 left empty.
        let ks = [10, 9, 8, 8, 7, 6, 5, 4, 2];
        let pts: Vec<CloudPoint> = ks.iter().map(|&k| on_grid(k, 5, 10.0)).collect();
        let out = to_returns(&pts, &HDL32E, &ReturnsOptions::default(), "t").unwrap();
        let firing = |r: &Return| r.packet * 12 + u32::from(r.block);
        let mut by_point = vec![0; ks.len()];
        for (r, &i) in out.returns.iter().zip(&out.order) {
            by_point[i as usize] = firing(r);
        }
        // Every other point keeps its own firing; the second of firing 8 takes the only
        // firing within two that no point claims (3 is too far; 6 and 7 are claimed).
        assert_eq!(by_point, vec![10, 9, 8, 8, 7, 6, 5, 4, 2]);
        assert_eq!((out.moved, out.shared), (0, 1));
        let pts: Vec<CloudPoint> = [10, 9, 8, 8, 6, 5]
            .iter()
            .map(|&k| on_grid(k, 5, 10.0))
            .collect();
        let out = to_returns(&pts, &HDL32E, &ReturnsOptions::default(), "t").unwrap();
        let mut by_point = vec![0; pts.len()];
        for (r, &i) in out.returns.iter().zip(&out.order) {
            by_point[i as usize] = firing(r);
        }
        assert_eq!(by_point, vec![10, 9, 8, 7, 6, 5]);
        assert_eq!((out.moved, out.shared), (1, 0));
    }

    #[test]
    fn a_full_slot_neighbourhood_is_shared_and_counted() {
        let pts: Vec<CloudPoint> = (0..7).map(|_| on_grid(40, 0, 10.0)).collect();
        let out = to_returns(&pts, &HDL32E, &ReturnsOptions::default(), "t").unwrap();
        assert_eq!((out.moved, out.shared), (4, 2));
    }

    #[test]
    fn points_sharing_slots_follow_their_slots_own_point_in_file_order() {
        // Crowded slots in file order against slot order (a later firing first, lasers
        // interleaved), ranges telling the points apart: each of the crowded slots keeps
        // its first point, the neighbours within reach take four more, the rest share.
        let crowds = [(300, 7), (40, 0), (40, 1), (41, 0), (12, 31)];
        let pts: Vec<CloudPoint> = (0..9)
            .flat_map(|n| {
                crowds
                    .iter()
                    .map(move |&(k, l)| on_grid(k, l, 10.0 + f64::from(n) * 0.01))
            })
            .collect();
        let out = to_returns(&pts, &HDL32E, &ReturnsOptions::default(), "t").unwrap();
        assert!(out.shared >= 8, "{}", out.shared);
        assert_eq!(out.order.len(), pts.len());
        // Returns in firing order, then laser, then file order: strictly ascending.
        let key = |r: &Return, i: u32| (r.packet * 12 + u32::from(r.block), r.laser, i);
        let keys: Vec<_> = out
            .returns
            .iter()
            .zip(&out.order)
            .map(|(r, &i)| key(r, i))
            .collect();
        assert!(keys.windows(2).all(|w| w[0] < w[1]), "{keys:?}");
        // Each point once, at its own range.
        let mut seen = out.order.clone();
        seen.sort_unstable();
        assert!(seen.iter().copied().eq(0..pts.len() as u32));
        for (r, &i) in out.returns.iter().zip(&out.order) {
            let p = &pts[i as usize];
            let (x, y, z) = (f64::from(p.x), f64::from(p.y), f64::from(p.z));
            assert_eq!(r.range, (x * x + y * y + z * z).sqrt() as f32, "point {i}");
        }
    }

    #[test]
    fn intensity_scales_by_format() {
        let p = point(5.0, 1.0, 0.0, 0.5, None);
        let unit = ReturnsOptions {
            intensity_scale: IntensityScale::Unit,
            ..ReturnsOptions::default()
        };
        let out = to_returns(&[p], &HDL32E, &unit, "t").unwrap();
        assert_eq!(out.returns[0].intensity, 128);
        let p = point(5.0, 1.0, 0.0, 300.0, None);
        let out = to_returns(&[p], &HDL32E, &ReturnsOptions::default(), "t").unwrap();
        assert_eq!(out.returns[0].intensity, 255);
    }

    #[test]
    fn bad_points_are_refused_with_their_index() {
        let opts = ReturnsOptions::default();
        let mut pts = vec![point(1.0, 2.0, 3.0, 4.0, None); 5];
        pts[3].y = f32::NAN;
        let e = to_returns(&pts, &HDL32E, &opts, "scan.bin")
            .unwrap_err()
            .to_string();
        assert!(e.contains("scan.bin: point 3 (0-based): y is NaN"), "{e}");
        pts[3].y = 0.0;
        pts[4].ring = Some(32);
        let e = to_returns(&pts, &HDL32E, &opts, "scan.bin")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("point 4 (0-based): ring 32 is out of range"),
            "{e}"
        );
        let slow = ReturnsOptions {
            rotation_hz: 1.0,
            ..opts
        };
        let e = to_returns(&pts[..1], &HDL32E, &slow, "t")
            .unwrap_err()
            .to_string();
        assert!(e.contains("rotation_hz 1"), "{e}");
    }

    #[test]
    fn the_origin_is_a_return_at_zero_range_not_a_nan() {
        let out = to_returns(
            &[point(0.0, 0.0, 0.0, 0.0, None)],
            &HDL32E,
            &ReturnsOptions::default(),
            "t",
        )
        .unwrap();
        let r = out.returns[0];
        assert_eq!((r.range, r.azimuth, r.elevation), (0.0, 0.0, 0.0));
    }

    /// A turn whose motor speeds up and slows down (the azimuth step of a firing from
    /// 0.13 to 0.23 degree, a real sensor's rate varies less), every laser of every
    /// firing, each point with its time in `unit_s` (the firing's start from `t0` plus
    /// the laser's offset).
    fn uneven_turn(firings: u32, unit_s: f64, t0: f64) -> Vec<CloudPoint> {
        let mut pts = Vec::new();
        let mut az = 0.0f64;
        for k in 0..firings {
            for laser in 0..32 {
                let el = crate::sensor::calibration::BUILTIN_ELEVATION_DEG[laser];
                let (sa, ca) = az.to_radians().sin_cos();
                let (se, ce) = el.to_radians().sin_cos();
                let t_us = f64::from(k) * 46.08 + HDL32E.laser_offset_us(laser);
                let mut p = point(
                    (10.0 * ce * ca) as f32,
                    (-10.0 * ce * sa) as f32,
                    (10.0 * se) as f32,
                    50.0,
                    Some(u16::from(HDL32E.rings()[laser])),
                );
                p.time = Some(t0 + t_us * 1e-6 / unit_s);
                pts.push(p);
            }
            az += 0.18 + 0.05 * (f64::from(k) * 0.01).sin();
        }
        pts
    }

    #[test]
    fn points_with_times_keep_their_own_firings() {
        let options = ReturnsOptions::default();
        for (unit, unit_s, t0) in [
            ("s", 1.0, 1.5e9),
            ("ms", 1e-3, 0.0),
            ("us", 1e-6, 7.0),
            ("ns", 1e-9, 0.0),
        ] {
            let pts = uneven_turn(1500, unit_s, t0);
            let out = to_returns(&pts, &HDL32E, &options, "t").unwrap();
            assert_eq!(out.time.map(|t| t.unit), Some(unit));
            assert_eq!((out.firings, out.moved, out.shared), (1500, 0, 0), "{unit}");
            for (j, r) in out.returns.iter().enumerate() {
                let i = out.order[j] as usize;
                assert_eq!(i, j, "{unit}: file order is firing order");
                let k = (i / 32) as u32;
                assert_eq!(r.packet * 12 + u32::from(r.block), k, "{unit}: point {i}");
                let want = pts[i].time.unwrap() - pts[0].time.unwrap();
                assert!((r.time - want * unit_s).abs() < 1e-6, "{unit}: point {i}");
            }
            // The same points by azimuth: the speeding turn puts some on other firings.
            let untimed: Vec<CloudPoint> = pts
                .iter()
                .map(|p| CloudPoint { time: None, ..*p })
                .collect();
            let out = to_returns(&untimed, &HDL32E, &options, "t").unwrap();
            assert_eq!(out.time, None);
            let off = out
                .returns
                .iter()
                .zip(&out.order)
                .filter(|(r, &i)| r.packet * 12 + u32::from(r.block) != i / 32)
                .count();
            assert!(off > 1000, "{unit}: {off}");
        }
    }

    #[test]
    fn times_that_cannot_place_points_leave_them_to_the_azimuth() {
        let options = ReturnsOptions::default();
        // All equal (a scan's one stamp on every point), and several turns in seconds.
        let mut same = uneven_turn(100, 1.0, 0.0);
        same.iter_mut().for_each(|p| p.time = Some(3.0));
        let mut long = uneven_turn(100, 1.0, 0.0);
        long.last_mut().unwrap().time = Some(1e12);
        for pts in [same, long] {
            let out = to_returns(&pts, &HDL32E, &options, "t").unwrap();
            assert_eq!(out.time, None);
            assert_eq!(out.firings, 2170);
        }
        // Two points of one firing and laser (a dual return) share its slot.
        let mut pts = uneven_turn(10, 1.0, 0.0);
        let twin = pts[33];
        pts.push(twin);
        let out = to_returns(&pts, &HDL32E, &options, "t").unwrap();
        assert_eq!((out.moved, out.shared), (0, 1));
        assert_eq!(out.order[34], 320);
        // A time that is not a number is refused with its point.
        let mut pts = uneven_turn(10, 1.0, 0.0);
        pts[7].time = Some(f64::NAN);
        let e = to_returns(&pts, &HDL32E, &options, "t").unwrap_err();
        assert!(
            e.to_string().contains("point 7 (0-based): time is NaN"),
            "{e}"
        );
    }
}
