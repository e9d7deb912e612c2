//! The checkpoint format of every training run: atomic checkpoint folders
//! with checksummed files, their integrity checks, pruning, and the record
//! of a finished run's model.
//!
//! A checkpoint is written into a temporary folder (`checkpoints/.tmp-...`),
//! every file synced, `state.json` written last with the size and CRC-32 of
//! the others, and the folder renamed to its final name
//! (`checkpoints/step-000001000`): a crash leaves either the complete
//! checkpoint or a temporary folder that is ignored and cleaned up.
//! [`verify_checkpoint_listing`] re-reads every file and compares sizes and
//! CRC-32s, so a truncated or corrupted file is reported by name before
//! anything is loaded. What a checkpoint holds besides the network, its
//! optimizer and the weight average ([`WEIGHTS_FILE`], [`OPTIMIZER_FILE`],
//! [`EMA_FILE`]) is the run's own description, written by its
//! [`Objective`](crate::Objective).

use std::collections::BTreeMap;
use std::fs::File;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::error::{Result, TrainError};

// The plain-file side of a run folder lives in mfm-files (readers of run
// folders need no libtorch); these are its names here.
pub use mfm_files::run_folder::{
    CheckpointInfo, CheckpointState, FileRecord, LogAccumulator, STATE_FILE, STATE_FORMAT,
    checkpoint_dir, list_checkpoints,
};

/// Network weights (safetensors).
pub const WEIGHTS_FILE: &str = "model.safetensors";
/// Network configuration (JSON), written next to the weights.
pub const NET_CONFIG_FILE: &str = "model.json";
/// The moving average of the weights (safetensors), in checkpoints of runs
/// with a weight average (with its `ema.json`).
pub const EMA_FILE: &str = "ema.safetensors";
/// Adam state (safetensors).
pub const OPTIMIZER_FILE: &str = "optimizer.safetensors";
/// [`FinalModelRecord`] (JSON): checksums of the final model.
pub const FINAL_RECORD_FILE: &str = "model.state.json";
/// The training log (CSV) in the run folder.
pub const LOG_FILE: &str = mfm_files::owned::RUN_LOG;
/// The folder of checkpoints in the run folder.
pub const CHECKPOINTS_DIR: &str = mfm_files::owned::RUN_CHECKPOINTS;

/// Writes `bytes` to `path` with [`mfm_files::write_atomic`]: a temporary
/// file in the same folder, synced, renamed over `path`; removed on failure.
///
/// # Errors
/// [`TrainError::Files`] (`Io`) naming the file (also for a folder, device or FIFO at
/// `path`, which is never replaced).
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    Ok(mfm_files::write_atomic(path, |w| w.write_all(bytes))?)
}

/// Size and CRC-32 of a file.
///
/// # Errors
/// [`TrainError::Files`] (`Io`) naming the file.
pub fn file_record(path: &Path) -> Result<FileRecord> {
    let bytes = std::fs::read(path).map_err(|e| TrainError::io(path, e))?;
    let mut h = crc32fast::Hasher::new();
    h.update(&bytes);
    Ok(FileRecord {
        bytes: bytes.len() as u64,
        crc32: h.finalize(),
    })
}

/// Removes temporary folders left in `checkpoints/` by interrupted writes.
///
/// # Errors
/// [`TrainError::Files`] (`Io`) naming the folder that could not be removed.
pub fn remove_stale_temporaries(run_dir: &Path) -> Result<()> {
    let root = run_dir.join(CHECKPOINTS_DIR);
    let Ok(entries) = std::fs::read_dir(&root) else {
        return Ok(());
    };
    for entry in entries.flatten() {
        let is_tmp = entry
            .file_name()
            .to_str()
            .is_some_and(|n| n.starts_with(".tmp-"));
        if is_tmp {
            let p = entry.path();
            std::fs::remove_dir_all(&p).map_err(|e| TrainError::io(&p, e))?;
        }
    }
    Ok(())
}

