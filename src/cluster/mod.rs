//! Single-linkage hierarchical clustering of non-ground returns.
//!
//! Two routes give the same flat clusters:
//! - the distance cut ([`CutRule::Distance`]) links every pair of points whose Euclidean
//!   distance is `<= cutoff` and takes connected components: a k-d tree radius search plus
//!   union-find, O(n log n), no distance matrix. With a fixed cutoff a voxel grid of side
//!   cutoff/sqrt(3) replaces the k-d tree (same exact result, expected O(n), see
//!   the `grid` module); the range-adaptive cutoff uses the tree. This equals SciPy's
//!   `fcluster(linkage(X, 'single'), t, 'distance')` (cophenetic distance `<= t`), PCL
//!   Euclidean cluster extraction, MATLAB `pcsegdist` and DBSCAN with `min_samples = 1`.
//! - the merge tree ([`linkage`]) is the Euclidean minimum spanning tree restricted to edges up
//!   to a bound, in SciPy's linkage-matrix layout, and is cut by the inconsistency criterion
//!   (MATLAB `clusterdata` default, depth 2) or by a maximum cluster count.
//!
//! # Distances and exactness
//! Points are `f32`; every distance that decides anything is computed in `f64` from the `f32`
//! coordinates as `sqrt(dx*dx + dy*dy + dz*dz)` (the formula SciPy's `pdist` uses) and
//! compared with `<=`. The k-d tree search runs in `f32` with a radius enlarged by a relative
//! 1e-5, far above the few-ulp error of an `f32` squared distance, so it only proposes
//! candidates and never decides: results equal an `f64` brute-force reference exactly. Only a
//! reference that computes distances differently (another summation order, `f32`) can
//! disagree, and then only for pairs at exactly the cutoff.
//!
//! Points with a non-finite coordinate are never linked: each is its own cluster.

mod describe;
mod grid;
mod msf;
mod tree;

pub use describe::{describe, describe_subset, ClusterInfo, ObjectRule, OrientedBox};
pub use tree::{cut_tree, inconsistent, linkage, write_linkage_csv, TreeCut};

use crate::error::{Error, Result};
use kiddo::immutable::float::kdtree::ImmutableKdTree;
use kiddo::SquaredEuclidean;
use std::borrow::Cow;

/// Relative enlargement of the `f32` search radius, so the tree never misses a candidate.
const SEARCH_MARGIN: f64 = 1e-5;

/// How the hierarchy is cut into flat clusters.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case", tag = "rule")]
pub enum CutRule {
    /// Link points closer than or at `cutoff_m` (+ `cutoff_per_m` x range): connected components.
    Distance,
    /// SciPy/MATLAB inconsistency criterion with depth 2 on the tree bounded by `max_edge_m`.
    Inconsistent {
        /// A node forms a cluster when its and all its descendants' coefficients are `<=` this.
        threshold: f64,
    },
    /// SciPy `maxclust`: the lowest merge height giving at most `k` clusters.
    MaxClust {
        /// Maximum number of clusters (at least 1).
        k: usize,
    },
}

/// Settings of [`cluster`].
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ClusterOptions {
    /// Cut rule.
    pub cut: CutRule,
    /// Distance cut in metres (used by [`CutRule::Distance`] only).
    pub cutoff_m: f64,
    /// Range-adaptive growth of the cutoff in metres per metre of range (0 = fixed cutoff).
    /// A pair links when `d <= cutoff_m + cutoff_per_m * max(range_i, range_j)`, range being
    /// the norm of the point (sensor at the origin). Used by [`CutRule::Distance`] only.
    pub cutoff_per_m: f64,
    /// Clusters with fewer points are noise (label -1); 0 or 1 keeps every cluster.
    pub min_points: usize,
    /// Longest edge of the merge tree in metres (tree-based rules only); may be infinite.
    pub max_edge_m: f64,
}

