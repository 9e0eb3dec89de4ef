//! Receiver and circuits (p-diagram 05/06): responsivity and per-laser gain scale the
//! power, a gain error scales the reported intensity, and an additive noise floor raises
//! the effective detection threshold; range noise follows the SNR.
//!
//! Model (pdiagram-models.md, 05/06): P' = responsivity * G_l * P with
//! G_l = exp(N(0, sigma_gain^2)) per laser, drawn once per seed (unit stream). Detection:
//! the return is dropped (`below_power`) when P' + n < p_th * (1 + noise_floor), with
//! n ~ N(0, (sigma_noise * p_th)^2). The doc's soft threshold is P' + n > p_th; the
//! `noise_floor` term (a multiple k of p_th) is this tool's stand-in for a raised
//! background level, so that "a floor of k times the threshold" drops exactly the
//! returns with P' < (1 + k) p_th when `sigma_noise = 0`. Range noise:
//! R' = R + N(0, s_R^2), s_R = range_noise_m / sqrt(2 * SNR), SNR = P'/p_th (LISA).
//! Defaults: the spread between units, to add to a recording (`sensor`, "What the
//! defaults stand for"): dR = 0.03 m, a third of LISA's 0.09 m (which is a whole
//! sensor's range noise and, with the clock and laser-diode defaults, added 2.2 cm at
//! 25 m before issue 29, beyond the datasheet's 2 cm for the whole sensor).
//! Intensity: the power factors show in the byte through the chain's intensity rule
//! (`noise`, "Intensity"), and `gain_error` multiplies the byte alone there
//! (I' = clamp(round(gain_error * I * P / P_i), 0, 255), rounded once). Saturation and
//! walk are not modelled. Source: LISA (velatkilic/LISA, dR = 0.09 m); gains and floor: engineering
//! assumption. Frame stream: two normal draws per return when the corresponding sigma
//! is non-zero.

use super::{fill_normals, float, normal, number, sigma, CHUNK};
use crate::config::reader::Section;
use crate::error::Result;
use crate::noise::registry::OptionSpec;
use crate::noise::spurious::MAX_LASERS;
use crate::noise::{Fate, NoiseStage, NoisyFrame, StageKind, LASER_MASK};

/// Bits of a laser id in a per-laser table ([`MAX_LASERS`] entries).
const LASER_BITS: u32 = MAX_LASERS.trailing_zeros();
use rand_chacha::ChaCha8Rng;
use std::sync::Arc;
use toml::Value;

/// The `type` name of this stage.
pub const NAME: &str = "receiver";

/// The receiver stage.
#[derive(Clone, Debug)]
pub struct Receiver {
    /// Common responsivity factor on power.
    pub responsivity: f64,
    /// SD of the per-laser log gain.
    pub sigma_gain: f64,
    /// Factor on the reported intensity.
    pub gain_error: f64,
    /// Additive floor in units of the detection threshold.
    pub noise_floor: f64,
    /// SD of the additive noise in units of the detection threshold.
    pub sigma_noise: f64,
    /// LISA's dR in metres.
    pub range_noise_m: f64,
    /// Per-laser gains in use, by laser id (all 1 until the unit draws are made; drawn
    /// in id order, so the first 32 do not depend on how many the sensor has).
    pub gains: [f64; MAX_LASERS],
}

