//! A reusable sparse Cholesky cache: symbolic analysis once, numeric factor
//! per set of values, many (parallel) solves per factor.
//!
//! The work is split the way faer splits it:
//!
//! 1. [`SymbolicAnalysis`] depends only on the sparsity pattern: it computes a
//!    fill-reducing ordering (approximate minimum degree), the elimination tree
//!    and the supernodal structure of the factor. For a mesh operator this is
//!    done once per connectivity and reused for every `L + tau M` with a new
//!    `tau`, a new metric or new mass (same pattern, new values).
//! 2. [`CholeskyFactor`] holds the numeric supernodal `L L^T` factor of one
//!    matrix with that pattern (faer's left-looking supernodal factorization,
//!    in `f64`), optionally converted to `f32` for a cheaper solve.
//! 3. Solves take a column-major block of right-hand sides. Blocks are cut
//!    into chunks of at most [`SOLVE_CHUNK`] columns (and at least one chunk
//!    per rayon thread when there are enough columns) that are solved
//!    concurrently, each chunk as a row-major panel: the factor is streamed
//!    once per chunk and every update is a vector operation over the chunk's
//!    columns, with register tiles of several rows and lanes. The panels
//!    (`n x 32` values at most) are kept by the factor, one per rayon thread
//!    at most, so repeated solves on a large factor do not pay for fresh
//!    memory each time ([`CholeskyFactor::release_workspace`] frees them).
//!
//! ## Conventions
//! - Inputs are `faer` compressed-column matrices with `usize` indices. The
//!   matrix is symmetric and **only its lower triangle (`row >= col`) is
//!   read**; the upper triangle may be stored (a full symmetric matrix) or not.
//! - Both [`SymbolicAnalysis`] and [`CholeskyFactor`] are `Send + Sync`: one
//!   factor can be shared (e.g. in an `Arc`) by many threads that solve
//!   different right-hand sides at the same time.
//! - Determinism: every column of a solve goes through exactly the same
//!   floating-point operations whatever block it belongs to and however the
//!   block is chunked, so a column's result is bit-identical to solving it
//!   alone, and never depends on the number of threads. (The bits may differ
//!   between machines with different vector instruction sets: fused
//!   multiply-adds are used when the CPU has them.)
//!
//! ## Example
//! ```
//! use faer::sparse::{SparseColMat, Triplet};
//! use mfm_solver::CholeskyFactor;
//! // 1D Dirichlet Laplacian (tridiagonal 2, -1), SPD
//! let n = 5;
//! let mut t = Vec::new();
//! for i in 0..n {
//!     t.push(Triplet::new(i, i, 2.0));
//!     if i + 1 < n {
//!         t.push(Triplet::new(i + 1, i, -1.0));
//!         t.push(Triplet::new(i, i + 1, -1.0));
//!     }
//! }
//! let a = SparseColMat::<usize, f64>::try_new_from_triplets(n, n, &t).unwrap();
//! let factor = CholeskyFactor::new(a.as_ref()).unwrap();
//! let x = factor.solve(&[1.0; 5]).unwrap();
//! // the exact solution is x_i = (i + 1)(n - i) / 2
//! for (i, xi) in x.iter().enumerate() {
//!     let exact = ((i + 1) * (n - i)) as f64 / 2.0;
//!     assert!((xi - exact).abs() < 1e-12);
//! }
//! // same pattern, new values: reuse the symbolic analysis
//! let a2 = SparseColMat::<usize, f64>::try_new_from_triplets(
//!     n, n, &t.iter().map(|e| Triplet::new(e.row, e.col, 3.0 * e.val)).collect::<Vec<_>>(),
//! ).unwrap();
//! let factor2 = factor.refactor(a2.as_ref()).unwrap();
//! let y = factor2.solve(&[1.0; 5]).unwrap();
//! assert!((3.0 * y[2] - x[2]).abs() < 1e-12);
//! ```

use std::sync::Arc;

