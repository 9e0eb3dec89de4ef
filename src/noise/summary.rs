//! Per-frame and per-capture counts of what the chain did.
//!
//! Counts and range-change sums are exact and merge in any order: the range change of
//! each kept return, R_n - R_i, is quantised to whole nanometres and summed in i128.
//! The 95th percentile is of the absolute change |R_n - R_i|, from a fixed histogram
//! that merges exactly: 0.1 mm bins below 0.1 m, 1 mm bins to 1 m, 1 cm bins to 10 m,
//! 10 cm bins to 100 m (3,700 bins, at most 1 % wide relative to their value) plus one
//! overflow bin. It is reported as the upper edge of the bin where 95 % of the returns
//! are reached, capped at the largest change, so it is never below the exact value and
//! at most one bin width (0.1 mm for changes under 10 cm) above it.

use crate::noise::{Fate, NoisyFrame};
use serde::ser::SerializeStruct;
use serde::{Deserialize, Serialize, Serializer};

/// Decades of the absolute-change histogram: (upper end in nm, bin width in nm).
const DECADES: [(u64, u64); 4] = [
    (100_000_000, 100_000),
    (1_000_000_000, 1_000_000),
    (10_000_000_000, 10_000_000),
    (100_000_000_000, 100_000_000),
];

/// Bins per decade after the first one (the first has 1,000).
const BINS: usize = 1000 + 3 * 900 + 1;

/// Histogram bin of an absolute change in nanometres.
///
/// The decades of [`DECADES`] written out: constant divisors compile to a multiplication,
/// where the loop over the table divided by a loaded width (a `div` per kept return).
/// `bins_tile_the_axis` checks it against [`bin_upper_nm`], which walks the table.
#[inline]
fn bin_of(abs_nm: u64) -> usize {
    if abs_nm < 100_000_000 {
        (abs_nm / 100_000) as usize
    } else if abs_nm < 1_000_000_000 {
        1000 + ((abs_nm - 100_000_000) / 1_000_000) as usize
    } else if abs_nm < 10_000_000_000 {
        1900 + ((abs_nm - 1_000_000_000) / 10_000_000) as usize
    } else if abs_nm < 100_000_000_000 {
        2800 + ((abs_nm - 10_000_000_000) / 100_000_000) as usize
    } else {
        BINS - 1
    }
}

/// [`bin_of`] of a change below 2^31 nm (the fast path of [`NoiseSummary::from_frame`]).
///
/// Why without branches: rain's range noise grows with range, so consecutive changes
/// land in different decades at random and `bin_of`'s branches mispredicted; the three
/// decades' bins are all computed and the right one picked by masks (about a third less
/// time for the paper chain's summaries).
#[inline]
fn bin_of_small(abs_nm: u32) -> usize {
    let in1 = 0u32.wrapping_sub(u32::from(abs_nm >= 100_000_000));
    let in2 = 0u32.wrapping_sub(u32::from(abs_nm >= 1_000_000_000));
    let b0 = abs_nm / 100_000;
    let b1 = 1000 + abs_nm.saturating_sub(100_000_000) / 1_000_000;
    let b2 = 1900 + abs_nm.saturating_sub(1_000_000_000) / 10_000_000;
    ((b0 & !in1) | (b1 & in1 & !in2) | (b2 & in2)) as usize
}

/// Upper edge of a histogram bin in nanometres (u64::MAX for the overflow bin).
fn bin_upper_nm(bin: usize) -> u64 {
    let mut first_bin = 0u64;
    let mut lower = 0u64;
    for (upper, width) in DECADES {
        let n = (upper - lower) / width;
        if (bin as u64) < first_bin + n {
            return lower + (bin as u64 - first_bin + 1) * width;
        }
        first_bin += n;
        lower = upper;
    }
    u64::MAX
}

/// `x.round() as i64` (half away from zero) without the libm `round` call, which the
/// per-return loop of [`NoiseSummary::from_frame`] paid for every kept return: below
/// 2^52 the truncation `t` and the fraction `x - t` are exact, so the fraction decides
/// the rounding exactly; NaN, infinities and larger values take `round` itself.
#[inline]
pub(crate) fn round_to_i64(x: f64) -> i64 {
    if x.abs() < 4_503_599_627_370_496.0 {
        let t = x as i64;
        let frac = x - t as f64;
        t + i64::from(frac >= 0.5) - i64::from(frac <= -0.5)
    } else {
        x.round() as i64
    }
}

/// Removed returns by cause.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct DropCounts {
    /// Removed by occlusion.
    pub occluded: u64,
    /// Under the power threshold.
    pub below_power: u64,
    /// Under the minimum range.
    pub below_min_range: u64,
}

