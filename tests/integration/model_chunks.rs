//! `run --chunk-frames` on captures of the sensors beside the HDL-32E (issue 31): a scan
//! gives each frame where it starts, a reader resumed there yields the frames a reader
//! from the start yields, and a chunked or sharded run writes the very bytes of one
//! plain run, and a chunked or sharded sweep those of one plain sweep. Captures
//! synthesized here (`synth`'s library), one per packet family.

use crate::common;

use crate::common::bin2 as bin;
use lidar_noise::frame::FrameSource;
use lidar_noise::sensor::frames::DecoderOptions;
use lidar_noise::sensor::frames::ModelFrameReader;
use lidar_noise::synth::{write_capture, Scene, SynthOptions};
use std::path::{Path, PathBuf};

/// A capture of `sensor` (a name `synth --sensor` takes) of `rotations` turns of the
/// parking scene at 10 Hz, written into `dir`.
fn capture(dir: &Path, sensor: &str, rotations: u32) -> PathBuf {
    let mut scene = Scene::preset("parking").unwrap();
    scene.frames = rotations;
    scene.sensor.rotation_hz = 10.0;
    let options = SynthOptions {
        sensor: lidar_noise::cloud::guess::sensor_by_name(sensor).unwrap(),
        ..SynthOptions::default()
    };
    let (_, pcap, _) = write_capture(&scene, &options, Vec::new(), Vec::new()).unwrap();
    let path = dir.join(format!("{sensor}.pcap"));
    std::fs::write(&path, pcap).unwrap();
    path
}

/// A dual-return VLS-128 capture (firmware 5.2.3 timing: one firing a packet, 57.8 us
/// apart, 0.21 deg a firing at 10 Hz) of `rotations` turns, written from the packet
/// layout (blocks 0-7: each bank's last then strongest return, flags FF EE, FF DD, FF CC,
/// FF BB by bank; blocks 8-11 empty; return mode 0x39, product 0xA1), into `dir`. `synth`
/// writes single-return captures only; dual mode is where a resumed reader needs the
/// packet before its first (the firing's azimuth step comes from it).
fn vls128_dual(dir: &Path, rotations: u32) -> PathBuf {
    const FLAGS: [[u8; 2]; 4] = [[0xFF, 0xEE], [0xFF, 0xDD], [0xFF, 0xCC], [0xFF, 0xBB]];
    let mut w = lidar_noise::capture::writer::PcapWriter::new(Vec::new()).unwrap();
    let packets = rotations * 36_000 / 21 + 40;
    for i in 0..packets {
        let ts = 1_000 + (f64::from(i) * 57.8).round() as u32;
        let az = ((i * 21 + 17_000) % 36_000) as u16;
        let mut p = vec![0u8; 1206];
        for b in 0..8usize {
            let at = b * 100;
            p[at..at + 2].copy_from_slice(&FLAGS[b / 2]);
            p[at + 2..at + 4].copy_from_slice(&az.to_le_bytes());
            for ch in 0..32usize {
                // Last 20 m and strongest 12 m, both varying by channel and turn.
                let d = if b % 2 == 0 { 5_000 } else { 3_000 } + (ch as u16) * 7 + (i % 50) as u16;
                let c = at + 4 + ch * 3;
                p[c..c + 2].copy_from_slice(&d.to_le_bytes());
                p[c + 2] = (ch * 5 + b) as u8;
            }
        }
        p[1200..1204].copy_from_slice(&ts.to_le_bytes());
        p[1204] = 0x39;
        p[1205] = 0xA1;
        w.write_udp(u64::from(ts), 2368, 2368, &p).unwrap();
    }
    let path = dir.join("vls128-dual.pcap");
    std::fs::write(&path, w.into_inner().unwrap()).unwrap();
    path
}

/// The frames (index, partial, returns) of `reader` in `frames`.
fn frames_of(
    reader: &mut ModelFrameReader,
    frames: std::ops::RangeInclusive<u32>,
) -> Vec<(u32, bool, Vec<lidar_noise::frame::Return>)> {
    reader
        .read_rest(&frames)
        .unwrap()
        .into_iter()
        .map(|f| (f.index, f.partial, f.returns))
        .collect()
}

