//! Fog (p-diagram 11): extinction of the hard-target power and the soft-target
//! backscatter echo of the fog itself, after Hahner, Sakaridis, Dai and Van Gool, "Fog
//! Simulation on Real LiDAR Point Clouds for 3D Object Detection in Adverse Weather",
//! ICCV 2021 (pdiagram-models.md, "11 Weather: fog").
//!
//! Model:
//! - extinction alpha = -ln(0.05) / V from the meteorological optical range V (5 %
//!   contrast), backscatter beta = beta_r / V;
//! - hard target: P_h = P exp(-2 alpha R0) on every alive return at its range R0;
//! - soft target (the fog): with the pulse s(t) = sin^2(pi t / (2 tau_H)) on
//!   [0, 2 tau_H] and the transmitter/receiver overlap xi(r) (0 below R1, 1 above R2,
//!   linear between), the echo at apparent range R is
//!   P_s(R) = gain * pi * kappa * beta * I(R; R0), with
//!   I(R; R0) = (c/2) int_0^{2 tau_H} s(t) exp(-2 alpha r) xi(r) / r^2 dt, r = R - c t/2,
//!   only r <= R0 (no fog behind the target). Written over r (dt = 2 dr / c) this is
//!   int_{R - c tau_H}^{min(R, R0)} sin^2(pi (R - r) / (c tau_H)) exp(-2 alpha r) xi(r) / r^2 dr.
//!   pi * kappa replaces the paper's C_A P_0, so that a Lambertian target (beta = rho/pi)
//!   gives exactly the tool's P = kappa rho / R^2; the released code instead scales its
//!   tabulated integral by intensity * R0^2 * beta / beta_0 with an empirical beta_0. The
//!   two differ, hence `gain`.
//! - the fog echo is the maximum of P_s over R, reported c tau_H / 2 earlier (where a
//!   hard target's pulse would put its range); it is *proposed* to the return's firing
//!   slot ([`NoisyFrame::propose`]) and competes there once, after the chain, with the
//!   target and other stages' echoes by the sensor's return logic (strongest mode: the
//!   fog point replaces the target when max P_s > P_h, as in the paper).
//!
//! The integral is computed here (Gauss-Legendre quadrature on the smooth pieces between
//! R1, R2 and R0, maximum over R by a scan and golden-section search), not read from the
//! paper's tables. It depends only on the options and R0, so it is tabulated once per
//! stage (on first use) on a 5 mm grid of R0, linearly interpolated; beyond the
//! untruncated peak (R0 >= argmax, a few metres) the truncation at R0 no longer touches
//! the maximum and the echo is constant, so the grid ends there.
//!
//! Deviations, stated: the paper's table generator only scans apparent ranges R <= R0;
//! we follow the formula (truncation of r at R0, any R), which differs only for targets
//! closer than the peak (a few metres). Slots without a return (sky, targets out of
//! range) get the untruncated fog echo too (option `empty_slots`), since the fog in front
//! of the sensor echoes whatever lies behind it; the paper's code only rewrites points.
//! The reported intensity of a kept target is not lowered (as in `rain`: power only).

use crate::config::reader::Section;
use crate::error::Result;
use crate::noise::registry::OptionSpec;
use crate::noise::sensor::{float, number, C_M_PER_S};
use crate::noise::{Echo, Fate, NoiseStage, NoisyFrame, StageKind};
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use std::sync::{Arc, OnceLock};
use toml::Value;

/// The `type` name of this stage.
pub const NAME: &str = "fog";

/// kappa (m^2) of the default power model, for frames built without one.
const DEFAULT_KAPPA_M2: f64 = 100.0;

/// Range (m) taken as the target range R0 of a slot without a return, for the range
/// noise of its fog echo: the HDL-32E's rated range.
pub const EMPTY_SLOT_RANGE_M: f64 = 100.0;

/// Grid step (m) of the tabulated echo over R0.
const TABLE_STEP_M: f64 = 0.005;

/// Extinction coefficient alpha (1/m) at meteorological optical range `v` metres:
/// -ln(0.05) / V (infinite V: 0).
pub fn extinction_per_m(visibility_m: f64) -> f64 {
    if visibility_m.is_infinite() {
        0.0
    } else {
        -(0.05f64.ln()) / visibility_m
    }
}

