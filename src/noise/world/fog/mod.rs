//! Fog (p-diagram 11): extinction of the hard-target power and the soft-target
//! backscatter echo of the fog itself, after Hahner, Sakaridis, Dai and Van Gool, "Fog
//! Simulation on Real LiDAR Point Clouds for 3D Object Detection in Adverse Weather",
//! ICCV 2021 (pdiagram-models.md, "11 Weather: fog"), with the transmitter/receiver
//! overlap of the HDL-32E derived from its optics (issue 29).
//!
//! Model:
//! - extinction alpha = -ln(0.05) / V from the meteorological optical range V (5 %
//!   contrast); backscatter beta = beta_r / V (`droplets = "hahner"`, the paper's
//!   beta_r = 0.046 /sr: lidar ratio alpha / beta = 65 sr) or beta = alpha (beta/alpha)_Mie
//!   for Shettle & Fenn advection or radiation fog droplets ([`super::fog_droplets`]:
//!   Bohren-Huffman Mie series for water at 905 nm; lidar ratios of 18-20 sr, so the
//!   Mie fog echoes 3.3-3.5 x more strongly than the paper's beta_r);
//! - hard target: P_h = P exp(-2 alpha R0) on every alive return at its range R0;
//! - soft target (the fog): with the pulse s(t) = sin^2(pi t / (2 tau_H)) on
//!   [0, 2 tau_H] and the transmitter/receiver overlap xi(r), the echo at apparent range
//!   R is P_s(R) = pi * kappa * beta * I(R; R0), with
//!   I(R; R0) = (c/2) int_0^{2 tau_H} s(t) exp(-2 alpha r) xi(r) / r^2 dt, r = R - c t/2,
//!   only r <= R0 (no fog behind the target). Written over r (dt = 2 dr / c) this is
//!   int_{R - c tau_H}^{min(R, R0)} sin^2(pi (R - r) / (c tau_H)) exp(-2 alpha r) xi(r) / r^2 dr.
//! - One power normalisation: the lidar equation gives a Lambertian hard target
//!   P = P0 eta A_r (rho / pi) / R^2 and a volume of backscatter beta
//!   P = P0 eta A_r beta (c/2) int s xi T^2 / r^2 dt (Measures, "Laser Remote Sensing",
//!   eq. 7.2-7.4 in its notation); the tool's hard targets use P = kappa rho / R^2, so
//!   P0 eta A_r = pi kappa and the fog echo is pi kappa beta I: the same constant, with
//!   no free factor (the former `gain` is gone). Hahner's released code instead scales
//!   its tabulated integral by intensity * R0^2 * beta / beta_0 with an empirical beta_0.
//!   The recorded hard targets already carry the sensor's own overlap (they are
//!   measured); xi = 1 at the 100 m reference range of kappa, so kappa holds as is.
//! - the fog echo as the receiver reports it ([`Crossing`], issue 50): the waveform
//!   P_s(R) is sampled in noise cells of one half-power pulse width; in each the signal
//!   fluctuates with the receiver's noise (`noise::detection`) and with the Poisson
//!   number of droplets in the cell's overlap volume; the reported echo is the first
//!   cell whose noisy peak crosses the threshold (a probability per beam, drawn), at
//!   that cell's apparent range less c tau_H / 2 (where a hard target's pulse would put
//!   its range), with the peak's drawn amplitude as its power. It is *proposed* to the
//!   beam's firing slot ([`NoisyFrame::propose`]) and competes there once, after the
//!   chain, with the target and other stages' echoes by the sensor's return logic
//!   (strongest mode: the fog point replaces the target when its peak is higher). Slots
//!   with and without a return follow the same rule (`empty_slots`), the fog in front of
//!   the sensor echoing whatever lies behind it. With `[detection] model = "threshold"`
//!   the stage works as before issue 50: the noiseless maximum of P_s over R, reported
//!   c tau_H / 2 earlier, proposed to every slot where it is detectable (every free
//!   slot or none). With the calibrated optics that maximum never reaches the threshold
//!   (0.58 p_th at most, near V = 27 m): fog then only attenuates.
//!
//! Overlap (`overlap = "biaxial"`, the default): the HDL-32E has its emitter lens and
//! its receiver lens side by side behind one window (32 laser/detector pairs share them),
//! a biaxial lidar with parallel axes. For circular apertures and top-hat beams xi(r) is
//! the area of the intersection of the beam disk (radius a_t + r tan(theta_t / 2)) and
//! the receiver's field disk (radius a_r + r tan(theta_r / 2)), centres d apart, over the
//! beam's area (Measures ch. 7; Stelmaszczyk et al., Appl. Opt. 44(7), 2005, the
//! geometric form factor of a top-hat beam); it is 0 up to
//! R1 = (d - a_t - a_r) / (tan(theta_t / 2) + tan(theta_r / 2)) and 1 from
//! R2 = (d + a_t - a_r) / (tan(theta_r / 2) - tan(theta_t / 2)) (Hahner's eqs. 11-12).
//! HDL-32E figures:
//! - beam divergence theta_t = 3.3 mrad: the manual (HDL-32E User's Manual, appendix
//!   "Laser spot size") gives a spot of about 4 in by 2 in at 100 ft, i.e. 3.3 x 1.7
//!   mrad full angle; the lenses sit side by side horizontally, so the horizontal figure
//!   is the one that matters (the exit size of the spot is neglected: an upper bound);
//! - pulse: tau_H = 4 ns ([`TAU_H_NS`]; Velodyne: pulses of "typically 4 nanoseconds");
//!   Hahner et al. took 20 ns, which spread the echo over 6 m of range;
//! - receiver field of view theta_r, apertures and axis separation: not published. The
//!   field must exceed theta_t for the receiver to collect the whole spot at the rated
//!   100 m: bounds 1.25-3 theta_t. The housing is 85.3 mm across (datasheet), so two
//!   lenses side by side are at most about 35 mm each: bounds of 20-30 mm clear
//!   apertures and a gap of 2-10 mm between them. Calibrated within these bounds
//!   against a real HDL-32E in fog (RADIATE `fog_6_0`, `docs/fidelity.md`, "Fog: a real
//!   HDL-32E"): its open sectors show no return at all within 3 m in any of 60 frames,
//!   and its far tail (30-40 m over 20-30 m, 0.17) puts its visibility at about 55-90 m
//!   in this model. The central estimates (25 mm apertures, 5 mrad field) put a fog
//!   echo in 94 % of the free slots at V = 90 m, at 2.5-3.4 m, which the recording
//!   rules out; the low corner (20 mm apertures, field 1.25 theta_t = 4.1 mrad, axes
//!   30 mm apart) gives R1 = 2.7 m, R2 = 75 m, and a fog echo in about 0.7 % of the free
//!   slots at V = 90 m, at 5-7 m, where the recording's ground returns would hide them.
//!
//! Clear air: the echo's mean peak falls as 1/V; with the receiver's noise the chance
//! of a fog echo falls smoothly with it, to under one echo in 10,000 frames at
//! V = 1 km and none at V >= 10 km (tests/integration/fog_calibration.rs).
//!
//! The integral is computed here (Gauss-Legendre quadrature on the smooth pieces between
//! R1, R2 and R0, the biaxial overlap in pieces of at most 0.75 m), not read from the
//! paper's tables. It depends only on the options and R0, so the first-crossing tables
//! are made once per stage and run (on first use) on a grid of R0 (a quarter cell),
//! taking the grid point at or below R0 (a nearer target cuts at least as much fog).
//! [`EchoTable`] keeps the noiseless peak (for reports and [`Fog::peak_power`]).
//!
//! Deviations, stated: the paper's table generator only scans apparent ranges R <= R0;
//! we follow the formula (truncation of r at R0, any R), which differs only for targets
//! closer than the peak. Slots without a return (sky, targets out of range) get fog
//! echoes too, since the fog in front of the sensor echoes whatever lies behind it; the
//! paper's code only rewrites points. The droplets' count uses one rms radius per
//! droplet type (advection 14.9 um, also for `"hahner"`; radiation 5.0 um): with
//! thousands of droplets in a cell its Poisson spread is a few percent of the signal,
//! far below the receiver's noise, and is kept for thin fog and small cells.
//!
//! Draw pattern: one uniform per recorded return (whatever its fate) and then one per
//! vacant slot (`empty_slots`), in that order, plus a second one each when
//! `range_noise_m` > 0, so streams stay aligned across sweeps of V.

