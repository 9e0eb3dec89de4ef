//! Multiple returns (p-diagram 07): mixed pixels at depth edges and second echoes.
//!
//! The beam footprint grows with range (diameter about R theta). At a depth edge it
//! covers the foreground and the background: echoes closer than c tau_p / 2 merge into
//! one whose timing lies between them (a mixed pixel: a point in empty space, weaker),
//! echoes farther apart stay separate and the return mode picks which is reported.
//!
//! Model (pdiagram-models.md, 07, after Hebert and Krotkov 1992 and Tuley et al. 2005):
//! a depth edge is a range jump of more than `edge_m` between the returns of one laser
//! in consecutive firings (azimuth neighbours at most 1 degree apart; jumps compared to
//! a tenth of a millimetre, so that a capture's jump of exactly `edge_m` is no edge
//! however its ranges round in `f32`). A return next to
//! an edge (the neighbour across the larger jump, if it has two) is an edge return; a
//! fraction `probability` (p_mix) of them is mixed. With g the fraction of its footprint
//! on the neighbour's surface, its own echo has power P1 = (1 - g) P_own and the
//! neighbour's P2 = g P_other (`P = kappa rho / R^2` is the power the frame holds for
//! each surface, so earlier stages' attenuation is included).
//! - |R2 - R1| < c tau_p / 2: one echo at R_mix = (P1 R1 + P2 R2) / (P1 + P2) with power
//!   P1 + P2 (the power-weighted centroid is the doc's engineering approximation). The
//!   return is moved there directly and marked `Replaced` (cause: this stage): it is a
//!   false point, although no other echo competes for it.
//! - otherwise two echoes: the return keeps its range with power P1 (its byte follows
//!   by the chain's intensity rule, `noise`, "Intensity"), and an echo at R2
//!   with power P2 is [proposed](NoisyFrame::propose_slot) to its firing slot, so the
//!   return-mode rule chooses: strongest mode reports the stronger, last mode the
//!   farther, dual mode both (the farther as the last return, the other as the strongest:
//!   second echoes in dual captures).
//!
//! g: `fraction = "uniform"` (default, the doc's first choice) draws g uniform in [0, 1];
//! `fraction = "footprint"` places the edge uniformly between the two beam centres and
//! takes g as the share of a uniform disc of angular diameter theta (`divergence_mrad`)
//! beyond it (the doc's "angular distance to the edge over theta"): with theta = 3 mrad
//! and 0.166 degree (2.9 mrad) between firings at 10 Hz, about half of the edge returns
//! reach across, mostly by a small share. theta enters only the footprint rule.
//!
//! Draws: one 64-bit word per firing slot (32 per firing, in firing order, whether or not
//! the slot holds an edge return), so the draws of a slot do not depend on the other
//! slots or on `probability` (common random numbers). Its top 53 bits decide the
//! selection (u < p_mix), a SplitMix64 hash of it gives g.
//! In dual captures the edge test uses each slot's last return; an entry holding the same
//! echo gets the same change.

use crate::config::reader::Section;
use crate::error::Result;
use crate::noise::registry::OptionSpec;
use crate::noise::sensor::{float, number, scale_byte, C_M_PER_S};
use crate::noise::world::{splitmix, unit};
use crate::noise::{Echo, Fate, NoiseStage, NoisyFrame, StageKind};
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use std::sync::Arc;
use toml::Value;

/// The `type` name of this stage.
pub const NAME: &str = "multipath";

/// Largest azimuth step (degrees) between two firings still taken as neighbours: beyond
/// it (a gap in the capture, the frame's seam) there is no shared footprint.
pub const MAX_STEP_DEG: f64 = 1.0;

/// How the footprint share g on the neighbouring surface is drawn.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Fraction {
    /// g uniform in [0, 1].
    Uniform,
    /// g from a uniform disc of diameter theta cut by an edge placed uniformly between
    /// the two beam centres.
    Footprint,
}

/// The multipath stage.
#[derive(Clone, Debug)]
pub struct Multipath {
    /// Fraction p_mix of edge returns that are mixed.
    pub probability: f64,
    /// Beam divergence theta (full angle), mrad.
    pub divergence_mrad: f64,
    /// Pulse width tau_p, ns (echoes closer than c tau_p / 2 merge).
    pub pulse_ns: f64,
    /// Smallest range jump (m) between neighbouring firings that makes a depth edge.
    pub edge_m: f64,
    /// How g is drawn.
    pub fraction: Fraction,
}