/// The optical parameters of the soft-target integral.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SoftTarget {
    /// Extinction alpha in 1/m.
    pub alpha: f64,
    /// Half-power pulse width tau_H in seconds.
    pub tau_h_s: f64,
    /// Overlap starts (xi > 0) at this range in metres (R1 > 0).
    pub overlap_start_m: f64,
    /// Overlap is complete (xi = 1) from this range in metres (R2 >= R1).
    pub overlap_full_m: f64,
}

impl SoftTarget {
    /// Pulse length in range, c tau_H (metres): the echo window is [R - c tau_H, R].
    pub fn window_m(&self) -> f64 {
        C_M_PER_S * self.tau_h_s
    }

    /// The overlap function xi(r).
    pub fn overlap(&self, r: f64) -> f64 {
        let (r1, r2) = (self.overlap_start_m, self.overlap_full_m);
        if r <= r1 {
            0.0
        } else if r >= r2 {
            1.0
        } else {
            (r - r1) / (r2 - r1)
        }
    }

    /// I(R; R0) in 1/m: the soft-target integral at apparent range `r_app` for a hard
    /// target at `r0` (`f64::INFINITY` for none), by Gauss-Legendre quadrature on the
    /// pieces where the integrand is smooth.
    pub fn integral(&self, r_app: f64, r0: f64) -> f64 {
        let l = self.window_m();
        let lo = (r_app - l).max(self.overlap_start_m);
        let hi = r_app.min(r0);
        if hi <= lo {
            return 0.0;
        }
        let k = std::f64::consts::PI / l;
        let f = |r: f64| {
            let s = (k * (r_app - r)).sin();
            s * s * (-2.0 * self.alpha * r).exp() * self.overlap(r) / (r * r)
        };
        // Breaks at R2 (kink of xi); R1 and R0 are ends already.
        let mid = self.overlap_full_m.clamp(lo, hi);
        gauss_legendre(&f, lo, mid) + gauss_legendre(&f, mid, hi)
    }

    /// The maximum of I(R; R0) over R: (argmax R, max).
    pub fn peak(&self, r0: f64) -> (f64, f64) {
        let l = self.window_m();
        // The untruncated integrand rises up to R2 and falls after it, so the
        // convolution with the pulse peaks before R2 + c tau_H; a target at R0 cuts the
        // window, and then the peak lies before R0 + c tau_H.
        let hi = if r0.is_finite() {
            r0.min(self.overlap_full_m + l) + l
        } else {
            self.overlap_full_m + l
        };
        let lo = self.overlap_start_m;
        maximise(&|r| self.integral(r, r0), lo, hi)
    }
}

/// Gauss-Legendre nodes and weights on [-1, 1] (16 points): exact for polynomials up
/// to degree 31; the pieces integrated here are analytic with the nearest singularity
/// (r = 0) far from the interval, so the error is far below 1e-9 relative.
fn gl16() -> &'static [(f64, f64)] {
    static NODES: OnceLock<Vec<(f64, f64)>> = OnceLock::new();
    NODES.get_or_init(|| legendre_nodes(16))
}

/// Nodes and weights of the n-point Gauss-Legendre rule (Newton on P_n).
fn legendre_nodes(n: usize) -> Vec<(f64, f64)> {
    let mut out = Vec::with_capacity(n);
    for i in 0..n {
        let mut x = (std::f64::consts::PI * (i as f64 + 0.75) / (n as f64 + 0.5)).cos();
        let mut dp = 1.0;
        for _ in 0..100 {
            // P_n(x) and P_n'(x) by the three-term recurrence.
            let (mut p0, mut p1) = (1.0, x);
            for k in 2..=n {
                let kf = k as f64;
                let p2 = ((2.0 * kf - 1.0) * x * p1 - (kf - 1.0) * p0) / kf;
                p0 = p1;
                p1 = p2;
            }
            dp = n as f64 * (x * p1 - p0) / (x * x - 1.0);
            let dx = p1 / dp;
            x -= dx;
            if dx.abs() < 1e-15 {
                break;
            }
        }
        out.push((x, 2.0 / ((1.0 - x * x) * dp * dp)));
    }
    out
}

fn gauss_legendre(f: &dyn Fn(f64) -> f64, a: f64, b: f64) -> f64 {
    if b <= a {
        return 0.0;
    }
    let (c, h) = ((a + b) / 2.0, (b - a) / 2.0);
    h * gl16().iter().map(|&(x, w)| w * f(c + h * x)).sum::<f64>()
}

