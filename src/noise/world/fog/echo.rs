//! The fog's soft-target echo: its power over range by quadrature, tabulated a visibility.

use super::*;

/// The optical parameters of the soft-target integral.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SoftTarget {
    /// Extinction alpha in 1/m.
    pub alpha: f64,
    /// Half-power pulse width tau_H in seconds.
    pub tau_h_s: f64,
    /// The transmitter/receiver overlap.
    pub overlap: Overlap,
}

/// Longest stretch (m) of the biaxial overlap integrated by one 16-point rule: its
/// xi has a (r - R1)^(3/2) onset and a kink at R2, so the pieces are kept short.
pub(super) const BIAXIAL_PIECE_M: f64 = 0.75;

impl SoftTarget {
    /// Pulse length in range, c tau_H (metres): the echo window is [R - c tau_H, R].
    pub fn window_m(&self) -> f64 {
        C_M_PER_S * self.tau_h_s
    }

    /// The overlap function xi(r).
    pub fn overlap(&self, r: f64) -> f64 {
        self.overlap.at(r)
    }

    /// I(R; R0) in 1/m: the soft-target integral at apparent range `r_app` for a hard
    /// target at `r0` (`f64::INFINITY` for none), by Gauss-Legendre quadrature on the
    /// pieces where the integrand is smooth.
    pub fn integral(&self, r_app: f64, r0: f64) -> f64 {
        let l = self.window_m();
        let lo = (r_app - l).max(self.overlap.start_m());
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
        let mid = self.overlap.full_m().clamp(lo, hi);
        match self.overlap {
            Overlap::Linear { .. } => gauss_legendre(&f, lo, mid) + gauss_legendre(&f, mid, hi),
            Overlap::Biaxial(_) => pieces(&f, lo, mid) + pieces(&f, mid, hi),
        }
    }

    /// The maximum of I(R; R0) over R: (argmax R, max).
    pub fn peak(&self, r0: f64) -> (f64, f64) {
        let l = self.window_m();
        let lo = self.overlap.start_m();
        // The untruncated integrand xi exp(-2 alpha r) / r^2 rises at most up to R2 and
        // falls after it, so the convolution with the pulse peaks before R2 + c tau_H
        // (R2 capped 150 m past R1 for a field that never contains the beam: there the
        // 1/r^2 has long won over xi); a target at R0 cuts the window, and then the
        // peak lies before R0 + c tau_H.
        let full = self.overlap.full_m().min(lo + 150.0);
        let hi = if r0.is_finite() {
            r0.min(full + l) + l
        } else {
            full + l
        };
        maximise(&|r| self.integral(r, r0), lo, hi)
    }
}

/// Gauss-Legendre on [a, b] cut into pieces of at most [`BIAXIAL_PIECE_M`].
pub(super) fn pieces(f: &dyn Fn(f64) -> f64, a: f64, b: f64) -> f64 {
    if b <= a {
        return 0.0;
    }
    let n = ((b - a) / BIAXIAL_PIECE_M).ceil().max(1.0) as usize;
    let h = (b - a) / n as f64;
    (0..n)
        .map(|k| gauss_legendre(f, a + h * k as f64, a + h * (k + 1) as f64))
        .sum()
}

/// Gauss-Legendre nodes and weights on [-1, 1] (16 points): exact for polynomials up
/// to degree 31; the pieces integrated here are analytic with the nearest singularity
/// (r = 0) far from the interval, so the error is far below 1e-9 relative.
pub(super) fn gl16() -> &'static [(f64, f64)] {
    static NODES: OnceLock<Vec<(f64, f64)>> = OnceLock::new();
    NODES.get_or_init(|| legendre_nodes(16))
}

/// Nodes and weights of the n-point Gauss-Legendre rule (Newton on P_n).
pub(super) fn legendre_nodes(n: usize) -> Vec<(f64, f64)> {
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

pub(super) fn gauss_legendre(f: &dyn Fn(f64) -> f64, a: f64, b: f64) -> f64 {
    if b <= a {
        return 0.0;
    }
    let (c, h) = ((a + b) / 2.0, (b - a) / 2.0);
    h * gl16().iter().map(|&(x, w)| w * f(c + h * x)).sum::<f64>()
}

/// Maximum of `f` on [lo, hi]: a 48-point scan, then golden-section search around the
/// best point (the functions maximised here are unimodal or nearly so).
pub(super) fn maximise(f: &dyn Fn(f64) -> f64, lo: f64, hi: f64) -> (f64, f64) {
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
    pub(super) start: f64,
    /// Grid step in metres.
    pub(super) step: f64,
    /// (reported range, max I) at R0 = start + k * step.
    pub(super) grid: Vec<(f64, f64)>,
    /// From this R0 on, the untruncated echo `far` applies.
    pub(super) far_from: f64,
    /// The echo of a target beyond the peak (or of no target).
    pub(super) far: (f64, f64),
}

impl EchoTable {
    /// Tabulates the echo of `soft`.
    pub fn new(soft: &SoftTarget) -> EchoTable {
        let shift = soft.window_m() / 2.0;
        let (peak_r, peak_i) = soft.peak(f64::INFINITY);
        let start = soft.overlap.start_m();
        let step = match soft.overlap {
            Overlap::Linear { .. } => TABLE_STEP_M,
            Overlap::Biaxial(_) => BIAXIAL_TABLE_STEP_M,
        };
        let n = ((peak_r - start) / step).ceil().max(0.0) as usize + 1;
        let grid = (0..=n)
            .map(|k| {
                let r0 = start + step * k as f64;
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
            step,
            far_from: start + step * n as f64,
            far: (peak_r - shift, peak_i),
        }
    }

    /// (reported range in m, max I in 1/m) of the fog echo in front of a target at `r0`.
    #[inline]
    pub fn lookup(&self, r0: f64) -> (f64, f64) {
        if r0 >= self.far_from {
            return self.far;
        }
        let u = (r0 - self.start) / self.step;
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
