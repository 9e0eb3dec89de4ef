//! Output folders never cost the user a file (issue 30, part 4 "Data loss"): the start-up
//! clean-up removes only what proves to be this tool's and only after the checks, nested
//! output folders are locked against each other, a rerun deletes only what the manifest
//! lists, a sweep replaces its results whole at the end, a failed sweep leaves nothing
//! partial, and inputs inside the output folder are never overwritten.

use crate::common;

use std::path::{Path, PathBuf};
use std::process::Output;

use common::{bin2 as bin, crossroad, EXIT_REFUSED};

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

fn run(capture: &Path, out: &Path, extra: &[&str]) -> Output {
    bin()
        .args(["--quiet", "run"])
        .arg(capture)
        .args(["--frames", "0..1", "-o"])
        .arg(out)
        .args(extra)
        .output()
        .unwrap()
}

/// A sweep of frame 0 (unless `extra` gives --frames).
fn sweep(capture: &Path, out: &Path, vary: &str, extra: &[&str]) -> Output {
    let mut c = bin();
    c.args(["--quiet", "sweep"])
        .arg(capture)
        .args(["--vary", vary]);
    if !extra.contains(&"--frames") {
        c.args(["--frames", "0"]);
    }
    c.arg("-o").arg(out).args(extra).output().unwrap()
}

fn ok(o: &Output) {
    assert!(o.status.success(), "{}", stderr(o));
}

fn write(path: &Path, text: &str) {
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    std::fs::write(path, text).unwrap();
}

/// Every file under `dir` but the lock file, by relative path, with its bytes.
fn files(dir: &Path) -> std::collections::BTreeMap<PathBuf, Vec<u8>> {
    if !dir.exists() {
        return Default::default();
    }
    let mut all = common::files(dir);
    all.remove(Path::new(".lidar-noise.lock"));
    all
}

/// Hidden leftovers of this tool in `dir` (staging folders, temporary files).
fn leftovers(dir: &Path) -> Vec<PathBuf> {
    files(dir)
        .into_keys()
        .filter(|p| {
            let s = p.to_string_lossy();
            s.contains(".staging-") || s.ends_with(".tmp") || s.contains(".replaces")
        })
        .collect()
}

/// Takes the lock of output folder `dir` the way the tool does (exclusive `flock` on
/// `DIR/.lidar-noise.lock`), as a run writing into it holds it.
fn hold_lock(dir: &Path) -> std::fs::File {
    std::fs::create_dir_all(dir).unwrap();
    let lock = std::fs::File::options()
        .create(true)
        .truncate(false)
        .write(true)
        .open(dir.join(".lidar-noise.lock"))
        .unwrap();
    lock.lock().unwrap();
    lock
}

#[test]
fn start_up_clean_up_keeps_the_users_hidden_files_even_when_the_run_is_refused() {
    // Issue 30, 4: every `.*.tmp` and `.*.staging-*` in DIR and two levels below went at
    // start-up, before any check: `sweep -o out` with `out/.draft.tmp` was refused and the
    // file was gone.
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("out");
    let user = [
        ".draft.tmp",
        ".x.tmp/notes.txt",
        ".mine.staging-1/notes.txt",
        "plots/.draft.tmp",
        "cells/crossroad/.sketch.tmp",
    ];
    for f in user {
        write(&out.join(f), "mine");
    }
    let o = sweep(&crossroad(), &out, "rain.rate_mm_h=0,3", &[]);
    // The sweep folder holds files the sweep did not write: refused, all kept.
    assert_eq!(o.status.code(), Some(EXIT_REFUSED), "{}", stderr(&o));
    assert!(stderr(&o).contains(".draft.tmp"), "{}", stderr(&o));
    for f in user {
        assert_eq!(std::fs::read_to_string(out.join(f)).unwrap(), "mine", "{f}");
    }
    // A run into the same folder (its results go to out/crossroad) keeps them too, and
    // so does its rerun.
    for _ in 0..2 {
        ok(&run(&crossroad(), &out, &[]));
        for f in user {
            assert_eq!(std::fs::read_to_string(out.join(f)).unwrap(), "mine", "{f}");
        }
    }
    // A results folder named like a temporary file (a capture `.x.tmp.pcap` once gave
    // `DIR/.x.tmp/`) is a results folder like any other.
    let hidden = tmp.path().join("x.tmp.pcap");
    std::fs::copy(crossroad(), &hidden).unwrap();
    ok(&run(&hidden, &out, &[]));
    ok(&run(&hidden, &out, &[]));
    assert!(out.join("x.tmp/summary.json").is_file());
    assert!(out.join(".x.tmp/notes.txt").is_file());
}

