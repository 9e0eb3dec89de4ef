//! Hostile inputs of issue 30 for the readers (defects 6, 7 and 8): duplicated packets,
//! a LAS header claiming more points than its file holds, garbage on standard input, a
//! FIFO capture, mixed sensors in the first packets, and how `run` and `convert` name a
//! capture in their messages.

use crate::common::command_at_root as bin;
use crate::common::fixture;
use lidar_noise::sensor::frames::{DecoderOptions, FrameReader, DUPLICATE_WINDOW};
use lidar_noise::sensor::index::FrameScan;
use std::io::Write;
use std::path::Path;
use std::process::{Command, Stdio};
use std::sync::Arc;

/// A classic pcap's file header and its records (each with its 16-byte header), with the
/// byte offset of each record.
fn records(pcap: &[u8]) -> (&[u8], Vec<(u64, &[u8])>) {
    let mut out = Vec::new();
    let mut at = 24;
    while at + 16 <= pcap.len() {
        let len = u32::from_le_bytes(pcap[at + 8..at + 12].try_into().unwrap()) as usize;
        let end = at + 16 + len;
        if end > pcap.len() {
            break;
        }
        out.push((at as u64, &pcap[at..end]));
        at = end;
    }
    (&pcap[..24], out)
}

/// The capture with every record written twice in a row (a capture recorded twice over
/// the same interface, or merged with itself).
fn doubled(pcap: &[u8]) -> Vec<u8> {
    let (header, recs) = records(pcap);
    let mut out = header.to_vec();
    for (_, r) in recs {
        out.extend_from_slice(r);
        out.extend_from_slice(r);
    }
    out
}

/// Every frame of a capture in memory, each return without its record number (the copies
/// move the records).
fn frames(
    bytes: Vec<u8>,
) -> (
    Vec<Vec<lidar_noise::frame::Return>>,
    lidar_noise::sensor::frames::CaptureSummary,
) {
    let mut reader = FrameReader::from_bytes(
        Arc::from(bytes),
        Path::new("c.pcap"),
        &DecoderOptions::default(),
    )
    .unwrap();
    let frames = reader
        .by_ref()
        .map(|f| {
            let mut f = f.unwrap().returns;
            for r in &mut f {
                r.packet = 0;
            }
            f
        })
        .collect();
    (frames, reader.summary())
}

#[test]
fn duplicated_packets_are_dropped_and_counted() {
    // Issue 30, defect 6: all packets duplicated gave 33 frames of doubled returns.
    let original = std::fs::read(fixture("crossroad.pcap")).unwrap();
    let twice = doubled(&original);
    let (expected, none) = frames(original.clone());
    let (got, dropped) = frames(twice.clone());
    let (none, dropped) = (none.duplicate_packets, dropped.duplicate_packets);
    assert_eq!(none, 0);
    assert_eq!(got.len(), expected.len());
    assert!(got == expected, "the frames differ from the original's");
    let (_, recs) = records(&original);
    let data = recs
        .iter()
        .filter(|(_, r)| r.len() == 16 + 42 + 1206)
        .count();
    assert_eq!(dropped, data as u64);

    // The frame index drops the same packets: a reader resumed at any frame it finds
    // yields that frame as a reader from the start does.
    let bytes: Arc<[u8]> = Arc::from(twice.clone());
    let scan: Vec<_> = FrameScan::from_bytes(
        bytes.clone(),
        Path::new("c.pcap"),
        &DecoderOptions::default(),
    )
    .unwrap()
    .map(Result::unwrap)
    .filter(|f| !f.partial)
    .collect();
    assert_eq!(scan.len(), expected.len());
    for (k, f) in scan.iter().enumerate() {
        let mut resumed = FrameReader::from_bytes_at(
            bytes.clone(),
            Path::new("c.pcap"),
            &DecoderOptions::default(),
            &f.seek,
        )
        .unwrap();
        let mut first = resumed.next().unwrap().unwrap().returns;
        for r in &mut first {
            r.packet = 0;
        }
        assert!(first == expected[k], "frame {k} resumed differs");
    }

    // `info` counts them, `convert` warns with the count and writes the original's frames.
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("twice.pcap");
    std::fs::write(&path, &twice).unwrap();
    let o = bin().arg("info").arg("--json").arg(&path).output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let info: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(info["duplicate_packets"], data as u64, "{info}");
    assert_eq!(info["data_packets"], data as u64, "{info}");
    assert!(info.get("clock_backward_steps").is_none(), "{info}");
    let o = bin()
        .arg("convert")
        .arg(&path)
        .arg("-o")
        .arg(dir.path().join("out"))
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert!(
        err.contains(&format!(
            "{}: dropped {data} duplicate data packets",
            path.display()
        )),
        "{err}"
    );
    let written = std::fs::read_dir(dir.path().join("out"))
        .unwrap()
        .filter(|e| e.as_ref().unwrap().path().extension() == Some("ply".as_ref()))
        .count();
    assert_eq!(written, expected.len());
}

