//! Object matching metrics on hand-made partitions (cluster id per clean return).

use crate::common::fixture;
use lidar_noise::score::metrics::{
    band_index, band_metrics, match_objects, object_outcomes, precision_recall, MatchRule,
    ObjectResult, Outcome, ReturnState, Tally,
};
use lidar_noise::sweep::run::Row;
use lidar_noise::sweep::tables::{self, aggregate, interval, metrics, per_seed, t_quantile};

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
fn precision_and_recall_of_a_labelling() {
    let truth = [true, true, true, false];
    let predicted = [true, true, false, true];
    let (p, r) = precision_recall(&truth, &predicted);
    assert_eq!(p, Some(2.0 / 3.0));
    assert_eq!(r, Some(2.0 / 3.0));
    assert_eq!(precision_recall(&[false], &[false]), (None, None));
}

/// `n` returns of `object`, reaching, not ground, in noisy cluster `cluster`, at (x, 0).
fn ret(n: usize, object: i32, cluster: i32, x: f32) -> Vec<ReturnState> {
    vec![
        ReturnState {
            object,
            reached: true,
            ground: false,
            cluster,
            xy: [x, 0.0],
        };
        n
    ]
}

/// `n` returns of `object` dropped before ground removal.
fn dropped(n: usize, object: i32, x: f32) -> Vec<ReturnState> {
    let mut v = ret(n, object, -1, x);
    for r in &mut v {
        r.reached = false;
    }
    v
}

/// `n` returns of `object` the method labels ground.
fn grounded(n: usize, object: i32, x: f32) -> Vec<ReturnState> {
    let mut v = ret(n, object, -1, x);
    for r in &mut v {
        r.ground = true;
    }
    v
}

fn outcomes(parts: Vec<Vec<ReturnState>>) -> Vec<ObjectResult> {
    object_outcomes(&parts.concat(), 5)
}

fn one(parts: Vec<Vec<ReturnState>>) -> ObjectResult {
    let r = outcomes(parts);
    assert_eq!(r.len(), 1, "{r:?}");
    r[0]
}

#[test]
fn a_whole_pure_cluster_is_detected_and_retained() {
    let r = one(vec![ret(20, 1, 0, 3.0)]);
    assert_eq!(
        (r.outcome, r.retained, r.clean, r.reached),
        (Outcome::Detected, true, 20, 20)
    );
    assert!((r.distance_m - 3.0).abs() < 1e-9);
}

#[test]
fn purity_just_above_and_below_one_half() {
    // Object 1 (10 returns) in cluster 0 with 9 clutter returns: purity 10/19 > 0.5.
    let r = outcomes(vec![ret(10, 1, 0, 3.0), ret(9, -1, 0, 3.0)]);
    assert_eq!(r[0].outcome, Outcome::Detected);
    // With 11 clutter returns: purity 10/21 < 0.5, held but impure: merged.
    let r = outcomes(vec![ret(10, 1, 0, 3.0), ret(11, -1, 0, 3.0)]);
    assert_eq!(r[0].outcome, Outcome::Merged);
    assert!(!r[0].retained);
    // Exactly 0.5 counts as pure.
    let r = outcomes(vec![ret(10, 1, 0, 3.0), ret(10, -1, 0, 3.0)]);
    assert_eq!(r[0].outcome, Outcome::Detected);
}

#[test]
fn merged_into_another_object() {
    // Objects 1 (10 returns) and 2 (30 returns) share noisy cluster 0: object 2 is the
    // majority (30/40) and detected; object 1 (10/40) is merged.
    let r = outcomes(vec![ret(10, 1, 0, 3.0), ret(30, 2, 0, 4.0)]);
    assert_eq!(r[0].id, 1);
    assert_eq!(r[0].outcome, Outcome::Merged);
    assert_eq!(r[1].outcome, Outcome::Detected);
    let t = Tally::of(&r);
    assert_eq!((t.objects, t.detected, t.merged, t.lost), (2, 1, 1, 0));
}

