//! Pure metric functions of the sweep: a noisy frame against its clean baseline.
//!
//! Every function takes plain arrays indexed by the frame's clean returns, so the
//! metrics can be checked on hand-made cases.
//!
//! # Object outcomes ([`object_outcomes`])
//! The *objects* of a frame are, with ground-truth labels, the labelled objects with at
//! least `min_points` returns in the clean frame; without labels, the clean baseline's
//! *object clusters* (clusters passing the `[cluster]` object rule, see
//! [`crate::cluster::ObjectRule`]). For an object `o`:
//! - `C(o)`: its clean returns (every return of the frame that belongs to it);
//! - `R(o)`: its *reaching* returns, those of `C(o)` kept by the noise stages and the
//!   detection filters, i.e. the returns that reach ground removal and clustering;
//! - `G(o)`: the returns of `R(o)` the method labels ground;
//! - for a noisy cluster `n` (any cluster of the noisy frame with at least `min_points`
//!   returns): `|n|` its returns, `O(o, n)` the returns of `o` in `n`, and the purity
//!   `O(o, n) / |n|`.
//!
//! Each object gets exactly one *outcome*, the first that applies, in this order:
//! 1. **detected**: some noisy cluster `n` has `O(o, n) >= 0.5 |R(o)|` and purity
//!    `>= 0.5` (needs `|R(o)| > 0`);
//! 2. **merged into ground**: `|G(o)| > 0.5 |R(o)|`;
//! 3. **merged**: some noisy cluster has `O(o, n) >= 0.5 |R(o)|` but purity `< 0.5`: the
//!    object is the minority of a cluster made mostly of other returns (another object,
//!    ground remnants or clutter);
//! 4. **split**: two or more noisy clusters each hold `O(o, n) >= 0.2 |R(o)|`;
//! 5. **lost**: anything else, including objects none of whose returns reach clustering.
//!
//! So detected + merged into ground + merged + split + lost = objects. Separately,
//! **retained** (a subset of detected) applies the detection test to the clean returns:
//! some noisy cluster has `O(o, n) >= 0.5 |C(o)|` and purity `>= 0.5`, so returns dropped
//! by noise or filters count as lost. Detected measures the method on what reached it;
//! retained measures what the whole chain keeps of the object.
//!
//! # Distance bands ([`band_index`])
//! An object's distance is the horizontal `(x, y)` distance from the sensor to the
//! centroid of its clean returns in the frame. Band edges `e0 < e1 < ... < ek` make the
//! bands `[e0, e1), [e1, e2), ..., [ek, inf)`: lower edge inclusive, upper edge
//! exclusive, the last band open. An object at exactly 5.0 m with edges 0, 5, 10 is in
//! `[5, 10)`; an object closer than `e0` is in no band.
//!
//! # IoU matching rule ([`match_objects`]; object survival)
//! A *partition* gives each clean return a cluster id (`>= 0`) or `-1` (ground, noise, or
//! for the noisy side, dropped). For a reference cluster `c` and a noisy cluster `n`, the
//! overlap `O(c, n)` counts returns in both; sizes `|c|`, `|n|` count all returns with
//! that id. Then:
//! - **IoU** = `O / (|c| + |n| - O)` (point-membership intersection over union).
//! - **matched**: pairs with IoU >= `min_iou` (0.5), taken greedily one-to-one by
//!   descending IoU (ties: smaller reference id, then smaller noisy id).
//! - **survival** = matched reference clusters / reference clusters (`None` when the
//!   reference has no cluster).
//! - a noisy cluster *holds* a reference cluster when `O(c, n) >= min_share * |c|`
//!   (`min_share` = 0.2 of the reference cluster's clean returns, dropped ones included).
//! - **split**: reference clusters held by two or more noisy clusters.
//! - **merged**: noisy clusters holding two or more reference clusters.
//! - **lost**: reference clusters held by no noisy cluster.
//! - **false**: noisy clusters whose returns come less than `min_share` from every
//!   reference cluster (`O(c, n) < min_share * |n|` for all `c`): mostly returns that
//!   were ground, noise or nothing in the reference.
//!
//! Lost and split exclude each other; a split or merged cluster may still be matched
//! when one part has IoU >= 0.5.

use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// Thresholds of the matching rule.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MatchRule {
    /// Smallest IoU of a match.
    pub min_iou: f64,
    /// Share of a cluster's returns that counts as holding it (split, merged, lost, false).
    pub min_share: f64,
}

impl Default for MatchRule {
    fn default() -> Self {
        MatchRule {
            min_iou: 0.5,
            min_share: 0.2,
        }
    }
}

