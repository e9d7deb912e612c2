//! The arbitrary-source model (the paper's section 5.1 and supplementary,
//! "Arbitrary 3D human shapes model"): one network that generates target
//! shapes over source meshes it never saw.
//!
//! Two networks, trained one after the other on a pairs dataset
//! ([`mfm_data::pairs`]: poses of body shapes of one template):
//!
//! 1. The **eigenvector predictor** ([`predictor`]): a PoissonNet (linear
//!    head) that maps a source's vertex positions to the first `k`
//!    eigenvectors of the template's Laplacian
//!    ([`mfm_data::eigenbasis::Eigenbasis`]), trained on every mesh of the
//!    dataset with a mass-weighted MSE. On a new source it gives a
//!    positional encoding that follows the body, not the triangulation.
//! 2. The **flow** ([`flow`]): a PoissonNet (NJF head) whose every block is
//!    conditioned on the source's positions, `t` and the frozen predictor's
//!    output on the source (`3 + 1 + k` channels), trained on (source,
//!    target) pairs with each source's own operators, noise and Poisson
//!    solves ([`sources::SourceSet`]: one symbolic analysis, numeric
//!    factorizations per source).
//!
//! ## Frames
//! Every source is moved into its own canonical frame
//! ([`mfm_geometry::frame`]: bounding box centred, largest extent 1) and
//! its target by the same map; generated targets come back through the
//! inverse. With augmentation (the official recipe) both then get one
//! random scale in `[0.7, 1.3]` and one Gaussian shift of standard
//! deviation 0.15 per item.
//!
//! ## Randomness
//! Every random choice of step `s` (items, times, noise, augmentation) is a
//! pure function of `(seed, s)`, so a resumed run repeats an uninterrupted
//! one.

pub mod evaluate;
pub mod flow;
pub mod predictor;
mod run;
pub mod sources;

use serde::{Deserialize, Serialize};

use crate::error::{FmError, Result};

pub use run::TrainReport;

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
    let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
    for p in positions.iter() {
        for a in 0..3 {
            lo[a] = lo[a].min(p[a]);
            hi[a] = hi[a].max(p[a]);
        }
    }
    let extent = (0..3).map(|a| hi[a] - lo[a]).fold(0.0, f64::max);
    if !(extent.is_finite() && extent > 0.0) {
        return Err(FmError::Config(format!(
            "a source mesh has a degenerate bounding box (largest extent {extent})"
        )));
    }
    let scale = 1.0 / extent;
    let shift: [f64; 3] = std::array::from_fn(|a| -0.5 * (lo[a] + hi[a]) * scale);
    let frame = mfm_geometry::frame::CanonicalFrame { scale, shift };
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
