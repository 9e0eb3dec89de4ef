//! Motion (p-diagram 08): the vehicle moves during the 0.1 s sweep (rolling shutter) and
//! vibrates.
//!
//! Model (pdiagram-models.md, 08): constant twist over the frame, forward speed v along
//! +x and yaw rate omega; dt = t_i - t_ref with t_ref the frame's first firing time
//! (`t_ref = "start"`, default) or the middle of its first and last (`"middle"`). A true
//! point p is reported as p' = Rz(omega dt)^T (p - v dt x) (read as if taken at t_ref).
//! Vibration: roll and pitch d(t) = A sin(2 pi f dt + phi), phases uniform per frame
//! (frame stream, two draws), applied as a rotation after the ego motion. The rotation
//! is evaluated once per firing (the doc's "one pose per firing"; within a firing times
//! differ by at most 36 us), the translation per return from its own time. Points move
//! in the sensor frame before any mounting error (`mounting` acts last in either chain
//! order). Range, azimuth and time fields stay as reported. Source: Zhang and Singh,
//! LOAM, RSS 2014; vibration values engineering assumption.
//!
//! Defaults: a scenario's conditions, not the unit's: no ego-motion, a mild vibration
//! (`sensor`, "What the defaults stand for").

use super::{float, number, sin_plus, FiringPose, Pose, Poses, SineTrack};
use crate::config::reader::Section;
use crate::error::Result;
use crate::noise::registry::OptionSpec;
use crate::noise::{NoiseStage, NoisyFrame, StageKind};
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use std::sync::Arc;
use toml::Value;

/// The `type` name of this stage.
pub const NAME: &str = "motion";

/// The motion stage.
#[derive(Clone, Debug)]
pub struct Motion {
    /// Forward speed, m/s.
    pub speed_mps: f64,
    /// Yaw rate, deg/s.
    pub yaw_rate_deg_s: f64,
    /// Reference time at the middle of the frame instead of its start.
    pub t_ref_middle: bool,
    /// Vibration amplitude (roll and pitch), degrees.
    pub vibration_deg: f64,
    /// Vibration frequency, Hz.
    pub vibration_hz: f64,
}

