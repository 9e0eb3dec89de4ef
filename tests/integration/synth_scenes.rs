//! Scene files: impossible scenes are refused naming key and line; presets keep their
//! promises (separation and return counts).

use lidar_noise::synth::scene::{Object, Shape};
use lidar_noise::synth::{cast_frames, Scene, SynthOptions};
use std::path::Path;

fn err(src: &str) -> String {
    Scene::parse(src, Path::new("bad.toml"), "bad")
        .expect_err("scene must be refused")
        .to_string()
}

const HEAD: &str = "[sensor]\nheight_m = 1.9\n";

#[test]
fn object_at_the_sensor_is_refused_with_key_and_line() {
    let src = format!(
        "{HEAD}\n[[objects]]\nkind = \"car\"\nx = 1.0\ny = 0.5\nlength_m = 4.5\nwidth_m = 1.8\nheight_m = 1.5\nreflectance = 0.5\n"
    );
    let e = err(&src);
    assert!(e.contains("bad.toml"), "{e}");
    assert!(e.contains("objects[0].x"), "{e}");
    assert!(e.contains("line 6"), "{e}");
    assert!(e.contains("sensor"), "{e}");
    let cyl = format!("{HEAD}[[objects]]\nkind = \"pole\"\nx = 0.05\ny = 0.0\nradius_m = 0.1\nheight_m = 3.0\nreflectance = 0.3\n");
    assert!(err(&cyl).contains("objects[0].x"));
}

#[test]
fn negative_size_is_refused_with_key_and_line() {
    let src = format!(
        "{HEAD}[[objects]]\nkind = \"car\"\nx = 5.0\ny = 0.0\nlength_m = 4.5\nwidth_m = -1.8\nheight_m = 1.5\nreflectance = 0.5\n"
    );
    let e = err(&src);
    assert!(e.contains("objects[0].width_m"), "{e}");
    assert!(e.contains("line 8"), "{e}");
    let zero = format!("{HEAD}[[objects]]\nkind = \"pole\"\nx = 5.0\ny = 0.0\nradius_m = 0.0\nheight_m = 1.5\nreflectance = 0.5\n");
    let e = err(&zero);
    assert!(
        e.contains("objects[0].radius_m") && e.contains("line 7"),
        "{e}"
    );
}

#[test]
fn other_impossible_values_are_refused() {
    let e = err("[sensor]\nheight_m = 1.9\nrotation_hz = 30.0\n");
    assert!(
        e.contains("sensor.rotation_hz") && e.contains("line 3"),
        "{e}"
    );
    let e = err(&format!("{HEAD}[ground]\nreflectance = 1.5\n"));
    assert!(
        e.contains("ground.reflectance") && e.contains("line 4"),
        "{e}"
    );
    let e = err(&format!(
        "{HEAD}[[objects]]\nkind = \"car\"\nx = 5.0\ny = 0.0\nlength_m = 4.5\nwidth_m = 1.8\nheight_m = 1.5\nreflectance = 2.0\n"
    ));
    assert!(
        e.contains("objects[0].reflectance") && e.contains("line 10"),
        "{e}"
    );
    let e = err(&format!(
        "{HEAD}[[objects]]\nkind = \"tree\"\nx = 5.0\ny = 0.0\nheight_m = 1.0\n"
    ));
    assert!(e.contains("objects[0].kind") && e.contains("line 4"), "{e}");
    let e = err("[sensor]\nheight_m = 1.9\ncolour = 3\n");
    assert!(e.contains("colour") && e.contains("line 3"), "{e}");
    let e = err("[sensor]\nheight_m = -1.0\n");
    assert!(e.contains("sensor.height_m") && e.contains("line 2"), "{e}");
    let e = err("frames = 0\n[sensor]\nheight_m = 1.9\n");
    assert!(e.contains("frames") && e.contains("line 1"), "{e}");
    let e = err("[sensor]\nheight_m = 1.9\n[ground]\nslope_deg = \"steep\"\n");
    assert!(
        e.contains("line 4") && e.contains("ground.slope_deg"),
        "{e}"
    );
    assert!(Scene::preset("nowhere").is_err());
}

/// Footprint outline as a convex polygon (cylinders as 64-gons, slightly outside).
fn outline(o: &Object) -> Vec<[f64; 2]> {
    match o.shape {
        Shape::Box {
            length_m,
            width_m,
            yaw_deg,
            ..
        } => {
            let (s, c) = yaw_deg.to_radians().sin_cos();
            [(1.0, 1.0), (-1.0, 1.0), (-1.0, -1.0), (1.0, -1.0)]
                .iter()
                .map(|(u, v)| {
                    let (u, v) = (u * length_m / 2.0, v * width_m / 2.0);
                    [o.x + c * u - s * v, o.y + s * u + c * v]
                })
                .collect()
        }
        Shape::Cylinder { radius_m, .. } => (0..64)
            .map(|k| {
                let a = k as f64 * std::f64::consts::TAU / 64.0;
                let r = radius_m / (std::f64::consts::PI / 64.0).cos();
                [o.x + r * a.cos(), o.y + r * a.sin()]
            })
            .collect(),
    }
}

fn point_segment(p: [f64; 2], a: [f64; 2], b: [f64; 2]) -> f64 {
    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
    let t = (((p[0] - a[0]) * dx + (p[1] - a[1]) * dy) / (dx * dx + dy * dy)).clamp(0.0, 1.0);
    ((p[0] - a[0] - t * dx).powi(2) + (p[1] - a[1] - t * dy).powi(2)).sqrt()
}

/// Distance between two non-overlapping convex polygons.
fn gap(a: &[[f64; 2]], b: &[[f64; 2]]) -> f64 {
    let mut best = f64::INFINITY;
    for (p, q) in [(a, b), (b, a)] {
        for &v in p {
            for k in 0..q.len() {
                best = best.min(point_segment(v, q[k], q[(k + 1) % q.len()]));
            }
        }
    }
    best
}

#[test]
fn presets_keep_objects_apart_and_visible() {
    for name in ["crossroad", "parking", "empty"] {
        let scene = Scene::preset(name).unwrap();
        assert_eq!(scene.name, name);
        let near: Vec<&Object> = scene
            .objects
            .iter()
            .filter(|o| o.x.hypot(o.y) < 20.0)
            .collect();
        for (i, a) in near.iter().enumerate() {
            for b in &near[i + 1..] {
                let g = gap(&outline(a), &outline(b));
                assert!(
                    g > 1.0,
                    "{name}: objects {} and {} are {g:.2} m apart",
                    a.id,
                    b.id
                );
            }
        }
        let frames = cast_frames(&scene, &SynthOptions::default());
        assert_eq!(frames.len(), scene.frames as usize);
        for (f, returns) in frames.iter().enumerate() {
            assert!(returns.iter().any(|r| r.label == 0), "{name}: ground seen");
            for o in &scene.objects {
                let n = returns.iter().filter(|r| r.label == o.id).count();
                assert!(
                    n >= 30,
                    "{name} frame {f}: object {} ({}) has {n} returns",
                    o.id,
                    o.kind
                );
            }
        }
    }
    assert!(Scene::preset("empty").unwrap().objects.is_empty());
    let crossroad = Scene::preset("crossroad").unwrap();
    let kinds: Vec<&str> = crossroad.objects.iter().map(|o| o.kind.as_str()).collect();
    for kind in ["car", "van", "truck", "pole", "barrel"] {
        assert!(kinds.contains(&kind), "crossroad has a {kind}");
    }
}