/// Removed returns by cause and laser id (index = laser id).
/// One entry a laser of the sensor (32 for the HDL-32E's frames, 64 for the HDL-64E's).
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct DropsByLaser {
    /// Removed by occlusion.
    pub occluded: Vec<u64>,
    /// Under the power threshold.
    pub below_power: Vec<u64>,
    /// Under the minimum range.
    pub below_min_range: Vec<u64>,
}

impl DropsByLaser {
    /// Zero counts for a sensor of `lasers` lasers (at least one).
    pub fn new(lasers: usize) -> Self {
        let zeros = vec![0; lasers.max(1)];
        DropsByLaser {
            occluded: zeros.clone(),
            below_power: zeros.clone(),
            below_min_range: zeros,
        }
    }

    /// Counts a return of `laser` dropped with `fate` (other fates are not drops); a
    /// laser id beyond the table counts as the last laser's.
    #[inline]
    fn add(&mut self, fate: Fate, laser: u8) {
        let column = match fate {
            Fate::Occluded => &mut self.occluded,
            Fate::BelowPower => &mut self.below_power,
            Fate::BelowMinRange => &mut self.below_min_range,
            _ => return,
        };
        if let Some(last) = column.len().checked_sub(1) {
            column[usize::from(laser).min(last)] += 1;
        }
    }

    /// Adds another sensor's or part's counts, laser by laser (the longer table wins).
    fn merge(&mut self, other: &DropsByLaser) {
        for (mine, theirs) in [
            (&mut self.occluded, &other.occluded),
            (&mut self.below_power, &other.below_power),
            (&mut self.below_min_range, &other.below_min_range),
        ] {
            if mine.len() < theirs.len() {
                mine.resize(theirs.len(), 0);
            }
            for (m, t) in mine.iter_mut().zip(theirs) {
                *m += t;
            }
        }
    }
}

/// Statistics of R_n - R_i over kept returns (serialised as count, mean_m, rms_m,
/// p95_abs_m, max_abs_m).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct RangeChange {
    count: u64,
    sum_nm: i128,
    sum_sq_nm2: i128,
    max_abs_nm: u64,
    /// Counts per bin of |change|; empty until the first change is added.
    abs_hist: Vec<u64>,
}

impl RangeChange {
    /// Adds one change in metres.
    #[inline]
    pub fn add(&mut self, delta_m: f64) {
        let nm = round_to_i64(delta_m * 1e9);
        let abs = nm.unsigned_abs();
        self.count += 1;
        self.sum_nm += i128::from(nm);
        self.sum_sq_nm2 += i128::from(nm) * i128::from(nm);
        self.max_abs_nm = self.max_abs_nm.max(abs);
        if self.abs_hist.is_empty() {
            self.abs_hist = vec![0; BINS];
        }
        self.abs_hist[bin_of(abs)] += 1;
    }

    /// Adds another set of changes.
    pub fn merge(&mut self, other: &RangeChange) {
        self.count += other.count;
        self.sum_nm += other.sum_nm;
        self.sum_sq_nm2 += other.sum_sq_nm2;
        self.max_abs_nm = self.max_abs_nm.max(other.max_abs_nm);
        if other.abs_hist.is_empty() {
            return;
        }
        if self.abs_hist.is_empty() {
            self.abs_hist = vec![0; BINS];
        }
        for (mine, theirs) in self.abs_hist.iter_mut().zip(&other.abs_hist) {
            *mine += theirs;
        }
    }

    /// Number of changes.
    pub fn count(&self) -> u64 {
        self.count
    }

    /// Mean signed change in metres (0 when empty).
    pub fn mean_m(&self) -> f64 {
        if self.count == 0 {
            return 0.0;
        }
        self.sum_nm as f64 / self.count as f64 * 1e-9
    }

    /// Root mean square of the signed change in metres (0 when empty).
    pub fn rms_m(&self) -> f64 {
        if self.count == 0 {
            return 0.0;
        }
        (self.sum_sq_nm2 as f64 / self.count as f64).sqrt() * 1e-9
    }

    /// 95th percentile of the absolute change in metres, to 0.1 mm (see module doc).
    pub fn p95_abs_m(&self) -> f64 {
        if self.count == 0 {
            return 0.0;
        }
        let need = (self.count * 95).div_ceil(100);
        let mut seen = 0;
        for (bin, &n) in self.abs_hist.iter().enumerate() {
            seen += n;
            if seen >= need {
                return bin_upper_nm(bin).min(self.max_abs_nm) as f64 * 1e-9;
            }
        }
        self.max_abs_nm as f64 * 1e-9
    }

