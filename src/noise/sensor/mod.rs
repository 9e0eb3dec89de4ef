//! Stages of the sensor's own noise factors (p-diagram 01-06, 08, 09, 13): one file per
//! stage, models and defaults from `pdiagram-models.md`. Shared here: the rigid
//! [`Pose`] and option readers that reject NaN, infinities and out-of-range values with
//! the key and its line.
//!
//! # What the defaults stand for
//! The tool replays recorded captures, which already hold their own unit's noise (the
//! HDL-32E datasheet: range accuracy < 2 cm, one sigma at 25 m, for the whole sensor).
//! A default added on top must therefore be the spread between units (what another
//! unit of the same model, or the same unit aged or remounted, adds), not the whole
//! sensor's noise, or a recording gets its noise twice. Per stage:
//! - `laser_diode`, `receiver` gains and range noise, `clock` jitter and drift,
//!   `mechanics`, `emitter`: spread between units (or ageing of the unit), to add to a
//!   recording. Their range terms at their defaults (per-laser bias 5 mm, jitter 20 ps
//!   = 3 mm, drift 50 ppm = 1.25 mm at 25 m, receiver 0.03 m / sqrt(2 SNR) = 5.3 mm for
//!   a 10 % target at 25 m) add 7.9 mm RMS at 25 m, so a unit within the datasheet
//!   stays within it when its own noise is under 1.8 cm (tests/integration/conventions.rs).
//!   For a noise-free synthetic scene, the whole sensor's noise is about
//!   `receiver.range_noise_m = 0.09` (LISA's dR) with `clock.jitter_ps = 70`.
//! - `mounting`: the spread between installations of a calibrated rig.
//! - `motion`, `ambient`: the operating conditions of a scenario (speed, vibration, sun,
//!   temperature), not the unit; their defaults are no motion, no sun, the calibration
//!   temperature (range bias 0), and a mild vibration.

pub mod ambient;
pub mod clock;
pub mod emitter;
pub mod laser_diode;
pub mod mechanics;
pub mod motion;
pub mod mounting;
pub mod receiver;
pub mod ziggurat;

use crate::config::reader::Section;
use crate::error::Result;
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

/// Speed of light in m/s.
pub const C_M_PER_S: f64 = 299_792_458.0;

/// A rigid motion p -> r p + t (rotation matrix rows, translation in metres).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pose {
    /// Rotation matrix, row major.
    pub r: [[f64; 3]; 3],
    /// Translation in metres.
    pub t: [f64; 3],
}

impl Pose {
    /// No motion.
    pub const IDENTITY: Pose = Pose {
        r: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        t: [0.0; 3],
    };

    /// Rotation Rz(yaw) Ry(pitch) Rx(roll) (radians, right-handed, yaw about +z turns
    /// +x towards +y) followed by translation `t`.
    pub fn from_rpy(roll: f64, pitch: f64, yaw: f64, t: [f64; 3]) -> Pose {
        Pose::from_sin_cos(roll.sin_cos(), pitch.sin_cos(), yaw.sin_cos(), t)
    }

    /// Same as [`Pose::from_rpy`] with sin and cos from a series for small angles (see
    /// `small_sin_cos`; exact `sin_cos` above 0.01 rad): the general form that
    /// `Pose::tilt_after_yaw`, motion's per-firing rotation, is tested against.
    #[cfg(test)]
    pub fn from_small_rpy(roll: f64, pitch: f64, yaw: f64, t: [f64; 3]) -> Pose {
        use crate::numeric::small_sin_cos;
        Pose::from_sin_cos(
            small_sin_cos(roll),
            small_sin_cos(pitch),
            small_sin_cos(yaw),
            t,
        )
    }

    /// `Pose::from_small_rpy(roll, pitch, 0, 0)` after `Pose::from_small_rpy(0, 0, yaw, 0)`
    /// (motion's rotation of a firing: the ego yaw, then the vibration's roll and pitch),
    /// written out. The general product also adds products with the zeros of the two
    /// factors and multiplies by their ones; leaving those out changes no entry that is
    /// not zero (x + (+-0) = x, x * 1 = x, and the sums keep their order), and an entry
    /// that is exactly zero (only with zero angles) at most in its sign. Per firing this
    /// was most of `motion`'s time.
    pub fn tilt_after_yaw(roll: f64, pitch: f64, yaw: f64) -> Pose {
        use crate::numeric::small_sin_cos;
        let (sr, cr) = small_sin_cos(roll);
        let (sp, cp) = small_sin_cos(pitch);
        let (sy, cy) = small_sin_cos(yaw);
        let (spsr, spcr, cpsr) = (sp * sr, sp * cr, cp * sr);
        Pose {
            r: [
                [cp * cy + spsr * sy, -(cp * sy) + spsr * cy, spcr],
                [cr * sy, cr * cy, -sr],
                [-(sp * cy) + cpsr * sy, sp * sy + cpsr * cy, cp * cr],
            ],
            t: [0.0; 3],
        }
    }

