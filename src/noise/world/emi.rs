//! Electromagnetic interference (p-diagram 16): bursts of dropped and spurious returns.
//!
//! Model (pdiagram-models.md 16): bursts arrive as a Poisson process in time at rate
//! lambda_b (`rate_hz`) and last d_b (`duration_us`). Inside a burst each alive return
//! is dropped with probability p_drop (fate `below_power`: the echo is lost in the
//! disturbance), else with probability p_spur replaced by a spurious range
//! U(minimum range, R_max) and a random intensity byte (uniform 0-255). Optionally whole
//! packets are lost with probability p_pkt each (their returns get fate `below_power`;
//! the packet stays in a `--pcap-out` capture with every slot empty, which is how the
//! decoder sees a corrupted packet it skipped).
//!
//! Choices, stated:
//! - A spurious return is an electrical trigger of the timing logic, not an optical echo,
//!   so it does not compete by the slot rule: the return's range, power and intensity are
//!   overwritten and its fate set to `Replaced` with this stage as cause (`range_clean`
//!   keeps the recorded range). Its power is that of the random intensity at the
//!   spurious range (the ideal-power model), raised to the detection threshold when
//!   lower: the trigger fired, so the sensor detected it.
//! - Burst times are drawn per frame over [t_first - d_b, t_last] of the frame's firing
//!   times (clean times: the disturbance happens in real time), so every instant of the
//!   frame is covered with the stationary probability 1 - exp(-lambda_b d_b). Frames draw
//!   independently: a burst near the end of one frame is not continued in the next.
//! - Packet losses are decided by a hash of the packet's record index and a per-seed key
//!   (a per-unit draw), so a packet shared by two frames is lost in both or neither.
//!
//! Defaults are the doc's: lambda_b = 1/s, d_b = 200 us (about 4 firings), p_drop = 0.5,
//! p_spur = 0.2, p_pkt = 1e-4, R_max = 100 m (the HDL-32E datasheet's range); all
//! engineering assumptions (no LiDAR-specific EMI measurement was found).

use crate::config::reader::Section;
use crate::error::Result;
use crate::noise::registry::OptionSpec;
use crate::noise::sensor::{float, number};
use crate::noise::{Fate, NoiseStage, NoisyFrame, StageKind};
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Poisson};
use std::sync::Arc;
use toml::Value;

/// The `type` name of this stage.
pub const NAME: &str = "emi";

/// The EMI stage.
#[derive(Clone, Debug)]
pub struct Emi {
    /// Burst rate lambda_b, per second.
    pub rate_hz: f64,
    /// Burst duration d_b, microseconds.
    pub duration_us: f64,
    /// Probability that a return inside a burst is dropped.
    pub p_drop: f64,
    /// Probability that a return inside a burst (not dropped) gets a spurious range.
    pub p_spur: f64,
    /// Largest spurious range R_max, metres.
    pub max_range_m: f64,
    /// Probability that a whole packet is lost.
    pub p_packet: f64,
    /// Per-seed key of the packet losses (a per-unit draw; 0 until drawn).
    key: u64,
}

impl Emi {
    /// The stage with these settings (packet-loss key 0 until the chain makes its per-unit
    /// draws).
    pub fn new(
        rate_hz: f64,
        duration_us: f64,
        p_drop: f64,
        p_spur: f64,
        max_range_m: f64,
        p_packet: f64,
    ) -> Emi {
        Emi {
            rate_hz,
            duration_us,
            p_drop,
            p_spur,
            max_range_m,
            p_packet,
            key: 0,
        }
    }

    /// The start times (seconds, ascending) of the bursts touching the frame whose firing
    /// times span [t_first, t_last]: the first draws of the stage's stream.
    pub fn bursts(&self, t_first: f64, t_last: f64, rng: &mut ChaCha8Rng) -> Vec<f64> {
        let d = self.duration_us * 1e-6;
        let span = (t_last - t_first).max(0.0) + d;
        let mean = self.rate_hz * span;
        if mean.is_nan() || mean <= 0.0 {
            return Vec::new();
        }
        let count = match Poisson::new(mean) {
            Ok(p) => p.sample(rng) as usize,
            Err(_) => 0,
        };
        let mut starts: Vec<f64> = (0..count)
            .map(|_| t_first - d + span * rng.random::<f64>())
            .collect();
        starts.sort_by(f64::total_cmp);
        starts
    }

