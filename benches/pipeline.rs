//! Ground removal plus clustering, and the whole per-frame pipeline, on a real frame.

use criterion::{criterion_group, criterion_main, Criterion};
use lidar_noise::cluster::{cluster, ClusterOptions};
use lidar_noise::config::Config;
use lidar_noise::ground::{segment, GroundOptions};
use lidar_noise::noise::stage_rng;
use lidar_noise::pipeline::Pipeline;
use lidar_noise::sensor::frames::{DecoderOptions, FrameReader};
use std::path::{Path, PathBuf};

fn bench_pipeline(c: &mut Criterion) {
    let path =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/data/hdl32e/monterey.pcap");
    if !path.exists() {
        eprintln!("SKIPPED: {} is absent", path.display());
        return;
    }
    let frame = FrameReader::open(&path, &DecoderOptions::default())
        .unwrap()
        .next()
        .unwrap()
        .unwrap();
    let ground_opts = GroundOptions::default();
    let cluster_opts = ClusterOptions {
        min_points: 10,
        ..ClusterOptions::default()
    };
    let non_ground = {
        let ground = segment(&frame.returns, &ground_opts, &mut stage_rng(1, 1, 1));
        frame
            .returns
            .iter()
            .zip(&ground)
            .filter(|(_, g)| !**g)
            .count()
    };
    eprintln!(
        "frame {}: {} returns, {non_ground} non-ground",
        frame.index,
        frame.returns.len()
    );
    let mut group = c.benchmark_group("pipeline");
    group.sample_size(30);
    group.bench_function("ground_plus_clustering_clean_frame", |b| {
        b.iter(|| {
            let ground = segment(&frame.returns, &ground_opts, &mut stage_rng(1, 1, 1));
            let points: Vec<[f32; 3]> = frame
                .returns
                .iter()
                .zip(&ground)
                .filter(|(_, g)| !**g)
                .map(|(r, _)| [r.x, r.y, r.z])
                .collect();
            cluster(&points, &cluster_opts).unwrap().n_clusters
        })
    });
    for name in ["clear", "paper"] {
        let cfg = Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("configs/{name}.toml"));
        let pipeline = Pipeline::new(&Config::load(Some(&cfg), &[], None).unwrap().0);
        group.bench_function(format!("whole_frame_{name}"), |b| {
            b.iter(|| pipeline.process(frame.clone()).unwrap().counts.clusters)
        });
    }
    group.finish();
}

criterion_group!(benches, bench_pipeline);
criterion_main!(benches);
