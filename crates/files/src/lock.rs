//! One writer per folder: an exclusive advisory lock a command holds while
//! it writes a run, dataset or sample folder.
//!
//! The lock is the file `.NAME.mfm-lock` beside the folder `NAME` (so a
//! folder that does not exist yet can be locked, and the folder's contents
//! stay the command's own), locked with `flock(LOCK_EX | LOCK_NB)` and
//! holding the holder's PID and command line. The operating system releases
//! the lock when the holder exits, however it exits, so a lock file left by
//! a killed process is stale and simply taken over; where the file system
//! does not support `flock`, the PID in the file decides: a lock whose
//! process is gone is stale. Dropping the [`FolderLock`] removes the file.

use crate::error::FileError;
use std::fs::{self, File, OpenOptions};
use std::io::{self, Read, Seek, Write};
use std::path::{Path, PathBuf};

/// An exclusive lock on a folder; see the [module docs](self).
///
/// # Example
/// ```
/// let dir = tempfile::tempdir().unwrap();
/// let run = dir.path().join("run");
/// let held = mfm_files::FolderLock::acquire(&run, "mfm train").unwrap();
/// // the same process may not take it twice either
/// let err = mfm_files::FolderLock::acquire(&run, "mfm train").unwrap_err();
/// assert!(err.to_string().contains("in use by"));
/// drop(held);
/// assert!(mfm_files::FolderLock::acquire(&run, "mfm train").is_ok());
/// ```
#[derive(Debug)]
pub struct FolderLock {
    path: PathBuf,
    _file: File,
    /// The holder line of a lock file a killed writer left, when this lock
    /// took it over.
    taken_over: Option<String>,
    /// Its entry in [`crate::interrupt`].
    id: u64,
}

impl FolderLock {
    /// Locks `dir` (which need not exist, nor its parents: missing parents
    /// are created, as the command writing `dir` would) for `command`, the
    /// line the refusal of a second writer names.
    ///
    /// # Errors
    /// [`FileError::Locked`] naming the folder and its holder;
    /// [`FileError::Io`] when the lock file cannot be created.
    pub fn acquire(dir: &Path, command: &str) -> Result<Self, FileError> {
        let path = lock_path(dir);
        // `--out a/b/c` with `a/b` not made yet: the command would create
        // the parents anyway, and the lock lives among them
        if let Some(parent) = path.parent()
            && !parent.as_os_str().is_empty()
        {
            fs::create_dir_all(parent).map_err(|e| FileError::io(parent, e))?;
        }
        loop {
            let mut file = OpenOptions::new()
                .read(true)
                .write(true)
                .create(true)
                .truncate(false)
                .open(&path)
                .map_err(|e| FileError::io(&path, e))?;
            let left_by = match try_flock(&file) {
                Ok(true) => holder_of(&mut file),
                Ok(false) => {
                    return Err(FileError::Locked {
                        path: dir.to_path_buf(),
                        holder: holder_of(&mut file),
                    });
                }
                // no flock here (some network file systems): the PID decides
                Err(_) => {
                    let holder = holder_of(&mut file);
                    if let Some(pid) = holder_pid(&holder)
                        && pid != std::process::id()
                        && process_alive(pid)
                    {
                        return Err(FileError::Locked {
                            path: dir.to_path_buf(),
                            holder,
                        });
                    }
                    holder
                }
            };
            // The holder before us may have removed the file after we opened
            // it: then our lock is on a file nobody else sees; start over.
            if !same_file(&file, &path) {
                continue;
            }
            file.set_len(0)
                .and_then(|()| file.rewind())
                .and_then(|()| writeln!(file, "PID {} ({command})", std::process::id()))
                .and_then(|()| file.sync_all())
                .map_err(|e| FileError::io(&path, e))?;
            let id = crate::interrupt::register(crate::interrupt::Pending::File(path.clone()));
            // a holder line in a file nobody holds: its writer was killed
            let taken_over = holder_pid(&left_by).is_some().then_some(left_by);
            return Ok(Self {
                path,
                _file: file,
                taken_over,
                id,
            });
        }
    }

    /// The lock file.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The holder line (`PID 123 (mfm dataset deform ...)`) of the lock
    /// file a killed writer left, when this lock took it over: what is in
    /// the folder may be that writer's half-finished work. `None` when the
    /// folder was free.
    pub fn taken_over(&self) -> Option<&str> {
        self.taken_over.as_deref()
    }
}

