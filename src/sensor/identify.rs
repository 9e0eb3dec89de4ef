//! Tells which described sensor a capture comes from by its structure, not by its
//! product byte alone: real VLP-16 captures exist whose product byte says 0x21.
//!
//! Three measures of the first data packets: the product byte (byte 1205), the packet
//! period (median spacing of the sensor timestamps, or of the capture timestamps when
//! the sensor clock does not move: 552.96 us for the HDL-32E and 1327.104 us for the
//! VLP-16 in single return mode, half in dual mode, from [`SensorModel::packet_period_us`])
//! and the azimuth step per block, which must give a rotation rate within the model's
//! range (5 to 20 Hz for these models; an HDL-32E reading of VLP-16 packets would turn
//! at 24 Hz and more). The period decides the timing family; the product byte then picks
//! the model within it (the VLP-16 and Puck Hi-Res share their timing); a product byte
//! that names no model of the measured family is reported as contradicted.
//!
//! The VLP-32C (663.552 us a packet in single mode, 331.776 us in dual) is told from a
//! VLP-16 in dual mode (also 663.552 us) by the mode byte, and from an HDL-32E (552.96
//! us) by the period. The HDL-64E S2 and S3 write no product or mode byte: their block
//! flags alternate 0xFFEE (upper bank) and 0xFFDD (lower bank), which no other model
//! writes, and the period tells them apart (6 firings of 48 us, 288 us, for the S2;
//! 6 of 57.6 us, 345.6 us, for the S3; half in dual mode, where the first blocks of the
//! two return groups carry the same azimuth).
//!
//! The VLS-128 writes flags 0xFFEE, 0xFFDD, 0xFFCC and 0xFFBB in turn (pairs of each in
//! dual mode), which no other model writes; its two firmware timings are told apart by
//! the period (173.4 us a packet with the 2.89 us channel, 160 us with the 8/3 us one;
//! a third in dual mode, where a packet holds one firing and the step per firing is
//! measured from one packet's first block to the next's), the nearer one where both fit.
//!
//! [`hdl32e_identity`] is the HDL-32E reader's check of its first data packets:
//! the product byte alone is not enough: real VLP-16 captures exist whose product
//! byte says 0x21. The firing period is: the HDL-32E fires every 46.08 us (12 firings
//! per single-return packet, about 553 us between packets), the VLP-16 every 55.296 us
//! with two 16-laser firings per block (24 per packet, about 1327 us between packets).

use super::packet;
use super::{ReturnMode, SensorModel, MODELS};

/// Relative tolerance on the packet period.
pub const PERIOD_TOLERANCE: f64 = 0.05;

/// What identification found.
#[derive(Clone, Debug, PartialEq)]
pub struct Identified {
    /// The model.
    pub model: &'static SensorModel,
    /// Return mode of the first data packet.
    pub mode: ReturnMode,
    /// Product byte the packets carry (0 for the HDL-64E, whose packets have none).
    pub product_byte: u8,
    /// False when the product byte names another model (or 0x00, old firmware); true
    /// where the layout has no product byte.
    pub product_byte_agrees: bool,
    /// Median time between data packets in microseconds.
    pub packet_period_us: f64,
    /// Median azimuth step between consecutive firings' blocks, in degrees.
    pub azimuth_step_deg: f64,
    /// Rotation rate implied by the step and the model's block duration, in Hz.
    pub rotation_hz: f64,
    /// A note for the user (why the product byte was overruled), empty when none.
    pub note: String,
}

fn median(mut values: Vec<f64>) -> Option<f64> {
    if values.is_empty() {
        return None;
    }
    values.sort_by(f64::total_cmp);
    Some(values[values.len() / 2])
}

/// Median positive spacing below 5 ms of a series of microsecond times.
fn spacing_us(times: impl Iterator<Item = f64>) -> Option<f64> {
    let t: Vec<f64> = times.collect();
    median(
        t.windows(2)
            .map(|w| w[1] - w[0])
            .filter(|d| *d > 0.0 && *d < 5_000.0)
            .collect(),
    )
}