use faer::dyn_stack::StackReq;
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::llt::factor::{LltError, LltRegularization};
use faer::prelude::{Reborrow, ReborrowMut};
use faer::sparse::linalg::cholesky::simplicial;
use faer::sparse::linalg::cholesky::supernodal::{self, SymbolicSupernodalCholesky};
use faer::sparse::linalg::{SymbolicSupernodalParams, amd};
use faer::sparse::{SparseColMatRef, SymbolicSparseColMatRef};
use faer::{Mat, MatMut, MatRef, Par};
use rayon::prelude::*;

use crate::error::{Result, SolverError};
use crate::kernel;
use crate::sparse::{LowerPattern, check_block, check_finite_matrix, check_square};

/// Maximum number of right-hand-side columns solved together by one task.
///
/// A block of `k` columns is cut into `max(ceil(k / SOLVE_CHUNK),
/// min(threads, ceil(k / 8)))` chunks of near-equal width that run
/// concurrently on the rayon pool. The chunking does not change any bit of the
/// result (see the module docs).
pub const SOLVE_CHUNK: usize = 32;

mod sealed {
    pub trait Sealed {}
    impl Sealed for f32 {}
    impl Sealed for f64 {}
}

/// Floating-point types a factor can be stored and applied in: `f64` and `f32`.
///
/// Factorization always happens in `f64`; a factor can then be converted to
/// `f32` ([`CholeskyFactor::to_f32`]) for solves that move half the memory.
pub trait Real:
    faer::traits::RealField + Copy + Send + Sync + Into<f64> + sealed::Sealed + 'static
{
    /// Rounds an `f64` to this type.
    fn from_f64(x: f64) -> Self;
    /// `self * a + b` with a single rounding.
    fn fused_mul_add(self, a: Self, b: Self) -> Self;
}

impl Real for f64 {
    #[inline(always)]
    fn from_f64(x: f64) -> Self {
        x
    }
    #[inline(always)]
    fn fused_mul_add(self, a: Self, b: Self) -> Self {
        self.mul_add(a, b)
    }
}

impl Real for f32 {
    #[inline(always)]
    fn from_f64(x: f64) -> Self {
        x as f32
    }
    #[inline(always)]
    fn fused_mul_add(self, a: Self, b: Self) -> Self {
        self.mul_add(a, b)
    }
}

/// Options of the numeric factorization.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FactorOptions {
    /// A pivot `d_i` of the factorization (the diagonal of the Schur
    /// complement, `L_ii^2`) is accepted only if `d_i > pivot_tolerance * A_ii`.
    ///
    /// `d_i / A_ii` is bounded below by `lambda_min(A) / A_ii`, so this rejects
    /// matrices that are singular to working precision (e.g. a pure Laplacian)
    /// even when round-off leaves their last pivot barely positive. Default
    /// `1e-13`; `0.0` accepts any positive pivot.
    pub pivot_tolerance: f64,
    /// Use faer's parallel dense kernels (on the current rayon pool) inside
    /// the factorization. Default `false`: mesh operators have mostly small
    /// supernodes, and on a 2-core machine the sequential factorization was
    /// measured faster (and much less sensitive to other load) up to 655k
    /// vertices. Worth enabling for very large factors on many idle cores.
    pub parallel: bool,
}

impl Default for FactorOptions {
    fn default() -> Self {
        Self {
            pivot_tolerance: 1e-13,
            parallel: false,
        }
    }
}

