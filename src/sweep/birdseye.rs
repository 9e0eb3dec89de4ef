//! The sweep's bird's-eye figure: one frame of the first capture through the clean
//! configuration, each noise stage type alone, and all of them.

use super::plan::BaseConfig;
use crate::error::{Error, Result};
use crate::frame::{Frame, FrameSource};
use crate::pipeline::Pipeline;
use crate::sensor::frames::CaptureFrames;
use crate::sensor::frames::DecoderOptions;
use rayon::prelude::*;
use std::ops::RangeInclusive;
use std::path::Path;

/// One panel of the bird's-eye figure: a configuration's result on one frame.
#[derive(Clone, Debug)]
pub struct Panel {
    /// Title, e.g. "rain only".
    pub title: String,
    /// Survivor x, y (metres) and class: -2 ground, -1 noise, k cluster id.
    pub points: Vec<(f32, f32, i32)>,
    /// Clusters found.
    pub clusters: usize,
    /// The noise stages applied, one "type: settings" line each, in chain order.
    pub stages: Vec<String>,
}

/// Runs one frame through the clean configuration, each stage type of the base alone, and
/// all of them (the reference study's figure 3 for occlusion and rain).
pub fn birdseye_panels(
    base: &BaseConfig,
    seed: u64,
    frame: &Frame,
    lasers: usize,
) -> Result<Vec<Panel>> {
    let mut types: Vec<&str> = Vec::new();
    for s in &base.config.noise {
        if !types.contains(&s.kind()) {
            types.push(s.kind());
        }
    }
    let mut variants: Vec<(String, Vec<&str>)> = vec![("clean".into(), Vec::new())];
    for t in &types {
        variants.push((format!("{t} only"), vec![t]));
    }
    if types.len() >= 2 {
        variants.push((types.join(" + "), types.clone()));
    }
    variants
        .par_iter()
        .map(|(title, kinds)| {
            let config = base.only_stages(kinds, seed)?;
            let pipeline = Pipeline::new(&config)
                .for_lasers(lasers)
                .map_err(Error::Invalid)?;
            let r = pipeline.process(frame.clone())?;
            let points = r
                .survivors
                .iter()
                .zip(&r.ground)
                .zip(&r.labels)
                .map(|((p, &g), &l)| (p.x, p.y, if g { -2 } else { l }))
                .collect();
            Ok(Panel {
                title: title.clone(),
                points,
                clusters: r.clusters.len(),
                stages: config
                    .noise
                    .iter()
                    .map(|s| format!("{}: {}", s.kind(), s.describe()))
                    .collect(),
            })
        })
        .collect()
}

/// Decodes the frame with index `index` of a capture (the first in `frames` when `None`),
/// with its sensor's number of lasers.
pub fn read_frame(
    path: &Path,
    decoder: &DecoderOptions,
    frames: &RangeInclusive<u32>,
    index: Option<u32>,
) -> Result<Option<(Frame, usize)>> {
    let (mut reader, lasers): (Box<dyn FrameSource>, usize) =
        match crate::sensor::frames::open_capture(path, decoder)? {
            CaptureFrames::Hdl32e(r) => (r, crate::sensor::HDL32E.lasers),
            CaptureFrames::Model(r) => {
                let lasers = r.model().lasers;
                (r, lasers)
            }
        };
    let everything = 0..=u32::MAX;
    loop {
        let batch = reader.next_batch(16, &everything)?;
        if batch.is_empty() {
            return Ok(None);
        }
        for frame in batch {
            let wanted = match index {
                Some(i) => frame.index == i,
                None => frames.contains(&frame.index),
            };
            if wanted {
                return Ok(Some((frame, lasers)));
            }
        }
    }
}
