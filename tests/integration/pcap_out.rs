//! `run --pcap-out`: the noisy capture decodes back to the noisy returns (2 mm quantum),
//! dropped returns are zero distance, every byte outside the return slots is the input's,
//! dual captures stay dual, unencodable ranges follow the stated rule, and a chain with a
//! stage a packet cannot express is refused before anything is written.

use assert_cmd::Command;
use lidar_noise::capture::writer::{PcapNgWriter, PcapWriter};
use lidar_noise::capture::CaptureReader;
use lidar_noise::config::Config;
use lidar_noise::frame::ReturnKind;
use lidar_noise::noise::Fate;
use lidar_noise::pipeline::Pipeline;
use lidar_noise::sensor::encode::{encode_data_packet, encode_position_packet, FiringBlock};
use lidar_noise::sensor::frames::{DecoderOptions, FrameReader};
use lidar_noise::sensor::packet;
use lidar_noise::sensor::packet::{DATA_PORT, POSITION_PORT};
use lidar_noise::writers::pcap::NoisyCapture;
use std::collections::BTreeMap;
use std::path::Path;
use std::sync::Arc;

/// Range and intensity stages that a packet can carry, on top of the built-in study
/// (occlusion + rain): clock bias and jitter (no drift: it stretches times), ambient
/// range offset and power, receiver intensity gain.
const SETS: &[&str] = &[
    "clock.bias_ns=0.5",
    "clock.jitter_ps=100",
    "clock.drift_ppm=0",
    "ambient.irradiance=0.3",
    "ambient.temperature_c=45",
    "receiver.gain_error=0.8",
];

type Slot = (u32, u8, u8, u8);

fn options() -> DecoderOptions {
    DecoderOptions {
        keep_partial: true,
        ..DecoderOptions::default()
    }
}

fn config() -> Config {
    let sets: Vec<String> = SETS.iter().map(|s| s.to_string()).collect();
    Config::load(None, &sets, None).unwrap().0
}

/// What the library run writes and what it expects back: the noisy capture's bytes,
/// the kept returns per slot (raw distance, intensity, noisy range) and the slots of
/// dropped returns.
struct Expected {
    bytes: Vec<u8>,
    kept: BTreeMap<Slot, (u16, u8, f32)>,
    dropped: Vec<Slot>,
}

fn run_library(input: &[u8], config: &Config) -> Expected {
    let opts = options();
    let pipeline = Pipeline::new(config);
    let capture =
        NoisyCapture::new(input.to_vec(), Path::new("in.pcap"), &opts.calibration).unwrap();
    let mut reader =
        FrameReader::from_bytes(Arc::from(input.to_vec()), Path::new("in.pcap"), &opts).unwrap();
    let (mut kept, mut dropped) = (BTreeMap::new(), Vec::new());
    for frame in reader.by_ref() {
        let result = pipeline.process(frame.unwrap()).unwrap();
        let noisy = &result.noisy;
        capture.encode_frame(noisy);
        for (i, r) in noisy.clean.iter().enumerate() {
            let slot = (r.packet, r.block, r.laser, r.kind as u8);
            if noisy.fate[i] == Fate::Kept {
                let raw = (noisy.range[i] / 0.002).round() as u16;
                let intensity = noisy.moved.intensity.as_ref().map_or(r.intensity, |v| v[i]);
                kept.insert(slot, (raw, intensity, noisy.range[i]));
            } else {
                dropped.push(slot);
            }
        }
    }
    assert_eq!(capture.unencodable(), 0, "no range leaves 0..131 m here");
    Expected {
        bytes: capture.into_bytes(),
        kept,
        dropped,
    }
}

fn decode(bytes: &[u8]) -> BTreeMap<Slot, (u16, u8, f32)> {
    let mut reader = FrameReader::from_bytes(
        Arc::from(bytes.to_vec()),
        Path::new("noisy.pcap"),
        &options(),
    )
    .unwrap();
    let mut out = BTreeMap::new();
    for frame in reader.by_ref() {
        for r in frame.unwrap().returns {
            let slot = (r.packet, r.block, r.laser, r.kind as u8);
            assert!(out
                .insert(slot, (r.raw_distance, r.intensity, r.range))
                .is_none());
        }
    }
    out
}