/// Outcome of matching a noisy partition against a reference partition.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ObjectMatch {
    /// Clusters in the reference.
    pub reference: usize,
    /// Clusters in the noisy partition.
    pub noisy: usize,
    /// Matched pairs: reference id, noisy id, IoU; by reference id.
    pub pairs: Vec<(i32, i32, f64)>,
    /// Reference clusters held by two or more noisy clusters.
    pub split: usize,
    /// Noisy clusters holding two or more reference clusters.
    pub merged: usize,
    /// Reference clusters held by no noisy cluster.
    pub lost: usize,
    /// Noisy clusters with less than `min_share` of their returns from any reference cluster.
    pub false_clusters: usize,
}

impl ObjectMatch {
    /// Number of matched reference clusters.
    pub fn matched(&self) -> usize {
        self.pairs.len()
    }

    /// Share of reference clusters matched; `None` without reference clusters.
    pub fn survival(&self) -> Option<f64> {
        (self.reference > 0).then(|| self.pairs.len() as f64 / self.reference as f64)
    }
}

/// Matches `noisy` against `reference` (cluster id per clean return, -1 for none).
///
/// The arrays are read pairwise; entries past the shorter one are ignored.
pub fn match_objects(reference: &[i32], noisy: &[i32], rule: MatchRule) -> ObjectMatch {
    // Ids are small non-negative integers (cluster ids 0..n): dense counts, and per
    // reference cluster the few noisy clusters it overlaps, found by a linear scan.
    let len = |ids: &[i32]| (ids.iter().copied().max().unwrap_or(-1) + 1).max(0) as usize;
    let mut ref_size = vec![0usize; len(reference)];
    let mut noisy_size = vec![0usize; len(noisy)];
    let mut parts: Vec<Vec<(i32, usize)>> = vec![Vec::new(); ref_size.len()];
    for (&c, &n) in reference.iter().zip(noisy) {
        if c >= 0 {
            ref_size[c as usize] += 1;
        }
        if n >= 0 {
            noisy_size[n as usize] += 1;
        }
        if c >= 0 && n >= 0 {
            let p = &mut parts[c as usize];
            match p.iter_mut().find(|x| x.0 == n) {
                Some(x) => x.1 += 1,
                None => p.push((n, 1)),
            }
        }
    }
    let overlap: Vec<(i32, i32, usize)> = parts
        .iter()
        .enumerate()
        .flat_map(|(c, p)| p.iter().map(move |&(n, o)| (c as i32, n, o)))
        .collect();
    let mut candidates: Vec<(f64, i32, i32)> = overlap
        .iter()
        .map(|&(c, n, o)| {
            let union = ref_size[c as usize] + noisy_size[n as usize] - o;
            (o as f64 / union as f64, c, n)
        })
        .filter(|&(iou, _, _)| iou >= rule.min_iou)
        .collect();
    candidates.sort_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)).then(a.2.cmp(&b.2)));
    let mut used_ref = vec![false; ref_size.len()];
    let mut used_noisy = vec![false; noisy_size.len()];
    let mut pairs = Vec::new();
    for (iou, c, n) in candidates {
        if used_ref[c as usize] || used_noisy[n as usize] {
            continue;
        }
        used_ref[c as usize] = true;
        used_noisy[n as usize] = true;
        pairs.push((c, n, iou));
    }
    pairs.sort_by_key(|p| (p.0, p.1));
    // Holding: how many noisy clusters hold each reference cluster and vice versa.
    let mut holders = vec![0usize; ref_size.len()];
    let mut held = vec![0usize; noisy_size.len()];
    let mut sourced = vec![false; noisy_size.len()];
    for &(c, n, o) in &overlap {
        let (c, n) = (c as usize, n as usize);
        if o as f64 >= rule.min_share * ref_size[c] as f64 {
            holders[c] += 1;
            held[n] += 1;
        }
        if o as f64 >= rule.min_share * noisy_size[n] as f64 {
            sourced[n] = true;
        }
    }
    let present = |size: &[usize]| size.iter().filter(|&&s| s > 0).count();
    ObjectMatch {
        reference: present(&ref_size),
        noisy: present(&noisy_size),
        pairs,
        split: holders.iter().filter(|&&h| h >= 2).count(),
        merged: held.iter().filter(|&&h| h >= 2).count(),
        lost: (0..ref_size.len())
            .filter(|&c| ref_size[c] > 0 && holders[c] == 0)
            .count(),
        false_clusters: (0..noisy_size.len())
            .filter(|&n| noisy_size[n] > 0 && !sourced[n])
            .count(),
    }
}

