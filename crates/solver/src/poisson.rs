//! Screened Poisson `(L + tau M) x = b` and shifted Laplacian `(L + eps I) x = b`
//! solvers built on the Cholesky cache.
//!
//! ## Conventions
//! - `L` is a symmetric positive **semi**-definite sparse matrix (the cotangent
//!   Laplacian in mfm's PSD convention, `L_ii > 0`, `L_ij <= 0` for
//!   Delaunay-like meshes). Only its lower triangle is read.
//! - `M` is diagonal and given as a slice of its (strictly positive) diagonal:
//!   the lumped mass.
//! - Right-hand-side blocks are `n x k` `faer` matrices, one right-hand side
//!   per column; the results come back with the same layout (column-major,
//!   contiguous for the returned [`Mat`]). Data held in a plain slice of
//!   `n * k` values, column after column, is viewed as such a block with
//!   `faer::MatMut::from_column_major_slice_mut(slice, n, k)`.
//!
//! ## Example
//! ```
//! use faer::Mat;
//! use faer::sparse::{SparseColMat, Triplet};
//! use mfm_solver::ScreenedPoisson;
//! // path-graph Laplacian on 4 vertices, unit masses
//! let n = 4;
//! let mut t = Vec::new();
//! for i in 0..n - 1 {
//!     t.extend([
//!         Triplet::new(i, i, 1.0), Triplet::new(i + 1, i + 1, 1.0),
//!         Triplet::new(i, i + 1, -1.0), Triplet::new(i + 1, i, -1.0),
//!     ]);
//! }
//! let l = SparseColMat::<usize, f64>::try_new_from_triplets(n, n, &t).unwrap();
//! let mass = vec![1.0; n];
//! let sp = ScreenedPoisson::new(&l, &mass, 2.0).unwrap();
//! // a constant right-hand side c gives the constant c / tau (L 1 = 0)
//! let x = sp.solve(&[3.0; 4]).unwrap();
//! assert!(x.iter().all(|v| (v - 1.5).abs() < 1e-12));
//! // 64 right-hand sides at once
//! let b = Mat::<f64>::from_fn(n, 64, |i, j| (i + j) as f64);
//! let xs = sp.solve_many(b.as_ref()).unwrap();
//! assert_eq!((xs.nrows(), xs.ncols()), (4, 64));
//! ```

use std::sync::{Arc, OnceLock};

use faer::sparse::SparseColMat;
use faer::{Mat, MatMut, MatRef};

use crate::cholesky::{CholeskyFactor, FactorOptions, SymbolicAnalysis};
use crate::error::{Result, SolverError};
use crate::sparse::{
    check_block, check_finite_matrix, check_mass, check_positive, check_square, check_vector,
};

/// A factor held in `f64`, with its `f32` copy made on first use; once only
/// `f32` solves remain, the `f64` values can be released
/// ([`FactorPair::release_f64`]), which halves what the pair holds.
///
/// Invariant: at least one of the two is present, and the `f32` copy is
/// made before the `f64` values go.
#[derive(Debug)]
struct FactorPair {
    f64: Option<CholeskyFactor>,
    f32: OnceLock<CholeskyFactor<f32>>,
    /// Which operator, for [`SolverError::FactorReleased`].
    what: &'static str,
}

impl FactorPair {
    fn new(factor: CholeskyFactor, what: &'static str) -> Self {
        Self {
            f64: Some(factor),
            f32: OnceLock::new(),
            what,
        }
    }

    fn f64(&self) -> Result<&CholeskyFactor> {
        self.f64
            .as_ref()
            .ok_or(SolverError::FactorReleased { what: self.what })
    }

    fn f32(&self) -> &CholeskyFactor<f32> {
        match (self.f32.get(), &self.f64) {
            (Some(f), _) => f,
            (None, Some(f64)) => self.f32.get_or_init(|| f64.to_f32()),
            (None, None) => unreachable!("the f32 copy is made before the f64 factor is released"),
        }
    }

    fn release_f64(&mut self) {
        self.f32();
        self.f64 = None;
    }

    fn holds_f64(&self) -> bool {
        self.f64.is_some()
    }

