//! `run` on captures of the other described sensors (issue 31): VLP-16, Puck Hi-Res,
//! VLP-32C, HDL-64E and VLS-128 captures are identified by structure, decoded, cut into
//! sweeps and run through the noise chain built for their lasers. Captures are
//! synthesized here (`synth --sensor`); the real VLP-16 capture of ../shared is used
//! when present. What `run` counts is checked against the returns the library's packet
//! decoder gives packet by packet, and `info` reports the same sensor and returns.
//! `--pcap-out` writes each sensor's packets back: every kept return in its own slot;
//! `convert`, `sweep` and standard input take these captures too.

use crate::common;

use common::{bin2, refused_scan};
use lidar_noise::capture::CaptureReader;
use lidar_noise::sensor::decode::{DualSelect, ModelDecoder};
use lidar_noise::sensor::SensorModel;
use std::path::{Path, PathBuf};

const CROSSROAD: &[&str] = &["--preset", "crossroad"];
/// The crossroad turns at 20 Hz, beyond the HDL-64E's 15 Hz: a random street for it.
const STREET: &[&str] = &["--random", "3"];

/// Every described sensor but the HDL-32E: its `synth` name, model, a scene it can turn
/// at, and a laser to occlude (past 31 where it has more).
const SENSORS: [(&str, &SensorModel, &[&str], u8); 7] = [
    ("vlp16", &lidar_noise::sensor::VLP16, CROSSROAD, 9),
    (
        "puck-hi-res",
        &lidar_noise::sensor::PUCK_HI_RES,
        CROSSROAD,
        2,
    ),
    ("vlp32c", &lidar_noise::sensor::VLP32C, CROSSROAD, 31),
    ("hdl64e s2", &lidar_noise::sensor::HDL64E_S2, STREET, 40),
    ("hdl64e s3", &lidar_noise::sensor::HDL64E_S3, STREET, 63),
    ("vls128", &lidar_noise::sensor::VLS128, CROSSROAD, 100),
    (
        "vls128 fw5.1",
        &lidar_noise::sensor::VLS128_FW51,
        CROSSROAD,
        127,
    ),
];

/// Returns per laser id of every data packet of the capture, decoded one by one.
fn decoded_per_laser(path: &Path, model: &SensorModel) -> Vec<u64> {
    let mut per_laser = vec![0u64; model.lasers];
    for (_, _, laser, _, _) in slots(path, model) {
        per_laser[usize::from(laser)] += 1;
    }
    per_laser
}

/// `run` of `capture` with `config` into `out`, partial sweeps too, reports only.
fn run_every_sweep(capture: &Path, config: &Path, out: &Path) {
    common::run_ok(capture, &["--keep-partial", "--no-ply"], config, out);
}

/// The vertex count a PLY file's header declares.
fn ply_vertices(path: &Path) -> u64 {
    let bytes = std::fs::read(path).unwrap();
    let head = String::from_utf8_lossy(&bytes[..bytes.len().min(4096)]).into_owned();
    head.lines()
        .find_map(|l| l.strip_prefix("element vertex "))
        .map(|n| n.trim().parse().unwrap())
        .unwrap_or_else(|| panic!("{}: no vertex count", path.display()))
}

fn summary(dir: &Path) -> serde_json::Value {
    serde_json::from_slice(&std::fs::read(dir.join("summary.json")).unwrap()).unwrap()
}

fn config(dir: &Path, text: &str) -> PathBuf {
    let p = dir.join("c.toml");
    std::fs::write(&p, text).unwrap();
    p
}

