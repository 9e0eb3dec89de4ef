//! Ray casting of HDL-32E beams against a [`Scene`]: ground plane, oriented boxes,
//! vertical cylinders and curbs (raised sidewalks that follow the ground's slope).
//!
//! A curb's returns are labelled 0, ground: the sidewalk top and the curb face are
//! surfaces a ground segmentation should keep out of the objects (SemanticKITTI counts
//! sidewalks among its ground classes), and the face is only 0.1-0.2 m high.

use super::scene::{Scene, Shape, CURB};
use crate::sensor::calibration::{Calibration, LASERS};

/// Farthest return the synthesizer reports, metres.
pub const MAX_RANGE_M: f64 = 100.0;
/// Size of one raw distance unit, metres.
pub const DISTANCE_UNIT_M: f64 = 0.002;

/// Nearest surface a ray meets.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    /// Distance along the ray, metres.
    pub range: f64,
    /// Cosine of the incidence angle (between the ray and the surface normal), 0..1.
    pub cos_incidence: f64,
    /// 0 for the ground, the object id otherwise.
    pub label: u16,
    /// Diffuse reflectance of the surface.
    pub reflectance: f64,
    /// True for a retro-reflector.
    pub retro: bool,
}

#[derive(Clone, Copy, Debug)]
enum Prim {
    Box {
        cx: f64,
        cy: f64,
        z0: f64,
        cos: f64,
        sin: f64,
        half: [f64; 3],
    },
    Cylinder {
        cx: f64,
        cy: f64,
        z0: f64,
        z1: f64,
        r: f64,
    },
    /// A raised slab on the ground: an oriented rectangle in xy (half sizes `half`)
    /// between the ground plane `n . p = d0` and the parallel plane `n . p = d1`.
    Curb {
        cx: f64,
        cy: f64,
        cos: f64,
        sin: f64,
        half: [f64; 2],
        n: [f64; 3],
        d0: f64,
        d1: f64,
    },
}

#[derive(Clone, Copy, Debug)]
struct Target {
    prim: Prim,
    /// Centre and squared radius of the xy bounding circle: the cheap early-out.
    cx: f64,
    cy: f64,
    r2: f64,
    label: u16,
    reflectance: f64,
    retro: bool,
}

/// Precomputed scene geometry for fast casting (no allocation per ray).
#[derive(Clone, Debug)]
pub struct Caster {
    origin: [f64; 3],
    rot: [[f64; 3]; 3],
    cos_elev: Vec<f64>,
    sin_elev: Vec<f64>,
    az_offset: Vec<f64>,
    ground_n: [f64; 3],
    ground_d: f64,
    ground_reflectance: f64,
    targets: Vec<Target>,
}

/// Unit beam direction in the sensor frame for azimuth `azimuth_deg` (clockwise from
/// x seen from above) and elevation `elevation_deg`: (cos w cos a, -cos w sin a, sin w).
pub fn beam_direction(azimuth_deg: f64, elevation_deg: f64) -> [f64; 3] {
    let (sa, ca) = azimuth_deg.to_radians().sin_cos();
    let (sw, cw) = elevation_deg.to_radians().sin_cos();
    [cw * ca, -cw * sa, sw]
}

/// Rotation taking sensor-frame vectors to the world frame: pitch about y, then roll
/// about x (world = Ry(pitch) * Rx(roll) * sensor).
pub fn sensor_rotation(scene: &Scene) -> [[f64; 3]; 3] {
    let (sp, cp) = scene.sensor.pitch_deg.to_radians().sin_cos();
    let (sr, cr) = scene.sensor.roll_deg.to_radians().sin_cos();
    // Ry(p) = [[cp,0,sp],[0,1,0],[-sp,0,cp]]; Rx(r) = [[1,0,0],[0,cr,-sr],[0,sr,cr]].
    [
        [cp, sp * sr, sp * cr],
        [0.0, cr, -sr],
        [-sp, cp * sr, cp * cr],
    ]
}

fn mul(m: &[[f64; 3]; 3], v: [f64; 3]) -> [f64; 3] {
    [
        m[0][0] * v[0] + m[0][1] * v[1] + m[0][2] * v[2],
        m[1][0] * v[0] + m[1][1] * v[1] + m[1][2] * v[2],
        m[2][0] * v[0] + m[2][1] * v[1] + m[2][2] * v[2],
    ]
}

