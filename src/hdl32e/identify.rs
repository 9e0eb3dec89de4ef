//! Tells an HDL-32E capture from other Velodyne sensors before decoding it.
//!
//! The product byte alone is not enough: real VLP-16 captures exist whose product
//! byte says 0x21. The firing period is: the HDL-32E fires every 46.08 us (12 firings
//! per single-return packet, about 553 us between packets), the VLP-16 every 55.296 us
//! with two 16-laser firings per block (24 per packet, about 1327 us between packets).

use super::packet::{self, ReturnMode};

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

fn median(mut values: Vec<f64>) -> Option<f64> {
    if values.is_empty() {
        return None;
    }
    values.sort_by(f64::total_cmp);
    Some(values[values.len() / 2])
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
pub fn identify(sample: &Sample) -> Result<Identity, Refusal> {
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
mod tests {
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
        assert!(identify(&sample(0x21, 0x37, 553)).is_ok());
        assert!(identify(&sample(0x21, 0x39, 276)).is_ok());
        assert!(identify(&sample(0x00, 0x00, 553)).is_ok());
    }

    #[test]
    fn vlp16_is_refused_by_product_or_by_timing() {
        let by_product = identify(&sample(0x22, 0x37, 1327)).unwrap_err();
        assert!(by_product.message.contains("VLP-16"), "{by_product}");
        assert!(by_product.other_sensor, "{by_product}");
        let by_timing = identify(&sample(0x21, 0x37, 1327)).unwrap_err();
        assert!(by_timing.message.contains("VLP-16"), "{by_timing}");
        assert!(!by_timing.other_sensor, "{by_timing}");
        let dual = identify(&sample(0x21, 0x39, 663)).unwrap_err();
        assert!(dual.message.contains("VLP-16"), "{dual}");
    }

    #[test]
    fn empty_and_mixed_samples_are_refused() {
        assert!(identify(&Sample::default()).is_err());
        let mut mixed = sample(0x21, 0x37, 553);
        mixed.products[3] = 0x22;
        assert!(identify(&mixed).is_err());
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
        let m = identify(&s).unwrap_err().message;
        assert!(
            m.contains("data packet 6 (record 8 at byte offset 10136) has 0x22 (VLP-16)")
                && m.contains("data packet 0 (record 2 at byte offset 2552) has 0x21"),
            "{m}"
        );
    }
}
