//! # mfm-solver
//!
//! Sparse linear algebra for triangle-mesh operators, on top of
//! [faer](https://docs.rs/faer):
//!
//! - [`SymbolicAnalysis`] / [`CholeskyFactor`]: a sparse Cholesky cache split
//!   the way faer splits it. The symbolic phase (fill-reducing ordering,
//!   elimination tree, supernodes) depends only on the sparsity pattern and is
//!   reused for new values; the numeric supernodal `L L^T` factor (`f64`, with
//!   an `f32` copy on demand) is shared by any number of threads that solve
//!   blocks of right-hand sides with a cache-friendly multi-RHS kernel.
//! - [`ScreenedPoisson`]: `(L + tau M) x = b`, the operator behind Matérn noise
//!   (factor once, sample many right-hand sides at once).
//! - [`LaplacianSolver`]: `(L + eps I) x = b` for a singular PSD Laplacian, with
//!   the shift grown x10 until the factorization succeeds (PoissonNet's solve).
//! - [`generalized_eigenpairs`]: the `k` smallest pairs of
//!   `L phi = lambda M phi`, by shift-invert block Krylov-Schur on the Cholesky
//!   cache (large meshes) or a dense eigendecomposition (small ones).
//!
//! ## Conventions
//! - Sparse matrices are `faer::sparse::SparseColMat<usize, f64>` (or views of
//!   them). Symmetric matrices are read through their **lower triangle only**.
//! - `L` is positive semi-definite (mfm's cotangent Laplacian convention, the
//!   negative of libigl's `cotmatrix`); `M` is the lumped mass, passed as the
//!   slice of its diagonal.
//! - Blocks of right-hand sides are `n x k` faer matrices, one right-hand side
//!   per column; results come back in the same layout.
//! - Results are deterministic: they do not depend on the number of threads,
//!   and each column of a block solve is bit-identical to solving that column
//!   alone (on a given machine and instruction set).
//!
//! This crate depends on neither libtorch, Python nor the mesh crate: its
//! inputs are sparse matrices and slices.
//!
//! ## Example
//! ```
//! use faer::Mat;
//! use faer::sparse::{SparseColMat, Triplet};
//! use mfm_solver::{EigenOptions, ScreenedPoisson, generalized_eigenpairs};
//!
//! // Laplacian of a cycle graph (a "closed mesh" in 1D), unit masses
//! let n = 50;
//! let mut t = Vec::new();
//! for i in 0..n {
//!     let j = (i + 1) % n;
//!     t.extend([
//!         Triplet::new(i, i, 1.0), Triplet::new(j, j, 1.0),
//!         Triplet::new(i, j, -1.0), Triplet::new(j, i, -1.0),
//!     ]);
//! }
//! let l = SparseColMat::<usize, f64>::try_new_from_triplets(n, n, &t).unwrap();
//! let mass = vec![1.0; n];
//!
//! // Matérn-style sampling: factor L + tau M once, solve 64 right-hand sides
//! let sp = ScreenedPoisson::new(&l, &mass, 10.0).unwrap();
//! let b = Mat::<f64>::from_fn(n, 64, |i, j| ((i * 31 + j * 17) % 7) as f64 - 3.0);
//! let x = sp.solve_many(b.as_ref()).unwrap();
//! assert_eq!((x.nrows(), x.ncols()), (n, 64));
//!
//! // the smallest eigenpairs: 0 (constant eigenvector), then 2 - 2 cos(2 pi / n) twice
//! let pairs = generalized_eigenpairs(&l, &mass, 3, &EigenOptions::default()).unwrap();
//! assert!(pairs.values[0].abs() < 1e-12);
//! assert!((pairs.values[1] - (2.0 - 2.0 * (std::f64::consts::TAU / n as f64).cos())).abs() < 1e-12);
//! ```

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
