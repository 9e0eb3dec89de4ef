//! `lidar-noise synth` command: writes the three files, refuses to overwrite its input.

use lidar_noise::synth::labels::read_labels_file;
use std::path::{Path, PathBuf};

/// The arguments of `lidar-noise synth` these tests vary.
struct SynthArgs {
    scene: Option<PathBuf>,
    preset: Option<String>,
    output: PathBuf,
    sensor: Option<String>,
}

/// `synth --preset crossroad --rotations 1 --seed 3 -o DIR`.
fn args(dir: &Path) -> SynthArgs {
    SynthArgs {
        scene: None,
        preset: Some("crossroad".into()),
        output: dir.to_path_buf(),
        sensor: None,
    }
}

/// Runs `lidar-noise --quiet synth` with `a`: Err(its error message) when it fails.
fn run(a: SynthArgs) -> Result<(), String> {
    let mut cmd = assert_cmd::Command::cargo_bin("lidar-noise").unwrap();
    cmd.args(["--quiet", "synth", "--rotations", "1", "--seed", "3", "-o"])
        .arg(&a.output);
    if let Some(scene) = &a.scene {
        cmd.arg(scene);
    }
    if let Some(preset) = &a.preset {
        cmd.args(["--preset", preset]);
    }
    if let Some(sensor) = &a.sensor {
        cmd.args(["--sensor", sensor]);
    }
    let out = cmd.output().unwrap();
    if out.status.success() {
        Ok(())
    } else {
        Err(String::from_utf8_lossy(&out.stderr).into_owned())
    }
}

#[test]
fn writes_capture_labels_and_objects() {
    let dir = tempfile::tempdir().unwrap();
    run(args(dir.path())).unwrap();
    let pcap = std::fs::read(dir.path().join("crossroad.pcap")).unwrap();
    assert_eq!(&pcap[..4], &[0xd4, 0xc3, 0xb2, 0xa1]);
    let rows = read_labels_file(&dir.path().join("crossroad.labels.csv.gz")).unwrap();
    assert!(!rows.is_empty() && rows.iter().all(|r| r.frame == 0));
    let objects: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(dir.path().join("crossroad.objects.json")).unwrap(),
    )
    .unwrap();
    assert_eq!(objects["objects"][0]["id"], 1);
    assert_eq!(objects["objects"][0]["kind"], "car");
    // No temporary files left behind.
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 3);
}

#[test]
fn refuses_to_overwrite_its_input() {
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("x.objects.json");
    std::fs::write(&scene, "name = \"x\"\n[sensor]\nheight_m = 1.9\n").unwrap();
    let mut a = args(dir.path());
    a.preset = None;
    a.scene = Some(scene.clone());
    let e = run(a).unwrap_err();
    assert!(e.contains("overwrite"), "{e}");
    assert!(std::fs::read_to_string(&scene)
        .unwrap()
        .contains("height_m"));
}

#[test]
fn sensor_option_picks_the_sensor_and_refuses_a_rate_it_cannot_turn() {
    let dir = tempfile::tempdir().unwrap();
    let mut a = args(dir.path());
    a.sensor = Some("vlp16".into());
    run(a).unwrap();
    let pcap = std::fs::read(dir.path().join("crossroad.pcap")).unwrap();
    // First record: 24-byte file header, 16-byte record header, 42 bytes of Ethernet,
    // IPv4 and UDP headers, then the 1206-byte payload: product byte 0x22 (VLP-16).
    assert_eq!(pcap[24 + 16 + 42 + 1205], 0x22);
    // The crossroad preset turns at 20 Hz: no HDL-64E does; nothing is written.
    let other = tempfile::tempdir().unwrap();
    let mut a = args(other.path());
    a.sensor = Some("HDL-64E S3".into());
    let e = run(a).unwrap_err();
    assert!(e.contains("HDL-64E S3") && e.contains("5 to 15 Hz"), "{e}");
    assert_eq!(std::fs::read_dir(other.path()).unwrap().count(), 0);
}
