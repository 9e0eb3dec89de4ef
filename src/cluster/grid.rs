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

/// Bits per radix-sort digit (a 2048-entry histogram stays in L1).
const RADIX_BITS: u32 = 11;

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
fn sq3(dx: f64, dy: f64, dz: f64) -> f64 {
    dx * dx + dy * dy + dz * dz
}

/// Gap between a coordinate interval and a value (0 inside): a lower bound of `|v - b|` for
/// every `b` in `[lo, hi]`, and since `f64` rounding is monotone the rounded gap is also a
/// lower bound of every rounded difference, so box tests never reject a linked pair.
#[inline(always)]
fn gap(lo: f64, hi: f64, v: f64) -> f64 {
    (lo - v).max(v - hi).max(0.0)
}

/// Voxel coordinate `floor(v / side)`, or `None` beyond [`CELL_LIMIT`] or for NaN. Written
/// out because `f64::floor` is a libm call on baseline x86-64.
#[inline(always)]
fn cell_of_coord(v: f32, side: f64) -> Option<i64> {
    let f = v as f64 / side;
    if f.is_nan() || f.abs() > CELL_LIMIT {
        return None;
    }
    let t = f as i64;
    Some(if (t as f64) > f { t - 1 } else { t })
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
    let rule = Rule {
        cutoff_m: cutoff,
        per_m: 0.0,
        ranges: None,
        lo: cutoff,
        hi: cutoff,
    };
    let (cell_of, mut sets) = link_cells(&fp.points, &rule)?;
    // Labels in input order, numbered by each component's smallest input index.
    let n_cells = sets.len();
    let mut cell_of_input = vec![u32::MAX; n];
    for (f, &i) in fp.index.iter().enumerate() {
        cell_of_input[i as usize] = cell_of[f];
    }
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

/// Voxel of each point and the union-find over voxels after linking, for the points of one
/// pass. The voxel side is `rule.lo / sqrt(3)` (every same-voxel pair links); `None` when
/// the grid does not apply (zero or infinite cutoff, `rule.hi` beyond two voxel sides,
/// coordinates too far out for the packed keys).
pub(crate) fn link_cells(points: &[[f32; 3]], rule: &Rule) -> Option<(Vec<u32>, UnionFind)> {
    // The 1e-6 shrink keeps same-voxel pairs below the cutoff despite rounding in the voxel
    // assignment and in the distance itself (both ~1e-16 relative).
    let side = rule.lo / 3f64.sqrt() * (1.0 - 1e-6);
    if !(side > 0.0 && side.is_finite()) || rule.hi > 2.0 * side {
        return None;
    }
    let m = points.len();
    if m == 0 {
        return Some((Vec::new(), UnionFind::new(0)));
    }
    // Two cheap passes (bounds, then keys) instead of storing every voxel triple.
    let (mut lo, mut hi) = ([i64::MAX; 3], [i64::MIN; 3]);
    for p in points {
        for a in 0..3 {
            let c = cell_of_coord(p[a], side)?;
            lo[a] = lo[a].min(c);
            hi[a] = hi[a].max(c);
        }
    }
    // Fields hold cell - lo + 2 in [2, span + 2], so a step of up to two either way stays
    // inside its field and key arithmetic never carries between fields.
    let width = |a: usize| 64 - ((hi[a] - lo[a] + 4) as u64).leading_zeros();
    let (wy, wz) = (width(1), width(2));
    let total = width(0) + wy + wz;
    if total > 62 {
        return None;
    }
    let (sx, sy) = (wy + wz, wz);
    let field = |p: &[f32; 3], a: usize| {
        (cell_of_coord(p[a], side).expect("checked in the first pass") - lo[a] + 2) as u64
    };
    let mut keys: Vec<u64> = points
        .iter()
        .map(|p| field(p, 0) << sx | field(p, 1) << sy | field(p, 2))
        .collect();
    let mut order: Vec<u32> = (0..m as u32).collect();
    radix_sort(&mut keys, &mut order, total);

    // Voxels as runs of the sorted keys; points copied in voxel order for locality.
    let mut cell_key: Vec<u64> = Vec::new();
    let mut cell_start: Vec<u32> = Vec::new();
    let mut cell_box: Vec<[f64; 6]> = Vec::new();
    let mut sp: Vec<[f32; 3]> = Vec::with_capacity(m);
    let mut cell_of: Vec<u32> = vec![0; m];
    // Range of each point in voxel order (adaptive passes only).
    let mut sr: Vec<f64> = Vec::with_capacity(if rule.ranges.is_some() { m } else { 0 });
    for (k, (&key, &i)) in keys.iter().zip(order.iter()).enumerate() {
        let pf = points[i as usize];
        if let Some(r) = rule.ranges {
            sr.push(r[i as usize]);
        }
        let p = pf.map(|c| c as f64);
        if k == 0 || keys[k - 1] != key {
            cell_key.push(key);
            cell_start.push(k as u32);
            cell_box.push([p[0], p[1], p[2], p[0], p[1], p[2]]);
        }
        let b = cell_box.last_mut().expect("pushed above");
        for a in 0..3 {
            b[a] = b[a].min(p[a]);
            b[a + 3] = b[a + 3].max(p[a]);
        }
        cell_of[i as usize] = (cell_key.len() - 1) as u32;
        sp.push(pf);
    }
    drop(keys);
    drop(order);
    let n_cells = cell_key.len();
    cell_start.push(m as u32);
    // Sentinel above every neighbour key (keys use at most 62 bits): walks need no bounds test.
    cell_key.push(u64::MAX);
    let mut sets = UnionFind::new(n_cells);
    // Squared distances up to `t` link for sure; above `t_hi` never; in between (adaptive
    // passes only) the exact pair rule decides.
    let t = squared_threshold(rule.lo);
    let t_hi = squared_threshold(rule.hi);
    let adaptive = rule.ranges.is_some();

    // Forward neighbour columns (dx > 0, or dx == 0 and dy > 0) in dz [-2, 2], walked as
    // three key spans, one per dx: for dx = 1, 2 the columns dy = -2..2 lie between
    // (dx, -2, -2) and (dx, 2, 2) in key order, for dx = 0 the columns dy = 1, 2 between
    // (0, 1, -2) and (0, 2, 2). A span also holds voxels of those columns beyond two steps
    // in z, skipped by their z field. One pointer per span instead of one per column:
    // the pointer walks were most of this function's time.
    let pack = |dx: i64, dy: i64, dz: i64| -> u64 { ((dx << sx) + (dy << sy) + dz) as u64 };
    let columns: [(u64, u64); 3] = [
        (pack(0, 1, -2), pack(0, 2, 2)),
        (pack(1, -2, -2), pack(1, 2, 2)),
        (pack(2, -2, -2), pack(2, 2, 2)),
    ];
    let z_mask = (1u64 << wz) - 1;
    let mut ptr = vec![0usize; columns.len()];

    // Tests one voxel pair and joins it when some point pair links.
    let try_link = |sets: &mut UnionFind, a: usize, b: usize| {
        let (ra, rb) = (sets.find(a as u32), sets.find(b as u32));
        if ra == rb {
            return;
        }
        let (ba, bb) = (&cell_box[a], &cell_box[b]);
        let g = sq3(
            (bb[0] - ba[3]).max(ba[0] - bb[3]).max(0.0),
            (bb[1] - ba[4]).max(ba[1] - bb[4]).max(0.0),
            (bb[2] - ba[5]).max(ba[2] - bb[5]).max(0.0),
        );
        if g > t_hi {
            return;
        }
        let (b0, b1) = (cell_start[b] as usize, cell_start[b + 1] as usize);
        let pb = &sp[b0..b1];
        for (ia, p) in sp[cell_start[a] as usize..cell_start[a + 1] as usize]
            .iter()
            .enumerate()
        {
            let p = p.map(|c| c as f64);
            let g = sq3(
                gap(bb[0], bb[3], p[0]),
                gap(bb[1], bb[4], p[1]),
                gap(bb[2], bb[5], p[2]),
            );
            if g > t_hi {
                continue;
            }
            let linked = if adaptive {
                let ra_range = sr[cell_start[a] as usize + ia];
                pb.iter().enumerate().any(|(ib, q)| {
                    let d2 = sq3(p[0] - q[0] as f64, p[1] - q[1] as f64, p[2] - q[2] as f64);
                    d2 <= t
                        || (d2 <= t_hi
                            && d2.sqrt() <= rule.cutoff_m + rule.per_m * ra_range.max(sr[b0 + ib]))
                })
            } else {
                pb.iter()
                    .any(|q| sq3(p[0] - q[0] as f64, p[1] - q[1] as f64, p[2] - q[2] as f64) <= t)
            };
            if linked {
                sets.join_roots(ra, rb);
                return;
            }
        }
    };

    for c in 0..n_cells {
        let key = cell_key[c];
        let mut q = c + 1;
        while cell_key[q] <= key + 2 {
            try_link(&mut sets, c, q);
            q += 1;
        }
        let z = key & z_mask;
        for (j, &(lo_off, hi_off)) in columns.iter().enumerate() {
            let (klo, khi) = (key.wrapping_add(lo_off), key.wrapping_add(hi_off));
            let mut p = ptr[j];
            while cell_key[p] < klo {
                p += 1;
            }
            ptr[j] = p;
            while cell_key[p] <= khi {
                if (cell_key[p] & z_mask).abs_diff(z) <= 2 {
                    try_link(&mut sets, c, p);
                }
                p += 1;
            }
        }
    }

    Some((cell_of, sets))
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
