//! Decoder settings and capture variants: ports, return modes, cut angle, calibration,
//! and `convert` output read back through ply-rs.

use crate::common;

use assert_cmd::Command;
use lidar_noise::capture::writer::PcapWriter;
use lidar_noise::frame::{Frame, ReturnKind};
use lidar_noise::sensor::calibration::Calibration;
use lidar_noise::sensor::decode::DualSelect;
use lidar_noise::sensor::encode::{encode_data_packet, FiringBlock};
use lidar_noise::sensor::frames::{DecoderOptions, FrameReader};
use ply_rs_bw::parser::Parser;
use ply_rs_bw::ply::{DefaultElement, Property};
use std::path::Path;
use std::sync::Arc;

fn decode_bytes(
    bytes: Vec<u8>,
    opts: &DecoderOptions,
) -> (Vec<Frame>, lidar_noise::sensor::frames::CaptureSummary) {
    let mut reader =
        FrameReader::from_bytes(Arc::from(bytes), Path::new("mem.pcap"), opts).unwrap();
    let frames = reader.by_ref().collect::<Result<Vec<_>, _>>().unwrap();
    (frames, reader.summary())
}

/// Two rotations of packets in the given return mode, every laser returning.
/// In dual mode the even block of a pair carries distance 1000 + laser (last), the odd
/// block 2000 + laser (strongest).
fn capture(mode: u8, port: u16) -> Vec<u8> {
    let dual = mode == 0x39;
    let firings_per_packet = if dual { 6 } else { 12 };
    let step = 20u32; // 0.2 degrees per firing
    let mut w = PcapWriter::new(Vec::new()).unwrap();
    let mut firing = 0u32;
    let mut ts = 1_000u32;
    while firing * step < 2 * 36000 + 600 {
        let mut blocks = [FiringBlock::default(); 12];
        for (b, block) in blocks.iter_mut().enumerate() {
            let f = firing + if dual { b as u32 / 2 } else { b as u32 };
            block.azimuth = ((f * step) % 36000) as u16;
            for j in 0..32 {
                block.distances[j] = if dual && b % 2 == 1 { 2000 } else { 1000 } + j as u16;
                block.intensities[j] = (b * 3 + j) as u8;
            }
        }
        let payload = encode_data_packet(&blocks, ts, mode);
        w.write_udp(u64::from(ts), port, port, &payload).unwrap();
        firing += firings_per_packet;
        ts += (firings_per_packet as f64 * 46.08).round() as u32;
    }
    w.into_inner().unwrap()
}

#[test]
fn any_udp_port_is_recognised_by_structure_and_reported() {
    let (a, sa) = decode_bytes(capture(0x37, 2368), &DecoderOptions::default());
    let (b, sb) = decode_bytes(capture(0x37, 443), &DecoderOptions::default());
    assert_eq!(sa.data_ports, vec![(2368, 2368)]);
    assert_eq!(sb.data_ports, vec![(443, 443)]);
    assert_eq!(
        a.len(),
        2,
        "two full rotations (the first starts at 0 degrees), then a partial one"
    );
    assert!(a.iter().zip(&b).all(|(x, y)| x.returns == y.returns));
}

#[test]
fn last_and_dual_return_modes_keep_the_selected_returns() {
    let (last, s) = decode_bytes(capture(0x38, 2368), &DecoderOptions::default());
    assert_eq!(format!("{:?}", s.return_mode), "Last");
    assert!(last[0].returns.iter().all(|r| r.kind == ReturnKind::Last));

    let dual = capture(0x39, 2368);
    let (both, s) = decode_bytes(dual.clone(), &DecoderOptions::default());
    assert_eq!(format!("{:?}", s.return_mode), "Dual");
    let n = both[0].returns.len();
    let lasts = both[0]
        .returns
        .iter()
        .filter(|r| r.kind == ReturnKind::DualLast)
        .count();
    assert_eq!(
        2 * lasts,
        n,
        "both returns of every firing are kept by default"
    );
    for r in &both[0].returns {
        let expected = match r.kind {
            ReturnKind::DualLast => 1000,
            ReturnKind::DualStrongest => 2000,
            other => panic!("unexpected kind {other:?}"),
        } + u16::from(r.laser);
        assert_eq!(r.raw_distance, expected);
        assert_eq!(r.block % 2, u8::from(r.kind == ReturnKind::DualStrongest));
    }
    // The two returns of one firing share azimuth and time.
    for pair in both[0].returns.chunks(64).take(50) {
        for j in 0..32 {
            assert_eq!(pair[j].azimuth, pair[32 + j].azimuth);
            assert_eq!(pair[j].time, pair[32 + j].time);
        }
    }
    for (select, kind) in [
        (DualSelect::Last, ReturnKind::DualLast),
        (DualSelect::Strongest, ReturnKind::DualStrongest),
    ] {
        let opts = DecoderOptions {
            dual: select,
            ..DecoderOptions::default()
        };
        let (frames, _) = decode_bytes(dual.clone(), &opts);
        assert_eq!(frames[0].returns.len(), n / 2);
        assert!(frames[0].returns.iter().all(|r| r.kind == kind));
    }
}

