//! Frame index: a reader resumed at a scanned frame yields what a reader from the start
//! yields from that frame on (frames, returns, partial flags, record numbers, errors and
//! container counters), on the fixtures, a pcapng copy, a damaged copy and the shared
//! recording.

use lidar_noise::frame::Frame;
use lidar_noise::sensor::frames::{DecoderOptions, FrameReader};
use lidar_noise::sensor::index::{FrameScan, ScannedFrame};
use std::path::{Path, PathBuf};
use std::sync::Arc;

fn options(keep_partial: bool, cut_angle_deg: f64) -> DecoderOptions {
    DecoderOptions {
        keep_partial,
        cut_angle_deg,
        ..DecoderOptions::default()
    }
}

/// Every frame a reader yields from `reader` on, then its error (if any) and its
/// container counters at the end.
fn drain(reader: FrameReader) -> (Vec<Frame>, Option<String>, String) {
    let mut reader = reader;
    let mut frames = Vec::new();
    let mut error = None;
    for f in reader.by_ref() {
        match f {
            Ok(f) => frames.push(f),
            Err(e) => error = Some(e.to_string()),
        }
    }
    let stats = serde_json::to_string(&reader.summary().capture).unwrap();
    (frames, error, stats)
}

fn same_frame(a: &Frame, b: &Frame, what: &str) {
    assert_eq!(a.index, b.index, "{what}");
    assert_eq!(a.partial, b.partial, "{what}: frame {}", a.index);
    assert_eq!(
        a.returns.len(),
        b.returns.len(),
        "{what}: frame {}",
        a.index
    );
    assert!(
        a.returns == b.returns,
        "{what}: frame {} returns differ",
        a.index
    );
}

/// Checks every scanned frame of `path` (resumed at, the rest read to the end); returns
/// the number of frames checked.
fn check_capture(path: &Path, opts: &DecoderOptions, every: usize) -> usize {
    let what = format!("{} (cut {})", path.display(), opts.cut_angle_deg);
    let (full, full_error, full_stats) = drain(FrameReader::open(path, opts).unwrap());
    let scanned: Vec<ScannedFrame> = FrameScan::open(path, opts)
        .unwrap()
        .take_while(Result::is_ok)
        .map(Result::unwrap)
        .collect();
    // The scan finds the reader's frames: every index, with the same partial flags.
    let listed: Vec<(u32, bool)> = scanned
        .iter()
        .filter(|s| opts.keep_partial || !s.partial)
        .map(|s| (s.index, s.partial))
        .collect();
    let read: Vec<(u32, bool)> = full.iter().map(|f| (f.index, f.partial)).collect();
    if full_error.is_none() {
        assert_eq!(listed, read, "{what}: scanned frames");
    } else {
        // The reader stops at the damage with the frame in progress; the scan too.
        assert!(
            read.starts_with(&listed[..listed.len().min(read.len())]),
            "{what}"
        );
    }
    let mut checked = 0;
    for s in scanned.iter().step_by(every.max(1)) {
        let Some(at) = full.iter().position(|f| f.index >= s.index) else {
            continue;
        };
        let (resumed, error, stats) = drain(FrameReader::open_at(path, opts, &s.seek).unwrap());
        assert_eq!(
            resumed.len(),
            full.len() - at,
            "{what}: resumed at {}",
            s.index
        );
        for (a, b) in resumed.iter().zip(&full[at..]) {
            same_frame(a, b, &format!("{what}: resumed at {}", s.index));
        }
        assert_eq!(error, full_error, "{what}: resumed at {}", s.index);
        assert_eq!(stats, full_stats, "{what}: resumed at {}", s.index);
        checked += 1;
    }
    checked
}

