//! Detection: whether the receiver reports a return or an echo, after the noise chain.
//!
//! Two models (`[detection] model`):
//! - `"threshold"`: a return is detected when its power is at or above `min_power`, as
//!   in the reference study (Goodin et al.); `configs/paper.toml` keeps it, so the
//!   published decisions stay exactly as they were.
//! - `"probabilistic"` (the default): the receiver's noise makes detection a probability
//!   of the signal-to-noise ratio. With the signal x in units of the threshold T, the
//!   peak the receiver sees is A = x + sigma(x) z, z standard normal, with
//!   sigma(x)^2 = 1 / k^2 + g x: thermal and ambient noise (k = `threshold_snr`, the
//!   threshold over that noise's standard deviation) and the signal's own shot noise
//!   with the photodiode's excess noise (g = `shot_noise` = F / N_T, with N_T the
//!   photoelectrons a pulse at the threshold gives and F the avalanche excess noise
//!   factor). The pulse is detected when A >= 1: P_d(x) = Q((1 - x) / sigma(x)).
//!   Estimates, not published for any Velodyne: k = 6, a threshold six noise deviations
//!   up (a false alarm a range gate at most 1e-9, as the clear sky of the recordings
//!   shows none); g = 0.05 (F = 3 for a silicon avalanche photodiode at a gain of
//!   50-100, N_T = 60 photoelectrons); calibrated against the far-range tail of a real
//!   HDL-32E in fog (`docs/fidelity.md`, "Fog: a real HDL-32E").
//!
//! Recorded returns were detected. The rule therefore applies to what the stages change,
//! not to the recording: a recorded return whose power the stages brought from P_0 to P
//! (and whose threshold from T_0 to T) is kept with probability
//! q = P_d(x) / P_d(x_0), with x_0 = max(P_0 / T_0, 1) and x = x_0 (P / P_0) (T_0 / T):
//! the probability of detection at the new power given detection at the recorded one,
//! for one noise realisation per pulse (the uniform u below is the pulse's noise
//! quantile: detected when u < P_d). x_0 is at least 1 because the recording says the
//! pulse crossed the threshold: where the power model gives less (a dark far target
//! whose reflectance the byte understates), the return is taken at the threshold. In
//! clear air P = P_0 and T = T_0, so q = 1: every recorded return is kept.
//!
//! Spurious echoes (fog, drops, flakes, crosstalk) have no recording: a stage draws one
//! uniform u per echo from its own stream and [`NoisyFrame::detect_echo`] reports it when
//! u < P_d(x) - P_d(0) (the sensor's noise-only false alarms, P_d(0) = Q(k), belong to
//! the recording, not to the echo), with the peak amplitude the draw gives:
//! z = Q^-1(u), A = x + sigma(x) z >= 1. That amplitude is the echo's power in the
//! slot's competition (strongest return), so an echo and a return of equal mean power
//! no longer tie. The recorded return competes with its mean power (its own peak is not
//! drawn: the recording fixed it, and the stages only scale it).
//!
//! Draw pattern: the recorded returns' decisions use a stream of their own, keyed like a
//! stage's by (seed, frame, [`DETECTION_TAG`]), one 32-bit draw per recorded return in
//! return order, whatever its fate, so streams stay aligned across a sweep of any stage's
//! strength. The minimum range stays a hard filter in both models.

use crate::config::{DetectionConfig, DetectionModel};
use crate::noise::{Echo, Fate, NoisyFrame, NO_CAUSE};
use rand::RngCore;
use rand_chacha::ChaCha8Rng;

/// Stream tag of the recorded returns' detection draws: FNV-1a of "detection" in the
/// stage tags' form (no stage type has that name, so no stage shares the stream).
pub const DETECTION_TAG: u32 = 0xdec7_0000;

/// Detection probability below which particle echoes are not drawn (a truncation, for
/// speed: drawing down to 1e-4 doubled moderate snow's time; on frames 0-5 of the shared
/// capture the flake echoes of moderate snow number 553 with a cut at 1e-4 and 563-604
/// over three seeds at 1e-2, within their spread).
pub const FAINTEST_P: f64 = 1e-2;

/// Table step in units of the threshold.
const STEP: f64 = 1.0 / 256.0;