#[test]
fn captures_of_every_other_sensor_run_with_their_own_lasers() {
    let tmp = tempfile::tempdir().unwrap();
    for (name, model, scene, occluded) in SENSORS {
        let capture = common::synth_capture(tmp.path(), name, scene, 2);
        let cfg = config(
            tmp.path(),
            &format!("seed = 2\n[[noise]]\ntype = \"occlusion\"\nlasers = [{occluded}]\n"),
        );
        let out = tmp.path().join(format!("out-{name}"));
        run_every_sweep(&capture, &cfg, &out);
        let dir = std::fs::read_dir(&out)
            .unwrap()
            .map(|e| e.unwrap().path())
            .find(|p| p.is_dir())
            .unwrap();
        let s = summary(&dir);
        assert_eq!(s["capture_summary"]["sensor"], model.name, "{name}");
        // Every decoded return is in a frame, once.
        let want = decoded_per_laser(&capture, model);
        let total: u64 = want.iter().sum();
        assert!(total > 1000, "{name}: {total} returns");
        assert_eq!(s["totals"]["noise"]["returns_in"], total, "{name}");
        let got: Vec<u64> = s["capture_summary"]["returns_per_laser"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_u64().unwrap())
            .collect();
        assert_eq!(got, want, "{name}");
        // `convert` writes every return into its sweep's PLY file.
        let converted = tmp.path().join(format!("convert-{name}"));
        bin2()
            .args(["--quiet", "convert", "--keep-partial"])
            .arg(&capture)
            .arg("-o")
            .arg(&converted)
            .assert()
            .success();
        let vertices: u64 = std::fs::read_dir(&converted)
            .unwrap()
            .map(|e| e.unwrap().path())
            .filter(|p| p.extension().is_some_and(|e| e == "ply"))
            .map(|p| ply_vertices(&p))
            .sum();
        assert_eq!(vertices, total, "{name}: convert");
        // `info` tells the same sensor and counts the same returns.
        let info = bin2()
            .args(["info", "--json"])
            .arg(&capture)
            .assert()
            .success();
        let info: serde_json::Value = serde_json::from_slice(&info.get_output().stdout).unwrap();
        assert_eq!(info["sensor"], model.name, "{name}: {info}");
        assert_eq!(info["returns"], total, "{name}: {info}");
        assert_eq!(info["file"], capture.display().to_string(), "{name}");
        let text = bin2().arg("info").arg(&capture).assert().success();
        let text = String::from_utf8_lossy(&text.get_output().stdout).into_owned();
        assert!(
            text.contains(&format!("sensor        {} (product id", model.name))
                && text.contains(&format!("returns       {total} in all")),
            "{name}: {text}"
        );
        // The chain's slots and counts are the sensor's: laser `occluded` and only it.
        let by_laser = &s["totals"]["noise"]["dropped_by_laser"]["occluded"];
        assert_eq!(by_laser.as_array().unwrap().len(), model.lasers, "{name}");
        for (l, &n) in want.iter().enumerate() {
            let expect = if l == usize::from(occluded) { n } else { 0 };
            assert_eq!(by_laser[l], expect, "{name} laser {l}");
        }
        // Frames are whole turns: two turns of the scene give at most three sweeps, and
        // none but the first and last is partial.
        let frames = s["frames"].as_array().unwrap();
        assert!(
            (2..=3).contains(&frames.len()),
            "{name}: {} frames",
            frames.len()
        );
    }
}

#[test]
fn what_a_capture_of_another_sensor_cannot_do_is_refused_before_writing() {
    let tmp = tempfile::tempdir().unwrap();
    let capture = common::synth_capture(tmp.path(), "vlp16", &["--preset", "crossroad"], 1);
    // The paper's occlusion names laser 30: the VLP-16 has 16.
    refused_scan(&capture, &[], "the VLP-16 (16 lasers)");
    // A VLP-32C capture whose mode byte no firmware writes: the other sensors' reader
    // says what it found, not that only the HDL-32E is decoded.
    let vlp32c = common::synth_capture(tmp.path(), "vlp32c", &["--preset", "crossroad"], 1);
    let mut bytes = std::fs::read(&vlp32c).unwrap();
    let mut at = 24;
    while at + 16 <= bytes.len() {
        let len = u32::from_le_bytes(bytes[at + 8..at + 12].try_into().unwrap()) as usize;
        if len == 42 + 1206 {
            bytes[at + 16 + 42 + 1204] = 0x55;
        }
        at += 16 + len;
    }
    let bad = tmp.path().join("bad-mode.pcap");
    std::fs::write(&bad, bytes).unwrap();
    refused_scan(&bad, &[], "unknown return mode byte 0x55");
}

