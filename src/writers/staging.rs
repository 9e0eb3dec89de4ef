//! One writer per output folder, and results that appear all at once or not at all.
//!
//! `OutputFolder::lock` takes an exclusive lock on `DIR/.lidar-noise.lock` (a second run
//! into the same folder fails at once) and removes what a killed run left (hidden
//! `.*.staging-*` folders and `.*.tmp` files). Each capture's results are written into a
//! hidden staging folder beside their target (`DIR/.NAME.staging-PID`) and renamed into
//! place only when every capture of the run succeeded; on failure or on a signal the
//! staging folders are deleted, and a folder the run created is removed again.
//!
//! Each result folder also holds a manifest (`.lidar-noise.json`): the command, the
//! settings that decide its results and the files it wrote. [`check_replace`] reads it to
//! tell a rerun of the same settings (replaced, same bytes) from another run's results
//! (refused unless `--force`), and refuses, even with `--force`, a folder holding files
//! this tool did not write, so that nothing but our own results is ever deleted.

use crate::error::{Error, Result};
use crate::signals;
use std::fs::{self, File};
use std::path::{Path, PathBuf};

/// Name of the lock file inside an output folder.
pub const LOCK_FILE: &str = ".lidar-noise.lock";

/// Name of the manifest in each result folder (the run that wrote it and its files).
pub const MANIFEST: &str = ".lidar-noise.json";

/// An output folder this process holds the lock of.
pub struct OutputFolder {
    dir: PathBuf,
    created: bool,
    _lock: File,
}

impl OutputFolder {
    /// Creates `dir` if needed, locks it and removes what killed runs left in it.
    pub fn lock(dir: &Path) -> Result<Self> {
        Self::lock_as(dir, true)
    }

    /// Creates `dir` if needed and takes a shared lock on it, for the shards of one sweep
    /// or batch that write distinct results into the same folder at the same time: they
    /// exclude an exclusive run (a merge) but not each other. Leftovers are not removed,
    /// since a hidden temporary file may be another shard's work in progress.
    pub fn lock_shared(dir: &Path) -> Result<Self> {
        Self::lock_as(dir, false)
    }

    fn lock_as(dir: &Path, exclusive: bool) -> Result<Self> {
        refuse_system_folder(dir)?;
        if dir.exists() && !dir.is_dir() {
            return Err(Error::Invalid(format!(
                "{}: the output folder is a file, not a folder",
                dir.display()
            )));
        }
        let created = !dir.exists();
        fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
        let lock_path = dir.join(LOCK_FILE);
        let mut options = File::options();
        options.create(true).truncate(false).write(true);
        // Never through a link: a (dangling) link at the lock's name would make us create
        // or lock a file outside the output folder.
        #[cfg(target_os = "linux")]
        {
            use std::os::unix::fs::OpenOptionsExt;
            options.custom_flags(libc::O_NOFOLLOW);
        }
        let file = options.open(&lock_path).map_err(|e| {
            if fs::symlink_metadata(&lock_path).is_ok_and(|m| m.file_type().is_symlink()) {
                Error::Invalid(format!(
                    "{}: is a symbolic link; lidar-noise does not follow links for its lock \
                     file: remove it",
                    lock_path.display()
                ))
            } else {
                Error::io(&lock_path, e)
            }
        })?;
        let locked = if exclusive {
            file.try_lock()
        } else {
            file.try_lock_shared()
        };
        match locked {
            Ok(()) => {}
            Err(fs::TryLockError::WouldBlock) => {
                return Err(Error::Invalid(format!(
                    "{}: another lidar-noise run is writing into this folder (it holds {}); \
                     wait for it to finish or choose another output folder",
                    dir.display(),
                    lock_path.display()
                )))
            }
            Err(fs::TryLockError::Error(e)) => return Err(Error::io(&lock_path, e)),
        }
        if exclusive {
            remove_stale(dir);
        }
        if created && exclusive {
            signals::critical(|g| g.created_folder(dir, &lock_path));
        }
        Ok(OutputFolder {
            dir: dir.to_path_buf(),
            // A shard never removes the folder again: another shard may be writing in it.
            created: created && exclusive,
            _lock: file,
        })
    }