/// The detection rule of a configuration, with P_d tabulated.
#[derive(Clone, Debug)]
pub struct DetectionRule {
    /// Which model.
    pub model: DetectionModel,
    /// k: the threshold over the thermal and ambient noise's standard deviation.
    pub threshold_snr: f64,
    /// g: the shot-noise variance per unit signal, in threshold units.
    pub shot_noise: f64,
    /// P_d(x) at x = j STEP, up to the first x where it is 1 to 1e-13.
    table: Vec<f64>,
    /// P_d(0): the noise-only false alarm probability.
    floor: f64,
    /// The lowest signal (threshold units) whose echo is reported with probability
    /// [`FAINTEST_P`] or more.
    faintest_x: f64,
}

/// Upper tail of the standard normal distribution, Q(z) = P(Z > z).
pub fn normal_tail(z: f64) -> f64 {
    0.5 * libm::erfc(z / std::f64::consts::SQRT_2)
}

/// The z with Q(z) = p, for p in (0, 1).
pub fn normal_tail_inverse(p: f64) -> f64 {
    std::f64::consts::SQRT_2 * statrs::function::erf::erfc_inv(2.0 * p)
}

impl DetectionRule {
    /// The rule of `[detection]`.
    pub fn new(config: &DetectionConfig) -> Self {
        let (k, g) = (config.threshold_snr, config.shot_noise);
        let exact = |x: f64| normal_tail((1.0 - x) / (1.0 / (k * k) + g * x.max(0.0)).sqrt());
        let mut table = Vec::new();
        // Up to the first x where P_d is 1 (to 1e-13), and at most 1e6 entries (x = 3906).
        for j in 0..1_000_000 {
            let p = exact(j as f64 * STEP);
            table.push(p);
            if p >= 1.0 - 1e-13 && j as f64 * STEP > 1.0 {
                break;
            }
        }
        let floor = table[0];
        // P_d is increasing: the first table entry whose excess reaches the cut.
        let faintest = table
            .iter()
            .position(|&p| (p - floor) / (1.0 - floor) >= FAINTEST_P)
            .unwrap_or(0);
        DetectionRule {
            model: config.model,
            threshold_snr: k,
            shot_noise: g,
            floor,
            faintest_x: faintest as f64 * STEP,
            table,
        }
    }

    /// True for the probabilistic model.
    pub fn is_probabilistic(&self) -> bool {
        self.model == DetectionModel::Probabilistic
    }

    /// sigma(x): the noise's standard deviation at signal x (threshold units).
    #[inline]
    pub fn sigma(&self, x: f64) -> f64 {
        (1.0 / (self.threshold_snr * self.threshold_snr) + self.shot_noise * x.max(0.0)).sqrt()
    }

    /// P_d(x): probability that a pulse of signal x (threshold units) crosses the
    /// threshold (tabulated, linear between entries).
    #[inline]
    pub fn p_detect(&self, x: f64) -> f64 {
        let u = x / STEP;
        // Also a NaN signal: the floor.
        if u.is_nan() || u <= 0.0 {
            return self.floor;
        }
        let j = u as usize;
        if j + 1 >= self.table.len() {
            return 1.0;
        }
        let t = u - j as f64;
        self.table[j] + t * (self.table[j + 1] - self.table[j])
    }

    /// Probability that an echo of signal x is reported on its own account: P_d(x)
    /// less the noise-only false alarms P_d(0), renormalised.
    #[inline]
    pub fn p_echo(&self, x: f64) -> f64 {
        ((self.p_detect(x) - self.floor) / (1.0 - self.floor)).max(0.0)
    }

    /// Probability that a recorded return whose signal the stages scaled by `loss`
    /// (P / P_0 times T_0 / T) is still detected, given that it was detected at the
    /// recorded signal `x0` (module documentation).
    #[inline]
    pub fn keep_probability(&self, x0: f64, loss: f64) -> f64 {
        let x0 = x0.max(1.0);
        let x = x0 * loss;
        if x >= x0 {
            return 1.0;
        }
        self.p_detect(x) / self.p_detect(x0)
    }

    /// The peak amplitude (threshold units) of an echo of signal `x` for its uniform
    /// draw `u`, when it is reported (`u < p_echo(x)`); `None` otherwise.
    #[inline]
    pub fn echo_amplitude(&self, x: f64, u: f64) -> Option<f64> {
        let p = self.p_echo(x);
        // Also a NaN draw or signal: none.
        if u.is_nan() || p.is_nan() || u >= p {
            return None;
        }
        // The echo crosses for z > z0 = (1 - x) / sigma, probability Q(z0) ~ p: the
        // quantile u of that tail (u in [0, p)) is the draw's own noise. The floor's
        // renormalisation changes p by at most Q(k) and is not carried into z.
        let z = normal_tail_inverse(u.max(f64::MIN_POSITIVE));
        Some((x + self.sigma(x) * z).max(1.0))
    }
}

