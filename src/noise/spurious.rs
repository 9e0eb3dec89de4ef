//! Spurious echoes: firing slots, the echoes stages propose, and the sensor's return logic
//! that chooses once per slot what the sensor reports.
//!
//! A sensor reports at most one return per laser per firing in single-return mode
//! (strongest 0x37 or last 0x38) and two in dual mode (0x39). Scatter stages (fog, snow,
//! rain drops, crosstalk, spoofing, ...) therefore do not write returns themselves: they
//! [propose](NoisyFrame::propose) echoes, and after the whole chain [`resolve`] lets every
//! slot's detectable echoes compete once with its return, as the sensor's return logic
//! does (`pdiagram-models.md`, "Spurious and replaced returns" and "Interactions": choosing
//! once keeps the stage order from deciding the result):
//! - strongest mode: the echo of highest power is reported;
//! - last mode: the farthest echo is reported;
//! - dual mode: the farthest is reported as the last return and the strongest of the
//!   others as the strongest (the last one again when it is the only echo).
//!
//! Only detectable echoes take part (power at or above the frame's threshold, range at or
//! above the minimum range), so an echo never hides a return and is then dropped by the
//! filters. Ties go to the recorded return, then to the earlier proposal. A slot whose
//! return was occluded gets no echo (occlusion removes the beam); an empty slot counts as
//! occluded when the return of the same laser its direction is taken from was.
//!
//! The winner replaces the slot's return (fate [`Fate::Replaced`], `clean` kept, so
//! `range_clean` stays the recorded range) or, in an empty slot, is appended as a new
//! return (fate [`Fate::Added`]); either way `cause` names the proposing stage.

use super::{Fate, NoisyFrame};
use crate::frame::{Return, ReturnKind};
use std::collections::HashMap;
use std::sync::Arc;

/// A spurious echo a stage proposes for one firing slot.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Echo {
    /// Range of the echo in metres (along the slot's beam).
    pub range: f32,
    /// Received power as a fraction of emitted power (the scale of `NoisyFrame::power`).
    pub power: f64,
}

impl Echo {
    /// No echo: the entry of a return without one in [`NoisyFrame::propose_each`].
    pub const NONE: Echo = Echo {
        range: f32::NAN,
        power: f64::NAN,
    };
}

/// Index of a firing slot in [`Slots`]: `firing * lasers + laser`.
pub type SlotId = u32;

/// An echo waiting for [`resolve`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Candidate {
    /// The slot it competes in.
    pub slot: SlotId,
    /// The echo.
    pub echo: Echo,
    /// Index in the chain of the stage that proposed it.
    pub stage: u8,
}

/// Echoes one stage proposed for every recorded return at once, one along each return's
/// beam in its slot: a column rather than a candidate each, because fog proposes one for
/// nearly every return and most lose to the return (pushing and then ranking a frame's
/// worth of candidates was a sixth of a weather chain's time). [`resolve`] treats them
/// as candidates proposed by `stage` in return order, before that stage's other ones.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct DenseEchoes {
    /// Index in the chain of the stage that proposed them.
    pub stage: u8,
    /// Per recorded return: its echo, or a NaN power for none.
    pub echo: Vec<Echo>,
}

/// Which return logic the capture's firings follow.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SlotMode {
    /// One return per laser and firing, the strongest.
    Strongest,
    /// One return per laser and firing, the last.
    Last,
    /// Two returns per laser and firing: last and strongest.
    Dual,
}

/// One firing (one block, or a pair of blocks in dual mode) of a frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Firing {
    /// Capture record (packet) that carried it.
    pub packet: u32,
    /// Its block in the packet (the even block of a dual pair).
    pub block: u8,
}

/// The firing slots of a frame: every (firing, laser) pair, occupied or not.
#[derive(Clone, Debug)]
pub struct Slots {
    /// The return logic.
    pub mode: SlotMode,
    /// The firings, in capture order.
    pub firings: Vec<Firing>,
    /// Slots a firing (the sensor's lasers: 16, 32, 64 or 128).
    lasers: usize,
    /// Per slot (`firing * lasers + laser`): up to two indices of returns in it
    /// (`u32::MAX` for none); in dual mode the last return first.
    occupants: Vec<[u32; 2]>,
    /// Slot of each recorded return.
    slot_of: Vec<SlotId>,
}

const NONE: u32 = u32::MAX;
/// Marks an entry of `resolve`'s best echoes as the dense column's echo of a return.
const DENSE: u32 = 1 << 31;
/// The slot of `laser` in firing `firing` of a sensor with `lasers` lasers a firing (a
/// laser id beyond counts as the last laser).
#[inline]
fn slot_id(firing: usize, laser: u8, lasers: usize) -> SlotId {
    (firing * lasers + usize::from(laser).min(lasers - 1)) as SlotId
}

/// Lasers of a firing when the sensor is not said (the HDL-32E's).
pub const DEFAULT_LASERS: usize = 32;
/// Most lasers a sensor model has (VLS-128): laser ids are below this.
pub const MAX_LASERS: usize = 128;

/// Firing number of each (packet, block) seen: a table indexed by packet and block when
/// the frame's packets span a short range (always, for a decoded capture: a frame's
/// packets are consecutive records), else a hash map (a hash per firing was a tenth of
/// a weather chain's time).
enum FiringIndex {
    Table { first: u32, of: Vec<u32> },
    Map(HashMap<(u32, u8), u32>),
}

