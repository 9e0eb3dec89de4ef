//! Output folders (issue 13 item 5): a rerun into a folder holding another run's results is
//! refused (exit 3, naming --force) and leaves them untouched; --force replaces the
//! capture's folder whole; files lidar-noise did not write are never deleted, even with
//! --force.

use crate::common;

use std::path::Path;
use std::process::Output;

use common::{bin2 as bin, crossroad, EXIT_REFUSED};

fn run(out: &Path, extra: &[&str]) -> Output {
    bin()
        .args(["--quiet", "run"])
        .arg(crossroad())
        .args(["--frames", "0..1", "-o"])
        .arg(out)
        .args(extra)
        .output()
        .unwrap()
}

fn names(dir: &Path) -> Vec<String> {
    common::files(dir)
        .into_keys()
        .map(|p| p.to_string_lossy().into_owned())
        .collect()
}

fn refused(o: &Output) -> String {
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    assert_eq!(o.status.code(), Some(EXIT_REFUSED), "{err}");
    err
}

#[test]
fn run_rerun_same_settings_replaces_with_the_same_bytes() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("out");
    assert!(run(&out, &["--seed", "3"]).status.success());
    let first = common::files(&out);
    assert!(first.contains_key(Path::new("crossroad/frame_00001.ply")));
    let o = run(&out, &["--seed", "3"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert_eq!(common::files(&out), first);
}

#[test]
fn run_other_seed_is_refused_and_force_replaces_the_folder_whole() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("out");
    assert!(run(&out, &["--seed", "3"]).status.success());
    let before = common::files(&out);

    let err = refused(&run(&out, &["--seed", "4"]));
    assert!(err.contains("--force"), "{err}");
    assert!(err.contains("another run"), "{err}");
    assert!(err.contains("seed"), "{err}");
    assert!(err.contains("crossroad"), "{err}");
    assert_eq!(
        common::files(&out),
        before,
        "refused run changed the folder"
    );

    // --force with other options: nothing of the earlier run stays (no PLY with --no-ply).
    let o = run(&out, &["--seed", "4", "--no-ply", "--force"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let after = names(&out.join("crossroad"));
    assert_eq!(
        after,
        vec![
            ".lidar-noise.json",
            "clusters.csv",
            "clusters.json",
            "summary.json"
        ],
        "stale files of the earlier run remain"
    );
    let summary = std::fs::read_to_string(out.join("crossroad/summary.json")).unwrap();
    assert!(summary.contains("--seed 4"), "{summary}");
}

#[test]
fn foreign_files_are_refused_even_with_force_and_kept() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("out");
    assert!(run(&out, &[]).status.success());
    let notes = out.join("crossroad/my-notes.txt");
    std::fs::write(&notes, "mine").unwrap();
    let before = common::files(&out);
    for extra in [&[][..], &["--force"][..], &["--seed", "9", "--force"][..]] {
        let err = refused(&run(&out, extra));
        assert!(err.contains("my-notes.txt"), "{err}");
        assert!(err.contains("did not write"), "{err}");
        assert_eq!(common::files(&out), before, "{extra:?}");
    }
    assert_eq!(std::fs::read_to_string(&notes).unwrap(), "mine");
}

#[test]
fn folders_without_a_manifest_are_another_run_unless_only_our_names() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("out");
    // Results of an older version (no manifest): our names, unknown settings.
    std::fs::create_dir_all(out.join("crossroad")).unwrap();
    std::fs::write(out.join("crossroad/frame_00007.ply"), "old").unwrap();
    std::fs::write(out.join("crossroad/summary.json"), "{}").unwrap();
    let err = refused(&run(&out, &[]));
    assert!(err.contains("--force"), "{err}");
    assert!(run(&out, &["--force"]).status.success());
    assert!(!out.join("crossroad/frame_00007.ply").exists());
    assert!(out.join("crossroad/frame_00001.ply").exists());
}

