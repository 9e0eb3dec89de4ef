//! Object matching metrics on hand-made partitions (cluster id per clean return).

use lidar_noise::sweep::metrics::{detection_scores, match_objects, precision_recall, MatchRule};

fn rule() -> MatchRule {
    MatchRule::default()
}

/// Ten returns per cluster id, in order.
fn blocks(ids: &[i32]) -> Vec<i32> {
    ids.iter()
        .flat_map(|&i| std::iter::repeat_n(i, 10))
        .collect()
}

#[test]
fn survival_is_one_against_itself() {
    let p = blocks(&[0, 1, -1, 2, 3]);
    let m = match_objects(&p, &p, rule());
    assert_eq!(m.survival(), Some(1.0));
    assert_eq!((m.split, m.merged, m.lost, m.false_clusters), (0, 0, 0, 0));
    assert_eq!(m.matched(), 4);
}

#[test]
fn relabelled_clusters_still_match() {
    let clean = blocks(&[0, 1]);
    let noisy = blocks(&[7, 3]);
    let m = match_objects(&clean, &noisy, rule());
    assert_eq!(
        m.pairs.iter().map(|p| (p.0, p.1)).collect::<Vec<_>>(),
        vec![(0, 7), (1, 3)]
    );
}

#[test]
fn a_split_is_counted() {
    // Clean cluster 0 (20 returns) becomes noisy 5 (first half) and 6 (second half).
    let clean = blocks(&[0, 0, 1]);
    let noisy = blocks(&[5, 6, 1]);
    let m = match_objects(&clean, &noisy, rule());
    assert_eq!(m.split, 1);
    assert_eq!(m.merged, 0);
    assert_eq!(m.lost, 0);
    assert_eq!(m.false_clusters, 0);
    // Each half has IoU 0.5 with the clean cluster: one of them matches.
    assert_eq!(m.matched(), 2);
}

#[test]
fn an_uneven_split_below_the_share_is_not_a_split() {
    // 90 % + 10 %: the small part holds less than 20 %.
    let clean = vec![0; 20];
    let mut noisy = vec![4; 18];
    noisy.extend([9, 9]);
    let m = match_objects(&clean, &noisy, rule());
    assert_eq!(m.split, 0);
    assert_eq!(m.matched(), 1);
    // The 2-return noisy cluster comes wholly from cluster 0: not false.
    assert_eq!(m.false_clusters, 0);
}

#[test]
fn a_merge_is_counted_and_unmatched() {
    let clean = blocks(&[0, 1, 2, 2]);
    let noisy = blocks(&[8, 8, 2, 2]);
    let m = match_objects(&clean, &noisy, rule());
    assert_eq!(m.merged, 1);
    assert_eq!(m.split, 0);
    assert_eq!(m.lost, 0);
    // Noisy 8 has IoU 0.5 with each of 0 and 1; only one of them can match.
    assert_eq!(m.matched(), 2);
    assert_eq!(m.survival(), Some(2.0 / 3.0));
}

#[test]
fn a_lost_object_is_counted() {
    // Cluster 1 is dropped or becomes noise entirely.
    let clean = blocks(&[0, 1]);
    let noisy = blocks(&[0, -1]);
    let m = match_objects(&clean, &noisy, rule());
    assert_eq!(m.lost, 1);
    assert_eq!(m.matched(), 1);
    assert_eq!(m.survival(), Some(0.5));
    assert_eq!(m.false_clusters, 0);
}

#[test]
fn a_false_cluster_is_counted() {
    // Returns that were ground (-1) in the clean frame form a noisy cluster.
    let clean = blocks(&[0, -1, -1]);
    let noisy = blocks(&[0, 3, 3]);
    let m = match_objects(&clean, &noisy, rule());
    assert_eq!(m.false_clusters, 1);
    assert_eq!(m.matched(), 1);
    assert_eq!(m.survival(), Some(1.0));
    assert_eq!((m.split, m.merged, m.lost), (0, 0, 0));
}

#[test]
fn shrunken_object_fails_iou_but_is_not_lost() {
    // Occlusion keeps 30 % of a cluster: IoU 0.3, held (>= 20 %), not lost.
    let clean = vec![0; 10];
    let mut noisy = vec![-1; 7];
    noisy.extend([2, 2, 2]);
    let m = match_objects(&clean, &noisy, rule());
    assert_eq!(m.matched(), 0);
    assert_eq!(m.lost, 0);
    assert_eq!(m.survival(), Some(0.0));
}

#[test]
fn no_reference_clusters_gives_no_survival() {
    let m = match_objects(&[-1, -1], &[0, 0], rule());
    assert_eq!(m.survival(), None);
    assert_eq!(m.false_clusters, 1);
}

#[test]
fn precision_and_recall_count_dropped_truth_as_missed() {
    let truth = [true, true, true, false];
    let predicted = [true, true, false, true];
    let (p, r) = precision_recall(&truth, &predicted);
    assert_eq!(p, Some(2.0 / 3.0));
    assert_eq!(r, Some(2.0 / 3.0));
    assert_eq!(precision_recall(&[false], &[false]), (None, None));
}

#[test]
fn detection_ignores_objects_smaller_than_min_points() {
    // Truth objects 1 (10 returns) and 2 (3 returns); min_points 5.
    let mut truth = vec![1; 10];
    truth.extend([2, 2, 2]);
    let mut noisy = vec![0; 10];
    noisy.extend([-1, -1, -1]);
    let (p, r) = detection_scores(&truth, &noisy, 5, rule());
    assert_eq!(p, Some(1.0));
    assert_eq!(r, Some(1.0));
}
