//! A sweep's memory does not grow with the length of its capture (issue 30: peak RSS
//! 65 / 69 / 77 MB at 1x / 10x / 30x a capture, while `run` stays flat).
//!
//! The heap is counted by this test binary's allocator (bytes live, and their highest
//! value), not timed: the same sweep over the crossroad fixture repeated 4 and 24 times
//! (8 and 48 frames, 8 cells) must reach the same peak within a margin far below what
//! the per-frame rows of the longer capture take: where every row was held in memory
//! (each cell's frames until the cell was done, then all of them for the tables) the
//! peak grew by 284,805 bytes (about 890 bytes a row) from 4x to 24x; streamed, by
//! nothing (24,850,844 and 24,850,729 bytes). One worker thread makes the allocations
//! the same from run to run. The tests of this binary run one at a time ([`SERIAL`]):
//! no other test allocates meanwhile.
//!
//! Why a test binary of its own, beside `tests/integration/`: its counting allocator is
//! the process's global allocator and its counts are process-wide, so in the shared
//! binary every other test's allocations would count too. It shares `common/` by path.

use lidar_noise::observe::Silent;
use lidar_noise::sensor::frames::DecoderOptions;
use lidar_noise::sweep::outputs::write_outputs;
use lidar_noise::sweep::plan::{BaseConfig, Vary};
use lidar_noise::sweep::run::{run, CaptureInput, SweepSettings};
use std::alloc::{GlobalAlloc, Layout, System};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering::Relaxed};

#[path = "../integration/common/mod.rs"]
mod common;

/// The system allocator, counting the bytes live and their peak.
struct Counting;

static LIVE: AtomicUsize = AtomicUsize::new(0);
static PEAK: AtomicUsize = AtomicUsize::new(0);

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        // SAFETY: forwarded as given.
        let p = unsafe { System.alloc(layout) };
        if !p.is_null() {
            let now = LIVE.fetch_add(layout.size(), Relaxed) + layout.size();
            PEAK.fetch_max(now, Relaxed);
        }
        p
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: forwarded as given.
        unsafe { System.dealloc(ptr, layout) };
        LIVE.fetch_sub(layout.size(), Relaxed);
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        // SAFETY: forwarded as given.
        let p = unsafe { System.realloc(ptr, layout, new_size) };
        if !p.is_null() {
            if new_size >= layout.size() {
                let now =
                    LIVE.fetch_add(new_size - layout.size(), Relaxed) + new_size - layout.size();
                PEAK.fetch_max(now, Relaxed);
            } else {
                LIVE.fetch_sub(layout.size() - new_size, Relaxed);
            }
        }
        p
    }
}

#[global_allocator]
static ALLOCATOR: Counting = Counting;

/// Held by each test: the counts are process-wide.
static SERIAL: std::sync::Mutex<()> = std::sync::Mutex::new(());

/// Peak heap (bytes above those live at the start) of a whole sweep, tables, plots and
/// page included, over `capture`; and the rows it wrote.
fn sweep_peak(capture: PathBuf, labels: Option<PathBuf>, out: &Path) -> (usize, usize) {
    let (base, _) = BaseConfig::load(None, &[]).unwrap();
    let varies = vec![Vary::parse("rain.rate_mm_h=0,1,2,3").unwrap()];
    let settings = SweepSettings {
        base,
        varies: varies.clone(),
        seeds: vec![1, 2],
        decoder: DecoderOptions::default(),
        frames: 0..=u32::MAX,
        output: out.to_path_buf(),
        bands: lidar_noise::score::metrics::DEFAULT_BANDS.to_vec(),
        chunk_frames: None,
    };
    let captures = vec![CaptureInput {
        name: "c".into(),
        path: capture,
        labels,
    }];
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap();
    pool.install(|| {
        let start = LIVE.load(Relaxed);
        PEAK.store(start, Relaxed);
        let outcome = run(&settings, &captures, &Silent).unwrap();
        write_outputs(
            out,
            &varies,
            &["c".into()],
            &outcome.rows,
            None,
            &[],
            &[],
            lidar_noise::writers::figure::FigureFormat::Png,
        )
        .unwrap();
        let rows = outcome.rows.len();
        drop(outcome);
        (PEAK.load(Relaxed) - start, rows)
    })
}