/// Converts a point in the sensor frame to the world frame.
pub fn sensor_to_world(scene: &Scene, p: [f64; 3]) -> [f64; 3] {
    let w = mul(&sensor_rotation(scene), p);
    let o = scene.sensor_position();
    [w[0] + o[0], w[1] + o[1], w[2] + o[2]]
}

/// Intensity byte for a return, as firmware 2 reports calibrated reflectivity.
///
/// This is a simple Lambertian model: diffuse surfaces give
/// `round(100 * reflectance * cos(incidence))` clamped to 0..100; retro-reflectors
/// give 101..255 (`101 + round(154 * cos(incidence))`), the range the sensor reserves
/// for them.
pub fn intensity(reflectance: f64, retro: bool, cos_incidence: f64) -> u8 {
    let c = cos_incidence.clamp(0.0, 1.0);
    if retro {
        (101.0 + (154.0 * c).round()).clamp(101.0, 255.0) as u8
    } else {
        (100.0 * reflectance * c).round().clamp(0.0, 100.0) as u8
    }
}

impl Caster {
    /// Precomputes the scene for casting with the calibration's elevations and
    /// azimuth offsets.
    pub fn new(scene: &Scene, cal: &Calibration) -> Caster {
        let elevation: Vec<f64> = cal.lasers.iter().map(|l| l.elevation_deg).collect();
        let offset: Vec<f64> = cal.lasers.iter().map(|l| l.azimuth_offset_deg).collect();
        debug_assert_eq!(elevation.len(), LASERS);
        Caster::with_angles(scene, &elevation, &offset)
    }

    /// Precomputes the scene for casting with any sensor's lasers: elevation and
    /// azimuth offset of each laser id in degrees (e.g. a `sensor::SensorModel`'s).
    pub fn with_angles(scene: &Scene, elevation_deg: &[f64], azimuth_offset_deg: &[f64]) -> Caster {
        let (sin_elev, cos_elev): (Vec<f64>, Vec<f64>) = elevation_deg
            .iter()
            .map(|w| w.to_radians().sin_cos())
            .unzip();
        let az_offset = azimuth_offset_deg.to_vec();
        // Ground: z = h0 + tan(s) * (x cos a - y sin a)  <=>  n_raw . p = h0.
        let g = &scene.ground;
        let t = g.slope_deg.to_radians().tan();
        let (sa, ca) = g.slope_azimuth_deg.to_radians().sin_cos();
        let n_raw = [-t * ca, t * sa, 1.0];
        let norm = (n_raw[0] * n_raw[0] + n_raw[1] * n_raw[1] + 1.0).sqrt();
        let ground_n = [n_raw[0] / norm, n_raw[1] / norm, n_raw[2] / norm];
        let ground_d = g.height_m / norm;
        let targets = scene
            .objects
            .iter()
            .map(|o| {
                let prim = match o.shape {
                    Shape::Box {
                        length_m,
                        width_m,
                        height_m,
                        yaw_deg,
                    } if o.kind != CURB => {
                        let (sin, cos) = yaw_deg.to_radians().sin_cos();
                        Prim::Box {
                            cx: o.x,
                            cy: o.y,
                            z0: o.z,
                            cos,
                            sin,
                            half: [length_m / 2.0, width_m / 2.0, height_m / 2.0],
                        }
                    }
                    Shape::Box {
                        length_m,
                        width_m,
                        height_m,
                        yaw_deg,
                    } => {
                        let (sin, cos) = yaw_deg.to_radians().sin_cos();
                        // The slab's top lies height_m above the ground, measured
                        // vertically: ground_n[2] * height_m along the normal.
                        Prim::Curb {
                            cx: o.x,
                            cy: o.y,
                            cos,
                            sin,
                            half: [length_m / 2.0, width_m / 2.0],
                            n: ground_n,
                            d0: ground_d,
                            d1: ground_d + ground_n[2] * height_m,
                        }
                    }
                    Shape::Cylinder { radius_m, height_m } => Prim::Cylinder {
                        cx: o.x,
                        cy: o.y,
                        z0: o.z,
                        z1: o.z + height_m,
                        r: radius_m,
                    },
                };
                let r = o.bounding_radius();
                Target {
                    prim,
                    cx: o.x,
                    cy: o.y,
                    r2: r * r,
                    // Curbs are ground (see the module notes).
                    label: if o.kind == CURB { 0 } else { o.id },
                    reflectance: o.reflectance,
                    retro: o.retro,
                }
            })
            .collect();
        Caster {
            origin: scene.sensor_position(),
            rot: sensor_rotation(scene),
            cos_elev,
            sin_elev,
            az_offset,
            ground_n,
            ground_d,
            ground_reflectance: g.reflectance,
            targets,
        }
    }

