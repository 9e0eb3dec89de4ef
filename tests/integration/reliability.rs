//! Issue 10: nothing wrong, nothing stale, nothing partial, clear messages, closed pipes.
//! Each test reproduces one reported defect (they failed before the fixes).

use crate::common;

use crate::common::command as bin;
use crate::common::fixture;
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};

fn run_ok(cmd: &mut Command) -> Output {
    let o = cmd.output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    o
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// Byte offsets of the UDP payloads of 1206-byte data packets in a classic pcap.
fn data_payloads(bytes: &[u8]) -> Vec<usize> {
    let mut out = Vec::new();
    let mut off = 24;
    while off + 16 <= bytes.len() {
        let incl = u32::from_le_bytes(bytes[off + 8..off + 12].try_into().unwrap()) as usize;
        if incl == 42 + 1206 {
            out.push(off + 16 + 42);
        }
        off += 16 + incl;
    }
    out
}

/// Applies `f` to every (laser, distance bytes, intensity byte) of every data packet.
fn edit_returns(bytes: &mut [u8], mut f: impl FnMut(usize, &mut [u8])) {
    for p in data_payloads(bytes) {
        for block in 0..12 {
            for laser in 0..32 {
                let at = p + 100 * block + 4 + 3 * laser;
                f(laser, &mut bytes[at..at + 3]);
            }
        }
    }
}

fn sweep(capture: &Path, out: &Path) -> String {
    let o = run_ok(
        bin()
            .arg("sweep")
            .arg(capture)
            .args([
                "--vary",
                "rain.rate_mm_h=0,3",
                "--seeds",
                "1..2",
                "--frames",
                "0..1",
                "-o",
            ])
            .arg(out),
    );
    stderr(&o)
}

/// Defect 2: a capture whose content changed (same name, same size) is recomputed.
#[test]
fn sweep_recomputes_cells_when_the_capture_content_changes() {
    let tmp = tempfile::tempdir().unwrap();
    let capture = tmp.path().join("scene.pcap");
    std::fs::copy(fixture("crossroad.pcap"), &capture).unwrap();
    let out = tmp.path().join("out");
    let first = sweep(&capture, &out);
    assert!(first.contains("4 cells computed, 0 loaded"), "{first}");
    let again = sweep(&capture, &out);
    assert!(again.contains("0 cells computed, 4 loaded"), "{again}");
    let mut bytes = std::fs::read(&capture).unwrap();
    let size = bytes.len();
    // Halve every distance in place: same file name and size, other data.
    edit_returns(&mut bytes, |_, r| {
        let d = u16::from_le_bytes([r[0], r[1]]) / 2;
        r[..2].copy_from_slice(&d.to_le_bytes());
    });
    assert_eq!(bytes.len(), size);
    std::fs::write(&capture, &bytes).unwrap();
    let changed = sweep(&capture, &out);
    assert!(changed.contains("4 cells computed, 0 loaded"), "{changed}");
}

/// Defect 3: a cell file cut short or edited is not trusted.
#[test]
fn sweep_recomputes_cells_that_were_edited_or_cut() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("out");
    let capture = fixture("crossroad.pcap");
    sweep(&capture, &out);
    let reference = common::files(&out.join("cells"));
    let cells: Vec<PathBuf> = reference.keys().cloned().collect();
    assert_eq!(cells.len(), 4, "{cells:?}");
    // Cut the frames list of one cell to its first frame (a valid, shorter JSON file).
    let cut = out.join("cells").join(&cells[0]);
    let mut v: serde_json::Value = serde_json::from_slice(&std::fs::read(&cut).unwrap()).unwrap();
    let frames = v["frames"].as_array_mut().unwrap();
    assert!(frames.len() >= 2);
    frames.truncate(1);
    std::fs::write(&cut, serde_json::to_vec_pretty(&v).unwrap()).unwrap();
    // Edit a number in another.
    let edited = out.join("cells").join(&cells[1]);
    let text = std::fs::read_to_string(&edited).unwrap();
    let at = text.find("\"object_survival\": ").unwrap() + "\"object_survival\": ".len();
    let end = at + text[at..].find([',', '\n']).unwrap();
    let text = format!("{}0.123{}", &text[..at], &text[end..]);
    std::fs::write(&edited, text).unwrap();
    let log = sweep(&capture, &out);
    assert!(log.contains("2 cells computed, 2 loaded"), "{log}");
    assert!(log.contains("recomputing"), "{log}");
    assert_eq!(common::files(&out.join("cells")), reference);
}