impl NoisyFrame {
    /// The echo as the receiver reports it, for the echo's uniform draw `u` (from the
    /// proposing stage's stream): with the threshold model, `Some(echo)` when its power
    /// and range are detectable; with the probabilistic model, `Some` with the drawn peak
    /// amplitude as its power when the noisy pulse crosses the threshold (module
    /// documentation) and its range is at or above the minimum range.
    #[inline]
    pub fn detect_echo(&self, echo: Echo, u: f64) -> Option<Echo> {
        if !(echo.range.is_finite() && echo.power.is_finite())
            || f64::from(echo.range) < self.min_range
        {
            return None;
        }
        match &self.detection {
            Some(rule) if rule.is_probabilistic() => {
                let t = self.threshold;
                rule.echo_amplitude(echo.power / t, u).map(|a| Echo {
                    range: echo.range,
                    power: a * t,
                })
            }
            _ => (echo.power >= self.threshold).then_some(echo),
        }
    }

    /// True when the detection of echoes is a probability (the stages then propose echoes
    /// below the threshold too and draw their detection with [`NoisyFrame::detect_echo`]).
    pub fn probabilistic(&self) -> bool {
        self.detection
            .as_ref()
            .is_some_and(|r| r.is_probabilistic())
    }

    /// The lowest mean power (fraction of emitted power) an echo needs to be reported
    /// with probability [`FAINTEST_P`] or more: the cut below which stages do not draw
    /// echoes (particles), stated as a truncation of the model.
    pub fn faintest_echo(&self) -> f64 {
        match &self.detection {
            Some(rule) if rule.is_probabilistic() => rule.faintest_x * self.threshold,
            _ => self.threshold,
        }
    }
}

/// True when return `i` of fate `fate` is a recorded return the probabilistic rule
/// decided (`i` below `decided`, [`NoisyFrame::decided_len`]) and still reports itself:
/// it counts as detected whatever its power.
#[inline]
pub fn settled(i: usize, fate: Fate, decided: usize) -> bool {
    (i < decided) & (fate == Fate::Kept)
}

/// Decides, before the slots' competition, which recorded returns the receiver still
/// detects after the stages (probabilistic model; module documentation): a drop gets
/// fate [`Fate::BelowPower`] and no cause. `ideal` holds the recorded (ideal) powers and
/// `t0` the configured threshold. Afterwards the recorded returns still alive count as
/// detected whatever their power.
pub fn decide_recorded(frame: &mut NoisyFrame, ideal: &[f64], t0: f64, rng: &mut ChaCha8Rng) {
    let Some(rule) = frame.detection.clone() else {
        return;
    };
    if !rule.is_probabilistic() {
        return;
    }
    let m = frame.clean_len.min(ideal.len());
    let t_ratio = t0 / frame.threshold;
    const SCALE: f64 = 1.0 / 4_294_967_296.0;
    for (((fate, cause), &p), &p0) in frame.fate[..m]
        .iter_mut()
        .zip(&mut frame.cause[..m])
        .zip(&frame.power[..m])
        .zip(&ideal[..m])
    {
        // One draw per recorded return, whatever its fate (aligned streams). Only a
        // return still reporting itself is decided: one a stage already replaced (EMI)
        // reports an echo.
        let u = f64::from(rng.next_u32()) * SCALE;
        if *fate != Fate::Kept || p0 <= 0.0 {
            continue;
        }
        let loss = p / p0 * t_ratio;
        if loss >= 1.0 {
            continue;
        }
        if u >= rule.keep_probability(p0 / t0, loss) {
            *fate = Fate::BelowPower;
            *cause = NO_CAUSE;
        }
    }
    frame.decided = true;
}

