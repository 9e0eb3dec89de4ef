//! Unit tests of `staging`.

use super::*;

#[test]
fn second_lock_fails_at_once_and_names_the_folder() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let first = OutputFolder::lock(&out).unwrap();
    let err = OutputFolder::lock(&out).err().unwrap().to_string();
    assert!(err.contains("another lidar-noise run"), "{err}");
    assert!(err.contains("out"), "{err}");
    drop(first);
    OutputFolder::lock(&out).unwrap();
}

#[test]
fn failed_stage_leaves_nothing_and_created_folder_goes() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let folder = OutputFolder::lock(&out).unwrap();
    let s = folder.stage("cap").unwrap();
    fs::write(s.path().join("frame.ply"), "x").unwrap();
    drop(s);
    folder.abandon();
    assert!(!out.exists());
}

#[test]
fn commit_replaces_the_target_whole() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    fs::create_dir_all(out.join("cap")).unwrap();
    fs::write(out.join("cap/old.ply"), "old").unwrap();
    let folder = OutputFolder::lock(&out).unwrap();
    let s = folder.stage("cap").unwrap();
    fs::write(s.path().join("new.ply"), "new").unwrap();
    commit(vec![s]).unwrap();
    let names: Vec<String> = fs::read_dir(out.join("cap"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert_eq!(names, vec!["new.ply".to_string()]);
    let hidden: Vec<String> = fs::read_dir(&out)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with('.') && n != LOCK_FILE)
        .collect();
    assert!(hidden.is_empty(), "{hidden:?}");
}

#[test]
fn a_failed_commit_returns_an_error_and_restores_instead_of_deadlocking() {
    // Issue 30, defect 3: a failed rename returned while the signal registry's lock
    // was held, and dropping the remaining staging folders took the same lock.
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    fs::create_dir_all(out.join("b")).unwrap();
    fs::write(out.join("b/old.ply"), "old b").unwrap();
    // A leftover of a killed run under the old fixed name must not matter either.
    fs::create_dir_all(out.join(".a.old/x")).unwrap();
    let folder = OutputFolder::lock(&out).unwrap();
    let a = folder.stage("a").unwrap();
    fs::write(a.path().join("new.ply"), "new a").unwrap();
    let b = folder.stage("b").unwrap();
    let c = folder.stage("c").unwrap();
    // b's staging folder vanishes: its rename fails.
    fs::remove_dir_all(b.path()).unwrap();
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        let r = commit(vec![a, b, c]);
        tx.send(r.map_err(|e| e.to_string())).unwrap();
    });
    // Generous: it returns at once, or never when it deadlocks.
    let r = rx
        .recv_timeout(std::time::Duration::from_secs(120))
        .expect("commit deadlocked");
    let err = r.expect_err("the failed rename is an error");
    assert!(err.contains("b"), "{err}");
    // a was committed; b's earlier results are back; c was not committed and its
    // staging folder is gone; the registry still works.
    assert_eq!(fs::read_to_string(out.join("a/new.ply")).unwrap(), "new a");
    assert_eq!(fs::read_to_string(out.join("b/old.ply")).unwrap(), "old b");
    assert!(!out.join("c").exists());
    let left: Vec<String> = fs::read_dir(&out)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.contains(".staging-"))
        .collect();
    assert!(left.is_empty(), "{left:?}");
    signals::register(&out.join("probe"));
    signals::unregister(&out.join("probe"));
}

fn refused(r: anyhow::Result<Vec<String>>) -> String {
    let e = r.expect_err("accepted");
    assert!(e.downcast_ref::<Refused>().is_some(), "{e}");
    e.to_string()
}

