//! Exact fixed-cutoff distance cut on a uniform voxel grid.
//!
//! The voxel side is `cutoff / sqrt(3)` (shrunk by 1e-6), so any two points of one voxel are
//! closer than the cutoff and every voxel starts as one set: the union-find runs over voxels,
//! not points. Linked points can only sit in voxels at most two steps apart per axis. Voxels
//! are identified by a packed `u64` key (x, y, z fields, z lowest), sorted by an LSD radix
//! sort; the voxels of one (x, y) column within two steps in z then form one contiguous key
//! range, so the 12 "forward" neighbour columns (plus the voxel's own column above it) are
//! found by monotone pointers walking the sorted keys (one per dx, the dy columns of one dx
//! being one key span), each voxel pair visited once, with no hashing. A voxel pair already in one set is skipped; otherwise point pairs are tested
//! exactly (same `f64` formula as [`super::point_distance`]) until the first link, with
//! bounding-box lower bounds discarding pairs and points that cannot link.

use super::{FinitePoints, UnionFind};
use crate::radix::{sort_packed as radix_sort_packed, RADIX_BITS};

/// Largest voxel coordinate magnitude handled (cells beyond it fall back to the k-d tree).
const CELL_LIMIT: f64 = 1e9;

/// Largest `s` with `sqrt(s) <= cutoff` in `f64`, so `s <= t` decides `sqrt(s) <= cutoff`
/// exactly: the rounded square root is monotone, hence the linked squared distances form a
/// down-set. Saves a square root per tested pair.
fn squared_threshold(cutoff: f64) -> f64 {
    // Neighbouring non-negative doubles by their bit patterns (`f64::next_up` needs Rust
    // 1.86, above the crate's MSRV).
    let up = |t: f64| f64::from_bits(t.to_bits() + 1);
    let down = |t: f64| f64::from_bits(t.to_bits() - 1);
    let mut t = cutoff * cutoff;
    while t > 0.0 && t.sqrt() > cutoff {
        t = down(t);
    }
    while t < f64::INFINITY && up(t).sqrt() <= cutoff {
        t = up(t);
    }
    t
}

/// Squared distance in the order `point_distance` sums it: `(dx*dx + dy*dy) + dz*dz`.
#[inline(always)]
fn sq3<T: Copy + std::ops::Mul<Output = T> + std::ops::Add<Output = T>>(dx: T, dy: T, dz: T) -> T {
    dx * dx + dy * dy + dz * dz
}

/// Squared gap between two voxel boxes (`[min x, min y, min z, max x, max y, max z]`, 0
/// where they overlap), in the boxes' own type: a lower bound of every squared distance
/// between a point of one and a point of the other. `try_link` takes it in `f32`.
#[inline(always)]
fn box_gap_sq<T>(a: &[T; 6], b: &[T; 6]) -> T
where
    T: Copy + PartialOrd + Default + std::ops::Sub<Output = T>,
    T: std::ops::Mul<Output = T> + std::ops::Add<Output = T>,
{
    let zero = T::default();
    sq3(
        max(max(b[0] - a[3], a[0] - b[3]), zero),
        max(max(b[1] - a[4], a[1] - b[4]), zero),
        max(max(b[2] - a[5], a[2] - b[5]), zero),
    )
}

/// The `f32` bound of the voxel box test: a squared box gap computed in `f32` above it
/// means the exact gap is above `t_hi`, so no point pair of the two voxels links.
///
/// Why `f32`: the boxes are `f32` (exact minima and maxima of `f32` coordinates), and
/// the test in `f64` widened all six corners first. Each of the five `f32` operations
/// (a difference, two squares, two sums; `max` is exact) errs by at most 2^-24 of its
/// result and every result is non-negative, so the computed squared gap is at most
/// (1 + 2^-24)^5 < 1 + 4e-7 times the exact one; a bound 1e-5 above `t_hi` (rounded up
/// into `f32`) leaves the exact squared gap above `t_hi` whenever the test rejects.
/// Underflow only lowers the computed gap, which keeps the pair (`points_link` decides).
fn box_gate(t_hi: f64) -> f32 {
    let g = (t_hi * (1.0 + 1e-5)) as f32;
    // `as` rounds to nearest: step up when that went below.
    if f64::from(g) < t_hi * (1.0 + 1e-5) {
        f32::from_bits(g.to_bits() + 1)
    } else {
        g
    }
}

/// Gap between a coordinate interval and a value (0 inside): a lower bound of `|v - b|` for
/// every `b` in `[lo, hi]`, and since `f64` rounding is monotone the rounded gap is also a
/// lower bound of every rounded difference, so box tests never reject a linked pair.
#[inline(always)]
fn gap(lo: f64, hi: f64, v: f64) -> f64 {
    max(max(lo - v, v - hi), 0.0)
}

/// The larger of two numbers that are not NaN (box gaps of finite points): one `maxsd`,
/// where `f64::max`'s handling of NaN cost three more instructions in the pair tests.
/// Where `f64::max` may return either zero of `max(-0.0, 0.0)`, this returns `b`; the
/// gaps are only squared and compared, so the sign of a zero never matters.
#[inline(always)]
fn max<T: PartialOrd>(a: T, b: T) -> T {
    if a > b {
        a
    } else {
        b
    }
}

