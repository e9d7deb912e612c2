//! The optimization loop both arbitrary-source trainings share: Adam with
//! gradient clipping and a step-decay schedule, a CSV log, atomic
//! checkpoints every few steps, resumption from the newest valid one, and
//! a stop flag checked between steps.

use std::collections::BTreeMap;
use std::fs::OpenOptions;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use mfm_net::{PoissonNet, PoissonNetConfig};
use tch::Device;

use crate::Schedule;
use mfm_fm::adam::Adam;
use mfm_fm::checkpoint::{
    self, CheckpointState, LOG_FILE, LogAccumulator, NET_CONFIG_FILE, OPTIMIZER_FILE, WEIGHTS_FILE,
};
use mfm_fm::seeding::INIT_LOCK;
use mfm_fm::train::{LOG_HEADER, truncate_log};
use mfm_fm::{FmError, Result};

/// Rows of the log: one per this many steps.
const LOG_EVERY: u64 = 10;
/// Checkpoints kept.
const KEEP: usize = 2;
/// What a checkpoint's `rng` field says.
const RNG: &str = "every random choice of step s is a pure function of (seed, s)";

/// What a training call did.
#[derive(Clone, Debug, PartialEq)]
pub struct TrainReport {
    /// The step the call started at (> 0 when resumed).
    pub start_step: u64,
    /// The step it stopped at.
    pub end_step: u64,
    /// The configured total.
    pub total_steps: u64,
    /// Whether the total was reached (the final model is written).
    pub finished: bool,
    /// Whether the stop flag ended it.
    pub stopped: bool,
    /// Seconds of this call.
    pub seconds: f64,
    /// The loss of the last step.
    pub last_loss: Option<f64>,
    /// The final weights, when finished.
    pub model: Option<PathBuf>,
    /// Newer checkpoints that failed their check and were passed over on
    /// resuming (folder and reason).
    pub skipped_checkpoints: Vec<String>,
}

impl TrainReport {
    /// The call on one line: steps of the total, seconds, last loss.
    pub fn summary(&self) -> String {
        format!(
            "steps {}..{} of {} in {:.1} s, last loss {}",
            self.start_step,
            self.end_step,
            self.total_steps,
            self.seconds,
            self.last_loss
                .map_or_else(|| "-".to_owned(), |l| format!("{l:.5}"))
        )
    }
}

/// Fields of a run's description (`predictor.json`, `arbitrary.json`) that
/// may change when it is resumed: how long it runs, how often it
/// checkpoints, and where its data now lives. Every other field shapes the
/// model or the optimisation.
pub const RESUMABLE_SPEC_FIELDS: &[&str] = &[
    "config.schedule.steps",
    "config.schedule.checkpoint_every",
    "dataset",
];

/// The scalar fields of a JSON value by dotted path (arrays whole).
fn flatten(prefix: &str, v: &serde_json::Value, out: &mut BTreeMap<String, String>) {
    match v {
        serde_json::Value::Object(map) => {
            for (k, x) in map {
                let key = if prefix.is_empty() {
                    k.clone()
                } else {
                    format!("{prefix}.{k}")
                };
                flatten(&key, x, out);
            }
        }
        other => {
            out.insert(prefix.to_owned(), other.to_string());
        }
    }
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
    let read = |path: &Path| -> Result<BTreeMap<String, String>> {
        let text = std::fs::read_to_string(path).map_err(|e| FmError::io(path, e))?;
        let v: serde_json::Value = serde_json::from_str(&text)
            .map_err(|e| FmError::format(path, format!("not readable as JSON: {e}")))?;
        let mut out = BTreeMap::new();
        flatten("", &v, &mut out);
        Ok(out)
    };
    let (before, after) = (read(&saved)?, read(&now)?);
    let keys: std::collections::BTreeSet<&String> = before.keys().chain(after.keys()).collect();
    let refused: Vec<String> = keys
        .into_iter()
        .filter(|k| before.get(*k) != after.get(*k))
        .filter(|k| !RESUMABLE_SPEC_FIELDS.contains(&k.as_str()))
        .map(|k| {
            let show =
                |m: &BTreeMap<String, String>| m.get(k).cloned().unwrap_or_else(|| "-".into());
            format!("{k} {} -> {}", show(&before), show(&after))
        })
        .collect();
    if !refused.is_empty() {
        return Err(FmError::Config(format!(
            "{} was edited after the checkpoint at step {step}: {}; a resumed run cannot change \
             these (only {} can): undo the edit, or start a new run",
            now.display(),
            refused.join(", "),
            RESUMABLE_SPEC_FIELDS.join(", ")
        )));
    }
    let steps = after
        .get("config.schedule.steps")
        .and_then(|s| s.parse::<u64>().ok());
    if let Some(total) = steps.filter(|&t| t < step) {
        return Err(FmError::Config(format!(
            "{}: config.schedule.steps = {total} is below the checkpoint's step {step}",
            now.display()
        )));
    }
    Ok(())
}