/// Distance (m) under which two echoes merge: c tau_p / 2.
pub fn merge_distance_m(pulse_ns: f64) -> f64 {
    C_M_PER_S * pulse_ns * 1e-9 / 2.0
}

/// Share of a uniform disc of radius 1 beyond a chord at distance `d` from its centre
/// (`d` >= 1: none; `d` = 0: half): (acos d - d sqrt(1 - d^2)) / pi.
pub fn disc_share_beyond(d: f64) -> f64 {
    if d >= 1.0 {
        0.0
    } else if d <= -1.0 {
        1.0
    } else {
        (d.acos() - d * (1.0 - d * d).sqrt()) / std::f64::consts::PI
    }
}

/// What a mixed edge return becomes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Mix {
    /// One merged echo (the return moves there).
    Merged {
        /// Range of the merged echo, m.
        range: f32,
        /// Its power.
        power: f64,
    },
    /// Two separate echoes: the return's own, weaker, and the neighbour's surface.
    Two {
        /// Power left to the return's own echo.
        own_power: f64,
        /// The echo of the neighbouring surface along this beam.
        echo: Echo,
    },
}

/// The echoes of a beam whose footprint puts a share `g` on a surface at `r_other` (of
/// full-footprint power `p_other`) and the rest on its own surface at `r_own`.
pub fn mix(r_own: f32, p_own: f64, r_other: f32, p_other: f64, g: f64, merge_m: f64) -> Mix {
    let p1 = (1.0 - g) * p_own;
    let p2 = g * p_other;
    let (r1, r2) = (f64::from(r_own), f64::from(r_other));
    if (r2 - r1).abs() < merge_m {
        let sum = p1 + p2;
        let range = if sum > 0.0 {
            (p1 * r1 + p2 * r2) / sum
        } else {
            r1 + g * (r2 - r1)
        };
        Mix::Merged {
            range: range as f32,
            power: sum,
        }
    } else {
        Mix::Two {
            own_power: p1,
            echo: Echo {
                range: r_other,
                power: p2,
            },
        }
    }
}

/// Step (metres) to which range jumps are rounded before they are compared with `edge_m`
/// and with each other. A capture's ranges are whole multiples of its unit (2 mm on the
/// HDL-32E), so a jump of exactly `edge_m` is common; in `f32` it came out a hair above
/// or below by how each range happened to round, and the same scene read from a capture
/// and from the points it was converted to decided such an edge either way. A tenth of a
/// millimetre is finer than any sensor's unit and far coarser than the rounding.
const JUMP_STEP_M: f64 = 1e-4;

/// `jump_m` in steps of [`JUMP_STEP_M`], rounded to the nearest.
#[inline]
fn jump_steps(jump_m: f64) -> i64 {
    (jump_m / JUMP_STEP_M).round() as i64
}

/// Signed azimuth difference b - a in degrees, wrapped to (-180, 180].
#[inline]
pub(crate) fn az_diff(a: f32, b: f32) -> f64 {
    let d = f64::from(b) - f64::from(a);
    if d > 180.0 {
        d - 360.0
    } else if d <= -180.0 {
        d + 360.0
    } else {
        d
    }
}

const NONE: u32 = u32::MAX;

