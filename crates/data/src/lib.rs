//! # mfm-data
//!
//! The data side of flow matching on meshes, without libtorch: datasets of
//! signals over one mesh (folder format, streaming reads, validation), the
//! GMM and deformation generators, their experiment meshes and folder
//! layout, the
//! distribution metrics (MMD, COV, 1-NNA, test error) and the
//! sample-quality measures that a flat, noisy or collapsed sample set cannot
//! pass, and the arbitrary-source model's data: (source, target) shape
//! pairs of a template ([`pairs`]) and the template's eigenvectors with
//! fixed signs ([`eigenbasis`]). `mfm-fm` trains and samples on top of it; `mfm` built without its
//! network feature uses this crate alone.

pub mod dataset;
pub mod deformations;
pub mod eigenbasis;
pub mod error;
pub mod evaluation;
pub mod experiment;
pub mod gmm;
pub mod layout;
pub mod metrics;
pub mod pairs;
pub mod pictures;
pub mod quality;
pub mod signals;

pub use error::{DataError, Result};
pub use signals::{InMemorySignals, SignalSource};
