//! Clock (p-diagram 09): time-of-flight bias and jitter become range error c*dt/2; an
//! oscillator frequency error scales range and stretches the frame's timestamps.
//!
//! Model (pdiagram-models.md, 09): R' = R*(1 + e) + c*b/2 + N(0, (c*s/2)^2);
//! t' = t_0 + (t - t_0)*(1 + e) + offset, with t_0 the frame's first firing time (the
//! doc's t*(1 + e) over the whole capture would shift frames by up to 0.18 s per hour
//! at 50 ppm; per frame keeps the timestamps of one rotation consistent and is what the
//! PLY's frame-relative `time` shows). Range is not re-quantised to 2 mm (no stage of
//! this tool does). Source: physics; magnitudes are engineering assumptions so that clock
//! plus receiver noise stay within the datasheet's 2 cm. The defaults are the spread
//! between units, to add to a recording (`sensor`, "What the defaults stand for"):
//! jitter 20 ps (3 mm; 70 ps, 1.05 cm, before issue 29, is about a whole sensor's
//! timing noise and counted it twice on a recording), drift 50 ppm (a common crystal
//! tolerance). One normal draw per return
//! when `jitter_ps > 0`, from the stage's frame stream.

use super::{fill_normals, float, number, sigma, CHUNK, C_M_PER_S};
use crate::config::reader::Section;
use crate::error::Result;
use crate::noise::registry::OptionSpec;
use crate::noise::{NoiseStage, NoisyFrame, StageKind, TimeStretch};
use rand_chacha::ChaCha8Rng;
use std::sync::Arc;
use toml::Value;

/// The `type` name of this stage.
pub const NAME: &str = "clock";

/// The clock stage.
#[derive(Clone, Debug)]
pub struct Clock {
    /// ToF bias in ns.
    pub bias_ns: f64,
    /// ToF jitter standard deviation in ps.
    pub jitter_ps: f64,
    /// Frequency error in ppm.
    pub drift_ppm: f64,
    /// Timestamp offset in microseconds.
    pub time_offset_us: f64,
}

impl NoiseStage for Clock {
    fn kind(&self) -> &'static str {
        NAME
    }
    fn describe(&self) -> String {
        format!(
            "ToF bias {} ns ({:.4} m), jitter {} ps ({:.4} m), drift {} ppm, time offset {} us",
            self.bias_ns,
            C_M_PER_S * self.bias_ns * 1e-9 / 2.0,
            self.jitter_ps,
            C_M_PER_S * self.jitter_ps * 1e-12 / 2.0,
            self.drift_ppm,
            self.time_offset_us
        )
    }
    fn settings(&self) -> Vec<(&'static str, Value)> {
        vec![
            ("bias_ns", float(self.bias_ns)),
            ("jitter_ps", float(self.jitter_ps)),
            ("drift_ppm", float(self.drift_ppm)),
            ("time_offset_us", float(self.time_offset_us)),
        ]
    }
    fn apply(&self, frame: &mut NoisyFrame, rng: &mut ChaCha8Rng) {
        let bias_m = C_M_PER_S * self.bias_ns * 1e-9 / 2.0;
        let sigma_m = C_M_PER_S * self.jitter_ps * 1e-12 / 2.0;
        let scale = 1.0 + self.drift_ppm * 1e-6;
        if bias_m != 0.0 || sigma_m != 0.0 || scale != 1.0 {
            // Draw before the fate test: one draw per return keeps streams aligned. The
            // draws of a chunk of returns are made first (same order; see `CHUNK`).
            let mut buf = [0.0f64; CHUNK];
            for (ranges, fates) in frame.range.chunks_mut(CHUNK).zip(frame.fate.chunks(CHUNK)) {
                let draws = &mut buf[..ranges.len()];
                if sigma_m > 0.0 {
                    fill_normals(rng, draws);
                }
                for ((range, fate), n) in ranges.iter_mut().zip(fates).zip(draws.iter()) {
                    if fate.is_alive() {
                        *range = (f64::from(*range) * scale + bias_m + sigma_m * n) as f32;
                    }
                }
            }
        }
        if scale != 1.0 || self.time_offset_us != 0.0 {
            // The stretch is kept as a map of the frame's times, applied where a time is
            // reported (see `TimeStretch`): the same operations on the same times as
            // writing every stretched time here, so the same values, without the pass
            // over 400 kB of times and the 400 kB vector.
            frame.moved.time_stretch.push(TimeStretch {
                t0: super::frame_start(frame),
                scale,
                offset: self.time_offset_us * 1e-6,
                len: frame.len(),
            });
        }
    }
}

/// Reads the options of a `clock` entry.
pub fn build(opts: &Section<'_>) -> Result<Arc<dyn NoiseStage>> {
    Ok(Arc::new(Clock {
        bias_ns: number(opts, "bias_ns", 0.0, -100.0, 100.0)?,
        jitter_ps: sigma(opts, "jitter_ps", 20.0, 10_000.0)?,
        drift_ppm: number(opts, "drift_ppm", 50.0, -10_000.0, 10_000.0)?,
        time_offset_us: number(opts, "time_offset_us", 0.0, -1e6, 1e6)?,
    }))
}

/// The registry entry of this stage.
pub const KIND: StageKind = StageKind {
    name: NAME,
    factor: "09 clock",
    model: "R' = R(1+e) + c b/2 + N(0, (c s/2)^2); t' = t0 + (t - t0)(1+e) + offset (t0: frame start)",
    source: "physics (c dt/2); magnitudes engineering assumptions within the 2 cm datasheet accuracy (pdiagram-models.md 09)",
    options: &[
        OptionSpec { name: "bias_ns", unit: "ns", default: "0", doc: "time-of-flight bias (1 ns = 0.1499 m)" },
        OptionSpec { name: "jitter_ps", unit: "ps", default: "20", doc: "Gaussian ToF jitter SD added (20 ps = 3 mm; 70 ps = 1.05 cm is about a whole sensor's)" },
        OptionSpec { name: "drift_ppm", unit: "ppm", default: "50", doc: "oscillator frequency error: range scale and timestamp stretch" },
        OptionSpec { name: "time_offset_us", unit: "us", default: "0", doc: "timestamp offset" },
    ],
    build,
};
