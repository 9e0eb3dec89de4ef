//! `run` on point-cloud scans (issue 31, "Point clouds in and out"): a scan becomes one
//! frame of HDL-32E returns and goes through the same pipeline as a capture's frame. The
//! scans are built here from a decoded frame of the crossroad fixture (float32 x y z
//! intensity ring, the nuScenes `.pcd.bin` layout), so the capture's own run is the
//! reference.

use crate::common;

use common::{bin2, crossroad, refused_scan};
use lidar_noise::frame::Frame;
use lidar_noise::sensor::frames::{DecoderOptions, FrameReader};
use std::path::Path;

/// Frame `index` of the crossroad fixture, decoded as `run` decodes it.
fn fixture_frame(index: u32) -> Frame {
    let reader = FrameReader::open(&crossroad(), &DecoderOptions::default()).unwrap();
    reader
        .map(Result::unwrap)
        .find(|f| f.index == index)
        .expect("the fixture has the frame")
}

/// The frame as a nuScenes `.pcd.bin`: x y z intensity ring, float32 little-endian.
fn write_pcd_bin(frame: &Frame, path: &Path) {
    let bytes: Vec<u8> = frame
        .returns
        .iter()
        .flat_map(|r| {
            [r.x, r.y, r.z, f32::from(r.intensity), f32::from(r.ring)]
                .into_iter()
                .flat_map(f32::to_le_bytes)
        })
        .collect();
    std::fs::write(path, bytes).unwrap();
}

/// The frame as a KITTI `.bin`.
fn write_kitti_bin(frame: &Frame, path: &Path) {
    std::fs::write(path, common::kitti_bytes(frame)).unwrap();
}

fn totals(summary: &Path) -> serde_json::Value {
    let v: serde_json::Value = serde_json::from_slice(&std::fs::read(summary).unwrap()).unwrap();
    v["totals"]["noise"].clone()
}

/// The frame as a CSV with each point's time (seconds), which places it by time.
fn write_timed_csv(frame: &Frame, path: &Path) {
    let mut text = String::from("x,y,z,intensity,ring,time\n");
    for r in &frame.returns {
        text.push_str(&format!(
            "{},{},{},{},{},{}\n",
            r.x, r.y, r.z, r.intensity, r.ring, r.time
        ));
    }
    std::fs::write(path, text).unwrap();
}

#[test]
fn a_scan_gives_the_same_fates_as_the_capture_frame_it_came_from() {
    let dir = tempfile::tempdir().unwrap();
    let scan = dir.path().join("scan.pcd.bin");
    write_pcd_bin(&fixture_frame(1), &scan);
    // The configs whose stages act on recorded returns only: those that also fill empty
    // firing slots need the scan on a grid of the capture's own rate (tested in
    // `tests/integration/cloud_equivalence.rs`, and by time in `a_scan_with_times_is_placed_by_them`).
    for config in ["clear", "occlusion", "paper", "rain", "pdiagram-sensor"] {
        let c = format!("configs/{config}.toml");
        let out = dir.path().join(format!("cloud-{config}"));
        let cap = dir.path().join(format!("cap-{config}"));
        // The threshold detection: the probabilistic one draws per frame, and the scan
        // runs as frame 0 where the capture's frame is frame 1 (other streams).
        let threshold = "detection.model=\"threshold\"";
        bin2()
            .args(["--quiet", "run"])
            .arg(&scan)
            .args([
                "-c",
                &c,
                "--set",
                threshold,
                "--rotation-hz",
                "10",
                "--no-ply",
                "-o",
            ])
            .arg(&out)
            .assert()
            .success();
        bin2()
            .args(["--quiet", "run"])
            .arg(crossroad())
            .args([
                "--frames", "1", "-c", &c, "--set", threshold, "--no-ply", "-o",
            ])
            .arg(&cap)
            .assert()
            .success();
        // Named after the scan's token, not "scan.pcd".
        let a = totals(&out.join("scan").join("summary.json"));
        let b = totals(&cap.join("crossroad").join("summary.json"));
        for key in [
            "returns_in",
            "returns_out",
            "dropped",
            "spurious",
            "dropped_by_laser",
        ] {
            assert_eq!(a[key], b[key], "{config}: {key}");
        }
    }
}

