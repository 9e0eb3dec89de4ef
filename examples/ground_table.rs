//! Prints ground precision and recall of every ground method on the preset scenes and
//! randomized scenes under clean, rain, occlusion and paper noise (the manual's table, "Ground removal").
//!
//! `cargo run --release --example ground_table [SEED...]`; without seeds, the test seeds
//! of `tests/integration/ground_targets.rs`.

#[path = "../tests/integration/common/ground_eval.rs"]
mod ground_eval;

use ground_eval::{config, labelled_frames, measure, CONFIGS};
use lidar_noise::ground::GroundMethod;
use lidar_noise::synth::scene::{random_scene, Scene};

fn main() {
    let seeds: Vec<u64> = std::env::args()
        .skip(1)
        .map(|a| a.parse().expect("seeds are integers"))
        .collect();
    let seeds = if seeds.is_empty() {
        ground_eval::TEST_SEEDS.to_vec()
    } else {
        seeds
    };
    let mut scenes: Vec<Scene> = ["crossroad", "parking", "empty"]
        .iter()
        .map(|n| Scene::preset(n).unwrap())
        .collect();
    scenes.extend(seeds.iter().map(|&s| random_scene(s)));
    let methods = [
        GroundMethod::Patchwork,
        GroundMethod::RangeImage,
        GroundMethod::Ransac,
    ];
    println!("| scene | noise | patchwork P | patchwork R | range-image P | range-image R | ransac P | ransac R |");
    println!("|---|---|---|---|---|---|---|---|");
    for mut scene in scenes {
        scene.frames = ground_eval::FRAMES;
        let frames = labelled_frames(&scene);
        for (name, file) in CONFIGS {
            let counts = measure(&frames, &config(file), &methods);
            print!("| {} | {name} |", scene.name);
            for c in counts {
                print!(" {:.3} | {:.3} |", c.precision(), c.recall());
            }
            println!();
        }
    }
}
