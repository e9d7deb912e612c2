//! A flow run's folder: its layout, the [`FlowSpec`] (what sampling needs
//! besides the weights), and the check of its checkpoints. The checkpoint
//! format itself (atomic folders, checksums, pruning, the final model's
//! record) is every training's: [`mfm_train::checkpoint`].
//!
//! ## Layout of a run folder
//! ```text
//! run/
//!   config.toml              the RunConfig the run was started with
//!   flow.json                FlowSpec: what sampling needs besides the weights
//!   prior.safetensors        the data prior (runs with noise.prior only; crate::prior)
//!   train_log.csv            step,loss,lr,grad_norm,seconds (one row per log interval)
//!   checkpoints/
//!     step-000001000/        one checkpoint (the newest `keep_checkpoints` are kept)
//!       model.safetensors    network weights
//!       model.json           network configuration (PoissonNetConfig)
//!       optimizer.safetensors Adam moments `m.<variable>`, `v.<variable>`
//!       ema.safetensors      the weight average (runs with train.ema; + ema.json)
//!       config.toml          copy of the run configuration
//!       flow.json            copy of the flow spec
//!       state.json           CheckpointState: step, seed, log accumulators,
//!                            size and CRC-32 of every other file
//!   model.safetensors        the final model (when training finished; the
//!                            weight average for runs with train.ema)
//!   model.json
//!   model.state.json         size and CRC-32 of the two files above
//! ```
//!
//! [`verify_checkpoint`] re-reads every file of a checkpoint and compares
//! sizes and CRC-32s, so a truncated or corrupted file is reported by name
//! before anything is loaded.

use std::path::Path;

use mfm_geometry::frame::{CanonicalFrame, SurfaceSize};
use mfm_noise::NoiseKind;
use serde::{Deserialize, Serialize};

use mfm_train::checkpoint::{
    CheckpointState, NET_CONFIG_FILE, NewestValid, OPTIMIZER_FILE, WEIGHTS_FILE, newest_valid_with,
    verify_checkpoint_listing, write_atomic,
};

use crate::error::{FmError, Result};

/// The run configuration file (in the run folder and in each checkpoint).
pub const CONFIG_FILE: &str = mfm_files::owned::RUN_CONFIG;
/// The [`FlowSpec`] file (in the run folder and in each checkpoint).
pub const FLOW_FILE: &str = mfm_files::owned::RUN_FLOW;

/// What a trained model needs besides its weights to generate samples:
/// the noise it starts from and how the network is conditioned. Fixed when
/// training starts (named noise scales and the mean offset are resolved on
/// the training data then) and stored as `flow.json`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FlowSpec {
    /// Channels `C` per vertex of the signals.
    pub channels: usize,
    /// The noise kind (command-line form in the file).
    #[serde(with = "mfm_noise::kind::as_text")]
    pub noise: NoiseKind,
    /// Factor applied to every noise sample.
    pub noise_scale: f64,
    /// Whether the network is conditioned on source xyz as well as `t`
    /// (conditioning `[x, y, z, t]` per vertex; otherwise `[t]`).
    pub condition_on_xyz: bool,
    /// The dataset's per-channel mean (`C` values; zeros when disabled),
    /// added to every sample, see
    /// [`ModelConfig::mean_offset`](crate::config::ModelConfig::mean_offset):
    /// after the last ODE step when [`FlowSpec::centered`], as a constant
    /// velocity otherwise.
    pub velocity_offset: Vec<f64>,
    /// The training frame: the map from the dataset's units to the frame the
    /// network saw ([`mfm_geometry::frame`]). Sampling meshes go through it
    /// and position samples come back through its inverse. Identity for runs
    /// written before frames existed.
    #[serde(default)]
    pub frame: CanonicalFrame,
    /// Whether the signals are vertex positions (mapped by the frame) rather
    /// than values (left alone). `false` for runs written before frames.
    #[serde(default)]
    pub positions: bool,
    /// Whether noise and targets were centred by their mass-weighted means
    /// ([`TrainConfig::center`](crate::config::TrainConfig::center));
    /// `false` for runs written before centring.
    #[serde(default)]
    pub centered: bool,
    /// Size of the training surface in the dataset's units, to tell a user
    /// whose sampling mesh is not that surface (or not in those units).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub training_surface: Option<SurfaceSize>,
    /// What the network's vertex output is
    /// ([`ModelConfig::prediction`](crate::config::ModelConfig::prediction));
    /// the velocity for runs written before the choice existed.
    #[serde(default, skip_serializing_if = "Prediction::is_velocity")]
    pub prediction: Prediction,
    /// Whether the flow generates displacements of the sampled mesh
    /// ([`ModelConfig::displacements`](crate::config::ModelConfig::displacements)):
    /// a sample is the ODE's end plus the mesh's own vertices (in the
    /// training frame). `false` for runs written before the choice existed.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub displacements: bool,
    /// The data prior every start adds to its noise ([`crate::prior`];
    /// `noise.prior`), with the size and checksum of its file. `None` for
    /// runs without one, and not written then.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub prior: Option<crate::prior::PriorSpec>,
}