/// Identifies the sensor from the first data packets of a capture: each entry is a UDP
/// payload and its capture timestamp in nanoseconds. Payloads that are not 1206-byte
/// data packets with block flags are skipped. The error says what was measured and why
/// no described sensor fits.
pub fn identify(packets: &[(&[u8], u64)]) -> Result<Identified, String> {
    // The layout most packets follow: all blocks 0xFFEE, or the HDL-64E's alternating
    // 0xFFEE / 0xFFDD banks.
    let layouts = [
        super::LAYOUT_1206,
        super::LAYOUT_HDL64E,
        super::LAYOUT_VLS128,
    ];
    let (layout, data) = layouts
        .iter()
        .map(|l| {
            let data: Vec<(&[u8], u64)> = packets
                .iter()
                .copied()
                .filter(|(p, _)| l.is_data_packet(p))
                .collect();
            (*l, data)
        })
        .max_by_key(|(_, d)| d.len())
        .expect("two layouts");
    if data.len() < 3 {
        return Err(format!(
            "{} Velodyne data packets (1206-byte UDP payloads with 0xFFEE block flags, or \
             0xFFEE and 0xFFDD alternating, or 0xFFEE, 0xFFDD, 0xFFCC, 0xFFBB in turn) among \
             {} packets: at least 3 are needed to tell the sensor by its packet timing",
            data.len(),
            packets.len()
        ));
    }
    let product = layout.product_at.map_or(0, |at| data[0].0[at]);
    if let Some(at) = layout.product_at {
        if let Some(k) = data.iter().position(|(p, _)| p[at] != product) {
            return Err(format!(
                "data packets disagree on the product id: data packet {k} has 0x{:02x} where \
                 data packet 0 has 0x{product:02x}: the capture mixes sensors",
                data[k].0[at]
            ));
        }
    }
    let mode = layout.return_mode(data[0].0).map_err(|byte| {
        format!("unknown return mode byte 0x{byte:02x} in the first data packet")
    })?;
    let device = spacing_us(data.iter().map(|(p, _)| f64::from(layout.timestamp_us(p))));
    let period = device
        .or_else(|| spacing_us(data.iter().map(|(_, ns)| *ns as f64 / 1000.0)))
        .ok_or("no two data packets with increasing timestamps: the packet timing is unknown")?;
    // Azimuth step between consecutive firings' first blocks inside each packet.
    let per = layout.blocks_per_firing(mode);
    let firings = layout.blocks / per;
    let mut steps: Vec<f64> = data
        .iter()
        .flat_map(|(p, _)| {
            (0..layout.blocks / per - 1).map(move |f| {
                let a = u32::from(layout.block_azimuth(p, f * per)) % 36000;
                let b = u32::from(layout.block_azimuth(p, (f + 1) * per)) % 36000;
                f64::from((b + 36000 - a) % 36000) * 0.01
            })
        })
        .filter(|s| *s > 0.0 && *s < 5.0)
        .collect();
    if firings == 1 {
        // One firing a packet (the VLS-128 in dual mode): the step from one packet's
        // first block to the next packet's.
        steps = data
            .windows(2)
            .map(|w| {
                let a = u32::from(layout.block_azimuth(w[0].0, 0)) % 36000;
                let b = u32::from(layout.block_azimuth(w[1].0, 0)) % 36000;
                f64::from((b + 36000 - a) % 36000) * 0.01
            })
            .filter(|s| *s > 0.0 && *s < 5.0)
            .collect();
    }
    let step =
        median(steps).ok_or("the block azimuths do not advance: the sensor is not turning")?;
    let fits = |m: &SensorModel| {
        let want = m.packet_period_us(mode);
        let hz = step / 360.0 / (m.block_us() * 1e-6);
        (period - want).abs() <= PERIOD_TOLERANCE * want
            && hz >= m.rotation_hz.0 * 0.9
            && hz <= m.rotation_hz.1 * 1.1
    };
    let mut candidates: Vec<&'static SensorModel> = MODELS
        .iter()
        .copied()
        .filter(|m| m.layout == layout && fits(m))
        .collect();
    // Nearest period first (stable: models of one timing keep their order). The two
    // VLS-128 timings both fit a real capture's 166 us (tier4/nebula's test data):
    // the nearer, 160 us, is the one velodyne_decoder also picks (below 167 us).
    candidates.sort_by(|a, b| {
        let off = |m: &SensorModel| (period - m.packet_period_us(mode)).abs();
        off(a).total_cmp(&off(b))
    });
    let product_name = match (layout.product_at, super::by_product(product)) {
        (None, _) => "none: status bytes",
        (_, Some(m)) => m.name,
        _ => crate::sensor::packet::product_name(product),
    };
    let Some(&first) = candidates.first() else {
        let expected: Vec<String> = MODELS
            .iter()
            .filter(|m| m.layout == layout)
            .map(|m| {
                format!(
                    "{} {:.0} us and {:.2} to {:.2} deg per block",
                    m.name,
                    m.packet_period_us(mode),
                    m.rotation_hz.0 * 360.0 * m.block_us() * 1e-6,
                    m.rotation_hz.1 * 360.0 * m.block_us() * 1e-6
                )
            })
            .collect();
        return Err(format!(
            "unknown sensor: product byte 0x{product:02x} ({product_name}), data packets \
             {period:.0} us apart, azimuth step {step:.3} deg per block in {mode:?} return \
             mode; no described sensor fits (expected: {})",
            expected.join("; ")
        ));
    };
    let (model, agrees) = match candidates.iter().find(|m| m.product_id == product) {
        _ if layout.product_at.is_none() => (first, true),
        Some(&m) => (m, true),
        None => (first, false),
    };
    let note = if agrees {
        String::new()
    } else {
        format!(
            "the product byte says 0x{product:02x} ({product_name}) but the packet timing \
             ({period:.0} us between data packets, {step:.3} deg per block) is that of the {}; \
             decoded as the {}",
            model.name, model.name
        )
    };
    Ok(Identified {
        model,
        mode,
        product_byte: product,
        product_byte_agrees: agrees,
        packet_period_us: period,
        azimuth_step_deg: step,
        rotation_hz: step / 360.0 / (model.block_us() * 1e-6),
        note,
    })
}