impl FiringIndex {
    /// For `n` returns of packets `lo..=hi` (`lo > hi` for none).
    fn new(lo: u32, hi: u32, n: usize) -> Self {
        let span = u64::from(hi.saturating_sub(lo)) + 1;
        // 256 blocks a packet (any u8), so the table is bounded by the frame's size.
        if lo <= hi && span * 256 <= 64 * n as u64 + 65_536 {
            FiringIndex::Table {
                first: lo,
                of: vec![NONE; span as usize * 256],
            }
        } else {
            FiringIndex::Map(HashMap::new())
        }
    }

    fn get_or_insert(&mut self, key: (u32, u8), new: impl FnOnce() -> u32) -> u32 {
        match self {
            FiringIndex::Table { first, of } => {
                let at = &mut of[(key.0 - *first) as usize * 256 + usize::from(key.1)];
                if *at == NONE {
                    *at = new();
                }
                *at
            }
            FiringIndex::Map(m) => *m.entry(key).or_insert_with(new),
        }
    }
}

impl Slots {
    /// The slots of a frame's recorded returns (the first `clean_len` of `returns`), of
    /// a sensor with `lasers` lasers a firing (1 to [`MAX_LASERS`]; a laser id beyond
    /// counts as the last).
    pub fn of(returns: &[Return], lasers: usize) -> Slots {
        let lasers = lasers.clamp(1, MAX_LASERS);
        Slots::of_single_in_order(returns, lasers).unwrap_or_else(|| Slots::of_any(returns, lasers))
    }

    /// [`Slots::of`] in one pass over the returns, for the usual frame (see
    /// [`SlotsBuilder`]); `None` for any other frame.
    fn of_single_in_order(returns: &[Return], lasers: usize) -> Option<Slots> {
        let mut b = SlotsBuilder::new(returns, lasers)?;
        b.push(returns).then_some(())?;
        b.finish()
    }

    /// [`Slots::of`] for any frame.
    fn of_any(returns: &[Return], lasers: usize) -> Slots {
        // A dual capture decoded with one of its two returns behaves like that single
        // mode: its slots hold one return of that kind.
        // One pass for the kinds and the span of packets (the returns are 48 bytes each:
        // every pass over a frame's returns streams megabytes).
        let (mut kinds, mut lo, mut hi) = (0u8, u32::MAX, 0u32);
        for r in returns {
            kinds |= 1 << (r.kind as u8);
            lo = lo.min(r.packet);
            hi = hi.max(r.packet);
        }
        let has = |k: ReturnKind| kinds & (1 << (k as u8)) != 0;
        let mode = match (has(ReturnKind::DualLast), has(ReturnKind::DualStrongest)) {
            (true, true) => SlotMode::Dual,
            (true, false) => SlotMode::Last,
            (false, true) => SlotMode::Strongest,
            _ if has(ReturnKind::Last) => SlotMode::Last,
            _ => SlotMode::Strongest,
        };
        // Room for the firings a capture's packets can hold (12 blocks each, at most one
        // firing per return), so the tables are not copied as they grow.
        let expected = if lo <= hi {
            ((hi - lo) as usize + 1)
                .saturating_mul(12)
                .min(returns.len())
        } else {
            0
        };
        let mut firings: Vec<Firing> = Vec::with_capacity(expected);
        let mut occupants: Vec<[u32; 2]> = Vec::with_capacity(expected * lasers);
        let mut slot_of = Vec::with_capacity(returns.len());
        let mut index = FiringIndex::new(lo, hi, returns.len());
        // A dual pair of blocks is one firing.
        let block_mask = if mode == SlotMode::Dual { !1u8 } else { !0u8 };
        // (packet, block) packed in 40 bits: u64::MAX is no key.
        let (mut last_key, mut f) = (u64::MAX, 0u32);
        for (i, r) in returns.iter().enumerate() {
            let block = r.block & block_mask;
            let key = u64::from(r.packet) << 8 | u64::from(block);
            if key != last_key {
                f = index.get_or_insert((r.packet, block), || {
                    firings.push(Firing {
                        packet: r.packet,
                        block,
                    });
                    occupants.extend(std::iter::repeat_n([NONE; 2], lasers));
                    (firings.len() - 1) as u32
                });
                last_key = key;
            }
            let slot = slot_id(f as usize, r.laser, lasers);
            let o = &mut occupants[slot as usize];
            // Dual: the last return in entry 0, the strongest in entry 1.
            let at = usize::from(r.kind == ReturnKind::DualStrongest || o[0] != NONE);
            if o[at] == NONE {
                o[at] = i as u32;
            }
            slot_of.push(slot);
        }
        Slots {
            mode,
            firings,
            lasers,
            occupants,
            slot_of,
        }
    }

    /// Slots a firing: the sensor's lasers.
    pub fn lasers(&self) -> usize {
        self.lasers
    }

    /// Number of slots (firings times the lasers).
    pub fn len(&self) -> usize {
        self.occupants.len()
    }

    /// True if the frame has no firings.
    pub fn is_empty(&self) -> bool {
        self.occupants.is_empty()
    }

    /// The slot of recorded return `i`.
    pub fn slot_of(&self, i: usize) -> SlotId {
        self.slot_of[i]
    }

    /// The slot of `laser` in firing `firing`.
    pub fn slot(&self, firing: usize, laser: u8) -> SlotId {
        slot_id(firing, laser, self.lasers)
    }

