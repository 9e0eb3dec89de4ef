//! One rotation of the crossroad preset at 10 Hz: ray casting plus packet encoding.

use criterion::{criterion_group, criterion_main, Criterion};
use lidar_noise::synth::{synthesize, Scene, SynthOptions};
use std::hint::black_box;

fn one_rotation(c: &mut Criterion) {
    let mut scene = Scene::preset("crossroad").expect("crossroad preset");
    scene.sensor.rotation_hz = 10.0;
    scene.frames = 1;
    let options = SynthOptions::default();
    c.bench_function("synth crossroad 1 rotation 10 Hz", |b| {
        b.iter(|| {
            let mut returns = 0usize;
            synthesize(black_box(&scene), &options, |record, cast| {
                black_box(record.payload());
                returns += cast.len();
                Ok(())
            })
            .expect("in-memory sink");
            returns
        })
    });
}

criterion_group!(benches, one_rotation);
criterion_main!(benches);