/// Reads a checkpoint's `state.json`, checks that it lists the files
/// `required` and checks every file it lists (size, then CRC-32).
///
/// Cost: one read of every file of the checkpoint.
///
/// # Errors
/// [`TrainError::Files`] (`Io`) for a missing or unreadable file,
/// (`Format`) naming the file that is truncated, corrupted, or unparsable,
/// or the required file the state does not list.
pub fn verify_checkpoint_listing(dir: &Path, required: &[&str]) -> Result<CheckpointState> {
    let state_path = dir.join(STATE_FILE);
    let text = std::fs::read_to_string(&state_path).map_err(|e| TrainError::io(&state_path, e))?;
    let state: CheckpointState = serde_json::from_str(&text).map_err(|e| {
        TrainError::format(
            &state_path,
            format!("unreadable checkpoint state (truncated or corrupted?): {e}"),
        )
    })?;
    if state.format != STATE_FORMAT {
        return Err(TrainError::format(
            &state_path,
            format!(
                "checkpoint format {} is not supported (expected {STATE_FORMAT})",
                state.format
            ),
        ));
    }
    for &required in required {
        if !state.files.contains_key(required) {
            return Err(TrainError::format(
                &state_path,
                format!("the checkpoint does not list its {required}"),
            ));
        }
    }
    verify_records(dir, &state.files, "checkpoint file")?;
    Ok(state)
}

/// Compares every file of `records` in `dir` with its recorded size and
/// CRC-32; `what` names the files in the message.
fn verify_records(dir: &Path, records: &BTreeMap<String, FileRecord>, what: &str) -> Result<()> {
    for (name, expected) in records {
        let path = dir.join(name);
        let found = file_record(&path)?;
        if found.bytes != expected.bytes {
            return Err(TrainError::format(
                &path,
                format!(
                    "{what} has {} bytes, expected {} (truncated or overwritten)",
                    found.bytes, expected.bytes
                ),
            ));
        }
        if found.crc32 != expected.crc32 {
            return Err(TrainError::format(
                &path,
                format!(
                    "{what} is corrupted: CRC-32 {:08x}, expected {:08x}",
                    found.crc32, expected.crc32
                ),
            ));
        }
    }
    Ok(())
}

/// `model.state.json` of a run folder: size and CRC-32 of the final model's
/// files, written right after them.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FinalModelRecord {
    /// [`WEIGHTS_FILE`] and [`NET_CONFIG_FILE`], by name.
    pub files: BTreeMap<String, FileRecord>,
}

/// Records the checksums of the final model in `run_dir` ([`FINAL_RECORD_FILE`]).
///
/// # Errors
/// [`TrainError::Files`] (`Io`) naming the file.
pub fn write_final_record(run_dir: &Path) -> Result<()> {
    write_file_record(run_dir, FINAL_RECORD_FILE, &[WEIGHTS_FILE, NET_CONFIG_FILE])
}

/// Records the size and CRC-32 of the files `names` of `dir` in the
/// [`FinalModelRecord`] file `record` (in `dir`): what
/// [`verify_file_record`] checks them against.
///
/// # Errors
/// [`TrainError::Files`] (`Io`) naming the file.
pub fn write_file_record(dir: &Path, record: &str, names: &[&str]) -> Result<()> {
    let mut files = BTreeMap::new();
    for name in names {
        files.insert((*name).to_owned(), file_record(&dir.join(name))?);
    }
    let path = dir.join(record);
    let json = serde_json::to_string_pretty(&FinalModelRecord { files })
        .map_err(|e| TrainError::format(&path, e.to_string()))?;
    write_atomic(&path, json.as_bytes())
}

/// Checks the files recorded in `dir`'s [`FinalModelRecord`] file `record`
/// ([`write_file_record`]); unlike [`verify_final_model`], a missing record
/// is an error: the files beside it cannot be trusted unchecked.
///
/// # Errors
/// [`TrainError::Files`] (`Format`) naming the missing record, or the file
/// that is truncated or corrupted.
pub fn verify_file_record(dir: &Path, record: &str) -> Result<()> {
    let path = dir.join(record);
    if !path.is_file() {
        return Err(TrainError::format(
            &path,
            "missing: the checksums of the model files beside it are gone, so they cannot be \
             checked; copy the whole run folder again, or train the run anew"
                .to_owned(),
        ));
    }
    read_and_verify_record(dir, &path)
}

/// Checks the final model of `run_dir` against its [`FINAL_RECORD_FILE`];
/// a run written before the record existed (no such file) passes.
///
/// # Errors
/// [`TrainError::Files`] (`Format`) naming the file that is truncated or corrupted, or an
/// unreadable record.
pub fn verify_final_model(run_dir: &Path) -> Result<()> {
    let path = run_dir.join(FINAL_RECORD_FILE);
    if !path.exists() {
        return Ok(());
    }
    read_and_verify_record(run_dir, &path)
}

