//! `--format las|laz`: the files read back with the `las` crate hold every field of the
//! PLY written by the same run, value for value.

use crate::common;

use crate::common::bin;
use std::collections::HashMap;
use std::path::Path;

fn run(out: &Path, extra: &[&str]) {
    bin()
        .env("RAYON_NUM_THREADS", "2")
        .args(["--quiet", "run"])
        .arg(common::fixtures().join("crossroad.pcap"))
        .args(["--seed", "3", "--frames", "0", "-o"])
        .arg(out)
        .args(extra)
        .assert()
        .success();
}

/// An ASCII PLY as columns of numbers by property name (every property is a float or a
/// small integer, so parsing as f32 is exact; widened to f64 for comparison).
fn read_ascii_ply(path: &Path) -> HashMap<String, Vec<f64>> {
    let text = std::fs::read_to_string(path).unwrap();
    let (header, body) = text.split_once("end_header\n").unwrap();
    let names: Vec<String> = header
        .lines()
        .filter_map(|l| l.strip_prefix("property "))
        .map(|l| l.split_whitespace().nth(1).unwrap().to_string())
        .collect();
    let mut cols: HashMap<String, Vec<f64>> = names.iter().map(|n| (n.clone(), vec![])).collect();
    for line in body.lines() {
        for (name, v) in names.iter().zip(line.split_whitespace()) {
            let v: f32 = v.parse().unwrap();
            cols.get_mut(name).unwrap().push(f64::from(v));
        }
    }
    cols
}

/// A LAS/LAZ file: header, points, and the extra dimensions decoded by the names and
/// types of its Extra Bytes descriptors.
struct LasFile {
    header: las::Header,
    points: Vec<las::Point>,
    extra: HashMap<String, Vec<f64>>,
    extra_names: Vec<String>,
}

fn read_las(path: &Path) -> LasFile {
    let mut reader = las::Reader::from_path(path).unwrap();
    let header = reader.header().clone();
    let points: Vec<las::Point> = reader
        .read_all()
        .unwrap()
        .points()
        .map(Result::unwrap)
        .collect();
    let vlr = header
        .vlrs()
        .iter()
        .find(|v| v.user_id == "LASF_Spec" && v.record_id == 4)
        .expect("an Extra Bytes VLR");
    assert_eq!(vlr.data.len() % 192, 0);
    let mut dims = Vec::new();
    for d in vlr.data.chunks(192) {
        let name: String = d[4..36]
            .iter()
            .take_while(|&&b| b != 0)
            .map(|&b| b as char)
            .collect();
        dims.push((name, d[2]));
    }
    let mut extra: HashMap<String, Vec<f64>> = HashMap::new();
    for p in &points {
        let mut at = 0;
        for (name, ty) in &dims {
            let b = &p.extra_bytes[at..];
            let (v, n) = match ty {
                1 => (f64::from(b[0]), 1),
                6 => (f64::from(i32::from_le_bytes(b[..4].try_into().unwrap())), 4),
                9 => (f64::from(f32::from_le_bytes(b[..4].try_into().unwrap())), 4),
                t => panic!("unexpected data type {t} of {name}"),
            };
            extra.entry(name.clone()).or_default().push(v);
            at += n;
        }
        assert_eq!(
            at,
            p.extra_bytes.len(),
            "descriptors cover every extra byte"
        );
    }
    LasFile {
        header,
        points,
        extra,
        extra_names: dims.into_iter().map(|(n, _)| n).collect(),
    }
}

#[test]
fn las_and_laz_hold_every_field_of_the_ply() {
    let tmp = tempfile::tempdir().unwrap();
    let (ply_dir, las_dir, laz_dir) = (
        tmp.path().join("ply"),
        tmp.path().join("las"),
        tmp.path().join("laz"),
    );
    run(&ply_dir, &["--keep-dropped", "--ascii"]);
    run(&las_dir, &["--keep-dropped", "--format", "las"]);
    run(&laz_dir, &["--keep-dropped", "--format", "laz"]);
    let ply = read_ascii_ply(&ply_dir.join("crossroad/frame_00000.ply"));
    let las = read_las(&las_dir.join("crossroad/frame_00000.las"));
    let laz = read_las(&laz_dir.join("crossroad/frame_00000.laz"));

    let h = &las.header;
    assert_eq!(h.version(), las::Version::new(1, 4));
    assert_eq!(h.point_format().to_u8().unwrap(), 6);
    assert!(!h.point_format().is_compressed);
    assert!(laz.header.point_format().is_compressed);
    assert_eq!(h.transforms().x.scale, 0.001);
    assert_eq!(h.transforms().z.scale, 0.001);
    let names = [
        "ring",
        "laser",
        "azimuth",
        "range",
        "time",
        "range_clean",
        "power",
        "ground",
        "fate",
        "cause",
        "cluster",
    ];
    assert_eq!(las.extra_names, names);

    let n = ply["x"].len();
    assert!(n > 1000, "{n} points");
    assert_eq!(las.points.len(), n);
    assert_eq!(las.points, laz.points, "LAZ decompresses to the LAS points");
    let fates: Vec<f64> = ply["fate"].clone();
    assert!(fates.iter().any(|&f| f > 0.0), "the run drops returns");
    assert!(ply["ground"].contains(&1.0));
    for (i, p) in las.points.iter().enumerate() {
        for (axis, v) in [("x", p.x), ("y", p.y), ("z", p.z)] {
            assert!(
                (v - ply[axis][i]).abs() <= 0.0005 + 1e-9,
                "point {i} {axis}: LAS {v} vs PLY {}",
                ply[axis][i]
            );
        }
        assert_eq!(f64::from(p.intensity), ply["intensity"][i], "point {i}");
        let dt_las = p.gps_time.unwrap() - las.points[0].gps_time.unwrap();
        let dt_ply = ply["time"][i] - ply["time"][0];
        assert!((dt_las - dt_ply).abs() < 2e-6, "point {i} time");
        let class = u8::from(p.classification);
        let dropped = (1.0..=3.0).contains(&fates[i]);
        let expected = if dropped {
            7
        } else if ply["ground"][i] == 1.0 {
            2
        } else {
            1
        };
        assert_eq!(class, expected, "point {i} classification");
        assert_eq!(p.is_withheld, dropped, "point {i} withheld");
        assert_eq!(p.is_synthetic, fates[i] >= 4.0, "point {i} synthetic");
        for name in names {
            assert_eq!(las.extra[name][i], ply[name][i], "point {i} {name}");
        }
    }
    // Provenance travels as a VLR with the PLY's comment lines.
    let prov = h
        .vlrs()
        .iter()
        .find(|v| v.user_id == "lidar-noise")
        .unwrap();
    let text = String::from_utf8(prov.data.clone()).unwrap();
    assert!(text.contains("frame 0"), "{text}");
    assert!(text.contains("seed 3"), "{text}");
}