/// Fog at 300 m with the optics before issue 50 (20 ns pulse, 25 mm apertures, 5 mrad
/// field) and the threshold detection, without range noise: every empty firing slot gets
/// a fog echo and no draw decides anything, so its counts follow from where the points
/// were placed alone (a scan runs as frame 0, the capture's frame is frame 1: their
/// random streams differ).
const FOG: &str = "seed = 42\n[[noise]]\ntype = \"fog\"\nvisibility_m = 300.0\ntau_h_ns = 20\ntx_aperture_mm = 25\nrx_aperture_mm = 25\nrx_fov_mrad = 5\n[detection]\nmodel = \"threshold\"\n";

#[test]
fn a_scan_with_times_is_placed_by_them() {
    let dir = tempfile::tempdir().unwrap();
    let config = dir.path().join("fog.toml");
    std::fs::write(&config, FOG).unwrap();
    let run = |input: &Path, extra: &[&str], out: &Path| {
        let extra: Vec<&str> = extra.iter().copied().chain(["--no-ply"]).collect();
        common::run_ok(input, &extra, &config, out);
    };
    let summary = |path: &Path| -> serde_json::Value {
        serde_json::from_slice(&std::fs::read(path).unwrap()).unwrap()
    };
    let scan = dir.path().join("timed.csv");
    write_timed_csv(&fixture_frame(1), &scan);
    let (out, cap) = (dir.path().join("cloud"), dir.path().join("cap"));
    run(&scan, &[], &out);
    run(&crossroad(), &["--frames", "1"], &cap);
    let v = summary(&out.join("timed").join("summary.json"));
    assert_eq!(v["capture_summary"]["placed_by_time"], "s");
    assert_eq!(v["capture_summary"]["firings"], 1085);
    let a = &v["totals"]["noise"];
    let b = totals(&cap.join("crossroad").join("summary.json"));
    for key in ["returns_in", "returns_out", "dropped", "spurious"] {
        assert_eq!(a[key], b[key], "{key}");
    }
    // Without the time column the same points are placed by azimuth, on the default
    // 10 Hz grid: twice the capture's firings, so other empty slots and other echoes.
    let text = std::fs::read_to_string(&scan).unwrap();
    let untimed: String = text
        .lines()
        .map(|l| l.rsplit_once(',').unwrap().0.to_string() + "\n")
        .collect();
    let scan2 = dir.path().join("untimed.csv");
    std::fs::write(&scan2, untimed).unwrap();
    let out2 = dir.path().join("cloud2");
    run(&scan2, &[], &out2);
    let v = summary(&out2.join("untimed").join("summary.json"));
    assert_eq!(
        v["capture_summary"]["placed_by_time"],
        serde_json::Value::Null
    );
    assert_eq!(v["capture_summary"]["firings"], 2170);
    let added = &v["totals"]["noise"]["spurious"]["added"];
    assert_ne!(added, &b["spurious"]["added"]);
}

