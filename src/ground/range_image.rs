//! Range-image ground segmentation after MATLAB `segmentGroundFromLidarData`
//! (Bogoslavskyi and Stachniss, "Fast range image-based segmentation of sparse 3D laser
//! scans for online operation", IROS 2016).
//!
//! The returns are organised into a ring x column image, column = azimuth bin. Choices,
//! where the reference leaves room:
//!
//! - **Columns.** The column width is the sensor's own azimuth step, estimated as the
//!   median step between consecutive returns of one ring (in input order, i.e. capture
//!   order), rounded so that a whole number of columns spans 360 degrees; 0.2 degrees when
//!   the frame is too small to tell. Each ring's bins are phased on that ring's first
//!   return, so per-laser azimuth offsets (calibration, firing-time interpolation) do not
//!   put a ring's returns on bin edges where jitter would make them collide or skip.
//! - **Shared cells.** Where several returns fall in one cell (dual returns, or two
//!   firings in one bin) the nearest represents the cell and every return in the cell
//!   gets the cell's label.
//! - **Angle.** A cell's angle is the slope atan2(|dz|, |dd|) (in `f32`, in degrees) of
//!   the segment from its return to the return of the next valid cell above it in the
//!   same column (dd is the difference of horizontal distances). The topmost valid cell
//!   of a column has no cell above, so it takes the slope of the segment from the valid
//!   cell below it: the top of a wall stays vertical instead of inheriting the slope to
//!   the sky. A cell alone in its column has no angle and is never ground. The tests on
//!   angles are made on a polynomial approximation where it decides them by a wide
//!   margin and on `atan2` otherwise: the labels are those of `atan2`, at a fraction of
//!   its cost.
//! - **Hole repair.** MATLAB fills empty cells from valid cells up to 5 rows away whose
//!   ranges agree within 1 m, so that a missing return does not break a column. We do not
//!   invent ranges; instead the column is bridged: the "next cell above" of a cell is the
//!   next valid one even across up to [`MAX_HOLE_ROWS`] consecutive empty rows, and that
//!   same link is a vertical neighbour for growing. The slope between two real returns
//!   is meaningful whatever their range difference, so MATLAB's 1 m agreement test (which
//!   guards the interpolated range) is not needed, and it would have to go anyway: across
//!   the five-laser occlusion band of the reference study (rings 15..19) flat ground
//!   jumps from 8.5 m to 26 m, so no range test could bridge it, and every column would
//!   be cut in two.
//! - **Seeds and growth.** In each column the lowest valid cell seeds the ground if its
//!   angle is at most the initial angle. Ground grows (flood fill) over 4-neighbours
//!   (the bridged cells above and below, and the same row in the adjacent columns,
//!   wrapping around in azimuth) to cells whose angle differs by less than the angle
//!   delta from the cell it is reached from, and (our addition) whose own angle is at
//!   most the initial angle. The relation is symmetric, so the result is the union of
//!   the connected components holding a seed: independent of visiting order.
//! - **Why the cap on grown cells.** Without it the ground leaks up walls. Where a ring's
//!   ground circle meets a wall, the next ring hits the wall just above its foot, and
//!   along the ring the slope from the ground cell to that wall hit rises smoothly from 0
//!   to 90 degrees, by less than the delta per 0.2 degree column; once it nears 90 the
//!   wall's own vertical cells join. Real range noise usually breaks such chains, clean
//!   data never does (a synthetic street lost 14 % precision to it). A cell steeper than
//!   the seed limit is not drivable ground anyway, so the seed limit caps growth too.

use crate::frame::Return;

/// Largest number of consecutive empty rows a column is bridged across.
pub const MAX_HOLE_ROWS: usize = 5;

/// Column width used when the frame is too small to measure the azimuth step, in degrees.
pub const DEFAULT_COLUMN_WIDTH_DEG: f64 = 0.2;

/// Sentinel for "no cell" / "no return".
const NONE: u32 = u32::MAX;

/// Number of azimuth steps sampled to estimate the column width.
const STEP_SAMPLES: usize = 1024;

