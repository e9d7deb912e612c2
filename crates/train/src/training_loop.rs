//! The optimization loop every training shares.
//!
//! One step `s` (0-based) of a [`TrainingLoop`]:
//! 1. the gradients are zeroed;
//! 2. the [`Objective`] runs the forward and backward passes of step `s`
//!    (gradients accumulate into the network's variables) and returns the
//!    loss; an error of a network whose weights went non-finite, or grew
//!    until its values overflowed, becomes [`TrainError::Diverged`]
//!    ([`divergence`]), and so does a non-finite loss;
//! 3. the global gradient norm is clipped to [`LoopConfig::grad_clip`] (0:
//!    measured, not clipped);
//! 4. one [`Adam`] step at [`LoopConfig::lr_at`]`(s)`;
//! 5. with [`LoopConfig::ema`] > 0 the weight average moves towards the new
//!    weights.
//!
//! Every [`LoopConfig::log_every`] steps a row `step,loss,lr,grad_norm,seconds`
//! goes to the run's log ([`LOG_HEADER`]: the mean loss and unclipped
//! gradient norm since the previous row, the last step's rate, training
//! seconds so far); every [`LoopConfig::checkpoint_every`] steps, at the
//! steps [`LoopConfig::keep_at`] and at the end a checkpoint
//! ([`crate::checkpoint`]) holds the weights, the average, Adam's moments,
//! the sums of the log row in progress and the objective's own files. At
//! the total the final model (the average when there is one) goes to
//! `run_dir/model.safetensors` with its checksums.
//!
//! A run resumed from a checkpoint repeats an uninterrupted one bit for bit
//! (on the CPU, with the same thread count) when its objective's random
//! choices are pure functions of the seed and the step, as every objective
//! of mfm's are ([`crate::seeding`]).

use std::collections::BTreeMap;
use std::fs::OpenOptions;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use mfm_net::{PoissonNet, PoissonNetConfig};
use tch::Device;

use crate::adam::Adam;
use crate::checkpoint::{
    self, CheckpointState, EMA_FILE, LOG_FILE, LogAccumulator, OPTIMIZER_FILE, WEIGHTS_FILE,
};
use crate::error::{Result, TrainError};
use crate::schedule::LrSchedule;
use crate::seeding::INIT_LOCK;

/// Header of the training log (defined with the rest of the run folder's
/// plain files in `mfm_files::run_folder`).
pub use mfm_files::run_folder::LOG_HEADER;

/// How the loop optimizes, logs and checkpoints: one configuration for
/// every training (each run description maps its own fields onto it).
#[derive(Clone, Debug, PartialEq)]
pub struct LoopConfig {
    /// Optimizer steps of the run.
    pub steps: u64,
    /// Base learning rate.
    pub lr: f64,
    /// The rate as a function of the step.
    pub lr_schedule: LrSchedule,
    /// Clip the global gradient norm to this value (0: no clipping).
    pub grad_clip: f64,
    /// Adam's `beta1`.
    pub adam_beta1: f64,
    /// Adam's `beta2`.
    pub adam_beta2: f64,
    /// Adam's `epsilon`.
    pub adam_eps: f64,
    /// The run's seed: initial weights (libtorch's generator, under
    /// [`INIT_LOCK`]); the objective derives its own draws from it.
    pub seed: u64,
    /// Steps between checkpoints (at least 1).
    pub checkpoint_every: u64,
    /// Rolling checkpoints kept (at least 1 is).
    pub keep_checkpoints: usize,
    /// Steps whose checkpoints are written and kept whatever
    /// `keep_checkpoints` says.
    pub keep_at: Vec<u64>,
    /// Steps per log row (at least 1).
    pub log_every: u64,
    /// Decay of the moving average of the weights (0: none). After step `k`
    /// (1-based) every averaged weight `w` becomes `d w + (1 - d) p`, `d =
    /// min(ema, (1 + k) / (10 + k))`, `p` the trained weight.
    pub ema: f64,
}

