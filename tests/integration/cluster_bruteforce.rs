//! The distance cut (voxel grid and k-d tree paths) against an O(n^2) brute-force reference.

use lidar_noise::cluster::{cluster, distance_components, ClusterOptions, CutRule};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

/// Blobs of varying spread plus uniform noise, with a few exact duplicates.
fn cloud(rng: &mut ChaCha8Rng, n: usize, extent: f32) -> Vec<[f32; 3]> {
    let n_blobs = rng.random_range(1..12);
    let centers: Vec<([f32; 3], f32)> = (0..n_blobs)
        .map(|_| {
            let c = [
                rng.random_range(-extent..extent),
                rng.random_range(-extent..extent),
                rng.random_range(-2.0..2.0),
            ];
            (c, rng.random_range(0.1..1.5))
        })
        .collect();
    let noise_share: f64 = rng.random_range(0.0..0.5);
    let mut pts = Vec::with_capacity(n);
    while pts.len() < n {
        let u: f64 = rng.random();
        if u < noise_share {
            pts.push([
                rng.random_range(-extent..extent),
                rng.random_range(-extent..extent),
                rng.random_range(-2.0..2.0),
            ]);
        } else if u < noise_share + 0.02 && !pts.is_empty() {
            let k = rng.random_range(0..pts.len());
            pts.push(pts[k]);
        } else {
            let (c, s) = centers[rng.random_range(0..centers.len())];
            let normal = Normal::new(0.0f32, s).unwrap();
            pts.push([
                c[0] + normal.sample(rng),
                c[1] + normal.sample(rng),
                c[2] + normal.sample(rng),
            ]);
        }
    }
    pts
}

fn dist(a: &[f32; 3], b: &[f32; 3]) -> f64 {
    let (dx, dy, dz) = (
        a[0] as f64 - b[0] as f64,
        a[1] as f64 - b[1] as f64,
        a[2] as f64 - b[2] as f64,
    );
    (dx * dx + dy * dy + dz * dz).sqrt()
}

/// Canonical partition: each point gets the first index of its component.
fn brute_force(pts: &[[f32; 3]], linked: impl Fn(usize, usize) -> bool) -> Vec<usize> {
    let n = pts.len();
    let mut comp: Vec<usize> = (0..n).collect();
    // Flood fill from each unvisited point (independent of the library's union-find).
    let mut seen = vec![false; n];
    for s in 0..n {
        if seen[s] {
            continue;
        }
        seen[s] = true;
        let mut stack = vec![s];
        while let Some(i) = stack.pop() {
            comp[i] = s;
            for (j, seen_j) in seen.iter_mut().enumerate() {
                if !*seen_j && linked(i, j) {
                    *seen_j = true;
                    stack.push(j);
                }
            }
        }
    }
    comp
}

/// Label-permutation-invariant form: each point gets the first index carrying its label.
fn canonical<T: Copy + Eq + std::hash::Hash>(labels: &[T]) -> Vec<usize> {
    let mut first = std::collections::HashMap::new();
    labels
        .iter()
        .enumerate()
        .map(|(i, l)| *first.entry(*l).or_insert(i))
        .collect()
}

#[test]
fn distance_cut_matches_brute_force() {
    let mut nontrivial = 0;
    for seed in 0..100u64 {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let n = if seed % 10 == 0 {
            3000
        } else {
            rng.random_range(2..1500)
        };
        let extent = rng.random_range(3.0..30.0);
        let pts = cloud(&mut rng, n, extent);
        let cutoff: f64 = rng.random_range(0.05..1.0);
        let expected = brute_force(&pts, |i, j| dist(&pts[i], &pts[j]) <= cutoff);
        let got = distance_components(&pts, cutoff, 0.0).unwrap();
        assert_eq!(
            canonical(&got),
            expected,
            "seed {seed}, n {n}, cutoff {cutoff}"
        );
        // Labels are numbered by smallest point index, so they already are canonical up to
        // renumbering: label k first appears before label k+1.
        let mut next = 0;
        for &l in &got {
            assert!(
                l <= next,
                "seed {seed}: labels not in first-appearance order"
            );
            if l == next {
                next += 1;
            }
        }
        // Non-trivial: at least two components of three or more points.
        let mut sizes = std::collections::HashMap::new();
        for &c in &expected {
            *sizes.entry(c).or_insert(0usize) += 1;
        }
        if sizes.values().filter(|&&s| s >= 3).count() >= 2 {
            nontrivial += 1;
        }
    }
    assert!(
        nontrivial >= 50,
        "only {nontrivial} clouds had non-trivial clusters"
    );
}

/// A point a billion metres out is beyond the voxel grid's coordinate limit (1e9 voxels of
/// side at most cutoff/sqrt(3)), which forces the k-d tree path for a fixed cutoff; the result
/// must match the brute force and, apart from the isolated outlier, the grid path's result.
#[test]
fn fixed_cutoff_tree_fallback_matches_brute_force_and_grid() {
    for seed in 0..30u64 {
        let mut rng = ChaCha8Rng::seed_from_u64(500 + seed);
        let n = rng.random_range(2..1500);
        let extent = rng.random_range(3.0..30.0);
        let mut pts = cloud(&mut rng, n, extent);
        let cutoff: f64 = rng.random_range(0.05..1.0);
        let grid = distance_components(&pts, cutoff, 0.0).unwrap();
        pts.push([1e9, 0.0, 0.0]);
        let expected = brute_force(&pts, |i, j| dist(&pts[i], &pts[j]) <= cutoff);
        let tree = distance_components(&pts, cutoff, 0.0).unwrap();
        assert_eq!(canonical(&tree), expected, "seed {seed}, n {n}");
        assert_eq!(
            tree[..n],
            grid[..],
            "seed {seed}: grid and tree labels differ"
        );
        let outlier = tree[n];
        assert!(tree[..n].iter().all(|&l| l != outlier));
    }
}

