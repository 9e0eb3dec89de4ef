//! Synthesized captures decode back to the ray-cast returns, and their labels line up.

use crate::common;

use lidar_noise::sensor::frames::{DecoderOptions, FrameReader};
use lidar_noise::synth::{cast_frames, labels, write_capture, Scene, SynthOptions};
use std::path::Path;
use std::sync::Arc;

fn synthesize(scene: &Scene) -> (Vec<u8>, Vec<u8>) {
    let (_, pcap, labels) =
        write_capture(scene, &SynthOptions::default(), Vec::new(), Vec::new()).unwrap();
    (pcap, labels)
}

fn decode(pcap: Vec<u8>) -> Vec<lidar_noise::frame::Frame> {
    FrameReader::from_bytes(
        Arc::from(pcap),
        Path::new("synth.pcap"),
        &DecoderOptions::default(),
    )
    .unwrap()
    .collect::<Result<_, _>>()
    .unwrap()
}

#[test]
fn decoding_a_synthesized_capture_reproduces_the_cast_returns() {
    for preset in ["crossroad", "parking", "empty"] {
        let scene = Scene::preset(preset).unwrap();
        let cast = cast_frames(&scene, &SynthOptions::default());
        let (pcap, _) = synthesize(&scene);
        let frames = decode(pcap);
        assert_eq!(frames.len(), scene.frames as usize, "{preset}: full frames");
        for (frame, expected) in frames.iter().zip(&cast) {
            assert_eq!(frame.index, expected[0].frame, "{preset}");
            let mut per_laser = [0usize; 32];
            let mut expected_per_laser = [0usize; 32];
            frame
                .returns
                .iter()
                .for_each(|r| per_laser[r.laser as usize] += 1);
            expected
                .iter()
                .for_each(|c| expected_per_laser[c.laser as usize] += 1);
            assert_eq!(
                per_laser, expected_per_laser,
                "{preset} frame {}: returns per laser",
                frame.index
            );
            for (r, c) in frame.returns.iter().zip(expected) {
                assert_eq!(
                    (r.packet, r.block, r.laser),
                    (c.packet, c.block, c.laser),
                    "{preset}: order"
                );
                assert_eq!(r.intensity, c.intensity);
                let cast_range = f64::from(c.raw_distance) * 0.002;
                assert!(
                    (f64::from(r.range) - cast_range).abs() <= 0.002,
                    "{preset}: range {} vs {cast_range}",
                    r.range
                );
            }
        }
    }
}

#[test]
fn labels_line_up_with_the_decoded_returns_one_to_one() {
    let scene = Scene::preset("crossroad").unwrap();
    let (pcap, label_bytes) = synthesize(&scene);
    let rows = labels::read_labels(&label_bytes[..], Path::new("mem.labels")).unwrap();
    let frames = decode(pcap);
    let decoded = frames.iter().map(|f| f.returns.len()).sum::<usize>();
    assert_eq!(rows.len(), decoded);
    let keys: Vec<(u32, u32, u8)> = frames
        .iter()
        .flat_map(|f| {
            labels::frame_keys(f)
                .into_iter()
                .map(move |(firing, laser)| (f.index, firing, laser))
        })
        .collect();
    for (row, key) in rows.iter().zip(&keys) {
        assert_eq!((row.frame, row.firing, row.laser), *key);
    }
    for f in &frames {
        let of_frame: Vec<_> = rows
            .iter()
            .filter(|r| r.frame == f.index)
            .copied()
            .collect();
        labels::check_frame(&of_frame, f, Path::new("mem.labels")).unwrap();
    }
    let objects = rows.iter().filter(|r| r.label > 0).count();
    let ground = rows.iter().filter(|r| r.label == 0).count();
    assert!(
        objects > 1000 && ground > 1000,
        "{objects} object and {ground} ground returns"
    );
}

/// The committed fixtures are exactly what the synthesizer writes today; after a
/// deliberate change, regenerate them with scripts/dev/make-fixtures.sh and review the diff.
#[test]
fn committed_fixtures_match_the_synthesizer() {
    for preset in ["crossroad", "parking", "empty"] {
        let dir = common::fixtures();
        let (pcap, label_bytes) = synthesize(&Scene::preset(preset).unwrap());
        let committed = std::fs::read(dir.join(format!("{preset}.pcap"))).unwrap();
        assert!(
            committed == pcap,
            "fixtures/{preset}.pcap is stale: run scripts/dev/make-fixtures.sh and review"
        );
        let committed_rows =
            labels::read_labels_file(&dir.join(format!("{preset}.labels.{}", labels::EXTENSION)))
                .unwrap();
        let rows = labels::read_labels(&label_bytes[..], Path::new("mem")).unwrap();
        assert!(committed_rows == rows, "fixtures/{preset} labels are stale");
        // And in the current format (the reader also converts the former one).
        let mut text = String::new();
        std::io::Read::read_to_string(
            &mut flate2::read::GzDecoder::new(
                &std::fs::read(dir.join(format!("{preset}.labels.{}", labels::EXTENSION))).unwrap()
                    [..],
            ),
            &mut text,
        )
        .unwrap();
        assert!(
            text.starts_with(labels::HEADER),
            "fixtures/{preset} labels are in an old format"
        );
    }
}

#[test]
fn fixtures_stay_small() {
    let total: u64 = std::fs::read_dir(common::fixtures())
        .unwrap()
        .map(|e| e.unwrap().metadata().unwrap().len())
        .sum();
    assert!(total < 2 * 1024 * 1024, "fixtures take {total} bytes");
    let crossroad: u64 = [
        "crossroad.pcap",
        "crossroad.labels.csv.gz",
        "crossroad.objects.json",
    ]
    .iter()
    .map(|f| std::fs::metadata(common::fixtures().join(f)).unwrap().len())
    .sum();
    assert!(crossroad < 1024 * 1024);
}