    /// Firing index and laser of a slot.
    pub fn split(&self, slot: SlotId) -> (usize, u8) {
        let s = slot as usize;
        (s / self.lasers, (s % self.lasers) as u8)
    }

    /// The recorded returns in a slot (none, one, or two in dual mode; last first).
    pub fn occupants(&self, slot: SlotId) -> impl Iterator<Item = usize> + '_ {
        self.occupants[slot as usize]
            .iter()
            .filter(|&&i| i != NONE)
            .map(|&i| i as usize)
    }

    /// A recorded return of firing `firing`, the lowest laser id's (its azimuth and time
    /// are the firing's up to the lasers' offsets).
    pub fn any_of_firing(&self, firing: usize) -> Option<usize> {
        (0..self.lasers).find_map(|l| self.occupants(self.slot(firing, l as u8)).next())
    }

    /// True when no recorded return is in the slot.
    pub fn is_vacant(&self, slot: SlotId) -> bool {
        self.occupants[slot as usize][0] == NONE
    }

    /// A recorded return of `laser` in the firing nearest to `firing` (the same firing
    /// first), searching at most `reach` firings each way.
    pub fn nearest_of_laser(&self, firing: usize, laser: u8, reach: usize) -> Option<usize> {
        let n = self.firings.len();
        for d in 0..=reach.min(n) {
            for f in [firing.checked_sub(d), Some(firing + d)]
                .into_iter()
                .flatten()
            {
                if f < n {
                    let o = self.occupants[f * self.lasers + usize::from(laser)][0];
                    if o != NONE {
                        return Some(o as usize);
                    }
                }
            }
        }
        None
    }

    /// A return present in both firings (same laser), for carrying angles and times
    /// from one firing to the other.
    fn common(&self, a: usize, b: usize) -> Option<(usize, usize)> {
        let n = self.lasers;
        (0..n).find_map(|l| {
            let x = self.occupants[a * n + l][0];
            let y = self.occupants[b * n + l][0];
            (x != NONE && y != NONE).then_some((x as usize, y as usize))
        })
    }

    /// The return a sensor would report in a vacant slot at `range`: direction, azimuth,
    /// time and elevation come from the nearest return of the same laser, turned to the
    /// slot's firing (by the azimuth and time difference of a laser present in both
    /// firings). `None` when the laser has no return within 1000 firings, or the two
    /// firings share no laser. Also gives the template's index.
    pub fn vacant_return(
        &self,
        returns: &[Return],
        slot: SlotId,
        range: f32,
    ) -> Option<(Return, usize)> {
        let (firing, laser) = self.split(slot);
        let t = self.nearest_of_laser(firing, laser, 1000)?;
        self.vacant_return_from(returns, slot, range, t)
    }

    /// [`Slots::vacant_return`] with its template `t` found by the caller (the nearest
    /// return of the slot's laser within 1000 firings).
    fn vacant_return_from(
        &self,
        returns: &[Return],
        slot: SlotId,
        range: f32,
        t: usize,
    ) -> Option<(Return, usize)> {
        let firing = self.split(slot).0;
        let template = returns[t];
        let tf = self.split(self.slot_of[t]).0;
        let (mut azimuth, mut time) = (f64::from(template.azimuth), template.time);
        if tf != firing {
            let (here, there) = self.common(firing, tf)?;
            let mut d_az = f64::from(returns[here].azimuth) - f64::from(returns[there].azimuth);
            if d_az > 180.0 {
                d_az -= 360.0;
            } else if d_az < -180.0 {
                d_az += 360.0;
            }
            azimuth = (azimuth + d_az).rem_euclid(360.0);
            time += returns[here].time - returns[there].time;
            // Turn the template's direction by the azimuth difference (clockwise seen from
            // above, like the sensor's azimuth).
        }
        let d = (f64::from(template.azimuth) - azimuth).to_radians();
        let (s, c) = d.sin_cos();
        let (x, y, z) = if template.range > 0.0 {
            let k = 1.0 / f64::from(template.range);
            (
                f64::from(template.x) * k,
                f64::from(template.y) * k,
                f64::from(template.z) * k,
            )
        } else {
            let (se, ce) = f64::from(template.elevation).to_radians().sin_cos();
            let (sa, ca) = f64::from(template.azimuth).to_radians().sin_cos();
            (ce * ca, -ce * sa, se)
        };
        let (ux, uy) = (x * c - y * s, x * s + y * c);
        let firing_info = self.firings[firing];
        let block = match (self.mode, template.kind) {
            (SlotMode::Dual, ReturnKind::DualStrongest) => firing_info.block + 1,
            _ => firing_info.block,
        };
        let r = f64::from(range);
        Some((
            Return {
                x: (ux * r) as f32,
                y: (uy * r) as f32,
                z: (z * r) as f32,
                range,
                azimuth: azimuth as f32,
                elevation: template.elevation,
                time,
                packet: firing_info.packet,
                raw_distance: (r / 0.002).round().clamp(0.0, 65535.0) as u16,
                intensity: 0,
                laser: template.laser,
                ring: template.ring,
                block,
                kind: template.kind,
            },
            t,
        ))
    }
}