#[test]
fn a_scan_with_times_is_written_back_with_them() {
    let dir = tempfile::tempdir().unwrap();
    let config = dir.path().join("fog.toml");
    std::fs::write(&config, FOG).unwrap();
    let scan = dir.path().join("timed.csv");
    write_timed_csv(&fixture_frame(1), &scan);
    let out = dir.path().join("out");
    common::run_ok(&scan, &[], &config, &out);
    let input: Vec<String> = std::fs::read_to_string(&scan)
        .unwrap()
        .lines()
        .map(String::from)
        .collect();
    let written = std::fs::read_to_string(out.join("timed/frame_00000.csv")).unwrap();
    let fates = std::fs::read_to_string(out.join("timed/frame_00000.fate.csv")).unwrap();
    let mut lines = written.lines();
    assert_eq!(lines.next(), Some("x,y,z,intensity,ring,time"));
    let (mut same, mut added) = (0, Vec::new());
    for (line, fate) in lines.zip(fates.lines().skip(1)) {
        let point: i64 = fate.split(',').next().unwrap().parse().unwrap();
        let time = line.rsplit(',').next().unwrap();
        if point >= 0 {
            // Fog changes no time: each recorded point's time is its input's, as written.
            let stored = input[point as usize + 1].rsplit(',').next().unwrap();
            assert_eq!(time, stored, "point {point}");
            same += 1;
        } else {
            added.push(time.parse::<f64>().unwrap());
        }
    }
    assert!(same > 20_000 && !added.is_empty(), "{same} {}", added.len());
    // An added echo's time lies in the input's span (the frame's own times).
    let span: Vec<f64> = input[1..]
        .iter()
        .map(|l| l.rsplit(',').next().unwrap().parse().unwrap())
        .collect();
    let (lo, hi) = span
        .iter()
        .fold((f64::MAX, f64::MIN), |(a, b), &t| (a.min(t), b.max(t)));
    assert!(added.iter().all(|&t| t >= lo - 1e-4 && t <= hi + 1e-4));
    // The noisy scan run again is placed by its times, on the same firings.
    let again = dir.path().join("again");
    common::run_ok(&out.join("timed/frame_00000.csv"), &[], &config, &again);
    let v: serde_json::Value =
        serde_json::from_slice(&std::fs::read(again.join("frame_00000/summary.json")).unwrap())
            .unwrap();
    assert_eq!(v["capture_summary"]["placed_by_time"], "s");
    assert_eq!(v["capture_summary"]["firings"], 1085);
}

#[test]
fn the_summary_says_how_the_scan_was_placed_on_the_sensor() {
    let dir = tempfile::tempdir().unwrap();
    let scan = dir.path().join("t.pcd.bin");
    let frame = fixture_frame(1);
    write_pcd_bin(&frame, &scan);
    let out = dir.path().join("out");
    bin2()
        .args(["--quiet", "run"])
        .arg(&scan)
        .arg("-o")
        .arg(&out)
        .assert()
        .success();
    let v: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("t/summary.json")).unwrap()).unwrap();
    let s = &v["capture_summary"];
    assert_eq!(s["format"], "nuScenes .pcd.bin");
    assert_eq!(s["sensor"], "HDL-32E");
    assert_eq!(s["points"], frame.returns.len());
    assert_eq!(s["ring_field"], true);
    // nuScenes spins at 20 Hz: half the HDL-32E's 2,170 firings a turn at 10 Hz.
    assert_eq!(s["rotation_hz"], 20.0);
    assert_eq!(s["firings"], 1085);
    assert_eq!(s["placed_by_time"], serde_json::Value::Null);
    // Written back in its own format by default.
    assert!(out.join("t/frame_00000.pcd.bin").exists());
}

#[test]
fn what_a_scan_cannot_do_is_refused_before_anything_is_written() {
    let dir = tempfile::tempdir().unwrap();
    let frame = fixture_frame(1);
    let scan = dir.path().join("s.pcd.bin");
    write_pcd_bin(&frame, &scan);
    refused_scan(&scan, &["--pcap-out"], "--pcap-out re-encodes a capture");
    refused_scan(
        &scan,
        &["--chunk-frames", "2"],
        "--chunk-frames splits captures",
    );
    // The paper's occlusion names laser 30, which a VLP-16 does not have; without it,
    // the HDL-32E's rings 16-31 are what the VLP-16 cannot have.
    refused_scan(&scan, &["--sensor", "vlp16"], "the VLP-16 (16 lasers)");
    let clear = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("configs/clear.toml");
    let clear = clear.to_str().unwrap();
    refused_scan(&scan, &["--sensor", "vlp16", "-c", clear], "ring 16");
    refused_scan(&scan, &["--frames", "3"], "a point-cloud scan is one frame");
    // A damaged file and a ring the sensor does not have: the file and the place.
    let cut = dir.path().join("cut.pcd.bin");
    std::fs::write(&cut, &std::fs::read(&scan).unwrap()[..47]).unwrap();
    refused_scan(&cut, &[], "cut.pcd.bin");
    let ring = dir.path().join("ring.pcd.bin");
    let mut b = std::fs::read(&scan).unwrap();
    b[16..20].copy_from_slice(&40f32.to_le_bytes());
    std::fs::write(&ring, &b).unwrap();
    refused_scan(&ring, &[], "ring 40");
}

