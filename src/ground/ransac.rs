//! RANSAC ground plane: the usual alternative for input that is not organised by ring.
//!
//! Each iteration draws three distinct returns from the caller's stream, rejects
//! degenerate triples and planes tilted more than the allowed angle from horizontal, and
//! counts returns within the distance threshold; the first plane with the most inliers
//! wins. That plane is refined by a least-squares fit z = a x + b y + c to its inliers
//! (well-posed because the plane is near horizontal), and the ground is the set of
//! returns within the threshold of the refined plane. If refining fails (collinear
//! inliers) or tilts the plane past the limit, the sampled plane is kept.

use crate::frame::Return;
use glam::DVec3;
use rand::Rng;
use rand_chacha::ChaCha8Rng;

/// A plane n . p + d = 0 with unit normal n pointing up.
#[derive(Clone, Copy, Debug)]
struct Plane {
    normal: DVec3,
    d: f64,
}

impl Plane {
    fn distance(&self, p: DVec3) -> f64 {
        (self.normal.dot(p) + self.d).abs()
    }
}

/// Labels returns within `threshold_m` of the best near-horizontal plane as ground.
///
/// Draws exactly three indices per iteration from `rng`, so the stream advances by the
/// same amount for the same input and settings.
pub fn segment(
    returns: &[Return],
    threshold_m: f64,
    iterations: u32,
    max_tilt_deg: f64,
    rng: &mut ChaCha8Rng,
) -> Vec<bool> {
    let mut labels = vec![false; returns.len()];
    // Only finite points take part; `index` maps them back to the input.
    let (index, pts): (Vec<usize>, Vec<DVec3>) = returns
        .iter()
        .enumerate()
        .filter(|(_, r)| r.x.is_finite() && r.y.is_finite() && r.z.is_finite())
        .map(|(i, r)| {
            (
                i,
                DVec3::new(f64::from(r.x), f64::from(r.y), f64::from(r.z)),
            )
        })
        .unzip();
    let m = pts.len();
    if m < 3 {
        return labels;
    }
    let min_up = max_tilt_deg.to_radians().cos();
    let inliers = |plane: &Plane| {
        pts.iter()
            .filter(|&&p| plane.distance(p) <= threshold_m)
            .count()
    };

    let mut best: Option<(Plane, usize)> = None;
    for _ in 0..iterations {
        let (i, j, k) = (
            rng.random_range(0..m),
            rng.random_range(0..m),
            rng.random_range(0..m),
        );
        if i == j || j == k || i == k {
            continue;
        }
        let Some(plane) = plane_through(pts[i], pts[j], pts[k]) else {
            continue;
        };
        if plane.normal.z < min_up {
            continue;
        }
        let count = inliers(&plane);
        if best.is_none_or(|(_, c)| count > c) {
            best = Some((plane, count));
        }
    }
    let Some((sampled, _)) = best else {
        return labels;
    };

    let plane = refine(&pts, &sampled, threshold_m)
        .filter(|p| p.normal.z >= min_up)
        .unwrap_or(sampled);
    for (&i, &p) in index.iter().zip(&pts) {
        labels[i] = plane.distance(p) <= threshold_m;
    }
    labels
}

/// The plane through three points, normal pointing up; None if they are collinear.
fn plane_through(a: DVec3, b: DVec3, c: DVec3) -> Option<Plane> {
    let n = (b - a).cross(c - a);
    let len = n.length();
    // Also rejects NaN lengths.
    if len.is_nan() || len <= 1e-9 {
        return None;
    }
    let n = if n.z < 0.0 { -n / len } else { n / len };
    Some(Plane {
        normal: n,
        d: -n.dot(a),
    })
}

/// Least-squares z = a x + b y + c over the inliers of `plane`, centred for conditioning.
fn refine(pts: &[DVec3], plane: &Plane, threshold_m: f64) -> Option<Plane> {
    let inl: Vec<DVec3> = pts
        .iter()
        .copied()
        .filter(|&p| plane.distance(p) <= threshold_m)
        .collect();
    if inl.len() < 3 {
        return None;
    }
    let mean = inl.iter().copied().sum::<DVec3>() / inl.len() as f64;
    let (mut sxx, mut sxy, mut syy, mut sxz, mut syz) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for p in &inl {
        let q = *p - mean;
        sxx += q.x * q.x;
        sxy += q.x * q.y;
        syy += q.y * q.y;
        sxz += q.x * q.z;
        syz += q.y * q.z;
    }
    let det = sxx * syy - sxy * sxy;
    if det.is_nan() || det.abs() <= 1e-12 * (sxx * syy).max(1e-300) {
        return None;
    }
    let a = (sxz * syy - syz * sxy) / det;
    let b = (syz * sxx - sxz * sxy) / det;
    let normal = DVec3::new(-a, -b, 1.0).normalize();
    Some(Plane {
        normal,
        d: -normal.dot(mean),
    })
}