impl LoopConfig {
    /// The learning rate of step `step` (0-based).
    pub fn lr_at(&self, step: u64) -> f64 {
        self.lr_schedule.lr(self.lr, step, self.steps)
    }

    fn check(&self) -> Result<()> {
        if self.checkpoint_every == 0 || self.log_every == 0 {
            return Err(TrainError::Config(format!(
                "checkpoint_every and log_every must be at least 1, found {} and {}",
                self.checkpoint_every, self.log_every
            )));
        }
        if !(self.ema.is_finite() && (0.0..1.0).contains(&self.ema)) {
            return Err(TrainError::Config(format!(
                "ema must be in [0, 1), found {}",
                self.ema
            )));
        }
        Ok(())
    }
}

/// The names a run's messages use.
#[derive(Clone, Debug)]
pub struct RunNames {
    /// What is trained, for the progress bar and errors ("training",
    /// "predictor").
    pub what: String,
    /// The setting to lower when the run diverges ("train.lr").
    pub lr_setting: String,
    /// The setting of the run's total steps ("train.steps").
    pub steps_setting: String,
    /// How the run's randomness is derived, recorded in every checkpoint.
    pub randomness: String,
}

/// What one training step computes: the part that differs between the
/// kinds of run (flow matching, the eigenvector predictor, the conditioned
/// flow).
pub trait Objective {
    /// The error of a step, which the loop's own errors convert into.
    type Error: StepError;

    /// Runs the forward and backward passes of step `step` (0-based) on
    /// `net`, whose gradients were zeroed and accumulate the step's; returns
    /// the loss. A non-finite loss may be returned without the backward
    /// pass: the loop then stops with [`TrainError::Diverged`] before any
    /// update.
    ///
    /// # Errors
    /// The objective's own (data, noise, network).
    fn step(&mut self, net: &PoissonNet, step: u64) -> Result<f64, Self::Error>;

    /// The run's description files every checkpoint keeps a copy of, as
    /// `(file name, contents)` (e.g. the configuration, which a resumed run
    /// is checked against).
    ///
    /// # Errors
    /// The objective's own.
    fn checkpoint_files(&self) -> Result<Vec<(String, Vec<u8>)>, Self::Error>;
}

/// What the loop needs to know of an objective's errors to tell a diverged
/// run from a broken one.
pub trait StepError: From<TrainError> + std::fmt::Display {
    /// Whether the error came from the network or libtorch, where the
    /// non-finite values of a diverged run surface (not data or files).
    fn is_numerical(&self) -> bool;
    /// Whether it reports a NaN or infinity (e.g. reaching a Poisson
    /// solve).
    fn reports_non_finite(&self) -> bool;
}

impl StepError for TrainError {
    fn is_numerical(&self) -> bool {
        matches!(self, Self::Net(_) | Self::Torch(_))
    }

    fn reports_non_finite(&self) -> bool {
        match self {
            Self::Net(e) => e.reports_non_finite(),
            Self::Torch(e) => mfm_net::error::torch_reports_non_finite(e),
            _ => false,
        }
    }
}

/// The error `e` of training step `step` read as the divergence it is:
/// after a step with a learning rate far too large the weights are NaN or
/// inf, or so large that the network's values overflow and a non-finite
/// value reaches its Poisson solves. Such an error becomes
/// [`TrainError::Diverged`], "`what` diverged at step N: ...; lower
/// `lr_setting`", naming the weights or their largest magnitude. Any other
/// error, and any error at step 0 (weights not yet trained), is returned
/// unchanged.
///
/// Cost: one pass over the weights, on the error path only.
pub fn divergence<E: StepError>(
    net: &PoissonNet,
    step: u64,
    what: &str,
    lr_setting: &str,
    e: E,
) -> E {
    if step == 0 || !e.is_numerical() {
        return e;
    }
    let mut largest = 0.0f64;
    for (name, w) in net.var_store().variables() {
        if !bool::try_from(w.isfinite().all()).unwrap_or(false) {
            return E::from(TrainError::Diverged(format!(
                "{what} diverged at step {step}: the weights `{name}` are NaN or inf; lower \
                 {lr_setting} (the last checkpoint is intact)"
            )));
        }
        let m = w.abs().max().double_value(&[]);
        largest = largest.max(m);
    }
    if e.reports_non_finite() {
        return E::from(TrainError::Diverged(format!(
            "{what} diverged at step {step}: the weights grew to {largest:.2e} and the network's \
             values overflowed ({e}); lower {lr_setting} (the last checkpoint is intact)"
        )));
    }
    e
}

