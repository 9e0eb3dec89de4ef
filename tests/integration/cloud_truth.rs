//! Dataset ground truth on scans (issue 31, "Ground truth from datasets"): KITTI `label_2`
//! boxes with their `calib` file, the labels found beside a scan, and a labelled scan's
//! ground and object scores. Every file is built here from the documented layouts (KITTI
//! object devkit `readme.txt`; SemanticKITTI `.label`): no dataset file is committed.

use lidar_noise::cloud::boxes::{box_truth, parse_calib, parse_label2, read_calib, read_label2};
use lidar_noise::cloud::returns::{to_returns, ReturnsOptions};
use lidar_noise::cloud::{read_file, CloudPoint, ReadOptions};
use lidar_noise::frame::Frame;
use lidar_noise::pipeline::Pipeline;
use lidar_noise::score::truth::{labels_beside, read_truth, score, LabelsBeside};
use lidar_noise::sensor::HDL64E_S2;
use std::path::Path;

/// A calibration whose rectification is the identity and whose Velodyne-to-camera turn
/// is the axes' swap alone: camera x = -velo y, y = -velo z, z = velo x.
const CALIB: &str = "P0: 1 0 0 0 0 1 0 0 0 0 1 0\n\
R0_rect: 1 0 0 0 1 0 0 0 1\n\
Tr_velo_to_cam: 0 -1 0 0 0 0 -1 0 1 0 0 0\n";

fn point(x: f32, y: f32, z: f32) -> CloudPoint {
    CloudPoint {
        x,
        y,
        z,
        intensity: 0.5,
        ring: None,
        time: None,
    }
}

#[test]
fn label_2_boxes_hold_the_points_inside_them_turned_by_rotation_y() {
    // A car 1.5 m high, 1.6 wide, 4 long, bottom centre 10 m ahead at camera y 1.7 (1.7 m
    // below the camera), and a rotated copy 30 m ahead; DontCare is no object.
    let text = "Car 0.00 0 -1.58 587 175 666 250 1.5 1.6 4.0 0.0 1.7 10.0 0.0\n\
                DontCare -1 -1 -10 503 169 590 190 -1 -1 -1 -1000 -1000 -1000 -10\n\
                Pedestrian 0.00 0 0 0 0 0 0 1.5 1.6 4.0 0.0 1.7 30.0 1.5707963\n";
    let boxes = parse_label2(text, Path::new("label_2/000000.txt")).unwrap();
    assert_eq!(boxes.len(), 2);
    assert_eq!(boxes[1].kind, "Pedestrian");
    let calib = parse_calib(CALIB, Path::new("calib/000000.txt")).unwrap();
    let pts = [
        point(10.0, 0.0, -1.0), // inside the car: camera (0, 1, 10)
        point(11.5, 0.0, -1.0), // 1.5 m past its centre along z: outside (half width 0.8)
        point(10.0, 1.9, -1.0), // 1.9 m to the side along x: inside (half length 2)
        point(10.0, 0.0, 0.5),  // above its top (camera y -0.5 < 1.7 - 1.5)
        point(31.5, 0.0, -1.0), // turned box: its length lies along z now, inside
        point(30.0, 1.9, -1.0), // turned box: 1.9 m along x, past its half width
    ];
    let t = box_truth(&pts, &boxes, &calib);
    assert_eq!(t.objects, vec![1, -1, 1, -1, 2, -1]);
    assert_eq!(t.classes.get(&2).map(String::as_str), Some("Pedestrian"));
    assert!(t.ground.iter().all(|&g| !g), "boxes say nothing of ground");
}

#[test]
fn bad_label_2_and_calib_files_name_the_file_and_the_line() {
    let e = parse_label2("Car 0 0 0 1 2 3\n", Path::new("x/label_2/000003.txt"))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("x/label_2/000003.txt") && e.contains("line 1") && e.contains("7 values"),
        "{e}"
    );
    let e = parse_label2(
        "Car 0 0 0 1 2 3 4 1.5 1.6 nan 0 1.7 10 0\n",
        Path::new("l.txt"),
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("line 1, value 11") && e.contains("not a finite number"),
        "{e}"
    );
    let e = parse_calib(
        "R0_rect: 1 0 0 0 1 0 0 0 1\n",
        Path::new("calib/000001.txt"),
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("calib/000001.txt") && e.contains("no Tr_velo_to_cam line"),
        "{e}"
    );
    let e = parse_calib(
        "R0_rect: 1 0 0 0 1 0 0 0 1\nTr_velo_to_cam: 1 2 3\n",
        Path::new("c.txt"),
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("line 2: Tr_velo_to_cam has 3 values, not 12"),
        "{e}"
    );
}