/// Builds a frame's [`Slots`] a chunk of returns at a time, in one pass, for the usual
/// frame: single-return kinds, packets within the first and last returns' (a decoded
/// capture's frame is consecutive records). Why: a 50k-return frame's returns are
/// 2.4 MB, beyond the L2 cache, and every pass over them streams it; the chain builds
/// the slots in the pass that reads the returns for the ideal powers. Other frames take
/// the general path of [`Slots::of`].
pub(crate) struct SlotsBuilder {
    lo: u32,
    /// Slots a firing.
    lasers: usize,
    /// Firing number of each (packet - lo, block), `NONE` for none yet.
    of: Vec<u32>,
    firings: Vec<Firing>,
    occupants: Vec<[u32; 2]>,
    slot_of: Vec<SlotId>,
    /// (packet, block) of the last return, packed in 40 bits (`u64::MAX`: none).
    last_key: u64,
    f: u32,
    kinds: u8,
}

impl SlotsBuilder {
    /// For the frame `returns` (only its first and last are read); `None` when its
    /// packets do not ascend from the first to the last or span too many.
    pub(crate) fn new(returns: &[Return], lasers: usize) -> Option<SlotsBuilder> {
        let lasers = lasers.clamp(1, MAX_LASERS);
        let (lo, hi) = (returns.first()?.packet, returns.last()?.packet);
        let span = u64::from(hi.checked_sub(lo)?) + 1;
        // The table's bound of `FiringIndex::new`.
        if span * 256 > 64 * returns.len() as u64 + 65_536 {
            return None;
        }
        let expected = (span as usize).saturating_mul(12).min(returns.len());
        Some(SlotsBuilder {
            lo,
            lasers,
            of: vec![NONE; span as usize * 256],
            firings: Vec::with_capacity(expected),
            occupants: Vec::with_capacity(expected * lasers),
            slot_of: Vec::with_capacity(returns.len()),
            last_key: u64::MAX,
            f: 0,
            kinds: 0,
        })
    }

    /// Adds the next returns of the frame; false when the frame needs the general path
    /// (a packet outside the span).
    pub(crate) fn push(&mut self, chunk: &[Return]) -> bool {
        for r in chunk {
            let i = self.slot_of.len() as u32;
            self.kinds |= 1 << (r.kind as u8);
            let key = u64::from(r.packet) << 8 | u64::from(r.block);
            if key != self.last_key {
                let index = r.packet.wrapping_sub(self.lo) as usize * 256 + usize::from(r.block);
                let Some(at) = self.of.get_mut(index) else {
                    return false;
                };
                if *at == NONE {
                    *at = self.firings.len() as u32;
                    self.firings.push(Firing {
                        packet: r.packet,
                        block: r.block,
                    });
                    self.occupants
                        .extend(std::iter::repeat_n([NONE; 2], self.lasers));
                }
                self.f = *at;
                self.last_key = key;
            }
            let slot = slot_id(self.f as usize, r.laser, self.lasers);
            let o = &mut self.occupants[slot as usize];
            let at = usize::from(o[0] != NONE);
            if o[at] == NONE {
                o[at] = i;
            }
            self.slot_of.push(slot);
        }
        true
    }

    /// The slots; `None` when the frame has dual-return kinds (the general path).
    pub(crate) fn finish(self) -> Option<Slots> {
        let dual = (1 << ReturnKind::DualLast as u8) | (1 << ReturnKind::DualStrongest as u8);
        if self.kinds & dual != 0 {
            return None;
        }
        let mode = if self.kinds & (1 << ReturnKind::Last as u8) != 0 {
            SlotMode::Last
        } else {
            SlotMode::Strongest
        };
        Some(Slots {
            mode,
            firings: self.firings,
            lasers: self.lasers,
            occupants: self.occupants,
            slot_of: self.slot_of,
        })
    }
}

impl NoisyFrame {
    /// The firing slots of the frame's recorded returns (built on first use).
    pub fn slots(&mut self) -> Arc<Slots> {
        if self.slots.is_none() {
            self.slots = Some(Arc::new(Slots::of(
                &self.clean[..self.clean_len],
                self.lasers,
            )));
        }
        Arc::clone(self.slots.as_ref().expect("just built"))
    }

    /// Proposes an echo in the firing slot of recorded return `i` (along its beam).
    pub fn propose(&mut self, i: usize, echo: Echo) {
        let slot = self.slots().slot_of(i);
        self.propose_slot(slot, echo);
    }

    /// Proposes `echo[i]` in the firing slot of every recorded return i (along its beam;
    /// a NaN power for none), as [`NoisyFrame::propose`] would one by one in that order.
    pub fn propose_each(&mut self, mut echo: Vec<Echo>) {
        echo.truncate(self.clean_len);
        if self.dense.is_some() {
            // A second such stage in the chain: its echoes as candidates, in order.
            for (i, e) in echo.into_iter().enumerate() {
                if !e.power.is_nan() {
                    self.propose(i, e);
                }
            }
            return;
        }
        for e in &mut echo {
            if !(e.range.is_finite() && e.power.is_finite()) {
                e.power = f64::NAN;
            }
        }
        echo.resize(self.clean_len, Echo::NONE);
        self.dense = Some(DenseEchoes {
            stage: self.stage,
            echo,
        });
    }

    /// Every proposed echo, in proposal order (the column of [`NoisyFrame::propose_each`]
    /// in its place among the candidates).
    pub fn proposals(&self) -> Vec<Candidate> {
        let Some(d) = &self.dense else {
            return self.candidates.clone();
        };
        let slots = Slots::of(&self.clean[..self.clean_len], self.lasers);
        let at = self.candidates.partition_point(|c| c.stage < d.stage);
        let mut all = self.candidates[..at].to_vec();
        all.extend(d.echo.iter().enumerate().filter_map(|(i, e)| {
            (!e.power.is_nan()).then_some(Candidate {
                slot: slots.slot_of(i),
                echo: *e,
                stage: d.stage,
            })
        }));
        all.extend_from_slice(&self.candidates[at..]);
        all
    }

