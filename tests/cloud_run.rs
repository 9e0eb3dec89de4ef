//! `run` on point-cloud scans (issue 31, "Point clouds in and out"): a scan becomes one
//! frame of HDL-32E returns and goes through the same pipeline as a capture's frame. The
//! scans are built here from a decoded frame of the crossroad fixture (float32 x y z
//! intensity ring, the nuScenes `.pcd.bin` layout), so the capture's own run is the
//! reference.

mod common;

use common::{bin2, crossroad};
use lidar_noise::frame::Frame;
use lidar_noise::hdl32e::frames::{DecoderOptions, FrameReader};
use std::path::{Path, PathBuf};

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

/// The frame as a KITTI `.bin`: x y z reflectance 0-1, float32 little-endian.
fn write_kitti_bin(frame: &Frame, path: &Path) {
    let bytes: Vec<u8> = frame
        .returns
        .iter()
        .flat_map(|r| {
            [r.x, r.y, r.z, f32::from(r.intensity) / 255.0]
                .into_iter()
                .flat_map(f32::to_le_bytes)
        })
        .collect();
    std::fs::write(path, bytes).unwrap();
}

fn totals(summary: &Path) -> serde_json::Value {
    let v: serde_json::Value = serde_json::from_slice(&std::fs::read(summary).unwrap()).unwrap();
    v["totals"]["noise"].clone()
}

#[test]
fn a_scan_gives_the_same_fates_as_the_capture_frame_it_came_from() {
    let dir = tempfile::tempdir().unwrap();
    let scan = dir.path().join("scan.pcd.bin");
    write_pcd_bin(&fixture_frame(1), &scan);
    // Every config whose stages act on recorded returns only (the ones that also fill empty
    // firing slots see the scan's firing grid, not the capture's packets: see the manual).
    for config in ["clear", "occlusion", "paper", "rain", "pdiagram-sensor"] {
        let c = format!("configs/{config}.toml");
        let out = dir.path().join(format!("cloud-{config}"));
        let cap = dir.path().join(format!("cap-{config}"));
        bin2()
            .args(["--quiet", "run"])
            .arg(&scan)
            .args(["-c", &c, "--rotation-hz", "10", "--no-ply", "-o"])
            .arg(&out)
            .assert()
            .success();
        bin2()
            .args(["--quiet", "run"])
            .arg(crossroad())
            .args(["--frames", "1", "-c", &c, "--no-ply", "-o"])
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
    assert!(out.join("t/frame_00000.ply").exists());
}

/// Runs `args` on `scan`, expects exit 1 with `what` in the message and no output folder.
fn refused(scan: &PathBuf, args: &[&str], what: &str) {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let o = bin2()
        .arg("run")
        .arg(scan)
        .args(args)
        .arg("-o")
        .arg(&out)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(err.contains(what), "{err}");
    assert!(!out.exists(), "{} was written", out.display());
}

#[test]
fn what_a_scan_cannot_do_is_refused_before_anything_is_written() {
    let dir = tempfile::tempdir().unwrap();
    let frame = fixture_frame(1);
    let scan = dir.path().join("s.pcd.bin");
    write_pcd_bin(&frame, &scan);
    refused(&scan, &["--pcap-out"], "--pcap-out re-encodes a capture");
    refused(
        &scan,
        &["--chunk-frames", "2"],
        "--chunk-frames splits captures",
    );
    refused(&scan, &["--sensor", "vlp16"], "--sensor vlp16");
    refused(&scan, &["--frames", "3"], "a point-cloud scan is one frame");
    // KITTI scans come from an HDL-64E: said, not guessed.
    let kitti = dir.path().join("000000.bin");
    write_kitti_bin(&frame, &kitti);
    refused(&kitti, &[], "HDL-64E");
    // A damaged file and a ring the sensor does not have: the file and the place.
    let cut = dir.path().join("cut.pcd.bin");
    std::fs::write(&cut, &std::fs::read(&scan).unwrap()[..47]).unwrap();
    refused(&cut, &[], "cut.pcd.bin");
    let ring = dir.path().join("ring.pcd.bin");
    let mut b = std::fs::read(&scan).unwrap();
    b[16..20].copy_from_slice(&40f32.to_le_bytes());
    std::fs::write(&ring, &b).unwrap();
    refused(&ring, &[], "ring 40");
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
