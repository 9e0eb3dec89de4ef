//! Measures how a real dataset scan becomes sensor returns and, where labels lie beside it
//! (or are given), what ground removal and clustering find against them on the clean scan
//! (no noise stage: `configs/clear.toml`), for the numbers of notes and manual (issue 31).
//!
//! `cargo run --release --example dataset_scan -- SCAN... [--sensor NAME] [--labels FILE]`
//!
//! Per scan: the sensor guessed from the data (or `--sensor`), the share of points whose
//! laser comes from the elevation and is ambiguous, and
//! - with a ring field: the share whose elevation gives the laser the ring names;
//! - without one (KITTI): scan rows from point order (KITTI stores a laser's points as one
//!   row around the turn; a row starts where the azimuth crosses 0 upwards), and the share
//!   of points given their row's most common laser (a row is one laser).

use lidar_noise::cloud::guess::{guess_sensor, sensor_by_name};
use lidar_noise::cloud::returns::{to_returns, ReturnsOptions};
use lidar_noise::cloud::{read_file, Format, ReadOptions};
use lidar_noise::frame::Frame;
use lidar_noise::pipeline::Pipeline;
use lidar_noise::score::truth::{labels_beside, read_truth, score, LabelsBeside};
use std::collections::HashMap;
use std::path::{Path, PathBuf};

fn main() {
    let mut args = std::env::args().skip(1);
    let (mut scans, mut sensor, mut labels) = (Vec::new(), None, None);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--sensor" => sensor = args.next(),
            "--labels" => labels = args.next().map(PathBuf::from),
            _ => scans.push(PathBuf::from(a)),
        }
    }
    for scan in &scans {
        if let Err(e) = one(scan, sensor.as_deref(), labels.as_deref()) {
            println!("{}: {e}", scan.display());
        }
    }
}