/// File offsets of every data packet's payload.
fn data_payloads(bytes: &[u8]) -> Vec<(u32, usize)> {
    let mut reader =
        CaptureReader::from_reader(std::io::Cursor::new(bytes.to_vec()), Path::new("x")).unwrap();
    let mut out = Vec::new();
    while let Some(d) = reader.next_datagram().unwrap() {
        if packet::is_data_packet(d.payload) {
            out.push((d.record, d.payload_offset as usize));
        }
    }
    out
}

/// The raw distance bytes of a slot in the written capture.
fn slot_raw(bytes: &[u8], payloads: &BTreeMap<u32, usize>, slot: &Slot) -> [u8; 3] {
    let at = payloads[&slot.0] + usize::from(slot.1) * 100 + 4 + 3 * usize::from(slot.2);
    [bytes[at], bytes[at + 1], bytes[at + 2]]
}

/// Checks the round trip of one capture; returns (kept, dropped) counts.
fn check_round_trip(input: &[u8], name: &str) -> (usize, usize) {
    let expected = run_library(input, &config());
    let out = &expected.bytes;
    assert_eq!(out.len(), input.len(), "{name}: same length");
    // Decode = noisy returns, to the 2 mm quantum.
    let decoded = decode(out);
    assert_eq!(
        decoded.len(),
        expected.kept.len(),
        "{name}: one decoded return per kept return"
    );
    for (slot, (raw, intensity, range)) in &expected.kept {
        let (draw, dint, drange) = decoded
            .get(slot)
            .unwrap_or_else(|| panic!("{name}: kept return {slot:?} missing"));
        assert_eq!((draw, dint), (raw, intensity), "{name}: {slot:?}");
        assert!(
            (drange - range).abs() <= 0.001 + 1e-4,
            "{name}: {slot:?} decoded {drange} m, noisy {range} m"
        );
    }
    // Dropped returns are zero distance on the wire.
    let payloads: BTreeMap<u32, usize> = data_payloads(input).into_iter().collect();
    for slot in &expected.dropped {
        let b = slot_raw(out, &payloads, slot);
        assert_eq!(&b[..2], &[0, 0], "{name}: dropped {slot:?} has a distance");
    }
    // Every byte outside return slots (and the UDP checksum) is the input's.
    let mut may_change = vec![false; input.len()];
    for &at in payloads.values() {
        may_change[at - 2] = true;
        may_change[at - 1] = true;
        for b in 0..12 {
            may_change[at + b * 100 + 4..at + (b + 1) * 100].fill(true);
        }
    }
    let changed = (0..input.len()).filter(|&i| out[i] != input[i]).count();
    for i in 0..input.len() {
        assert!(
            may_change[i] || out[i] == input[i],
            "{name}: byte {i} outside the return slots changed"
        );
    }
    assert!(changed > 0, "{name}: the noise changed nothing on the wire");
    (expected.kept.len(), expected.dropped.len())
}

#[test]
fn fixtures_round_trip_to_the_noisy_returns() {
    for name in ["crossroad", "parking", "empty"] {
        let input = std::fs::read(format!("fixtures/{name}.pcap")).unwrap();
        let (kept, dropped) = check_round_trip(&input, name);
        assert!(kept > 1000, "{name}: {kept} kept");
        assert!(dropped > 0, "{name}: occlusion drops returns");
    }
}

#[test]
fn shared_capture_round_trips_to_the_noisy_returns() {
    let path = Path::new("../shared/data/hdl32e/monterey.pcap");
    if !path.exists() {
        eprintln!("SKIPPED: {} is absent", path.display());
        return;
    }
    let input = std::fs::read(path).unwrap();
    let (kept, dropped) = check_round_trip(&input, "monterey");
    assert!(
        kept > 100_000 && dropped > 0,
        "{kept} kept, {dropped} dropped"
    );
}