#[test]
fn check_replace_tells_reruns_other_runs_and_foreign_files_apart() {
    let dir = tempfile::tempdir().unwrap();
    let t = dir.path().join("cap");
    let ours = |f: &str| f.ends_with(".ply");
    let none = |_: &str| false;
    let a = serde_json::json!({"seed": 1, "frames": [0, 3]});
    let b = serde_json::json!({"seed": 2, "frames": [0, 3]});
    // Missing and empty folders take anything.
    assert!(check_replace(&t, "run", &a, &ours, &none, false, &[])
        .unwrap()
        .is_empty());
    fs::create_dir_all(&t).unwrap();
    fs::write(t.join("frame_00000.ply"), "x").unwrap();
    fs::write(t.join("summary.json"), "{}").unwrap();
    write_manifest(
        &t,
        "run",
        &a,
        vec!["frame_00000.ply".into(), "summary.json".into()],
    )
    .unwrap();
    let files = check_replace(&t, "run", &a, &ours, &none, false, &[]).unwrap();
    assert_eq!(files, vec!["frame_00000.ply", "summary.json"]);
    let e = refused(check_replace(&t, "run", &b, &ours, &none, false, &[]));
    assert!(e.contains("--force") && e.contains("different seed"), "{e}");
    assert!(!e.contains("frames"), "{e}");
    let e = refused(check_replace(&t, "convert", &a, &ours, &none, false, &[]));
    assert!(e.contains("lidar-noise run"), "{e}");
    assert_eq!(
        check_replace(&t, "run", &b, &ours, &none, true, &[])
            .unwrap()
            .len(),
        2
    );
    // Leftovers of killed runs are not foreign; a file of someone else is.
    fs::write(t.join(".frame_00000.ply.x1Y2z3.tmp"), "").unwrap();
    check_replace(&t, "run", &a, &ours, &none, false, &[]).unwrap();
    // An empty temporary, whatever its target: a write killed before its first bytes.
    fs::write(t.join(".cell.json.Ab12Cd.tmp"), "").unwrap();
    check_replace(&t, "run", &a, &ours, &none, false, &[]).unwrap();
    fs::write(t.join(".cell.json.Ab12Cd.tmp"), "mine").unwrap();
    let e = refused(check_replace(&t, "run", &a, &ours, &none, true, &[]));
    assert!(e.contains(".cell.json.Ab12Cd.tmp"), "{e}");
    fs::remove_file(t.join(".cell.json.Ab12Cd.tmp")).unwrap();
    fs::write(t.join("notes.txt"), "mine").unwrap();
    let e = refused(check_replace(&t, "run", &a, &ours, &none, true, &[]));
    assert!(
        e.contains("notes.txt") && e.contains("even with --force"),
        "{e}"
    );
    // Issue 30, 4: beside a manifest, a file that merely looks like an output (the
    // command's names) is not ours either; without one, the names decide.
    fs::remove_file(t.join("notes.txt")).unwrap();
    fs::write(t.join("frame_00099.ply"), "mine").unwrap();
    let e = refused(check_replace(&t, "run", &a, &ours, &none, true, &[]));
    assert!(e.contains("frame_00099.ply"), "{e}");
    let cells = |f: &str| f == "frame_00099.ply";
    check_replace(&t, "run", &a, &ours, &cells, false, &[]).unwrap();
    fs::remove_file(t.join(MANIFEST)).unwrap();
    let legacy = |f: &str| ours(f) || f == "summary.json";
    check_replace(&t, "run", &a, &legacy, &none, true, &[]).unwrap();
    // An input among the results is a plain error.
    let input = t.join("frame_00000.ply");
    let e = check_replace(&t, "run", &a, &ours, &none, true, &[&input]).unwrap_err();
    assert!(e.downcast_ref::<Refused>().is_none(), "{e}");
}

#[test]
fn remove_results_keeps_what_is_asked_and_prunes_empty_folders() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    fs::create_dir_all(d.join("plots/a")).unwrap();
    fs::create_dir_all(d.join("cells/a")).unwrap();
    for f in [
        "plots/a/x.png",
        "cells/a/1.json",
        "cells/a/2.json",
        "sweep.csv",
    ] {
        fs::write(d.join(f), "").unwrap();
    }
    let files = result_files(d);
    remove_results(d, &files, &|f| f == "cells/a/2.json");
    assert_eq!(result_files(d), vec!["cells/a/2.json"]);
    assert!(!d.join("plots").exists());
}
fn entries(dir: &Path) -> Vec<String> {
    let mut out: Vec<String> = result_files_all(dir);
    out.sort();
    out
}

/// Every file under `dir`, hidden or not (relative paths).
fn result_files_all(dir: &Path) -> Vec<String> {
    let mut out = Vec::new();
    let mut stack = vec![(dir.to_path_buf(), String::new())];
    while let Some((d, prefix)) = stack.pop() {
        for e in fs::read_dir(&d).unwrap() {
            let e = e.unwrap();
            let name = format!("{prefix}{}", e.file_name().to_string_lossy());
            if e.file_type().unwrap().is_dir() {
                stack.push((e.path(), format!("{name}/")));
            } else {
                out.push(name);
            }
        }
    }
    out
}