#[test]
fn the_real_vlp16_capture_runs_as_a_vlp16() {
    let Some(path) = common::shared("negative/vlp16_mrpt.pcap") else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let cfg = config(
        tmp.path(),
        "seed = 1\n[[noise]]\ntype = \"rain\"\nrate_mm_h = 5.0\n",
    );
    let out = tmp.path().join("out");
    run_every_sweep(&path, &cfg, &out);
    let s = summary(&out.join("vlp16_mrpt"));
    assert_eq!(s["capture_summary"]["sensor"], "VLP-16");
    let want = decoded_per_laser(&path, &lidar_noise::sensor::VLP16);
    assert_eq!(s["totals"]["noise"]["returns_in"], want.iter().sum::<u64>());
    assert_eq!(
        s["totals"]["noise"]["dropped_by_laser"]["below_power"]
            .as_array()
            .unwrap()
            .len(),
        16
    );
}

/// Every return of every data packet, decoded one by one: (record, firing slot, laser,
/// raw distance, intensity).
fn slots(path: &Path, model: &SensorModel) -> Vec<(u32, u8, u8, u16, u8)> {
    let dec = ModelDecoder::new(model, true, DualSelect::Both);
    let mut reader = CaptureReader::open(path).unwrap();
    let (mut all, mut out) = (Vec::new(), Vec::new());
    while let Some(d) = reader.next_datagram().unwrap() {
        if !model.layout.is_data_packet(d.payload) {
            continue;
        }
        out.clear();
        dec.decode_packet(d.payload, d.record, 0.0, &mut out)
            .unwrap();
        all.extend(
            out.iter()
                .map(|r| (d.record, r.block, r.laser, r.raw_distance, r.intensity)),
        );
    }
    all
}

#[test]
fn pcap_out_writes_every_other_sensors_packets_back() {
    let tmp = tempfile::tempdir().unwrap();
    for (name, model, scene, occluded) in SENSORS {
        let capture = common::synth_capture(tmp.path(), name, scene, 2);
        let input = slots(&capture, model);
        for (k, text) in [
            "seed = 1\n".to_string(),
            format!("seed = 1\n[[noise]]\ntype = \"occlusion\"\nlasers = [{occluded}]\n"),
        ]
        .iter()
        .enumerate()
        {
            let cfg = tmp.path().join(format!("pcap-out-{k}.toml"));
            std::fs::write(&cfg, text).unwrap();
            let out = tmp.path().join(format!("pcap-out-{name}-{k}"));
            bin2()
                .args(["--quiet", "run", "--keep-partial", "--no-ply", "--pcap-out"])
                .arg(&capture)
                .arg("-c")
                .arg(&cfg)
                .arg("-o")
                .arg(&out)
                .assert()
                .success();
            let dir = std::fs::read_dir(&out)
                .unwrap()
                .map(|e| e.unwrap().path())
                .find(|p| p.is_dir())
                .unwrap();
            let noisy = dir.join("noisy.pcap");
            assert_eq!(
                std::fs::metadata(&noisy).unwrap().len(),
                std::fs::metadata(&capture).unwrap().len(),
                "{name}"
            );
            // What the run kept is in the noisy capture, each return in the slot it
            // was decoded from with its distance and intensity (no stage here changes
            // them); what it dropped is not.
            let written = slots(&noisy, model);
            let s = summary(&dir);
            assert_eq!(s["totals"]["noise"]["returns_out"], written.len(), "{name}");
            let recorded: std::collections::HashSet<_> = input.iter().collect();
            assert!(
                written.iter().all(|w| recorded.contains(w)),
                "{name}: a return the input does not hold"
            );
            assert!(written.len() * 10 > input.len() * 7, "{name}");
            let on = |v: &[(u32, u8, u8, u16, u8)]| v.iter().filter(|w| w.2 == occluded).count();
            if k == 1 {
                assert!(on(&input) > 0, "{name}: laser {occluded} returns nothing");
                assert_eq!(on(&written), 0, "{name}: laser {occluded} is occluded");
            }
        }
    }
}