/// Two rotations in dual mode (even block last at 10 m + laser, odd block strongest at
/// 20 m + laser), with a position packet every 10 data packets: (time, port, payload).
fn dual_packets() -> Vec<(u64, u16, Vec<u8>)> {
    let (mut firing, mut ts, mut n) = (0u32, 1_000u32, 0);
    let mut out = Vec::new();
    while firing * 20 < 2 * 36000 + 600 {
        let mut blocks = [FiringBlock::default(); 12];
        for (b, block) in blocks.iter_mut().enumerate() {
            block.azimuth = (((firing + b as u32 / 2) * 20) % 36000) as u16;
            for j in 0..32 {
                block.distances[j] = if b % 2 == 1 { 10_000 } else { 5_000 } + j as u16;
                block.intensities[j] = (b * 3 + j) as u8;
            }
        }
        let payload = encode_data_packet(&blocks, ts, 0x39);
        out.push((u64::from(ts), DATA_PORT, payload.to_vec()));
        if n % 10 == 0 {
            let pos = encode_position_packet(ts);
            out.push((u64::from(ts), POSITION_PORT, pos.to_vec()));
        }
        n += 1;
        firing += 6;
        ts += (6.0f64 * 46.08).round() as u32;
    }
    out
}

fn dual_capture() -> Vec<u8> {
    let mut w = PcapWriter::new(Vec::new()).unwrap();
    for (ts, port, payload) in dual_packets() {
        w.write_udp(ts, port, port, &payload).unwrap();
    }
    w.into_inner().unwrap()
}

#[test]
fn pcapng_captures_round_trip_and_are_written_as_pcapng() {
    let mut w = PcapNgWriter::new(Vec::new()).unwrap();
    for (ts, port, payload) in dual_packets() {
        w.write_udp(ts, port, port, &payload).unwrap();
    }
    let input = w.into_inner().unwrap();
    check_round_trip(&input, "pcapng");
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("ng.pcapng");
    std::fs::write(&path, &input).unwrap();
    Command::cargo_bin("lidar-noise")
        .unwrap()
        .arg("run")
        .arg(&path)
        .args(["--pcap-out", "--no-ply", "--keep-partial"])
        .arg("-o")
        .arg(dir.path().join("out"))
        .assert()
        .success();
    let written = std::fs::read(dir.path().join("out/ng/noisy.pcapng")).unwrap();
    assert_eq!(
        &written[..4],
        &[0x0A, 0x0D, 0x0D, 0x0A],
        "a pcapng section header"
    );
    assert_eq!(written.len(), input.len());
}

#[test]
fn dual_captures_stay_dual() {
    let input = dual_capture();
    let (kept, _) = check_round_trip(&input, "dual");
    let out = run_library(&input, &config()).bytes;
    let kinds: Vec<u8> = decode(&out).keys().map(|s| s.3).collect();
    let last = kinds
        .iter()
        .filter(|&&k| k == ReturnKind::DualLast as u8)
        .count();
    let strongest = kinds
        .iter()
        .filter(|&&k| k == ReturnKind::DualStrongest as u8)
        .count();
    assert_eq!(last + strongest, kept);
    assert!(
        last > 0 && strongest > 0,
        "{last} last, {strongest} strongest"
    );
    for (_, at) in data_payloads(&out) {
        assert_eq!(out[at + 1204], 0x39, "the return mode byte stays dual");
    }
}

