//! Sharded runs over frame ranges (issue 14): `run --shard K/N --chunk-frames M` deals
//! the (capture, chunk) units disjointly and completely, and `run --merge` joins the
//! shards' parts into the very bytes of one run on one machine (every file, the hidden
//! manifest and lock file included), whatever the order of the shards or how often they
//! ran; missing parts are listed, another chunk size is refused.

use crate::common;

use crate::common::bin2 as bin;
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::process::Output;

/// Exit code of a refused output folder (README and manual, exit codes).
const EXIT_REFUSED: i32 = 3;

/// Two captures with their partial sweeps: 3 + 2 frames.
fn run(out: &Path, extra: &[&str]) -> Output {
    bin()
        .arg("run")
        .arg(common::fixtures().join("crossroad.pcap"))
        .arg(common::fixtures().join("parking.pcap"))
        .args(["--keep-partial", "-o"])
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

fn failed(o: Output) -> String {
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    assert!(!o.status.success(), "succeeded: {err}");
    err
}

fn parts(dir: &Path) -> BTreeSet<PathBuf> {
    if !dir.exists() {
        return BTreeSet::new();
    }
    common::files(dir)
        .into_keys()
        .filter(|p| {
            p.file_name()
                .is_some_and(|n| n.to_string_lossy().starts_with(".run.chunk"))
        })
        .collect()
}

/// The units of the two captures with chunks of `m` frames, in deal order.
fn units(m: usize) -> Vec<PathBuf> {
    let mut out = Vec::new();
    for (capture, frames) in [("crossroad", 3usize), ("parking", 2)] {
        for j in 0..frames.div_ceil(m) {
            out.push(PathBuf::from(capture).join(format!(".run.chunk{m}-{j:05}.json")));
        }
    }
    out
}

fn single(tmp: &Path, extra: &[&str]) -> BTreeMap<PathBuf, Vec<u8>> {
    let dir = tmp.join(format!("single{}", extra.join("")));
    ok(run(&dir, extra));
    common::files(&dir)
}

#[test]
fn shards_partition_the_units_and_merge_to_the_single_run_for_1_to_7() {
    let tmp = tempfile::tempdir().unwrap();
    let expected = single(tmp.path(), &["--no-ply"]);
    for m in [1usize, 2] {
        let all = units(m);
        for n in 1..=7usize {
            let out = tmp.path().join(format!("m{m}n{n}"));
            let mut owner: BTreeMap<PathBuf, usize> = BTreeMap::new();
            // Odd N in reverse order.
            let order: Vec<usize> = if n % 2 == 1 {
                (0..n).rev().collect()
            } else {
                (0..n).collect()
            };
            for k in order {
                let before = parts(&out);
                let msg = ok(run(
                    &out,
                    &[
                        "--no-ply",
                        "--chunk-frames",
                        &m.to_string(),
                        "--shard",
                        &format!("{k}/{n}"),
                    ],
                ));
                assert!(msg.contains("fall to this shard"), "{msg}");
                for p in parts(&out).difference(&before) {
                    assert!(owner.insert(p.clone(), k).is_none(), "{p:?} twice");
                }
            }
            // Disjoint (above) and complete, dealt round-robin over the units in order.
            let dealt: Vec<(PathBuf, usize)> = owner.into_iter().collect();
            let want: BTreeMap<PathBuf, usize> = all
                .iter()
                .enumerate()
                .map(|(i, p)| (p.clone(), i % n))
                .collect();
            assert_eq!(dealt, want.into_iter().collect::<Vec<_>>(), "M {m}, N {n}");
            // Merged (and a shard rerun) for a few N only, to keep the test fast.
            if ![1, 3, 7].contains(&n) {
                continue;
            }
            // A shard run again computes nothing and changes nothing.
            let files = common::files(&out);
            let msg = ok(run(
                &out,
                &[
                    "--no-ply",
                    "--chunk-frames",
                    &m.to_string(),
                    "--shard",
                    &format!("0/{n}"),
                ],
            ));
            assert!(msg.contains("(0 computed"), "{msg}");
            assert_eq!(common::files(&out), files);
            ok(run(
                &out,
                &["--no-ply", "--chunk-frames", &m.to_string(), "--merge"],
            ));
            // Keys first: a differing file list reads better than a byte dump.
            let got = common::files(&out);
            assert_eq!(
                got.keys().collect::<Vec<_>>(),
                expected.keys().collect::<Vec<_>>(),
                "M {m}, N {n}"
            );
            assert!(got == expected, "M {m}, N {n}: merged bytes differ");
        }
    }
}

#[test]
fn merged_point_clouds_and_manifest_equal_the_single_run() {
    let tmp = tempfile::tempdir().unwrap();
    let extra = ["--seed", "7"];
    let expected = single(tmp.path(), &extra);
    assert!(expected.contains_key(Path::new("crossroad/frame_00002.ply")));
    assert!(expected.contains_key(Path::new("parking/.lidar-noise.json")));
    for (m, n) in [(1, 2), (2, 3)] {
        let out = tmp.path().join(format!("m{m}n{n}"));
        let with = |more: &[&str]| -> Vec<String> {
            let m = m.to_string();
            let mut a: Vec<String> = extra.iter().map(|s| s.to_string()).collect();
            a.extend(["--chunk-frames".to_string(), m]);
            a.extend(more.iter().map(|s| s.to_string()));
            a
        };
        for k in (0..n).rev() {
            let args = with(&["--shard", &format!("{k}/{n}")]);
            let args: Vec<&str> = args.iter().map(String::as_str).collect();
            ok(run(&out, &args));
        }
        if m == 1 {
            // A frame file lost after its shard ran: its part no longer counts, and the
            // shard that owns it (unit 1: shard 1) computes it again.
            std::fs::remove_file(out.join("crossroad/frame_00001.ply")).unwrap();
            let args = with(&["--merge"]);
            let args: Vec<&str> = args.iter().map(String::as_str).collect();
            let err = failed(run(&out, &args));
            assert!(err.contains("1 capture chunk part is missing"), "{err}");
            assert!(err.contains("crossroad/.run.chunk1-00001.json"), "{err}");
            let args = with(&["--shard", &format!("1/{n}")]);
            let args: Vec<&str> = args.iter().map(String::as_str).collect();
            let msg = ok(run(&out, &args));
            assert!(msg.contains("(1 computed"), "{msg}");
        }
        let args = with(&["--merge"]);
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        ok(run(&out, &args));
        assert!(common::files(&out) == expected, "M {m}, N {n}");
        // A shard rerun after the merge finds its units done; merged again: the same.
        let args = with(&["--shard", &format!("0/{n}")]);
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let msg = ok(run(&out, &args));
        assert!(msg.contains("(0 computed"), "{msg}");
        assert!(parts(&out).is_empty());
        let args = with(&["--merge"]);
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        ok(run(&out, &args));
        assert!(common::files(&out) == expected, "M {m}, N {n}, rerun");
    }
    // Without --shard, --chunk-frames computes every unit and merges: the same folder.
    let out = tmp.path().join("all");
    ok(run(&out, &["--seed", "7", "--chunk-frames", "2"]));
    assert!(common::files(&out) == expected);
}

#[test]
fn merge_lists_missing_parts_trusts_no_broken_one_and_refuses_another_chunk_size() {
    let tmp = tempfile::tempdir().unwrap();
    let expected = single(tmp.path(), &["--no-ply"]);
    let out = tmp.path().join("out");
    let args = |more: &[&str]| -> Vec<String> {
        let mut a = vec!["--no-ply".to_string()];
        a.extend(more.iter().map(|s| s.to_string()));
        a
    };
    let go = |more: &[&str]| {
        let a = args(more);
        let a: Vec<&str> = a.iter().map(String::as_str).collect();
        run(&out, &a)
    };
    ok(go(&["--chunk-frames", "1", "--shard", "0/3"]));
    let err = failed(go(&["--chunk-frames", "1", "--merge"]));
    // Units 1, 2 (crossroad) and 4 (parking) belong to shards 1 and 2.
    assert!(err.contains("3 capture chunk parts are missing"), "{err}");
    for missing in [
        "crossroad/.run.chunk1-00001.json",
        "crossroad/.run.chunk1-00002.json",
        "parking/.run.chunk1-00001.json",
    ] {
        assert!(err.contains(missing), "{missing}: {err}");
    }
    assert!(!err.contains(".run.chunk1-00000.json"), "{err}");
    assert!(!out.join("crossroad/summary.json").exists());

    // Another chunk size is refused, for a shard and for the merge, naming the one used.
    for more in [
        &["--chunk-frames", "2", "--shard", "1/3"][..],
        &["--chunk-frames", "2", "--merge"][..],
    ] {
        let err = failed(go(more));
        assert!(err.contains("--chunk-frames 1"), "{err}");
    }

    // A shard killed mid-part: a temporary file and a part cut short. Neither is trusted.
    ok(go(&["--chunk-frames", "1", "--shard", "1/3"]));
    let part = out.join("crossroad/.run.chunk1-00001.json");
    let bytes = std::fs::read(&part).unwrap();
    std::fs::write(&part, &bytes[..bytes.len() / 2]).unwrap();
    // (named as our writer names its temporary files: `.NAME.XXXXXX.tmp`)
    std::fs::write(
        out.join("crossroad/..run.chunk1-00002.json.a1b2c3.tmp"),
        b"{",
    )
    .unwrap();
    ok(go(&["--chunk-frames", "1", "--shard", "2/3"]));
    let err = failed(go(&["--chunk-frames", "1", "--merge"]));
    assert!(err.contains("1 capture chunk part is missing"), "{err}");
    assert!(err.contains("checksum"), "{err}");
    assert!(err.contains("crossroad/.run.chunk1-00001.json"), "{err}");
    // Its shard reruns; the merge then equals the single run (leftovers removed).
    let msg = ok(go(&["--chunk-frames", "1", "--shard", "1/3"]));
    assert!(msg.contains("(1 computed, 1 already done)"), "{msg}");
    ok(go(&["--chunk-frames", "1", "--merge"]));
    assert!(common::files(&out) == expected);
    assert!(parts(&out).is_empty());
}

#[test]
fn chunked_runs_refuse_pcap_out_stdin_force_on_shards_and_other_runs_folders() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("out");
    let err = failed(run(&out, &["--chunk-frames", "1", "--pcap-out"]));
    assert!(err.contains("--pcap-out"), "{err}");
    let o = bin()
        .args(["run", "-", "--chunk-frames", "1", "-o"])
        .arg(&out)
        .write_stdin(std::fs::read(common::fixtures().join("crossroad.pcap")).unwrap())
        .output()
        .unwrap();
    let err = failed(o);
    assert!(err.contains("standard input"), "{err}");
    let err = failed(run(&out, &["--merge"]));
    assert!(err.contains("--chunk-frames"), "{err}");
    let err = failed(run(
        &out,
        &["--chunk-frames", "1", "--shard", "0/2", "--force"],
    ));
    assert!(err.contains("--force"), "{err}");
    assert!(!out.join("crossroad").exists());

    // A folder holding another run's results (another seed) is refused, untouched.
    ok(run(&out, &["--no-ply", "--seed", "1"]));
    let before = common::files(&out);
    let o = run(
        &out,
        &[
            "--no-ply",
            "--seed",
            "2",
            "--chunk-frames",
            "1",
            "--shard",
            "0/2",
        ],
    );
    assert_eq!(o.status.code(), Some(EXIT_REFUSED));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("another run"), "{err}");
    assert_eq!(common::files(&out), before);
    // A file this tool did not write is refused too.
    std::fs::write(out.join("parking/notes.txt"), b"mine").unwrap();
    let o = run(
        &out,
        &[
            "--no-ply",
            "--seed",
            "1",
            "--chunk-frames",
            "1",
            "--shard",
            "0/2",
        ],
    );
    assert_eq!(o.status.code(), Some(EXIT_REFUSED));
    assert!(String::from_utf8_lossy(&o.stderr).contains("notes.txt"));
    assert!(out.join("parking/notes.txt").exists());
}

#[test]
fn stale_frame_files_of_another_range_are_refused_by_the_merge_and_force_deletes_them() {
    let tmp = tempfile::tempdir().unwrap();
    let expected = single(tmp.path(), &["--frames", "0..1"]);
    let out = tmp.path().join("out");
    // Shards of a run over all frames, never merged, then the run over 0..1.
    ok(run(&out, &["--chunk-frames", "1", "--shard", "0/1"]));
    for f in [
        "crossroad/.run.chunk1-00002.json",
        "parking/.run.chunk1-00001.json",
    ] {
        std::fs::remove_file(out.join(f)).unwrap();
    }
    ok(run(
        &out,
        &["--frames", "0..1", "--chunk-frames", "1", "--shard", "0/1"],
    ));
    let o = run(
        &out,
        &["--frames", "0..1", "--chunk-frames", "1", "--merge"],
    );
    assert_eq!(o.status.code(), Some(EXIT_REFUSED));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("frame_00002.ply"), "{err}");
    ok(run(
        &out,
        &[
            "--frames",
            "0..1",
            "--chunk-frames",
            "1",
            "--merge",
            "--force",
        ],
    ));
    assert!(common::files(&out) == expected);
}