#[test]
fn merged_into_ground() {
    // 12 of 20 reaching returns labelled ground, 8 in a pure cluster: not detected (8 < 10).
    let r = one(vec![grounded(12, 1, 5.0), ret(8, 1, 0, 5.0)]);
    assert_eq!(r.outcome, Outcome::MergedIntoGround);
    // Exactly half ground is not "most": 10 ground, 10 clustered -> detected.
    let r = one(vec![grounded(10, 1, 5.0), ret(10, 1, 0, 5.0)]);
    assert_eq!(r.outcome, Outcome::Detected);
}

#[test]
fn an_even_two_way_split_is_still_detected() {
    // Each half holds exactly 50 % of the reaching returns, purely: detected.
    let r = one(vec![ret(10, 1, 0, 5.0), ret(10, 1, 1, 5.0)]);
    assert_eq!(r.outcome, Outcome::Detected);
}

#[test]
fn split_over_two_clusters() {
    // 40 % + 40 % + 20 % unclustered: no cluster holds half, two hold >= 20 %.
    let r = one(vec![
        ret(8, 1, 0, 5.0),
        ret(8, 1, 1, 5.0),
        ret(4, 1, -1, 5.0),
    ]);
    assert_eq!(r.outcome, Outcome::Split);
    // 45 % + 15 % + 40 % unclustered: only one part holds >= 20 %: lost.
    let r = one(vec![
        ret(9, 1, 0, 5.0),
        ret(3, 1, 1, 5.0),
        ret(8, 1, -1, 5.0),
    ]);
    assert_eq!(r.outcome, Outcome::Lost);
}

#[test]
fn dropped_returns_are_not_retained_but_may_be_detected() {
    // 20 clean returns, 12 dropped by noise, 8 reach and form a pure cluster:
    // detected (8 >= 0.5 * 8) but not retained (8 < 0.5 * 20).
    let r = one(vec![dropped(12, 1, 5.0), ret(8, 1, 0, 5.0)]);
    assert_eq!((r.outcome, r.retained), (Outcome::Detected, false));
    assert_eq!((r.clean, r.reached), (20, 8));
}

#[test]
fn dropped_then_lost() {
    // Every return dropped: nothing reaches clustering, the object is lost.
    let r = one(vec![dropped(20, 1, 5.0)]);
    assert_eq!(
        (r.outcome, r.retained, r.reached),
        (Outcome::Lost, false, 0)
    );
    // Some reach but none is clustered: lost too.
    let r = one(vec![dropped(15, 1, 5.0), ret(5, 1, -1, 5.0)]);
    assert_eq!(r.outcome, Outcome::Lost);
}

#[test]
fn objects_smaller_than_min_points_are_not_counted() {
    let r = outcomes(vec![ret(4, 1, 0, 5.0), ret(5, 2, 1, 5.0)]);
    assert_eq!(r.iter().map(|o| o.id).collect::<Vec<_>>(), vec![2]);
}

#[test]
fn outcome_counts_add_up_on_a_mixed_frame() {
    let r = outcomes(vec![
        ret(20, 1, 0, 2.0),   // detected, retained
        dropped(30, 2, 7.0),  // lost
        grounded(9, 3, 12.0), // merged into ground
        ret(5, 4, 1, 25.0),   // split (5 + 5 of 12 reaching) ...
        ret(5, 4, 2, 25.0),   // ... over clusters 1 and 2
        ret(2, 4, -1, 25.0),  // (unclustered)
        ret(5, 5, 3, 50.0),   // merged: 5 of cluster 3's 25
        ret(20, 6, 3, 50.0),  // detected (20/25)
    ]);
    let t = Tally::of(&r);
    assert_eq!(
        (
            t.objects,
            t.detected,
            t.retained,
            t.split,
            t.merged,
            t.merged_into_ground,
            t.lost
        ),
        (6, 2, 2, 1, 1, 1, 1)
    );
    assert_eq!(
        t.detected + t.split + t.merged + t.merged_into_ground + t.lost,
        t.objects
    );
    let bands = band_metrics(&r, &[0.0, 5.0, 10.0, 20.0, 40.0]);
    let per: Vec<(u64, u64)> = bands.iter().map(|b| (b.objects, b.detected)).collect();
    assert_eq!(per, vec![(1, 1), (1, 0), (1, 0), (1, 0), (2, 1)]);
    assert_eq!((bands[4].lo_m, bands[4].hi_m), (40.0, None));
    assert_eq!((bands[1].lo_m, bands[1].hi_m), (5.0, Some(10.0)));
}

