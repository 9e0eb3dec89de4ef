//! Detection filters run after the noise chain: power threshold, then minimum range.

use crate::config::DetectionConfig;
use crate::noise::{Fate, NoisyFrame, NO_CAUSE};

/// Marks returns a real sensor could not detect. Only alive returns are examined, so an
/// earlier cause (occlusion) wins, and power is tested before range. The filters are no
/// stage: their drops get cause [`NO_CAUSE`].
pub fn apply_detection(frame: &mut NoisyFrame, detection: &DetectionConfig) {
    let min_range = detection.min_range_m;
    for (((fate, cause), &p), &r) in frame
        .fate
        .iter_mut()
        .zip(&mut frame.cause)
        .zip(&frame.power)
        .zip(&frame.range)
    {
        if !fate.is_alive() {
            continue;
        }
        if p < detection.min_power {
            *fate = Fate::BelowPower;
            *cause = NO_CAUSE;
        } else if f64::from(r) < min_range {
            *fate = Fate::BelowMinRange;
            *cause = NO_CAUSE;
        }
    }
}