    /// Sensor-frame direction of laser `laser` at block azimuth `azimuth_deg`
    /// (calibration azimuth offset included).
    pub fn beam(&self, azimuth_deg: f64, laser: usize) -> [f64; 3] {
        let (sa, ca) = (azimuth_deg + self.az_offset[laser]).to_radians().sin_cos();
        let cw = self.cos_elev[laser];
        [cw * ca, -cw * sa, self.sin_elev[laser]]
    }

    /// Casts laser `laser` at azimuth `azimuth_deg`; None when nothing lies within
    /// [`MAX_RANGE_M`].
    pub fn cast(&self, azimuth_deg: f64, laser: usize) -> Option<Hit> {
        let d = mul(&self.rot, self.beam(azimuth_deg, laser));
        self.cast_world(d)
    }

    /// Casts a unit world-frame ray from the sensor origin.
    pub fn cast_world(&self, d: [f64; 3]) -> Option<Hit> {
        let o = self.origin;
        let mut best = Hit {
            range: MAX_RANGE_M,
            cos_incidence: 0.0,
            label: 0,
            reflectance: 0.0,
            retro: false,
        };
        let mut found = false;
        // Ground plane.
        let n = self.ground_n;
        let denom = n[0] * d[0] + n[1] * d[1] + n[2] * d[2];
        if denom < -1e-12 {
            let t = (self.ground_d - (n[0] * o[0] + n[1] * o[1] + n[2] * o[2])) / denom;
            if t > 0.0 && t <= best.range {
                best = Hit {
                    range: t,
                    cos_incidence: -denom,
                    label: 0,
                    reflectance: self.ground_reflectance,
                    retro: false,
                };
                found = true;
            }
        }
        let dxy2 = d[0] * d[0] + d[1] * d[1];
        for target in &self.targets {
            // Early out: the ray's xy line must pass within the bounding circle, ahead
            // of the sensor and closer than the best hit so far.
            let wx = target.cx - o[0];
            let wy = target.cy - o[1];
            let along = wx * d[0] + wy * d[1];
            let w2 = wx * wx + wy * wy;
            if dxy2 < 1e-18 {
                if w2 > target.r2 {
                    continue;
                }
            } else {
                let perp2 = w2 - along * along / dxy2;
                if perp2 > target.r2 {
                    continue;
                }
                // Entry into the circle along the xy projection, converted to 3D range.
                let r = target.r2.sqrt();
                let t_centre = along / dxy2;
                let t_entry = t_centre - (r / dxy2.sqrt()).max(0.0);
                if t_centre + r / dxy2.sqrt() < 0.0 || t_entry > best.range {
                    continue;
                }
            }
            if let Some((t, cos_inc)) = intersect(&target.prim, o, d) {
                if t < best.range {
                    best = Hit {
                        range: t,
                        cos_incidence: cos_inc,
                        label: target.label,
                        reflectance: target.reflectance,
                        retro: target.retro,
                    };
                    found = true;
                }
            }
        }
        found.then_some(best)
    }
}

/// Narrows `[t_near, t_far]` to where `a + b t` lies in `[lo, hi]`; records in `axis`
/// the slab (`which`) the ray enters last. False when the interval becomes empty.
fn clip(a: f64, b: f64, lo: f64, hi: f64, which: usize, t: &mut (f64, f64, usize)) -> bool {
    if b.abs() < 1e-15 {
        return a >= lo && a <= hi;
    }
    let mut t0 = (lo - a) / b;
    let mut t1 = (hi - a) / b;
    if t0 > t1 {
        std::mem::swap(&mut t0, &mut t1);
    }
    if t0 > t.0 {
        t.0 = t0;
        t.2 = which;
    }
    t.1 = t.1.min(t1);
    t.0 <= t.1
}

