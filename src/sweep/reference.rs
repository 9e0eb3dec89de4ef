//! A frame's metrics in a sweep: its clean baseline reduced to what the metrics need,
//! and a cell's result on the frame scored against it (and against ground truth).

use super::labels::Truth;
use crate::pipeline::FrameResult;
use crate::score::metrics::{self, ClassMetrics, FrameMetrics, MatchRule, ReturnState, Tally};
use std::collections::BTreeMap;

/// The baseline of one frame, reduced to what the metrics need.
pub(super) struct Reference {
    /// Cluster id per clean return (-1 for none).
    labels: Vec<i32>,
    /// Object cluster id per clean return (-1 for none and for non-object clusters).
    objects: Vec<i32>,
    kept: u64,
    clusters: u64,
    object_clusters: u64,
    /// Horizontal centroid distance of each object cluster.
    distance: BTreeMap<i32, f64>,
}

/// Cluster id of every clean return (-1 when dropped, ground or noise).
/// Cluster id per recorded return (-1: none). A spurious echo (replaced or added) is no
/// recorded return: it gets no label, so it never counts for an object.
fn labels_per_clean(r: &FrameResult) -> Vec<i32> {
    let mut out = vec![-1; r.noisy.clean_len];
    for (&k, &l) in r.kept.iter().zip(&r.labels) {
        if r.noisy.fate[k as usize] == crate::noise::Fate::Kept {
            out[k as usize] = l;
        }
    }
    out
}

/// Object clusters made of spurious echoes only: false clusters no recorded return shows.
fn spurious_object_clusters(r: &FrameResult) -> u64 {
    let mut real = std::collections::BTreeSet::new();
    let mut any = std::collections::BTreeSet::new();
    for (&k, &l) in r.kept.iter().zip(&r.labels) {
        if l >= 0 {
            any.insert(l);
            if r.noisy.fate[k as usize] == crate::noise::Fate::Kept {
                real.insert(l);
            }
        }
    }
    r.clusters
        .iter()
        .filter(|c| c.object && any.contains(&c.id) && !real.contains(&c.id))
        .count() as u64
}

/// `labels` (cluster id per clean return) with every cluster that is not an object set
/// to -1.
fn object_labels(r: &FrameResult, labels: &[i32]) -> Vec<i32> {
    // Cluster ids are 0..n in id order, so a dense lookup is enough.
    let len = r
        .clusters
        .iter()
        .map(|c| c.id + 1)
        .max()
        .unwrap_or(0)
        .max(0) as usize;
    let mut object = vec![false; len];
    for c in r.clusters.iter().filter(|c| c.object && c.id >= 0) {
        object[c.id as usize] = true;
    }
    labels
        .iter()
        .map(|&l| {
            if l >= 0 && object.get(l as usize).copied().unwrap_or(false) {
                l
            } else {
                -1
            }
        })
        .collect()
}

pub(super) fn reference_of(r: &FrameResult) -> Reference {
    let labels = labels_per_clean(r);
    let objects = object_labels(r, &labels);
    Reference {
        labels,
        objects,
        kept: r.counts.kept,
        clusters: r.clusters.len() as u64,
        object_clusters: r.counts.objects,
        distance: r
            .clusters
            .iter()
            .filter(|c| c.object)
            .map(|c| (c.id, c.centroid[0].hypot(c.centroid[1])))
            .collect(),
    }
}