impl NoiseStage for Receiver {
    fn kind(&self) -> &'static str {
        NAME
    }
    fn uses_layout(&self) -> bool {
        true
    }
    fn describe(&self) -> String {
        format!(
            "responsivity {}, per-laser gain SD {}, intensity gain {}, noise floor {} x p_th (SD {} x p_th), range noise {} m / sqrt(2 SNR)",
            self.responsivity, self.sigma_gain, self.gain_error, self.noise_floor, self.sigma_noise, self.range_noise_m
        )
    }
    fn settings(&self) -> Vec<(&'static str, Value)> {
        vec![
            ("responsivity", float(self.responsivity)),
            ("sigma_gain", float(self.sigma_gain)),
            ("gain_error", float(self.gain_error)),
            ("noise_floor", float(self.noise_floor)),
            ("sigma_noise", float(self.sigma_noise)),
            ("range_noise_m", float(self.range_noise_m)),
        ]
    }
    fn with_unit_draws(&self, rng: &mut ChaCha8Rng) -> Option<Arc<dyn NoiseStage>> {
        let mut s = self.clone();
        for g in s.gains.iter_mut() {
            *g = (self.sigma_gain * normal(rng)).exp();
        }
        Some(Arc::new(s))
    }
    fn apply(&self, frame: &mut NoisyFrame, rng: &mut ChaCha8Rng) {
        let p_th = frame.threshold;
        let cut = p_th * (1.0 + self.noise_floor);
        let scale_power = self.responsivity != 1.0 || self.sigma_gain != 0.0;
        let any = scale_power
            || self.noise_floor != 0.0
            || self.sigma_noise != 0.0
            || self.range_noise_m != 0.0;
        if any {
            // Per-laser power factor, formed once per frame (same product as per return).
            // Entries from MAX_LASERS on are 1 for dead returns (see below).
            let mut factor = [1.0f64; 2 * MAX_LASERS];
            for (f, g) in factor.iter_mut().zip(self.gains) {
                *f = self.responsivity * g;
            }
            let (draw_det, draw_range) = (self.sigma_noise > 0.0, self.range_noise_m > 0.0);
            let noise_sd = self.sigma_noise * p_th;
            // Draws per return, in stream order: detection noise, then range noise (each
            // only when its sigma is non-zero), made before the fate test so a return
            // draws the same numbers whatever earlier stages dropped (common random
            // numbers). They are drawn a chunk at a time (see `CHUNK`).
            let per = usize::from(draw_det) + usize::from(draw_range);
            let mut buf = [0.0f64; 2 * CHUNK];
            let mut s_r = [0.0f32; CHUNK];
            // s_R = dR / sqrt(2 P'/p_th) = k / sqrt(P') with k = dR sqrt(p_th / 2), in f32
            // (relative error 6e-8 on a standard deviation; the range is f32): one
            // square root and one division per return, four to a vector instruction.
            let k = (self.range_noise_m * (p_th / 2.0).sqrt()) as f32;
            let n = frame.len();
            let lay = frame.layout();
            let NoisyFrame {
                range,
                power,
                fate,
                cause,
                stage,
                ..
            } = frame;
            let mut start = 0;
            while start < n {
                let end = (start + CHUNK).min(n);
                let draws = &mut buf[..per * (end - start)];
                fill_normals(rng, draws);
                let (power, fate) = (&mut power[start..end], &mut fate[start..end]);
                if scale_power {
                    // Dead returns keep their power: they are multiplied by 1, which
                    // gives back every f64 bit for bit (signalling NaNs aside, which no
                    // arithmetic makes). Why not a select: the compiler turned every
                    // form of it (`if`, a select of bits, `select_unpredictable`) into a
                    // branch over the product, which missed on the fates that the drops
                    // of earlier stages leave.
                    for ((p, f), &l) in power
                        .iter_mut()
                        .zip(fate.iter())
                        .zip(&lay.laser[start..end])
                    {
                        let dead = usize::from(!f.is_alive());
                        *p *= factor[usize::from(l & LASER_MASK) | dead << LASER_BITS];
                    }
                }
                let s_r = &mut s_r[..end - start];
                if draw_range {
                    // The range SD of every return of the chunk (values of dead returns
                    // are not used). The powers are narrowed to f32 in a pass of their
                    // own, so the square roots and divisions run four to an instruction
                    // (narrowing f64 on the fly gave two).
                    for (s, &p) in s_r.iter_mut().zip(power.iter()) {
                        *s = p as f32;
                    }
                    for s in s_r.iter_mut() {
                        *s = k / s.sqrt();
                    }
                }
                let (range, cause) = (&mut range[start..end], &mut cause[start..end]);
                let detect = Detect {
                    cut,
                    noise_sd,
                    stage: *stage,
                };
                // One loop per combination of draws, so the stride and the optional
                // parts are constants of the loop (they were per-return tests).
                match (draw_det, draw_range) {
                    (true, true) => detect.run::<true, true>(draws, power, fate, cause, range, s_r),
                    (true, false) => {
                        detect.run::<true, false>(draws, power, fate, cause, range, s_r)
                    }
                    (false, true) => {
                        detect.run::<false, true>(draws, power, fate, cause, range, s_r)
                    }
                    (false, false) => {
                        detect.run::<false, false>(draws, power, fate, cause, range, s_r)
                    }
                }
                start = end;
            }
        }
        if self.gain_error != 1.0 {
            // A factor on the byte alone, applied with the power losses by the chain's
            // intensity rule (rounded once; see `noise`, "Intensity").
            let g = frame.moved.intensity_gain.unwrap_or(1.0) * self.gain_error;
            frame.moved.intensity_gain = Some(g);
        }
    }
}

/// The detection test and range noise of one chunk of returns.
struct Detect {
    /// Effective threshold (1 + floor) p_th.
    cut: f64,
    /// SD of the detection noise, sigma_noise p_th.
    noise_sd: f64,
    /// Index of the stage in the chain (the cause of its drops).
    stage: u8,
}