    /// The folder.
    pub fn path(&self) -> &Path {
        &self.dir
    }

    /// A new, empty staging folder for the results that will become `DIR/name`.
    pub fn stage(&self, name: &str) -> Result<Staged> {
        let path = self
            .dir
            .join(format!(".{name}.staging-{}", std::process::id()));
        signals::remove_path(&path);
        signals::critical(|g| {
            fs::create_dir(&path).map_err(|e| Error::io(&path, e))?;
            g.register(&path);
            Ok(Staged {
                path,
                target: self.dir.join(name),
                done: false,
            })
        })
    }
}

/// Refuses the root folder and the system's top-level folders as output folders: the
/// run's clean-up and `--force` act on what is in the folder.
fn refuse_system_folder(dir: &Path) -> Result<()> {
    const SYSTEM: [&str; 16] = [
        "/", "/bin", "/boot", "/dev", "/etc", "/home", "/lib", "/lib32", "/lib64", "/proc",
        "/root", "/run", "/sbin", "/sys", "/usr", "/var",
    ];
    let resolved = fs::canonicalize(dir).unwrap_or_else(|_| dir.to_path_buf());
    if SYSTEM.iter().any(|s| resolved == Path::new(s)) {
        return Err(Error::Invalid(format!(
            "{}: refusing a system folder ({}) as the output folder; give a folder of its \
             own, e.g. -o lidar-noise-out",
            dir.display(),
            resolved.display()
        )));
    }
    Ok(())
}

impl OutputFolder {
    /// Called when the run failed: removes the folder again if this run created it and
    /// nothing but the lock file is in it.
    pub fn abandon(self) {
        if !self.created {
            return;
        }
        let only_lock = fs::read_dir(&self.dir).is_ok_and(|entries| {
            entries
                .filter_map(|e| e.ok())
                .all(|e| e.file_name() == LOCK_FILE)
        });
        if only_lock {
            let _ = fs::remove_file(self.dir.join(LOCK_FILE));
            let _ = fs::remove_dir(&self.dir);
        }
    }
}

/// Removes hidden leftovers of killed runs in `dir` and its subfolders two levels down
/// (the depth of our outputs, e.g. `plots/<capture>/`): `.*.staging-*` folders and
/// `.*.tmp` files. Call it only while holding the folder's lock.
pub fn remove_stale(dir: &Path) {
    remove_stale_below(dir, 2);
}

fn remove_stale_below(dir: &Path, depth: u32) {
    let Ok(entries) = fs::read_dir(dir) else {
        return;
    };
    for e in entries.filter_map(|e| e.ok()) {
        let name = e.file_name().to_string_lossy().into_owned();
        if name.starts_with('.') && (name.contains(".staging-") || name.ends_with(".tmp")) {
            signals::remove_path(&e.path());
        } else if depth > 0 && e.file_type().is_ok_and(|t| t.is_dir()) {
            remove_stale_below(&e.path(), depth - 1);
        }
    }
}

/// A staging folder; deleted on drop unless committed.
pub struct Staged {
    path: PathBuf,
    target: PathBuf,
    done: bool,
}

impl Staged {
    /// Where to write the results.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The folder the results will become.
    pub fn target(&self) -> &Path {
        &self.target
    }
}

impl Drop for Staged {
    fn drop(&mut self) {
        if !self.done {
            signals::remove_path(&self.path);
            signals::unregister(&self.path);
        }
    }
}