impl NoiseStage for Multipath {
    fn kind(&self) -> &'static str {
        NAME
    }
    fn describe(&self) -> String {
        let rule = match self.fraction {
            Fraction::Uniform => "footprint share uniform".to_string(),
            Fraction::Footprint => format!("footprint of {} mrad", self.divergence_mrad),
        };
        format!(
            "{} of edge returns (jump > {} m) mixed, {rule}; echoes within {:.2} m merge",
            self.probability,
            self.edge_m,
            merge_distance_m(self.pulse_ns)
        )
    }
    fn settings(&self) -> Vec<(&'static str, Value)> {
        let fraction = match self.fraction {
            Fraction::Uniform => "uniform",
            Fraction::Footprint => "footprint",
        };
        vec![
            ("probability", float(self.probability)),
            ("divergence_mrad", float(self.divergence_mrad)),
            ("pulse_ns", float(self.pulse_ns)),
            ("edge_m", float(self.edge_m)),
            ("fraction", Value::String(fraction.into())),
        ]
    }
    fn proposes_echoes(&self) -> bool {
        self.probability > 0.0
    }
    fn apply(&self, frame: &mut NoisyFrame, rng: &mut ChaCha8Rng) {
        if self.probability <= 0.0 || frame.clean_len == 0 {
            return;
        }
        let slots = frame.slots();
        let n_fir = slots.firings.len();
        // The slot's representative return (the last one in dual mode).
        let mut rep = vec![NONE; slots.len()];
        for (s, r) in rep.iter_mut().enumerate() {
            if let Some(i) = slots.occupants(s as u32).next() {
                *r = i as u32;
            }
        }
        let merge_m = merge_distance_m(self.pulse_ns);
        let edge = jump_steps(self.edge_m);
        let half_theta = self.divergence_mrad * 1e-3 / 2.0;
        // Decide every change from the state before this stage, then apply.
        let mut actions: Vec<(u32, usize, Mix)> = Vec::new();
        let lasers = slots.lasers();
        let mut words = vec![0u64; lasers];
        for f in 0..n_fir {
            rng.fill(&mut words[..]);
            for (l, &w) in words.iter().enumerate() {
                let s = f * lasers + l;
                let i = rep[s];
                if i == NONE || unit(w) >= self.probability {
                    continue;
                }
                let i = i as usize;
                if !frame.fate[i].is_alive() {
                    continue;
                }
                let (ri, ai) = (frame.range[i], frame.clean[i].azimuth);
                let mut best: Option<(usize, i64, f64)> = None;
                for nf in [f.wrapping_sub(1), f + 1] {
                    if nf >= n_fir {
                        continue;
                    }
                    let j = rep[nf * lasers + l];
                    if j == NONE || !frame.fate[j as usize].is_alive() {
                        continue;
                    }
                    let j = j as usize;
                    let step = az_diff(ai, frame.clean[j].azimuth).abs();
                    let jump = jump_steps((f64::from(frame.range[j]) - f64::from(ri)).abs());
                    if step > MAX_STEP_DEG || jump <= edge || best.is_some_and(|b| b.1 >= jump) {
                        continue;
                    }
                    best = Some((j, jump, step));
                }
                let Some((j, _, step)) = best else {
                    continue;
                };
                let v = unit(splitmix(w));
                let g = match self.fraction {
                    Fraction::Uniform => v,
                    Fraction::Footprint => {
                        // Angular distance between the beam centres, across the beam.
                        let sep = step.to_radians()
                            * f64::from(frame.clean[i].elevation).to_radians().cos();
                        if half_theta > 0.0 {
                            disc_share_beyond(v * sep / half_theta)
                        } else {
                            0.0
                        }
                    }
                };
                if g <= 0.0 {
                    continue;
                }
                let m = mix(
                    ri,
                    frame.power[i],
                    frame.range[j],
                    frame.power[j],
                    g,
                    merge_m,
                );
                actions.push((s as u32, i, m));
            }
        }
        if actions.is_empty() {
            return;
        }
        let model = frame.power_model.clone();
        let clean = &frame.clean;
        frame
            .moved
            .intensity
            .get_or_insert_with(|| clean.iter().map(|r| r.intensity).collect());
        for (s, i, m) in actions {
            let (r0, p0) = (frame.range[i], frame.power[i]);
            // The entries of the slot that hold this echo (two in a dual slot whose
            // entries report the same echo).
            let mut targets = [usize::MAX; 2];
            for (k, t) in slots.occupants(s).take(2).enumerate() {
                if t == i || (frame.range[t], frame.power[t]) == (r0, p0) {
                    targets[k] = t;
                }
            }
            let targets = targets.into_iter().filter(|&t| t != usize::MAX);
            match m {
                Mix::Merged { range, power } => {
                    for t in targets {
                        frame.range[t] = range;
                        frame.power[t] = power;
                        let inten = frame.moved.intensity.as_mut().expect("allocated");
                        inten[t] = match &model {
                            Some(model) => model.echo_intensity(power, range),
                            None if p0 > 0.0 => scale_byte(inten[t], power / p0),
                            None => inten[t],
                        };
                        frame.set_fate(t, Fate::Replaced);
                    }
                }
                Mix::Two { own_power, echo } => {
                    for t in targets {
                        // The return keeps its own echo, weaker: its byte follows its
                        // power by the chain's intensity rule.
                        frame.power[t] = own_power;
                    }
                    frame.propose_slot(s, echo);
                }
            }
        }
    }
}

/// Reads the options of a `multipath` entry.
pub fn build(opts: &Section<'_>) -> Result<Arc<dyn NoiseStage>> {
    let fraction = match opts.choice("fraction", &["uniform", "footprint"])? {
        Some("footprint") => Fraction::Footprint,
        _ => Fraction::Uniform,
    };
    let pulse_ns = number(opts, "pulse_ns", 10.0, 0.0, 1000.0)?;
    Ok(Arc::new(Multipath {
        probability: number(opts, "probability", 0.5, 0.0, 1.0)?,
        divergence_mrad: number(opts, "divergence_mrad", 3.0, 0.0, 100.0)?,
        pulse_ns,
        edge_m: number(opts, "edge_m", 0.3, 0.0, 1000.0)?,
        fraction,
    }))
}