impl Detect {
    /// Drops (fate and cause) and range noise of a chunk. `draws` holds the chunk's
    /// normals in stream order, `DET as usize + RNG as usize` per return (detection
    /// noise first); `s_r` the range SDs when `RNG`. The values are those of the
    /// per-return branches they replace: a dead return keeps fate, cause and range, a
    /// return dropped here keeps its range, the others move by `s_r n`.
    #[inline(always)]
    fn run<const DET: bool, const RNG: bool>(
        &self,
        draws: &[f64],
        power: &[f64],
        fate: &mut [Fate],
        cause: &mut [u8],
        range: &mut [f32],
        s_r: &[f32],
    ) {
        let per = usize::from(DET) + usize::from(RNG);
        let n = fate.len();
        let (power, cause, range) = (&power[..n], &mut cause[..n], &mut range[..n]);
        let draws = &draws[..per * n];
        let s_r = &s_r[..if RNG { n } else { 0 }];
        for k in 0..n {
            let alive = fate[k].is_alive();
            let n_det = if DET { draws[per * k] } else { 0.0 };
            // `&`, not `&&`: both sides are evaluated anyway, and no branch is made.
            let dropped = alive & (power[k] + self.noise_sd * n_det < self.cut);
            if dropped {
                // As `NoisyFrame::set_fate` (the frame is borrowed field by field).
                fate[k] = Fate::BelowPower;
                cause[k] = self.stage;
            }
            if RNG {
                let n_range = draws[per * k + per - 1];
                let moved = (f64::from(range[k]) + f64::from(s_r[k]) * n_range) as f32;
                range[k] = if alive & !dropped { moved } else { range[k] };
            }
        }
    }
}

/// Reads the options of a `receiver` entry.
pub fn build(opts: &Section<'_>) -> Result<Arc<dyn NoiseStage>> {
    Ok(Arc::new(Receiver {
        responsivity: number(opts, "responsivity", 1.0, 0.0, 10.0)?,
        sigma_gain: sigma(opts, "sigma_gain", 0.05, 2.0)?,
        gain_error: number(opts, "gain_error", 1.0, 0.0, 10.0)?,
        noise_floor: number(opts, "noise_floor", 0.0, 0.0, 1e6)?,
        sigma_noise: sigma(opts, "sigma_noise", 0.3, 100.0)?,
        range_noise_m: sigma(opts, "range_noise_m", 0.03, 10.0)?,
        gains: [1.0; MAX_LASERS],
    }))
}

/// The registry entry of this stage.
pub const KIND: StageKind = StageKind {
    name: NAME,
    factor: "05 receiver, 06 circuits",
    model: "P' = responsivity G_l P (G_l lognormal per laser, per seed); dropped if P' + N(0,(s_n p_th)^2) < (1+floor) p_th; R' = R + N(0, (dR/sqrt(2 P'/p_th))^2); I' = gain_error I",
    source: "range-noise law and dR from LISA (velatkilic/LISA pylisa/lisa.py); gains, floor, soft threshold: engineering assumption (pdiagram-models.md 05/06)",
    options: &[
        OptionSpec { name: "responsivity", unit: "-", default: "1", doc: "factor on power (detector responsivity), in [0, 10]" },
        OptionSpec { name: "sigma_gain", unit: "-", default: "0.05", doc: "SD of the per-laser log gain, drawn once per seed" },
        OptionSpec { name: "gain_error", unit: "-", default: "1", doc: "factor on the reported intensity byte" },
        OptionSpec { name: "noise_floor", unit: "x p_th", default: "0", doc: "additive floor: effective threshold (1 + k) p_th" },
        OptionSpec { name: "sigma_noise", unit: "x p_th", default: "0.3", doc: "SD of the additive detection noise (soft threshold)" },
        OptionSpec { name: "range_noise_m", unit: "m", default: "0.03", doc: "dR: range SD is dR / sqrt(2 SNR) (LISA's whole-sensor 0.09 for synthetic scenes)" },
    ],
    build,
};

#[cfg(test)]
mod tests {
    #[test]
    fn a_product_with_one_gives_back_every_power_bit_for_bit() {
        // Dead returns are multiplied by 1 instead of being skipped: the product must be
        // the value itself for every kind of f64 (quiet NaNs with their payload too).
        let mut values = vec![
            0.0,
            -0.0,
            f64::MIN_POSITIVE,
            f64::MIN_POSITIVE / 3.0,
            -5e-324,
            1.0,
            0.1,
            f64::MAX,
            f64::MIN,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NAN,
            -f64::NAN,
            f64::from_bits(0x7ff8_0000_dead_beef),
            f64::from_bits(0xfff8_0000_0000_0001),
        ];
        let mut x = 1e-300f64;
        while x < 1e300 {
            values.extend([x, -x, x * 1.234_567, x.next_up()]);
            x *= 7.3;
        }
        for v in values {
            assert_eq!((v * 1.0).to_bits(), v.to_bits(), "{v:e}");
        }
    }
}
