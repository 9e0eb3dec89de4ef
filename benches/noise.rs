//! Speed of the noise chain: occlusion + rain + detection filters on a 50,000-return
//! synthetic frame (target: under 2 ms on one core).

use criterion::{criterion_group, criterion_main, Criterion};
use lidar_noise::config::Config;
use lidar_noise::frame::{Frame, Return, ReturnKind};
use lidar_noise::noise::NoiseChain;
use lidar_noise::sensor::calibration::Calibration;
use std::hint::black_box;

// The allocator of the `lidar-noise` binary (src/main.rs), so the chain is timed as it
// runs there: under glibc malloc the timings depended on whether a frame's total heap
// use crossed the dynamic trim threshold, which returned pages to the kernel and
// faulted them in again on every iteration.
#[global_allocator]
static GLOBAL: mimalloc::MiMalloc = mimalloc::MiMalloc;

/// 50,000 returns: every laser in turn, ranges 1..80 m, varied intensities.
fn synthetic_frame() -> Frame {
    let cal = Calibration::builtin();
    let rings = cal.rings();
    let returns = (0..50_000u32)
        .map(|i| {
            let laser = (i % 32) as u8;
            let range = 1.0 + (i.wrapping_mul(2_654_435_761) % 7900) as f32 / 100.0;
            let azimuth = (i / 32) as f32 * 0.2 % 360.0;
            let el = cal.lasers[laser as usize].elevation_deg as f32;
            let (se, ce) = el.to_radians().sin_cos();
            let (sa, ca) = azimuth.to_radians().sin_cos();
            Return {
                x: range * ce * ca,
                y: -range * ce * sa,
                z: range * se,
                range,
                azimuth,
                elevation: el,
                time: 0.0,
                packet: i / 384,
                raw_distance: (range / 0.002) as u16,
                intensity: (i % 101) as u8,
                laser,
                ring: rings[laser as usize],
                block: ((i / 32) % 12) as u8,
                kind: ReturnKind::Strongest,
            }
        })
        .collect();
    Frame {
        index: 0,
        partial: false,
        returns,
    }
}

