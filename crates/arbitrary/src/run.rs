//! Both arbitrary-source trainings on the one training loop
//! ([`mfm_train::TrainingLoop`]): their [`Schedule`] as the loop's
//! settings, their run description (`predictor.json`, `arbitrary.json`)
//! copied into every checkpoint and checked on resuming
//! ([`mfm_train::resume`]), and a step closure as the loop's
//! [`Objective`].

use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;

use mfm_net::{PoissonNet, PoissonNetConfig};
use mfm_train::checkpoint::{
    self, NET_CONFIG_FILE, OPTIMIZER_FILE, WEIGHTS_FILE, newest_valid_with,
    verify_checkpoint_listing,
};
use mfm_train::resume::{self, ResumePolicy};
use mfm_train::{Objective, RunNames, TrainSummary, TrainingLoop};
use tch::Device;

use crate::Schedule;
use crate::error::{ArbitraryError, Result};

/// What a checkpoint's `rng` field says.
const RNG: &str = "every random choice of step s is a pure function of (seed, s)";

/// Fields of a run's description (`predictor.json`, `arbitrary.json`) that
/// may change when it is resumed: how long it runs, how it checkpoints,
/// where it runs and where its data now lives. Every other field shapes
/// the model or the optimisation.
pub const RESUMABLE_SPEC_FIELDS: &[&str] = &[
    "config.schedule.steps",
    "config.schedule.checkpoint_every",
    "config.schedule.keep_checkpoints",
    "config.schedule.keep_at",
    "config.schedule.device",
    "dataset",
];

/// Reads a run description as a JSON value.
fn read_value(path: &Path) -> Result<serde_json::Value> {
    let text = std::fs::read_to_string(path).map_err(|e| ArbitraryError::io(path, e))?;
    serde_json::from_str(&text)
        .map_err(|e| ArbitraryError::format(path, format!("not readable as JSON: {e}")))
}

/// Refuses to resume `run_dir` from the checkpoint `checkpoint` (of
/// `step`) when its `spec_file` was edited since in a field outside
/// [`RESUMABLE_SPEC_FIELDS`], naming each change, or when its steps fall
/// below the checkpoint's. A checkpoint without a copy (written before
/// checkpoints kept one) is not checked.
fn refuse_spec_edits(run_dir: &Path, checkpoint: &Path, spec_file: &str, step: u64) -> Result<()> {
    let saved = checkpoint.join(spec_file);
    if !saved.is_file() {
        return Ok(());
    }
    let now = run_dir.join(spec_file);
    let after = read_value(&now)?;
    let changes = resume::changes(&read_value(&saved)?, &after);
    let steps = after
        .pointer("/config/schedule/steps")
        .and_then(serde_json::Value::as_u64);
    resume::refuse_edits(
        &now,
        step,
        &changes,
        steps,
        ResumePolicy {
            resumable: RESUMABLE_SPEC_FIELDS,
            steps_field: "config.schedule.steps",
            otherwise: "start a new run",
        },
    )?;
    Ok(())
}

/// The loop of a fresh run in `run_dir` (initial weights from the
/// schedule's seed, the log started), or of the newest valid checkpoint of
/// `run_dir` when there is one. `spec_file` names the run's description
/// (`predictor.json`, `arbitrary.json`): every checkpoint keeps a copy, and
/// resuming refuses edits made to it since the checkpoint other than
/// [`RESUMABLE_SPEC_FIELDS`]. Newer checkpoints that fail their check are
/// passed over with a warning on standard error.
pub(crate) fn start_or_resume(
    run_dir: &Path,
    spec_file: &str,
    net: &PoissonNetConfig,
    schedule: &Schedule,
    what: &str,
    device: Device,
) -> Result<TrainingLoop> {
    schedule.validate()?;
    checkpoint::remove_stale_temporaries(run_dir)?;
    let names = RunNames {
        what: what.to_owned(),
        lr_setting: "the learning rate".into(),
        steps_setting: "config.schedule.steps".into(),
        randomness: RNG.into(),
    };
    let mut run = TrainingLoop::new(run_dir, net, schedule.loop_config(), names, device)?;
    let (newest, rejected) = newest_valid_with(run_dir, |dir| {
        verify_checkpoint_listing(dir, &[WEIGHTS_FILE, NET_CONFIG_FILE, OPTIMIZER_FILE])
    })?;
    for (dir, e) in &rejected {
        eprintln!(
            "warning: passed over a damaged checkpoint: {}: {e}",
            dir.display()
        );
    }
    match newest {
        Some((info, state)) => {
            refuse_spec_edits(run_dir, &info.dir, spec_file, state.step)?;
            run.resume_from(&info.dir, &state)?;
        }
        None => {
            checkpoint::refuse_restart_over_final_model(run_dir)?;
            run.start_log()?;
        }
    }
    Ok(run)
}

/// A step closure `step(net, s)` (forward and backward passes, the loss
/// back) as the loop's [`Objective`], with the run's description as the
/// file every checkpoint keeps.
pub(crate) struct StepClosure<F> {
    step: F,
    spec: PathBuf,
    spec_file: String,
}

impl<F: FnMut(&PoissonNet, u64) -> Result<f64>> StepClosure<F> {
    /// `step` on the run in `run_dir` described by `spec_file`.
    pub(crate) fn new(run_dir: &Path, spec_file: &str, step: F) -> Self {
        Self {
            step,
            spec: run_dir.join(spec_file),
            spec_file: spec_file.to_owned(),
        }
    }
}

impl<F: FnMut(&PoissonNet, u64) -> Result<f64>> Objective for StepClosure<F> {
    type Error = ArbitraryError;

    fn step(&mut self, net: &PoissonNet, step: u64) -> Result<f64> {
        (self.step)(net, step)
    }

    fn checkpoint_files(&self) -> Result<Vec<(String, Vec<u8>)>> {
        let bytes = std::fs::read(&self.spec).map_err(|e| ArbitraryError::io(&self.spec, e))?;
        Ok(vec![(self.spec_file.clone(), bytes)])
    }
}

/// Trains `run` to its total (or `stop`) with `step`.
pub(crate) fn train_to_end<F: FnMut(&PoissonNet, u64) -> Result<f64>>(
    mut run: TrainingLoop,
    spec_file: &str,
    stop: &AtomicBool,
    progress: bool,
    step: F,
) -> Result<TrainSummary> {
    let mut objective = StepClosure::new(run.run_dir(), spec_file, step);
    let total = run.config().steps;
    run.run_until(total, &mut objective, stop, progress)
}