/// `floor(f)` for `|f| <= CELL_LIMIT`, written out because `f64::floor` is a libm call on
/// baseline x86-64.
#[inline(always)]
fn floor_i64(f: f64) -> i64 {
    let t = f as i64;
    if (t as f64) > f {
        t - 1
    } else {
        t
    }
}

/// Stable LSD radix sort of `keys` (only the low `bits` bits set) carrying `vals` along.
fn radix_sort(keys: &mut Vec<u64>, vals: &mut Vec<u32>, bits: u32) {
    let n = keys.len();
    let mut k2 = vec![0u64; n];
    let mut v2 = vec![0u32; n];
    let buckets = 1usize << RADIX_BITS;
    let mask = (buckets - 1) as u64;
    let mut hist = vec![0usize; buckets];
    let mut shift = 0;
    while shift < bits {
        hist.iter_mut().for_each(|h| *h = 0);
        for &k in keys.iter() {
            hist[((k >> shift) & mask) as usize] += 1;
        }
        // A digit shared by every key leaves the order unchanged.
        if !hist.contains(&n) {
            let mut sum = 0;
            for h in hist.iter_mut() {
                let c = *h;
                *h = sum;
                sum += c;
            }
            for (&k, &v) in keys.iter().zip(vals.iter()) {
                let d = ((k >> shift) & mask) as usize;
                k2[hist[d]] = k;
                v2[hist[d]] = v;
                hist[d] += 1;
            }
            std::mem::swap(keys, &mut k2);
            std::mem::swap(vals, &mut v2);
        }
        shift += RADIX_BITS;
    }
}

/// Component number per input point (`n` inputs, finite ones in `fp`), numbered 0.. in order
/// of each component's smallest input index; non-finite points are singletons. `None` when
/// the grid does not apply (zero or infinite cutoff, coordinates too far out for the packed
/// keys); the caller then uses the k-d tree.
pub(crate) fn components(fp: &FinitePoints, n: usize, cutoff: f64) -> Option<Vec<u32>> {
    if fp.points.is_empty() {
        return Some((0..n as u32).collect());
    }
    let rule = Rule::fixed(cutoff);
    let Linked {
        cell_of, mut sets, ..
    } = link_cells(&fp.points, &rule)?;
    // Labels in input order, numbered by each component's smallest input index.
    let n_cells = sets.len();
    let cell_of_input = in_input_order(fp, n, cell_of);
    let mut root_label = vec![u32::MAX; n_cells];
    let mut next = 0u32;
    let labels = cell_of_input
        .iter()
        .map(|&c| {
            if c == u32::MAX {
                next += 1;
                return next - 1;
            }
            let r = sets.find(c) as usize;
            if root_label[r] == u32::MAX {
                root_label[r] = next;
                next += 1;
            }
            root_label[r]
        })
        .collect();
    Some(labels)
}

/// The fixed cut's clustering with `min_points` applied (as [`super::apply_min_points`]
/// on [`components`]' partition), in one pass over the points: the voxel sets' point
/// counts come from the voxels, so each point's label is decided as it is met (a part
/// below `min_points` is noise, the others are numbered in order of their first point).
/// The partition, its part sizes and the labels were four passes over the points, the
/// sizes' increments scattered. `None` where [`components`] gives `None`.
pub(crate) fn clustering(
    fp: &FinitePoints,
    n: usize,
    cutoff: f64,
    min_points: usize,
) -> Option<super::Clustering> {
    if fp.points.is_empty() {
        let singletons: Vec<u32> = (0..n as u32).collect();
        return Some(super::apply_min_points(&singletons, min_points));
    }
    let rule = Rule::fixed(cutoff);
    let Linked {
        cell_of,
        mut sets,
        cell_start,
    } = link_cells(&fp.points, &rule)?;
    // Each voxel's root, and the points under each root (`cell_start` ends with the
    // point count).
    let n_cells = sets.len();
    let mut root_of = vec![0u32; n_cells];
    let mut points_under = vec![0u32; n_cells];
    for (c, root) in root_of.iter_mut().enumerate() {
        *root = sets.find(c as u32);
        points_under[*root as usize] += cell_start[c + 1] - cell_start[c];
    }
    // A root's label: -1 (noise) for small sets, -2 (a cluster not numbered yet) else.
    let mut id: Vec<i32> = points_under
        .iter()
        .map(|&k| if (k as usize) < min_points { -1 } else { -2 })
        .collect();
    let mut next = 0i32;
    let mut label = |c: u32| -> i32 {
        if c == u32::MAX {
            // A point that is not finite is a part of its own.
            if min_points > 1 {
                return -1;
            }
            next += 1;
            return next - 1;
        }
        let slot = &mut id[root_of[c as usize] as usize];
        if *slot == -2 {
            *slot = next;
            next += 1;
        }
        *slot
    };
    let labels: Vec<i32> = in_input_order(fp, n, cell_of)
        .iter()
        .map(|&c| label(c))
        .collect();
    let n_noise_points = labels.iter().filter(|&&l| l < 0).count();
    Some(super::Clustering {
        labels,
        n_clusters: next as usize,
        n_noise_points,
    })
}

