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
//!
//! # Intensity
//! One rule sets the intensity byte the sensor reports, applied once after the chain
//! (stages, spurious echoes resolved, detection filters) by
//! [`NoisyFrame::apply_intensity_rule`]:
//! - a return's own echo (fate [`Fate::Kept`]) reports
//!   I' = clamp(round(I g P / P_i), 0, 255), with I the recorded byte, P_i its ideal
//!   power (see [`power`]), P its power after every stage and g the product of the
//!   receivers' `gain_error` (a factor on the byte alone, not on the power). Every
//!   attenuating stage (fog, rain, snow, lens damage, occlusion with a transmission,
//!   emitter, laser-diode and receiver gains, a mixed pixel's own share) only multiplies
//!   `power`, so the byte sees the product of all losses, rounded once.
//! - In reflectivity mode the firmware turns the raw level into reflectivity with a
//!   range compensation calibrated in clear air (the recorded byte already carries it):
//!   the compensation stays, and what the atmosphere and the optics take from the echo
//!   shows as a lower reflectivity (Filgueira et al., Measurement 95, 2017: HDL-32E
//!   intensity falls with the rain rate). In raw mode the level is proportional to the
//!   received power of an unsaturated linear receiver, so a loss factor f on the power
//!   is a factor f on the level: the same factor in both modes. The compensation is
//!   that of the recorded range (a range noise of centimetres changes it by well under
//!   one byte).
//! - Spurious echoes (fates [`Fate::Replaced`], [`Fate::Added`]: fog, drops, flakes,
//!   crosstalk, spoofing, multipath mixtures, EMI, scattered beams) keep the intensity
//!   their stage or [`IdealPower::intensity_of`] gave them from their own power.
//! - Saturation: the ideal power is clamped at 1 (a bound of the power model, reached
//!   within about 10 m of a white target), and stages multiply the clamped value, so
//!   P / P_i is still exactly the product of the loss factors and the byte is scaled by
//!   it. This treats the byte as the linear reflectivity the firmware reports
//!   (including retro-reflectors above 100) rather than modelling a receiver that hides
//!   a loss until the echo falls below saturation, which the capture cannot tell us.
//! - At zero strength every stage leaves P = P_i bit for bit and g = 1, so every byte
//!   is the recorded one and no intensity column is made (same output bytes).

pub mod detection;
pub mod power;
pub mod registry;
pub mod sensor;
pub mod spurious;
pub mod summary;
pub mod transmission;
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

pub use detection::{apply_detection, decide_recorded, DetectionRule};
pub use power::{IdealPower, PowerConstants};
pub use spurious::{DenseEchoes, Echo, SlotId, Slots};
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
    /// Replaced by a spurious echo that won its firing slot: the position and range are
    /// the echo's, `clean` keeps the return that was recorded.
    Replaced = 4,
    /// Added by a stage in a firing slot that had no return (no clean origin).
    Added = 5,
}

/// `cause` of returns whose fate no stage decided: kept returns, and returns dropped by
/// the detection filters.
pub const NO_CAUSE: u8 = u8::MAX;

impl Fate {
    /// The causes of removal, in pipeline order.
    pub const DROPS: [Fate; 3] = [Fate::Occluded, Fate::BelowPower, Fate::BelowMinRange];

    /// True while the sensor still reports the return (kept, or a spurious echo in its place).
    #[inline]
    pub fn is_alive(self) -> bool {
        matches!(self, Fate::Kept | Fate::Replaced | Fate::Added)
    }

    /// True for returns that are echoes of no recorded return.
    #[inline]
    pub fn is_spurious(self) -> bool {
        matches!(self, Fate::Replaced | Fate::Added)
    }

    /// Short snake_case name (as in reports).
    pub fn name(self) -> &'static str {
        match self {
            Fate::Kept => "kept",
            Fate::Occluded => "occluded",
            Fate::BelowPower => "below_power",
            Fate::BelowMinRange => "below_min_range",
            Fate::Replaced => "replaced",
            Fate::Added => "added",
        }
    }
}

/// One frame on its way through the chain: clean returns plus per-return noisy state.
///
/// All vectors have one entry per return, in the clean order: first the `clean_len`
/// returns of the capture, then the returns stages added (fate [`Fate::Added`]), whose
/// `clean` entry is the echo itself.
#[derive(Clone, Debug, Default)]
pub struct NoisyFrame {
    /// Index of the frame in the capture (keys the random streams).
    pub index: u32,
    /// The returns as recorded (and, past `clean_len`, the added returns).
    pub clean: Vec<Return>,
    /// Number of returns of the capture; entries from here on were added by stages.
    pub clean_len: usize,
    /// Current range in metres (the clean range until a stage changes it).
    pub range: Vec<f32>,
    /// Current power as a fraction of emitted power (the ideal power at first).
    pub power: Vec<f64>,
    /// Current fate; stages and filters only change alive entries ([`Fate::is_alive`]).
    pub fate: Vec<Fate>,
    /// Index in the chain of the stage that decided the fate ([`NO_CAUSE`] for kept
    /// returns and for the detection filters' drops).
    pub cause: Vec<u8>,
    /// The detection threshold (fraction of emitted power) the filters will apply, for
    /// stages that raise it (receiver noise floor, ambient light).
    pub threshold: f64,
    /// The minimum range (m) of the detection filters.
    pub min_range: f64,
    /// Index in the chain of the stage being applied (set by the chain).
    pub stage: u8,
    /// Echoes proposed by the stages, resolved once per firing slot after the chain.
    pub candidates: Vec<spurious::Candidate>,
    /// Echoes one stage proposed for every recorded return at once (fog), resolved with
    /// `candidates` as if proposed in their place ([`NoisyFrame::propose_each`]).
    pub dense: Option<spurious::DenseEchoes>,
    /// The recorded intensity bytes of the clean returns, when the chain read them with
    /// the ideal powers: the copy the intensity column starts from when an echo replaces
    /// a return (rather than one more strided read of `clean`).
    pub recorded_intensity: Option<Vec<u8>>,
    /// The firing slots of the frame, built when a stage first asks for them.
    pub slots: Option<Arc<Slots>>,
    /// Lasers a firing of the sensor that recorded the frame (the slots a firing; set by
    /// the chain from its sensor, [`spurious::DEFAULT_LASERS`] until then).
    pub lasers: usize,
    /// The ideal-power model, for the intensity of spurious echoes.
    pub power_model: Option<Arc<IdealPower>>,
    /// The detection rule (`None`: the threshold, as for frames built outside a chain).
    pub detection: Option<Arc<detection::DetectionRule>>,
    /// True once [`detection::decide_recorded`] has decided the recorded returns: those
    /// still alive count as detected whatever their power.
    pub decided: bool,
    /// Per-return state that only sensor stages change; `None` until one does, so that a
    /// chain without them (or with them at zero magnitude) writes the same bytes.
    pub moved: Moved,
    /// Compact columns of the clean returns, built when a stage first asks for them
    /// ([`NoisyFrame::layout`]).
    pub layout: Option<Arc<Layout>>,
}

