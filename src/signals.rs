//! SIGINT and SIGTERM: remove what an interrupted run was writing, then exit 130 or 143.
//!
//! Files and folders that must not outlive the process (temporary files, staging folders)
//! are registered here while they exist. A signal takes the registry's lock, deletes every
//! registered path and exits with 128 + the signal number. Sections that must not be cut
//! in half (renaming a finished staging folder into place) run under the same lock, so a
//! signal waits for them to finish. SIGKILL cannot be caught: what it leaves behind is
//! hidden (`.NAME.*.tmp`, `.NAME.staging-PID`) and removed by the next run into the folder.

use std::path::{Path, PathBuf};
use std::sync::{Mutex, MutexGuard, Once};

#[derive(Default)]
struct Registry {
    paths: Vec<PathBuf>,
    /// Folders this process created, with their lock file: removed on a signal when
    /// nothing else is in them, so an interrupted first run leaves no empty folder.
    created: Vec<(PathBuf, PathBuf)>,
    exiting: bool,
}

static REGISTRY: Mutex<Registry> = Mutex::new(Registry {
    paths: Vec::new(),
    created: Vec::new(),
    exiting: false,
});
static INSTALL: Once = Once::new();

fn registry() -> MutexGuard<'static, Registry> {
    // A panic while holding the lock leaves the list itself intact.
    let guard = REGISTRY.lock().unwrap_or_else(|e| e.into_inner());
    if guard.exiting {
        // The process is exiting on a signal: create nothing more.
        drop(guard);
        loop {
            std::thread::park();
        }
    }
    guard
}

/// Installs the SIGINT/SIGTERM handler (once per process; later calls do nothing).
pub fn install() {
    INSTALL.call_once(|| {
        use signal_hook::consts::{SIGINT, SIGTERM};
        let Ok(mut signals) = signal_hook::iterator::Signals::new([SIGINT, SIGTERM]) else {
            return;
        };
        std::thread::spawn(move || {
            if let Some(signal) = signals.forever().next() {
                let mut reg = REGISTRY.lock().unwrap_or_else(|e| e.into_inner());
                reg.exiting = true;
                for path in reg.paths.iter().rev() {
                    remove_path(path);
                }
                for (dir, lock) in &reg.created {
                    let only_lock = std::fs::read_dir(dir).is_ok_and(|entries| {
                        entries.filter_map(|e| e.ok()).all(|e| e.path() == *lock)
                    });
                    if only_lock {
                        let _ = std::fs::remove_file(lock);
                        let _ = std::fs::remove_dir(dir);
                    }
                }
                std::process::exit(128 + signal);
            }
        });
    });
}

/// Runs `f` with the registry locked (a signal waits until `f` is done) and lets it
/// register paths through the `Guarded` handle.
pub fn critical<T>(f: impl FnOnce(&mut Guarded<'_>) -> T) -> T {
    let mut reg = registry();
    f(&mut Guarded(&mut reg))
}

/// Access to the registry inside `critical`.
pub struct Guarded<'a>(&'a mut Registry);

impl Guarded<'_> {
    /// Registers a path to delete on a signal.
    pub fn register(&mut self, path: &Path) {
        self.0.paths.push(path.to_path_buf());
    }

    /// Registers a folder this process created and its lock file: on a signal both are
    /// removed if nothing else is in the folder.
    pub fn created_folder(&mut self, dir: &Path, lock: &Path) {
        self.0.created.push((dir.to_path_buf(), lock.to_path_buf()));
    }

    /// Forgets a path (it was renamed into place or removed).
    pub fn unregister(&mut self, path: &Path) {
        if let Some(i) = self.0.paths.iter().rposition(|p| p == path) {
            self.0.paths.remove(i);
        }
    }
}

/// Registers a path to delete on a signal.
pub fn register(path: &Path) {
    critical(|g| g.register(path));
}

/// Forgets a registered path.
pub fn unregister(path: &Path) {
    critical(|g| g.unregister(path));
}

/// Deletes a file or a folder with its contents, ignoring errors (best effort cleanup).
pub fn remove_path(path: &Path) {
    match std::fs::symlink_metadata(path) {
        Ok(m) if m.is_dir() => {
            // A staging folder's marker goes last, so that a kill in the middle leaves a
            // folder the next run still knows as a leftover of ours.
            let marker = crate::writers::staging::STAGING_MARKER;
            if let Ok(entries) = std::fs::read_dir(path) {
                for e in entries.filter_map(|e| e.ok()) {
                    if e.file_name() != marker {
                        let p = e.path();
                        match e.file_type() {
                            Ok(t) if t.is_dir() => {
                                let _ = std::fs::remove_dir_all(&p);
                            }
                            _ => {
                                let _ = std::fs::remove_file(&p);
                            }
                        }
                    }
                }
            }
            let _ = std::fs::remove_dir_all(path);
        }
        Ok(_) => {
            let _ = std::fs::remove_file(path);
        }
        Err(_) => {}
    }
}
