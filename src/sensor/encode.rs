//! Data packet encoding for any [`SensorModel`]: the inverse of [`super::decode`], for
//! writing noisy returns back into a capture (`--pcap-out`) and for synthesizing
//! captures of any described sensor.
//!
//! A return's place in the packet is [`SensorModel::packet_position`] of its
//! `Return::block` and laser id (the inverse of the decoder's
//! [`SensorModel::return_block`]); only its 3-byte slot (distance u16 LE, intensity u8)
//! is written. Re-encoding a packet ([`reencode_packet`]) clears every slot of the
//! blocks its mode uses, then writes each return: block flags, azimuths, timestamp,
//! mode, product and status bytes, and the blocks a dual-mode VLS-128 packet leaves
//! empty stay as they were, so decode -> re-encode -> decode gives the same returns
//! (tests: every model, every mode). [`encode_packet`] builds a packet from nothing:
//! the model's flags, one azimuth per firing on every block of that firing, the
//! timestamp and the mode and product bytes (status bytes on the HDL-64E).

use super::{ReturnMode, SensorModel};
use crate::frame::Return;

/// The mode byte a sensor writes for a return mode (0x37, 0x38, 0x39; 0x00 for the old
/// firmware's unknown mode).
pub fn mode_byte(mode: ReturnMode) -> u8 {
    match mode {
        ReturnMode::Strongest => 0x37,
        ReturnMode::Last => 0x38,
        ReturnMode::Dual => 0x39,
        ReturnMode::Unknown => 0x00,
    }
}

/// Clears every return slot (distance and intensity) of the blocks a data packet's mode
/// uses and returns the mode. The payload must be a data packet of the model's layout.
pub fn clear_returns(model: &SensorModel, payload: &mut [u8]) -> Result<ReturnMode, String> {
    let lay = &model.layout;
    if payload.len() != lay.payload_bytes {
        return Err(format!(
            "data packet of {} bytes where the {} sends {}",
            payload.len(),
            model.name,
            lay.payload_bytes
        ));
    }
    if let Some(b) = lay.bad_flag(payload) {
        return Err(format!(
            "block {b} has not the {}'s flag (payload byte offset {})",
            model.name,
            b * lay.block_bytes
        ));
    }
    let mode = lay
        .return_mode(payload)
        .map_err(|byte| format!("unknown return mode byte 0x{byte:02x}"))?;
    for block in 0..lay.used_blocks(mode) {
        let at = lay.channel_at(block, 0);
        payload[at..at + 3 * lay.channels].fill(0);
    }
    Ok(mode)
}

/// Writes one slot: raw distance `raw` and intensity of laser `laser` in the firing
/// slot `return_block` (a `Return::block` value) of a packet in mode `mode`. An
/// out-of-range laser or block is an error naming it, never a write elsewhere.
pub fn write_slot(
    model: &SensorModel,
    mode: ReturnMode,
    payload: &mut [u8],
    return_block: usize,
    laser: usize,
    raw: u16,
    intensity: u8,
) -> Result<(), String> {
    if laser >= model.lasers {
        return Err(format!(
            "laser {laser}: the {} has {}",
            model.name, model.lasers
        ));
    }
    let (block, channel) = model.packet_position(mode, return_block, laser);
    if block >= model.layout.used_blocks(mode) {
        return Err(format!(
            "firing slot {return_block} is past the {}'s packet in {mode:?} mode",
            model.name
        ));
    }
    let at = model.layout.channel_at(block, channel);
    payload[at..at + 2].copy_from_slice(&raw.to_le_bytes());
    payload[at + 2] = intensity;
    Ok(())
}

/// Writes a decoded (or noisy) return's raw distance and intensity into its slot.
pub fn write_return(
    model: &SensorModel,
    mode: ReturnMode,
    payload: &mut [u8],
    r: &Return,
) -> Result<(), String> {
    write_slot(
        model,
        mode,
        payload,
        usize::from(r.block),
        usize::from(r.laser),
        r.raw_distance,
        r.intensity,
    )
}

/// Re-encodes a data packet in place from its returns: every slot of the used blocks
/// cleared, then each return written (decode with `DualSelect::Both`, then this, gives
/// back the packet up to the intensity bytes of empty slots).
pub fn reencode_packet(
    model: &SensorModel,
    payload: &mut [u8],
    returns: &[Return],
) -> Result<(), String> {
    let mode = clear_returns(model, payload)?;
    for r in returns {
        write_return(model, mode, payload, r)?;
    }
    Ok(())
}

