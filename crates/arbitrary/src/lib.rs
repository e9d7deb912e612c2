#![doc = include_str!("../README.md")]

pub mod error;
pub mod evaluate;
pub mod flow;
pub mod folders;
pub mod markers;
pub mod official;
pub mod predictor;
mod run;
pub mod sources;

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use mfm_fm::device::DeviceChoice;
use mfm_train::LrSchedule;
use mfm_train::checkpoint::WEIGHTS_FILE;

pub use error::{ArbitraryError, Result};
pub use run::RESUMABLE_SPEC_FIELDS;

/// The optimization settings shared by both trainings: the settings of
/// the training loop ([`Schedule::loop_config`], [`mfm_train::LoopConfig`])
/// as a run description states them.
///
/// The fields after `checkpoint_every` are optional in the description
/// (absent: their default, and a default value is not written), so runs
/// written before they existed read and resume unchanged.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Schedule {
    /// Base learning rate.
    pub lr: f64,
    /// Meshes (predictor) or pairs (flow) per step.
    pub batch: usize,
    /// Optimizer steps.
    pub steps: u64,
    /// Steps at which the rate is multiplied by `gamma`.
    pub milestones: Vec<u64>,
    /// The factor at each milestone.
    pub gamma: f64,
    /// Largest gradient norm (clipped above; 0: no clipping).
    pub grad_clip: f64,
    /// Random scale in `[0.7, 1.3]` and shift of sd 0.15 per item.
    pub augment: bool,
    /// The run's seed.
    pub seed: u64,
    /// Steps between checkpoints.
    pub checkpoint_every: u64,
    /// Another rate schedule instead of `milestones` and `gamma` (which
    /// must then be empty and 1): e.g. a warm-up and cosine
    /// ([`LrSchedule`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lr_schedule: Option<LrSchedule>,
    /// Adam's `beta1` (default 0.9).
    #[serde(default = "default_beta1", skip_serializing_if = "is_default_beta1")]
    pub adam_beta1: f64,
    /// Adam's `beta2` (default 0.999).
    #[serde(default = "default_beta2", skip_serializing_if = "is_default_beta2")]
    pub adam_beta2: f64,
    /// Adam's `epsilon` (default `1e-8`).
    #[serde(default = "default_eps", skip_serializing_if = "is_default_eps")]
    pub adam_eps: f64,
    /// Decay of the moving average of the weights that the finished model
    /// is (default 0: none; see [`mfm_train::LoopConfig::ema`]).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub ema: f64,
    /// Rolling checkpoints kept (default 2).
    #[serde(default = "default_keep", skip_serializing_if = "is_default_keep")]
    pub keep_checkpoints: usize,
    /// Steps whose checkpoints are kept whatever `keep_checkpoints` says
    /// (default none).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub keep_at: Vec<u64>,
    /// Steps per log row (default 10).
    #[serde(
        default = "default_log_every",
        skip_serializing_if = "is_default_log_every"
    )]
    pub log_every: u64,
    /// Where the network trains (default `auto`: the first CUDA device when
    /// libtorch sees one, else the CPU); the sources' operators and solves
    /// stay on the CPU, as for the flow.
    #[serde(default, skip_serializing_if = "is_auto")]
    pub device: DeviceChoice,
}

fn is_auto(d: &DeviceChoice) -> bool {
    *d == DeviceChoice::Auto
}

fn default_beta1() -> f64 {
    0.9
}
fn is_default_beta1(x: &f64) -> bool {
    *x == default_beta1()
}
fn default_beta2() -> f64 {
    0.999
}
fn is_default_beta2(x: &f64) -> bool {
    *x == default_beta2()
}
fn default_eps() -> f64 {
    1e-8
}
fn is_default_eps(x: &f64) -> bool {
    *x == default_eps()
}
fn is_zero(x: &f64) -> bool {
    *x == 0.0
}
fn default_keep() -> usize {
    2
}
fn is_default_keep(x: &usize) -> bool {
    *x == default_keep()
}
fn default_log_every() -> u64 {
    10
}
fn is_default_log_every(x: &u64) -> bool {
    *x == default_log_every()
}

