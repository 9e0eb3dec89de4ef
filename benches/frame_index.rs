//! Frame index: scanning a capture's frame starts (no returns decoded) against decoding
//! it, and reading the middle frame resumed at its start against decoding up to it (what
//! a chunk of a sharded run or sweep saves), on the shared HDL-32E capture in memory.

use criterion::{criterion_group, criterion_main, Criterion};
use lidar_noise::sensor::frames::{DecoderOptions, FrameReader};
use lidar_noise::sensor::index::FrameScan;
use std::path::{Path, PathBuf};
use std::sync::Arc;

fn bench_index(c: &mut Criterion) {
    let path =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/data/hdl32e/monterey.pcap");
    let Ok(bytes) = std::fs::read(&path) else {
        eprintln!("SKIPPED: {} is absent", path.display());
        return;
    };
    let bytes: Arc<[u8]> = Arc::from(bytes);
    let name = Path::new("monterey.pcap");
    let options = DecoderOptions {
        keep_partial: true,
        ..DecoderOptions::default()
    };
    let frames: Vec<_> = FrameScan::from_bytes(bytes.clone(), name, &options)
        .unwrap()
        .map(Result::unwrap)
        .collect();
    let middle = frames[frames.len() / 2].clone();
    let mut group = c.benchmark_group("frame_index");
    group.sample_size(20);
    group.bench_function("scan_frame_starts", |b| {
        b.iter(|| {
            FrameScan::from_bytes(bytes.clone(), name, &options)
                .unwrap()
                .count()
        })
    });
    group.bench_function("decode_every_frame", |b| {
        b.iter(|| {
            let mut reader = FrameReader::from_bytes(bytes.clone(), name, &options).unwrap();
            let mut n = 0;
            while let Some(frame) = reader.next() {
                let frame = frame.unwrap();
                n += frame.returns.len();
                reader.recycle(frame);
            }
            n
        })
    });
    group.bench_function("middle_frame_resumed", |b| {
        b.iter(|| {
            let mut reader =
                FrameReader::from_bytes_at(bytes.clone(), name, &options, &middle.seek).unwrap();
            reader.next().unwrap().unwrap().returns.len()
        })
    });
    group.bench_function("middle_frame_decoded_from_the_start", |b| {
        b.iter(|| {
            let reader = FrameReader::from_bytes(bytes.clone(), name, &options).unwrap();
            reader
                .map(Result::unwrap)
                .find(|f| f.index == middle.index)
                .unwrap()
                .returns
                .len()
        })
    });
    group.finish();
}

criterion_group!(benches, bench_index);
criterion_main!(benches);