    /// Largest absolute change in metres.
    pub fn max_abs_m(&self) -> f64 {
        self.max_abs_nm as f64 * 1e-9
    }
}

/// The exact state of a [`RangeChange`] (its sums and histogram), which carries it
/// between processes without the rounding of its report form: the parts of a sharded
/// `run` merge into the totals of the run on one machine, bit for bit.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct RangeChangeState {
    /// Changes counted.
    pub count: u64,
    /// Sum of the changes in nm (an i128 in decimal: JSON numbers stop at 64 bits).
    pub sum_nm: String,
    /// Sum of the squared changes in nm² (i128 in decimal).
    pub sum_sq_nm2: String,
    /// Largest absolute change in nm.
    pub max_abs_nm: u64,
    /// Non-empty histogram bins as (bin, count).
    pub abs_hist: Vec<(u32, u64)>,
}

impl RangeChange {
    /// The exact state.
    pub fn state(&self) -> RangeChangeState {
        RangeChangeState {
            count: self.count,
            sum_nm: self.sum_nm.to_string(),
            sum_sq_nm2: self.sum_sq_nm2.to_string(),
            max_abs_nm: self.max_abs_nm,
            abs_hist: (self.abs_hist.iter().enumerate())
                .filter(|(_, &n)| n > 0)
                .map(|(b, &n)| (b as u32, n))
                .collect(),
        }
    }

    /// Rebuilds the statistic from its exact state (None when the state is malformed).
    pub fn from_state(s: &RangeChangeState) -> Option<Self> {
        let mut abs_hist = Vec::new();
        // An empty histogram stays empty, as before the first change.
        if s.count > 0 {
            abs_hist = vec![0; BINS];
            for &(b, n) in &s.abs_hist {
                *abs_hist.get_mut(b as usize)? = n;
            }
        }
        Some(RangeChange {
            count: s.count,
            sum_nm: s.sum_nm.parse().ok()?,
            sum_sq_nm2: s.sum_sq_nm2.parse().ok()?,
            max_abs_nm: s.max_abs_nm,
            abs_hist,
        })
    }
}

impl Serialize for RangeChange {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        let mut s = serializer.serialize_struct("RangeChange", 5)?;
        s.serialize_field("count", &self.count)?;
        s.serialize_field("mean_m", &self.mean_m())?;
        s.serialize_field("rms_m", &self.rms_m())?;
        s.serialize_field("p95_abs_m", &self.p95_abs_m())?;
        s.serialize_field("max_abs_m", &self.max_abs_m())?;
        s.end()
    }
}

/// What the chain did to one frame or, merged, to a capture.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize)]
pub struct NoiseSummary {
    /// Frames merged into this summary.
    pub frames: u64,
    /// Returns entering the chain.
    pub returns_in: u64,
    /// Returns surviving the chain and filters.
    pub returns_out: u64,
    /// Removed returns by cause.
    pub dropped: DropCounts,
    /// Removed returns by cause and laser id.
    pub dropped_by_laser: DropsByLaser,
    /// R_n - R_i of kept returns.
    pub range_change: RangeChange,
    /// Returns that are spurious echoes (left out of reports while there are none, so
    /// chains without scatter stages report as before).
    #[serde(skip_serializing_if = "SpuriousCounts::is_empty")]
    pub spurious: SpuriousCounts,
}

/// Reported returns that are spurious echoes, by kind.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct SpuriousCounts {
    /// Recorded returns replaced by an echo that won their firing slot (fate 4).
    pub replaced: u64,
    /// Echoes added in firing slots that had no return (fate 5).
    pub added: u64,
}

impl SpuriousCounts {
    /// True when there are none.
    pub fn is_empty(&self) -> bool {
        self.replaced == 0 && self.added == 0
    }
}