/// A network with its optimizer in a run folder.
#[derive(Debug)]
pub(crate) struct Optimization {
    pub(crate) net: PoissonNet,
    adam: Adam,
    schedule: Schedule,
    run_dir: PathBuf,
    spec_file: &'static str,
    step: u64,
    elapsed: f64,
    last_loss: Option<f64>,
    /// The sums of the log row in progress (kept in checkpoints, so that a
    /// resumed run writes the rows an uninterrupted one does).
    acc: LogAccumulator,
    skipped: Vec<String>,
}

impl Optimization {
    /// A fresh network (initial weights from the schedule's seed), or the
    /// state of the newest valid checkpoint of `run_dir` when there is one.
    /// `spec_file` names the run's description (`predictor.json`,
    /// `arbitrary.json`): every checkpoint keeps a copy, and resuming
    /// refuses edits made to it since the checkpoint other than
    /// [`RESUMABLE_SPEC_FIELDS`].
    pub(crate) fn start_or_resume(
        run_dir: &Path,
        spec_file: &'static str,
        net: &PoissonNetConfig,
        schedule: &Schedule,
        device: Device,
    ) -> Result<Self> {
        schedule.validate()?;
        mfm_net::runtime::tune_allocator();
        checkpoint::remove_stale_temporaries(run_dir)?;
        let mut network = {
            let _guard = INIT_LOCK.lock().unwrap_or_else(|p| p.into_inner());
            tch::manual_seed(schedule.seed as i64);
            PoissonNet::new(net, device)?
        };
        let mut adam = Adam::new(&network, 0.9, 0.999, 1e-8);
        let (newest, rejected) = checkpoint::newest_valid_with(run_dir, |dir| {
            checkpoint::verify_checkpoint_listing(
                dir,
                &[WEIGHTS_FILE, NET_CONFIG_FILE, OPTIMIZER_FILE],
            )
        })?;
        let skipped = rejected
            .into_iter()
            .map(|(dir, e)| format!("{}: {e}", dir.display()))
            .collect();
        let log = run_dir.join(LOG_FILE);
        let (step, elapsed, last_loss, acc) = match newest {
            Some((info, state)) => {
                refuse_spec_edits(run_dir, &info.dir, spec_file, state.step)?;
                network.load_weights(info.dir.join(WEIGHTS_FILE))?;
                adam.load(&info.dir.join(OPTIMIZER_FILE), state.step)?;
                truncate_log(&log, state.step)?;
                (
                    state.step,
                    state.elapsed_seconds,
                    state.last_loss,
                    state.log,
                )
            }
            None => {
                checkpoint::refuse_restart_over_final_model(run_dir)?;
                checkpoint::write_atomic(&log, format!("{LOG_HEADER}\n").as_bytes())?;
                (0, 0.0, None, LogAccumulator::default())
            }
        };
        Ok(Self {
            net: network,
            adam,
            schedule: schedule.clone(),
            run_dir: run_dir.to_path_buf(),
            spec_file,
            step,
            elapsed,
            last_loss,
            acc,
            skipped,
        })
    }

    fn write_checkpoint(&self) -> Result<()> {
        let state = CheckpointState {
            format: checkpoint::STATE_FORMAT,
            step: self.step,
            seed: self.schedule.seed,
            rng: RNG.into(),
            elapsed_seconds: self.elapsed,
            last_loss: self.last_loss,
            log: self.acc,
            files: BTreeMap::new(),
        };
        let (net, adam) = (&self.net, &self.adam);
        let spec = self.run_dir.join(self.spec_file);
        checkpoint::write_checkpoint(&self.run_dir, state, |tmp| {
            net.save(tmp.join(WEIGHTS_FILE))?;
            adam.save(&tmp.join(OPTIMIZER_FILE))?;
            let bytes = std::fs::read(&spec).map_err(|e| FmError::io(&spec, e))?;
            checkpoint::write_atomic(&tmp.join(self.spec_file), &bytes)
        })?;
        checkpoint::prune_checkpoints(&self.run_dir, KEEP)?;
        Ok(())
    }

