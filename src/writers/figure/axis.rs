//! Axis ranges and tick marks of the line plots and bird's-eye panels.

use super::decimals_for;

/// Tick layout of one axis: its range, how many labels to ask plotters for, and the
/// decimals every label gets (one format per axis).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Axis {
    pub(super) lo: f64,
    pub(super) hi: f64,
    pub(super) labels: usize,
    pub(super) decimals: usize,
}

/// The ticks plotters draws for `lo..hi` when asked for `n` labels.
pub(super) fn ticks(lo: f64, hi: f64, n: usize) -> Vec<f64> {
    use plotters::coord::ranged1d::Ranged;
    use plotters::coord::types::RangedCoordf64;
    RangedCoordf64::from(lo..hi).key_points(n)
}

/// Lays out an axis over `lo..hi`. An integer axis (counts, integer parameter values)
/// gets only integer ticks, printed without decimals: the number of labels is lowered
/// until plotters' ticks are whole numbers, and the range widened to whole numbers when
/// it is narrower than one.
pub(super) fn axis(lo: f64, hi: f64, integer: bool) -> Axis {
    const WANT: usize = 8;
    if !integer {
        let t = ticks(lo, hi, WANT);
        return Axis {
            lo,
            hi,
            labels: WANT,
            decimals: decimals_for(&t),
        };
    }
    let whole = |t: &[f64]| t.len() >= 2 && t.iter().all(|v| (v - v.round()).abs() < 1e-9);
    for n in (2..=WANT).rev() {
        if whole(&ticks(lo, hi, n)) {
            return Axis {
                lo,
                hi,
                labels: n,
                decimals: 0,
            };
        }
    }
    // Narrower than one unit: show the whole numbers around it.
    let (mut a, mut b) = (lo.floor(), hi.ceil());
    if b - a < 1.0 {
        a -= 1.0;
        b += 1.0;
    }
    let (a, b) = (a - 0.05 * (b - a), b + 0.05 * (b - a));
    let labels = (2..=WANT)
        .rev()
        .find(|&n| whole(&ticks(a, b, n)))
        .unwrap_or(2);
    Axis {
        lo: a,
        hi: b,
        labels,
        decimals: 0,
    }
}