/// Number of columns of the range image for this frame (see the module notes).
pub fn column_count(returns: &[Return]) -> usize {
    let mut last = [f32::NAN; 256];
    let mut steps: Vec<f32> = Vec::with_capacity(STEP_SAMPLES);
    for r in returns {
        let prev = last[r.ring as usize];
        let step = r.azimuth - prev;
        // Steps of 0 are the second return of a dual pair; large ones are gaps.
        if step > 1e-3 && step < 2.0 {
            steps.push(step);
            if steps.len() == STEP_SAMPLES {
                break;
            }
        }
        last[r.ring as usize] = r.azimuth;
    }
    let width = if steps.len() < 8 {
        DEFAULT_COLUMN_WIDTH_DEG
    } else {
        let mid = steps.len() / 2;
        let (_, median, _) = steps.select_nth_unstable_by(mid, f32::total_cmp);
        f64::from(*median)
    };
    // Between 0.05 and 1 degree: finer than any HDL-32E step, coarser than any sane one.
    ((360.0 / width).round() as usize).clamp(360, 7200)
}

/// Labels each return as ground (true) or not; see the module notes for the method.
pub fn segment(returns: &[Return], initial_angle_deg: f64, max_angle_delta_deg: f64) -> Vec<bool> {
    segment_with_margin(returns, initial_angle_deg, max_angle_delta_deg, MARGIN_DEG)
}

/// Margin (degrees) of the approximate angles: a comparison whose approximate operands
/// lie further than this from deciding the other way is decided on them; any other is
/// decided on the exact angles. More than ten times the worst gap between the two angles
/// (see [`approx_slope_deg`] and the tests).
const MARGIN_DEG: f64 = 2e-3;