#[test]
fn cut_angle_moves_frame_starts_and_the_first_sweep_can_count_as_full() {
    let Some(path) = common::shared("hdl32e/monterey.pcap") else {
        return;
    };
    // The capture's first packet starts at 150.54 degrees.
    let opts = DecoderOptions {
        cut_angle_deg: 150.54,
        keep_partial: true,
        ..DecoderOptions::default()
    };
    let mut reader = FrameReader::open(&path, &opts).unwrap();
    let frames = reader.by_ref().collect::<Result<Vec<_>, _>>().unwrap();
    let s = reader.summary();
    assert_eq!((s.full_frames, s.partial_frames), (17, 1));
    assert!(!frames[0].partial, "starts within one step of the cut");
    assert!(frames.last().unwrap().partial);
    for f in &frames[1..] {
        let first = f
            .returns
            .iter()
            .filter(|r| r.laser == 0)
            .map(|r| r.azimuth)
            .next()
            .unwrap();
        let from_cut = (first - 150.54).rem_euclid(360.0);
        assert!(
            from_cut < 0.5,
            "frame {} starts {from_cut} degrees after the cut",
            f.index
        );
    }
}

#[test]
fn a_calibration_file_with_the_manual_angles_decodes_like_the_built_in_table() {
    let Some(path) = common::shared("hdl32e/monterey.pcap") else {
        return;
    };
    let data = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/calibration");
    let builtin = FrameReader::open(&path, &DecoderOptions::default())
        .unwrap()
        .next()
        .unwrap()
        .unwrap();
    for file in ["hdl32e_ros.yaml", "hdl32e_veloview.xml"] {
        let calibration = Calibration::from_file(&data.join(file)).unwrap();
        let opts = DecoderOptions {
            calibration,
            ..DecoderOptions::default()
        };
        let frame = FrameReader::open(&path, &opts)
            .unwrap()
            .next()
            .unwrap()
            .unwrap();
        assert_eq!(frame.returns.len(), builtin.returns.len());
        for (a, b) in frame.returns.iter().zip(&builtin.returns) {
            assert_eq!(
                (a.laser, a.ring, a.raw_distance, a.intensity),
                (b.laser, b.ring, b.raw_distance, b.intensity)
            );
            let d = ((a.x - b.x).powi(2) + (a.y - b.y).powi(2) + (a.z - b.z).powi(2)).sqrt();
            assert!(d < 1e-3, "{file}: {d} m apart");
        }
    }
}

#[test]
fn convert_output_reads_back_through_ply_rs_to_exactly_the_decoded_returns() {
    let capture = common::shared("hdl32e/monterey.pcap")
        .unwrap_or_else(|| common::fixtures().join("crossroad.pcap"));
    let frame = FrameReader::open(&capture, &DecoderOptions::default())
        .unwrap()
        .next()
        .unwrap()
        .unwrap();
    let tmp = tempfile::tempdir().unwrap();
    Command::cargo_bin("lidar-noise")
        .unwrap()
        .args(["--quiet", "convert"])
        .arg(&capture)
        .args(["--frames", &frame.index.to_string(), "-o"])
        .arg(tmp.path())
        .assert()
        .success();
    let bytes = std::fs::read(tmp.path().join(format!("frame_{:05}.ply", frame.index))).unwrap();
    let ply = Parser::<DefaultElement>::new()
        .read_ply(&mut &bytes[..])
        .unwrap();
    let vertices = &ply.payload["vertex"];
    assert_eq!(vertices.len(), frame.returns.len());
    let f = |v: &DefaultElement, k: &str| match &v[k] {
        Property::Float(x) => *x,
        other => panic!("{k}: {other:?}"),
    };
    let u = |v: &DefaultElement, k: &str| match &v[k] {
        Property::UChar(x) => *x,
        other => panic!("{k}: {other:?}"),
    };
    let t0 = frame.start_time();
    for (v, r) in vertices.iter().zip(&frame.returns) {
        assert_eq!((f(v, "x"), f(v, "y"), f(v, "z")), (r.x, r.y, r.z));
        assert_eq!((f(v, "azimuth"), f(v, "range")), (r.azimuth, r.range));
        assert_eq!(
            (u(v, "intensity"), u(v, "ring"), u(v, "laser")),
            (r.intensity, r.ring, r.laser)
        );
        assert_eq!(f(v, "time"), (r.time - t0) as f32);
    }
}
