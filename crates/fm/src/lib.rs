#![doc = include_str!("../README.md")]

pub mod adam;
pub mod checkpoint;
pub mod config;
pub mod context;
pub mod error;
pub mod official;
pub mod run_folder;
pub mod sample;
pub mod sample_folder;
pub mod seeding;
pub mod train;

pub use error::{FmError, Result};
pub use mfm_data::{
    DataError, InMemorySignals, SignalSource, dataset, deformations, experiment, gmm, pictures,
    signals,
};
