//! One writer per output folder, and results that appear all at once or not at all.
//!
//! `OutputFolder::lock` takes an exclusive lock on `DIR/.lidar-noise.lock` (a second run
//! into the same folder fails at once) and removes what a killed run left (hidden
//! `.*.staging-*` folders and `.*.tmp` files). Each capture's results are written into a
//! hidden staging folder beside their target (`DIR/.NAME.staging-PID`) and renamed into
//! place only when every capture of the run succeeded; on failure or on a signal the
//! staging folders are deleted, and a folder the run created is removed again.

use crate::error::{Error, Result};
use crate::signals;
use std::fs::{self, File};
use std::path::{Path, PathBuf};

/// Name of the lock file inside an output folder.
pub const LOCK_FILE: &str = ".lidar-noise.lock";

/// An output folder this process holds the lock of.
pub struct OutputFolder {
    dir: PathBuf,
    created: bool,
    _lock: File,
}

impl OutputFolder {
    /// Creates `dir` if needed, locks it and removes what killed runs left in it.
    pub fn lock(dir: &Path) -> Result<Self> {
        if dir.exists() && !dir.is_dir() {
            return Err(Error::Invalid(format!(
                "{}: the output folder is a file, not a folder",
                dir.display()
            )));
        }
        let created = !dir.exists();
        fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
        let lock_path = dir.join(LOCK_FILE);
        let file = File::options()
            .create(true)
            .truncate(false)
            .write(true)
            .open(&lock_path)
            .map_err(|e| Error::io(&lock_path, e))?;
        match file.try_lock() {
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
        remove_stale(dir);
        if created {
            signals::critical(|g| g.created_folder(dir, &lock_path));
        }
        Ok(OutputFolder {
            dir: dir.to_path_buf(),
            created,
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
    signals::critical(|g| {
        for mut s in staged {
            let old = s.path.with_extension("old");
            if s.target.exists() {
                fs::rename(&s.target, &old).map_err(|e| Error::io(&s.target, e))?;
            }
            fs::rename(&s.path, &s.target).map_err(|e| Error::io(&s.target, e))?;
            g.unregister(&s.path);
            s.done = true;
            signals::remove_path(&old);
        }
        Ok(())
    })
}

/// Moves every file of a staging folder into `dir` (the folder the files belong in, for
/// commands such as `convert` whose output folder is the target itself), replacing files
/// of the same name, with signals held off; then deletes the staging folder.
pub fn commit_files(mut staged: Staged, dir: &Path) -> Result<()> {
    signals::critical(|g| {
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
}
