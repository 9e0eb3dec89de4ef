//! The minimum spanning forest of a point cloud's edges up to a length bound, in memory
//! linear in the points (Boruvka's algorithm over a k-d tree).
//!
//! The merge tree (`linkage`) used to collect every pair of points within `max_edge_m`
//! and sort them (Kruskal): on a dense frame that is hundreds of millions of pairs, 0.3
//! to 2 GB per frame and thread. Single linkage only needs the forest's edges. Boruvka
//! finds them in O(log n) rounds: in each, every component takes its lightest edge to
//! another component, found by nearest-neighbour searches that skip k-d tree nodes whose
//! points all belong to the searching point's component. Edges are ordered by (length,
//! smaller index, larger index), a strict total order, so the forest is unique and is
//! exactly the one Kruskal's sort by the same key gives (tested against it).
//!
//! Written by hand: kiddo's searches cannot skip a subtree by a per-round label (the
//! component), which is what keeps the later rounds fast, and its within-radius search
//! is what made the edge list large.

use super::point_distance;

/// Points per leaf of the tree.
const LEAF: usize = 16;
const NONE: u32 = u32::MAX;

/// A node: its points are `perm[start..end]`, its box `lo..=hi`, its children `left`
/// and `right` (`NONE` for a leaf).
#[derive(Clone, Copy)]
struct Node {
    lo: [f32; 3],
    hi: [f32; 3],
    start: u32,
    end: u32,
    left: u32,
    right: u32,
}

struct Tree {
    nodes: Vec<Node>,
    perm: Vec<u32>,
}

impl Tree {
    fn new(points: &[[f32; 3]]) -> Tree {
        let mut t = Tree {
            nodes: Vec::with_capacity(2 * points.len() / LEAF + 2),
            perm: (0..points.len() as u32).collect(),
        };
        t.build(points, 0, points.len());
        t
    }

    /// Builds the node over `perm[start..end]`, split at the median of its widest axis;
    /// returns its index.
    fn build(&mut self, points: &[[f32; 3]], start: usize, end: usize) -> u32 {
        let (mut lo, mut hi) = ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
        for &i in &self.perm[start..end] {
            for a in 0..3 {
                lo[a] = lo[a].min(points[i as usize][a]);
                hi[a] = hi[a].max(points[i as usize][a]);
            }
        }
        let me = self.nodes.len() as u32;
        self.nodes.push(Node {
            lo,
            hi,
            start: start as u32,
            end: end as u32,
            left: NONE,
            right: NONE,
        });
        if end - start > LEAF {
            let axis = (0..3)
                .max_by(|&a, &b| (hi[a] - lo[a]).total_cmp(&(hi[b] - lo[b])))
                .unwrap_or(0);
            let mid = (start + end) / 2;
            self.perm[start..end].select_nth_unstable_by(mid - start, |&i, &j| {
                points[i as usize][axis].total_cmp(&points[j as usize][axis])
            });
            let left = self.build(points, start, mid);
            let right = self.build(points, mid, end);
            self.nodes[me as usize].left = left;
            self.nodes[me as usize].right = right;
        }
        me
    }
}

/// Lower bound of `point_distance(p, q)` for any q in the box: the same operations on
/// each axis's smallest possible difference (exact in f64 for f32 inputs), and rounding
/// is monotone, so no point of the box can be nearer.
fn box_distance(p: &[f32; 3], lo: &[f32; 3], hi: &[f32; 3]) -> f64 {
    let gap = |a: usize| {
        let (x, l, h) = (f64::from(p[a]), f64::from(lo[a]), f64::from(hi[a]));
        if x < l {
            l - x
        } else if x > h {
            x - h
        } else {
            0.0
        }
    };
    let (dx, dy, dz) = (gap(0), gap(1), gap(2));
    (dx * dx + dy * dy + dz * dz).sqrt()
}

/// An edge: (length, smaller index, larger index), ordered by that tuple.
type Edge = (f64, u32, u32);

fn less(a: &Edge, b: &Edge) -> bool {
    a.0.total_cmp(&b.0)
        .then(a.1.cmp(&b.1))
        .then(a.2.cmp(&b.2))
        .is_lt()
}

