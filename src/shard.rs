//! Sharded runs and sweeps: how a batch's work is dealt to shards (`--shard K/N`), how a
//! long capture is cut into chunks of frames (`--chunk-frames M`), and the part files a
//! unit of work leaves for the merge.
//!
//! A batch is a list of units in a canonical order: captures for `run`, cells for
//! `sweep`, and with chunks (capture, chunk) or (cell, chunk). Shard K of N owns the units
//! whose index is K modulo N. A unit of a chunked batch writes a part
//! `.<stem>.chunk<M>-<j>.json` (the run's `stem` is `run`, a sweep cell's its cell file's)
//! under a temporary name renamed when complete; the chunk size is in every part's name
//! and settings, so that parts of another `--chunk-frames` are refused, never joined.

use crate::error::{Error, Result};
use crate::sensor::frames::CaptureSeek;
use crate::sensor::index::{FrameScan, FrameSeek};
use crate::sensor::SensorModel;
use std::ops::RangeInclusive;
use std::path::{Path, PathBuf};

/// Shard `k` of `n` (0-based, like Slurm's array task ids): the items whose index is `k`
/// modulo `n` (a round-robin deal, so shards differ by at most one item).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Shard {
    /// This shard, 0..n.
    pub k: u32,
    /// Number of shards.
    pub n: u32,
}

impl Shard {
    /// Parses `K/N` with 0 <= K < N.
    pub fn parse(text: &str) -> std::result::Result<Shard, String> {
        let bad = || {
            format!(
                "{text}: expected K/N with 0 <= K < N, e.g. 0/4 (K counts from 0, like \
                 $SLURM_ARRAY_TASK_ID with --array=0-3)"
            )
        };
        let (k, n) = text.split_once('/').ok_or_else(bad)?;
        let k: u32 = k.trim().parse().map_err(|_| bad())?;
        let n: u32 = n.trim().parse().map_err(|_| bad())?;
        if n == 0 || k >= n {
            return Err(bad());
        }
        Ok(Shard { k, n })
    }

    /// True when item `index` (in the batch's canonical order) falls to this shard.
    pub fn owns(&self, index: usize) -> bool {
        index % self.n as usize == self.k as usize
    }
}

impl std::fmt::Display for Shard {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}/{}", self.k, self.n)
    }
}

/// Index of unit (item, chunk) in a batch's list of units, which shards deal round-robin:
/// `offset` units come before this capture's, whose items (cells) each have `chunks`
/// chunks. Without chunks (`chunks` 1) this is the item's index.
pub fn unit_index(offset: usize, item: usize, chunk: usize, chunks: usize) -> usize {
    offset + item * chunks + chunk
}

/// Chunks' frame ranges, where each starts, and the number of frames.
pub type ChunkRanges = (Vec<RangeInclusive<u32>>, Vec<CaptureSeek>, usize);

/// The sensor of the capture at `path`, and its chunks of `m` frames among those a
/// reader yields in `frames` (partial sweeps only with the decoder's `keep_partial`). An
/// HDL-32E capture is scanned without decoding returns, in bounded memory; another
/// sensor's is decoded once.
pub fn capture_chunks(
    path: &Path,
    decoder: &crate::sensor::frames::DecoderOptions,
    frames: &RangeInclusive<u32>,
    m: u32,
) -> Result<(&'static SensorModel, ChunkRanges)> {
    let (sensor, found) = crate::sensor::frames::scan_capture(path, decoder)?;
    let chunks = chunks_of(found, frames, decoder.keep_partial, m)?;
    Ok((sensor, chunks))
}

/// Chunks of `m` frames among the frames a reader yields in `frames` (partial sweeps only
/// with `keep_partial`), from an HDL-32E frame index: ranges, each chunk's seek point,
/// frame count.
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

/// File name of part `chunk` of `file` (a cell file `X.json`, or `run` for a run's
/// capture folder) with chunks of `m` frames: `.X.chunk<m>-<chunk>.json`.
pub fn part_name(file: &str, m: u32, chunk: usize) -> String {
    let stem = file.strip_suffix(".json").unwrap_or(file);
    format!(".{stem}.chunk{m}-{chunk:05}.json")
}

/// The stem and chunk size of a part file name (None for other names).
pub fn part_of(name: &str) -> Option<(&str, u32)> {
    let rest = name.strip_prefix('.')?.strip_suffix(".json")?;
    let (stem, tail) = rest.rsplit_once(".chunk")?;
    let (m, j) = tail.split_once('-')?;
    (j.len() >= 5 && j.bytes().all(|b| b.is_ascii_digit())).then_some(())?;
    Some((stem, m.parse().ok()?))
}

/// Chunk size of a part file name of any stem (None for other names).
pub fn part_chunk_size(name: &str) -> Option<u32> {
    part_of(name).map(|(_, m)| m)
}

/// Chunk size of a run's part file name (None for other names, a sweep cell's parts
/// included).
pub fn run_part_chunk_size(name: &str) -> Option<u32> {
    part_of(name).and_then(|(stem, m)| (stem == "run").then_some(m))
}

