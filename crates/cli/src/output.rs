//! The output guard every command runs before it writes
//! ([`mfm_files::Outputs::prepare`]), and the lock of the folder a command
//! writes ([`mfm_files::FolderLock`]).

use anyhow::Result;
use std::path::{Path, PathBuf};

pub use mfm_files::ensure_empty_dir as ensure_empty;

/// Refuses outputs that are inputs, lie in an input folder or a folder
/// another command owns, name one file twice or are not regular files,
/// and `implicit` outputs (written without the user naming them, the
/// companions of `outputs[0]`) that exist when `outputs[0]` does not;
/// creates the outputs' folders, and returns the [`mfm_files::Undo`] of
/// what the command creates.
pub fn prepare_outputs(
    inputs: &[Option<&Path>],
    outputs: &[PathBuf],
    implicit: &[PathBuf],
) -> Result<mfm_files::Undo> {
    let guard = mfm_files::Outputs::new().inputs(inputs.iter().flatten());
    let guard = match outputs.first() {
        Some(main) => implicit
            .iter()
            .fold(guard.outputs(outputs), |g, p| g.implicit(p, main)),
        None => guard.outputs(implicit),
    };
    Ok(guard.prepare()?)
}

/// Locks the folder `dir` a command writes (a run, dataset, sample or
/// report folder) for this process, naming its command line: a second
/// writer is refused naming this one. Held until dropped.
///
/// # Errors
/// [`mfm_files::FileError::Locked`] naming the holder.
pub fn lock_folder(dir: &Path) -> Result<mfm_files::FolderLock> {
    let command: Vec<String> = std::env::args().collect();
    Ok(mfm_files::FolderLock::acquire(dir, &command.join(" "))?)
}

/// Locks the folder `dir` an `mfm dataset` command fills and checks it is
/// empty. When the lock was left by an `mfm dataset` command that was
/// killed (SIGKILL, a crash) and the folder holds only what such a command
/// writes ([`mfm_data::layout::EXPERIMENT_ENTRIES`]), that half-made
/// experiment is removed first, and said.
///
/// # Errors
/// [`mfm_files::FileError::Locked`]; a folder that is not empty.
pub fn claim_dataset_folder(dir: &Path) -> Result<mfm_files::FolderLock> {
    let lock = lock_folder(dir)?;
    if let Some(holder) = lock.taken_over()
        && holder.contains(" dataset ")
        && let Ok(entries) = std::fs::read_dir(dir)
    {
        let names: Vec<std::ffi::OsString> = entries.flatten().map(|e| e.file_name()).collect();
        let ours = |n: &std::ffi::OsString| {
            n.to_str().is_some_and(|n| {
                n.starts_with('.') || mfm_data::layout::EXPERIMENT_ENTRIES.contains(&n)
            })
        };
        if !names.is_empty() && names.iter().all(ours) {
            mfm_files::interrupt::remove_stale_temporaries(dir, None);
            for name in &names {
                let path = dir.join(name);
                if path.is_dir() {
                    let _ = std::fs::remove_dir_all(&path);
                } else {
                    let _ = std::fs::remove_file(&path);
                }
            }
            eprintln!(
                "note: {} held what a killed command left ({holder}); removed it",
                dir.display()
            );
        }
    }
    ensure_empty(dir)?;
    Ok(lock)
}

/// Installs the handler of SIGINT, SIGTERM and SIGHUP of every command but
/// `train` (which checkpoints instead): it removes what the command had
/// created, temporaries, half-filled folders and its lock included
/// ([`mfm_files::interrupt::clean_up`]), and exits with status 130.
pub fn clean_up_on_interrupt() {
    let installed = ctrlc::set_handler(|| {
        mfm_files::interrupt::clean_up();
        eprintln!("\nmfm: interrupted; removed what this command had written");
        mfm_files::interrupt::exit_now(130);
    });
    if let Err(e) = installed {
        eprintln!(
            "mfm: warning: cannot install the interrupt handler ({e}); an interrupt may leave temporary files"
        );
    }
}

/// Signals that come before `main` installs the command's own handler (a
/// network build spends its first fraction of a second in libtorch's
/// start-up, before any Rust code runs) end the process as an interrupt
/// does: status 130, with nothing written yet to remove. Installed by
/// [`crate::preinit`], before every shared library's initializers; the
/// command's handler replaces it.
#[cfg(target_os = "linux")]
pub(crate) mod early_signals {
    /// What the early handler prints (one `write`, async-signal-safe).
    const MESSAGE: &[u8] = b"\nmfm: interrupted while starting; nothing was written\n";

    extern "C" fn exit_interrupted(_: libc::c_int) {
        // SAFETY: write and _exit are async-signal-safe; MESSAGE is static.
        unsafe {
            libc::write(2, MESSAGE.as_ptr().cast(), MESSAGE.len());
            libc::_exit(130);
        }
    }

    /// Installs the early handler for SIGINT, SIGTERM and SIGHUP.
    pub(crate) fn install() {
        // SAFETY: a zeroed sigaction with a handler and an empty mask is
        // valid; nothing else runs yet in this process.
        unsafe {
            let mut action: libc::sigaction = std::mem::zeroed();
            action.sa_sigaction = exit_interrupted as *const () as libc::sighandler_t;
            libc::sigemptyset(&mut action.sa_mask);
            for signal in [libc::SIGINT, libc::SIGTERM, libc::SIGHUP] {
                libc::sigaction(signal, &action, std::ptr::null_mut());
            }
        }
    }
}
