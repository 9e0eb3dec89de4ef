//! The single-linkage merge tree (SciPy linkage-matrix layout) and the cuts on it.

use super::{point_distance, FinitePoints};
use crate::error::{Error, Result};
use std::io::Write;

/// A cut of a merge tree into flat clusters, as SciPy's `fcluster` criteria.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum TreeCut {
    /// `criterion='distance'`: a node is a cluster when its height (and its descendants') is `<= t`.
    Distance {
        /// Cut height in metres.
        t: f64,
    },
    /// `criterion='inconsistent'`: a node is a cluster when its inconsistency coefficient and
    /// all its descendants' are `<= threshold`.
    Inconsistent {
        /// Coefficient threshold.
        threshold: f64,
        /// Levels of links included in each link's statistics (MATLAB/SciPy default 2).
        depth: usize,
    },
    /// `criterion='maxclust'`: the distance cut at the lowest merge height giving at most `k`
    /// clusters (all singletons when `k >= n`).
    MaxClust {
        /// Maximum number of clusters (at least 1).
        k: usize,
    },
}

/// Union-find whose roots are linkage cluster ids: a merge creates the next id `n + row`.
struct LinkageUnionFind {
    parent: Vec<u32>,
    size: Vec<u32>,
    next: u32,
}

impl LinkageUnionFind {
    fn new(n: usize) -> Self {
        let cap = (2 * n).saturating_sub(1);
        Self {
            parent: (0..cap as u32).collect(),
            size: (0..cap).map(|i| u32::from(i < n)).collect(),
            next: n as u32,
        }
    }

    fn find(&mut self, x: u32) -> u32 {
        let mut root = x;
        while self.parent[root as usize] != root {
            root = self.parent[root as usize];
        }
        let mut y = x;
        while self.parent[y as usize] != root {
            let up = self.parent[y as usize];
            self.parent[y as usize] = root;
            y = up;
        }
        root
    }

    /// Merges roots `a` and `b` under a new id; returns the merged size.
    fn merge(&mut self, a: u32, b: u32) -> u32 {
        let new = self.next;
        self.parent[a as usize] = new;
        self.parent[b as usize] = new;
        let s = self.size[a as usize] + self.size[b as usize];
        self.size[new as usize] = s;
        self.next += 1;
        s
    }
}

/// Turns edges in merge order into linkage rows, skipping edges inside one cluster.
fn label_edges(n: usize, edges: impl IntoIterator<Item = (u32, u32, f64)>) -> Vec<[f64; 4]> {
    let mut uf = LinkageUnionFind::new(n);
    let mut rows = Vec::with_capacity(n.saturating_sub(1));
    for (i, j, d) in edges {
        let (ri, rj) = (uf.find(i), uf.find(j));
        if ri == rj {
            continue;
        }
        let (a, b) = if ri < rj { (ri, rj) } else { (rj, ri) };
        let count = uf.merge(a, b);
        rows.push([a as f64, b as f64, d, count as f64]);
    }
    rows
}

/// Single-linkage merge tree of the points, restricted to edges of length `<= max_edge_m`.
///
/// Rows are `[idx1, idx2, height, count]` in SciPy's layout: point ids are 0..n, the merge in
/// row r creates id `n + r`, `idx1 < idx2`, rows by increasing height. Heights are `f64`
/// distances between the `f32` points. Points not connected below the bound stay in separate
/// trees (fewer than n-1 rows, a forest); non-finite points are never merged.
///
/// With a finite bound the rows are Kruskal's over the edges sorted by (length, i, j), from
/// the minimum spanning forest under that order (`msf`, in memory linear in the points). With an infinite bound it runs SciPy's own MST algorithm (Prim's, in
/// O(n^2) time and O(n) memory, distances computed on the fly), so equal heights come out in
/// SciPy's order too. Both give the same heights and, without ties, the same rows.
pub fn linkage(points: &[[f32; 3]], max_edge_m: f64) -> Result<Vec<[f64; 4]>> {
    if max_edge_m.is_nan() || max_edge_m < 0.0 {
        return Err(Error::Invalid(format!(
            "clustering: max_edge_m must be a non-negative number, got {max_edge_m}"
        )));
    }
    let fp = FinitePoints::new(points)?;
    let n = points.len();
    let m = fp.points.len();
    if m < 2 {
        return Ok(Vec::new());
    }
    if max_edge_m.is_infinite() {
        return Ok(label_edges(n, prim_edges(&fp)));
    }
    let edges = super::msf::forest(&fp.points, max_edge_m, |i| fp.global(i));
    Ok(label_edges(n, edges.into_iter().map(|(d, i, j)| (i, j, d))))
}