    /// Proposes an echo in a firing slot (occupied or vacant).
    pub fn propose_slot(&mut self, slot: SlotId, echo: Echo) {
        if self.candidates.capacity() == 0 {
            // Scatter stages often propose for most returns, and a chain's other scatter
            // stages a few percent more: room for them all, so the buffer is not copied
            // as it grows (fog's echo a return is a column, `propose_each`).
            let most = if self.dense.is_some() { 0 } else { self.len() };
            self.candidates.reserve(most + self.len() / 4 + 1024);
        }
        if echo.range.is_finite() && echo.power.is_finite() {
            self.candidates.push(Candidate {
                slot,
                echo,
                stage: self.stage,
            });
        }
    }

    /// Makes room for `n` more returns in every per-return column.
    fn reserve_returns(&mut self, n: usize) {
        self.range.reserve(n);
        self.power.reserve(n);
        self.fate.reserve(n);
        self.cause.reserve(n);
        self.clean.reserve(n);
        let m = &mut self.moved;
        for v in [&mut m.azimuth_deg, &mut m.elevation_deg]
            .into_iter()
            .flatten()
        {
            v.reserve(n);
        }
        if let Some(v) = &mut m.time {
            v.reserve(n);
        }
        if let Some(v) = &mut m.intensity {
            v.reserve(n);
        }
        if let Some(ix) = m.pose.as_mut().and_then(|p| p.index.as_mut()) {
            ix.reserve(n);
        }
    }

    /// Appends a return with fate `Added` and the given cause; every per-return column
    /// grows by one entry.
    fn push_added(&mut self, ret: Return, power: f64, cause: u8, pose_of: usize) {
        let n = self.len();
        self.range.push(ret.range);
        self.power.push(power);
        self.fate.push(Fate::Added);
        self.cause.push(cause);
        let m = &mut self.moved;
        if let Some(v) = &mut m.azimuth_deg {
            v.push(0.0);
        }
        if let Some(v) = &mut m.elevation_deg {
            v.push(0.0);
        }
        if let Some(v) = &mut m.time {
            v.push(ret.time);
        }
        if let Some(v) = &mut m.intensity {
            v.push(ret.intensity);
        }
        if let Some(p) = &mut m.pose {
            if let Some(ix) = &mut p.index {
                let f = ix[pose_of];
                ix.push(f);
            }
        }
        self.clean.push(ret);
        debug_assert_eq!(self.clean.len(), n + 1);
    }

    /// The intensity byte the sensor reports for an echo.
    fn echo_intensity(&self, echo: &Echo) -> u8 {
        self.power_model
            .as_ref()
            .map_or(0, |m| m.echo_intensity(echo.power, echo.range))
    }

    /// [`NoisyFrame::replace`] of every recorded return `i` in `which` by `echo[i]`.
    fn replace_each(&mut self, which: &[u32], echo: &[Echo], cause: u8) {
        let Some(&first) = which.first() else {
            return;
        };
        // The first one makes the intensity column; the rest only write.
        self.replace(first as usize, echo[first as usize], cause);
        let NoisyFrame {
            range,
            power,
            fate,
            cause: causes,
            moved,
            power_model,
            ..
        } = self;
        let intensity = moved.intensity.as_mut().expect("made by `replace`");
        let model = power_model.as_deref();
        for &i in &which[1..] {
            let (i, e) = (i as usize, echo[i as usize]);
            range[i] = e.range;
            power[i] = e.power;
            fate[i] = Fate::Replaced;
            causes[i] = cause;
            intensity[i] = model.map_or(0, |m| m.echo_intensity(e.power, e.range));
        }
    }

    /// Makes recorded (or added) return `i` report `echo` proposed by stage `cause`.
    fn replace(&mut self, i: usize, echo: Echo, cause: u8) {
        self.range[i] = echo.range;
        self.power[i] = echo.power;
        self.fate[i] = Fate::Replaced;
        self.cause[i] = cause;
        let intensity = self.echo_intensity(&echo);
        let n = self.len();
        let (clean, recorded) = (&self.clean, &self.recorded_intensity);
        self.moved.intensity.get_or_insert_with(|| {
            let mut col = recorded.clone().unwrap_or_default();
            col.truncate(clean.len());
            col.extend(clean[col.len()..].iter().map(|r| r.intensity));
            col
        })[i] = intensity;
        debug_assert_eq!(self.moved.intensity.as_ref().map(Vec::len), Some(n));
    }
}

/// One contender of a slot: a recorded return (index) or a candidate.
#[derive(Clone, Copy, Debug)]
struct Contender {
    range: f32,
    power: f64,
    /// `Ok(return index)` or `Err(candidate index)`.
    who: Result<usize, usize>,
}