fn one(scan: &Path, sensor: Option<&str>, labels: Option<&Path>) -> Result<(), String> {
    let cloud = read_file(scan, &ReadOptions::default()).map_err(|e| e.to_string())?;
    println!(
        "== {} ({}, {} points)",
        scan.display(),
        cloud.info.format.name(),
        cloud.points.len()
    );
    let model = match sensor {
        Some(n) => sensor_by_name(n).ok_or(format!("--sensor {n}: unknown"))?,
        None => {
            let g = guess_sensor(&cloud.points)?;
            println!("guess: {}", g.reason);
            g.model
        }
    };
    let opts = ReturnsOptions {
        rotation_hz: if cloud.info.format == Format::NuScenes {
            20.0
        } else {
            10.0
        },
        intensity_scale: cloud.info.intensity_scale,
        start_time: 0.0,
    };
    let shown = scan.display().to_string();
    let placed = to_returns(&cloud.points, model, &opts, &shown).map_err(|e| e.to_string())?;
    let pct = |a: usize, b: usize| 100.0 * a as f64 / b.max(1) as f64;
    println!(
        "{}: {} firings; moved to a neighbouring firing {:.2} %, sharing a slot {:.2} %",
        model.name,
        placed.firings,
        pct(placed.moved, cloud.points.len()),
        pct(placed.shared, cloud.points.len())
    );
    // The laser of every point from its elevation alone (ring field dropped).
    let bare: Vec<_> = cloud
        .points
        .iter()
        .map(|p| lidar_noise::cloud::CloudPoint { ring: None, ..*p })
        .collect();
    let by_el = to_returns(&bare, model, &opts, &shown).map_err(|e| e.to_string())?;
    let mut laser_of_point = vec![0u8; bare.len()];
    for (r, &i) in by_el.returns.iter().zip(&by_el.order) {
        laser_of_point[i as usize] = r.laser;
    }
    println!(
        "laser from elevation: {} points, ambiguous (middle half between two beams) {:.1} %",
        by_el.from_elevation,
        pct(by_el.ambiguous, by_el.from_elevation)
    );
    let rings = model.rings();
    if cloud.info.fields.ring {
        let far: Vec<usize> = (0..bare.len())
            .filter(|&i| {
                let p = &bare[i];
                p.x * p.x + p.y * p.y + p.z * p.z > 1.0
            })
            .collect();
        let same = far
            .iter()
            .filter(|&&i| {
                cloud.points[i].ring == Some(u16::from(rings[usize::from(laser_of_point[i])]))
            })
            .count();
        let near = far
            .iter()
            .filter(|&&i| {
                let want = i32::from(cloud.points[i].ring.unwrap_or(0));
                (i32::from(rings[usize::from(laser_of_point[i])]) - want).abs() <= 1
            })
            .count();
        println!(
            "against the ring field ({} points beyond 1 m): same ring {:.1} %, within one ring {:.1} %",
            far.len(),
            pct(same, far.len()),
            pct(near, far.len())
        );
    } else {
        // Rows from point order. KITTI files differ: object-benchmark scans (cut to the
        // camera's view) start each row at azimuth 0, so a row begins where the azimuth
        // crosses 0 upwards; odometry (SemanticKITTI) scans wrap at the back, so a row
        // begins where the azimuth falls by more than 180 deg. Of the two splits, the one
        // whose rows are the thinnest in elevation (median of each row's 10-90 % spread)
        // is taken.
        let az: Vec<f32> = bare.iter().map(|p| p.y.atan2(p.x)).collect();
        let el: Vec<f32> = bare
            .iter()
            .map(|p| p.z.atan2((p.x * p.x + p.y * p.y).sqrt()).to_degrees())
            .collect();
        let split = |front: bool| -> Vec<usize> {
            let mut row = 0;
            let mut rows = vec![0usize; az.len()];
            for i in 1..az.len() {
                let (a, b) = (az[i - 1], az[i]);
                let new = if front {
                    a < 0.0 && b >= 0.0 && b - a < 0.5
                } else {
                    b - a < -std::f32::consts::PI
                };
                row += usize::from(new);
                rows[i] = row;
            }
            rows
        };
        let spread = |rows: &[usize]| -> f32 {
            let mut by: HashMap<usize, Vec<f32>> = HashMap::new();
            for (&r, &e) in rows.iter().zip(&el) {
                by.entry(r).or_default().push(e);
            }
            let mut s: Vec<f32> = by
                .into_values()
                .filter(|v| v.len() >= 20)
                .map(|mut v| {
                    v.sort_by(f32::total_cmp);
                    v[v.len() * 9 / 10] - v[v.len() / 10]
                })
                .collect();
            s.sort_by(f32::total_cmp);
            s.get(s.len() / 2).copied().unwrap_or(f32::MAX)
        };
        let (a, b) = (split(true), split(false));
        let rows = if spread(&a) <= spread(&b) { a } else { b };
        let row = rows.last().copied().unwrap_or(0);
        let mut counts: HashMap<(usize, u8), usize> = HashMap::new();
        for (i, &r) in rows.iter().enumerate() {
            *counts.entry((r, laser_of_point[i])).or_default() += 1;
        }
        let mut best: HashMap<usize, usize> = HashMap::new();
        for (&(r, _), &c) in &counts {
            let b = best.entry(r).or_default();
            *b = (*b).max(c);
        }
        let majority: usize = best.values().sum();
        println!(
            "rows from point order: {}; points given their row's most common laser {:.1} %",
            row + 1,
            pct(majority, bare.len())
        );
    }
    let found = match labels {
        Some(p) => Some(LabelsBeside::PerPoint(p.to_path_buf())),
        None => labels_beside(scan),
    };
    let Some(found) = found else {
        return Ok(());
    };
    let truth = read_truth(&found, &cloud.points).map_err(|e| e.to_string())?;
    let (config, _) =
        lidar_noise::config::Config::load(Some(Path::new("configs/clear.toml")), &[], None)
            .map_err(|e| e.to_string())?;
    let pipeline = Pipeline::new(&config);
    let frame = Frame {
        index: 0,
        partial: false,
        returns: placed.returns.clone(),
    };
    let r = pipeline.process(frame).map_err(|e| e.to_string())?;
    let s = score(
        &r,
        &truth,
        &placed.order,
        config.cluster.min_points,
        &lidar_noise::score::metrics::DEFAULT_BANDS,
        &found.shown(),
    );
    println!("labels: {}", s.labels);
    println!("{}", serde_json::to_string(&s).unwrap_or_default());
    Ok(())
}