/// The rows Kruskal's algorithm gives over every edge up to `max_edge_m` (what `linkage`
/// did before its forest was found in linear memory): the reference of the tests.
#[cfg(test)]
fn kruskal_linkage(points: &[[f32; 3]], max_edge_m: f64) -> Vec<[f64; 4]> {
    use kiddo::SquaredEuclidean;
    let fp = FinitePoints::new(points).expect("points");
    let n = points.len();
    if fp.points.len() < 2 {
        return Vec::new();
    }
    let tree = fp.tree();
    let r2 = super::search_radius_sq(max_edge_m);
    let mut edges: Vec<(f64, u32, u32)> = Vec::new();
    for (i, p) in fp.points.iter().enumerate() {
        for nb in tree.within_unsorted::<SquaredEuclidean>(p, r2) {
            let j = nb.item as usize;
            if j <= i {
                continue;
            }
            let d = point_distance(p, &fp.points[j]);
            if d <= max_edge_m {
                edges.push((d, fp.global(i), fp.global(j)));
            }
        }
    }
    edges.sort_unstable_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)).then(a.2.cmp(&b.2)));
    label_edges(n, edges.into_iter().map(|(d, i, j)| (i, j, d)))
}

/// SciPy's `mst_single_linkage` order: Prim's from the first point, each row (last added,
/// next added, distance), then a stable sort by distance.
fn prim_edges(fp: &FinitePoints) -> Vec<(u32, u32, f64)> {
    let m = fp.points.len();
    let mut merged = vec![false; m];
    let mut best = vec![f64::INFINITY; m];
    let mut rows = Vec::with_capacity(m - 1);
    let mut x = 0usize;
    for _ in 0..m - 1 {
        merged[x] = true;
        let mut y = 0usize;
        let mut current = f64::INFINITY;
        let px = fp.points[x];
        for i in 0..m {
            if merged[i] {
                continue;
            }
            let d = point_distance(&px, &fp.points[i]);
            if best[i] > d {
                best[i] = d;
            }
            if best[i] < current {
                y = i;
                current = best[i];
            }
        }
        rows.push((fp.global(x), fp.global(y), current));
        x = y;
    }
    rows.sort_by(|a, b| a.2.total_cmp(&b.2));
    rows
}

/// Checks that `z` is a linkage (forest) over `n` points: each row merges two existing,
/// not yet merged ids into id `n + row`.
fn validate(z: &[[f64; 4]], n: usize) -> Result<()> {
    if z.len() >= n.max(1) {
        return Err(Error::Invalid(format!(
            "linkage: {} rows for {n} points (at most n-1)",
            z.len()
        )));
    }
    let mut used = vec![false; n + z.len()];
    for (r, row) in z.iter().enumerate() {
        for &c in &row[..2] {
            let ok = c.fract() == 0.0 && c >= 0.0 && (c as usize) < n + r;
            if !ok || used[c as usize] {
                return Err(Error::Invalid(format!(
                    "linkage row {r}: cluster id {c} is not a point or an earlier unmerged cluster"
                )));
            }
            used[c as usize] = true;
        }
        if row[0] == row[1] || row[2].is_nan() {
            return Err(Error::Invalid(format!("linkage row {r}: invalid merge")));
        }
    }
    Ok(())
}

/// SciPy's `inconsistent(Z, depth)` for a linkage (forest) over `n` points.
///
/// Each row is `[mean, std, count, coefficient]` over the link and the links below it down to
/// `depth` levels (depth 1 or less: the link alone). The standard deviation is the sample one
/// (divisor count-1); the coefficient is `(height - mean) / std`, 0 when std is 0. Sums run in
/// SciPy's order (left subtree, right subtree, the link) so the values are bit-identical.
pub fn inconsistent(z: &[[f64; 4]], n: usize, depth: usize) -> Result<Vec<[f64; 4]>> {
    validate(z, n)?;
    Ok(inconsistent_unchecked(z, n, depth))
}

