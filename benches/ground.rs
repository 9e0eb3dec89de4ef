//! Speed of ground segmentation on a synthetic full HDL-32E frame (32 x 1800 returns),
//! and of every method on a real frame (monterey frame 1, about 50k returns) when the
//! shared data is present.

#[path = "../tests/integration/common/ground_scene.rs"]
mod ground_scene;

use criterion::{criterion_group, criterion_main, Criterion};
use ground_scene::Scene;
use lidar_noise::ground::{segment, GroundMethod, GroundOptions};
use lidar_noise::sensor::frames::{DecoderOptions, FrameReader};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use std::hint::black_box;

fn bench_ground(c: &mut Criterion) {
    // Ground inside a ring of walls, so every beam returns: 32 x 1800 = 57,600 returns.
    let mut scene = Scene::street(0.0);
    scene.blocks = wall_ring();
    let (returns, _) = scene.frame(0.2, &[]);
    assert!(returns.len() > 50_000, "{} returns", returns.len());
    let (street, _) = Scene::street(0.0).frame(0.2, &[]);

    let mut group = c.benchmark_group("ground");
    let range_image = GroundOptions {
        method: GroundMethod::RangeImage,
        ..Default::default()
    };
    group.bench_function("range-image 57600", |b| {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        b.iter(|| segment(black_box(&returns), &range_image, &mut rng))
    });
    group.bench_function(format!("range-image street {}", street.len()), |b| {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        b.iter(|| segment(black_box(&street), &range_image, &mut rng))
    });
    let ransac = GroundOptions {
        method: GroundMethod::Ransac,
        ..Default::default()
    };
    group.bench_function("ransac 57600", |b| {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        b.iter(|| segment(black_box(&returns), &ransac, &mut rng))
    });
    let patchwork = GroundOptions {
        method: GroundMethod::Patchwork,
        ..Default::default()
    };
    group.bench_function("patchwork 57600", |b| {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        b.iter(|| segment(black_box(&returns), &patchwork, &mut rng))
    });
    let path = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/data/hdl32e/monterey.pcap");
    if path.exists() {
        // Frame 1: the first full rotation (frame 0 is the partial first sweep).
        let frame = FrameReader::open(&path, &DecoderOptions::default())
            .unwrap()
            .next()
            .unwrap()
            .unwrap();
        let real = frame.returns;
        for (name, opts) in [
            ("patchwork", &patchwork),
            ("range-image", &range_image),
            ("ransac", &ransac),
        ] {
            group.bench_function(format!("{name} monterey frame {}", frame.index), |b| {
                let mut rng = ChaCha8Rng::seed_from_u64(1);
                b.iter(|| segment(black_box(&real), opts, &mut rng))
            });
        }
        eprintln!("monterey frame {}: {} returns", frame.index, real.len());
    } else {
        eprintln!("SKIPPED: {} is absent", path.display());
    }
    group.finish();
}

/// Four 20 m high walls 40 m away on every side, so beams above the horizon return too.
fn wall_ring() -> Vec<ground_scene::Block> {
    use ground_scene::Block;
    let (d, t, h) = (40.0, 1.0, 20.0);
    vec![
        Block {
            min: [d, -d - t],
            max: [d + t, d + t],
            height: h,
        },
        Block {
            min: [-d - t, -d - t],
            max: [-d, d + t],
            height: h,
        },
        Block {
            min: [-d, d],
            max: [d, d + t],
            height: h,
        },
        Block {
            min: [-d, -d - t],
            max: [d, -d],
            height: h,
        },
    ]
}

criterion_group!(benches, bench_ground);
criterion_main!(benches);