#[test]
fn leftovers_of_killed_runs_are_still_removed() {
    use lidar_noise::writers::staging::STAGING_MARKER;
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("out");
    ok(&run(&crossroad(), &out, &[]));
    let reference = files(&out);
    // What a SIGKILL leaves: a staging folder (marked), earlier results a commit moved
    // aside (marked; their target is in place), a temporary file of one of our outputs.
    let staging = out.join(".crossroad.staging-4000000");
    write(&staging.join("frame_00000.ply"), "partial");
    write(&staging.join(STAGING_MARKER), "{}");
    let old = out.join(".crossroad.staging-4000001.old");
    write(&old.join("frame_00000.ply"), "old");
    write(&old.join(STAGING_MARKER), "{}");
    write(
        &out.join("crossroad/.frame_00001.ply.a1B2c3.tmp"),
        "partial",
    );
    ok(&run(&crossroad(), &out, &[]));
    assert!(leftovers(&out).is_empty(), "{:?}", leftovers(&out));
    assert!(files(&out) == reference, "{:?}", files(&out).keys());
}

#[test]
fn nested_output_folders_are_locked_against_each_other() {
    // Issue 30, 4: `run big.pcap -o cc/out &` and `convert big.pcap -o cc/out/big` both
    // exited 0, and the run's rename removed convert's frames.
    let tmp = tempfile::tempdir().unwrap();
    let outer = tmp.path().join("cc/out");
    let inner = outer.join("big");
    let convert = || {
        bin()
            .args(["--quiet", "convert"])
            .arg(crossroad())
            .args(["--frames", "0", "-o"])
            .arg(&inner)
            .output()
            .unwrap()
    };
    // A run writing into cc/out holds its lock: a convert into cc/out/big is refused.
    let lock = hold_lock(&outer);
    let o = convert();
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    let err = stderr(&o);
    assert!(
        err.contains("another lidar-noise run") && err.contains("contains this folder"),
        "{err}"
    );
    assert!(files(&inner).is_empty(), "{:?}", files(&inner).keys());
    drop(lock);
    // A convert writing into cc/out/big holds its lock: a run into cc/out is refused and
    // the frames stay.
    ok(&convert());
    let frames = files(&inner);
    assert!(frames.contains_key(Path::new("frame_00000.ply")));
    let lock = hold_lock(&inner);
    let o = run(&crossroad(), &outer, &[]);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    let err = stderr(&o);
    assert!(
        err.contains("another lidar-noise run") && err.contains("inside this folder"),
        "{err}"
    );
    assert!(!outer.join("crossroad").exists());
    let o = sweep(&crossroad(), &outer, "rain.rate_mm_h=0,3", &[]);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(files(&inner) == frames);
    drop(lock);
}

#[test]
fn a_rerun_deletes_only_what_the_manifest_lists() {
    // Issue 30, 4: a same-settings rerun deleted user files that merely looked like
    // outputs (`frame_00099.ply`, `linkage_00007.csv`, `plots/my_annotated.png`).
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("out");
    ok(&run(&crossroad(), &out, &[]));
    for f in ["crossroad/frame_00099.ply", "crossroad/linkage_00007.csv"] {
        write(&out.join(f), "mine");
    }
    let before = files(&out);
    for extra in [&[][..], &["--force"][..]] {
        let o = run(&crossroad(), &out, extra);
        assert_eq!(o.status.code(), Some(EXIT_REFUSED), "{}", stderr(&o));
        let err = stderr(&o);
        assert!(
            err.contains("frame_00099.ply") && err.contains("linkage_00007.csv"),
            "{err}"
        );
        assert!(files(&out) == before, "{extra:?}");
    }

    let frames = tmp.path().join("frames");
    let convert = |extra: &[&str]| {
        bin()
            .args(["--quiet", "convert"])
            .arg(crossroad())
            .args(["--frames", "0", "-o"])
            .arg(&frames)
            .args(extra)
            .output()
            .unwrap()
    };
    ok(&convert(&[]));
    write(&frames.join("frame_00099.ply"), "mine");
    let o = convert(&["--force"]);
    assert_eq!(o.status.code(), Some(EXIT_REFUSED), "{}", stderr(&o));
    assert_eq!(
        std::fs::read_to_string(frames.join("frame_00099.ply")).unwrap(),
        "mine"
    );

    let swept = tmp.path().join("sweep");
    ok(&sweep(&crossroad(), &swept, "rain.rate_mm_h=0,3", &[]));
    write(&swept.join("plots/crossroad/my_annotated.png"), "mine");
    let before = files(&swept);
    for extra in [&[][..], &["--force"][..]] {
        let o = sweep(&crossroad(), &swept, "rain.rate_mm_h=0,3", extra);
        assert_eq!(o.status.code(), Some(EXIT_REFUSED), "{}", stderr(&o));
        assert!(stderr(&o).contains("my_annotated.png"), "{}", stderr(&o));
        assert!(files(&swept) == before, "{extra:?}");
    }
}