impl Default for ClusterOptions {
    fn default() -> Self {
        Self {
            cut: CutRule::Distance,
            cutoff_m: 0.5,
            cutoff_per_m: 0.0,
            min_points: 1,
            max_edge_m: 2.0,
        }
    }
}

/// Flat clustering of a point set.
#[derive(Clone, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct Clustering {
    /// Cluster id per point, 0..n_clusters numbered by smallest point index; -1 is noise.
    pub labels: Vec<i32>,
    /// Number of clusters with at least `min_points` points.
    pub n_clusters: usize,
    /// Number of points labelled -1.
    pub n_noise_points: usize,
}

/// Disjoint-set forest with union by size and path halving.
pub(crate) struct UnionFind {
    parent: Vec<u32>,
    size: Vec<u32>,
}

impl UnionFind {
    /// `n` singletons.
    pub(crate) fn new(n: usize) -> Self {
        Self {
            parent: (0..n as u32).collect(),
            size: vec![1; n],
        }
    }

    /// Parent of `x` (its root when the path is short).
    #[inline]
    pub(crate) fn parent(&self, x: u32) -> u32 {
        self.parent[x as usize]
    }

    /// Root of `x`.
    #[inline]
    pub(crate) fn find(&mut self, mut x: u32) -> u32 {
        while self.parent[x as usize] != x {
            let grand = self.parent[self.parent[x as usize] as usize];
            self.parent[x as usize] = grand;
            x = grand;
        }
        x
    }

    /// Joins the sets of `a` and `b`; returns false when they already were one set.
    #[inline]
    pub(crate) fn union(&mut self, a: u32, b: u32) -> bool {
        let (ra, rb) = (self.find(a), self.find(b));
        if ra == rb {
            return false;
        }
        self.join_roots(ra, rb);
        true
    }

    /// Joins two distinct roots (union by size); returns the root of the joined set.
    #[inline]
    pub(crate) fn join_roots(&mut self, mut ra: u32, mut rb: u32) -> u32 {
        if self.size[ra as usize] < self.size[rb as usize] {
            std::mem::swap(&mut ra, &mut rb);
        }
        self.parent[rb as usize] = ra;
        self.size[ra as usize] += self.size[rb as usize];
        ra
    }

    /// Appends the elements of `other`, numbered after this one's, with their sets.
    pub(crate) fn append(&mut self, other: UnionFind) {
        let n = self.parent.len() as u32;
        self.parent.extend(other.parent.iter().map(|&p| p + n));
        self.size.extend(other.size);
    }

    /// Number of elements.
    pub(crate) fn len(&self) -> usize {
        self.parent.len()
    }

    /// Component number per element, 0.. in order of each component's smallest element.
    pub(crate) fn component_labels(&mut self) -> (Vec<u32>, usize) {
        let n = self.parent.len();
        let mut root_label = vec![u32::MAX; n];
        let mut labels = Vec::with_capacity(n);
        let mut next = 0u32;
        for i in 0..n as u32 {
            let r = self.find(i) as usize;
            if root_label[r] == u32::MAX {
                root_label[r] = next;
                next += 1;
            }
            labels.push(root_label[r]);
        }
        (labels, next as usize)
    }
}

/// Exact distance between two points, in `f64` from the `f32` coordinates.
#[inline]
pub fn point_distance(a: &[f32; 3], b: &[f32; 3]) -> f64 {
    let dx = a[0] as f64 - b[0] as f64;
    let dy = a[1] as f64 - b[1] as f64;
    let dz = a[2] as f64 - b[2] as f64;
    (dx * dx + dy * dy + dz * dz).sqrt()
}

/// Distance of a point from the sensor at the origin, in `f64`.
#[inline]
pub fn point_range(a: &[f32; 3]) -> f64 {
    point_distance(a, &[0.0; 3])
}