fn read_and_verify_record(dir: &Path, path: &Path) -> Result<()> {
    let text = std::fs::read_to_string(path).map_err(|e| TrainError::io(path, e))?;
    let record: FinalModelRecord = serde_json::from_str(&text).map_err(|e| {
        TrainError::format(
            path,
            format!("unreadable model record (truncated or corrupted?): {e}"),
        )
    })?;
    verify_records(dir, &record.files, "the final model file")
}

/// Refuses to train a run over its final model from step 0: called when
/// resuming finds no valid checkpoint. A run folder holding a final model
/// ([`WEIGHTS_FILE`]) but no checkpoint (deleted, or all damaged) is
/// finished; restarting it would replace that model.
///
/// # Errors
/// [`TrainError::RunFolder`] naming the run and what to do.
pub fn refuse_restart_over_final_model(run_dir: &Path) -> Result<()> {
    if run_dir.join(WEIGHTS_FILE).exists() {
        return Err(TrainError::RunFolder(format!(
            "{}: the run is finished ({WEIGHTS_FILE}) but has no valid checkpoint in \
             {CHECKPOINTS_DIR}/ to continue from; --resume would train over the final model \
             from step 0. Sample the final model as it is, or train a new run with another --out",
            run_dir.display()
        )));
    }
    Ok(())
}

/// Writes the checkpoint after `state.step` steps: `fill` writes the
/// payload files into a fresh temporary folder, then the checksums of every
/// file there go into `state.files`, `state.json` is written, and the folder
/// is renamed to [`checkpoint_dir`] (replacing an older checkpoint of the
/// same step). Returns the final folder. The disk must first have room for
/// a checkpoint as large as the last one ([`mfm_files::space::ensure_space`]);
/// on any failure the temporary folder is removed.
///
/// # Errors
/// Those of `fill`; [`TrainError::Files`] (`Io`) naming the file or folder;
/// (`NoSpace`) when the disk is full, before or while writing.
pub fn write_checkpoint(
    run_dir: &Path,
    state: CheckpointState,
    fill: impl FnOnce(&Path) -> Result<()>,
) -> Result<PathBuf> {
    let root = run_dir.join(CHECKPOINTS_DIR);
    std::fs::create_dir_all(&root).map_err(|e| TrainError::io(&root, e))?;
    // a checkpoint is about as large as the one before it
    let expected = list_checkpoints(run_dir)
        .ok()
        .and_then(|c| c.last().map(|c| folder_bytes(&c.dir)))
        .unwrap_or(0);
    mfm_files::space::ensure_space(&root, expected)?;
    let tmp = root.join(format!(
        ".tmp-step-{:09}-{}",
        state.step,
        std::process::id()
    ));
    if tmp.exists() {
        std::fs::remove_dir_all(&tmp).map_err(|e| TrainError::io(&tmp, e))?;
    }
    // an interrupt that kills the process before the rename removes it
    // (registered before it exists, so no moment leaves it unregistered)
    let _interruptible = mfm_files::interrupt::TemporaryDir::register(&tmp);
    std::fs::create_dir(&tmp).map_err(|e| TrainError::io(&tmp, e))?;
    let written = fill_and_place(run_dir, &root, &tmp, state, fill);
    if let Err(e) = written {
        // nothing half-written stays; a full disk is said as such
        let error = disk_full_or(e, &root, expected.max(folder_bytes(&tmp)));
        let _ = std::fs::remove_dir_all(&tmp);
        return Err(error);
    }
    written
}