/// Symbolic Cholesky analysis of a symmetric sparsity pattern: fill-reducing
/// ordering, elimination tree and supernodal structure of the factor.
///
/// Depends only on the pattern of the lower triangle (plus the diagonal, which
/// is always part of it), so it can be shared by every matrix with that pattern
/// ([`CholeskyFactor::with_symbolic`], [`CholeskyFactor::refactor`]).
/// Computing it costs roughly as much as one numeric factorization of a
/// sparse mesh operator; it is `Send + Sync` and usually held in an [`Arc`].
#[derive(Debug)]
pub struct SymbolicAnalysis {
    /// Lower pattern in the caller's numbering.
    pattern: LowerPattern,
    /// `perm_fwd[new] = old`.
    perm_fwd: Vec<usize>,
    /// `perm_inv[old] = new`.
    perm_inv: Vec<usize>,
    /// Lower triangle of `P A P^T` (rows sorted within each column).
    plow_col_ptr: Vec<usize>,
    plow_row_idx: Vec<usize>,
    /// Entry `p` of `pattern` goes to position `scatter[p]` of the permuted values.
    scatter: Vec<usize>,
    supernodal: SymbolicSupernodalCholesky<usize>,
    isa: kernel::Isa,
}

fn backend(context: &'static str) -> impl Fn(faer::sparse::FaerError) -> SolverError {
    move |e| SolverError::Backend {
        context,
        message: format!("{e:?}"),
    }
}

impl SymbolicAnalysis {
    /// Analyses the pattern of the lower triangle of `a` (entries with
    /// `row >= col`; the diagonal is always included).
    ///
    /// Errors: [`SolverError::NotSquare`], [`SolverError::Backend`] (out of
    /// memory / index overflow in faer). Cost: AMD ordering plus symbolic
    /// factorization, about `O(nnz(L_factor))`.
    pub fn new(a: SymbolicSparseColMatRef<'_, usize>) -> Result<Self> {
        check_square(a.nrows(), a.ncols())?;
        Self::from_pattern(LowerPattern::from_matrix(a))
    }

    pub(crate) fn from_pattern(pattern: LowerPattern) -> Result<Self> {
        let n = pattern.n;
        let nnz = pattern.nnz();
        // 1. fill-reducing ordering (AMD on the pattern of A + A^T)
        let mut perm_fwd = vec![0usize; n];
        let mut perm_inv = vec![0usize; n];
        {
            let mut mem = MemBuffer::try_new(amd::order_scratch::<usize>(n, nnz))
                .map_err(|_| backend("AMD ordering")(faer::sparse::FaerError::OutOfMemory))?;
            amd::order(
                &mut perm_fwd,
                &mut perm_inv,
                pattern.symbolic(),
                amd::Control::default(),
                MemStack::new(&mut mem),
            )
            .map_err(backend("AMD ordering"))?;
        }
        // 2. lower triangle of P A P^T, and where each input entry goes
        let mut count = vec![0usize; n + 1];
        for j in 0..n {
            for &i in &pattern.row_idx[pattern.col_ptr[j]..pattern.col_ptr[j + 1]] {
                count[perm_inv[i].min(perm_inv[j]) + 1] += 1;
            }
        }
        for c in 0..n {
            count[c + 1] += count[c];
        }
        let plow_col_ptr = count.clone();
        let mut next = count;
        // (row, input position) per permuted column, then sorted by row
        let mut entries = vec![(0usize, 0usize); nnz];
        for j in 0..n {
            for p in pattern.col_ptr[j]..pattern.col_ptr[j + 1] {
                let (a, b) = (perm_inv[pattern.row_idx[p]], perm_inv[j]);
                let (r, c) = if a >= b { (a, b) } else { (b, a) };
                entries[next[c]] = (r, p);
                next[c] += 1;
            }
        }
        let mut plow_row_idx = vec![0usize; nnz];
        let mut scatter = vec![0usize; nnz];
        for c in 0..n {
            let range = plow_col_ptr[c]..plow_col_ptr[c + 1];
            entries[range.clone()].sort_unstable();
            for q in range {
                plow_row_idx[q] = entries[q].0;
                scatter[entries[q].1] = q;
            }
        }
        // 3. its transpose (upper triangle), rows sorted, for the symbolic phase
        let mut up_ptr = vec![0usize; n + 1];
        for &r in &plow_row_idx {
            up_ptr[r + 1] += 1;
        }
        for c in 0..n {
            up_ptr[c + 1] += up_ptr[c];
        }
        let mut up_next = up_ptr.clone();
        let mut up_row = vec![0usize; nnz];
        for c in 0..n {
            for &r in &plow_row_idx[plow_col_ptr[c]..plow_col_ptr[c + 1]] {
                up_row[up_next[r]] = c;
                up_next[r] += 1;
            }
        }
        let upper = SymbolicSparseColMatRef::new_checked(n, n, &up_ptr, None, &up_row);
        // 4. elimination tree, column counts, supernodal structure
        let mut etree = vec![0isize; n];
        let mut col_counts = vec![0usize; n];
        let req = StackReq::any_of(&[
            simplicial::prefactorize_symbolic_cholesky_scratch::<usize>(n, nnz),
            supernodal::factorize_supernodal_symbolic_cholesky_scratch::<usize>(n),
        ]);
        let mut mem = MemBuffer::try_new(req)
            .map_err(|_| backend("symbolic Cholesky")(faer::sparse::FaerError::OutOfMemory))?;
        let stack = MemStack::new(&mut mem);
        let etree_ref =
            simplicial::prefactorize_symbolic_cholesky(&mut etree, &mut col_counts, upper, stack);
        let supernodal = supernodal::factorize_supernodal_symbolic_cholesky(
            upper,
            etree_ref,
            &col_counts,
            stack,
            SymbolicSupernodalParams::default(),
        )
        .map_err(backend("symbolic Cholesky"))?;
        Ok(Self {
            pattern,
            perm_fwd,
            perm_inv,
            plow_col_ptr,
            plow_row_idx,
            scatter,
            supernodal,
            isa: kernel::detect_isa(),
        })
    }