/// The voxel of each of the `n` input points, `u32::MAX` for those that are not finite,
/// from the voxels of the finite points (`cell_of`, in `fp`'s order).
fn in_input_order(fp: &FinitePoints, n: usize, cell_of: Vec<u32>) -> Vec<u32> {
    if fp.is_identity() {
        return cell_of;
    }
    let mut by_input = vec![u32::MAX; n];
    for (f, &c) in cell_of.iter().enumerate() {
        by_input[fp.global(f) as usize] = c;
    }
    by_input
}

/// Pair rule of one grid pass: a pair links when `d <= cutoff_m + per_m * max(range_i,
/// range_j)` (`per_m` 0 and no ranges: the fixed cutoff). `lo` and `hi` bound every pair
/// cutoff of the pass from below and above.
pub(crate) struct Rule<'a> {
    /// Fixed part of the cutoff, metres.
    pub(crate) cutoff_m: f64,
    /// Range-proportional part of the cutoff.
    pub(crate) per_m: f64,
    /// Range of each point of the pass (same order), when `per_m > 0`.
    pub(crate) ranges: Option<&'a [f64]>,
    /// Smallest pair cutoff of the pass.
    pub(crate) lo: f64,
    /// Largest pair cutoff of the pass.
    pub(crate) hi: f64,
}

impl Rule<'_> {
    /// The fixed cut: pairs at most `cutoff` apart link.
    fn fixed(cutoff: f64) -> Self {
        Rule {
            cutoff_m: cutoff,
            per_m: 0.0,
            ranges: None,
            lo: cutoff,
            hi: cutoff,
        }
    }
}