/// What a call of [`TrainingLoop::run_until`] did.
#[derive(Clone, Debug, PartialEq)]
pub struct TrainSummary {
    /// Step the call started at (> 0 when resumed).
    pub start_step: u64,
    /// Step it ended at.
    pub end_step: u64,
    /// The run's total steps.
    pub total_steps: u64,
    /// Whether the run reached its total (the final model was written).
    pub finished: bool,
    /// Whether the stop flag ended the call.
    pub stopped: bool,
    /// Wall seconds of this call's steps (checkpoints included).
    pub seconds: f64,
    /// `seconds / (end_step - start_step)` (0 when no step ran).
    pub seconds_per_step: f64,
    /// Loss of the last step, if any ran in the run so far.
    pub last_loss: Option<f64>,
    /// The newest checkpoint written by this call.
    pub checkpoint: Option<PathBuf>,
    /// The final model, when finished.
    pub model: Option<PathBuf>,
}

impl TrainSummary {
    /// The call on one line: steps of the total, seconds, seconds per step,
    /// last loss.
    pub fn line(&self) -> String {
        format!(
            "steps {}..{} of {} in {:.1} s ({:.3} s/step), last loss {}",
            self.start_step,
            self.end_step,
            self.total_steps,
            self.seconds,
            self.seconds_per_step,
            self.last_loss
                .map_or_else(|| "-".to_owned(), |l| format!("{l:.5}"))
        )
    }
}

/// A network, its optimizer and its weight average training in a run
/// folder. See the [module docs](self).
pub struct TrainingLoop {
    run_dir: PathBuf,
    config: LoopConfig,
    names: RunNames,
    net: PoissonNet,
    ema: Option<PoissonNet>,
    adam: Adam,
    step: u64,
    elapsed: f64,
    last_loss: Option<f64>,
    log: LogAccumulator,
    last_checkpoint_step: Option<u64>,
}

impl std::fmt::Debug for TrainingLoop {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("TrainingLoop")
            .field("run_dir", &self.run_dir)
            .field("what", &self.names.what)
            .field("step", &self.step)
            .field("total_steps", &self.config.steps)
            .finish()
    }
}

impl TrainingLoop {
    /// A fresh network of `net_config` on `device`, its initial weights from
    /// libtorch's generator seeded with `config.seed` (under [`INIT_LOCK`],
    /// so concurrent trainings in one process initialize reproducibly), the
    /// weight average a copy of them when `config.ema > 0`, Adam's moments
    /// zero, at step 0. Tunes libtorch's allocator
    /// ([`mfm_net::runtime::tune_allocator`], process-wide). Writes nothing:
    /// see [`TrainingLoop::start_log`] and [`TrainingLoop::resume_from`].
    ///
    /// # Errors
    /// [`TrainError::Config`] for `checkpoint_every` or `log_every` 0 or an
    /// `ema` outside `[0, 1)`; network errors.
    pub fn new(
        run_dir: &Path,
        net_config: &PoissonNetConfig,
        config: LoopConfig,
        names: RunNames,
        device: Device,
    ) -> Result<Self> {
        config.check()?;
        mfm_net::runtime::tune_allocator();
        let (net, ema) = {
            let _guard = INIT_LOCK.lock().unwrap_or_else(|p| p.into_inner());
            // libtorch seeds are i64; the bits of the u64 seed are kept
            tch::manual_seed(config.seed as i64);
            let net = PoissonNet::new(net_config, device)?;
            // the average starts as a copy; building it draws from libtorch's
            // generator too, so it happens under the same lock (another
            // thread's seeded initialization must not see those draws)
            let ema = if config.ema > 0.0 {
                let mut avg = PoissonNet::new(net_config, device)?;
                avg.var_store_mut().copy(net.var_store())?;
                Some(avg)
            } else {
                None
            };
            (net, ema)
        };
        let adam = Adam::new(&net, config.adam_beta1, config.adam_beta2, config.adam_eps);
        Ok(Self {
            run_dir: run_dir.to_path_buf(),
            config,
            names,
            net,
            ema,
            adam,
            step: 0,
            elapsed: 0.0,
            last_loss: None,
            log: LogAccumulator::default(),
            last_checkpoint_step: None,
        })
    }

