//! Labels file: write/read roundtrip and agreement with the synthesized returns.

use lidar_noise::synth::labels::{read_labels, read_labels_file, LabelRow, LabelWriter};
use lidar_noise::synth::{cast_frames, write_capture, Scene, SynthOptions};
use std::path::Path;

#[test]
fn roundtrip_of_arbitrary_rows() {
    let rows: Vec<LabelRow> = (0..5000u32)
        .map(|i| LabelRow {
            frame: i / 1000,
            packet: i / 37 + 3,
            block: (i % 12) as u8,
            laser: (i * 7 % 32) as u8,
            label: (i % 19) as u16,
        })
        .collect();
    let mut w = LabelWriter::new(Vec::new()).unwrap();
    for r in &rows {
        w.write(r).unwrap();
    }
    let bytes = w.finish().unwrap();
    assert_eq!(&bytes[..2], &[0x1f, 0x8b], "gzip magic");
    let back = read_labels(&bytes[..], Path::new("mem")).unwrap();
    assert_eq!(back, rows);
}

#[test]
fn labels_of_a_capture_match_the_cast_returns() {
    let scene = Scene::preset("crossroad").unwrap();
    let options = SynthOptions::default();
    let (summary, pcap, labels) = write_capture(&scene, &options, Vec::new(), Vec::new()).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("x.labels.csv.gz");
    std::fs::write(&path, &labels).unwrap();
    let rows = read_labels_file(&path).unwrap();
    let cast: Vec<LabelRow> = cast_frames(&scene, &options)
        .iter()
        .flatten()
        .map(|r| r.label_row())
        .collect();
    assert_eq!(rows.len() as u64, summary.returns);
    assert_eq!(rows, cast);
    // Capture order: (packet, block, laser) strictly increasing; frames never decrease.
    for w in rows.windows(2) {
        assert!((w[0].packet, w[0].block, w[0].laser) < (w[1].packet, w[1].block, w[1].laser));
        assert!(w[0].frame <= w[1].frame);
    }
    // The fixture (capture + labels + objects) stays under 1 MB.
    let objects = lidar_noise::synth::objects_json(&scene);
    let total = pcap.len() + labels.len() + objects.len();
    assert!(total < 1_000_000, "crossroad fixture is {total} bytes");
}

#[test]
fn truncated_or_garbled_labels_are_refused() {
    let p = Path::new("bad.csv");
    assert!(read_labels(&b""[..], p).is_err());
    assert!(read_labels(&b"frame,packet,block,laser,label\n1,2,3\n"[..], p).is_err());
    assert!(read_labels(&b"frame,packet,block,laser,label\n1,2,3,40,0\n"[..], p).is_err());
}