/// What the first data packets of a capture say about the sensor.
#[derive(Clone, Debug, Default)]
pub struct Sample {
    /// Product id byte of each sampled data packet.
    pub products: Vec<u8>,
    /// Return mode byte of each sampled data packet.
    pub modes: Vec<u8>,
    /// Sensor timestamp (us past the hour) of each sampled data packet.
    pub device_us: Vec<u32>,
    /// Capture timestamp (ns) of each sampled data packet.
    pub capture_ns: Vec<u64>,
    /// Record number and byte offset in the capture of each sampled data packet, for
    /// messages (empty when the sample was built without them).
    pub places: Vec<(u32, u64)>,
}

/// How many data packets [`identify`] wants to see.
pub const SAMPLE_PACKETS: usize = 64;

impl Sample {
    /// Adds one data packet to the sample: its payload, capture time, record number and
    /// byte offset.
    pub fn push(&mut self, payload: &[u8], capture_ns: u64, record: u32, offset: u64) {
        self.places.push((record, offset));
        self.products.push(packet::product_byte(payload));
        self.modes.push(packet::return_mode_byte(payload));
        self.device_us.push(packet::timestamp_us(payload));
        self.capture_ns.push(capture_ns);
    }

    /// True once enough packets have been seen.
    pub fn is_full(&self) -> bool {
        self.products.len() >= SAMPLE_PACKETS
    }
}

/// The identified sensor.
#[derive(Clone, Debug, PartialEq)]
pub struct Identity {
    /// Product id byte (0x21, or 0x00 from old firmware).
    pub product: u8,
    /// Return mode of the capture.
    pub mode: ReturnMode,
    /// Median time between data packets in microseconds, if measurable.
    pub packet_period_us: Option<f64>,
}

/// Median spacing of consecutive timestamps, ignoring gaps and clock wraps.
fn packet_period_us(sample: &Sample) -> Option<f64> {
    let device: Vec<f64> = sample
        .device_us
        .windows(2)
        .filter_map(|w| {
            let d = i64::from(w[1]) - i64::from(w[0]);
            (d > 0 && d < 5_000).then_some(d as f64)
        })
        .collect();
    if device.len() >= 2 {
        return median(device);
    }
    // Sensors without a synchronised clock may leave the timestamp at zero: fall back
    // to the capture clock, which is noisier but still separates 553 from 1327 us.
    let capture: Vec<f64> = sample
        .capture_ns
        .windows(2)
        .filter_map(|w| {
            let d = w[1] as f64 / 1000.0 - w[0] as f64 / 1000.0;
            (d > 0.0 && d < 5_000.0).then_some(d)
        })
        .collect();
    if capture.len() >= 2 {
        median(capture)
    } else {
        None
    }
}

/// Why sampled packets were not taken for an HDL-32E's.
#[derive(Clone, Debug, PartialEq)]
pub struct Refusal {
    /// What the packets are, for the user.
    pub message: String,
    /// Whether their product byte names another sensor (whose own reader then explains).
    pub other_sensor: bool,
}

impl From<String> for Refusal {
    fn from(message: String) -> Self {
        Refusal {
            message,
            other_sensor: false,
        }
    }
}

impl std::fmt::Display for Refusal {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.message)
    }
}

