#![doc = include_str!("../README.md")]

pub mod archive;
pub mod error;
pub mod pickle;
pub mod tensor;
pub mod writer;

pub use archive::Checkpoint;
pub use error::{Result, TorchFileError};
pub use pickle::{TensorRef, Value};
pub use tensor::{Dtype, TensorData};
pub use writer::state_dict_archive;