/// What a flow network predicts.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Prediction {
    /// The velocity `v(x_t, t)` itself (the paper's).
    #[default]
    Velocity,
    /// The clean signal `x1_hat(x_t, t)`; the velocity is
    /// `(x1_hat - x_t) / (1 - t)`. The NJF head's Jacobian output is then
    /// the predicted signal's gradient.
    Clean,
}

impl Prediction {
    /// `true` for [`Prediction::Velocity`].
    pub fn is_velocity(&self) -> bool {
        *self == Self::Velocity
    }
}

impl FlowSpec {
    /// One line on the frame and the noise, for a run's log (`None` when
    /// the data is trained as it is, in the identity frame).
    pub fn frame_summary(&self) -> Option<String> {
        if self.frame.is_identity() {
            return None;
        }
        let sh = self.frame.shift;
        Some(format!(
            "frame: p -> {:.4} p + [{:.4}, {:.4}, {:.4}] (bounding box centred, largest extent 1){}; noise {} x {}{}",
            self.frame.scale,
            sh[0],
            sh[1],
            sh[2],
            match (self.positions, self.displacements) {
                (true, true) => ", positions moved with it, generated as displacements of the mesh",
                (true, false) => ", positions moved with it",
                _ => "",
            },
            self.noise,
            self.noise_scale,
            if self.centered {
                ", noise and targets centred"
            } else {
                ""
            }
        ))
    }

    /// Reads a `flow.json`.
    ///
    /// # Errors
    /// [`FmError::Files`] (`Io`) / [`FmError::Files`] (`Format`) naming the file; a spec whose
    /// offset length differs from its channel count is a format error.
    pub fn read(path: impl AsRef<Path>) -> Result<Self> {
        let path = path.as_ref();
        let text = std::fs::read_to_string(path).map_err(|e| FmError::io(path, e))?;
        let spec: Self = serde_json::from_str(&text)
            .map_err(|e| FmError::format(path, format!("invalid flow spec: {e}")))?;
        if spec.velocity_offset.len() != spec.channels || spec.channels == 0 {
            return Err(FmError::format(
                path,
                format!(
                    "velocity_offset has {} values for {} channels",
                    spec.velocity_offset.len(),
                    spec.channels
                ),
            ));
        }
        let f = spec.frame;
        if !(f.scale.is_finite() && f.scale > 0.0 && f.shift.iter().all(|x| x.is_finite())) {
            return Err(FmError::format(
                path,
                format!(
                    "frame must have a finite scale > 0 and a finite shift, found scale {} and shift {:?}",
                    f.scale, f.shift
                ),
            ));
        }
        if spec.positions && spec.channels != 3 {
            return Err(FmError::format(
                path,
                format!("positions need 3 channels, the spec has {}", spec.channels),
            ));
        }
        if spec.displacements && !spec.positions {
            return Err(FmError::format(
                path,
                "displacements need position signals, the spec has positions = false",
            ));
        }
        if !(spec.noise_scale.is_finite() && spec.noise_scale > 0.0) {
            return Err(FmError::format(
                path,
                format!(
                    "noise_scale must be finite and > 0, found {}",
                    spec.noise_scale
                ),
            ));
        }
        Ok(spec)
    }