/// Renames every staging folder onto its target (replacing an earlier run's results),
/// with signals held off so that no target is left half replaced.
pub fn commit(staged: Vec<Staged>) -> Result<()> {
    // Folders not committed when a rename fails: dropped (unregistered and deleted) only
    // after the registry's lock is released, since their `Drop` takes that lock (dropping
    // them inside `critical` deadlocked, and the signal thread waited on the same lock).
    let mut rest: Vec<Staged> = Vec::new();
    let result = signals::critical(|g| {
        let mut queue = staged.into_iter();
        while let Some(mut s) = queue.next() {
            // The earlier results move aside under a name of this process's own, so that
            // a leftover of a killed run (a partly deleted old folder) never blocks the
            // rename; the start-up clean-up removes such leftovers (`.*.staging-*`).
            let mut old = s.path.clone().into_os_string();
            old.push(".old");
            let old = PathBuf::from(old);
            let had_target = s.target.exists();
            let moved = (|| {
                if had_target {
                    fs::rename(&s.target, &old).map_err(|e| Error::io(&s.target, e))?;
                }
                fs::rename(&s.path, &s.target).map_err(|e| {
                    // Put the earlier results back: a failed commit changes nothing.
                    if had_target {
                        let _ = fs::rename(&old, &s.target);
                    }
                    Error::io(&s.target, e)
                })
            })();
            if let Err(e) = moved {
                rest.push(s);
                rest.extend(queue);
                return Err(e);
            }
            g.unregister(&s.path);
            s.done = true;
            signals::remove_path(&old);
        }
        Ok(())
    });
    drop(rest);
    result
}

/// Moves every file of a staging folder into `dir` (the folder the files belong in, for
/// commands such as `convert` whose output folder is the target itself), after deleting
/// `old` (an earlier run's results, from [`check_replace`]), with signals held off; then
/// deletes the staging folder.
pub fn commit_files(mut staged: Staged, dir: &Path, old: &[String]) -> Result<()> {
    signals::critical(|g| {
        remove_results(dir, old, &|_| false);
        let entries = fs::read_dir(&staged.path).map_err(|e| Error::io(&staged.path, e))?;
        let mut names: Vec<_> = entries
            .filter_map(|e| e.ok())
            .map(|e| e.file_name())
            .collect();
        names.sort();
        for name in names {
            let target = dir.join(&name);
            fs::rename(staged.path.join(&name), &target).map_err(|e| Error::io(&target, e))?;
        }
        signals::remove_path(&staged.path);
        g.unregister(&staged.path);
        staged.done = true;
        Ok(())
    })
}

/// The manifest of a result folder: which command wrote it, with which settings, and
/// which files (relative paths with `/`, sorted).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Manifest {
    /// Always `lidar-noise`.
    pub tool: String,
    /// Tool version that wrote the folder (recorded, not compared).
    pub version: String,
    /// The subcommand (`run`, `convert`, `sweep`).
    pub command: String,
    /// Everything that decides the folder's results.
    pub settings: serde_json::Value,
    /// The files written (a sweep's cells are named by pattern instead).
    pub files: Vec<String>,
}

/// A refused output folder: it holds another run's results (without `--force`) or files
/// this tool did not write. The command exits with [`crate::cli::EXIT_REFUSED`].
#[derive(Debug)]
pub struct Refused(pub String);