    fn from_sin_cos(
        (sr, cr): (f64, f64),
        (sp, cp): (f64, f64),
        (sy, cy): (f64, f64),
        t: [f64; 3],
    ) -> Pose {
        Pose {
            r: [
                [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
                [-sp, cp * sr, cp * cr],
            ],
            t,
        }
    }

    /// `self` after `first`: p -> self(first(p)).
    pub fn then_after(&self, first: &Pose) -> Pose {
        let mut r = [[0.0; 3]; 3];
        for (i, row) in r.iter_mut().enumerate() {
            for (j, v) in row.iter_mut().enumerate() {
                *v = (0..3).map(|k| self.r[i][k] * first.r[k][j]).sum();
            }
        }
        let mut t = self.t;
        for (i, ti) in t.iter_mut().enumerate() {
            *ti += (0..3).map(|k| self.r[i][k] * first.t[k]).sum::<f64>();
        }
        Pose { r, t }
    }

    /// Applies the motion to a point.
    #[inline]
    pub fn apply(&self, p: [f32; 3]) -> [f32; 3] {
        let p = p.map(f64::from);
        let mut out = [0.0f32; 3];
        for (i, o) in out.iter_mut().enumerate() {
            *o = (self.r[i][0] * p[0] + self.r[i][1] * p[1] + self.r[i][2] * p[2] + self.t[i])
                as f32;
        }
        out
    }
}

/// The rigid motion of the returns of one firing: p -> r p + t + velocity (time - t_ref),
/// with `time` the return's clean firing time and `t_ref` the table's reference time
/// ([`Poses::t_ref`]). The velocity term lets the returns of a firing (fired 1.152 us
/// apart) share one rotation and still move by their own time (motion's translation).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FiringPose {
    /// Rotation and translation at `t_ref`.
    pub pose: Pose,
    /// Translation per second of firing time after `t_ref`, metres per second.
    pub velocity: [f64; 3],
}

impl FiringPose {
    /// `self` after `first`: p -> self(first(p)) (velocity terms compose linearly).
    pub fn then_after(&self, first: &FiringPose) -> FiringPose {
        let r = &self.pose.r;
        let mut velocity = self.velocity;
        for (i, v) in velocity.iter_mut().enumerate() {
            *v += r[i][0] * first.velocity[0]
                + r[i][1] * first.velocity[1]
                + r[i][2] * first.velocity[2];
        }
        FiringPose {
            pose: self.pose.then_after(&first.pose),
            velocity,
        }
    }

    /// Applies the motion to a point fired `dt` seconds after the table's `t_ref`.
    #[inline]
    pub fn apply(&self, p: [f32; 3], dt: f64) -> [f32; 3] {
        let p = p.map(f64::from);
        let (r, t, v) = (&self.pose.r, &self.pose.t, &self.velocity);
        let mut out = [0.0f32; 3];
        for (i, o) in out.iter_mut().enumerate() {
            *o = (r[i][0] * p[0] + r[i][1] * p[1] + r[i][2] * p[2] + (t[i] + v[i] * dt)) as f32;
        }
        out
    }
}

/// Rigid motions of a frame's returns: a table of per-firing poses plus, per return, the
/// index of its firing (one pose per firing instead of one per return: 4 bytes per
/// return instead of 96, and composing stages costs one product per firing).
#[derive(Clone, Debug, PartialEq)]
pub struct Poses {
    /// Reference time of the velocity terms (seconds, as `Return::time`).
    pub t_ref: f64,
    /// The poses, one per firing (or a single one shared by every return).
    pub firings: Vec<FiringPose>,
    /// Index into `firings` of each return; `None` when every return uses `firings[0]`.
    pub index: Option<Vec<u32>>,
}

impl Poses {
    /// One pose for every return.
    pub fn uniform(pose: Pose) -> Poses {
        Poses {
            t_ref: 0.0,
            firings: vec![FiringPose {
                pose,
                velocity: [0.0; 3],
            }],
            index: None,
        }
    }