    /// The spec as pretty-printed JSON (the contents of `flow.json`).
    ///
    /// # Errors
    /// [`FmError::Config`] when it cannot be serialized.
    pub fn to_json(&self) -> Result<String> {
        serde_json::to_string_pretty(self)
            .map_err(|e| FmError::Config(format!("cannot serialize the flow spec: {e}")))
    }

    /// Writes the spec as JSON, atomically.
    ///
    /// # Errors
    /// [`FmError::Files`] (`Io`) naming the file.
    pub fn write(&self, path: impl AsRef<Path>) -> Result<()> {
        let path = path.as_ref();
        let json = serde_json::to_string_pretty(self)
            .map_err(|e| FmError::format(path, format!("cannot serialize the flow spec: {e}")))?;
        Ok(write_atomic(path, json.as_bytes())?)
    }
}

/// The files every checkpoint of a flow run lists: the weights, the
/// network configuration, the optimizer, [`CONFIG_FILE`], [`FLOW_FILE`].
pub const FLOW_CHECKPOINT_FILES: [&str; 5] = [
    WEIGHTS_FILE,
    NET_CONFIG_FILE,
    OPTIMIZER_FILE,
    CONFIG_FILE,
    FLOW_FILE,
];

/// Reads a flow checkpoint's `state.json` and checks every file it lists
/// (size, then CRC-32) and that it lists [`FLOW_CHECKPOINT_FILES`].
///
/// Cost: one read of every file of the checkpoint.
///
/// # Errors
/// [`FmError::Files`] (`Io`) for a missing or unreadable file, (`Format`)
/// naming the file that is truncated, corrupted, or unparsable.
pub fn verify_checkpoint(dir: &Path) -> Result<CheckpointState> {
    Ok(verify_checkpoint_listing(dir, &FLOW_CHECKPOINT_FILES)?)
}

/// The newest checkpoint of a flow run that passes [`verify_checkpoint`],
/// and the newer ones that did not, each with its error (newest first).
///
/// # Errors
/// [`FmError::Files`] (`Io`) if the checkpoint folder cannot be listed.
pub fn newest_valid_checkpoint(run_dir: &Path) -> Result<NewestValid> {
    Ok(newest_valid_with(run_dir, |dir| {
        verify_checkpoint_listing(dir, &FLOW_CHECKPOINT_FILES)
    })?)
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use mfm_geometry::frame::{CanonicalFrame, SurfaceSize};

    #[test]
    fn flow_specs_of_earlier_runs_read_as_identity_frame_and_uncentred() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join(FLOW_FILE);
        let old = r#"{"channels": 1, "noise": "matern:100", "noise_scale": 1.0,
                      "condition_on_xyz": false, "velocity_offset": [0.25]}"#;
        std::fs::write(&path, old).unwrap();
        let spec = FlowSpec::read(&path).unwrap();
        assert!(spec.frame.is_identity() && !spec.centered && !spec.positions);
        assert_eq!(spec.training_surface, None);
        // and a new spec round-trips with its frame
        let mut new = spec.clone();
        new.frame = CanonicalFrame {
            scale: 0.5,
            shift: [1.0, -2.0, 0.25],
        };
        new.centered = true;
        new.training_surface = Some(SurfaceSize {
            extent: 2.0,
            area: 3.0,
            euler: Some(2),
            components: Some(1),
        });
        new.write(&path).unwrap();
        assert_eq!(FlowSpec::read(&path).unwrap(), new);
        // a degenerate frame is refused, naming the file
        let bad = old.replace(
            "[0.25]}",
            r#"[0.25], "frame": {"scale": 0.0, "shift": [0, 0, 0]}}"#,
        );
        std::fs::write(&path, bad).unwrap();
        let e = FlowSpec::read(&path).unwrap_err().to_string();
        assert!(e.contains("frame") && e.contains(FLOW_FILE), "{e}");
    }
}
