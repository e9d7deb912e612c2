//! # mfm-fm
//!
//! Flow matching on triangle meshes (DESIGN.md sections 6-8): training a
//! PoissonNet along the rectified-flow path from Matérn noise, ODE sampling
//! on any triangulation, run configurations and the flow's run folders. The
//! datasets and generators are the libtorch-free [`mfm_data`] crate, the
//! metrics and quality measures `mfm-eval`, the training loop (Adam,
//! schedules, seeding, checkpoints) [`mfm_train`]; the arbitrary-source
//! model, built on this crate's context, path and sampling, is the
//! `mfm-arbitrary` crate.

pub mod checkpoint;
pub mod config;
pub mod context;
pub mod device;
pub mod error;
pub mod official;
pub mod path;
pub mod presets;
pub mod run_folder;
pub mod sample;
pub mod sample_folder;
pub mod train;

pub use error::{FmError, Result};
