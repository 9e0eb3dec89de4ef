//! Hostile inputs of issue 30 (defects 6, 7 and 8): impossible calibration values, reads
//! without a size limit, and a `--set` whose value hides a second line.

use crate::common::command_at_root as bin;

fn fails_with(args: &[&str], needles: &[&str]) {
    let dir = tempfile::tempdir().unwrap();
    let o = bin()
        .args(args)
        .arg("-o")
        .arg(dir.path().join("out"))
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{args:?}: {err}");
    for n in needles {
        assert!(err.contains(n), "{args:?}: {err}");
    }
    assert!(!dir.path().join("out").exists(), "{args:?}: output written");
}

#[test]
fn impossible_calibration_values_are_refused_naming_the_value() {
    let root = env!("CARGO_MANIFEST_DIR");
    let xml = std::fs::read_to_string(format!(
        "{root}/fuzz/corpus/calibration/hdl32e_veloview.xml"
    ))
    .unwrap();
    let yaml =
        std::fs::read_to_string(format!("{root}/fuzz/corpus/calibration/hdl32e_ros.yaml")).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let cases: Vec<(String, &str, &str)> = vec![
        (
            regex_free_replace(&xml, "<distLSB_>", "</distLSB_>", "1e9"),
            "xml",
            "distance resolution",
        ),
        (
            regex_free_replace(&xml, "<distLSB_>", "</distLSB_>", "1e-320"),
            "xml",
            "distance resolution",
        ),
        (
            regex_free_replace(&xml, "<rotCorrection_>", "</rotCorrection_>", "1e308"),
            "xml",
            "rotational correction",
        ),
        (
            yaml.replacen("distance_resolution: 0.002", "distance_resolution: 1e9", 1),
            "yaml",
            "distance resolution",
        ),
    ];
    for (k, (text, ext, needle)) in cases.into_iter().enumerate() {
        let path = dir.path().join(format!("cal{k}.{ext}"));
        std::fs::write(&path, &text).unwrap();
        let p = path.to_string_lossy().into_owned();
        fails_with(
            &[
                "--quiet",
                "convert",
                "fixtures/crossroad.pcap",
                "--frames",
                "0",
                "--calibration",
                &p,
            ],
            &[needle, &format!("cal{k}.{ext}")],
        );
    }
}

/// `text` with the content between the first `open` and the next `close` set to `value`.
fn regex_free_replace(text: &str, open: &str, close: &str, value: &str) -> String {
    let a = text.find(open).expect("tag") + open.len();
    let b = a + text[a..].find(close).expect("closing tag");
    format!("{}{value}{}", &text[..a], &text[b..])
}

#[test]
fn endless_inputs_are_refused_after_a_bounded_read() {
    if !std::path::Path::new("/dev/zero").exists() {
        eprintln!("SKIPPED: /dev/zero is absent on this system");
        return;
    }
    fails_with(
        &["--quiet", "run", "-c", "/dev/zero"],
        &["/dev/zero", "larger than"],
    );
    fails_with(
        &[
            "--quiet",
            "convert",
            "fixtures/crossroad.pcap",
            "--calibration",
            "/dev/zero",
        ],
        &["/dev/zero", "larger than"],
    );
    fails_with(
        &["--quiet", "synth", "/dev/zero"],
        &["/dev/zero", "larger than"],
    );
    let labels = lidar_noise::synth::labels::read_labels_file(std::path::Path::new("/dev/zero"))
        .unwrap_err()
        .to_string();
    assert!(
        labels.contains("/dev/zero") && labels.contains("longer than"),
        "{labels}"
    );
}