    /// Starts the run's log: the header alone (an earlier log is replaced).
    ///
    /// # Errors
    /// [`TrainError::Files`] naming the log.
    pub fn start_log(&self) -> Result<()> {
        truncate_log(&self.run_dir.join(LOG_FILE), 0)
    }

    /// Continues from the checkpoint in `dir` whose verified state is
    /// `state`: its weights, weight average and Adam's moments are loaded,
    /// the step, seconds, last loss and the log row in progress restored,
    /// and the log cut back to the checkpoint's step.
    ///
    /// # Errors
    /// Files missing or unreadable, named (a run with a weight average
    /// resumed from a checkpoint without one among them); network errors.
    pub fn resume_from(&mut self, dir: &Path, state: &CheckpointState) -> Result<()> {
        self.net.load_weights(dir.join(WEIGHTS_FILE))?;
        if let Some(avg) = &mut self.ema {
            let path = dir.join(EMA_FILE);
            if !path.is_file() {
                return Err(TrainError::format(
                    &path,
                    "the run averages its weights (ema) but the checkpoint has no moving \
                     average (it was written by a run without one)",
                ));
            }
            avg.load_weights(&path)?;
        }
        self.adam.load(&dir.join(OPTIMIZER_FILE), state.step)?;
        self.step = state.step;
        self.elapsed = state.elapsed_seconds;
        self.log = state.log;
        self.last_loss = state.last_loss;
        self.last_checkpoint_step = Some(state.step);
        truncate_log(&self.run_dir.join(LOG_FILE), state.step)
    }

    /// The run folder.
    pub fn run_dir(&self) -> &Path {
        &self.run_dir
    }

    /// The loop's configuration.
    pub fn config(&self) -> &LoopConfig {
        &self.config
    }

    /// The network being trained.
    pub fn net(&self) -> &PoissonNet {
        &self.net
    }

    /// The weights sampling uses: the moving average when there is one,
    /// else the trained weights.
    pub fn sampling_net(&self) -> &PoissonNet {
        self.ema.as_ref().unwrap_or(&self.net)
    }

    /// Steps completed.
    pub fn step(&self) -> u64 {
        self.step
    }

    /// Changes the run's total steps (the rate of a schedule that spans
    /// the run follows).
    ///
    /// # Errors
    /// [`TrainError::Config`] for 0 or a total below the current step,
    /// naming [`RunNames::steps_setting`].
    pub fn set_total_steps(&mut self, steps: u64) -> Result<()> {
        if steps == 0 || steps < self.step {
            return Err(TrainError::Config(format!(
                "{} must be at least 1 and at least the current step {}, found {steps}",
                self.names.steps_setting, self.step
            )));
        }
        self.config.steps = steps;
        Ok(())
    }

    /// Moves the weight average towards the weights after step `k`
    /// (1-based).
    fn update_ema(&mut self, k: u64) -> Result<()> {
        let Some(avg) = &mut self.ema else {
            return Ok(());
        };
        let warm = (1.0 + k as f64) / (10.0 + k as f64);
        let d = self.config.ema.min(warm);
        let trained = self.net.var_store().variables();
        tch::no_grad(|| -> Result<()> {
            for (name, mut w) in avg.var_store().variables() {
                let p = trained.get(&name).ok_or_else(|| {
                    TrainError::Config(format!(
                        "the weight average has a variable {name} the network lacks"
                    ))
                })?;
                let _ = w.f_mul_scalar_(d)?;
                let _ = w.f_add_(&(p * (1.0 - d)))?;
            }
            Ok(())
        })
    }