    /// Runs steps until the total or `stop`. `step_fn(net, step)` runs the
    /// forward and backward passes of step `step` (gradients accumulate
    /// into the network's variables) and returns its loss; this loop zeroes
    /// the gradients before, clips and applies Adam after.
    pub(crate) fn run(
        &mut self,
        stop: &AtomicBool,
        progress: bool,
        what: &str,
        mut step_fn: impl FnMut(&PoissonNet, u64) -> Result<f64>,
    ) -> Result<TrainReport> {
        let total = self.schedule.steps;
        let start_step = self.step;
        let target = if progress {
            ProgressDrawTarget::stderr()
        } else {
            ProgressDrawTarget::hidden()
        };
        let bar = ProgressBar::with_draw_target(Some(total), target).with_position(start_step);
        if let Ok(style) = ProgressStyle::with_template(
            "{prefix} {elapsed_precise} [{bar:30}] {pos}/{len} eta {eta} {msg}",
        ) {
            bar.set_style(style.progress_chars("=> "));
        }
        bar.set_prefix(what.to_owned());
        let log_path = self.run_dir.join(LOG_FILE);
        let mut log = OpenOptions::new()
            .append(true)
            .create(true)
            .open(&log_path)
            .map_err(|e| FmError::io(&log_path, e))?;
        let session = Instant::now();
        let base = self.elapsed;
        let mut stopped = false;
        let mut last_checkpoint = None;
        while self.step < total {
            if stop.load(Ordering::Relaxed) {
                stopped = true;
                break;
            }
            self.adam.zero_grad();
            let s = self.step;
            let loss = step_fn(&self.net, s).map_err(|e| {
                mfm_fm::train::divergence(&self.net, s, what, "the learning rate", e)
            })?;
            if !loss.is_finite() {
                return Err(FmError::Diverged(format!(
                    "{what} diverged at step {s}: the loss is {loss}; lower the learning rate \
                     (the last checkpoint is intact)"
                )));
            }
            let grad_norm = self.adam.clip_grad_norm(self.schedule.grad_clip)?;
            let lr = self.schedule.lr_at(s);
            self.adam.step(lr)?;
            self.step += 1;
            self.last_loss = Some(loss);
            self.elapsed = base + session.elapsed().as_secs_f64();
            self.acc.loss_sum += loss;
            self.acc.grad_norm_sum += grad_norm;
            self.acc.count += 1;
            if self.step % LOG_EVERY == 0 || self.step == total {
                let acc = std::mem::take(&mut self.acc);
                let n = acc.count.max(1) as f64;
                let row = format!(
                    "{},{},{},{},{:.3}\n",
                    self.step,
                    acc.loss_sum / n,
                    lr,
                    acc.grad_norm_sum / n,
                    self.elapsed
                );
                log.write_all(row.as_bytes())
                    .and_then(|()| log.flush())
                    .map_err(|e| FmError::io(&log_path, e))?;
            }
            bar.set_position(self.step);
            bar.set_message(format!("loss {loss:.4e} lr {lr:.1e}"));
            if self.step % self.schedule.checkpoint_every == 0 || self.step == total {
                self.write_checkpoint()?;
                last_checkpoint = Some(self.step);
            }
        }
        if last_checkpoint != Some(self.step) && self.step > start_step {
            self.write_checkpoint()?;
        }
        bar.finish_and_clear();
        let finished = self.step >= total;
        let model = if finished {
            let path = self.run_dir.join(WEIGHTS_FILE);
            self.net.save(&path)?;
            checkpoint::write_final_record(&self.run_dir)?;
            Some(path)
        } else {
            None
        };
        Ok(TrainReport {
            start_step,
            end_step: self.step,
            total_steps: total,
            finished,
            stopped,
            seconds: session.elapsed().as_secs_f64(),
            last_loss: self.last_loss,
            model,
            skipped_checkpoints: std::mem::take(&mut self.skipped),
        })
    }
}
