//! Sharded sweeps and runs (issue 14): `--shard K/N` partitions the cells (and `run`'s
//! captures) disjointly and completely, and the shards' cells merged give the very bytes
//! of the single-machine sweep, whatever the order of the shards or how often they ran.
//!
//! Folders are compared file by file over every file, hidden ones included (the lock
//! file and the manifest `.lidar-noise.json`); nothing is excluded: the outputs hold no
//! timing.

use crate::common;

use crate::common::bin2 as bin;
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::process::Output;

/// A small sweep: two captures x two rates x two seeds = 8 cells.
fn sweep(out: &Path, extra: &[&str]) -> Output {
    bin()
        .arg("sweep")
        .arg(common::fixtures().join("crossroad.pcap"))
        .arg(common::fixtures().join("parking.pcap"))
        .args([
            "--vary",
            "rain.rate_mm_h=0,3",
            "--seeds",
            "1..2",
            "--frames",
            "0",
            "-o",
        ])
        .arg(out)
        .args(extra)
        .output()
        .unwrap()
}

fn ok(o: Output) -> String {
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    assert!(o.status.success(), "{err}");
    err
}

fn cells(dir: &Path) -> BTreeSet<PathBuf> {
    common::files(dir)
        .into_keys()
        .filter(|p| p.starts_with("cells"))
        .collect()
}

fn single(tmp: &Path) -> (PathBuf, BTreeMap<PathBuf, Vec<u8>>) {
    let dir = tmp.join("single");
    ok(sweep(&dir, &[]));
    let files = common::files(&dir);
    (dir, files)
}

#[test]
fn shards_are_disjoint_and_cover_every_cell_for_1_to_7() {
    let tmp = tempfile::tempdir().unwrap();
    let (dir, _) = single(tmp.path());
    let all = cells(&dir);
    assert_eq!(all.len(), 8, "{all:?}");
    for n in 1..=7 {
        let mut union = BTreeSet::new();
        for k in 0..n {
            let out = tmp.path().join(format!("n{n}k{k}"));
            let msg = ok(sweep(&out, &["--shard", &format!("{k}/{n}")]));
            assert!(msg.contains("writes no tables"), "{msg}");
            assert!(!out.join("sweep.csv").exists() && !out.join("index.html").exists());
            let mine = cells(&out);
            assert!(
                mine.len() == 8 / n || mine.len() == 8 / n + 1,
                "shard {k}/{n}: {} cells, not a fair share",
                mine.len()
            );
            for c in &mine {
                assert!(union.insert(c.clone()), "{c:?} falls to two shards of {n}");
            }
        }
        assert_eq!(union, all, "the shards of {n} do not cover the sweep");
    }
}

#[test]
fn sharded_then_merged_equals_the_single_run_in_any_order_or_repeated() {
    let tmp = tempfile::tempdir().unwrap();
    let (_, expected) = single(tmp.path());

    // In order, then merged.
    let a = tmp.path().join("a");
    for k in 0..3 {
        ok(sweep(&a, &["--shard", &format!("{k}/3")]));
    }
    ok(sweep(&a, &["--merge"]));
    assert_eq!(common::files(&a), expected);

    // Reverse order, a shard twice, and a plain rerun in place of --merge.
    let b = tmp.path().join("b");
    for k in [3, 2, 1, 0, 2] {
        ok(sweep(&b, &["--shard", &format!("{k}/4")]));
    }
    let msg = ok(sweep(&b, &[]));
    assert!(msg.contains("0 cells computed, 8 loaded"), "{msg}");
    assert_eq!(common::files(&b), expected);

    // A shard rerun after the merge changes nothing.
    ok(sweep(&b, &["--shard", "1/4"]));
    assert_eq!(common::files(&b), expected);
}

#[test]
fn merge_refuses_missing_cells_and_trusts_no_partial_file() {
    let tmp = tempfile::tempdir().unwrap();
    let (_, expected) = single(tmp.path());
    let out = tmp.path().join("out");
    ok(sweep(&out, &["--shard", "0/2"]));
    let done = cells(&out);
    // What a shard killed mid-cell leaves: the atomic writer's hidden temporary file,
    // and (as if copied by hand) a cell file cut short under its real name.
    let (_, all) = single(&tmp.path().join("again"));
    let missing: Vec<&PathBuf> = all
        .keys()
        .filter(|p| p.starts_with("cells") && !done.contains(*p))
        .collect();
    assert_eq!(missing.len(), 4);
    let cut = missing[0];
    let bytes = &all[cut];
    std::fs::write(out.join(cut), &bytes[..bytes.len() / 2]).unwrap();
    let name = cut.file_name().unwrap().to_string_lossy().into_owned();
    std::fs::write(
        out.join(cut.with_file_name(format!(".{name}.a1b2c3.tmp"))),
        &bytes[..bytes.len() - 10],
    )
    .unwrap();

    let o = sweep(&out, &["--merge"]);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("4 cells are missing"), "{err}");
    for m in &missing {
        let n = m.file_name().unwrap().to_string_lossy();
        assert!(err.contains(&*n), "{n} not listed: {err}");
    }
    assert!(
        !out.join("sweep.csv").exists(),
        "a failed merge wrote tables"
    );

    // The other shard completes the sweep; the merge then equals the single run (the
    // temporary file is removed by the merge's exclusive lock, the cut cell recomputed).
    ok(sweep(&out, &["--shard", "1/2"]));
    ok(sweep(&out, &["--merge"]));
    assert_eq!(common::files(&out), expected);
}

