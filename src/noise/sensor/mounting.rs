//! Mounting (p-diagram 02): extrinsic error between the sensor and the vehicle frame.
//!
//! Model (pdiagram-models.md, 02): p' = Rot(roll, pitch, yaw) * p + t with a proper
//! rotation Rz(yaw) Ry(pitch) Rx(roll); each angle is the fixed value plus
//! N(0, sigma_rot_deg^2), each translation axis the fixed value plus N(0, sigma_t_m^2),
//! drawn once per seed from the stage's unit stream (not per frame: a rigid mount).
//! Points move; range, azimuth and intensity stay as the sensor reports them.
//! Source: 3D_Corruptions_AD spatial alignment noise (Dong et al., CVPR 2023) for the
//! kind of error; defaults (0.2 deg, 0.02 m, a calibrated rig) are engineering assumptions.
//!
//! Defaults: the spread between installations of a calibrated rig, to add to a
//! recording (`sensor`, "What the defaults stand for").

use super::{float, normal, number, sigma, Pose, Poses};
use crate::config::reader::Section;
use crate::error::Result;
use crate::noise::registry::OptionSpec;
use crate::noise::{NoiseStage, NoisyFrame, StageKind};
use rand_chacha::ChaCha8Rng;
use std::sync::Arc;
use toml::Value;

/// The `type` name of this stage.
pub const NAME: &str = "mounting";

/// The mounting stage.
#[derive(Clone, Debug)]
pub struct Mounting {
    /// Fixed roll, pitch, yaw in degrees.
    pub rpy_deg: [f64; 3],
    /// Fixed translation x, y, z in metres.
    pub t_m: [f64; 3],
    /// SD of each angle drawn per seed, degrees.
    pub sigma_rot_deg: f64,
    /// SD of each translation axis drawn per seed, metres.
    pub sigma_t_m: f64,
    /// The pose in use (fixed part plus the unit draws once made).
    pub pose: Pose,
}

impl Mounting {
    fn pose_of(rpy: [f64; 3], t: [f64; 3]) -> Pose {
        Pose::from_rpy(
            rpy[0].to_radians(),
            rpy[1].to_radians(),
            rpy[2].to_radians(),
            t,
        )
    }
}

impl NoiseStage for Mounting {
    fn kind(&self) -> &'static str {
        NAME
    }
    fn describe(&self) -> String {
        format!(
            "roll/pitch/yaw {:?} deg + N(0, {}^2), translation {:?} m + N(0, {}^2), drawn once per seed",
            self.rpy_deg, self.sigma_rot_deg, self.t_m, self.sigma_t_m
        )
    }
    fn settings(&self) -> Vec<(&'static str, Value)> {
        vec![
            ("roll_deg", float(self.rpy_deg[0])),
            ("pitch_deg", float(self.rpy_deg[1])),
            ("yaw_deg", float(self.rpy_deg[2])),
            ("x_m", float(self.t_m[0])),
            ("y_m", float(self.t_m[1])),
            ("z_m", float(self.t_m[2])),
            ("sigma_rot_deg", float(self.sigma_rot_deg)),
            ("sigma_t_m", float(self.sigma_t_m)),
        ]
    }
    fn with_unit_draws(&self, rng: &mut ChaCha8Rng) -> Option<Arc<dyn NoiseStage>> {
        // Always six draws, so the translation draws do not depend on sigma_rot_deg.
        let d: Vec<f64> = (0..6).map(|_| normal(rng)).collect();
        let rpy = [0, 1, 2].map(|i| self.rpy_deg[i] + self.sigma_rot_deg * d[i]);
        let t = [0, 1, 2].map(|i| self.t_m[i] + self.sigma_t_m * d[3 + i]);
        let mut s = self.clone();
        s.pose = Mounting::pose_of(rpy, t);
        Some(Arc::new(s))
    }
    fn apply(&self, frame: &mut NoisyFrame, _rng: &mut ChaCha8Rng) {
        if self.pose == Pose::IDENTITY {
            return;
        }
        // The mount acts last: whatever moved the point in the sensor frame (motion,
        // vibration) happened before the sensor-to-vehicle transform. One product per
        // firing pose, not per return.
        match &mut frame.moved.pose {
            None => frame.moved.pose = Some(Poses::uniform(self.pose)),
            Some(poses) => poses.then(&self.pose),
        }
    }
}

/// Reads the options of a `mounting` entry.
pub fn build(opts: &Section<'_>) -> Result<Arc<dyn NoiseStage>> {
    let rpy_deg = [
        number(opts, "roll_deg", 0.0, -90.0, 90.0)?,
        number(opts, "pitch_deg", 0.0, -90.0, 90.0)?,
        number(opts, "yaw_deg", 0.0, -180.0, 180.0)?,
    ];
    let t_m = [
        number(opts, "x_m", 0.0, -10.0, 10.0)?,
        number(opts, "y_m", 0.0, -10.0, 10.0)?,
        number(opts, "z_m", 0.0, -10.0, 10.0)?,
    ];
    Ok(Arc::new(Mounting {
        rpy_deg,
        t_m,
        sigma_rot_deg: sigma(opts, "sigma_rot_deg", 0.2, 45.0)?,
        sigma_t_m: sigma(opts, "sigma_t_m", 0.02, 10.0)?,
        pose: Mounting::pose_of(rpy_deg, t_m),
    }))
}

/// The registry entry of this stage.
pub const KIND: StageKind = StageKind {
    name: NAME,
    factor: "02 mounting (extrinsic error)",
    model: "p' = Rz(yaw) Ry(pitch) Rx(roll) p + t; angles and translation fixed plus N(0, sigma^2) drawn once per seed",
    source: "3D_Corruptions_AD spatial alignment noise (Dong et al., CVPR 2023); defaults engineering assumption (calibrated rig)",
    options: &[
        OptionSpec { name: "roll_deg", unit: "deg", default: "0", doc: "fixed roll about x, in [-90, 90]" },
        OptionSpec { name: "pitch_deg", unit: "deg", default: "0", doc: "fixed pitch about y, in [-90, 90]" },
        OptionSpec { name: "yaw_deg", unit: "deg", default: "0", doc: "fixed yaw about z (+x towards +y), in [-180, 180]" },
        OptionSpec { name: "x_m", unit: "m", default: "0", doc: "fixed translation x" },
        OptionSpec { name: "y_m", unit: "m", default: "0", doc: "fixed translation y" },
        OptionSpec { name: "z_m", unit: "m", default: "0", doc: "fixed translation z" },
        OptionSpec { name: "sigma_rot_deg", unit: "deg", default: "0.2", doc: "SD of each angle, drawn once per seed" },
        OptionSpec { name: "sigma_t_m", unit: "m", default: "0.02", doc: "SD of each translation axis, drawn once per seed" },
    ],
    build,
};