/// Marks returns a real sensor could not detect. Only alive returns are examined, so an
/// earlier cause (occlusion) wins, and power is tested before range. The filters are no
/// stage: their drops get cause [`NO_CAUSE`]. Recorded returns already decided by
/// [`decide_recorded`] are tested for range only.
pub fn apply_detection(frame: &mut NoisyFrame, detection: &DetectionConfig) {
    let (min_power, min_range) = (detection.min_power, detection.min_range_m);
    // Recorded returns decided by the probabilistic rule pass the power test.
    let decided = frame.decided_len();
    // One branch per return, on whether the filters drop it (rare), not one on its fate:
    // after stages that drop returns at random (rain, a receiver's soft threshold) the
    // fate branch mispredicted often; stores only for drops (storing every fate and
    // cause was slower where nothing is dropped). Same fates and causes as the tests
    // in order (alive; power; range).
    for (i, (((fate, cause), &p), &r)) in frame
        .fate
        .iter_mut()
        .zip(&mut frame.cause)
        .zip(&frame.power)
        .zip(&frame.range)
        .enumerate()
    {
        let below_power = (p < min_power) & !settled(i, *fate, decided);
        let drop = fate.is_alive() & (below_power | (f64::from(r) < min_range));
        let dropped = if below_power {
            Fate::BelowPower
        } else {
            Fate::BelowMinRange
        };
        if drop {
            *fate = dropped;
            *cause = NO_CAUSE;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    fn rule() -> DetectionRule {
        DetectionRule::new(&DetectionConfig::default())
    }

    #[test]
    fn the_table_follows_the_formula() {
        let r = rule();
        let (k, g) = (r.threshold_snr, r.shot_noise);
        for x in [0.0, 0.1, 0.3, 0.5, 0.77, 1.0, 1.3, 2.0, 5.0] {
            let exact = normal_tail((1.0 - x) / (1.0 / (k * k) + g * x).sqrt());
            assert!((r.p_detect(x) - exact).abs() < 1e-4, "x {x}");
        }
        assert!((r.p_detect(1.0) - 0.5).abs() < 1e-12);
        assert_eq!(r.p_detect(1e6), 1.0);
        // Non-decreasing.
        let mut last = 0.0;
        for j in 0..4000 {
            let p = r.p_detect(j as f64 * 0.001);
            assert!(p >= last);
            last = p;
        }
    }

    #[test]
    fn an_unchanged_return_is_kept_and_a_weakened_one_by_the_ratio() {
        let r = rule();
        for x0 in [0.01, 0.5, 1.0, 3.0, 100.0] {
            assert_eq!(r.keep_probability(x0, 1.0), 1.0);
            assert_eq!(r.keep_probability(x0, 1.2), 1.0);
        }
        // A return at 3 T weakened to 1.5 T: P_d(1.5) / P_d(3).
        let want = r.p_detect(1.5) / r.p_detect(3.0);
        assert!((r.keep_probability(3.0, 0.5) - want).abs() < 1e-12);
        // A dark return the power model puts under the threshold counts as at it.
        assert!((r.keep_probability(0.2, 0.5) - r.p_detect(0.5) / 0.5).abs() < 1e-12);
    }

    #[test]
    fn echoes_are_reported_at_their_probability_with_a_peak_above_the_threshold() {
        let r = rule();
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        for x in [0.4, 0.8, 1.0, 1.5] {
            let n = 200_000;
            let (mut hits, mut above_mean) = (0usize, 0usize);
            for _ in 0..n {
                let u = f64::from(rng.next_u32()) / 4_294_967_296.0;
                if let Some(a) = r.echo_amplitude(x, u) {
                    assert!(a >= 1.0);
                    hits += 1;
                    above_mean += usize::from(a > x);
                }
            }
            let p = r.p_echo(x);
            let sd = (n as f64 * p * (1.0 - p)).sqrt();
            assert!(
                (hits as f64 - n as f64 * p).abs() < 5.0 * sd + 1.0,
                "x {x}: {hits} against {}",
                n as f64 * p
            );
            if x >= 1.0 {
                // Strong echoes: the drawn peak lies above the mean about half the time
                // (no tie with a return of the same mean power).
                assert!(above_mean > hits / 3, "x {x}: {above_mean} of {hits}");
            }
        }
        // The noise-only false alarms are the recording's: an echo of no signal is never
        // reported.
        assert_eq!(r.p_echo(0.0), 0.0);
    }

    #[test]
    fn the_threshold_model_is_the_hard_cut() {
        let cfg = DetectionConfig {
            model: DetectionModel::Threshold,
            ..DetectionConfig::default()
        };
        let frame = NoisyFrame {
            threshold: cfg.min_power,
            min_range: cfg.min_range_m,
            detection: Some(std::sync::Arc::new(DetectionRule::new(&cfg))),
            ..NoisyFrame::default()
        };
        let e = |p| Echo {
            range: 5.0,
            power: p,
        };
        assert_eq!(frame.detect_echo(e(1e-3), 0.99), Some(e(1e-3)));
        assert_eq!(frame.detect_echo(e(0.99e-3), 0.0), None);
        assert_eq!(frame.faintest_echo(), 1e-3);
    }
}
