//! All-or-nothing file output: write to a temporary file beside the target, rename on success.
//!
//! A crash, an error or Ctrl-C mid-write leaves at most a stray `.NAME.*.tmp` file (removed
//! on drop where the process survives), never a truncated output. Paths that are inputs of
//! the run are refused as targets so a typo cannot overwrite a capture.
//!
//! Built on `tempfile` (reviewed for issue 33): [`temp_file_for`] makes the hidden
//! temporary with `tempfile::Builder` and both writers finish with
//! `NamedTempFile::persist` (a rename in the same folder; the temporary is deleted on
//! drop). What this module adds is what `tempfile` does not do:
//! - refusing the run's inputs as targets, by canonical path and by device and inode
//!   ([`refuse_inputs`]: another spelling, a symbolic link or a hard link to a capture);
//! - refusing to rename over anything but a regular file ([`refuse_special`]): rename(2)
//!   does not follow a symbolic link but replaces the link itself, and over a device node
//!   would replace the node; `persist` does either silently, we refuse and say why;
//! - registering the temporary for deletion on SIGINT/SIGTERM (`tempfile` deletes on
//!   drop, which a signal's exit skips);
//! - mode 0644 rather than `tempfile`'s 0600, so outputs read like any file.
//!
//! Like `persist`, nothing here calls fsync: the rename is atomic against a crash of the
//! process (never a truncated file), not against a power loss, where a file system may
//! keep an empty file. Outputs are reproducible, so rerunning is the recovery; an fsync
//! of the file and its folder made writing a small file about 25 times slower on ext4,
//! which a sweep writing hundreds of cells would pay on each.

use crate::error::{Error, Result};
use std::fs;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

/// Size of the write buffer of a streamed file ([`AtomicFile`]).
const BUFFER_BYTES: usize = 1 << 20;

/// Size of the write buffer of [`write_atomically`]. Writes at least this large go to the
/// file directly (most documents are encoded whole and written in one call); smaller
/// writes are gathered. A small buffer is recycled by the allocator from file to file,
/// where a fresh 1 MiB one cost page faults for every file.
const DOCUMENT_BUFFER_BYTES: usize = 64 << 10;

/// Writes `path` through `write`, atomically, refusing to overwrite any of `protected_inputs`.
///
/// `write` receives a buffered writer onto a temporary file created in `path`'s folder
/// (so the final rename never crosses file systems). Only when `write` returns `Ok` and
/// the buffer is flushed is the file renamed onto `path`, replacing any existing file.
/// The folder must exist. The file gets mode 0644 on Unix (temporary files are 0600).
pub fn write_atomically<F>(path: &Path, protected_inputs: &[&Path], write: F) -> Result<()>
where
    F: FnOnce(&mut dyn Write) -> std::io::Result<()>,
{
    refuse_inputs(path, protected_inputs)?;
    refuse_special(path)?;
    // Registered so that SIGINT/SIGTERM deletes it; created under the registry's lock so
    // that no temporary file can appear unregistered.
    let mut tmp = crate::signals::critical(|g| {
        let tmp = temp_file_for(path)?;
        g.register(tmp.path());
        Ok::<_, Error>(tmp)
    })?;
    let tmp_path = tmp.path().to_path_buf();
    let result = (|| {
        {
            let mut out = BufWriter::with_capacity(DOCUMENT_BUFFER_BYTES, tmp.as_file_mut());
            write(&mut out).map_err(|e| Error::io(path, e))?;
            out.flush().map_err(|e| Error::io(path, e))?;
        }
        tmp.persist(path).map_err(|e| Error::io(path, e.error))?;
        Ok(())
    })();
    crate::signals::unregister(&tmp_path);
    result
}

/// A file written over time (streamed) that appears at its path only when complete.
///
/// The streaming counterpart of [`write_atomically`] for outputs too large to produce in
/// one call: the bytes go to a temporary file beside the target (registered so that
/// SIGINT/SIGTERM deletes it), [`AtomicFile::commit`] renames it onto the target, and
/// dropping it uncommitted (an error, a panic) deletes it, so no partial output is left.
pub struct AtomicFile {
    out: Option<BufWriter<tempfile::NamedTempFile>>,
    path: PathBuf,
    tmp_path: PathBuf,
}

impl AtomicFile {
    /// Starts writing `path`, refusing to overwrite any of `protected_inputs`.
    pub fn create(path: &Path, protected_inputs: &[&Path]) -> Result<Self> {
        Self::with_buffer(path, protected_inputs, BUFFER_BYTES)
    }

