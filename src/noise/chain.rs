//! [`NoiseChain`]: the configured stages run in file order on each frame, then detection.

use super::*;
use crate::config::Config;
use crate::frame::{Frame, Return};
use rayon::prelude::*;
use std::sync::Arc;

/// The configured chain, ready to process frames (shareable between threads).
#[derive(Clone, Debug)]
pub struct NoiseChain {
    seed: u64,
    power: Arc<IdealPower>,
    stages: Vec<Arc<dyn NoiseStage>>,
    tags: Vec<u32>,
    detection: crate::config::DetectionConfig,
    /// The detection rule with its table, shared by every frame.
    rule: Arc<DetectionRule>,
    /// Some stage reads the frame's layout.
    layout: bool,
    /// True when a stage may propose echoes: the firing slots are built as the frame
    /// starts.
    echoes: bool,
    /// Lasers a firing of the sensor whose frames the chain processes.
    lasers: usize,
}

impl NoiseChain {
    /// Builds the chain of a configuration.
    pub fn new(config: &Config) -> Self {
        let kinds: Vec<&str> = config.noise.iter().map(|s| s.kind()).collect();
        let tags = stage_tags(&kinds);
        let stages = registry::build_all(&config.noise)
            .into_iter()
            .zip(&tags)
            .map(|(stage, &tag)| {
                let mut unit = stage_rng(config.seed, UNIT_FRAME, tag);
                stage.with_unit_draws(&mut unit).unwrap_or(stage)
            })
            .collect::<Vec<Arc<dyn NoiseStage>>>();
        NoiseChain {
            layout: stages.iter().any(|s| s.uses_layout()),
            echoes: stages.iter().any(|s| s.proposes_echoes()),
            seed: config.seed,
            power: Arc::new(IdealPower::new(
                &config.power,
                &config.sensor,
                &config.detection,
            )),
            stages,
            tags,
            detection: config.detection.clone(),
            rule: Arc::new(DetectionRule::new(&config.detection)),
            lasers: spurious::DEFAULT_LASERS,
        }
    }

    /// The chain for frames of a sensor with `lasers` lasers (an HDL-32E's 32 unless
    /// said); an error, naming the stage and option, when a stage's per-laser options
    /// do not fit that sensor (a list of 32 values for a 64-laser sensor).
    pub fn for_lasers(mut self, lasers: usize) -> Result<Self, String> {
        if !(1..=spurious::MAX_LASERS).contains(&lasers) {
            return Err(format!(
                "a sensor with {lasers} lasers: the noise stages model 1 to {}",
                spurious::MAX_LASERS
            ));
        }
        for (i, stage) in self.stages.iter().enumerate() {
            stage
                .check_lasers(lasers)
                .map_err(|e| format!("[[noise]] #{} ({}): {e}", i + 1, stage.kind()))?;
        }
        self.lasers = lasers;
        Ok(self)
    }

    /// The chain for frames of `sensor`: [`NoiseChain::for_lasers`] with its laser count,
    /// and each stage's options checked against its laser table
    /// ([`NoiseStage::check_sensor`]).
    pub fn for_sensor(self, sensor: &crate::sensor::SensorModel) -> Result<Self, String> {
        let chain = self.for_lasers(sensor.lasers)?;
        for (i, stage) in chain.stages.iter().enumerate() {
            stage
                .check_sensor(sensor)
                .map_err(|e| format!("[[noise]] #{} ({}): {e}", i + 1, stage.kind()))?;
        }
        Ok(chain)
    }

    /// Lasers a firing of the sensor the chain is for.
    pub fn lasers(&self) -> usize {
        self.lasers
    }

    /// The lasers a firing when the frame's slots are built as it starts.
    fn slots(&self) -> Option<usize> {
        self.echoes.then_some(self.lasers)
    }

    /// The ideal-power model and its constants.
    pub fn ideal_power(&self) -> &IdealPower {
        &self.power
    }

