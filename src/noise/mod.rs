//! The noise chain: ideal power, noise stages in configured order, detection filters.
//!
//! A frame enters as clean returns; [`NoiseChain::process`] gives each return an ideal
//! power (see [`power`]), runs the `[[noise]]` stages in file order on a [`NoisyFrame`]
//! and then the detection filters (see [`detection`]). Nothing is removed from the
//! arrays: each return gets a [`Fate`], and [`NoisyFrame::survivors`] builds the
//! surviving returns with their noisy range and coordinates.
//!
//! # Adding a stage
//! Write one file with a type implementing [`NoiseStage`] and a `build` function reading
//! its options from a `Section`, then add one [`StageKind`] line to [`REGISTRY`]. A
//! stage sees only its own options, the frame being processed and its own random stream.
//!
//! # Random streams
//! Every stage of every frame draws from its own ChaCha8 stream:
//! key = `ChaCha8Rng::seed_from_u64(seed)`, stream number =
//! `frame_index << 32 | stage_tag`, where `stage_tag = fnv1a16(type) << 16 | occurrence`
//! (occurrence = how many stages of the same `type` come earlier in the chain). Keying by
//! type and occurrence rather than by chain position means adding or removing another
//! stage (say, the occlusion) leaves the rain draws unchanged, so "rain alone" and
//! "rain + occlusion" use common random numbers. Because every frame has its own stream,
//! frames can be processed in any order on any number of threads with identical results.

pub mod detection;
pub mod power;
pub mod registry;
pub mod summary;
pub mod world;

pub use registry::{build_stage, StageKind, REGISTRY};
pub use world::{occlusion, rain};

use crate::config::Config;
use crate::frame::{Frame, Return};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use serde::Serialize;
use std::sync::Arc;

pub use detection::apply_detection;
pub use power::{IdealPower, PowerConstants};
pub use summary::NoiseSummary;

/// What happened to a return; the first cause in pipeline order wins.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize)]
#[serde(rename_all = "snake_case")]
#[repr(u8)]
pub enum Fate {
    /// Survives the chain and the filters.
    Kept = 0,
    /// Removed by an occlusion stage (the beam was never emitted).
    Occluded = 1,
    /// Noisy power under the detection threshold.
    BelowPower = 2,
    /// Noisy range under the minimum range.
    BelowMinRange = 3,
}

impl Fate {
    /// The causes of removal, in pipeline order.
    pub const DROPS: [Fate; 3] = [Fate::Occluded, Fate::BelowPower, Fate::BelowMinRange];

    /// Short snake_case name (as in reports).
    pub fn name(self) -> &'static str {
        match self {
            Fate::Kept => "kept",
            Fate::Occluded => "occluded",
            Fate::BelowPower => "below_power",
            Fate::BelowMinRange => "below_min_range",
        }
    }
}

/// One frame on its way through the chain: clean returns plus per-return noisy state.
///
/// All vectors have one entry per clean return, in the clean order.
#[derive(Clone, Debug, Default)]
pub struct NoisyFrame {
    /// Index of the frame in the capture (keys the random streams).
    pub index: u32,
    /// The returns as recorded.
    pub clean: Vec<Return>,
    /// Current range in metres (the clean range until a stage changes it).
    pub range: Vec<f32>,
    /// Current power as a fraction of emitted power (the ideal power at first).
    pub power: Vec<f64>,
    /// Current fate; stages and filters only change `Kept` entries.
    pub fate: Vec<Fate>,
}

impl NoisyFrame {
    /// Starts a noisy frame: ranges are the clean ranges, powers the ideal powers.
    pub fn new(index: u32, clean: Vec<Return>, ideal: &IdealPower) -> Self {
        let range = clean.iter().map(|r| r.range).collect();
        let power = clean
            .iter()
            .map(|r| ideal.power(r.intensity, r.range))
            .collect();
        let fate = vec![Fate::Kept; clean.len()];
        NoisyFrame {
            index,
            clean,
            range,
            power,
            fate,
        }
    }

    /// Number of returns (clean and noisy alike).
    pub fn len(&self) -> usize {
        self.clean.len()
    }

    /// True if the frame has no returns.
    pub fn is_empty(&self) -> bool {
        self.clean.is_empty()
    }

    /// Indices (into `clean`) of the returns that survived, in clean order.
    pub fn kept_indices(&self) -> Vec<u32> {
        (0..self.len() as u32)
            .filter(|&i| self.fate[i as usize] == Fate::Kept)
            .collect()
    }

    /// The surviving returns with the noisy range; x, y, z are scaled by R_n / R_i so the
    /// point moves along its beam. Pairs with [`NoisyFrame::kept_indices`].
    pub fn survivors(&self) -> Vec<Return> {
        self.clean
            .iter()
            .zip(&self.range)
            .zip(&self.fate)
            .filter(|(_, &f)| f == Fate::Kept)
            .map(|((r, &rn), _)| {
                let mut out = *r;
                // A zero clean range has no direction to scale along; keep the point.
                if r.range > 0.0 {
                    let s = rn / r.range;
                    out.x *= s;
                    out.y *= s;
                    out.z *= s;
                }
                out.range = rn;
                out
            })
            .collect()
    }