/// Maximum of `f` on [lo, hi]: a 48-point scan, then golden-section search around the
/// best point (the functions maximised here are unimodal or nearly so).
fn maximise(f: &dyn Fn(f64) -> f64, lo: f64, hi: f64) -> (f64, f64) {
    const N: usize = 48;
    let step = (hi - lo) / N as f64;
    let (mut best, mut best_v) = (lo, f(lo));
    for k in 1..=N {
        let x = lo + step * k as f64;
        let v = f(x);
        if v > best_v {
            best = x;
            best_v = v;
        }
    }
    let (mut a, mut b) = ((best - step).max(lo), (best + step).min(hi));
    let g = (5f64.sqrt() - 1.0) / 2.0;
    let (mut x1, mut x2) = (b - g * (b - a), a + g * (b - a));
    let (mut f1, mut f2) = (f(x1), f(x2));
    while b - a > 1e-6 {
        if f1 < f2 {
            a = x1;
            x1 = x2;
            f1 = f2;
            x2 = a + g * (b - a);
            f2 = f(x2);
        } else {
            b = x2;
            x2 = x1;
            f2 = f1;
            x1 = b - g * (b - a);
            f1 = f(x1);
        }
    }
    let x = (a + b) / 2.0;
    let v = f(x);
    [(x, v), (best, best_v)]
        .into_iter()
        .fold((x, v), |m, c| if c.1 > m.1 { c } else { m })
}

/// The fog echo as a function of the target range R0: reported range (the argmax moved
/// c tau_H / 2 earlier) and the integral's maximum, on a grid of R0.
#[derive(Clone, Debug)]
pub struct EchoTable {
    /// R0 of the first grid entry (R1: no echo below).
    start: f64,
    /// (reported range, max I) at R0 = start + k * TABLE_STEP_M.
    grid: Vec<(f64, f64)>,
    /// From this R0 on, the untruncated echo `far` applies.
    far_from: f64,
    /// The echo of a target beyond the peak (or of no target).
    far: (f64, f64),
}

impl EchoTable {
    /// Tabulates the echo of `soft`.
    pub fn new(soft: &SoftTarget) -> EchoTable {
        let shift = soft.window_m() / 2.0;
        let (peak_r, peak_i) = soft.peak(f64::INFINITY);
        let start = soft.overlap_start_m;
        let n = ((peak_r - start) / TABLE_STEP_M).ceil().max(0.0) as usize + 1;
        let grid = (0..=n)
            .map(|k| {
                let r0 = start + TABLE_STEP_M * k as f64;
                if r0 >= peak_r {
                    (peak_r - shift, peak_i)
                } else {
                    let (r, i) = soft.peak(r0);
                    (r - shift, i)
                }
            })
            .collect();
        EchoTable {
            start,
            grid,
            far_from: start + TABLE_STEP_M * n as f64,
            far: (peak_r - shift, peak_i),
        }
    }

    /// (reported range in m, max I in 1/m) of the fog echo in front of a target at `r0`.
    #[inline]
    pub fn lookup(&self, r0: f64) -> (f64, f64) {
        if r0 >= self.far_from {
            return self.far;
        }
        let u = (r0 - self.start) / TABLE_STEP_M;
        if u.is_nan() || u < 0.0 {
            return (0.0, 0.0);
        }
        let k = u as usize;
        let t = u - k as f64;
        let (a, b) = (self.grid[k], self.grid[k + 1]);
        (a.0 + t * (b.0 - a.0), a.1 + t * (b.1 - a.1))
    }

    /// The echo of a slot without a target.
    pub fn far(&self) -> (f64, f64) {
        self.far
    }
}

/// The fog stage.
#[derive(Clone, Debug)]
pub struct Fog {
    /// Meteorological optical range V in metres (infinite: no fog).
    pub visibility_m: f64,
    /// beta_r: backscatter beta = beta_r / V (1/(m sr)).
    pub beta_r: f64,
    /// Half-power pulse width tau_H in ns.
    pub tau_h_ns: f64,
    /// R1: the receiver starts to see the beam (m).
    pub overlap_start_m: f64,
    /// R2: the receiver sees the whole beam (m).
    pub overlap_full_m: f64,
    /// Factor on the fog echo power.
    pub gain: f64,
    /// n: fog echo range scaled by R0 / U(R0 - n, R0 + n) (Hahner's noise variant v1);
    /// 0 for none.
    pub range_noise_m: f64,
    /// Fog echoes also in slots without a return.
    pub empty_slots: bool,
    table: OnceLock<Arc<EchoTable>>,
}