/// [`write_checkpoint`] after its temporary folder `tmp` exists: the
/// payload, the checksums, the state, the rename.
fn fill_and_place(
    run_dir: &Path,
    root: &Path,
    tmp: &Path,
    mut state: CheckpointState,
    fill: impl FnOnce(&Path) -> Result<()>,
) -> Result<PathBuf> {
    fill(tmp)?;
    let mut files = BTreeMap::new();
    for entry in std::fs::read_dir(tmp).map_err(|e| TrainError::io(tmp, e))? {
        let entry = entry.map_err(|e| TrainError::io(tmp, e))?;
        let Some(name) = entry.file_name().to_str().map(str::to_owned) else {
            continue;
        };
        if name.starts_with('.') || name == STATE_FILE || !entry.path().is_file() {
            continue;
        }
        let path = entry.path();
        // make sure the payload is on disk before the state that vouches for it
        File::open(&path)
            .and_then(|f| f.sync_all())
            .map_err(|e| TrainError::io(&path, e))?;
        files.insert(name, file_record(&path)?);
    }
    state.files = files;
    state.format = STATE_FORMAT;
    let json = serde_json::to_string_pretty(&state).map_err(|e| {
        TrainError::format(
            tmp.join(STATE_FILE),
            format!("cannot serialize the state: {e}"),
        )
    })?;
    write_atomic(&tmp.join(STATE_FILE), json.as_bytes())?;
    let dest = checkpoint_dir(run_dir, state.step);
    if dest.exists() {
        std::fs::remove_dir_all(&dest).map_err(|e| TrainError::io(&dest, e))?;
    }
    std::fs::rename(tmp, &dest).map_err(|e| TrainError::io(&dest, e))?;
    // persist the rename (best effort: not every platform can sync a folder)
    if let Ok(d) = File::open(root) {
        let _ = d.sync_all();
    }
    Ok(dest)
}

/// The bytes of the files directly in `dir` (0 when it cannot be read).
fn folder_bytes(dir: &Path) -> u64 {
    std::fs::read_dir(dir)
        .map(|entries| {
            entries
                .flatten()
                .filter_map(|e| e.metadata().ok())
                .filter(|m| m.is_file())
                .map(|m| m.len())
                .sum()
        })
        .unwrap_or(0)
}

/// `error`, or a [`mfm_files::FileError::NoSpace`] naming `root` when its
/// file system is full (less free than [`mfm_files::space::margin`]): a
/// write that failed for want of space, whatever layer reported it
/// (libtorch's own writer among them), says so with the numbers.
fn disk_full_or(error: TrainError, root: &Path, needed: u64) -> TrainError {
    let full = matches!(
        &error,
        TrainError::Files(mfm_files::FileError::Io { source, .. })
            if source.kind() == std::io::ErrorKind::StorageFull
    );
    match mfm_files::space::available_bytes(root) {
        Ok(Some(available)) if full || available < mfm_files::space::margin(available) / 2 => {
            TrainError::Files(mfm_files::FileError::NoSpace {
                path: root.to_path_buf(),
                needed,
                margin: mfm_files::space::margin(available),
                available,
            })
        }
        _ => error,
    }
}

/// Deletes all but the newest `keep` checkpoints; returns the deleted
/// folders.
///
/// # Errors
/// [`TrainError::Files`] (`Io`) naming the folder that could not be removed.
pub fn prune_checkpoints(run_dir: &Path, keep: usize) -> Result<Vec<PathBuf>> {
    prune_checkpoints_keeping(run_dir, keep, &[])
}

/// [`prune_checkpoints`] that also keeps the checkpoints of the steps
/// `snapshots` (`train.keep_at`), which do not count towards `keep`.
///
/// # Errors
/// As [`prune_checkpoints`].
pub fn prune_checkpoints_keeping(
    run_dir: &Path,
    keep: usize,
    snapshots: &[u64],
) -> Result<Vec<PathBuf>> {
    let rolling: Vec<CheckpointInfo> = list_checkpoints(run_dir)?
        .into_iter()
        .filter(|c| !snapshots.contains(&c.step))
        .collect();
    let n = rolling.len().saturating_sub(keep.max(1));
    let mut removed = Vec::new();
    for c in rolling.into_iter().take(n) {
        std::fs::remove_dir_all(&c.dir).map_err(|e| TrainError::io(&c.dir, e))?;
        removed.push(c.dir);
    }
    Ok(removed)
}

/// What [`newest_valid_with`] found: the newest checkpoint that passed
/// its check (with its state), and the newer ones that did not, each with
/// its error (newest first).
pub type NewestValid = (
    Option<(CheckpointInfo, CheckpointState)>,
    Vec<(PathBuf, TrainError)>,
);

