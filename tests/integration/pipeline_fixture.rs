//! The whole pipeline on the crossroad fixture, whose ground truth is known.

use crate::common;

use lidar_noise::config::Config;
use lidar_noise::noise::Fate;
use lidar_noise::pipeline::{FrameResult, Pipeline};
use lidar_noise::sensor::frames::{DecoderOptions, FrameReader};
use lidar_noise::synth::labels::{check_frame, read_labels_file, LabelRow};
use std::collections::HashMap;
use std::path::Path;

fn config(name: &str) -> Config {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("configs")
        .join(format!("{name}.toml"));
    Config::load(Some(&path), &[], None).unwrap().0
}

/// Pipeline results of every frame with the label of every clean return.
fn run(config: &Config) -> Vec<(FrameResult, Vec<u16>)> {
    let fixtures = common::fixtures();
    let rows: Vec<LabelRow> = read_labels_file(&fixtures.join("crossroad.labels.csv.gz")).unwrap();
    let mut by_frame: HashMap<u32, Vec<&LabelRow>> = HashMap::new();
    for r in &rows {
        by_frame.entry(r.frame).or_default().push(r);
    }
    let pipeline = Pipeline::new(config);
    FrameReader::open(&fixtures.join("crossroad.pcap"), &DecoderOptions::default())
        .unwrap()
        .map(|frame| {
            let frame = frame.unwrap();
            let labels: Vec<LabelRow> = by_frame[&frame.index].iter().map(|l| **l).collect();
            check_frame(&labels, &frame, Path::new("crossroad.labels.csv.gz")).unwrap();
            let labels: Vec<u16> = labels.iter().map(|l| l.label).collect();
            (pipeline.process(frame).unwrap(), labels)
        })
        .collect()
}

#[test]
fn clear_ground_precision_and_recall_reach_0_97() {
    let results = run(&config("clear"));
    let (mut tp, mut fp, mut fn_) = (0u64, 0u64, 0u64);
    for (r, labels) in &results {
        for (s, &k) in r.kept.iter().enumerate() {
            let truth = labels[k as usize] == 0;
            match (r.ground[s], truth) {
                (true, true) => tp += 1,
                (true, false) => fp += 1,
                (false, true) => fn_ += 1,
                _ => {}
            }
        }
    }
    let precision = tp as f64 / (tp + fp) as f64;
    let recall = tp as f64 / (tp + fn_) as f64;
    eprintln!("ground precision {precision:.4}, recall {recall:.4}");
    assert!(
        precision >= 0.97 && recall >= 0.97,
        "precision {precision}, recall {recall}"
    );
}

/// Objects of at least 30 kept returns whose returns lie mostly within 20 m.
fn near_objects(r: &FrameResult, labels: &[u16]) -> Vec<u16> {
    let mut count: HashMap<u16, (usize, f64)> = HashMap::new();
    for (s, &k) in r.kept.iter().enumerate() {
        let l = labels[k as usize];
        if l > 0 {
            let e = count.entry(l).or_default();
            e.0 += 1;
            e.1 += f64::from(r.survivors[s].range);
        }
    }
    let mut out: Vec<u16> = count
        .into_iter()
        .filter(|(_, (n, sum))| *n >= 30 && sum / *n as f64 <= 20.0)
        .map(|(l, _)| l)
        .collect();
    out.sort();
    out
}

/// Objects that form their own cluster: the cluster holding most of the object's
/// non-ground returns holds at least half of them, at least 95 % of its object returns
/// are this object's (ground returns left next to an object do not count against it: a
/// car with a fringe of road is still its own cluster, a car merged with a pole is not),
/// and no other object claims the same cluster.
fn objects_found(r: &FrameResult, labels: &[u16]) -> (Vec<u16>, Vec<u16>) {
    let near = near_objects(r, labels);
    let mut found = Vec::new();
    let mut missed = Vec::new();
    let mut claimed: HashMap<i32, u16> = HashMap::new();
    // Returns of any object per cluster.
    let mut cluster_size: HashMap<i32, usize> = HashMap::new();
    for (s, &c) in r.labels.iter().enumerate() {
        if labels[r.kept[s] as usize] > 0 {
            *cluster_size.entry(c).or_default() += 1;
        }
    }
    for &object in &near {
        let mut in_cluster: HashMap<i32, usize> = HashMap::new();
        let mut non_ground = 0;
        for (s, &k) in r.kept.iter().enumerate() {
            if labels[k as usize] == object && !r.ground[s] {
                non_ground += 1;
                *in_cluster.entry(r.labels[s]).or_default() += 1;
            }
        }
        let best = in_cluster
            .iter()
            .filter(|(c, _)| **c >= 0)
            .max_by_key(|(c, n)| (**n, -**c));
        if std::env::var("DEBUG_OBJECTS").is_ok() {
            eprintln!(
                "object {object}: non-ground {non_ground}, clusters {in_cluster:?}, sizes {:?}",
                best.map(|(c, _)| cluster_size[c])
            );
        }
        let ok = match best {
            Some((&c, &n)) => {
                let own = 2 * n >= non_ground;
                let pure = n as f64 >= 0.95 * cluster_size[&c] as f64;
                own && pure && claimed.insert(c, object).is_none()
            }
            None => false,
        };
        if ok {
            found.push(object);
        } else {
            missed.push(object);
        }
    }
    (found, missed)
}