fn inconsistent_unchecked(z: &[[f64; 4]], n: usize, depth: usize) -> Vec<[f64; 4]> {
    struct Acc {
        count: usize,
        sum: f64,
        sum_sq: f64,
    }
    fn visit(z: &[[f64; 4]], n: usize, link: usize, level: usize, depth: usize, acc: &mut Acc) {
        if level + 1 < depth {
            for &c in &z[link][..2] {
                let c = c as usize;
                if c >= n {
                    visit(z, n, c - n, level + 1, depth, acc);
                }
            }
        }
        let d = z[link][2];
        acc.count += 1;
        acc.sum += d;
        acc.sum_sq += d * d;
    }
    (0..z.len())
        .map(|i| {
            let mut acc = Acc {
                count: 0,
                sum: 0.0,
                sum_sq: 0.0,
            };
            visit(z, n, i, 0, depth, &mut acc);
            let c = acc.count as f64;
            let mean = acc.sum / c;
            let var = if acc.count < 2 {
                (acc.sum_sq - acc.sum * acc.sum) / c
            } else {
                (acc.sum_sq - (acc.sum * acc.sum) / c) / (c - 1.0)
            };
            if var > 0.0 {
                let std = var.sqrt();
                [mean, std, c, (z[i][2] - mean) / std]
            } else {
                [mean, 0.0, c, 0.0]
            }
        })
        .collect()
}

/// Maximum of a per-link value over each link and its descendants (links only).
fn subtree_max(z: &[[f64; 4]], n: usize, value: impl Fn(usize) -> f64) -> Vec<f64> {
    let mut mc: Vec<f64> = Vec::with_capacity(z.len());
    for (k, row) in z.iter().enumerate() {
        let mut m = value(k);
        for &c in &row[..2] {
            let c = c as usize;
            if c >= n && mc[c - n] > m {
                m = mc[c - n];
            }
        }
        mc.push(m);
    }
    mc
}

/// Flat clusters of the points under a linkage (forest) cut by `cut`.
///
/// Returns a component number per point, numbered 0.. by smallest point index. A link is
/// merged when its criterion value, maximised over its subtree, is `<= ` the threshold (SciPy's
/// `cluster_monocrit`); points of unconnected trees are never merged.
pub fn cut_tree(z: &[[f64; 4]], n: usize, cut: TreeCut) -> Result<Vec<u32>> {
    validate(z, n)?;
    let (mc, thresh) = match cut {
        TreeCut::Distance { t } => (subtree_max(z, n, |k| z[k][2]), t),
        TreeCut::Inconsistent { threshold, depth } => {
            let r = inconsistent_unchecked(z, n, depth);
            (subtree_max(z, n, |k| r[k][3]), threshold)
        }
        TreeCut::MaxClust { k } => {
            if k == 0 {
                return Err(Error::Invalid("maxclust: k must be at least 1".into()));
            }
            let mc = subtree_max(z, n, |r| z[r][2]);
            let thresh = if k >= n {
                f64::NEG_INFINITY
            } else {
                // Merged links form a downward-closed set, each removing one cluster, so a
                // threshold t leaves n - #{mc <= t} clusters: take the smallest mc value that
                // leaves at most k (or all merges when the forest cannot get down to k).
                let mut sorted = mc.clone();
                sorted.sort_by(f64::total_cmp);
                let need = n - k;
                if need <= sorted.len() {
                    sorted[need - 1]
                } else {
                    f64::INFINITY
                }
            };
            (mc, thresh)
        }
    };
    let mut uf = super::UnionFind::new(n);
    // A leaf point standing for each cluster id, to union whole subtrees with one operation.
    let mut rep: Vec<u32> = (0..n as u32).collect();
    for (k, row) in z.iter().enumerate() {
        let (a, b) = (rep[row[0] as usize], rep[row[1] as usize]);
        if mc[k] <= thresh {
            uf.union(a, b);
        }
        rep.push(a);
    }
    Ok(uf.component_labels().0)
}