#[test]
fn a_reader_resumed_at_a_scanned_frame_yields_the_frames_from_the_start() {
    let dir = tempfile::tempdir().unwrap();
    let mut captures: Vec<(&str, PathBuf)> = ["vlp16", "vlp32c", "hdl64e", "vls128"]
        .into_iter()
        .map(|sensor| (sensor, capture(dir.path(), sensor, 4)))
        .collect();
    captures.push(("vls128 dual", vls128_dual(dir.path(), 4)));
    for (sensor, path) in &captures {
        let options = DecoderOptions {
            keep_partial: true,
            ..DecoderOptions::default()
        };
        let open = || ModelFrameReader::open(path, &options).unwrap().unwrap();
        let all = frames_of(&mut open(), 0..=u32::MAX);
        let scanned: Vec<_> = open().scan().map(Result::unwrap).collect();
        let found: Vec<(u32, bool)> = scanned.iter().map(|f| (f.index, f.partial)).collect();
        let want: Vec<(u32, bool)> = all.iter().map(|f| (f.0, f.1)).collect();
        assert_eq!(found, want, "{sensor}: the scan's frames");
        assert!(all.len() >= 4, "{sensor}: {} frames", all.len());
        for s in &scanned {
            assert_eq!(s.seek.frame, s.index);
            let mut resumed = open();
            resumed.resume_at(path, &s.seek).unwrap();
            let got = frames_of(&mut resumed, s.index..=u32::MAX);
            let tail = &all[all.iter().position(|f| f.0 == s.index).unwrap()..];
            assert_eq!(got.len(), tail.len(), "{sensor}: from frame {}", s.index);
            for (g, w) in got.iter().zip(tail) {
                assert_eq!((g.0, g.1), (w.0, w.1), "{sensor}: from frame {}", s.index);
                assert!(
                    common::same_returns(&g.2, &w.2),
                    "{sensor}: frame {} resumed at {}",
                    g.0,
                    s.index
                );
            }
        }
    }
}

/// `lidar-noise COMMAND capture -c configs/adverse-weather.toml --keep-partial --quiet
/// -o out EXTRA...`, which must succeed.
fn lidar_noise(command: &str, capture: &Path, out: &Path, extra: &[&str]) {
    let o = bin()
        .arg(command)
        .arg(capture)
        .args([
            "-c",
            "configs/adverse-weather.toml",
            "--keep-partial",
            "--quiet",
        ])
        .arg("-o")
        .arg(out)
        .args(extra)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}

fn run(capture: &Path, out: &Path, extra: &[&str]) {
    lidar_noise("run", capture, out, extra);
}

#[test]
fn chunked_and_sharded_runs_of_other_sensors_equal_the_plain_run() {
    let dir = tempfile::tempdir().unwrap();
    let captures = [
        ("vlp16", capture(dir.path(), "vlp16", 3)),
        ("hdl64e", capture(dir.path(), "hdl64e", 3)),
        ("vls128-dual", vls128_dual(dir.path(), 3)),
    ];
    for (sensor, path) in &captures {
        let plain = dir.path().join(format!("{sensor}-plain"));
        run(path, &plain, &[]);
        let expected = common::files(&plain);
        assert!(expected.len() >= 6, "{sensor}: {} files", expected.len());
        let chunked = dir.path().join(format!("{sensor}-chunked"));
        run(path, &chunked, &["--chunk-frames", "2"]);
        assert!(common::files(&chunked) == expected, "{sensor}: chunked");
        // Shards in reverse order, then the merge.
        let sharded = dir.path().join(format!("{sensor}-sharded"));
        for k in ["2/3", "1/3", "0/3"] {
            run(path, &sharded, &["--chunk-frames", "1", "--shard", k]);
        }
        run(path, &sharded, &["--chunk-frames", "1", "--merge"]);
        assert!(common::files(&sharded) == expected, "{sensor}: sharded");
    }
}

#[test]
fn chunked_sweeps_of_other_sensors_equal_the_plain_sweep() {
    let dir = tempfile::tempdir().unwrap();
    let path = capture(dir.path(), "vlp16", 3);
    let sweep = |out: &Path, extra: &[&str]| {
        let vary = ["--vary", "rain.rate_mm_h=0,3", "--seeds", "1..2"];
        lidar_noise("sweep", &path, out, &[&vary[..], extra].concat());
    };
    let plain = dir.path().join("plain");
    sweep(&plain, &[]);
    let expected = common::files(&plain);
    let chunked = dir.path().join("chunked");
    sweep(&chunked, &["--chunk-frames", "2"]);
    assert!(common::files(&chunked) == expected, "chunked");
    let sharded = dir.path().join("sharded");
    for k in ["1/2", "0/2"] {
        sweep(&sharded, &["--chunk-frames", "1", "--shard", k]);
    }
    sweep(&sharded, &["--chunk-frames", "1", "--merge"]);
    assert!(common::files(&sharded) == expected, "sharded");
}
