//! Detection filters run after the noise chain: power threshold, then minimum range.

use crate::config::DetectionConfig;
use crate::noise::{Fate, NoisyFrame};

/// Marks returns a real sensor could not detect. Only `Kept` returns are examined, so an
/// earlier cause (occlusion) wins, and power is tested before range.
pub fn apply_detection(frame: &mut NoisyFrame, detection: &DetectionConfig) {
    let min_range = detection.min_range_m;
    for ((fate, &p), &r) in frame.fate.iter_mut().zip(&frame.power).zip(&frame.range) {
        if *fate != Fate::Kept {
            continue;
        }
        if p < detection.min_power {
            *fate = Fate::BelowPower;
        } else if f64::from(r) < min_range {
            *fate = Fate::BelowMinRange;
        }
    }
}
