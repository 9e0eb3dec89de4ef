//! Writes a synthetic frame as PLY, for checking files with outside readers
//! (`python3 scripts/ci/plyfile_check.py OUT.ply`, CloudCompare, Open3D).
//!
//! Usage: `cargo run --example write_sample_ply -- OUT.ply [--ascii] [--points N] [--extras]`

use lidar_noise::frame::{Return, ReturnKind};
use lidar_noise::writers::ply::{PlyColumns, PlyEncoding, PlyFrame};
use lidar_noise::writers::write_file;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::path::PathBuf;
use std::time::Instant;

fn main() -> anyhow::Result<()> {
    let mut out: Option<PathBuf> = None;
    let mut ascii = false;
    let mut extras = false;
    let mut n = 50_000usize;
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--ascii" => ascii = true,
            "--extras" => extras = true,
            "--points" => {
                let v = args
                    .next()
                    .ok_or_else(|| anyhow::anyhow!("--points needs a number"))?;
                n = v.parse()?;
            }
            _ if out.is_none() => out = Some(PathBuf::from(a)),
            _ => anyhow::bail!("unexpected argument {a:?}"),
        }
    }
    let out = out.ok_or_else(|| {
        anyhow::anyhow!("usage: write_sample_ply OUT.ply [--ascii] [--points N] [--extras]")
    })?;

    // A sweep over 32 lasers at 10 m to 60 m, like a frame of the real sensor.
    let mut rng = ChaCha8Rng::seed_from_u64(2026);
    let start = 1800.0;
    let returns: Vec<Return> = (0..n)
        .map(|i| {
            let laser = (i % 32) as u8;
            let elevation = -30.67 + f64::from(laser) * 1.33;
            let azimuth = (i / 32) as f64 * 360.0 / (n as f64 / 32.0).max(1.0);
            let range = rng.random_range(10.0..60.0f64);
            let (w, a) = (elevation.to_radians(), azimuth.to_radians());
            Return {
                x: (range * w.cos() * a.cos()) as f32,
                y: (-range * w.cos() * a.sin()) as f32,
                z: (range * w.sin()) as f32,
                range: range as f32,
                azimuth: azimuth as f32,
                elevation: elevation as f32,
                time: start + i as f64 * 1.44e-6,
                packet: (i / 384) as u32,
                raw_distance: (range / 0.002) as u16,
                intensity: rng.random(),
                laser,
                ring: laser,
                block: ((i / 32) % 12) as u8,
                kind: ReturnKind::Strongest,
            }
        })
        .collect();
    let range_clean: Vec<f32> = returns.iter().map(|r| r.range).collect();
    let power: Vec<f32> = (0..n).map(|_| rng.random_range(0.0..1.0f32)).collect();
    let fate: Vec<u8> = (0..n).map(|_| rng.random_range(0..3)).collect();
    let ground: Vec<u8> = returns.iter().map(|r| u8::from(r.z < -1.5)).collect();
    let cluster: Vec<i32> = (0..n).map(|i| (i / 1000) as i32 - 1).collect();
    let comments = vec!["fate 0 = kept, 1 = occluded, 2 = rain".to_string()];

    let mut frame = PlyFrame::new(&returns, "synthetic", 0, start);
    frame.comments = &comments;
    if ascii {
        frame.encoding = PlyEncoding::Ascii;
    }
    if extras {
        frame.columns = PlyColumns {
            range_clean: Some(&range_clean),
            power: Some(&power),
            fate: Some(&fate),
            cause: None,
            ground: Some(&ground),
            cluster: Some(&cluster),
        };
    }
    let t = Instant::now();
    write_file(&frame, &out, &[])?;
    println!(
        "wrote {} points to {} in {:.2} ms",
        n,
        out.display(),
        t.elapsed().as_secs_f64() * 1e3
    );
    Ok(())
}
