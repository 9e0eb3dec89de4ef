//! Other LiDARs (p-diagram 15): crosstalk, pulses of another sensor timed as echoes.
//!
//! Model A (`model = "benchmark"`, the default; pdiagram-models.md 15, the benchmarks'
//! corruption): a fraction p_x of the returns whose azimuth lies in the chosen sectors get
//! a false echo at R' = R + s_x z, z standard normal, proposed in the return's firing slot
//! with the interferer's received power P_x; the sensor's return logic then decides
//! whether the false echo is reported (it replaces the return in strongest mode when P_x
//! is higher, in last mode when R' is farther; see `noise::spurious`).
//!
//! Model B (`model = "physical"`): every firing slot (laser and firing, with a return or
//! empty) of a firing whose azimuth lies in the sectors (the interferer's direction
//! +-psi_x) gets, with probability q_x (`fraction`), a false echo at R ~ U(minimum range,
//! R_max) with power P_x, competing in the same way (an empty slot, e.g. sky, gets an
//! added return). The doc's q_x = 0.01 and psi_x = 5 deg (`sectors_deg = [[355, 5]]` for
//! an interferer straight ahead) are engineering assumptions.
//!
//! Deviations, and why:
//! - The benchmarks (3D_Corruptions_AD `lidar_crosstalk_noise`, Robo3D
//!   `gen_crosstalk.py`) add N(0, s_x^2) to x, y and z. A sensor reports a point only along
//!   the beam of its firing (azimuth per firing, elevation per laser), so only the
//!   component along the beam is kept: for an isotropic Gaussian it is N(0, s_x^2) itself.
//!   The benchmarks also perturb intensity; the doc says not to, and we do not.
//! - The benchmarks corrupt exactly round(p_x n) points; here the count is
//!   Binomial(n, p_x) over the n eligible returns (slots in model B), as if each were hit
//!   independently with probability p_x. Drawing the count and then that many distinct
//!   returns (`rand::seq::index::sample`) gives the same distribution as one Bernoulli
//!   draw per return at the cost of O(p_x n) draws instead of n (the speed target of
//!   issue 12). Common random numbers across `fraction` values are therefore not kept.
//! - An echo whose range falls under the minimum range (or below zero) is not detectable
//!   and loses its slot: the return stays.
//!
//! Echo power P_x, from a model of the interfering sensor (issue 29; before it P_x = 1
//! for every echo, which always won its slot in strongest mode). The interferer is
//! another HDL-32E unless told otherwise: `interferer_power` = r, its pulse power over
//! ours (1 for the same model). Powers are in this tool's unit, a fraction of our
//! emitted power on the kappa scale (`noise::power`: a Lambertian target of reflectance
//! rho at R returns kappa rho / R^2, kappa = eta A_rx / pi in physical terms, so any
//! physical ratio to our own echo carries over with the same kappa):
//! - Model A, reflected: the false echo is the interferer's pulse diffusely reflected by
//!   the surface our beam sees (it lands near the return's range, as the benchmarks
//!   place it). A Lambertian spot lit by a pulse of power P_t sends eta A_rx rho P_t /
//!   (pi R^2) into our aperture whoever fired it; the interferer's spot (its divergence
//!   times its distance d_i) puts all its power inside our footprint when d_i <= R and a
//!   share (R / d_i)^2 of it otherwise, so P_x = r min(1, (R / d_i)^2) P <= r P, with P
//!   the return's current power (same surface, same path back to us). We take the upper
//!   bound P_x = r P (interferer at most as far from the surface as we are). Consequence:
//!   an equal interferer's reflection ties with the true echo and never replaces it in
//!   strongest mode (ties go to the recorded return); in last and dual mode the farther
//!   echoes are reported. Source: the Lambertian lidar equation (e.g. Jelalian, Laser
//!   Radar Systems, 1992, ch. 1), as `noise::power`.
//! - Model B, direct: the interferer's pulse reaches our aperture straight from its
//!   emitter, at distance d (`interferer_distance_m`), spread over its spot. The HDL-32E
//!   manual (appendix D, "Laser Spot Size") gives a rectangular spot of about 4 x 2
//!   inches at 100 feet: full divergences theta_w = 0.1016 / 30.48 = 3.33 mrad and
//!   theta_h = 1.67 mrad. The aperture receives P_t A_rx / (theta_w theta_h d^2) against
//!   eta A_rx rho P_t / (pi R^2) from our own echo, so in our unit
//!   P_x = min(1, r kappa pi / (theta_w theta_h d^2)): with kappa = 100 m^2 that is 1
//!   (saturation) for any d under 7.5 km, the value the stage used before, now derived.
//! - `power` sets P_x directly (both models) and overrides the two.
//!
//! Defaults: p_x = 0.01 (the benchmarks' 0.4-2 %), s_x = 3 m (both benchmarks), the
//! whole turn, r = 1 (another HDL-32E), d = 20 m (a car in the next lane, model B).

