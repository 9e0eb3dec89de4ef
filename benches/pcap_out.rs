//! Cost of `run --pcap-out` per frame (target: under 1 ms per frame on one core), on one
//! frame of 50,304 returns (131 data packets):
//! - the worker's part: turning the frame into slot patches (`encode_frame`);
//! - the whole per-frame cost: patches, then the streamed output of that frame's 131
//!   packets (second sequential reading of the input, copy, slots cleared, patches
//!   applied), as `frame_done`/`finish` write it. Setting up a capture (three readers) is
//!   not per frame and is included here for a one-frame capture.

use criterion::{criterion_group, criterion_main, BatchSize, Criterion};
use lidar_noise::capture::writer::PcapWriter;
use lidar_noise::config::Config;
use lidar_noise::noise::NoiseChain;
use lidar_noise::sensor::encode::{encode_data_packet, FiringBlock};
use lidar_noise::sensor::frames::{DecoderOptions, FrameReader};
use lidar_noise::sensor::packet::DATA_PORT;
use lidar_noise::writers::pcap::NoisyCapture;
use std::hint::black_box;
use std::path::Path;
use std::sync::Arc;

/// 131 packets, every slot returning (1..80 m, varied intensities): one frame of 50,304
/// returns over 314 degrees.
fn capture() -> Vec<u8> {
    let mut w = PcapWriter::new(Vec::new()).unwrap();
    let mut ts = 1_000u32;
    for p in 0..131u32 {
        let mut blocks = [FiringBlock::default(); 12];
        for (b, block) in blocks.iter_mut().enumerate() {
            let f = p * 12 + b as u32;
            block.azimuth = ((f * 20) % 36000) as u16;
            for j in 0..32 {
                let i = f * 32 + j as u32;
                block.distances[j] = 500 + (i.wrapping_mul(2_654_435_761) % 39_500) as u16;
                block.intensities[j] = (i % 101) as u8;
            }
        }
        let payload = encode_data_packet(&blocks, ts, 0x37);
        w.write_udp(u64::from(ts), DATA_PORT, DATA_PORT, &payload)
            .unwrap();
        ts += 553;
    }
    w.into_inner().unwrap()
}

fn bench_pcap_out(c: &mut Criterion) {
    let bytes = capture();
    let opts = DecoderOptions {
        keep_partial: true,
        ..DecoderOptions::default()
    };
    let mut reader =
        FrameReader::from_bytes(Arc::from(bytes.clone()), Path::new("bench.pcap"), &opts).unwrap();
    let frame = reader.next().unwrap().unwrap();
    assert_eq!(frame.returns.len(), 131 * 384);
    let (config, _) = Config::load(None, &[], None).expect("built-in config");
    let noisy = NoiseChain::new(&config).process(&frame);
    let new = || NoisyCapture::new(bytes.clone(), Path::new("bench.pcap"), &opts.calibration);
    c.bench_function("pcap-out encode frame, 50k returns", |b| {
        b.iter_batched(
            || new().unwrap(),
            |out| {
                out.encode_frame(black_box(&noisy));
                out
            },
            BatchSize::SmallInput,
        )
    });
    c.bench_function("pcap-out encode and write frame, 50k returns", |b| {
        b.iter_batched(
            || bytes.clone(),
            |input| {
                let out =
                    NoisyCapture::new(input, Path::new("bench.pcap"), &opts.calibration).unwrap();
                out.encode_frame(black_box(&noisy));
                out.frame_done(noisy.index).unwrap();
                out.into_bytes()
            },
            BatchSize::SmallInput,
        )
    });
}

criterion_group!(benches, bench_pcap_out);
criterion_main!(benches);