#[test]
fn a_kitti_scan_said_to_be_from_an_hdl32e_runs() {
    let dir = tempfile::tempdir().unwrap();
    let frame = fixture_frame(1);
    let kitti = dir.path().join("000001.bin");
    write_kitti_bin(&frame, &kitti);
    let out = dir.path().join("out");
    bin2()
        .args(["--quiet", "run"])
        .arg(&kitti)
        .args(["--sensor", "hdl32e", "-o"])
        .arg(&out)
        .assert()
        .success();
    let v: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("000001/summary.json")).unwrap()).unwrap();
    // No ring field: lasers from the elevation; reflectance 0-1 scaled to the byte.
    assert_eq!(v["capture_summary"]["ring_field"], false);
    assert_eq!(v["capture_summary"]["intensity_scale"], "0-1, times 255");
    assert_eq!(v["totals"]["noise"]["returns_in"], frame.returns.len());
}

/// The float32 records of a scan file (`fields` floats a point).
fn floats(path: &Path, fields: usize) -> Vec<Vec<f32>> {
    let bytes = std::fs::read(path).unwrap();
    assert_eq!(bytes.len() % (4 * fields), 0);
    bytes
        .chunks_exact(4 * fields)
        .map(|c| {
            c.chunks_exact(4)
                .map(|v| f32::from_le_bytes(v.try_into().unwrap()))
                .collect()
        })
        .collect()
}

#[test]
fn a_scan_is_written_back_in_its_own_format_in_input_order_with_its_fates() {
    let dir = tempfile::tempdir().unwrap();
    let scan = dir.path().join("s.pcd.bin");
    write_pcd_bin(&fixture_frame(1), &scan);
    let input = floats(&scan, 5);
    let out = dir.path().join("out");
    bin2()
        .args(["--quiet", "run"])
        .arg(&scan)
        .args(["-c", "configs/clear.toml", "-o"])
        .arg(&out)
        .assert()
        .success();
    let written = floats(&out.join("s/frame_00000.pcd.bin"), 5);
    assert!(!out.join("s/frame_00000.ply").exists());
    let fates = std::fs::read_to_string(out.join("s/frame_00000.fate.csv")).unwrap();
    let mut lines = fates.lines();
    assert_eq!(
        lines.next(),
        Some("point,fate,cause,range_clean,ground,cluster")
    );
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    assert_eq!(rows.len(), written.len());
    let kept = totals(&out.join("s/summary.json"))["returns_out"]
        .as_u64()
        .unwrap();
    assert_eq!(written.len() as u64, kept);
    // Clear air keeps every recorded return but those under the minimum range (issue 50:
    // detection applies to what the stages change).
    let dropped = &totals(&out.join("s/summary.json"))["dropped"];
    assert_eq!(dropped["below_power"], 0);
    assert_eq!(
        written.len() as u64 + dropped["below_min_range"].as_u64().unwrap(),
        input.len() as u64
    );
    // No noise in clear.toml: every kept point is its input point, bit for bit, and the
    // points keep the input's order.
    let mut last = -1i64;
    for (row, p) in rows.iter().zip(&written) {
        let i: i64 = row[0].parse().unwrap();
        assert!(i > last, "input order: {i} after {last}");
        last = i;
        assert_eq!(row[1], "0", "fate kept");
        assert_eq!(p, &input[i as usize], "point {i}");
    }
    // --format ply writes the usual frame file instead.
    let ply = dir.path().join("ply");
    bin2()
        .args(["--quiet", "run"])
        .arg(&scan)
        .args(["--format", "ply", "-o"])
        .arg(&ply)
        .assert()
        .success();
    assert!(ply.join("s/frame_00000.ply").exists());
    assert!(!ply.join("s/frame_00000.pcd.bin").exists());
}