#[test]
fn range_adaptive_cutoff_matches_brute_force() {
    // Seeds cover the shell grids (c0 > 0, small per_m), per_m beyond the shells' reach and
    // c0 = 0 (k-d tree fallback), and clouds far out where shells are wide.
    for seed in 0..120u64 {
        let mut rng = ChaCha8Rng::seed_from_u64(1000 + seed);
        let n = rng.random_range(2..1500);
        let extent = if seed % 3 == 0 { 120.0 } else { 50.0 };
        let pts = cloud(&mut rng, n, extent);
        let c0: f64 = match seed % 10 {
            0 => 0.0,
            _ => rng.random_range(0.01..0.6),
        };
        let per_m: f64 = match seed % 7 {
            0 => rng.random_range(0.1..0.5),
            _ => rng.random_range(0.0005..0.05),
        };
        let range = |p: &[f32; 3]| dist(p, &[0.0; 3]);
        let expected = brute_force(&pts, |i, j| {
            dist(&pts[i], &pts[j]) <= c0 + per_m * range(&pts[i]).max(range(&pts[j]))
        });
        let got = distance_components(&pts, c0, per_m).unwrap();
        assert_eq!(canonical(&got), expected, "seed {seed}, n {n}");
    }
}

#[test]
fn min_points_and_non_finite_points() {
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let mut pts = cloud(&mut rng, 800, 10.0);
    pts[3] = [f32::NAN, 0.0, 0.0];
    pts[10] = [f32::INFINITY, 1.0, 1.0];
    let opts = ClusterOptions {
        cut: CutRule::Distance,
        cutoff_m: 0.4,
        cutoff_per_m: 0.0,
        min_points: 5,
        max_edge_m: 1.0,
    };
    let c = cluster(&pts, &opts).unwrap();
    let finite: Vec<usize> = (0..pts.len()).filter(|&i| i != 3 && i != 10).collect();
    let partition = brute_force(&pts, |i, j| {
        finite.contains(&i) && finite.contains(&j) && dist(&pts[i], &pts[j]) <= 0.4
    });
    let mut sizes = std::collections::HashMap::new();
    for &p in &partition {
        *sizes.entry(p).or_insert(0usize) += 1;
    }
    let mut ids = std::collections::HashMap::new();
    let expected: Vec<i32> = partition
        .iter()
        .map(|p| {
            if sizes[p] < 5 {
                -1
            } else {
                let next = ids.len() as i32;
                *ids.entry(*p).or_insert(next)
            }
        })
        .collect();
    assert_eq!(c.labels, expected);
    assert_eq!(c.labels[3], -1);
    assert_eq!(c.n_clusters, ids.len());
    assert_eq!(
        c.n_noise_points,
        expected.iter().filter(|&&l| l < 0).count()
    );
    assert!(c.n_clusters > 1 && c.n_noise_points > 0);
}

#[test]
fn invalid_options_are_errors() {
    let pts = [[0.0f32; 3]; 3];
    assert!(distance_components(&pts, -1.0, 0.0).is_err());
    assert!(distance_components(&pts, f64::NAN, 0.0).is_err());
    assert!(distance_components(&pts, 0.5, -0.1).is_err());
    // Zero cutoff still joins exact duplicates.
    assert_eq!(distance_components(&pts, 0.0, 0.0).unwrap(), vec![0, 0, 0]);
    assert!(distance_components(&[], 0.5, 0.0).unwrap().is_empty());
}

/// Pairs at exactly the cutoff (which link: `<=`), points on and next to voxel faces and
/// clouds far from the origin, where the voxel assignment's rounding is largest: the grid
/// must still match the brute force exactly.
#[test]
fn boundary_distances_match_brute_force() {
    for seed in 0..60u64 {
        let mut rng = ChaCha8Rng::seed_from_u64(7000 + seed);
        let n = rng.random_range(50..800);
        let step = [0.25f32, 0.125, 0.5][seed as usize % 3];
        let origin = match seed % 4 {
            0 => [0.0f32; 3],
            1 => [1000.0, -2000.0, 5.0],
            2 => [-40_000.0, 30_000.0, 0.0],
            _ => [rng.random_range(-100.0..100.0), 7.0, -3.0],
        };
        let mut pts: Vec<[f32; 3]> = (0..n)
            .map(|_| {
                // Lattice points (many pairs at exactly k * step), some nudged by one ulp.
                let mut p = [0f32; 3];
                for (a, c) in p.iter_mut().enumerate() {
                    let v = origin[a] + step * rng.random_range(-12i32..12) as f32;
                    *c = match rng.random_range(0..6) {
                        0 => f32::from_bits(v.to_bits() + 1),
                        1 if v != 0.0 => f32::from_bits(v.to_bits() - 1),
                        _ => v,
                    };
                }
                p
            })
            .collect();
        // Cutoffs that equal some pair's exact f64 distance.
        let (i, j) = (rng.random_range(0..n), rng.random_range(0..n));
        pts.push(pts[i]);
        let cutoffs = [
            2.0 * step as f64,
            step as f64,
            dist(&pts[i], &pts[j]).clamp(0.01, 3.0),
            (2.0 * (step as f64).powi(2)).sqrt(),
        ];
        for cutoff in cutoffs {
            let expected = brute_force(&pts, |a, b| dist(&pts[a], &pts[b]) <= cutoff);
            let got = distance_components(&pts, cutoff, 0.0).unwrap();
            assert_eq!(canonical(&got), expected, "seed {seed}, cutoff {cutoff}");
        }
    }
}
