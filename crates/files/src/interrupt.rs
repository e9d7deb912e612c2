//! What an interrupted command leaves behind: nothing of its own.
//!
//! Every [`crate::AtomicFile`] temporary, every [`crate::Undo`] that has not
//! been kept and every [`crate::FolderLock`] is registered here while it is
//! alive. A signal handler (the `mfm` binary installs one for SIGINT,
//! SIGTERM and SIGHUP) calls [`clean_up`] before exiting: the temporaries
//! and lock files are removed and every open [`crate::Undo`] is undone
//! (newest first), exactly as if the command had failed. A process killed
//! with SIGKILL cannot clean up; its temporaries carry its PID in their
//! names.

use std::path::PathBuf;
use std::sync::Mutex;
use std::sync::atomic::{AtomicU64, Ordering};

/// What is removed when a command is interrupted.
#[derive(Clone, Debug)]
pub(crate) enum Pending {
    /// A file that is ours alone (a temporary, a lock file).
    File(PathBuf),
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
        match what {
            Pending::File(p) => {
                let _ = std::fs::remove_file(p);
            }
            Pending::Undo { owned, created } => crate::undo::remove(owned.as_deref(), created),
        }
    }
    all.len()
}