/// Finite points and their original indices (the tree must not see NaN or infinity).
pub(crate) struct FinitePoints<'a> {
    /// Finite points in input order (the input itself when every point is finite).
    pub(crate) points: Cow<'a, [[f32; 3]]>,
    /// Original index of each finite point; `None` when every point is finite (identity),
    /// which spares copying the input, the common case.
    index: Option<Vec<u32>>,
}

impl<'a> FinitePoints<'a> {
    pub(crate) fn new(points: &'a [[f32; 3]]) -> Result<Self> {
        if points.len() >= u32::MAX as usize {
            return Err(Error::Invalid(format!(
                "clustering: {} points is more than the {} supported",
                points.len(),
                u32::MAX - 1
            )));
        }
        let finite = |p: &[f32; 3]| p.iter().all(|c| c.is_finite());
        if points.iter().all(finite) {
            return Ok(Self {
                points: Cow::Borrowed(points),
                index: None,
            });
        }
        let mut kept = Vec::with_capacity(points.len());
        let mut index = Vec::with_capacity(points.len());
        for (i, p) in points.iter().enumerate() {
            if finite(p) {
                kept.push(*p);
                index.push(i as u32);
            }
        }
        Ok(Self {
            points: Cow::Owned(kept),
            index: Some(index),
        })
    }

    /// Original index of finite point `f`.
    #[inline]
    pub(crate) fn global(&self, f: usize) -> u32 {
        match &self.index {
            None => f as u32,
            Some(index) => index[f],
        }
    }

    /// True when every input point is finite (point `f` is input point `f`).
    pub(crate) fn is_identity(&self) -> bool {
        self.index.is_none()
    }

    /// k-d tree over the finite points, items are positions in `self.points`.
    pub(crate) fn tree(&self) -> ImmutableKdTree<f32, u32, 3, 32> {
        ImmutableKdTree::new_from_slice(&self.points)
    }
}

/// Squared `f32` search radius that cannot miss a pair at distance `<= radius` in `f64`.
#[inline]
pub(crate) fn search_radius_sq(radius: f64) -> f32 {
    let r = radius * (1.0 + SEARCH_MARGIN);
    (r * r) as f32
}

fn check_non_negative(name: &str, v: f64) -> Result<()> {
    if v.is_nan() || v < 0.0 {
        return Err(Error::Invalid(format!(
            "clustering: {name} must be a non-negative number, got {v}"
        )));
    }
    Ok(())
}

/// Connected components of the graph linking pairs with `d <= cutoff_m + cutoff_per_m *
/// max(range_i, range_j)`; one union-find over all input indices.
pub fn distance_components(
    points: &[[f32; 3]],
    cutoff_m: f64,
    cutoff_per_m: f64,
) -> Result<Vec<u32>> {
    check_non_negative("cutoff_m", cutoff_m)?;
    check_non_negative("cutoff_per_m", cutoff_per_m)?;
    let fp = FinitePoints::new(points)?;
    if cutoff_per_m == 0.0 {
        if let Some(labels) = grid::components(&fp, points.len(), cutoff_m) {
            return Ok(labels);
        }
    } else if let Some(labels) = adaptive_shells(&fp, points.len(), cutoff_m, cutoff_per_m) {
        return Ok(labels);
    }
    Ok(tree_components(&fp, points.len(), cutoff_m, cutoff_per_m))
}

