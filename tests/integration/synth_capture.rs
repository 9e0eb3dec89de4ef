//! Capture writer and encoder: files parse with pcap-parser, payloads are byte-exact,
//! synthesis is deterministic.

use lidar_noise::capture::writer::{
    ByteOrder, PcapNgWriter, PcapOptions, PcapWriter, TimeResolution,
};
use lidar_noise::sensor::encode::{encode_data_packet, encode_position_packet, FiringBlock};
use lidar_noise::synth::{synthesize, write_capture, Scene, SynthOptions};
use pcap_parser::traits::PcapNGPacketBlock;
use pcap_parser::{Block, PcapBlockOwned, PcapError};
use std::path::Path;

/// One parsed record: timestamp in µs, link-layer frame bytes.
type Parsed = (u64, Vec<u8>);

/// Parses any pcap/pcapng byte buffer with pcap-parser; returns the link type and records.
fn parse(bytes: &[u8]) -> (i32, Vec<Parsed>) {
    let mut reader = pcap_parser::create_reader(65536, bytes).expect("a capture header");
    let mut out = Vec::new();
    let mut linktype = -1;
    let mut nano = false;
    loop {
        match reader.next() {
            Ok((offset, block)) => {
                match block {
                    PcapBlockOwned::LegacyHeader(h) => {
                        linktype = h.network.0;
                        nano = h.is_nanosecond_precision();
                    }
                    PcapBlockOwned::Legacy(b) => {
                        let frac = if nano {
                            u64::from(b.ts_usec) / 1000
                        } else {
                            u64::from(b.ts_usec)
                        };
                        out.push((u64::from(b.ts_sec) * 1_000_000 + frac, b.data.to_vec()));
                    }
                    PcapBlockOwned::NG(Block::InterfaceDescription(idb)) => {
                        linktype = idb.linktype.0;
                    }
                    PcapBlockOwned::NG(Block::EnhancedPacket(epb)) => {
                        let ts = (u64::from(epb.ts_high) << 32) | u64::from(epb.ts_low);
                        out.push((ts, epb.packet_data().to_vec()));
                    }
                    PcapBlockOwned::NG(_) => {}
                }
                reader.consume(offset);
            }
            Err(PcapError::Eof) => break,
            Err(PcapError::Incomplete(_)) => reader.refill().expect("refill"),
            Err(e) => panic!("pcap-parser error: {e:?}"),
        }
    }
    (linktype, out)
}

fn udp_ports(frame: &[u8]) -> (u16, u16) {
    (
        u16::from_be_bytes([frame[34], frame[35]]),
        u16::from_be_bytes([frame[36], frame[37]]),
    )
}

fn sample_payloads() -> Vec<(u64, u16, Vec<u8>)> {
    let mut v = Vec::new();
    for i in 0..5u16 {
        let mut blocks = [FiringBlock::default(); 12];
        for (b, block) in blocks.iter_mut().enumerate() {
            block.azimuth = (i * 200 + b as u16 * 17) % 36000;
            for j in 0..32 {
                block.distances[j] = i * 1000 + (b * 32 + j) as u16;
                block.intensities[j] = (j * 7 + b) as u8;
            }
        }
        let ts = 1_000 + u32::from(i) * 553;
        v.push((
            1_700_000_000_000_000 + u64::from(ts),
            2368,
            encode_data_packet(&blocks, ts, 0x37).to_vec(),
        ));
        if i == 2 {
            v.push((
                1_700_000_000_000_000 + 2_200,
                8308,
                encode_position_packet(2_200).to_vec(),
            ));
        }
    }
    v
}

#[test]
fn classic_pcap_in_all_variants_parses_byte_exact() {
    let input = sample_payloads();
    for byte_order in [ByteOrder::Little, ByteOrder::Big] {
        for resolution in [TimeResolution::Micro, TimeResolution::Nano] {
            let options = PcapOptions {
                byte_order,
                resolution,
            };
            let mut w = PcapWriter::with_options(Vec::new(), options).unwrap();
            for (ts, port, payload) in &input {
                w.write_udp(*ts, *port, *port, payload).unwrap();
            }
            assert_eq!(w.records(), input.len() as u64);
            let bytes = w.into_inner().unwrap();
            let magic = match (byte_order, resolution) {
                (ByteOrder::Little, TimeResolution::Micro) => [0xd4, 0xc3, 0xb2, 0xa1],
                (ByteOrder::Little, TimeResolution::Nano) => [0x4d, 0x3c, 0xb2, 0xa1],
                (ByteOrder::Big, TimeResolution::Micro) => [0xa1, 0xb2, 0xc3, 0xd4],
                (ByteOrder::Big, TimeResolution::Nano) => [0xa1, 0xb2, 0x3c, 0x4d],
            };
            assert_eq!(&bytes[..4], &magic, "{options:?}");
            let (linktype, records) = parse(&bytes);
            assert_eq!(linktype, 1, "{options:?}");
            assert_eq!(records.len(), input.len(), "{options:?}");
            for ((ts, port, payload), (pts, frame)) in input.iter().zip(&records) {
                assert_eq!(pts, ts, "{options:?}");
                assert_eq!(&frame[42..], &payload[..], "{options:?}");
                assert_eq!(udp_ports(frame), (*port, *port));
                assert_eq!(frame.len(), 42 + payload.len());
            }
        }
    }
}

