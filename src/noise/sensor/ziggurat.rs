//! Standard normal draws for the per-return noise of the sensor stages: the ziggurat of
//! Marsaglia and Tsang (J. Stat. Softw. 5(8), 2000) with 256 layers, one 32-bit word per
//! draw in the common case.
//!
//! Why not `rand_distr::StandardNormal`: it takes a 64-bit word per draw and was, with
//! the ChaCha8 refill behind it, the largest cost of the sensor chain (three draws per
//! return). Here a word gives the layer (its low 8 bits) and a signed 24-bit uniform
//! (its high 24 bits): index and value use disjoint bits, which avoids the correlation
//! Doornik (2005) found in the original, where they share bits. The algorithm is exact
//! (rejection), up to the 2^-23 granularity of the uniform within a layer.
//!
//! Why 256 layers, not the paper's 128: 1.5 % of draws leave the one-word path (for the
//! wedge test, the tail or a fresh word) instead of 2.8 %, and those were a quarter of
//! the normals' time (the top layer alone, which never accepts at once, was 0.8 %).

use rand::{Rng, RngCore};
use rand_chacha::ChaCha8Rng;
use std::sync::OnceLock;

/// Number of layers.
const LAYERS: usize = 256;
/// Bits of a word that pick the layer.
const LAYER_BITS: u32 = 8;
/// Right edge of the base layer (256 layers; the recursion closes at the top layer, see
/// the tests).
const R: f64 = 3.654_152_885_361_009;
/// Area of each layer (and of the base layer with its tail).
const V: f64 = 4.928_673_233_99e-3;
/// Scale of the signed uniform: |hz| < 2^23.
const M: f64 = 8_388_608.0;

struct Tables {
    /// |hz| below k[i] lies inside layer i's rectangle under the curve: accept at once.
    k: [u32; LAYERS],
    /// x = hz w[i].
    w: [f64; LAYERS],
    /// Density exp(-x^2/2) at the layers' edges.
    f: [f64; LAYERS],
    /// Bounds of the density over each layer's wedge (see [`Wedge`]).
    wedge: [Wedge; LAYERS],
}

/// Lines bounding the density g(a) = exp(-a^2/2) over the wedge of one layer,
/// a in [x_{i-1}, x_i], so that most wedge tests are decided without `exp`.
///
/// Where g is convex (a >= 1) its chord through the layer's edges lies above it on the
/// layer and its tangent at the middle below it everywhere; where g is concave (a <= 1)
/// the other way round. A point above the upper line or below the lower one by more
/// than [`WEDGE_EPS`] is decided as the test against `exp` decides it; the rest (the
/// thin band between the lines, and the layer that holds a = 1) call `exp`.
#[derive(Clone, Copy, Debug, Default)]
struct Wedge {
    /// 1: convex on the layer, -1: concave, 0: neither (always `exp`).
    shape: i8,
    /// Outer edge x_i and the density there.
    x_hi: f64,
    f_hi: f64,
    /// Slope of the chord.
    chord: f64,
    /// Middle of the layer, density there and its derivative.
    mid: f64,
    g_mid: f64,
    slope_mid: f64,
}

/// Margin of the line tests. It covers every rounding: the values compared are at most
/// 1, so the libm `exp` (under 1 ulp), the rounding of -x^2/2, the table values and the
/// line evaluations are each off by about 1e-15 at most; and x reaches below the inner
/// edge x_{i-1} by at most one step w_i < 4.4e-7 (the acceptance bound k_i is
/// truncated), where the chord, extended, is off the density's side by at most
/// 4.4e-7 * (|g'| + |chord slope|) < 4.4e-7 * 2 e^-1/2 = 5.3e-7.
const WEDGE_EPS: f64 = 1e-6;

impl Wedge {
    fn new(x_lo: f64, x_hi: f64, f_lo: f64, f_hi: f64) -> Wedge {
        let mid = 0.5 * (x_lo + x_hi);
        let g_mid = (-0.5 * mid * mid).exp();
        // Convexity must hold on the whole reach of x, down to x_lo minus one step.
        let shape = if x_lo - 1e-6 >= 1.0 {
            1
        } else if x_hi <= 1.0 {
            -1
        } else {
            0
        };
        Wedge {
            shape,
            x_hi,
            f_hi,
            chord: (f_lo - f_hi) / (x_lo - x_hi),
            mid,
            g_mid,
            slope_mid: -mid * g_mid,
        }
    }

