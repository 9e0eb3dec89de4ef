//! One sensor stack (issue 51): every model is read by the same rules. A capture with
//! every data packet recorded twice gives exactly the original's returns, the copies
//! dropped and reported, whatever the model; occlusion's elevation interval is checked
//! against the capture's own sensor, not the HDL-32E's table.

use crate::common;
use crate::common::bin2;
use lidar_noise::sensor::SensorModel;
use std::path::Path;

/// One sensor of each family: its `synth` name and scene arguments.
const FAMILIES: [(&str, &[&str]); 5] = [
    ("hdl32e", &["--preset", "crossroad"]),
    ("vlp16", &["--preset", "crossroad"]),
    ("vlp32c", &["--preset", "crossroad"]),
    // The crossroad turns at 20 Hz, beyond the HDL-64E's 15 Hz.
    ("hdl64e s2", &["--random", "3"]),
    ("vls128", &["--preset", "crossroad"]),
];

/// The classic pcap at `src` with every data packet (1206-byte payload) recorded twice in
/// a row, written to `dst`; the number of data packets.
fn doubled(src: &Path, dst: &Path) -> u64 {
    let pcap = std::fs::read(src).unwrap();
    let mut out = pcap[..24].to_vec();
    let (mut at, mut data) = (24, 0);
    while at + 16 <= pcap.len() {
        let len = u32::from_le_bytes(pcap[at + 8..at + 12].try_into().unwrap()) as usize;
        let record = &pcap[at..at + 16 + len];
        out.extend_from_slice(record);
        if len == 42 + 1206 {
            out.extend_from_slice(record);
            data += 1;
        }
        at += 16 + len;
    }
    std::fs::write(dst, out).unwrap();
    data
}

/// `info --json` of a capture.
fn info(capture: &Path) -> serde_json::Value {
    let o = bin2()
        .args(["info", "--json"])
        .arg(capture)
        .assert()
        .success();
    serde_json::from_slice(&o.get_output().stdout).unwrap()
}

/// The x, y, z, intensity and laser of every point of every PLY file `convert` writes
/// for a capture (every sweep), by file name; and its standard error.
fn converted(capture: &Path, out: &Path) -> (Vec<(String, Vec<u8>)>, String) {
    let o = bin2()
        .args(["convert", "--keep-partial"])
        .arg(capture)
        .arg("-o")
        .arg(out)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    assert!(o.status.success(), "{err}");
    let mut files: Vec<(String, Vec<u8>)> = std::fs::read_dir(out)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "ply"))
        .map(|p| {
            let name = p.file_name().unwrap().to_string_lossy().into_owned();
            (name, common::ply_payload(&p))
        })
        .collect();
    files.sort();
    (files, err)
}

/// `run --chunk-frames 1` (each frame read from where the frame index puts it) of a
/// capture, every sweep; the returns it read.
fn run_chunked(capture: &Path, dir: &Path) -> u64 {
    let cfg = dir.join("none.toml");
    std::fs::write(&cfg, "seed = 1\n").unwrap();
    let out = dir.join("run");
    common::run_ok(
        capture,
        &["--keep-partial", "--no-ply", "--chunk-frames", "1"],
        &cfg,
        &out,
    );
    let sub = std::fs::read_dir(&out)
        .unwrap()
        .map(|e| e.unwrap().path())
        .find(|p| p.is_dir())
        .unwrap();
    let s: serde_json::Value =
        serde_json::from_slice(&std::fs::read(sub.join("summary.json")).unwrap()).unwrap();
    s["totals"]["noise"]["returns_in"].as_u64().unwrap()
}

