//! Speed of a whole sweep (the budget): 7 rain rates x occlusion on/off x 3 seeds
//! over the 17 frames of the shared HDL-32E capture, computed from scratch each time
//! (target: under 15 s on the 2-core machine), tables and plots included.

use criterion::{criterion_group, criterion_main, BatchSize, Criterion};
use lidar_noise::observe::Silent;
use lidar_noise::sensor::frames::DecoderOptions;
use lidar_noise::sweep::outputs::write_outputs;
use lidar_noise::sweep::plan::{BaseConfig, Vary};
use lidar_noise::sweep::run::{run, CaptureInput, SweepSettings};
use std::path::PathBuf;

fn bench(c: &mut Criterion) {
    let capture =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/data/hdl32e/monterey.pcap");
    if !capture.exists() {
        eprintln!("SKIPPED: {} is absent", capture.display());
        return;
    }
    let (base, _) = BaseConfig::load(None, &[]).unwrap();
    let varies = vec![
        Vary::parse("rain.rate_mm_h=0,0.5,1,2,3,5,7").unwrap(),
        Vary::parse("occlusion=on,off").unwrap(),
    ];
    let captures = vec![CaptureInput {
        name: "monterey".into(),
        path: capture,
        labels: None,
    }];
    let mut group = c.benchmark_group("sweep");
    group.sample_size(10);
    group.bench_function("monterey_7x2x3", |b| {
        b.iter_batched(
            || tempfile::tempdir().unwrap(),
            |dir| {
                let settings = SweepSettings {
                    base: base.clone(),
                    varies: varies.clone(),
                    seeds: vec![1, 2, 3],
                    decoder: DecoderOptions::default(),
                    frames: 0..=u32::MAX,
                    output: dir.path().to_path_buf(),
                    bands: lidar_noise::score::metrics::DEFAULT_BANDS.to_vec(),
                    chunk_frames: None,
                };
                let outcome = run(&settings, &captures, &Silent).unwrap();
                assert_eq!(outcome.computed, 42);
                write_outputs(
                    dir.path(),
                    &varies,
                    &["monterey".into()],
                    &outcome.rows,
                    None,
                    &[],
                    &[],
                    lidar_noise::writers::figure::FigureFormat::Png,
                )
                .unwrap();
                dir
            },
            BatchSize::PerIteration,
        )
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
