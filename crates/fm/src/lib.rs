//! # mfm-fm
//!
//! Flow matching on triangle meshes (DESIGN.md sections 6-8): training a
//! PoissonNet along the rectified-flow path from Matérn noise, ODE sampling
//! on any triangulation, run configurations and checkpoints. The datasets
//! and generators live in the libtorch-free [`mfm_data`] crate and are
//! re-exported here under their old paths (the metrics and quality
//! measures are the `mfm-eval` crate); the
//! arbitrary-source model, built on this crate's context, Adam, seeding
//! and checkpoint format, is the `mfm-arbitrary` crate.

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
pub use mfm_data::{
    DataError, InMemorySignals, SignalSource, dataset, deformations, experiment, gmm, pictures,
    signals,
};