#[test]
fn convert_other_frames_refused_and_force_leaves_no_stale_frame() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("frames");
    let convert = |extra: &[&str]| {
        bin()
            .args(["--quiet", "convert"])
            .arg(crossroad())
            .arg("-o")
            .arg(&out)
            .args(extra)
            .output()
            .unwrap()
    };
    assert!(convert(&["--frames", "0..2"]).status.success());
    let before = common::files(&out);
    assert!(convert(&["--frames", "0..2"]).status.success());
    assert_eq!(common::files(&out), before);
    let err = refused(&convert(&["--frames", "0"]));
    assert!(err.contains("--force") && err.contains("frames"), "{err}");
    assert_eq!(common::files(&out), before);
    assert!(convert(&["--frames", "0", "--force"]).status.success());
    let left: Vec<String> = names(&out)
        .into_iter()
        .filter(|n| n.starts_with("frame_"))
        .collect();
    assert_eq!(left, vec!["frame_00000.ply"]);

    std::fs::write(out.join("README.txt"), "mine").unwrap();
    let err = refused(&convert(&["--frames", "1", "--force"]));
    assert!(err.contains("README.txt"), "{err}");
    assert!(out.join("README.txt").exists() && out.join("frame_00000.ply").exists());
}

#[test]
fn sweep_of_another_plan_refused_same_plan_resumes_force_replaces() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("sweep");
    let sweep = |vary: &str, extra: &[&str]| {
        bin()
            .args(["--quiet", "sweep"])
            .arg(crossroad())
            .args(["--vary", vary, "--frames", "0", "-o"])
            .arg(&out)
            .args(extra)
            .output()
            .unwrap()
    };
    assert!(sweep("rain.rate_mm_h=0,3", &[]).status.success());
    let before = common::files(&out);
    // The same plan again: resume (every cell loaded), same bytes.
    assert!(sweep("rain.rate_mm_h=0,3", &[]).status.success());
    assert_eq!(common::files(&out), before);
    // Another plan: refused, nothing changed.
    let err = refused(&sweep("occlusion=on,off", &[]));
    assert!(err.contains("--force") && err.contains("varies"), "{err}");
    assert_eq!(common::files(&out), before);
    // --force: the other plan's cells, tables and plots are gone.
    let o = sweep("occlusion=on,off", &["--force"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let cells: Vec<String> = names(&out)
        .into_iter()
        .filter(|n| n.starts_with("cells/"))
        .collect();
    assert_eq!(cells.len(), 2, "{cells:?}");
    assert!(cells.iter().all(|c| c.contains("occlusion=")), "{cells:?}");
    // Every plot left is one the new sweep wrote (its manifest lists them); the earlier
    // plan had a plot per metric over the rain rate, the new one (on/off) has none.
    let manifest: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join(".lidar-noise.json")).unwrap()).unwrap();
    let listed: Vec<&str> = manifest["files"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| f.as_str().unwrap())
        .collect();
    let plots_before = before
        .keys()
        .filter(|p| p.starts_with("plots") && !listed.contains(&&*p.to_string_lossy()))
        .count();
    assert!(plots_before > 0, "the earlier plan drew no plot of its own");
    for p in names(&out).iter().filter(|n| n.starts_with("plots/")) {
        assert!(listed.contains(&p.as_str()), "stale plot {p}");
    }
}

#[test]
fn a_capture_named_dot_pcap_gets_a_folder_of_its_own_and_reruns_do_not_hang() {
    // Issue 30, defect 3: `..pcap` (stem `.`) made the results folder `DIR/.`, whose
    // rename failed and deadlocked the process; a leftover `.NAME.old` of a killed run
    // made every rerun hang the same way.
    let dir = tempfile::tempdir().unwrap();
    let capture = dir.path().join("..pcap");
    std::fs::copy(crossroad(), &capture).unwrap();
    let out = dir.path().join("out");
    for extra in [&[][..], &["--force"][..]] {
        let o = bin()
            .args(["--quiet", "run"])
            .arg(&capture)
            .args(["--frames", "0", "-o"])
            .arg(&out)
            .args(extra)
            .timeout(std::time::Duration::from_secs(300))
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        assert!(out.join("capture./summary.json").is_file());
    }
    std::fs::create_dir_all(out.join(".crossroad.old/x")).unwrap();
    for _ in 0..2 {
        let o = bin()
            .args(["--quiet", "run"])
            .arg(crossroad())
            .args(["--frames", "0", "--force", "-o"])
            .arg(&out)
            .timeout(std::time::Duration::from_secs(300))
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    }
    assert!(out.join("crossroad/summary.json").is_file());
}
