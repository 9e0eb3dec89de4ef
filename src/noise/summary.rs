//! Per-frame and per-capture counts of what the chain did.
//!
//! Counts and range-change sums are exact and merge in any order: the range change of
//! each kept return, R_n - R_i, is quantised to whole nanometres and summed in i128.
//! The 95th percentile is of the absolute change |R_n - R_i|, from a sparse histogram
//! of 0.1 mm bins that merges exactly; it is reported as the upper edge of the bin where
//! 95 % of the returns are reached (capped at the largest change), so it is at most
//! 0.1 mm above the exact value.

use crate::noise::{Fate, NoisyFrame};
use serde::ser::SerializeStruct;
use serde::{Serialize, Serializer};
use std::collections::BTreeMap;

/// Histogram bin width of absolute range changes, in nanometres (0.1 mm).
const BIN_NM: u64 = 100_000;

/// Removed returns by cause.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct DropCounts {
    /// Removed by occlusion.
    pub occluded: u64,
    /// Under the power threshold.
    pub below_power: u64,
    /// Under the minimum range.
    pub below_min_range: u64,
}

/// Removed returns by cause and laser id (index = laser id).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub struct DropsByLaser {
    /// Removed by occlusion.
    pub occluded: [u64; 32],
    /// Under the power threshold.
    pub below_power: [u64; 32],
    /// Under the minimum range.
    pub below_min_range: [u64; 32],
}

impl Default for DropsByLaser {
    fn default() -> Self {
        DropsByLaser {
            occluded: [0; 32],
            below_power: [0; 32],
            below_min_range: [0; 32],
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
    abs_hist: BTreeMap<u64, u64>,
}

impl RangeChange {
    /// Adds one change in metres.
    pub fn add(&mut self, delta_m: f64) {
        let nm = (delta_m * 1e9).round() as i64;
        let abs = nm.unsigned_abs();
        self.count += 1;
        self.sum_nm += i128::from(nm);
        self.sum_sq_nm2 += i128::from(nm) * i128::from(nm);
        self.max_abs_nm = self.max_abs_nm.max(abs);
        *self.abs_hist.entry(abs / BIN_NM).or_insert(0) += 1;
    }

    /// Adds another set of changes.
    pub fn merge(&mut self, other: &RangeChange) {
        self.count += other.count;
        self.sum_nm += other.sum_nm;
        self.sum_sq_nm2 += other.sum_sq_nm2;
        self.max_abs_nm = self.max_abs_nm.max(other.max_abs_nm);
        for (&bin, &n) in &other.abs_hist {
            *self.abs_hist.entry(bin).or_insert(0) += n;
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
        for (&bin, &n) in &self.abs_hist {
            seen += n;
            if seen >= need {
                return ((bin + 1) * BIN_NM).min(self.max_abs_nm) as f64 * 1e-9;
            }
        }
        self.max_abs_nm as f64 * 1e-9
    }

    /// Largest absolute change in metres.
    pub fn max_abs_m(&self) -> f64 {
        self.max_abs_nm as f64 * 1e-9
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
}

impl NoiseSummary {
    /// Summarises one processed frame.
    pub fn from_frame(frame: &NoisyFrame) -> Self {
        let mut s = NoiseSummary {
            frames: 1,
            returns_in: frame.len() as u64,
            ..Default::default()
        };
        for ((r, &fate), &rn) in frame.clean.iter().zip(&frame.fate).zip(&frame.range) {
            let laser = usize::from(r.laser).min(31);
            match fate {
                Fate::Kept => {
                    s.returns_out += 1;
                    s.range_change.add(f64::from(rn) - f64::from(r.range));
                }
                Fate::Occluded => {
                    s.dropped.occluded += 1;
                    s.dropped_by_laser.occluded[laser] += 1;
                }
                Fate::BelowPower => {
                    s.dropped.below_power += 1;
                    s.dropped_by_laser.below_power[laser] += 1;
                }
                Fate::BelowMinRange => {
                    s.dropped.below_min_range += 1;
                    s.dropped_by_laser.below_min_range[laser] += 1;
                }
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
        for i in 0..32 {
            self.dropped_by_laser.occluded[i] += other.dropped_by_laser.occluded[i];
            self.dropped_by_laser.below_power[i] += other.dropped_by_laser.below_power[i];
            self.dropped_by_laser.below_min_range[i] +=
                other.dropped_by_laser.below_min_range[i];
        }
        self.range_change.merge(&other.range_change);
    }
}
