//! Decoding speed: the shared HDL-32E capture, in memory, to returns with xyz.

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use lidar_noise::sensor::frames::{DecoderOptions, FrameReader};
use std::path::{Path, PathBuf};
use std::sync::Arc;

fn bench_decode(c: &mut Criterion) {
    let path =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/data/hdl32e/monterey.pcap");
    let Ok(bytes) = std::fs::read(&path) else {
        eprintln!("SKIPPED: {} is absent", path.display());
        return;
    };
    let bytes: Arc<[u8]> = Arc::from(bytes);
    let options = DecoderOptions {
        keep_partial: true,
        ..DecoderOptions::default()
    };
    let count = |bytes: &Arc<[u8]>| -> usize {
        let mut reader =
            FrameReader::from_bytes(bytes.clone(), Path::new("monterey.pcap"), &options).unwrap();
        let mut n = 0;
        while let Some(frame) = reader.next() {
            let frame = frame.unwrap();
            n += frame.returns.len();
            reader.recycle(frame);
        }
        n
    };
    let returns = count(&bytes);
    let mut group = c.benchmark_group("decode");
    group.throughput(Throughput::Elements(returns as u64));
    group.sample_size(30);
    group.bench_function("monterey_to_returns_xyz", |b| b.iter(|| count(&bytes)));
    group.finish();
}

criterion_group!(benches, bench_decode);
criterion_main!(benches);
