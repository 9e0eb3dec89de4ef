//! Small numeric helpers shared across the pipeline: rounding, angle wrapping, small-angle
//! sin and cos, and running a loop compiled for the processor's widest vectors.

/// `x.round().clamp(0.0, max) as u16` without the libm call `round` is on the x86-64
/// baseline and without a branch: the clamp first, in floating point (max(NaN, 0) is 0,
/// so the conversion is a plain one that vectorises), then one step up by the fraction,
/// which `x - t` gives exactly (t <= max <= x, or 0 <= x - t < 1).
#[inline(always)]
pub(crate) fn round_clamped(x: f64, max: u16) -> u16 {
    // `clamp` would pass a NaN through.
    #[allow(clippy::manual_clamp)]
    let c = x.max(0.0).min(f64::from(max));
    // SAFETY: c is finite and in [0, 65535], so its integer part fits an i32.
    let t = unsafe { c.to_int_unchecked::<i32>() };
    let up = i32::from(x - f64::from(t) >= 0.5);
    (t + up).min(i32::from(max)) as u16
}

/// `a.rem_euclid(360.0)` without the `fmod` call for the angles sensor stages produce
/// (within one turn of [0, 360)): the same value, since `a - 360` is exact there and
/// `a + 360` is the rounded sum `rem_euclid` also returns.
#[inline]
pub(crate) fn wrap_360(a: f64) -> f64 {
    if (0.0..360.0).contains(&a) {
        a
    } else if a > -360.0 && a < 0.0 {
        // (-360 itself gives -0.0 under rem_euclid: left to it below.)
        a + 360.0
    } else if (360.0..720.0).contains(&a) {
        a - 360.0
    } else {
        a.rem_euclid(360.0)
    }
}

/// sin and cos of `t` radians; a Taylor series for the small angles sensor stages use
/// (|t| < 0.01: truncation error below 1e-13, far under f32 precision), which is several
/// times faster than `sin_cos` in the per-return loop of [`NoisyFrame::survivors`].
///
/// The series multiplies by rounded reciprocals instead of dividing by 6, 20 and 12 (and
/// by 0.5 instead of 2, which is exact): its four divisions were most of its time, and a
/// rounded reciprocal moves a term by an ulp, 1e-16 of a term itself under 2e-5.
pub(crate) fn small_sin_cos(t: f64) -> (f64, f64) {
    if t.abs() < 0.01 {
        let t2 = t * t;
        (
            t * (1.0 - t2 * (1.0 / 6.0) * (1.0 - t2 * (1.0 / 20.0))),
            1.0 - t2 * 0.5 * (1.0 - t2 * (1.0 / 12.0)),
        )
    } else {
        t.sin_cos()
    }
}

/// Runs `f`, a loop over a frame's columns, compiled for AVX-512 or else AVX2 where the
/// processor has it (eight or four doubles a vector instead of SSE2's two; detected at
/// run time, because the crate is built for the x86-64 baseline). The results are the same bits: AVX2 brings
/// wider vectors, not fused multiply-adds, and the compiler never fuses on its own.
/// Only a small `f` is reliably inlined into the AVX2 function: the larger loops (the Mie
/// rain pass, the intensity rule) have their own `#[target_feature]` twin instead, which
/// measured 4 M instructions a frame less than going through this closure.
#[inline(always)]
pub fn wide<R>(f: impl FnOnce() -> R) -> R {
    #[cfg(target_arch = "x86_64")]
    {
        if avx512() {
            // SAFETY: the processor has AVX-512 F and DQ (checked on the line above).
            return unsafe { with_avx512(f) };
        }
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the processor has AVX2 (checked on the line above).
            return unsafe { with_avx2(f) };
        }
    }
    f()
}

/// Whether the processor has AVX-512's foundation and its double and quadword
/// instructions (eight doubles a vector; the conversions between doubles and 64-bit
/// integers). The loops compiled for it give the same bits as with AVX2 or SSE2: wider
/// vectors again, no fused multiply-adds (tests compare every variant).
#[cfg(target_arch = "x86_64")]
#[inline(always)]
pub(crate) fn avx512() -> bool {
    std::arch::is_x86_feature_detected!("avx512f")
        && std::arch::is_x86_feature_detected!("avx512dq")
}

/// `f` inlined into a function compiled with AVX-512 enabled.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx512dq")]
pub(crate) unsafe fn with_avx512<R>(f: impl FnOnce() -> R) -> R {
    f()
}

/// `f` inlined into a function compiled with AVX2 enabled.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
pub(crate) unsafe fn with_avx2<R>(f: impl FnOnce() -> R) -> R {
    f()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn small_sin_cos_agrees_with_sin_cos() {
        // A dense walk over the series' range (-0.01, 0.01) and past it, with its ends and
        // signed zeros: within 1e-14 of libm (a wrong coefficient, e.g. 1/7 for 1/6, is
        // off by 2e-8 at 0.01), the sign of sin kept, and libm itself past the range.
        let mut ts = vec![0.0, -0.0, 1e-300, -1e-300, 0.009_999_999, -0.009_999_999];
        ts.extend((-60_000..=60_000).map(|k| f64::from(k) * 4.999_9e-7));
        for t in ts {
            let ((s, c), (ls, lc)) = (small_sin_cos(t), t.sin_cos());
            assert!((s - ls).abs() < 1e-14 && (c - lc).abs() < 1e-14, "{t:e}");
            assert_eq!(s.to_bits() >> 63, ls.to_bits() >> 63, "sign of sin {t:e}");
            if t.abs() >= 0.01 {
                assert_eq!((s.to_bits(), c.to_bits()), (ls.to_bits(), lc.to_bits()));
            }
        }
        assert_eq!(small_sin_cos(0.5), 0.5f64.sin_cos());
    }
}
