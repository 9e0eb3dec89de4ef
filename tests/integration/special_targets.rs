//! Output targets that are not regular files or folders of their own (issue 30, defect 5):
//! `--junit` over a device, a FIFO or a link; a dangling link at the lock file's name;
//! the root folder as `-o`.

use crate::common::command_at_root as bin;
use std::process::Command;

/// Makes result folders `a` in `dir` to compare.
fn results(dir: &std::path::Path) -> String {
    let out = dir.join("a");
    let o = bin()
        .args(["--quiet", "run", "--frames", "0", "--no-ply", "-o"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    out.to_string_lossy().into_owned()
}

#[test]
fn junit_refuses_links_fifos_and_devices_and_leaves_them_as_they_were() {
    let dir = tempfile::tempdir().unwrap();
    let a = results(dir.path());
    let victim = dir.path().join("victim.txt");
    std::fs::write(&victim, "keep").unwrap();
    let link = dir.path().join("link.xml");
    std::os::unix::fs::symlink(&victim, &link).unwrap();
    let fifo = dir.path().join("fifo.xml");
    let made = Command::new("mkfifo").arg(&fifo).status();
    let mut targets = vec![(link.clone(), "symbolic link")];
    if made.is_ok_and(|s| s.success()) {
        targets.push((fifo.clone(), "special file"));
    } else {
        eprintln!("SKIPPED (FIFO case): mkfifo is not available");
    }
    if std::path::Path::new("/dev/null").exists() {
        targets.push(("/dev/null".into(), "special file"));
    }
    for (target, kind) in targets {
        let o = bin()
            .args(["compare", &a, &a, "--junit"])
            .arg(&target)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert_ne!(o.status.code(), Some(0), "{}: {err}", target.display());
        assert!(err.contains(kind), "{}: {err}", target.display());
        let meta = std::fs::symlink_metadata(&target).unwrap();
        assert!(
            !meta.file_type().is_file(),
            "{} was replaced",
            target.display()
        );
    }
    assert_eq!(std::fs::read_to_string(&victim).unwrap(), "keep");
    // A regular file is still written.
    let ok = dir.path().join("report.xml");
    let o = bin()
        .args(["compare", &a, &a, "--quiet", "--junit"])
        .arg(&ok)
        .output()
        .unwrap();
    assert_eq!(
        o.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(std::fs::read_to_string(&ok).unwrap().contains("testsuite"));
}

#[test]
fn a_dangling_link_at_the_lock_file_creates_nothing_outside_the_folder() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    std::fs::create_dir(&out).unwrap();
    let outside = dir.path().join("outside.lock");
    std::os::unix::fs::symlink(&outside, out.join(".lidar-noise.lock")).unwrap();
    let o = bin()
        .args(["--quiet", "run", "--frames", "0", "--no-ply", "-o"])
        .arg(&out)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(err.contains("symbolic link"), "{err}");
    assert!(!outside.exists(), "a file was created through the link");
}

#[test]
fn the_root_and_system_folders_are_refused_as_output_folders() {
    for target in ["/", "/usr", "/etc/"] {
        let o = bin()
            .args(["--quiet", "run", "--frames", "0", "--no-ply", "-o", target])
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(1), "{target}: {err}");
        assert!(err.contains("system folder"), "{target}: {err}");
    }
    assert!(!std::path::Path::new("/crossroad").exists());
    assert!(!std::path::Path::new("/.lidar-noise.lock").exists());
}