#[test]
fn duplicates_are_looked_for_in_a_bounded_window() {
    // Memory must not grow with the capture: a copy further back than the window is a
    // packet like any other (the sensor clock running backwards is warned about apart).
    let original = std::fs::read(fixture("crossroad.pcap")).unwrap();
    let (header, recs) = records(&original);
    let data: Vec<&[u8]> = recs
        .iter()
        .map(|(_, r)| *r)
        .filter(|r| r.len() == 16 + 42 + 1206)
        .take(40)
        .collect();
    for (gap, dropped) in [(DUPLICATE_WINDOW, 1), (DUPLICATE_WINDOW + 1, 0)] {
        let mut bytes = header.to_vec();
        for r in &data[..30] {
            bytes.extend_from_slice(r);
        }
        // A copy of the packet `gap` data packets back.
        bytes.extend_from_slice(data[30 - gap]);
        for r in &data[30..] {
            bytes.extend_from_slice(r);
        }
        let mut reader = FrameReader::from_bytes(
            Arc::from(bytes),
            Path::new("c.pcap"),
            &DecoderOptions {
                keep_partial: true,
                ..DecoderOptions::default()
            },
        )
        .unwrap();
        for f in reader.by_ref() {
            f.unwrap();
        }
        let s = reader.summary();
        assert_eq!(s.duplicate_packets, dropped, "gap {gap}");
        assert_eq!(s.clock_backward_steps, 1 - dropped, "gap {gap}");
    }
}

#[test]
fn run_and_convert_name_the_capture_by_the_path_given() {
    // Issue 30, defect 8: `run` named the bare file name where `convert` named the path.
    let original = std::fs::read(fixture("crossroad.pcap")).unwrap();
    let mut twice = doubled(&original);
    twice.truncate(twice.len() - 100);
    let dir = tempfile::tempdir().unwrap();
    let sub = dir.path().join("sub");
    std::fs::create_dir(&sub).unwrap();
    let path = sub.join("twice.pcap");
    std::fs::write(&path, &twice).unwrap();
    for cmd in ["run", "convert"] {
        let o = bin()
            .arg(cmd)
            .arg(&path)
            .arg("-o")
            .arg(dir.path().join(cmd))
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(o.status.success(), "{cmd}: {err}");
        for what in ["the capture ends inside a record", "dropped"] {
            assert!(
                err.contains(&format!("{}: {what}", path.display())),
                "{cmd}: {err}"
            );
        }
        // No line names the capture by its bare file name.
        assert!(
            err.lines().all(|l| !l.starts_with("twice.pcap")),
            "{cmd}: {err}"
        );
    }
}

#[test]
fn garbage_on_standard_input_is_refused_after_its_first_bytes() {
    // Issue 30, defect 7: `info - </dev/zero` read 3.1 GB before refusing. The test feeds
    // zeros until the tool stops reading (the pipe breaks), up to 64 MiB.
    let mut child = bin()
        .args(["info", "-"])
        .stdin(Stdio::piped())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut stdin = child.stdin.take().unwrap();
    let chunk = vec![0u8; 1 << 16];
    let mut written = 0usize;
    while written < 64 << 20 {
        match stdin.write(&chunk) {
            Ok(n) => written += n,
            Err(_) => break,
        }
    }
    drop(stdin);
    let o = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(
        err.contains("<stdin>") && err.contains("unknown file header"),
        "{err}"
    );
    // The pipe holds 64 KiB at most: the tool stopped after a few chunks.
    assert!(
        written <= 1 << 20,
        "{written} bytes written before the refusal"
    );
}

#[test]
fn short_and_empty_standard_input_is_named() {
    for (input, needle) in [
        (&b""[..], "is empty"),
        (&[0xd4, 0xc3][..], "ends inside the capture's file header"),
        (&b"GET / HTTP/1.1\r\n"[..], "unknown file header"),
    ] {
        let mut child = bin()
            .args(["info", "-"])
            .stdin(Stdio::piped())
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        let mut stdin = child.stdin.take().unwrap();
        stdin.write_all(input).ok();
        drop(stdin);
        let o = child.wait_with_output().unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(1), "{err}");
        assert!(err.contains("<stdin>") && err.contains(needle), "{err}");
    }
}

