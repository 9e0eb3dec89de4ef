//! Pure metric functions of the sweep: a noisy frame against its clean baseline.
//!
//! Every function takes plain arrays indexed by the frame's clean returns, so the
//! metrics can be checked on hand-made cases.
//!
//! # Object matching rule
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
    let mut ref_size: BTreeMap<i32, usize> = BTreeMap::new();
    let mut noisy_size: BTreeMap<i32, usize> = BTreeMap::new();
    let mut overlap: BTreeMap<(i32, i32), usize> = BTreeMap::new();
    for (&c, &n) in reference.iter().zip(noisy) {
        if c >= 0 {
            *ref_size.entry(c).or_default() += 1;
        }
        if n >= 0 {
            *noisy_size.entry(n).or_default() += 1;
        }
        if c >= 0 && n >= 0 {
            *overlap.entry((c, n)).or_default() += 1;
        }
    }
    let mut candidates: Vec<(f64, i32, i32)> = overlap
        .iter()
        .map(|(&(c, n), &o)| {
            let union = ref_size[&c] + noisy_size[&n] - o;
            (o as f64 / union as f64, c, n)
        })
        .filter(|&(iou, _, _)| iou >= rule.min_iou)
        .collect();
    candidates.sort_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)).then(a.2.cmp(&b.2)));
    let mut used_ref = std::collections::BTreeSet::new();
    let mut used_noisy = std::collections::BTreeSet::new();
    let mut pairs = Vec::new();
    for (iou, c, n) in candidates {
        if used_ref.contains(&c) || used_noisy.contains(&n) {
            continue;
        }
        used_ref.insert(c);
        used_noisy.insert(n);
        pairs.push((c, n, iou));
    }
    pairs.sort_by_key(|p| (p.0, p.1));
    // Holding: how many noisy clusters hold each reference cluster and vice versa.
    let mut holders: BTreeMap<i32, usize> = BTreeMap::new();
    let mut held: BTreeMap<i32, usize> = BTreeMap::new();
    let mut sourced: BTreeMap<i32, bool> = BTreeMap::new();
    for (&(c, n), &o) in &overlap {
        if o as f64 >= rule.min_share * ref_size[&c] as f64 {
            *holders.entry(c).or_default() += 1;
            *held.entry(n).or_default() += 1;
        }
        if o as f64 >= rule.min_share * noisy_size[&n] as f64 {
            sourced.insert(n, true);
        }
    }
    let split = holders.values().filter(|&&h| h >= 2).count();
    let lost = ref_size.keys().filter(|c| !holders.contains_key(c)).count();
    let merged = held.values().filter(|&&h| h >= 2).count();
    let false_clusters = noisy_size
        .keys()
        .filter(|n| !sourced.contains_key(n))
        .count();
    ObjectMatch {
        reference: ref_size.len(),
        noisy: noisy_size.len(),
        pairs,
        split,
        merged,
        lost,
        false_clusters,
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
/// `predicted[i]` is true when return `i` was kept and called positive; `truth[i]` is the
/// ground truth of every clean return, so dropped positives count as missed.
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

/// Object detection precision and recall against ground-truth objects.
///
/// `truth` holds the object id per clean return (-1 for ground); objects with fewer than
/// `min_points` returns in the frame are ignored. Recall = truth objects matched / truth
/// objects; precision = noisy clusters matched / noisy clusters.
pub fn detection_scores(
    truth: &[i32],
    noisy: &[i32],
    min_points: usize,
    rule: MatchRule,
) -> (Option<f64>, Option<f64>) {
    let truth = drop_small(truth, min_points);
    let m = match_objects(&truth, noisy, rule);
    let precision = (m.noisy > 0).then(|| m.matched() as f64 / m.noisy as f64);
    (precision, m.survival())
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
    /// Clusters (objects) found.
    pub clusters: u64,
    /// Clusters of the clean baseline.
    pub baseline_clusters: u64,
    /// Baseline clusters matched (IoU >= 0.5).
    pub matched: u64,
    /// Share of baseline clusters matched.
    pub object_survival: Option<f64>,
    /// Baseline clusters split.
    pub split: u64,
    /// Noisy clusters merging baseline clusters.
    pub merged: u64,
    /// Baseline clusters lost.
    pub lost: u64,
    /// Noisy clusters matching nothing of the baseline.
    pub false_clusters: u64,
    /// Ground-plane distance of the farthest matched baseline cluster's centroid, metres.
    pub farthest_matched_m: Option<f64>,
    /// Same for the farthest baseline cluster.
    pub baseline_farthest_m: Option<f64>,
    /// Ground precision against the capture's labels.
    pub ground_precision: Option<f64>,
    /// Ground recall against the capture's labels.
    pub ground_recall: Option<f64>,
    /// Object detection precision against the capture's labels.
    pub object_precision: Option<f64>,
    /// Object detection recall against the capture's labels.
    pub object_recall: Option<f64>,
    /// Objects of the frame (labelled objects, or clean-baseline object clusters).
    #[serde(default)]
    pub objects: u64,
    /// Of those, detected.
    #[serde(default)]
    pub detected: u64,
    /// Object outcomes per distance band, in band order (the same in every row).
    #[serde(default)]
    pub bands: Vec<BandMetrics>,
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