/// Writes a linkage as CSV: header `cluster_a,cluster_b,distance,count`, one row per merge.
pub fn write_linkage_csv<W: Write>(mut w: W, z: &[[f64; 4]]) -> std::io::Result<()> {
    writeln!(w, "cluster_a,cluster_b,distance,count")?;
    for row in z {
        // Ids and counts are integers; `{}` on f64 prints the shortest exact round trip.
        writeln!(
            w,
            "{},{},{},{}",
            row[0] as u64, row[1] as u64, row[2], row[3] as u64
        )?;
    }
    w.flush()
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    /// Random clouds with ties (points on a coarse grid, repeated points) and non-finite
    /// points: the linear-memory forest gives exactly Kruskal's rows.
    #[test]
    fn forest_rows_are_kruskal_rows() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        for case in 0..60 {
            let n = [2, 3, 17, 40, 300, 2_000][case % 6];
            let grid = case % 3 == 0;
            let mut pts: Vec<[f32; 3]> = (0..n)
                .map(|_| {
                    let mut p = [0f32; 3];
                    for c in &mut p {
                        *c = if grid {
                            f32::from(rng.random_range(0u8..6)) * 0.5
                        } else {
                            rng.random_range(-8.0f32..8.0)
                        };
                    }
                    p
                })
                .collect();
            if case % 4 == 1 {
                pts[n / 2] = [f32::NAN, 0.0, 0.0];
                pts[0] = pts[n - 1];
            }
            for max_edge in [0.0, 0.5, 0.75, 1.3, 4.0, 100.0] {
                let fast = linkage(&pts, max_edge).expect("linkage");
                let want = kruskal_linkage(&pts, max_edge);
                assert_eq!(
                    fast.len(),
                    want.len(),
                    "case {case} n {n} max_edge {max_edge}"
                );
                for (a, b) in fast.iter().zip(&want) {
                    assert_eq!(
                        a.map(f64::to_bits),
                        b.map(f64::to_bits),
                        "case {case} max_edge {max_edge}"
                    );
                }
            }
        }
    }

    /// Five points on a line at 0, 1, 2 (spacing 1), then 10, 12.
    /// Single linkage: (0,1)@1 -> 5, (2,5)@1 -> 6, (3,4)@2 -> 7, (6,7)@8 -> 8.
    fn line() -> Vec<[f32; 3]> {
        [0.0, 1.0, 2.0, 10.0, 12.0]
            .iter()
            .map(|&x| [x, 0.0, 0.0])
            .collect()
    }

    #[test]
    fn linkage_by_hand() {
        let expected = vec![
            [0.0, 1.0, 1.0, 2.0],
            [2.0, 5.0, 1.0, 3.0],
            [3.0, 4.0, 2.0, 2.0],
            [6.0, 7.0, 8.0, 5.0],
        ];
        assert_eq!(linkage(&line(), f64::INFINITY).unwrap(), expected);
        assert_eq!(linkage(&line(), 100.0).unwrap(), expected);
        // Bound 5 drops the last merge: a forest of two trees.
        assert_eq!(linkage(&line(), 5.0).unwrap(), expected[..3].to_vec());
    }

    #[test]
    fn inconsistent_by_hand() {
        let z = linkage(&line(), f64::INFINITY).unwrap();
        let r = inconsistent(&z, 5, 2).unwrap();
        // Links 0 and 2 have no link children: one height, std 0, coefficient 0.
        assert_eq!(r[0], [1.0, 0.0, 1.0, 0.0]);
        assert_eq!(r[2], [2.0, 0.0, 1.0, 0.0]);
        // Link 1 (height 1) over link 0 (height 1): mean 1, std 0.
        assert_eq!(r[1], [1.0, 0.0, 2.0, 0.0]);
        // Root (8) over links 1 (1) and 2 (2): mean 11/3, sample variance
        // ((1-11/3)^2 + (2-11/3)^2 + (8-11/3)^2) / 2 = (64/9 + 25/9 + 169/9) / 2 = 129/9,
        // coefficient (8 - 11/3) / sqrt(129/9) = 13 / sqrt(129).
        assert!((r[3][0] - 11.0 / 3.0).abs() < 1e-12);
        assert!((r[3][1] - (129.0f64 / 9.0).sqrt()).abs() < 1e-12);
        assert_eq!(r[3][2], 3.0);
        let coef = 13.0 / 129f64.sqrt(); // about 1.1446
        assert!((r[3][3] - coef).abs() < 1e-12);

        // Threshold above the root's coefficient: everything one cluster.
        let all = cut_tree(
            &z,
            5,
            TreeCut::Inconsistent {
                threshold: 1.2,
                depth: 2,
            },
        )
        .unwrap();
        assert_eq!(all, vec![0, 0, 0, 0, 0]);
        // Below it: the root splits, every other link (coefficient 0) holds.
        let two = cut_tree(
            &z,
            5,
            TreeCut::Inconsistent {
                threshold: 1.1,
                depth: 2,
            },
        )
        .unwrap();
        assert_eq!(two, vec![0, 0, 0, 1, 1]);
        // Depth 1: every coefficient is 0, so threshold 0 keeps everything merged.
        let d1 = cut_tree(
            &z,
            5,
            TreeCut::Inconsistent {
                threshold: 0.0,
                depth: 1,
            },
        )
        .unwrap();
        assert_eq!(d1, vec![0, 0, 0, 0, 0]);
    }

    #[test]
    fn inconsistent_descendant_rule() {
        // Points 0, 1, 3, 6 on a line: links (0,1)@1 -> 4, (4,2)@2 -> 5, (5,3)@3 -> 6.
        // Link 5: heights {1, 2}: mean 1.5, std sqrt(0.5), coefficient 0.5/sqrt(0.5) = 0.7071.
        // Link 6: heights {2, 3}: same coefficient 0.7071.
        let pts: Vec<[f32; 3]> = [0.0, 1.0, 3.0, 6.0]
            .iter()
            .map(|&x| [x, 0.0, 0.0])
            .collect();
        let z = linkage(&pts, f64::INFINITY).unwrap();
        assert_eq!(z[1][..3], [2.0, 4.0, 2.0]);
        let r = inconsistent(&z, 4, 2).unwrap();
        let c = 0.5 / 0.5f64.sqrt();
        assert!((r[1][3] - c).abs() < 1e-12 && (r[2][3] - c).abs() < 1e-12);
        let at = |t| {
            cut_tree(
                &z,
                4,
                TreeCut::Inconsistent {
                    threshold: t,
                    depth: 2,
                },
            )
            .unwrap()
        };
        assert_eq!(at(0.71), vec![0, 0, 0, 0]);
        // 0.70 < c: links 5 and 6 fail; link 4 (coefficient 0) holds.
        assert_eq!(at(0.70), vec![0, 0, 1, 2]);
    }

    #[test]
    fn maxclust_by_hand() {
        let z = linkage(&line(), f64::INFINITY).unwrap();
        let at = |k| cut_tree(&z, 5, TreeCut::MaxClust { k }).unwrap();
        assert_eq!(at(1), vec![0, 0, 0, 0, 0]);
        assert_eq!(at(2), vec![0, 0, 0, 1, 1]);
        // Heights 1, 1 tie: cutting at 1 gives 3 clusters, so k = 3 and k = 4 both give 3.
        assert_eq!(at(3), vec![0, 0, 0, 1, 2]);
        assert_eq!(at(4), vec![0, 0, 0, 1, 2]);
        assert_eq!(at(5), vec![0, 1, 2, 3, 4]);
        assert_eq!(at(9), vec![0, 1, 2, 3, 4]);
        assert!(cut_tree(&z, 5, TreeCut::MaxClust { k: 0 }).is_err());
        // A forest cannot go below its number of trees.
        let f = linkage(&line(), 5.0).unwrap();
        assert_eq!(
            cut_tree(&f, 5, TreeCut::MaxClust { k: 1 }).unwrap(),
            vec![0, 0, 0, 1, 1]
        );
    }

    #[test]
    fn distance_cut_on_tree_is_inclusive() {
        let z = linkage(&line(), f64::INFINITY).unwrap();
        let at = |t| cut_tree(&z, 5, TreeCut::Distance { t }).unwrap();
        assert_eq!(at(2.0), vec![0, 0, 0, 1, 1]);
        assert_eq!(at(1.999), vec![0, 0, 0, 1, 2]);
        assert_eq!(at(0.5), vec![0, 1, 2, 3, 4]);
    }

    #[test]
    fn invalid_linkage_is_an_error() {
        assert!(cut_tree(&[[0.0, 0.0, 1.0, 2.0]], 2, TreeCut::Distance { t: 1.0 }).is_err());
        assert!(cut_tree(&[[0.0, 5.0, 1.0, 2.0]], 2, TreeCut::Distance { t: 1.0 }).is_err());
        assert!(linkage(&line(), f64::NAN).is_err());
    }

    #[test]
    fn csv_layout() {
        let z = linkage(&line(), f64::INFINITY).unwrap();
        let mut out = Vec::new();
        write_linkage_csv(&mut out, &z).unwrap();
        let text = String::from_utf8(out).unwrap();
        assert_eq!(
            text,
            "cluster_a,cluster_b,distance,count\n0,1,1,2\n2,5,1,3\n3,4,2,2\n6,7,8,5\n"
        );
    }
}
