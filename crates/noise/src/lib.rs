#![doc = include_str!("../README.md")]

pub mod error;
pub mod kind;
mod rng;
pub mod sampler;
pub mod spectrum;
pub mod stream;

pub use error::{NoiseError, Result};
pub use kind::{DEFAULT_TAU, KindName, KindParameters, NoiseKind};
pub use sampler::{NoiseBatch, NoiseSampler};
pub use spectrum::{SpectralAnalyzer, SpectrumComparison, SpectrumReport, Theory};

/// The linear algebra crate of the sampler's public API (sparse operators,
/// eigenvectors), re-exported so callers use the same version.
pub use faer;
/// The mesh type and procedural meshes of `mfm-geometry`, re-exported so
/// that sampling noise on a mesh needs no other import.
pub use mfm_geometry::{TriMesh, procedural};