    /// Dimension `n` of the analysed `n x n` matrix.
    pub fn dim(&self) -> usize {
        self.pattern.n
    }

    /// Number of stored entries of the lower triangle (diagonal included) of
    /// the analysed pattern.
    pub fn input_nnz(&self) -> usize {
        self.pattern.nnz()
    }

    /// Number of values stored for the supernodal factor (its dense supernode
    /// blocks), a measure of fill-in and of the memory a factor takes.
    pub fn factor_len(&self) -> usize {
        self.supernodal.len_val()
    }

    /// Number of supernodes of the factor.
    pub fn num_supernodes(&self) -> usize {
        self.supernodal.n_supernodes()
    }

    /// The fill-reducing permutation: entry `i` is the original index of the
    /// `i`-th row/column of the permuted matrix that is factored.
    pub fn permutation(&self) -> &[usize] {
        &self.perm_fwd
    }

    pub(crate) fn pattern(&self) -> &LowerPattern {
        &self.pattern
    }

    pub(crate) fn supernodal(&self) -> &SymbolicSupernodalCholesky<usize> {
        &self.supernodal
    }
}

/// Numeric supernodal Cholesky factor `P A P^T = L L^T` of a symmetric
/// positive-definite sparse matrix, stored in `T` (`f64` or `f32`).
///
/// Built in `f64` by [`CholeskyFactor::new`] / [`CholeskyFactor::with_symbolic`];
/// [`CholeskyFactor::to_f32`] gives an `f32` copy. Cheap to share: `Send +
/// Sync`, and solving never mutates the factor. A solve with `k` right-hand
/// sides costs about `4 k nnz(L)` flops.
#[derive(Debug, Clone)]
pub struct CholeskyFactor<T: Real = f64> {
    symbolic: Arc<SymbolicAnalysis>,
    values: Vec<T>,
    pool: PanelPool,
}

/// Solve panels kept between solves, so that repeated solves on a large
/// factor do not pay for fresh memory each time. Clones start empty.
#[derive(Default)]
struct PanelPool {
    panels: std::sync::Mutex<Vec<Box<dyn std::any::Any + Send>>>,
}

impl Clone for PanelPool {
    fn clone(&self) -> Self {
        Self::default()
    }
}

impl std::fmt::Debug for PanelPool {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let n = self.panels.lock().map(|p| p.len()).unwrap_or(0);
        write!(f, "PanelPool({n} panels)")
    }
}