impl Fog {
    /// The stage with these options (valid values assumed, as `build` checks them).
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        visibility_m: f64,
        beta_r: f64,
        tau_h_ns: f64,
        overlap_start_m: f64,
        overlap_full_m: f64,
        gain: f64,
        range_noise_m: f64,
        empty_slots: bool,
    ) -> Fog {
        Fog {
            visibility_m,
            beta_r,
            tau_h_ns,
            overlap_start_m,
            overlap_full_m,
            gain,
            range_noise_m,
            empty_slots,
            table: OnceLock::new(),
        }
    }

    /// Extinction alpha in 1/m.
    pub fn alpha(&self) -> f64 {
        extinction_per_m(self.visibility_m)
    }

    /// Backscatter beta in 1/(m sr).
    pub fn beta(&self) -> f64 {
        if self.visibility_m.is_infinite() {
            0.0
        } else {
            self.beta_r / self.visibility_m
        }
    }

    /// The soft-target parameters.
    pub fn soft_target(&self) -> SoftTarget {
        SoftTarget {
            alpha: self.alpha(),
            tau_h_s: self.tau_h_ns * 1e-9,
            overlap_start_m: self.overlap_start_m,
            overlap_full_m: self.overlap_full_m,
        }
    }

    /// The echo table (computed on first use, shared by every frame and thread).
    pub fn table(&self) -> &EchoTable {
        self.table
            .get_or_init(|| Arc::new(EchoTable::new(&self.soft_target())))
    }

    /// Power factor turning the integral I into a power for power constant `kappa`.
    pub fn echo_scale(&self, kappa_m2: f64) -> f64 {
        self.gain * std::f64::consts::PI * kappa_m2 * self.beta()
    }

    /// The fog echo (unnoised) in front of a target at `r0` m, for power constant
    /// `kappa`.
    pub fn echo(&self, r0: f64, kappa_m2: f64) -> Echo {
        let (r, i) = self.table().lookup(r0);
        Echo {
            range: r as f32,
            power: self.echo_scale(kappa_m2) * i,
        }
    }

    fn echoes(&self) -> bool {
        self.beta() * self.gain > 0.0
    }
}

