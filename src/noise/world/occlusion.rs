//! Lens occlusion (factor 12): beams of the selected lasers are blocked or attenuated.
//!
//! Options: exactly one of `lasers = [ids]`, `rings = [rings]` (0 = lowest) or
//! `elevation_deg = [lo, hi]` (inclusive, with 0.005 degree slack so table values such
//! as -5.33 match although stored as f32); optional `azimuth_deg = [from, to]`, the
//! sector clockwise from `from` (inclusive) to `to` (exclusive), which may wrap through
//! 0 (`[300, 60]`); optional `transmission` in [0, 1): 0 (default) blocks the beam —
//! the return is marked `Occluded`, its power and range untouched — while 0 < T < 1
//! attenuates it and keeps the return for the later stages and filters.
//!
//! Transmission convention (shared with `lens_damage`): T is the one-way transmission
//! of the obstruction (dirt, a film, a thin cover), which the pulse crosses on its way
//! out and its echo on the way back, so P' = T^2 P (two-way loss; a film that passes
//! 70 % of the light passes 49 % of the echo). Before issue 29 this stage multiplied by
//! T once; `configs/paper.toml` uses T = 0 (blocked), which this does not touch. The
//! intensity byte follows through the chain's intensity rule (`noise`, "Intensity").

use crate::config::reader::Section;
use crate::error::Result;
use crate::noise::{check_ids, Fate, LaserSet, NoiseStage, NoisyFrame, LASER_MASK};
use crate::sensor::SensorModel;
use rand_chacha::ChaCha8Rng;
use std::sync::Arc;
use toml::Value;

/// The `type` name of this stage.
pub const NAME: &str = "occlusion";

/// Slack on elevation interval bounds, in degrees.
const ELEVATION_SLACK_DEG: f64 = 0.005;

/// Which beams are occluded.
#[derive(Clone, Debug, PartialEq)]
pub enum Selection {
    /// By laser id (firing order, 0 to the sensor's lasers - 1).
    Lasers(Vec<u8>),
    /// By ring (elevation order, 0 = lowest).
    Rings(Vec<u8>),
    /// By elevation interval [lo, hi] in degrees.
    Elevation([f64; 2]),
}

/// The occlusion stage.
#[derive(Clone, Debug)]
pub struct Occlusion {
    /// The occluded beams.
    pub selection: Selection,
    /// Optional azimuth sector [from, to) in degrees, clockwise, may wrap.
    pub azimuth_deg: Option<[f64; 2]>,
    /// One-way transmission T of the obstruction (power x T^2, out and back); 0 blocks.
    pub transmission: f64,
    /// The laser ids (or rings) selected.
    mask: LaserSet,
}

impl Occlusion {
    /// Builds the stage; `selection` and `azimuth_deg` must already be valid.
    pub fn new(selection: Selection, azimuth_deg: Option<[f64; 2]>, transmission: f64) -> Self {
        let mask = match &selection {
            Selection::Lasers(ids) | Selection::Rings(ids) => LaserSet::of(ids),
            Selection::Elevation(_) => LaserSet::NONE,
        };
        Occlusion {
            selection,
            azimuth_deg,
            transmission,
            mask,
        }
    }

    /// True if the beam of this return passes through the obstruction.
    pub fn covers(&self, laser: u8, ring: u8, elevation: f32, azimuth: f32) -> bool {
        let beam = match &self.selection {
            Selection::Lasers(_) => self.mask.contains(laser),
            Selection::Rings(_) => self.mask.contains(ring),
            Selection::Elevation([lo, hi]) => {
                let e = f64::from(elevation);
                e >= lo - ELEVATION_SLACK_DEG && e <= hi + ELEVATION_SLACK_DEG
            }
        };
        beam && self
            .azimuth_deg
            .is_none_or(|s| in_sector(f64::from(azimuth), s))
    }
}

/// True if `azimuth` lies in the clockwise sector [from, to), wrapping through 0.
pub fn in_sector(azimuth: f64, [from, to]: [f64; 2]) -> bool {
    let a = azimuth.rem_euclid(360.0);
    let (from, to) = (from.rem_euclid(360.0), to.rem_euclid(360.0));
    if from <= to {
        a >= from && a < to
    } else {
        a >= from || a < to
    }
}

