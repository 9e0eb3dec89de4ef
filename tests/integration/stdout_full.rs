//! A full standard output is an error with a message and exit 1, never a panic (issue 30,
//! defect 7: `stages`, `completions`, `validate`, `compare` exited 101 with "failed printing
//! to stdout").

use std::process::{Command, Stdio};

#[test]
fn every_command_that_prints_exits_1_with_a_message_on_a_full_stdout() {
    let Ok(full) = std::fs::OpenOptions::new().write(true).open("/dev/full") else {
        eprintln!("SKIPPED: /dev/full is absent on this system");
        return;
    };
    let root = env!("CARGO_MANIFEST_DIR");
    let paper = format!("{root}/configs/paper.toml");
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let made = Command::new(env!("CARGO_BIN_EXE_lidar-noise"))
        .args(["--quiet", "run", "--frames", "0", "--no-ply", "-o"])
        .arg(&out)
        .status()
        .unwrap();
    assert!(made.success());
    let results = out.to_string_lossy().into_owned();
    let calls: Vec<Vec<&str>> = vec![
        vec!["stages"],
        vec!["stages", "--markdown"],
        vec!["completions", "bash"],
        vec!["validate", &paper],
        vec!["validate", &paper, "--print"],
        vec!["man"],
        vec!["compare", &results, &results],
        vec!["info", "--json", "fixtures/crossroad.pcap"],
    ];
    for args in calls {
        let o = Command::new(env!("CARGO_BIN_EXE_lidar-noise"))
            .current_dir(root)
            .args(&args)
            .stdout(Stdio::from(full.try_clone().unwrap()))
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(1), "{args:?}: {err}");
        assert!(!err.contains("panicked"), "{args:?}: {err}");
        assert!(err.contains("No space left"), "{args:?}: {err}");
    }
}
