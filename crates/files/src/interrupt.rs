//! What an interrupted command leaves behind: nothing of its own.
//!
//! Every [`crate::AtomicFile`] temporary, every [`crate::Undo`] that has not
//! been kept and every [`crate::FolderLock`] is registered here while it is
//! alive. A signal handler (the `mfm` binary installs one for SIGINT,
//! SIGTERM and SIGHUP) calls [`clean_up`] before exiting: the temporaries
//! and lock files are removed and every open [`crate::Undo`] is undone
//! (newest first), exactly as if the command had failed. A process killed
//! with SIGKILL cannot clean up; its temporaries carry its PID in their
//! names, and the next command that writes there removes them
//! ([`remove_stale_temporaries`]).

use std::path::PathBuf;
use std::sync::Mutex;
use std::sync::atomic::{AtomicU64, Ordering};

/// What is removed when a command is interrupted.
#[derive(Clone, Debug)]
pub(crate) enum Pending {
    /// A file that is ours alone (a temporary, a lock file).
    File(PathBuf),
    /// A temporary folder that is ours alone, with all in it
    /// ([`TemporaryDir`]).
    Dir(PathBuf),
    /// An open [`crate::Undo`]: its taken folder and created paths.
    Undo {
        owned: Option<PathBuf>,
        created: Vec<PathBuf>,
    },
}

static NEXT: AtomicU64 = AtomicU64::new(1);
static PENDING: Mutex<Vec<(u64, Pending)>> = Mutex::new(Vec::new());

fn pending() -> std::sync::MutexGuard<'static, Vec<(u64, Pending)>> {
    PENDING.lock().unwrap_or_else(|p| p.into_inner())
}

/// Registers `what`; returns its id.
pub(crate) fn register(what: Pending) -> u64 {
    let id = NEXT.fetch_add(1, Ordering::Relaxed);
    pending().push((id, what));
    id
}

/// Replaces the entry `id` (an [`crate::Undo`] that recorded more).
pub(crate) fn update(id: u64, what: Pending) {
    if let Some(entry) = pending().iter_mut().find(|(i, _)| *i == id) {
        entry.1 = what;
    }
}

/// Removes the entry `id` (committed, kept or dropped).
pub(crate) fn forget(id: u64) {
    pending().retain(|(i, _)| *i != id);
}

/// Removes everything registered, newest first, and forgets it: for a
/// signal handler, just before the process exits. Returns how many entries
/// there were.
pub fn clean_up() -> usize {
    let all = std::mem::take(&mut *pending());
    for (_, what) in all.iter().rev() {
        remove(what);
    }
    all.len()
}

/// Removes only the temporaries and lock files ([`crate::AtomicFile`],
/// [`TemporaryDir`], [`crate::FolderLock`]), newest first, and forgets
/// them; open [`crate::Undo`]s stay as they are. For a command whose
/// output already holds the user's progress (a training run with a
/// checkpoint), which an interrupt must not undo. Returns how many were
/// removed.
pub fn clean_up_temporaries() -> usize {
    let mut all = pending();
    let (temporaries, rest): (Vec<_>, Vec<_>) = std::mem::take(&mut *all)
        .into_iter()
        .partition(|(_, what)| !matches!(what, Pending::Undo { .. }));
    *all = rest;
    drop(all);
    for (_, what) in temporaries.iter().rev() {
        remove(what);
    }
    temporaries.len()
}

fn remove(what: &Pending) {
    match what {
        Pending::File(p) => {
            let _ = std::fs::remove_file(p);
        }
        Pending::Dir(p) => remove_dir_being_written(p),
        Pending::Undo { owned, created } => crate::undo::remove(owned.as_deref(), created),
    }
}

/// Removes the folder `dir` that another thread of this process may still
/// be writing into (a checkpoint being filled when the second Ctrl-C
/// comes): a file created after `remove_dir_all` listed the folder makes
/// its last step fail, so it is tried again until the folder is gone (the
/// writer makes a bounded number of files; at most 200 tries, 1 ms apart).
fn remove_dir_being_written(dir: &std::path::Path) {
    for _ in 0..200 {
        match std::fs::remove_dir_all(dir) {
            Ok(()) => return,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return,
            Err(_) => std::thread::sleep(std::time::Duration::from_millis(1)),
        }
    }
}