/// Compact copies of the clean returns' fields that sensor stages read, and the frame's
/// firings, built in one pass over the returns.
///
/// Why: a 50k-return frame's `clean` is 2.4 MB, more than the L2 cache, and every stage
/// that read one byte (laser id) or one time per return streamed all of it again; these
/// columns are 50-400 kB.
#[derive(Clone, Debug, Default)]
pub struct Layout {
    /// Laser id of each return (modulo [`spurious::MAX_LASERS`], so per-laser tables of
    /// that size need no bounds check).
    pub laser: Vec<u8>,
    /// Clean intensity byte of each return.
    pub intensity: Vec<u8>,
    /// Clean firing time of each return (seconds, as `Return::time`).
    pub time: Vec<f64>,
    /// Clean azimuth of each return (degrees).
    pub azimuth: Vec<f32>,
    /// Maximal runs of consecutive returns with the same packet and block (firings), as
    /// ranges of return indices `[start, end)`, in order.
    pub firings: Vec<[u32; 2]>,
    /// Smallest and largest clean firing time, NaN ignored (`[inf, -inf]` when there is
    /// none): lets stages whose factor is monotone in time table it for the frame.
    pub time_range: [f64; 2],
    /// Some clean firing time is NaN (outside `time_range`).
    pub time_nan: bool,
}

impl Layout {
    /// The columns and firings of `clean`.
    pub fn of(clean: &[Return]) -> Layout {
        Layout::build(clean, |_| {})
    }

    /// The columns and firings of `clean`, with `also` called on every chunk of at most
    /// [`LAYOUT_CHUNK`] returns, in order, in the same pass.
    ///
    /// Why chunks: each chunk's columns are written to small buffers (in L1 cache) and
    /// appended to the columns, which are therefore never zeroed first (`vec![0; n]`
    /// wrote them all once more); `also` reads the chunk's returns while they are in
    /// cache; and the loop over one chunk keeps its few pointers in registers (the
    /// iterator over every column and the return spilled them to the stack).
    #[inline(always)]
    fn build(clean: &[Return], mut also: impl FnMut(&[Return])) -> Layout {
        const B: usize = LAYOUT_CHUNK;
        let n = clean.len();
        let mut l = Layout {
            laser: Vec::with_capacity(n),
            intensity: Vec::with_capacity(n),
            time: Vec::with_capacity(n),
            azimuth: Vec::with_capacity(n),
            firings: Vec::with_capacity(n / 32 + 1),
            time_range: [f64::INFINITY, f64::NEG_INFINITY],
            time_nan: false,
        };
        let (mut laser, mut intensity) = ([0u8; B], [0u8; B]);
        let (mut time, mut azimuth) = ([0f64; B], [0f32; B]);
        // The running extremes of the times, as four pairs (see `TimeExtremes`).
        let mut extremes = TimeExtremes::new();
        // A firing starts where packet or block changes (its end is set below).
        let mut key = None;
        for (c, chunk) in clean.chunks(B).enumerate() {
            also(chunk);
            let m = chunk.len();
            for (j, r) in chunk.iter().enumerate() {
                laser[j] = r.laser & LASER_MASK;
                intensity[j] = r.intensity;
                time[j] = r.time;
                azimuth[j] = r.azimuth;
                let k = (r.packet, r.block);
                if key != Some(k) {
                    key = Some(k);
                    l.firings.push([(c * B + j) as u32, n as u32]);
                }
            }
            extremes.add(&time[..m]);
            l.laser.extend_from_slice(&laser[..m]);
            l.intensity.extend_from_slice(&intensity[..m]);
            l.time.extend_from_slice(&time[..m]);
            l.azimuth.extend_from_slice(&azimuth[..m]);
        }
        // Each firing ends where the next starts (the last at `n`, as pushed).
        for k in 1..l.firings.len() {
            l.firings[k - 1][1] = l.firings[k][0];
        }
        l.time_range = extremes.range();
        l.time_nan = extremes.nan;
        l
    }

    /// Number of returns covered.
    pub fn len(&self) -> usize {
        self.laser.len()
    }

    /// True when it covers no return.
    pub fn is_empty(&self) -> bool {
        self.laser.is_empty()
    }
}

/// Why laser ids (or rings) given at `key` do not all exist on a sensor of `lasers`
/// lasers, if they do not.
pub fn check_ids(key: &str, ids: Option<&[u8]>, lasers: usize) -> Result<(), String> {
    match ids.and_then(|ids| ids.iter().find(|&&i| usize::from(i) >= lasers)) {
        Some(i) => Err(format!(
            "{key} names {i}, but the sensor has {lasers} lasers (0 to {})",
            lasers - 1
        )),
        None => Ok(()),
    }
}

/// A set of laser ids (or rings) below [`spurious::MAX_LASERS`]: the lasers a stage
/// acts on, tested per return with one shift.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LaserSet(u128);

impl LaserSet {
    /// Every id.
    pub const ALL: LaserSet = LaserSet(u128::MAX);
    /// No id.
    pub const NONE: LaserSet = LaserSet(0);

    /// The set of `ids` (ids from [`spurious::MAX_LASERS`] up are taken modulo it).
    pub fn of(ids: &[u8]) -> Self {
        LaserSet(ids.iter().fold(0, |m, &i| m | (1u128 << (i & LASER_MASK))))
    }

    /// True when `id` is in the set (never for an id from [`spurious::MAX_LASERS`] up).
    #[inline]
    pub fn contains(self, id: u8) -> bool {
        id <= LASER_MASK && self.0 & (1u128 << id) != 0
    }
}

/// Keeps a laser id within a per-laser table of [`spurious::MAX_LASERS`] entries.
pub const LASER_MASK: u8 = (spurious::MAX_LASERS - 1) as u8;

/// Returns per chunk of [`Layout`]'s pass (a multiple of 4, see [`TimeExtremes`]).
const LAYOUT_CHUNK: usize = 256;

/// The smallest and largest time of a column fed in order, NaN ignored: four running
/// pairs, so successive comparisons do not wait on each other (a NaN compares false and
/// is left out; the selects are single min/max instructions). Times go to pair `i % 4`
/// by their index `i` in the column, and the last `len % 4` to pair 0, as long as every
/// piece fed but the last has a length that is a multiple of 4.
struct TimeExtremes {
    lo: [f64; 4],
    hi: [f64; 4],
    /// Some time was NaN.
    nan: bool,
}

impl TimeExtremes {
    fn new() -> Self {
        TimeExtremes {
            lo: [f64::INFINITY; 4],
            hi: [f64::NEG_INFINITY; 4],
            nan: false,
        }
    }

