//! Frame ranges of long captures as units of a sharded sweep (`--chunk-frames M`).
//!
//! With chunks, a sweep's work units are (cell, chunk j), chunk j being the capture's
//! frames at positions [j*M, (j+1)*M) of those in `--frames`. Each unit writes a part of
//! its cell, `cells/<capture>/.<cell>.chunk<M>-<j>.json`, in the cell file format
//! (atomic rename, checksum, the cell's settings plus the chunk's); the merge (or a plain
//! rerun) joins the parts of a cell in frame order into the cell file a sweep without
//! chunks writes, byte for byte, and deletes them. Baselines are per frame, so a part
//! needs nothing from other frames. The chunk size is in every part's name and settings:
//! a sweep whose `--chunk-frames` differs from the parts found is refused.

use super::run::SweepSettings;
use crate::error::{Error, Result};
use crate::sensor::frames::CaptureSeek;
use crate::sensor::index::{FrameScan, FrameSeek};
use crate::sensor::SensorModel;
use std::ops::RangeInclusive;
use std::path::{Path, PathBuf};

/// The capture's sensor, the frame-index ranges of the chunks of `M` frames of it within
/// `s.frames`, where each chunk's first frame starts (to resume a reader there, see
/// [`crate::sensor::frames::scan_capture`]), and the number of frames; errors when the
/// capture has no frame in range. An HDL-32E capture is scanned without decoding
/// returns, in bounded memory; another sensor's is decoded once.
pub fn chunk_ranges(
    s: &SweepSettings,
    path: &Path,
    frames_per_chunk: u32,
) -> Result<(&'static SensorModel, ChunkRanges)> {
    let (sensor, found) = crate::sensor::frames::scan_capture(path, &s.decoder)?;
    let (ranges, seeks, n) = chunks_of(found, &s.frames, s.decoder.keep_partial, frames_per_chunk)?;
    if n == 0 {
        return Err(Error::Invalid(format!(
            "{}: no frame to process in {} (partial sweeps need --keep-partial)",
            path.display(),
            crate::options::frames_phrase(&s.frames)
        )));
    }
    Ok((sensor, (ranges, seeks, n)))
}

/// Chunks' frame ranges, where each starts, and the number of frames.
pub type ChunkRanges = (Vec<RangeInclusive<u32>>, Vec<CaptureSeek>, usize);

/// Chunks of `m` frames among the frames a reader yields in `frames` (partial sweeps only
/// with `keep_partial`), from a scan: ranges, each chunk's seek point, frame count.
pub fn chunk_plan(
    scan: FrameScan,
    frames: &RangeInclusive<u32>,
    keep_partial: bool,
    m: u32,
) -> Result<(Vec<RangeInclusive<u32>>, Vec<FrameSeek>, usize)> {
    let found = scan.map(|f| f.map(|f| (f.index, f.partial, f.seek)));
    chunks_of(found, frames, keep_partial, m)
}

/// [`chunk_plan`] of any scan: `found` gives each frame's (index, partial, seek) in
/// frame order.
pub fn chunks_of<S>(
    found: impl IntoIterator<Item = Result<(u32, bool, S)>>,
    frames: &RangeInclusive<u32>,
    keep_partial: bool,
    m: u32,
) -> Result<(Vec<RangeInclusive<u32>>, Vec<S>, usize)> {
    let m = m.max(1) as usize;
    let (mut ranges, mut seeks, mut n) = (Vec::new(), Vec::new(), 0usize);
    for found in found {
        let (index, partial, seek) = found?;
        if index > *frames.end() {
            break;
        }
        if !frames.contains(&index) || (partial && !keep_partial) {
            continue;
        }
        if n % m == 0 {
            ranges.push(index..=index);
            seeks.push(seek);
        } else if let Some(last) = ranges.last_mut() {
            *last = *last.start()..=index;
        }
        n += 1;
    }
    Ok((ranges, seeks, n))
}

/// Index of unit (cell, chunk) in the sweep's list of units, which `--shard K/N` deals
/// round-robin: `offset` units come before this capture's, whose cells each have
/// `chunks` chunks. Without chunks (`chunks` 1) this is the cell's index.
pub fn unit_index(offset: usize, cell: usize, chunk: usize, chunks: usize) -> usize {
    offset + cell * chunks + chunk
}

/// File name of part `chunk` of the cell file `cell_file` with chunks of `m` frames.
pub fn part_name(cell_file: &str, m: u32, chunk: usize) -> String {
    let stem = cell_file.strip_suffix(".json").unwrap_or(cell_file);
    format!(".{stem}.chunk{m}-{chunk:05}.json")
}

/// Chunk size of a part file name (None for other names).
pub fn part_chunk_size(name: &str) -> Option<u32> {
    let rest = name.strip_prefix('.')?.strip_suffix(".json")?;
    let (_, tail) = rest.rsplit_once(".chunk")?;
    let (m, j) = tail.split_once('-')?;
    (j.len() >= 5 && j.bytes().all(|b| b.is_ascii_digit())).then_some(())?;
    m.parse().ok()
}