#[test]
fn every_model_drops_repeated_packets_and_reports_them() {
    let tmp = tempfile::tempdir().unwrap();
    for (name, scene) in FAMILIES {
        let original = common::synth_capture(tmp.path(), name, scene, 2);
        let twice = tmp.path().join(format!("{name}-twice.pcap"));
        let data = doubled(&original, &twice);
        assert!(data > 20, "{name}: {data} data packets");

        let (a, b) = (info(&original), info(&twice));
        assert!(a["returns"].as_u64().unwrap() > 1000, "{name}: {a}");
        assert_eq!(a["returns"], b["returns"], "{name}");
        assert_eq!(a["data_packets"], b["data_packets"], "{name}");
        assert!(a.get("duplicate_packets").is_none(), "{name}: {a}");
        assert_eq!(b["duplicate_packets"], data, "{name}: {b}");

        // The same sweeps with the same points, and a warning with the count.
        let (want, _) = converted(&original, &tmp.path().join(format!("{name}-a")));
        let (got, err) = converted(&twice, &tmp.path().join(format!("{name}-b")));
        assert!(!want.is_empty(), "{name}");
        assert!(got == want, "{name}: the sweeps differ from the original's");
        assert!(
            err.contains(&format!(
                "{}: dropped {data} duplicate data packets",
                twice.display()
            )),
            "{name}: {err}"
        );

        // The frame index drops the same copies: chunks read from it see the original's
        // returns.
        let a_dir = tmp.path().join(format!("{name}-ra"));
        let b_dir = tmp.path().join(format!("{name}-rb"));
        std::fs::create_dir_all(&a_dir).unwrap();
        std::fs::create_dir_all(&b_dir).unwrap();
        assert_eq!(
            run_chunked(&twice, &b_dir),
            run_chunked(&original, &a_dir),
            "{name}"
        );
    }
}

/// The lasers of `model` inside `[lo, hi]` (with occlusion's 0.005 degree slack).
fn inside(model: &SensorModel, [lo, hi]: [f64; 2]) -> Vec<usize> {
    (0..model.lasers)
        .filter(|&k| {
            let e = model.elevation_deg[k];
            e >= lo - 0.005 && e <= hi + 0.005
        })
        .collect()
}

#[test]
fn occlusion_elevations_are_checked_against_the_captures_sensor() {
    use lidar_noise::sensor::{HDL32E, VLP16};
    // -5 degrees: VLP-16 laser 10, between two HDL-32E lasers (-5.33 and -4).
    let interval = [-5.1, -4.9];
    assert_eq!(inside(&VLP16, interval), vec![10]);
    assert!(inside(&HDL32E, interval).is_empty());
    let tmp = tempfile::tempdir().unwrap();
    let cfg = tmp.path().join("occ.toml");
    std::fs::write(
        &cfg,
        "seed = 1\n[[noise]]\ntype = \"occlusion\"\nelevation_deg = [-5.1, -4.9]\n",
    )
    .unwrap();
    bin2().arg("validate").arg(&cfg).assert().success();

    // A VLP-16 capture: laser 10's returns, and only they, are occluded.
    let capture = common::synth_capture(tmp.path(), "vlp16", &["--preset", "crossroad"], 2);
    let out = tmp.path().join("vlp16-out");
    common::run_ok(&capture, &["--keep-partial", "--no-ply"], &cfg, &out);
    let sub = std::fs::read_dir(&out)
        .unwrap()
        .map(|e| e.unwrap().path())
        .find(|p| p.is_dir())
        .unwrap();
    let s: serde_json::Value =
        serde_json::from_slice(&std::fs::read(sub.join("summary.json")).unwrap()).unwrap();
    let per_laser = &s["capture_summary"]["returns_per_laser"];
    let occluded = &s["totals"]["noise"]["dropped_by_laser"]["occluded"];
    assert!(per_laser[10].as_u64().unwrap() > 0, "{per_laser}");
    for k in 0..VLP16.lasers {
        let want = if k == 10 {
            &per_laser[10]
        } else {
            &serde_json::json!(0)
        };
        assert_eq!(&occluded[k], want, "laser {k}");
    }

    // The HDL-32E crossroad has no laser there: refused, naming the sensor.
    let o = bin2()
        .args(["--quiet", "run"])
        .arg(common::crossroad())
        .arg("-c")
        .arg(&cfg)
        .arg("-o")
        .arg(tmp.path().join("hdl32e-out"))
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(
        err.contains("elevation_deg [-5.1, -4.9] selects no laser")
            && err.contains("the HDL-32E's lasers point from"),
        "{err}"
    );
}
