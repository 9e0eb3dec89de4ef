//! Speed of a dataset scan's way in (issue 31, "Speed"): a synthesized 120,000-point KITTI
//! `.bin` (the HDL-64E's 64 beams of the built-in table, 1875 points a beam around the
//! turn, ranges 4 to 60 m) read from memory and from a file in the page cache (target:
//! at least 1 GB/s), and its points turned into HDL-64E S2 returns (the firing grid, the
//! laser from the elevation); and its way out: the per-point `fate.csv` sidecar a dataset
//! run writes beside each scan. With `LIDAR_NOISE_BENCH_KITTI=path/to/scan.bin` also the
//! same conversion of that real scan (whose points collide on the firing grid and share
//! slots as a synthesized one's do not; SemanticKITTI 00/000964 has been the project's).
//!
//! `cargo bench --bench cloud` (one core: `taskset -c 0 cargo bench --bench cloud`).

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use lidar_noise::cloud::returns::{to_returns, ReturnsOptions};
use lidar_noise::cloud::{read_bytes, read_file, Format, IntensityScale, ReadOptions};
use lidar_noise::sensor::HDL64E_S2;
use lidar_noise::writers::scan::{Fates, ScanPoint};
use lidar_noise::writers::Output;
use std::path::Path;

/// The scan's bytes: float32 x y z reflectance a point, beam by beam as KITTI stores it.
fn scan_bytes() -> Vec<u8> {
    let mut out = Vec::with_capacity(120_000 * 16);
    for (laser, &el) in HDL64E_S2.elevation_deg.iter().enumerate() {
        for k in 0..1875u32 {
            let az = f64::from(k) * 360.0 / 1875.0;
            // A range that varies along the turn and by beam, as a street scene would.
            let r = 4.0 + 56.0 * ((f64::from(k) * 0.013 + laser as f64 * 0.7).sin() * 0.5 + 0.5);
            let (se, ce) = el.to_radians().sin_cos();
            let (sa, ca) = az.to_radians().sin_cos();
            for v in [r * ce * ca, -r * ce * sa, r * se, 0.3] {
                out.extend_from_slice(&(v as f32).to_le_bytes());
            }
        }
    }
    out
}

fn bench_cloud(c: &mut Criterion) {
    let bytes = scan_bytes();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("000000.bin");
    std::fs::write(&path, &bytes).unwrap();
    let options = ReadOptions {
        format: Some(Format::Kitti),
        lasers: Some(64),
    };
    let mut group = c.benchmark_group("cloud");
    group.sample_size(20);
    group.throughput(Throughput::Bytes(bytes.len() as u64));
    group.bench_function("kitti_120k_parse_from_memory", |b| {
        b.iter(|| read_bytes(&bytes, Path::new("000000.bin"), &options).unwrap())
    });
    group.bench_function("kitti_120k_read_file", |b| {
        b.iter(|| read_file(&path, &options).unwrap())
    });
    let cloud = read_file(&path, &options).unwrap();
    let returns = ReturnsOptions {
        rotation_hz: 10.0,
        intensity_scale: IntensityScale::Unit,
        start_time: 0.0,
    };
    group.throughput(Throughput::Elements(cloud.points.len() as u64));
    group.bench_function("kitti_120k_to_hdl64e_returns", |b| {
        b.iter(|| to_returns(&cloud.points, &HDL64E_S2, &returns, "000000.bin").unwrap())
    });
    if let Some(real) = std::env::var_os("LIDAR_NOISE_BENCH_KITTI") {
        let real = read_file(Path::new(&real), &options).expect("LIDAR_NOISE_BENCH_KITTI");
        group.throughput(Throughput::Elements(real.points.len() as u64));
        group.bench_function("kitti_real_to_hdl64e_returns", |b| {
            b.iter(|| to_returns(&real.points, &HDL64E_S2, &returns, "real.bin").unwrap())
        });
        group.throughput(Throughput::Elements(cloud.points.len() as u64));
    }
    // The scan's points as a dataset run writes them back: each its clean range (the
    // float text is most of the cost), a few removed by a stage, the low beams ground,
    // the others in clusters of a few hundred points.
    let scan: Vec<ScanPoint> = cloud
        .points
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let removed = i % 13 == 0;
            ScanPoint {
                x: p.x,
                y: p.y,
                z: p.z,
                intensity: 77,
                ring: (i / 1875) as u16,
                point: Some(i as u32),
                fate: if removed { 2 } else { 0 },
                cause: if removed { 3 } else { 255 },
                range_clean: (p.x * p.x + p.y * p.y + p.z * p.z).sqrt(),
                ground: u8::from(i < 20 * 1875),
                cluster: if i < 20 * 1875 { -1 } else { (i / 300) as i32 },
            }
        })
        .collect();
    let mut out = Vec::with_capacity(8 << 20);
    group.bench_function("kitti_120k_fate_csv", |b| {
        b.iter(|| {
            out.clear();
            Fates { points: &scan }.write_to(&mut out).unwrap();
            out.len()
        })
    });
    group.finish();
}

criterion_group!(benches, bench_cloud);
criterion_main!(benches);