#[test]
fn sweep_memory_does_not_grow_with_the_capture() {
    let _alone = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let tmp = tempfile::tempdir().unwrap();
    let crossroad = common::fixtures().join("crossroad.pcap");
    let mut peaks = Vec::new();
    for n in [4, 24] {
        let capture = tmp.path().join(format!("c{n}.pcap"));
        common::repeated(&crossroad, n, &capture);
        let (peak, rows) = sweep_peak(capture, None, &tmp.path().join(format!("out{n}")));
        eprintln!("{n}x: {rows} rows, peak heap {peak} bytes");
        peaks.push((peak, rows));
    }
    let [(short, short_rows), (long, long_rows)] = peaks[..] else {
        unreachable!()
    };
    assert_eq!(
        long_rows,
        6 * short_rows,
        "{short_rows} and {long_rows} rows"
    );
    // Rows held in memory take about 890 bytes each: 18 rows' worth, 16 KiB, is far
    // below the 320 more rows of the longer capture (285 KB).
    let growth = long.saturating_sub(short);
    assert!(
        growth < 16 << 10,
        "peak heap {short} bytes at 4x, {long} bytes at 24x: {growth} bytes more for {} \
         more rows",
        long_rows - short_rows
    );
}

/// The same with ground-truth labels (a synthesized capture of 4 and 24 rotations): the
/// labels file was read whole, 12 bytes and more per labelled return; now each pass over
/// the capture reads it again a frame at a time.
#[test]
fn labelled_sweep_memory_does_not_grow_with_the_capture() {
    let _alone = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let tmp = tempfile::tempdir().unwrap();
    let mut peaks = Vec::new();
    for n in [4, 24] {
        let dir = tmp.path().join(format!("syn{n}"));
        let o = assert_cmd::Command::cargo_bin("lidar-noise")
            .unwrap()
            .args(["--quiet", "synth", "--preset", "crossroad", "--rotations"])
            .arg(n.to_string())
            .arg("-o")
            .arg(&dir)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let labels = dir.join("crossroad.labels.csv.gz");
        let (peak, rows) = sweep_peak(
            dir.join("crossroad.pcap"),
            Some(labels),
            &tmp.path().join(format!("out{n}")),
        );
        eprintln!("{n} rotations: {rows} rows, peak heap {peak} bytes");
        peaks.push((peak, rows));
    }
    let [(short, short_rows), (long, long_rows)] = peaks[..] else {
        unreachable!()
    };
    assert!(
        long_rows > 5 * short_rows,
        "{short_rows} and {long_rows} rows"
    );
    let growth = long.saturating_sub(short);
    assert!(
        growth < 16 << 10,
        "peak heap {short} bytes at 4 rotations, {long} bytes at 24: {growth} bytes more"
    );
}

/// Labels are read a frame at a time only when the file is in frame order; a file whose
/// frames come in another order is grouped whole as before, with the same results.
#[test]
fn labels_out_of_frame_order_give_the_same_results() {
    use std::io::Read;
    let _alone = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let tmp = tempfile::tempdir().unwrap();
    let fixtures = common::fixtures();
    let mut text = String::new();
    flate2::read::MultiGzDecoder::new(
        std::fs::File::open(fixtures.join("crossroad.labels.csv.gz")).unwrap(),
    )
    .read_to_string(&mut text)
    .unwrap();
    let mut lines = text.lines();
    let header = lines.next().unwrap();
    let rows: Vec<&str> = lines.collect();
    // Frames last to first, each frame's rows in their order.
    let mut frames: Vec<&str> = rows.iter().map(|r| r.split(',').next().unwrap()).collect();
    frames.dedup();
    assert!(frames.len() >= 2, "{frames:?}");
    let mut reordered = vec![header];
    for f in frames.iter().rev() {
        reordered.extend(rows.iter().filter(|r| r.split(',').next() == Some(f)));
    }
    let shuffled = tmp.path().join("shuffled.labels.csv");
    std::fs::write(&shuffled, reordered.join("\n") + "\n").unwrap();
    // The object kinds are read beside the labels.
    std::fs::copy(
        fixtures.join("crossroad.objects.json"),
        tmp.path().join("shuffled.objects.json"),
    )
    .unwrap();
    let mut tables = Vec::new();
    for (name, labels) in [
        ("in-order", fixtures.join("crossroad.labels.csv.gz")),
        ("shuffled", shuffled),
    ] {
        let out = tmp.path().join(name);
        let o = assert_cmd::Command::cargo_bin("lidar-noise")
            .unwrap()
            .args(["--quiet", "sweep"])
            .arg(fixtures.join("crossroad.pcap"))
            .args(["--vary", "rain.rate_mm_h=0,3", "--labels"])
            .arg(&labels)
            .arg("-o")
            .arg(&out)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let csv = std::fs::read_to_string(out.join("aggregate.csv")).unwrap();
        assert!(csv.contains("detected_share_"), "labels not used: {csv}");
        tables.push(csv);
    }
    assert_eq!(tables[0], tables[1]);
}