use crate::config::reader::Section;
use crate::error::Result;
use crate::noise::registry::OptionSpec;
use crate::noise::sensor::{float, number};
use crate::noise::{Echo, NoiseStage, NoisyFrame, StageKind};
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Binomial, Distribution, StandardNormal};
use std::sync::Arc;
use toml::Value;

/// The `type` name of this stage.
pub const NAME: &str = "crosstalk";

/// kappa of the default power model (m^2), for descriptions and frames without one.
const DEFAULT_KAPPA_M2: f64 = 100.0;

/// An azimuth sector: `width` degrees clockwise from `from` (the sensor's azimuth
/// direction), possibly through 0; a width of 360 is the whole turn.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sector {
    /// Start azimuth in [0, 360) degrees.
    pub from: f64,
    /// Clockwise width in (0, 360] degrees.
    pub width: f64,
}

impl Sector {
    /// The whole turn.
    pub const FULL: Sector = Sector {
        from: 0.0,
        width: 360.0,
    };

    /// The sector [from, to) clockwise; `[0, 360]` (or any pair 360 apart) is the whole turn.
    pub fn new(from: f64, to: f64) -> Sector {
        let mut width = (to - from).rem_euclid(360.0);
        if width == 0.0 {
            width = 360.0;
        }
        Sector {
            from: from.rem_euclid(360.0),
            width,
        }
    }

    /// True if the sector is the whole turn.
    pub fn is_full(&self) -> bool {
        self.width >= 360.0
    }

    /// True if `azimuth` (degrees in [0, 360), as the decoder reports it) lies in the sector.
    #[inline]
    pub fn contains(&self, azimuth: f64) -> bool {
        if self.is_full() {
            return true;
        }
        // One addition instead of a `rem_euclid` per return (both angles are in [0, 360)).
        let mut d = azimuth - self.from;
        if d < 0.0 {
            d += 360.0;
        }
        if d >= 360.0 {
            d -= 360.0;
        }
        d < self.width
    }

    /// The sector as written in TOML, `[from, to]`.
    pub fn to_value(self) -> Value {
        let to = if self.is_full() {
            self.from + 360.0
        } else {
            (self.from + self.width).rem_euclid(360.0)
        };
        Value::Array(vec![float(self.from), float(to)])
    }
}

/// Reads a sector `[from, to]` (degrees in [0, 360]) at `key`; `from == to` is refused
/// unless the two are 0 and 360 (the whole turn).
pub fn read_sector(opts: &Section<'_>, key: &str) -> Result<Option<Sector>> {
    let Some([from, to]) = opts.pair(key)? else {
        return Ok(None);
    };
    check_sector(opts, key, [from, to]).map(Some)
}

fn check_sector(opts: &Section<'_>, key: &str, [from, to]: [f64; 2]) -> Result<Sector> {
    for (i, a) in [from, to].into_iter().enumerate() {
        if !(0.0..=360.0).contains(&a) {
            return Err(opts.error(
                &format!("{key}[{i}]"),
                format!("{a} is outside [0, 360] degrees"),
            ));
        }
    }
    if from == to {
        return Err(opts.error(
            key,
            format!("the sector [{from}, {to}] is empty; [0, 360] is the whole turn"),
        ));
    }
    Ok(Sector::new(from, to))
}

