#![doc = include_str!("../README.md")]

pub mod evaluate;
pub mod flow;
pub mod folders;
pub mod official;
pub mod predictor;
mod run;
pub mod sources;

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use mfm_fm::checkpoint::WEIGHTS_FILE;
use mfm_fm::{FmError, Result};

pub use run::{RESUMABLE_SPEC_FIELDS, TrainReport};

/// The optimization settings shared by both trainings.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Schedule {
    /// Base learning rate (Adam, betas 0.9 / 0.999, eps 1e-8).
    pub lr: f64,
    /// Meshes (predictor) or pairs (flow) per step.
    pub batch: usize,
    /// Optimizer steps.
    pub steps: u64,
    /// Steps at which the rate is multiplied by `gamma`.
    pub milestones: Vec<u64>,
    /// The factor at each milestone.
    pub gamma: f64,
    /// Largest gradient norm (clipped above).
    pub grad_clip: f64,
    /// Random scale in `[0.7, 1.3]` and shift of sd 0.15 per item.
    pub augment: bool,
    /// The run's seed.
    pub seed: u64,
    /// Steps between checkpoints.
    pub checkpoint_every: u64,
}

impl Schedule {
    /// The rate at `step`.
    pub fn lr_at(&self, step: u64) -> f64 {
        let passed = self.milestones.iter().filter(|&&m| m <= step).count();
        self.lr * self.gamma.powi(passed as i32)
    }

    /// Checks the values.
    ///
    /// # Errors
    /// [`FmError::Config`] naming the field.
    pub fn validate(&self) -> Result<()> {
        let bad = |what: &str, v: String| Err(FmError::Config(format!("{what}, found {v}")));
        if !(self.lr.is_finite() && self.lr > 0.0) {
            return bad("lr must be finite and > 0", self.lr.to_string());
        }
        if self.batch == 0 || self.steps == 0 || self.checkpoint_every == 0 {
            return bad(
                "batch, steps and checkpoint_every must be at least 1",
                format!(
                    "{} / {} / {}",
                    self.batch, self.steps, self.checkpoint_every
                ),
            );
        }
        if !(self.gamma.is_finite() && self.gamma > 0.0) {
            return bad("gamma must be finite and > 0", self.gamma.to_string());
        }
        if !(self.grad_clip.is_finite() && self.grad_clip > 0.0) {
            return bad(
                "grad_clip must be finite and > 0",
                self.grad_clip.to_string(),
            );
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
    /// [`FmError::Config`] for a degenerate bounding box
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
/// [`FmError::Config`] for a degenerate bounding box.
pub fn to_own_frame(
    positions: &mut [[f64; 3]],
    also: Option<&mut [[f64; 3]]>,
) -> Result<mfm_geometry::frame::CanonicalFrame> {
    let frame = mfm_geometry::frame::CanonicalFrame::of_points(positions).map_err(|e| {
        FmError::Config(format!("a source mesh has a degenerate bounding box: {e}"))
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
    let text = std::fs::read_to_string(path).map_err(|e| FmError::io(path, e))?;
    serde_json::from_str(&text).map_err(|e| FmError::format(path, format!("{what}: {e}")))
}

/// The error for resuming `run_dir` with a configuration other than its
/// stored one, `Ok` when they are equal.
pub(crate) fn same_config<T: PartialEq>(run_dir: &Path, stored: &T, given: &T) -> Result<()> {
    if stored == given {
        return Ok(());
    }
    Err(FmError::Config(format!(
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
        return Err(FmError::Config(format!(
            "{} has no finished {what} ({WEIGHTS_FILE}); train it to the end first",
            run_dir.display()
        )));
    }
    mfm_fm::checkpoint::verify_file_record(run_dir, mfm_fm::checkpoint::FINAL_RECORD_FILE)?;
    Ok(weights)
}