/// Voxel of each point and the union-find over voxels after linking, for the points of one
/// pass (all finite). The voxel side is `rule.lo / sqrt(3)` (every same-voxel pair links);
/// `None` when the grid does not apply (zero or infinite cutoff, `rule.hi` beyond two voxel
/// sides, coordinates too far out for the packed keys).
///
/// The result (which voxels end up in one set, hence the partition of the points) does not
/// depend on how each point is assigned to a voxel, as long as same-voxel points are closer
/// than `rule.lo` and linked points lie at most two voxels apart per axis: so the voxel
/// coordinate is `floor(v * (1 / side))`, a multiplication, whose relative rounding error
/// (~1e-16) is far inside the 1e-6 shrink of the side.
pub(crate) fn link_cells(points: &[[f32; 3]], rule: &Rule) -> Option<Linked> {
    // The 1e-6 shrink keeps same-voxel pairs below the cutoff despite rounding in the voxel
    // assignment and in the distance itself (both ~1e-16 relative).
    let side = rule.lo / 3f64.sqrt() * (1.0 - 1e-6);
    if !(side > 0.0 && side.is_finite()) || rule.hi > 2.0 * side {
        return None;
    }
    let inv = 1.0 / side;
    let m = points.len();
    if m == 0 {
        return Some(Linked {
            cell_of: Vec::new(),
            sets: UnionFind::new(0),
            cell_start: vec![0],
        });
    }
    // Coordinate bounds in f32 (no division per point); `floor(v * inv)` is monotone in `v`,
    // so the voxel bounds are the voxels of the coordinate bounds.
    // Plain comparisons, not `f32::min` (whose NaN handling costs instructions): callers
    // pass finite points only (see `FinitePoints`).
    debug_assert!(points.iter().flatten().all(|c| c.is_finite()));
    let (mut mn, mut mx) = (points[0], points[0]);
    for p in points {
        for a in 0..3 {
            if p[a] < mn[a] {
                mn[a] = p[a];
            }
            if p[a] > mx[a] {
                mx[a] = p[a];
            }
        }
    }
    let (mut lo, mut hi) = ([0i64; 3], [0i64; 3]);
    for a in 0..3 {
        let (f_lo, f_hi) = (mn[a] as f64 * inv, mx[a] as f64 * inv);
        // Also rejects NaN bounds (only from non-finite points, which callers never pass).
        if !(f_lo.abs() <= CELL_LIMIT && f_hi.abs() <= CELL_LIMIT) {
            return None;
        }
        lo[a] = floor_i64(f_lo);
        hi[a] = floor_i64(f_hi);
    }
    // A point's field on axis `a` is `trunc(v * inv - (lo[a] - 2))`. The exact value of the
    // difference lies in [2, span + 3) (`v * inv` rounded lies in [lo, hi + 1)), so the
    // rounded one lies in [2, span + 3] and is positive: truncation is the floor and no
    // `floor` emulation is needed. That is the voxel `floor(v * inv) - lo + 2` up to the
    // rounding of the subtraction, below 2^31 * 2^-53 = 2.4e-7 of a voxel (spans are below
    // 2^31 voxels by CELL_LIMIT); with the rounding of `v * inv` (at most 1.2e-7 of a voxel
    // there) that is well inside the
    // 1e-6 shrink of the side, so same-voxel points still link and linked points still lie
    // at most two voxels apart (see above: that is all the partition depends on). Fields
    // up to span + 3 plus a step of two must stay below 2^width, so no key arithmetic ever
    // carries between fields.
    let width = |a: usize| 64 - ((hi[a] - lo[a] + 5) as u64).leading_zeros();
    let (wy, wz) = (width(1), width(2));
    let total = width(0) + wy + wz;
    if total > 62 {
        return None;
    }
    let (sx, sy) = (wy + wz, wz);
    let grid = KeyGrid {
        inv,
        off: lo.map(|l| (l - 2) as f64),
        sx,
        sy,
    };
    // The points in key order: (key, point index) packed in one u64 when both fit (one
    // array to sort and scatter instead of two, read straight off the sorted array), else
    // sorted as two arrays.
    let ib = 32 - (m as u32).leading_zeros();
    let Voxels {
        mut cell_key,
        mut cell_start,
        cell_box,
        sp,
        sr,
        cell_of,
    } = if total + ib <= 64 {
        let idx_mask = (1u64 << ib) - 1;
        let mut items = packed_keys(points, grid, ib);
        radix_sort_packed(&mut items, ib, total);
        let order = items.iter().map(|&k| (k >> ib, (k & idx_mask) as u32));
        Voxels::of(points, rule.ranges, order)
    } else {
        let mut keys: Vec<u64> = points.iter().map(|p| grid.key(p)).collect();
        let mut order: Vec<u32> = (0..m as u32).collect();
        radix_sort(&mut keys, &mut order, total);
        Voxels::of(points, rule.ranges, keys.into_iter().zip(order))
    };
    let n_cells = cell_key.len();
    cell_start.push(m as u32);
    // Sentinel above every neighbour key (keys use at most 62 bits): walks need no bounds test.
    cell_key.push(u64::MAX);
    // Squared distances up to `t` link for sure; above `t_hi` never; in between (adaptive
    // passes only) the exact pair rule decides.
    let t = squared_threshold(rule.lo);
    let t_hi = squared_threshold(rule.hi);
    let adaptive = rule.ranges.is_some();

    // Forward neighbour columns (dx > 0, or dx == 0 and dy > 0) in dz [-2, 2], walked as
    // three key spans, one per dx: for dx = 1, 2 the columns dy = -2..2 lie between
    // (dx, -2, -2) and (dx, 2, 2) in key order; for dx = 0 the voxel's own column above
    // it and the columns dy = 1, 2 lie between the next key (0, 0, 1) and (0, 2, 2). A
    // span also holds voxels of those columns beyond two steps in z, skipped by their z
    // field. One pointer per span instead of one per column: the pointer walks were most
    // of this function's time; and the own column as part of the dx = 0 span, not a walk
    // of its own (two loops fewer per voxel).
    let pack = |dx: i64, dy: i64, dz: i64| -> u64 { ((dx << sx) + (dy << sy) + dz) as u64 };
    let links = Links {
        walk: Walk {
            cell_box: &cell_box,
            cell_start: &cell_start,
            sp: &sp,
            sr: &sr,
            t,
            t_hi,
            t_gate: box_gate(t_hi),
            adaptive,
            cutoff_m: rule.cutoff_m,
            per_m: rule.per_m,
        },
        cell_key: &cell_key,
        columns: [
            (1, pack(0, 2, 2)),
            (pack(1, -2, -2), pack(1, 2, 2)),
            (pack(2, -2, -2), pack(2, 2, 2)),
        ],
        z_mask: (1u64 << wz) - 1,
    };
    // Every key is below the sentinel: no key bound.
    let all = (0, u64::MAX - 1);
    // The voxels in two halves at an x boundary (keys sort by x first, so each half is an
    // index range): a fork an idle worker may take (see `crate::par::join`). A voxel's
    // forward neighbours have larger keys, so the upper half links within itself; the
    // lower half links within itself too, and the pairs across the boundary (dx = 1, 2
    // from the lower half's last two x columns) are linked after. The partition is the
    // connected components of the linking voxel pairs, which does not depend on the order
    // the pairs are tested in, so it is the same as one pass's (as are the labels, numbered
    // by smallest input index).
    let x_of = |c: usize| cell_key[c] >> sx;
    let split = (n_cells >= SPLIT_MIN_CELLS)
        .then(|| (n_cells / 2..n_cells).find(|&c| x_of(c) != x_of(c - 1)))
        .flatten();
    let sets = match split {
        None => {
            let mut sets = UnionFind::new(n_cells);
            links.link(&mut sets, 0, 0..n_cells, all, 0..3);
            sets
        }
        Some(half) => {
            let limit = x_of(half) << sx;
            let (mut sets, upper) = crate::par::join(
                || {
                    let mut sets = UnionFind::new(half);
                    links.link(&mut sets, 0, 0..half, (0, limit - 1), 0..3);
                    sets
                },
                || {
                    let mut sets = UnionFind::new(n_cells - half);
                    links.link(&mut sets, half, half..n_cells, all, 0..3);
                    sets
                },
            );
            sets.append(upper);
            // Pairs across the boundary: from the lower half's voxels two x columns or
            // less below it (x fields are at least 2, so `limit` is above two columns), to
            // the upper half's, on the dx = 1, 2 spans only (the others stay in a column).
            let near = limit - (2u64 << sx);
            let from = cell_key[..half].partition_point(|&k| k < near);
            links.link(&mut sets, 0, from..half, (limit, u64::MAX - 1), 1..3);
            sets
        }
    };

    Some(Linked {
        cell_of,
        sets,
        cell_start,
    })
}

