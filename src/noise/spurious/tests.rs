//! Unit tests of `spurious`.

use super::*;

fn ret(packet: u32, block: u8, laser: u8, kind: ReturnKind) -> Return {
    Return {
        range: 1.0,
        packet,
        laser,
        block,
        kind,
        ..Return::BLANK
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