/// [`distance_components`] of the `n` points (finite ones in `fp`) by a k-d tree radius
/// search, where the voxel grids do not apply.
fn tree_components(fp: &FinitePoints, n: usize, cutoff_m: f64, cutoff_per_m: f64) -> Vec<u32> {
    let mut uf = UnionFind::new(n);
    if fp.points.len() > 1 {
        let tree = fp.tree();
        let pts = &fp.points;
        if cutoff_per_m == 0.0 {
            // Each pair is examined once, from its lower index.
            let r2 = search_radius_sq(cutoff_m);
            for (i, p) in pts.iter().enumerate() {
                let gi = fp.global(i);
                for nb in tree.within_unsorted::<SquaredEuclidean>(p, r2) {
                    let j = nb.item as usize;
                    if j <= i {
                        continue;
                    }
                    let gj = fp.global(j);
                    if uf.find(gi) == uf.find(gj) {
                        continue;
                    }
                    if point_distance(p, &pts[j]) <= cutoff_m {
                        uf.union(gi, gj);
                    }
                }
            }
        } else {
            // The pair cutoff grows with the larger range of the two, so a pair is examined
            // from its endpoint with the larger (range, index): that endpoint's own cutoff is
            // the pair's cutoff, hence its search radius is exact for every pair it owns.
            let ranges: Vec<f64> = pts.iter().map(point_range).collect();
            let key_less = |a: usize, b: usize| (ranges[a], a) < (ranges[b], b);
            for (i, p) in pts.iter().enumerate() {
                let cut = cutoff_m + cutoff_per_m * ranges[i];
                let r2 = search_radius_sq(cut);
                let gi = fp.global(i);
                for nb in tree.within_unsorted::<SquaredEuclidean>(p, r2) {
                    let j = nb.item as usize;
                    if !key_less(j, i) {
                        continue;
                    }
                    let gj = fp.global(j);
                    if uf.find(gi) == uf.find(gj) {
                        continue;
                    }
                    let pair_cut = cutoff_m + cutoff_per_m * ranges[i].max(ranges[j]);
                    if point_distance(p, &pts[j]) <= pair_cut {
                        uf.union(gi, gj);
                    }
                }
            }
        }
    }
    uf.component_labels().0
}

/// Largest ratio of the largest to the smallest pair cutoff inside one grid pass: the voxel
/// side is the smallest cutoff over sqrt(3) and linked points must lie within two voxels,
/// so the ratio must stay below 2 / sqrt(3); the 1e-3 margin absorbs rounding.
fn shell_ratio() -> f64 {
    2.0 / 3f64.sqrt() * (1.0 - 1e-3)
}

/// Range-adaptive cut on voxel grids, one pass per range shell.
///
/// A pair owned by its farther point `i` (range in shell `[r_lo, r_hi)`) has cutoff
/// `c(r_i) < c(r_hi)` and its other point lies at range `>= r_lo - c(r_hi)` (the distance
/// bounds the range difference). So the pass of that shell takes every point with range in
/// `[r_lo - c(r_hi), r_hi)`; all its pair cutoffs lie in `[c(r_lo - c(r_hi)), c(r_hi))`, and
/// `r_hi` is chosen so that this interval's ratio stays below [`shell_ratio`], which lets the
/// fixed cut's voxel grid ([`grid::link_cells`]) run with the exact pair rule. Every link a
/// pass finds is a true link (same-voxel pairs are closer than the pass's smallest cutoff),
/// and every true link is found by its farther point's pass, so the union of the passes is
/// exactly the brute-force partition. `None` (the caller falls back to the k-d tree) when a
/// shell cannot grow: `cutoff_m` 0, or `cutoff_per_m >= (ratio - 1) / ratio` (about 0.13).
fn adaptive_shells(fp: &FinitePoints, n: usize, cutoff_m: f64, per_m: f64) -> Option<Vec<u32>> {
    let q = shell_ratio();
    let growth = q / (1.0 + q * per_m);
    if !(cutoff_m > 0.0 && growth > 1.0 + 1e-3 && cutoff_m.is_finite() && per_m.is_finite()) {
        return None;
    }
    let ranges: Vec<f64> = fp.points.iter().map(point_range).collect();
    let r_max = ranges.iter().copied().fold(0.0f64, f64::max);
    let cut = |r: f64| cutoff_m + per_m * r;
    // Points sorted by range: each pass is a contiguous slice.
    let mut order: Vec<u32> = (0..fp.points.len() as u32).collect();
    order.sort_unstable_by(|&a, &b| ranges[a as usize].total_cmp(&ranges[b as usize]));
    let sorted_r: Vec<f64> = order.iter().map(|&i| ranges[i as usize]).collect();
    let mut uf = UnionFind::new(n);
    let mut r_lo = 0.0f64;
    let mut pts: Vec<[f32; 3]> = Vec::new();
    let mut rs: Vec<f64> = Vec::new();
    loop {
        // Largest cutoff c_hi with c_hi <= q * c(r_lo - c_hi), i.e. c_hi (1 + q b) <= q c(r_lo).
        let c_hi = cut(r_lo) * growth;
        let r_hi = (c_hi - cutoff_m) / per_m;
        let last = r_hi > r_max;
        let from = sorted_r.partition_point(|&r| r < r_lo - c_hi);
        let to = if last {
            sorted_r.len()
        } else {
            sorted_r.partition_point(|&r| r < r_hi)
        };
        if to > from {
            pts.clear();
            rs.clear();
            for &i in &order[from..to] {
                pts.push(fp.points[i as usize]);
                rs.push(ranges[i as usize]);
            }
            let lo = rs.iter().map(|&r| cut(r)).fold(f64::INFINITY, f64::min);
            let hi = rs.iter().map(|&r| cut(r)).fold(0.0f64, f64::max);
            let rule = grid::Rule {
                cutoff_m,
                per_m,
                ranges: Some(&rs),
                lo,
                hi,
            };
            let grid::Linked {
                cell_of, mut sets, ..
            } = grid::link_cells(&pts, &rule)?;
            // Fold the pass's voxel sets into the point union-find.
            let mut first = vec![u32::MAX; sets.len()];
            for (k, &c) in cell_of.iter().enumerate() {
                let g = fp.global(order[from + k] as usize);
                let root = sets.find(c) as usize;
                if first[root] == u32::MAX {
                    first[root] = g;
                } else {
                    uf.union(first[root], g);
                }
            }
        }
        if last {
            break;
        }
        r_lo = r_hi;
    }
    Some(uf.component_labels().0)
}