#[test]
fn leftovers_go_only_when_proved_ours_and_only_when_asked() {
    // Issue 30, 4: every `.*.tmp` and `.*.staging-*` in the folder and two levels
    // below went at start-up, the user's too, even when the run was then refused.
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let user = [
        ".draft.tmp",
        ".x.tmp/frame_00000.ply",
        ".notes.staging-12/mine.txt",
        "cap/.mine.txt.Ab12Cd.tmp",
        "cap/.frame_00001.ply.tmp",
        "plots/a/.draft.tmp",
    ];
    for f in user {
        let p = out.join(f);
        fs::create_dir_all(p.parent().unwrap()).unwrap();
        fs::write(&p, "mine").unwrap();
    }
    // Ours: a killed run's staging folder (marked), earlier results a killed commit
    // moved aside (marked, their target back in place), temporaries of our outputs.
    {
        let folder = OutputFolder::lock(&out).unwrap();
        let s = folder.stage("cap").unwrap();
        fs::write(s.path().join("frame_00000.ply"), "new").unwrap();
        signals::unregister(s.path());
        std::mem::forget(s);
    }
    let pid = std::process::id();
    let old = out.join(format!(".cap.staging-{}.old", pid + 1));
    fs::create_dir_all(&old).unwrap();
    fs::write(old.join("frame_00000.ply"), "old").unwrap();
    mark(&old).unwrap();
    for f in [
        "cap/.frame_00001.ply.Ab12Cd.tmp",
        "plots/a/.x.png.Zz09Yy.tmp",
        "..lidar-noise.json.q1W2e3.tmp",
    ] {
        fs::write(out.join(f), "partial").unwrap();
    }
    let ours = |f: &str| f.ends_with(".ply") || f.ends_with(".png");
    let folder = OutputFolder::lock(&out).unwrap();
    // Locking alone removes nothing (a refused run must leave everything).
    assert!(out
        .join(format!(".cap.staging-{pid}/{STAGING_MARKER}"))
        .exists());
    assert!(out.join("cap/.frame_00001.ply.Ab12Cd.tmp").exists());
    folder.remove_leftovers(&ours);
    drop(folder);
    let mut want: Vec<String> = user.iter().map(|f| f.to_string()).collect();
    want.push(LOCK_FILE.into());
    want.sort();
    assert_eq!(entries(&out), want);
}

#[test]
fn a_planted_replacement_cannot_reach_outside_the_folder() {
    // A staging folder is a file in the output folder: one written by someone else
    // must not make the next run delete or move files elsewhere.
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let victim = dir.path().join("victim.txt");
    fs::write(&victim, "keep").unwrap();
    fs::create_dir_all(dir.path().join("elsewhere")).unwrap();
    fs::write(dir.path().join("elsewhere/x.txt"), "keep").unwrap();
    fs::create_dir_all(&out).unwrap();
    #[cfg(unix)]
    std::os::unix::fs::symlink(dir.path().join("elsewhere"), out.join("link")).unwrap();
    for list in [
        r#"["../victim.txt"]"#,
        r#"["/tmp/../victim.txt"]"#,
        r#"["link/x.txt"]"#,
    ] {
        let stage = out.join(".sweep.staging-1");
        fs::create_dir_all(&stage).unwrap();
        mark(&stage).unwrap();
        write_manifest(&stage, "sweep", &serde_json::json!(1), vec![]).unwrap();
        fs::write(stage.join(REPLACES), list).unwrap();
        let e = apply_staged(&stage, &out).unwrap_err().to_string();
        assert!(e.contains("not a path inside"), "{e}");
        drop(OutputFolder::lock(&out).unwrap());
        signals::remove_path(&stage);
    }
    assert_eq!(fs::read_to_string(&victim).unwrap(), "keep");
    assert!(dir.path().join("elsewhere/x.txt").exists());
}

#[test]
fn results_a_killed_commit_moved_aside_are_put_back() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let old = out.join(".cap.staging-7.old");
    fs::create_dir_all(&old).unwrap();
    fs::write(old.join("summary.json"), "old").unwrap();
    mark(&old).unwrap();
    // Put back when the folder is locked, before the run's checks look at it.
    let folder = OutputFolder::lock(&out).unwrap();
    assert_eq!(entries(&out), vec![LOCK_FILE, "cap/summary.json"]);
    folder.remove_leftovers(&|_| false);
    assert_eq!(entries(&out), vec![LOCK_FILE, "cap/summary.json"]);
}