pub(super) fn frame_metrics(
    r: &FrameResult,
    reference: &Reference,
    truth: Option<&Truth>,
    classes: &BTreeMap<i32, String>,
    min_points: usize,
    bands: &[f64],
) -> FrameMetrics {
    use crate::noise::Fate;
    let count = |f: Fate| r.noisy.fate.iter().filter(|&&x| x == f).count() as u64;
    let change = metrics::range_change(
        r.kept
            .iter()
            .filter(|&&k| r.noisy.fate[k as usize] == Fate::Kept)
            .map(|&k| (r.noisy.clean[k as usize].range, r.noisy.range[k as usize])),
    );
    let noisy = labels_per_clean(r);
    let rule = MatchRule::default();
    // IoU survival of the baseline's object clusters.
    let m = metrics::match_objects(&reference.objects, &noisy, rule);
    // Clutter: noisy object clusters that come from no baseline cluster at all.
    let noisy_objects = object_labels(r, &noisy);
    let clutter = metrics::match_objects(&reference.labels, &noisy_objects, rule);
    let farthest = |ids: &mut dyn Iterator<Item = i32>| {
        ids.filter_map(|id| reference.distance.get(&id).copied())
            .max_by(f64::total_cmp)
    };
    // Per clean return: reached, method ground, noisy cluster, clean position.
    let mut states: Vec<ReturnState> = r
        .noisy
        .clean
        .iter()
        .zip(&noisy)
        .map(|(c, &n)| ReturnState {
            object: -1,
            reached: false,
            ground: false,
            cluster: n,
            xy: [c.x, c.y],
        })
        .collect();
    for (&k, &g) in r.kept.iter().zip(&r.ground) {
        // Only recorded returns the sensor still reports reach an object; echoes do not.
        if r.noisy.fate[k as usize] == Fate::Kept {
            states[k as usize].reached = true;
            states[k as usize].ground = g;
        }
    }
    let object_ids = truth.map_or(&reference.objects, |t| &t.objects);
    for (s, &o) in states.iter_mut().zip(object_ids) {
        s.object = o;
    }
    let results = metrics::object_outcomes(&states, min_points);
    let whole = Tally::of(&results);
    let mut out = FrameMetrics {
        frame: r.noisy.index,
        returns: r.noisy.len() as u64,
        kept: r.counts.kept,
        baseline_kept: reference.kept,
        occluded: count(Fate::Occluded),
        below_power: count(Fate::BelowPower),
        below_min_range: count(Fate::BelowMinRange),
        range_change_mean_m: change.mean,
        range_change_rms_m: change.rms,
        range_change_p95_m: change.p95_abs,
        clusters: r.clusters.len() as u64,
        object_clusters: r.counts.objects,
        baseline_clusters: reference.clusters,
        baseline_object_clusters: reference.object_clusters,
        matched: m.matched() as u64,
        object_survival: m.survival(),
        false_clusters: clutter.false_clusters as u64 + spurious_object_clusters(r),
        farthest_matched_m: farthest(&mut m.pairs.iter().map(|p| p.0)),
        baseline_farthest_m: farthest(&mut reference.distance.keys().copied()),
        labelled: truth.is_some(),
        objects: whole.objects,
        detected: whole.detected,
        retained: whole.retained,
        split: whole.split,
        merged: whole.merged,
        merged_into_ground: whole.merged_into_ground,
        lost: whole.lost,
        bands: metrics::band_metrics(&results, bands),
        ..FrameMetrics::default()
    };
    if let Some(t) = truth {
        // Ground precision and recall over the returns that reach ground removal; the
        // ground returns dropped before it are reported on their own.
        // A spurious echo is never ground in truth (it is no recorded return).
        let truth_reached: Vec<bool> = r
            .kept
            .iter()
            .map(|&k| r.noisy.fate[k as usize] == Fate::Kept && t.ground[k as usize])
            .collect();
        (out.ground_precision, out.ground_recall) =
            metrics::precision_recall(&truth_reached, &r.ground);
        let ground_total = t.ground.iter().filter(|&&g| g).count();
        let ground_reached = truth_reached.iter().filter(|&&g| g).count();
        out.ground_lost_before_share = (ground_total > 0)
            .then(|| (ground_total - ground_reached) as f64 / ground_total as f64);
        let mut by_class: BTreeMap<&str, Tally> = BTreeMap::new();
        for o in &results {
            if let Some(kind) = classes.get(&o.id) {
                by_class.entry(kind).or_default().add(o);
            }
        }
        out.classes = by_class
            .into_iter()
            .map(|(kind, counts)| ClassMetrics {
                kind: kind.to_string(),
                counts,
            })
            .collect();
    }
    out
}
