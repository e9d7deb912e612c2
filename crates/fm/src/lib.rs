//! # mfm-fm
//!
//! Flow matching on triangle meshes (DESIGN.md sections 6-8): datasets of
//! signals over one mesh, the GMM generator, training a PoissonNet along the
//! rectified-flow path from Matérn noise, ODE sampling on any triangulation,
//! checkpoints, the evaluation metrics, and sample-quality measures.

pub mod checkpoint;
pub mod config;
pub mod dataset;
pub mod deformations;
pub mod error;
pub mod experiment;
pub mod geodesic;
pub mod gmm;
pub mod metrics;
pub mod quality;
pub mod sample;
pub mod signals;
pub mod train;

pub use error::{FmError, Result};
pub use signals::{InMemorySignals, SignalSource};
