//! `--pcap-out` with spurious returns (issue 12): replaced returns carry the echo's range
//! and intensity in their own slot, added returns land in the vacant slots they were
//! resolved into, dual captures keep both entries of a slot, and the streamed output
//! (written as frames complete) is byte for byte the whole-copy re-encoding.
//!
//! Frames come from the built-in chain (occlusion + rain); echoes are proposed on top with
//! `propose`/`propose_slot` and chosen by `noise::spurious::resolve`, as a world stage's
//! would be.

use lidar_noise::capture::writer::PcapWriter;
use lidar_noise::capture::CaptureReader;
use lidar_noise::config::Config;
use lidar_noise::frame::ReturnKind;
use lidar_noise::noise::spurious::{resolve, Echo};
use lidar_noise::noise::{Fate, NoiseChain, NoisyFrame};
use lidar_noise::sensor::encode::{encode_data_packet, encode_position_packet, FiringBlock};
use lidar_noise::sensor::frames::{DecoderOptions, FrameReader};
use lidar_noise::sensor::packet;
use lidar_noise::sensor::packet::{DATA_PORT, POSITION_PORT};
use lidar_noise::writers::pcap::NoisyCapture;
use std::collections::BTreeMap;
use std::path::Path;
use std::sync::Arc;

/// (record, block, laser, kind) of a return slot entry.
type Slot = (u32, u8, u8, u8);

/// The stage index the test's echoes are attributed to.
const ECHO_STAGE: u8 = 7;

fn options() -> DecoderOptions {
    DecoderOptions {
        keep_partial: true,
        ..DecoderOptions::default()
    }
}

fn frames(input: &[u8]) -> Vec<lidar_noise::frame::Frame> {
    let reader =
        FrameReader::from_bytes(Arc::from(input.to_vec()), Path::new("in.pcap"), &options())
            .unwrap();
    reader.map(|f| f.unwrap()).collect()
}

/// The built-in chain's output for every frame, with spurious echoes proposed on top and
/// resolved: every 7th alive recorded return gets a stronger echo at 60 % of its range
/// (`propose`), every 5th vacant slot an echo at 20-69 m (`propose_slot`).
fn noisy_frames(input: &[u8]) -> Vec<NoisyFrame> {
    let (config, _) = Config::load(None, &[], None).unwrap();
    let chain = NoiseChain::new(&config);
    frames(input)
        .into_iter()
        .map(|frame| {
            let mut noisy = chain.process(&frame);
            noisy.stage = ECHO_STAGE;
            for i in (0..noisy.clean_len).step_by(7) {
                if noisy.fate[i].is_alive() {
                    let echo = Echo {
                        range: noisy.range[i] * 0.6,
                        power: noisy.power[i] * 4.0,
                    };
                    noisy.propose(i, echo);
                }
            }
            let slots = noisy.slots();
            let vacant: Vec<u32> = (0..slots.len() as u32)
                .filter(|&s| slots.is_vacant(s))
                .collect();
            for (k, &s) in vacant.iter().enumerate().step_by(5) {
                let echo = Echo {
                    range: 20.0 + (k % 50) as f32,
                    power: noisy.threshold * (2.0 + (k % 13) as f64),
                };
                noisy.propose_slot(s, echo);
            }
            resolve(&mut noisy);
            noisy
        })
        .collect()
}

/// The raw distance of a range in the built-in calibration (no distance offsets), or
/// `None` when a packet cannot hold it (rounds below 1 or above 65535 units).
fn wire_distance(range: f32) -> Option<u16> {
    let q = (range / 0.002).round();
    (1.0..=65535.0).contains(&q).then_some(q as u16)
}

/// Alive returns a packet cannot hold.
fn unencodable(frames: &[NoisyFrame]) -> u64 {
    let alive =
        |f: &NoisyFrame, i: usize| f.fate[i].is_alive() && wire_distance(f.range[i]).is_none();
    frames
        .iter()
        .map(|f| (0..f.len()).filter(|&i| alive(f, i)).count() as u64)
        .sum()
}

