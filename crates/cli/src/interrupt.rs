//! Ctrl-C during training: the first stops the run after the current step
//! with a checkpoint, the second ends the process at once.

use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

/// The flag a training loop checks between steps, set by the first Ctrl-C
/// (or SIGTERM, SIGHUP). A second one ends the process at once: its
/// temporaries (a checkpoint or model half written) and its lock go; a run
/// folder `out` this command created goes too unless it holds a
/// checkpoint, the user's progress.
pub fn stop_training_on_interrupt(out: &Path) -> Arc<AtomicBool> {
    let stop = Arc::new(AtomicBool::new(false));
    let flag = Arc::clone(&stop);
    let out = out.to_path_buf();
    let installed = ctrlc::set_handler(move || {
        if flag.swap(true, Ordering::SeqCst) {
            let progress =
                mfm_train::checkpoint::list_checkpoints(&out).is_ok_and(|c| !c.is_empty());
            if progress {
                mfm_files::interrupt::clean_up_temporaries();
                eprintln!(
                    "\nmfm: killed; removed this command's temporaries, the run's checkpoints are intact"
                );
            } else {
                mfm_files::interrupt::clean_up();
                eprintln!("\nmfm: killed; removed what this command had written");
            }
            mfm_files::interrupt::exit_now(130);
        }
        eprintln!(
            "\nmfm: stopping after this step and writing a checkpoint (Ctrl-C again to kill)"
        );
    });
    if let Err(e) = installed {
        eprintln!(
            "mfm: warning: cannot install the Ctrl-C handler ({e}); Ctrl-C will lose the steps since the last checkpoint"
        );
    }
    stop
}