/// What [`link_cells`] found: each point's voxel, the union-find over the voxels, and
/// each voxel's first point in voxel order (and one past the last point).
pub(crate) struct Linked {
    pub(crate) cell_of: Vec<u32>,
    pub(crate) sets: UnionFind,
    pub(crate) cell_start: Vec<u32>,
}

/// How [`link_cells`] turns a point into its voxel key: fields `trunc(v * inv - off)` on
/// the three axes, x shifted up by `sx`, y by `sy`.
#[derive(Clone, Copy)]
struct KeyGrid {
    inv: f64,
    off: [f64; 3],
    sx: u32,
    sy: u32,
}

impl KeyGrid {
    /// The voxel key of `p`.
    #[inline(always)]
    fn key(&self, p: &[f32; 3]) -> u64 {
        // SAFETY: each value lies in [2, span + 3] (see `link_cells`), finite and far
        // inside i64. Unchecked, because `as` saturates, and that test per value kept
        // the conversions scalar even with AVX-512's vector one.
        let f =
            |a: usize| unsafe { (p[a] as f64 * self.inv - self.off[a]).to_int_unchecked::<i64>() }
                as u64;
        f(0) << self.sx | f(1) << self.sy | f(2)
    }
}

/// Each point's voxel key ([`KeyGrid::key`]) shifted up by `ib` bits with the
/// point's index in the low bits, compiled for AVX-512 where the processor has it: its
/// conversions from doubles to 64-bit integers make the loop a vector one (with AVX2 or
/// SSE2 each conversion is a scalar instruction). The same keys on every build.
fn packed_keys(points: &[[f32; 3]], grid: KeyGrid, ib: u32) -> Vec<u64> {
    #[cfg(target_arch = "x86_64")]
    {
        if crate::numeric::avx512() {
            // SAFETY: the processor has AVX-512 F and DQ (checked on the line above).
            return unsafe { packed_keys_avx512(points, grid, ib) };
        }
    }
    packed_keys_body(points, grid, ib)
}

/// [`packed_keys`] compiled with AVX-512.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx512dq")]
unsafe fn packed_keys_avx512(points: &[[f32; 3]], grid: KeyGrid, ib: u32) -> Vec<u64> {
    packed_keys_body(points, grid, ib)
}

/// The loop of [`packed_keys`].
#[inline(always)]
fn packed_keys_body(points: &[[f32; 3]], grid: KeyGrid, ib: u32) -> Vec<u64> {
    // A loop over a zeroed vector, not `collect`: `collect`'s loop is a function of its
    // own, not inlined into the AVX-512 build.
    let mut keys = vec![0u64; points.len()];
    for (i, (k, p)) in keys.iter_mut().zip(points).enumerate() {
        *k = grid.key(p) << ib | i as u64;
    }
    keys
}

/// The voxels of [`link_cells`]: sorted keys, each voxel's first position in key order,
/// boxes, the points in key order with their ranges (adaptive passes only), and each
/// point's voxel.
struct Voxels {
    cell_key: Vec<u64>,
    cell_start: Vec<u32>,
    cell_box: Vec<[f32; 6]>,
    sp: Vec<[f32; 3]>,
    sr: Vec<f64>,
    cell_of: Vec<u32>,
}

impl Voxels {
    /// The voxels of `points` taken in key order (`order`: key and point index), as runs
    /// of equal keys; points copied in voxel order for locality. Boxes are kept in f32
    /// (the coordinates are f32, so min and max are exact) and widened to f64 where they
    /// are compared.
    ///
    /// Inlined into each caller's loop: as a closure called per point it was not (2.4 %
    /// of a run's samples in its own frame).
    #[inline(always)]
    fn of(
        points: &[[f32; 3]],
        ranges: Option<&[f64]>,
        order: impl Iterator<Item = (u64, u32)>,
    ) -> Voxels {
        let m = points.len();
        // At most one voxel per point (and one sentinel): no regrowth, whose copies cost
        // about 1 % of a run.
        let mut v = Voxels {
            cell_key: Vec::with_capacity(m + 1),
            cell_start: Vec::with_capacity(m + 1),
            cell_box: Vec::with_capacity(m),
            sp: Vec::with_capacity(m),
            sr: Vec::with_capacity(if ranges.is_some() { m } else { 0 }),
            cell_of: vec![0; m],
        };
        let mut prev_key = u64::MAX;
        for (k, (key, i)) in order.enumerate() {
            let p = points[i as usize];
            if let Some(r) = ranges {
                v.sr.push(r[i as usize]);
            }
            if key != prev_key {
                prev_key = key;
                v.cell_key.push(key);
                v.cell_start.push(k as u32);
                v.cell_box.push([p[0], p[1], p[2], p[0], p[1], p[2]]);
            } else {
                let b = v.cell_box.last_mut().expect("pushed above");
                for a in 0..3 {
                    b[a] = b[a].min(p[a]);
                    b[a + 3] = b[a + 3].max(p[a]);
                }
            }
            v.cell_of[i as usize] = (v.cell_key.len() - 1) as u32;
            v.sp.push(p);
        }
        v
    }
}