#[test]
fn nested_output_folders_exclude_each_other() {
    // Issue 30, 4: `run -o cc/out` and `convert -o cc/out/big` ran at once, and the
    // run's rename removed what convert wrote.
    let dir = tempfile::tempdir().unwrap();
    let outer = dir.path().join("cc/out");
    let inner = outer.join("big");
    let a = OutputFolder::lock(&outer).unwrap();
    let e = OutputFolder::lock(&inner).err().unwrap().to_string();
    assert!(
        e.contains("another lidar-noise run") && e.contains("contains"),
        "{e}"
    );
    // Refused before writing: the folder it would have created is not left.
    assert!(!inner.exists());
    drop(a);
    let b = OutputFolder::lock_shared(&inner).unwrap();
    let e = OutputFolder::lock(&outer).err().unwrap().to_string();
    assert!(
        e.contains("another lidar-noise run") && e.contains("inside"),
        "{e}"
    );
    // The outer folder had no lock file when the inner run started: found by the
    // walk below the outer folder.
    let other = dir.path().join("dd/out");
    let _e = OutputFolder::lock(&other.join("big")).unwrap();
    let e = OutputFolder::lock(&other).err().unwrap().to_string();
    assert!(
        e.contains("another lidar-noise run") && e.contains("inside"),
        "{e}"
    );
    // Siblings do not conflict, nor does a folder that merely shares a prefix.
    let _c = OutputFolder::lock(&outer.join("small")).unwrap();
    let _d = OutputFolder::lock(&dir.path().join("cc/out2")).unwrap();
    drop(b);
    drop(_c);
    OutputFolder::lock(&outer).unwrap();
}

/// Old results of a sweep-like folder (its own target) and a staged replacement.
fn staged_replacement(out: &Path) -> (OutputFolder, Staged, Vec<String>) {
    fs::create_dir_all(out.join("plots/a")).unwrap();
    for (f, text) in [
        ("table.csv", "old table"),
        ("gone.csv", "old only"),
        ("plots/a/p.png", "old plot"),
    ] {
        fs::write(out.join(f), text).unwrap();
    }
    let old_files = vec![
        "gone.csv".into(),
        "plots/a/p.png".into(),
        "table.csv".into(),
    ];
    write_manifest(out, "sweep", &serde_json::json!(1), old_files).unwrap();
    let folder = OutputFolder::lock(out).unwrap();
    let s = folder.stage("sweep").unwrap();
    fs::create_dir_all(s.path().join("plots/b")).unwrap();
    fs::write(s.path().join("table.csv"), "new table").unwrap();
    fs::write(s.path().join("plots/b/q.png"), "new plot").unwrap();
    let new_files = vec!["plots/b/q.png".into(), "table.csv".into()];
    write_manifest(s.path(), "sweep", &serde_json::json!(2), new_files).unwrap();
    (folder, s, vec!["gone.csv".into(), "plots/a/p.png".into()])
}

fn old_whole(out: &Path) -> bool {
    entries(out)
        == vec![
            MANIFEST,
            LOCK_FILE,
            "gone.csv",
            "plots/a/p.png",
            "table.csv",
        ]
        && fs::read_to_string(out.join("table.csv")).unwrap() == "old table"
        && read_manifest(out).unwrap().settings == serde_json::json!(1)
}

fn new_whole(out: &Path) -> bool {
    entries(out) == vec![MANIFEST, LOCK_FILE, "plots/b/q.png", "table.csv"]
        && fs::read_to_string(out.join("table.csv")).unwrap() == "new table"
        && read_manifest(out).unwrap().settings == serde_json::json!(2)
}

#[test]
fn a_replacement_cut_at_any_step_leaves_the_old_or_is_finished_whole() {
    // Issue 30, 4: an interrupted `sweep --force` left neither the old nor the new
    // results. A failure injected at each step of the commit stands for a kill there.
    let mut steps = 0;
    for k in 1.. {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("out");
        let (folder, s, replaces) = staged_replacement(&out);
        FAIL_AFTER.with(|f| f.set(k));
        let r = commit_into(s, &replaces);
        FAIL_AFTER.with(|f| f.set(0));
        drop(folder);
        if r.is_ok() {
            assert!(new_whole(&out), "{k}: {:?}", entries(&out));
            break;
        }
        steps += 1;
        let e = r.unwrap_err().to_string();
        assert!(e.contains("next lidar-noise run"), "{e}");
        // The next run into the folder finishes the replacement.
        let folder = OutputFolder::lock(&out).unwrap();
        folder.remove_leftovers(&|_| false);
        drop(folder);
        assert!(new_whole(&out), "cut at step {k}: {:?}", entries(&out));
    }
    assert!(steps >= 5, "{steps}");
    // Cut before the staging folder is complete (an error or a kill while writing
    // the new results): the old results stay whole, the staging folder goes.
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let (folder, s, _) = staged_replacement(&out);
    signals::unregister(s.path());
    std::mem::forget(s);
    drop(folder);
    let folder = OutputFolder::lock(&out).unwrap();
    folder.remove_leftovers(&|_| false);
    drop(folder);
    assert!(old_whole(&out), "{:?}", entries(&out));
}