#[cfg(unix)]
#[test]
fn a_fifo_capture_is_read_once() {
    // Issue 30, defect 8: a FIFO was read twice (to identify the sensor, then to decode)
    // and the second read met "unknown file header".
    let dir = tempfile::tempdir().unwrap();
    let fifo = dir.path().join("capture.pcap");
    match Command::new("mkfifo").arg(&fifo).status() {
        Ok(s) if s.success() => {}
        _ => {
            eprintln!("SKIPPED: mkfifo is not available");
            return;
        }
    }
    let expected = bin()
        .args(["info", "--json"])
        .arg(fixture("crossroad.pcap"))
        .output()
        .unwrap();
    let expected: serde_json::Value = serde_json::from_slice(&expected.stdout).unwrap();
    let bytes = std::fs::read(fixture("crossroad.pcap")).unwrap();
    let writer = {
        let fifo = fifo.clone();
        std::thread::spawn(move || {
            // Blocks until the tool opens the FIFO.
            let mut f = std::fs::OpenOptions::new().write(true).open(&fifo).unwrap();
            f.write_all(&bytes).ok();
            drop(f);
            // A second, empty writer: a tool that opens the FIFO again reads its end
            // (instead of waiting for ever); when it does not, the test opens it below.
            drop(std::fs::OpenOptions::new().write(true).open(&fifo));
        })
    };
    let o = bin().args(["info", "--json"]).arg(&fifo).output().unwrap();
    {
        use std::os::unix::fs::OpenOptionsExt;
        let _unblock = std::fs::OpenOptions::new()
            .read(true)
            .custom_flags(libc::O_NONBLOCK)
            .open(&fifo)
            .unwrap();
        writer.join().unwrap();
    }
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    let got: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    for key in ["data_packets", "full_frames", "returns", "duration_s"] {
        assert_eq!(got[key], expected[key], "{key}");
    }
    // What reads a capture again or at an offset refuses a FIFO before opening it (an
    // open waits for a writer, and none comes here).
    for args in [&["--chunk-frames", "2"][..], &["--pcap-out"][..]] {
        let o = bin()
            .arg("run")
            .args(args)
            .arg(&fifo)
            .arg("-o")
            .arg(dir.path().join("out"))
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(1), "{args:?}: {err}");
        assert!(
            err.contains(&fifo.display().to_string()) && err.contains("FIFO"),
            "{args:?}: {err}"
        );
        assert!(!dir.path().join("out").exists(), "{args:?}");
    }
}

#[test]
fn mixed_sensors_in_the_first_packets_name_the_packet_and_offset() {
    // Issue 30, defect 8: "data packets disagree on the product id (0x21 and 0x22)"
    // named no packet nor offset.
    let mut bytes = std::fs::read(fixture("crossroad.pcap")).unwrap();
    let (_, recs) = records(&bytes);
    let data: Vec<(usize, u64)> = recs
        .iter()
        .enumerate()
        .filter(|(_, (_, r))| r.len() == 16 + 42 + 1206)
        .map(|(i, (at, _))| (i, *at))
        .collect();
    let (record, offset) = data[5];
    // The product byte is the payload's last byte.
    let last = offset as usize + 16 + 42 + 1205;
    bytes[last] = 0x22;
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("mixed.pcap");
    std::fs::write(&path, &bytes).unwrap();
    let o = bin().arg("info").arg(&path).output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    let (r0, o0) = data[0];
    assert!(
        err.contains(&path.display().to_string())
            && err.contains(&format!(
                "data packet 5 (record {record} at byte offset {offset}) has 0x22 (VLP-16)"
            ))
            && err.contains(&format!(
                "data packet 0 (record {r0} at byte offset {o0}) has 0x21"
            )),
        "{err}"
    );
}

/// Offset of the LAS 1.4 header's 64-bit point count.
const LAS14_POINT_COUNT: usize = 247;
/// Offset of the legacy 32-bit point count (read instead of the 64-bit one unless 0).
const LEGACY_POINT_COUNT: usize = 107;