/// Fewest voxels for [`link_cells`] to link in two halves: below it the fork is not worth
/// its bookkeeping. Small, so that tests of small point sets take the split path too.
const SPLIT_MIN_CELLS: usize = 256;

/// Most voxels [`Links::link`] gathers from one span before testing them.
const BATCH: usize = 16;

/// The forward-neighbour walks of [`link_cells`] over the sorted voxel keys.
struct Links<'a> {
    walk: Walk<'a>,
    /// Sorted voxel keys and a `u64::MAX` sentinel.
    cell_key: &'a [u64],
    /// Key offsets of the first and last voxel of each forward neighbour span (span 0
    /// starts at the voxel's next key).
    columns: [(u64, u64); 3],
    /// The z field of a key.
    z_mask: u64,
}

impl Links<'_> {
    /// Links each voxel of `cells` with its forward neighbours whose keys lie in `keys`
    /// (both included), on the neighbour spans `spans` (0 the voxel's own column above it
    /// and the dx = 0 span, 1 and 2 the dx = 1, 2 spans); `sets` holds the voxels from
    /// `off` on (voxel `c` is its element `c - off`).
    fn link(
        &self,
        sets: &mut UnionFind,
        off: usize,
        cells: std::ops::Range<usize>,
        keys: (u64, u64),
        spans: std::ops::Range<usize>,
    ) {
        let (cell_key, walk, z_mask) = (self.cell_key, &self.walk, self.z_mask);
        // Forward neighbours have larger keys than the voxel, so the walks start at it
        // (span 0 starts at the voxel's next key and needs no pointer: `ptr[0]` is unused).
        let mut ptr = [cells.start; 3];
        for c in cells {
            let key = cell_key[c];
            // Only this loop's own joins can change `c`'s root, and `try_link` reports them.
            let mut root = sets.find((c - off) as u32);
            let z = key & z_mask;
            for j in spans.clone() {
                let (lo_off, hi_off) = self.columns[j];
                let khi = key.wrapping_add(hi_off).min(keys.1);
                // Span 0 starts right above the voxel in its own column: the next key is
                // its first. The others start where their pointer, moved on, meets the
                // span's first key.
                let mut p = if j == 0 {
                    c + 1
                } else {
                    let klo = key.wrapping_add(lo_off).max(keys.0);
                    let mut p = ptr[j];
                    while cell_key[p] < klo {
                        p += 1;
                    }
                    ptr[j] = p;
                    p
                };
                // The voxels within two steps in z that do not hang right under the
                // voxel's root are gathered without a branch (whether one does is a coin
                // toss the predictor loses), a batch at a time, and tested in the same
                // order as one at a time. A voxel under the root as the batch starts is
                // in the voxel's set for good (joins only merge sets), so skipping it is
                // what `try_link` would do.
                while cell_key[p] <= khi {
                    let mut batch = [0u32; BATCH];
                    let mut n = 0;
                    let end = p + BATCH;
                    while p < end && cell_key[p] <= khi {
                        batch[n] = p as u32;
                        let near = (cell_key[p] & z_mask).abs_diff(z) <= 2;
                        let other = sets.parent((p - off) as u32) != root;
                        n += usize::from(near & other);
                        p += 1;
                    }
                    for &b in &batch[..n] {
                        root = walk.try_link(sets, root, c, b as usize, off);
                    }
                }
            }
        }
    }
}

/// What the voxel-pair test of [`link_cells`] reads: a struct with methods rather than a
/// closure so that the cheap checks inline into both walks and the point loop does not.
struct Walk<'a> {
    cell_box: &'a [[f32; 6]],
    cell_start: &'a [u32],
    sp: &'a [[f32; 3]],
    sr: &'a [f64],
    t: f64,
    t_hi: f64,
    /// `t_hi` with room for the rounding of the `f32` box test (see [`box_gate`]).
    t_gate: f32,
    adaptive: bool,
    cutoff_m: f64,
    per_m: f64,
}