/// [`segment`] with the margin of its approximate angles: with `f64::INFINITY` every
/// comparison is made on the exact angles (`atan2` in `f32`, as the module notes define
/// them), the reference the approximate path is tested against; both give the same
/// labels for any margin at least [`segment`]'s (smaller ones and NaN are raised to it).
pub fn segment_with_margin(
    returns: &[Return],
    initial_angle_deg: f64,
    max_angle_delta_deg: f64,
    margin_deg: f64,
) -> Vec<bool> {
    // A smaller margin could decide on the approximation where it is not decisive.
    let margin_deg = margin_deg.max(MARGIN_DEG);
    let n = returns.len();
    if n == 0 {
        return Vec::new();
    }
    let cols = column_count(returns);
    let width = 360.0 / cols as f64;

    // One pass over the returns (48 bytes each, read once) gathers what the cells need in
    // compact columns: each valid return's column and ring, and its range. Per-ring bin
    // phase: the first return of each ring (with a finite azimuth) sits at a bin centre;
    // it comes before every other return of its ring, so the phase is known when they
    // are binned. The number of rows (highest ring + 1) comes from the same pass.
    let mut phase = [f64::NAN; 256];
    let mut top_ring = 0u8;
    // Column << 8 | ring of each return (its cell once the stride is known, below),
    // `NONE` for the invalid ones.
    let mut cell_of = vec![NONE; n];
    let mut range = Vec::with_capacity(n);
    for (i, r) in returns.iter().enumerate() {
        top_ring = top_ring.max(r.ring);
        range.push(r.range);
        let ring = r.ring as usize;
        let p = &mut phase[ring];
        if p.is_nan() && r.azimuth.is_finite() {
            *p = f64::from(r.azimuth).rem_euclid(width);
        }
        if !(r.x.is_finite() && r.y.is_finite() && r.z.is_finite() && r.azimuth.is_finite()) {
            continue;
        }
        // Nearest bin; the cast saturates and rem_euclid below keeps it in range.
        // `floor` written out (it is a libm call on baseline x86-64); same value for every
        // finite input, and the azimuth and phase are finite here.
        let x = (f64::from(r.azimuth) - *p) / width + 0.5;
        let t = x as i64;
        let bin = if (t as f64) > x { t - 1 } else { t };
        // Almost every bin is already in range: skip the integer division then.
        let col = if (0..cols as i64).contains(&bin) {
            bin as usize
        } else {
            bin.rem_euclid(cols as i64) as usize
        };
        // Columns are below 7200 (see `column_count`): 13 bits.
        cell_of[i] = (col << 8 | ring) as u32;
    }
    let rows = usize::from(top_ring) + 1;

    // Column-major cells (col * stride + row) keep a column contiguous for the link scans;
    // the power-of-two stride makes a cell's row a mask, not a division (rows past `rows`
    // stay empty).
    let stride = rows.next_power_of_two();
    let row_mask = stride - 1;
    let cells = stride * cols;
    let mut rep = vec![NONE; cells];
    for (i, c) in cell_of.iter_mut().enumerate() {
        if *c == NONE {
            continue;
        }
        let cell = (*c as usize >> 8) * stride + (*c as usize & 255);
        *c = cell as u32;
        let cur = rep[cell];
        if cur == NONE || range[i] < range[cur as usize] {
            rep[cell] = i as u32;
        }
    }

    let slopes = Slopes {
        returns,
        rep: &rep,
        rows,
        row_mask,
    };
    // A cell's approximate angle, computed on first use and cached: the growth reads
    // only the cells next to the ground. Angles are in [0, 90] or NaN, so -1 marks "not
    // computed yet".
    const UNKNOWN: f32 = -1.0;
    let mut angle = vec![UNKNOWN; cells];
    let mut angle_of = |cell: usize| -> f32 {
        let cached = angle[cell];
        if cached != UNKNOWN {
            return cached;
        }
        let a = slopes.approx(cell);
        angle[cell] = a;
        a
    };
    let initial = initial_angle_deg as f32;
    let delta = max_angle_delta_deg as f32;
    // The method's tests on the exact angles, taken on the approximate ones where those
    // decide them by more than the margin (see `at_most`). Why: `atan2` was about a
    // quarter of this function's time.
    let at_most_initial =
        |cell: usize, a: f32| at_most(a, initial, margin_deg, || slopes.exact(cell));
    let close = |cur: usize, a_cur: f32, nb: usize, a_nb: f32| {
        closer_than(a_cur, a_nb, delta, margin_deg, || {
            (slopes.exact(cur), slopes.exact(nb))
        })
    };

    // Seeds and growth.
    let mut ground = vec![false; cells];
    // A stack, not a queue: the grown set does not depend on the visiting order.
    let mut stack: Vec<u32> = Vec::new();
    let wrap = (cols - 1) * stride;
    for col in 0..cols {
        let base = col * stride;
        let Some(lowest) = (base..base + rows).find(|&c| rep[c] != NONE) else {
            continue;
        };
        // NaN angles fail this test, so a lone cell never seeds.
        let seeds = at_most_initial(lowest, angle_of(lowest));
        if ground[lowest] || !seeds {
            continue;
        }
        ground[lowest] = true;
        stack.push(lowest as u32);
        while let Some(cur) = stack.pop() {
            let cur = cur as usize;
            // Same row in the adjacent columns, wrapping around in azimuth.
            let left = if cur >= stride {
                cur - stride
            } else {
                cur + wrap
            };
            let right = if cur < wrap { cur + stride } else { cur - wrap };
            let a = angle_of(cur);
            for nb in [slopes.up(cur), slopes.down(cur), left as u32, right as u32] {
                if nb == NONE || ground[nb as usize] {
                    continue;
                }
                let nb = nb as usize;
                // Empty cells have a NaN angle and fail the comparison.
                let an = angle_of(nb);
                if at_most_initial(nb, an) && close(cur, a, nb, an) {
                    ground[nb] = true;
                    stack.push(nb as u32);
                }
            }
        }
    }

    cell_of
        .iter()
        .map(|&cell| cell != NONE && ground[cell as usize])
        .collect()
}

/// `exact <= limit`, taken on `approx` when it lies further than `margin` from `limit`,
/// else on `exact()`. Exact for any margin at least the gap between the two angles
/// (under a tenth of [`MARGIN_DEG`], see [`approx_slope_deg`]); NaN (a cell alone in its
/// column) is NaN on both and fails.
#[inline]
fn at_most(approx: f32, limit: f32, margin: f64, exact: impl FnOnce() -> f32) -> bool {
    let a = f64::from(approx);
    if a < f64::from(limit) - margin {
        true
    } else if a > f64::from(limit) + margin {
        false
    } else {
        exact() <= limit
    }
}

