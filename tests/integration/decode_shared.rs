//! Decoder against the real HDL-32E capture in ../shared/data.

use crate::common;

use lidar_noise::frame::Return;
use lidar_noise::sensor::frames::{DecoderOptions, FrameReader};
use serde_json::Value;

fn decode_all(
    opts: &DecoderOptions,
) -> Option<(
    Vec<lidar_noise::frame::Frame>,
    lidar_noise::sensor::frames::CaptureSummary,
)> {
    let path = common::shared("hdl32e/monterey.pcap")?;
    let mut reader = FrameReader::open(&path, opts).expect("open monterey");
    let frames: Vec<_> = reader.by_ref().collect::<Result<_, _>>().expect("decode");
    Some((frames, reader.summary()))
}

#[test]
fn packet_counts_frames_and_per_ring_aggregates_match_the_reference() {
    let opts = DecoderOptions {
        keep_partial: true,
        ..DecoderOptions::default()
    };
    let Some((frames, summary)) = decode_all(&opts) else {
        return;
    };
    let Some(json_path) = common::shared("hdl32e/monterey.per_ring.json") else {
        return;
    };
    let reference: Value =
        serde_json::from_str(&std::fs::read_to_string(json_path).unwrap()).unwrap();

    assert_eq!(summary.data_packets, 2702);
    assert_eq!(summary.position_packets, 299);
    assert_eq!(summary.full_frames, 17);
    assert_eq!(summary.partial_frames, 2);
    assert_eq!(summary.returns, 872_800);
    assert_eq!(
        summary.returns,
        reference["valid_returns"].as_u64().unwrap()
    );
    assert!(frames.first().unwrap().partial && frames.last().unwrap().partial);
    assert_eq!(frames.iter().filter(|f| !f.partial).count(), 17);

    let mut count = [0u64; 32];
    let mut sum_range = [0u64; 32];
    let mut sum_intensity = [0u64; 32];
    let mut laser_of_ring = [0u8; 32];
    for r in frames.iter().flat_map(|f| f.returns.iter()) {
        let ring = r.ring as usize;
        count[ring] += 1;
        sum_range[ring] += u64::from(r.raw_distance);
        sum_intensity[ring] += u64::from(r.intensity);
        laser_of_ring[ring] = r.laser;
    }
    let rings = reference["per_ring"].as_array().unwrap();
    assert_eq!(rings.len(), 32);
    for entry in rings {
        let ring = entry["ring"].as_u64().unwrap() as usize;
        assert_eq!(
            u64::from(laser_of_ring[ring]),
            entry["laser"].as_u64().unwrap(),
            "ring {ring} laser"
        );
        assert_eq!(
            count[ring],
            entry["returns"].as_u64().unwrap(),
            "ring {ring} returns"
        );
        assert_eq!(
            sum_range[ring],
            entry["sum_range_2mm"].as_u64().unwrap(),
            "ring {ring} distance sum"
        );
        assert_eq!(
            sum_intensity[ring],
            entry["sum_intensity"].as_u64().unwrap(),
            "ring {ring} intensity sum"
        );
    }
}

#[test]
fn full_frames_leave_out_the_partial_sweeps_by_default() {
    let Some((frames, summary)) = decode_all(&DecoderOptions::default()) else {
        return;
    };
    assert_eq!(frames.len(), 17);
    assert!(frames.iter().all(|f| !f.partial));
    let indices: Vec<u32> = frames.iter().map(|f| f.index).collect();
    assert_eq!(
        indices,
        (1..=17).collect::<Vec<u32>>(),
        "sweep numbering keeps the partial first sweep"
    );
    let in_frames: u64 = frames.iter().map(|f| f.returns.len() as u64).sum();
    assert_eq!(in_frames, summary.returns_in_full_frames);
    assert!(summary.returns_in_full_frames < summary.returns);
    let hz = summary.rotation_hz.unwrap();
    assert!((11.0..12.5).contains(&hz), "rotation {hz} Hz");
}

/// Every point of the independent decoder's frame 1 has a decoded point of the same
/// ring and intensity within 3 cm.
#[test]
fn frame1_matches_the_independent_decoder_within_3_cm() {
    let Some(csv_path) = common::shared("hdl32e/monterey.frame1.reference.csv") else {
        return;
    };
    let Some((frames, _)) = decode_all(&DecoderOptions {
        keep_partial: true,
        ..DecoderOptions::default()
    }) else {
        return;
    };
    // The reference cuts frames at the first packet's azimuth, so its frame 1 spans parts
    // of our sweeps 1 and 2: search them all, bucketed by (ring, intensity).
    let mut buckets: std::collections::HashMap<(u8, u8), Vec<&Return>> = Default::default();
    for r in frames.iter().flat_map(|f| f.returns.iter()) {
        buckets.entry((r.ring, r.intensity)).or_default().push(r);
    }
    let mut reader = csv::Reader::from_path(csv_path).unwrap();
    let mut n = 0usize;
    let mut worst = 0.0f64;
    for row in reader.records() {
        let row = row.unwrap();
        let x: f64 = row[0].parse().unwrap();
        let y: f64 = row[1].parse().unwrap();
        let z: f64 = row[2].parse().unwrap();
        let intensity: u8 = row[3].parse().unwrap();
        let ring: u8 = row[5].parse().unwrap();
        let best = buckets
            .get(&(ring, intensity))
            .map(|v| {
                v.iter()
                    .map(|r| {
                        let d = (f64::from(r.x) - x).powi(2)
                            + (f64::from(r.y) - y).powi(2)
                            + (f64::from(r.z) - z).powi(2);
                        d.sqrt()
                    })
                    .fold(f64::INFINITY, f64::min)
            })
            .unwrap_or(f64::INFINITY);
        assert!(
            best <= 0.03,
            "reference point {n} ({x}, {y}, {z}) ring {ring}: nearest decoded point {best} m away"
        );
        worst = worst.max(best);
        n += 1;
    }
    assert_eq!(n, 49_537);
    eprintln!("frame 1: {n} reference points, worst distance {worst:.4} m");
}

#[test]
fn vlp16_capture_is_refused_naming_the_vlp16() {
    let Some(path) = common::shared("negative/vlp16_mrpt.pcap") else {
        return;
    };
    let err = FrameReader::open(&path, &DecoderOptions::default())
        .err()
        .expect("must refuse");
    let msg = err.to_string();
    assert!(msg.contains("VLP-16"), "{msg}");
    assert!(msg.contains("vlp16_mrpt.pcap"), "{msg}");
}