/// The newest checkpoint of `run_dir` that passes `verify` (e.g.
/// [`verify_checkpoint_listing`] with the files a kind of run needs), and
/// the newer ones that did not, each with its error (newest first).
///
/// # Errors
/// [`TrainError::Files`] (`Io`) if the checkpoint folder cannot be listed.
pub fn newest_valid_with(
    run_dir: &Path,
    verify: impl Fn(&Path) -> Result<CheckpointState>,
) -> Result<NewestValid> {
    let mut rejected = Vec::new();
    for c in list_checkpoints(run_dir)?.into_iter().rev() {
        match verify(&c.dir) {
            Ok(state) if state.step == c.step => return Ok((Some((c, state)), rejected)),
            Ok(state) => {
                let msg = format!(
                    "folder name says step {} but the state says {}",
                    c.step, state.step
                );
                rejected.push((
                    c.dir.clone(),
                    TrainError::format(c.dir.join(STATE_FILE), msg),
                ));
            }
            Err(e) => rejected.push((c.dir.clone(), e)),
        }
    }
    Ok((None, rejected))
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    fn verify(dir: &Path) -> Result<CheckpointState> {
        verify_checkpoint_listing(dir, &[WEIGHTS_FILE, "config.toml"])
    }

    fn state(step: u64) -> CheckpointState {
        CheckpointState {
            format: STATE_FORMAT,
            step,
            seed: 1,
            rng: "test".into(),
            elapsed_seconds: 0.0,
            last_loss: None,
            log: LogAccumulator::default(),
            files: BTreeMap::new(),
        }
    }

    fn fill(dir: &Path) -> Result<()> {
        for name in [WEIGHTS_FILE, NET_CONFIG_FILE, OPTIMIZER_FILE, "config.toml"] {
            std::fs::write(dir.join(name), format!("contents of {name}"))
                .map_err(|e| TrainError::io(dir, e))?;
        }
        Ok(())
    }

    #[test]
    fn write_verify_detect_and_prune() {
        let run = tempfile::tempdir().unwrap();
        for step in [5, 10, 15] {
            write_checkpoint(run.path(), state(step), fill).unwrap();
        }
        let steps: Vec<u64> = list_checkpoints(run.path())
            .unwrap()
            .iter()
            .map(|c| c.step)
            .collect();
        assert_eq!(steps, [5, 10, 15]);
        let s = verify(&checkpoint_dir(run.path(), 15)).unwrap();
        assert_eq!(s.files.len(), 4);
        assert_eq!(
            s.files["config.toml"].bytes,
            "contents of config.toml".len() as u64
        );

        // same length, one byte changed: only the CRC can tell
        let f = checkpoint_dir(run.path(), 15).join("config.toml");
        std::fs::write(&f, "contents of config.tomm").unwrap();
        let err = verify(&checkpoint_dir(run.path(), 15)).unwrap_err();
        assert!(err.to_string().contains("config.toml") && err.to_string().contains("CRC"));
        let (best, rejected) = newest_valid_with(run.path(), verify).unwrap();
        assert_eq!(best.unwrap().0.step, 10);
        assert_eq!(rejected.len(), 1);

        assert_eq!(prune_checkpoints(run.path(), 2).unwrap().len(), 1);
        let steps: Vec<u64> = list_checkpoints(run.path())
            .unwrap()
            .iter()
            .map(|c| c.step)
            .collect();
        assert_eq!(steps, [10, 15]);
    }

    #[test]
    fn a_failed_checkpoint_leaves_nothing_and_a_full_disk_says_so() {
        let run = tempfile::tempdir().unwrap();
        write_checkpoint(run.path(), state(5), fill).unwrap();
        let only_step_5 = || {
            let names: Vec<String> = std::fs::read_dir(run.path().join(CHECKPOINTS_DIR))
                .unwrap()
                .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
                .collect();
            assert_eq!(names.len(), 1, "{names:?}");
            assert!(names[0].contains("000000005"), "{names:?}");
        };
        // the disk fills up halfway through the payload
        let full = |dir: &Path| -> Result<()> {
            std::fs::write(dir.join(WEIGHTS_FILE), [0u8; 1000]).unwrap();
            Err(TrainError::io(
                dir.join(OPTIMIZER_FILE),
                std::io::Error::from(std::io::ErrorKind::StorageFull),
            ))
        };
        let e = write_checkpoint(run.path(), state(10), full).unwrap_err();
        let message = e.to_string();
        assert!(
            matches!(e, TrainError::Files(mfm_files::FileError::NoSpace { .. }))
                && message.contains("disk full")
                && message.contains(CHECKPOINTS_DIR),
            "{message}"
        );
        only_step_5();
        // any other failure: its own error, and nothing left either
        let broken = |_: &Path| -> Result<()> { Err(TrainError::Config("broken".into())) };
        let e = write_checkpoint(run.path(), state(10), broken).unwrap_err();
        assert!(e.to_string().contains("broken"), "{e}");
        only_step_5();
    }
}