fn corrupt_mid_file(dir: &Path) -> PathBuf {
    let mut bytes = std::fs::read(fixture("crossroad.pcap")).unwrap();
    let payloads = data_payloads(&bytes);
    // The record header of a packet near the end claims 4 GB.
    let record = payloads[payloads.len() - 5] - 42 - 16;
    bytes[record + 8..record + 12].copy_from_slice(&0xFFFF_FFF0u32.to_le_bytes());
    let path = dir.join("bad.pcap");
    std::fs::write(&path, bytes).unwrap();
    path
}

/// Defect 4: a failed run writes nothing (corrupt capture, second capture bad, input as
/// target, no frame in range), and leaves no folder it created.
#[test]
fn failed_runs_leave_nothing_behind() {
    let tmp = tempfile::tempdir().unwrap();
    let bad = corrupt_mid_file(tmp.path());
    let good = fixture("crossroad.pcap");
    let out = tmp.path().join("out");
    let o = bin()
        .arg("run")
        .arg(&bad)
        .arg("-o")
        .arg(&out)
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(
        !out.exists(),
        "a corrupt capture left {:?}",
        common::files(&out).keys()
    );
    let o = bin()
        .arg("run")
        .arg(&good)
        .arg(&bad)
        .arg("-o")
        .arg(&out)
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(
        !out.exists(),
        "good + bad left {:?}",
        common::files(&out).keys()
    );
    // An input that is the second capture's target folder: refused before anything.
    let inputs = tmp.path().join("in");
    std::fs::create_dir_all(&inputs).unwrap();
    let named = inputs.join("scan");
    std::fs::copy(&good, &named).unwrap();
    let o = bin()
        .arg("run")
        .arg(&good)
        .arg(&named)
        .arg("-o")
        .arg(&inputs)
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(stderr(&o).contains("refusing"), "{}", stderr(&o));
    assert!(!inputs.join("crossroad").exists());
    let o = bin()
        .args(["run", "--frames", "999", "-o"])
        .arg(&out)
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(!out.exists(), "--frames 999 left a folder");
    // An existing result survives a failed rerun unchanged.
    run_ok(bin().arg("run").arg(&good).arg("-o").arg(&out));
    let before = common::files(&out);
    let o = bin()
        .arg("run")
        .arg(&good)
        .arg(&bad)
        .arg("-o")
        .arg(&out)
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(1));
    assert_eq!(common::files(&out), before);
}

/// Defect 4 for `convert`: a failed convert leaves no frame and no folder.
#[test]
fn failed_convert_leaves_nothing_behind() {
    let tmp = tempfile::tempdir().unwrap();
    let bad = corrupt_mid_file(tmp.path());
    let out = tmp.path().join("ply");
    let o = bin()
        .arg("convert")
        .arg(&bad)
        .arg("-o")
        .arg(&out)
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(!out.exists(), "left {:?}", common::files(&out).keys());
    let o = bin()
        .arg("convert")
        .arg(fixture("crossroad.pcap"))
        .args(["--frames", "999", "-o"])
        .arg(&out)
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(!out.exists());
    run_ok(
        bin()
            .arg("convert")
            .arg(fixture("crossroad.pcap"))
            .arg("-o")
            .arg(&out),
    );
    let names: Vec<String> = visible_files(&out)
        .into_keys()
        .map(|p| p.to_string_lossy().into_owned())
        .collect();
    assert_eq!(names, ["frame_00000.ply", "frame_00001.ply"], "{names:?}");
}

/// Defect 5: a second run into a folder that is being written fails at once.
#[test]
fn concurrent_run_into_the_same_folder_fails_at_once() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("out");
    std::fs::create_dir_all(&out).unwrap();
    // Hold the lock the way a running lidar-noise does.
    let lock = std::fs::File::options()
        .create(true)
        .truncate(false)
        .write(true)
        .open(out.join(".lidar-noise.lock"))
        .unwrap();
    lock.lock().unwrap();
    let o = bin().arg("run").arg("-o").arg(&out).output().unwrap();
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("another lidar-noise run"),
        "{}",
        stderr(&o)
    );
    assert!(!out.join("crossroad").exists());
    let o = bin()
        .arg("sweep")
        .arg(fixture("crossroad.pcap"))
        .args(["--vary", "rain.rate_mm_h=0,3", "-o"])
        .arg(&out)
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("another lidar-noise run"),
        "{}",
        stderr(&o)
    );
    drop(lock);
    // Released: a run gets through. (A child that another test forks at this moment holds
    // a copy of the descriptor until it execs, so allow it a moment.)
    let mut ok = false;
    for _ in 0..50 {
        let o = bin().arg("run").arg("-o").arg(&out).output().unwrap();
        if o.status.success() {
            ok = true;
            break;
        }
        assert!(
            stderr(&o).contains("another lidar-noise run"),
            "{}",
            stderr(&o)
        );
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
    assert!(ok, "the lock was not released");
}