impl NoiseStage for Fog {
    fn kind(&self) -> &'static str {
        NAME
    }

    fn describe(&self) -> String {
        format!(
            "visibility {} m: alpha = {:.5} 1/m, beta = {:.3e} 1/(m sr); soft echo tau_H = {} ns, overlap {}..{} m, gain {}",
            self.visibility_m,
            self.alpha(),
            self.beta(),
            self.tau_h_ns,
            self.overlap_start_m,
            self.overlap_full_m,
            self.gain
        )
    }

    fn settings(&self) -> Vec<(&'static str, Value)> {
        vec![
            ("visibility_m", float(self.visibility_m)),
            ("beta_r", float(self.beta_r)),
            ("tau_h_ns", float(self.tau_h_ns)),
            ("overlap_start_m", float(self.overlap_start_m)),
            ("overlap_full_m", float(self.overlap_full_m)),
            ("gain", float(self.gain)),
            ("range_noise_m", float(self.range_noise_m)),
            ("empty_slots", Value::Boolean(self.empty_slots)),
        ]
    }

    fn proposes_echoes(&self) -> bool {
        self.echoes()
    }

    fn apply(&self, frame: &mut NoisyFrame, rng: &mut ChaCha8Rng) {
        let two_alpha = 2.0 * self.alpha();
        if !self.echoes() {
            if two_alpha > 0.0 {
                for ((power, &range), fate) in
                    frame.power.iter_mut().zip(&frame.range).zip(&frame.fate)
                {
                    if fate.is_alive() {
                        *power *= (-two_alpha * f64::from(range)).exp();
                    }
                }
            }
            return;
        }
        let kappa = frame
            .power_model
            .as_ref()
            .map_or(DEFAULT_KAPPA_M2, |m| m.constants().kappa_m2);
        let scale = self.echo_scale(kappa);
        let table = self.table();
        let n = self.range_noise_m;
        let slots = frame.slots();
        // One draw per recorded return (whatever its fate) and per empty slot, so the
        // stream stays aligned when fates change.
        let noisy = |rng: &mut ChaCha8Rng, range: f64, r0: f64| -> f64 {
            if n > 0.0 {
                let u: f64 = rng.random();
                // U(R0 - n, R0 + n), kept positive for targets nearer than n.
                let lo = (r0 - n).max(r0 * 0.5);
                range * r0 / (lo + u * (r0 + n - lo))
            } else {
                range
            }
        };
        // Most targets lie beyond the echo's peak, where the echo does not depend on R0:
        // decide its detectability once.
        let (far_r, far_i) = table.far();
        let far = Echo {
            range: far_r as f32,
            power: scale * far_i,
        };
        let far_ok = frame.detectable(far.range, far.power);
        let far_from = table.far_from;
        let vacant = if self.empty_slots {
            slots.len().saturating_sub(frame.clean_len)
        } else {
            0
        };
        frame.candidates.reserve(frame.clean_len + vacant);
        for i in 0..frame.clean_len {
            let r0 = f64::from(frame.range[i]);
            let fate = frame.fate[i];
            // Hard target: two-way extinction (alive returns only).
            if fate.is_alive() {
                frame.power[i] *= (-two_alpha * r0).exp();
            }
            let echo = if r0 >= far_from && n == 0.0 {
                if !far_ok {
                    continue;
                }
                far
            } else {
                let (r, integral) = table.lookup(r0);
                Echo {
                    range: noisy(rng, r, r0) as f32,
                    power: scale * integral,
                }
            };
            // Occlusion removes the beam; only detectable echoes can take part in the
            // slot's competition.
            if fate != Fate::Occluded && frame.detectable(echo.range, echo.power) {
                frame.propose_slot(slots.slot_of(i), echo);
            }
        }
        if self.empty_slots {
            for slot in 0..slots.len() as u32 {
                if !slots.is_vacant(slot) {
                    continue;
                }
                let echo = Echo {
                    range: noisy(rng, far_r, EMPTY_SLOT_RANGE_M) as f32,
                    power: far.power,
                };
                if frame.detectable(echo.range, echo.power) {
                    frame.propose_slot(slot, echo);
                }
            }
        }
    }
}

/// Reads the options of a `fog` entry.
pub fn build(opts: &Section<'_>) -> Result<Arc<dyn NoiseStage>> {
    // `inf` (no fog) is allowed: the identity, for sweeps down from clear weather.
    let visibility_m = match opts.value("visibility_m") {
        None => return Err(opts.missing("visibility_m")),
        Some(Value::Float(f)) if *f == f64::INFINITY => f64::INFINITY,
        Some(_) => number(opts, "visibility_m", 0.0, 1e-3, 1e9)?,
    };
    let beta_r = number(opts, "beta_r", 0.046, 0.0, 10.0)?;
    let tau_h_ns = number(opts, "tau_h_ns", 20.0, 0.1, 1000.0)?;
    let overlap_start_m = number(opts, "overlap_start_m", 0.9, 0.01, 100.0)?;
    let overlap_full_m = number(opts, "overlap_full_m", 1.0, 0.01, 100.0)?;
    if overlap_full_m < overlap_start_m {
        return Err(opts.error(
            "overlap_full_m",
            format!("{overlap_full_m} is below overlap_start_m ({overlap_start_m})"),
        ));
    }
    let gain = number(opts, "gain", 1.0, 0.0, 1e6)?;
    let range_noise_m = number(opts, "range_noise_m", 0.0, 0.0, 100.0)?;
    let empty_slots = super::bool_option(opts, "empty_slots", true)?;
    Ok(Arc::new(Fog::new(
        visibility_m,
        beta_r,
        tau_h_ns,
        overlap_start_m,
        overlap_full_m,
        gain,
        range_noise_m,
        empty_slots,
    )))
}