    /// True if packet `packet` is lost.
    pub fn packet_lost(&self, packet: u32) -> bool {
        let u = super::unit(super::splitmix(self.key ^ u64::from(packet)));
        u < self.p_packet
    }

    /// True if the stage changes nothing (zero burst rate or no effect inside bursts, and
    /// no packet loss).
    pub fn is_identity(&self) -> bool {
        (self.rate_hz == 0.0
            || self.duration_us == 0.0
            || (self.p_drop == 0.0 && self.p_spur == 0.0))
            && self.p_packet == 0.0
    }
}

/// True if `t` lies in one of the bursts `[s, s + d)` (`starts` ascending).
#[inline]
pub fn in_burst(starts: &[f64], d: f64, t: f64) -> bool {
    // The latest start at or before t ends last among those that could hold t.
    let k = starts.partition_point(|&s| s <= t);
    k > 0 && t < starts[k - 1] + d
}

impl NoiseStage for Emi {
    fn kind(&self) -> &'static str {
        NAME
    }

    fn describe(&self) -> String {
        format!(
            "bursts {}/s of {} us: drop {}, else spurious range {}; packets lost {}",
            self.rate_hz, self.duration_us, self.p_drop, self.p_spur, self.p_packet
        )
    }

    fn settings(&self) -> Vec<(&'static str, Value)> {
        vec![
            ("rate_hz", float(self.rate_hz)),
            ("duration_us", float(self.duration_us)),
            ("p_drop", float(self.p_drop)),
            ("p_spur", float(self.p_spur)),
            ("max_range_m", float(self.max_range_m)),
            ("p_packet", float(self.p_packet)),
        ]
    }

    fn proposes_echoes(&self) -> bool {
        // Spurious returns are marked `Replaced`: the PLY should say which they are.
        self.rate_hz > 0.0 && self.duration_us > 0.0 && self.p_spur > 0.0 && self.p_drop < 1.0
    }

    fn with_unit_draws(&self, rng: &mut ChaCha8Rng) -> Option<Arc<dyn NoiseStage>> {
        let mut s = self.clone();
        s.key = rng.random();
        Some(Arc::new(s))
    }

    fn apply(&self, frame: &mut NoisyFrame, rng: &mut ChaCha8Rng) {
        if self.is_identity() || frame.is_empty() {
            return;
        }
        let n = frame.len();
        if self.p_packet > 0.0 {
            let mut last: Option<(u32, bool)> = None;
            for i in 0..n {
                let p = frame.clean[i].packet;
                let lost = match last {
                    Some((q, lost)) if q == p => lost,
                    _ => self.packet_lost(p),
                };
                last = Some((p, lost));
                if lost && frame.fate[i].is_alive() {
                    frame.set_fate(i, Fate::BelowPower);
                }
            }
        }
        let (mut t0, mut t1) = (f64::INFINITY, f64::NEG_INFINITY);
        for r in &frame.clean[..frame.clean_len] {
            t0 = t0.min(r.time);
            t1 = t1.max(r.time);
        }
        if t0.is_nan() || t1.is_nan() || t0 > t1 {
            return;
        }
        let starts = self.bursts(t0, t1, rng);
        if starts.is_empty() {
            return;
        }
        let d = self.duration_us * 1e-6;
        let lo_range = frame.min_range.max(0.0);
        let model = frame.power_model.clone();
        for i in 0..n {
            if !frame.fate[i].is_alive() || !in_burst(&starts, d, frame.clean[i].time) {
                continue;
            }
            if rng.random::<f64>() < self.p_drop {
                frame.set_fate(i, Fate::BelowPower);
                continue;
            }
            if rng.random::<f64>() >= self.p_spur {
                continue;
            }
            let range = (lo_range + (self.max_range_m - lo_range) * rng.random::<f64>()) as f32;
            let intensity: u8 = rng.random();
            let power = model
                .as_ref()
                .map_or(frame.power[i], |m| m.power(intensity, range))
                .max(frame.threshold);
            frame.range[i] = range;
            frame.power[i] = power;
            let clean = &frame.clean;
            frame
                .moved
                .intensity
                .get_or_insert_with(|| clean.iter().map(|r| r.intensity).collect())[i] = intensity;
            frame.set_fate(i, Fate::Replaced);
        }
    }
}