/// `|exact_b - exact_a| < delta` (in `f32`, as the method defines it), taken on the
/// approximate angles when their difference lies further than twice `margin` from
/// `delta` (each operand carries the approximation's gap; the `f32` rounding of the
/// exact difference, under 4e-6 degrees, is far inside the margin), else on `exact()`.
#[inline]
fn closer_than(
    a: f32,
    b: f32,
    delta: f32,
    margin: f64,
    exact: impl FnOnce() -> (f32, f32),
) -> bool {
    let d = (f64::from(b) - f64::from(a)).abs();
    if d < f64::from(delta) - 2.0 * margin {
        true
    } else if d > f64::from(delta) + 2.0 * margin {
        false
    } else {
        let (ea, eb) = exact();
        (eb - ea).abs() < delta
    }
}

/// The bridged vertical links and slopes of the cells of one range image.
struct Slopes<'a> {
    returns: &'a [Return],
    /// Representative return of each cell (column-major), `NONE` when empty.
    rep: &'a [u32],
    rows: usize,
    row_mask: usize,
}

impl Slopes<'_> {
    /// The next valid cell above a valid cell at most `MAX_HOLE_ROWS` empty rows away
    /// (scanning the column, contiguous in `rep`); `NONE` for empty cells and at the
    /// column's top.
    fn up(&self, cell: usize) -> u32 {
        if self.rep[cell] == NONE {
            return NONE;
        }
        let row = cell & self.row_mask;
        let top = (row + MAX_HOLE_ROWS + 2).min(self.rows);
        (cell + 1..cell - row + top)
            .find(|&c| self.rep[c] != NONE)
            .map_or(NONE, |c| c as u32)
    }

    /// As [`Slopes::up`], below.
    fn down(&self, cell: usize) -> u32 {
        if self.rep[cell] == NONE {
            return NONE;
        }
        let row = cell & self.row_mask;
        let bottom = row.saturating_sub(MAX_HOLE_ROWS + 1);
        (cell - row + bottom..cell)
            .rev()
            .find(|&c| self.rep[c] != NONE)
            .map_or(NONE, |c| c as u32)
    }

    /// Height and horizontal-distance differences `(|dz|, |dd|)` of a cell's slope: to
    /// the cell of its upward link, else from the cell of its downward one; `None`
    /// without either. Read only when a cell's angle is computed (only cells next to
    /// the ground are): gathering them for every cell cost more.
    fn legs(&self, cell: usize) -> Option<(f32, f32)> {
        let (a, b) = match self.up(cell) {
            NONE => match self.down(cell) {
                NONE => return None,
                d => (d as usize, cell),
            },
            u => (cell, u as usize),
        };
        let dz = |cell: usize| {
            let r = &self.returns[self.rep[cell] as usize];
            ((r.x * r.x + r.y * r.y).sqrt(), r.z)
        };
        let ((da, za), (db, zb)) = (dz(a), dz(b));
        Some(((zb - za).abs(), (db - da).abs()))
    }

    /// The cell's angle in degrees as the module notes define it (NaN without links).
    fn exact(&self, cell: usize) -> f32 {
        self.legs(cell)
            .map_or(f32::NAN, |(dz, dd)| slope_deg(dz, dd))
    }

    /// The cell's angle within a tenth of [`MARGIN_DEG`] of [`Slopes::exact`] (NaN
    /// exactly when it is NaN); the exact angle where the legs are not finite.
    fn approx(&self, cell: usize) -> f32 {
        match self.legs(cell) {
            None => f32::NAN,
            Some((dz, dd)) if dz.is_finite() && dd.is_finite() => approx_slope_deg(dz, dd) as f32,
            Some((dz, dd)) => slope_deg(dz, dd),
        }
    }
}

/// The angle of legs `(|dz|, |dd|)` in degrees, as the module notes define it.
fn slope_deg(dz: f32, dd: f32) -> f32 {
    dz.atan2(dd).to_degrees()
}