#[test]
fn shards_and_merge_check_their_arguments() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("out");
    for bad in ["3/3", "1/0", "a/b", "2"] {
        let o = sweep(&out, &["--shard", bad]);
        assert_eq!(o.status.code(), Some(2), "--shard {bad}");
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(err.contains("K/N"), "{err}");
    }
    let o = sweep(&out, &["--shard", "0/2", "--merge"]);
    assert_eq!(o.status.code(), Some(2));
    let o = sweep(&out, &["--shard", "0/2", "--force"]);
    assert_eq!(o.status.code(), Some(2));
}

#[test]
fn run_shards_split_captures_and_equal_the_single_run() {
    let tmp = tempfile::tempdir().unwrap();
    let caps: Vec<PathBuf> = ["crossroad.pcap", "parking.pcap", "empty.pcap"]
        .iter()
        .map(|c| common::fixtures().join(c))
        .collect();
    let run = |out: &Path, extra: &[&str]| {
        bin()
            .arg("run")
            .args(&caps)
            .args(["--frames", "0", "--no-ply", "-o"])
            .arg(out)
            .args(extra)
            .output()
            .unwrap()
    };
    let single = tmp.path().join("single");
    ok(run(&single, &[]));
    let expected = common::files(&single);
    let sharded = tmp.path().join("sharded");
    let mut seen = BTreeSet::new();
    for k in [1, 0] {
        let before: BTreeSet<PathBuf> = if sharded.exists() {
            common::files(&sharded).into_keys().collect()
        } else {
            BTreeSet::new()
        };
        let msg = ok(run(&sharded, &["--shard", &format!("{k}/2")]));
        assert!(msg.contains("fall to this shard"), "{msg}");
        for p in common::files(&sharded).into_keys() {
            if !before.contains(&p) && p.components().count() > 1 {
                let capture = p.components().next().unwrap().as_os_str().to_owned();
                seen.insert((k, capture));
            }
        }
    }
    assert_eq!(common::files(&sharded), expected);
    // Shard 0 of 2 has captures 0 and 2, shard 1 capture 1.
    let by_shard = |k: i32| -> Vec<String> {
        seen.iter()
            .filter(|(s, _)| *s == k)
            .map(|(_, c)| c.to_string_lossy().into_owned())
            .collect()
    };
    assert_eq!(by_shard(0), vec!["crossroad", "empty"]);
    assert_eq!(by_shard(1), vec!["parking"]);
}

/// A shard killed (SIGKILL) at several points: the merge then either finds every cell or
/// refuses listing the missing ones, never trusting a half-written file; after the shard
/// reruns, the merge equals the single run. The shared capture makes cells long enough to
/// be caught mid-write; the fixtures stand in when it is absent.
#[test]
fn a_killed_shard_leaves_nothing_a_merge_trusts() {
    let tmp = tempfile::tempdir().unwrap();
    let capture = common::shared("hdl32e/monterey.pcap")
        .unwrap_or_else(|| common::fixtures().join("crossroad.pcap"));
    let args = |out: &Path| -> Vec<std::ffi::OsString> {
        let mut a: Vec<std::ffi::OsString> = vec!["--quiet".into(), "sweep".into()];
        a.push(capture.clone().into());
        for s in [
            "--vary",
            "rain.rate_mm_h=0,3",
            "--seeds",
            "1..2",
            "--frames",
            "0..3",
            "-o",
        ] {
            a.push(s.into());
        }
        a.push(out.into());
        a
    };
    let single = tmp.path().join("single");
    ok(bin().args(args(&single)).output().unwrap());
    let expected = common::files(&single);
    let exe = assert_cmd::cargo::cargo_bin("lidar-noise");
    for (i, delay_ms) in [40u64, 120, 250].into_iter().enumerate() {
        let out = tmp.path().join(format!("killed{i}"));
        ok(bin()
            .args(args(&out))
            .args(["--shard", "1/2"])
            .output()
            .unwrap());
        let mut child = std::process::Command::new(&exe)
            .args(args(&out))
            .args(["--shard", "0/2"])
            .env("RAYON_NUM_THREADS", "2")
            .spawn()
            .unwrap();
        std::thread::sleep(std::time::Duration::from_millis(delay_ms));
        let _ = child.kill();
        let _ = child.wait();
        let merge = bin().args(args(&out)).arg("--merge").output().unwrap();
        // A kill mid-write leaves a hidden temporary file (cells are streamed to theirs
        // while computed): the sets must be equal, not only their sizes.
        let complete = cells(&out) == cells(&single)
            && cells(&out)
                .iter()
                .all(|c| std::fs::read(out.join(c)).unwrap() == expected[c]);
        if merge.status.success() {
            assert!(complete, "merge accepted an incomplete set of cells");
            assert_eq!(common::files(&out), expected);
        } else {
            let err = String::from_utf8_lossy(&merge.stderr);
            assert!(err.contains("missing"), "{err}");
            assert!(!out.join("sweep.csv").exists());
        }
        ok(bin()
            .args(args(&out))
            .args(["--shard", "0/2"])
            .output()
            .unwrap());
        ok(bin().args(args(&out)).arg("--merge").output().unwrap());
        assert_eq!(
            common::files(&out),
            expected,
            "after a kill at {delay_ms} ms"
        );
    }
}

