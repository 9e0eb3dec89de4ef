//! One writer per output folder, and results that appear all at once or not at all.
//!
//! `OutputFolder::lock` takes an exclusive lock on `DIR/.lidar-noise.lock` (a second run
//! into the same folder fails at once), and shared locks on the lock files of the folders
//! that contain DIR, and it refuses a folder inside or around one another run is writing:
//! a run into `out` renames its results into place and would remove what a run into
//! `out/big` wrote. Each capture's results are written into a hidden staging folder beside
//! their target (`DIR/.NAME.staging-PID`, marked by a `.lidar-noise.staging` file) and
//! renamed into place only when every capture of the run succeeded; on failure or on a
//! signal the staging folders are deleted, and a folder the run created is removed again.
//!
//! What a killed run left is removed by the next run into the folder, after its checks
//! ([`OutputFolder::remove_leftovers`]), and only what proves to be this tool's: staging
//! folders holding the marker or a manifest, earlier results moved aside by a commit
//! (`.NAME.staging-PID.old`, marked the same way), and temporary files named as our
//! writers name them (`.FILE.XXXXXX.tmp`) for a FILE the folder's manifest lists or the
//! command writes. A user's `.draft.tmp` or a results folder named `.x.tmp` stays.
//!
//! Each result folder also holds a manifest (`.lidar-noise.json`): the command, the
//! settings that decide its results and the files it wrote. [`check_replace`] reads it to
//! tell a rerun of the same settings (replaced, same bytes) from another run's results
//! (refused unless `--force`), and refuses, even with `--force`, a folder holding files
//! the manifest does not list, so that nothing but our own results is ever deleted.

use crate::error::{Error, Result};
use crate::signals;
use std::fs::{self, File};
use std::path::{Path, PathBuf};

/// Name of the lock file inside an output folder.
pub const LOCK_FILE: &str = ".lidar-noise.lock";

/// Name of the manifest in each result folder (the run that wrote it and its files).
pub const MANIFEST: &str = ".lidar-noise.json";

/// Name of the marker file in a staging folder (and in earlier results moved aside): it
/// proves the folder is this tool's work, so that a killed run's leftover can be deleted.
pub const STAGING_MARKER: &str = ".lidar-noise.staging";

/// Name of the list of files a staged replacement deletes ([`commit_into`]); written last,
/// so that a staging folder holding it is complete and a killed commit can be finished.
pub const REPLACES: &str = ".lidar-noise.replaces";

/// An output folder this process holds the lock of.
pub struct OutputFolder {
    dir: PathBuf,
    created: bool,
    exclusive: bool,
    repaired: bool,
    _lock: File,
    /// Shared locks on the lock files of the folders containing `dir`.
    _around: Vec<File>,
}