impl CholeskyFactor<f64> {
    /// Analyses and factors the symmetric positive-definite matrix whose lower
    /// triangle is read from `a`, with default [`FactorOptions`].
    ///
    /// Errors: [`SolverError::NotSquare`], [`SolverError::NonFinite`],
    /// [`SolverError::NotPositiveDefinite`] (naming the failing column).
    pub fn new(a: SparseColMatRef<'_, usize, f64>) -> Result<Self> {
        Self::with_options(a, &FactorOptions::default())
    }

    /// [`CholeskyFactor::new`] with explicit options.
    pub fn with_options(a: SparseColMatRef<'_, usize, f64>, opts: &FactorOptions) -> Result<Self> {
        check_square(a.nrows(), a.ncols())?;
        check_finite_matrix(a, "matrix")?;
        let symbolic = Arc::new(SymbolicAnalysis::new(a.symbolic())?);
        let values = symbolic.pattern.gather_values(a)?;
        Self::from_lower_values(symbolic, &values, opts)
    }

    /// Factors `a` reusing an existing symbolic analysis (only the numeric
    /// phase runs). The lower triangle of `a` must fit in the analysed pattern
    /// (a subset is fine: missing entries are zeros).
    ///
    /// Errors: as [`CholeskyFactor::new`], plus [`SolverError::SizeMismatch`]
    /// and [`SolverError::PatternMismatch`].
    pub fn with_symbolic(
        symbolic: &Arc<SymbolicAnalysis>,
        a: SparseColMatRef<'_, usize, f64>,
        opts: &FactorOptions,
    ) -> Result<Self> {
        let n = check_square(a.nrows(), a.ncols())?;
        if n != symbolic.dim() {
            return Err(SolverError::SizeMismatch {
                what: "matrix",
                expected: symbolic.dim(),
                found: n,
            });
        }
        check_finite_matrix(a, "matrix")?;
        let values = symbolic.pattern.gather_values(a)?;
        Self::from_lower_values(Arc::clone(symbolic), &values, opts)
    }

    /// Factors a new matrix with the same pattern as `self` (reusing the
    /// symbolic analysis) and default options.
    pub fn refactor(&self, a: SparseColMatRef<'_, usize, f64>) -> Result<Self> {
        Self::with_symbolic(&self.symbolic, a, &FactorOptions::default())
    }

    /// Numeric factorization from values laid out on the analysed lower pattern.
    pub(crate) fn from_lower_values(
        symbolic: Arc<SymbolicAnalysis>,
        lower_values: &[f64],
        opts: &FactorOptions,
    ) -> Result<Self> {
        let n = symbolic.dim();
        debug_assert_eq!(lower_values.len(), symbolic.pattern.nnz());
        let par = if opts.parallel {
            Par::rayon(0)
        } else {
            Par::Seq
        };
        let mut permuted = vec![0.0f64; lower_values.len()];
        for (&v, &dst) in lower_values.iter().zip(&symbolic.scatter) {
            permuted[dst] = v;
        }
        let a = SparseColMatRef::new(
            SymbolicSparseColMatRef::new_checked(
                n,
                n,
                &symbolic.plow_col_ptr,
                None,
                &symbolic.plow_row_idx,
            ),
            &permuted,
        );
        let sn = &symbolic.supernodal;
        let mut values = vec![0.0f64; sn.len_val()];
        let req = supernodal::factorize_supernodal_numeric_llt_scratch::<usize, f64>(
            sn,
            par,
            Default::default(),
        );
        let mut mem = MemBuffer::try_new(req).map_err(|_| SolverError::Backend {
            context: "Cholesky factorization",
            message: "out of memory".into(),
        })?;
        let res = supernodal::factorize_supernodal_numeric_llt::<usize, f64>(
            &mut values,
            a,
            LltRegularization::default(),
            sn,
            par,
            MemStack::new(&mut mem),
            Default::default(),
        );
        let original = |i: usize| symbolic.perm_fwd[i];
        let diag = |col: usize| lower_values[symbolic.pattern.diag_pos(col)];
        if let Err(LltError::NonPositivePivot { index }) = res {
            let column = original(index.min(n.saturating_sub(1)));
            return Err(SolverError::NotPositiveDefinite {
                column,
                pivot: f64::NAN,
                diagonal: diag(column),
                tolerance: opts.pivot_tolerance,
            });
        }
        // Reject pivots that are positive only through round-off.
        let begin = sn.supernode_begin();
        let end = sn.supernode_end();
        let cp = sn.col_ptr_for_val();
        for s in 0..sn.n_supernodes() {
            let ncols = end[s] - begin[s];
            let nrows = (cp[s + 1] - cp[s]) / ncols.max(1);
            for c in 0..ncols {
                let l = values[cp[s] + c * nrows + c];
                let column = original(begin[s] + c);
                let d = diag(column);
                let pivot = l * l;
                if pivot.is_nan() || pivot <= opts.pivot_tolerance * d {
                    return Err(SolverError::NotPositiveDefinite {
                        column,
                        pivot,
                        diagonal: d,
                        tolerance: opts.pivot_tolerance,
                    });
                }
            }
        }
        Ok(Self {
            symbolic,
            values,
            pool: PanelPool::default(),
        })
    }