impl Schedule {
    /// The settings of an official schedule (a step decay by `gamma` at
    /// `milestones`), the optional fields at their defaults.
    #[allow(clippy::too_many_arguments)]
    pub fn step_decay(
        lr: f64,
        batch: usize,
        steps: u64,
        milestones: Vec<u64>,
        gamma: f64,
        grad_clip: f64,
        augment: bool,
        seed: u64,
        checkpoint_every: u64,
    ) -> Self {
        Self {
            lr,
            batch,
            steps,
            milestones,
            gamma,
            grad_clip,
            augment,
            seed,
            checkpoint_every,
            lr_schedule: None,
            adam_beta1: default_beta1(),
            adam_beta2: default_beta2(),
            adam_eps: default_eps(),
            ema: 0.0,
            keep_checkpoints: default_keep(),
            keep_at: Vec::new(),
            log_every: default_log_every(),
            device: DeviceChoice::Auto,
        }
    }

    /// The rate schedule: `lr_schedule` when given, else the step decay by
    /// `gamma` at each of `milestones`.
    pub fn rate_schedule(&self) -> LrSchedule {
        self.lr_schedule
            .clone()
            .unwrap_or_else(|| LrSchedule::Decay {
                factor: self.gamma,
                at: self.milestones.clone(),
            })
    }

    /// The rate at `step`.
    pub fn lr_at(&self, step: u64) -> f64 {
        self.rate_schedule().lr(self.lr, step, self.steps)
    }

    /// The training loop's settings.
    pub fn loop_config(&self) -> mfm_train::LoopConfig {
        mfm_train::LoopConfig {
            steps: self.steps,
            lr: self.lr,
            lr_schedule: self.rate_schedule(),
            grad_clip: self.grad_clip,
            adam_beta1: self.adam_beta1,
            adam_beta2: self.adam_beta2,
            adam_eps: self.adam_eps,
            seed: self.seed,
            checkpoint_every: self.checkpoint_every,
            keep_checkpoints: self.keep_checkpoints,
            keep_at: self.keep_at.clone(),
            log_every: self.log_every,
            ema: self.ema,
        }
    }

    /// Checks the values.
    ///
    /// # Errors
    /// [`ArbitraryError::Config`] naming the field.
    pub fn validate(&self) -> Result<()> {
        let bad = |what: &str, v: String| Err(ArbitraryError::Config(format!("{what}, found {v}")));
        if !(self.lr.is_finite() && self.lr > 0.0) {
            return bad("lr must be finite and > 0", self.lr.to_string());
        }
        if self.batch == 0 || self.steps == 0 || self.checkpoint_every == 0 || self.log_every == 0 {
            return bad(
                "batch, steps, checkpoint_every and log_every must be at least 1",
                format!(
                    "{} / {} / {} / {}",
                    self.batch, self.steps, self.checkpoint_every, self.log_every
                ),
            );
        }
        if !(self.gamma.is_finite() && self.gamma > 0.0) {
            return bad("gamma must be finite and > 0", self.gamma.to_string());
        }
        if !(self.grad_clip.is_finite() && self.grad_clip >= 0.0) {
            return bad(
                "grad_clip must be finite and >= 0 (0: no clipping)",
                self.grad_clip.to_string(),
            );
        }
        if let Some(s) = &self.lr_schedule {
            if !self.milestones.is_empty() || self.gamma != 1.0 {
                return bad(
                    "lr_schedule replaces milestones and gamma: give milestones = [] and gamma = 1 with it",
                    format!("{:?} and {}", self.milestones, self.gamma),
                );
            }
            s.validate()
                .map_err(|e| ArbitraryError::Config(format!("lr_schedule: {e}")))?;
        }
        let betas = [self.adam_beta1, self.adam_beta2];
        if !betas
            .iter()
            .all(|b| b.is_finite() && (0.0..1.0).contains(b))
        {
            return bad(
                "adam_beta1 and adam_beta2 must be in [0, 1)",
                format!("{} and {}", self.adam_beta1, self.adam_beta2),
            );
        }
        if !(self.adam_eps.is_finite() && self.adam_eps > 0.0) {
            return bad("adam_eps must be finite and > 0", self.adam_eps.to_string());
        }
        if !(self.ema.is_finite() && (0.0..1.0).contains(&self.ema)) {
            return bad("ema must be in [0, 1)", self.ema.to_string());
        }
        Ok(())
    }
}