impl OutputFolder {
    /// Creates `dir` if needed and locks it, finishing a replacement a killed run had
    /// started (see [`commit_into`]); call [`OutputFolder::remove_leftovers`] after the
    /// checks to remove what killed runs left.
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
        let had_lock = fs::symlink_metadata(&lock_path).is_ok();
        // Refused before anything was written: a folder (and lock file) this call
        // created goes again.
        let undo = || {
            if !had_lock {
                let _ = fs::remove_file(&lock_path);
            }
            if created {
                let _ = fs::remove_dir(dir);
            }
        };
        let file = open_lock(&lock_path, true).map_err(|e| {
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
                    "{}: another lidar-noise run is writing into this folder or a folder \
                     inside it (it holds {}); wait for it to finish or choose another output \
                     folder",
                    dir.display(),
                    lock_path.display()
                )))
            }
            Err(fs::TryLockError::Error(e)) => return Err(Error::io(&lock_path, e)),
        }
        let around = match lock_nesting(dir) {
            Ok(around) => around,
            Err(e) => {
                drop(file);
                undo();
                return Err(e);
            }
        };
        let repaired = exclusive && finish_commits(dir);
        if created && exclusive {
            signals::critical(|g| g.created_folder(dir, &lock_path));
        }
        Ok(OutputFolder {
            dir: dir.to_path_buf(),
            // A shard never removes the folder again: another shard may be writing in it.
            created: created && exclusive,
            exclusive,
            repaired,
            _lock: file,
            _around: around,
        })
    }

    /// True when locking finished a commit a killed run had left half done (results put
    /// in place or back): checks made before the lock must then be made again.
    pub fn repaired(&self) -> bool {
        self.repaired
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
            let staged = Staged {
                path,
                target: self.dir.join(name),
                done: false,
            };
            // The marker makes the folder recognisably ours should the process be killed.
            mark(&staged.path)?;
            Ok(staged)
        })
    }

    /// Removes what killed runs of this tool left in the folder, and only that: staging
    /// folders holding our marker or a manifest, earlier results a commit moved aside
    /// (put back when their target is missing), and temporary files `.FILE.XXXXXX.tmp`
    /// down to two levels below (the depth of our outputs, e.g. `plots/<capture>/`) whose
    /// FILE (a path relative to the folder) `ours` accepts or the folder's manifest lists.
    /// Call it after the run's checks; shared locks remove nothing (another shard may be
    /// writing).
    pub fn remove_leftovers(&self, ours: &dyn Fn(&str) -> bool) {
        if !self.exclusive {
            return;
        }
        let listed = read_manifest(&self.dir)
            .map(|m| m.files)
            .unwrap_or_default();
        let owns = |rel: &str| rel == MANIFEST || ours(rel) || listed.iter().any(|f| f == rel);
        let Ok(entries) = fs::read_dir(&self.dir) else {
            return;
        };
        for e in entries.filter_map(|e| e.ok()) {
            let name = e.file_name().to_string_lossy().into_owned();
            let path = e.path();
            let is_dir = e.file_type().is_ok_and(|t| t.is_dir());
            if is_dir && is_staging_name(&name) {
                // Earlier results whose target is missing were not put back (see
                // `finish_commits`): they are the only copy, never deleted.
                if moved_aside_target(&self.dir, &name)
                    .is_some_and(|t| fs::symlink_metadata(t).is_err())
                {
                    continue;
                }
                if is_our_staging(&path) {
                    signals::remove_path(&path);
                } else {
                    // An empty one (a kill between the marker and the folder) holds nothing.
                    let _ = fs::remove_dir(&path);
                }
            } else if is_dir {
                remove_temporaries(&path, &format!("{name}/"), 1, &owns);
            } else if temporary_of(&name).is_some_and(&owns) {
                let _ = fs::remove_file(&path);
            }
        }
    }
}

/// Opens (creating if asked) a lock file, never through a link: a (dangling) link at the
/// lock's name would make us create or lock a file outside the output folder.
fn open_lock(path: &Path, create: bool) -> std::io::Result<File> {
    let mut options = File::options();
    if create {
        options.create(true).truncate(false).write(true);
    } else {
        options.read(true);
    }
    #[cfg(target_os = "linux")]
    {
        use std::os::unix::fs::OpenOptionsExt;
        options.custom_flags(libc::O_NOFOLLOW);
    }
    options.open(path)
}

/// Refuses `dir` when another run writes into a folder containing it or inside it, and
/// returns shared locks on the lock files of the folders containing it: held while this
/// run writes, they make a later run into such a folder wait its turn (refused). A run
/// into a folder inside ours is refused by the same test from its side.
fn lock_nesting(dir: &Path) -> Result<Vec<File>> {
    let Ok(resolved) = fs::canonicalize(dir) else {
        return Ok(Vec::new());
    };
    let busy = |other: &Path, lock: &Path, relation: &str| {
        Error::Invalid(format!(
            "{}: another lidar-noise run is writing into {} (it holds {}), {relation}; a run \
             into one would replace or remove what the other writes: wait for it to finish \
             or choose an output folder outside it",
            dir.display(),
            other.display(),
            lock.display()
        ))
    };
    let mut around = Vec::new();
    for folder in resolved.ancestors().skip(1) {
        let lock = folder.join(LOCK_FILE);
        let Ok(file) = open_lock(&lock, false) else {
            continue;
        };
        match file.try_lock_shared() {
            Ok(()) => around.push(file),
            Err(fs::TryLockError::WouldBlock) => {
                return Err(busy(folder, &lock, "which contains this folder"))
            }
            Err(fs::TryLockError::Error(_)) => {}
        }
    }
    // Below: a run inside that started while this folder had no lock file yet (else its
    // shared lock on ours made our lock fail). Bounded, so that `-o .` in a large tree
    // stays cheap: our results lie at most three levels down (`plots/<capture>/x.png`).
    const DEPTH: usize = 4;
    const MAX_FOLDERS: usize = 100_000;
    let mut stack = vec![(resolved, 0usize)];
    let mut seen = 0usize;
    while let Some((d, depth)) = stack.pop() {
        let Ok(entries) = fs::read_dir(&d) else {
            continue;
        };
        for e in entries.filter_map(|e| e.ok()) {
            // Links are not followed: what they point to is not replaced by this run.
            if !e.file_type().is_ok_and(|t| t.is_dir()) {
                continue;
            }
            seen += 1;
            if seen > MAX_FOLDERS {
                return Ok(around);
            }
            let sub = e.path();
            let lock = sub.join(LOCK_FILE);
            if let Ok(file) = open_lock(&lock, false) {
                if let Err(fs::TryLockError::WouldBlock) = file.try_lock() {
                    return Err(busy(&sub, &lock, "which is inside this folder"));
                }
            }
            if depth + 1 < DEPTH {
                stack.push((sub, depth + 1));
            }
        }
    }
    Ok(around)
}