/// The header of a packet built by [`encode_packet`].
#[derive(Clone, Debug, PartialEq)]
pub struct PacketHeader {
    /// Return mode (the mode byte; on the HDL-64E only the block order and azimuths
    /// show it, and Last cannot be told from Strongest).
    pub mode: ReturnMode,
    /// Azimuth of each firing of the packet in hundredths of a degree (0..35999),
    /// written on every block of that firing.
    pub firing_azimuths: Vec<u16>,
    /// Timestamp, microseconds past the hour.
    pub timestamp_us: u32,
    /// Bytes 1204-1205 on layouts without mode and product bytes (the HDL-64E's status
    /// type and value); ignored elsewhere.
    pub status: (u8, u8),
}

/// A data packet of the model from a header and its slots `(return_block, laser, raw
/// distance, intensity)`; slots not given are empty (distance 0).
pub fn encode_packet(
    model: &SensorModel,
    header: &PacketHeader,
    slots: impl IntoIterator<Item = (usize, usize, u16, u8)>,
) -> Result<Vec<u8>, String> {
    let lay = &model.layout;
    let mode = header.mode;
    if !model.return_modes.contains(&mode) {
        return Err(format!("the {} has no {mode:?} return mode", model.name));
    }
    let firings = lay.blocks / lay.blocks_per_firing(mode);
    if header.firing_azimuths.len() != firings {
        return Err(format!(
            "{} firing azimuths where a {} packet in {mode:?} mode has {firings}",
            header.firing_azimuths.len(),
            model.name
        ));
    }
    let mut p = vec![0u8; lay.payload_bytes];
    let per = lay.blocks_per_firing(mode);
    for block in 0..lay.used_blocks(mode) {
        let at = block * lay.block_bytes;
        let az = header.firing_azimuths[block / per] % 36000;
        p[at..at + 2].copy_from_slice(&lay.expected_flag(mode, block).to_le_bytes());
        p[at + 2..at + 4].copy_from_slice(&az.to_le_bytes());
    }
    // Empty blocks (the VLS-128's last four in dual mode): no flag, the firing's
    // azimuth, as velodyne_decoder's mock dual capture writes them.
    for block in lay.used_blocks(mode)..lay.blocks {
        let at = block * lay.block_bytes + 2;
        p[at..at + 2].copy_from_slice(&(header.firing_azimuths[0] % 36000).to_le_bytes());
    }
    let t = lay.timestamp_at;
    p[t..t + 4].copy_from_slice(&header.timestamp_us.to_le_bytes());
    match (lay.return_mode_at, lay.product_at) {
        (Some(m), Some(id)) => {
            p[m] = mode_byte(mode);
            p[id] = model.product_id;
        }
        _ => {
            p[t + 4] = header.status.0;
            p[t + 5] = header.status.1;
        }
    }
    for (rb, laser, raw, intensity) in slots {
        write_slot(model, mode, &mut p, rb, laser, raw, intensity)?;
    }
    Ok(p)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sensor::decode::{DualSelect, ModelDecoder};
    use crate::sensor::MODELS;

    /// A data packet of `model` in `mode` from the layout (not from [`encode_packet`]):
    /// flags per the manuals' block order, azimuths of a 10 Hz turn, pseudo-random
    /// distances with about a tenth empty (intensity 0 there).
    fn packet(model: &SensorModel, mode: ReturnMode, seed: u32) -> Vec<u8> {
        let lay = &model.layout;
        let banks = lay.banks();
        let dual = mode == ReturnMode::Dual;
        let per = banks * if dual { 2 } else { 1 };
        let used = 12 / per * per;
        let mut p = vec![0u8; 1206];
        let mut x = seed.wrapping_mul(2_654_435_761).wrapping_add(12345);
        for b in 0..12 {
            let bank = if dual && lay.dual_pairs_adjacent {
                (b / 2) % banks
            } else {
                b % banks
            };
            let flag: u16 = [0xEEFF, 0xDDFF, 0xCCFF, 0xBBFF][bank];
            let az = ((35_900 + 20 * (b / per)) % 36_000) as u16;
            p[b * 100..b * 100 + 2].copy_from_slice(&flag.to_le_bytes());
            p[b * 100 + 2..b * 100 + 4].copy_from_slice(&az.to_le_bytes());
            for c in 0..32 {
                x ^= x << 13;
                x ^= x >> 17;
                x ^= x << 5;
                let at = b * 100 + 4 + 3 * c;
                if b < used && !x.is_multiple_of(10) {
                    p[at..at + 2].copy_from_slice(&((x >> 8) as u16 | 1).to_le_bytes());
                    p[at + 2] = (x >> 3) as u8;
                } else if b >= used {
                    // The VLS-128's empty blocks: whatever is there must survive.
                    p[at] = 0x5A;
                }
            }
        }
        p[1200..1204].copy_from_slice(&(1_000_000 + seed).to_le_bytes());
        if lay.return_mode_at.is_some() {
            p[1204] = mode_byte(mode);
            p[1205] = model.product_id;
        } else {
            p[1204] = b'H';
            p[1205] = 7;
            if dual {
                // HDL-64E dual: the second return group repeats the azimuths.
                for b in 0..12 {
                    let az = ((35_900 + 20 * (b / 4)) % 36_000) as u16;
                    p[b * 100 + 2..b * 100 + 4].copy_from_slice(&az.to_le_bytes());
                }
            }
        }
        p
    }

    #[test]
    fn decode_reencode_decode_is_exact_for_every_model_and_mode() {
        for model in MODELS {
            for &mode in model.return_modes {
                for seed in 0..3 {
                    let original = packet(model, mode, seed);
                    let dec = ModelDecoder::new(model, true, DualSelect::Both);
                    let mut first = Vec::new();
                    dec.decode_packet(&original, 0, 0.0, &mut first).unwrap();
                    assert!(
                        first.len() > 200,
                        "{} {mode:?}: {}",
                        model.name,
                        first.len()
                    );
                    let mut again = original.clone();
                    // Scribble over every slot first: re-encoding must clear them.
                    for b in 0..model.layout.used_blocks(mode) {
                        again[b * 100 + 4..b * 100 + 100].fill(0xAB);
                    }
                    reencode_packet(model, &mut again, &first).unwrap();
                    assert!(again == original, "{} {mode:?} seed {seed}", model.name);
                    let mut second = Vec::new();
                    dec.decode_packet(&again, 0, 0.0, &mut second).unwrap();
                    assert_eq!(first, second, "{} {mode:?}", model.name);
                    // From nothing: the header and the slots give the same packet.
                    let per = model.layout.blocks_per_firing(mode);
                    let header = PacketHeader {
                        mode,
                        firing_azimuths: (0..12 / per)
                            .map(|f| model.layout.block_azimuth(&original, f * per))
                            .collect(),
                        timestamp_us: model.layout.timestamp_us(&original),
                        status: (original[1204], original[1205]),
                    };
                    let slots = first.iter().map(|r| {
                        let (b, l) = (usize::from(r.block), usize::from(r.laser));
                        (b, l, r.raw_distance, r.intensity)
                    });
                    let built = encode_packet(model, &header, slots).unwrap();
                    let used = model.layout.used_blocks(mode) * 100;
                    assert!(built[..used] == original[..used], "{} {mode:?}", model.name);
                    assert!(built[1200..] == original[1200..], "{} {mode:?}", model.name);
                    let mut third = Vec::new();
                    dec.decode_packet(&built, 0, 0.0, &mut third).unwrap();
                    assert_eq!(first, third, "{} {mode:?}", model.name);
                }
            }
        }
    }

    #[test]
    fn bad_slots_and_packets_are_refused() {
        let m = &crate::sensor::VLS128;
        let mut p = packet(m, ReturnMode::Dual, 1);
        let e = write_slot(m, ReturnMode::Dual, &mut p, 2, 5, 1, 1).unwrap_err();
        assert!(e.contains("firing slot 2"), "{e}");
        let e = write_slot(m, ReturnMode::Dual, &mut p, 0, 128, 1, 1).unwrap_err();
        assert!(e.contains("laser 128"), "{e}");
        p[200] = 0;
        let e = clear_returns(m, &mut p).unwrap_err();
        assert!(e.contains("block 2") && e.contains("200"), "{e}");
        let e = clear_returns(m, &mut p[..1000]).unwrap_err();
        assert!(e.contains("1000 bytes"), "{e}");
        let header = PacketHeader {
            mode: ReturnMode::Strongest,
            firing_azimuths: vec![0; 2],
            timestamp_us: 0,
            status: (0, 0),
        };
        let e = encode_packet(m, &header, []).unwrap_err();
        assert!(
            e.contains("2 firing azimuths") && e.contains("has 3"),
            "{e}"
        );
    }
}