    /// [`AtomicFile::create`] with a write buffer of `bytes` (files written side by
    /// side, as a sweep's cells, each keep one).
    pub fn with_buffer(path: &Path, protected_inputs: &[&Path], bytes: usize) -> Result<Self> {
        refuse_inputs(path, protected_inputs)?;
        refuse_special(path)?;
        let tmp = crate::signals::critical(|g| {
            let tmp = temp_file_for(path)?;
            g.register(tmp.path());
            Ok::<_, Error>(tmp)
        })?;
        Ok(AtomicFile {
            tmp_path: tmp.path().to_path_buf(),
            out: Some(BufWriter::with_capacity(bytes, tmp)),
            path: path.to_path_buf(),
        })
    }

    /// The final path (for messages).
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Appends `bytes`; an error names the final path.
    pub fn write_all(&mut self, bytes: &[u8]) -> Result<()> {
        let out = self.out.as_mut().expect("written only before commit");
        out.write_all(bytes).map_err(|e| Error::io(&self.path, e))
    }

    /// Flushes the bytes and renames the temporary file onto the path.
    pub fn commit(mut self) -> Result<()> {
        let out = self.out.take().expect("committed once");
        let tmp = out
            .into_inner()
            .map_err(|e| Error::io(&self.path, e.into_error()))?;
        tmp.persist(&self.path)
            .map_err(|e| Error::io(&self.path, e.error))?;
        Ok(())
    }
}

/// Streams bytes into the file (errors do not name it: see [`AtomicFile::write_all`]).
impl Write for AtomicFile {
    fn write(&mut self, bytes: &[u8]) -> std::io::Result<usize> {
        self.out
            .as_mut()
            .ok_or_else(|| std::io::Error::other("written after commit"))?
            .write(bytes)
    }
    fn flush(&mut self) -> std::io::Result<()> {
        self.out.as_mut().map_or(Ok(()), Write::flush)
    }
}

impl Drop for AtomicFile {
    fn drop(&mut self) {
        // The temporary file itself is deleted by `NamedTempFile` (when not persisted).
        drop(self.out.take());
        crate::signals::unregister(&self.tmp_path);
    }
}

/// Creates the temporary file that will become `path`: in the same folder, hidden, mode
/// 0644 on Unix. Persist it with `NamedTempFile::persist(path)` once complete.
pub fn temp_file_for(path: &Path) -> Result<tempfile::NamedTempFile> {
    let dir = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let name = path
        .file_name()
        .ok_or_else(|| Error::Invalid(format!("{}: not a file name", path.display())))?;
    let prefix = format!(".{}.", name.to_string_lossy());
    let mut builder = tempfile::Builder::new();
    // Six random characters: the shape by which the next run's clean-up knows the file
    // as ours (`staging::OutputFolder::remove_leftovers`).
    builder.prefix(&prefix).suffix(".tmp").rand_bytes(6);
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        builder.permissions(fs::Permissions::from_mode(0o644));
    }
    builder.tempfile_in(&dir).map_err(|e| Error::io(path, e))
}

/// Refuses to replace anything but a regular file at `path`: renaming over a device node,
/// a FIFO or a symbolic link would replace it with our file (as root, `/dev/full` itself).
pub fn refuse_special(path: &Path) -> Result<()> {
    let Ok(meta) = fs::symlink_metadata(path) else {
        return Ok(());
    };
    let t = meta.file_type();
    if t.is_file() {
        return Ok(());
    }
    let kind = if t.is_symlink() {
        "a symbolic link"
    } else if t.is_dir() {
        "a folder"
    } else {
        "a special file (device, FIFO or socket)"
    };
    Err(Error::Invalid(format!(
        "{}: is {kind}; lidar-noise writes regular files only: give the path of a new or \
         regular file",
        path.display()
    )))
}

/// Errors when `target` names the same file as one of `inputs`.
///
/// Paths are compared canonicalized (symlinks and `..` resolved; a target that does not
/// exist yet is resolved through its folder), and on Unix also by device and inode so a
/// hard link to an input is caught too.
pub fn refuse_inputs(target: &Path, inputs: &[&Path]) -> Result<()> {
    if inputs.is_empty() {
        return Ok(());
    }
    let target_meta = fs::metadata(target).ok();
    let mut target_resolved = None;
    for input in inputs {
        let input_meta = fs::metadata(input).ok();
        // A target that does not exist cannot name an input that does (resolved, both
        // would be one existing path), so the usual case, a new file, skips the path
        // walks of canonicalizing both (a dozen system calls per written file).
        if target_meta.is_none() && input_meta.is_some() {
            continue;
        }
        let same_path = match (
            target_resolved.get_or_insert_with(|| resolve(target)),
            resolve(input),
        ) {
            (Some(a), Some(b)) => *a == b,
            _ => false,
        };
        let same_file = match (&target_meta, input_meta) {
            (Some(a), Some(b)) => same_inode(a, &b),
            _ => false,
        };
        if same_path || same_file {
            return Err(Error::Invalid(format!(
                "{}: refusing to overwrite an input file ({})",
                target.display(),
                input.display()
            )));
        }
    }
    Ok(())
}