/// Writes the staging marker into `dir`.
fn mark(dir: &Path) -> Result<()> {
    let path = dir.join(STAGING_MARKER);
    let text = format!(
        "{{\"tool\": \"lidar-noise\", \"pid\": {}}}\n",
        std::process::id()
    );
    fs::write(&path, text).map_err(|e| Error::io(&path, e))
}

/// True for the names of staging folders and of results moved aside
/// (`.NAME.staging-SUFFIX`, `.NAME.staging-SUFFIX.old`).
fn is_staging_name(name: &str) -> bool {
    name.starts_with('.') && name.contains(".staging-")
}

/// True when the folder at `path` proves to be this tool's staging folder (or earlier
/// results moved aside by a commit): it holds the marker or a manifest of this tool.
fn is_our_staging(path: &Path) -> bool {
    fs::symlink_metadata(path).is_ok_and(|m| m.is_dir())
        && (fs::symlink_metadata(path.join(STAGING_MARKER)).is_ok_and(|m| m.is_file())
            || read_manifest(path).is_some_and(|m| m.tool == "lidar-noise"))
}

/// The FILE of a temporary file our writers create for it (`.FILE.XXXXXX.tmp`, six
/// letters or digits: see `atomic::temp_file_for`), or None for any other name.
fn temporary_of(name: &str) -> Option<&str> {
    let rest = name.strip_prefix('.')?.strip_suffix(".tmp")?;
    let (file, random) = rest.rsplit_once('.')?;
    (!file.is_empty() && random.len() == 6 && random.bytes().all(|b| b.is_ascii_alphanumeric()))
        .then_some(file)
}

/// Removes the temporary files of `dir` (at `prefix` in the output folder) and of its
/// subfolders `depth` levels down whose FILE `owns` accepts.
fn remove_temporaries(dir: &Path, prefix: &str, depth: u32, owns: &dyn Fn(&str) -> bool) {
    let Ok(entries) = fs::read_dir(dir) else {
        return;
    };
    for e in entries.filter_map(|e| e.ok()) {
        let name = e.file_name().to_string_lossy().into_owned();
        let Ok(t) = e.file_type() else {
            continue;
        };
        if t.is_file() {
            if temporary_of(&name).is_some_and(|f| owns(&format!("{prefix}{f}"))) {
                let _ = fs::remove_file(e.path());
            }
        } else if t.is_dir() && depth > 0 {
            remove_temporaries(&e.path(), &format!("{prefix}{name}/"), depth - 1, owns);
        }
    }
}

/// The target of earlier results a commit moved aside (`DIR/.NAME.staging-PID.old`:
/// `DIR/NAME`), or None for another name.
fn moved_aside_target(dir: &Path, name: &str) -> Option<PathBuf> {
    let (target, _) = name
        .strip_suffix(".old")?
        .strip_prefix('.')?
        .rsplit_once(".staging-")?;
    Some(dir.join(target))
}