    fn symbolic(&self) -> &Arc<SymbolicAnalysis> {
        match &self.f64 {
            Some(f) => f.symbolic(),
            None => self.f32().symbolic(),
        }
    }

    fn dim(&self) -> usize {
        self.symbolic().dim()
    }
}

/// Validated lower-triangle values of `L` on the pattern of `symbolic`.
fn lower_values_of(symbolic: &SymbolicAnalysis, l: &SparseColMat<usize, f64>) -> Result<Vec<f64>> {
    let n = check_square(l.nrows(), l.ncols())?;
    if n != symbolic.dim() {
        return Err(SolverError::SizeMismatch {
            what: "Laplacian",
            expected: symbolic.dim(),
            found: n,
        });
    }
    check_finite_matrix(l.as_ref(), "Laplacian")?;
    symbolic.pattern().gather_values(l.as_ref())
}

/// Factors `L + s * diag(d)` given the lower values of `L`.
fn factor_shifted(
    symbolic: &Arc<SymbolicAnalysis>,
    lower_l: &[f64],
    d: impl Fn(usize) -> f64,
    s: f64,
    opts: &FactorOptions,
) -> Result<CholeskyFactor> {
    let pattern = symbolic.pattern();
    let mut values = lower_l.to_vec();
    for j in 0..pattern.n {
        values[pattern.diag_pos(j)] += s * d(j);
    }
    CholeskyFactor::from_lower_values(Arc::clone(symbolic), &values, opts)
}

/// Factored screened Poisson operator `A = L + tau M` (`L` sparse PSD, `M`
/// diagonal positive, `tau > 0`, so `A` is SPD).
///
/// Construction costs one symbolic analysis (skip it with
/// [`ScreenedPoisson::with_symbolic`] or [`ScreenedPoisson::with_tau`]) and one
/// numeric factorization; each solve then costs `~4 nnz(factor)` flops per
/// right-hand side. `Send + Sync`: solve from many threads at once.
#[derive(Debug)]
pub struct ScreenedPoisson {
    factor: FactorPair,
    lower_l: Vec<f64>,
    mass: Vec<f64>,
    tau: f64,
}

impl ScreenedPoisson {
    /// Symbolic analysis for the pattern of `L + tau M` (the lower triangle of
    /// `L` plus the diagonal), to share between operators that differ only in
    /// values (`tau`, mass, metric).
    pub fn analyse(l: &SparseColMat<usize, f64>) -> Result<Arc<SymbolicAnalysis>> {
        check_square(l.nrows(), l.ncols())?;
        Ok(Arc::new(SymbolicAnalysis::new(l.symbolic())?))
    }

    /// Analyses and factors `L + tau M`.
    ///
    /// Errors: [`SolverError::NotSquare`], [`SolverError::SizeMismatch`] (mass
    /// length), [`SolverError::NonFinite`], [`SolverError::NonPositiveMass`],
    /// [`SolverError::InvalidParameter`] (`tau <= 0` or not finite),
    /// [`SolverError::NotPositiveDefinite`] (`L` not PSD).
    pub fn new(l: &SparseColMat<usize, f64>, mass: &[f64], tau: f64) -> Result<Self> {
        check_positive("tau", tau)?;
        let symbolic = Self::analyse(l)?;
        Self::with_symbolic(&symbolic, l, mass, tau)
    }

    /// Factors `L + tau M` reusing a symbolic analysis of `L`'s pattern
    /// (from [`ScreenedPoisson::analyse`] or another operator's
    /// [`ScreenedPoisson::symbolic`]). Errors: as [`ScreenedPoisson::new`], plus
    /// [`SolverError::PatternMismatch`].
    pub fn with_symbolic(
        symbolic: &Arc<SymbolicAnalysis>,
        l: &SparseColMat<usize, f64>,
        mass: &[f64],
        tau: f64,
    ) -> Result<Self> {
        check_positive("tau", tau)?;
        let lower_l = lower_values_of(symbolic, l)?;
        check_mass(mass, symbolic.dim())?;
        let factor = factor_shifted(
            symbolic,
            &lower_l,
            |j| mass[j],
            tau,
            &FactorOptions::default(),
        )?;
        Ok(Self {
            factor: FactorPair::new(factor, SCREENED),
            lower_l,
            mass: mass.to_vec(),
            tau,
        })
    }