/// Turns a partition (component number per point) into labels, dropping small clusters.
///
/// Clusters with fewer than `min_points` points become noise (-1); the rest are numbered
/// 0..k in order of their smallest point index.
pub fn apply_min_points(partition: &[u32], min_points: usize) -> Clustering {
    let n_parts = partition
        .iter()
        .copied()
        .max()
        .map_or(0, |m| m as usize + 1);
    let mut counts = vec![0usize; n_parts];
    for &c in partition {
        counts[c as usize] += 1;
    }
    // Each part's label decided up front where it can be: -1 (noise) for the small
    // parts, -2 (a cluster not numbered yet) for the others, so the loop over the points
    // branches only on a cluster's first point, not on every point's part size (noise
    // and clusters alternate along the points, and that test mispredicted).
    let mut new_id: Vec<i32> = counts
        .iter()
        .map(|&n| if n < min_points { -1 } else { -2 })
        .collect();
    let mut next = 0i32;
    let mut labels = Vec::with_capacity(partition.len());
    for &c in partition {
        let id = &mut new_id[c as usize];
        if *id == -2 {
            *id = next;
            next += 1;
        }
        labels.push(*id);
    }
    let n_noise = counts.iter().filter(|&&n| n < min_points).sum();
    Clustering {
        labels,
        n_clusters: next as usize,
        n_noise_points: n_noise,
    }
}