/// Paths of the parts of `file` in `dir`, in chunk order.
pub fn part_paths(dir: &Path, file: &str, m: u32, chunks: usize) -> Vec<PathBuf> {
    (0..chunks)
        .map(|j| dir.join(part_name(file, m, j)))
        .collect()
}

/// A part's settings: its cell's or run's, plus the chunk (size, index, count and frame
/// range).
pub fn part_settings(
    whole: &serde_json::Value,
    m: u32,
    j: usize,
    n: usize,
    range: &RangeInclusive<u32>,
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

/// What kind of batch a folder's parts belong to, for [`check_parts`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Batch {
    /// `run --chunk-frames`: parts of a capture folder.
    Run,
    /// `sweep --chunk-frames`: parts of the cells of a capture.
    Sweep,
}

/// Refuses a batch whose `--chunk-frames` (`m`, None without) differs from the chunk size
/// of a part found in `dir`: joining parts of other ranges would be wrong, and mixing
/// sizes would compute frames twice.
pub fn check_parts(dir: &Path, m: Option<u32>, batch: Batch) -> Result<()> {
    let size_of = match batch {
        Batch::Run => run_part_chunk_size,
        Batch::Sweep => part_chunk_size,
    };
    let Some((name, found)) = other_chunk_size(dir, m, size_of) else {
        return Ok(());
    };
    let path = dir.join(&name);
    let given = m.map_or("no --chunk-frames".into(), |m| {
        format!("--chunk-frames {m}")
    });
    Err(Error::Invalid(match batch {
        Batch::Run => format!(
            "{}: a part of a run computed with --chunk-frames {found}, and this run has \
             {given}: give --chunk-frames {found} to every shard and the merge of this run \
             (or delete the parts to start over)",
            path.display()
        ),
        Batch::Sweep => format!(
            "{}: a part of a cell computed with --chunk-frames {found}, and this sweep has \
             {given}: give --chunk-frames {found} to every shard, the merge and reruns of \
             this sweep (or delete the parts to start over)",
            path.display()
        ),
    }))
}

/// Writes `part` as JSON behind a first line `magic` + the xxh3 checksum of the JSON,
/// under a temporary name renamed when complete.
pub fn write_checked<T: serde::Serialize>(
    path: &Path,
    magic: &str,
    part: &T,
    inputs: &[&Path],
) -> Result<()> {
    let body = serde_json::to_vec(part).map_err(|e| Error::Invalid(format!("internal: {e}")))?;
    let sum = xxhash_rust::xxh3::xxh3_64(&body);
    crate::writers::atomic::write_atomically(path, inputs, |out| {
        out.write_all(format!("{magic}{sum:016x}\n").as_bytes())?;
        out.write_all(&body)
    })?;
    Ok(())
}

/// Reads a file [`write_checked`] wrote: None when absent, Err(why) when it cannot be
/// trusted.
pub fn read_checked<T: serde::de::DeserializeOwned>(
    path: &Path,
    magic: &str,
) -> Option<std::result::Result<T, String>> {
    let bytes = std::fs::read(path).ok()?;
    Some((|| {
        let nl = bytes
            .iter()
            .position(|&b| b == b'\n')
            .ok_or("not a part file")?;
        let head = std::str::from_utf8(&bytes[..nl]).map_err(|_| "not a part file")?;
        let sum = head.strip_prefix(magic).ok_or("not a part file")?;
        let body = &bytes[nl + 1..];
        if format!("{:016x}", xxhash_rust::xxh3::xxh3_64(body)) != sum {
            return Err(
                "the part is incomplete or was changed after it was written \
                        (checksum mismatch)"
                    .to_string(),
            );
        }
        serde_json::from_slice(body).map_err(|e| format!("unreadable part: {e}"))
    })())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shards_parse_and_deal_round_robin() {
        assert_eq!(Shard::parse("2/5").unwrap(), Shard { k: 2, n: 5 });
        for bad in ["5/5", "1/0", "x/2", "1", "-1/3", "1/2/3"] {
            assert!(Shard::parse(bad).is_err(), "{bad}");
        }
        for n in 1..=7u32 {
            for index in 0..50 {
                let owners: Vec<u32> = (0..n).filter(|&k| Shard { k, n }.owns(index)).collect();
                assert_eq!(owners.len(), 1, "item {index} of {n} shards: {owners:?}");
            }
        }
    }

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
        assert_eq!(run_part_chunk_size(&n), None);
        let n = part_name("run", 40, 7);
        assert_eq!(n, ".run.chunk40-00007.json");
        assert_eq!(run_part_chunk_size(&n), Some(40));
        for other in [
            "rain-0a1b2c3d.json",
            ".rain.json.a1b2.tmp",
            ".x.chunkA-00001.json",
            ".x.chunk4-1.json",
            ".run.chunk4-1.json",
            "summary.json",
            "frame_00001.ply",
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
                let shard = Shard { k, n };
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