    /// The same `L` and `M` with another `tau`: only the numeric factorization
    /// runs.
    pub fn with_tau(&self, tau: f64) -> Result<Self> {
        check_positive("tau", tau)?;
        let factor = factor_shifted(
            self.symbolic(),
            &self.lower_l,
            |j| self.mass[j],
            tau,
            &FactorOptions::default(),
        )?;
        Ok(Self {
            factor: FactorPair::new(factor, SCREENED),
            lower_l: self.lower_l.clone(),
            mass: self.mass.clone(),
            tau,
        })
    }

    /// The screening weight `tau`.
    pub fn tau(&self) -> f64 {
        self.tau
    }

    /// Number of vertices `n`.
    pub fn dim(&self) -> usize {
        self.factor.dim()
    }

    /// The lumped mass this operator was built with.
    pub fn mass(&self) -> &[f64] {
        &self.mass
    }

    /// The `f64` Cholesky factor of `L + tau M`.
    ///
    /// Errors: [`SolverError::FactorReleased`] after
    /// [`ScreenedPoisson::release_f64_factor`].
    pub fn factor(&self) -> Result<&CholeskyFactor> {
        self.factor.f64()
    }

    /// The `f32` copy of the factor (made on first use, then cached).
    pub fn factor_f32(&self) -> &CholeskyFactor<f32> {
        self.factor.f32()
    }

    /// Keeps only the `f32` factor (made now if it was not yet): the
    /// memory of the `f64` values (8 bytes per factor entry) goes back, and
    /// `f64` solves fail with [`SolverError::FactorReleased`] from then on.
    /// For a caller that solves in `f32` only, e.g. sampling noise on a
    /// mesh of millions of vertices.
    pub fn release_f64_factor(&mut self) {
        self.factor.release_f64();
    }

    /// Whether the `f64` factor is still held (`false` after
    /// [`ScreenedPoisson::release_f64_factor`]).
    pub fn holds_f64_factor(&self) -> bool {
        self.factor.holds_f64()
    }

    /// The symbolic analysis (share it with [`ScreenedPoisson::with_symbolic`]).
    pub fn symbolic(&self) -> &Arc<SymbolicAnalysis> {
        self.factor.symbolic()
    }

    /// Solves `(L + tau M) x = b` for one right-hand side.
    ///
    /// Errors: [`SolverError::SizeMismatch`], [`SolverError::NonFinite`],
    /// [`SolverError::FactorReleased`].
    pub fn solve(&self, b: &[f64]) -> Result<Vec<f64>> {
        check_vector(b, self.dim(), "right-hand side")?;
        self.factor()?.solve(b)
    }

    /// Solves for a block `B` (`n x k`, one right-hand side per column).
    pub fn solve_many(&self, b: MatRef<'_, f64>) -> Result<Mat<f64>> {
        self.factor()?.solve_many(b)
    }

    /// Solves in place: `b` holds `B` on entry and `X` on return.
    pub fn solve_many_in_place(&self, b: MatMut<'_, f64>) -> Result<()> {
        self.factor()?.solve_in_place(b)
    }

    /// Solves for a block in `f32` with the `f32` factor (see
    /// [`CholeskyFactor::to_f32`] for the accuracy).
    pub fn solve_many_f32(&self, b: MatRef<'_, f32>) -> Result<Mat<f32>> {
        check_block(b, self.dim(), "right-hand side")?;
        self.factor_f32().solve_many(b)
    }

    /// Solves an `f32` block in place.
    pub fn solve_many_f32_in_place(&self, b: MatMut<'_, f32>) -> Result<()> {
        self.factor_f32().solve_in_place(b)
    }
}

/// The operator names of [`SolverError::FactorReleased`].
const SCREENED: &str = "L + tau M";
const SHIFTED: &str = "L + eps I";

/// How the diagonal shift `eps` of [`LaplacianSolver`] is specified.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Shift {
    /// `eps` itself.
    Absolute(f64),
    /// `eps = value * mean(L_ii)`: invariant under a global scaling of `L`.
    Relative(f64),
}

