//! # mfm-train
//!
//! The training loop of every mfm network, one piece per idea: [`Adam`]
//! with exactly restorable state, learning-rate schedules
//! ([`LrSchedule`]), keyed random streams ([`seeding`]), the moving average
//! of the weights, atomic checksummed checkpoints ([`checkpoint`]), the
//! resume check of a run's description ([`resume`]), and the loop that
//! ties them ([`TrainingLoop`]). What one step computes is an
//! [`Objective`]: flow matching on a mesh (`mfm-fm`), and the
//! arbitrary-source model's eigenvector predictor and conditioned flow
//! (`mfm-arbitrary`) are its implementations, so every training gets the
//! same schedules, weight average, checkpoints, logs, divergence checks and
//! resumption.
//!
//! # Example
//! ```no_run
//! use std::sync::atomic::AtomicBool;
//! use mfm_net::{MeshTensors, PoissonNet, PoissonNetConfig, loss};
//! use mfm_train::{LoopConfig, LrSchedule, Objective, RunNames, TrainError, TrainingLoop};
//!
//! /// Fit the network's output to a fixed field on one mesh.
//! struct Fit {
//!     mesh: MeshTensors,
//!     input: tch::Tensor,
//!     target: tch::Tensor,
//! }
//!
//! impl Objective for Fit {
//!     type Error = TrainError;
//!     fn step(&mut self, net: &PoissonNet, _step: u64) -> Result<f64, TrainError> {
//!         let out = net.forward(&self.mesh, &self.input, None)?;
//!         let l = loss::mass_weighted_mse(&self.mesh, &out.vertex, &self.target)?;
//!         l.f_backward()?;
//!         Ok(l.double_value(&[]))
//!     }
//!     fn checkpoint_files(&self) -> Result<Vec<(String, Vec<u8>)>, TrainError> {
//!         Ok(Vec::new())
//!     }
//! }
//!
//! let mesh = mfm_geometry::procedural::icosphere(2);
//! let v = mesh.num_vertices() as i64;
//! let mut fit = Fit {
//!     mesh: MeshTensors::new(&mesh)?,
//!     input: tch::Tensor::ones([1, v, 1], (tch::Kind::Float, tch::Device::Cpu)),
//!     target: tch::Tensor::zeros([1, v, 1], (tch::Kind::Float, tch::Device::Cpu)),
//! };
//! let net = PoissonNetConfig {
//!     width: 8, blocks: 1, vector_layers: 2, in_channels: 1, out_channels: 1,
//!     cond_channels: 0, modulation: true, head: mfm_net::HeadKind::Linear,
//! };
//! let config = LoopConfig {
//!     steps: 100, lr: 1e-3, lr_schedule: LrSchedule::constant(), grad_clip: 1.0,
//!     adam_beta1: 0.9, adam_beta2: 0.999, adam_eps: 1e-8, seed: 0,
//!     checkpoint_every: 50, keep_checkpoints: 2, keep_at: Vec::new(), log_every: 10, ema: 0.0,
//! };
//! let names = RunNames { what: "fit".into(), lr_setting: "lr".into(), randomness: "none".into() };
//! let dir = std::path::Path::new("runs/fit");
//! let mut run = TrainingLoop::new(dir, &net, config, names, tch::Device::Cpu)?;
//! run.start_log()?;
//! let summary = run.run_until(u64::MAX, &mut fit, &AtomicBool::new(false), true)?;
//! println!("{}", summary.line());
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

pub mod adam;
pub mod checkpoint;
pub mod error;
pub mod resume;
pub mod schedule;
pub mod seeding;
pub mod training_loop;

pub use adam::Adam;
pub use error::{Result, TrainError};
pub use schedule::LrSchedule;
pub use training_loop::{
    LOG_HEADER, LoopConfig, Objective, RunNames, StepError, TrainSummary, TrainingLoop, divergence,
    truncate_log,
};