#[test]
fn labels_are_found_where_the_datasets_put_them() {
    let dir = tempfile::tempdir().unwrap();
    let seq = dir.path().join("sequences/00");
    std::fs::create_dir_all(seq.join("velodyne")).unwrap();
    std::fs::create_dir_all(seq.join("labels")).unwrap();
    let scan = seq.join("velodyne/000007.bin");
    std::fs::write(&scan, [0u8; 16]).unwrap();
    assert_eq!(labels_beside(&scan), None);
    std::fs::write(seq.join("labels/000007.label"), [0u8; 4]).unwrap();
    assert_eq!(
        labels_beside(&scan),
        Some(LabelsBeside::PerPoint(seq.join("labels/000007.label")))
    );
    // KITTI object layout: label_2 and calib beside velodyne.
    let obj = dir.path().join("training");
    std::fs::create_dir_all(obj.join("velodyne")).unwrap();
    std::fs::create_dir_all(obj.join("label_2")).unwrap();
    let scan = obj.join("velodyne/000003.bin");
    std::fs::write(&scan, [0u8; 16]).unwrap();
    std::fs::write(obj.join("label_2/000003.txt"), "").unwrap();
    assert_eq!(labels_beside(&scan), None, "no calib: no boxes");
    std::fs::create_dir_all(obj.join("calib")).unwrap();
    std::fs::write(obj.join("calib/000003.txt"), CALIB).unwrap();
    let found = labels_beside(&scan).unwrap();
    assert!(matches!(found, LabelsBeside::Boxes { .. }), "{found:?}");
    let truth = read_truth(&found, &[point(10.0, 0.0, -1.0)]).unwrap();
    assert_eq!(truth.objects, vec![-1]);
    assert!(read_label2(&obj.join("label_2/000003.txt"))
        .unwrap()
        .is_empty());
    assert!(read_calib(&obj.join("calib/000003.txt")).is_ok());
}

/// A street for the HDL-64E mounted 1.73 m up (KITTI's height): flat ground to 40 m and
/// one car-sized block 10 to 14 m ahead, 1.5 m high, 2 m wide. Every beam, 2000 azimuths;
/// returns the points and each point's SemanticKITTI label (road 40, car 10 instance 7).
fn street() -> (Vec<CloudPoint>, Vec<u32>) {
    let (mut pts, mut labels) = (Vec::new(), Vec::new());
    let h = 1.73;
    for &el in HDL64E_S2.elevation_deg {
        for k in 0..2000 {
            let az = f64::from(k) * 360.0 / 2000.0;
            let (se, ce) = el.to_radians().sin_cos();
            let (sa, ca) = az.to_radians().sin_cos();
            let d = [ce * ca, -ce * sa, se];
            // The block: x in [10, 14], y in [-1, 1], z in [-h, -h + 1.5] (slabs).
            let (mut t0, mut t1) = (0.0f64, f64::MAX);
            for (axis, lo, hi) in [(0, 10.0, 14.0), (1, -1.0, 1.0), (2, -h, -h + 1.5)] {
                if d[axis] == 0.0 {
                    t0 = f64::MAX;
                    continue;
                }
                let (a, b) = (lo / d[axis], hi / d[axis]);
                t0 = t0.max(a.min(b));
                t1 = t1.min(a.max(b));
            }
            let (t, label) = if t0 <= t1 && t0 > 0.0 {
                (t0, (7u32 << 16) | 10)
            } else if se < 0.0 && h / -se * ce < 40.0 {
                (h / -se, 40)
            } else {
                continue;
            };
            pts.push(point(
                (t * d[0]) as f32,
                (t * d[1]) as f32,
                (t * d[2]) as f32,
            ));
            labels.push(label);
        }
    }
    (pts, labels)
}