/// Sets clusters with fewer than `min_points` returns to -1 (they are not objects).
pub fn drop_small(labels: &[i32], min_points: usize) -> Vec<i32> {
    let mut size: BTreeMap<i32, usize> = BTreeMap::new();
    for &l in labels.iter().filter(|&&l| l >= 0) {
        *size.entry(l).or_default() += 1;
    }
    labels
        .iter()
        .map(|&l| {
            if l >= 0 && size[&l] >= min_points {
                l
            } else {
                -1
            }
        })
        .collect()
}

/// Statistics of the range change (noisy minus clean) of kept returns, in metres.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct RangeChange {
    /// Mean signed change.
    pub mean: f64,
    /// Root mean square change.
    pub rms: f64,
    /// 95th percentile of the absolute change (nearest rank).
    pub p95_abs: f64,
}

/// Range change of pairs `(clean, noisy)`; zeros when there is none.
pub fn range_change(pairs: impl IntoIterator<Item = (f32, f32)>) -> RangeChange {
    let mut abs = Vec::new();
    let (mut sum, mut sq) = (0.0f64, 0.0f64);
    for (c, n) in pairs {
        let d = f64::from(n) - f64::from(c);
        sum += d;
        sq += d * d;
        abs.push(d.abs());
    }
    if abs.is_empty() {
        return RangeChange::default();
    }
    let len = abs.len() as f64;
    abs.sort_by(f64::total_cmp);
    let rank = ((0.95 * len).ceil() as usize).clamp(1, abs.len());
    RangeChange {
        mean: sum / len,
        rms: (sq / len).sqrt(),
        p95_abs: abs[rank - 1],
    }
}

/// Precision and recall of a binary labelling; `None` where the denominator is zero.
///
/// The slices hold the returns to score: the sweep passes only the returns that reach
/// ground removal, so returns dropped before it are neither hits nor misses.
pub fn precision_recall(truth: &[bool], predicted: &[bool]) -> (Option<f64>, Option<f64>) {
    let (mut tp, mut p, mut t) = (0usize, 0usize, 0usize);
    for (&tr, &pr) in truth.iter().zip(predicted) {
        tp += usize::from(tr && pr);
        p += usize::from(pr);
        t += usize::from(tr);
    }
    let ratio = |a: usize, b: usize| (b > 0).then(|| a as f64 / b as f64);
    (ratio(tp, p), ratio(tp, t))
}

/// Object outcomes of one distance band in one frame.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct BandMetrics {
    /// Lower edge of the band, metres (inclusive).
    pub lo_m: f64,
    /// Upper edge of the band, metres (exclusive); `None` for the open last band.
    pub hi_m: Option<f64>,
    /// Objects (labelled objects, or clean-baseline object clusters without labels) in the band.
    pub objects: u64,
    /// Of those, detected.
    pub detected: u64,
    /// Of those, retained (held against all their clean returns, dropped ones included).
    pub retained: u64,
    /// Of those, split over two or more noisy clusters.
    pub split: u64,
    /// Of those, merged into a cluster another object dominates or shares.
    pub merged: u64,
    /// Of those, mostly called ground by the method.
    pub merged_into_ground: u64,
    /// Of those, lost (not detected, not split, not merged, not merged into ground).
    pub lost: u64,
}

/// Outcome of one object in one frame (exclusive; see the module documentation).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Outcome {
    /// One pure noisy cluster holds at least half of its reaching returns.
    Detected,
    /// More than half of its reaching returns are labelled ground.
    MergedIntoGround,
    /// One noisy cluster holds at least half of its reaching returns but is impure.
    Merged,
    /// Two or more noisy clusters each hold at least 20 % of its reaching returns.
    Split,
    /// None of the above.
    Lost,
}

/// What became of one object in one frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ObjectResult {
    /// Object id (label or baseline cluster id).
    pub id: i32,
    /// The exclusive outcome.
    pub outcome: Outcome,
    /// Detected against its clean returns (dropped returns count as lost).
    pub retained: bool,
    /// Clean returns `|C(o)|`.
    pub clean: usize,
    /// Reaching returns `|R(o)|`.
    pub reached: usize,
    /// Horizontal distance of the centroid of its clean returns from the sensor, metres.
    pub distance_m: f64,
}

/// Share of an object's returns a cluster must hold to detect (or merge) it.
pub const HOLD_SHARE: f64 = 0.5;
/// Smallest purity of a detecting cluster.
pub const MIN_PURITY: f64 = 0.5;
/// Share of an object's reaching returns each part of a split holds.
pub const SPLIT_SHARE: f64 = 0.2;

