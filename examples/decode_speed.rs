//! Decodes a capture from memory N times and prints returns per second of CPU time;
//! run under `perf stat` or `time` on a loaded machine (criterion's wall clock suffers).
use lidar_noise::sensor::frames::{DecoderOptions, FrameReader};
use std::path::Path;
use std::sync::Arc;

fn main() {
    let mut args = std::env::args().skip(1);
    let path = args.next().expect("usage: decode_speed CAPTURE [REPEATS]");
    let repeats: usize = args.next().map_or(20, |s| s.parse().expect("REPEATS"));
    let bytes: Arc<[u8]> = Arc::from(std::fs::read(&path).expect("read capture"));
    let options = DecoderOptions {
        keep_partial: true,
        ..DecoderOptions::default()
    };
    let start = std::time::Instant::now();
    let mut total = 0usize;
    for _ in 0..repeats {
        let mut reader =
            FrameReader::from_bytes(bytes.clone(), Path::new(&path), &options).expect("open");
        while let Some(frame) = reader.next() {
            let frame = frame.expect("decode");
            total += frame.returns.len();
            reader.recycle(frame);
        }
    }
    let secs = start.elapsed().as_secs_f64();
    println!(
        "{total} returns in {secs:.3} s wall: {:.1} M returns/s",
        total as f64 / secs / 1e6
    );
}