    /// Writes the checkpoint of the current step (with `files`) and prunes
    /// old ones.
    fn write_checkpoint(&mut self, files: Vec<(String, Vec<u8>)>) -> Result<PathBuf> {
        let state = CheckpointState {
            format: checkpoint::STATE_FORMAT,
            step: self.step,
            seed: self.config.seed,
            rng: self.names.randomness.clone(),
            elapsed_seconds: self.elapsed,
            last_loss: self.last_loss,
            log: self.log,
            files: BTreeMap::new(),
        };
        let (net, ema, adam) = (&self.net, self.ema.as_ref(), &self.adam);
        let dir = checkpoint::write_checkpoint(&self.run_dir, state, |tmp| {
            net.save(tmp.join(WEIGHTS_FILE))?;
            if let Some(avg) = ema {
                avg.save(tmp.join(EMA_FILE))?;
            }
            adam.save(&tmp.join(OPTIMIZER_FILE))?;
            for (name, bytes) in &files {
                checkpoint::write_atomic(&tmp.join(name), bytes)?;
            }
            Ok(())
        })?;
        checkpoint::prune_checkpoints_keeping(
            &self.run_dir,
            self.config.keep_checkpoints,
            &self.config.keep_at,
        )?;
        self.last_checkpoint_step = Some(self.step);
        Ok(dir)
    }

    /// One step of `objective` at `self.step`: loss, clipped gradient norm,
    /// rate.
    fn optimizer_step<O: Objective>(
        &mut self,
        objective: &mut O,
    ) -> Result<(f64, f64, f64), O::Error> {
        let s = self.step;
        self.adam.zero_grad();
        let loss = objective.step(&self.net, s)?;
        if !loss.is_finite() {
            return Err(O::Error::from(TrainError::Diverged(format!(
                "{} diverged at step {s}: the loss is {loss}; lower {} (the last checkpoint is \
                 intact)",
                self.names.what, self.names.lr_setting
            ))));
        }
        let grad_norm = self.adam.clip_grad_norm(self.config.grad_clip)?;
        let lr = self.config.lr_at(s);
        self.adam.step(lr)?;
        self.update_ema(s + 1)?;
        Ok((loss, grad_norm, lr))
    }

