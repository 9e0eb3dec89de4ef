//! Detection filters run after the noise chain: power threshold, then minimum range.

use crate::config::DetectionConfig;
use crate::noise::{Fate, NoisyFrame, NO_CAUSE};

/// Marks returns a real sensor could not detect. Only alive returns are examined, so an
/// earlier cause (occlusion) wins, and power is tested before range. The filters are no
/// stage: their drops get cause [`NO_CAUSE`].
pub fn apply_detection(frame: &mut NoisyFrame, detection: &DetectionConfig) {
    let (min_power, min_range) = (detection.min_power, detection.min_range_m);
    // One branch per return, on whether the filters drop it (rare), not one on its fate:
    // after stages that drop returns at random (rain, a receiver's soft threshold) the
    // fate branch mispredicted often; stores only for drops (storing every fate and
    // cause was slower where nothing is dropped). Same fates and causes as the tests
    // in order (alive; power; range).
    for (((fate, cause), &p), &r) in frame
        .fate
        .iter_mut()
        .zip(&mut frame.cause)
        .zip(&frame.power)
        .zip(&frame.range)
    {
        let below_power = p < min_power;
        let drop = fate.is_alive() & (below_power | (f64::from(r) < min_range));
        let dropped = if below_power {
            Fate::BelowPower
        } else {
            Fate::BelowMinRange
        };
        if drop {
            *fate = dropped;
            *cause = NO_CAUSE;
        }
    }
}