/// Options of [`LaplacianSolver`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ShiftOptions {
    /// First shift tried. Default `Shift::Absolute(1e-6)` (the PoissonNet
    /// convention). A zero shift is allowed: it is tried once, and the next
    /// attempt uses `1e-12 * mean(L_ii)`.
    pub initial: Shift,
    /// Factor by which `eps` grows after a failed factorization. Default `10`.
    pub growth: f64,
    /// Maximum number of factorizations attempted. Default `12`.
    pub max_attempts: usize,
    /// Options of each factorization (its pivot tolerance decides what counts
    /// as a failure).
    pub factor: FactorOptions,
}

impl Default for ShiftOptions {
    fn default() -> Self {
        Self {
            initial: Shift::Absolute(1e-6),
            growth: 10.0,
            max_attempts: 12,
            factor: FactorOptions::default(),
        }
    }
}

/// Factored `L + eps I` for a positive semi-definite `L` (e.g. a pure cotangent
/// Laplacian, singular on closed meshes), with the smallest shift of the
/// sequence `eps_0, growth * eps_0, ...` whose factorization succeeds.
///
/// The shift that was used is reported by [`LaplacianSolver::eps`]. Solving a
/// right-hand side with zero mean (`sum b = 0` on a connected closed mesh)
/// gives the Poisson solution plus an `O(eps)` perturbation; otherwise the
/// constant component is amplified by `1/eps`.
#[derive(Debug)]
pub struct LaplacianSolver {
    factor: FactorPair,
    eps: f64,
    attempts: usize,
}

impl LaplacianSolver {
    /// Factors `L + eps I` with the default [`ShiftOptions`] (`eps` starts at
    /// `1e-6` absolute and grows x10 on failure).
    pub fn new(l: &SparseColMat<usize, f64>) -> Result<Self> {
        Self::with_options(l, &ShiftOptions::default())
    }

    /// Factors `L + eps I`, growing `eps` on failure as `opts` says.
    ///
    /// Errors: [`SolverError::NotSquare`], [`SolverError::NonFinite`],
    /// [`SolverError::InvalidParameter`] (negative or non-finite shift,
    /// `growth <= 1`, `max_attempts == 0`), [`SolverError::ShiftExhausted`]
    /// (carrying the last factorization error).
    pub fn with_options(l: &SparseColMat<usize, f64>, opts: &ShiftOptions) -> Result<Self> {
        check_square(l.nrows(), l.ncols())?;
        let symbolic = Arc::new(SymbolicAnalysis::new(l.symbolic())?);
        Self::with_symbolic(&symbolic, l, opts)
    }

    /// [`LaplacianSolver::with_options`] reusing a symbolic analysis of
    /// `L`'s pattern (e.g. [`ScreenedPoisson::symbolic`] of a Matérn noise
    /// sampler on the same mesh): only the numeric factorizations run, and
    /// the factor is the same bits as with a fresh analysis.
    ///
    /// Errors: as [`LaplacianSolver::with_options`], plus
    /// [`SolverError::PatternMismatch`].
    pub fn with_symbolic(
        symbolic: &Arc<SymbolicAnalysis>,
        l: &SparseColMat<usize, f64>,
        opts: &ShiftOptions,
    ) -> Result<Self> {
        let n = check_square(l.nrows(), l.ncols())?;
        let lower_l = lower_values_of(symbolic, l)?;
        let mean_diag = if n == 0 {
            1.0
        } else {
            (0..n)
                .map(|j| lower_l[symbolic.pattern().diag_pos(j)].abs())
                .sum::<f64>()
                / n as f64
        };
        let mut eps = match opts.initial {
            Shift::Absolute(e) => e,
            Shift::Relative(r) => r * mean_diag,
        };
        if !(eps.is_finite() && eps >= 0.0) {
            return Err(SolverError::InvalidParameter {
                name: "eps",
                expected: "a finite shift >= 0",
                value: eps,
            });
        }
        if !(opts.growth.is_finite() && opts.growth > 1.0) {
            return Err(SolverError::InvalidParameter {
                name: "growth",
                expected: "a finite factor > 1",
                value: opts.growth,
            });
        }
        if opts.max_attempts == 0 {
            return Err(SolverError::InvalidParameter {
                name: "max_attempts",
                expected: "at least 1",
                value: 0.0,
            });
        }
        let mut last_error = None;
        for attempt in 1..=opts.max_attempts {
            match factor_shifted(symbolic, &lower_l, |_| 1.0, eps, &opts.factor) {
                Ok(factor) => {
                    return Ok(Self {
                        factor: FactorPair::new(factor, SHIFTED),
                        eps,
                        attempts: attempt,
                    });
                }
                Err(e @ SolverError::NotPositiveDefinite { .. }) => last_error = Some(e),
                Err(e) => return Err(e),
            }
            if attempt < opts.max_attempts {
                eps = if eps == 0.0 {
                    let floor = 1e-12 * mean_diag;
                    if floor > 0.0 { floor } else { 1e-12 }
                } else {
                    eps * opts.growth
                };
            }
        }
        Err(SolverError::ShiftExhausted {
            attempts: opts.max_attempts,
            last_eps: eps,
            last_error: Box::new(last_error.unwrap_or(SolverError::Backend {
                context: "shifted factorization",
                message: "no attempt was made".into(),
            })),
        })
    }