/// What the sensor now reports, per slot entry: (raw distance, intensity, range, fate).
fn reported(frames: &[NoisyFrame]) -> BTreeMap<Slot, (u16, u8, f32, Fate)> {
    let mut out = BTreeMap::new();
    for f in frames {
        for (i, r) in f.clean.iter().enumerate() {
            if !f.fate[i].is_alive() {
                continue;
            }
            let slot = (r.packet, r.block, r.laser, r.kind as u8);
            let Some(raw) = wire_distance(f.range[i]) else {
                continue; // written as no return (manual, "Noisy capture out": ranges the wire cannot hold)
            };
            let intensity = f.moved.intensity.as_ref().map_or(r.intensity, |v| v[i]);
            let before = out.insert(slot, (raw, intensity, f.range[i], f.fate[i]));
            assert!(before.is_none(), "two reported returns in slot {slot:?}");
        }
    }
    out
}

/// Decodes a capture with this tool's decoder: (raw distance, intensity, range) per slot.
fn decode(bytes: &[u8]) -> BTreeMap<Slot, (u16, u8, f32)> {
    let mut out = BTreeMap::new();
    for frame in frames(bytes) {
        for r in frame.returns {
            let slot = (r.packet, r.block, r.laser, r.kind as u8);
            assert!(out
                .insert(slot, (r.raw_distance, r.intensity, r.range))
                .is_none());
        }
    }
    out
}

/// Streams the frames through `NoisyCapture` as `run` does: encoded in an order other
/// than the capture's (workers), completed in frame order (`frame_done`).
fn streamed(input: &[u8], frames: &[NoisyFrame]) -> Vec<u8> {
    let opts = options();
    let capture =
        NoisyCapture::new(input.to_vec(), Path::new("in.pcap"), &opts.calibration).unwrap();
    for pair in frames.chunks(2) {
        for f in pair.iter().rev() {
            capture.encode_frame(f);
        }
        for f in pair {
            capture.frame_done(f.index).unwrap();
        }
    }
    assert_eq!(capture.unencodable(), unencodable(frames));
    capture.into_bytes()
}

/// The re-encoding as a whole copy of the input (the writer before it streamed): every
/// data payload's return slots cleared and its UDP checksum zeroed, then every alive
/// return written into its slot.
fn whole_copy(input: &[u8], frames: &[NoisyFrame]) -> Vec<u8> {
    let mut out = input.to_vec();
    let mut payloads = BTreeMap::new();
    let mut reader =
        CaptureReader::from_reader(std::io::Cursor::new(input.to_vec()), Path::new("x")).unwrap();
    while let Some(d) = reader.next_datagram().unwrap() {
        if packet::is_data_packet(d.payload) {
            payloads.insert(d.record, d.payload_offset as usize);
        }
    }
    for &at in payloads.values() {
        out[at - 2..at].fill(0);
        for b in 0..12 {
            out[at + b * 100 + 4..at + (b + 1) * 100].fill(0);
        }
    }
    for (slot, (raw, intensity, _, _)) in reported(frames) {
        let at = payloads[&slot.0] + usize::from(slot.1) * 100 + 4 + 3 * usize::from(slot.2);
        out[at..at + 2].copy_from_slice(&raw.to_le_bytes());
        out[at + 2] = intensity;
    }
    out
}

/// Checks the round trip with the test's echoes; returns the number of (replaced,
/// added) returns.
fn check(input: &[u8], name: &str) -> (usize, usize) {
    let frames = noisy_frames(input);
    // The echoes' intensities come from their power and range, not a constant.
    let echo_intensities: std::collections::BTreeSet<u8> = reported(&frames)
        .values()
        .filter(|v| v.3.is_spurious())
        .map(|v| v.1)
        .collect();
    assert!(echo_intensities.len() > 3, "{name}: {echo_intensities:?}");
    check_frames(input, &frames, name)
}