fn visible_files(dir: &Path) -> std::collections::BTreeMap<PathBuf, Vec<u8>> {
    if !dir.exists() {
        return Default::default();
    }
    common::files(dir)
        .into_iter()
        // The lock file and the manifest (`.lidar-noise.json`, tests/integration/output_folders.rs).
        .filter(|(p, _)| !p.ends_with(".lidar-noise.lock") && !p.ends_with(".lidar-noise.json"))
        .collect()
}

fn leftovers(dir: &Path) -> Vec<PathBuf> {
    visible_files(dir)
        .into_keys()
        .filter(|p| {
            let s = p.to_string_lossy();
            s.contains(".tmp") || s.contains(".staging-") || s.contains(".part")
        })
        .collect()
}

/// Must-hold 2: `run` and `sweep` killed with SIGINT and SIGKILL at several points leave
/// no temporary file, no mixed folder, and the rerun writes the same bytes.
#[test]
fn interrupted_run_and_sweep_leave_nothing_partial_and_rerun_identically() {
    let tmp = tempfile::tempdir().unwrap();
    let capture = common::shared("hdl32e/monterey.pcap").unwrap_or_else(|| fixture("empty.pcap"));
    let run_args = |out: &Path| {
        let mut c = bin();
        c.arg("run")
            .arg(&capture)
            .arg("--keep-dropped")
            .arg("-o")
            .arg(out);
        c
    };
    // About 1.5 s on the shared capture, so the kills land mid-sweep.
    let sweep_capture =
        common::shared("hdl32e/monterey.pcap").unwrap_or_else(|| fixture("crossroad.pcap"));
    let sweep_args = |out: &Path| {
        let mut c = bin();
        c.arg("sweep")
            .arg(&sweep_capture)
            .args(["--vary", "rain.rate_mm_h=0,3", "--seeds", "1..3", "-o"])
            .arg(out);
        c
    };
    for (what, args) in [
        ("run", &run_args as &dyn Fn(&Path) -> Command),
        ("sweep", &sweep_args),
    ] {
        let reference = tmp.path().join(format!("{what}-ref"));
        run_ok(&mut args(&reference));
        let reference = visible_files(&reference);
        let out = tmp.path().join(format!("{what}-out"));
        for (i, delay_ms) in [30u64, 80, 150, 250, 400, 700].into_iter().enumerate() {
            let sigkill = i % 2 == 1;
            let fresh = !out.exists();
            let mut child = args(&out)
                .stdout(Stdio::null())
                .stderr(Stdio::null())
                .spawn()
                .unwrap();
            std::thread::sleep(std::time::Duration::from_millis(delay_ms));
            if sigkill {
                child.kill().ok();
            } else {
                Command::new("kill")
                    .args(["-INT", &child.id().to_string()])
                    .status()
                    .unwrap();
            }
            let status = child.wait().unwrap();
            if !sigkill {
                // 130: the handler cleaned up; 0: it had finished. On a loaded machine the
                // signal may come before the process installed its handler (before it
                // wrote anything): then it dies of the signal itself, which is no
                // failure as long as nothing is left behind (checked below).
                use std::os::unix::process::ExitStatusExt;
                assert!(
                    matches!(status.code(), Some(130) | Some(0)) || status.signal() == Some(2),
                    "{what}: SIGINT after {delay_ms} ms gave {status:?}"
                );
                assert!(leftovers(&out).is_empty(), "{what}: {:?}", leftovers(&out));
                // (A sweep keeps the cells it finished: a rerun resumes from them.)
                if what == "run" && fresh && status.code() == Some(130) {
                    assert!(
                        !out.exists(),
                        "{what}: an interrupted first run left its folder"
                    );
                }
            }
            if what == "run" {
                // The results folder is whole: absent or an entire run's output.
                let name = capture.file_stem().unwrap();
                let got = visible_files(&out.join(name));
                let want: std::collections::BTreeMap<_, _> = reference
                    .iter()
                    .filter_map(|(p, b)| {
                        Some((p.strip_prefix(name).ok()?.to_path_buf(), b.clone()))
                    })
                    .collect();
                assert!(
                    got.is_empty() || got == want,
                    "{what}: mixed folder after {delay_ms} ms"
                );
            }
            run_ok(&mut args(&out));
            assert!(leftovers(&out).is_empty(), "{what}: {:?}", leftovers(&out));
            assert!(
                visible_files(&out) == reference,
                "{what}: the rerun after an interruption at {delay_ms} ms differs"
            );
        }
    }
}