impl Drop for FolderLock {
    fn drop(&mut self) {
        crate::interrupt::forget(self.id);
        // removed while still locked: a waiting writer that opened it finds
        // it gone and takes a fresh one
        let _ = fs::remove_file(&self.path);
    }
}

/// `.NAME.mfm-lock` beside `dir`.
fn lock_path(dir: &Path) -> PathBuf {
    let resolved = crate::guard::absolute_resolved(dir);
    match (resolved.parent(), resolved.file_name()) {
        (Some(parent), Some(name)) => {
            let mut lock = std::ffi::OsString::from(".");
            lock.push(name);
            lock.push(".mfm-lock");
            parent.join(lock)
        }
        _ => resolved.join(".mfm-lock"),
    }
}

/// The first line of the lock file: who holds it.
fn holder_of(file: &mut File) -> String {
    let mut text = String::new();
    let _ = file.rewind().and_then(|()| file.read_to_string(&mut text));
    let line = text.lines().next().unwrap_or("").trim();
    if line.is_empty() {
        "another mfm process".to_owned()
    } else {
        line.to_owned()
    }
}

/// The PID of a holder line `PID N (...)`.
fn holder_pid(holder: &str) -> Option<u32> {
    holder
        .strip_prefix("PID ")?
        .split_whitespace()
        .next()?
        .parse()
        .ok()
}

#[cfg(unix)]
fn try_flock(file: &File) -> io::Result<bool> {
    use std::os::unix::io::AsRawFd;
    // SAFETY: the descriptor is open for the lifetime of `file`.
    let rc = unsafe { libc::flock(file.as_raw_fd(), libc::LOCK_EX | libc::LOCK_NB) };
    if rc == 0 {
        return Ok(true);
    }
    let e = io::Error::last_os_error();
    if e.raw_os_error() == Some(libc::EWOULDBLOCK) {
        Ok(false)
    } else {
        Err(e)
    }
}

#[cfg(not(unix))]
fn try_flock(_: &File) -> io::Result<bool> {
    Err(io::Error::other("no flock on this platform"))
}

/// Whether a process `pid` is running (or exists under another user).
#[cfg(unix)]
pub(crate) fn process_alive(pid: u32) -> bool {
    let Ok(pid) = libc::pid_t::try_from(pid) else {
        return false;
    };
    // SAFETY: signal 0 only checks that the process exists.
    let rc = unsafe { libc::kill(pid, 0) };
    rc == 0 || io::Error::last_os_error().raw_os_error() == Some(libc::EPERM)
}

/// Whether a process `pid` is running: always assumed here.
#[cfg(not(unix))]
pub(crate) fn process_alive(_: u32) -> bool {
    true
}

#[cfg(unix)]
fn same_file(file: &File, path: &Path) -> bool {
    use std::os::unix::fs::MetadataExt;
    match (file.metadata(), fs::metadata(path)) {
        (Ok(a), Ok(b)) => a.dev() == b.dev() && a.ino() == b.ino(),
        _ => false,
    }
}

#[cfg(not(unix))]
fn same_file(_: &File, path: &Path) -> bool {
    path.exists()
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn a_second_writer_is_refused_naming_the_holder_and_a_stale_file_is_taken_over() {
        let dir = tempfile::tempdir().unwrap();
        let run = dir.path().join("run");
        // a lock file left by a killed process: nobody holds its flock
        fs::write(
            dir.path().join(".run.mfm-lock"),
            "PID 999999999 (mfm train)\n",
        )
        .unwrap();
        let held = FolderLock::acquire(&run, "mfm train --out run").unwrap();
        let e = FolderLock::acquire(&run, "mfm sample")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains(&format!("PID {}", std::process::id())) && e.contains("mfm train --out run"),
            "{e}"
        );
        assert!(!run.exists(), "locking creates no folder");
        drop(held);
        assert!(!dir.path().join(".run.mfm-lock").exists());
        assert_eq!(holder_pid("PID 12 (x)"), Some(12));
        assert!(!process_alive(999_999_999));
    }

    #[test]
    fn a_folder_whose_parents_do_not_exist_yet_can_be_locked() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("samples").join("deeper").join("step-100");
        let held = FolderLock::acquire(&out, "mfm sample").unwrap();
        assert!(held.path().exists());
        assert!(!out.exists(), "the folder itself is the command's to make");
        drop(held);
        assert!(
            !dir.path()
                .join("samples/deeper/.step-100.mfm-lock")
                .exists()
        );
    }
}