/// Checks the round trip of `frames` (the processed frames of `input`): the streamed
/// bytes are the whole-copy re-encoding and decode to exactly the reported returns.
fn check_frames(input: &[u8], frames: &[NoisyFrame], name: &str) -> (usize, usize) {
    let expected = reported(frames);
    let out = streamed(input, frames);
    assert!(
        out == whole_copy(input, frames),
        "{name}: the streamed bytes differ from the whole-copy re-encoding"
    );
    let decoded = decode(&out);
    // The same set of reported slot entries, both ways.
    let missing: Vec<_> = expected
        .keys()
        .filter(|s| !decoded.contains_key(s))
        .collect();
    let extra: Vec<_> = decoded
        .keys()
        .filter(|s| !expected.contains_key(s))
        .collect();
    assert!(
        missing.is_empty() && extra.is_empty(),
        "{name}: {} reported returns not decoded (first {:?}), {} decoded returns not \
         reported (first {:?})",
        missing.len(),
        missing.first(),
        extra.len(),
        extra.first()
    );
    for (slot, (raw, intensity, range, fate)) in &expected {
        let (draw, dint, drange) = decoded[slot];
        assert_eq!(
            (draw, dint),
            (*raw, *intensity),
            "{name}: {fate:?} {slot:?}"
        );
        assert!(
            (drange - range).abs() <= 0.001 + 1e-4,
            "{name}: {fate:?} {slot:?} decoded {drange} m, noisy {range} m"
        );
    }
    let count = |f: Fate| expected.values().filter(|v| v.3 == f).count();
    (count(Fate::Replaced), count(Fate::Added))
}

#[test]
fn spurious_returns_round_trip_in_a_single_return_capture() {
    let input = std::fs::read("fixtures/parking.pcap").unwrap();
    let (replaced, added) = check(&input, "parking");
    assert!(replaced > 1000, "{replaced} replaced");
    assert!(added > 1000, "{added} added");
}

/// One rotation and a bit in dual mode (0x39): even block last at 10 m + laser, odd block
/// strongest at 20 m + laser, or one echo in both when `(firing + laser) % 9 == 0`; every
/// laser with `(firing + laser) % 5 == 0` has no return at all (vacant slots).
fn dual_capture() -> Vec<u8> {
    let mut w = PcapWriter::new(Vec::new()).unwrap();
    let (mut firing, mut ts, mut n) = (0u32, 1_000u32, 0);
    while firing * 20 < 36000 + 2400 {
        let mut blocks = [FiringBlock::default(); 12];
        for (b, block) in blocks.iter_mut().enumerate() {
            let f = firing + b as u32 / 2;
            block.azimuth = ((f * 20) % 36000) as u16;
            for j in 0..32u32 {
                let (last, strongest) = match (f + j) % 45 {
                    x if x % 5 == 0 => (0, 0),
                    x if x % 9 == 0 => (7_000 + j as u16, 7_000 + j as u16),
                    _ => (10_000 + j as u16, 5_000 + j as u16),
                };
                block.distances[j as usize] = if b % 2 == 0 { last } else { strongest };
                block.intensities[j as usize] = (b * 3 + j as usize) as u8;
            }
        }
        let payload = encode_data_packet(&blocks, ts, 0x39);
        w.write_udp(u64::from(ts), DATA_PORT, DATA_PORT, &payload)
            .unwrap();
        if n % 10 == 0 {
            let pos = encode_position_packet(ts);
            w.write_udp(u64::from(ts), POSITION_PORT, POSITION_PORT, &pos)
                .unwrap();
        }
        n += 1;
        firing += 6;
        ts += (6.0f64 * 46.08).round() as u32;
    }
    w.into_inner().unwrap()
}

#[test]
fn spurious_returns_round_trip_in_a_dual_capture_and_it_stays_dual() {
    let input = dual_capture();
    let (replaced, added) = check(&input, "dual");
    assert!(replaced > 100, "{replaced} replaced");
    assert!(added > 100, "{added} added");
    // Every added return has its partner in the other block of its firing slot: a dual
    // sensor reports a single echo as both the last and the strongest return.
    let frames = noisy_frames(&input);
    let reported = reported(&frames);
    for (slot, v) in &reported {
        if v.3 == Fate::Added {
            let (partner_block, partner_kind) = if slot.3 == ReturnKind::DualLast as u8 {
                (slot.1 + 1, ReturnKind::DualStrongest as u8)
            } else {
                (slot.1 - 1, ReturnKind::DualLast as u8)
            };
            assert_eq!(
                slot.1 % 2,
                u8::from(slot.3 == ReturnKind::DualStrongest as u8)
            );
            let partner = reported
                .get(&(slot.0, partner_block, slot.2, partner_kind))
                .unwrap_or_else(|| panic!("added {slot:?} has no partner entry"));
            assert!(partner.3.is_spurious(), "{slot:?}: partner {partner:?}");
        }
    }
    let out = streamed(&input, &frames);
    let mut reader =
        CaptureReader::from_reader(std::io::Cursor::new(out), Path::new("noisy")).unwrap();
    let mut data = 0;
    while let Some(d) = reader.next_datagram().unwrap() {
        if packet::is_data_packet(d.payload) {
            assert_eq!(d.payload[1204], 0x39, "the return mode byte stays dual");
            data += 1;
        }
    }
    assert!(data > 100);
}

