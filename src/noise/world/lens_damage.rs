//! Lens damage (p-diagram 10): transmission loss and beams scattered off their aim.
//!
//! Scratches, pits, worn coating or a crack lower the transmission of the optics and
//! scatter part of the beam. The HDL-32E's lens turns with the head, so a damage spot
//! affects some lasers at every azimuth (`lasers`, default all), unlike dirt on a fixed
//! window (a blocked sector is the `occlusion` stage, factor 12).
//!
//! Model (pdiagram-models.md, 10; engineering assumption, no quantitative lens-damage
//! study was found):
//! - transmission: `transmission` is the one-way transmission T of the optics, crossed
//!   out and back: P' = T^2 P on the chosen lasers (the convention `occlusion` shares).
//!   The intensity byte follows through the chain's intensity rule (`noise`,
//!   "Intensity"), I' = T^2 I for a return with no other loss.
//! - scatter: with probability p_s (`scatter_probability`) per return of a chosen laser
//!   the beam is deflected by (d_a, d_w) ~ N(0, s_d^2) each (`scatter_sigma_deg`) in
//!   azimuth and elevation. The return then comes from the surface in the deflected
//!   direction, read from the frame's organized laser x firing image (the laser nearest
//!   in elevation, the firing nearest in azimuth, the state before this stage), and is
//!   reported at the nominal angles: range R_d of that surface, power T^2 q P_d, with q
//!   (`scatter_fraction`) the share of the deflected echo that the receiver, aimed along
//!   the nominal direction, collects back through the damaged spot. The return is marked
//!   `Replaced` (cause: this stage; `range_clean` keeps the aimed range): no other echo
//!   competes, the aimed surface is not lit. A beam deflected to an empty cell (sky, no
//!   return) brings nothing back and is dropped (`below_power`, cause: this stage).
//!
//! Draws: one 64-bit word per return (all returns, whatever their laser or fate, so the
//! draws of a return do not depend on the others): its top 53 bits decide the scatter,
//! two normals from a SplitMix64 hash of it (Box-Muller) give the deflection. No draws
//! when p_s = 0. In dual captures a slot's entries share the draw of its last return.

use super::multipath::az_diff;
use super::{splitmix, unit};
use crate::config::reader::Section;
use crate::error::Result;
use crate::noise::registry::OptionSpec;
use crate::noise::sensor::{float, number, scale_byte, sigma, CHUNK};
use crate::noise::spurious::SlotMode;
use crate::noise::spurious::MAX_LASERS;
use crate::noise::{
    check_ids, Fate, LaserSet, NoiseStage, NoisyFrame, Slots, StageKind, LASER_MASK,
};
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use std::sync::Arc;
use toml::Value;

/// The `type` name of this stage.
pub const NAME: &str = "lens_damage";

/// Farthest the deflected direction is searched for, in firings either way (0.5 degree
/// sigma is 3 firings at 10 Hz; 200 firings is 33 degrees).
const MAX_WALK: usize = 200;

/// The lens-damage stage.
#[derive(Clone, Debug)]
pub struct LensDamage {
    /// Laser ids behind the damaged spot; `None` for every laser of the sensor.
    pub lasers: Option<Vec<u8>>,
    /// One-way transmission T of the damaged optics.
    pub transmission: f64,
    /// Probability p_s that a return's beam is scattered.
    pub scatter_probability: f64,
    /// SD s_d of the deflection per axis, degrees.
    pub scatter_sigma_deg: f64,
    /// Share q of the deflected echo collected back.
    pub scatter_fraction: f64,
    /// The damaged lasers.
    mask: LaserSet,
}

impl LensDamage {
    /// Builds the stage (options already valid).
    pub fn new(
        lasers: Option<Vec<u8>>,
        transmission: f64,
        scatter_probability: f64,
        scatter_sigma_deg: f64,
        scatter_fraction: f64,
    ) -> Self {
        let mask = lasers.as_deref().map_or(LaserSet::ALL, LaserSet::of);
        LensDamage {
            lasers,
            transmission,
            scatter_probability,
            scatter_sigma_deg,
            scatter_fraction,
            mask,
        }
    }

    #[inline]
    fn damaged(&self, laser: u8) -> bool {
        self.mask.contains(laser)
    }
}

/// Two standard normals from a word (Box-Muller on two 32-bit halves of its hash).
#[inline]
fn normals(w: u64) -> (f64, f64) {
    let h = splitmix(w);
    // (0, 1]: never ln(0).
    let u1 = ((h >> 32) as f64 + 1.0) / 4_294_967_296.0;
    let u2 = (h & 0xffff_ffff) as f64 / 4_294_967_296.0;
    let r = (-2.0 * u1.ln()).sqrt();
    let (s, c) = (std::f64::consts::TAU * u2).sin_cos();
    (r * c, r * s)
}