/// Per clean return of one frame: what the metrics need to know.
#[derive(Clone, Copy, Debug)]
pub struct ReturnState {
    /// Object id (`>= 0`) or -1 (ground, clutter).
    pub object: i32,
    /// Kept by the noise stages and filters.
    pub reached: bool,
    /// Labelled ground by the method (only meaningful when reached).
    pub ground: bool,
    /// Noisy cluster id (`>= 0`, at least `min_points` returns) or -1.
    pub cluster: i32,
    /// Clean horizontal position (x, y), metres.
    pub xy: [f32; 2],
}

/// The outcome of every object with at least `min_points` clean returns, by id.
pub fn object_outcomes(returns: &[ReturnState], min_points: usize) -> Vec<ObjectResult> {
    #[derive(Default)]
    struct Acc {
        clean: usize,
        reached: usize,
        ground: usize,
        sx: f64,
        sy: f64,
        parts: Vec<(i32, usize)>,
    }
    let mut objects: BTreeMap<i32, Acc> = BTreeMap::new();
    let mut cluster_size: Vec<usize> = Vec::new();
    for r in returns {
        if r.cluster >= 0 {
            let c = r.cluster as usize;
            if c >= cluster_size.len() {
                cluster_size.resize(c + 1, 0);
            }
            cluster_size[c] += 1;
        }
        if r.object < 0 {
            continue;
        }
        let a = objects.entry(r.object).or_default();
        a.clean += 1;
        a.sx += f64::from(r.xy[0]);
        a.sy += f64::from(r.xy[1]);
        if r.reached {
            a.reached += 1;
            if r.ground {
                a.ground += 1;
            } else if r.cluster >= 0 {
                match a.parts.iter_mut().find(|p| p.0 == r.cluster) {
                    Some(p) => p.1 += 1,
                    None => a.parts.push((r.cluster, 1)),
                }
            }
        }
    }
    objects
        .into_iter()
        .filter(|(_, a)| a.clean >= min_points.max(1))
        .map(|(id, a)| {
            let pure =
                |&(n, o): &(i32, usize)| o as f64 >= MIN_PURITY * cluster_size[n as usize] as f64;
            let holds = |o: usize, of: usize| of > 0 && o as f64 >= HOLD_SHARE * of as f64;
            let detected = a.parts.iter().any(|p| holds(p.1, a.reached) && pure(p));
            let retained = a.parts.iter().any(|p| holds(p.1, a.clean) && pure(p));
            let outcome = if detected {
                Outcome::Detected
            } else if a.reached > 0 && a.ground as f64 > 0.5 * a.reached as f64 {
                Outcome::MergedIntoGround
            } else if a.parts.iter().any(|p| holds(p.1, a.reached)) {
                Outcome::Merged
            } else if a
                .parts
                .iter()
                .filter(|p| p.1 as f64 >= SPLIT_SHARE * a.reached as f64)
                .count()
                >= 2
            {
                Outcome::Split
            } else {
                Outcome::Lost
            };
            let n = a.clean as f64;
            ObjectResult {
                id,
                outcome,
                retained,
                clean: a.clean,
                reached: a.reached,
                distance_m: (a.sx / n).hypot(a.sy / n),
            }
        })
        .collect()
}

/// The band of a distance: `k` when `edges[k] <= d < edges[k + 1]`, the last band when
/// `d >= edges[last]`, `None` below the first edge (or for a NaN distance).
pub fn band_index(distance_m: f64, edges: &[f64]) -> Option<usize> {
    if edges.is_empty() || distance_m.is_nan() || distance_m < edges[0] {
        return None;
    }
    Some(edges.partition_point(|&e| e <= distance_m) - 1)
}

/// Counts of object outcomes.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Tally {
    /// Objects.
    pub objects: u64,
    /// Detected.
    pub detected: u64,
    /// Retained (a subset of detected).
    pub retained: u64,
    /// Split.
    pub split: u64,
    /// Merged into a cluster of mostly other returns.
    pub merged: u64,
    /// Merged into ground.
    pub merged_into_ground: u64,
    /// Lost.
    pub lost: u64,
}

impl Tally {
    /// Counts one object.
    pub fn add(&mut self, r: &ObjectResult) {
        self.objects += 1;
        self.retained += u64::from(r.retained);
        match r.outcome {
            Outcome::Detected => self.detected += 1,
            Outcome::MergedIntoGround => self.merged_into_ground += 1,
            Outcome::Merged => self.merged += 1,
            Outcome::Split => self.split += 1,
            Outcome::Lost => self.lost += 1,
        }
    }