/// The registry entry of this stage.
pub const KIND: StageKind = StageKind {
    name: NAME,
    factor: "07 multiple returns (mixed pixels, dual returns)",
    model: "at depth edges (range jump > edge_m between neighbouring firings of a laser) a fraction p_mix of returns mix g of the neighbour's surface: echoes within c tau_p/2 merge at the power-weighted range (P1 + P2), farther ones compete as a second echo with the return-mode rule",
    source: "Hebert and Krotkov, IVC 1992; Tuley, Vandapel and Hebert, ICRA 2005; theta 3 mrad from LISA, tau_p 10 ns from LiDAR_snow_sim (pdiagram-models.md 07); centroid rule: engineering approximation",
    options: &[
        OptionSpec { name: "probability", unit: "-", default: "0.5", doc: "fraction p_mix of edge returns that are mixed, in [0, 1]" },
        OptionSpec { name: "divergence_mrad", unit: "mrad", default: "3", doc: "beam divergence theta (full angle; used by fraction = \"footprint\")" },
        OptionSpec { name: "pulse_ns", unit: "ns", default: "10", doc: "pulse width tau_p: echoes within c tau_p / 2 merge" },
        OptionSpec { name: "edge_m", unit: "m", default: "0.3", doc: "range jump between neighbouring firings that makes a depth edge" },
        OptionSpec { name: "fraction", unit: "-", default: "\"uniform\"", doc: "footprint share g: \"uniform\" in [0, 1] or \"footprint\" (disc of theta cut by the edge)" },
    ],
    build,
};

#[cfg(test)]
mod tests {
    use super::*;
    use super::{splitmix, unit};

    #[test]
    fn merge_distance_of_10_ns_is_1_5_m() {
        assert!((merge_distance_m(10.0) - 1.498_962_29).abs() < 1e-8);
    }

    #[test]
    fn disc_share_is_half_at_the_centre_and_none_outside() {
        assert!((disc_share_beyond(0.0) - 0.5).abs() < 1e-15);
        assert_eq!(disc_share_beyond(1.0), 0.0);
        assert_eq!(disc_share_beyond(3.0), 0.0);
        // Symmetry: the two sides of a chord add up to the disc.
        for d in [0.1, 0.3, 0.77] {
            assert!((disc_share_beyond(d) + disc_share_beyond(-d) - 1.0).abs() < 1e-12);
        }
        // Monotone decreasing.
        let mut last = 1.0;
        for k in 0..=100 {
            let s = disc_share_beyond(f64::from(k) / 100.0);
            assert!(s <= last);
            last = s;
        }
        // Numerical area of the segment x > 0.5 of the unit disc.
        let n = 200_000;
        let mut area = 0.0;
        for k in 0..n {
            let x = 0.5 + 0.5 * (f64::from(k) + 0.5) / f64::from(n);
            area += 2.0 * (1.0 - x * x).sqrt() * 0.5 / f64::from(n);
        }
        assert!((disc_share_beyond(0.5) - area / std::f64::consts::PI).abs() < 1e-6);
    }

    #[test]
    fn close_echoes_merge_at_the_power_weighted_range() {
        let m = mix(10.0, 2.0, 11.0, 1.0, 0.5, 1.5);
        // P1 = 1, P2 = 0.5: R = (10 + 5.5) / 1.5.
        match m {
            Mix::Merged { range, power } => {
                assert!((f64::from(range) - 15.5 / 1.5).abs() < 1e-5);
                assert!((power - 1.5).abs() < 1e-15);
            }
            other => panic!("{other:?}"),
        }
        let far = mix(10.0, 2.0, 12.0, 1.0, 0.25, 1.5);
        assert_eq!(
            far,
            Mix::Two {
                own_power: 1.5,
                echo: Echo {
                    range: 12.0,
                    power: 0.25
                }
            }
        );
    }

    #[test]
    fn splitmix_words_look_uniform() {
        let n = 100_000u64;
        let mean = (0..n).map(|k| unit(splitmix(k))).sum::<f64>() / n as f64;
        // SD of the mean of n uniforms: 1/sqrt(12 n) = 0.0009.
        assert!((mean - 0.5).abs() < 0.004, "{mean}");
    }
}