    /// The pose of return `i`.
    #[inline]
    pub fn of(&self, i: usize) -> &FiringPose {
        match &self.index {
            None => &self.firings[0],
            Some(ix) => &self.firings[ix[i] as usize],
        }
    }

    /// Applies `outer` after every pose (a rigid mount acting last).
    pub fn then(&mut self, outer: &Pose) {
        let outer = FiringPose {
            pose: *outer,
            velocity: [0.0; 3],
        };
        for f in self.firings.iter_mut() {
            *f = outer.then_after(f);
        }
    }

    /// Every pose of `self` applied after the pose of the same return in `inner`
    /// (`inner` then `self`); the result keeps `inner`'s firing index.
    pub fn after(&self, mut inner: Poses) -> Poses {
        // Re-reference inner's velocity terms to self's reference time:
        // t + v (time - t_in) = (t + v (t_self - t_in)) + v (time - t_self).
        let shift = self.t_ref - inner.t_ref;
        if shift != 0.0 {
            for f in inner.firings.iter_mut() {
                for k in 0..3 {
                    f.pose.t[k] += f.velocity[k] * shift;
                }
            }
        }
        match (&self.index, &inner.index) {
            (None, _) => {
                let outer = self.firings[0];
                for f in inner.firings.iter_mut() {
                    *f = outer.then_after(f);
                }
                inner.t_ref = self.t_ref;
                inner
            }
            (Some(_), None) => {
                let mut out = self.clone();
                for f in out.firings.iter_mut() {
                    *f = f.then_after(&inner.firings[0]);
                }
                out
            }
            (Some(a), Some(b)) => {
                // Both per firing: one entry per distinct pair of indices (the same
                // firing grouping gives one pair per firing).
                let mut firings = Vec::new();
                let mut index = Vec::with_capacity(a.len());
                let mut last = None;
                for (&ia, &ib) in a.iter().zip(b) {
                    if last != Some((ia, ib)) {
                        last = Some((ia, ib));
                        firings.push(
                            self.firings[ia as usize].then_after(&inner.firings[ib as usize]),
                        );
                    }
                    index.push(firings.len() as u32 - 1);
                }
                Poses {
                    t_ref: self.t_ref,
                    firings,
                    index: Some(index),
                }
            }
        }
    }
}

/// `clamp(round(v g), 0, 255)` for a factor `g >= 0` (a finite gain), without a libm
/// call: for non-negative x, round (half away from zero) is the truncation plus one when
/// the fraction (exact: x - trunc(x)) is at least 0.5. Same bytes as `f64::round`.
#[inline]
pub fn scale_byte(v: u8, g: f64) -> u8 {
    let x = f64::from(v) * g;
    if x.is_nan() || x < 0.0 {
        // NaN or negative: keep the exact formula for the cases the fast path skips.
        return x.round().clamp(0.0, 255.0) as u8;
    }
    let t = x.min(256.0) as u32;
    let up = u32::from(x - f64::from(t) >= 0.5);
    (t + up).min(255) as u8
}

/// Returns per chunk of [`fill_normals`]: the draws of a chunk are made first (same
/// stream order as one draw at a time), then the arithmetic runs on a buffer, free of
/// calls, so the square roots and divisions of successive returns overlap.
pub const CHUNK: usize = 256;

/// sin and cos of an angle that advances in small steps from call to call (the
/// azimuths of a frame's firings, a vibration's phase at their times), carried by angle
/// addition instead of a libm call per firing, which made most of `mechanics`' and
/// `motion`'s time on real captures.
///
/// A step of at most [`SineTrack::MAX_STEP`] rad uses the series of `small_sin_cos`
/// (truncation below 2e-18 at 0.006 rad); a larger step, a NaN and every
/// [`SineTrack::ANCHOR_EVERY`]th call take libm's `sin_cos` afresh, so the rounding of the
/// additions (a few 1e-16 per step) stays below 1e-13, far under the f32 outputs'
/// precision (a test checks the bound against libm).
#[derive(Clone, Copy, Debug)]
pub struct SineTrack {
    x: f64,
    sin: f64,
    cos: f64,
    steps: u32,
}

impl Default for SineTrack {
    fn default() -> Self {
        SineTrack {
            x: f64::NAN,
            sin: f64::NAN,
            cos: f64::NAN,
            steps: Self::ANCHOR_EVERY,
        }
    }
}