/// The largest relative change of the augmentation's scale.
pub const AUGMENT_SCALE: (f64, f64) = (0.7, 1.3);
/// The standard deviation of the augmentation's shift.
pub const AUGMENT_SHIFT: f64 = 0.15;

/// Where a run puts a source before its networks see it, and where the
/// generated targets end up.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum SourceFrame {
    /// mfm's convention (the default, and what runs written before this
    /// option hold): each source moved into its own canonical frame
    /// ([`to_own_frame`]: bounding box centred, largest extent 1); the
    /// targets come back into the source's units with its mass-weighted
    /// centroid added.
    #[default]
    Own,
    /// The official code's convention (imported runs): sources as they
    /// are, in their own units and place; the targets keep the mass-mean
    /// zero the flow generates (no centroid added back), as the official
    /// sampler writes them.
    AsIs,
}

impl SourceFrame {
    /// Whether this is [`SourceFrame::Own`] (for `skip_serializing_if`: a
    /// run of the default frame writes its description as before).
    pub fn is_own(&self) -> bool {
        *self == Self::Own
    }

    /// Moves `positions` (and `also` by the same map) into this frame:
    /// [`to_own_frame`] for [`SourceFrame::Own`] (returning the frame), no
    /// change for [`SourceFrame::AsIs`] (`None`).
    ///
    /// # Errors
    /// [`ArbitraryError::Source`] for a degenerate bounding box
    /// ([`SourceFrame::Own`] only).
    pub fn apply(
        self,
        positions: &mut [[f64; 3]],
        also: Option<&mut [[f64; 3]]>,
    ) -> Result<Option<mfm_geometry::frame::CanonicalFrame>> {
        match self {
            Self::Own => to_own_frame(positions, also).map(Some),
            Self::AsIs => Ok(None),
        }
    }
}

/// Moves `positions` (and `also`, the same map) into the canonical frame
/// of `positions`' bounding box: centred, largest extent 1. Returns the
/// frame.
///
/// # Errors
/// [`ArbitraryError::Source`] for a degenerate bounding box.
pub fn to_own_frame(
    positions: &mut [[f64; 3]],
    also: Option<&mut [[f64; 3]]>,
) -> Result<mfm_geometry::frame::CanonicalFrame> {
    let frame = mfm_geometry::frame::CanonicalFrame::of_points(positions).map_err(|e| {
        ArbitraryError::Source(format!("a source mesh has a degenerate bounding box: {e}"))
    })?;
    for p in positions.iter_mut() {
        *p = frame.to_canonical(*p);
    }
    if let Some(q) = also {
        for p in q.iter_mut() {
            *p = frame.to_canonical(*p);
        }
    }
    Ok(frame)
}

/// Reads a run folder's JSON description; `what` names it in the error.
pub(crate) fn read_json<T: serde::de::DeserializeOwned>(path: &Path, what: &str) -> Result<T> {
    let text = std::fs::read_to_string(path).map_err(|e| ArbitraryError::io(path, e))?;
    serde_json::from_str(&text).map_err(|e| ArbitraryError::format(path, format!("{what}: {e}")))
}

/// The error for resuming `run_dir` with a configuration other than its
/// stored one, `Ok` when they are equal.
pub(crate) fn same_config<T: PartialEq>(run_dir: &Path, stored: &T, given: &T) -> Result<()> {
    if stored == given {
        return Ok(());
    }
    Err(ArbitraryError::Mismatch(format!(
        "{} was started with another configuration; resume it with the stored one \
         or train into a new folder",
        run_dir.display()
    )))
}

/// The final weights of a finished run in `run_dir` (`what`: the kind of
/// model, for the error).
pub(crate) fn finished_weights(run_dir: &Path, what: &str) -> Result<PathBuf> {
    let weights = run_dir.join(WEIGHTS_FILE);
    if !weights.is_file() {
        return Err(ArbitraryError::RunFolder(format!(
            "{} has no finished {what} ({WEIGHTS_FILE}); train it to the end first",
            run_dir.display()
        )));
    }
    mfm_train::checkpoint::verify_file_record(run_dir, mfm_train::checkpoint::FINAL_RECORD_FILE)?;
    Ok(weights)
}