#[test]
fn clear_run_finds_every_object_within_20_m() {
    for (r, labels) in run(&config("clear")) {
        let (found, missed) = objects_found(&r, &labels);
        eprintln!(
            "frame {}: found objects {found:?}, missed {missed:?}",
            r.noisy.index
        );
        assert!(
            found.len() >= 5,
            "the crossroad has several objects within 20 m"
        );
        assert!(
            missed.is_empty(),
            "frame {}: objects {missed:?} do not form their own cluster",
            r.noisy.index
        );
    }
}

#[test]
fn every_return_has_one_fate_and_cluster_counts_add_up_under_all_four_configs() {
    for name in ["clear", "occlusion", "rain", "paper"] {
        let mut objects = 0;
        let mut found_total = 0;
        for (r, labels) in run(&config(name)) {
            let n = r.noisy.clean.len();
            assert_eq!(r.noisy.fate.len(), n);
            let kept = r.noisy.fate.iter().filter(|&&f| f == Fate::Kept).count();
            let dropped = &r.noise.dropped;
            assert_eq!(
                kept as u64 + dropped.occluded + dropped.below_power + dropped.below_min_range,
                n as u64,
                "{name}"
            );
            assert_eq!(kept, r.survivors.len());
            assert_eq!(r.kept.len(), kept);
            let non_ground = r.ground.iter().filter(|g| !**g).count();
            let in_clusters: usize = r.clusters.iter().map(|c| c.n_points).sum();
            let labelled = r.labels.iter().filter(|&&l| l >= 0).count();
            assert_eq!(in_clusters, labelled, "{name}");
            assert_eq!(
                in_clusters as u64 + r.counts.noise_points,
                non_ground as u64,
                "{name}"
            );
            assert!(
                r.labels.iter().zip(&r.ground).all(|(&l, &g)| !g || l == -1),
                "{name}: ground is never clustered"
            );
            objects = r.clusters.len();
            found_total += objects_found(&r, &labels).0.len();
        }
        // Which way these go is a finding, not something to assert.
        eprintln!("{name}: {objects} clusters in the last frame, {found_total} objects found over the frames");
    }
}

#[test]
fn forks_on_a_pool_change_no_result() {
    // On a thread of a rayon pool, `process` forks the frame's independent parts (noise
    // summary beside segmentation, the voxel links and the clusters' descriptions in two
    // halves each) and the pool's idle thread takes them; everything it returns must equal
    // the one-thread path.
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(2)
        .build()
        .unwrap();
    for name in ["paper", "clear"] {
        let config = config(name);
        let pipeline = Pipeline::new(&config);
        let reader = FrameReader::open(
            &common::fixtures().join("crossroad.pcap"),
            &DecoderOptions::default(),
        )
        .unwrap();
        for frame in reader {
            let frame = frame.unwrap();
            let (a, b) = (
                pipeline.process(frame.clone()).unwrap(),
                pool.install(|| pipeline.process(frame)).unwrap(),
            );
            assert!(
                !a.clusters.is_empty(),
                "{name}: the halves have clusters to split"
            );
            assert_eq!(a.noise, b.noise, "{name} frame {}", a.noisy.index);
            assert_eq!(a.counts, b.counts);
            assert_eq!(a.survivors, b.survivors);
            assert_eq!(
                (&a.kept, &a.ground, &a.labels),
                (&b.kept, &b.ground, &b.labels)
            );
            assert_eq!(a.clusters, b.clusters);
        }
    }
}

/// A dataset run's lean processing gives every value the scan files and the truth
/// scores read exactly as the full processing does, and leaves out only the reports'.
#[test]
fn process_points_matches_process_but_for_the_reports() {
    let fixtures = common::fixtures();
    for name in ["paper", "adverse-weather"] {
        let pipeline = Pipeline::new(&config(name));
        let frames: Vec<_> =
            FrameReader::open(&fixtures.join("crossroad.pcap"), &DecoderOptions::default())
                .unwrap()
                .take(3)
                .map(|f| f.unwrap())
                .collect();
        for frame in frames {
            let full = pipeline.process(frame.clone()).unwrap();
            let lean = pipeline.process_points(frame).unwrap();
            assert_eq!(lean.kept, full.kept, "{name}");
            assert_eq!(lean.ground, full.ground, "{name}");
            assert_eq!(lean.labels, full.labels, "{name}");
            assert_eq!(lean.survivors.len(), full.survivors.len(), "{name}");
            assert_eq!(lean.noisy.fate, full.noisy.fate, "{name}");
            assert_eq!(lean.noisy.cause, full.noisy.cause, "{name}");
            for (a, b) in lean.survivors.iter().zip(&full.survivors) {
                assert_eq!((a.x, a.y, a.z, a.intensity), (b.x, b.y, b.z, b.intensity));
            }
            assert!(
                !full.clusters.is_empty(),
                "{name}: the fixture has clusters"
            );
            assert!(lean.clusters.is_empty(), "{name}");
            assert_eq!(lean.counts.clusters, full.counts.clusters, "{name}");
        }
    }
}