#[test]
fn a_labelled_scan_scores_ground_and_its_object_against_the_labels() {
    let dir = tempfile::tempdir().unwrap();
    let seq = dir.path().join("00");
    std::fs::create_dir_all(seq.join("velodyne")).unwrap();
    std::fs::create_dir_all(seq.join("labels")).unwrap();
    let (pts, labels) = street();
    let scan = seq.join("velodyne/000000.bin");
    let bytes: Vec<u8> = pts
        .iter()
        .flat_map(|p| {
            [p.x, p.y, p.z, p.intensity]
                .into_iter()
                .flat_map(f32::to_le_bytes)
        })
        .collect();
    std::fs::write(&scan, bytes).unwrap();
    let label_bytes: Vec<u8> = labels.iter().flat_map(|l| l.to_le_bytes()).collect();
    std::fs::write(seq.join("labels/000000.label"), label_bytes).unwrap();

    let cloud = read_file(&scan, &ReadOptions::default()).unwrap();
    let placed = to_returns(
        &cloud.points,
        &HDL64E_S2,
        &ReturnsOptions {
            intensity_scale: cloud.info.intensity_scale,
            ..ReturnsOptions::default()
        },
        "scan",
    )
    .unwrap();
    let config = Path::new(env!("CARGO_MANIFEST_DIR")).join("configs/clear.toml");
    let (config, _) = lidar_noise::config::Config::load(Some(&config), &[], None).unwrap();
    let r = Pipeline::new(&config)
        .process(Frame {
            index: 0,
            partial: false,
            returns: placed.returns,
        })
        .unwrap();
    let found = labels_beside(&scan).expect("labels/000000.label beside velodyne/");
    let truth = read_truth(&found, &cloud.points).unwrap();
    let s = score(
        &r,
        &truth,
        &placed.order,
        config.cluster.min_points,
        &[0.0, 10.0, 20.0],
        "t",
    );
    let ground = labels.iter().filter(|&&l| l == 40).count();
    assert_eq!(s.ground_points, ground);
    // Flat ground and one block: a ground method worth the name finds nearly all of it.
    let (p, rc) = (s.ground_precision.unwrap(), s.ground_recall.unwrap());
    assert!(p > 0.95 && rc > 0.9, "ground precision {p}, recall {rc}");
    // The block is one object, 10 to 14 m away (its centroid past 10 m), detected.
    assert_eq!(s.objects.objects, 1, "{s:?}");
    assert_eq!(s.objects.detected, 1, "{s:?}");
    assert_eq!(s.bands[1].objects, 1, "{s:?}");
    assert_eq!(s.classes.len(), 1);
    assert_eq!(s.classes[0].kind, "car");
    // A label file for another scan is refused naming both counts.
    std::fs::write(seq.join("labels/000000.label"), [40u8, 0, 0, 0]).unwrap();
    let e = read_truth(&found, &cloud.points).unwrap_err().to_string();
    assert!(
        e.contains("1 labels") && e.contains(&format!("{} points", pts.len())),
        "{e}"
    );
}

/// `run` on a nuScenes scan with `--labels` (nuScenes-lidarseg: one class byte a point)
/// writes the scores to truth.json beside summary.json.
#[test]
fn run_scores_a_labelled_scan_into_truth_json() {
    let dir = tempfile::tempdir().unwrap();
    // The street again, on the HDL-32E's beams (ring from the beam's rank), 1000 azimuths.
    let model = &lidar_noise::sensor::HDL32E;
    let rings = model.rings();
    let (mut bytes, mut classes) = (Vec::new(), Vec::new());
    for (laser, &el) in model.elevation_deg.iter().enumerate() {
        for k in 0..1000 {
            let az = f64::from(k) * 0.36;
            let (se, ce) = el.to_radians().sin_cos();
            let (sa, ca) = az.to_radians().sin_cos();
            let (t, class) = if se < 0.0 && 1.8 / -se * ce < 40.0 {
                (1.8 / -se, 24u8) // flat.driveable_surface
            } else {
                (30.0, 28u8) // static.manmade: a wall around at 30 m
            };
            for v in [
                t * ce * ca,
                -t * ce * sa,
                t * se,
                50.0,
                f64::from(rings[laser]),
            ] {
                bytes.extend_from_slice(&(v as f32).to_le_bytes());
            }
            classes.push(class);
        }
    }
    let scan = dir.path().join("n0__LIDAR_TOP__1.pcd.bin");
    std::fs::write(&scan, &bytes).unwrap();
    let labels = dir.path().join("tok_lidarseg.bin");
    std::fs::write(&labels, &classes).unwrap();
    let out = dir.path().join("out");
    let config = Path::new(env!("CARGO_MANIFEST_DIR")).join("configs/clear.toml");
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_lidar-noise"))
        .arg("run")
        .arg(&scan)
        .arg("--labels")
        .arg(&labels)
        .arg("-c")
        .arg(&config)
        .arg("-o")
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let found: Vec<_> = walk(&out)
        .into_iter()
        .filter(|p| p.file_name().is_some_and(|n| n == "truth.json"))
        .collect();
    assert_eq!(found.len(), 1, "{found:?}");
    let v: serde_json::Value = serde_json::from_slice(&std::fs::read(&found[0]).unwrap()).unwrap();
    let ground = classes.iter().filter(|&&c| c == 24).count() as u64;
    assert_eq!(v["ground_points"], ground);
    assert!(v["ground_recall"].as_f64().unwrap() > 0.9, "{v}");
    assert!(v["ground_precision"].as_f64().unwrap() > 0.9, "{v}");
    assert!(v["labels"].as_str().unwrap().ends_with("tok_lidarseg.bin"));
    // Labels of another scan: refused naming both counts, nothing written.
    std::fs::write(&labels, &classes[..10]).unwrap();
    let out2 = dir.path().join("out2");
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_lidar-noise"))
        .arg("run")
        .arg(&scan)
        .arg("--labels")
        .arg(&labels)
        .arg("-o")
        .arg(&out2)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(
        err.contains("10 labels") && err.contains(&format!("{} points", classes.len())),
        "{err}"
    );
    assert!(!out2.exists());
}

fn walk(dir: &Path) -> Vec<std::path::PathBuf> {
    let mut out = Vec::new();
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() {
            out.extend(walk(&p));
        } else {
            out.push(p);
        }
    }
    out
}
