//! The two-argument arc tangent of the points-to-returns conversion, written here rather
//! than called from the C library: `f64::atan2` is a call into libm per value, which the
//! compiler cannot inline or vectorise, and two of them a point (azimuth and elevation)
//! were a third of the time a dataset scan took to become returns (perf on a nuScenes
//! sweep and a 120k-point KITTI scan). This one is branch-free arithmetic (selects,
//! two divisions), so a loop over points compiles to AVX2 vectors, and it gives the same
//! bits on every platform (libm's result may differ by an ulp between C libraries).
//! No crate offers that for f64: `libm` is musl's branching scalar code, and the SIMD
//! math crates approximate in f32.
//!
//! The method is Cephes' `atan` (S. L. Moshier, *Methods and Programs for Mathematical
//! Functions*, 1989; netlib cephes `atan.c`): the ratio of the smaller to the larger
//! absolute coordinate, in [0, 1], is taken to [0, 0.66] by atan(a) = pi/4 +
//! atan((a - 1) / (a + 1)) above 0.66, where the degree 4/5 rational approximation
//! atan(t) = t + t^3 P(t^2) / Q(t^2) has a peak relative error of 2.6e-18; the octant is
//! restored with pi/2 and pi split into a double and its remainder. The reduced argument
//! is formed from the coordinates themselves, (s - l) / (s + l) (s - l exact by
//! Sterbenz's lemma there), one rounding less than from the rounded ratio. Measured
//! within 2 ulp of glibc's `atan2` (tests below).

/// Numerator coefficients of Cephes' atan rational approximation, highest power first.
#[allow(clippy::excessive_precision)]
const P: [f64; 5] = [
    -8.750608600031904122785e-1,
    -1.615753718733365076637e1,
    -7.500855792314704667340e1,
    -1.228866684490136173410e2,
    -6.485021904942025371773e1,
];

/// Denominator coefficients (leading 1 implied), highest power first.
#[allow(clippy::excessive_precision)]
const Q: [f64; 5] = [
    2.485846490142306297962e1,
    1.650270098316988542046e2,
    4.328810604912902668951e2,
    4.853903996359136964868e2,
    1.945506571482613964425e2,
];

/// pi/4 - FRAC_PI_4, pi/2 - FRAC_PI_2 and pi - PI: what the doubles leave out.
const PIO4_LO: f64 = 3.061616997868383e-17;
const PIO2_LO: f64 = 6.123233995736766e-17;
const PI_LO: f64 = 1.2246467991473532e-16;

/// atan2(y, x) in radians, as `f64::atan2` for finite arguments (signed zeros included:
/// atan2(+-0, -0) = +-pi). Infinite arguments are not handled (the conversion refuses
/// non-finite coordinates before).
#[inline(always)]
pub(crate) fn atan2(y: f64, x: f64) -> f64 {
    use std::f64::consts::{FRAC_PI_2, FRAC_PI_4, PI};
    let (ax, ay) = (x.abs(), y.abs());
    let swap = ay > ax;
    let (small, large) = if swap { (ax, ay) } else { (ay, ax) };
    // Above 0.66 (ratio): pi/4 + atan((s - l) / (s + l)); the threshold's rounding only
    // moves which of two valid forms a ratio near it takes.
    let reduced = small > 0.66 * large;
    let num = if reduced { small - large } else { small };
    let den = if reduced { small + large } else { large };
    // Both zero: atan2's value is 0 before the signs (not 0 / 0).
    let t = if den == 0.0 { 0.0 } else { num / den };
    let z = t * t;
    let p = (((P[0] * z + P[1]) * z + P[2]) * z + P[3]) * z + P[4];
    let q = ((((z + Q[0]) * z + Q[1]) * z + Q[2]) * z + Q[3]) * z + Q[4];
    let core = t + t * (z * p / q);
    // atan2 = base + s atan(ratio), base 0, pi/2 or pi by the octant, s = -1 where the
    // swap and x's sign disagree; the constants' high parts summed first (exactly, their
    // rounding error carried), the small parts and the core after: one rounding at the
    // end, so an axis or a diagonal comes out as libm's.
    let negative_x = x.is_sign_negative();
    let s = if swap != negative_x { -1.0 } else { 1.0 };
    let (base_hi, base_lo) = match (swap, negative_x) {
        (false, false) => (0.0, 0.0),
        (true, _) => (FRAC_PI_2, PIO2_LO),
        (false, true) => (PI, PI_LO),
    };
    let (r_hi, r_lo) = if reduced {
        (FRAC_PI_4, PIO4_LO)
    } else {
        (0.0, 0.0)
    };
    // Fast2Sum: base_hi is 0 or at least r_hi in size, so `error` is hi's rounding error.
    let hi = base_hi + s * r_hi;
    let error = (base_hi - hi) + s * r_hi;
    let r = hi + ((error + base_lo) + s * (core + r_lo));
    if y.is_sign_negative() {
        -r
    } else {
        r
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    /// Distance in units in the last place between two doubles of one sign.
    fn ulps(a: f64, b: f64) -> u64 {
        assert_eq!(a.is_sign_negative(), b.is_sign_negative(), "{a} vs {b}");
        a.to_bits().abs_diff(b.to_bits())
    }

    #[test]
    fn within_two_ulp_of_libm() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let mut worst = (0, 0.0, 0.0);
        let mut check = |y: f64, x: f64| {
            let d = ulps(atan2(y, x), y.atan2(x));
            if d > worst.0 {
                worst = (d, y, x);
            }
        };
        // Coordinates as a scan holds them (metres, every direction), ratios near the
        // reduction's edges (0.66, 1) and the axes, and extremes of scale.
        for _ in 0..400_000 {
            let (y, x) = (
                rng.random_range(-200.0..200.0),
                rng.random_range(-200.0..200.0),
            );
            check(y, x);
        }
        for _ in 0..200_000 {
            let x: f64 = rng.random_range(-1e3..1e3);
            let ratio = [0.66, 1.0, 1e-9, 1.5151515151515151][rng.random_range(0..4)];
            let y = x * ratio * (1.0 + rng.random_range(-1e-6..1e-6));
            check(y, x);
            check(x, y);
            check(-y, x);
        }
        for _ in 0..100_000 {
            let e: i32 = rng.random_range(-300..300);
            let (y, x) = (
                rng.random_range(-1.0..1.0) * 2f64.powi(e),
                rng.random_range(-1.0..1.0),
            );
            check(y, x);
            check(x, y);
        }
        eprintln!(
            "worst: {} ulp at atan2({:e}, {:e})",
            worst.0, worst.1, worst.2
        );
        assert!(
            worst.0 <= 2,
            "{} ulp at atan2({:e}, {:e})",
            worst.0,
            worst.1,
            worst.2
        );
    }

    #[test]
    fn axes_and_diagonals_exactly_as_libm() {
        let values = [
            0.0,
            -0.0,
            1.0,
            -1.0,
            0.5,
            -3.0,
            1e-300,
            -1e300,
            f64::MIN_POSITIVE,
        ];
        for y in values {
            for x in values {
                let (got, want) = (atan2(y, x), y.atan2(x));
                if y == 0.0 || x == 0.0 || y.abs() == x.abs() {
                    assert_eq!(
                        got.to_bits(),
                        want.to_bits(),
                        "atan2({y:e}, {x:e}): {got} vs {want}"
                    );
                } else {
                    assert!(ulps(got, want) <= 2, "atan2({y:e}, {x:e}): {got} vs {want}");
                }
            }
        }
    }
}