/// Nearest positive intersection of a ray with a primitive: (range, cos incidence).
fn intersect(prim: &Prim, o: [f64; 3], d: [f64; 3]) -> Option<(f64, f64)> {
    match *prim {
        Prim::Curb {
            cx,
            cy,
            cos,
            sin,
            half,
            n,
            d0,
            d1,
        } => {
            let (px, py) = (o[0] - cx, o[1] - cy);
            let pu = cos * px + sin * py;
            let pv = -sin * px + cos * py;
            let qu = cos * d[0] + sin * d[1];
            let qv = -sin * d[0] + cos * d[1];
            let pn = n[0] * o[0] + n[1] * o[1] + n[2] * o[2];
            let qn = n[0] * d[0] + n[1] * d[1] + n[2] * d[2];
            let mut t = (f64::NEG_INFINITY, f64::INFINITY, 0usize);
            if !(clip(pu, qu, -half[0], half[0], 0, &mut t)
                && clip(pv, qv, -half[1], half[1], 1, &mut t)
                && clip(pn, qn, d0, d1, 2, &mut t))
            {
                return None;
            }
            if t.0 <= 0.0 {
                return None;
            }
            let cos_inc = match t.2 {
                0 => qu.abs(),
                1 => qv.abs(),
                _ => qn.abs(),
            };
            Some((t.0, cos_inc))
        }
        Prim::Box {
            cx,
            cy,
            z0,
            cos,
            sin,
            half,
        } => {
            // Into the box frame (centred, axis-aligned): rotate by -yaw.
            let px = o[0] - cx;
            let py = o[1] - cy;
            let p = [
                cos * px + sin * py,
                -sin * px + cos * py,
                o[2] - (z0 + half[2]),
            ];
            let q = [cos * d[0] + sin * d[1], -sin * d[0] + cos * d[1], d[2]];
            let mut t_near = f64::NEG_INFINITY;
            let mut t_far = f64::INFINITY;
            let mut axis = 0;
            for k in 0..3 {
                if q[k].abs() < 1e-15 {
                    if p[k].abs() > half[k] {
                        return None;
                    }
                    continue;
                }
                let inv = 1.0 / q[k];
                let mut t0 = (-half[k] - p[k]) * inv;
                let mut t1 = (half[k] - p[k]) * inv;
                if t0 > t1 {
                    std::mem::swap(&mut t0, &mut t1);
                }
                if t0 > t_near {
                    t_near = t0;
                    axis = k;
                }
                t_far = t_far.min(t1);
                if t_near > t_far {
                    return None;
                }
            }
            if t_near <= 0.0 {
                // The sensor is never inside an object (validated), so a box behind
                // the sensor or around it yields no return.
                return None;
            }
            Some((t_near, q[axis].abs()))
        }
        Prim::Cylinder { cx, cy, z0, z1, r } => {
            let px = o[0] - cx;
            let py = o[1] - cy;
            let mut best: Option<(f64, f64)> = None;
            // Side: |p + t d|_xy = r.
            let a = d[0] * d[0] + d[1] * d[1];
            if a > 1e-18 {
                let b = px * d[0] + py * d[1];
                let c = px * px + py * py - r * r;
                let disc = b * b - a * c;
                if disc >= 0.0 {
                    let t = (-b - disc.sqrt()) / a;
                    let z = o[2] + t * d[2];
                    if t > 0.0 && z >= z0 && z <= z1 {
                        let nx = (px + t * d[0]) / r;
                        let ny = (py + t * d[1]) / r;
                        best = Some((t, (nx * d[0] + ny * d[1]).abs()));
                    }
                }
            }
            // Caps.
            if d[2].abs() > 1e-15 {
                for zc in [z0, z1] {
                    let t = (zc - o[2]) / d[2];
                    if t > 0.0 && best.is_none_or(|(bt, _)| t < bt) {
                        let x = px + t * d[0];
                        let y = py + t * d[1];
                        if x * x + y * y <= r * r {
                            best = Some((t, d[2].abs()));
                        }
                    }
                }
            }
            best
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    fn scene(src: &str) -> Scene {
        Scene::parse(src, Path::new("t.toml"), "t").unwrap()
    }

    #[test]
    fn flat_ground_range_matches_geometry() {
        let s = scene("[sensor]\nheight_m = 2.0\n");
        let c = Caster::new(&s, &Calibration::builtin());
        // Laser 0 points 30.67 degrees down: range = 2 / sin(30.67).
        let hit = c.cast(0.0, 0).unwrap();
        assert_eq!(hit.label, 0);
        assert!((hit.range - 2.0 / 30.67f64.to_radians().sin()).abs() < 1e-9);
        // Laser 31 points up: no return.
        assert!(c.cast(0.0, 31).is_none());
    }

    #[test]
    fn box_ahead_is_hit_on_its_near_face() {
        let s = scene(
            "[sensor]\nheight_m = 1.0\n[[objects]]\nkind = \"wall\"\nx = 10.0\ny = 0.0\nlength_m = 1.0\nwidth_m = 4.0\nheight_m = 3.0\nreflectance = 0.5\n",
        );
        let c = Caster::new(&s, &Calibration::builtin());
        let hit = c.cast(0.0, 15).unwrap(); // laser 15: elevation 0
        assert_eq!(hit.label, 1);
        assert!((hit.range - 9.5).abs() < 1e-9);
        assert!((hit.cos_incidence - 1.0).abs() < 1e-12);
        assert_eq!(intensity(hit.reflectance, hit.retro, hit.cos_incidence), 50);
        // Behind the sensor the wall is not seen.
        assert_ne!(c.cast(180.0, 15).map(|h| h.label), Some(1));
    }

    #[test]
    fn cylinder_side_and_cap() {
        let s = scene(
            "[sensor]\nheight_m = 1.0\n[[objects]]\nkind = \"pole\"\nx = 0.0\ny = -5.0\nradius_m = 0.5\nheight_m = 0.5\nreflectance = 0.5\n",
        );
        let c = Caster::new(&s, &Calibration::builtin());
        // Azimuth 90 points to -y (clockwise from x). Laser 15 passes over the 0.5 m cylinder.
        assert_ne!(c.cast(90.0, 15).map(|h| h.label), Some(1));
        // Straight down from above the cap: cast a world ray.
        let d = {
            let v = [0.0f64, -5.0, -0.5];
            let n = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
            [v[0] / n, v[1] / n, v[2] / n]
        };
        let hit = c.cast_world(d).unwrap();
        assert_eq!(hit.label, 1);
    }

    #[test]
    fn curb_top_and_face_are_ground_and_follow_the_slope() {
        for slope in [0.0, 4.0] {
            let s = scene(&format!(
                "[sensor]\nheight_m = 2.0\n[ground]\nslope_deg = {slope}\n[[objects]]\nkind = \"curb\"\nx = 5.0\ny = 0.0\nlength_m = 2.0\nwidth_m = 4.0\nheight_m = 0.15\nreflectance = 0.3\n"
            ));
            let c = Caster::new(&s, &Calibration::builtin());
            let g = &s.ground;
            let ray = |x: f64, z: f64| {
                let n = (x * x + (z - 2.0) * (z - 2.0)).sqrt();
                [x / n, 0.0, (z - 2.0) / n]
            };
            // Onto the top at x = 5.5: it lies 0.15 m above the (sloped) ground there.
            let top = g.z_at(5.5, 0.0) + 0.15;
            let hit = c.cast_world(ray(5.5, top)).unwrap();
            assert_eq!(hit.label, 0);
            let want = (5.5f64.powi(2) + (top - 2.0).powi(2)).sqrt();
            assert!(
                (hit.range - want).abs() < 1e-6,
                "{slope}: {} {want}",
                hit.range
            );
            // Onto the face at x = 4, halfway up.
            let mid = g.z_at(4.0, 0.0) + 0.07;
            let hit = c.cast_world(ray(4.0, mid)).unwrap();
            assert_eq!(hit.label, 0);
            let want = (16.0 + (mid - 2.0).powi(2)).sqrt();
            assert!(
                (hit.range - want).abs() < 1e-6,
                "{slope}: {} {want}",
                hit.range
            );
            assert!(hit.cos_incidence > 0.8);
        }
    }

    #[test]
    fn intensity_model() {
        assert_eq!(intensity(0.5, false, 1.0), 50);
        assert_eq!(intensity(1.0, false, 0.5), 50);
        assert_eq!(intensity(0.0, false, 1.0), 0);
        assert_eq!(intensity(0.3, true, 1.0), 255);
        assert_eq!(intensity(0.3, true, 0.0), 101);
    }
}