/// The registry entry of this stage.
pub const KIND: StageKind = StageKind {
    name: NAME,
    factor: "11 weather (fog)",
    model: "alpha = -ln(0.05)/V, hard target P exp(-2 alpha R); soft-target echo max_R gain pi kappa beta int s(t) exp(-2 alpha r) xi(r)/r^2 (c/2) dt, computed by quadrature, proposed to the firing slot (strongest: replaces the target when stronger)",
    source: "Hahner et al., ICCV 2021 (Fog Simulation on Real LiDAR Point Clouds); pdiagram-models.md 11 fog; overlap and gain uncalibrated for the HDL-32E",
    options: &[
        OptionSpec { name: "visibility_m", unit: "m", default: "required", doc: "meteorological optical range V (inf: no fog)" },
        OptionSpec { name: "beta_r", unit: "1/sr", default: "0.046", doc: "backscatter beta = beta_r / V (paper range 0.023-0.092)" },
        OptionSpec { name: "tau_h_ns", unit: "ns", default: "20", doc: "half-power pulse width tau_H" },
        OptionSpec { name: "overlap_start_m", unit: "m", default: "0.9", doc: "R1: transmitter/receiver overlap starts (xi = 0 below)" },
        OptionSpec { name: "overlap_full_m", unit: "m", default: "1.0", doc: "R2: overlap complete (xi = 1 above, linear between)" },
        OptionSpec { name: "gain", unit: "-", default: "1", doc: "factor on the fog echo power (calibration)" },
        OptionSpec { name: "range_noise_m", unit: "m", default: "0", doc: "n: fog echo range x R0 / U(R0 - n, R0 + n) (Hahner v1; 0 = none)" },
        OptionSpec { name: "empty_slots", unit: "-", default: "true", doc: "fog echoes also in firing slots without a return" },
    ],
    build,
};

#[cfg(test)]
mod tests {
    use super::*;

    fn soft(v: f64, r2: f64) -> SoftTarget {
        SoftTarget {
            alpha: extinction_per_m(v),
            tau_h_s: 20e-9,
            overlap_start_m: 0.9,
            overlap_full_m: r2,
        }
    }

    #[test]
    fn legendre_rule_integrates_polynomials_and_exp() {
        let x5 = gauss_legendre(&|x: f64| x.powi(5) + 3.0 * x * x, 0.0, 2.0);
        assert!((x5 - (64.0 / 6.0 + 8.0)).abs() < 1e-12, "{x5}");
        let e = gauss_legendre(&|x: f64| (-x).exp(), 0.0, 3.0);
        assert!((e - (1.0 - (-3.0f64).exp())).abs() < 1e-14);
    }

    #[test]
    fn echo_magnitudes_match_the_documented_ones() {
        // pdiagram-models.md: with kappa = 100 and tau_H = 20 ns the echo sits at
        // 1.5-1.7 m with P_s about 0.17 (V = 50 m), 0.06 (150 m), 0.017 (600 m).
        for (v, p) in [(50.0, 0.17), (150.0, 0.06), (600.0, 0.017)] {
            let s = soft(v, 1.0);
            let (r, i) = s.peak(f64::INFINITY);
            let ps = std::f64::consts::PI * 100.0 * 0.046 / v * i;
            let reported = r - s.window_m() / 2.0;
            assert!((ps / p - 1.0).abs() < 0.15, "V {v}: {ps}");
            assert!((1.4..1.8).contains(&reported), "V {v}: {reported}");
        }
        // R2 = 5 m divides P_s by about 4-5.
        let ratio = soft(150.0, 1.0).peak(f64::INFINITY).1 / soft(150.0, 5.0).peak(f64::INFINITY).1;
        assert!((3.5..5.5).contains(&ratio), "{ratio}");
    }

    #[test]
    fn table_interpolates_within_a_tenth_of_a_percent() {
        for s in [soft(100.0, 1.0), soft(600.0, 3.0)] {
            let t = EchoTable::new(&s);
            let (r_star, i_star) = s.peak(f64::INFINITY);
            for k in 0..400 {
                let r0 = 0.91 + 0.0173 * f64::from(k);
                let (re, exact) = s.peak(r0);
                let (rg, got) = t.lookup(r0);
                // Relative 1e-3 once the overlap is complete; just past R1 the echo is
                // tiny (and reported at a negative range), so only absolutely small.
                let tol = if r0 > s.overlap_full_m + 0.05 {
                    1e-3 * exact
                } else {
                    1e-3 * i_star
                };
                assert!((got - exact).abs() <= tol, "{r0}: {got} vs {exact}");
                assert!(
                    (rg - (re - s.window_m() / 2.0)).abs() < 0.01,
                    "{r0}: {rg} vs {re}"
                );
            }
            assert!(r_star > s.overlap_full_m);
            assert_eq!(t.lookup(0.5).1, 0.0);
            assert_eq!(t.lookup(80.0), t.far());
        }
    }
}
