//! What the stages of a chain change beyond a return's range and intensity: its
//! direction, the sensor's pose or the firing time, which a data packet cannot carry
//! (azimuths are per firing, elevations the calibration's, times the packet's timestamp).
//!
//! Each stage is applied alone to a probe rotation (180 firings of the HDL-32E's 32
//! lasers at 10 m) and what it reports changed is read back. Probing rather than listing
//! stage types keeps the answer right for a stage configured at zero magnitude (no
//! change) and for stages added later.

use super::{stage_rng, NoiseChain, NoisyFrame};
use crate::frame::{Return, ReturnKind};
use crate::sensor::HDL32E;

/// A stage of a chain that changes what a data packet cannot carry.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct GeometryChange {
    /// Index of the stage in the chain (`noise[i]`).
    pub stage: usize,
    /// The stage's `type`.
    pub kind: &'static str,
    /// What it changes: "azimuth", "elevation", "position (pose)", "firing time".
    pub what: Vec<&'static str>,
}

impl NoiseChain {
    /// The stages that change a return's azimuth, elevation, position or firing time,
    /// each applied alone to a probe rotation with its stream of `seed`.
    pub fn geometry_changes(&self, seed: u64) -> Vec<GeometryChange> {
        let probe = probe_returns();
        let mut changes = Vec::new();
        for (i, stage) in self.stages().iter().enumerate() {
            let mut frame = NoisyFrame::new(0, probe.clone(), self.ideal_power());
            frame.threshold = 0.0;
            let mut rng = stage_rng(seed, 0, i as u32);
            stage.apply(&mut frame, &mut rng);
            let m = &frame.moved;
            let mut what = Vec::new();
            let nonzero =
                |v: &Option<Vec<f32>>| v.as_ref().is_some_and(|v| v.iter().any(|&a| a != 0.0));
            if nonzero(&m.azimuth_deg) {
                what.push("azimuth");
            }
            if nonzero(&m.elevation_deg) {
                what.push("elevation");
            }
            if m.pose.as_ref().is_some_and(|poses| {
                probe.iter().enumerate().any(|(i, r)| {
                    poses.of(i).apply([r.x, r.y, r.z], r.time - poses.t_ref) != [r.x, r.y, r.z]
                })
            }) {
                what.push("position (pose)");
            }
            if (m.time.is_some() || !m.time_stretch.is_empty())
                && probe
                    .iter()
                    .enumerate()
                    .any(|(i, r)| m.reported_time(i, r.time) != r.time)
            {
                what.push("firing time");
            }
            if !what.is_empty() {
                changes.push(GeometryChange {
                    stage: i,
                    kind: stage.kind(),
                    what,
                });
            }
        }
        changes
    }
}

/// A synthetic rotation in the HDL-32E's laser geometry, for
/// [`NoiseChain::geometry_changes`].
fn probe_returns() -> Vec<Return> {
    let model = &HDL32E;
    let rings = model.rings();
    let mut out = Vec::with_capacity(180 * model.lasers);
    for f in 0..180u32 {
        let az = f as f32 * 2.0;
        for (j, &elevation) in model.elevation_deg.iter().enumerate() {
            let range = 10.0f32;
            let (w, a) = (elevation.to_radians() as f32, az.to_radians());
            out.push(Return {
                x: range * w.cos() * a.cos(),
                y: -range * w.cos() * a.sin(),
                z: range * w.sin(),
                range,
                azimuth: az,
                elevation: elevation as f32,
                time: 1.0 + f64::from(f) * 46.08e-6 + j as f64 * 1.152e-6,
                packet: f / 12,
                raw_distance: 5000,
                intensity: 40,
                laser: j as u8,
                ring: rings[j],
                block: (f % 12) as u8,
                kind: ReturnKind::Strongest,
            });
        }
    }
    out
}
