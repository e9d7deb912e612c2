//! How mfm's errors reach Python: `ValueError` for bad input (with the
//! argument or file named first), `FileNotFoundError` / `OSError` for files
//! that cannot be opened or written, `RuntimeError` for a computation that
//! failed on valid input (a factorization that did not succeed).

use pyo3::PyErr;
use pyo3::exceptions::{PyFileNotFoundError, PyOSError, PyRuntimeError, PyValueError};

/// A `ValueError` with `message`.
pub fn value_error(message: impl Into<String>) -> PyErr {
    PyValueError::new_err(message.into())
}

/// A `ValueError` that names the argument: `"{argument}: {problem}"`.
pub fn bad_argument(argument: &str, problem: impl std::fmt::Display) -> PyErr {
    PyValueError::new_err(format!("{argument}: {problem}"))
}

/// A `RuntimeError` with `message`.
pub fn runtime_error(message: impl Into<String>) -> PyErr {
    PyRuntimeError::new_err(message.into())
}

/// The exception for a failed file read or write: `FileNotFoundError` for a
/// missing file, `OSError` for other I/O failures, `ValueError` for a file
/// that was read but is not a valid mesh (`message` is the CLI's own).
pub fn file_error(io: Option<&std::io::Error>, message: String) -> PyErr {
    match io {
        Some(e) if e.kind() == std::io::ErrorKind::NotFound => {
            PyFileNotFoundError::new_err(message)
        }
        Some(_) => PyOSError::new_err(message),
        None => PyValueError::new_err(message),
    }
}