impl SineTrack {
    /// Largest step carried by angle addition, radians (a firing's azimuth step is
    /// about 0.003 rad, a 20 Hz vibration's phase moves 0.006 rad per firing).
    pub const MAX_STEP: f64 = 0.01;
    /// Calls between two libm anchors.
    pub const ANCHOR_EVERY: u32 = 64;

    /// (sin x, cos x), within 1e-13 of libm's.
    #[inline]
    pub fn at(&mut self, x: f64) -> (f64, f64) {
        let d = x - self.x;
        if self.steps < Self::ANCHOR_EVERY && d.abs() <= Self::MAX_STEP {
            if d != 0.0 {
                let (sd, cd) = crate::numeric::small_sin_cos(d);
                let sin = self.sin * cd + self.cos * sd;
                self.cos = self.cos * cd - self.sin * sd;
                self.sin = sin;
                self.x = x;
            }
            self.steps += 1;
        } else {
            (self.sin, self.cos) = x.sin_cos();
            self.x = x;
            self.steps = 0;
        }
        (self.sin, self.cos)
    }
}

/// sin(x + phi) from (sin x, cos x) and (sin phi, cos phi).
#[inline]
pub fn sin_plus((s, c): (f64, f64), (sp, cp): (f64, f64)) -> f64 {
    s * cp + c * sp
}

/// Fills `out` with standard normal draws from the stage's stream `rng`: the ziggurat of
/// [`ziggurat::fill`], one 32-bit word per draw taken in one bulk fill (the rare
/// rejections take further words from `rng`). Draw `j` of a fill starts from word `j`,
/// so the per-return draws of a stage do not depend on the fates of the returns.
pub fn fill_normals(rng: &mut ChaCha8Rng, out: &mut [f64]) {
    ziggurat::fill(rng, out);
}

/// One standard normal draw.
#[inline]
pub fn normal(rng: &mut ChaCha8Rng) -> f64 {
    rng.sample::<f64, _>(StandardNormal)
}

/// A finite number at `key` in `[lo, hi]`, or `default`.
pub fn number(opts: &Section<'_>, key: &str, default: f64, lo: f64, hi: f64) -> Result<f64> {
    match opts.f64(key)? {
        None => Ok(default),
        Some(v) if !v.is_finite() => Err(opts.error(key, format!("{v} is not a finite number"))),
        Some(v) if v < lo || v > hi => Err(opts.error(key, format!("{v} is outside [{lo}, {hi}]"))),
        Some(v) => Ok(v),
    }
}

/// A standard deviation at `key` (finite, not negative, at most `hi`), or `default`.
pub fn sigma(opts: &Section<'_>, key: &str, default: f64, hi: f64) -> Result<f64> {
    match opts.f64(key)? {
        Some(v) if v < 0.0 => {
            Err(opts.error(key, format!("{v} is negative (a standard deviation)")))
        }
        _ => number(opts, key, default, 0.0, hi),
    }
}

/// A list of finite numbers in `[lo, hi]` at `key`, one per laser id of the sensor
/// (its length is checked against the sensor by [`check_per_laser`]), if given.
pub fn per_laser(opts: &Section<'_>, key: &str, lo: f64, hi: f64) -> Result<Option<Vec<f64>>> {
    let Some(v) = opts.value(key) else {
        return Ok(None);
    };
    let bad = || {
        opts.error(
            key,
            format!("must be a list of numbers in [{lo}, {hi}], one per laser id"),
        )
    };
    let toml::Value::Array(items) = v else {
        return Err(bad());
    };
    // The laser counts of the modelled sensors; which one is checked when the sensor is
    // known ([`check_per_laser`]).
    if ![16, 32, 64, 128].contains(&items.len()) {
        return Err(opts.error(
            key,
            format!(
                "has {} entries; give one per laser of the sensor (16, 32, 64 or 128)",
                items.len()
            ),
        ));
    }
    items
        .iter()
        .map(|x| match x {
            toml::Value::Float(f) if f.is_finite() && (lo..=hi).contains(f) => Ok(*f),
            toml::Value::Integer(i) if (lo..=hi).contains(&(*i as f64)) => Ok(*i as f64),
            _ => Err(bad()),
        })
        .collect::<Result<Vec<f64>>>()
        .map(Some)
}