    /// `Some(y < exp(-a^2/2))` when the lines decide it, else `None`.
    #[inline]
    fn decide(&self, y: f64, a: f64) -> Option<bool> {
        let chord = self.f_hi + self.chord * (a - self.x_hi);
        let tangent = self.g_mid + self.slope_mid * (a - self.mid);
        match self.shape {
            1 if y >= chord + WEDGE_EPS => Some(false),
            1 if y < tangent - WEDGE_EPS => Some(true),
            -1 if y < chord - WEDGE_EPS => Some(true),
            -1 if y >= tangent + WEDGE_EPS => Some(false),
            _ => None,
        }
    }
}

fn tables() -> &'static Tables {
    static T: OnceLock<Tables> = OnceLock::new();
    T.get_or_init(|| {
        let mut t = Tables {
            k: [0; LAYERS],
            w: [0.0; LAYERS],
            f: [0.0; LAYERS],
            wedge: [Wedge::default(); LAYERS],
        };
        let mut dn = R;
        let mut tn = dn;
        let q = V / (-0.5 * dn * dn).exp();
        t.k[0] = (dn / q * M) as u32;
        t.k[1] = 0;
        t.w[0] = q / M;
        t.w[LAYERS - 1] = dn / M;
        t.f[0] = 1.0;
        t.f[LAYERS - 1] = (-0.5 * dn * dn).exp();
        for i in (1..=LAYERS - 2).rev() {
            dn = (-2.0 * (V / dn + (-0.5 * dn * dn).exp()).ln()).sqrt();
            t.k[i + 1] = (dn / tn * M) as u32;
            tn = dn;
            t.f[i] = (-0.5 * dn * dn).exp();
            t.w[i] = dn / M;
        }
        // Layer i spans x_{i-1} = w[i-1] M to x_i = w[i] M (exact: M is a power of two),
        // the top layer from 0.
        for i in 1..LAYERS {
            let x_lo = if i == 1 { 0.0 } else { t.w[i - 1] * M };
            t.wedge[i] = Wedge::new(x_lo, t.w[i] * M, t.f[i - 1], t.f[i]);
        }
        t
    })
}

/// A uniform in (0, 1) (never 0, so its logarithm is finite).
#[inline]
fn open01(rng: &mut ChaCha8Rng) -> f64 {
    ((rng.next_u64() >> 11) as f64 + 0.5) * (1.0 / 9_007_199_254_740_992.0)
}

/// A word's signed uniform (its high 24 bits, arithmetic shift) and layer (its low 8).
#[inline(always)]
fn split(w: u32) -> (i32, usize) {
    ((w as i32) >> LAYER_BITS, (w & (LAYERS as u32 - 1)) as usize)
}

/// The rare case (about 1.5 % of draws): the wedge test, the tail beyond [`R`], or a
/// fresh word; every further word or uniform comes from `rng`.
#[cold]
fn slow(t: &Tables, mut hz: i32, mut iz: usize, rng: &mut ChaCha8Rng) -> f64 {
    loop {
        let x = f64::from(hz) * t.w[iz];
        if iz == 0 {
            // Tail beyond R (Marsaglia 1964).
            loop {
                let x = -open01(rng).ln() / R;
                let y = -open01(rng).ln();
                if y + y >= x * x {
                    return if hz > 0 { R + x } else { -R - x };
                }
            }
        }
        let y = t.f[iz] + open01(rng) * (t.f[iz - 1] - t.f[iz]);
        let inside = match t.wedge[iz].decide(y, x.abs()) {
            Some(inside) => inside,
            None => y < (-0.5 * x * x).exp(),
        };
        if inside {
            return x;
        }
        (hz, iz) = split(rng.next_u32());
        if hz.unsigned_abs() < t.k[iz] {
            return f64::from(hz) * t.w[iz];
        }
    }
}