#[test]
fn a_capture_of_another_sensor_on_standard_input_runs_as_the_file_does() {
    let tmp = tempfile::tempdir().unwrap();
    let capture = common::synth_capture(tmp.path(), "vlp32c", &["--preset", "crossroad"], 2);
    let cfg = config(
        tmp.path(),
        "seed = 4\n[[noise]]\ntype = \"rain\"\nrate_mm_h = 8.0\n",
    );
    let run = |input: &str, out: &Path, stdin: Option<&Path>| {
        let mut cmd = bin2();
        cmd.args(["--quiet", "run", "--keep-partial", input, "-c"])
            .arg(&cfg)
            .arg("-o")
            .arg(out);
        if let Some(p) = stdin {
            cmd.pipe_stdin(p).unwrap();
        }
        cmd.assert().success();
    };
    let (a, b) = (tmp.path().join("file"), tmp.path().join("stdin"));
    run(capture.to_str().unwrap(), &a, None);
    run("-", &b, Some(&capture));
    let (a, b) = (a.join("crossroad"), b.join("stdin"));
    assert_eq!(summary(&b)["capture_summary"]["sensor"], "VLP-32C");
    assert_eq!(
        summary(&a)["totals"]["noise"],
        summary(&b)["totals"]["noise"]
    );
    let frames: Vec<_> = std::fs::read_dir(&a)
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .filter(|n| n.to_string_lossy().ends_with(".ply"))
        .collect();
    assert!(frames.len() >= 2, "{frames:?}");
    // The same points, byte for byte (the headers name the source).
    let body = |p: PathBuf| {
        let bytes = std::fs::read(p).unwrap();
        let end = b"end_header\n";
        let at = bytes.windows(end.len()).position(|w| w == end).unwrap();
        bytes[at..].to_vec()
    };
    for f in frames {
        assert!(body(a.join(&f)) == body(b.join(&f)), "{f:?} differs");
    }
    // `info -` reads it too.
    let info = bin2()
        .args(["info", "--json", "-"])
        .pipe_stdin(&capture)
        .unwrap()
        .assert()
        .success();
    let info: serde_json::Value = serde_json::from_slice(&info.get_output().stdout).unwrap();
    assert_eq!(info["sensor"], "VLP-32C");
    assert_eq!(
        info["returns"],
        summary(&a)["totals"]["noise"]["returns_in"]
    );
}

#[test]
fn sweeps_run_on_captures_of_other_sensors_with_their_labels() {
    let tmp = tempfile::tempdir().unwrap();
    for (name, _, scene, _) in SENSORS {
        let capture = common::synth_capture(tmp.path(), name, scene, 3);
        let out = tmp.path().join(format!("sweep-{name}"));
        bin2()
            .args(["--quiet", "sweep"])
            .arg(&capture)
            .args(["-c", "configs/rain.toml", "--vary", "rain.rate_mm_h=0,8"])
            .args(["--seeds", "1..2", "-o"])
            .arg(&out)
            .assert()
            .success();
        // The synthesizer's labels line up with the sweeps the reader cuts (else the
        // sweep refuses them), and every object of the scene is counted.
        let text = std::fs::read_to_string(out.join("aggregate.csv")).unwrap();
        let mut lines = text.lines();
        let header: Vec<&str> = lines.next().unwrap().split(',').collect();
        let col = |n: &str| header.iter().position(|h| *h == n).unwrap();
        let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
        assert_eq!(rows.len(), 2, "{name}: {text}");
        for r in &rows {
            let objects: f64 = r[col("objects_mean")].parse().unwrap();
            let detected: f64 = r[col("detected_share_mean")].parse().unwrap();
            assert!(objects >= 3.0, "{name}: {objects} objects");
            assert!(detected > 0.0, "{name}: nothing detected");
        }
    }
    // What does not fit the sensor is refused before anything is written.
    let capture = common::synth_capture(tmp.path(), "vlp16", CROSSROAD, 1);
    let cfg = config(
        tmp.path(),
        "seed = 1\n[[noise]]\ntype = \"occlusion\"\nlasers = [20]\n",
    );
    let out = tmp.path().join("refused");
    let err = bin2()
        .args(["--quiet", "sweep"])
        .arg(&capture)
        .arg("-c")
        .arg(&cfg)
        .args(["--seeds", "1..2", "-o"])
        .arg(&out)
        .assert()
        .failure();
    let err = String::from_utf8_lossy(&err.get_output().stderr).into_owned();
    assert!(err.contains("the VLP-16 (16 lasers)"), "{err}");
    assert!(!out.join("aggregate.csv").exists());
}
