//! Where the receiver's noisy waveform first crosses the threshold in fog: the crossing
//! table of the probabilistic detection rule.

use super::*;

/// Half-power pulse width (ns) of the default: Velodyne's pulses last "typically 4
/// nanoseconds" (Velodyne, "HDL-64E: concept", the sensors' shared principle of
/// operation); Hahner et al. took 20 ns.
pub const TAU_H_NS: f64 = 4.0;

/// Effective droplet radius (m) for the count of droplets in the overlap volume: the
/// rms radius of Shettle & Fenn's advection fog (modified gamma, alpha = 3, b = 0.3 /um:
/// <r^2> = (alpha + 1)(alpha + 2) / b^2, 14.9 um), also taken for `droplets = "hahner"`;
/// radiation fog (alpha = 6, b = 1.5 /um) 5.0 um.
pub(super) fn rms_droplet_radius_m(droplets: Droplets) -> f64 {
    match droplets {
        Droplets::Radiation => (7.0f64 * 8.0).sqrt() / 1.5 * 1e-6,
        _ => (4.0f64 * 5.0).sqrt() / 0.3 * 1e-6,
    }
}

/// What a [`Crossing`] depends on besides the stage: the echo's scale over the
/// threshold, the minimum range and the detection rule's parameters (bits).
pub(super) type CrossingKey = [u64; 4];

/// The fog echo as the receiver reports it: where the noisy waveform first crosses the
/// threshold, tabulated over the target range R0.
///
/// The soft-target waveform P_s(R) = pi kappa beta I(R; R0) is sampled in cells of one
/// half-power pulse width (c tau_H / 2 in range: the receiver's noise, filtered to the
/// pulse, decorrelates over about that time). In cell j the signal x_j = P_s / T
/// fluctuates with the receiver's noise (`noise::detection`: sigma_rx(x)^2 =
/// 1/k^2 + g x) and with the number of droplets in the cell's overlap volume, which is
/// Poisson: the echo is a sum over droplets, so its relative variance is 1 / N_eff with
/// N_eff = n_d (int w)^2 / int w^2 / A_b (w(r) = s xi exp(-2 alpha r) / r^2 the pulse-
/// and overlap-weighted contribution at r, A_b the beam's cross-section, n_d = alpha /
/// (2 pi <r_d^2>) droplets a cubic metre). The cell crosses with probability
/// p_j = Q((1 - x_j) / sqrt(sigma_rx^2 + x_j^2 / N_eff)) less the noise-only floor Q(k);
/// the first crossing is in cell j with probability p_j prod_{i<j} (1 - p_i). One
/// uniform u per beam picks it by inversion; its position within the cell and the
/// peak's amplitude (the tail quantile of the cell's noise) follow from the same draw.
/// The range reported is the cell's apparent range less c tau_H / 2 (where a hard
/// target's pulse would put its range); cells reported nearer than the minimum range
/// are blanked (the receiver ignores crossings there).
#[derive(Debug)]
pub struct Crossing {
    /// Reported range of cell 0's centre (m) and the cell length (m).
    first: f64,
    cell: f64,
    /// R0 of row 0, the grid step of R0 and the R0 from which the untruncated row (the
    /// last) applies.
    start: f64,
    step: f64,
    far_from: f64,
    /// Per row: the cumulative first-crossing probability of cells 0..=j.
    cum: Vec<Vec<f64>>,
    /// Per row and cell: (signal x, its standard deviation, crossing probability).
    cells: Vec<Vec<(f64, f64, f64)>>,
}