/// Lets every slot's proposed echoes compete with its return (see the module
/// documentation) and applies the winners.
pub fn resolve(frame: &mut NoisyFrame) {
    if frame.candidates.is_empty() && frame.dense.is_none() {
        return;
    }
    let slots = frame.slots();
    let mut contenders: Vec<Contender> = Vec::with_capacity(8);
    if slots.mode == SlotMode::Dual {
        let mut candidates = frame.proposals();
        frame.dense = None;
        frame.candidates.clear();
        resolve_dual(frame, &slots, &mut candidates, &mut contenders);
        return;
    }
    let mut candidates = std::mem::take(&mut frame.candidates);
    let dense = frame.dense.take();
    {
        // One report per slot: only each slot's best detectable echo (the first of the
        // highest power, or of the farthest range, in proposal order) can win, so the
        // others need no grouping (sorting a frame's worth of echoes by slot was a tenth
        // of a weather chain's time). Slots are then settled in slot order, as in dual.
        let last = slots.mode == SlotMode::Last;
        let n = candidates
            .iter()
            .map(|c| c.slot as usize + 1)
            .max()
            .unwrap_or(0)
            .max(if dense.is_some() { slots.len() } else { 0 });
        let mut best = vec![NONE; n];
        let beats = |e: &Echo, o: &Echo| {
            if last {
                e.range > o.range
            } else {
                e.power > o.power
            }
        };
        // How many vacant slots gain a return (the column's echoes are all in occupied
        // ones), so the columns grow once.
        let mut gains = 0;
        for (k, c) in candidates.iter().enumerate() {
            if !frame.detectable(c.echo.range, c.echo.power) {
                continue;
            }
            let b = &mut best[c.slot as usize];
            if *b == NONE {
                let vacant = slots
                    .occupants
                    .get(c.slot as usize)
                    .is_none_or(|o| o[0] == NONE);
                gains += usize::from(vacant);
                *b = k as u32;
            } else if beats(&c.echo, &candidates[*b as usize].echo) {
                *b = k as u32;
            }
        }
        // The column's echoes, proposed (in return order) after the candidates of earlier
        // stages and before those of its own and later ones: against a slot's best
        // candidate, it wins when better, or as good and proposed earlier. Most slots
        // hold one return and no candidate: their echo competes with the return alone,
        // decided here (the same rule as below; the returns it replaces are disjoint from
        // the slots settled below, so the order does not matter).
        if let Some(d) = &dense {
            let (threshold, min_range) = (frame.threshold, frame.min_range);
            let detectable = |r: f32, p: f64| p >= threshold && f64::from(r) >= min_range;
            let (range, power, fate) = (&frame.range, &frame.power, &frame.fate);
            // Branch-free for the usual slot (whether an echo wins is a coin toss to the
            // branch predictor): every return is written, the count moves on a win.
            let mut replaced = vec![0u32; d.echo.len()];
            let mut m = 0;
            for (i, (e, &slot)) in d.echo.iter().zip(&slots.slot_of).enumerate() {
                let ok = detectable(e.range, e.power);
                let b = &mut best[slot as usize];
                let usual = *b == NONE && slots.occupants[slot as usize] == [i as u32, NONE];
                if usual || !ok {
                    let f = fate[i];
                    let alive = frame.return_detectable(i);
                    let better = if last {
                        e.range > range[i]
                    } else {
                        e.power > power[i]
                    };
                    let wins = ok & (f != Fate::Occluded) & (!alive | better);
                    replaced[m] = i as u32;
                    m += usize::from(wins);
                    continue;
                }
                let wins = match *b {
                    NONE => true,
                    x if x & DENSE != 0 => beats(e, &d.echo[(x & !DENSE) as usize]),
                    k => {
                        let c = &candidates[k as usize];
                        beats(e, &c.echo) || (c.stage >= d.stage && !beats(&c.echo, e))
                    }
                };
                if wins {
                    *b = DENSE | i as u32;
                }
            }
            frame.replace_each(&replaced[..m], &d.echo, d.stage);
        }
        let candidate = |b: u32, slot: usize| -> Candidate {
            match &dense {
                Some(d) if b & DENSE != 0 => Candidate {
                    slot: slot as SlotId,
                    echo: d.echo[(b & !DENSE) as usize],
                    stage: d.stage,
                },
                _ => candidates[b as usize],
            }
        };
        frame.reserve_returns(gains);
        for (slot, &b) in best.iter().enumerate() {
            if b == NONE {
                continue;
            }
            let c = candidate(b, slot);
            match slots.occupants.get(slot) {
                // The common case, one recorded return, as `resolve_slot` decides it.
                Some(&[i, NONE]) if i != NONE => {
                    let i = i as usize;
                    if frame.fate[i] == Fate::Occluded {
                        continue;
                    }
                    let alive = frame.return_detectable(i);
                    let wins = !alive
                        || if last {
                            c.echo.range > frame.range[i]
                        } else {
                            c.echo.power > frame.power[i]
                        };
                    if wins {
                        frame.replace(i, c.echo, c.stage);
                    }
                }
                _ => resolve_slot(frame, &slots, slot as SlotId, &[c], &mut contenders),
            }
        }
    }
    // Hand the (cleared) buffer back so a later chain run on this frame reuses it.
    candidates.clear();
    frame.candidates = candidates;
}