impl NoiseStage for Occlusion {
    fn kind(&self) -> &'static str {
        NAME
    }

    fn describe(&self) -> String {
        let what = match &self.selection {
            Selection::Lasers(ids) => format!("laser ids {ids:?}"),
            Selection::Rings(r) => format!("rings {r:?}"),
            Selection::Elevation([lo, hi]) => format!("elevations {lo}..{hi} deg"),
        };
        let sector = match self.azimuth_deg {
            Some([a, b]) => format!(", azimuth {a}..{b} deg"),
            None => ", all azimuths".into(),
        };
        let effect = if self.transmission == 0.0 {
            "blocked".to_string()
        } else {
            format!(
                "one-way transmission {}: power x {}",
                self.transmission,
                self.transmission * self.transmission
            )
        };
        format!("{what}{sector}: {effect}")
    }

    fn settings(&self) -> Vec<(&'static str, Value)> {
        let ints = |v: &[u8]| Value::Array(v.iter().map(|&i| Value::Integer(i.into())).collect());
        let floats = |v: [f64; 2]| Value::Array(v.iter().map(|&x| Value::Float(x)).collect());
        let mut out = vec![match &self.selection {
            Selection::Lasers(ids) => ("lasers", ints(ids)),
            Selection::Rings(r) => ("rings", ints(r)),
            Selection::Elevation(e) => ("elevation_deg", floats(*e)),
        }];
        if let Some(s) = self.azimuth_deg {
            out.push(("azimuth_deg", floats(s)));
        }
        out.push(("transmission", Value::Float(self.transmission)));
        out
    }

    fn check_lasers(&self, lasers: usize) -> std::result::Result<(), String> {
        match &self.selection {
            Selection::Lasers(ids) => check_ids("lasers", Some(ids), lasers),
            Selection::Rings(ids) => check_ids("rings", Some(ids), lasers),
            Selection::Elevation(_) => Ok(()),
        }
    }

    fn check_sensor(&self, sensor: &SensorModel) -> std::result::Result<(), String> {
        match self.selection {
            Selection::Elevation([lo, hi]) if !selects_a_laser(sensor, [lo, hi]) => {
                let (min, max) = sensor
                    .elevation_deg
                    .iter()
                    .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &e| {
                        (a.min(e), b.max(e))
                    });
                Err(format!(
                    "elevation_deg [{lo}, {hi}] selects no laser: the {}'s lasers point \
                     from {min} to {max} degrees",
                    sensor.name
                ))
            }
            _ => Ok(()),
        }
    }

    fn apply(&self, frame: &mut NoisyFrame, _rng: &mut ChaCha8Rng) {
        let stage = frame.stage;
        let blocks = self.transmission == 0.0;
        // Out and back through the obstruction.
        let t2 = self.transmission * self.transmission;
        // Every return written, by selects: a beam's returns recur every firing, and a
        // branch a return mispredicts (a slower paper chain).
        for (((r, fate), cause), power) in frame
            .clean
            .iter()
            .zip(frame.fate.iter_mut())
            .zip(frame.cause.iter_mut())
            .zip(frame.power.iter_mut())
        {
            let hit = fate.is_alive() & self.covers(r.laser, r.ring, r.elevation, r.azimuth);
            let occluded = hit & blocks;
            *fate = if occluded { Fate::Occluded } else { *fate };
            *cause = if occluded { stage } else { *cause };
            *power = if hit & !blocks { *power * t2 } else { *power };
        }
    }
}

/// True when a laser of `sensor`'s table lies in the elevation interval (with the slack
/// of [`Occlusion::covers`]; a calibration file moves lasers by hundredths of a degree,
/// and the frame's own elevations decide at run time).
fn selects_a_laser(sensor: &SensorModel, [lo, hi]: [f64; 2]) -> bool {
    sensor
        .elevation_deg
        .iter()
        .any(|&e| e >= lo - ELEVATION_SLACK_DEG && e <= hi + ELEVATION_SLACK_DEG)
}

/// Reads the options of an `occlusion` entry.
pub fn build(opts: &Section<'_>) -> Result<Arc<dyn NoiseStage>> {
    let given: Vec<&str> = ["lasers", "rings", "elevation_deg"]
        .into_iter()
        .filter(|k| opts.has(k))
        .collect();
    if given.len() > 1 {
        return Err(opts.error(
            given[1],
            format!(
                "give only one of lasers, rings, elevation_deg (found {})",
                given.join(" and ")
            ),
        ));
    }
    let selection = if let Some(ids) = opts.id_list("lasers", LASER_MASK)? {
        Selection::Lasers(ids)
    } else if let Some(rings) = opts.id_list("rings", LASER_MASK)? {
        Selection::Rings(rings)
    } else if let Some([lo, hi]) = opts.pair("elevation_deg")? {
        if lo > hi {
            return Err(opts.error(
                "elevation_deg",
                format!("interval [{lo}, {hi}] is empty: lo must not exceed hi"),
            ));
        }
        // An interval between the lasers of every described sensor occludes nothing:
        // refuse it like `lasers = []`. The capture's own sensor is checked once it is
        // known ([`NoiseStage::check_sensor`]).
        if !crate::sensor::MODELS
            .iter()
            .any(|m| selects_a_laser(m, [lo, hi]))
        {
            return Err(opts.error(
                "elevation_deg",
                format!("[{lo}, {hi}] selects no laser of any described sensor"),
            ));
        }
        Selection::Elevation([lo, hi])
    } else {
        return Err(opts.error(
            "",
            "occlusion needs one of lasers = [...], rings = [...] or elevation_deg = [lo, hi]",
        ));
    };
    let azimuth = opts.pair("azimuth_deg")?;
    if let Some([from, to]) = azimuth {
        for (i, a) in [from, to].into_iter().enumerate() {
            if !(0.0..=360.0).contains(&a) {
                return Err(opts.error(
                    &format!("azimuth_deg[{i}]"),
                    format!("{a} is outside [0, 360] degrees"),
                ));
            }
        }
        if from.rem_euclid(360.0) == to.rem_euclid(360.0) {
            return Err(opts.error(
                "azimuth_deg",
                "the sector is empty (from == to); leave azimuth_deg out for the full turn",
            ));
        }
    }
    let transmission = opts.f64("transmission")?.unwrap_or(0.0);
    if !(0.0..1.0).contains(&transmission) {
        return Err(opts.error(
            "transmission",
            format!("{transmission} is outside [0, 1): 0 blocks, 0 < t < 1 attenuates"),
        ));
    }
    Ok(Arc::new(Occlusion::new(selection, azimuth, transmission)))
}