/// Why a per-laser list given at `key` does not fit a sensor of `lasers` lasers (it
/// must have one entry per laser), if it does not.
pub fn check_per_laser(
    key: &str,
    given: Option<&[f64]>,
    lasers: usize,
) -> std::result::Result<(), String> {
    match given {
        Some(g) if g.len() != lasers => Err(format!(
            "{key} has {} entries, but the sensor has {lasers} lasers: give one per laser",
            g.len()
        )),
        _ => Ok(()),
    }
}

/// A TOML float.
pub fn float(v: f64) -> toml::Value {
    toml::Value::Float(v)
}

/// The clean firing time of the frame's first return (reference for per-frame times).
pub fn frame_start(frame: &super::NoisyFrame) -> f64 {
    frame.clean.first().map_or(0.0, |r| r.time)
}

#[cfg(test)]
mod tests {
    use super::{scale_byte, sin_plus, Pose, SineTrack};

    #[test]
    fn tilt_after_yaw_is_the_general_product() {
        // Small angles as motion makes them, larger ones (libm branch), and zeros of
        // both signs; entries equal (+0 == -0), and bit for bit where not zero.
        let mut state = 11u64;
        let mut unit = || crate::test_util::lcg_unit(&mut state);
        let mut angle = |k: u32| match k % 7 {
            0 => 0.0,
            1 => -0.0,
            2 => (unit() - 0.5) * 0.2,
            _ => (unit() - 0.5) * 0.004,
        };
        for k in 0..20_000u32 {
            let (roll, pitch, yaw) = (angle(k), angle(k / 7), angle(k / 49));
            let want = Pose::from_small_rpy(roll, pitch, 0.0, [0.0; 3])
                .then_after(&Pose::from_small_rpy(0.0, 0.0, yaw, [0.0; 3]));
            let got = Pose::tilt_after_yaw(roll, pitch, yaw);
            for (g, w) in got.r.iter().flatten().zip(want.r.iter().flatten()) {
                assert!(g == w && (*w == 0.0 || g.to_bits() == w.to_bits()), "{k}");
            }
            assert_eq!(got.t, want.t, "{k}");
        }
    }

    #[test]
    fn sine_track_stays_within_1e_13_of_libm() {
        // Walks as the stages make them: azimuth steps (radians of f32 degrees) across
        // 0..2 pi and beyond, vibration phases up to about 20 rad, steps of both signs,
        // repeats, steps just above the series' limit, jumps (a turn's wrap) and a NaN.
        let mut state = 5u64;
        let mut unit = || crate::test_util::lcg_unit(&mut state);
        let mut worst = 0.0f64;
        let mut anchored = 0;
        for walk in 0..200 {
            let mut track = SineTrack::default();
            let mut x = unit() * 20.0;
            let phase = (unit() * 6.0).sin_cos();
            for _ in 0..2000 {
                let r = unit();
                x += match walk % 4 {
                    0 => f64::from(((unit() * 0.17) as f32).to_radians()),
                    1 => (r - 0.3) * 0.012,
                    2 if r < 0.01 => -std::f64::consts::TAU,
                    _ => r * 0.0058,
                };
                let (s, c) = track.at(x);
                anchored += usize::from(track.steps == 0);
                worst = worst.max((s - x.sin()).abs()).max((c - x.cos()).abs());
                let want = (x + phase.0.atan2(phase.1)).sin();
                worst = worst.max((sin_plus((s, c), phase) - want).abs() - 1e-15);
            }
        }
        assert!(worst < 1e-13, "worst {worst}");
        // Mostly carried, not anchored.
        assert!(anchored < 200 * 2000 / 10, "{anchored}");
        let mut track = SineTrack::default();
        assert!(track.at(f64::NAN).0.is_nan());
        assert_eq!(track.at(1.0), 1.0f64.sin_cos());
    }

    #[test]
    fn scale_byte_rounds_like_f64_round() {
        let gains = [
            0.0, 0.25, 0.5, 0.9, 0.95, 1.0, 1.02, 1.5, 1.7, 2.0, 3.3, 10.0,
        ];
        for v in 0..=255u8 {
            for g in gains
                .into_iter()
                .chain((0..200).map(|k| 0.8 + f64::from(k) * 0.0021))
            {
                let want = (f64::from(v) * g).round().clamp(0.0, 255.0) as u8;
                assert_eq!(scale_byte(v, g), want, "{v} * {g}");
            }
        }
        // Exact halves round up (away from zero), like f64::round.
        assert_eq!(scale_byte(5, 0.5), 3);
        assert_eq!(scale_byte(1, 0.5), 1);
    }
}