/// Finishes what killed commits left half done in `dir`, before the run's checks (which
/// must see the folder as it stands): staging folders holding [`REPLACES`] are complete,
/// and their commit is carried out; earlier results moved aside whose target is missing
/// (killed between the two renames of [`commit`]) are put back. Best effort: what fails
/// stays for a later run, never deleted, as it may hold the only copy of results.
fn finish_commits(dir: &Path) -> bool {
    let Ok(entries) = fs::read_dir(dir) else {
        return false;
    };
    let mut found: Vec<(String, PathBuf)> = entries
        .filter_map(|e| e.ok())
        .filter(|e| e.file_type().is_ok_and(|t| t.is_dir()))
        .map(|e| (e.file_name().to_string_lossy().into_owned(), e.path()))
        .filter(|(name, path)| is_staging_name(name) && is_our_staging(path))
        .collect();
    found.sort();
    let mut changed = false;
    for (name, path) in found {
        if let Some(target) = moved_aside_target(dir, &name) {
            if fs::symlink_metadata(&target).is_err() {
                let _ = fs::remove_file(path.join(STAGING_MARKER));
                let _ = fs::rename(&path, &target);
                changed = true;
            }
        } else if path.join(REPLACES).is_file() {
            let _ = signals::critical(|_| apply_staged(&path, dir));
            changed = true;
        }
    }
    changed
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
            // rename; the next run's clean-up removes such leftovers, or puts them back
            // when a kill came before the new results were in place.
            let mut old = s.path.clone().into_os_string();
            old.push(".old");
            let old = PathBuf::from(old);
            let had_target = s.target.exists();
            // The marker goes before the folder becomes the results (its manifest still
            // marks it as ours until then).
            let _ = fs::remove_file(s.path.join(STAGING_MARKER));
            let moved = (|| {
                if had_target {
                    fs::rename(&s.target, &old).map_err(|e| Error::io(&s.target, e))?;
                    let _ = mark(&old);
                }
                fs::rename(&s.path, &s.target).map_err(|e| {
                    // Put the earlier results back: a failed commit changes nothing.
                    if had_target {
                        let _ = fs::remove_file(old.join(STAGING_MARKER));
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

/// Replaces results in the folder that holds the staging folder (for `sweep` and a
/// one-capture `convert`, whose output folder is their results): the staging folder holds the new files and their
/// manifest (written by the caller, listing them); `replaces` are files of the earlier
/// results to delete (relative paths). The list is written into the staging folder
/// first, which makes it complete: from then on the commit goes to its end even if the
/// process is killed, since the next run into the folder finishes it (see
/// [`OutputFolder::lock`]). Signals are held off meanwhile. Before that point a failure or
/// a kill leaves the earlier results as they were.
pub fn commit_into(mut staged: Staged, replaces: &[String]) -> Result<()> {
    let dir = match staged.path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    if read_manifest(&staged.path).is_none() {
        return Err(Error::Invalid(format!(
            "internal: {}: a staging folder without its manifest cannot be committed",
            staged.path.display()
        )));
    }
    let list = serde_json::to_vec_pretty(replaces)
        .map_err(|e| Error::Invalid(format!("{}: {e}", staged.path.display())))?;
    crate::writers::atomic::write_atomically(&staged.path.join(REPLACES), &[], |o| {
        o.write_all(&list)
    })?;
    signals::critical(|g| {
        // Complete: never deleted from here on (on an error, the next run finishes it).
        g.unregister(&staged.path);
        staged.done = true;
        apply_staged(&staged.path, &dir).map_err(|e| {
            Error::Invalid(format!(
                "{e}; the new results wait complete in {}: the next lidar-noise run into {} \
                 puts them in place",
                staged.path.display(),
                dir.display()
            ))
        })
    })
}

/// Carries out a complete staged replacement (see [`commit_into`]); each step can be
/// repeated, so a commit cut short by a kill is finished by calling it again.
fn apply_staged(stage: &Path, dir: &Path) -> Result<()> {
    let list = stage.join(REPLACES);
    let replaces: Vec<String> = fs::read(&list)
        .ok()
        .and_then(|b| serde_json::from_slice(&b).ok())
        .ok_or_else(|| Error::Invalid(format!("{}: unreadable", list.display())))?;
    // Paths come from files in the output folder, which someone else may have written:
    // only plain relative paths below it, never through a link, are acted on.
    if let Some(bad) = replaces.iter().find(|f| !inside(dir, f)) {
        return Err(Error::Invalid(format!(
            "{}: lists `{bad}`, not a path inside {}",
            list.display(),
            dir.display()
        )));
    }
    // The manifest moves last of the new files: while it is in the staging folder, some
    // of its files may still be there.
    if let Some(manifest) = read_manifest(stage) {
        if let Some(bad) = manifest.files.iter().find(|f| !inside(dir, f)) {
            return Err(Error::Invalid(format!(
                "{}: lists `{bad}`, not a path inside {}",
                stage.join(MANIFEST).display(),
                dir.display()
            )));
        }
        for f in &manifest.files {
            let from = stage.join(f);
            if fs::symlink_metadata(&from).is_err() {
                continue;
            }
            let to = dir.join(f);
            if let Some(parent) = to.parent() {
                fs::create_dir_all(parent).map_err(|e| Error::io(parent, e))?;
            }
            fault_point()?;
            fs::rename(&from, &to).map_err(|e| Error::io(&to, e))?;
        }
        fault_point()?;
        let to = dir.join(MANIFEST);
        fs::rename(stage.join(MANIFEST), &to).map_err(|e| Error::io(&to, e))?;
    }
    for f in &replaces {
        fault_point()?;
        remove_results(dir, std::slice::from_ref(f), &|_| false);
    }
    signals::remove_path(stage);
    Ok(())
}

/// True when `rel` is a relative path of plain names (no `..`, no root) whose folders
/// inside `dir` are not links: acting on `dir/rel` stays inside `dir`.
fn inside(dir: &Path, rel: &str) -> bool {
    use std::path::Component;
    let rel = Path::new(rel);
    if rel.as_os_str().is_empty() || !rel.components().all(|c| matches!(c, Component::Normal(_))) {
        return false;
    }
    let mut at = dir.to_path_buf();
    let mut parts: Vec<_> = rel.components().collect();
    parts.pop();
    parts.into_iter().all(|c| {
        at.push(c);
        fs::symlink_metadata(&at).map_or(true, |m| !m.file_type().is_symlink())
    })
}

#[cfg(test)]
thread_local! {
    /// Steps of [`apply_staged`] left before an injected failure (tests of a killed
    /// commit); 0: none.
    static FAIL_AFTER: std::cell::Cell<usize> = const { std::cell::Cell::new(0) };
}

/// A step of [`apply_staged`]: fails when a test injected a failure here.
fn fault_point() -> Result<()> {
    #[cfg(test)]
    {
        let left = FAIL_AFTER.with(|f| f.get());
        if left == 1 {
            FAIL_AFTER.with(|f| f.set(0));
            return Err(Error::Invalid("injected failure".into()));
        }
        FAIL_AFTER.with(|f| f.set(left.saturating_sub(1)));
    }
    Ok(())
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
    /// Earlier plans this folder's results grew from, oldest first (a sweep given new
    /// values or seeds reuses its finished cells: each entry holds the earlier varied
    /// values and seeds); absent when none.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub growth: Vec<serde_json::Value>,
}

/// A refused output folder: it holds another run's results (without `--force`) or files
/// this tool did not write. The command line exits with code 3 for it (`EXIT_REFUSED`).
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
    files: Vec<String>,
) -> Result<()> {
    write_manifest_grown(dir, command, settings, files, Vec::new())
}

/// [`write_manifest`] of results that grew from earlier plans ([`Manifest::growth`]).
pub fn write_manifest_grown(
    dir: &Path,
    command: &str,
    settings: &serde_json::Value,
    mut files: Vec<String>,
    growth: Vec<serde_json::Value>,
) -> Result<()> {
    files.sort();
    files.dedup();
    let manifest = Manifest {
        tool: "lidar-noise".into(),
        version: env!("CARGO_PKG_VERSION").into(),
        command: command.into(),
        settings: settings.clone(),
        files,
        growth,
    };
    let mut bytes = serde_json::to_vec_pretty(&manifest)
        .map_err(|e| Error::Invalid(format!("{}: {e}", dir.join(MANIFEST).display())))?;
    bytes.push(b'\n');
    crate::writers::atomic::write_atomically(&dir.join(MANIFEST), &[], |o| o.write_all(&bytes))
}

/// Files of a folder (relative, `/`-separated, sorted), without the lock file, the
/// manifest, our staging folders and the temporary files our writers name
/// (`.FILE.XXXXXX.tmp`).
pub fn result_files(dir: &Path) -> Vec<String> {
    files_but_leftovers(dir, &|_| true)
}

/// [`result_files`], skipping only the temporary files whose FILE `owns` accepts.
fn files_but_leftovers(dir: &Path, owns: &dyn Fn(&str) -> bool) -> Vec<String> {
    let mut out = Vec::new();
    list_files(dir, "", owns, &mut out);
    out.retain(|f| ![LOCK_FILE, MANIFEST, STAGING_MARKER, REPLACES].contains(&f.as_str()));
    out.sort();
    out
}

fn list_files(dir: &Path, prefix: &str, owns: &dyn Fn(&str) -> bool, out: &mut Vec<String>) {
    let Ok(entries) = fs::read_dir(dir) else {
        return;
    };
    for e in entries.filter_map(|e| e.ok()) {
        let name = e.file_name().to_string_lossy().into_owned();
        let rel = format!("{prefix}{name}");
        if e.file_type().is_ok_and(|t| t.is_dir()) {
            // Our staging folders (and results moved aside) are leftovers, not results.
            if is_staging_name(&name) && is_our_staging(&e.path()) {
                continue;
            }
            list_files(&e.path(), &format!("{rel}/"), owns, out);
        } else if temporary_of(&name).is_some_and(|f| {
            f == MANIFEST
                || owns(&format!("{prefix}{f}"))
                || owns(&rel)
                || e.metadata().is_ok_and(|m| m.len() == 0)
        }) {
            // A temporary file is a leftover when its target is ours or it proves by
            // its own content that we wrote it (a streamed file killed before its
            // target first existed: `unlisted` reads it); no name pattern of ours ends
            // in `.tmp`. An empty one too: a write killed before its first bytes left
            // the buffer leaves one (a sweep shard killed as a cell starts), and it
            // holds nothing to mix with results or lose.
            continue;
        } else {
            out.push(rel);
        }
    }
}

/// Checks that `target` may receive the results of `command` run with `settings`, and
/// returns the files of an earlier run in it (to be replaced).
///
/// A file is this tool's when the folder's manifest lists it, when `unlisted` accepts it
/// (files that say by their content that this tool wrote them, such as a sweep's cells,
/// which no single manifest can list), or, in a folder without a manifest (written before
/// manifests existed), when its name is one of the command's output names (`ours`).
/// Refused, even with `force`: any other file (replacing the folder would delete it,
/// even one that merely looks like an output, such as a `frame_00099.ply` of the user's
/// beside a manifest that does not list it). Refused without `force`: results of another
/// run (other command or settings, or no manifest to tell). An empty or missing folder
/// and a rerun with the same settings are accepted.
pub fn check_replace(
    target: &Path,
    command: &str,
    settings: &serde_json::Value,
    ours: &dyn Fn(&str) -> bool,
    unlisted: &dyn Fn(&str) -> bool,
    force: bool,
    inputs: &[&Path],
) -> anyhow::Result<Vec<String>> {
    let manifest = read_manifest(target);
    let owns = |f: &str| {
        unlisted(f)
            || match &manifest {
                Some(m) => m.files.iter().any(|x| x == f),
                None => ours(f),
            }
    };
    let files = files_but_leftovers(target, &owns);
    if files.is_empty() {
        return Ok(files);
    }
    // An input kept among the results is never replaced (a plain error, as elsewhere).
    for f in &files {
        crate::writers::atomic::refuse_inputs(&target.join(f), inputs)?;
    }
    let foreign: Vec<&String> = files.iter().filter(|f| !owns(f)).collect();
    if !foreign.is_empty() {
        let mut names: Vec<String> = foreign.iter().take(5).map(|f| f.to_string()).collect();
        if foreign.len() > 5 {
            names.push(format!("and {} more", foreign.len() - 5));
        }
        let listing = if manifest.is_some() {
            " according to its record of the run (.lidar-noise.json)"
        } else {
            ""
        };
        return Err(anyhow::Error::new(Refused(format!(
            "{}: holds {} that `lidar-noise {command}` did not write{listing} ({}); \
             refusing to write into it, even with --force, so as not to mix results with \
             them or delete them; move them away or choose another output folder",
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
mod tests;
