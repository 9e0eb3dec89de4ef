//! Two-way transmission exp(-2 alpha R) of every return of a frame, for the extinction
//! stages (fog, rain, snow), without a libm call per return.
//!
//! Written by hand because libm's `exp` is an opaque call the compiler cannot vectorise:
//! three weather stages each took it once per return, a sixth of a weather chain's time.
//! No maintained crate offers a portable, vectorisable exp with a stated accuracy on
//! stable Rust. The method is the textbook one (Cody and Waite's reduction, as in
//! fdlibm's `e_exp.c`): x = k ln 2 + r with |r| <= ln 2 / 2, e^r by its Taylor series to
//! r^13 (truncation below 5e-18 relative), scaled by 2^k through the exponent bits.
//! Within 2 ulp of the exact value (tested against libm over the whole range).

use crate::numeric::wide;
use std::f64::consts::LOG2_E;

/// ln 2 split so that k * LN2_HI is exact for |k| < 2^20 (fdlibm's `ln2HI`).
const LN2_HI: f64 = f64::from_bits(0x3fe6_2e42_fee0_0000);
/// ln 2 - LN2_HI (fdlibm's `ln2LO`).
const LN2_LO: f64 = f64::from_bits(0x3dea_39ef_3579_3c76);
/// Below this, e^x is under the smallest normal double: transmission 0 in all but name.
const FLOOR: f64 = -708.0;

/// e^x for x <= 0 (inputs above 0 are taken as 0, below -708 as -708; NaN gives NaN).
#[inline(always)]
pub fn exp_nonpositive(x: f64) -> f64 {
    // Branch-free, so a loop over a frame's returns vectorises.
    let x = x.clamp(FLOOR, 0.0);
    // Round x / ln 2 to the nearest integer by the 1.5 * 2^52 trick (no SSE4.1 round).
    const SHIFT: f64 = 6_755_399_441_055_744.0;
    let shifted = x * LOG2_E + SHIFT;
    let k = shifted - SHIFT;
    let r = x - k * LN2_HI - k * LN2_LO;
    // Taylor coefficients 1/n!, n = 13 down to 2, Horner.
    let mut p = 1.0 / 6_227_020_800.0;
    for c in [
        1.0 / 479_001_600.0,
        1.0 / 39_916_800.0,
        1.0 / 3_628_800.0,
        1.0 / 362_880.0,
        1.0 / 40_320.0,
        1.0 / 5_040.0,
        1.0 / 720.0,
        1.0 / 120.0,
        1.0 / 24.0,
        1.0 / 6.0,
        0.5,
        1.0,
        1.0,
    ] {
        p = p * r + c;
    }
    // 2^k, k in [-1022, 0]: a normal double built from its exponent field. `shifted`
    // lies in [2^52, 2^53), where doubles are the integers, so its bits are SHIFT's plus
    // k; shifted left by 52 SHIFT's own bits fall off and (k + 1023) fills the exponent
    // field. Integer adds and shifts vectorise; a float-to-int conversion does not.
    let scale = f64::from_bits(shifted.to_bits().wrapping_add(1023) << 52);
    p * scale
}

/// Multiplies the power of every return still alive by exp(-`two_alpha` R), R its range.
pub fn attenuate(power: &mut [f64], range: &[f32], fate: &[super::Fate], two_alpha: f64) {
    if two_alpha <= 0.0 {
        return;
    }
    wide(|| {
        for ((p, &r), f) in power.iter_mut().zip(range).zip(fate) {
            let t = exp_nonpositive(-two_alpha * f64::from(r));
            // A select, not a branch: the loop stays vectorisable.
            *p *= if f.is_alive() { t } else { 1.0 };
        }
    });
}

#[cfg(test)]
mod tests {
    use super::*;
    #[cfg(target_arch = "x86_64")]
    use crate::numeric::{avx512, with_avx2, with_avx512};

    /// Each build of a `wide` loop this processor runs gives the baseline loop's bits:
    /// the attenuation factors of ranges from 0 to past the underflow.
    #[test]
    fn every_wide_build_gives_the_plain_loops_bits() {
        let x: Vec<f64> = (0..20_011)
            .map(|i| -(f64::from(i) * 0.037_1).powf(1.3))
            .collect();
        let run =
            |x: &[f64]| -> Vec<u64> { x.iter().map(|&v| exp_nonpositive(v).to_bits()).collect() };
        let plain = run(&x);
        assert_eq!(wide(|| run(&x)), plain, "picked");
        #[cfg(target_arch = "x86_64")]
        {
            if std::arch::is_x86_feature_detected!("avx2") {
                // SAFETY: the processor has AVX2 (checked on the line above).
                assert_eq!(unsafe { with_avx2(|| run(&x)) }, plain, "avx2");
            }
            if avx512() {
                // SAFETY: the processor has AVX-512 F and DQ (checked on the line above).
                assert_eq!(unsafe { with_avx512(|| run(&x)) }, plain, "avx512");
            }
        }
        // The walk passes the floor (-708) into the clamp, from 1 at 0.
        assert_eq!(plain[0], 1f64.to_bits());
        assert!(x.iter().filter(|&&v| v < FLOOR).count() > 1000);
    }

    /// Distance in units in the last place between two positive doubles.
    fn ulps(a: f64, b: f64) -> u64 {
        a.to_bits().abs_diff(b.to_bits())
    }

    #[test]
    fn within_two_ulp_of_libm_over_the_range() {
        let mut worst = 0;
        // A dense walk over [-708, 0] with irregular steps, and the reduction's edges
        // (multiples of ln 2 / 2, where k changes).
        let mut xs: Vec<f64> = (0..2_000_000)
            .map(|i| -f64::from(i) * 3.540_000_1e-4)
            .collect();
        xs.extend((0..2_045).flat_map(|k| {
            let e = -f64::from(k) * std::f64::consts::LN_2 / 2.0;
            [e, e + 1e-12, e - 1e-12]
        }));
        xs.extend([0.0, -0.0, -1e-300, -5e-324, -1e-17, -707.999_999, -708.0]);
        for x in xs.into_iter().filter(|x| (FLOOR..=0.0).contains(x)) {
            let (got, want) = (exp_nonpositive(x), x.exp());
            let d = ulps(got, want);
            assert!(d <= 2, "exp({x:e}) = {got:e}, libm {want:e}: {d} ulp");
            worst = worst.max(d);
        }
        assert_eq!(exp_nonpositive(0.0), 1.0);
        assert_eq!(LN2_HI + LN2_LO, std::f64::consts::LN_2);
        // A wrong coefficient (1/5! for 1/4!) would be off by far more than 2 ulp.
        assert!(worst <= 2);
    }

    #[test]
    fn clamps_outside_the_domain() {
        assert_eq!(exp_nonpositive(1.0), 1.0);
        assert_eq!(exp_nonpositive(-1e6), exp_nonpositive(-708.0));
        assert!(exp_nonpositive(f64::NAN).is_nan());
        assert!(exp_nonpositive(f64::NEG_INFINITY) < 1e-300);
    }

    #[test]
    fn attenuates_only_returns_still_alive() {
        use crate::noise::Fate;
        let mut power = vec![1.0, 2.0, 3.0];
        let range = [10.0f32, 20.0, 30.0];
        let fate = [Fate::Kept, Fate::Occluded, Fate::Kept];
        attenuate(&mut power, &range, &fate, 0.02);
        assert!((power[0] - (-0.2f64).exp()).abs() < 1e-15);
        assert_eq!(power[1], 2.0);
        assert!((power[2] - 3.0 * (-0.6f64).exp()).abs() < 1e-15);
    }
}