#[test]
fn a_set_with_a_line_break_is_refused() {
    let o = bin()
        .args(["validate", "--print", "--set", "seed=1\nseed=2"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(err.contains("line break"), "{err}");
    assert!(o.stdout.is_empty());
}

#[test]
fn no_frame_without_frames_names_the_whole_capture_not_a_range_nobody_gave() {
    // Issue 30, defect 8: "no frame to process in --frames 0..4294967295" without --frames.
    let short = "fuzz/findings/capture/backward-clock.pcap";
    fails_with(
        &["--quiet", "run", short],
        &["no frame to process in the whole capture"],
    );
    fails_with(
        &["--quiet", "run", short, "--frames", "3.."],
        &["in --frames 3..:"],
    );
}

#[test]
fn no_frame_names_the_full_frames_where_they_are() {
    // The full frames' indexes were guessed from the partial count: a capture whose only
    // partial sweep is its last (crossroad: full frames 0 and 1) was said to hold 1..2.
    fails_with(
        &["--quiet", "run", "fixtures/crossroad.pcap", "--frames", "9"],
        &["2 full frames (indexes 0..1)"],
    );
    fails_with(
        &["--quiet", "run", "fixtures/parking.pcap", "--frames", "1"],
        &["1 full frame (indexes 0..0)"],
    );
}

#[test]
fn a_calibration_file_inside_the_output_folder_is_never_replaced() {
    // Issue 30, defect 4: `run C --calibration out/crossroad/summary.json -o out --force`
    // replaced the calibration with the report.
    let root = env!("CARGO_MANIFEST_DIR");
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let first = bin()
        .args(["--quiet", "run", "--frames", "0", "--no-ply", "-o"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(first.status.success());
    let cal = out.join("crossroad/summary.json");
    let text = std::fs::read(format!("{root}/fuzz/corpus/calibration/hdl32e_ros.yaml")).unwrap();
    std::fs::write(&cal, &text).unwrap();
    let c = cal.to_string_lossy().into_owned();
    let o = out.to_string_lossy().into_owned();
    for args in [
        vec![
            "--quiet",
            "run",
            "--frames",
            "0",
            "--no-ply",
            "--force",
            "--calibration",
            &c,
            "-o",
            &o,
        ],
        vec![
            "--quiet",
            "convert",
            "fixtures/crossroad.pcap",
            "--frames",
            "0",
            "--force",
            "--calibration",
            &c,
            "-o",
            &o,
        ],
    ] {
        let r = bin().args(&args).output().unwrap();
        let err = String::from_utf8_lossy(&r.stderr);
        assert_ne!(r.status.code(), Some(0), "{args:?}: accepted");
        assert!(err.contains("input"), "{args:?}: {err}");
        assert_eq!(
            std::fs::read(&cal).unwrap(),
            text,
            "{args:?}: calibration replaced"
        );
    }
}

#[test]
fn a_later_packet_of_another_sensor_is_refused_naming_record_and_offset() {
    // Issue 30, defect 6: only the first 64 data packets identified the sensor, so an
    // HDL-32E capture followed by a VLP-16 one decoded the VLP-16 packets as garbage.
    let root = env!("CARGO_MANIFEST_DIR");
    let mut bytes = std::fs::read(format!("{root}/fixtures/crossroad.pcap")).unwrap();
    let (mut at, mut record, mut patched) = (24usize, 0u32, None);
    while at + 16 <= bytes.len() {
        let len = u32::from_le_bytes(bytes[at + 8..at + 12].try_into().unwrap()) as usize;
        // Ethernet + IPv4 + UDP headers (42 bytes), then the 1206-byte payload whose last
        // byte is the product id.
        if len == 42 + 1206 && record >= 150 && patched.is_none() {
            bytes[at + 16 + 42 + 1205] = 0x22;
            patched = Some((record, at));
        }
        at += 16 + len;
        record += 1;
    }
    let (record, offset) = patched.expect("a data packet past record 150");
    let dir = tempfile::tempdir().unwrap();
    let mixed = dir.path().join("mixed.pcap");
    std::fs::write(&mixed, &bytes).unwrap();
    let m = mixed.to_string_lossy().into_owned();
    fails_with(
        &["--quiet", "run", &m, "--pcap-out"],
        &[
            "mixed.pcap",
            &format!("record {record} at byte offset {offset}"),
            "0x22 (VLP-16)",
            "mixes sensors",
        ],
    );
}

#[test]
fn duplicated_packets_are_reported() {
    // Issue 30, defect 6: every packet twice gave frames of doubled returns, silently.
    let root = env!("CARGO_MANIFEST_DIR");
    let bytes = std::fs::read(format!("{root}/fixtures/crossroad.pcap")).unwrap();
    let mut out = bytes[..24].to_vec();
    let mut at = 24usize;
    let mut data = 0u64;
    while at + 16 <= bytes.len() {
        let len = u32::from_le_bytes(bytes[at + 8..at + 12].try_into().unwrap()) as usize;
        let rec = &bytes[at..at + 16 + len];
        out.extend_from_slice(rec);
        out.extend_from_slice(rec);
        data += u64::from(len == 42 + 1206);
        at += 16 + len;
    }
    let dir = tempfile::tempdir().unwrap();
    let dup = dir.path().join("dup.pcap");
    std::fs::write(&dup, &out).unwrap();
    let o = bin()
        .args(["run", "--no-ply", "-o"])
        .arg(dir.path().join("out"))
        .arg(&dup)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    // The copies are dropped and counted (see tests/integration/readers_hostile.rs): no copy is
    // decoded, so the clock no longer seems to run backwards.
    assert!(
        err.contains(&format!("dropped {data} duplicate data packets")),
        "{err}"
    );
    assert!(!err.contains("clock runs backwards"), "{err}");
}
