//! The sensor's microsecond clock restarts every hour; decoding must carry time across the
//! wrap wherever in the hour the capture starts (issue 10, defect 1).

use crate::common;

use lidar_noise::capture::writer::PcapWriter;
use lidar_noise::capture::CaptureReader;
use lidar_noise::sensor::frames::{DecoderOptions, FrameReader};
use std::path::Path;
use std::sync::Arc;

const HOUR_US: u64 = 3_600_000_000;

struct Record {
    ts_us: u64,
    ports: (u16, u16),
    payload: Vec<u8>,
}

fn records(path: &Path) -> Vec<Record> {
    let mut reader = CaptureReader::open(path).unwrap();
    let mut out = Vec::new();
    while let Some(d) = reader.next_datagram().unwrap() {
        out.push(Record {
            ts_us: d.ts_ns / 1000,
            ports: (d.src_port, d.dst_port),
            payload: d.payload.to_vec(),
        });
    }
    out
}

/// The capture with every data packet's sensor clock moved so that the first reads
/// `start_us` past the hour (wrapping at the hour like the sensor's).
fn shifted(records: &[Record], start_us: u64) -> Vec<u8> {
    let first = records
        .iter()
        .find(|r| r.payload.len() == 1206)
        .map(|r| timestamp(&r.payload))
        .unwrap();
    let mut w = PcapWriter::new(Vec::new()).unwrap();
    for r in records {
        let mut payload = r.payload.clone();
        if payload.len() >= 1204 {
            // Elapsed sensor time since the first packet, with the original wraps undone.
            let ts = timestamp(&payload);
            let elapsed = (ts + HOUR_US - first) % HOUR_US;
            let new = ((start_us + elapsed) % HOUR_US) as u32;
            payload[1200..1204].copy_from_slice(&new.to_le_bytes());
        }
        w.write_udp(r.ts_us, r.ports.0, r.ports.1, &payload)
            .unwrap();
    }
    w.into_inner().unwrap()
}

fn timestamp(p: &[u8]) -> u64 {
    u64::from(u32::from_le_bytes([p[1200], p[1201], p[1202], p[1203]]))
}

/// Duration, rotation rate, frame count and per-frame time spans of a capture.
fn decode(bytes: Vec<u8>) -> (f64, f64, u32, Vec<(u32, usize, f64)>) {
    let mut reader = FrameReader::from_bytes(
        Arc::from(bytes),
        Path::new("shifted.pcap"),
        &DecoderOptions::default(),
    )
    .unwrap();
    let mut frames = Vec::new();
    loop {
        let batch = reader.next_batch(8, &(0..=u32::MAX)).unwrap();
        if batch.is_empty() {
            break;
        }
        for f in batch {
            let t0 = f.returns.iter().map(|r| r.time).fold(f64::MAX, f64::min);
            let t1 = f.returns.iter().map(|r| r.time).fold(f64::MIN, f64::max);
            frames.push((f.index, f.returns.len(), t1 - t0));
        }
    }
    let s = reader.summary();
    (
        s.duration_s,
        s.rotation_hz.unwrap_or(0.0),
        s.full_frames,
        frames,
    )
}

fn check_every_position(path: &Path) {
    let recs = records(path);
    let reference = decode(shifted(&recs, 0));
    assert!(reference.0 > 0.0 && reference.0 < 60.0, "{:?}", reference.0);
    let span_us = (reference.0 * 1e6) as u64;
    // Starts every minute of the hour, plus starts that put the wrap at 16 places inside
    // the capture (first packets to the last ones).
    let mut starts: Vec<u64> = (0..60).map(|m| m * 60_000_000).collect();
    starts.extend((0..=16).map(|k| HOUR_US - 1 - span_us * k / 16));
    for start in starts {
        let got = decode(shifted(&recs, start));
        assert!(
            (got.0 - reference.0).abs() < 1e-6,
            "start {start} us: duration {} s, expected {} s",
            got.0,
            reference.0
        );
        assert!(
            (got.1 - reference.1).abs() < 1e-6,
            "start {start} us: rotation {} Hz, expected {} Hz",
            got.1,
            reference.1
        );
        assert_eq!(got.2, reference.2, "start {start} us: full frames");
        assert_eq!(got.3.len(), reference.3.len(), "start {start} us: frames");
        for (a, b) in got.3.iter().zip(&reference.3) {
            assert_eq!((a.0, a.1), (b.0, b.1), "start {start} us");
            assert!(
                (a.2 - b.2).abs() < 1e-6,
                "start {start} us: frame {} spans {} s, expected {} s",
                a.0,
                a.2,
                b.2
            );
        }
    }
}