/// Defect 7: raw intensity levels read as reflectivity are pointed out; dead lasers too.
#[test]
fn raw_intensity_and_dead_lasers_are_reported() {
    let tmp = tempfile::tempdir().unwrap();
    let mut bytes = std::fs::read(fixture("crossroad.pcap")).unwrap();
    edit_returns(&mut bytes, |laser, r| {
        r[2] = 200u8.saturating_add((laser % 50) as u8);
        if laser == 5 {
            r[0] = 0;
            r[1] = 0;
        }
    });
    let path = tmp.path().join("old-firmware.pcap");
    std::fs::write(&path, bytes).unwrap();
    let o = run_ok(bin().arg("info").arg(&path));
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(text.contains("dead lasers   5 "), "{text}");
    assert!(
        stderr(&o).contains("sensor.intensity=\"raw\""),
        "{}",
        stderr(&o)
    );
    let o = run_ok(
        bin()
            .arg("run")
            .arg(&path)
            .arg("--no-ply")
            .arg("-o")
            .arg(tmp.path().join("o")),
    );
    assert!(
        stderr(&o).contains("sensor.intensity=\"raw\""),
        "{}",
        stderr(&o)
    );
    assert!(stderr(&o).contains("dead laser"), "{}", stderr(&o));
    // The fix silences the intensity warning.
    let o = run_ok(
        bin()
            .arg("run")
            .arg(&path)
            .args(["--no-ply", "--set", "sensor.intensity=\"raw\"", "-o"])
            .arg(tmp.path().join("o2")),
    );
    assert!(
        !stderr(&o).contains("sensor.intensity=\"raw\""),
        "{}",
        stderr(&o)
    );
    // Real reflectivity data gives no such warning.
    let o = run_ok(bin().arg("info").arg(fixture("crossroad.pcap")));
    assert!(!stderr(&o).contains("raw"), "{}", stderr(&o));
}

/// Defect 8 (frames): reversed and partial-only ranges are explained.
#[test]
fn frame_range_messages_explain_the_problem() {
    let o = bin()
        .args(["run", "--frames", "5..2", "-o", "/nonexistent/x"])
        .output()
        .unwrap();
    assert!(stderr(&o).contains("reversed"), "{}", stderr(&o));
    let Some(capture) = common::shared("hdl32e/monterey.pcap") else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    // `convert` stops decoding at the end of the range too, and still counts every frame.
    for command in ["run", "convert"] {
        let o = bin()
            .arg(command)
            .arg(&capture)
            .args(["--frames", "0", "-o"])
            .arg(tmp.path().join(command))
            .output()
            .unwrap();
        let e = stderr(&o);
        assert_eq!(o.status.code(), Some(1), "{command}: {e}");
        assert!(e.contains("partial first sweep"), "{command}: {e}");
        assert!(
            e.contains("17 full frames") && e.contains("1..17"),
            "{command}: {e}"
        );
    }
}