impl std::fmt::Display for Refused {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for Refused {}

/// Reads the manifest of `dir`, if there is a readable one.
pub fn read_manifest(dir: &Path) -> Option<Manifest> {
    let bytes = fs::read(dir.join(MANIFEST)).ok()?;
    serde_json::from_slice(&bytes).ok()
}

/// Writes `dir/.lidar-noise.json` (atomically) for `command` with `settings` and `files`.
pub fn write_manifest(
    dir: &Path,
    command: &str,
    settings: &serde_json::Value,
    mut files: Vec<String>,
) -> Result<()> {
    files.sort();
    files.dedup();
    let manifest = Manifest {
        tool: "lidar-noise".into(),
        version: env!("CARGO_PKG_VERSION").into(),
        command: command.into(),
        settings: settings.clone(),
        files,
    };
    let mut bytes = serde_json::to_vec_pretty(&manifest)
        .map_err(|e| Error::Invalid(format!("{}: {e}", dir.join(MANIFEST).display())))?;
    bytes.push(b'\n');
    crate::writers::atomic::write_atomically(&dir.join(MANIFEST), &[], |o| o.write_all(&bytes))
}

/// Files of a folder (relative, `/`-separated, sorted), without hidden leftovers of killed
/// runs, the lock file and the manifest.
pub fn result_files(dir: &Path) -> Vec<String> {
    let mut out = Vec::new();
    list_files(dir, "", &mut out);
    out.retain(|f| f != LOCK_FILE && f != MANIFEST);
    out.sort();
    out
}

fn list_files(dir: &Path, prefix: &str, out: &mut Vec<String>) {
    let Ok(entries) = fs::read_dir(dir) else {
        return;
    };
    for e in entries.filter_map(|e| e.ok()) {
        let name = e.file_name().to_string_lossy().into_owned();
        if is_leftover(&name) {
            continue;
        }
        let rel = format!("{prefix}{name}");
        if e.file_type().is_ok_and(|t| t.is_dir()) {
            list_files(&e.path(), &format!("{rel}/"), out);
        } else {
            out.push(rel);
        }
    }
}

/// True for the hidden temporary names our writers use (`.*.staging-*`, `.*.tmp`).
fn is_leftover(name: &str) -> bool {
    name.starts_with('.') && (name.contains(".staging-") || name.ends_with(".tmp"))
}

/// Checks that `target` may receive the results of `command` run with `settings`, and
/// returns the files of an earlier run in it (to be replaced).
///
/// `ours` tells whether a relative path is one of the command's output names (for folders
/// written before manifests existed). Refused, even with `force`: a file neither named in
/// the manifest nor matching `ours` (it was not written by this tool, and replacing the
/// folder would delete it). Refused without `force`: results of another run (other
/// command or settings, or no manifest to tell). An empty or missing folder and a rerun
/// with the same settings are accepted.
pub fn check_replace(
    target: &Path,
    command: &str,
    settings: &serde_json::Value,
    ours: &dyn Fn(&str) -> bool,
    force: bool,
    inputs: &[&Path],
) -> anyhow::Result<Vec<String>> {
    let files = result_files(target);
    if files.is_empty() {
        return Ok(files);
    }
    // An input kept among the results is never replaced (a plain error, as elsewhere).
    for f in &files {
        crate::writers::atomic::refuse_inputs(&target.join(f), inputs)?;
    }
    let manifest = read_manifest(target);
    let listed = |f: &String| manifest.as_ref().is_some_and(|m| m.files.contains(f));
    let foreign: Vec<&String> = files.iter().filter(|f| !listed(f) && !ours(f)).collect();
    if !foreign.is_empty() {
        let mut names: Vec<String> = foreign.iter().take(5).map(|f| f.to_string()).collect();
        if foreign.len() > 5 {
            names.push(format!("and {} more", foreign.len() - 5));
        }
        return Err(anyhow::Error::new(Refused(format!(
            "{}: holds {} that `lidar-noise {command}` did not write ({}); refusing to \
             write into it, even with --force, so as not to mix results with them or \
             delete them; move them away or choose another output folder",
            target.display(),
            if foreign.len() == 1 {
                "a file"
            } else {
                "files"
            },
            names.join(", ")
        ))));
    }
    let why = match &manifest {
        None => "results without a record of the run that wrote them".to_string(),
        Some(m) if m.command != command => format!("results of `lidar-noise {}`", m.command),
        Some(m) if m.settings != *settings => {
            let mut diff = Vec::new();
            differences(&m.settings, settings, "", &mut diff);
            let more = diff.len().saturating_sub(4);
            diff.truncate(4);
            if more > 0 {
                diff.push(format!("{more} more"));
            }
            format!("results of another run: different {}", diff.join(", "))
        }
        Some(_) => return Ok(files),
    };
    if force {
        return Ok(files);
    }
    Err(anyhow::Error::new(Refused(format!(
        "{}: holds {why}; rerun with --force to replace them (the folder's results are \
         replaced as a whole), or choose another output folder",
        target.display()
    ))))
}

/// Dotted paths where `a` and `b` differ (objects by key, arrays by index).
fn differences(a: &serde_json::Value, b: &serde_json::Value, path: &str, out: &mut Vec<String>) {
    use serde_json::Value;
    let join = |k: &str| {
        if path.is_empty() {
            k.to_string()
        } else {
            format!("{path}.{k}")
        }
    };
    match (a, b) {
        (Value::Object(x), Value::Object(y)) => {
            let mut keys: Vec<&String> = x.keys().chain(y.keys()).collect();
            keys.sort();
            keys.dedup();
            for k in keys {
                match (x.get(k), y.get(k)) {
                    (Some(p), Some(q)) => differences(p, q, &join(k), out),
                    _ => out.push(join(k)),
                }
            }
        }
        (Value::Array(x), Value::Array(y)) if x.len() == y.len() => {
            for (i, (p, q)) in x.iter().zip(y).enumerate() {
                differences(p, q, &format!("{path}[{i}]"), out);
            }
        }
        _ if a != b => out.push(if path.is_empty() {
            "settings".into()
        } else {
            path.to_string()
        }),
        _ => {}
    }
}

/// Deletes `files` (relative to `dir`, results of an earlier run that `check_replace`
/// returned) and the folders they leave empty, except those `keep` selects.
pub fn remove_results(dir: &Path, files: &[String], keep: &dyn Fn(&str) -> bool) {
    for f in files.iter().filter(|f| !keep(f)) {
        let path = dir.join(f);
        let _ = fs::remove_file(&path);
        let mut parent = path.parent();
        while let Some(p) = parent.filter(|p| *p != dir) {
            if fs::remove_dir(p).is_err() {
                break;
            }
            parent = p.parent();
        }
    }
}

#[cfg(test)]
mod tests {
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
        let a = serde_json::json!({"seed": 1, "frames": [0, 3]});
        let b = serde_json::json!({"seed": 2, "frames": [0, 3]});
        // Missing and empty folders take anything.
        assert!(check_replace(&t, "run", &a, &ours, false, &[])
            .unwrap()
            .is_empty());
        fs::create_dir_all(&t).unwrap();
        fs::write(t.join("frame_00000.ply"), "x").unwrap();
        fs::write(t.join("summary.json"), "{}").unwrap();
        write_manifest(&t, "run", &a, vec!["summary.json".into()]).unwrap();
        let files = check_replace(&t, "run", &a, &ours, false, &[]).unwrap();
        assert_eq!(files, vec!["frame_00000.ply", "summary.json"]);
        let e = refused(check_replace(&t, "run", &b, &ours, false, &[]));
        assert!(e.contains("--force") && e.contains("different seed"), "{e}");
        assert!(!e.contains("frames"), "{e}");
        let e = refused(check_replace(&t, "convert", &a, &ours, false, &[]));
        assert!(e.contains("lidar-noise run"), "{e}");
        assert_eq!(
            check_replace(&t, "run", &b, &ours, true, &[])
                .unwrap()
                .len(),
            2
        );
        // Leftovers of killed runs are not foreign; a file of someone else is.
        fs::write(t.join(".frame_00001.ply.x1.tmp"), "").unwrap();
        check_replace(&t, "run", &a, &ours, false, &[]).unwrap();
        fs::write(t.join("notes.txt"), "mine").unwrap();
        let e = refused(check_replace(&t, "run", &a, &ours, true, &[]));
        assert!(
            e.contains("notes.txt") && e.contains("even with --force"),
            "{e}"
        );
        // An input among the results is a plain error.
        fs::remove_file(t.join("notes.txt")).unwrap();
        let input = t.join("frame_00000.ply");
        let e = check_replace(&t, "run", &a, &ours, true, &[&input]).unwrap_err();
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
}
