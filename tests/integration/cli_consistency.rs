//! Command-line consistency: renamed flags keep their old spellings, `validate -c`, the
//! `--set` stage shorthand, `convert` with several captures, examples in every `--help`,
//! `--threads`, `-` for standard input, shell completions and the man page.

use crate::common;

use crate::common::bin;
use lidar_noise::compare::{compare_file, Status, Tolerances};
use std::path::Path;

fn stdout(args: &[&str]) -> String {
    let out = bin().args(args).output().unwrap();
    assert!(
        out.status.success(),
        "{args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout).unwrap()
}

#[test]
fn synth_new_and_old_spellings_write_the_same_capture() {
    let tmp = tempfile::tempdir().unwrap();
    let (a, b) = (tmp.path().join("a"), tmp.path().join("b"));
    let run = |dir: &Path, flags: &[&str]| {
        bin()
            .args(["--quiet", "synth", "--preset", "empty", "--seed", "2", "-o"])
            .arg(dir)
            .args(flags)
            .assert()
            .success();
    };
    run(&a, &["--rotations", "1", "--no-interpolate"]);
    run(&b, &["--frames", "1", "--no-interpolation"]);
    let pcap = |d: &Path| std::fs::read(d.join("empty.pcap")).unwrap();
    assert_eq!(pcap(&a), pcap(&b));
    // The old spellings do not clutter the help.
    let help = stdout(&["synth", "--help"]);
    assert!(
        help.contains("--rotations") && help.contains("--no-interpolate"),
        "{help}"
    );
    assert!(
        !help.contains("--no-interpolation ") && !help.contains("--frames <"),
        "{help}"
    );
}

#[test]
fn validate_takes_c_and_set_takes_the_stage_shorthand() {
    let long = stdout(&["validate", "--print", "--set", "noise[1].rate_mm_h=2.5"]);
    let short = stdout(&["validate", "--print", "--set", "rain.rate_mm_h=2.5"]);
    let body = |t: &str| {
        t.lines()
            .filter(|l| !l.starts_with('#'))
            .collect::<Vec<_>>()
            .join("\n")
    };
    assert_eq!(body(&long), body(&short));
    assert!(short.contains("rate_mm_h = 2.5"), "{short}");
    let config = common::fixtures().join("../configs/rain.toml");
    let c = config.to_str().unwrap();
    assert_eq!(stdout(&["validate", "-c", c]), stdout(&["validate", c]));
    bin().args(["validate", "-c", c, c]).assert().code(2);
}

#[test]
fn every_subcommand_help_ends_with_examples() {
    for cmd in [
        "run",
        "info",
        "convert",
        "validate",
        "synth",
        "sweep",
        "compare",
        "completions",
        "man",
    ] {
        let help = stdout(&[cmd, "--help"]);
        let tail = &help[help
            .find("Examples:")
            .unwrap_or_else(|| panic!("{cmd}: {help}"))..];
        let examples = tail
            .lines()
            .filter(|l| l.trim_start().starts_with("lidar-noise ") || l.contains("| lidar-noise "))
            .count();
        assert!(
            (2..=3).contains(&examples),
            "{cmd}: {examples} examples\n{tail}"
        );
    }
}

#[test]
fn threads_and_stdin_give_the_same_results() {
    let tmp = tempfile::tempdir().unwrap();
    let fixture = common::fixtures().join("crossroad.pcap");
    let run = |dir: &Path, threads: &str, capture: &str, stdin: Option<Vec<u8>>| {
        let mut cmd = bin();
        cmd.args([
            "--quiet",
            "--threads",
            threads,
            "run",
            capture,
            "--frames",
            "0",
            "-o",
        ])
        .arg(dir);
        if let Some(bytes) = stdin {
            cmd.write_stdin(bytes);
        }
        cmd.assert().success();
    };
    let (a, b, c) = (
        tmp.path().join("a"),
        tmp.path().join("b"),
        tmp.path().join("c"),
    );
    run(&a, "1", fixture.to_str().unwrap(), None);
    run(&b, "2", fixture.to_str().unwrap(), None);
    run(&c, "2", "-", Some(std::fs::read(&fixture).unwrap()));
    let files = |d: &Path| common::files(d);
    assert_eq!(files(&a), files(&b), "--threads does not change outputs");
    // From standard input: the capture's folder is `stdin`; the data are the same.
    let t = Tolerances::default();
    for f in ["frame_00000.ply", "clusters.csv"] {
        let status = compare_file(&a.join("crossroad").join(f), &c.join("stdin").join(f), &t);
        assert_eq!(status, Status::Same, "{f}");
    }
    bin()
        .args(["info", "-", "-"])
        .write_stdin(vec![])
        .assert()
        .code(1);
    bin().args(["--threads", "0", "info", "x"]).assert().code(2);
}

#[test]
fn convert_takes_several_captures_into_subfolders() {
    let tmp = tempfile::tempdir().unwrap();
    bin()
        .args(["--quiet", "convert"])
        .arg(common::fixtures().join("crossroad.pcap"))
        .arg(common::fixtures().join("parking.pcap"))
        .args(["--frames", "0", "-o"])
        .arg(tmp.path())
        .assert()
        .success();
    for name in ["crossroad", "parking"] {
        assert!(
            tmp.path().join(name).join("frame_00000.ply").is_file(),
            "{name}"
        );
    }
}

#[test]
fn completions_and_man_page() {
    for shell in ["bash", "zsh", "fish"] {
        let script = stdout(&["completions", shell]);
        assert!(
            script.contains("lidar-noise") && script.contains("compare"),
            "{shell}"
        );
    }
    let man = stdout(&["man"]);
    assert!(
        man.contains(".TH lidar-noise 1"),
        "{}",
        &man[..200.min(man.len())]
    );
    assert!(man.contains("compare"));
}