/// `atan2(dz, dd)` in degrees for finite `dz, dd >= 0` (NaN for NaN inputs), within
/// 1.1e-4 degrees of the true value: a degree-11 odd polynomial for `atan` on [0, 1]
/// (least-squares fit, worst error 1.8e-6 rad, see the tests), reflected about 45
/// degrees. The `f32` result of `atan2` and `to_degrees` is within a few `f32` ulps
/// (7.6e-6 degrees each at 90) of the true value, so within 2e-4 of this one.
fn approx_slope_deg(dz: f32, dd: f32) -> f64 {
    const C: [f64; 6] = [
        0.999_979_834_012_258_2,
        -0.332_655_482_732_351_8,
        0.193_670_316_140_423_96,
        -0.116_651_116_323_222_05,
        0.052_823_487_849_916_74,
        -0.011_770_499_896_160_733,
    ];
    let (y, x) = (f64::from(dz), f64::from(dd));
    let (lo, hi) = if y <= x { (y, x) } else { (x, y) };
    if hi == 0.0 {
        // atan2(0, 0) = 0 (both legs are non-negative zeros).
        return 0.0;
    }
    let t = lo / hi;
    let u = t * t;
    // Estrin's scheme: three independent pairs, so the chain of dependent operations is
    // half of Horner's.
    let u2 = u * u;
    let p = t * ((C[0] + u * C[1]) + u2 * ((C[2] + u * C[3]) + u2 * (C[4] + u * C[5])));
    let rad = if y <= x {
        p
    } else {
        std::f64::consts::FRAC_PI_2 - p
    };
    rad.to_degrees()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The worst gap between the approximate angle and the exact one (`atan2` in `f32`
    /// and `to_degrees`, as `segment` defined it) over a dense sweep of slopes and
    /// lengths must stay far inside the margin.
    #[test]
    fn approximate_slopes_are_within_the_margin() {
        let mut worst = 0.0f64;
        for i in 0..=200_000u32 {
            // Angles 0..90 degrees, and lengths from millimetres to kilometres.
            let theta = f64::from(i) / 200_000.0 * std::f64::consts::FRAC_PI_2;
            for len in [0.003f64, 0.7, 13.0, 450.0] {
                let (dz, dd) = ((len * theta.sin()) as f32, (len * theta.cos()) as f32);
                let exact = f64::from(slope_deg(dz, dd));
                // As cached: narrowed to f32.
                let approx = f64::from(approx_slope_deg(dz, dd) as f32);
                worst = worst.max((approx - exact).abs());
            }
        }
        for (dz, dd) in [
            (0.0f32, 0.0f32),
            (0.0, 5.0),
            (5.0, 0.0),
            (1e-30, 1.0),
            (1.0, 1e-30),
        ] {
            let exact = f64::from(slope_deg(dz, dd));
            worst = worst.max((approx_slope_deg(dz, dd) - exact).abs());
        }
        assert!(worst < MARGIN_DEG / 10.0, "worst gap {worst} degrees");
    }

    /// Slopes within a few `f32` steps of the limits, where the approximate angle alone
    /// decides wrongly about half the time: the decisions must be the exact ones.
    #[test]
    fn decisions_at_the_limits_are_exact() {
        let (mut near, mut wrong_alone) = (0, 0);
        for limit in [30.0f32, 5.0, 45.0, 0.5] {
            let theta = f64::from(limit).to_radians();
            for len in [0.4f64, 3.0, 17.0] {
                let (dz0, dd) = ((len * theta.sin()) as f32, (len * theta.cos()) as f32);
                // Walk dz over a few hundred f32 steps around the limit's slope.
                for k in -300i32..=300 {
                    let dz = f32::from_bits((dz0.to_bits() as i32 + k) as u32);
                    let (e, a) = (slope_deg(dz, dd), approx_slope_deg(dz, dd) as f32);
                    let truth = e <= limit;
                    assert_eq!(at_most(a, limit, MARGIN_DEG, || e), truth, "{dz} {dd}");
                    near += 1;
                    wrong_alone += usize::from((a <= limit) != truth);
                    // A difference of angles at the limit: a flat cell beside this one.
                    let truth = (e - 0.0f32).abs() < limit;
                    assert_eq!(
                        closer_than(0.0, a, limit, MARGIN_DEG, || (0.0, e)),
                        truth,
                        "{dz} {dd}"
                    );
                }
            }
        }
        // The sweep must reach cases the approximation alone gets wrong.
        assert!(
            wrong_alone > 0,
            "{wrong_alone} of {near} decided wrongly alone"
        );
    }
}