/// Clusters points by single linkage and the chosen cut rule.
///
/// Tree-based rules ([`CutRule::Inconsistent`], [`CutRule::MaxClust`]) use the merge tree
/// bounded by `max_edge_m`: points not connected by edges up to the bound are never merged,
/// which is exact for every merge below the bound.
pub fn cluster(points: &[[f32; 3]], opts: &ClusterOptions) -> Result<Clustering> {
    let partition = match opts.cut {
        CutRule::Distance if opts.cutoff_per_m == 0.0 => {
            check_non_negative("cutoff_m", opts.cutoff_m)?;
            let fp = FinitePoints::new(points)?;
            // The fixed cut's voxel grid labels the points itself (one pass instead of
            // the partition's and `apply_min_points`' four).
            match grid::clustering(&fp, points.len(), opts.cutoff_m, opts.min_points) {
                Some(c) => return Ok(c),
                // Where the grid does not apply, the partition of the k-d tree.
                None => tree_components(&fp, points.len(), opts.cutoff_m, 0.0),
            }
        }
        CutRule::Distance => distance_components(points, opts.cutoff_m, opts.cutoff_per_m)?,
        CutRule::Inconsistent { threshold } => {
            if threshold.is_nan() {
                return Err(Error::Invalid(
                    "clustering: inconsistent threshold is NaN".into(),
                ));
            }
            let z = linkage(points, opts.max_edge_m)?;
            cut_tree(
                &z,
                points.len(),
                TreeCut::Inconsistent {
                    threshold,
                    depth: 2,
                },
            )?
        }
        CutRule::MaxClust { k } => {
            let z = linkage(points, opts.max_edge_m)?;
            cut_tree(&z, points.len(), TreeCut::MaxClust { k })?
        }
    };
    Ok(apply_min_points(&partition, opts.min_points))
}

/// Points of decoded returns, for [`cluster`].
pub fn points_of(returns: &[crate::frame::Return]) -> Vec<[f32; 3]> {
    returns.iter().map(|r| [r.x, r.y, r.z]).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    /// Where the voxel grid does not apply (a zero cutoff, coordinates beyond its keys),
    /// `cluster` takes the k-d tree's partition: the same labels as `apply_min_points`
    /// of `distance_components`, and pairs within the cutoff still link.
    #[test]
    fn the_fixed_cut_beyond_the_grid_is_the_trees() {
        let far = 1e12f32;
        let points = [
            [0.0, 0.0, 0.0],
            [0.0, 0.0, 0.0],
            [far, 0.0, 0.0],
            [far, 0.25, 0.0],
            [f32::NAN, 0.0, 0.0],
            [-far, 0.0, 0.0],
        ];
        for (cutoff_m, min_points) in [(0.0, 1), (0.0, 2), (0.5, 1), (0.5, 2)] {
            let opts = ClusterOptions {
                cutoff_m,
                min_points,
                ..ClusterOptions::default()
            };
            let got = cluster(&points, &opts).unwrap();
            let partition = distance_components(&points, cutoff_m, 0.0).unwrap();
            assert_eq!(got, apply_min_points(&partition, min_points), "{cutoff_m}");
            // The two equal points always link; the pair 0.25 m apart at 0.5 m only.
            assert_eq!(partition[0], partition[1]);
            assert_eq!(partition[2] == partition[3], cutoff_m == 0.5);
        }
    }

    /// `apply_min_points` against the rule written out one point at a time, on random
    /// partitions (parts of every size, interleaved) and thresholds.
    #[test]
    fn min_points_numbers_clusters_by_first_point() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        for case in 0..200 {
            let n = rng.random_range(0..400);
            let parts = rng.random_range(1..60u32);
            let partition: Vec<u32> = (0..n).map(|_| rng.random_range(0..parts)).collect();
            let min_points = [0, 1, 2, 3, 5, 8, 20][case % 7];
            let got = apply_min_points(&partition, min_points);
            let size = |c: u32| partition.iter().filter(|&&x| x == c).count();
            let mut ids = std::collections::HashMap::new();
            let want: Vec<i32> = partition
                .iter()
                .map(|&c| {
                    if size(c) < min_points {
                        -1
                    } else {
                        let next = ids.len() as i32;
                        *ids.entry(c).or_insert(next)
                    }
                })
                .collect();
            assert_eq!(got.labels, want, "case {case}");
            assert_eq!(got.n_clusters, ids.len(), "case {case}");
            let noise = want.iter().filter(|&&l| l < 0).count();
            assert_eq!(got.n_noise_points, noise, "case {case}");
        }
    }
}