/// The forest's edges (length, smaller index, larger index) of `points` (all finite),
/// every edge at most `max_edge_m` long, sorted by that key; indices are `id(i)`, an
/// increasing map of the point's position (its index in the caller's full input).
pub(crate) fn forest(points: &[[f32; 3]], max_edge_m: f64, id: impl Fn(usize) -> u32) -> Vec<Edge> {
    let n = points.len();
    let tree = Tree::new(points);
    let ids: Vec<u32> = (0..n).map(&id).collect();
    let mut uf = super::UnionFind::new(n);
    let mut comp: Vec<u32> = (0..n as u32).collect();
    // Per node: the component of all its points, or NONE when they differ.
    let mut node_comp = vec![NONE; tree.nodes.len()];
    // A component that found no edge is final (nothing lies within reach of it, so no
    // other component reaches it either).
    let mut done = vec![false; n];
    let mut edges: Vec<Edge> = Vec::with_capacity(n.saturating_sub(1));
    let mut best: Vec<Option<Edge>> = vec![None; n];
    let mut stack: Vec<u32> = Vec::with_capacity(64);
    loop {
        for (i, c) in comp.iter_mut().enumerate() {
            *c = uf.find(i as u32);
        }
        // Children come after their parent, so a reverse walk sees them first.
        for k in (0..tree.nodes.len()).rev() {
            let nd = tree.nodes[k];
            node_comp[k] = if nd.left == NONE {
                let first = comp[tree.perm[nd.start as usize] as usize];
                let same = tree.perm[nd.start as usize..nd.end as usize]
                    .iter()
                    .all(|&i| comp[i as usize] == first);
                if same {
                    first
                } else {
                    NONE
                }
            } else {
                let (l, r) = (node_comp[nd.left as usize], node_comp[nd.right as usize]);
                if l == r {
                    l
                } else {
                    NONE
                }
            };
        }
        best.iter_mut().for_each(|b| *b = None);
        for i in 0..n {
            let ci = comp[i];
            if done[ci as usize] {
                continue;
            }
            let p = &points[i];
            // Only edges lighter than the component's best so far can matter.
            let mut bound = best[ci as usize].map_or(max_edge_m, |e| e.0.min(max_edge_m));
            let mut found: Option<Edge> = best[ci as usize];
            stack.clear();
            stack.push(0);
            while let Some(k) = stack.pop() {
                let nd = &tree.nodes[k as usize];
                if node_comp[k as usize] == ci || box_distance(p, &nd.lo, &nd.hi) > bound {
                    continue;
                }
                if nd.left == NONE {
                    for &j in &tree.perm[nd.start as usize..nd.end as usize] {
                        let j = j as usize;
                        if comp[j] == ci {
                            continue;
                        }
                        let d = point_distance(p, &points[j]);
                        if d > bound {
                            continue;
                        }
                        let (a, b) = (ids[i].min(ids[j]), ids[i].max(ids[j]));
                        let e = (d, a, b);
                        if found.is_none_or(|f| less(&e, &f)) {
                            found = Some(e);
                            bound = d;
                        }
                    }
                } else {
                    // The nearer child last, so it is searched first.
                    let (l, r) = (
                        &tree.nodes[nd.left as usize],
                        &tree.nodes[nd.right as usize],
                    );
                    let (dl, dr) = (box_distance(p, &l.lo, &l.hi), box_distance(p, &r.lo, &r.hi));
                    if dl <= dr {
                        stack.push(nd.right);
                        stack.push(nd.left);
                    } else {
                        stack.push(nd.left);
                        stack.push(nd.right);
                    }
                }
            }
            best[ci as usize] = found;
        }
        // Point indices of each edge, to merge: ids are increasing, so a binary search.
        let mut merged = false;
        for c in 0..n {
            if comp[c] != c as u32 || done[c] {
                continue;
            }
            match best[c] {
                None => done[c] = true,
                Some(e) => {
                    let (a, b) = (
                        ids.partition_point(|&x| x < e.1),
                        ids.partition_point(|&x| x < e.2),
                    );
                    // Two components may pick the same edge: it joins them once.
                    if uf.union(a as u32, b as u32) {
                        edges.push(e);
                        merged = true;
                    }
                }
            }
        }
        if !merged {
            break;
        }
    }
    edges.sort_unstable_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)).then(a.2.cmp(&b.2)));
    edges
}