#[test]
fn ranges_the_wire_cannot_hold_are_written_as_no_return() {
    let input = std::fs::read("fixtures/parking.pcap").unwrap();
    let opts = options();
    let pipeline = Pipeline::new(&config());
    let capture =
        NoisyCapture::new(input.clone(), Path::new("in.pcap"), &opts.calibration).unwrap();
    let mut reader =
        FrameReader::from_bytes(Arc::from(input.clone()), Path::new("in"), &opts).unwrap();
    let frame = reader.next().unwrap().unwrap();
    let mut noisy = pipeline.process(frame).unwrap().noisy;
    let kept: Vec<usize> = (0..noisy.len())
        .filter(|&i| noisy.fate[i] == Fate::Kept)
        .collect();
    // Negative, rounding to zero, just beyond 65535 units, far beyond, and the largest
    // that fits.
    let bad = [-1.0f32, 0.0009, 131.072, 500.0];
    for (k, &v) in bad.iter().enumerate() {
        noisy.range[kept[k]] = v;
    }
    noisy.range[kept[10]] = 131.07;
    capture.encode_frame(&noisy);
    assert_eq!(capture.unencodable(), bad.len() as u64);
    let out = capture.into_bytes();
    let payloads: BTreeMap<u32, usize> = data_payloads(&input).into_iter().collect();
    let slot = |i: usize| {
        let r = &noisy.clean[i];
        slot_raw(&out, &payloads, &(r.packet, r.block, r.laser, r.kind as u8))
    };
    for k in 0..bad.len() {
        assert_eq!(slot(kept[k]), [0, 0, 0], "range {} m", bad[k]);
    }
    let top = slot(kept[10]);
    assert_eq!(u16::from_le_bytes([top[0], top[1]]), 65535);
}

#[test]
fn cli_writes_what_the_library_writes() {
    let dir = tempfile::tempdir().unwrap();
    let input = std::fs::read("fixtures/parking.pcap").unwrap();
    let expected = run_library(&input, &config()).bytes;
    // Workers fill disjoint slots: the bytes do not depend on the thread count.
    for threads in ["1", "2"] {
        let out = dir.path().join(threads);
        let mut cmd = Command::cargo_bin("lidar-noise").unwrap();
        cmd.args([
            "--threads",
            threads,
            "run",
            "fixtures/parking.pcap",
            "--pcap-out",
        ])
        .args(["--keep-partial", "--no-ply"])
        .arg("-o")
        .arg(&out);
        for s in SETS {
            cmd.args(["--set", s]);
        }
        cmd.assert().success();
        let written = std::fs::read(out.join("parking/noisy.pcap")).unwrap();
        assert!(written == expected, "{threads} threads");
    }
}

#[test]
fn a_stage_a_packet_cannot_express_is_refused_before_anything_is_written() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let assert = Command::cargo_bin("lidar-noise")
        .unwrap()
        .args(["run", "fixtures/parking.pcap", "--pcap-out"])
        .args(["--set", "mounting.yaw_deg=1", "--set", "clock.drift_ppm=0"])
        .args(["--set", "clock.time_offset_us=5"])
        .arg("-o")
        .arg(&out)
        .assert()
        .code(1);
    let stderr = String::from_utf8_lossy(&assert.get_output().stderr).to_string();
    assert!(
        stderr.contains("(mounting) changes the position"),
        "{stderr}"
    );
    assert!(
        stderr.contains("(clock) changes the firing time"),
        "{stderr}"
    );
    assert!(
        !stderr.contains("(occlusion)") && !stderr.contains("(rain)"),
        "{stderr}"
    );
    assert!(!out.exists(), "nothing is written");
    // The same chain with the stages at zero is accepted.
    Command::cargo_bin("lidar-noise")
        .unwrap()
        .args(["run", "fixtures/parking.pcap", "--pcap-out", "--no-ply"])
        .args([
            "--set",
            "mounting.sigma_rot_deg=0",
            "--set",
            "mounting.sigma_t_m=0",
        ])
        .args(["--set", "clock.drift_ppm=0"])
        .arg("-o")
        .arg(&out)
        .assert()
        .success();
    assert!(out.join("parking/noisy.pcap").exists());
}

#[test]
fn a_dual_capture_decoded_as_single_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("dual.pcap");
    std::fs::write(&path, dual_capture()).unwrap();
    let out = dir.path().join("out");
    let assert = Command::cargo_bin("lidar-noise")
        .unwrap()
        .arg("run")
        .arg(&path)
        .args(["--pcap-out", "--dual", "last", "-o"])
        .arg(&out)
        .assert()
        .code(1);
    let stderr = String::from_utf8_lossy(&assert.get_output().stderr).to_string();
    assert!(stderr.contains("--dual both"), "{stderr}");
    assert!(!out.exists(), "nothing is written");
}