    /// Counts every object.
    pub fn of<'a>(results: impl IntoIterator<Item = &'a ObjectResult>) -> Tally {
        let mut t = Tally::default();
        for r in results {
            t.add(r);
        }
        t
    }
}

/// The per-band counts of `results` for band `edges` (see [`band_index`]).
pub fn band_metrics(results: &[ObjectResult], edges: &[f64]) -> Vec<BandMetrics> {
    let mut tallies = vec![Tally::default(); edges.len()];
    for r in results {
        if let Some(b) = band_index(r.distance_m, edges) {
            tallies[b].add(r);
        }
    }
    tallies
        .into_iter()
        .enumerate()
        .map(|(k, t)| BandMetrics {
            lo_m: edges[k],
            hi_m: edges.get(k + 1).copied(),
            objects: t.objects,
            detected: t.detected,
            retained: t.retained,
            split: t.split,
            merged: t.merged,
            merged_into_ground: t.merged_into_ground,
            lost: t.lost,
        })
        .collect()
}

/// Object outcomes of one object class in one frame.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ClassMetrics {
    /// Class name (`kind` in the scene's object list).
    pub kind: String,
    /// Outcome counts.
    #[serde(flatten)]
    pub counts: Tally,
}

/// Default distance band edges, metres.
pub const DEFAULT_BANDS: [f64; 5] = [0.0, 5.0, 10.0, 20.0, 40.0];

/// Per-frame metrics of one sweep cell (one row of the tidy table).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct FrameMetrics {
    /// Frame index in the capture.
    pub frame: u32,
    /// Returns recorded in the frame.
    pub returns: u64,
    /// Returns kept after noise and filters.
    pub kept: u64,
    /// Returns kept in the clean baseline.
    pub baseline_kept: u64,
    /// Returns removed by occlusion.
    pub occluded: u64,
    /// Returns under the power threshold.
    pub below_power: u64,
    /// Returns under the minimum range.
    pub below_min_range: u64,
    /// Mean range change of kept returns, metres.
    pub range_change_mean_m: f64,
    /// RMS range change of kept returns, metres.
    pub range_change_rms_m: f64,
    /// 95th percentile of the absolute range change, metres.
    pub range_change_p95_m: f64,
    /// Clusters (at least `min_points` returns) found.
    pub clusters: u64,
    /// Of those, object clusters (passing the object rule).
    pub object_clusters: u64,
    /// Clusters of the clean baseline.
    pub baseline_clusters: u64,
    /// Object clusters of the clean baseline.
    pub baseline_object_clusters: u64,
    /// Baseline object clusters matched by a noisy cluster (IoU >= 0.5).
    pub matched: u64,
    /// Share of baseline object clusters matched (IoU rule).
    pub object_survival: Option<f64>,
    /// Noisy object clusters less than 20 % of whose returns come from any baseline cluster.
    pub false_clusters: u64,
    /// Ground-plane distance of the farthest matched baseline object cluster, metres.
    pub farthest_matched_m: Option<f64>,
    /// Same for the farthest baseline object cluster.
    pub baseline_farthest_m: Option<f64>,
    /// True when the objects are the capture's labelled objects (else baseline object clusters).
    pub labelled: bool,
    /// Objects of the frame (labelled objects, or clean-baseline object clusters).
    pub objects: u64,
    /// Of those, detected.
    pub detected: u64,
    /// Of those, retained (a subset of detected).
    pub retained: u64,
    /// Of those, split.
    pub split: u64,
    /// Of those, merged into a cluster of mostly other returns.
    pub merged: u64,
    /// Of those, merged into ground.
    pub merged_into_ground: u64,
    /// Of those, lost.
    pub lost: u64,
    /// Ground precision against the labels, over the returns that reach ground removal.
    pub ground_precision: Option<f64>,
    /// Ground recall against the labels, over the returns that reach ground removal.
    pub ground_recall: Option<f64>,
    /// Share of the labelled ground returns dropped before ground removal.
    pub ground_lost_before_share: Option<f64>,
    /// Object outcomes per distance band, in band order (the same in every row).
    pub bands: Vec<BandMetrics>,
    /// Object outcomes per object class (labelled captures naming classes), by name.
    pub classes: Vec<ClassMetrics>,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn range_change_of_known_pairs() {
        let r = range_change([(1.0, 1.5), (2.0, 1.5), (3.0, 3.0), (4.0, 4.0)]);
        assert_eq!(r.mean, 0.0);
        assert!((r.rms - (0.5f64 / 4.0).sqrt()).abs() < 1e-12);
        assert_eq!(r.p95_abs, 0.5);
    }
}