impl NoiseSummary {
    /// Summarises one processed frame.
    ///
    /// Same result as [`RangeChange::add`] for every kept return in order, with the sums
    /// of the usual small changes (under 2^31 nm, 2.1 m) kept in 64/128-bit locals and
    /// added once: integer sums do not depend on the order, and neither local can
    /// overflow (fewer than 2^32 returns of magnitude under 2^31 nm). Larger changes
    /// take `add` itself.
    pub fn from_frame(frame: &NoisyFrame) -> Self {
        const SMALL: u64 = 1 << 31;
        let mut s = NoiseSummary {
            frames: 1,
            returns_in: frame.clean_len as u64,
            dropped_by_laser: DropsByLaser::new(frame.lasers),
            ..Default::default()
        };
        let n = frame
            .clean
            .len()
            .min(frame.fate.len())
            .min(frame.range.len());
        if n as u64 >= 1 << 32 {
            // Beyond the bound of the local sums: the plain per-return path.
            return Self::from_frame_plain(frame);
        }
        // Counts of the dropped fates, their laser tallies, and the small changes' sums
        // and histogram (merged into `range_change` after the loop).
        let mut by_fate = [0u64; 6];
        let (mut sum_small, mut sq_small, mut n_small) = (0i64, 0u128, 0u64);
        let mut max_small = 0u64;
        let mut hist = vec![0u64; BINS];
        let mut n_seen = 0u64;
        let rc = &mut s.range_change;
        for ((r, &fate), &rn) in frame.clean.iter().zip(&frame.fate).zip(&frame.range) {
            n_seen += 1;
            if fate == Fate::Kept {
                let delta_m = f64::from(rn) - f64::from(r.range);
                let nm = round_to_i64(delta_m * 1e9);
                let abs = nm.unsigned_abs();
                if abs < SMALL {
                    sum_small += nm;
                    sq_small += u128::from(abs * abs);
                    n_small += 1;
                    max_small = max_small.max(abs);
                    hist[bin_of_small(abs as u32)] += 1;
                } else {
                    rc.add(delta_m);
                }
                continue;
            }
            by_fate[fate as usize] += 1;
            s.dropped_by_laser.add(fate, r.laser);
        }
        if n_small > 0 {
            rc.count += n_small;
            rc.sum_nm += i128::from(sum_small);
            rc.sum_sq_nm2 += sq_small as i128;
            rc.max_abs_nm = rc.max_abs_nm.max(max_small);
            if rc.abs_hist.is_empty() {
                rc.abs_hist = hist;
            } else {
                for (mine, small) in rc.abs_hist.iter_mut().zip(&hist) {
                    *mine += small;
                }
            }
        }
        let dropped = by_fate[Fate::Occluded as usize]
            + by_fate[Fate::BelowPower as usize]
            + by_fate[Fate::BelowMinRange as usize];
        s.returns_out = n_seen - dropped;
        s.spurious.replaced = by_fate[Fate::Replaced as usize];
        s.spurious.added = by_fate[Fate::Added as usize];
        s.dropped.occluded = by_fate[Fate::Occluded as usize];
        s.dropped.below_power = by_fate[Fate::BelowPower as usize];
        s.dropped.below_min_range = by_fate[Fate::BelowMinRange as usize];
        s
    }

    /// [`NoiseSummary::from_frame`] one return at a time through [`RangeChange::add`]:
    /// the reference the fast path is tested against.
    fn from_frame_plain(frame: &NoisyFrame) -> Self {
        let mut s = NoiseSummary {
            frames: 1,
            returns_in: frame.clean_len as u64,
            dropped_by_laser: DropsByLaser::new(frame.lasers),
            ..Default::default()
        };
        for ((r, &fate), &rn) in frame.clean.iter().zip(&frame.fate).zip(&frame.range) {
            s.dropped_by_laser.add(fate, r.laser);
            match fate {
                Fate::Kept => {
                    s.returns_out += 1;
                    s.range_change.add(f64::from(rn) - f64::from(r.range));
                }
                Fate::Replaced => {
                    s.returns_out += 1;
                    s.spurious.replaced += 1;
                }
                Fate::Added => {
                    s.returns_out += 1;
                    s.spurious.added += 1;
                }
                Fate::Occluded => s.dropped.occluded += 1,
                Fate::BelowPower => s.dropped.below_power += 1,
                Fate::BelowMinRange => s.dropped.below_min_range += 1,
            }
        }
        s
    }