/// Reads the options of an `emi` entry.
pub fn build(opts: &Section<'_>) -> Result<Arc<dyn NoiseStage>> {
    let rate_hz = number(opts, "rate_hz", 1.0, 0.0, 1e5)?;
    let duration_us = number(opts, "duration_us", 200.0, 0.0, 1e6)?;
    let p_drop = number(opts, "p_drop", 0.5, 0.0, 1.0)?;
    let p_spur = number(opts, "p_spur", 0.2, 0.0, 1.0)?;
    // The wire holds ranges up to 131.07 m (65535 x 2 mm).
    let max_range_m = number(opts, "max_range_m", 100.0, 1.0, 131.0)?;
    let p_packet = number(opts, "p_packet", 1e-4, 0.0, 1.0)?;
    Ok(Arc::new(Emi::new(
        rate_hz,
        duration_us,
        p_drop,
        p_spur,
        max_range_m,
        p_packet,
    )))
}

/// The registry entry of this stage.
pub const KIND: StageKind = StageKind {
    name: NAME,
    factor: "16 EMI",
    model: "Poisson bursts (rate lambda_b, length d_b): inside, returns dropped with p_drop, else replaced by U(min range, R_max) with random intensity with p_spur; whole packets lost with p_pkt",
    source: "pdiagram-models.md 16 (engineering assumption: no LiDAR-specific EMI measurement found)",
    options: &[
        OptionSpec { name: "rate_hz", unit: "1/s", default: "1", doc: "burst rate lambda_b" },
        OptionSpec { name: "duration_us", unit: "us", default: "200", doc: "burst length d_b" },
        OptionSpec { name: "p_drop", unit: "-", default: "0.5", doc: "probability a return in a burst is dropped" },
        OptionSpec { name: "p_spur", unit: "-", default: "0.2", doc: "probability a return in a burst (not dropped) gets a spurious range" },
        OptionSpec { name: "max_range_m", unit: "m", default: "100", doc: "largest spurious range R_max (at most 131 m, the wire's limit)" },
        OptionSpec { name: "p_packet", unit: "-", default: "0.0001", doc: "probability a whole packet is lost" },
    ],
    build,
};

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    fn emi(rate_hz: f64, p_packet: f64) -> Emi {
        Emi {
            rate_hz,
            duration_us: 200.0,
            p_drop: 0.5,
            p_spur: 0.2,
            max_range_m: 100.0,
            p_packet,
            key: 7,
        }
    }

    #[test]
    fn burst_membership_is_half_open() {
        let starts = [1.0, 1.0001, 5.0];
        let d = 200e-6;
        assert!(in_burst(&starts, d, 1.0));
        assert!(in_burst(&starts, d, 1.00029));
        assert!(!in_burst(&starts, d, 1.0003));
        assert!(!in_burst(&starts, d, 0.9999));
        assert!(in_burst(&starts, d, 5.0001));
        assert!(!in_burst(&[], d, 5.0));
    }

    #[test]
    fn burst_count_follows_the_poisson_mean() {
        // 2000 windows of 0.1 s + 200 us at 5 bursts/s: mean 0.501 per window; the total
        // is Poisson(1002), SD 31.7.
        let e = emi(5.0, 0.0);
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let total: usize = (0..2000)
            .map(|_| {
                let b = e.bursts(10.0, 10.1, &mut rng);
                assert!(b.windows(2).all(|w| w[0] <= w[1]));
                assert!(b.iter().all(|&s| (10.0 - 200e-6..=10.1).contains(&s)));
                b.len()
            })
            .sum();
        assert!((total as f64 - 1002.0).abs() < 4.0 * 31.7, "{total}");
    }

    #[test]
    fn packet_loss_rate_matches_p_packet() {
        let e = emi(0.0, 0.01);
        let lost = (0..100_000u32).filter(|&p| e.packet_lost(p)).count();
        // Binomial(1e5, 0.01): mean 1000, SD 31.5.
        assert!((lost as f64 - 1000.0).abs() < 4.0 * 31.5, "{lost}");
        assert!(!emi(0.0, 0.0).packet_lost(3));
    }
}