impl Walk<'_> {
    /// Tests one voxel pair (`ra` the current root of `a`'s set) and joins it when some
    /// point pair links; returns the root of `a`'s set afterwards. `sets` holds the voxels
    /// from `off` on.
    #[inline(always)]
    fn try_link(&self, sets: &mut UnionFind, ra: u32, a: usize, b: usize, off: usize) -> u32 {
        // The walk dropped the neighbours under the root as its batch started; a join
        // earlier in the batch may have put this one there since: seen without the walk
        // (and the write) of `find`.
        let b_el = (b - off) as u32;
        if sets.parent(b_el) == ra {
            return ra;
        }
        // The box test before `find`: three in four of the pairs that get here lie in
        // other sets with boxes too far apart, and the test spares their `find`.
        let (ba, bb) = (&self.cell_box[a], &self.cell_box[b]);
        if box_gap_sq(ba, bb) > self.t_gate {
            return ra;
        }
        let bb: [f64; 6] = bb.map(f64::from);
        let rb = sets.find(b_el);
        if ra == rb || !self.points_link(a, b, &bb) {
            return ra;
        }
        sets.join_roots(ra, rb)
    }

    /// True when some point of voxel `a` links with some point of voxel `b` (box `bb`).
    #[inline(never)]
    fn points_link(&self, a: usize, b: usize, bb: &[f64; 6]) -> bool {
        let (t, t_hi) = (self.t, self.t_hi);
        let (a0, a1) = (self.cell_start[a] as usize, self.cell_start[a + 1] as usize);
        let (b0, b1) = (self.cell_start[b] as usize, self.cell_start[b + 1] as usize);
        let pb = &self.sp[b0..b1];
        for (ia, p) in self.sp[a0..a1].iter().enumerate() {
            let p = p.map(|c| c as f64);
            let g = sq3(
                gap(bb[0], bb[3], p[0]),
                gap(bb[1], bb[4], p[1]),
                gap(bb[2], bb[5], p[2]),
            );
            if g > t_hi {
                continue;
            }
            let linked = if self.adaptive {
                let ra_range = self.sr[a0 + ia];
                pb.iter().enumerate().any(|(ib, q)| {
                    let d2 = sq3(p[0] - q[0] as f64, p[1] - q[1] as f64, p[2] - q[2] as f64);
                    d2 <= t
                        || (d2 <= t_hi
                            && d2.sqrt()
                                <= self.cutoff_m + self.per_m * ra_range.max(self.sr[b0 + ib]))
                })
            } else {
                pb.iter()
                    .any(|q| sq3(p[0] - q[0] as f64, p[1] - q[1] as f64, p[2] - q[2] as f64) <= t)
            };
            if linked {
                return true;
            }
        }
        false
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn squared_threshold_decides_like_sqrt() {
        for &c in &[0.5, 0.1, 1.0, 0.3, 1e-3, 7.77, 0.05] {
            let t = squared_threshold(c);
            assert!(t.sqrt() <= c, "{c}");
            assert!(f64::from_bits(t.to_bits() + 1).sqrt() > c, "{c}");
        }
    }

    /// The `f32` box test rejects only voxel pairs whose exact box gap is above the largest
    /// linking distance: on boxes whose gap lies within a few `f32` steps of the cutoff,
    /// in every direction, wherever the boxes sit, the exact gap of a rejected pair
    /// (computed in `f64`, then compared with the cutoff itself) is above the cutoff.
    /// A gate of `t_hi` rounded to `f32` without the margin rejects linking pairs here.
    #[test]
    fn f32_box_test_never_rejects_a_linking_pair() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let (mut rejected, mut unsafe_gate) = (0, 0);
        for &cutoff in &[0.5f64, 0.1, 1.0, 0.37, 2.5] {
            let t_hi = squared_threshold(cutoff);
            let gate = box_gate(t_hi);
            assert!(f64::from(gate) > t_hi, "{cutoff}");
            for _ in 0..20_000 {
                // A box near some point, and one at about the cutoff from it along a
                // random direction (its exact gap to the first is close to the cutoff).
                let base = [0, 1, 2].map(|_| rng.random_range(-120.0f32..120.0));
                let size = [0, 1, 2].map(|_| rng.random_range(0.0f32..0.28));
                let a = [
                    base[0],
                    base[1],
                    base[2],
                    base[0] + size[0],
                    base[1] + size[1],
                    base[2] + size[2],
                ];
                let dir = [0, 1, 2].map(|_| rng.random_range(-1.0f64..1.0));
                let len = (dir[0] * dir[0] + dir[1] * dir[1] + dir[2] * dir[2]).sqrt();
                let scale = cutoff * (1.0 + rng.random_range(-4e-7..4e-7)) / len;
                let mut b = [0f32; 6];
                for k in 0..3 {
                    let d = dir[k] * scale;
                    // Beyond the box on the side the direction points to.
                    let lo = if d >= 0.0 {
                        f64::from(a[k + 3]) + d
                    } else {
                        f64::from(a[k]) + d
                    };
                    b[k] = lo as f32;
                    b[k + 3] = b[k];
                }
                // The test `try_link` runs, and the same gap widened to `f64`.
                let g32 = box_gap_sq(&a, &b);
                let g64 = box_gap_sq(&a.map(f64::from), &b.map(f64::from));
                if g32 > gate {
                    rejected += 1;
                    assert!(g64 > t_hi, "cutoff {cutoff}: {a:?} {b:?}");
                }
                if g32 > t_hi as f32 && g64 <= t_hi {
                    unsafe_gate += 1;
                }
            }
        }
        // The boxes straddle the cutoff: some pairs are rejected, and a gate without its
        // margin would have rejected some linking ones.
        assert!(rejected > 1000, "{rejected}");
        assert!(unsafe_gate > 0, "{unsafe_gate}");
    }

    #[test]
    fn voxels_linked_in_two_halves_join_across_the_boundary() {
        // Lines along x with points 0.2 m apart, cutoff 0.5 m: each line is one set, and
        // only the links across the halves' x boundary make it one.
        let rule = |c: f64| Rule {
            cutoff_m: c,
            per_m: 0.0,
            ranges: None,
            lo: c,
            hi: c,
        };
        for lines in [1usize, 2, 3] {
            let mut points = Vec::new();
            for l in 0..lines {
                for i in 0..2000 {
                    points.push([i as f32 * 0.2, 5.0 * l as f32, 0.1 * (i % 3) as f32]);
                }
            }
            let mut sets = link_cells(&points, &rule(0.5)).unwrap().sets;
            assert!(sets.len() >= 2 * SPLIT_MIN_CELLS, "the halves are taken");
            assert_eq!(sets.component_labels().1, lines, "{lines} lines");
            // Below the 0.2 m spacing no two points link: every voxel is its own set.
            let mut sets = link_cells(&points, &rule(0.19)).unwrap().sets;
            assert_eq!(
                sets.component_labels().1,
                sets.len(),
                "no voxel links at 0.19 m"
            );
        }
    }

    /// The AVX-512 build of the voxel keys (where this machine has it) gives the baseline
    /// build's keys, on points spread as `link_cells` spreads them.
    #[test]
    fn every_build_of_the_voxel_keys_gives_the_same_keys() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(8);
        let points: Vec<[f32; 3]> = (0..10_007)
            .map(|_| [0, 1, 2].map(|_| rng.random_range(-80.0f32..80.0)))
            .collect();
        // The offsets and field shifts of a 0.5 m cutoff: fields 2 and up, 10 bits each.
        let inv = 3f64.sqrt() / 0.5;
        let off = [0, 1, 2].map(|_| (-80.0 * inv).floor() - 2.0);
        let grid = KeyGrid {
            inv,
            off,
            sx: 20,
            sy: 10,
        };
        let plain = packed_keys_body(&points, grid, 14);
        // Each key is the point's own fields and index.
        for (i, (k, p)) in plain.iter().zip(&points).enumerate() {
            let f = |a: usize| (f64::from(p[a]) * inv - off[a]).floor() as u64;
            assert_eq!(*k, (f(0) << 20 | f(1) << 10 | f(2)) << 14 | i as u64);
        }
        assert_eq!(packed_keys(&points, grid, 14), plain, "picked");
        #[cfg(target_arch = "x86_64")]
        {
            if crate::numeric::avx512() {
                // SAFETY: the processor has AVX-512 F and DQ (checked on the line above).
                let wide = unsafe { packed_keys_avx512(&points, grid, 14) };
                assert_eq!(wide, plain, "avx512");
            }
        }
    }

    /// The grid's own labels are `apply_min_points` of its partition: random clumps and
    /// scattered points, some not finite, every `min_points` from 0 to past the largest
    /// part, on both sides of the halves' split.
    #[test]
    fn the_grids_labels_are_the_partitions_with_min_points() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(21);
        for case in 0..60 {
            let n = [0, 1, 5, 300, 3000][case % 5];
            let mut points: Vec<[f32; 3]> = (0..n)
                .map(|_| {
                    let c = rng.random_range(0..8) as f32 * 3.0;
                    [0, 1, 2].map(|_| c + rng.random_range(-1.5f32..1.5))
                })
                .collect();
            for k in 0..n / 50 {
                let i = rng.random_range(0..n);
                points[i][k % 3] = [f32::NAN, f32::INFINITY][k % 2];
            }
            let fp = FinitePoints::new(&points).unwrap();
            let cutoff = [0.3, 0.5, 1.0][case % 3];
            let partition = components(&fp, n, cutoff).unwrap();
            let largest = (0..n as u32)
                .map(|c| partition.iter().filter(|&&x| x == c).count())
                .max()
                .unwrap_or(0);
            for min_points in [0, 1, 2, 3, 10, largest, largest + 1] {
                let got = clustering(&fp, n, cutoff, min_points).unwrap();
                let want = super::super::apply_min_points(&partition, min_points);
                assert_eq!(got, want, "case {case}, min_points {min_points}");
            }
        }
    }

    #[test]
    fn radix_sort_sorts_and_carries_values() {
        let mut keys: Vec<u64> = (0..5000u64)
            .map(|i| (i * 2_654_435_761) % (1 << 40))
            .collect();
        let mut vals: Vec<u32> = (0..5000).collect();
        let orig = keys.clone();
        radix_sort(&mut keys, &mut vals, 40);
        assert!(keys.windows(2).all(|w| w[0] <= w[1]));
        for (k, v) in keys.iter().zip(&vals) {
            assert_eq!(orig[*v as usize], *k);
        }
    }
}
