//! The error of the kernels: libtorch, the sparse solve, the mesh operators
//! and the tensors passed in. `mfm-net`'s `NetError` holds it beside the
//! network's own errors (configuration, weights files).

/// Everything that can go wrong building or running a kernel or a mesh
/// operator as a tensor operation.
#[derive(Debug, thiserror::Error)]
pub enum KernelError {
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
    /// A custom autograd operation failed (forward or backward).
    #[error("custom op {op}: {message}")]
    CustomOp {
        /// The operation's name.
        op: String,
        /// What went wrong.
        message: String,
    },
}

/// Result alias of this crate.
pub type Result<T, E = KernelError> = std::result::Result<T, E>;

/// A [`KernelError::Shape`] naming `what`, the expected shape in words and
/// `t`'s actual shape.
pub fn shape_error(
    what: impl Into<String>,
    expected: impl Into<String>,
    t: &tch::Tensor,
) -> KernelError {
    KernelError::Shape {
        what: what.into(),
        expected: expected.into(),
        found: t.size(),
    }
}

/// The error of a custom operation whose backward pass runs without the
/// state its forward pass saves.
pub fn backward_before_forward(op: &str) -> KernelError {
    KernelError::CustomOp {
        op: op.to_owned(),
        message: "backward before forward".into(),
    }
}
