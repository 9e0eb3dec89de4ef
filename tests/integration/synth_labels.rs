//! Labels file: write/read roundtrip and agreement with the synthesized returns.

use lidar_noise::frame::{Frame, Return, ReturnKind};
use lidar_noise::synth::labels::{
    check_frame, read_labels, read_labels_file, LabelRow, LabelWriter,
};
use lidar_noise::synth::{cast_frames, label_rows, write_capture, Scene, SynthOptions};
use std::path::Path;

#[test]
fn roundtrip_of_arbitrary_rows() {
    let rows: Vec<LabelRow> = (0..5000u32)
        .map(|i| LabelRow {
            frame: i / 1000,
            firing: i % 1000 / 20,
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
    let cast = label_rows(cast_frames(&scene, &options).iter().flatten());
    assert_eq!(rows.len() as u64, summary.returns);
    assert_eq!(rows, cast);
    // Capture order: (frame, firing, laser) strictly increasing; firings restart at 0
    // in each frame and grow by at most one.
    for w in rows.windows(2) {
        assert!((w[0].frame, w[0].firing, w[0].laser) < (w[1].frame, w[1].firing, w[1].laser));
        if w[0].frame == w[1].frame {
            assert!(w[1].firing - w[0].firing <= 1);
        } else {
            assert_eq!(w[1].firing, 0);
        }
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
    assert!(read_labels(&b"frame,firing,laser,label\n1,2\n"[..], p).is_err());
    // Laser ids reach 127 (VLS-128 captures); 128 is refused.
    assert!(read_labels(&b"frame,firing,laser,label\n1,2,128,0\n"[..], p).is_err());
    assert!(read_labels(&b"frame,packet,block,laser,label\n1,2,3\n"[..], p).is_err());
    let err = read_labels(&b"frame,firing,laser,label\n1,2,3\n"[..], p)
        .unwrap_err()
        .to_string();
    assert!(err.contains("bad.csv") && err.contains("line 2"), "{err}");
}

fn ret(packet: u32, block: u8, laser: u8) -> Return {
    Return {
        x: 1.0,
        y: 0.0,
        z: 0.0,
        range: 1.0,
        azimuth: 0.0,
        elevation: 0.0,
        time: 0.0,
        packet,
        raw_distance: 500,
        intensity: 10,
        laser,
        ring: 0,
        block,
        kind: ReturnKind::Strongest,
    }
}

#[test]
fn keys_survive_renumbered_records_and_mismatches_say_where() {
    // Frame 3: firings (7, 11) -> 0, (8, 0) -> 1; a re-encoded capture numbers the same
    // firings (20, 5) and (22, 1): the keys and so the labels are the same.
    let rows = vec![
        LabelRow {
            frame: 3,
            firing: 0,
            laser: 0,
            label: 0,
        },
        LabelRow {
            frame: 3,
            firing: 0,
            laser: 4,
            label: 2,
        },
        LabelRow {
            frame: 3,
            firing: 1,
            laser: 4,
            label: 2,
        },
    ];
    let frame = |returns: Vec<Return>| Frame {
        index: 3,
        partial: false,
        returns,
    };
    let p = std::path::Path::new("x.labels.csv.gz");
    let a = frame(vec![ret(7, 11, 0), ret(7, 11, 4), ret(8, 0, 4)]);
    let b = frame(vec![ret(20, 5, 0), ret(20, 5, 4), ret(22, 1, 4)]);
    check_frame(&rows, &a, p).unwrap();
    check_frame(&rows, &b, p).unwrap();
    // A different laser in the second firing: the message names the frame, the return
    // and both keys.
    let c = frame(vec![ret(7, 11, 0), ret(7, 11, 4), ret(8, 0, 5)]);
    let err = check_frame(&rows, &c, p).unwrap_err().to_string();
    assert!(
        err.contains("x.labels.csv.gz") && err.contains("frame 3"),
        "{err}"
    );
    assert!(
        err.contains("return 2")
            && err.contains("expected firing 1 laser 5")
            && err.contains("found firing 1 laser 4"),
        "{err}"
    );
    // A missing return: the counts.
    let d = frame(vec![ret(7, 11, 0), ret(7, 11, 4)]);
    let err = check_frame(&rows, &d, p).unwrap_err().to_string();
    assert!(err.contains("3 label rows but 2 decoded returns"), "{err}");
}