#[test]
fn band_edges_are_lower_inclusive_upper_exclusive() {
    let edges = [0.0, 5.0, 10.0, 20.0, 40.0];
    assert_eq!(band_index(0.0, &edges), Some(0));
    assert_eq!(band_index(4.999_999, &edges), Some(0));
    assert_eq!(band_index(5.0, &edges), Some(1));
    assert_eq!(band_index(9.99, &edges), Some(1));
    assert_eq!(band_index(10.0, &edges), Some(2));
    assert_eq!(band_index(40.0, &edges), Some(4));
    assert_eq!(band_index(1e6, &edges), Some(4));
    assert_eq!(band_index(f64::NAN, &edges), None);
    assert_eq!(band_index(1.0, &[2.0, 5.0]), None);
    // Distance is horizontal: an object at (3, 4) with any height is at exactly 5 m.
    let mut at = ret(10, 1, 0, 3.0);
    for r in &mut at {
        r.xy = [3.0, 4.0];
    }
    let r = object_outcomes(&at, 5);
    assert_eq!(band_index(r[0].distance_m, &edges), Some(1));
}

fn row(seed: u64, frame: u32, objects: u64, detected: u64, kept: u64) -> Row {
    let mut m = lidar_noise::score::metrics::FrameMetrics {
        frame,
        objects,
        detected,
        kept,
        ..Default::default()
    };
    m.bands = band_metrics(&[], &[0.0, 5.0]);
    Row {
        capture: "c".into(),
        values: vec!["1".into()],
        seed,
        metrics: m,
    }
}

#[test]
fn aggregation_reduces_each_seed_first() {
    // Seed 1: 3 frames, kept 10, 20, 30 (mean 20); seed 2: 1 frame, kept 40.
    // Over frames the mean would be 25; per seed it is (20 + 40) / 2 = 30.
    let rows = vec![
        row(1, 0, 4, 4, 10),
        row(1, 1, 4, 2, 20),
        row(1, 2, 2, 0, 30),
        row(2, 0, 10, 5, 40),
    ];
    let ms = metrics(&rows);
    let kept = ms.iter().find(|m| m.name == "kept").unwrap();
    let refs: Vec<&Row> = rows.iter().collect();
    assert_eq!(per_seed(kept, &refs), vec![20.0, 40.0]);
    // Shares are pooled per seed: seed 1 detected 6 of 10 objects.
    let share = ms.iter().find(|m| m.name == "detected_share").unwrap();
    assert_eq!(per_seed(share, &refs), vec![0.6, 0.5]);
    let groups = aggregate(&rows, &ms);
    assert_eq!(groups.len(), 1);
    assert_eq!((groups[0].rows, groups[0].seeds), (4, 2));
    let i = groups[0].metrics[ms.iter().position(|m| m.name == "kept").unwrap()].unwrap();
    assert_eq!((i.n, i.mean), (2, 30.0));
    // sd of (20, 40) = sqrt(200); half-width = t(0.975, 1) * sqrt(200) / sqrt(2) = 12.706 * 10.
    assert!((i.hi.unwrap() - (30.0 + 127.062_047)).abs() < 1e-3, "{i:?}");
    // Band columns exist, and with one seed no interval is invented.
    assert!(ms.iter().any(|m| m.name == "detected_share_5m_plus"));
    let single: Vec<Row> = rows.into_iter().filter(|r| r.seed == 1).collect();
    let g = aggregate(&single, &ms);
    let i = g[0].metrics[0].unwrap();
    assert_eq!((i.n, i.lo, i.hi), (1, None, None));
}