/// Refuses a sweep whose `--chunk-frames` (`m`, None without) differs from the chunk size
/// of a part found in `dir`: joining parts of other ranges would be wrong, and mixing
/// sizes would compute frames twice.
pub fn check_parts(dir: &Path, m: Option<u32>) -> Result<()> {
    if let Some((name, found)) = other_chunk_size(dir, m, part_chunk_size) {
        let given = m.map_or("no --chunk-frames".into(), |m| {
            format!("--chunk-frames {m}")
        });
        return Err(Error::Invalid(format!(
            "{}: a part of a cell computed with --chunk-frames {found}, and this sweep \
             has {given}: give --chunk-frames {found} to every shard, the merge and \
             reruns of this sweep (or delete the parts to start over)",
            dir.join(&name).display()
        )));
    }
    Ok(())
}

/// The first part in `dir` (in name order) whose chunk size, read from its name by
/// `chunk_size_of`, differs from `m` (None: no part may be there), with that size.
pub fn other_chunk_size(
    dir: &Path,
    m: Option<u32>,
    chunk_size_of: impl Fn(&str) -> Option<u32>,
) -> Option<(String, u32)> {
    let entries = std::fs::read_dir(dir).ok()?;
    let mut names: Vec<String> = entries
        .filter_map(|e| e.ok())
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    names.into_iter().find_map(|name| {
        let found = chunk_size_of(&name)?;
        (Some(found) != m).then_some((name, found))
    })
}

/// A part's settings: its cell's or run's, plus the chunk (size, index, count and frame
/// range).
pub fn part_settings(
    whole: &serde_json::Value,
    m: u32,
    j: usize,
    n: usize,
    range: &std::ops::RangeInclusive<u32>,
) -> serde_json::Value {
    let mut v = whole.clone();
    v["chunk"] = serde_json::json!({
        "frames_per_chunk": m,
        "index": j,
        "of": n,
        "frames": [range.start(), range.end()],
    });
    v
}

/// Part paths of a cell, in chunk order.
pub fn part_paths(dir: &Path, cell_file: &str, m: u32, chunks: usize) -> Vec<PathBuf> {
    (0..chunks)
        .map(|j| dir.join(part_name(cell_file, m, j)))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn chunk_plans_cut_the_frames_the_reader_yields() {
        use crate::sensor::frames::{DecoderOptions, FrameReader};
        let path = Path::new("fixtures/crossroad.pcap");
        for keep in [false, true] {
            let opts = DecoderOptions {
                keep_partial: keep,
                ..DecoderOptions::default()
            };
            let read: Vec<u32> = FrameReader::open(path, &opts)
                .unwrap()
                .map(|f| f.unwrap().index)
                .collect();
            for range in [0..=u32::MAX, 1..=1, 0..=0] {
                for m in 1..=3u32 {
                    let scan = FrameScan::open(path, &opts).unwrap();
                    let (ranges, seeks, n) = chunk_plan(scan, &range, keep, m).unwrap();
                    let want: Vec<u32> =
                        read.iter().copied().filter(|i| range.contains(i)).collect();
                    let expected: Vec<RangeInclusive<u32>> = want
                        .chunks(m as usize)
                        .map(|c| c[0]..=c[c.len() - 1])
                        .collect();
                    assert_eq!(n, want.len());
                    assert_eq!(ranges, expected, "keep {keep}, {range:?}, m {m}");
                    let starts: Vec<u32> = seeks.iter().map(|s| s.frame).collect();
                    let first: Vec<u32> = expected.iter().map(|r| *r.start()).collect();
                    assert_eq!(starts, first);
                }
            }
        }
    }

    #[test]
    fn part_names_round_trip_their_chunk_size() {
        let n = part_name("rain.rate_mm_h=3_seed=1-0a1b2c3d.json", 40, 7);
        assert_eq!(n, ".rain.rate_mm_h=3_seed=1-0a1b2c3d.chunk40-00007.json");
        assert_eq!(part_chunk_size(&n), Some(40));
        for other in [
            "rain-0a1b2c3d.json",
            ".rain.json.a1b2.tmp",
            ".x.chunkA-00001.json",
            ".x.chunk4-1.json",
        ] {
            assert_eq!(part_chunk_size(other), None, "{other}");
        }
    }

    #[test]
    fn units_are_dealt_disjointly_and_completely() {
        // Two captures of 3 and 1 chunks, 4 cells each: 16 units.
        let caps = [(4usize, 3usize), (4, 1)];
        for n in 1..=7u32 {
            let mut owner = vec![None; 16];
            for k in 0..n {
                let shard = crate::options::Shard { k, n };
                let mut offset = 0;
                for &(cells, chunks) in &caps {
                    for c in 0..cells {
                        for j in 0..chunks {
                            let i = unit_index(offset, c, j, chunks);
                            if shard.owns(i) {
                                assert!(owner[i].replace(k).is_none(), "unit {i} twice");
                            }
                        }
                    }
                    offset += cells * chunks;
                }
            }
            assert!(owner.iter().all(Option::is_some), "{n}: {owner:?}");
        }
    }
}