mod crossing;
mod echo;
mod optics;

pub use super::fog_droplets::Droplets;
use crate::config::reader::Section;
use crate::error::Result;
use crate::noise::detection::{normal_tail, normal_tail_inverse};
use crate::noise::registry::OptionSpec;
use crate::noise::sensor::{float, number, C_M_PER_S};
use crate::noise::{DetectionRule, Echo, Fate, NoiseStage, NoisyFrame, StageKind};
use crossing::*;
pub use crossing::{Crossing, TAU_H_NS};
pub use echo::{EchoTable, SoftTarget};
use optics::*;
pub use optics::{
    disk_intersection, hdl32e_optics, hdl32e_overlap, Biaxial, Overlap, HDL32E_DIVERGENCE_MRAD,
};
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use std::sync::{Arc, Mutex, OnceLock};
use toml::Value;

/// The `type` name of this stage.
pub const NAME: &str = "fog";

/// Range (m) taken as the target range R0 of a slot without a return, for the range
/// noise of its fog echo: the HDL-32E's rated range.
pub const EMPTY_SLOT_RANGE_M: f64 = 100.0;

/// Grid step (m) of the tabulated echo over R0 for the linear overlap (its echo bends
/// sharply within a few cm of R1 and R2).
const TABLE_STEP_M: f64 = 0.005;
/// Grid step (m) for the biaxial overlap, whose echo varies smoothly with R0 (its
/// table spans R1..~7 m; test: interpolation within 1e-3 of the peak).
const BIAXIAL_TABLE_STEP_M: f64 = 0.02;