/// Azimuth of a firing: that of its first recorded return.
fn firing_azimuth(frame: &NoisyFrame, slots: &Slots, firing: usize) -> Option<f32> {
    slots.any_of_firing(firing).map(|i| frame.clean[i].azimuth)
}

/// The firing whose azimuth is nearest to `d_az` degrees from firing `f`'s (walking from
/// `f` while the distance shrinks).
fn deflected_firing(frame: &NoisyFrame, slots: &Slots, f: usize, d_az: f64) -> usize {
    let Some(a0) = firing_azimuth(frame, slots, f) else {
        return f;
    };
    let n = slots.firings.len();
    let mut best = f;
    let mut best_err = d_az.abs();
    for k in 1..=MAX_WALK {
        let g = if d_az >= 0.0 {
            f + k
        } else if k <= f {
            f - k
        } else {
            break;
        };
        if g >= n {
            break;
        }
        let Some(a) = firing_azimuth(frame, slots, g) else {
            continue;
        };
        let err = (az_diff(a0, a) - d_az).abs();
        if err < best_err {
            best = g;
            best_err = err;
        } else {
            break;
        }
    }
    best
}

/// What happens to a scattered return.
#[derive(Clone, Copy)]
enum Scatter {
    /// Reported at this range and power.
    To(f32, f64),
    /// Nothing in the deflected direction.
    Lost,
}

impl NoiseStage for LensDamage {
    fn kind(&self) -> &'static str {
        NAME
    }
    fn describe(&self) -> String {
        let lasers = match &self.lasers {
            Some(ids) => format!("{} lasers", ids.len()),
            None => "all lasers".to_string(),
        };
        format!(
            "{lasers}: power x T^2 = {:.4}; {} of beams deflected by N(0, {}^2) deg, echo x {}",
            self.transmission * self.transmission,
            self.scatter_probability,
            self.scatter_sigma_deg,
            self.scatter_fraction
        )
    }
    fn settings(&self) -> Vec<(&'static str, Value)> {
        let mut v = Vec::new();
        if let Some(ids) = &self.lasers {
            let ids = ids.iter().map(|&l| Value::Integer(l.into())).collect();
            v.push(("lasers", Value::Array(ids)));
        }
        v.extend([
            ("transmission", float(self.transmission)),
            ("scatter_probability", float(self.scatter_probability)),
            ("scatter_sigma_deg", float(self.scatter_sigma_deg)),
            ("scatter_fraction", float(self.scatter_fraction)),
        ]);
        v
    }
    fn check_lasers(&self, lasers: usize) -> std::result::Result<(), String> {
        check_ids("lasers", self.lasers.as_deref(), lasers)
    }
    fn proposes_echoes(&self) -> bool {
        // Scattered returns become `Replaced`: the PLY then carries fate and cause.
        self.scatter_probability > 0.0
    }
    fn apply(&self, frame: &mut NoisyFrame, rng: &mut ChaCha8Rng) {
        let t2 = self.transmission * self.transmission;
        let n = frame.len();
        // Scatter first, from the state before this stage.
        let mut scattered: Vec<(usize, Scatter)> = Vec::new();
        if self.scatter_probability > 0.0 && frame.clean_len > 0 {
            let slots = frame.slots();
            let dual = slots.mode == SlotMode::Dual;
            // Elevation of each laser in this frame (the calibration's).
            let mut elevation = [f32::NAN; MAX_LASERS];
            let mut found = 0;
            for r in &frame.clean[..frame.clean_len] {
                let l = usize::from(r.laser & LASER_MASK);
                if elevation[l].is_nan() {
                    elevation[l] = r.elevation;
                    found += 1;
                    if found == slots.lasers() {
                        break;
                    }
                }
            }
            let mut words = [0u64; CHUNK];
            let mut start = 0;
            while start < n {
                let end = (start + CHUNK).min(n);
                rng.fill(&mut words[..end - start]);
                for (k, i) in (start..end).enumerate() {
                    let w = words[k];
                    if unit(w) >= self.scatter_probability
                        || i >= frame.clean_len
                        || !frame.fate[i].is_alive()
                        || !self.damaged(frame.clean[i].laser)
                    {
                        continue;
                    }
                    let slot = slots.slot_of(i);
                    if dual && slots.occupants(slot).next() != Some(i) {
                        // Handled with the slot's last return.
                        continue;
                    }
                    let (n_az, n_el) = normals(w);
                    let r = &frame.clean[i];
                    let (f, _) = slots.split(slot);
                    let target_el = r.elevation as f64 + self.scatter_sigma_deg * n_el;
                    let laser = (0..MAX_LASERS as u8)
                        .filter(|&l| !elevation[usize::from(l)].is_nan())
                        .min_by(|&a, &b| {
                            let da = (f64::from(elevation[usize::from(a)]) - target_el).abs();
                            let db = (f64::from(elevation[usize::from(b)]) - target_el).abs();
                            da.total_cmp(&db)
                        })
                        .unwrap_or(r.laser);
                    let g = deflected_firing(frame, &slots, f, self.scatter_sigma_deg * n_az);
                    let what = match slots.occupants(slots.slot(g, laser)).next() {
                        Some(j) if frame.fate[j].is_alive() => {
                            Scatter::To(frame.range[j], t2 * self.scatter_fraction * frame.power[j])
                        }
                        _ => Scatter::Lost,
                    };
                    for t in slots.occupants(slot) {
                        if t == i || !dual {
                            continue;
                        }
                        if frame.fate[t].is_alive() {
                            scattered.push((t, what));
                        }
                    }
                    scattered.push((i, what));
                }
                start = end;
            }
        }
        if t2 != 1.0 {
            // Power only: the byte follows by the chain's intensity rule.
            // With every laser damaged, skip reading the (large) returns for their laser.
            let all = self.mask == LaserSet::ALL;
            for ((p, fate), r) in frame.power.iter_mut().zip(&frame.fate).zip(&frame.clean) {
                if fate.is_alive() && (all || self.damaged(r.laser)) {
                    *p *= t2;
                }
            }
        }
        if scattered.is_empty() {
            return;
        }
        let model = frame.power_model.clone();
        let clean = &frame.clean;
        frame
            .moved
            .intensity
            .get_or_insert_with(|| clean.iter().map(|r| r.intensity).collect());
        for (i, what) in scattered {
            match what {
                Scatter::To(range, power) => {
                    let p0 = frame.power[i];
                    frame.range[i] = range;
                    frame.power[i] = power;
                    let inten = frame.moved.intensity.as_mut().expect("allocated");
                    inten[i] = match &model {
                        Some(model) => model.echo_intensity(power, range),
                        None if p0 > 0.0 => scale_byte(inten[i], power / p0),
                        None => inten[i],
                    };
                    frame.set_fate(i, Fate::Replaced);
                }
                Scatter::Lost => frame.set_fate(i, Fate::BelowPower),
            }
        }
    }
}