#[test]
fn a_las_header_claiming_more_points_than_the_file_holds_is_named() {
    // Issue 30, defect 7: a LAS claiming 2^63 points filled the memory in `compare`.
    let dir = tempfile::tempdir().unwrap();
    let o = bin()
        .args(["--quiet", "convert", "--format", "las", "--frames", "1"])
        .arg(fixture("crossroad.pcap"))
        .arg("-o")
        .arg(dir.path().join("expected"))
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let name = std::fs::read_dir(dir.path().join("expected"))
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .find(|n| n.to_string_lossy().ends_with(".las"))
        .unwrap();
    let good = std::fs::read(dir.path().join("expected").join(&name)).unwrap();
    assert_eq!(&good[..4], b"LASF");
    assert_eq!((good[24], good[25]), (1, 4), "LAS 1.4");
    let claimed = u64::from_le_bytes(
        good[LAS14_POINT_COUNT..LAS14_POINT_COUNT + 8]
            .try_into()
            .unwrap(),
    );
    assert!(claimed > 0);
    let actual = dir.path().join("actual");
    std::fs::create_dir(&actual).unwrap();
    let mut bad = good.clone();
    bad[LEGACY_POINT_COUNT..LEGACY_POINT_COUNT + 4].copy_from_slice(&[0; 4]);
    bad[LAS14_POINT_COUNT..LAS14_POINT_COUNT + 8].copy_from_slice(&(1u64 << 63).to_le_bytes());
    std::fs::write(actual.join(&name), &bad).unwrap();
    let o = bin()
        .arg("compare")
        .arg(dir.path().join("expected"))
        .arg(&actual)
        .output()
        .unwrap();
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
    assert_eq!(o.status.code(), Some(1), "{text}");
    assert!(
        text.contains(&actual.join(&name).display().to_string())
            && text.contains(&format!("claims {} points", 1u64 << 63)),
        "{text}"
    );
}

/// The data records of `pcap` reordered: those whose first block's azimuth lies in
/// [0, 60) degrees alternate with those in [270, 360), each payload's timestamp rewritten
/// to rise in record order (an in-order clock, as a capture of interleaved packets merged
/// by arrival time has).
fn alternating(pcap: &[u8]) -> Vec<u8> {
    let (header, recs) = records(pcap);
    let data: Vec<&[u8]> = recs
        .iter()
        .map(|(_, r)| *r)
        .filter(|r| r.len() == 16 + 42 + 1206)
        .collect();
    let azimuth = |r: &[u8]| u16::from_le_bytes([r[16 + 42 + 2], r[16 + 42 + 3]]);
    let a: Vec<&[u8]> = data.iter().copied().filter(|r| azimuth(r) < 6000).collect();
    let b: Vec<&[u8]> = data
        .iter()
        .copied()
        .filter(|r| azimuth(r) >= 27000)
        .collect();
    let mut out = header.to_vec();
    let mut ts = 1_000_000u32;
    for (x, y) in a.iter().zip(&b) {
        for r in [x, y] {
            let mut r = r.to_vec();
            r[16 + 42 + 1200..16 + 42 + 1204].copy_from_slice(&ts.to_le_bytes());
            ts += 553;
            out.extend_from_slice(&r);
        }
    }
    out
}

#[test]
fn alternating_azimuths_are_reported_as_short_frames() {
    // Issue 30, defect 6: alternating azimuths gave 1,201 frames without a word.
    let original = std::fs::read(fixture("crossroad.pcap")).unwrap();
    let summary = |bytes: Vec<u8>| frames(bytes).1;
    let clean = summary(original.clone());
    assert_eq!(clean.short_frames, 0);
    let mixed = alternating(&original);
    let s = summary(mixed.clone());
    assert_eq!(
        s.clock_backward_steps, 0,
        "the clock was meant to run forward"
    );
    // One frame a jump, most far shorter than a turn (the fixture holds about 30 pairs).
    assert!(
        s.short_frames > 10 && 2 * s.short_frames >= u64::from(s.full_frames),
        "{} short frames of {}",
        s.short_frames,
        s.full_frames
    );
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("alt.pcap");
    std::fs::write(&path, &mixed).unwrap();
    let o = bin()
        .args(["run", "--no-ply", "-o"])
        .arg(dir.path().join("out"))
        .arg(&path)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert!(
        err.contains(&format!(
            "{} frames between the first and the last",
            s.short_frames
        )) && err.contains("azimuths jump back"),
        "{err}"
    );
    // `info` says it too; the reproducer kept in fuzz/findings/capture/ is such a capture.
    let kept = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("fuzz/findings/capture/alternating-azimuths.pcap");
    for capture in [path.as_path(), kept.as_path()] {
        let o = bin().arg("info").arg(capture).output().unwrap();
        let text = String::from_utf8_lossy(&o.stdout);
        assert!(
            o.status.success() && text.contains("short frames"),
            "{text}"
        );
    }
}