/// [`resolve`] in dual-return mode: every slot's echoes compete together.
fn resolve_dual(
    frame: &mut NoisyFrame,
    slots: &Slots,
    candidates: &mut Vec<Candidate>,
    contenders: &mut Vec<Contender>,
) {
    // Group by slot; a stable sort keeps proposal order inside a slot (stages mostly
    // propose in slot order, which the sort only checks).
    if !candidates.is_sorted_by_key(|c| c.slot) {
        *candidates = sort_by_slot(std::mem::take(candidates));
    }
    // Room for every return the vacant slots could gain (two each), so the columns grow
    // once.
    let mut gains = 0;
    let mut last = None;
    for c in candidates.iter() {
        if last != Some(c.slot)
            && slots
                .occupants
                .get(c.slot as usize)
                .is_none_or(|o| o[0] == NONE)
        {
            gains += 2;
        }
        last = Some(c.slot);
    }
    frame.reserve_returns(gains);
    let mut start = 0;
    while start < candidates.len() {
        let slot = candidates[start].slot;
        let mut end = start + 1;
        while end < candidates.len() && candidates[end].slot == slot {
            end += 1;
        }
        resolve_slot(frame, slots, slot, &candidates[start..end], contenders);
        start = end;
    }
}

/// The candidates in slot order, proposal order kept within a slot (a counting sort:
/// linear in candidates and slots, where a comparison sort of a frame's worth of echoes
/// was a tenth of a weather chain's time).
fn sort_by_slot(candidates: Vec<Candidate>) -> Vec<Candidate> {
    let slots = candidates
        .iter()
        .map(|c| c.slot as usize + 1)
        .max()
        .unwrap_or(0);
    let mut start = vec![0u32; slots + 1];
    for c in &candidates {
        start[c.slot as usize + 1] += 1;
    }
    for k in 1..start.len() {
        start[k] += start[k - 1];
    }
    let mut sorted = vec![candidates[0]; candidates.len()];
    for c in candidates {
        let at = &mut start[c.slot as usize];
        sorted[*at as usize] = c;
        *at += 1;
    }
    sorted
}