#[test]
fn hourly_wrap_at_every_position_on_the_fixture() {
    check_every_position(&common::fixtures().join("crossroad.pcap"));
}

#[test]
fn hourly_wrap_at_every_position_on_the_shared_capture() {
    let Some(path) = common::shared("hdl32e/monterey.pcap") else {
        return;
    };
    check_every_position(&path);
}

/// The records in `order` (indices into `records`), re-written as a capture.
fn reordered(records: &[Record], order: impl Iterator<Item = usize>) -> Vec<u8> {
    let mut w = PcapWriter::new(Vec::new()).unwrap();
    for i in order {
        let r = &records[i];
        w.write_udp(r.ts_us, r.ports.0, r.ports.1, &r.payload)
            .unwrap();
    }
    w.into_inner().unwrap()
}

/// Summary of a capture read to the end.
fn summary_of(bytes: Vec<u8>) -> lidar_noise::sensor::frames::CaptureSummary {
    let mut reader = FrameReader::from_bytes(
        Arc::from(bytes),
        Path::new("reordered.pcap"),
        &DecoderOptions::default(),
    )
    .unwrap();
    for frame in reader.by_ref() {
        frame.unwrap();
    }
    reader.summary()
}

#[test]
fn a_clock_that_runs_backwards_gives_its_span_and_is_reported() {
    // Issue 30, defect 6: reversed packets gave a negative duration (-1.493 s on the
    // shared capture), and the fuzzer found a mutated timestamp doing the same.
    let recs = records(&common::fixtures().join("crossroad.pcap"));
    let forward = summary_of(reordered(&recs, 0..recs.len()));
    assert_eq!(forward.clock_backward_steps, 0);
    assert!(forward.duration_s > 0.05, "{}", forward.duration_s);
    let backward = summary_of(reordered(&recs, (0..recs.len()).rev()));
    let data = recs.iter().filter(|r| r.payload.len() == 1206).count() as u64;
    // Every data packet but the first starts before the one read before it.
    assert_eq!(backward.clock_backward_steps, data - 1);
    // The span of the same firings: the forward duration.
    assert!(
        (backward.duration_s - forward.duration_s).abs() < 1e-9,
        "{} vs {}",
        backward.duration_s,
        forward.duration_s
    );
    // One packet moved back in time: a single backward step, the span unchanged.
    let mut order: Vec<usize> = (0..recs.len()).collect();
    let late = (0..recs.len())
        .rev()
        .find(|&i| recs[i].payload.len() == 1206)
        .unwrap();
    let at = order.len() / 2;
    let moved = order.remove(late);
    order.insert(at, moved);
    let one = summary_of(reordered(&recs, order.into_iter()));
    assert!(
        one.clock_backward_steps >= 1,
        "{}",
        one.clock_backward_steps
    );
    assert!((one.duration_s - forward.duration_s).abs() < 1e-9);
    // The summary's JSON names the count only when the clock ran backwards.
    let json = serde_json::to_string(&forward).unwrap();
    assert!(!json.contains("clock_backward_steps"), "{json}");
    let json = serde_json::to_string(&backward).unwrap();
    assert!(json.contains("\"clock_backward_steps\""), "{json}");
}
