//! `run DATASET_DIR` (issue 31, "Dataset folders"): a KITTI sequence folder and a nuScenes
//! `samples/LIDAR_TOP` folder, built here from decoded frames of the fixtures (the datasets
//! themselves are non-commercial: nothing of them is kept in the repository), walked in
//! parallel, sharded, resumed, and refused with the file named when a scan is bad.

use crate::common;

use common::{bin2, files, fixtures, kitti_bytes};
use lidar_noise::frame::Frame;
use lidar_noise::sensor::frames::{DecoderOptions, FrameReader};
use std::path::{Path, PathBuf};

/// The full frames of fixture `name`, decoded as `run` decodes them.
fn frames(name: &str) -> Vec<Frame> {
    let reader = FrameReader::open(
        &fixtures().join(format!("{name}.pcap")),
        &DecoderOptions::default(),
    )
    .unwrap();
    reader.map(Result::unwrap).filter(|f| !f.partial).collect()
}

/// Scans for a dataset: the fixtures' full frames, each also thinned to every other
/// return, so that the scans differ from one another.
fn scans() -> Vec<Frame> {
    let mut out = Vec::new();
    for name in ["crossroad", "parking", "empty"] {
        for f in frames(name) {
            let mut thin = f.clone();
            thin.returns = f.returns.iter().step_by(2).copied().collect();
            out.push(f);
            out.push(thin);
        }
    }
    out.retain(|f| !f.returns.is_empty());
    assert!(out.len() >= 4, "the fixtures give {} scans", out.len());
    out
}

/// The frame as a nuScenes `.pcd.bin`: x y z intensity ring, float32 little-endian.
fn nuscenes_bytes(frame: &Frame) -> Vec<u8> {
    frame
        .returns
        .iter()
        .flat_map(|r| {
            [r.x, r.y, r.z, f32::from(r.intensity), f32::from(r.ring)]
                .into_iter()
                .flat_map(f32::to_le_bytes)
        })
        .collect()
}

/// A KITTI sequence folder `dir/seq` with `velodyne/NNNNNN.bin`.
fn kitti(dir: &Path) -> PathBuf {
    let seq = dir.join("seq");
    std::fs::create_dir_all(seq.join("velodyne")).unwrap();
    for (i, f) in scans().iter().enumerate() {
        std::fs::write(
            seq.join("velodyne").join(format!("{i:06}.bin")),
            kitti_bytes(f),
        )
        .unwrap();
    }
    seq
}

/// A nuScenes root `dir/nus` with `samples/LIDAR_TOP/<token>.pcd.bin`.
fn nuscenes(dir: &Path) -> PathBuf {
    let root = dir.join("nus");
    let lidar = root.join("samples/LIDAR_TOP");
    std::fs::create_dir_all(&lidar).unwrap();
    for (i, f) in scans().iter().enumerate() {
        let name = format!("n008-2018-08-01-15-16-36-0400__LIDAR_TOP__15331516036{i:05}.pcd.bin");
        std::fs::write(lidar.join(name), nuscenes_bytes(f)).unwrap();
    }
    root
}