/// A share of 0.984 over three seeds (1, 1, 0.952): the Student t interval reached past 1
/// ("0.984 [0.943, 1.024]"); the aggregate's percentile bootstrap stays in [0, 1], and
/// the column dictionary says which method each bound comes from.
#[test]
fn share_intervals_stay_in_zero_one_and_the_columns_say_how() {
    let rows = vec![
        row(1, 0, 21, 21, 10),
        row(2, 0, 21, 21, 20),
        row(3, 0, 21, 20, 60),
        row(4, 0, 21, 0, 10),
    ];
    let ms = metrics(&rows);
    let at = |name: &str| ms.iter().position(|m| m.name == name).unwrap();
    let high = aggregate(&rows[..3], &ms);
    let i = high[0].metrics[at("detected_share")].unwrap();
    assert!((i.mean - 0.984).abs() < 1e-3, "{i:?}");
    let (lo, hi) = (i.lo.unwrap(), i.hi.unwrap());
    assert!(hi <= 1.0 && lo >= 0.0 && lo < i.mean, "{i:?}");
    // The t interval of the same values is the defect.
    assert!(interval(&[1.0, 1.0, 20.0 / 21.0]).unwrap().hi.unwrap() > 1.0);
    // Near 0: two seeds detect none of 21 objects, one 1 of 1000 ("0.001 [-0.001, ...]").
    let low: Vec<Row> = vec![
        row(1, 0, 21, 0, 1),
        row(2, 0, 21, 0, 1),
        row(3, 0, 1000, 1, 1),
    ];
    let g = aggregate(&low, &metrics(&low));
    let i = g[0].metrics[at("detected_share")].unwrap();
    assert!(i.lo.unwrap() >= 0.0 && i.hi.unwrap() <= 1.0, "{i:?}");
    assert!(interval(&[0.0, 0.0, 0.001]).unwrap().lo.unwrap() < 0.0);
    // Counts keep the Student t interval.
    let k = high[0].metrics[at("kept")].unwrap();
    let t = interval(&[10.0, 20.0, 60.0]).unwrap();
    assert_eq!((k.lo, k.hi), (t.lo, t.hi));
    // The dictionary: one row per aggregate column, saying what it holds.
    let keys = vec!["rain.rate_mm_h".to_string()];
    let dict = String::from_utf8(tables::aggregate_columns_csv(&keys, &ms)).unwrap();
    let agg = String::from_utf8(tables::aggregate_csv(&keys, &high, &ms)).unwrap();
    let header = agg.lines().next().unwrap();
    let mut r = csv::Reader::from_reader(dict.as_bytes());
    let described: Vec<(String, String)> = r
        .records()
        .map(|rec| {
            let rec = rec.unwrap();
            (rec[0].to_string(), rec[2].to_string())
        })
        .collect();
    let names: Vec<&str> = described.iter().map(|(c, _)| c.as_str()).collect();
    assert_eq!(
        names.join(","),
        header,
        "one description per column, in order"
    );
    let holds = |c: &str| &described.iter().find(|(n, _)| n == c).unwrap().1;
    assert!(holds("detected_share_lo").contains("percentile bootstrap over seeds"));
    assert!(holds("detected_share_hi").contains("percentile bootstrap over seeds"));
    assert!(holds("kept_hi").contains("Student t"));
    assert!(holds("ground_recall_lo").contains("bootstrap"));
}

#[test]
fn t_quantile_and_interval_match_known_values() {
    assert!((t_quantile(0.975, 2).unwrap() - 4.302_653).abs() < 1e-6);
    assert!((t_quantile(0.975, 30).unwrap() - 2.042_272).abs() < 1e-6);
    // Past 30 degrees of freedom the quantile is not 1.96.
    assert!((t_quantile(0.975, 31).unwrap() - 2.039_513).abs() < 1e-6);
    let i = interval(&[1.0, 2.0, 3.0]).unwrap();
    assert!((i.lo.unwrap() - (2.0 - 4.302_653 / 3f64.sqrt())).abs() < 1e-6);
}

#[test]
fn bands_option_needs_increasing_non_negative_edges() {
    use lidar_noise::sweep::plan::parse_bands;
    assert_eq!(
        parse_bands("0,5,10,20,40").unwrap(),
        vec![0.0, 5.0, 10.0, 20.0, 40.0]
    );
    assert_eq!(parse_bands(" 2.5 , 7").unwrap(), vec![2.5, 7.0]);
    for bad in ["0,5,5", "10,5", "-1,5", "0,x", "", "0,inf"] {
        let e = parse_bands(bad).unwrap_err().to_string();
        assert!(e.contains("--bands"), "{bad}: {e}");
    }
}