/// The registry entry of this stage.
pub const KIND: crate::noise::StageKind = crate::noise::StageKind {
    name: NAME,
    factor: "12 obstruction (lens occlusion)",
    model: "beams of the selected lasers (optionally in an azimuth sector) are blocked, or their power multiplied by T^2 (one-way transmission T, out and back)",
    source: "the reference study (five occluded lasers); noise-models.md",
    options: &[
        crate::noise::registry::OptionSpec { name: "lasers", unit: "laser id", default: "one of lasers/rings/elevation_deg required", doc: "occluded lasers (ids from 0 in firing order, below the sensor's lasers)" },
        crate::noise::registry::OptionSpec { name: "rings", unit: "ring", default: "-", doc: "occluded rings (0 = lowest)" },
        crate::noise::registry::OptionSpec { name: "elevation_deg", unit: "deg", default: "-", doc: "occluded elevation interval [lo, hi]" },
        crate::noise::registry::OptionSpec { name: "azimuth_deg", unit: "deg", default: "all", doc: "sector [from, to), clockwise, may wrap" },
        crate::noise::registry::OptionSpec { name: "transmission", unit: "-", default: "0", doc: "one-way transmission T: 0 blocks the beam, 0 < T < 1 scales power by T^2 (out and back)" },
    ],
    build,
};

#[cfg(test)]
mod tests {
    use super::*;
    use crate::frame::Return;
    use rand::SeedableRng;

    /// Whole beams by laser or by ring with nothing let through occlude exactly the live
    /// returns the rule `covers` names, leave returns an earlier stage dropped as they
    /// were, and write the stage as the cause.
    #[test]
    fn whole_beams_occlude_exactly_the_live_returns_of_the_rule() {
        let clean: Vec<Return> = (0..3000u32)
            .map(|k| Return {
                range: 5.0 + (k % 50) as f32,
                laser: (k % 64) as u8,
                ring: ((k * 7) % 64) as u8,
                azimuth: (k / 64) as f32 * 0.17,
                packet: k / 384,
                block: ((k / 64) % 6) as u8,
                ..Return::BLANK
            })
            .collect();
        let ideal = crate::noise::IdealPower::new(
            &crate::config::PowerConfig::default(),
            &crate::config::SensorConfig::default(),
            &crate::config::DetectionConfig::default(),
        );
        let dead = [Fate::BelowPower, Fate::BelowMinRange, Fate::Occluded];
        for selection in [
            Selection::Lasers(vec![7, 5, 3, 1, 30, 63]),
            Selection::Rings(vec![0, 15, 16, 40]),
        ] {
            let stage = Occlusion::new(selection.clone(), None, 0.0);
            let mut frame = NoisyFrame::new(0, clean.clone(), &ideal);
            frame.stage = 4;
            // Every third return dropped or occluded already, by stage 2.
            for (i, (f, c)) in frame.fate.iter_mut().zip(&mut frame.cause).enumerate() {
                if i % 3 == 0 {
                    *f = dead[i / 3 % dead.len()];
                    *c = 2;
                }
            }
            let (before, causes) = (frame.fate.clone(), frame.cause.clone());
            stage.apply(&mut frame, &mut ChaCha8Rng::seed_from_u64(1));
            let mut hits = 0;
            for (i, r) in clean.iter().enumerate() {
                let hit =
                    before[i].is_alive() && stage.covers(r.laser, r.ring, r.elevation, r.azimuth);
                hits += usize::from(hit);
                let want = if hit {
                    (Fate::Occluded, 4)
                } else {
                    (before[i], causes[i])
                };
                assert_eq!((frame.fate[i], frame.cause[i]), want, "{selection:?}: {i}");
            }
            assert!(hits > 100, "{selection:?}: {hits}");
        }
    }
}