/// Runs `run DATASET -o OUT` with `extra` arguments (after `run`) and `threads` workers;
/// panics unless it succeeds.
fn run(dataset: &Path, out: &Path, threads: &str, extra: &[&str]) {
    let o = bin2()
        .args(["--quiet", "--threads", threads, "run"])
        .arg(dataset)
        .args(extra)
        .args(["-c", "configs/paper.toml", "-o"])
        .arg(out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}

const KITTI: &[&str] = &["--sensor", "hdl32e"];

#[test]
fn a_kitti_sequence_comes_out_in_its_layout_the_same_for_any_thread_count() {
    let dir = tempfile::tempdir().unwrap();
    let seq = kitti(dir.path());
    let (one, four) = (dir.path().join("one"), dir.path().join("four"));
    run(&seq, &one, "1", KITTI);
    // The velodyne folder itself is the same sequence.
    run(&seq.join("velodyne"), &four, "4", KITTI);
    let a = files(&one);
    assert_eq!(a, files(&four), "1 thread and 4 threads differ");
    let n = scans().len();
    for i in 0..n {
        for ext in ["bin", "fate.csv"] {
            let rel = PathBuf::from(format!("velodyne/{i:06}.{ext}"));
            assert!(a.contains_key(&rel), "{} missing", rel.display());
        }
    }
    // Scans, sidecars and the settings file, nothing else.
    assert_eq!(a.len(), 2 * n + 1, "{:?}", a.keys().collect::<Vec<_>>());
    // Each written scan is whole KITTI points, one sidecar row per point written.
    for i in 0..n {
        let bin = &a[&PathBuf::from(format!("velodyne/{i:06}.bin"))];
        let fate = &a[&PathBuf::from(format!("velodyne/{i:06}.fate.csv"))];
        assert_eq!(bin.len() % 16, 0);
        let rows = fate.iter().filter(|&&b| b == b'\n').count() - 1;
        assert_eq!(rows, bin.len() / 16, "scan {i}");
    }
}

#[test]
fn each_scan_is_the_scan_run_alone_at_its_index() {
    // Scan 0 of the folder is frame 0, as a single scan run on its own: same bytes.
    let dir = tempfile::tempdir().unwrap();
    let seq = kitti(dir.path());
    let out = dir.path().join("out");
    run(&seq, &out, "2", KITTI);
    let alone = dir.path().join("alone");
    run(&seq.join("velodyne/000000.bin"), &alone, "2", KITTI);
    for ext in ["bin", "fate.csv"] {
        assert_eq!(
            std::fs::read(out.join(format!("velodyne/000000.{ext}"))).unwrap(),
            std::fs::read(alone.join(format!("000000/frame_00000.{ext}"))).unwrap(),
            "{ext}"
        );
    }
}

#[test]
fn the_same_scan_at_two_indexes_draws_two_streams() {
    // Random draws derive from the file's index, not from its content or name.
    let dir = tempfile::tempdir().unwrap();
    let seq = dir.path().join("seq");
    std::fs::create_dir_all(seq.join("velodyne")).unwrap();
    let bytes = kitti_bytes(&scans()[0]);
    for i in 0..2 {
        std::fs::write(seq.join(format!("velodyne/{i:06}.bin")), &bytes).unwrap();
    }
    let out = dir.path().join("out");
    // Rain draws a fate for every return: two streams cannot give the same scan.
    let o = bin2()
        .args(["--quiet", "run"])
        .arg(&seq)
        .args(KITTI)
        .args(["-c", "configs/rain.toml", "-o"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert_ne!(
        std::fs::read(out.join("velodyne/000000.fate.csv")).unwrap(),
        std::fs::read(out.join("velodyne/000001.fate.csv")).unwrap()
    );
}

#[test]
fn two_shards_write_what_the_whole_run_writes() {
    let dir = tempfile::tempdir().unwrap();
    let seq = kitti(dir.path());
    let (whole, sharded) = (dir.path().join("whole"), dir.path().join("sharded"));
    run(&seq, &whole, "2", KITTI);
    let mut first = KITTI.to_vec();
    first.extend(["--shard", "0/2"]);
    run(&seq, &sharded, "2", &first);
    let half = files(&sharded);
    // Shard 0 of 2 writes the even scans only.
    assert!(half.contains_key(Path::new("velodyne/000000.bin")));
    assert!(!half.contains_key(Path::new("velodyne/000001.bin")));
    let mut second = KITTI.to_vec();
    second.extend(["--shard", "1/2"]);
    run(&seq, &sharded, "2", &second);
    assert_eq!(files(&whole), files(&sharded));
}

#[test]
fn a_rerun_computes_only_the_missing_files() {
    let dir = tempfile::tempdir().unwrap();
    let seq = kitti(dir.path());
    let out = dir.path().join("out");
    run(&seq, &out, "2", KITTI);
    let before = files(&out);
    // One output deleted, another replaced by a marker: the rerun writes the first again
    // and skips the second (its outputs are there), which shows it was not recomputed.
    std::fs::remove_file(out.join("velodyne/000001.bin")).unwrap();
    std::fs::write(out.join("velodyne/000002.bin"), b"marker").unwrap();
    run(&seq, &out, "2", KITTI);
    let after = files(&out);
    assert_eq!(
        after[Path::new("velodyne/000001.bin")],
        before[Path::new("velodyne/000001.bin")]
    );
    assert_eq!(after[Path::new("velodyne/000002.bin")], b"marker");
    // Other settings: refused, then --force recomputes every file.
    let o = bin2()
        .args(["--quiet", "run"])
        .arg(&seq)
        .args(KITTI)
        .args(["-c", "configs/clear.toml", "-o"])
        .arg(&out)
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&o.stderr).contains("other settings"));
    let mut force = KITTI.to_vec();
    force.push("--force");
    run(&seq, &out, "2", &force);
    assert_eq!(files(&out), before);
}

#[test]
fn a_bad_scan_is_named_and_writes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let seq = kitti(dir.path());
    // Not a whole number of 16-byte KITTI points.
    let bad = seq.join("velodyne/000001.bin");
    let mut bytes = std::fs::read(&bad).unwrap();
    bytes.truncate(bytes.len() - 5);
    std::fs::write(&bad, bytes).unwrap();
    let out = dir.path().join("out");
    let o = bin2()
        .args(["--quiet", "run"])
        .arg(&seq)
        .args(KITTI)
        .args(["-c", "configs/paper.toml", "-o"])
        .arg(&out)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(err.contains(&bad.display().to_string()), "{err}");
    let written = files(&out);
    assert!(!written.contains_key(Path::new("velodyne/000001.bin")));
    assert!(!written.contains_key(Path::new("velodyne/000001.fate.csv")));
    // The good scans are written (a rerun after fixing the bad one finishes the folder).
    assert!(written.contains_key(Path::new("velodyne/000000.bin")));
    assert!(written.contains_key(Path::new("velodyne/000002.bin")));
}