/// Reads the options of a `lens_damage` entry.
pub fn build(opts: &Section<'_>) -> Result<Arc<dyn NoiseStage>> {
    let lasers = opts.id_list("lasers", LASER_MASK)?;
    Ok(Arc::new(LensDamage::new(
        lasers,
        number(opts, "transmission", 0.9, 0.0, 1.0)?,
        number(opts, "scatter_probability", 0.01, 0.0, 1.0)?,
        sigma(opts, "scatter_sigma_deg", 0.5, 45.0)?,
        number(opts, "scatter_fraction", 0.1, 0.0, 1.0)?,
    )))
}

/// The registry entry of this stage.
pub const KIND: StageKind = StageKind {
    name: NAME,
    factor: "10 lens damage",
    model: "chosen lasers: P' = T^2 P; with probability p_s a beam is deflected by N(0, s_d^2) in azimuth and elevation and reports, at its nominal angles, the range of the surface in the deflected direction with power T^2 q P_d",
    source: "engineering assumption (pdiagram-models.md 10: no quantitative lens-damage study was found)",
    options: &[
        OptionSpec { name: "lasers", unit: "laser id", default: "all", doc: "lasers behind the damaged spot (ids from 0 in firing order, below the sensor's lasers; all when left out)" },
        OptionSpec { name: "transmission", unit: "-", default: "0.9", doc: "one-way transmission T_l in [0, 1]; power x T^2" },
        OptionSpec { name: "scatter_probability", unit: "-", default: "0.01", doc: "probability p_s that a beam is deflected" },
        OptionSpec { name: "scatter_sigma_deg", unit: "deg", default: "0.5", doc: "SD s_d of the deflection per axis" },
        OptionSpec { name: "scatter_fraction", unit: "-", default: "0.1", doc: "share q of the deflected echo collected back" },
    ],
    build,
};

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn box_muller_normals_have_unit_spread() {
        let n = 50_000u64;
        let (mut s1, mut s2, mut m) = (0.0, 0.0, 0.0);
        for k in 0..n {
            let (a, b) = normals(k.wrapping_mul(0x2545_f491_4f6c_dd1d));
            s1 += a * a;
            s2 += b * b;
            m += a + b;
        }
        let n = n as f64;
        // SD of a sample variance of n normals: sqrt(2/n) = 0.0063.
        assert!((s1 / n - 1.0).abs() < 0.03 && (s2 / n - 1.0).abs() < 0.03);
        assert!((m / (2.0 * n)).abs() < 0.02);
    }
}
