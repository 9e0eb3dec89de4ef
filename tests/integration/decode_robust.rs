//! Container variants, damaged captures and impostor sensors.

use crate::common;

use lidar_noise::frame::Frame;
use lidar_noise::sensor::frames::{DecoderOptions, FrameReader};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::path::Path;
use std::sync::Arc;

/// Classic pcap records: (ts_sec, ts_usec, frame bytes).
fn records(pcap: &[u8]) -> Vec<(u32, u32, Vec<u8>)> {
    assert_eq!(&pcap[..4], &0xa1b2c3d4u32.to_le_bytes());
    let mut out = Vec::new();
    let mut at = 24;
    while at + 16 <= pcap.len() {
        let word = |i: usize| u32::from_le_bytes(pcap[at + i..at + i + 4].try_into().unwrap());
        let caplen = word(8) as usize;
        out.push((word(0), word(4), pcap[at + 16..at + 16 + caplen].to_vec()));
        at += 16 + caplen;
    }
    out
}

fn classic(records: &[(u32, u32, Vec<u8>)], big_endian: bool, nanos: bool) -> Vec<u8> {
    let w32 = |v: u32| {
        if big_endian {
            v.to_be_bytes()
        } else {
            v.to_le_bytes()
        }
    };
    let w16 = |v: u16| {
        if big_endian {
            v.to_be_bytes()
        } else {
            v.to_le_bytes()
        }
    };
    let mut out = Vec::new();
    out.extend_from_slice(&w32(if nanos { 0xa1b23c4d } else { 0xa1b2c3d4 }));
    out.extend_from_slice(&w16(2));
    out.extend_from_slice(&w16(4));
    out.extend_from_slice(&w32(0));
    out.extend_from_slice(&w32(0));
    out.extend_from_slice(&w32(65535));
    out.extend_from_slice(&w32(1));
    for (sec, usec, data) in records {
        out.extend_from_slice(&w32(*sec));
        out.extend_from_slice(&w32(if nanos { usec * 1000 } else { *usec }));
        out.extend_from_slice(&w32(data.len() as u32));
        out.extend_from_slice(&w32(data.len() as u32));
        out.extend_from_slice(data);
    }
    out
}

/// The same records as pcapng: section header, one Ethernet interface, enhanced packets.
fn pcapng(records: &[(u32, u32, Vec<u8>)]) -> Vec<u8> {
    let mut out = Vec::new();
    let block = |out: &mut Vec<u8>, kind: u32, body: &[u8]| {
        let padded = body.len().div_ceil(4) * 4;
        let len = (12 + padded) as u32;
        out.extend_from_slice(&kind.to_le_bytes());
        out.extend_from_slice(&len.to_le_bytes());
        out.extend_from_slice(body);
        out.resize(out.len() + padded - body.len(), 0);
        out.extend_from_slice(&len.to_le_bytes());
    };
    let mut shb = Vec::new();
    shb.extend_from_slice(&0x1a2b3c4du32.to_le_bytes());
    shb.extend_from_slice(&1u16.to_le_bytes());
    shb.extend_from_slice(&0u16.to_le_bytes());
    shb.extend_from_slice(&(-1i64).to_le_bytes());
    block(&mut out, 0x0a0d0d0a, &shb);
    let mut idb = Vec::new();
    idb.extend_from_slice(&1u16.to_le_bytes());
    idb.extend_from_slice(&0u16.to_le_bytes());
    idb.extend_from_slice(&0u32.to_le_bytes());
    block(&mut out, 1, &idb);
    for (sec, usec, data) in records {
        let ts = u64::from(*sec) * 1_000_000 + u64::from(*usec);
        let mut epb = Vec::new();
        epb.extend_from_slice(&0u32.to_le_bytes());
        epb.extend_from_slice(&((ts >> 32) as u32).to_le_bytes());
        epb.extend_from_slice(&(ts as u32).to_le_bytes());
        epb.extend_from_slice(&(data.len() as u32).to_le_bytes());
        epb.extend_from_slice(&(data.len() as u32).to_le_bytes());
        epb.extend_from_slice(data);
        block(&mut out, 6, &epb);
    }
    out
}

fn decode(bytes: Vec<u8>, opts: &DecoderOptions) -> lidar_noise::error::Result<Vec<Frame>> {
    let reader = FrameReader::from_bytes(Arc::from(bytes), Path::new("test.pcap"), opts)?;
    reader.collect()
}

fn keep_all() -> DecoderOptions {
    DecoderOptions {
        keep_partial: true,
        ..DecoderOptions::default()
    }
}

