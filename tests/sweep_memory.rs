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
//! the same from run to run. Alone in its binary: no other test allocates meanwhile.

use lidar_noise::hdl32e::frames::DecoderOptions;
use lidar_noise::sweep::outputs::write_outputs;
use lidar_noise::sweep::plan::{BaseConfig, Vary};
use lidar_noise::sweep::run::{run, CaptureInput, Silent, SweepSettings};
use std::alloc::{GlobalAlloc, Layout, System};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering::Relaxed};

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

/// Writes the classic pcap `src` repeated `n` times, record times shifted so that each
/// copy follows the last (payloads unchanged: frames repeat).
fn repeated(src: &Path, n: u32, dst: &Path) {
    let data = std::fs::read(src).unwrap();
    let (header, body) = data.split_at(24);
    let mut records = Vec::new();
    let mut at = 0;
    while at + 16 <= body.len() {
        let len = u32::from_le_bytes(body[at + 8..at + 12].try_into().unwrap()) as usize;
        records.push(&body[at..at + 16 + len]);
        at += 16 + len;
    }
    let secs = |r: &[u8]| u32::from_le_bytes(r[..4].try_into().unwrap());
    let span = secs(records[records.len() - 1]) - secs(records[0]) + 1;
    let mut out = header.to_vec();
    for k in 0..n {
        for r in &records {
            out.extend_from_slice(&(secs(r) + k * span).to_le_bytes());
            out.extend_from_slice(&r[4..]);
        }
    }
    std::fs::write(dst, out).unwrap();
}

/// Peak heap (bytes above those live at the start) of a whole sweep, tables, plots and
/// page included, over `capture`; and the rows it wrote.
fn sweep_peak(capture: PathBuf, out: &Path) -> (usize, usize) {
    let (base, _) = BaseConfig::load(None, &[]).unwrap();
    let varies = vec![Vary::parse("rain.rate_mm_h=0,1,2,3").unwrap()];
    let settings = SweepSettings {
        base,
        varies: varies.clone(),
        seeds: vec![1, 2],
        decoder: DecoderOptions::default(),
        frames: 0..=u32::MAX,
        output: out.to_path_buf(),
        bands: lidar_noise::sweep::metrics::DEFAULT_BANDS.to_vec(),
        chunk_frames: None,
    };
    let captures = vec![CaptureInput {
        name: "c".into(),
        path: capture,
        labels: None,
    }];
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap();
    pool.install(|| {
        let start = LIVE.load(Relaxed);
        PEAK.store(start, Relaxed);
        let outcome = run(&settings, &captures, &Silent).unwrap();
        write_outputs(out, &varies, &["c".into()], &outcome.rows, None, &[], &[]).unwrap();
        let rows = outcome.rows.len();
        drop(outcome);
        (PEAK.load(Relaxed) - start, rows)
    })
}

#[test]
fn sweep_memory_does_not_grow_with_the_capture() {
    let tmp = tempfile::tempdir().unwrap();
    let crossroad = common::fixtures().join("crossroad.pcap");
    let mut peaks = Vec::new();
    for n in [4, 24] {
        let capture = tmp.path().join(format!("c{n}.pcap"));
        repeated(&crossroad, n, &capture);
        let (peak, rows) = sweep_peak(capture, &tmp.path().join(format!("out{n}")));
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