/// A copy of crossroad.pcap whose name makes the sweep's bird's-eye figure name too long
/// for the file system: the sweep fails after its cells and tables, while writing plots.
fn capture_failing_late(dir: &Path) -> PathBuf {
    let path = dir.join(format!("{}.pcap", "c".repeat(240)));
    std::fs::copy(crossroad(), &path).unwrap();
    path
}

#[test]
fn a_sweep_replacing_another_keeps_the_old_results_until_the_new_are_whole() {
    // Issue 30, 4: an interrupted `sweep --force` left neither the old nor the new
    // results: the old plan's tables, plots, page and cells were deleted at start-up.
    // Here the new sweep fails after its cells and tables (a failure at the end, as an
    // interruption there); the commit itself, cut at every step, is tested in
    // writers::staging (a_replacement_cut_at_any_step_leaves_the_old_or_is_finished_whole).
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("out");
    ok(&sweep(&crossroad(), &out, "rain.rate_mm_h=0,3", &[]));
    let before = files(&out);
    let late = capture_failing_late(tmp.path());
    let o = sweep(&late, &out, "occlusion=on,off", &["--force"]);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(stderr(&o).contains("too long"), "{}", stderr(&o));
    assert!(leftovers(&out).is_empty(), "{:?}", leftovers(&out));
    // Every file of the earlier sweep is there with its bytes (the new sweep's cells,
    // finished before the failure, are kept beside them for a rerun).
    let after = files(&out);
    for (path, bytes) in &before {
        assert!(after.get(path) == Some(bytes), "{} changed", path.display());
    }
    let extra: Vec<&PathBuf> = after.keys().filter(|p| !before.contains_key(*p)).collect();
    assert!(extra.iter().all(|p| p.starts_with("cells")), "{extra:?}");
    // The earlier plan still reruns as a resume: same bytes.
    ok(&sweep(&crossroad(), &out, "rain.rate_mm_h=0,3", &[]));
    let rerun = files(&out);
    for (path, bytes) in &before {
        assert!(rerun.get(path) == Some(bytes), "{} changed", path.display());
    }
}

#[test]
fn failed_sweeps_leave_nothing_partial() {
    // Issue 30, 4: `--frames 99`, a bad `--labels` and a failure after the tables and
    // plots (`--bands 0,1e308`: "File name too long") left files behind.
    let tmp = tempfile::tempdir().unwrap();
    let bad_labels = tmp.path().join("bad.labels.csv");
    std::fs::write(&bad_labels, "not,a\nlabels,file\n").unwrap();
    let labels = bad_labels.to_string_lossy().into_owned();
    let cases: [(&str, Vec<&str>); 3] = [
        ("frames", vec!["--frames", "99"]),
        ("labels", vec!["--labels", &labels]),
        ("bands", vec!["--bands", "0,1e308"]),
    ];
    for (what, extra) in cases {
        let out = tmp.path().join(what);
        let o = sweep(&crossroad(), &out, "rain.rate_mm_h=0,3", &extra);
        assert_eq!(o.status.code(), Some(1), "{what}: {}", stderr(&o));
        assert!(!out.exists(), "{what}: left {:?}", files(&out).keys());
    }
    let err = stderr(&sweep(
        &crossroad(),
        &tmp.path().join("x"),
        "rain.rate_mm_h=0,3",
        &["--bands", "0,1e308"],
    ));
    assert!(err.contains("--bands") && err.contains("1e308"), "{err}");
    // A failure while writing the plots, into a new folder: no table, plot or page is
    // left (the finished cells stay, with the record of their plan, for a rerun).
    let out = tmp.path().join("late");
    let late = capture_failing_late(tmp.path());
    let o = sweep(&late, &out, "rain.rate_mm_h=0,3", &[]);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    let left: Vec<PathBuf> = files(&out)
        .into_keys()
        .filter(|p| !p.starts_with("cells") && p != Path::new(".lidar-noise.json"))
        .collect();
    assert!(left.is_empty(), "{left:?}");
    let manifest: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join(".lidar-noise.json")).unwrap()).unwrap();
    assert_eq!(manifest["files"], serde_json::json!([]));
}

