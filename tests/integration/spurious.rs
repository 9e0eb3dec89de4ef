//! Bookkeeping of spurious echoes on hand-made frames: what the firing-slot rule reports
//! (pdiagram-models.md, "Spurious and replaced returns"), the fates, causes and clean
//! ranges it records, and that stage order does not decide the result.

use crate::common;

use crate::common::ideal;
use lidar_noise::frame::{Return, ReturnKind};
use lidar_noise::noise::spurious::resolve;
use lidar_noise::noise::{Echo, Fate, NoisyFrame, NO_CAUSE};
use std::sync::Arc;

/// A return of `laser` at `range` m in firing `firing` (azimuth 0.2 deg per firing).
fn ret(laser: u8, range: f32, firing: u32, kind: ReturnKind) -> Return {
    let time = 10.0 + f64::from(firing) * 46.08e-6 + f64::from(laser) * 1.152e-6;
    common::beam_return(laser, range, firing as f32 * 0.2, 50, firing, time, kind)
}

fn frame(returns: Vec<Return>) -> NoisyFrame {
    let p = ideal();
    let mut f = NoisyFrame::new(0, returns, &p);
    f.power_model = Some(Arc::new(p));
    f
}

/// Three firings of lasers 0..31 at 20 m, strongest mode, except laser 5 of firing 1
/// (an empty slot).
fn strongest_frame() -> NoisyFrame {
    let mut v = Vec::new();
    for firing in 0..3 {
        for laser in 0..32 {
            if firing == 1 && laser == 5 {
                continue;
            }
            v.push(ret(laser, 20.0, firing, ReturnKind::Strongest));
        }
    }
    frame(v)
}

fn index_of(f: &NoisyFrame, firing: u32, laser: u8) -> usize {
    (0..f.clean_len)
        .find(|&i| f.clean[i].laser == laser && f.clean[i].block == firing as u8)
        .unwrap()
}

#[test]
fn a_stronger_echo_replaces_the_return_and_records_its_cause() {
    let mut f = strongest_frame();
    let i = index_of(&f, 2, 7);
    let p = f.power[i];
    f.stage = 3;
    f.propose(
        i,
        Echo {
            range: 1.6,
            power: p * 2.0,
        },
    );
    resolve(&mut f);
    assert_eq!(f.fate[i], Fate::Replaced);
    assert_eq!(f.cause[i], 3);
    assert_eq!(f.range[i], 1.6);
    assert_eq!(f.power[i], p * 2.0);
    // The recorded return is kept as the clean one: range_clean stays 20 m.
    assert_eq!(f.clean[i].range, 20.0);
    // The point moves along its beam to the echo's range.
    let s = f.noisy_return(i);
    let d = (s.x * s.x + s.y * s.y + s.z * s.z).sqrt();
    assert!((d - 1.6).abs() < 1e-5, "{d}");
    // Every other return is untouched.
    for k in (0..f.len()).filter(|&k| k != i) {
        assert_eq!(f.fate[k], Fate::Kept);
        assert_eq!(f.cause[k], NO_CAUSE);
    }
    assert_eq!(f.len(), f.clean_len);
}

#[test]
fn a_weaker_or_undetectable_echo_loses_in_strongest_mode() {
    let mut f = strongest_frame();
    let i = index_of(&f, 0, 9);
    let p = f.power[i];
    f.propose(
        i,
        Echo {
            range: 3.0,
            power: p * 0.5,
        },
    );
    // Stronger than the return, but under the threshold: it never takes part.
    f.propose(
        i,
        Echo {
            range: 3.0,
            power: f.threshold * 0.99,
        },
    );
    // Stronger, but closer than the minimum range.
    f.propose(
        i,
        Echo {
            range: (f.min_range * 0.5) as f32,
            power: 1.0,
        },
    );
    resolve(&mut f);
    assert_eq!(f.fate[i], Fate::Kept);
    assert_eq!(f.range[i], 20.0);
}

#[test]
fn last_mode_reports_the_farthest() {
    let mut v = Vec::new();
    for laser in 0..32 {
        v.push(ret(laser, 20.0, 0, ReturnKind::Last));
    }
    let mut f = frame(v);
    let p = f.power[4];
    // A strong near echo loses to the detectable target; a weak far one wins.
    f.propose(
        4,
        Echo {
            range: 2.0,
            power: 0.9,
        },
    );
    f.propose(
        5,
        Echo {
            range: 35.0,
            power: p * 0.1 + f.threshold,
        },
    );
    resolve(&mut f);
    assert_eq!(f.fate[4], Fate::Kept);
    assert_eq!(f.fate[5], Fate::Replaced);
    assert_eq!(f.range[5], 35.0);
}