/// Canonical form of `path`, or of its folder joined with its name when it does not exist.
fn resolve(path: &Path) -> Option<PathBuf> {
    if let Ok(p) = fs::canonicalize(path) {
        return Some(p);
    }
    let name = path.file_name()?;
    let dir = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    fs::canonicalize(dir).ok().map(|d| d.join(name))
}

#[cfg(unix)]
fn same_inode(a: &fs::Metadata, b: &fs::Metadata) -> bool {
    use std::os::unix::fs::MetadataExt;
    a.dev() == b.dev() && a.ino() == b.ino()
}

#[cfg(not(unix))]
fn same_inode(_: &fs::Metadata, _: &fs::Metadata) -> bool {
    false
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tmp_entries(dir: &Path) -> Vec<String> {
        fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .filter(|n| n.ends_with(".tmp"))
            .collect()
    }

    #[test]
    fn writes_and_replaces_on_success() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("out.txt");
        fs::write(&out, "old").unwrap();
        write_atomically(&out, &[], |w| w.write_all(b"new contents")).unwrap();
        assert_eq!(fs::read_to_string(&out).unwrap(), "new contents");
        assert!(tmp_entries(dir.path()).is_empty());
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            let mode = fs::metadata(&out).unwrap().permissions().mode() & 0o777;
            assert_eq!(mode, 0o644);
        }
    }

    #[test]
    fn failure_keeps_old_file_and_leaves_no_temporary() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("out.txt");
        fs::write(&out, "old").unwrap();
        let err = write_atomically(&out, &[], |w| {
            w.write_all(b"partial")?;
            Err(std::io::Error::other("disk on fire"))
        })
        .unwrap_err();
        assert!(err.to_string().contains("out.txt"), "{err}");
        assert!(err.to_string().contains("disk on fire"), "{err}");
        assert_eq!(fs::read_to_string(&out).unwrap(), "old");
        assert!(tmp_entries(dir.path()).is_empty());
    }

    #[test]
    fn refuses_inputs_by_other_spellings_symlinks_and_hard_links() {
        let dir = tempfile::tempdir().unwrap();
        let input = dir.path().join("capture.pcap");
        fs::write(&input, "precious").unwrap();
        let sub = dir.path().join("sub");
        fs::create_dir(&sub).unwrap();
        let dotted = sub.join("..").join("capture.pcap");
        let mut targets = vec![input.clone(), dotted];
        #[cfg(unix)]
        {
            let link = dir.path().join("link.pcap");
            std::os::unix::fs::symlink(&input, &link).unwrap();
            let hard = dir.path().join("hard.pcap");
            fs::hard_link(&input, &hard).unwrap();
            targets.push(link);
            targets.push(hard);
        }
        for target in &targets {
            let err = write_atomically(target, &[&input], |w| w.write_all(b"x")).unwrap_err();
            assert!(err.to_string().contains("refusing to overwrite"), "{err}");
        }
        assert_eq!(fs::read_to_string(&input).unwrap(), "precious");
        // A different file in the same folder is fine.
        let other = dir.path().join("frame.ply");
        write_atomically(&other, &[&input], |w| w.write_all(b"x")).unwrap();
        assert_eq!(fs::read(&other).unwrap(), b"x");
    }

    #[test]
    fn streamed_file_appears_only_when_committed() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("big.pcap");
        fs::write(&out, "old").unwrap();
        let mut f = AtomicFile::create(&out, &[]).unwrap();
        f.write_all(b"first ").unwrap();
        assert_eq!(fs::read_to_string(&out).unwrap(), "old", "not yet replaced");
        assert_eq!(tmp_entries(dir.path()).len(), 1);
        f.write_all(b"second").unwrap();
        f.commit().unwrap();
        assert_eq!(fs::read_to_string(&out).unwrap(), "first second");
        assert!(tmp_entries(dir.path()).is_empty());
        // Dropped before commit: the old file stays and no temporary is left.
        let mut f = AtomicFile::create(&out, &[]).unwrap();
        f.write_all(b"partial").unwrap();
        drop(f);
        assert_eq!(fs::read_to_string(&out).unwrap(), "first second");
        assert!(tmp_entries(dir.path()).is_empty());
        // Inputs are refused before anything is created.
        let input = dir.path().join("in.pcap");
        fs::write(&input, "precious").unwrap();
        let err = AtomicFile::create(&input, &[&input]).err().unwrap();
        assert!(err.to_string().contains("refusing to overwrite"), "{err}");
        assert!(tmp_entries(dir.path()).is_empty());
    }

    #[test]
    fn missing_folder_is_an_error_naming_the_target() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("no/such/dir/out.ply");
        let err = write_atomically(&out, &[], |w| w.write_all(b"x")).unwrap_err();
        assert!(err.to_string().contains("out.ply"), "{err}");
    }
}