impl Crossing {
    /// The table of `soft` for echo scale `x_scale` (x = x_scale I), detection `rule`,
    /// droplet density `n_d` (1/m^3), beam radius at the sensor and growth `beam`
    /// (m, m/m) and minimum range `min_range` (m).
    pub fn new(
        soft: &SoftTarget,
        x_scale: f64,
        rule: &DetectionRule,
        n_d: f64,
        beam: (f64, f64),
        min_range: f64,
    ) -> Crossing {
        let l = soft.window_m();
        let cell = l / 2.0;
        let r1 = soft.overlap.start_m();
        let app0 = r1 + cell / 2.0;
        // The untruncated waveform, cell by cell, to where no later cell could cross
        // with probability above 1e-12 (x tiny and falling, past the peak).
        let faint = {
            let mut x = 1.0;
            while rule.p_echo(x) > 1e-12 && x > 1e-9 {
                x *= 0.5;
            }
            x
        };
        let mut apps = Vec::new();
        let mut peak: f64 = 0.0;
        for j in 0..10_000 {
            let app = app0 + cell * j as f64;
            let x = x_scale * soft.integral(app, f64::INFINITY);
            peak = peak.max(x);
            apps.push(app);
            if (x < faint && x < peak * 0.5) || app > 2000.0 {
                break;
            }
        }
        let far_from = *apps.last().unwrap_or(&r1) + l;
        let step = (cell / 4.0).max(0.02);
        let rows = ((far_from - r1) / step).ceil().max(0.0) as usize + 1;
        let (a0, grow) = beam;
        // Pulse- and overlap-weighted integrals over the cell's window [app - L, min(app, R0)]:
        // (int w, int w^2 / A_b) for N_eff.
        let moments = |app: f64, r0: f64| -> (f64, f64) {
            let lo = (app - l).max(r1);
            let hi = app.min(r0);
            if hi <= lo {
                return (0.0, 0.0);
            }
            const K: usize = 64;
            let h = (hi - lo) / K as f64;
            let (mut m1, mut m2) = (0.0, 0.0);
            for k in 0..K {
                let r = lo + h * (k as f64 + 0.5);
                let sp = (std::f64::consts::PI * (app - r) / l).sin();
                let w = sp * sp * (-2.0 * soft.alpha * r).exp() * soft.overlap(r) / (r * r);
                let area = std::f64::consts::PI * (a0 + grow * r).powi(2);
                m1 += w * h;
                m2 += w * w / area.max(1e-12) * h;
            }
            (m1, m2)
        };
        let mut cum = Vec::with_capacity(rows + 1);
        let mut cells = Vec::with_capacity(rows + 1);
        let k = rule.threshold_snr;
        let floor = normal_tail(k);
        for row in 0..=rows {
            let r0 = if row == rows {
                f64::INFINITY
            } else {
                r1 + step * row as f64
            };
            let mut c = Vec::with_capacity(apps.len());
            let mut f = Vec::with_capacity(apps.len());
            let mut survive = 1.0;
            let mut acc = 0.0;
            for &app in &apps {
                let x = x_scale * soft.integral(app, r0);
                let blanked = app - cell < min_range || x <= 0.0;
                let (m1, m2) = if blanked {
                    (0.0, 0.0)
                } else {
                    moments(app, r0)
                };
                let rel_var = if m1 > 0.0 && n_d > 0.0 {
                    m2 / (n_d * m1 * m1)
                } else {
                    0.0
                };
                let sigma = (rule.sigma(x).powi(2) + x * x * rel_var).sqrt();
                let p = if blanked {
                    0.0
                } else {
                    ((normal_tail((1.0 - x) / sigma) - floor) / (1.0 - floor)).clamp(0.0, 1.0)
                };
                acc += survive * p;
                survive *= 1.0 - p;
                c.push((x, sigma, p));
                f.push(acc);
            }
            cells.push(c);
            cum.push(f);
        }
        Crossing {
            first: app0 - cell,
            cell,
            start: r1,
            step,
            far_from,
            cum,
            cells,
        }
    }

    /// Probability that a beam whose target lies at `r0` (infinite: none) reports a fog
    /// echo.
    pub fn probability(&self, r0: f64) -> f64 {
        self.cum[self.row(r0)].last().copied().unwrap_or(0.0)
    }

    fn row(&self, r0: f64) -> usize {
        let last = self.cum.len() - 1;
        // Also a NaN range: the untruncated row.
        if r0.is_nan() || r0 >= self.far_from {
            return last;
        }
        let u = (r0 - self.start) / self.step;
        if u.is_nan() || u < 0.0 {
            return 0;
        }
        // The grid point at or below R0 (a nearer target cuts at least as much fog).
        (u as usize).min(last - 1)
    }

    /// The fog echo reported in a beam whose target lies at `r0` for its uniform `u`
    /// (the power is the peak's amplitude, at or above the threshold `T` in units of
    /// which x is: multiply by the threshold, [`Crossing::draw`] does).
    #[inline]
    fn draw_x(&self, r0: f64, u: f64) -> Option<(f64, f64)> {
        let row = self.row(r0);
        let cum = &self.cum[row];
        let total = *cum.last()?;
        if u.is_nan() || u >= total {
            return None;
        }
        let j = cum.partition_point(|&f| f <= u).min(cum.len() - 1);
        let below = if j == 0 { 0.0 } else { cum[j - 1] };
        // u within cell j's share, as a uniform w in [0, 1).
        let w = ((u - below) / (cum[j] - below)).clamp(0.0, 1.0 - f64::EPSILON);
        let (x, sigma, p) = self.cells[row][j];
        // The peak: the tail quantile w p of the cell's noise (at or above the threshold).
        let z = normal_tail_inverse((w * p).max(f64::MIN_POSITIVE));
        let amplitude = (x + sigma * z).max(1.0);
        // The crossing's place in the cell: the finer digits of w.
        let within = (w * 4096.0).fract();
        let range = self.first + self.cell * (j as f64 + within);
        Some((range, amplitude))
    }

    /// [`Crossing::draw_x`] as an echo, for threshold `t`.
    #[inline]
    pub fn draw_echo(&self, r0: f64, u: f64, t: f64) -> Option<Echo> {
        self.draw_x(r0, u).map(|(range, a)| Echo {
            range: range as f32,
            power: a * t,
        })
    }
}