fn temp(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("lidar-noise-frame-index-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

#[test]
fn resuming_at_each_fixture_frame_equals_decoding_from_the_start() {
    for name in ["crossroad", "parking", "empty"] {
        let path = PathBuf::from(format!("fixtures/{name}.pcap"));
        for (keep, cut) in [(false, 0.0), (true, 0.0), (true, 137.5)] {
            let n = check_capture(&path, &options(keep, cut), 1);
            assert!(n >= 1, "{name}: no frame checked");
        }
    }
}

#[test]
fn resuming_works_in_pcapng_and_keeps_record_numbers_in_errors() {
    let bytes = std::fs::read("fixtures/crossroad.pcap").unwrap();
    // The same records as pcapng (section header, interface, enhanced packets).
    let mut out = Vec::new();
    {
        let mut w = lidar_noise::capture::writer::PcapNgWriter::new(&mut out).unwrap();
        let mut r = lidar_noise::capture::CaptureReader::open(Path::new("fixtures/crossroad.pcap"))
            .unwrap();
        while let Some(d) = r.next_datagram().unwrap() {
            w.write_udp(d.ts_ns / 1000, d.src_port, d.dst_port, d.payload)
                .unwrap();
        }
        w.into_inner().unwrap();
    }
    let ng = temp("crossroad.pcapng");
    std::fs::write(&ng, &out).unwrap();
    assert!(check_capture(&ng, &options(true, 0.0), 1) >= 2);

    // A record near the end claims a huge length: the capture is corrupt from there,
    // and the resumed reader names the same record and byte offset.
    let mut damaged = bytes.clone();
    let mut at = 24;
    let mut records = Vec::new();
    while at + 16 <= damaged.len() {
        records.push(at);
        let caplen = u32::from_le_bytes(damaged[at + 8..at + 12].try_into().unwrap()) as usize;
        at += 16 + caplen;
    }
    let victim = records[records.len() * 9 / 10];
    damaged[victim + 8..victim + 12].copy_from_slice(&0x7fff_0000u32.to_le_bytes());
    damaged[victim + 12..victim + 16].copy_from_slice(&0x7fff_0000u32.to_le_bytes());
    let bad = temp("damaged.pcap");
    std::fs::write(&bad, &damaged).unwrap();
    let (_, error, _) = drain(FrameReader::open(&bad, &options(true, 0.0)).unwrap());
    let error = error.expect("the damaged capture fails");
    assert!(error.contains(&format!("byte offset {victim}")), "{error}");
    assert!(check_capture(&bad, &options(true, 0.0), 1) >= 1);

    // Cut mid-record: the resumed reader reports the same truncation offset.
    let cut = temp("cut.pcap");
    std::fs::write(&cut, &bytes[..bytes.len() - 500]).unwrap();
    assert!(check_capture(&cut, &options(true, 0.0), 1) >= 1);

    // From memory, as the built-in capture is read.
    let opts = options(false, 0.0);
    let arc: Arc<[u8]> = Arc::from(bytes);
    let name = Path::new("mem.pcap");
    let scanned: Vec<ScannedFrame> = FrameScan::from_bytes(arc.clone(), name, &opts)
        .unwrap()
        .map(Result::unwrap)
        .filter(|s| !s.partial)
        .collect();
    let full: Vec<Frame> = FrameReader::from_bytes(arc.clone(), name, &opts)
        .unwrap()
        .map(Result::unwrap)
        .collect();
    let last = scanned.last().unwrap();
    let mut resumed = FrameReader::from_bytes_at(arc, name, &opts, &last.seek).unwrap();
    same_frame(
        &resumed.next().unwrap().unwrap(),
        full.last().unwrap(),
        "from memory",
    );
    std::fs::remove_dir_all(ng.parent().unwrap()).ok();
}

#[test]
fn resuming_at_frames_of_the_shared_recording_equals_decoding_from_the_start() {
    let path = Path::new("../shared/data/hdl32e/monterey.pcap");
    if !path.exists() {
        println!("SKIPPED: {} is absent", path.display());
        return;
    }
    // Every third frame resumed at, the rest of the capture compared each time.
    let n = check_capture(path, &options(true, 0.0), 3);
    assert!(n >= 5, "{n} frames checked");
    check_capture(path, &options(false, 200.0), 5);
}
