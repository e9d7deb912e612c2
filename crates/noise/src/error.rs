//! The error type of every fallible entry point of the crate.

use mfm_geometry::operators::OperatorError;
use mfm_solver::SolverError;
use thiserror::Error;

/// Everything that can go wrong when building a sampler, sampling, analysing
/// a spectrum or drawing a plot.
///
/// Each variant says what was expected, what was found and where.
#[derive(Debug, Error)]
pub enum NoiseError {
    /// A parameter of a [`NoiseKind`](crate::NoiseKind) or of an analysis is
    /// out of range.
    #[error("invalid parameter {name}: expected {expected}, found {found}")]
    InvalidParameter {
        /// Name of the parameter (`"tau"`, `"c"`, `"k"`, ...).
        name: &'static str,
        /// What it must satisfy.
        expected: &'static str,
        /// The value given, as text.
        found: String,
    },

    /// A noise-kind specification string could not be parsed.
    #[error("cannot parse noise kind {input:?}: {reason}")]
    ParseKind {
        /// The text given.
        input: String,
        /// What was wrong with it, and the accepted forms.
        reason: String,
    },

    /// A parameter was given, in the long form of a noise kind
    /// ([`NoiseKind::from_parts`](crate::NoiseKind::from_parts)), to a kind
    /// that does not take it.
    #[error("{parameter} does not apply to {kind} noise{hint}")]
    UnusedParameter {
        /// The kind's name (`"matern"`, ...).
        kind: &'static str,
        /// The parameter (`"tau"`, `"c"`, `"k"`).
        parameter: &'static str,
        /// What to give instead, as `" (...)"`, or empty.
        hint: &'static str,
    },

    /// A vertex has a lumped mass that is zero, negative or not finite (an
    /// unreferenced vertex, or a degenerate neighbourhood).
    #[error("vertex {vertex} has lumped mass {mass:e}; expected a finite mass > 0 at every vertex")]
    NonPositiveMass {
        /// Vertex number (0-based).
        vertex: usize,
        /// Its mass.
        mass: f64,
    },

    /// Two sizes that must agree do not.
    #[error("size mismatch: {what} has {found}, expected {expected}")]
    SizeMismatch {
        /// What was measured (e.g. `"mass vector length"`).
        what: &'static str,
        /// The size implied by the other inputs.
        expected: usize,
        /// The size found.
        found: usize,
    },

    /// The mesh operators could not be built (a degenerate face).
    #[error("cannot build the mesh operators: {0}")]
    Operators(#[from] OperatorError),

    /// An output file could not be written.
    #[error(transparent)]
    File(#[from] mfm_files::FileError),

    /// A factorization, solve or eigensolve failed.
    #[error("linear algebra failed: {0}")]
    Solver(#[from] SolverError),

    /// A batch would hold more values than memory can address.
    #[error(
        "a batch of {samples} samples x {vertices} vertices x {channels} channels is too large"
    )]
    TooLarge {
        /// Samples requested.
        samples: usize,
        /// Vertices of the mesh.
        vertices: usize,
        /// Channels requested.
        channels: usize,
    },
}

/// Shorthand for results of this crate.
pub type Result<T, E = NoiseError> = std::result::Result<T, E>;