/// Extinction coefficient alpha (1/m) at meteorological optical range `v` metres:
/// -ln(0.05) / V (infinite V: 0).
pub fn extinction_per_m(visibility_m: f64) -> f64 {
    if visibility_m.is_infinite() {
        0.0
    } else {
        -(0.05f64.ln()) / visibility_m
    }
}

/// The fog stage.
#[derive(Clone, Debug)]
pub struct Fog {
    /// Meteorological optical range V in metres (infinite: no fog).
    pub visibility_m: f64,
    /// beta_r: backscatter beta = beta_r / V (1/(m sr)) with `droplets` Hahner.
    pub beta_r: f64,
    /// Source of the backscatter coefficient.
    pub droplets: Droplets,
    /// Half-power pulse width tau_H in ns.
    pub tau_h_ns: f64,
    /// Transmitter/receiver overlap.
    pub overlap: Overlap,
    /// n: fog echo range scaled by R0 / U(R0 - n, R0 + n) (Hahner's noise variant v1);
    /// 0 for none.
    pub range_noise_m: f64,
    /// Fog echoes also in slots without a return.
    pub empty_slots: bool,
    table: OnceLock<Arc<EchoTable>>,
    /// The noise cells' first-crossing tables, per (echo scale over threshold, minimum
    /// range, detection rule): frames of one run share one entry.
    crossings: CrossingCache,
}

/// The tables of [`Fog::crossing`]; a clone starts empty (a clone may be changed).
#[derive(Debug, Default)]
struct CrossingCache(Mutex<Vec<(CrossingKey, Arc<Crossing>)>>);

impl Clone for CrossingCache {
    fn clone(&self) -> Self {
        CrossingCache::default()
    }
}