impl NoiseStage for Motion {
    fn kind(&self) -> &'static str {
        NAME
    }
    fn uses_layout(&self) -> bool {
        true
    }
    fn describe(&self) -> String {
        format!(
            "ego speed {} m/s, yaw rate {} deg/s (t_ref = frame {}), vibration {} deg at {} Hz",
            self.speed_mps,
            self.yaw_rate_deg_s,
            if self.t_ref_middle { "middle" } else { "start" },
            self.vibration_deg,
            self.vibration_hz
        )
    }
    fn settings(&self) -> Vec<(&'static str, Value)> {
        vec![
            ("speed_mps", float(self.speed_mps)),
            ("yaw_rate_deg_s", float(self.yaw_rate_deg_s)),
            (
                "t_ref",
                Value::String(if self.t_ref_middle { "middle" } else { "start" }.into()),
            ),
            ("vibration_deg", float(self.vibration_deg)),
            ("vibration_hz", float(self.vibration_hz)),
        ]
    }
    fn apply(&self, frame: &mut NoisyFrame, rng: &mut ChaCha8Rng) {
        // Phases first and always, so the stream does not depend on the magnitudes.
        let phi = [
            rng.random::<f64>() * std::f64::consts::TAU,
            rng.random::<f64>() * std::f64::consts::TAU,
        ];
        let vib = self.vibration_deg.to_radians();
        if self.speed_mps == 0.0 && self.yaw_rate_deg_s == 0.0 && vib == 0.0 {
            return;
        }
        let n = frame.len();
        let first = frame.clean.first().map_or(0.0, |r| r.time);
        let last = frame.clean.last().map_or(0.0, |r| r.time);
        let t_ref = if self.t_ref_middle {
            0.5 * (first + last)
        } else {
            first
        };
        let omega = self.yaw_rate_deg_s.to_radians();
        let w = std::f64::consts::TAU * self.vibration_hz;
        // One pose per firing (the returns of a data block): the rotation at the
        // firing's time, and a velocity term that moves each return by its own time:
        // p' = R (p - v dt x) = R p + (-v R x) dt.
        // One pose per firing of the frame's layout (consecutive returns with the same
        // packet and block); the time of a firing is that of its first return.
        let lay = frame.layout();
        let mut firings = Vec::with_capacity(lay.firings.len());
        let mut index = Vec::with_capacity(n);
        // The pose is a function of the firing's time alone: consecutive firings with the
        // same time (frames whose returns carry no firing time) share one entry.
        let mut last_dt = None;
        // sin and cos of w dt carried from firing to firing ([`SineTrack`], within 1e-13
        // of libm's; a 20 Hz phase moves 0.006 rad per firing), the phases added by
        // angle addition: two libm sines per firing were most of this stage's time.
        let phases = phi.map(f64::sin_cos);
        let mut track = SineTrack::default();
        for &[start, end] in &lay.firings {
            let dt = lay.time[start as usize] - t_ref;
            if last_dt != Some(dt.to_bits()) {
                last_dt = Some(dt.to_bits());
                let sc = track.at(w * dt);
                let roll = vib * sin_plus(sc, phases[0]);
                let pitch = vib * sin_plus(sc, phases[1]);
                let rot = Pose::tilt_after_yaw(roll, pitch, -omega * dt);
                let velocity = [0, 1, 2].map(|k| -self.speed_mps * rot.r[k][0]);
                firings.push(FiringPose {
                    pose: rot,
                    velocity,
                });
            }
            index.resize(end as usize, firings.len() as u32 - 1);
        }
        let poses = Poses {
            t_ref,
            firings,
            index: Some(index),
        };
        frame.moved.pose = Some(match frame.moved.pose.take() {
            None => poses,
            // Whatever is already there (a mount) acts after the motion.
            Some(existing) => existing.after(poses),
        });
    }
}

/// Reads the options of a `motion` entry.
pub fn build(opts: &Section<'_>) -> Result<Arc<dyn NoiseStage>> {
    let t_ref_middle = matches!(opts.choice("t_ref", &["start", "middle"])?, Some("middle"));
    Ok(Arc::new(Motion {
        speed_mps: number(opts, "speed_mps", 0.0, -100.0, 100.0)?,
        yaw_rate_deg_s: number(opts, "yaw_rate_deg_s", 0.0, -360.0, 360.0)?,
        t_ref_middle,
        vibration_deg: number(opts, "vibration_deg", 0.05, 0.0, 10.0)?,
        vibration_hz: number(opts, "vibration_hz", 20.0, 0.0, 1000.0)?,
    }))
}

/// The registry entry of this stage.
pub const KIND: StageKind = StageKind {
    name: NAME,
    factor: "08 motion (rolling shutter, vibration)",
    model: "p' = Rz(omega dt)^T (p - v dt x), dt = t - t_ref; vibration roll/pitch A sin(2 pi f dt + phi)",
    source: "Zhang and Singh, LOAM, RSS 2014; vibration engineering assumption (pdiagram-models.md 08)",
    options: &[
        OptionSpec { name: "speed_mps", unit: "m/s", default: "0", doc: "forward (+x) ego speed" },
        OptionSpec { name: "yaw_rate_deg_s", unit: "deg/s", default: "0", doc: "ego yaw rate" },
        OptionSpec { name: "t_ref", unit: "-", default: "\"start\"", doc: "reference time: \"start\" or \"middle\" of the frame" },
        OptionSpec { name: "vibration_deg", unit: "deg", default: "0.05", doc: "roll/pitch vibration amplitude" },
        OptionSpec { name: "vibration_hz", unit: "Hz", default: "20", doc: "vibration frequency" },
    ],
    build,
};