    /// Copy of the factor rounded to `f32`.
    ///
    /// Accuracy: a solve with the `f32` factor has a relative error of about
    /// `cond(A) * 6e-8` (versus `cond(A) * 1e-16` in `f64`); for screened
    /// Poisson systems on meshes (`cond` up to ~`1e3`-`1e4` for the usual
    /// `tau`) that is ~`1e-5`-`1e-4`. It halves the memory traffic of a solve.
    pub fn to_f32(&self) -> CholeskyFactor<f32> {
        CholeskyFactor {
            symbolic: Arc::clone(&self.symbolic),
            values: self.values.iter().map(|&v| v as f32).collect(),
            pool: PanelPool::default(),
        }
    }
}

impl<T: Real> CholeskyFactor<T> {
    /// Dimension `n` of the factored `n x n` matrix.
    pub fn dim(&self) -> usize {
        self.symbolic.dim()
    }

    /// The symbolic analysis this factor was built on (share it to factor other
    /// matrices with the same pattern).
    pub fn symbolic(&self) -> &Arc<SymbolicAnalysis> {
        &self.symbolic
    }

    /// The supernodal values (faer's layout, see `kernel`).
    #[cfg(test)]
    pub(crate) fn values(&self) -> &[T] {
        &self.values
    }

    /// Solves `A x = b` for one right-hand side and returns `x`.
    ///
    /// Errors: [`SolverError::SizeMismatch`], [`SolverError::NonFinite`].
    pub fn solve(&self, b: &[T]) -> Result<Vec<T>> {
        let mut x = b.to_vec();
        let n = x.len();
        self.solve_in_place(MatMut::from_column_major_slice_mut(&mut x, n, 1))?;
        Ok(x)
    }

    /// Solves `A X = B` for a block of right-hand sides (`n x k`, any strides)
    /// and returns `X` (`n x k`, column-major).
    pub fn solve_many(&self, b: MatRef<'_, T>) -> Result<Mat<T>> {
        let mut x = b.to_owned();
        self.solve_in_place(x.as_mut())?;
        Ok(x)
    }

    /// Solves `A X = B` in place: `rhs` holds `B` (`n x k`) on entry and `X` on
    /// return. Chunks of at most [`SOLVE_CHUNK`] columns run concurrently on
    /// the rayon pool; call it from several threads at once freely. The
    /// panels the chunks are solved in (`n x 8`, `16` or `32` values each)
    /// are kept for the next solve, at most one per rayon thread
    /// ([`CholeskyFactor::release_workspace`]).
    ///
    /// Errors: [`SolverError::SizeMismatch`], [`SolverError::NonFinite`]
    /// (`rhs` is left untouched on error).
    pub fn solve_in_place(&self, rhs: MatMut<'_, T>) -> Result<()> {
        check_block(rhs.rb(), self.dim(), "right-hand side")?;
        self.solve_in_place_unchecked(rhs);
        Ok(())
    }

