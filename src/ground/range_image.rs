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
//! - **Angle.** A cell's angle is the slope atan2(|dz|, |dd|) of the segment from its
//!   return to the return of the next valid cell above it in the same column (dd is the
//!   difference of horizontal distances). The topmost valid cell of a column has no cell
//!   above, so it takes the slope of the segment from the valid cell below it: the top of
//!   a wall stays vertical instead of inheriting the slope to the sky. A cell alone in its
//!   column has no angle and is never ground.
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
    let n = returns.len();
    if n == 0 {
        return Vec::new();
    }
    let rows = returns.iter().map(|r| r.ring as usize).max().unwrap_or(0) + 1;
    let cols = column_count(returns);
    let width = 360.0 / cols as f64;

    // Per-ring bin phase: the first return of each ring sits at a bin centre.
    let mut phase = [f64::NAN; 256];
    for r in returns {
        let p = &mut phase[r.ring as usize];
        if p.is_nan() && r.azimuth.is_finite() {
            *p = f64::from(r.azimuth).rem_euclid(width);
        }
    }

    // Column-major cells (col * stride + row) keep a column contiguous for the link scans;
    // the power-of-two stride makes a cell's row a mask, not a division (rows past `rows`
    // stay empty).
    let stride = rows.next_power_of_two();
    let row_mask = stride - 1;
    let cells = stride * cols;
    let mut rep = vec![NONE; cells];
    let mut cell_of = vec![NONE; n];
    for (i, r) in returns.iter().enumerate() {
        if !(r.x.is_finite() && r.y.is_finite() && r.z.is_finite() && r.azimuth.is_finite()) {
            continue;
        }
        let ring = r.ring as usize;
        // Nearest bin; the cast saturates and rem_euclid below keeps it in range.
        // `floor` written out (it is a libm call on baseline x86-64); same value for every
        // finite input, and the azimuth and phase are finite here.
        let x = (f64::from(r.azimuth) - phase[ring]) / width + 0.5;
        let t = x as i64;
        let bin = if (t as f64) > x { t - 1 } else { t };
        // Almost every bin is already in range: skip the integer division then.
        let col = if (0..cols as i64).contains(&bin) {
            bin as usize
        } else {
            bin.rem_euclid(cols as i64) as usize
        };
        let cell = col * stride + ring;
        cell_of[i] = cell as u32;
        let cur = rep[cell];
        if cur == NONE || r.range < returns[cur as usize].range {
            rep[cell] = i as u32;
        }
    }

    // Horizontal distance and height of a cell's return, read when its angle is computed
    // (only cells next to the ground are): gathering them for every cell cost more.
    let dz = |cell: usize| {
        let r = &returns[rep[cell] as usize];
        ((r.x * r.x + r.y * r.y).sqrt(), r.z)
    };
    let slope = |a: usize, b: usize| {
        let ((da, za), (db, zb)) = (dz(a), dz(b));
        (zb - za).abs().atan2((db - da).abs()).to_degrees()
    };

    // Bridged vertical links, found on demand by scanning the column (contiguous in `rep`):
    // the next valid cell above (below) a valid cell at most `MAX_HOLE_ROWS` empty rows
    // away; `NONE` for empty cells and at the column ends.
    let up = |cell: usize| -> u32 {
        if rep[cell] == NONE {
            return NONE;
        }
        let row = cell & row_mask;
        let top = (row + MAX_HOLE_ROWS + 2).min(rows);
        (cell + 1..cell - row + top)
            .find(|&c| rep[c] != NONE)
            .map_or(NONE, |c| c as u32)
    };
    let down = |cell: usize| -> u32 {
        if rep[cell] == NONE {
            return NONE;
        }
        let row = cell & row_mask;
        let bottom = row.saturating_sub(MAX_HOLE_ROWS + 1);
        (cell - row + bottom..cell)
            .rev()
            .find(|&c| rep[c] != NONE)
            .map_or(NONE, |c| c as u32)
    };
    // A cell's angle, from its upward link, else its downward one; NaN without either
    // (empty cells have neither). Computed on first use and cached: the growth reads only
    // the cells next to the ground, and `atan2` was most of this function's time. Angles
    // are in [0, 90] or NaN, so -1 marks "not computed yet".
    const UNKNOWN: f32 = -1.0;
    let mut angle = vec![UNKNOWN; cells];
    let mut angle_of = |cell: usize| -> f32 {
        let cached = angle[cell];
        if cached != UNKNOWN {
            return cached;
        }
        let u = up(cell);
        let a = if u != NONE {
            slope(cell, u as usize)
        } else {
            match down(cell) {
                NONE => f32::NAN,
                d => slope(d as usize, cell),
            }
        };
        angle[cell] = a;
        a
    };

    // Seeds and growth.
    let initial = initial_angle_deg as f32;
    let delta = max_angle_delta_deg as f32;
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
        let seeds = angle_of(lowest) <= initial;
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
            for nb in [up(cur), down(cur), left as u32, right as u32] {
                if nb == NONE || ground[nb as usize] {
                    continue;
                }
                let nb = nb as usize;
                // Empty cells have a NaN angle and fail the comparison.
                let an = angle_of(nb);
                if an <= initial && (an - a).abs() < delta {
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
