//! [`NoisyFrame`]: a frame on its way through the chain, the clean returns with their
//! per-return noisy state.

use super::layout::LAYOUT_CHUNK;
use super::reported::{intensity_bytes, View};
use super::*;
use crate::frame::Return;
use std::sync::Arc;

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
    crate::numeric::wide(|| {
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
    pub(super) fn new_keeping_bytes(
        index: u32,
        clean: Vec<Return>,
        ideal: &IdealPower,
        slots: Option<usize>,
    ) -> (Self, Vec<u8>) {
        let (columns, built) = start_columns(&clean, None, ideal, slots);
        NoisyFrame::of_columns(index, clean, columns, built)
    }

    /// [`NoisyFrame::new_keeping_bytes`] of a copy of `returns`, made in the same pass.
    pub(super) fn copy_keeping_bytes(
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
    pub(super) fn intensity_rule_on(&mut self, ideal: &[f64], mut col: Vec<u8>) {
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
pub(super) fn along_beam(r: &Return, rn: f32) -> Return {
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
