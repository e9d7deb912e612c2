//! What a training run folder holds besides its model, as far as it is
//! plain files: where its checkpoints are and which ones there are, what a
//! checkpoint's `state.json` records, and the columns of its log.
//!
//! The training loop (`mfm_train`) writes these and re-exports them from
//! `mfm_train::checkpoint`; they live here, with the names of
//! [`crate::owned`], so that tools which only read run folders (the
//! reproduction commands) need no network crate and no libtorch.
//!
//! ```text
//! RUN/train_log.csv                       LOG_HEADER, one row per log interval
//! RUN/checkpoints/step-000001000/state.json   CheckpointState
//! ```

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::error::FileError;
use crate::owned::{RUN_CHECKPOINTS, RUN_LOG};

/// A checkpoint's [`CheckpointState`] (JSON), written last.
pub const STATE_FILE: &str = "state.json";
/// Version of [`CheckpointState`]'s format.
pub const STATE_FORMAT: u32 = 1;
/// The header row of a run's log ([`RUN_LOG`]): after `step` steps, the
/// mean loss and unclipped gradient norm of the interval, the learning rate
/// of its last step and the training seconds so far.
pub const LOG_HEADER: &str = "step,loss,lr,grad_norm,seconds";

/// Size and CRC-32 (IEEE) of one file of a checkpoint.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FileRecord {
    /// Length in bytes.
    pub bytes: u64,
    /// CRC-32 of the contents.
    pub crc32: u32,
}

/// Running sums of the current log interval (so a resumed run writes the
/// same rows as an uninterrupted one).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LogAccumulator {
    /// Sum of the step losses since the last row.
    pub loss_sum: f64,
    /// Sum of the (unclipped) gradient norms since the last row.
    pub grad_norm_sum: f64,
    /// Number of steps since the last row.
    pub count: u64,
}

/// `state.json` of a checkpoint.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CheckpointState {
    /// [`STATE_FORMAT`].
    pub format: u32,
    /// Optimizer steps completed (the next step to run).
    pub step: u64,
    /// The run's seed.
    pub seed: u64,
    /// How the run's randomness is derived: every random choice of step `s`
    /// is a pure function of `(seed, s)`, so `step` is the whole generator
    /// state; recorded for readers of the file.
    pub rng: String,
    /// Training seconds before this checkpoint (summed over resumed
    /// sessions).
    pub elapsed_seconds: f64,
    /// The loss of the last step, if any.
    pub last_loss: Option<f64>,
    /// The current log interval's sums.
    pub log: LogAccumulator,
    /// Every other file of the checkpoint, by name.
    pub files: BTreeMap<String, FileRecord>,
}

impl CheckpointState {
    /// Reads and parses the `state.json` of the checkpoint folder `dir`,
    /// without checking the files it lists (`mfm_train` verifies those
    /// before it loads anything).
    ///
    /// # Errors
    /// [`FileError::Io`] for a missing or unreadable file,
    /// [`FileError::Format`] for one that does not parse.
    pub fn read(dir: &Path) -> Result<Self, FileError> {
        let path = dir.join(STATE_FILE);
        let text = std::fs::read_to_string(&path).map_err(|e| FileError::io(&path, e))?;
        serde_json::from_str(&text).map_err(|e| {
            FileError::format(
                &path,
                format!("unreadable checkpoint state (truncated or corrupted?): {e}"),
            )
        })
    }
}

/// A checkpoint folder found in a run folder.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct CheckpointInfo {
    /// Steps completed.
    pub step: u64,
    /// The folder.
    pub dir: PathBuf,
}

/// The folder of the checkpoint after `step` steps.
pub fn checkpoint_dir(run_dir: &Path, step: u64) -> PathBuf {
    run_dir
        .join(RUN_CHECKPOINTS)
        .join(format!("step-{step:09}"))
}

/// The checkpoint folders of a run (`checkpoints/step-N`), ascending in
/// step; temporary folders are skipped. No folder: an empty list.
///
/// Cost: one listing of the checkpoints folder.
///
/// # Errors
/// [`FileError::Io`] if the folder cannot be listed.
///
/// # Example
/// ```
/// use mfm_files::run_folder::{checkpoint_dir, list_checkpoints};
/// let run = tempfile::tempdir().unwrap();
/// assert!(list_checkpoints(run.path()).unwrap().is_empty());
/// for step in [20, 5] {
///     std::fs::create_dir_all(checkpoint_dir(run.path(), step)).unwrap();
/// }
/// let steps: Vec<u64> = list_checkpoints(run.path()).unwrap().iter().map(|c| c.step).collect();
/// assert_eq!(steps, [5, 20]);
/// ```
pub fn list_checkpoints(run_dir: &Path) -> Result<Vec<CheckpointInfo>, FileError> {
    let root = run_dir.join(RUN_CHECKPOINTS);
    let entries = match std::fs::read_dir(&root) {
        Ok(e) => e,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Vec::new()),
        Err(e) => return Err(FileError::io(&root, e)),
    };
    let mut out = Vec::new();
    for entry in entries {
        let entry = entry.map_err(|e| FileError::io(&root, e))?;
        let name = entry.file_name();
        let Some(step) = name
            .to_str()
            .and_then(|n| n.strip_prefix("step-"))
            .and_then(|n| n.parse::<u64>().ok())
        else {
            continue;
        };
        if entry.path().is_dir() {
            out.push(CheckpointInfo {
                step,
                dir: entry.path(),
            });
        }
    }
    out.sort_by_key(|c| c.step);
    Ok(out)
}