/// Fills `out` with standard normal draws: one 32-bit word of `rng` per draw, taken in
/// one bulk fill, so draw `j` starts from word `j` of the fill; the rare rejections then
/// take further words from `rng`, in order.
pub fn fill(rng: &mut ChaCha8Rng, out: &mut [f64]) {
    let t = tables();
    let mut buf = [0u32; 512];
    for out in out.chunks_mut(512) {
        let words = &mut buf[..out.len()];
        rng.fill(words);
        for (x, &w) in out.iter_mut().zip(words.iter()) {
            let (hz, iz) = split(w);
            *x = if hz.unsigned_abs() < t.k[iz] {
                f64::from(hz) * t.w[iz]
            } else {
                slow(t, hz, iz, rng)
            };
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use statrs::distribution::{ContinuousCDF, Normal};

    fn draws(n: usize) -> Vec<f64> {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let mut v = vec![0.0; n];
        for c in v.chunks_mut(300) {
            fill(&mut rng, c);
        }
        v
    }

    #[test]
    fn tables_close_the_ziggurat() {
        // The recursion must end at the top layer: x_1 about 0.21524, whose layer has the
        // area V of every other (x_1 (1 - f(x_1)) = V to 1e-11 when it closes),
        // and the base layer accepts most of its draws at once.
        let t = tables();
        assert!(
            (t.w[1] * M - 0.215_241_895_913_273_8).abs() < 1e-9,
            "{}",
            t.w[1] * M
        );
        let x1 = t.w[1] * M;
        assert!((x1 * (1.0 - (-0.5 * x1 * x1).exp()) - V).abs() < 1e-11);
        assert!(t.k[0] > (0.9 * M) as u32);
    }

    #[test]
    fn draws_pass_kolmogorov_smirnov_and_the_tail_share() {
        // 200,000 draws: the KS statistic's 99.9 % critical value is 1.95 / sqrt(n)
        // = 0.0044; the share beyond the base layer's edge (|x| > R, expected 2.58e-4,
        // 52 draws) within 4 binomial SDs.
        let n = 200_000;
        let mut v = draws(n);
        v.sort_by(f64::total_cmp);
        let normal = Normal::new(0.0, 1.0).unwrap();
        let d = v
            .iter()
            .enumerate()
            .map(|(i, &x)| {
                let c = normal.cdf(x);
                (c - i as f64 / n as f64).max((i + 1) as f64 / n as f64 - c)
            })
            .fold(0.0, f64::max);
        assert!(d < 1.95 / (n as f64).sqrt(), "KS D = {d}");
        let p = 2.0 * (1.0 - normal.cdf(R));
        let tail = v.iter().filter(|x| x.abs() > R).count() as f64;
        let sd = (n as f64 * p * (1.0 - p)).sqrt();
        assert!(
            (tail - n as f64 * p).abs() < 4.0 * sd,
            "{tail} vs {}",
            n as f64 * p
        );
        let mean = v.iter().sum::<f64>() / n as f64;
        let var = v.iter().map(|x| (x - mean) * (x - mean)).sum::<f64>() / n as f64;
        assert!(mean.abs() < 4.0 / (n as f64).sqrt(), "{mean}");
        assert!((var - 1.0).abs() < 4.0 * (2.0 / n as f64).sqrt(), "{var}");
    }

    #[test]
    fn wedge_lines_decide_as_exp_does() {
        // Every point of every layer's wedge that the lines decide must get the answer
        // of the test against exp: x over the whole reach of the layer (from one step
        // below the acceptance bound to the outer edge), y over the wedge's height,
        // plus points near the density itself, where the lines must not decide wrongly.
        let t = tables();
        let mut decided = 0u64;
        let mut total = 0u64;
        for i in 1..LAYERS {
            let (k, w) = (f64::from(t.k[i].saturating_sub(1)), t.w[i]);
            for a_step in 0..=400 {
                let hz = k + (M - 1.0 - k) * f64::from(a_step) / 400.0;
                let x = hz.floor() * w;
                let e = (-0.5 * x * x).exp();
                let ys = (0..=200)
                    .map(|j| t.f[i] + f64::from(j) / 200.0 * (t.f[i - 1] - t.f[i]))
                    .chain([-1e-5, -1e-7, -1e-12, 0.0, 1e-12, 1e-7, 1e-5].map(|d| e + d));
                for y in ys {
                    total += 1;
                    for x in [x, -x] {
                        if let Some(inside) = t.wedge[i].decide(y, x.abs()) {
                            decided += 1;
                            assert_eq!(inside, y < (-0.5 * x * x).exp(), "layer {i} x {x} y {y}");
                        }
                    }
                }
            }
        }
        // The lines decide most of the wedge (the band between them is thin).
        assert!(
            decided as f64 > 0.9 * 2.0 * total as f64,
            "{decided} of {}",
            2 * total
        );
    }

    #[test]
    fn each_draw_starts_from_its_own_word() {
        // Draw j of a fill is a function of word j of the stream alone when it is
        // accepted at once (about 99 % of draws), whatever the rejections before it.
        let mut a = ChaCha8Rng::seed_from_u64(3);
        let mut b = ChaCha8Rng::seed_from_u64(3);
        let mut x = [0.0; 64];
        fill(&mut a, &mut x);
        let mut words = [0u32; 64];
        b.fill(&mut words[..]);
        let t = tables();
        for (x, w) in x.iter().zip(words) {
            let (hz, iz) = ((w as i32) >> LAYER_BITS, (w & (LAYERS as u32 - 1)) as usize);
            if hz.unsigned_abs() < t.k[iz] {
                assert_eq!(*x, f64::from(hz) * t.w[iz]);
            }
        }
    }
}