    /// Counts and range statistics of this frame.
    pub fn summary(&self) -> NoiseSummary {
        NoiseSummary::from_frame(self)
    }
}

/// One noise factor acting on the powers and ranges of a frame.
pub trait NoiseStage: Send + Sync + std::fmt::Debug {
    /// The `type` of the stage in `[[noise]]`.
    fn kind(&self) -> &'static str;
    /// One line for humans: what the stage does with which settings.
    fn describe(&self) -> String;
    /// The effective options (without `type`), for reports and `effective_toml`.
    fn settings(&self) -> Vec<(&'static str, toml::Value)>;
    /// Applies the stage to the frame, drawing only from `rng` (this stage's stream for
    /// this frame). Only returns whose fate is still `Kept` may be changed.
    fn apply(&self, frame: &mut NoisyFrame, rng: &mut ChaCha8Rng);
}

/// 16-bit FNV-1a of a stage type name: a stable number for the stream derivation.
fn fnv1a16(name: &str) -> u64 {
    let mut h: u32 = 0x811c_9dc5;
    for b in name.bytes() {
        h ^= u32::from(b);
        h = h.wrapping_mul(0x0100_0193);
    }
    u64::from((h >> 16) ^ (h & 0xffff))
}

/// The random stream of one stage in one frame (see the module documentation).
pub fn stage_rng(seed: u64, frame_index: u32, stage_tag: u32) -> ChaCha8Rng {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    rng.set_stream((u64::from(frame_index) << 32) | u64::from(stage_tag));
    rng
}

/// Stream tags of a chain of stage types: type hash and occurrence of that type.
pub fn stage_tags(kinds: &[&str]) -> Vec<u32> {
    kinds
        .iter()
        .enumerate()
        .map(|(i, kind)| {
            let occurrence = kinds[..i].iter().filter(|k| *k == kind).count() as u64;
            ((fnv1a16(kind) << 16) | (occurrence & 0xffff)) as u32
        })
        .collect()
}

/// The configured chain, ready to process frames (shareable between threads).
#[derive(Clone, Debug)]
pub struct NoiseChain {
    seed: u64,
    power: IdealPower,
    stages: Vec<Arc<dyn NoiseStage>>,
    tags: Vec<u32>,
    detection: crate::config::DetectionConfig,
}

impl NoiseChain {
    /// Builds the chain of a configuration.
    pub fn new(config: &Config) -> Self {
        let kinds: Vec<&str> = config.noise.iter().map(|s| s.kind()).collect();
        NoiseChain {
            seed: config.seed,
            power: IdealPower::new(&config.power, &config.sensor, &config.detection),
            stages: registry::build_all(&config.noise),
            tags: stage_tags(&kinds),
            detection: config.detection.clone(),
        }
    }

    /// The ideal-power model and its constants.
    pub fn ideal_power(&self) -> &IdealPower {
        &self.power
    }

    /// The stages in chain order.
    pub fn stages(&self) -> &[Arc<dyn NoiseStage>] {
        &self.stages
    }

    /// Runs ideal power, the stages and the detection filters on a copy of `frame`.
    pub fn process(&self, frame: &Frame) -> NoisyFrame {
        self.process_returns(frame.index, frame.returns.clone())
    }

    /// Same as [`NoiseChain::process`], taking the frame's returns without copying.
    pub fn process_owned(&self, frame: Frame) -> NoisyFrame {
        self.process_returns(frame.index, frame.returns)
    }

    /// Runs the chain on returns of the frame with capture index `index`.
    pub fn process_returns(&self, index: u32, returns: Vec<Return>) -> NoisyFrame {
        let mut noisy = NoisyFrame::new(index, returns, &self.power);
        for (stage, &tag) in self.stages.iter().zip(&self.tags) {
            let mut rng = stage_rng(self.seed, index, tag);
            stage.apply(&mut noisy, &mut rng);
        }
        apply_detection(&mut noisy, &self.detection);
        noisy
    }

    /// Processes many frames in parallel; the output is in input order and identical for
    /// any thread count.
    pub fn process_all(&self, frames: Vec<Frame>) -> Vec<NoisyFrame> {
        frames
            .into_par_iter()
            .map(|f| self.process_owned(f))
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stage_tags_count_occurrences_per_type() {
        let tags = stage_tags(&["occlusion", "rain", "occlusion"]);
        assert_eq!(tags[0] & 0xffff, 0);
        assert_eq!(tags[2] & 0xffff, 1);
        assert_eq!(tags[0] >> 16, tags[2] >> 16);
        assert_ne!(tags[0] >> 16, tags[1] >> 16);
        // The rain tag does not depend on what precedes it.
        assert_eq!(stage_tags(&["rain"])[0], tags[1]);
    }
}
