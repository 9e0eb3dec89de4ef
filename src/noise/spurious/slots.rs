//! The firing slots of a frame: which returns share a laser and firing, and where a
//! slot without a return lies.

use super::*;

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
    pub(super) lasers: usize,
    /// Per slot (`firing * lasers + laser`): up to two indices of returns in it
    /// (`u32::MAX` for none); in dual mode the last return first.
    pub(super) occupants: Vec<[u32; 2]>,
    /// Slot of each recorded return.
    pub(super) slot_of: Vec<SlotId>,
}

pub(super) const NONE: u32 = u32::MAX;
/// Marks an entry of `resolve`'s best echoes as the dense column's echo of a return.
pub(super) const DENSE: u32 = 1 << 31;
/// The slot of `laser` in firing `firing` of a sensor with `lasers` lasers a firing (a
/// laser id beyond counts as the last laser).
#[inline]
pub(super) fn slot_id(firing: usize, laser: u8, lasers: usize) -> SlotId {
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
pub(super) enum FiringIndex {
    Table { first: u32, of: Vec<u32> },
    Map(HashMap<(u32, u8), u32>),
}

impl FiringIndex {
    /// For `n` returns of packets `lo..=hi` (`lo > hi` for none).
    pub(super) fn new(lo: u32, hi: u32, n: usize) -> Self {
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

    pub(super) fn get_or_insert(&mut self, key: (u32, u8), new: impl FnOnce() -> u32) -> u32 {
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
    pub(super) fn of_single_in_order(returns: &[Return], lasers: usize) -> Option<Slots> {
        let mut b = SlotsBuilder::new(returns, lasers)?;
        b.push(returns).then_some(())?;
        b.finish()
    }

    /// [`Slots::of`] for any frame.
    pub(super) fn of_any(returns: &[Return], lasers: usize) -> Slots {
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
    pub(super) fn common(&self, a: usize, b: usize) -> Option<(usize, usize)> {
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
    pub(super) fn vacant_return_from(
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
    pub(super) lo: u32,
    /// Slots a firing.
    pub(super) lasers: usize,
    /// Firing number of each (packet - lo, block), `NONE` for none yet.
    pub(super) of: Vec<u32>,
    pub(super) firings: Vec<Firing>,
    pub(super) occupants: Vec<[u32; 2]>,
    pub(super) slot_of: Vec<SlotId>,
    /// (packet, block) of the last return, packed in 40 bits (`u64::MAX`: none).
    pub(super) last_key: u64,
    pub(super) f: u32,
    pub(super) kinds: u8,
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