#[test]
fn pcapng_parses_byte_exact() {
    let input = sample_payloads();
    let mut w = PcapNgWriter::new(Vec::new()).unwrap();
    for (ts, port, payload) in &input {
        w.write_udp(*ts, *port, *port, payload).unwrap();
    }
    let bytes = w.into_inner().unwrap();
    assert_eq!(&bytes[..4], &[0x0A, 0x0D, 0x0D, 0x0A]);
    let (linktype, records) = parse(&bytes);
    assert_eq!(linktype, 1);
    assert_eq!(records.len(), input.len());
    for ((ts, port, payload), (pts, frame)) in input.iter().zip(&records) {
        assert_eq!(pts, ts);
        assert_eq!(&frame[42..], &payload[..]);
        assert_eq!(udp_ports(frame).1, *port);
    }
}

#[test]
fn synthesized_capture_parses_and_matches_the_records() {
    let scene = Scene::preset("crossroad").unwrap();
    let options = SynthOptions::default();
    let mut expected: Vec<(u64, u16, Vec<u8>)> = Vec::new();
    let summary = synthesize(&scene, &options, |r, _| {
        expected.push((r.capture_time_us(), r.port(), r.payload().to_vec()));
        Ok(())
    })
    .unwrap();
    let (_, pcap, _) = write_capture(&scene, &options, Vec::new(), Vec::new()).unwrap();
    let (linktype, records) = parse(&pcap);
    assert_eq!(linktype, 1);
    assert_eq!(records.len(), expected.len());
    assert_eq!(records.len() as u32, summary.records);
    assert_eq!(
        summary.records,
        summary.data_packets + summary.position_packets
    );
    let mut data = 0;
    for ((ts, port, payload), (pts, frame)) in expected.iter().zip(&records) {
        assert_eq!(pts, ts);
        assert_eq!(udp_ports(frame), (*port, *port));
        assert_eq!(&frame[42..], &payload[..]);
        // Source address 192.168.1.201, destination broadcast.
        assert_eq!(&frame[26..34], &[192, 168, 1, 201, 255, 255, 255, 255]);
        if *port == 2368 {
            assert_eq!(payload.len(), 1206);
            data += 1;
        } else {
            assert_eq!((*port, payload.len()), (8308, 512));
        }
    }
    assert_eq!(data, summary.data_packets);
    // Timestamps are increasing and data packets are 552.96 µs apart on average.
    assert!(records.windows(2).all(|w| w[0].0 < w[1].0));
}

#[test]
fn first_block_is_at_azimuth_zero_and_rotation_is_full() {
    let scene = Scene::preset("crossroad").unwrap();
    let mut azimuths = Vec::new();
    synthesize(&scene, &SynthOptions::default(), |r, _| {
        if r.port() == 2368 {
            let p = r.payload();
            for b in 0..12 {
                azimuths.push(u16::from_le_bytes([p[b * 100 + 2], p[b * 100 + 3]]));
            }
        }
        Ok(())
    })
    .unwrap();
    assert_eq!(azimuths[0], 0);
    let wraps = azimuths.windows(2).filter(|w| w[1] < w[0]).count();
    // Frames 0..frames-1 are full; the last packet may start rotation `frames`.
    assert!(wraps == scene.frames as usize || wraps == scene.frames as usize - 1);
    // At 20 Hz a block turns 0.3318 degrees: steps of 33 or 34 hundredths.
    for w in azimuths.windows(2) {
        let step = (i32::from(w[1]) - i32::from(w[0])).rem_euclid(36000);
        assert!(step == 33 || step == 34, "step {step}");
    }
}

#[test]
fn same_seed_gives_identical_bytes_and_other_seed_with_noise_differs() {
    let src = "frames = 1\nseed = 7\nrange_noise_m = 0.02\n[sensor]\nheight_m = 1.8\nrotation_hz = 20.0\n[[objects]]\nkind = \"car\"\nx = 8.0\ny = 1.0\nlength_m = 4.0\nwidth_m = 1.8\nheight_m = 1.5\nreflectance = 0.5\n";
    let a = Scene::parse(src, Path::new("a.toml"), "a").unwrap();
    let run = |scene: &Scene| {
        let (_, pcap, labels) =
            write_capture(scene, &SynthOptions::default(), Vec::new(), Vec::new()).unwrap();
        (pcap, labels)
    };
    let first = run(&a);
    let second = run(&a);
    assert!(
        first == second,
        "same scene and seed must give identical bytes"
    );
    let mut b = a.clone();
    b.seed = 8;
    let other = run(&b);
    assert_ne!(
        first.0, other.0,
        "another seed with range noise must differ"
    );
    // Without noise the seed does not matter.
    let mut quiet_a = a.clone();
    quiet_a.range_noise_m = 0.0;
    let mut quiet_b = b.clone();
    quiet_b.range_noise_m = 0.0;
    assert!(run(&quiet_a).0 == run(&quiet_b).0);
}