/// Decides whether the sampled packets come from an HDL-32E; the error says what they are.
pub fn hdl32e_identity(sample: &Sample) -> Result<Identity, Refusal> {
    let Some(&product) = sample.products.first() else {
        return Err(String::from(
            "no HDL-32E data packets found (1206-byte UDP payloads with 0xFFEE block \
                    flags): is this a Velodyne capture?",
        )
        .into());
    };
    if let Some(k) = sample.products.iter().position(|&p| p != product) {
        let other = sample.products[k];
        let place = |i: usize| match sample.places.get(i) {
            Some((record, offset)) => format!(" (record {record} at byte offset {offset})"),
            None => String::new(),
        };
        return Err(Refusal::from(format!(
            "data packets disagree on the product id: data packet {k}{} has 0x{other:02x} ({}) \
             where data packet 0{} has 0x{product:02x} ({}): the capture mixes sensors; keep \
             one sensor's packets (e.g. filter by UDP port) and rerun",
            place(k),
            packet::product_name(other),
            place(0),
            packet::product_name(product)
        )));
    }
    if product != packet::PRODUCT_HDL32E && product != 0 {
        return Err(Refusal {
            message: format!(
                "this is a {} capture (product id 0x{product:02x}), not an HDL-32E",
                packet::product_name(product)
            ),
            other_sensor: true,
        });
    }
    let mode_byte = sample.modes[0];
    let mode = ReturnMode::from_byte(mode_byte).ok_or_else(|| {
        Refusal::from(format!(
            "unknown return mode byte 0x{mode_byte:02x} in the first data packet"
        ))
    })?;
    let period = packet_period_us(sample);
    if let Some(period) = period {
        let firings = if mode == ReturnMode::Dual { 6.0 } else { 12.0 };
        let per_firing = period / firings;
        if !(40.0..=52.0).contains(&per_firing) {
            let vlp16 = (100.0..=122.0).contains(&per_firing);
            let what = if vlp16 {
                "the packet timing of a VLP-16 (two 16-laser firings per block, about 1327 us \
                 between data packets)"
            } else {
                "a packet timing no HDL-32E produces"
            };
            return Err(Refusal::from(format!(
                "the product byte says 0x{product:02x} but data packets are {period:.0} us apart, \
                 {what}; an HDL-32E sends one every {:.0} us",
                firings * packet::FIRING_US
            )));
        }
    } else if product == 0 {
        return Err(String::from(
            "product id 0x00 (old firmware) and too few data packets to confirm the HDL-32E \
             packet timing",
        )
        .into());
    }
    Ok(Identity {
        product,
        mode,
        packet_period_us: period,
    })
}

#[cfg(test)]
mod hdl32e_tests {
    use super::*;

    fn sample(product: u8, mode: u8, period: u32) -> Sample {
        let mut s = Sample::default();
        for i in 0..10u32 {
            s.products.push(product);
            s.modes.push(mode);
            s.device_us.push(1_000 + i * period);
            s.capture_ns.push(u64::from(i) * 1_000_000);
        }
        s
    }

    #[test]
    fn hdl32e_timing_is_accepted_in_single_and_dual_mode() {
        assert!(hdl32e_identity(&sample(0x21, 0x37, 553)).is_ok());
        assert!(hdl32e_identity(&sample(0x21, 0x39, 276)).is_ok());
        assert!(hdl32e_identity(&sample(0x00, 0x00, 553)).is_ok());
    }

    #[test]
    fn vlp16_is_refused_by_product_or_by_timing() {
        let by_product = hdl32e_identity(&sample(0x22, 0x37, 1327)).unwrap_err();
        assert!(by_product.message.contains("VLP-16"), "{by_product}");
        assert!(by_product.other_sensor, "{by_product}");
        let by_timing = hdl32e_identity(&sample(0x21, 0x37, 1327)).unwrap_err();
        assert!(by_timing.message.contains("VLP-16"), "{by_timing}");
        assert!(!by_timing.other_sensor, "{by_timing}");
        let dual = hdl32e_identity(&sample(0x21, 0x39, 663)).unwrap_err();
        assert!(dual.message.contains("VLP-16"), "{dual}");
    }

    #[test]
    fn empty_and_mixed_samples_are_refused() {
        assert!(hdl32e_identity(&Sample::default()).is_err());
        let mut mixed = sample(0x21, 0x37, 553);
        mixed.products[3] = 0x22;
        assert!(hdl32e_identity(&mixed).is_err());
    }

    #[test]
    fn mixed_products_name_the_packet_and_its_offset() {
        // Issue 30, defect 8: the message named no packet nor offset.
        let mut payload = vec![0u8; packet::DATA_PACKET_BYTES];
        let mut s = Sample::default();
        for i in 0..10u32 {
            payload[packet::DATA_PACKET_BYTES - 1] = if i == 6 { 0x22 } else { 0x21 };
            s.push(&payload, u64::from(i), i + 2, 24 + 1264 * u64::from(i + 2));
        }
        let m = hdl32e_identity(&s).unwrap_err().message;
        assert!(
            m.contains("data packet 6 (record 8 at byte offset 10136) has 0x22 (VLP-16)")
                && m.contains("data packet 0 (record 2 at byte offset 2552) has 0x21"),
            "{m}"
        );
    }
}
