//! The error type shared by every fallible entry point of the crate.

use thiserror::Error;

/// Everything that can go wrong when factoring, solving or computing eigenpairs.
///
/// Each variant says what was expected, what was found and where (the index of
/// the offending entry, in the caller's numbering).
#[derive(Debug, Clone, PartialEq, Error)]
pub enum SolverError {
    /// A matrix that must be square is not.
    #[error("expected a square matrix, found {nrows} x {ncols}")]
    NotSquare {
        /// Rows of the matrix that was passed.
        nrows: usize,
        /// Columns of the matrix that was passed.
        ncols: usize,
    },

    /// A vector or block does not have the length the matrix dimension requires.
    #[error(
        "size mismatch: {what} has {found} rows/entries, expected {expected} (the matrix dimension)"
    )]
    SizeMismatch {
        /// Which argument is wrong (e.g. `"mass"`, `"right-hand side"`).
        what: &'static str,
        /// The length implied by the matrix.
        expected: usize,
        /// The length that was passed.
        found: usize,
    },

    /// An input contains a NaN or an infinity.
    #[error("non-finite value {value} in {what} at row {row}, column {col}")]
    NonFinite {
        /// Which argument holds the value.
        what: &'static str,
        /// Row of the value (the entry index for vectors).
        row: usize,
        /// Column of the value (0 for vectors).
        col: usize,
        /// The value found.
        value: f64,
    },

    /// A lumped mass entry is zero or negative.
    #[error("expected a positive lumped mass, found {value} at vertex {index}")]
    NonPositiveMass {
        /// The vertex whose mass is wrong.
        index: usize,
        /// The mass found there.
        value: f64,
    },

    /// A scalar parameter is out of its valid range.
    #[error("invalid parameter {name}: expected {expected}, found {value}")]
    InvalidParameter {
        /// Name of the parameter (e.g. `"tau"`).
        name: &'static str,
        /// What the parameter must satisfy.
        expected: &'static str,
        /// The value passed.
        value: f64,
    },

    /// The Cholesky factorization met a pivot that is not (numerically) positive.
    ///
    /// `column` is the row/column of the *input* matrix (not of the permuted
    /// one) whose pivot failed; `pivot` is the value of the Schur complement
    /// diagonal there (`NaN` when the dense kernel stopped on a pivot that is
    /// zero, negative or not finite before reporting it) and `diagonal` the
    /// original diagonal entry, so `pivot / diagonal` is the relative size of
    /// the pivot.
    #[error(
        "matrix is not positive definite: {}",
        pivot_text(*.column, *.pivot, *.diagonal, *.tolerance)
    )]
    NotPositiveDefinite {
        /// Column (in the caller's numbering) whose pivot failed.
        column: usize,
        /// The Schur-complement pivot found there (`NaN` if unknown).
        pivot: f64,
        /// The diagonal entry of the input matrix at that column.
        diagonal: f64,
        /// The relative pivot tolerance that was applied.
        tolerance: f64,
    },

    /// A shifted factorization kept failing while the shift was grown.
    #[error(
        "factorization of L + eps I failed {attempts} times; the last shift tried was \
         eps = {last_eps:e} (last error: {last_error})"
    )]
    ShiftExhausted {
        /// How many factorizations were attempted.
        attempts: usize,
        /// The largest shift that was tried.
        last_eps: f64,
        /// The error of the last attempt.
        last_error: Box<SolverError>,
    },

    /// A factor was reused with a matrix whose sparsity pattern it was not built for.
    #[error(
        "sparsity pattern mismatch: entry ({row}, {col}) of the lower triangle is not in \
         the pattern of the symbolic analysis"
    )]
    PatternMismatch {
        /// Row of the entry that is not in the analysed pattern.
        row: usize,
        /// Column of that entry.
        col: usize,
    },

    /// More eigenpairs were requested than the problem has (or than the chosen method supports).
    #[error(
        "requested {k} eigenpairs, but at most {max} are available for a matrix of dimension {n}"
    )]
    KTooLarge {
        /// Number of pairs requested.
        k: usize,
        /// The largest valid `k`.
        max: usize,
        /// Dimension of the matrix.
        n: usize,
    },

    /// The iterative eigensolver stopped before every requested pair converged.
    #[error(
        "eigensolver did not converge: {converged} of {k} eigenpairs reached the tolerance \
         {tol:e} after {restarts} restarts (worst relative residual {worst_residual:e})"
    )]
    NotConverged {
        /// Pairs that converged.
        converged: usize,
        /// Pairs requested.
        k: usize,
        /// Restarts performed.
        restarts: usize,
        /// Requested tolerance.
        tol: f64,
        /// Largest relative residual among the requested pairs.
        worst_residual: f64,
    },

    /// A dense or sparse kernel of faer failed (out of memory, index overflow,
    /// no convergence of the dense eigensolver).
    #[error("linear algebra backend failed in {context}: {message}")]
    Backend {
        /// What was being computed.
        context: &'static str,
        /// The backend's message.
        message: String,
    },

    /// An `f64` solve on a solver whose `f64` factor was released to save
    /// memory (`release_f64_factor`); its `f32` solves still work.
    #[error(
        "the f64 factor of {what} was released to save memory; only f32 solves remain \
         (keep the f64 factor for f64 solves)"
    )]
    FactorReleased {
        /// Which operator (e.g. `"L + eps I"`).
        what: &'static str,
    },
}

/// Shorthand for results of this crate.
pub type Result<T, E = SolverError> = std::result::Result<T, E>;

/// The words that open the message of [`SolverError::NonFinite`]. A solve
/// that runs inside a libtorch autograd node reaches its caller as text
/// only (the error crosses libtorch's C++), where
/// [`SolverError::marks_non_finite`] recognises it.
pub const NON_FINITE_MARK: &str = "non-finite value";

impl SolverError {
    /// Whether this is [`SolverError::NonFinite`].
    pub fn is_non_finite(&self) -> bool {
        matches!(self, Self::NonFinite { .. })
    }

    /// Whether `text` holds the message of a [`SolverError::NonFinite`]
    /// (the text of an error that crossed libtorch).
    pub fn marks_non_finite(text: &str) -> bool {
        text.contains(NON_FINITE_MARK)
    }
}

fn pivot_text(column: usize, pivot: f64, diagonal: f64, tolerance: f64) -> String {
    if pivot.is_nan() {
        format!(
            "the pivot of column {column} is zero, negative or not finite (diagonal entry {diagonal:e})"
        )
    } else {
        format!(
            "the pivot of column {column} is {pivot:e}, expected more than {tolerance:e} times its \
             diagonal entry {diagonal:e}"
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_non_finite_message_carries_its_mark_and_no_other_does() {
        let e = SolverError::NonFinite {
            what: "right-hand side",
            row: 3,
            col: 1,
            value: f64::NAN,
        };
        assert!(e.is_non_finite());
        assert!(SolverError::marks_non_finite(&format!(
            "custom op solve: {e}"
        )));
        let other = SolverError::NotSquare { nrows: 2, ncols: 3 };
        assert!(!other.is_non_finite());
        assert!(!SolverError::marks_non_finite(&other.to_string()));
    }
}
