//! PyTorch checkpoint files without Python or libtorch.
//!
//! `torch.save` writes a zip archive whose `data.pkl` is a Python pickle of
//! the saved object and whose `data/<key>` records hold tensor elements.
//! This crate reads such files with a restricted unpickler
//! ([`pickle::unpickle`]) that builds only plain values, containers and
//! tensor references, never importing or calling what a file names, and
//! refuses a file holding anything else, naming the entry
//! ([`Checkpoint::open`]); and writes state dicts in the same format
//! ([`state_dict_archive`]), readable by `torch.load(..., weights_only=True)`.
//!
//! It is what `mfm import` reads the authors' Lightning checkpoints with and
//! what `mfm export-weights` writes.

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