#[test]
fn dual_mode_reports_the_echo_and_the_target() {
    // One firing, every laser's two returns equal (a single target at 20 m).
    let mut v = Vec::new();
    for laser in 0..32 {
        v.push(ret(laser, 20.0, 0, ReturnKind::DualLast));
    }
    for laser in 0..32 {
        v.push(ret(laser, 20.0, 0, ReturnKind::DualStrongest));
    }
    let mut f = frame(v);
    let last = 3;
    let strongest = 32 + 3;
    let p = f.power[last];
    f.stage = 1;
    f.propose(
        last,
        Echo {
            range: 1.7,
            power: p * 3.0,
        },
    );
    resolve(&mut f);
    // The target stays the last return; the stronger near echo is the strongest.
    assert_eq!(f.fate[last], Fate::Kept);
    assert_eq!(f.fate[strongest], Fate::Replaced);
    assert_eq!(f.range[strongest], 1.7);
    assert_eq!(f.cause[strongest], 1);
    // A weaker echo of a one-target slot is the second strongest: reported too.
    let mut g = frame(f.clean.clone());
    g.propose(
        7,
        Echo {
            range: 2.5,
            power: p * 0.5,
        },
    );
    resolve(&mut g);
    assert_eq!(g.fate[7], Fate::Kept);
    assert_eq!(g.fate[32 + 7], Fate::Replaced);
    assert_eq!(g.range[32 + 7], 2.5);
    // Never more than two returns per laser and firing.
    assert_eq!(g.len(), 64);
}

#[test]
fn an_echo_in_an_empty_slot_is_added_along_that_slots_beam() {
    let mut f = strongest_frame();
    let slots = f.slots();
    let slot = slots.slot(1, 5);
    assert!(slots.is_vacant(slot));
    f.stage = 2;
    f.propose_slot(
        slot,
        Echo {
            range: 12.0,
            power: 0.5,
        },
    );
    resolve(&mut f);
    assert_eq!(f.len(), f.clean_len + 1);
    let a = f.len() - 1;
    assert_eq!(f.fate[a], Fate::Added);
    assert_eq!(f.cause[a], 2);
    let r = f.noisy_return(a);
    assert_eq!((r.laser, r.block, r.packet), (5, 1, 0));
    assert_eq!(r.range, 12.0);
    // Direction: laser 5's elevation, firing 1's azimuth (0.2 deg), clockwise.
    let want = ret(5, 12.0, 1, ReturnKind::Strongest);
    for (got, want) in [(r.x, want.x), (r.y, want.y), (r.z, want.z)] {
        assert!((got - want).abs() < 1e-4, "{got} vs {want}");
    }
    assert!((r.azimuth - 0.2).abs() < 1e-5);
    assert!((r.time - want.time).abs() < 1e-9);
    // It is reported: survivors include it, last.
    let s = f.survivors();
    assert_eq!(s.len(), f.len());
    assert_eq!(s.last().unwrap().range, 12.0);
}

#[test]
fn occluded_slots_get_no_echo() {
    let mut f = strongest_frame();
    let i = index_of(&f, 0, 5);
    let j = index_of(&f, 2, 5);
    f.fate[i] = Fate::Occluded;
    f.fate[j] = Fate::Occluded;
    f.propose(
        i,
        Echo {
            range: 2.0,
            power: 0.9,
        },
    );
    // The empty slot of laser 5 in firing 1 takes its beam from an occluded return.
    let slot = f.slots().slot(1, 5);
    f.propose_slot(
        slot,
        Echo {
            range: 2.0,
            power: 0.9,
        },
    );
    resolve(&mut f);
    assert_eq!(f.fate[i], Fate::Occluded);
    assert_eq!(f.len(), f.clean_len);
}

#[test]
fn stage_order_does_not_decide_the_winner() {
    let run = |order: [(u8, Echo); 2]| {
        let mut f = strongest_frame();
        let i = index_of(&f, 1, 1);
        for (stage, echo) in order {
            f.stage = stage;
            f.propose(i, echo);
        }
        resolve(&mut f);
        (f.fate[i], f.cause[i], f.range[i])
    };
    let a = (
        0,
        Echo {
            range: 1.6,
            power: 0.3,
        },
    );
    let b = (
        1,
        Echo {
            range: 8.0,
            power: 0.6,
        },
    );
    assert_eq!(run([a, b]), run([b, a]));
    assert_eq!(run([a, b]), (Fate::Replaced, 1, 8.0));
}

/// A dual frame where one slot holds only its strongest return (no last return for that
/// laser, as a frame built by hand or from the Python package may be): an echo there
/// competes with that return instead of panicking on the empty entry (it read the
/// empty marker, u32::MAX, as an index).
#[test]
fn a_dual_slot_with_only_its_strongest_return_resolves() {
    let mut v = Vec::new();
    for laser in 0..32u8 {
        v.push(ret(laser, 20.0, 0, ReturnKind::DualLast));
    }
    // Laser 0 of firing 1: its strongest return only.
    v.push(ret(0, 20.0, 1, ReturnKind::DualStrongest));
    let mut f = frame(v);
    let i = f.len() - 1;
    let p = f.power[i];
    f.stage = 2;
    f.propose(
        i,
        Echo {
            range: 3.0,
            power: p * 4.0,
        },
    );
    resolve(&mut f);
    // The stronger echo wins the strongest-return entry of the slot.
    assert_eq!(f.fate[i], Fate::Replaced);
    assert_eq!(f.cause[i], 2);
    assert_eq!(f.range[i], 3.0);
}