#[test]
fn pcapng_big_endian_and_nanosecond_rewrites_decode_to_identical_returns() {
    let Some(path) = common::shared("hdl32e/monterey.pcap") else {
        return;
    };
    let original = std::fs::read(path).unwrap();
    let recs = records(&original);
    let reference = decode(original, &keep_all()).unwrap();
    assert!(reference.len() > 10);
    for (name, bytes) in [
        ("pcapng", pcapng(&recs)),
        ("big-endian", classic(&recs, true, false)),
        ("nanosecond", classic(&recs, false, true)),
    ] {
        let frames = decode(bytes, &keep_all()).unwrap();
        assert_eq!(frames.len(), reference.len(), "{name}");
        for (a, b) in frames.iter().zip(&reference) {
            assert_eq!(a.index, b.index, "{name}");
            assert_eq!(a.partial, b.partial, "{name}");
            assert!(a.returns == b.returns, "{name}: frame {} differs", a.index);
        }
    }
}

#[test]
fn vlp16_patched_to_say_hdl32e_is_refused_by_its_structure() {
    let Some(path) = common::shared("negative/vlp16_mrpt.pcap") else {
        return;
    };
    let bytes = std::fs::read(path).unwrap();
    let mut recs = records(&bytes);
    let mut patched = 0;
    for (_, _, frame) in &mut recs {
        let n = frame.len();
        if n == 42 + 1206 && frame[n - 1] == 0x22 {
            frame[n - 1] = 0x21;
            patched += 1;
        }
    }
    assert!(patched > 10, "expected VLP-16 data packets to patch");
    let err = decode(classic(&recs, false, false), &keep_all()).expect_err("must refuse");
    let msg = err.to_string();
    assert!(msg.contains("VLP-16") && msg.contains("0x21"), "{msg}");
}

/// A few hundred packets of the real capture: big enough for frames, small enough to
/// damage hundreds of times.
fn small_capture() -> Option<Vec<u8>> {
    let path = common::shared("hdl32e/monterey.pcap")?;
    let recs = records(&std::fs::read(path).unwrap());
    Some(classic(&recs[..400], false, false))
}

#[test]
fn truncation_at_any_offset_decodes_whole_packets_and_never_panics() {
    let Some(bytes) = small_capture() else { return };
    let full: usize = decode(bytes.clone(), &keep_all())
        .unwrap()
        .iter()
        .map(|f| f.returns.len())
        .sum();
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let mut offsets: Vec<usize> = (0..64).collect();
    offsets.extend((0..300).map(|_| rng.random_range(0..bytes.len())));
    let mut decoded_cases = 0;
    for cut in offsets {
        let result = decode(bytes[..cut].to_vec(), &keep_all());
        match result {
            Ok(frames) => {
                decoded_cases += 1;
                let n: usize = frames.iter().map(|f| f.returns.len()).sum();
                assert!(
                    n <= full,
                    "cut at {cut}: more returns than the whole capture"
                );
            }
            Err(e) => assert!(e.to_string().contains("test.pcap"), "cut at {cut}: {e}"),
        }
    }
    assert!(
        decoded_cases > 250,
        "most cuts leave whole packets to decode"
    );
}

#[test]
fn truncated_capture_reports_the_byte_offset() {
    let Some(bytes) = small_capture() else { return };
    let cut = bytes.len() - 500;
    let mut reader = FrameReader::from_bytes(
        Arc::from(bytes[..cut].to_vec()),
        Path::new("t.pcap"),
        &keep_all(),
    )
    .unwrap();
    for frame in reader.by_ref() {
        frame.unwrap();
    }
    let summary = reader.summary();
    let offset = summary.capture.truncated_at.expect("truncation reported") as usize;
    assert!(
        offset < cut && offset + 1248 + 16 > cut,
        "offset {offset} for a cut at {cut}"
    );
    assert_eq!(
        summary.data_packets + summary.position_packets,
        summary.capture.records
    );
}

#[test]
fn corrupted_bytes_never_panic() {
    let Some(bytes) = small_capture() else { return };
    let ng = {
        let recs = records(&bytes);
        pcapng(&recs[..120])
    };
    for seed in 0..300u64 {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let base = if seed % 3 == 0 { &ng } else { &bytes };
        let mut damaged = base.clone();
        let flips = rng.random_range(1..40);
        for _ in 0..flips {
            let at = if rng.random_bool(0.3) {
                rng.random_range(0..damaged.len().min(64))
            } else {
                rng.random_range(0..damaged.len())
            };
            damaged[at] = rng.random();
        }
        if seed % 5 == 0 {
            let cut = rng.random_range(0..damaged.len());
            damaged.truncate(cut);
        }
        // Decoding either succeeds or fails cleanly with the file named.
        if let Err(e) = decode(damaged, &keep_all()) {
            assert!(e.to_string().contains("test.pcap"), "seed {seed}: {e}");
        }
    }
}

#[test]
fn not_a_capture_is_an_error_naming_the_file() {
    for bytes in [
        Vec::new(),
        b"hello world, not a capture".to_vec(),
        vec![0xd4, 0xc3],
    ] {
        let err = decode(bytes, &keep_all()).expect_err("must fail");
        assert!(err.to_string().contains("test.pcap"), "{err}");
    }
}
