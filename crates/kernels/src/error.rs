//! The one error type of the kernels and of the network (`mfm-net`).

use std::path::PathBuf;

/// Everything that can go wrong building, running, saving or loading a
/// PoissonNet.
#[derive(Debug, thiserror::Error)]
pub enum NetError {
    /// An error reported by libtorch (through tch).
    #[error("libtorch: {0}")]
    Torch(#[from] tch::TchError),
    /// An error of the sparse solver (factorization or solve).
    #[error("solver: {0}")]
    Solver(#[from] mfm_solver::SolverError),
    /// An error building the mesh operators.
    #[error("mesh operators: {0}")]
    Operators(#[from] mfm_geometry::operators::OperatorError),
    /// A tensor has the wrong shape for the operation.
    #[error("{what}: expected shape {expected}, found {found:?}")]
    Shape {
        /// Which tensor or operation.
        what: String,
        /// The expected shape, in words (e.g. `[B, V=642, C]`).
        expected: String,
        /// The shape that was passed.
        found: Vec<i64>,
    },
    /// A tensor has an element type the operation does not support.
    #[error("{what}: unsupported element type {kind:?} (expected f32 or f64)")]
    Kind {
        /// Which tensor or operation.
        what: String,
        /// The element type that was passed.
        kind: tch::Kind,
    },
    /// An invalid configuration value.
    #[error("invalid configuration: {0}")]
    Config(String),
    /// A custom autograd operation failed (forward or backward).
    #[error("custom op {op}: {message}")]
    CustomOp {
        /// The operation's name.
        op: String,
        /// What went wrong.
        message: String,
    },
    /// Reading or writing a file failed.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// A configuration file could not be parsed or written.
    #[error("{path}: {source}")]
    Json {
        /// The file.
        path: PathBuf,
        /// The JSON error.
        source: serde_json::Error,
    },
    /// A weights file does not match the network it is loaded into.
    #[error("weights file {path} does not match the network: {detail}")]
    WeightsMismatch {
        /// The weights file.
        path: PathBuf,
        /// What differs (names, shapes or configuration fields).
        detail: String,
    },
}

/// Result alias of this crate and of `mfm-net`.
pub type Result<T, E = NetError> = std::result::Result<T, E>;

/// A [`NetError::Shape`] naming `what`, the expected shape in words and
/// `t`'s actual shape.
pub fn shape_error(
    what: impl Into<String>,
    expected: impl Into<String>,
    t: &tch::Tensor,
) -> NetError {
    NetError::Shape {
        what: what.into(),
        expected: expected.into(),
        found: t.size(),
    }
}

/// The error of a custom operation whose backward pass runs without the
/// state its forward pass saves.
pub fn backward_before_forward(op: &str) -> NetError {
    NetError::CustomOp {
        op: op.to_owned(),
        message: "backward before forward".into(),
    }
}