impl Fog {
    /// The stage with these options (valid values assumed, as `build` checks them).
    pub fn new(
        visibility_m: f64,
        beta_r: f64,
        tau_h_ns: f64,
        overlap: Overlap,
        range_noise_m: f64,
        empty_slots: bool,
    ) -> Fog {
        Fog {
            visibility_m,
            beta_r,
            droplets: Droplets::Hahner,
            tau_h_ns,
            overlap,
            range_noise_m,
            empty_slots,
            table: OnceLock::new(),
            crossings: CrossingCache::default(),
        }
    }

    /// Extinction alpha in 1/m.
    pub fn alpha(&self) -> f64 {
        extinction_per_m(self.visibility_m)
    }

    /// The same stage with backscatter from `droplets`.
    pub fn with_droplets(mut self, droplets: Droplets) -> Fog {
        self.droplets = droplets;
        self
    }

    /// beta * V (1/sr): beta_r, or -ln(0.05) (beta / alpha)_Mie for Mie droplets.
    pub fn beta_times_v(&self) -> f64 {
        match self.droplets.backscatter_ratio() {
            None => self.beta_r,
            Some(ratio) => -(0.05f64.ln()) * ratio,
        }
    }

    /// Backscatter beta in 1/(m sr).
    pub fn beta(&self) -> f64 {
        if self.visibility_m.is_infinite() {
            0.0
        } else {
            self.beta_times_v() / self.visibility_m
        }
    }

    /// The soft-target parameters.
    pub fn soft_target(&self) -> SoftTarget {
        SoftTarget {
            alpha: self.alpha(),
            tau_h_s: self.tau_h_ns * 1e-9,
            overlap: self.overlap,
        }
    }

    /// The echo table (computed on first use, shared by every frame and thread).
    pub fn table(&self) -> &EchoTable {
        self.table
            .get_or_init(|| Arc::new(EchoTable::new(&self.soft_target())))
    }