#[test]
fn a_kitti_scan_comes_back_as_kitti_with_reflectance_from_0_to_1() {
    let dir = tempfile::tempdir().unwrap();
    let frame = fixture_frame(1);
    let kitti = dir.path().join("000002.bin");
    write_kitti_bin(&frame, &kitti);
    let input = floats(&kitti, 4);
    let out = dir.path().join("out");
    bin2()
        .args(["--quiet", "run"])
        .arg(&kitti)
        .args(["--sensor", "hdl32e", "-c", "configs/clear.toml", "-o"])
        .arg(&out)
        .assert()
        .success();
    let written = floats(&out.join("000002/frame_00000.bin"), 4);
    let fates = std::fs::read_to_string(out.join("000002/frame_00000.fate.csv")).unwrap();
    for (line, p) in fates.lines().skip(1).zip(&written) {
        let i: usize = line.split(',').next().unwrap().parse().unwrap();
        assert_eq!(p, &input[i], "point {i}");
        assert!((0.0..=1.0).contains(&p[3]));
    }
}

#[test]
fn every_format_written_reads_back_as_written() {
    use lidar_noise::cloud::{read_bytes, Format, ReadOptions};
    use lidar_noise::writers::scan::{Scan, ScanPoint};
    use lidar_noise::writers::Output;
    let points: Vec<ScanPoint> = (0..5u16)
        .map(|k| ScanPoint {
            x: 1.5 + f32::from(k),
            y: -2.25,
            z: 0.125 * f32::from(k),
            intensity: (40 * k) as u8,
            ring: 31 - k,
            point: Some(u32::from(k)),
            fate: 0,
            cause: 255,
            range_clean: 1.0,
            ground: 0,
            cluster: -1,
        })
        .collect();
    // Times as a tool stores them: seconds of the epoch, to the nanosecond's f64 step.
    let times: Vec<f64> = (0..5).map(|k| 1.7e9 + 0.1 / 3.0 * f64::from(k)).collect();
    for (format, name, timed) in [
        (Format::Kitti, "a.bin", false),
        (Format::NuScenes, "a.pcd.bin", false),
        (Format::Pcd, "a.pcd", false),
        (Format::Csv, "a.csv", false),
        (Format::Pcd, "t.pcd", true),
        (Format::Csv, "t.csv", true),
    ] {
        let mut bytes = Vec::new();
        Scan {
            format,
            points: &points,
            times: timed.then_some(&times[..]),
        }
        .write_to(&mut bytes)
        .unwrap();
        let cloud = read_bytes(&bytes, Path::new(name), &ReadOptions::default()).unwrap();
        assert_eq!(cloud.info.format, format);
        assert_eq!(cloud.points.len(), points.len());
        for (got, want) in cloud.points.iter().zip(&points) {
            assert_eq!((got.x, got.y, got.z), (want.x, want.y, want.z), "{name}");
            let intensity = if format == Format::Kitti {
                got.intensity * 255.0
            } else {
                got.intensity
            };
            assert!(
                (intensity - f32::from(want.intensity)).abs() < 1e-3,
                "{name}"
            );
            if format != Format::Kitti {
                assert_eq!(got.ring, Some(want.ring), "{name}");
            }
        }
        let got: Vec<Option<f64>> = cloud.points.iter().map(|p| p.time).collect();
        let want: Vec<Option<f64>> = times.iter().map(|&t| timed.then_some(t)).collect();
        assert_eq!(got, want, "{name}");
    }
}