    #[inline(always)]
    fn add(&mut self, times: &[f64]) {
        let (lo, hi) = (&mut self.lo, &mut self.hi);
        let mut quads = times.chunks_exact(4);
        for q in &mut quads {
            for k in 0..4 {
                lo[k] = if q[k] < lo[k] { q[k] } else { lo[k] };
                hi[k] = if q[k] > hi[k] { q[k] } else { hi[k] };
            }
        }
        for &t in quads.remainder() {
            lo[0] = if t < lo[0] { t } else { lo[0] };
            hi[0] = if t > hi[0] { t } else { hi[0] };
        }
        self.nan |= times.iter().fold(false, |any, t| any | t.is_nan());
    }

    /// `[smallest, largest]` (`[inf, -inf]` when no time was a number).
    fn range(&self) -> [f64; 2] {
        [
            self.lo.into_iter().fold(f64::INFINITY, f64::min),
            self.hi.into_iter().fold(f64::NEG_INFINITY, f64::max),
        ]
    }
}

/// Per-return angle, pose, time and intensity state of a [`NoisyFrame`]; each vector is
/// allocated (one entry per return) by the first stage that changes it.
#[derive(Clone, Debug, Default)]
pub struct Moved {
    /// Reported azimuth change in degrees (encoder, laser pointing): the point is reported
    /// along the changed direction at its (noisy) range.
    pub azimuth_deg: Option<Vec<f32>>,
    /// Elevation change in degrees, like `azimuth_deg`.
    pub elevation_deg: Option<Vec<f32>>,
    /// Rigid motion applied to the reported point last (mounting, ego-motion, vibration),
    /// one pose per firing.
    pub pose: Option<sensor::Poses>,
    /// Reported firing time (seconds, as `Return::time`).
    pub time: Option<Vec<f64>>,
    /// Clock stretches of the reported firing times, in the order they were made; each
    /// acts on the first [`TimeStretch::len`] returns, after `time` (see
    /// [`Moved::reported_time`]).
    pub time_stretch: Vec<TimeStretch>,
    /// Reported intensity byte.
    pub intensity: Option<Vec<u8>>,
    /// Product of the receivers' gain errors on the intensity byte (`None` = 1), applied
    /// by the intensity rule ([`NoisyFrame::apply_intensity_rule`]).
    pub intensity_gain: Option<f64>,
}

/// The affine map t -> t0 + (t - t0) scale + offset of the reported firing times of the
/// first `len` returns of a frame (the clock's oscillator drift and time offset).
///
/// Why a map and not a vector of times: the clock stage wrote 400 kB of times per
/// 50k-return frame (and read as many), while the map is applied, with the same
/// operations in the same order and so to the same value, only where a time is reported.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TimeStretch {
    /// Fixed point of the stretch (the frame's first firing time), seconds.
    pub t0: f64,
    /// Factor on the time since `t0`.
    pub scale: f64,
    /// Offset added last, seconds.
    pub offset: f64,
    /// Number of returns it covers: those of the frame when it was made (returns added
    /// later, such as spurious echoes, keep their own time).
    pub len: usize,
}

impl TimeStretch {
    /// The stretched time.
    #[inline]
    pub fn apply(&self, t: f64) -> f64 {
        self.t0 + (t - self.t0) * self.scale + self.offset
    }

    /// Time `t` of return `i` through the stretches of `all` that cover `i`, in order.
    #[inline]
    pub fn apply_all(all: &[TimeStretch], i: usize, t: f64) -> f64 {
        all.iter().filter(|s| i < s.len).fold(t, |t, s| s.apply(t))
    }
}

impl Moved {
    /// The reported firing time of return `i` whose clean time is `clean`: `time[i]` if
    /// set (else `clean`), through the stretches that cover `i`, in order.
    #[inline]
    pub fn reported_time(&self, i: usize, clean: f64) -> f64 {
        let t = self.time.as_ref().map_or(clean, |v| v[i]);
        TimeStretch::apply_all(&self.time_stretch, i, t)
    }

    /// The azimuth changes, allocated as zeros on first use.
    pub fn azimuth_mut(&mut self, n: usize) -> &mut Vec<f32> {
        self.azimuth_deg.get_or_insert_with(|| vec![0.0; n])
    }
    /// The elevation changes, allocated as zeros on first use.
    pub fn elevation_mut(&mut self, n: usize) -> &mut Vec<f32> {
        self.elevation_deg.get_or_insert_with(|| vec![0.0; n])
    }
}

/// Room kept in a frame's columns for the returns the chain may add in empty firing
/// slots (a real HDL-32E frame has about 15 % of its slots empty), so that adding them
/// does not move every column of a 50k-return frame (a tenth of a fog stage's time).
pub(crate) fn room_for_added(n: usize) -> usize {
    n / 4 + 64
}

/// The ranges, ideal powers and intensity bytes of `returns`, and their firing slots
/// when `slots` gives the lasers a firing (and the frame is of the usual kind,
/// [`spurious::SlotsBuilder`]), with a copy of the returns appended to `copy` when
/// given: one pass over the returns, a chunk at a time, where separate passes each
/// streamed a frame's 2.4 MB of returns from beyond the L2 cache.
#[allow(clippy::type_complexity)]
fn start_columns(
    returns: &[Return],
    mut copy: Option<&mut Vec<Return>>,
    ideal: &IdealPower,
    slots: Option<usize>,
) -> ((Vec<f32>, Vec<f64>, Vec<u8>), Option<Slots>) {
    let n = returns.len();
    let mut range = Vec::with_capacity(n + room_for_added(n));
    let mut power = Vec::with_capacity(n + room_for_added(n));
    let mut bytes = Vec::with_capacity(n);
    let mut builder = slots.and_then(|lasers| spurious::SlotsBuilder::new(returns, lasers));
    for chunk in returns.chunks(LAYOUT_CHUNK) {
        if let Some(c) = copy.as_mut() {
            c.extend_from_slice(chunk);
        }
        for r in chunk {
            range.push(r.range);
            bytes.push(r.intensity);
        }
        if builder.as_mut().is_some_and(|b| !b.push(chunk)) {
            builder = None;
        }
    }
    // The powers from the columns: a loop that vectorises (a division a return).
    crate::noise::transmission::wide(|| {
        power.extend(range.iter().zip(&bytes).map(|(&r, &b)| ideal.power(b, r)));
    });
    let built = builder.and_then(spurious::SlotsBuilder::finish);
    ((range, power, bytes), built)
}

impl NoisyFrame {
    /// Starts a noisy frame: ranges are the clean ranges, powers the ideal powers.
    pub fn new(index: u32, clean: Vec<Return>, ideal: &IdealPower) -> Self {
        let range = clean.iter().map(|r| r.range).collect();
        let power = clean
            .iter()
            .map(|r| ideal.power(r.intensity, r.range))
            .collect();
        NoisyFrame::of_parts(index, clean, range, power, None)
    }

