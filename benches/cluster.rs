//! Clustering speed on a synthetic LiDAR frame's non-ground points (about 26,000), and on a
//! real HDL-32E frame's crude non-ground set when the shared capture is present.

use criterion::{criterion_group, criterion_main, Criterion};
use lidar_noise::cluster::{cluster, linkage, ClusterOptions, CutRule};
use lidar_noise::sensor::frames::{DecoderOptions, FrameReader};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::hint::black_box;

/// Axis-aligned box [min, max] standing on the ground.
type Aabb = ([f64; 3], [f64; 3]);

/// Entry distance of a ray from the origin into a box (slab method).
// Three parallel arrays indexed by axis read clearer than a zip.
#[allow(clippy::needless_range_loop)]
fn hit(dir: [f64; 3], b: &Aabb) -> Option<f64> {
    let (mut t0, mut t1) = (0.0f64, f64::INFINITY);
    for a in 0..3 {
        if dir[a].abs() < 1e-12 {
            if 0.0 < b.0[a] || 0.0 > b.1[a] {
                return None;
            }
            continue;
        }
        let (ta, tb) = (b.0[a] / dir[a], b.1[a] / dir[a]);
        t0 = t0.max(ta.min(tb));
        t1 = t1.min(ta.max(tb));
    }
    (t0 <= t1).then_some(t0)
}

/// HDL-32E-like scan (32 lasers, 0.16 degree steps, sensor 1.8 m above flat ground) of cars,
/// walls and poles, ground hits dropped, plus scattered vegetation points.
fn frame() -> Vec<[f32; 3]> {
    let mut rng = ChaCha8Rng::seed_from_u64(42);
    let ground = -1.8;
    let mut boxes: Vec<Aabb> = Vec::new();
    let mut place = |rng: &mut ChaCha8Rng, size: [f64; 3], rmin: f64, rmax: f64| {
        let r: f64 = rng.random_range(rmin..rmax);
        let phi: f64 = rng.random_range(0.0..std::f64::consts::TAU);
        let (cx, cy) = (r * phi.cos(), r * phi.sin());
        let (sx, sy) = if rng.random_bool(0.5) {
            (size[0], size[1])
        } else {
            (size[1], size[0])
        };
        boxes.push((
            [cx - sx / 2.0, cy - sy / 2.0, ground],
            [cx + sx / 2.0, cy + sy / 2.0, ground + size[2]],
        ));
    };
    for _ in 0..25 {
        place(&mut rng, [4.5, 1.8, 1.5], 4.0, 40.0);
    }
    for _ in 0..6 {
        place(&mut rng, [20.0, 0.3, 3.0], 15.0, 45.0);
    }
    for _ in 0..30 {
        place(&mut rng, [0.3, 0.3, 4.0], 3.0, 30.0);
    }
    let mut pts = Vec::new();
    for laser in 0..32 {
        let el = (-30.67 + laser as f64 * 4.0 / 3.0).to_radians();
        for step in 0..2250 {
            let az = (step as f64 * 0.16).to_radians();
            let dir = [el.cos() * az.cos(), el.cos() * az.sin(), el.sin()];
            let t = boxes
                .iter()
                .filter_map(|b| hit(dir, b))
                .fold(f64::INFINITY, f64::min);
            if t.is_finite() && t < 100.0 {
                let p = [dir[0] * t, dir[1] * t, dir[2] * t];
                pts.push(p.map(|c| c as f32));
            }
        }
    }
    // Bushes: clumps of scattered points.
    for _ in 0..40 {
        let c = [rng.random_range(-30.0..30.0), rng.random_range(-30.0..30.0)];
        for _ in 0..rng.random_range(20..120) {
            pts.push([
                (c[0] + rng.random_range(-1.0..1.0)) as f32,
                (c[1] + rng.random_range(-1.0..1.0)) as f32,
                (ground + rng.random_range(0.1..1.5)) as f32,
            ]);
        }
    }
    pts
}

/// Returns above z = -1.5 m (a crude ground removal) of the largest of the first frames of
/// the shared Monterey capture; `None` (with a message) when the file is absent.
fn real_frame() -> Option<Vec<[f32; 3]>> {
    let path = std::path::Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../shared/data/hdl32e/monterey.pcap"
    ));
    if !path.exists() {
        eprintln!("skipping the real-frame case: {} is absent", path.display());
        return None;
    }
    let reader = FrameReader::open(path, &DecoderOptions::default()).expect("readable capture");
    let frame = reader
        .take(3)
        .map(|f| f.expect("decodable frame"))
        .max_by_key(|f| f.returns.len())?;
    Some(
        frame
            .returns
            .iter()
            .filter(|r| r.z > -1.5)
            .map(|r| [r.x, r.y, r.z])
            .collect(),
    )
}

fn bench(c: &mut Criterion) {
    let pts = frame();
    let opts = ClusterOptions {
        cut: CutRule::Distance,
        cutoff_m: 0.5,
        cutoff_per_m: 0.0,
        min_points: 10,
        max_edge_m: 0.5,
    };
    let n = cluster(&pts, &opts).expect("valid options").n_clusters;
    eprintln!(
        "synthetic frame: {} non-ground points, {n} clusters",
        pts.len()
    );
    c.bench_function("distance_cut_0.5m", |b| {
        b.iter(|| cluster(black_box(&pts), &opts).expect("valid options"))
    });
    let adaptive = ClusterOptions {
        cutoff_m: 0.3,
        cutoff_per_m: 0.01,
        ..opts
    };
    c.bench_function("distance_cut_adaptive", |b| {
        b.iter(|| cluster(black_box(&pts), &adaptive).expect("valid options"))
    });
    if let Some(real) = real_frame() {
        let n = cluster(&real, &opts).expect("valid options").n_clusters;
        eprintln!(
            "monterey frame: {} points with z > -1.5 m, {n} clusters",
            real.len()
        );
        c.bench_function("distance_cut_0.5m_monterey", |b| {
            b.iter(|| cluster(black_box(&real), &opts).expect("valid options"))
        });
        // Range-adaptive cut (shell grids): 0.5 m + 2 cm per metre of range.
        let adaptive_real = ClusterOptions {
            cutoff_per_m: 0.02,
            ..opts
        };
        c.bench_function("adaptive_cut_monterey", |b| {
            b.iter(|| cluster(black_box(&real), &adaptive_real).expect("valid options"))
        });
    }
    c.bench_function("linkage_bound_0.5m", |b| {
        b.iter(|| linkage(black_box(&pts), 0.5).expect("valid bound"))
    });
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(20);
    targets = bench
}
criterion_main!(benches);