#[test]
fn las_is_reproducible_and_convert_writes_unclassified_laz() {
    let tmp = tempfile::tempdir().unwrap();
    let (a, b) = (tmp.path().join("a"), tmp.path().join("b"));
    run(&a, &["--format", "las"]);
    run(&b, &["--format", "las"]);
    let file = Path::new("crossroad/frame_00000.las");
    assert_eq!(
        std::fs::read(a.join(file)).unwrap(),
        std::fs::read(b.join(file)).unwrap(),
        "same input and seed give the same bytes"
    );
    let kept = read_las(&a.join(file));
    assert!(!kept.extra_names.contains(&"fate".to_string()));
    assert!(kept.points.iter().all(|p| u8::from(p.classification) != 7));

    let conv = tmp.path().join("conv");
    bin()
        .args(["--quiet", "convert"])
        .arg(common::fixtures().join("crossroad.pcap"))
        .args(["--frames", "0", "--format", "laz", "-o"])
        .arg(&conv)
        .assert()
        .success();
    let c = read_las(&conv.join("frame_00000.laz"));
    assert_eq!(c.extra_names, ["ring", "laser", "azimuth", "range", "time"]);
    assert!(c.points.iter().all(|p| u8::from(p.classification) == 0));
    assert!(c.extra["range"].iter().all(|&r| r > 0.5 && r < 130.0));
    assert!(c.extra["ring"].iter().all(|&r| r < 32.0));

    let bad = bin()
        .args(["convert"])
        .arg(common::fixtures().join("crossroad.pcap"))
        .args(["--format", "las", "--ascii", "-o"])
        .arg(tmp.path().join("bad"))
        .assert()
        .code(1);
    let stderr = String::from_utf8_lossy(&bad.get_output().stderr).into_owned();
    assert!(stderr.contains("--ascii"), "{stderr}");
}

/// Spurious echoes are reported returns: they keep the ground/other classification of the
/// ground step and carry the Synthetic flag; only the returns the sensor dropped are
/// noise (class 7, Withheld). (Before, every echo was class 7, hiding ground and objects:
/// 28,413 points of `adverse-weather` frame 1, 28,409 of them clustered.)
#[test]
fn echoes_keep_their_classification_and_are_flagged_synthetic() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("las");
    let config = Path::new(env!("CARGO_MANIFEST_DIR")).join("configs/adverse-weather.toml");
    run(
        &dir,
        &[
            "--keep-dropped",
            "--format",
            "las",
            "-c",
            config.to_str().unwrap(),
        ],
    );
    let las = read_las(&dir.join("crossroad/frame_00000.las"));
    let (mut echoes, mut echo_ground, mut dropped) = (0, 0, 0);
    for (i, p) in las.points.iter().enumerate() {
        let fate = las.extra["fate"][i];
        let class = u8::from(p.classification);
        let ground = las.extra["ground"][i] == 1.0;
        if fate >= 4.0 {
            echoes += 1;
            echo_ground += usize::from(ground);
            assert!(p.is_synthetic && !p.is_withheld, "point {i}");
            assert_eq!(class, if ground { 2 } else { 1 }, "point {i}");
        } else if fate >= 1.0 {
            dropped += 1;
            assert!(p.is_withheld && !p.is_synthetic && class == 7, "point {i}");
        } else {
            assert!(!p.is_withheld && !p.is_synthetic && class != 7, "point {i}");
        }
        // The frame-relative time, as the PLY gives it.
        let t = las.extra["time"][i];
        let dt = p.gps_time.unwrap() - las.points[0].gps_time.unwrap();
        assert!(
            (t - las.extra["time"][0] - dt).abs() < 2e-6,
            "point {i} time"
        );
    }
    // (Dropped returns are checked on the paper configuration above; fog, rain and snow
    // at these levels drop few or none of the fixture's.)
    assert!(echoes > 100, "{echoes} echoes, {dropped} dropped");
    // Fog echoes lie a metre or two from the sensor, above the ground: class 1.
    assert!(
        echo_ground < echoes,
        "{echo_ground} of {echoes} echoes on the ground"
    );
}