    /// Same as [`NoisyFrame::new`], also returning the recorded intensity bytes, read in
    /// the same pass (for the intensity rule), and with the firing slots built in it
    /// when `slots` gives the lasers a firing (for chains whose stages propose echoes).
    fn new_keeping_bytes(
        index: u32,
        clean: Vec<Return>,
        ideal: &IdealPower,
        slots: Option<usize>,
    ) -> (Self, Vec<u8>) {
        let (columns, built) = start_columns(&clean, None, ideal, slots);
        NoisyFrame::of_columns(index, clean, columns, built)
    }

    /// [`NoisyFrame::new_keeping_bytes`] of a copy of `returns`, made in the same pass.
    fn copy_keeping_bytes(
        index: u32,
        returns: &[Return],
        ideal: &IdealPower,
        slots: Option<usize>,
    ) -> (Self, Vec<u8>) {
        let n = returns.len();
        let mut clean = Vec::with_capacity(n + room_for_added(n));
        let (columns, built) = start_columns(returns, Some(&mut clean), ideal, slots);
        NoisyFrame::of_columns(index, clean, columns, built)
    }

    fn of_columns(
        index: u32,
        clean: Vec<Return>,
        (range, power, bytes): (Vec<f32>, Vec<f64>, Vec<u8>),
        slots: Option<Slots>,
    ) -> (Self, Vec<u8>) {
        let mut frame = NoisyFrame::of_parts(index, clean, range, power, None);
        frame.slots = slots.map(Arc::new);
        (frame, bytes)
    }

    /// Same as [`NoisyFrame::new`] with its [`Layout`] built in the same pass over the
    /// returns (for chains whose stages read it: a 50k-return frame's returns are
    /// 2.4 MB, and the three passes of `new` and `Layout::of` each streamed them).
    pub fn with_layout(index: u32, clean: Vec<Return>, ideal: &IdealPower) -> Self {
        let n = clean.len();
        let mut range = Vec::with_capacity(n + room_for_added(n));
        let mut power = Vec::with_capacity(n + room_for_added(n));
        // The same values as `new`, a chunk at a time (see `Layout::build`).
        let l = Layout::build(&clean, |chunk| {
            range.extend(chunk.iter().map(|r| r.range));
            power.extend(chunk.iter().map(|r| ideal.power(r.intensity, r.range)));
        });
        NoisyFrame::of_parts(index, clean, range, power, Some(Arc::new(l)))
    }

    fn of_parts(
        index: u32,
        clean: Vec<Return>,
        range: Vec<f32>,
        power: Vec<f64>,
        layout: Option<Arc<Layout>>,
    ) -> Self {
        let n = clean.len();
        let room = range.capacity().max(n);
        let mut fate = Vec::with_capacity(room);
        fate.resize(n, Fate::Kept);
        let mut cause = Vec::with_capacity(room);
        cause.resize(n, NO_CAUSE);
        NoisyFrame {
            index,
            clean,
            clean_len: n,
            range,
            power,
            fate,
            cause,
            threshold: crate::config::DetectionConfig::default().min_power,
            min_range: crate::config::DetectionConfig::default().min_range_m,
            stage: 0,
            candidates: Vec::new(),
            dense: None,
            recorded_intensity: None,
            slots: None,
            lasers: spurious::DEFAULT_LASERS,
            power_model: None,
            detection: None,
            decided: false,
            moved: Moved::default(),
            layout,
        }
    }

    /// The compact columns and firing runs of the clean returns, built on first use and
    /// shared by the stages of the chain (stages do not change the clean returns).
    pub fn layout(&mut self) -> Arc<Layout> {
        match &self.layout {
            Some(l) if l.len() == self.clean.len() => Arc::clone(l),
            _ => {
                let l = Arc::new(Layout::of(&self.clean));
                self.layout = Some(Arc::clone(&l));
                l
            }
        }
    }

    /// Sets the fate of return `i`, recording the stage being applied as its cause.
    #[inline]
    pub fn set_fate(&mut self, i: usize, fate: Fate) {
        self.fate[i] = fate;
        self.cause[i] = self.stage;
    }

    /// True if the sensor could detect an echo of `power` at `range` metres now (power at
    /// or above the current threshold, range at or above the minimum range).
    #[inline]
    pub fn detectable(&self, range: f32, power: f64) -> bool {
        power >= self.threshold && f64::from(range) >= self.min_range
    }

    /// True if return `i` is alive and the sensor detects it: a recorded return already
    /// decided by the probabilistic rule ([`NoisyFrame::decided`]) by its range alone,
    /// any other by [`NoisyFrame::detectable`].
    #[inline]
    pub fn return_detectable(&self, i: usize) -> bool {
        let fate = self.fate[i];
        fate.is_alive()
            & (f64::from(self.range[i]) >= self.min_range)
            & (detection::settled(i, fate, self.decided_len()) | (self.power[i] >= self.threshold))
    }

    /// How many returns (the first, recorded ones) [`detection::decide_recorded`] decided:
    /// the recorded returns once it ran, none before.
    #[inline]
    pub fn decided_len(&self) -> usize {
        if self.decided {
            self.clean_len
        } else {
            0
        }
    }

    /// kappa (m^2) of the frame's power model, or of the default one for frames built
    /// without it.
    pub fn kappa_m2(&self) -> f64 {
        self.power_model
            .as_ref()
            .map_or(power::DEFAULT_KAPPA_M2, |m| m.constants().kappa_m2)
    }

    /// The intensity rule (module documentation, "Intensity"): every kept return reports
    /// its recorded byte times g P / P_i, rounded once and clamped to the byte, where
    /// `ideal` holds each return's ideal power P_i (the powers the frame started with)
    /// and g is [`Moved::intensity_gain`]; spurious and dropped returns keep their byte.
    /// The intensity column is kept only when some byte changes.
    ///
    /// One pass over the returns that writes the whole column (50 kB for a 50k-return
    /// frame) and reads the recorded bytes once (from the layout when built: 1 byte per
    /// return against 48 in `clean`); a first pass to find whether anything changes, then
    /// a copy of the bytes, read `clean` twice and cost twice as much.
    pub fn apply_intensity_rule(&mut self, ideal: &[f64]) {
        let n = ideal.len().min(self.clean_len);
        // The recorded bytes (a copy from the layout, or one strided read of `clean`).
        let recorded = match self.layout.as_ref().filter(|l| l.len() >= n) {
            Some(l) => l.intensity[..n].to_vec(),
            None => self.clean[..n].iter().map(|r| r.intensity).collect(),
        };
        self.intensity_rule_on(ideal, recorded);
    }