#[test]
fn a_nuscenes_folder_comes_out_as_samples_lidar_top() {
    let dir = tempfile::tempdir().unwrap();
    let root = nuscenes(dir.path());
    let (one, four) = (dir.path().join("one"), dir.path().join("four"));
    run(&root, &one, "1", &[]);
    // The LIDAR_TOP folder itself is the same dataset.
    run(&root.join("samples/LIDAR_TOP"), &four, "4", &[]);
    let a = files(&one);
    assert_eq!(a, files(&four));
    let name = "n008-2018-08-01-15-16-36-0400__LIDAR_TOP__1533151603600000";
    for ext in ["pcd.bin", "fate.csv"] {
        let rel = PathBuf::from(format!("samples/LIDAR_TOP/{name}.{ext}"));
        assert!(
            a.contains_key(&rel),
            "{} missing: {:?}",
            rel.display(),
            a.keys()
        );
    }
    // nuScenes points are 5 floats.
    assert_eq!(
        a[&PathBuf::from(format!("samples/LIDAR_TOP/{name}.pcd.bin"))].len() % 20,
        0
    );
}

#[test]
fn a_folder_that_is_no_dataset_is_refused_naming_it() {
    let dir = tempfile::tempdir().unwrap();
    let empty = dir.path().join("scans");
    std::fs::create_dir_all(&empty).unwrap();
    std::fs::write(empty.join("notes.txt"), b"x").unwrap();
    let out = dir.path().join("out");
    let o = bin2()
        .args(["--quiet", "run"])
        .arg(&empty)
        .arg("-o")
        .arg(&out)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(err.contains(&empty.display().to_string()), "{err}");
    assert!(
        err.contains("velodyne/*.bin") && err.contains("LIDAR_TOP"),
        "{err}"
    );
    assert!(!out.exists());
}

#[test]
fn a_labelled_sequence_gets_each_scans_scores_and_resumes_them() {
    // SemanticKITTI labels beside the scans (u32 a point: class in the low 16 bits,
    // instance in the high ones): returns below -1.2 m are road (40), the rest of those
    // within 20 m one car (10, instance 7), the others unlabelled (0).
    let dir = tempfile::tempdir().unwrap();
    let seq = kitti(dir.path());
    std::fs::create_dir_all(seq.join("labels")).unwrap();
    for (i, f) in scans().iter().enumerate() {
        let labels: Vec<u8> = f
            .returns
            .iter()
            .map(|r| {
                if r.z < -1.2 {
                    40u32
                } else if r.x.hypot(r.y) < 20.0 {
                    (7 << 16) | 10
                } else {
                    0
                }
            })
            .flat_map(u32::to_le_bytes)
            .collect();
        std::fs::write(seq.join("labels").join(format!("{i:06}.label")), labels).unwrap();
    }
    let out = dir.path().join("out");
    run(&seq, &out, "2", KITTI);
    let n = scans().len();
    for i in 0..n {
        let text = std::fs::read_to_string(out.join(format!("velodyne/{i:06}.truth.json")))
            .unwrap_or_else(|e| panic!("scan {i}: {e}"));
        let v: serde_json::Value = serde_json::from_str(&text).unwrap();
        assert!(
            v["labels"]
                .as_str()
                .unwrap()
                .ends_with(&format!("{i:06}.label")),
            "{v}"
        );
        assert!(v["ground_points"].as_u64().unwrap() > 0, "{v}");
        let p = v["ground_precision"].as_f64().unwrap();
        assert!((0.0..=1.0).contains(&p), "{v}");
    }
    // A missing score is computed again on a rerun; a scan without its labels' score is
    // not complete.
    let before = files(&out);
    std::fs::remove_file(out.join("velodyne/000001.truth.json")).unwrap();
    run(&seq, &out, "2", KITTI);
    assert_eq!(files(&out), before);
    // A label file of the wrong length names it and writes nothing for that scan.
    std::fs::write(seq.join("labels/000002.label"), [0u8; 12]).unwrap();
    let fresh = dir.path().join("fresh");
    let o = bin2()
        .args(["--quiet", "run"])
        .arg(&seq)
        .args(KITTI)
        .args(["-c", "configs/paper.toml", "-o"])
        .arg(&fresh)
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(1));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("000002.label"), "{err}");
    for ext in ["bin", "fate.csv", "truth.json"] {
        assert!(
            !fresh.join(format!("velodyne/000002.{ext}")).exists(),
            "{ext}"
        );
    }
    assert!(fresh.join("velodyne/000003.truth.json").is_file());
}
