#![doc = include_str!("../README.md")]

pub mod atomic;
pub mod error;
pub mod guard;
pub mod interrupt;
pub mod lock;
pub mod matrix_market;
pub mod npy;
pub mod owned;
pub mod run_folder;
pub mod space;
pub mod text;
pub mod undo;

pub use atomic::{AtomicFile, open_regular, read_regular, write_atomic, write_json};
pub use error::FileError;
pub use guard::{Outputs, ensure_empty_dir};
pub use lock::FolderLock;
pub use text::fmt_f64;
pub use undo::Undo;