/// `--chunk-frames M` (frame ranges of long captures): two captures with their partial
/// frames (3 and 2 frames) x 4 cells.
fn chunked(out: &Path, extra: &[&str]) -> Output {
    bin()
        .arg("sweep")
        .arg(common::fixtures().join("crossroad.pcap"))
        .arg(common::fixtures().join("parking.pcap"))
        .args([
            "--vary",
            "rain.rate_mm_h=0,3",
            "--seeds",
            "1..2",
            "--keep-partial",
            "-o",
        ])
        .arg(out)
        .args(extra)
        .output()
        .unwrap()
}

fn parts(dir: &Path) -> BTreeSet<PathBuf> {
    if !dir.exists() {
        return BTreeSet::new();
    }
    cells(dir)
        .into_iter()
        .filter(|p| p.to_string_lossy().contains(".chunk"))
        .collect()
}

#[test]
fn chunked_shards_partition_the_parts_and_merge_to_the_single_run() {
    let tmp = tempfile::tempdir().unwrap();
    let single = tmp.path().join("single");
    ok(chunked(&single, &[]));
    let expected = common::files(&single);
    for (m, units) in [(1usize, 20usize), (2, 12)] {
        let mf = m.to_string();
        // Disjoint and complete for N = 1..7 (parts are left unjoined by shards).
        for n in [1usize, 2, 3, 7] {
            let out = tmp.path().join(format!("m{m}n{n}"));
            let mut union = BTreeSet::new();
            for k in (0..n).rev() {
                let before = parts(&out);
                ok(chunked(
                    &out,
                    &["--shard", &format!("{k}/{n}"), "--chunk-frames", &mf],
                ));
                let mine: BTreeSet<PathBuf> = parts(&out).difference(&before).cloned().collect();
                assert!(
                    mine.len() == units / n || mine.len() == units / n + 1,
                    "M {m}, shard {k}/{n}: {} parts",
                    mine.len()
                );
                union.extend(mine);
            }
            assert_eq!(union.len(), units, "M {m}, N {n}");
            // A shard run twice adds nothing and changes nothing.
            let again = common::files(&out);
            ok(chunked(&out, &["--shard", "0/1", "--chunk-frames", &mf]));
            assert_eq!(common::files(&out), again);
            ok(chunked(&out, &["--merge", "--chunk-frames", &mf]));
            assert_eq!(common::files(&out), expected, "M {m}, N {n}");
        }
    }
}

#[test]
fn chunked_merge_lists_missing_parts_and_refuses_another_chunk_size() {
    let tmp = tempfile::tempdir().unwrap();
    let single = tmp.path().join("single");
    ok(chunked(&single, &[]));
    let out = tmp.path().join("out");
    ok(chunked(&out, &["--shard", "1/2", "--chunk-frames", "1"]));
    let o = chunked(&out, &["--merge", "--chunk-frames", "1"]);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("10 cell parts are missing"), "{err}");
    assert!(err.contains(".chunk1-00000.json"), "{err}");
    assert!(!out.join("sweep.csv").exists());
    for other in [&["--merge"][..], &["--merge", "--chunk-frames", "2"]] {
        let o = chunked(&out, other);
        assert!(!o.status.success(), "{other:?}");
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(err.contains("give --chunk-frames 1"), "{err}");
    }
    // A plain rerun computes the missing parts and joins them.
    ok(chunked(&out, &["--chunk-frames", "1"]));
    assert_eq!(common::files(&out), common::files(&single));
}