    /// Adds another summary (exact, in any order).
    pub fn merge(&mut self, other: &NoiseSummary) {
        self.frames += other.frames;
        self.returns_in += other.returns_in;
        self.returns_out += other.returns_out;
        self.dropped.occluded += other.dropped.occluded;
        self.dropped.below_power += other.dropped.below_power;
        self.dropped.below_min_range += other.dropped.below_min_range;
        self.dropped_by_laser.merge(&other.dropped_by_laser);
        self.range_change.merge(&other.range_change);
        self.spurious.replaced += other.spurious.replaced;
        self.spurious.added += other.spurious.added;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn range_change_state_round_trips_exactly_through_json() {
        let mut r = RangeChange::default();
        assert_eq!(RangeChange::from_state(&r.state()), Some(r.clone()));
        for d in [0.0123456789, -3.5, 120.0, 1e-7, -0.049999] {
            r.add(d);
        }
        let json = serde_json::to_string(&r.state()).unwrap();
        let back: RangeChangeState = serde_json::from_str(&json).unwrap();
        assert_eq!(RangeChange::from_state(&back), Some(r.clone()));
        let mut bad = r.state();
        bad.abs_hist.push((BINS as u32, 1));
        assert_eq!(RangeChange::from_state(&bad), None);
    }

    #[test]
    fn round_to_i64_rounds_like_round() {
        let mut xs = vec![
            0.0,
            -0.0,
            0.5,
            -0.5,
            1.5,
            -1.5,
            2.5,
            -2.5,
            0.49999999999999994,
            -0.49999999999999994,
            4_503_599_627_370_495.5,
            -4_503_599_627_370_495.5,
            4_503_599_627_370_496.0,
            9.3e18,
            -9.3e18,
            1e300,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NAN,
        ];
        let mut v = 1e-3f64;
        while v < 1e17 {
            for k in [-1.0, 1.0] {
                xs.push(k * v);
                xs.push(k * (v.floor() + 0.5));
                xs.push(k * f64::from_bits((v.floor() + 0.5).to_bits() - 1));
            }
            v *= 1.37;
        }
        for x in xs {
            assert_eq!(round_to_i64(x), x.round() as i64, "{x}");
        }
    }

    #[test]
    fn from_frame_equals_the_per_return_reference() {
        use crate::frame::Return;
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let fates = [
            Fate::Kept,
            Fate::Occluded,
            Fate::BelowPower,
            Fate::BelowMinRange,
            Fate::Replaced,
            Fate::Added,
        ];
        for case in 0..40 {
            let n = rng.random_range(0..3000);
            let mut f = NoisyFrame::default();
            for _ in 0..n {
                let range: f32 = rng.random_range(0.5..130.0);
                // Mostly centimetre changes; some beyond the small-change bound (2.1 m),
                // and far-off ranges (the i128 sums stay in range, as with real data).
                // Every third case has small changes only.
                let pick = if case % 3 == 0 {
                    19
                } else {
                    rng.random_range(0..20)
                };
                let rn = match pick {
                    0 => range + rng.random_range(-50.0..50.0),
                    1 => range + 2.147_483_5,
                    2 => 1.0e6,
                    3 => -range,
                    // Decimetres to metres: changes across the histogram's decade edges.
                    4 | 5 => range + rng.random_range(-1.5..1.5),
                    _ => range + rng.random_range(-0.05..0.05),
                };
                f.clean.push(Return {
                    range,
                    laser: rng.random_range(0..40),
                    ..Return::BLANK
                });
                f.range.push(rn);
                // Mostly kept, as in real frames; every fate in some cases.
                let fate = if case % 2 == 0 || rng.random_range(0..4) == 0 {
                    fates[rng.random_range(0..6)]
                } else {
                    Fate::Kept
                };
                f.fate.push(fate);
            }
            f.clean_len = n;
            assert_eq!(
                NoiseSummary::from_frame(&f),
                NoiseSummary::from_frame_plain(&f),
                "case {case}"
            );
        }
    }

    #[test]
    fn bins_tile_the_axis() {
        assert_eq!(bin_of(0), 0);
        assert_eq!(bin_of(99_999), 0);
        assert_eq!(bin_of(100_000), 1);
        assert_eq!(bin_of(99_999_999), 999);
        assert_eq!(bin_of(100_000_000), 1000);
        assert_eq!(bin_of(1_000_000_000), 1900);
        assert_eq!(bin_of(99_999_999_999), BINS - 2);
        assert_eq!(bin_of(u64::MAX), BINS - 1);
        for b in 0..BINS - 1 {
            // Every value just under a bin's upper edge falls in that bin.
            assert_eq!(bin_of(bin_upper_nm(b) - 1), b, "bin {b}");
            assert_eq!(bin_of(bin_upper_nm(b)), b + 1, "bin {b}");
            // The branch-free path agrees below its bound, edges included.
            for v in [bin_upper_nm(b) - 1, bin_upper_nm(b)] {
                if v < 1 << 31 {
                    assert_eq!(bin_of_small(v as u32), bin_of(v), "{v} nm");
                }
            }
        }
        for v in [
            0u32,
            1,
            (1 << 31) - 1,
            2_000_000_000,
            999_999_999,
            99_999_999,
        ] {
            assert_eq!(bin_of_small(v), bin_of(u64::from(v)), "{v} nm");
        }
    }
}