    /// Solves `A X = B` in place like [`CholeskyFactor::solve_in_place`],
    /// but entirely on the calling thread (chunks of [`SOLVE_CHUNK`]
    /// columns one after the other), for callers that run several solves
    /// in parallel on a thread pool of their own. Row-major blocks (column
    /// stride 1, e.g. a `[V, C]` signal with one right-hand side per
    /// channel) are read and written one contiguous row at a time. Each
    /// column's result is the same as with [`CholeskyFactor::solve_in_place`]
    /// (columns are solved independently, in the same order of operations).
    ///
    /// Errors: [`SolverError::SizeMismatch`], [`SolverError::NonFinite`]
    /// (`rhs` is left untouched on error).
    pub fn solve_in_place_sequential(&self, rhs: MatMut<'_, T>) -> Result<()> {
        check_block(rhs.rb(), self.dim(), "right-hand side")?;
        if self.dim() > 0 {
            self.solve_chunk(rhs);
        }
        Ok(())
    }

    /// Solve without input validation (rows already checked by the caller).
    pub(crate) fn solve_in_place_unchecked(&self, rhs: MatMut<'_, T>) {
        let k = rhs.ncols();
        if k == 0 || self.dim() == 0 {
            return;
        }
        let threads = rayon::current_num_threads().max(1);
        let count = k.div_ceil(SOLVE_CHUNK).max(threads.min(k.div_ceil(8)));
        if count == 1 {
            self.solve_chunk(rhs);
            return;
        }
        let width = k.div_ceil(count);
        let mut chunks = Vec::with_capacity(count);
        let mut rest = rhs;
        while rest.ncols() > width {
            let (head, tail) = rest.split_at_col_mut(width);
            chunks.push(head);
            rest = tail;
        }
        chunks.push(rest);
        chunks.into_par_iter().for_each(|c| self.solve_chunk(c));
    }

    /// Solves one chunk (at most [`SOLVE_CHUNK`] columns) sequentially with
    /// the narrowest panel that holds it.
    fn solve_chunk(&self, rhs: MatMut<'_, T>) {
        match rhs.ncols() {
            0 => {}
            1..=8 => self.solve_chunk_k::<8>(rhs),
            9..=16 => self.solve_chunk_k::<16>(rhs),
            17..=SOLVE_CHUNK => self.solve_chunk_k::<SOLVE_CHUNK>(rhs),
            _ => {
                // wider chunks are not produced by `solve_in_place_unchecked`
                let (head, tail) = rhs.split_at_col_mut(SOLVE_CHUNK);
                self.solve_chunk_k::<SOLVE_CHUNK>(head);
                self.solve_chunk(tail);
            }
        }
    }

    /// A panel of `n` rows of width `K` from the pool, or a new one. Its
    /// values are left over from an earlier solve (finite: inputs are
    /// checked) or zero.
    fn take_panel<const K: usize>(&self) -> Vec<kernel::Row<T, K>> {
        let n = self.dim();
        let mut pool = self.pool.panels.lock().unwrap_or_else(|e| e.into_inner());
        while let Some(i) = pool.iter().position(|p| p.is::<Vec<kernel::Row<T, K>>>()) {
            if let Ok(p) = pool.swap_remove(i).downcast::<Vec<kernel::Row<T, K>>>() {
                if p.len() == n {
                    return *p;
                }
            }
        }
        drop(pool);
        vec![kernel::Row([T::from_f64(0.0); K]); n]
    }

    /// Returns a panel to the pool, which keeps at most one per rayon thread.
    fn give_back_panel<const K: usize>(&self, panel: Vec<kernel::Row<T, K>>) {
        let mut pool = self.pool.panels.lock().unwrap_or_else(|e| e.into_inner());
        if pool.len() < rayon::current_num_threads().max(1) {
            pool.push(Box::new(panel));
        }
    }

