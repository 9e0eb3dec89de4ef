//! Standard normal draws for the per-return noise of the sensor stages: the ziggurat of
//! Marsaglia and Tsang (J. Stat. Softw. 5(8), 2000) with 128 layers, one 32-bit word per
//! draw in the common case.
//!
//! Why not `rand_distr::StandardNormal`: it takes a 64-bit word per draw and was, with
//! the ChaCha8 refill behind it, the largest cost of the sensor chain (three draws per
//! return). Here a word gives the layer (its low 7 bits) and a signed 25-bit uniform
//! (its high 25 bits): index and value use disjoint bits, which avoids the correlation
//! Doornik (2005) found in the original, where they share bits. The algorithm is exact
//! (rejection), up to the 2^-24 granularity of the uniform within a layer.

use rand::{Rng, RngCore};
use rand_chacha::ChaCha8Rng;
use std::sync::OnceLock;

/// Right edge of the base layer (Marsaglia and Tsang, 128 layers).
const R: f64 = 3.442_619_855_899;
/// Area of each layer (and of the base layer with its tail).
const V: f64 = 9.912_563_035_262_17e-3;
/// Scale of the signed uniform: |hz| < 2^24.
const M: f64 = 16_777_216.0;

struct Tables {
    /// |hz| below k[i] lies inside layer i's rectangle under the curve: accept at once.
    k: [u32; 128],
    /// x = hz w[i].
    w: [f64; 128],
    /// Density exp(-x^2/2) at the layers' edges.
    f: [f64; 128],
}

fn tables() -> &'static Tables {
    static T: OnceLock<Tables> = OnceLock::new();
    T.get_or_init(|| {
        let mut t = Tables {
            k: [0; 128],
            w: [0.0; 128],
            f: [0.0; 128],
        };
        let mut dn = R;
        let mut tn = dn;
        let q = V / (-0.5 * dn * dn).exp();
        t.k[0] = (dn / q * M) as u32;
        t.k[1] = 0;
        t.w[0] = q / M;
        t.w[127] = dn / M;
        t.f[0] = 1.0;
        t.f[127] = (-0.5 * dn * dn).exp();
        for i in (1..=126).rev() {
            dn = (-2.0 * (V / dn + (-0.5 * dn * dn).exp()).ln()).sqrt();
            t.k[i + 1] = (dn / tn * M) as u32;
            tn = dn;
            t.f[i] = (-0.5 * dn * dn).exp();
            t.w[i] = dn / M;
        }
        t
    })
}

/// A uniform in (0, 1) (never 0, so its logarithm is finite).
#[inline]
fn open01(rng: &mut ChaCha8Rng) -> f64 {
    ((rng.next_u64() >> 11) as f64 + 0.5) * (1.0 / 9_007_199_254_740_992.0)
}

/// The rare case (about 1.2 % of draws): the wedge test, the tail beyond [`R`], or a
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
        if t.f[iz] + open01(rng) * (t.f[iz - 1] - t.f[iz]) < (-0.5 * x * x).exp() {
            return x;
        }
        let w = rng.next_u32();
        hz = (w as i32) >> 7;
        iz = (w & 127) as usize;
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
            let hz = (w as i32) >> 7;
            let iz = (w & 127) as usize;
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
        // The recursion must end at the top layer: x_1 about 0.2723 (Marsaglia and Tsang),
        // and the base layer accepts most of its draws at once.
        let t = tables();
        assert!(
            (t.w[1] * M - 0.272_320_864_704_670_1).abs() < 1e-6,
            "{}",
            t.w[1] * M
        );
        assert!(t.k[0] > (0.9 * M) as u32);
    }

    #[test]
    fn draws_pass_kolmogorov_smirnov_and_the_tail_share() {
        // 200,000 draws: the KS statistic's 99.9 % critical value is 1.95 / sqrt(n)
        // = 0.0044; the share beyond the base layer's edge (|x| > R, expected 5.76e-4,
        // 115 draws) within 4 binomial SDs.
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
            let (hz, iz) = ((w as i32) >> 7, (w & 127) as usize);
            if hz.unsigned_abs() < t.k[iz] {
                assert_eq!(*x, f64::from(hz) * t.w[iz]);
            }
        }
    }
}