/// Reads a non-empty list of sectors `[[from, to], ...]` at `key`.
fn read_sectors(opts: &Section<'_>, key: &str) -> Result<Option<Vec<Sector>>> {
    let Some(v) = opts.value(key) else {
        return Ok(None);
    };
    let bad = || {
        opts.error(
            key,
            "expected an array of sectors [[from, to], ...] in degrees",
        )
    };
    let Value::Array(items) = v else {
        return Err(bad());
    };
    if items.is_empty() {
        return Err(opts.error(key, "the list is empty: name at least one sector"));
    }
    let mut out = Vec::with_capacity(items.len());
    for (i, item) in items.iter().enumerate() {
        let elem = format!("{key}[{i}]");
        let pair = match item {
            Value::Array(p) if p.len() == 2 => {
                let mut xy = [0.0; 2];
                for (j, x) in p.iter().enumerate() {
                    xy[j] = match x {
                        Value::Integer(n) => *n as f64,
                        Value::Float(f) if f.is_finite() => *f,
                        _ => {
                            return Err(opts.error(
                                &format!("{elem}[{j}]"),
                                format!("expected a number, found {x}"),
                            ))
                        }
                    };
                }
                xy
            }
            _ => {
                return Err(opts.error(&elem, format!("expected a sector [from, to], found {item}")))
            }
        };
        out.push(check_sector(opts, &elem, pair)?);
    }
    Ok(Some(out))
}

/// Which of the doc's two crosstalk models the stage runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Model {
    /// Model A: a fraction of the returns get a false echo about their range.
    Benchmark,
    /// Model B: a fraction of the firing slots get a false echo at a uniform range.
    Physical,
}

/// The crosstalk stage.
#[derive(Clone, Debug)]
pub struct Crosstalk {
    /// Model A or B.
    pub model: Model,
    /// Model A: fraction p_x of the eligible returns; model B: probability q_x per firing
    /// slot.
    pub fraction: f64,
    /// Model A: SD s_x of the false echo's range about the return's range, metres.
    pub sigma_m: f64,
    /// Model B: largest false range R_max, metres.
    pub max_range_m: f64,
    /// Azimuth sectors of the interferers.
    pub sectors: Vec<Sector>,
    /// Received power of the false echo (fraction of emitted power) when set; `None`:
    /// from the interferer model (module documentation).
    pub power: Option<f64>,
    /// Interferer's pulse power over ours (r).
    pub interferer_power: f64,
    /// Model B: distance d of the interferer's emitter, metres.
    pub interferer_distance_m: f64,
}

/// Full divergences (width, height) of the HDL-32E's spot, radians: about 4 x 2 inches
/// at 100 feet (HDL-32E user's manual, appendix D, "Laser Spot Size").
pub const SPOT_DIVERGENCE_RAD: [f64; 2] = [0.1016 / 30.48, 0.0508 / 30.48];

impl Crosstalk {
    /// Model B's direct-path power in our unit for a power model with `kappa_m2`:
    /// min(1, r kappa pi / (theta_w theta_h d^2)), or `power` when set.
    pub fn direct_power(&self, kappa_m2: f64) -> f64 {
        self.power.unwrap_or_else(|| {
            let [tw, th] = SPOT_DIVERGENCE_RAD;
            let d = self.interferer_distance_m;
            (self.interferer_power * kappa_m2 * std::f64::consts::PI / (tw * th * d * d)).min(1.0)
        })
    }

    /// True if a return at `azimuth` degrees lies in one of the sectors.
    #[inline]
    fn covers(&self, azimuth: f64) -> bool {
        self.sectors.iter().any(|s| s.contains(azimuth))
    }

    /// How many of `n` candidates get a false echo: Binomial(n, fraction).
    fn count(&self, n: usize, rng: &mut ChaCha8Rng) -> usize {
        if self.fraction >= 1.0 {
            return n;
        }
        Binomial::new(n as u64, self.fraction).map_or(0, |b| b.sample(rng) as usize)
    }

    /// Model A: false echoes about the ranges of eligible returns.
    fn apply_benchmark(&self, frame: &mut NoisyFrame, rng: &mut ChaCha8Rng) {
        // The eligible returns: alive and in a sector (one pass, no draws).
        let full = self.sectors.iter().any(Sector::is_full);
        let eligible: Vec<u32> = (0..frame.len())
            .filter(|&i| {
                frame.fate[i].is_alive() && (full || self.covers(f64::from(frame.clean[i].azimuth)))
            })
            .map(|i| i as u32)
            .collect();
        let n = eligible.len();
        if n == 0 {
            return;
        }
        let count = self.count(n, rng);
        let mut chosen = rand::seq::index::sample(rng, n, count).into_vec();
        // Proposal order (and the range draws) follow the return order.
        chosen.sort_unstable();
        for k in chosen {
            let i = eligible[k] as usize;
            let z: f64 = rng.sample(StandardNormal);
            let range = (f64::from(frame.range[i]) + self.sigma_m * z) as f32;
            // Reflected by the surface the return comes from: r times its power.
            let power = self.power.unwrap_or(self.interferer_power * frame.power[i]);
            frame.propose(i, Echo { range, power });
        }
    }