    /// The stages in chain order.
    pub fn stages(&self) -> &[Arc<dyn NoiseStage>] {
        &self.stages
    }

    /// True when some stage may propose spurious echoes.
    pub fn proposes_echoes(&self) -> bool {
        self.stages.iter().any(|s| s.proposes_echoes())
    }

    /// Runs ideal power, the stages and the detection filters on a copy of `frame`.
    pub fn process(&self, frame: &Frame) -> NoisyFrame {
        if self.stages.is_empty() || self.layout {
            let n = frame.returns.len();
            let mut returns = Vec::with_capacity(n + room_for_added(n));
            returns.extend_from_slice(&frame.returns);
            return self.process_returns(frame.index, returns);
        }
        // The copy made in the pass that reads the returns.
        let (noisy, bytes) =
            NoisyFrame::copy_keeping_bytes(frame.index, &frame.returns, &self.power, self.slots());
        self.process_started(frame.index, (noisy, Some(bytes)))
    }

    /// Same as [`NoiseChain::process`], taking the frame's returns without copying.
    pub fn process_owned(&self, frame: Frame) -> NoisyFrame {
        self.process_returns(frame.index, frame.returns)
    }

    /// Runs the chain on returns of the frame with capture index `index`.
    pub fn process_returns(&self, index: u32, mut returns: Vec<Return>) -> NoisyFrame {
        if !self.stages.is_empty() {
            // Moves the returns only when they lack the room (a decoder's vector usually
            // has it from growing).
            returns.reserve(room_for_added(returns.len()));
        }
        // The recorded bytes for the intensity rule: read with the ideal powers when
        // no layout (which holds them) is built.
        let started = if self.layout {
            (NoisyFrame::with_layout(index, returns, &self.power), None)
        } else if self.stages.is_empty() {
            (NoisyFrame::new(index, returns, &self.power), None)
        } else {
            let (f, b) = NoisyFrame::new_keeping_bytes(index, returns, &self.power, self.slots());
            (f, Some(b))
        };
        self.process_started(index, started)
    }

    /// The rest of [`NoiseChain::process_returns`] from the started frame and, when read,
    /// its recorded intensity bytes.
    fn process_started(
        &self,
        index: u32,
        (mut noisy, recorded): (NoisyFrame, Option<Vec<u8>>),
    ) -> NoisyFrame {
        noisy.recorded_intensity = recorded;
        noisy.lasers = self.lasers;
        noisy.threshold = self.detection.min_power;
        noisy.min_range = self.detection.min_range_m;
        noisy.power_model = Some(Arc::clone(&self.power));
        noisy.detection = Some(Arc::clone(&self.rule));
        // The ideal powers, for the intensity rule after the chain (no stage, no change).
        let ideal = if self.stages.is_empty() {
            Vec::new()
        } else {
            noisy.power.clone()
        };
        for (i, (stage, &tag)) in self.stages.iter().zip(&self.tags).enumerate() {
            // Chains are far shorter than 255 stages (checked when the config is read).
            noisy.stage = i.min(usize::from(NO_CAUSE) - 1) as u8;
            let mut rng = stage_rng(self.seed, index, tag);
            stage.apply(&mut noisy, &mut rng);
        }
        // The recorded returns the receiver still detects (probabilistic model), then
        // every stage's echoes compete once, per firing slot, with the return-mode rule.
        // Without stages nothing changed: every recorded return is kept (no draw).
        let mut rng = stage_rng(self.seed, index, detection::DETECTION_TAG);
        decide_recorded(&mut noisy, &ideal, self.detection.min_power, &mut rng);
        spurious::resolve(&mut noisy);
        apply_detection(&mut noisy, &self.detection);
        if !self.stages.is_empty() {
            match noisy.recorded_intensity.take() {
                Some(bytes) => noisy.intensity_rule_on(&ideal, bytes),
                None => noisy.apply_intensity_rule(&ideal),
            }
        }
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