fn sweep_cmd(out: &std::path::Path, extra: &[&str]) -> std::process::Output {
    assert_cmd::Command::cargo_bin("lidar-noise")
        .unwrap()
        .arg("--quiet")
        .arg("sweep")
        .arg(fixture("crossroad.pcap"))
        .args([
            "--vary",
            "occlusion=on,off",
            "--seeds",
            "1",
            "--bands",
            "0,10",
        ])
        .args(extra)
        .arg("-o")
        .arg(out)
        .output()
        .unwrap()
}

#[test]
fn a_labelled_sweep_reports_objects_by_band_and_class() {
    let tmp = tempfile::tempdir().unwrap();
    let o = sweep_cmd(tmp.path(), &[]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let json: serde_json::Value =
        serde_json::from_slice(&std::fs::read(tmp.path().join("sweep.json")).unwrap()).unwrap();
    let rows = json["rows"].as_array().unwrap();
    assert_eq!(rows.len(), 4, "2 cells x 2 frames");
    for r in rows {
        let m = &r["metrics"];
        assert_eq!(m["labelled"], true);
        let n = |v: &serde_json::Value| v.as_u64().unwrap();
        let objects = n(&m["objects"]);
        assert!(objects >= 10, "{m}");
        let outcomes = ["detected", "split", "merged", "merged_into_ground", "lost"];
        assert_eq!(outcomes.iter().map(|k| n(&m[k])).sum::<u64>(), objects);
        assert!(n(&m["retained"]) <= n(&m["detected"]));
        let bands = m["bands"].as_array().unwrap();
        assert_eq!(bands.len(), 2);
        assert_eq!(
            (bands[0]["lo_m"].as_f64(), bands[0]["hi_m"].as_f64()),
            (Some(0.0), Some(10.0))
        );
        assert_eq!(
            (bands[1]["lo_m"].as_f64(), bands[1]["hi_m"].is_null()),
            (Some(10.0), true)
        );
        assert_eq!(n(&bands[0]["objects"]) + n(&bands[1]["objects"]), objects);
        let classes = m["classes"].as_array().unwrap();
        assert!(classes.iter().any(|c| c["kind"] == "car"), "{m}");
        assert_eq!(
            classes.iter().map(|c| n(&c["objects"])).sum::<u64>(),
            objects
        );
        assert!(m["ground_lost_before_share"].as_f64().is_some());
    }
    // The aggregate has per-band and per-class columns and, with one seed, no bounds.
    let agg = std::fs::read_to_string(tmp.path().join("aggregate.csv")).unwrap();
    let mut lines = agg.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let col = |name: &str| header.iter().position(|h| *h == name).unwrap();
    let first: Vec<&str> = lines.next().unwrap().split(',').collect();
    assert!(!first[col("detected_share_0_10m_mean")].is_empty());
    assert!(first[col("detected_share_0_10m_lo")].is_empty());
    assert!(first[col("detected_share_car_mean")].parse::<f64>().is_ok());
    let csv = std::fs::read_to_string(tmp.path().join("sweep.csv")).unwrap();
    assert!(csv.lines().next().unwrap().contains("detected_10m_plus"));
    let html = std::fs::read_to_string(tmp.path().join("index.html")).unwrap();
    assert!(html.contains("Objects by distance band"));
}

#[test]
fn labels_that_do_not_line_up_are_refused_naming_the_frame() {
    use lidar_noise::synth::labels::{read_labels_file, LabelWriter};
    let tmp = tempfile::tempdir().unwrap();
    let mut rows = read_labels_file(&fixture("crossroad.labels.csv.gz")).unwrap();
    // Change the laser of the 5th row of frame 1.
    let k = rows.iter().position(|r| r.frame == 1).unwrap() + 4;
    rows[k].laser = (rows[k].laser + 1) % 32;
    let mut w = LabelWriter::new(Vec::new()).unwrap();
    for r in &rows {
        w.write(r).unwrap();
    }
    let bad = tmp.path().join("bad.labels.csv.gz");
    std::fs::write(&bad, w.finish().unwrap()).unwrap();
    let out = tmp.path().join("o");
    let o = sweep_cmd(&out, &["--labels", bad.to_str().unwrap()]);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("bad.labels.csv.gz") && err.contains("frame 1") && err.contains("return 4"),
        "{err}"
    );
    assert!(!out.join("sweep.csv").exists(), "no partial output");
}