    /// [`NoisyFrame::apply_intensity_rule`] with the recorded bytes of the first
    /// `ideal.len()` returns given (and reused as the intensity column): the chain reads
    /// them in the pass that computes the ideal powers, where the returns are in cache,
    /// rather than once more from the 48-byte returns at the end.
    fn intensity_rule_on(&mut self, ideal: &[f64], mut col: Vec<u8>) {
        let g = self.moved.intensity_gain.unwrap_or(1.0);
        let n = ideal.len().min(self.clean_len).min(col.len());
        col.truncate(n);
        let NoisyFrame {
            clean,
            power,
            fate,
            moved,
            ..
        } = self;
        let existing = moved.intensity.as_deref();
        let any = intensity_bytes(
            &mut col[..n],
            existing.map(|c| &c[..n.min(c.len())]),
            (&power[..n], &ideal[..n], &fate[..n]),
            g,
        );
        if !any {
            return;
        }
        // Returns past the ideal powers (added by stages) keep their bytes.
        col.extend((n..clean.len()).map(|i| existing.map_or(clean[i].intensity, |c| c[i])));
        moved.intensity = Some(col);
    }

    /// Number of returns (clean and noisy alike).
    pub fn len(&self) -> usize {
        self.clean.len()
    }

    /// True if the frame has no returns.
    pub fn is_empty(&self) -> bool {
        self.clean.is_empty()
    }

    /// Indices (into `clean`) of the returns the sensor reports (kept, replaced and
    /// added), in order.
    pub fn kept_indices(&self) -> Vec<u32> {
        // Branch-free compaction (write every index, advance past the kept ones) into a
        // buffer sized once: a filtered `collect` grows its buffer step by step.
        let mut kept = vec![0u32; self.fate.len()];
        let mut k = 0;
        for (i, fate) in self.fate.iter().enumerate() {
            kept[k] = i as u32;
            k += usize::from(fate.is_alive());
        }
        kept.truncate(k);
        kept
    }

    /// The surviving returns with the noisy range; x, y, z are scaled by R_n / R_i so the
    /// point moves along its beam. Pairs with [`NoisyFrame::kept_indices`].
    ///
    /// Sensor stages may also have changed the reported angles (the point is then placed
    /// along the changed direction), time and intensity, and moved the point rigidly
    /// (`moved.pose`, applied last; range and angles stay as the sensor reports them).
    pub fn survivors(&self) -> Vec<Return> {
        let view = View::of(self);
        let mut out = Vec::with_capacity(self.len());
        if view.plain() {
            // No sensor stage moved anything: only the range scaling, in a loop free of
            // the per-return tests of the optional parts (`along_beam`, as `noisy_return`
            // starts).
            for ((r, &rn), fate) in self.clean.iter().zip(&self.range).zip(&self.fate) {
                if fate.is_alive() {
                    out.push(along_beam(r, rn));
                }
            }
            return out;
        }
        for (i, fate) in self.fate.iter().enumerate() {
            if fate.is_alive() {
                out.push(view.noisy_return(i));
            }
        }
        out
    }

    /// The noisy version of return `i` (whatever its fate).
    pub fn noisy_return(&self, i: usize) -> Return {
        View::of(self).noisy_return(i)
    }

    /// What the sensor reports of each return, for callers that visit many: see
    /// [`Reported::of`].
    pub fn reported(&self) -> Reported<'_> {
        Reported {
            view: View::of(self),
            fate: &self.fate,
        }
    }

    /// Counts and range statistics of this frame.
    pub fn summary(&self) -> NoiseSummary {
        NoiseSummary::from_frame(self)
    }
}

/// Return `r` moved along its beam to range `rn` (x, y, z scaled by `rn / r.range`).
// Inlined into the loops of `survivors` for the reason given at `View::noisy_return`.
#[inline(always)]
fn along_beam(r: &Return, rn: f32) -> Return {
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
}

/// The returns of a [`NoisyFrame`] as reported: noisy where the sensor still reports
/// the return, as recorded where it was dropped (as `run --keep-dropped` writes them).
/// The frame's optional parts are resolved once for all the returns visited, where
/// [`NoisyFrame::noisy_return`] resolves them at every call.
pub struct Reported<'a> {
    view: View<'a>,
    fate: &'a [Fate],
}

impl Reported<'_> {
    /// Return `i` as reported.
    #[inline(always)]
    pub fn of(&self, i: usize) -> Return {
        if self.fate[i].is_alive() {
            self.view.noisy_return(i)
        } else {
            self.view.clean[i]
        }
    }
}

/// The per-return state of a [`NoisyFrame`] with its optional parts resolved once, so
/// the per-return loop of [`NoisyFrame::survivors`] tests no `Option` per return.
struct View<'a> {
    clean: &'a [Return],
    range: &'a [f32],
    azimuth: Option<&'a [f32]>,
    elevation: Option<&'a [f32]>,
    pose: Option<&'a sensor::Poses>,
    time: Option<&'a [f64]>,
    time_stretch: &'a [TimeStretch],
    intensity: Option<&'a [u8]>,
}

impl<'a> View<'a> {
    fn of(frame: &'a NoisyFrame) -> Self {
        let m = &frame.moved;
        View {
            clean: &frame.clean,
            range: &frame.range,
            azimuth: m.azimuth_deg.as_deref(),
            elevation: m.elevation_deg.as_deref(),
            pose: m.pose.as_ref(),
            time: m.time.as_deref(),
            time_stretch: &m.time_stretch,
            intensity: m.intensity.as_deref(),
        }
    }

    /// True when no sensor state is set (only the range changed).
    fn plain(&self) -> bool {
        self.azimuth.is_none()
            && self.elevation.is_none()
            && self.pose.is_none()
            && self.time.is_none()
            && self.time_stretch.is_empty()
            && self.intensity.is_none()
    }