#[test]
fn labels_inside_the_output_folder_are_never_overwritten() {
    // Issue 30, 4 (with 77bdbbd for calibration files): inputs inside the output folder
    // are refused, never replaced, with or without --force.
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("out");
    let labels_src = common::fixtures().join("crossroad.labels.csv.gz");
    ok(&sweep(
        &crossroad(),
        &out,
        "rain.rate_mm_h=0,3",
        &["--labels", &labels_src.to_string_lossy()],
    ));
    // Labels kept at an output's name and at a name of their own.
    let at_output = out.join("sweep.csv");
    std::fs::copy(&labels_src, &at_output).unwrap();
    let own = out.join("crossroad.labels.csv.gz");
    std::fs::copy(&labels_src, &own).unwrap();
    let bytes = std::fs::read(&labels_src).unwrap();
    for labels in [&at_output, &own] {
        for extra in [&[][..], &["--force"][..]] {
            let mut args = vec!["--labels", labels.to_str().unwrap()];
            args.extend_from_slice(extra);
            let o = sweep(&crossroad(), &out, "rain.rate_mm_h=0,3", &args);
            assert!(!o.status.success(), "{}", stderr(&o));
            assert!(
                stderr(&o).contains(&*labels.file_name().unwrap().to_string_lossy()),
                "{}",
                stderr(&o)
            );
            assert_eq!(std::fs::read(labels).unwrap(), bytes);
        }
    }
    // The calibration of a run kept among its results (done in 77bdbbd) stays too.
    let run_out = tmp.path().join("run");
    ok(&run(&crossroad(), &run_out, &[]));
    let calibration = run_out.join("crossroad/summary.json");
    let text = "<boost_serialization><px><item>not used</item></px></boost_serialization>";
    std::fs::write(&calibration, text).unwrap();
    let o = run(
        &crossroad(),
        &run_out,
        &["--force", "--calibration", calibration.to_str().unwrap()],
    );
    assert!(!o.status.success(), "{}", stderr(&o));
    assert_eq!(std::fs::read_to_string(&calibration).unwrap(), text);
}

#[cfg(target_os = "linux")]
#[test]
fn a_sweep_force_killed_mid_way_keeps_the_old_results() {
    // Issue 30, 4: an interrupted `sweep --force` left neither the old nor the new results
    // (20 of 30 tries). The new sweep is stopped at a known point, without timing: its
    // labels are a FIFO, which it reads while computing its cells; once it has the FIFO
    // open (a writer can then open it without blocking), it waits for bytes that never
    // come, and gets SIGKILL or SIGINT there.
    use std::os::unix::fs::OpenOptionsExt;
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("out");
    ok(&sweep(&crossroad(), &out, "rain.rate_mm_h=0,3", &[]));
    let before = files(&out);
    let fifo = tmp.path().join("labels.fifo");
    let made = std::process::Command::new("mkfifo")
        .arg(&fifo)
        .status()
        .unwrap();
    assert!(made.success());
    for signal in ["KILL", "INT"] {
        let mut child = std::process::Command::new(assert_cmd::cargo::cargo_bin!("lidar-noise"))
            .env("RAYON_NUM_THREADS", "2")
            .args(["--quiet", "sweep"])
            .arg(crossroad())
            .args(["--vary", "occlusion=on,off", "--frames", "0", "--force"])
            .arg("--labels")
            .arg(&fifo)
            .arg("-o")
            .arg(&out)
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        let writer = loop {
            match std::fs::File::options()
                .write(true)
                .custom_flags(libc::O_NONBLOCK)
                .open(&fifo)
            {
                Ok(w) => break w,
                Err(e) if e.raw_os_error() == Some(libc::ENXIO) => {
                    if let Some(status) = child.try_wait().unwrap() {
                        let mut err = String::new();
                        use std::io::Read;
                        child
                            .stderr
                            .take()
                            .unwrap()
                            .read_to_string(&mut err)
                            .unwrap();
                        panic!("the sweep ended before reading its labels: {status}: {err}");
                    }
                    // Polling, not a deadline: the test waits as long as the sweep needs.
                    std::thread::sleep(std::time::Duration::from_millis(5));
                }
                Err(e) => panic!("{e}"),
            }
        };
        let killed = std::process::Command::new("kill")
            .args([format!("-{signal}"), child.id().to_string()])
            .status()
            .unwrap();
        assert!(killed.success());
        let status = child.wait().unwrap();
        drop(writer);
        assert!(!status.success(), "{signal}: {status}");
        assert!(
            leftovers(&out).is_empty(),
            "{signal}: {:?}",
            leftovers(&out)
        );
        assert!(
            files(&out) == before,
            "{signal}: the earlier results changed: {:?}",
            files(&out).keys()
        );
    }
}
