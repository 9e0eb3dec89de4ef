//! Ray-cast returns lie where they should: ground returns on the ground plane, object
//! returns inside their object. Points are rebuilt here from the raw distance and the
//! beam direction, independently of the caster.

use lidar_noise::sensor::calibration::Calibration;
use lidar_noise::synth::{synthesize, CastReturn, Scene, SynthOptions};
use std::path::Path;

/// World points of every cast return: (return, world xyz).
fn world_points(scene: &Scene, interpolate: bool) -> Vec<(CastReturn, [f64; 3])> {
    let cal = Calibration::builtin();
    let options = SynthOptions {
        interpolate,
        ..SynthOptions::default()
    };
    let (sp, cp) = scene.sensor.pitch_deg.to_radians().sin_cos();
    let (sr, cr) = scene.sensor.roll_deg.to_radians().sin_cos();
    let h = scene.ground.height_m + scene.sensor.height_m;
    let mut out = Vec::new();
    let mut block_az: Vec<u16> = Vec::new();
    let mut pending: Vec<(CastReturn, usize)> = Vec::new();
    synthesize(scene, &options, |record, returns| {
        if record.port() == 2368 {
            let p = record.payload();
            let base = block_az.len();
            for b in 0..12 {
                block_az.push(u16::from_le_bytes([p[b * 100 + 2], p[b * 100 + 3]]));
                // The payload carries the same distance as the cast return.
            }
            for r in returns {
                let at = 4 + r.block as usize * 100 + 3 * r.laser as usize;
                assert_eq!(u16::from_le_bytes([p[at], p[at + 1]]), r.raw_distance);
                assert_eq!(p[at + 2], r.intensity);
                pending.push((*r, base + r.block as usize));
            }
        }
        Ok(())
    })
    .unwrap();
    for (r, n) in pending {
        let a0 = f64::from(block_az[n]);
        let a = if interpolate && n + 1 < block_az.len() {
            let mut step = f64::from(block_az[n + 1]) - a0;
            if step < 0.0 {
                step += 36000.0;
            }
            (a0 + step * f64::from(r.laser) / 40.0) / 100.0
        } else {
            a0 / 100.0
        };
        let w = cal.lasers[r.laser as usize].elevation_deg.to_radians();
        let a = a.to_radians();
        let range = f64::from(r.raw_distance) * 0.002;
        let s = [
            range * w.cos() * a.cos(),
            -range * w.cos() * a.sin(),
            range * w.sin(),
        ];
        // world = Ry(pitch) * Rx(roll) * s + (0, 0, h)
        let rx = [s[0], cr * s[1] - sr * s[2], sr * s[1] + cr * s[2]];
        let p = [cp * rx[0] + sp * rx[2], rx[1], -sp * rx[0] + cp * rx[2] + h];
        out.push((r, p));
    }
    out
}

fn check_scene(scene: &Scene, interpolate: bool) {
    let points = world_points(scene, interpolate);
    assert!(points.len() > 1000, "too few returns: {}", points.len());
    let mut ground = 0;
    for (r, p) in &points {
        if r.label == 0 {
            ground += 1;
            let dz = p[2] - scene.ground.z_at(p[0], p[1]);
            assert!(
                dz.abs() < 0.01,
                "ground return {r:?} at {p:?} is {dz} m off the plane"
            );
            for o in &scene.objects {
                assert!(
                    !o.contains(*p, -0.02),
                    "ground return {r:?} inside object {}",
                    o.id
                );
            }
        } else {
            let o = &scene.objects[r.label as usize - 1];
            assert_eq!(o.id, r.label);
            assert!(
                o.contains(*p, 0.01),
                "return {r:?} at {p:?} outside object {}",
                o.id
            );
        }
    }
    assert!(ground > 100);
}

#[test]
fn crossroad_returns_lie_on_their_surfaces() {
    let scene = Scene::preset("crossroad").unwrap();
    check_scene(&scene, true);
    let labels: std::collections::BTreeSet<u16> = world_points(&scene, true)
        .iter()
        .map(|(r, _)| r.label)
        .collect();
    assert_eq!(
        labels.len(),
        scene.objects.len() + 1,
        "every object is seen"
    );
}

#[test]
fn tilted_sensor_on_sloped_ground_without_interpolation() {
    let src = "frames = 1\n[sensor]\nheight_m = 2.2\npitch_deg = 3.0\nroll_deg = -2.0\nrotation_hz = 15.0\n[ground]\nheight_m = 0.5\nslope_deg = 4.0\nslope_azimuth_deg = 30.0\n[[objects]]\nkind = \"truck\"\nx = 12.0\ny = -6.0\nyaw_deg = 25.0\nlength_m = 8.0\nwidth_m = 2.5\nheight_m = 3.5\nreflectance = 0.5\n[[objects]]\nkind = \"barrel\"\nx = -4.0\ny = 3.0\nradius_m = 0.4\nheight_m = 1.0\nretro = true\n";
    let scene = Scene::parse(src, Path::new("t.toml"), "t").unwrap();
    check_scene(&scene, false);
    check_scene(&scene, true);
    let retro: Vec<u8> = world_points(&scene, true)
        .iter()
        .filter(|(r, _)| r.label == 2)
        .map(|(r, _)| r.intensity)
        .collect();
    assert!(!retro.is_empty() && retro.iter().all(|&i| i > 100));
}