    // Inlined into the loop of `survivors` so the return is built in registers and stored
    // once into the output (a call wrote it to the stack first and the loop copied it,
    // stalling on the store forwarding of every return).
    #[inline(always)]
    fn noisy_return(&self, i: usize) -> Return {
        let r = &self.clean[i];
        let mut out = along_beam(r, self.range[i]);
        let da = self.azimuth.map_or(0.0, |v| v[i]);
        let de = self.elevation.map_or(0.0, |v| v[i]);
        if (da != 0.0 || de != 0.0) && r.range > 0.0 {
            // Turn the actual direction of the point (whatever the calibration's azimuth
            // offsets): elevation in the vertical plane of the beam, then azimuth about
            // z, clockwise seen from above like the sensor's azimuth.
            let (x, y, z) = (f64::from(out.x), f64::from(out.y), f64::from(out.z));
            let (se, ce) = small_sin_cos(f64::from(de).to_radians());
            let (x1, y1, z2) = if de != 0.0 || (x == 0.0 && y == 0.0) {
                let h = (x * x + y * y).sqrt();
                let (h2, z2) = (h * ce - z * se, h * se + z * ce);
                if h > 0.0 {
                    let k = h2 / h;
                    (x * k, y * k, z2)
                } else {
                    (h2, 0.0, z2)
                }
            } else {
                // No elevation change (se = +-0, ce = 1) and h > 0: the turn above gives
                // h2 = h, k = 1 and z2 = (+-0) + z exactly, so skip its square root and
                // division (h * se is a zero with the sign of se).
                (x, y, se + z * ce)
            };
            let (sa, ca) = small_sin_cos(f64::from(da).to_radians());
            out.x = (x1 * ca + y1 * sa) as f32;
            out.y = (y1 * ca - x1 * sa) as f32;
            out.z = z2 as f32;
            out.azimuth = wrap_360(f64::from(r.azimuth) + f64::from(da)) as f32;
            out.elevation = r.elevation + de;
        }
        if let Some(p) = self.pose {
            let [x, y, z] = p.of(i).apply([out.x, out.y, out.z], r.time - p.t_ref);
            out.x = x;
            out.y = y;
            out.z = z;
        }
        if let Some(t) = self.time {
            out.time = t[i];
        }
        // As `Moved::reported_time` (here with `time` resolved once).
        out.time = TimeStretch::apply_all(self.time_stretch, i, out.time);
        if let Some(v) = self.intensity {
            out.intensity = v[i];
        }
        out
    }
}

/// `x` rounded half up and clamped to a byte, the value of
/// [`sensor::scale_byte`]`(1, x)` (`round(x).clamp(0, 255)`): [`round_clamped`] to 255.
#[inline(always)]
fn round_byte(x: f64) -> u8 {
    round_clamped(x, 255) as u8
}

/// `x.round().clamp(0.0, max) as u16` without the libm call `round` is on the x86-64
/// baseline and without a branch: the clamp first, in floating point (max(NaN, 0) is 0,
/// so the conversion is a plain one that vectorises), then one step up by the fraction,
/// which `x - t` gives exactly (t <= max <= x, or 0 <= x - t < 1).
#[inline(always)]
pub(crate) fn round_clamped(x: f64, max: u16) -> u16 {
    // `clamp` would pass a NaN through.
    #[allow(clippy::manual_clamp)]
    let c = x.max(0.0).min(f64::from(max));
    // SAFETY: c is finite and in [0, 65535], so its integer part fits an i32.
    let t = unsafe { c.to_int_unchecked::<i32>() };
    let up = i32::from(x - f64::from(t) >= 0.5);
    (t + up).min(i32::from(max)) as u16
}

/// The intensity rule on recorded bytes `bytes` in place (module documentation,
/// "Intensity"): each kept return's byte times g P / P_i, rounded once and clamped;
/// other returns get their current byte (`current`, else their recorded one). True when
/// some byte differs from the current one. Free of branches so it vectorises, with
/// AVX-512 or AVX2 where the processor has it (see [`transmission::wide`]).
fn intensity_bytes(
    bytes: &mut [u8],
    current: Option<&[u8]>,
    columns: (&[f64], &[f64], &[Fate]),
    g: f64,
) -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        if transmission::avx512() {
            // SAFETY: the processor has AVX-512 F and DQ (checked on the line above).
            return unsafe { intensity_bytes_avx512(bytes, current, columns, g) };
        }
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the processor has AVX2 (checked on the line above).
            return unsafe { intensity_bytes_avx2(bytes, current, columns, g) };
        }
    }
    intensity_bytes_body(bytes, current, columns, g)
}

/// [`intensity_bytes`] compiled with AVX-512.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx512dq")]
unsafe fn intensity_bytes_avx512(
    bytes: &mut [u8],
    current: Option<&[u8]>,
    columns: (&[f64], &[f64], &[Fate]),
    g: f64,
) -> bool {
    intensity_bytes_body(bytes, current, columns, g)
}

/// [`intensity_bytes`] compiled with AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn intensity_bytes_avx2(
    bytes: &mut [u8],
    current: Option<&[u8]>,
    columns: (&[f64], &[f64], &[Fate]),
    g: f64,
) -> bool {
    intensity_bytes_body(bytes, current, columns, g)
}

/// The loops of [`intensity_bytes`].
#[inline(always)]
fn intensity_bytes_body(
    bytes: &mut [u8],
    current: Option<&[u8]>,
    (power, ideal, fate): (&[f64], &[f64], &[Fate]),
    g: f64,
) -> bool {
    // The rule's byte of a return whose recorded byte is `v`, or `cur` unless kept.
    let byte = |v: u8, p: f64, p0: f64, fate: Fate, cur: u8| {
        // A zero ideal power (reflectance floor 0 and byte 0) has byte 0 anyway.
        let f = if p0 > 0.0 { g * (p / p0) } else { g };
        let new = round_byte(f64::from(v) * f);
        if fate == Fate::Kept {
            new
        } else {
            cur
        }
    };
    let parts = power.iter().zip(ideal).zip(fate);
    let mut any = false;
    match current {
        // One loop per case, so neither tests an `Option` per return.
        None => {
            for (v, ((&p, &p0), &fate)) in bytes.iter_mut().zip(parts) {
                let out = byte(*v, p, p0, fate, *v);
                any |= out != *v;
                *v = out;
            }
        }
        Some(c) => {
            for ((v, &cur), ((&p, &p0), &fate)) in bytes.iter_mut().zip(c).zip(parts) {
                let out = byte(*v, p, p0, fate, cur);
                any |= out != cur;
                *v = out;
            }
        }
    }
    any
}

/// `a.rem_euclid(360.0)` without the `fmod` call for the angles sensor stages produce
/// (within one turn of [0, 360)): the same value, since `a - 360` is exact there and
/// `a + 360` is the rounded sum `rem_euclid` also returns.
#[inline]
pub(crate) fn wrap_360(a: f64) -> f64 {
    if (0.0..360.0).contains(&a) {
        a
    } else if a > -360.0 && a < 0.0 {
        // (-360 itself gives -0.0 under rem_euclid: left to it below.)
        a + 360.0
    } else if (360.0..720.0).contains(&a) {
        a - 360.0
    } else {
        a.rem_euclid(360.0)
    }
}

