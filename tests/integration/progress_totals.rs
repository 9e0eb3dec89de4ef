//! `run` and `convert` know their progress totals before work starts (issue 33: `run`
//! showed a spinner with no total): the frames in range, counted from the frame index
//! without decoding. Checked on the count itself and, when tmux is installed, on what
//! the bars draw in a terminal (the totals, never the times: nothing here depends on
//! the machine's speed).

use crate::common;

use lidar_noise::engine::inputs::frames_total;
use lidar_noise::sensor::frames::{DecoderOptions, FrameReader};
use std::path::Path;

/// Frames the reader yields in `range`: what `run` and `convert` process.
fn frames_run(path: &Path, options: &DecoderOptions, range: std::ops::RangeInclusive<u32>) -> u64 {
    FrameReader::open(path, options)
        .unwrap()
        .map(|f| f.unwrap())
        .filter(|f| range.contains(&f.index))
        .count() as u64
}

#[test]
fn the_total_is_the_frames_processed() {
    let crossroad = common::crossroad();
    let dir = tempfile::tempdir().unwrap();
    let long = dir.path().join("long.pcap");
    common::repeated(&crossroad, 5, &long);
    let partial = DecoderOptions {
        keep_partial: true,
        ..DecoderOptions::default()
    };
    for path in [&crossroad, &long] {
        for options in [DecoderOptions::default(), partial.clone()] {
            for range in [0..=u32::MAX, 1..=1, 3..=7, 1000..=2000] {
                assert_eq!(
                    frames_total(path, &options, &range),
                    Some(frames_run(path, &options, range.clone())),
                    "{} {range:?} keep_partial {}",
                    path.display(),
                    options.keep_partial
                );
            }
        }
    }
    // The fixture: 2 full frames and a partial one.
    let all = 0..=u32::MAX;
    assert_eq!(
        frames_total(&crossroad, &DecoderOptions::default(), &all),
        Some(2)
    );
    assert_eq!(frames_total(&crossroad, &partial, &all), Some(3));
    // Standard input and a FIFO can be read only once: no total (and no blocking).
    assert_eq!(frames_total(Path::new("-"), &partial, &all), None);
    let fifo = dir.path().join("fifo.pcap");
    if std::process::Command::new("mkfifo")
        .arg(&fifo)
        .status()
        .is_ok_and(|s| s.success())
    {
        assert_eq!(frames_total(&fifo, &partial, &all), None);
    }
    assert_eq!(
        frames_total(&dir.path().join("none.pcap"), &partial, &all),
        None
    );
}

/// Runs `command` in a detached tmux terminal and returns every byte it wrote there
/// (tmux's pipe-pane logs the pane from before the command starts to after it ends);
/// None when tmux cannot start. Each call has its own server on its own socket in
/// `dir`: with one shared socket, a new session could reach the server that the last
/// call's kill-session was shutting down, and fail with "server exited unexpectedly"
/// on a slow machine (seen in CI).
fn in_tmux(command: &str, dir: &Path, call: usize) -> Option<String> {
    let socket = dir.join(format!("tmux{call}.sock"));
    let tmux = |args: &[&str]| {
        let out = std::process::Command::new("tmux")
            .arg("-S")
            .arg(&socket)
            .args(["-f", "/dev/null"])
            .args(args)
            .current_dir(dir)
            .output();
        match out {
            Ok(o) if o.status.success() => Ok(()),
            Ok(o) => Err(format!(
                "tmux {args:?}: {}",
                String::from_utf8_lossy(&o.stderr).trim()
            )),
            Err(e) => Err(format!("tmux {args:?}: {e}")),
        }
    };
    let session = format!("p{}", std::process::id());
    let log = dir.join(format!("pane{call}.log"));
    if let Err(e) = tmux(&["new-session", "-d", "-s", &session, "-x", "160", "-y", "20"]) {
        eprintln!("{e}");
        return None;
    }
    let ran = tmux(&[
        "pipe-pane",
        "-t",
        &session,
        &format!("cat >> '{}'", log.display()),
    ])
    .and_then(|()| {
        tmux(&[
            "send-keys",
            "-t",
            &session,
            &format!(
                "{command}; tmux -S '{}' wait-for -S {session}",
                socket.display()
            ),
            "Enter",
        ])
    })
    .and_then(|()| tmux(&["wait-for", &session]));
    let _ = tmux(&["kill-server"]);
    // tmux started: a failure from here on is the test's, not a missing tmux.
    if let Err(e) = ran {
        panic!("{e}");
    }
    Some(String::from_utf8_lossy(&std::fs::read(&log).unwrap_or_default()).into_owned())
}

#[test]
fn the_bars_show_their_totals_in_a_terminal() {
    let dir = tempfile::tempdir().unwrap();
    let long = dir.path().join("long.pcap");
    // 30 copies of the fixture: 60 full frames (the partial one is the last copy's).
    common::repeated(&common::crossroad(), 30, &long);
    let total = frames_total(&long, &DecoderOptions::default(), &(0..=u32::MAX)).unwrap();
    let exe = assert_cmd::cargo::cargo_bin("lidar-noise");
    for (call, (what, args)) in [
        ("run", format!("run {} -o out", long.display())),
        ("convert", format!("convert {} -o frames", long.display())),
        (
            "run --frames 2..9",
            format!("run {} --frames 2..9 -o out8", long.display()),
        ),
    ]
    .into_iter()
    .enumerate()
    {
        let Some(log) = in_tmux(&format!("'{}' {args}", exe.display()), dir.path(), call) else {
            // `.ci/run` installs tmux and requires the check.
            assert!(
                std::env::var_os("LIDAR_NOISE_REQUIRE_TMUX").is_none(),
                "tmux cannot run, and LIDAR_NOISE_REQUIRE_TMUX is set"
            );
            eprintln!("SKIPPED: tmux is not installed or cannot start (apt-get install tmux)");
            return;
        };
        let want = if what.contains("--frames") { 8 } else { total };
        // The first draw already has the total (0/N or further); never a bare count.
        assert!(
            log.contains(&format!("/{want} frames")),
            "{what}: no \"/{want} frames\" in the terminal: {log:?}"
        );
    }
}
