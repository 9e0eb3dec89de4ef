//! The [`NoiseStage`] trait and the random streams stages draw from.

use super::*;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use std::sync::Arc;

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
    /// The stage with its per-unit draws made (values fixed for a run and seed, such as
    /// per-laser offsets), from `rng`, the stage's unit stream (frame key
    /// [`UNIT_FRAME`]); `None` when the stage has none.
    fn with_unit_draws(&self, _rng: &mut ChaCha8Rng) -> Option<Arc<dyn NoiseStage>> {
        None
    }
    /// True when the stage, with its options, may propose spurious echoes (the PLY of
    /// kept returns then carries `fate` and `cause`).
    fn proposes_echoes(&self) -> bool {
        false
    }
    /// True when the stage reads the frame's [`Layout`] ([`NoisyFrame::layout`]): the
    /// chain then builds it in the pass that starts the frame.
    fn uses_layout(&self) -> bool {
        false
    }
    /// Why the stage's options do not fit a sensor with `lasers` lasers (per-laser
    /// values or laser ids beyond it), if they do not.
    fn check_lasers(&self, _lasers: usize) -> Result<(), String> {
        Ok(())
    }
    /// Why the stage's options do not fit the sensor's geometry (an elevation interval
    /// holding none of its lasers), if they do not; laser counts are
    /// [`NoiseStage::check_lasers`]'s.
    fn check_sensor(&self, _sensor: &crate::sensor::SensorModel) -> Result<(), String> {
        Ok(())
    }
}

/// Frame index reserved for per-unit draws: the unit stream of a stage is
/// `stage_rng(seed, UNIT_FRAME, tag)`, which no frame uses and which does not depend on
/// the frame, so per-unit values are the same in every frame and every thread.
pub const UNIT_FRAME: u32 = u32::MAX;

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