    /// Frees the panels kept for later solves (see
    /// [`CholeskyFactor::solve_in_place`]); the next solve allocates anew.
    pub fn release_workspace(&self) {
        self.pool
            .panels
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .clear();
    }

    /// Permutes the chunk into a row-major panel of width `K`, runs the
    /// supernodal substitutions on it, and permutes the result back.
    ///
    /// Both permutations walk the caller's rows in order (sequential streams
    /// through every column) and move one whole panel row at a time.
    fn solve_chunk_k<const K: usize>(&self, mut rhs: MatMut<'_, T>) {
        let k = rhs.ncols();
        debug_assert!(k <= K);
        let inv = &self.symbolic.perm_inv[..];
        let zero = T::from_f64(0.0);
        let mut panel = self.take_panel::<K>();
        let cols: Option<Vec<&[T]>> = (0..k)
            .map(|j| rhs.rb().col(j).try_as_col_major().map(|c| c.as_slice()))
            .collect();
        let row_major = k > 1 && rhs.col_stride() == 1;
        match cols {
            _ if row_major => {
                for (o, &p) in inv.iter().enumerate() {
                    let row = &mut panel[p].0;
                    match rhs.rb().row(o).try_as_row_major() {
                        Some(src) => row[..k].copy_from_slice(src.as_slice()),
                        None => (0..k).for_each(|j| row[j] = rhs[(o, j)]),
                    }
                    row[k..].fill(zero);
                }
            }
            Some(cols) => {
                for (o, &p) in inv.iter().enumerate() {
                    let row = &mut panel[p].0;
                    for (x, c) in row.iter_mut().zip(&cols) {
                        *x = c[o];
                    }
                    row[k..].fill(zero);
                }
            }
            None => {
                for (o, &p) in inv.iter().enumerate() {
                    for j in 0..k {
                        panel[p].0[j] = rhs[(o, j)];
                    }
                    panel[p].0[k..].fill(zero);
                }
            }
        }
        let sn = kernel::Supernodes::new(self.symbolic.supernodal());
        let isa = self.symbolic.isa;
        // register tiles: two 256-bit vectors of lanes, eight in the dense
        // backward block (see `kernel`)
        let single = std::mem::size_of::<T>() == 4;
        let v = &self.values;
        match K {
            8 => kernel::solve_panel::<T, K, 8, 8>(isa, &sn, v, &mut panel),
            16 if single => kernel::solve_panel::<T, K, 16, 16>(isa, &sn, v, &mut panel),
            16 => kernel::solve_panel::<T, K, 8, 16>(isa, &sn, v, &mut panel),
            _ if single => kernel::solve_panel::<T, K, 16, 32>(isa, &sn, v, &mut panel),
            _ => kernel::solve_panel::<T, K, 8, 32>(isa, &sn, v, &mut panel),
        }
        if row_major {
            for (o, &p) in inv.iter().enumerate() {
                match rhs.rb_mut().row_mut(o).try_as_row_major_mut() {
                    Some(dst) => dst.as_slice_mut().copy_from_slice(&panel[p].0[..k]),
                    None => (0..k).for_each(|j| rhs[(o, j)] = panel[p].0[j]),
                }
            }
            self.give_back_panel(panel);
            return;
        }
        let mut cols: Vec<&mut [T]> = rhs
            .rb_mut()
            .col_iter_mut()
            .filter_map(|c| c.try_as_col_major_mut().map(|c| c.as_slice_mut()))
            .collect();
        if cols.len() == k {
            for (o, &p) in inv.iter().enumerate() {
                let row = &panel[p].0;
                for (c, &x) in cols.iter_mut().zip(row) {
                    c[o] = x;
                }
            }
        } else {
            drop(cols);
            for (o, &p) in inv.iter().enumerate() {
                for j in 0..k {
                    rhs[(o, j)] = panel[p].0[j];
                }
            }
        }
        self.give_back_panel(panel);
    }
}