/// sin and cos of `t` radians; a Taylor series for the small angles sensor stages use
/// (|t| < 0.01: truncation error below 1e-13, far under f32 precision), which is several
/// times faster than `sin_cos` in the per-return loop of [`NoisyFrame::survivors`].
///
/// The series multiplies by rounded reciprocals instead of dividing by 6, 20 and 12 (and
/// by 0.5 instead of 2, which is exact): its four divisions were most of its time, and a
/// rounded reciprocal moves a term by an ulp, 1e-16 of a term itself under 2e-5.
pub(crate) fn small_sin_cos(t: f64) -> (f64, f64) {
    if t.abs() < 0.01 {
        let t2 = t * t;
        (
            t * (1.0 - t2 * (1.0 / 6.0) * (1.0 - t2 * (1.0 / 20.0))),
            1.0 - t2 * 0.5 * (1.0 - t2 * (1.0 / 12.0)),
        )
    } else {
        t.sin_cos()
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn small_sin_cos_agrees_with_sin_cos() {
        // A dense walk over the series' range (-0.01, 0.01) and past it, with its ends and
        // signed zeros: within 1e-14 of libm (a wrong coefficient, e.g. 1/7 for 1/6, is
        // off by 2e-8 at 0.01), the sign of sin kept, and libm itself past the range.
        let mut ts = vec![0.0, -0.0, 1e-300, -1e-300, 0.009_999_999, -0.009_999_999];
        ts.extend((-60_000..=60_000).map(|k| f64::from(k) * 4.999_9e-7));
        for t in ts {
            let ((s, c), (ls, lc)) = (small_sin_cos(t), t.sin_cos());
            assert!((s - ls).abs() < 1e-14 && (c - lc).abs() < 1e-14, "{t:e}");
            assert_eq!(s.to_bits() >> 63, ls.to_bits() >> 63, "sign of sin {t:e}");
            if t.abs() >= 0.01 {
                assert_eq!((s.to_bits(), c.to_bits()), (ls.to_bits(), lc.to_bits()));
            }
        }
        assert_eq!(small_sin_cos(0.5), 0.5f64.sin_cos());
    }

    /// Bytes, powers, ideal powers, fates, ranges and draws.
    type Columns = (Vec<u8>, Vec<f64>, Vec<f64>, Vec<Fate>, Vec<f32>, Vec<f64>);

    /// Columns of mixed fates, powers (zero, tiny, large, NaN) and bytes, from a fixed seed.
    fn mixed_columns(n: usize) -> Columns {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let fates = [
            Fate::Kept,
            Fate::Occluded,
            Fate::BelowPower,
            Fate::Replaced,
            Fate::Added,
        ];
        let mut cols = (vec![], vec![], vec![], vec![], vec![], vec![]);
        for i in 0..n {
            cols.0.push(rng.random::<u8>());
            let p = match i % 7 {
                0 => 0.0,
                1 => f64::NAN,
                2 => 1e-300,
                _ => rng.random::<f64>() * 3.0,
            };
            cols.1.push(p);
            cols.2.push(if i % 11 == 0 {
                0.0
            } else {
                rng.random::<f64>() * 2.0
            });
            cols.3.push(fates[rng.random_range(0..fates.len())]);
            cols.4.push(rng.random::<f32>() * 120.0);
            cols.5.push(rng.random::<f64>() * 2.0 - 1.0);
        }
        cols
    }

    #[test]
    fn the_wide_intensity_loop_gives_the_plain_loops_bits() {
        // The AVX2 and AVX-512 builds (where this machine has them) against the loop
        // compiled for the baseline: the same bytes, with and without current bytes.
        let (bytes, power, ideal, fate, _, _) = mixed_columns(10_007);
        let current: Vec<u8> = bytes.iter().map(|b| b.wrapping_mul(3)).collect();
        type Rule = fn(&mut [u8], Option<&[u8]>, (&[f64], &[f64], &[Fate]), f64) -> bool;
        let mut builds: Vec<(&str, Rule)> = vec![("picked", intensity_bytes)];
        #[cfg(target_arch = "x86_64")]
        {
            if std::arch::is_x86_feature_detected!("avx2") {
                // SAFETY: the processor has AVX2 (checked on the line above).
                builds.push(("avx2", |b, c, cols, g| unsafe {
                    intensity_bytes_avx2(b, c, cols, g)
                }));
            }
            if transmission::avx512() {
                // SAFETY: the processor has AVX-512 F and DQ (checked on the line above).
                builds.push(("avx512", |b, c, cols, g| unsafe {
                    intensity_bytes_avx512(b, c, cols, g)
                }));
            }
        }
        for (name, build) in &builds {
            for cur in [None, Some(&current[..])] {
                for g in [1.0, 0.37, 2.5] {
                    let (mut a, mut b) = (bytes.clone(), bytes.clone());
                    let any_a = build(&mut a, cur, (&power, &ideal, &fate), g);
                    let any_b = intensity_bytes_body(&mut b, cur, (&power, &ideal, &fate), g);
                    assert_eq!((a, any_a), (b, any_b), "{name}");
                }
            }
        }
    }

    #[test]
    fn the_wide_attenuation_gives_the_plain_loops_bits() {
        let (_, power, _, fate, range, _) = mixed_columns(10_007);
        let mut wide = power.clone();
        transmission::attenuate(&mut wide, &range, &fate, 0.013);
        for i in 0..power.len() {
            let t = transmission::exp_nonpositive(-0.013 * f64::from(range[i]));
            let want = if fate[i].is_alive() {
                power[i] * t
            } else {
                power[i]
            };
            assert_eq!(wide[i].to_bits(), want.to_bits(), "{i}");
        }
    }

    #[test]
    fn round_byte_is_scale_byte() {
        let mut xs = vec![
            f64::NAN,
            -1.0,
            -0.4,
            -0.0,
            0.0,
            0.5,
            254.5,
            255.49,
            255.5,
            1e12,
        ];
        xs.push(f64::INFINITY);
        xs.push(f64::NEG_INFINITY);
        xs.extend((0..60_000).map(|k| f64::from(k) * 0.004_999_7));
        xs.extend((0..=600).map(|k| f64::from(k) * 0.5));
        xs.push(0.499_999_999_999_999_94);
        for x in xs {
            let want = x.round().clamp(0.0, 255.0) as u8;
            assert_eq!(round_byte(x), want, "{x}");
            assert_eq!(round_byte(x), sensor::scale_byte(1, x), "{x}");
        }
    }

    #[test]
    fn wrap_360_agrees_with_rem_euclid() {
        let mut a = -1000.0f64;
        while a < 1000.0 {
            for x in [
                a,
                a + 1e-9,
                -1e-300,
                -0.0,
                0.0,
                359.99999999999994,
                -360.0,
                720.0,
            ] {
                assert_eq!(wrap_360(x).to_bits(), x.rem_euclid(360.0).to_bits(), "{x}");
            }
            a += 0.37;
        }
    }

    /// `n` returns: firings of up to 32 lasers (some missing), times with NaNs and a
    /// repeat, azimuths varied.
    fn returns(n: usize) -> Vec<Return> {
        (0..n)
            .map(|i| {
                let k = i as u32;
                let time = match i % 97 {
                    5 => f64::NAN,
                    6 => 0.25,
                    _ => 0.25 + f64::from(k) * 1.152e-6 - f64::from(k % 7) * 3e-6,
                };
                Return {
                    range: 1.0 + (k.wrapping_mul(2_654_435_761) % 7900) as f32 / 100.0,
                    azimuth: (k / 29) as f32 * 0.17 + (k % 3) as f32 * 0.01,
                    time,
                    packet: k / 350,
                    intensity: (k % 101) as u8,
                    laser: (k % 29) as u8 + 3 * u8::from(k.is_multiple_of(5)),
                    block: ((k / 29) % 12) as u8,
                    ..crate::sensor::decode::BLANK
                }
            })
            .collect()
    }

    #[test]
    fn the_clamped_rounding_is_libms() {
        let mut xs = vec![
            0.0,
            -0.0,
            0.5,
            -0.5,
            1.5,
            -1.5,
            2.5,
            -2.5,
            0.499_999_999_999_999_94,
            -0.499_999_999_999_999_94,
            254.5,
            255.49,
            255.5,
            65_534.5,
            65_535.4,
            65_535.5,
            1e12,
            -1e12,
            4.5e15,
            9.3e18,
            -9.3e18,
            1e300,
            -1e300,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NAN,
            f64::MIN_POSITIVE,
            -f64::MIN_POSITIVE,
        ];
        xs.extend((-200_000..200_000).map(|k| f64::from(k) * 0.004_999_7));
        xs.extend((-2_000..2_000).map(|k| f64::from(k) * 0.5));
        xs.extend((0..2_000).map(|k| 65_000.0 + f64::from(k) * 0.37));
        for x in xs {
            assert_eq!(
                round_clamped(x, 255),
                x.round().clamp(0.0, 255.0) as u16,
                "{x}"
            );
            let want = x.round().clamp(0.0, f64::from(u16::MAX)) as u16;
            assert_eq!(round_clamped(x, u16::MAX), want, "{x}");
        }
    }

    #[test]
    fn a_copied_frame_gives_what_the_owned_frame_gives() {
        // `process` copies the returns in the pass that reads them and builds the firing
        // slots there; `process_owned` reads the returns it is given. Weather with
        // echoes of every kind, and a sensor chain (the layout's path).
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("configs");
        for name in [
            "adverse-weather.toml",
            "pdiagram-world.toml",
            "pdiagram-sensor.toml",
        ] {
            let path = dir.join(name);
            let (cfg, _) = Config::load(Some(&path), &[], None).unwrap();
            let chain = NoiseChain::new(&cfg);
            let frame = Frame {
                index: 3,
                partial: false,
                returns: returns(5000),
            };
            let a = chain.process(&frame);
            let b = chain.process_owned(frame.clone());
            let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&a.power), bits(&b.power), "{name}");
            assert_eq!(a.range, b.range, "{name}");
            assert_eq!(a.fate, b.fate, "{name}");
            assert_eq!(a.cause, b.cause, "{name}");
            // Debug text: the returns' times hold NaNs.
            let text = |f: &NoisyFrame| format!("{:?}", f.clean);
            assert!(text(&a) == text(&b), "{name}: the returns differ");
            assert_eq!(a.moved.intensity, b.moved.intensity, "{name}");
            assert!(
                a.fate.iter().any(|f| *f != Fate::Kept),
                "{name}: nothing happened"
            );
        }
    }

    #[test]
    fn with_layout_gives_new_s_values_and_the_columns_of_each_return() {
        let ideal = IdealPower::new(
            &crate::config::PowerConfig::default(),
            &crate::config::SensorConfig::default(),
            &crate::config::DetectionConfig::default(),
        );
        // Sizes around the chunk of `Layout::build` and its quads.
        for n in [0, 1, 3, 255, 256, 257, 1000, 3 * LAYOUT_CHUNK + 5] {
            let clean = returns(n);
            let a = NoisyFrame::with_layout(3, clean.clone(), &ideal);
            let b = NoisyFrame::new(3, clean.clone(), &ideal);
            assert_eq!(a.range, b.range);
            assert!(a
                .power
                .iter()
                .zip(&b.power)
                .all(|(x, y)| x.to_bits() == y.to_bits()));
            let l = a.layout.as_ref().expect("built");
            for (i, r) in clean.iter().enumerate() {
                assert_eq!(l.laser[i], r.laser & LASER_MASK);
                assert_eq!(l.intensity[i], r.intensity);
                assert_eq!(l.time[i].to_bits(), r.time.to_bits());
                assert_eq!(l.azimuth[i].to_bits(), r.azimuth.to_bits());
            }
            assert_eq!(l.len(), n);
            // Firings: maximal runs of the same (packet, block), covering every return.
            let mut runs: Vec<[u32; 2]> = Vec::new();
            for (i, r) in clean.iter().enumerate() {
                match runs.last_mut() {
                    Some(last)
                        if {
                            let p = &clean[i - 1];
                            (p.packet, p.block) == (r.packet, r.block)
                        } =>
                    {
                        last[1] = i as u32 + 1
                    }
                    _ => runs.push([i as u32, i as u32 + 1]),
                }
            }
            assert_eq!(l.firings, runs);
            let numbers = clean.iter().map(|r| r.time).filter(|t| !t.is_nan());
            let lo = numbers.clone().fold(f64::INFINITY, f64::min);
            let hi = numbers.fold(f64::NEG_INFINITY, f64::max);
            assert_eq!(l.time_range, [lo, hi], "{n}");
            assert_eq!(l.time_nan, clean.iter().any(|r| r.time.is_nan()), "{n}");
        }
    }

    #[test]
    fn time_stretches_give_the_times_of_stretching_each_time_in_place() {
        let clean = returns(700);
        let maps = [
            TimeStretch {
                t0: clean[0].time,
                scale: 1.0 + 80e-6,
                offset: 12.5e-6,
                len: 600,
            },
            TimeStretch {
                t0: clean[0].time,
                scale: 1.0 - 20e-6,
                offset: -3e-6,
                len: 650,
            },
        ];
        let mut moved = Moved::default();
        // In place, as the clock did: each stretch over the times of the returns it
        // covers (here the returns beyond a stretch's `len` came later).
        let mut times: Vec<f64> = clean.iter().map(|r| r.time).collect();
        for m in &maps {
            moved.time_stretch.push(*m);
            for t in &mut times[..m.len] {
                *t = m.t0 + (*t - m.t0) * m.scale + m.offset;
            }
        }
        let frame = NoisyFrame {
            range: clean.iter().map(|r| r.range).collect(),
            fate: vec![Fate::Kept; clean.len()],
            clean: clean.clone(),
            moved,
            ..NoisyFrame::default()
        };
        let out = frame.survivors();
        for (i, r) in clean.iter().enumerate() {
            let want = times[i].to_bits();
            assert_eq!(frame.moved.reported_time(i, r.time).to_bits(), want, "{i}");
            assert_eq!(out[i].time.to_bits(), want, "{i}");
        }
    }

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