fn resolve_slot(
    frame: &mut NoisyFrame,
    slots: &Slots,
    slot: SlotId,
    group: &[Candidate],
    contenders: &mut Vec<Contender>,
) {
    // The occupied entries, whichever they are: a dual slot may hold only its strongest
    // return (entry 1) when the frame has no last return for it (a frame of returns
    // given through the Python package, say); taking the first `n` entries then read
    // the empty marker as an index.
    let pair = slots.occupants[slot as usize];
    let mut occupants = [0usize; 2];
    let mut n_occ = 0;
    for i in pair {
        if i != NONE {
            occupants[n_occ] = i as usize;
            n_occ += 1;
        }
    }
    let occupants = &occupants[..n_occ];
    let vacant = occupants.is_empty();
    // The common case (one recorded return, one echo, single-return mode) without the
    // general machinery below; it makes the same choice.
    if let ([i], [c], SlotMode::Strongest | SlotMode::Last) = (occupants, group, slots.mode) {
        let i = *i;
        if frame.fate[i] == Fate::Occluded || !frame.detectable(c.echo.range, c.echo.power) {
            return;
        }
        let alive = frame.return_detectable(i);
        let wins = !alive
            || match slots.mode {
                SlotMode::Last => c.echo.range > frame.range[i],
                _ => c.echo.power > frame.power[i],
            };
        if wins {
            frame.replace(i, c.echo, c.stage);
        }
        return;
    }
    // The other common case: a vacant slot, one echo, single-return mode (a weather
    // stage's echo where no target answered). The echo alone contends, so it is the
    // slot's return when detectable and the beam is not occluded; the general machinery
    // below makes the same choice (it was a third of a fog stage on a nuScenes sweep).
    if let ([], [c], SlotMode::Strongest | SlotMode::Last) = (occupants, group, slots.mode) {
        let (firing, laser) = slots.split(slot);
        let nearest = slots.nearest_of_laser(firing, laser, 1000);
        if nearest.is_some_and(|t| frame.fate[t] == Fate::Occluded)
            || !frame.detectable(c.echo.range, c.echo.power)
        {
            return;
        }
        if let Some((mut ret, template)) =
            nearest.and_then(|t| slots.vacant_return_from(&frame.clean, slot, c.echo.range, t))
        {
            ret.intensity = frame.echo_intensity(&c.echo);
            frame.push_added(ret, c.echo.power, c.stage, template);
        }
        return;
    }
    // A vacant slot's template (`Slots::vacant_return`), found once for the occlusion
    // check and the return (searching twice for it was a tenth of a fog stage's slots).
    let nearest = if vacant {
        let (firing, laser) = slots.split(slot);
        slots.nearest_of_laser(firing, laser, 1000)
    } else {
        None
    };
    // Occlusion removes the beam: no echo in an occluded slot.
    let occluded = if vacant {
        nearest.is_some_and(|t| frame.fate[t] == Fate::Occluded)
    } else {
        occupants.iter().any(|&i| frame.fate[i] == Fate::Occluded)
    };
    if occluded {
        return;
    }
    contenders.clear();
    for &i in occupants {
        let (range, power) = (frame.range[i], frame.power[i]);
        // Dual: both entries may hold the same echo (the only one); count it once.
        let same = contenders
            .iter()
            .any(|c| c.range == range && c.power == power);
        if frame.return_detectable(i) && !same {
            contenders.push(Contender {
                range,
                power,
                who: Ok(i),
            });
        }
    }
    let real = contenders.len();
    for (k, c) in group.iter().enumerate() {
        if frame.detectable(c.echo.range, c.echo.power) {
            contenders.push(Contender {
                range: c.echo.range,
                power: c.echo.power,
                who: Err(k),
            });
        }
    }
    if contenders.len() == real {
        return;
    }
    // First maximum wins: recorded returns come first, then proposal order.
    let strongest_of = |cs: &[Contender], skip: Option<usize>| -> Option<usize> {
        let mut best: Option<usize> = None;
        for (k, c) in cs.iter().enumerate() {
            if Some(k) != skip && best.is_none_or(|b| c.power > cs[b].power) {
                best = Some(k);
            }
        }
        best
    };
    let farthest = {
        let mut best = 0;
        for (k, c) in contenders.iter().enumerate() {
            if c.range > contenders[best].range {
                best = k;
            }
        }
        best
    };
    let strongest = strongest_of(contenders, None).expect("non-empty");
    // What each entry of the slot reports: (entry kind, contender).
    let (picks, n_picks): ([(Option<ReturnKind>, usize); 2], usize) = match slots.mode {
        SlotMode::Strongest => ([(None, strongest), (None, strongest)], 1),
        SlotMode::Last => ([(None, farthest), (None, farthest)], 1),
        SlotMode::Dual => {
            let second = strongest_of(contenders, Some(farthest)).unwrap_or(farthest);
            (
                [
                    (Some(ReturnKind::DualLast), farthest),
                    (Some(ReturnKind::DualStrongest), second),
                ],
                2,
            )
        }
    };
    for &(kind, pick) in &picks[..n_picks] {
        let c = contenders[pick];
        // The entry of the slot this pick goes to.
        let entry = match kind {
            None => occupants.first().copied(),
            Some(k) => occupants
                .iter()
                .copied()
                .find(|&i| frame.clean[i].kind == k),
        };
        let echo = Echo {
            range: c.range,
            power: c.power,
        };
        match (entry, c.who) {
            // The entry already reports this echo (a dual slot's two entries may hold the
            // same one).
            (Some(i), Ok(j))
                if i == j || (frame.range[i], frame.power[i]) == (c.range, c.power) => {}
            (Some(i), Ok(_)) => {
                // The other recorded return of a dual slot now reports here.
                let cause = group[0].stage;
                frame.replace(i, echo, cause);
            }
            (Some(i), Err(k)) => frame.replace(i, echo, group[k].stage),
            (None, Err(k)) if vacant => {
                if let Some((mut ret, template)) = nearest
                    .and_then(|t| slots.vacant_return_from(&frame.clean, slot, echo.range, t))
                {
                    if let Some(kind) = kind {
                        ret.kind = kind;
                        let firing = slots.firings[slots.split(slot).0];
                        ret.block = firing.block + u8::from(kind == ReturnKind::DualStrongest);
                    }
                    ret.intensity = frame.echo_intensity(&echo);
                    frame.push_added(ret, echo.power, group[k].stage, template);
                }
            }
            // A recorded return already reports this pick, or no entry can hold it.
            _ => {}
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ret(packet: u32, block: u8, laser: u8, kind: ReturnKind) -> Return {
        Return {
            range: 1.0,
            packet,
            laser,
            block,
            kind,
            ..crate::sensor::decode::BLANK
        }
    }

    fn same(a: &Slots, b: &Slots) -> bool {
        a.mode == b.mode
            && a.firings == b.firings
            && a.occupants == b.occupants
            && a.slot_of == b.slot_of
    }

    #[test]
    fn the_one_pass_slots_equal_the_general_ones_and_leave_other_frames_to_them() {
        // Consecutive packets of 12 blocks, lasers missing here and there, a laser twice
        // in a firing (a duplicate), both single kinds.
        for kind in [ReturnKind::Strongest, ReturnKind::Last] {
            let mut v = Vec::new();
            for packet in 7..12u32 {
                for block in 0..12u8 {
                    for laser in 0..32u8 {
                        if (u32::from(laser) * 7 + packet + u32::from(block)) % 5 != 0 {
                            v.push(ret(packet, block, laser, kind));
                        }
                    }
                    v.push(ret(packet, block, 3, kind));
                }
            }
            let fast = Slots::of_single_in_order(&v, 32).expect("the usual frame");
            assert!(same(&fast, &Slots::of_any(&v, 32)), "{kind:?}");
            assert!(same(&Slots::of(&v, 32), &fast));
            // Chunk by chunk, as the chain builds it.
            let mut b = SlotsBuilder::new(&v, 32).unwrap();
            for chunk in v.chunks(100) {
                assert!(b.push(chunk));
            }
            assert!(same(&b.finish().unwrap(), &fast));
            // A packet before the first one's: the general path, the same slots.
            let mut w = v.clone();
            w[40].packet = 3;
            assert!(Slots::of_single_in_order(&w, 32).is_none());
            assert!(same(&Slots::of(&w, 32), &Slots::of_any(&w, 32)));
            assert_eq!(Slots::of(&w, 32).firings.len(), fast.firings.len() + 1);
        }
        // Dual kinds: the general path.
        let v: Vec<Return> = (0..4u8)
            .flat_map(|block| {
                let kind = if block % 2 == 0 {
                    ReturnKind::DualLast
                } else {
                    ReturnKind::DualStrongest
                };
                (0..32u8).map(move |laser| ret(1, block, laser, kind))
            })
            .collect();
        assert!(Slots::of_single_in_order(&v, 32).is_none());
        let s = Slots::of(&v, 32);
        assert_eq!(s.mode, SlotMode::Dual);
        assert_eq!(s.firings.len(), 2);
        assert!(Slots::of_single_in_order(&[], 32).is_none());
    }
}
