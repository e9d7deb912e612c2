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

impl KernelError {
    /// Whether this error reports a NaN or infinity reaching a sparse solve
    /// ([`mfm_solver::SolverError::NonFinite`]): by its variant when the
    /// solve ran in Rust, by the solver's mark in the text when it ran
    /// inside a libtorch autograd node (whose errors cross libtorch's C++ as
    /// text, [`KernelError::CustomOp`] or [`KernelError::Torch`]).
    pub fn reports_non_finite(&self) -> bool {
        match self {
            Self::Solver(e) => e.is_non_finite(),
            Self::Torch(e) => torch_reports_non_finite(e),
            Self::CustomOp { message, .. } => mfm_solver::SolverError::marks_non_finite(message),
            Self::Operators(_) | Self::Shape { .. } | Self::Kind { .. } => false,
        }
    }
}

/// Whether a libtorch error carries a [`mfm_solver::SolverError::NonFinite`]
/// raised inside one of the crate's autograd nodes (see
/// [`KernelError::reports_non_finite`]).
pub fn torch_reports_non_finite(e: &tch::TchError) -> bool {
    mfm_solver::SolverError::marks_non_finite(&e.to_string())
}

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
