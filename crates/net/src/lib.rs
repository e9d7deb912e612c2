#![doc = include_str!("../README.md")]

#[cfg(feature = "bench")]
pub mod bench;
pub mod config;
pub mod error;
pub mod layers;
pub mod loss;
pub mod model;
pub mod official;

pub use config::{HeadKind, PRESETS, PoissonNetConfig};
pub use error::{KernelError, NetError, Result};
pub use mfm_kernels::{Backend, MeshTensors, mesh, runtime};
pub use model::{LayerRow, PoissonNet, PoissonNetOutput, Summary};