/// Defect 8 (configs): settings that would silently do nothing are pointed out.
#[test]
fn configs_that_do_nothing_are_refused_or_noted() {
    let tmp = tempfile::tempdir().unwrap();
    for interval in ["[20, 30]", "[-100, -95]", "[-40, -35]"] {
        let path = tmp.path().join("occ.toml");
        std::fs::write(
            &path,
            format!("[[noise]]\ntype = \"occlusion\"\nelevation_deg = {interval}\n"),
        )
        .unwrap();
        let o = bin().arg("validate").arg(&path).output().unwrap();
        let e = stderr(&o);
        assert_eq!(o.status.code(), Some(1), "{interval}: {e}");
        assert!(
            e.contains("elevation_deg") && e.contains("line 3") && e.contains("selects no laser"),
            "{e}"
        );
    }
    // An interval holding a laser (-30.67) is fine.
    let path = tmp.path().join("ok.toml");
    std::fs::write(
        &path,
        "[[noise]]\ntype = \"occlusion\"\nelevation_deg = [-31, -30]\n",
    )
    .unwrap();
    run_ok(bin().arg("validate").arg(&path));
    let empty = tmp.path().join("empty.toml");
    std::fs::write(&empty, "").unwrap();
    let o = run_ok(
        bin()
            .arg("run")
            .arg("-c")
            .arg(&empty)
            .arg("--no-ply")
            .arg("-o")
            .arg(tmp.path().join("o")),
    );
    assert!(stderr(&o).contains("no noise stage"), "{}", stderr(&o));
    let o = bin()
        .args(["validate", "--set", "noise[2].type=\"rain\""])
        .output()
        .unwrap();
    let e = stderr(&o);
    assert_eq!(o.status.code(), Some(1), "{e}");
    assert!(e.contains("--set noise[2].type"), "{e}");
    assert!(
        !e.contains("line "),
        "blames a line of the built-in file: {e}"
    );
}

/// Defect 9: messages say what is wrong, once.
#[test]
fn messages_name_the_problem_once() {
    let tmp = tempfile::tempdir().unwrap();
    let o = bin()
        .args(["info", "/nonexistent/capture.pcap"])
        .output()
        .unwrap();
    let e = stderr(&o);
    assert_eq!(e.matches("os error 2").count(), 1, "{e}");
    let o = bin().arg("info").arg(tmp.path()).output().unwrap();
    assert!(stderr(&o).contains("directory"), "{}", stderr(&o));
    // A pcapng whose interface description block was removed.
    let mut w = lidar_noise::capture::writer::PcapNgWriter::new(Vec::new()).unwrap();
    let payload =
        &std::fs::read(fixture("crossroad.pcap")).unwrap()[24 + 16 + 42..24 + 16 + 42 + 1206];
    for i in 0..20 {
        w.write_udp(1_000_000 + i * 553, 2368, 2368, payload)
            .unwrap();
    }
    let ng = w.into_inner().unwrap();
    let shb = u32::from_le_bytes(ng[4..8].try_into().unwrap()) as usize;
    let idb = u32::from_le_bytes(ng[shb + 4..shb + 8].try_into().unwrap()) as usize;
    assert_eq!(
        u32::from_le_bytes(ng[shb..shb + 4].try_into().unwrap()),
        1,
        "IDB expected"
    );
    let no_idb = [&ng[..shb], &ng[shb + idb..]].concat();
    let path = tmp.path().join("no-idb.pcapng");
    std::fs::write(&path, no_idb).unwrap();
    let o = bin().arg("info").arg(&path).output().unwrap();
    let e = stderr(&o);
    assert!(e.contains("interface description block"), "{e}");
    // A packet with an invalid return mode byte: run says it skipped it.
    let mut bytes = std::fs::read(fixture("crossroad.pcap")).unwrap();
    let p = data_payloads(&bytes)[40];
    bytes[p + 1204] = 0x99;
    let path = tmp.path().join("one-bad.pcap");
    std::fs::write(&path, bytes).unwrap();
    let o = run_ok(
        bin()
            .arg("run")
            .arg(&path)
            .arg("--no-ply")
            .arg("-o")
            .arg(tmp.path().join("o")),
    );
    assert!(
        stderr(&o).contains("skipped 1 malformed packet"),
        "{}",
        stderr(&o)
    );
    let o = run_ok(
        bin()
            .arg("convert")
            .arg(fixture("crossroad.pcap"))
            .args(["--frames", "1", "-o"])
            .arg(tmp.path().join("c")),
    );
    assert!(stderr(&o).contains("wrote 1 frame "), "{}", stderr(&o));
}

/// Defect 10: `info X | head -1` exits 0 quietly when the reader closes the pipe.
#[test]
fn closed_stdout_is_not_an_error() {
    let mut child = bin()
        .arg("info")
        .args([
            fixture("crossroad.pcap"),
            fixture("parking.pcap"),
            fixture("empty.pcap"),
        ])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    drop(child.stdout.take());
    let o = child.wait_with_output().unwrap();
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(o.stderr.is_empty(), "{}", stderr(&o));
}