    /// The shift `eps` actually used in the factor.
    pub fn eps(&self) -> f64 {
        self.eps
    }

    /// How many factorizations were needed (1 when the initial shift worked).
    pub fn attempts(&self) -> usize {
        self.attempts
    }

    /// Number of vertices `n`.
    pub fn dim(&self) -> usize {
        self.factor.dim()
    }

    /// The `f64` Cholesky factor of `L + eps I`.
    ///
    /// Errors: [`SolverError::FactorReleased`] after
    /// [`LaplacianSolver::release_f64_factor`].
    pub fn factor(&self) -> Result<&CholeskyFactor> {
        self.factor.f64()
    }

    /// The `f32` copy of the factor (made on first use, then cached).
    pub fn factor_f32(&self) -> &CholeskyFactor<f32> {
        self.factor.f32()
    }

    /// Keeps only the `f32` factor (made now if it was not yet): the
    /// memory of the `f64` values (8 bytes per factor entry) goes back, and
    /// `f64` solves fail with [`SolverError::FactorReleased`] from then on.
    /// For a caller that solves in `f32` only, e.g. a network sampling on a
    /// mesh of millions of vertices.
    pub fn release_f64_factor(&mut self) {
        self.factor.release_f64();
    }

    /// Whether the `f64` factor is still held (`false` after
    /// [`LaplacianSolver::release_f64_factor`]).
    pub fn holds_f64_factor(&self) -> bool {
        self.factor.holds_f64()
    }

    /// The symbolic analysis of `L`'s pattern (share it with
    /// [`LaplacianSolver::with_symbolic`]).
    pub fn symbolic(&self) -> &Arc<SymbolicAnalysis> {
        self.factor.symbolic()
    }

    /// Solves `(L + eps I) x = b`.
    ///
    /// Errors: [`SolverError::SizeMismatch`], [`SolverError::NonFinite`],
    /// [`SolverError::FactorReleased`].
    pub fn solve(&self, b: &[f64]) -> Result<Vec<f64>> {
        check_vector(b, self.dim(), "right-hand side")?;
        self.factor()?.solve(b)
    }

    /// Solves for a block `B` (`n x k`, one right-hand side per column).
    pub fn solve_many(&self, b: MatRef<'_, f64>) -> Result<Mat<f64>> {
        self.factor()?.solve_many(b)
    }

    /// Solves in place: `b` holds `B` on entry and `X` on return.
    pub fn solve_many_in_place(&self, b: MatMut<'_, f64>) -> Result<()> {
        self.factor()?.solve_in_place(b)
    }

    /// Solves for a block in `f32` with the `f32` factor (see
    /// [`CholeskyFactor::to_f32`] for the accuracy; with a tiny `eps` the
    /// system is ill-conditioned, so prefer zero-mean right-hand sides).
    pub fn solve_many_f32(&self, b: MatRef<'_, f32>) -> Result<Mat<f32>> {
        check_block(b, self.dim(), "right-hand side")?;
        self.factor_f32().solve_many(b)
    }

    /// Solves an `f32` block in place.
    pub fn solve_many_f32_in_place(&self, b: MatMut<'_, f32>) -> Result<()> {
        self.factor_f32().solve_in_place(b)
    }
}