    /// Power factor turning the integral I into a power for power constant `kappa`:
    /// pi kappa beta, the hard target's normalisation (module comment).
    pub fn echo_scale(&self, kappa_m2: f64) -> f64 {
        std::f64::consts::PI * kappa_m2 * self.beta()
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

    /// Peak power of the fog echo with no target in the beam (the strongest it gets).
    pub fn peak_power(&self, kappa_m2: f64) -> f64 {
        // The untruncated peak itself (not the table, which is built for many R0).
        self.echo_scale(kappa_m2) * self.soft_target().peak(f64::INFINITY).1
    }

    /// The visibility (m) above which the fog echo stays below the threshold `p_th`
    /// for power constant `kappa`, with these options otherwise. The peak power
    /// pi kappa beta I_max rises as V falls (beta = beta_r / V) until extinction
    /// (alpha = 3.0 / V) takes over at a few metres, so the strongest V is found on a log
    /// scan and the onset by bisection on ln V above it. Infinite if the echo is never
    /// this weak (up to 1e8 m); 0 if never this strong.
    pub fn echo_onset_visibility_m(&self, kappa_m2: f64, p_th: f64) -> f64 {
        let at = |v: f64| {
            Fog::new(v, self.beta_r, self.tau_h_ns, self.overlap, 0.0, true)
                .with_droplets(self.droplets)
                .peak_power(kappa_m2)
        };
        // 1 m to 1e8 m, 10 points per decade.
        let strongest = (0..=80)
            .map(|k| 10f64.powf(f64::from(k) / 10.0))
            .map(|v| (v, at(v)))
            .fold((1.0, f64::MIN), |m, c| if c.1 > m.1 { c } else { m });
        let (mut lo, mut hi) = (strongest.0, 1e8f64);
        if strongest.1 < p_th {
            return 0.0;
        }
        if at(hi) >= p_th {
            return f64::INFINITY;
        }
        while hi / lo > 1.0 + 1e-6 {
            let mid = (lo * hi).sqrt();
            if at(mid) >= p_th {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        (lo * hi).sqrt()
    }

    /// The first-crossing table for `frame` (its threshold, minimum range and detection
    /// rule, which must be the probabilistic one) and power constant `kappa`, made once
    /// per run and shared.
    pub fn crossing(&self, frame: &NoisyFrame, kappa: f64) -> Arc<Crossing> {
        let t = frame.threshold;
        let x_scale = self.echo_scale(kappa) / t;
        // Only probabilistic frames come here (`apply`); a frame without a rule (built
        // outside a chain) takes the default one.
        let rule = frame.detection.clone().unwrap_or_else(|| {
            Arc::new(DetectionRule::new(
                &crate::config::DetectionConfig::default(),
            ))
        });
        let key = [
            x_scale.to_bits(),
            frame.min_range.to_bits(),
            rule.threshold_snr.to_bits(),
            rule.shot_noise.to_bits(),
        ];
        let mut cache = self.crossings.0.lock().unwrap_or_else(|e| e.into_inner());
        if let Some((_, c)) = cache.iter().find(|(k, _)| *k == key) {
            return Arc::clone(c);
        }
        let alpha = self.alpha();
        let r = rms_droplet_radius_m(self.droplets);
        let n_d = alpha / (2.0 * std::f64::consts::PI * r * r);
        let beam = match self.overlap {
            Overlap::Biaxial(b) => (b.tx_radius_m, (b.divergence_rad / 2.0).tan()),
            Overlap::Linear { .. } => {
                let b = hdl32e_optics();
                (b.tx_radius_m, (b.divergence_rad / 2.0).tan())
            }
        };
        let c = Arc::new(Crossing::new(
            &self.soft_target(),
            x_scale,
            &rule,
            n_d,
            beam,
            frame.min_range,
        ));
        cache.push((key, Arc::clone(&c)));
        c
    }

    /// The echoes with the threshold detection (`[detection] model = "threshold"`), as
    /// before issue 50: the noiseless maximum of the waveform, proposed to every slot
    /// where it is detectable (one draw per beam only with `range_noise_m`).
    fn propose_noiseless(&self, frame: &mut NoisyFrame, rng: &mut ChaCha8Rng) {
        let kappa = frame.kappa_m2();
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
        // One echo a recorded return, as a column (`propose_each`).
        let none = Echo::NONE;
        let (threshold, min_range) = (frame.threshold, frame.min_range);
        let m = frame.clean_len;
        let each: Vec<Echo> = frame.range[..m]
            .iter()
            .zip(&frame.fate[..m])
            .map(|(&r0, &fate)| {
                let r0 = f64::from(r0);
                let echo = if r0 >= far_from && n == 0.0 {
                    if far_ok {
                        far
                    } else {
                        none
                    }
                } else {
                    let (r, integral) = table.lookup(r0);
                    Echo {
                        range: noisy(rng, r, r0) as f32,
                        power: scale * integral,
                    }
                };
                // Occlusion removes the beam; only detectable echoes can take part in the
                // slot's competition (`NoisyFrame::detectable`).
                let detectable = echo.power >= threshold && f64::from(echo.range) >= min_range;
                if fate != Fate::Occluded && detectable {
                    echo
                } else {
                    none
                }
            })
            .collect();
        frame.propose_each(each);
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

    fn echoes(&self) -> bool {
        self.beta() > 0.0
    }
}

impl NoiseStage for Fog {
    fn kind(&self) -> &'static str {
        NAME
    }

    fn describe(&self) -> String {
        let overlap = match self.overlap {
            Overlap::Linear { start_m, full_m } => format!("linear {start_m}..{full_m} m"),
            Overlap::Biaxial(b) => format!(
                "biaxial d = {} mm, apertures {}/{} mm, divergence {} mrad, fov {} mrad: R1 = {:.2} m, R2 = {:.1} m",
                b.separation_m * 1e3,
                b.tx_radius_m * 2e3,
                b.rx_radius_m * 2e3,
                b.divergence_rad * 1e3,
                b.fov_rad * 1e3,
                b.start_m(),
                b.full_m()
            ),
        };
        format!(
            "visibility {} m: alpha = {:.5} 1/m, beta = {:.3e} 1/(m sr) ({} droplets); soft echo tau_H = {} ns, overlap {overlap}",
            self.visibility_m,
            self.alpha(),
            self.beta(),
            self.droplets.name(),
            self.tau_h_ns,
        )
    }

    fn settings(&self) -> Vec<(&'static str, Value)> {
        let mut v = vec![
            ("visibility_m", float(self.visibility_m)),
            ("droplets", Value::String(self.droplets.name().into())),
        ];
        if self.droplets == Droplets::Hahner {
            v.push(("beta_r", float(self.beta_r)));
        }
        v.push(("tau_h_ns", float(self.tau_h_ns)));
        match self.overlap {
            Overlap::Linear { start_m, full_m } => {
                v.push(("overlap", Value::String("linear".into())));
                v.push(("overlap_start_m", float(start_m)));
                v.push(("overlap_full_m", float(full_m)));
            }
            Overlap::Biaxial(b) => {
                v.push(("overlap", Value::String("biaxial".into())));
                v.push(("axis_separation_mm", float(b.separation_m * 1e3)));
                v.push(("tx_aperture_mm", float(b.tx_radius_m * 2e3)));
                v.push(("rx_aperture_mm", float(b.rx_radius_m * 2e3)));
                v.push(("beam_divergence_mrad", float(b.divergence_rad * 1e3)));
                v.push(("rx_fov_mrad", float(b.fov_rad * 1e3)));
            }
        }
        v.push(("range_noise_m", float(self.range_noise_m)));
        v.push(("empty_slots", Value::Boolean(self.empty_slots)));
        v
    }

    fn proposes_echoes(&self) -> bool {
        self.echoes()
    }

    fn apply(&self, frame: &mut NoisyFrame, rng: &mut ChaCha8Rng) {
        let two_alpha = 2.0 * self.alpha();
        // Hard targets: two-way extinction (alive returns only).
        crate::noise::transmission::attenuate(
            &mut frame.power,
            &frame.range,
            &frame.fate,
            two_alpha,
        );
        if !self.echoes() {
            return;
        }
        if !frame.probabilistic() {
            self.propose_noiseless(frame, rng);
            return;
        }
        let kappa = frame.kappa_m2();
        let crossing = self.crossing(frame, kappa);
        let t = frame.threshold;
        let n = self.range_noise_m;
        let slots = frame.slots();
        // Hahner's range noise: the echo's range times R0 / U(R0 - n, R0 + n).
        let noisy = |v: f64, range: f64, r0: f64| -> f64 {
            // U(R0 - n, R0 + n), kept positive for targets nearer than n.
            let lo = (r0 - n).max(r0 * 0.5);
            range * r0 / (lo + v * (r0 + n - lo))
        };
        // One uniform per recorded return (whatever its fate), then one per vacant slot,
        // and a second one each when `range_noise_m` > 0: streams stay aligned across
        // sweeps of V.
        for i in 0..frame.clean_len {
            let u: f64 = rng.random();
            let v: f64 = if n > 0.0 { rng.random() } else { 0.0 };
            if frame.fate[i] == Fate::Occluded {
                continue;
            }
            let r0 = f64::from(frame.range[i]);
            if let Some(mut e) = crossing.draw_echo(r0, u, t) {
                if n > 0.0 {
                    e.range = noisy(v, f64::from(e.range), r0) as f32;
                }
                frame.propose(i, e);
            }
        }
        if self.empty_slots {
            for slot in 0..slots.len() as u32 {
                if !slots.is_vacant(slot) {
                    continue;
                }
                let u: f64 = rng.random();
                let v: f64 = if n > 0.0 { rng.random() } else { 0.0 };
                if let Some(mut e) = crossing.draw_echo(f64::INFINITY, u, t) {
                    if n > 0.0 {
                        e.range = noisy(v, f64::from(e.range), EMPTY_SLOT_RANGE_M) as f32;
                    }
                    frame.propose_slot(slot, e);
                }
            }
        }
    }
}

/// Options that belong to one overlap model only.
const LINEAR_KEYS: [&str; 2] = ["overlap_start_m", "overlap_full_m"];
const BIAXIAL_KEYS: [&str; 5] = [
    "axis_separation_mm",
    "tx_aperture_mm",
    "rx_aperture_mm",
    "beam_divergence_mrad",
    "rx_fov_mrad",
];

/// Reads the options of a `fog` entry.
pub fn build(opts: &Section<'_>) -> Result<Arc<dyn NoiseStage>> {
    // `inf` (no fog) is allowed: the identity, for sweeps down from clear weather.
    let visibility_m = match opts.value("visibility_m") {
        None => return Err(opts.missing("visibility_m")),
        Some(Value::Float(f)) if *f == f64::INFINITY => f64::INFINITY,
        Some(_) => number(opts, "visibility_m", 0.0, 1e-3, 1e9)?,
    };
    let droplets = match opts
        .choice("droplets", &["hahner", "advection", "radiation"])?
        .unwrap_or("hahner")
    {
        "advection" => Droplets::Advection,
        "radiation" => Droplets::Radiation,
        _ => Droplets::Hahner,
    };
    if droplets != Droplets::Hahner && opts.has("beta_r") {
        return Err(opts.error(
            "beta_r",
            format!(
                "not an option of droplets = \"{}\" (beta comes from Mie theory; beta_r belongs to droplets = \"hahner\")",
                droplets.name()
            ),
        ));
    }
    let beta_r = number(opts, "beta_r", 0.046, 0.0, 10.0)?;
    let tau_h_ns = number(opts, "tau_h_ns", TAU_H_NS, 0.1, 1000.0)?;
    let model = opts
        .choice("overlap", &["biaxial", "linear"])?
        .unwrap_or("biaxial");
    let (own, other): (&[&str], &[&str]) = if model == "linear" {
        (&LINEAR_KEYS, &BIAXIAL_KEYS)
    } else {
        (&BIAXIAL_KEYS, &LINEAR_KEYS)
    };
    if let Some(k) = other.iter().find(|k| opts.has(k)) {
        return Err(opts.error(
            k,
            format!(
                "not an option of overlap = \"{model}\" (its options: {})",
                own.join(", ")
            ),
        ));
    }
    let overlap = if model == "linear" {
        let start_m = number(opts, "overlap_start_m", 0.9, 0.01, 100.0)?;
        let full_m = number(opts, "overlap_full_m", 1.0, 0.01, 100.0)?;
        if full_m < start_m {
            return Err(opts.error(
                "overlap_full_m",
                format!("{full_m} is below overlap_start_m ({start_m})"),
            ));
        }
        Overlap::Linear { start_m, full_m }
    } else {
        let d = number(
            opts,
            "axis_separation_mm",
            HDL32E_SEPARATION_MM,
            0.0,
            1000.0,
        )?;
        let at = number(opts, "tx_aperture_mm", HDL32E_APERTURE_MM, 0.01, 1000.0)?;
        let ar = number(opts, "rx_aperture_mm", HDL32E_APERTURE_MM, 0.01, 1000.0)?;
        let div = number(
            opts,
            "beam_divergence_mrad",
            HDL32E_DIVERGENCE_MRAD,
            0.01,
            500.0,
        )?;
        let fov = number(opts, "rx_fov_mrad", HDL32E_FOV_MRAD, 0.01, 500.0)?;
        Overlap::Biaxial(Biaxial {
            separation_m: d * 1e-3,
            tx_radius_m: at * 0.5e-3,
            rx_radius_m: ar * 0.5e-3,
            divergence_rad: div * 1e-3,
            fov_rad: fov * 1e-3,
        })
    };
    let range_noise_m = number(opts, "range_noise_m", 0.0, 0.0, 100.0)?;
    let empty_slots = super::bool_option(opts, "empty_slots", true)?;
    Ok(Arc::new(
        Fog::new(
            visibility_m,
            beta_r,
            tau_h_ns,
            overlap,
            range_noise_m,
            empty_slots,
        )
        .with_droplets(droplets),
    ))
}

/// The registry entry of this stage.
pub const KIND: StageKind = StageKind {
    name: NAME,
    factor: "11 weather (fog)",
    model: "alpha = -ln(0.05)/V, hard target P exp(-2 alpha R); soft-target echo max_R pi kappa beta int s(t) exp(-2 alpha r) xi(r)/r^2 (c/2) dt (the hard target's normalisation), xi the biaxial overlap of the HDL-32E, computed by quadrature, proposed to the firing slot (strongest: replaces the target when stronger)",
    source: "Hahner et al., ICCV 2021 (Fog Simulation on Real LiDAR Point Clouds); overlap: Measures, Laser Remote Sensing, ch. 7, Stelmaszczyk et al. 2005 (top-hat biaxial); HDL-32E manual (spot 4 x 2 in at 100 ft); apertures, axis separation and receiver FOV estimated (module comment)",
    options: &[
        OptionSpec { name: "visibility_m", unit: "m", default: "required", doc: "meteorological optical range V (inf: no fog)" },
        OptionSpec { name: "beta_r", unit: "1/sr", default: "0.046", doc: "backscatter beta = beta_r / V (paper range 0.023-0.092; 0: extinction only)" },
        OptionSpec { name: "droplets", unit: "-", default: "hahner", doc: "backscatter: \"hahner\" (beta = beta_r / V) or Mie for Shettle & Fenn \"advection\" / \"radiation\" fog (beta = alpha (beta/alpha)_Mie, lidar ratio about 18 sr)" },
        OptionSpec { name: "tau_h_ns", unit: "ns", default: "4", doc: "half-power pulse width tau_H (Velodyne: pulses of typically 4 ns; Hahner et al. used 20)" },
        OptionSpec { name: "overlap", unit: "-", default: "biaxial", doc: "\"biaxial\" (geometric overlap, HDL-32E defaults: no fog echo at V >= 10 km) or \"linear\" (Hahner's R1..R2 ramp)" },
        OptionSpec { name: "axis_separation_mm", unit: "mm", default: "30", doc: "biaxial: distance between transmitter and receiver axes (estimated, 27-40)" },
        OptionSpec { name: "tx_aperture_mm", unit: "mm", default: "20", doc: "biaxial: transmitted beam diameter at the exit (estimated, 20-30; calibrated)" },
        OptionSpec { name: "rx_aperture_mm", unit: "mm", default: "20", doc: "biaxial: receiver aperture diameter (estimated, 20-30; calibrated)" },
        OptionSpec { name: "beam_divergence_mrad", unit: "mrad", default: "3.3", doc: "biaxial: full beam divergence (HDL-32E manual: 4 in at 100 ft)" },
        OptionSpec { name: "rx_fov_mrad", unit: "mrad", default: "4.1", doc: "biaxial: receiver full field of view (estimated, 1.25-3 x divergence; calibrated)" },
        OptionSpec { name: "overlap_start_m", unit: "m", default: "0.9", doc: "linear: R1, overlap starts (xi = 0 below)" },
        OptionSpec { name: "overlap_full_m", unit: "m", default: "1.0", doc: "linear: R2, overlap complete (xi = 1 above)" },
        OptionSpec { name: "range_noise_m", unit: "m", default: "0", doc: "n: fog echo range x R0 / U(R0 - n, R0 + n) (Hahner v1; 0 = none)" },
        OptionSpec { name: "empty_slots", unit: "-", default: "true", doc: "fog echoes also in firing slots without a return" },
    ],
    build,
};

#[cfg(test)]
mod tests;
