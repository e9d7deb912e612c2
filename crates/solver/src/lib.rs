#![doc = include_str!("../README.md")]

pub mod cholesky;
pub mod eigen;
pub mod error;
mod kernel;
pub mod poisson;
mod sparse;

pub use cholesky::{CholeskyFactor, FactorOptions, Real, SOLVE_CHUNK, SymbolicAnalysis};
pub use eigen::{EigenInfo, EigenMethod, EigenOptions, Eigenpairs, generalized_eigenpairs};
pub use error::{Result, SolverError};
pub use poisson::{LaplacianSolver, ScreenedPoisson, Shift, ShiftOptions};

/// The linear algebra crate of this crate's public API (sparse matrices,
/// dense blocks of right-hand sides), re-exported so callers use the same
/// version.
pub use faer;