/// One row of a run's log ([`LOG_HEADER`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LogRow {
    /// Steps completed.
    pub step: u64,
    /// Mean loss over the interval.
    pub loss: f64,
    /// Learning rate of the interval's last step.
    pub lr: f64,
    /// Mean unclipped gradient norm over the interval.
    pub grad_norm: f64,
    /// Training seconds so far (summed over resumed sessions).
    pub seconds: f64,
}

/// Reads the log of the run folder `run_dir` ([`RUN_LOG`]): its header
/// must be [`LOG_HEADER`]; an empty last line is allowed.
///
/// # Errors
/// [`FileError::Io`] for a missing or unreadable log,
/// [`FileError::Format`] naming the line that is not a row of five numbers
/// or a header that is not [`LOG_HEADER`].
pub fn read_log(run_dir: &Path) -> Result<Vec<LogRow>, FileError> {
    let path = run_dir.join(RUN_LOG);
    let text = std::fs::read_to_string(&path).map_err(|e| FileError::io(&path, e))?;
    let mut lines = text.lines();
    if lines.next() != Some(LOG_HEADER) {
        return Err(FileError::format(
            &path,
            format!("the first line is not the log header `{LOG_HEADER}`"),
        ));
    }
    let mut rows = Vec::new();
    for (i, line) in lines.enumerate().filter(|(_, l)| !l.trim().is_empty()) {
        let bad = || FileError::format(&path, format!("line {} is not a log row: {line:?}", i + 2));
        let fields: Vec<&str> = line.split(',').collect();
        let [step, loss, lr, grad_norm, seconds] = fields[..] else {
            return Err(bad());
        };
        let num = |s: &str| s.trim().parse::<f64>().map_err(|_| bad());
        rows.push(LogRow {
            step: step.trim().parse().map_err(|_| bad())?,
            loss: num(loss)?,
            lr: num(lr)?,
            grad_norm: num(grad_norm)?,
            seconds: num(seconds)?,
        });
    }
    Ok(rows)
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn checkpoints_are_listed_by_step_and_temporaries_skipped() {
        let run = tempfile::tempdir().unwrap();
        for step in [100, 7, 30] {
            std::fs::create_dir_all(checkpoint_dir(run.path(), step)).unwrap();
        }
        let root = run.path().join(RUN_CHECKPOINTS);
        std::fs::create_dir(root.join(".tmp-step-000000040-1")).unwrap();
        // a file named like a checkpoint is not one
        std::fs::write(root.join("step-50"), "").unwrap();
        let found = list_checkpoints(run.path()).unwrap();
        let steps: Vec<u64> = found.iter().map(|c| c.step).collect();
        assert_eq!(steps, [7, 30, 100]);
        assert_eq!(found[0].dir, checkpoint_dir(run.path(), 7));
        assert!(found[0].dir.ends_with("checkpoints/step-000000007"));
    }

    #[test]
    fn a_state_round_trips_and_a_broken_one_names_its_file() {
        let dir = tempfile::tempdir().unwrap();
        let state = CheckpointState {
            format: STATE_FORMAT,
            step: 12,
            seed: 3,
            rng: "test".into(),
            elapsed_seconds: 4.5,
            last_loss: Some(0.25),
            log: LogAccumulator::default(),
            files: BTreeMap::from([(
                "model.safetensors".to_owned(),
                FileRecord { bytes: 8, crc32: 1 },
            )]),
        };
        std::fs::write(
            dir.path().join(STATE_FILE),
            serde_json::to_string(&state).unwrap(),
        )
        .unwrap();
        assert_eq!(CheckpointState::read(dir.path()).unwrap(), state);
        std::fs::write(dir.path().join(STATE_FILE), "{\"format\": 1").unwrap();
        let e = CheckpointState::read(dir.path()).unwrap_err().to_string();
        assert!(e.contains(STATE_FILE) && e.contains("unreadable"), "{e}");
    }

    #[test]
    fn the_log_reads_as_rows_and_refuses_other_files() {
        let run = tempfile::tempdir().unwrap();
        let log = run.path().join(RUN_LOG);
        std::fs::write(
            &log,
            format!("{LOG_HEADER}\n100,0.5,0.004,1.25,3.5\n200,0.25,0.002,1,7\n"),
        )
        .unwrap();
        let rows = read_log(run.path()).unwrap();
        assert_eq!(rows.len(), 2);
        assert_eq!(
            rows[1],
            LogRow {
                step: 200,
                loss: 0.25,
                lr: 0.002,
                grad_norm: 1.0,
                seconds: 7.0
            }
        );
        std::fs::write(&log, format!("{LOG_HEADER}\n100,0.5,0.004\n")).unwrap();
        let e = read_log(run.path()).unwrap_err().to_string();
        assert!(e.contains("line 2"), "{e}");
        std::fs::write(&log, "step,loss\n").unwrap();
        assert!(read_log(run.path()).is_err());
    }
}
