#![doc = include_str!("../README.md")]

pub mod checkpoint;
pub mod config;
pub mod context;
pub mod coupling;
pub mod device;
pub mod error;
pub mod official;
pub mod path;
pub mod presets;
pub mod prior;
pub mod run_folder;
pub mod sample;
pub mod sample_folder;
pub mod train;

pub use error::{FmError, Result};