    /// Model B: false echoes at uniform ranges in firing slots, occupied or empty.
    fn apply_physical(&self, frame: &mut NoisyFrame, rng: &mut ChaCha8Rng) {
        if frame.clean_len == 0 {
            return;
        }
        let slots = frame.slots();
        let full = self.sectors.iter().any(Sector::is_full);
        // Firings in a sector, by the azimuth of any of their returns (the lasers of a
        // firing are within 0.17 degrees of each other on the HDL-32E, 10 on the HDL-64E).
        let firings: Vec<u32> = (0..slots.firings.len())
            .filter(|&f| {
                full || slots
                    .any_of_firing(f)
                    .is_some_and(|i| self.covers(f64::from(frame.clean[i].azimuth)))
            })
            .map(|f| f as u32)
            .collect();
        let lasers = slots.lasers();
        let n = firings.len() * lasers;
        if n == 0 {
            return;
        }
        let count = self.count(n, rng);
        let mut chosen = rand::seq::index::sample(rng, n, count).into_vec();
        chosen.sort_unstable();
        let lo = frame.min_range.max(0.0);
        let kappa = frame
            .power_model
            .as_ref()
            .map_or(DEFAULT_KAPPA_M2, |m| m.constants().kappa_m2);
        let power = self.direct_power(kappa);
        for k in chosen {
            let slot = slots.slot(firings[k / lasers] as usize, (k % lasers) as u8);
            let range = (lo + (self.max_range_m - lo) * rng.random::<f64>()) as f32;
            frame.propose_slot(slot, Echo { range, power });
        }
    }
}

impl NoiseStage for Crosstalk {
    fn kind(&self) -> &'static str {
        NAME
    }

    fn describe(&self) -> String {
        let sectors: Vec<String> = self
            .sectors
            .iter()
            .map(|s| {
                if s.is_full() {
                    "all azimuths".to_string()
                } else {
                    format!("{}+{} deg", s.from, s.width)
                }
            })
            .collect();
        let power = match (self.power, self.model) {
            (Some(p), _) => format!("power {p}"),
            (None, Model::Benchmark) => format!(
                "power {} x the return's (interferer's reflection)",
                self.interferer_power
            ),
            (None, Model::Physical) => format!(
                "power {} (direct pulse of an interferer {} x ours at {} m)",
                self.direct_power(DEFAULT_KAPPA_M2),
                self.interferer_power,
                self.interferer_distance_m
            ),
        };
        match self.model {
            Model::Benchmark => format!(
                "{} % of returns in {} get a false echo at R + N(0, {} m), {power}",
                self.fraction * 100.0,
                sectors.join(", "),
                self.sigma_m,
            ),
            Model::Physical => format!(
                "{} % of firing slots in {} get a false echo at U(min range, {} m), {power}",
                self.fraction * 100.0,
                sectors.join(", "),
                self.max_range_m,
            ),
        }
    }

    fn settings(&self) -> Vec<(&'static str, Value)> {
        let model = match self.model {
            Model::Benchmark => "benchmark",
            Model::Physical => "physical",
        };
        let mut v = vec![
            ("model", Value::String(model.into())),
            ("fraction", float(self.fraction)),
            ("sigma_m", float(self.sigma_m)),
            ("max_range_m", float(self.max_range_m)),
            (
                "sectors_deg",
                Value::Array(self.sectors.iter().map(|s| s.to_value()).collect()),
            ),
            ("interferer_power", float(self.interferer_power)),
            ("interferer_distance_m", float(self.interferer_distance_m)),
        ];
        if let Some(p) = self.power {
            v.push(("power", float(p)));
        }
        v
    }

    fn proposes_echoes(&self) -> bool {
        self.fraction > 0.0 && self.power.unwrap_or(self.interferer_power) > 0.0
    }

    fn apply(&self, frame: &mut NoisyFrame, rng: &mut ChaCha8Rng) {
        if !self.proposes_echoes() {
            return;
        }
        match self.model {
            Model::Benchmark => self.apply_benchmark(frame, rng),
            Model::Physical => self.apply_physical(frame, rng),
        }
    }
}

