//! `synth --sensor NAME` (issue 31): a synthesized capture of every described sensor is
//! a pcap that identification by structure names as that sensor, and that its decoder
//! reads back into exactly the cast returns (laser ids over the sensor's whole beam
//! table, raw distances, intensities, positions where the ray hit); the labels file
//! keys every return. The HDL-32E default keeps its bytes (tests/integration/synth_capture.rs and
//! the fixtures).

use lidar_noise::capture::CaptureReader;
use lidar_noise::sensor::decode::{DualSelect, ModelDecoder};
use lidar_noise::sensor::identify::identify;
use lidar_noise::sensor::{by_name, MODELS};
use lidar_noise::synth::raycast::Caster;
use lidar_noise::synth::SynthOptions;
use lidar_noise::synth::{labels, synthesize, write_capture, CastReturn, Record, Scene};
use std::path::Path;

/// Data payloads with capture times (ns), and the cast returns, of a synthesis.
fn run(scene: &Scene, options: &SynthOptions) -> (Vec<(Vec<u8>, u64)>, Vec<CastReturn>) {
    let mut packets = Vec::new();
    let mut cast = Vec::new();
    synthesize(scene, options, |record, returns| {
        if let Record::Data { .. } = record {
            packets.push((record.payload().to_vec(), record.capture_time_us() * 1000));
        }
        cast.extend_from_slice(returns);
        Ok(())
    })
    .unwrap();
    (packets, cast)
}

#[test]
fn every_sensor_synthesizes_a_capture_identified_and_decoded_as_itself() {
    let mut scene = Scene::preset("crossroad").unwrap();
    scene.frames = 1;
    // The preset turns at 20 Hz; the HDL-64E turns at 5 to 15 Hz.
    scene.sensor.rotation_hz = 10.0;
    for model in MODELS.iter().skip(1) {
        let options = SynthOptions {
            sensor: model,
            ..SynthOptions::default()
        };
        let (packets, cast) = run(&scene, &options);
        let refs: Vec<(&[u8], u64)> = packets.iter().map(|(p, t)| (p.as_slice(), *t)).collect();
        let id = identify(&refs).unwrap_or_else(|e| panic!("{}: {e}", model.name));
        assert_eq!(
            (id.model.name, id.product_byte_agrees),
            (model.name, true),
            "{}",
            id.note
        );
        assert!(
            (id.rotation_hz - scene.sensor.rotation_hz).abs() < 0.2,
            "{}",
            model.name
        );
        let dec = ModelDecoder::new(model, true, DualSelect::Both).with_vertical_offsets(false);
        let mut out = Vec::new();
        for (i, (p, _)) in packets.iter().enumerate() {
            dec.decode_packet(p, i as u32, 0.0, &mut out).unwrap();
        }
        assert_eq!(out.len(), cast.len(), "{}", model.name);
        assert!(out.len() > 5_000, "{}: {} returns", model.name, out.len());
        let mut lasers = vec![false; model.lasers];
        for (r, c) in out.iter().zip(&cast) {
            assert_eq!(
                (r.packet, r.block, r.laser, r.raw_distance, r.intensity),
                (c.packet, c.block, c.laser, c.raw_distance, c.intensity),
                "{}",
                model.name
            );
            lasers[usize::from(r.laser)] = true;
        }
        // Every laser aimed at the ground within 100 m returns: laser ids span the
        // sensor's whole table (16, 32, 64 or 128 lasers).
        for (k, &seen) in lasers.iter().enumerate() {
            if model.elevation_deg[k] < -2.0 {
                assert!(seen, "{}: laser {k} has no return", model.name);
            }
        }
        assert!(lasers[model.lasers - 1] || model.elevation_deg[model.lasers - 1] > -2.0);
        // Casting each decoded return's laser again at its decoded azimuth (minus the
        // laser's offset, which the caster adds) hits at its decoded range: the firing
        // timing and azimuths the synthesizer casts with are those the decoder reads.
        // (Azimuth steps of a packet's last firing are the decoder's estimate, and a
        // ray grazing an edge may hit another surface: a few per mille may differ.)
        let caster = Caster::with_angles(&scene, model.elevation_deg, model.azimuth_offset_deg);
        let off = out
            .iter()
            .filter(|r| {
                let k = usize::from(r.laser);
                let az = f64::from(r.azimuth) - model.azimuth_offset_deg[k];
                let again = caster.cast(az, k).map_or(0.0, |h| h.range);
                (again - f64::from(r.range)).abs() > 0.02
            })
            .count();
        assert!(
            off * 200 < out.len(),
            "{}: {off} of {} returns not where the ray hits",
            model.name,
            out.len()
        );
    }
}

#[test]
fn sensor_captures_are_pcaps_with_labels_and_names_are_checked() {
    let mut scene = Scene::preset("parking").unwrap();
    scene.frames = 1;
    let options = SynthOptions {
        sensor: by_name("vls128").unwrap(),
        ..SynthOptions::default()
    };
    let (summary, pcap, label_bytes) =
        write_capture(&scene, &options, Vec::new(), Vec::new()).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("vls.pcap");
    std::fs::write(&path, &pcap).unwrap();
    let mut reader = CaptureReader::open(&path).unwrap();
    let mut n = 0;
    while let Some(d) = reader.next_datagram().unwrap() {
        assert_eq!((d.payload.len(), d.payload[1205]), (1206, 0xA1));
        n += 1;
    }
    assert_eq!(n, summary.data_packets);
    let rows = labels::read_labels(&label_bytes[..], Path::new("vls.labels.csv.gz")).unwrap();
    assert_eq!(rows.len() as u64, summary.returns);
    assert!(rows.iter().any(|r| r.laser >= 96), "bank 3 lasers labelled");
    // 20 Hz is more than an HDL-64E turns: refused, with both rates.
    scene.sensor.rotation_hz = 20.0;
    let hdl64 = SynthOptions {
        sensor: by_name("hdl64e s2").unwrap(),
        ..SynthOptions::default()
    };
    let Err(e) = write_capture(&scene, &hdl64, Vec::new(), Vec::new()) else {
        panic!("an HDL-64E turning at 20 Hz was synthesized");
    };
    assert!(
        e.to_string().contains("20 Hz") && e.to_string().contains("5 to 15 Hz"),
        "{e}"
    );
    let e = by_name("VLP-64").unwrap_err();
    assert!(
        e.contains("unknown sensor 'VLP-64'") && e.contains("VLS-128"),
        "{e}"
    );
}