#[test]
fn frame_done_writes_only_what_no_later_frame_can_touch() {
    // Frames completed one by one, each right after it is encoded, give the same bytes as
    // all frames encoded first and written at the end.
    let input = std::fs::read("fixtures/crossroad.pcap").unwrap();
    let frames = noisy_frames(&input);
    assert!(frames.len() >= 3);
    let opts = options();
    let one_by_one =
        NoisyCapture::new(input.clone(), Path::new("in.pcap"), &opts.calibration).unwrap();
    for f in &frames {
        one_by_one.encode_frame(f);
        one_by_one.frame_done(f.index).unwrap();
    }
    let at_end = NoisyCapture::new(input.clone(), Path::new("in.pcap"), &opts.calibration).unwrap();
    for f in frames.iter().rev() {
        at_end.encode_frame(f);
    }
    let one_by_one = one_by_one.into_bytes();
    assert!(one_by_one == at_end.into_bytes());
    assert!(one_by_one == whole_copy(&input, &frames));
}

#[test]
fn a_streamed_capture_appears_only_when_finished() {
    let input = std::fs::read("fixtures/empty.pcap").unwrap();
    let frames = noisy_frames(&input);
    let dir = tempfile::tempdir().unwrap();
    let source = lidar_noise::writers::pcap::Source::File("fixtures/empty.pcap".into());
    let calibration = options().calibration;
    let capture = NoisyCapture::create(
        source.clone(),
        Path::new("fixtures/empty.pcap"),
        lidar_noise::writers::pcap::Wire::Hdl32e(&calibration),
        dir.path(),
        &[],
    )
    .unwrap();
    let target = dir.path().join("noisy.pcap");
    for f in &frames {
        capture.encode_frame(f);
        capture.frame_done(f.index).unwrap();
        assert!(!target.exists(), "no output before finish");
    }
    assert_eq!(capture.finish().unwrap(), 0);
    let written = std::fs::read(&target).unwrap();
    assert!(written == whole_copy(&input, &frames));
    let names: Vec<String> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert_eq!(names, ["noisy.pcap"], "no temporary file is left");
    // Dropped unfinished (an error elsewhere in the run): nothing is left behind.
    let out = dir.path().join("again");
    std::fs::create_dir(&out).unwrap();
    let capture = NoisyCapture::create(
        source,
        Path::new("fixtures/empty.pcap"),
        lidar_noise::writers::pcap::Wire::Hdl32e(&calibration),
        &out,
        &[],
    )
    .unwrap();
    capture.encode_frame(&frames[0]);
    capture.frame_done(frames[0].index).unwrap();
    drop(capture);
    assert_eq!(std::fs::read_dir(&out).unwrap().count(), 0);
    // An input named like the output is never overwritten, and nothing is created.
    let input_dir = dir.path().join("in");
    std::fs::create_dir(&input_dir).unwrap();
    let precious = input_dir.join("noisy.pcap");
    std::fs::write(&precious, &input).unwrap();
    let err = NoisyCapture::create(
        lidar_noise::writers::pcap::Source::File(precious.clone()),
        &precious,
        lidar_noise::writers::pcap::Wire::Hdl32e(&calibration),
        &input_dir,
        &[&precious],
    )
    .err()
    .expect("refused");
    assert!(err.to_string().contains("refusing to overwrite"), "{err}");
    assert_eq!(std::fs::read_dir(&input_dir).unwrap().count(), 1);
    assert!(std::fs::read(&precious).unwrap() == input);
}