    /// Trains until step `until` (capped at the total), `stop` is set, or an
    /// error occurs. At the end of the call (target reached or stopped) a
    /// checkpoint of the current step is written if there is none yet; at
    /// the total, the final model goes to `run_dir/model.safetensors` (+
    /// `model.json`, `model.state.json`). `progress` shows a progress bar
    /// on standard error with the loss, the rate and steps per second.
    ///
    /// # Errors
    /// The objective's; [`TrainError::Diverged`] (converted) when the loss
    /// or the weights stop being finite (nothing is written for that step);
    /// I/O errors naming the file.
    pub fn run_until<O: Objective>(
        &mut self,
        until: u64,
        objective: &mut O,
        stop: &AtomicBool,
        progress: bool,
    ) -> Result<TrainSummary, O::Error> {
        let total = self.config.steps;
        let end = until.min(total);
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
        bar.set_prefix(self.names.what.clone());
        bar.reset_eta();
        let log_path = self.run_dir.join(LOG_FILE);
        let mut log_file = OpenOptions::new()
            .append(true)
            .create(true)
            .open(&log_path)
            .map_err(|e| TrainError::io(&log_path, e))?;
        let session = Instant::now();
        let base_elapsed = self.elapsed;
        let mut stopped = false;
        let mut checkpoint_dir = None;
        while self.step < end {
            if stop.load(Ordering::Relaxed) {
                stopped = true;
                break;
            }
            let (loss, grad_norm, lr) = self.optimizer_step(objective).map_err(|e| {
                divergence(
                    &self.net,
                    self.step,
                    &self.names.what,
                    &self.names.lr_setting,
                    e,
                )
            })?;
            self.step += 1;
            self.last_loss = Some(loss);
            self.log.loss_sum += loss;
            self.log.grad_norm_sum += grad_norm;
            self.log.count += 1;
            self.elapsed = base_elapsed + session.elapsed().as_secs_f64();
            if self.step % self.config.log_every == 0 || self.step == total {
                let n = self.log.count.max(1) as f64;
                let row = format!(
                    "{},{},{},{},{:.3}\n",
                    self.step,
                    self.log.loss_sum / n,
                    lr,
                    self.log.grad_norm_sum / n,
                    self.elapsed
                );
                log_file
                    .write_all(row.as_bytes())
                    .and_then(|()| log_file.flush())
                    .map_err(|e| TrainError::io(&log_path, e))?;
                self.log = LogAccumulator::default();
            }
            let done = (self.step - start_step) as f64;
            bar.set_position(self.step);
            bar.set_message(format!(
                "loss {loss:.4e} lr {lr:.1e} {:.2} steps/s",
                done / session.elapsed().as_secs_f64().max(1e-9)
            ));
            if self.step % self.config.checkpoint_every == 0
                || self.step == total
                || self.config.keep_at.contains(&self.step)
            {
                let files = objective.checkpoint_files()?;
                checkpoint_dir = Some(self.write_checkpoint(files)?);
            }
        }
        if self.last_checkpoint_step != Some(self.step) {
            let files = objective.checkpoint_files()?;
            checkpoint_dir = Some(self.write_checkpoint(files)?);
        }
        let finished = self.step >= total;
        let model = if finished {
            let path = self.run_dir.join(WEIGHTS_FILE);
            self.sampling_net().save(&path).map_err(TrainError::from)?;
            checkpoint::write_final_record(&self.run_dir)?;
            Some(path)
        } else {
            None
        };
        bar.finish_and_clear();
        let seconds = session.elapsed().as_secs_f64();
        let ran = self.step - start_step;
        Ok(TrainSummary {
            start_step,
            end_step: self.step,
            total_steps: total,
            finished,
            stopped,
            seconds,
            seconds_per_step: if ran > 0 { seconds / ran as f64 } else { 0.0 },
            last_loss: self.last_loss,
            checkpoint: checkpoint_dir,
            model,
        })
    }
}

/// Rewrites the log at `path` keeping the header and the rows with `step <=
/// keep` (creates it with only the header when missing): a resumed run
/// first drops the rows after its checkpoint, so rows are never duplicated.
/// A torn last line (a killed run) or any malformed row is dropped.
///
/// # Errors
/// [`TrainError::Files`] naming the log.
pub fn truncate_log(path: &Path, keep: u64) -> Result<()> {
    let text = match std::fs::read_to_string(path) {
        Ok(t) => t,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => String::new(),
        Err(e) => return Err(TrainError::io(path, e)),
    };
    let mut out = String::from(LOG_HEADER);
    out.push('\n');
    let complete = text.ends_with('\n');
    let lines: Vec<&str> = text.lines().skip(1).collect();
    for (i, line) in lines.iter().enumerate() {
        let torn = i + 1 == lines.len() && !complete;
        let fields: Vec<&str> = line.split(',').collect();
        let well_formed = fields.len() == 5 && fields.iter().all(|f| f.parse::<f64>().is_ok());
        let step = fields.first().and_then(|s| s.parse::<u64>().ok());
        if let (false, true, Some(s)) = (torn, well_formed, step) {
            if s <= keep {
                out.push_str(line);
                out.push('\n');
            }
        }
    }
    checkpoint::write_atomic(path, out.as_bytes())
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn log_truncation_keeps_rows_up_to_the_step() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join(LOG_FILE);
        std::fs::write(
            &p,
            format!("{LOG_HEADER}\n5,1,1,1,0\n10,1,1,1,0\n15,1,1,1,0\n1"),
        )
        .unwrap();
        truncate_log(&p, 10).unwrap();
        assert_eq!(
            std::fs::read_to_string(&p).unwrap(),
            format!("{LOG_HEADER}\n5,1,1,1,0\n10,1,1,1,0\n")
        );
    }
}