fn bench_chain(c: &mut Criterion) {
    // As the binary does at start-up (src/main.rs), so the heap behaves as it does there.
    lidar_noise::memory::no_transparent_huge_pages();
    let (config, _) = Config::load(None, &[], None).expect("built-in config");
    let chain = NoiseChain::new(&config);
    let frame = synthetic_frame();
    c.bench_function("paper chain + filters, 50k returns", |b| {
        b.iter(|| black_box(chain.process(black_box(&frame))))
    });
    let out = chain.process(&frame);
    c.bench_function("survivors, 50k returns", |b| {
        b.iter(|| black_box(black_box(&out).survivors()))
    });
    c.bench_function("frame summary, 50k returns", |b| {
        b.iter(|| black_box(black_box(&out).summary()))
    });
    // The p-diagram part 1 chain (configs/pdiagram-sensor.toml) alone and after the
    // paper chain: the difference with "paper chain + filters" is what the sensor
    // stages add (target: at most 1 ms per 50k-return frame).
    let path =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("configs/pdiagram-sensor.toml");
    let (sensor, _) = Config::load(Some(&path), &[], None).expect("pdiagram-sensor.toml");
    let sensor_chain = NoiseChain::new(&sensor);
    c.bench_function("pdiagram-sensor chain + filters, 50k returns", |b| {
        b.iter(|| black_box(sensor_chain.process(black_box(&frame))))
    });
    // The same configuration without its `[[noise]]` stages (same power model and
    // detection filters): the difference with the line above is exactly what the eight
    // sensor stages cost.
    let mut bare = sensor.clone();
    bare.noise.clear();
    let bare_chain = NoiseChain::new(&bare);
    c.bench_function(
        "pdiagram-sensor config without its stages, 50k returns",
        |b| b.iter(|| black_box(bare_chain.process(black_box(&frame)))),
    );
    // The same pair on a real frame (the shared capture's first full sweep, about
    // 50,000 returns with their own firing times and azimuths): the synthetic frame's
    // returns all have time 0, which some stages' shortcuts favour.
    let capture = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/data/hdl32e/monterey.pcap");
    if capture.exists() {
        let options = lidar_noise::sensor::frames::DecoderOptions::default();
        let real = lidar_noise::sensor::frames::FrameReader::open(&capture, &options)
            .expect("monterey.pcap opens")
            .next()
            .expect("a frame")
            .expect("decodes");
        let n = real.returns.len();
        c.bench_function(
            &format!("pdiagram-sensor chain + filters, monterey frame ({n} returns)"),
            |b| b.iter(|| black_box(sensor_chain.process(black_box(&real)))),
        );
        c.bench_function(
            &format!("pdiagram-sensor config without its stages, monterey frame ({n} returns)"),
            |b| b.iter(|| black_box(bare_chain.process(black_box(&real)))),
        );
    } else {
        eprintln!(
            "SKIPPED: {} is absent (real-frame sensor chain)",
            capture.display()
        );
    }
    let out = sensor_chain.process(&frame);
    c.bench_function("survivors after the sensor chain, 50k returns", |b| {
        b.iter(|| black_box(black_box(&out).survivors()))
    });
    // Crosstalk (p-diagram 15) alone at 1 % and 2 % of returns, against the same
    // configuration without stages: the difference is what crosstalk costs, including
    // the firing-slot table it makes the frame build and the one resolution of its
    // echoes (issue 12 target: fog with backscatter plus crosstalk at most 3 ms per
    // 50k-return frame). It draws the number of false returns (binomial) and then which
    // ones, not one Bernoulli draw per return.
    let (bare_default, _) = Config::load(None, &[], None).expect("built-in config");
    let mut bare_default = bare_default;
    bare_default.noise.clear();
    let no_stage = NoiseChain::new(&bare_default);
    c.bench_function("no stage + filters, 50k returns", |b| {
        b.iter(|| black_box(no_stage.process(black_box(&frame))))
    });
    for fraction in ["0.01", "0.02"] {
        let text = format!("[[noise]]\ntype = \"crosstalk\"\nfraction = {fraction}\n");
        let (cfg, _) = Config::from_toml_str(&text, std::path::Path::new("x.toml"), &[], None)
            .expect("crosstalk config");
        let chain = NoiseChain::new(&cfg);
        c.bench_function(
            &format!("crosstalk {fraction} + filters, 50k returns"),
            |b| b.iter(|| black_box(chain.process(black_box(&frame)))),
        );
    }
    // Of which the firing-slot table every echo-proposing stage needs (built once per
    // frame, shared by all of them).
    c.bench_function("firing-slot table, 50k returns", |b| {
        b.iter(|| black_box(lidar_noise::noise::Slots::of(black_box(&frame.returns), 32)))
    });
    // The p-diagram part 2 chain (configs/pdiagram-world.toml) as far as it exists.
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("configs/pdiagram-world.toml");
    let (world, _) = Config::load(Some(&path), &[], None).expect("pdiagram-world.toml");
    let world_chain = NoiseChain::new(&world);
    c.bench_function("pdiagram-world chain + filters, 50k returns", |b| {
        b.iter(|| black_box(world_chain.process(black_box(&frame))))
    });
    // The geometry world stages (p-diagram 07 and 10) at their defaults, each alone: the
    // difference with "stages: none" is what the stage costs. The synthetic frame's
    // ranges are random, so nearly every return is at a depth edge (multipath's worst
    // case).
    let none = NoiseChain::new(
        &Config::from_toml_str("seed = 1\n", std::path::Path::new("b"), &[], None)
            .expect("bare")
            .0,
    );
    c.bench_function("stages: none + filters, 50k returns", |b| {
        b.iter(|| black_box(none.process(black_box(&frame))))
    });
    for kind in ["multipath", "lens_damage"] {
        let text = format!("seed = 1\n[[noise]]\ntype = \"{kind}\"\n");
        let (cfg, _) = Config::from_toml_str(&text, std::path::Path::new("b"), &[], None)
            .expect("stage config");
        let chain = NoiseChain::new(&cfg);
        c.bench_function(&format!("stages: {kind} + filters, 50k returns"), |b| {
            b.iter(|| black_box(chain.process(black_box(&frame))))
        });
    }
    // Fog with backscatter (issue 12: fog with backscatter plus crosstalk at most 3 ms
    // per 50k-return frame). At V = 150 m every beam draws its fog echo (issue 50: the
    // first noise cell that crosses) and a few are reported; the bare line below is the
    // same power model and filters without the stage.
    let fog_text = "seed = 42\n[[noise]]\ntype = \"fog\"\nvisibility_m = 150.0\n";
    let (fog, _) = Config::from_toml_str(fog_text, std::path::Path::new("fog.toml"), &[], None)
        .expect("fog config");
    let fog_chain = NoiseChain::new(&fog);
    let _ = fog_chain.process(&frame); // the echo table is computed once, on first use
    c.bench_function("fog with backscatter + filters, 50k returns", |b| {
        b.iter(|| black_box(fog_chain.process(black_box(&frame))))
    });
    // The pair: fog with backscatter and crosstalk (1 %) in one chain.
    let pair_text = "seed = 42\n[[noise]]\ntype = \"fog\"\nvisibility_m = 150.0\n\
                     [[noise]]\ntype = \"crosstalk\"\nfraction = 0.01\n";
    let (pair, _) = Config::from_toml_str(pair_text, std::path::Path::new("pair.toml"), &[], None)
        .expect("fog + crosstalk config");
    let pair_chain = NoiseChain::new(&pair);
    let _ = pair_chain.process(&frame);
    c.bench_function(
        "fog with backscatter + crosstalk + filters, 50k returns",
        |b| b.iter(|| black_box(pair_chain.process(black_box(&frame)))),
    );
    // Issue 29: configs/adverse-weather.toml (fog + rain with drop echoes + snow) at most
    // 3 ms per 50k-return frame; its stages' cost is the difference with the same config
    // without stages. Rain and snow alone: Mie drop and flake echoes sampled only where
    // detectable, against Goodin's rain with LISA's brute-force cone sampling.
    let path =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("configs/adverse-weather.toml");
    let (adverse, _) = Config::load(Some(&path), &[], None).expect("adverse-weather.toml");
    let adverse_chain = NoiseChain::new(&adverse);
    let _ = adverse_chain.process(&frame);
    c.bench_function("adverse-weather chain + filters, 50k returns", |b| {
        b.iter(|| black_box(adverse_chain.process(black_box(&frame))))
    });
    let mut bare = adverse.clone();
    bare.noise.clear();
    let bare_chain = NoiseChain::new(&bare);
    c.bench_function(
        "adverse-weather config without its stages, 50k returns",
        |b| b.iter(|| black_box(bare_chain.process(black_box(&frame)))),
    );
    for (name, body) in [
        (
            "rain mie 3.125 mm/h + drop echoes",
            "type = \"rain\"\nmodel = \"mie\"\nrate_mm_h = 3.125\nbackscatter = true",
        ),
        (
            "rain goodin 3.125 mm/h + drop echoes (LISA sampler)",
            "type = \"rain\"\nmodel = \"goodin\"\nrate_mm_h = 3.125\nbackscatter = true",
        ),
        (
            "snow moderate preset (8.85 mm/h w.e.)",
            "type = \"snow\"\npreset = \"moderate\"",
        ),
        ("snow 1 mm/h w.e.", "type = \"snow\"\nrate_mm_h = 1.0"),
    ] {
        let text = format!("seed = 42\n[[noise]]\n{body}\n");
        let (cfg, _) = Config::from_toml_str(&text, std::path::Path::new("b"), &[], None)
            .expect("stage config");
        let chain = NoiseChain::new(&cfg);
        let _ = chain.process(&frame);
        c.bench_function(&format!("{name} + filters, 50k returns"), |b| {
            b.iter(|| black_box(chain.process(black_box(&frame))))
        });
    }
    let mut clear = fog.clone();
    clear.noise.clear();
    let clear_chain = NoiseChain::new(&clear);
    c.bench_function("fog config without its stage, 50k returns", |b| {
        b.iter(|| black_box(clear_chain.process(black_box(&frame))))
    });
}

criterion_group!(benches, bench_chain);
criterion_main!(benches);
