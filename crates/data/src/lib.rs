#![doc = include_str!("../README.md")]

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
pub mod principal;
pub mod signals;
pub mod transfer;

pub use error::{DataError, Result};
pub use signals::{InMemorySignals, SignalSource};