/// A frame of `firings` firings of 32 lasers in `mode` (`Strongest`, `Last` or dual),
/// some slots empty, fates and powers drawn from small sets so that ties are common.
fn random_frame(seed: u64, firings: u32, mode: ReturnKind) -> NoisyFrame {
    use rand::{Rng, SeedableRng};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let kinds: &[ReturnKind] = match mode {
        ReturnKind::Strongest | ReturnKind::Last => &[mode],
        _ => &[ReturnKind::DualLast, ReturnKind::DualStrongest],
    };
    let mut v = Vec::new();
    for firing in 0..firings {
        for &kind in kinds {
            for laser in 0..32u8 {
                if rng.random_bool(0.1) {
                    continue;
                }
                v.push(ret(
                    laser,
                    [5.0, 10.0, 20.0][rng.random_range(0..3)],
                    firing,
                    kind,
                ));
            }
        }
    }
    let mut f = frame(v);
    for i in 0..f.clean_len {
        f.power[i] = [0.0005, 0.002, 0.004, 0.008][rng.random_range(0..4)];
        f.fate[i] = [
            Fate::Kept,
            Fate::Kept,
            Fate::Kept,
            Fate::Occluded,
            Fate::BelowPower,
        ][rng.random_range(0..5)];
    }
    f
}

/// An echo from the same small sets (a NaN power for none, sometimes).
fn random_echo(rng: &mut rand_chacha::ChaCha8Rng) -> Echo {
    use rand::Rng;
    Echo {
        range: [1.5, 5.0, 10.0, 20.0][rng.random_range(0..4)],
        power: [0.0005, 0.002, 0.004, 0.008, f64::NAN][rng.random_range(0..5)],
    }
}

#[test]
fn an_echo_for_every_return_resolves_as_the_same_echoes_proposed_one_by_one() {
    // The column of `propose_each` (fog's echoes) stands for candidates proposed in
    // return order, after the earlier stages' and before its own stage's others: the
    // same fates, causes, ranges, powers and bytes in every return mode, ties included.
    use rand::{Rng, SeedableRng};
    for mode in [
        ReturnKind::Strongest,
        ReturnKind::Last,
        ReturnKind::DualLast,
    ] {
        for seed in 0..40 {
            let mut column = random_frame(seed, 6, mode);
            let mut one_by_one = random_frame(seed, 6, mode);
            let slots = column.slots();
            let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1000 + seed);
            // Stage 0: a few echoes anywhere; stage 1: the column, then more echoes;
            // stage 2: a few more.
            let early: Vec<(u32, Echo)> = (0..20)
                .map(|_| {
                    (
                        rng.random_range(0..slots.len() as u32),
                        random_echo(&mut rng),
                    )
                })
                .collect();
            let each: Vec<Echo> = (0..column.clean_len)
                .map(|_| random_echo(&mut rng))
                .collect();
            // The rest of stage 1: every empty slot and some occupied ones.
            let vacant: Vec<(u32, Echo)> = (0..slots.len() as u32)
                .filter(|&s| slots.is_vacant(s) || s % 7 == 0)
                .map(|s| (s, random_echo(&mut rng)))
                .collect();
            let late: Vec<(u32, Echo)> = (0..20)
                .map(|_| {
                    (
                        rng.random_range(0..slots.len() as u32),
                        random_echo(&mut rng),
                    )
                })
                .collect();
            for (f, dense) in [(&mut column, true), (&mut one_by_one, false)] {
                f.stage = 0;
                for &(s, e) in &early {
                    f.propose_slot(s, e);
                }
                f.stage = 1;
                if dense {
                    f.propose_each(each.clone());
                } else {
                    for (i, &e) in each.iter().enumerate() {
                        if !e.power.is_nan() {
                            f.propose(i, e);
                        }
                    }
                }
                for &(s, e) in &vacant {
                    f.propose_slot(s, e);
                }
                f.stage = 2;
                for &(s, e) in &late {
                    f.propose_slot(s, e);
                }
            }
            assert_eq!(column.proposals(), one_by_one.candidates, "{mode:?} {seed}");
            resolve(&mut column);
            resolve(&mut one_by_one);
            let what = format!("{mode:?} seed {seed}");
            assert_eq!(column.fate, one_by_one.fate, "{what}");
            assert_eq!(column.cause, one_by_one.cause, "{what}");
            assert_eq!(column.range, one_by_one.range, "{what}");
            assert_eq!(column.power, one_by_one.power, "{what}");
            assert_eq!(column.clean, one_by_one.clean, "{what}");
            assert_eq!(column.moved.intensity, one_by_one.moved.intensity, "{what}");
            // Not vacuous: echoes won.
            assert!(column.fate.contains(&Fate::Replaced), "{what}");
        }
    }
}