/// Reads the options of a `crosstalk` entry.
pub fn build(opts: &Section<'_>) -> Result<Arc<dyn NoiseStage>> {
    let model = match opts.choice("model", &["benchmark", "physical"])? {
        Some("physical") => Model::Physical,
        _ => Model::Benchmark,
    };
    let fraction = number(opts, "fraction", 0.01, 0.0, 1.0)?;
    let sigma_m = number(opts, "sigma_m", 3.0, 0.0, 1000.0)?;
    // The wire holds ranges up to 131.07 m (65535 x 2 mm).
    let max_range_m = number(opts, "max_range_m", 100.0, 1.0, 131.0)?;
    let sectors = read_sectors(opts, "sectors_deg")?.unwrap_or_else(|| vec![Sector::FULL]);
    let power = match opts.value("power") {
        None => None,
        Some(_) => Some(number(opts, "power", 1.0, 0.0, 1.0)?),
    };
    let interferer_power = number(opts, "interferer_power", 1.0, 0.0, 1e3)?;
    let interferer_distance_m = number(opts, "interferer_distance_m", 20.0, 0.1, 1e6)?;
    if model == Model::Benchmark && fraction > 0.02 {
        opts.warn(
            "fraction",
            format!(
                "{fraction} is above the 0.4-2 % of points the benchmarks (3D_Corruptions_AD, \
                 Robo3D) use"
            ),
        );
    }
    Ok(Arc::new(Crosstalk {
        model,
        fraction,
        sigma_m,
        max_range_m,
        sectors,
        power,
        interferer_power,
        interferer_distance_m,
    }))
}

/// The registry entry of this stage.
pub const KIND: StageKind = StageKind {
    name: NAME,
    factor: "15 other LiDARs (crosstalk)",
    model: "A (benchmark): Binomial(n, p_x) of the n returns in the sectors get a false echo at R + N(0, s_x^2) along the beam; B (physical): Binomial(n, q_x) of the n firing slots in the sectors get one at U(min range, R_max); power P_x: A the interferer's reflection off the return's surface, r P; B its direct pulse, min(1, r kappa pi / (theta_w theta_h d^2)); competing by the slot rule",
    source: "3D_Corruptions_AD lidar_crosstalk_noise (0.4-2 %, SD 3 m); Robo3D gen_crosstalk.py (0.6-1 %, SD 3 m); P_x: Lambertian lidar equation with the HDL-32E spot (user's manual appendix D, 4 x 2 in at 100 ft); model B engineering assumption (pdiagram-models.md 15)",
    options: &[
        OptionSpec { name: "model", unit: "-", default: "\"benchmark\"", doc: "\"benchmark\" (model A, about the true range) or \"physical\" (model B, uniform ranges in any slot)" },
        OptionSpec { name: "fraction", unit: "-", default: "0.01", doc: "A: fraction p_x of the returns in the sectors; B: probability q_x per firing slot" },
        OptionSpec { name: "sigma_m", unit: "m", default: "3", doc: "A: SD s_x of the false echo's range about the return's range" },
        OptionSpec { name: "max_range_m", unit: "m", default: "100", doc: "B: largest false range R_max (at most 131 m, the wire's limit)" },
        OptionSpec { name: "sectors_deg", unit: "deg", default: "[[0, 360]]", doc: "interferer sectors [[from, to], ...], clockwise, may wrap" },
        OptionSpec { name: "interferer_power", unit: "-", default: "1", doc: "interferer's pulse power over ours, r (1: another HDL-32E)" },
        OptionSpec { name: "interferer_distance_m", unit: "m", default: "20", doc: "B: distance d of the interferer's emitter (direct pulse)" },
        OptionSpec { name: "power", unit: "-", default: "model", doc: "fixed received power of every false echo (fraction of emitted power, 1 = saturation); overrides the interferer model" },
    ],
    build,
};

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sectors_wrap_and_the_full_turn_holds_everything() {
        let s = Sector::new(300.0, 60.0);
        assert_eq!(s.width, 120.0);
        assert!(s.contains(300.0) && s.contains(359.9) && s.contains(0.0) && s.contains(59.9));
        assert!(!s.contains(60.0) && !s.contains(180.0) && !s.contains(299.9));
        let full = Sector::new(0.0, 360.0);
        assert!(full.is_full() && full.contains(0.0) && full.contains(359.99));
        let narrow = Sector::new(10.0, 20.0);
        assert!(narrow.contains(10.0) && !narrow.contains(20.0) && !narrow.contains(9.99));
        assert_eq!(
            Sector::new(300.0, 60.0).to_value(),
            Value::Array(vec![float(300.0), float(60.0)])
        );
        assert_eq!(
            full.to_value(),
            Value::Array(vec![float(0.0), float(360.0)])
        );
    }
}