/// Ends the process at once with `code`, from a signal handler's thread:
/// no exit handlers or static destructors run (libtorch's, torn down while
/// the main thread is inside it, crash the process instead of letting it
/// exit with `code`). Call [`clean_up`] or [`clean_up_temporaries`] first;
/// standard error is unbuffered, so what was printed is out.
pub fn exit_now(code: i32) -> ! {
    #[cfg(unix)]
    {
        // SAFETY: _exit only ends the process; nothing of ours is touched.
        unsafe { libc::_exit(code) }
    }
    #[cfg(not(unix))]
    std::process::exit(code)
}

/// A temporary folder (a checkpoint being written) that an interrupt
/// removes whole while this guard lives. Dropping the guard only forgets
/// the folder: by then it was renamed into place or removed by its writer.
#[derive(Debug)]
#[must_use = "the folder is registered only while the guard lives"]
pub struct TemporaryDir {
    id: u64,
}

impl TemporaryDir {
    /// Registers `dir` (created by the caller, ours alone).
    pub fn register(dir: &std::path::Path) -> Self {
        Self {
            id: register(Pending::Dir(dir.to_path_buf())),
        }
    }
}

impl Drop for TemporaryDir {
    fn drop(&mut self) {
        forget(self.id);
    }
}

/// The PID in the name of an mfm temporary of `name` (or of any name when
/// `name` is `None`): a file `.NAME.PID.N.tmp` ([`crate::AtomicFile`]) or a
/// folder `.NAME.tmp-PID-N` / `.NAME.old-PID-N` (a dataset being written or
/// replaced).
fn temporary_pid(entry: &str, name: Option<&str>) -> Option<u32> {
    let inner = entry.strip_prefix('.')?;
    let (stem, pid) = if let Some(rest) = inner.strip_suffix(".tmp") {
        let mut parts = rest.rsplitn(3, '.');
        let (n, pid, stem) = (parts.next()?, parts.next()?, parts.next()?);
        n.parse::<u64>().ok()?;
        (stem, pid)
    } else {
        let (stem, tail) = inner.rsplit_once('.')?;
        let rest = tail
            .strip_prefix("tmp-")
            .or_else(|| tail.strip_prefix("old-"))?;
        let (pid, n) = rest.split_once('-')?;
        n.parse::<u64>().ok()?;
        (stem, pid)
    };
    if name.is_some_and(|want| want != stem) {
        return None;
    }
    pid.parse().ok()
}

/// Removes from the folder `dir` the temporaries of `name` (of any name when
/// `None`) that an mfm process killed outright left there: those whose PID
/// is no longer a running process (a file `.NAME.PID.N.tmp`, or a folder
/// `.NAME.tmp-PID-N` / `.NAME.old-PID-N`).
/// Temporaries of a live process, this one included, are left alone.
/// Returns how many were removed.
///
/// Cost: one listing of `dir`.
pub fn remove_stale_temporaries(dir: &std::path::Path, name: Option<&str>) -> usize {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return 0;
    };
    let mut removed = 0;
    for e in entries.flatten() {
        let file_name = e.file_name();
        let Some(pid) = file_name.to_str().and_then(|n| temporary_pid(n, name)) else {
            continue;
        };
        if pid == std::process::id() || crate::lock::process_alive(pid) {
            continue;
        }
        let path = e.path();
        let gone = match e.file_type() {
            Ok(t) if t.is_dir() => std::fs::remove_dir_all(&path),
            _ => std::fs::remove_file(&path),
        };
        if gone.is_ok() {
            removed += 1;
        }
    }
    removed
}

#[cfg(test)]
mod tests {
    #[test]
    fn temporary_names_give_their_pid() {
        use super::temporary_pid as pid;
        assert_eq!(pid(".big.npy.123.0.tmp", None), Some(123));
        assert_eq!(pid(".big.npy.123.0.tmp", Some("big.npy")), Some(123));
        assert_eq!(pid(".big.npy.123.0.tmp", Some("other.npy")), None);
        assert_eq!(pid(".train.tmp-77-0", None), Some(77));
        assert_eq!(pid(".train.old-77-3", Some("train")), Some(77));
        for not_ours in [
            "big.npy",
            ".hidden",
            ".x.tmp",
            ".a.b.tmp",
            ".train.tmp-x-0",
            ".t.new-1-2",
        ] {
            assert_eq!(pid(not_ours, None), None, "{not_ours}");
        }
    }
}
