//! # mfm-data
//!
//! The data side of flow matching on meshes, without libtorch: datasets of
//! signals over one mesh (folder format, streaming reads, validation), the
//! GMM and deformation generators, their experiment meshes and folder
//! layout with previews, and the arbitrary-source model's data: (source,
//! target) shape pairs of a template ([`pairs`]) and the template's
//! eigenvectors with fixed signs ([`eigenbasis`]). What is measured of
//! generated sets against these data (metrics, quality fits, the `mfm eval`
//! protocol) is the `mfm-eval` crate; `mfm-fm` trains and samples on top of
//! this one; `mfm` built without its network feature uses both alone.

pub mod dataset;
pub mod deformations;
pub mod eigenbasis;
pub mod error;
pub mod experiment;
pub mod gmm;
pub mod import;
pub mod layout;
pub mod pairs;
pub mod pictures;
pub mod signals;
pub mod transfer;

pub use error::{DataError, Result};
pub use signals::{InMemorySignals, SignalSource};
