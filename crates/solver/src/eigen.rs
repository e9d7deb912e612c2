//! Generalized symmetric eigenpairs `L phi = lambda M phi` of a sparse PSD
//! matrix `L` and a positive diagonal mass `M`: the `k` smallest pairs,
//! eigenvalues ascending, eigenvectors `M`-orthonormal (`Phi^T M Phi = I`).
//!
//! Two methods:
//!
//! - **Sparse** (large meshes): shift-invert block Krylov-Schur (thick-restart
//!   block Lanczos with full reorthogonalization). With `sigma` below the
//!   spectrum, the symmetric operator `Op = M^1/2 (L - sigma M)^-1 M^1/2` has
//!   eigenvalues `theta = 1 / (lambda - sigma)` and eigenvectors `M^1/2 phi`,
//!   so the wanted pairs are its largest ones. `L - sigma M` is factored once
//!   with the crate's sparse Cholesky; each Krylov step solves a whole block of
//!   right-hand sides at once, and orthogonalization/Rayleigh-Ritz run as dense
//!   matrix-matrix products. Cost per restart cycle, for a subspace of
//!   dimension `m` and block size `b`: `m` solves plus `~4 n m^2` flops of
//!   reorthogonalization plus one dense `m x m` eigendecomposition.
//! - **Dense** (small meshes, or `k` close to `n`): the full eigendecomposition
//!   of `M^-1/2 L M^-1/2` with faer's dense self-adjoint solver, `O(n^3)`.
//!
//! ## Conventions
//! - Only the lower triangle of `L` is read.
//! - Eigenvalues are ascending; each eigenvector is normalized to
//!   `phi^T M phi = 1` and its sign fixed so that its entry of largest
//!   magnitude is positive (the first such entry on ties).
//! - The sparse method converges when every requested Ritz pair of `Op` has a
//!   residual `||Op y - theta y|| <= tol * theta`; eigenvalues are then
//!   accurate to about `tol^2` relative, eigenvectors to about `tol / gap`.
//!
//! ## Example
//! ```
//! use faer::sparse::{SparseColMat, Triplet};
//! use mfm_solver::{EigenOptions, generalized_eigenpairs};
//! // cycle graph on 8 vertices: eigenvalues 2 - 2 cos(2 pi j / 8)
//! let n = 8;
//! let mut t = Vec::new();
//! for i in 0..n {
//!     let j = (i + 1) % n;
//!     t.extend([
//!         Triplet::new(i, i, 1.0), Triplet::new(j, j, 1.0),
//!         Triplet::new(i, j, -1.0), Triplet::new(j, i, -1.0),
//!     ]);
//! }
//! let l = SparseColMat::<usize, f64>::try_new_from_triplets(n, n, &t).unwrap();
//! let pairs = generalized_eigenpairs(&l, &vec![1.0; n], 3, &EigenOptions::default()).unwrap();
//! assert!(pairs.values[0].abs() < 1e-12);
//! let l1 = 2.0 - 2.0 * (std::f64::consts::TAU / 8.0).cos();
//! assert!((pairs.values[1] - l1).abs() < 1e-12 && (pairs.values[2] - l1).abs() < 1e-12);
//! ```

use faer::linalg::matmul::matmul;
use faer::linalg::triangular_solve::solve_upper_triangular_in_place;
use faer::prelude::{Reborrow, ReborrowMut};
use faer::sparse::SparseColMat;
use faer::{Accum, Mat, MatMut, MatRef, Par, Side};
use rayon::prelude::*;

use crate::cholesky::{CholeskyFactor, FactorOptions, SymbolicAnalysis};
use crate::error::{Result, SolverError};
use crate::sparse::{check_finite_matrix, check_mass, check_square};

/// Which algorithm [`generalized_eigenpairs`] uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum EigenMethod {
    /// Dense when `n <= EigenOptions::dense_max` or when `k` is too close to
    /// `n` for the Krylov method, sparse otherwise.
    #[default]
    Auto,
    /// Full dense eigendecomposition (`O(n^3)` time, `O(n^2)` memory).
    Dense,
    /// Shift-invert block Krylov-Schur on a sparse Cholesky factor.
    Sparse,
}

/// Options of [`generalized_eigenpairs`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EigenOptions {
    /// Algorithm choice. Default [`EigenMethod::Auto`].
    pub method: EigenMethod,
    /// `Auto` uses the dense method up to this many vertices. Default `1000`.
    pub dense_max: usize,
    /// Shift of the sparse method; must lie below the smallest eigenvalue so
    /// that `L - sigma M` is positive definite. `None` (default) picks
    /// `sigma = -trace(L) / (n trace(M))`: for a mesh Laplacian that is a
    /// few times smaller than the first nonzero eigenvalue (about
    /// `lambda_1 / 4` to `lambda_1 / 8` on spheres, tori and grids), and it
    /// follows `lambda -> lambda / s^2` under a global scale `s`. (It moves
    /// 10x further down if the factorization fails.) A shift of that size
    /// keeps `L - sigma M` well conditioned and the transformed spectrum free
    /// of a dominant outlier at `lambda = 0`, which keeps the eigenvalues
    /// accurate to ~`1e-13` relative; shifts very close to 0 (e.g.
    /// `-1e-8`) work too but cost accuracy (~`1e-16 |lambda / sigma|`).
    pub sigma: Option<f64>,
    /// Relative residual tolerance of the sparse method (see the module
    /// docs). Default `1e-10`.
    pub tol: f64,
    /// Block size of the sparse method (`0`: automatic, 8, 16 or 32 depending
    /// on `k`).
    pub block_size: usize,
    /// Maximum Krylov subspace dimension of the sparse method (`0`:
    /// automatic, `2k + 4 * block`; rounded up to a multiple of the block).
    pub max_subspace: usize,
    /// Maximum number of thick restarts of the sparse method. Default `100`.
    pub max_restarts: usize,
    /// Seed of the random starting block (results are deterministic for a
    /// given seed and thread count).
    pub seed: u64,
}

impl Default for EigenOptions {
    fn default() -> Self {
        Self {
            method: EigenMethod::Auto,
            dense_max: 1000,
            sigma: None,
            tol: 1e-10,
            block_size: 0,
            max_subspace: 0,
            max_restarts: 100,
            seed: 0x5eed_1234_abcd_0042,
        }
    }
}

/// The `k` smallest generalized eigenpairs of `(L, M)`.
#[derive(Debug, Clone)]
pub struct Eigenpairs {
    /// Eigenvalues, ascending.
    pub values: Vec<f64>,
    /// Eigenvectors as the columns of an `n x k` matrix, `M`-orthonormal.
    pub vectors: Mat<f64>,
    /// How they were computed.
    pub info: EigenInfo,
}

/// Diagnostics of an eigensolve.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EigenInfo {
    /// The method that ran ([`EigenMethod::Dense`] or [`EigenMethod::Sparse`]).
    pub method: EigenMethod,
    /// Shift used by the sparse method (`0.0` for the dense one).
    pub sigma: f64,
    /// Thick restarts performed by the sparse method.
    pub restarts: usize,
    /// Right-hand sides solved with the factor of `L - sigma M`.
    pub solves: usize,
}

/// Computes the `k` smallest eigenpairs of `L phi = lambda M phi`.
///
/// `l` is symmetric positive semi-definite (only its lower triangle is read),
/// `mass` the positive diagonal of `M`. See the module docs for the methods,
/// their cost and the normalization of the result.
///
/// Errors: [`SolverError::NotSquare`], [`SolverError::SizeMismatch`],
/// [`SolverError::NonFinite`], [`SolverError::NonPositiveMass`],
/// [`SolverError::KTooLarge`] (`k > n`, or `k` too large for an explicitly
/// requested sparse method), [`SolverError::InvalidParameter`],
/// [`SolverError::NotPositiveDefinite`] (an explicit `sigma` above the
/// smallest eigenvalue), [`SolverError::NotConverged`].
pub fn generalized_eigenpairs(
    l: &SparseColMat<usize, f64>,
    mass: &[f64],
    k: usize,
    opts: &EigenOptions,
) -> Result<Eigenpairs> {
    let n = check_square(l.nrows(), l.ncols())?;
    check_mass(mass, n)?;
    check_finite_matrix(l.as_ref(), "Laplacian")?;
    if k > n {
        return Err(SolverError::KTooLarge { k, max: n, n });
    }
    if !(opts.tol.is_finite() && opts.tol > 0.0 && opts.tol < 1.0) {
        return Err(SolverError::InvalidParameter {
            name: "tol",
            expected: "a number in (0, 1)",
            value: opts.tol,
        });
    }
    if let Some(s) = opts.sigma
        && !s.is_finite()
    {
        return Err(SolverError::InvalidParameter {
            name: "sigma",
            expected: "a finite shift",
            value: s,
        });
    }
    let b = block_size(opts, k);
    if opts.max_subspace > 0 && opts.max_subspace < k + (2 * b).max(k / 4) {
        return Err(SolverError::InvalidParameter {
            name: "max_subspace",
            expected: "at least k + max(2 block, k / 4)",
            value: opts.max_subspace as f64,
        });
    }
    // the basis holds mmax + b orthonormal vectors of length n
    let cap = (n.saturating_sub(b) / b) * b;
    let mmax = subspace_size(opts, k, b).min(cap);
    // a buffer of unwanted Ritz vectors keeps the restarts effective
    let buffer = |k: usize| (2 * b).max(k / 4);
    let sparse_fits = k > 0 && mmax >= k + buffer(k);
    let method = match opts.method {
        EigenMethod::Auto if n <= opts.dense_max || !sparse_fits => EigenMethod::Dense,
        EigenMethod::Auto => EigenMethod::Sparse,
        m => m,
    };
    let mut pairs = match method {
        EigenMethod::Dense => dense(l, mass, k)?,
        _ => {
            if !sparse_fits {
                let max = (1..=cap)
                    .rev()
                    .find(|&kk| kk + buffer(kk) <= cap)
                    .unwrap_or(0);
                return Err(SolverError::KTooLarge { k, max, n });
            }
            sparse(l, mass, k, b, mmax, opts)?
        }
    };
    normalize_signs(pairs.vectors.as_mut());
    Ok(pairs)
}

fn block_size(opts: &EigenOptions, k: usize) -> usize {
    if opts.block_size > 0 {
        opts.block_size
    } else if k <= 16 {
        8
    } else if k <= 96 {
        16
    } else {
        32
    }
}

fn subspace_size(opts: &EigenOptions, k: usize, b: usize) -> usize {
    let m = if opts.max_subspace > 0 {
        opts.max_subspace
    } else {
        2 * k + 4 * b
    };
    m.div_ceil(b) * b
}

/// Makes the entry of largest magnitude of each column positive.
fn normalize_signs(mut v: MatMut<'_, f64>) {
    for j in 0..v.ncols() {
        let mut best = 0.0f64;
        let mut sign = 1.0;
        for i in 0..v.nrows() {
            let x = v[(i, j)];
            if x.abs() > best {
                best = x.abs();
                sign = x.signum();
            }
        }
        if sign < 0.0 {
            for i in 0..v.nrows() {
                v[(i, j)] = -v[(i, j)];
            }
        }
    }
}

/// Dense path: eigendecomposition of `M^-1/2 L M^-1/2`.
fn dense(l: &SparseColMat<usize, f64>, mass: &[f64], k: usize) -> Result<Eigenpairs> {
    let n = l.nrows();
    let inv_sqrt: Vec<f64> = mass.iter().map(|m| 1.0 / m.sqrt()).collect();
    let mut c = Mat::<f64>::zeros(n, n);
    for j in 0..n {
        for (i, &v) in l.row_idx_of_col(j).zip(l.val_of_col(j)) {
            if i >= j {
                c[(i, j)] += v * inv_sqrt[i] * inv_sqrt[j];
            }
        }
    }
    let (s, u) = symmetric_eigen(c.as_ref(), "dense eigendecomposition")?;
    let values = s[..k].to_vec();
    let vectors = Mat::from_fn(n, k, |i, j| u[(i, j)] * inv_sqrt[i]);
    Ok(Eigenpairs {
        values,
        vectors,
        info: EigenInfo {
            method: EigenMethod::Dense,
            sigma: 0.0,
            restarts: 0,
            solves: 0,
        },
    })
}

/// Eigendecomposition of a symmetric matrix (lower triangle read),
/// eigenvalues ascending, computed sequentially (deterministic whatever the
/// thread count).
fn symmetric_eigen(a: MatRef<'_, f64>, context: &'static str) -> Result<(Vec<f64>, Mat<f64>)> {
    use faer::dyn_stack::{MemBuffer, MemStack};
    use faer::linalg::evd;
    let n = a.nrows();
    let mut s = faer::diag::Diag::<f64>::zeros(n);
    let mut u = Mat::<f64>::zeros(n, n);
    let req = evd::self_adjoint_evd_scratch::<f64>(
        n,
        evd::ComputeEigenvectors::Yes,
        Par::Seq,
        Default::default(),
    );
    let mut mem = MemBuffer::try_new(req).map_err(|_| SolverError::Backend {
        context,
        message: "out of memory".into(),
    })?;
    evd::self_adjoint_evd(
        a,
        s.as_mut(),
        Some(u.as_mut()),
        Par::Seq,
        MemStack::new(&mut mem),
        Default::default(),
    )
    .map_err(|e| SolverError::Backend {
        context,
        message: format!("{e:?}"),
    })?;
    Ok((s.column_vector().iter().copied().collect(), u))
}

/// Small deterministic generator for starting and replacement vectors.
struct SplitMix(u64);

impl SplitMix {
    fn next_f64(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^= z >> 31;
        (z >> 11) as f64 / (1u64 << 53) as f64 - 0.5
    }
}

/// Factor of `L - sigma M`, moving an automatic shift further down on failure.
fn shifted_factor(
    l: &SparseColMat<usize, f64>,
    mass: &[f64],
    opts: &EigenOptions,
) -> Result<(CholeskyFactor, f64)> {
    let n = l.nrows();
    let symbolic = std::sync::Arc::new(SymbolicAnalysis::new(l.symbolic())?);
    let pattern = symbolic.pattern();
    let lower = pattern.gather_values(l.as_ref())?;
    let factor_with = |sigma: f64| {
        let mut values = lower.clone();
        for (j, &m) in mass.iter().enumerate() {
            values[pattern.diag_pos(j)] -= sigma * m;
        }
        // the shift keeps the matrix safely definite; accept any positive pivot
        let fo = FactorOptions {
            pivot_tolerance: 0.0,
            ..FactorOptions::default()
        };
        CholeskyFactor::from_lower_values(std::sync::Arc::clone(&symbolic), &values, &fo)
    };
    if let Some(sigma) = opts.sigma {
        return Ok((factor_with(sigma)?, sigma));
    }
    let trace_l: f64 = (0..n).map(|j| lower[pattern.diag_pos(j)]).sum();
    let trace_m: f64 = mass.iter().sum();
    let scale = if trace_l > 0.0 {
        trace_l / (trace_m * n as f64)
    } else {
        1.0 / trace_m.max(f64::MIN_POSITIVE)
    };
    let mut sigma = -scale;
    let mut last = None;
    for _ in 0..8 {
        match factor_with(sigma) {
            Ok(f) => return Ok((f, sigma)),
            Err(e @ SolverError::NotPositiveDefinite { .. }) => last = Some(e),
            Err(e) => return Err(e),
        }
        sigma *= 10.0;
    }
    Err(last.unwrap_or(SolverError::Backend {
        context: "shift-invert factorization",
        message: "no attempt".into(),
    }))
}

/// State of the shift-invert block Krylov-Schur iteration.
struct Krylov<'a> {
    n: usize,
    b: usize,
    mmax: usize,
    factor: &'a CholeskyFactor,
    sqrt_m: Vec<f64>,
    /// Orthonormal basis, `n x (mmax + b)`.
    v: Mat<f64>,
    /// Projected operator: `Op V[:, :m] = V[:, :m + b] H[:m + b, :m]`.
    h: Mat<f64>,
    /// Work block (`n x b`): the new Krylov block being orthogonalized.
    w: Mat<f64>,
    /// Copy of the work block for the Gram-Schmidt fallback.
    w_copy: Mat<f64>,
    rng: SplitMix,
    solves: usize,
    par: Par,
}

/// Rows per slab of the tall-skinny products below. Products are computed
/// slab by slab on the rayon pool, each slab with a sequential kernel, and
/// reductions are summed in slab order: the results do not depend on the
/// number of threads, and oversubscribed machines degrade gracefully.
const SLAB: usize = 2048;

/// Splits the rows of `m` into consecutive slabs of [`SLAB`] rows.
fn row_slabs(m: MatMut<'_, f64>) -> Vec<MatMut<'_, f64>> {
    let mut out = Vec::with_capacity(m.nrows().div_ceil(SLAB));
    let mut rest = m;
    while rest.nrows() > SLAB {
        let (head, tail) = rest.split_at_row_mut(SLAB);
        out.push(head);
        rest = tail;
    }
    if rest.nrows() > 0 {
        out.push(rest);
    }
    out
}

/// `A^T B` for tall `A` (`n x p`) and `B` (`n x q`).
fn gemm_tn(a: MatRef<'_, f64>, b: MatRef<'_, f64>, par: Par) -> Mat<f64> {
    let n = a.nrows();
    let starts: Vec<usize> = (0..n.div_ceil(SLAB)).map(|s| s * SLAB).collect();
    let part = |r0: usize| {
        let rows = SLAB.min(n - r0);
        let mut c = Mat::<f64>::zeros(a.ncols(), b.ncols());
        matmul(
            c.as_mut(),
            Accum::Replace,
            a.subrows(r0, rows).transpose(),
            b.subrows(r0, rows),
            1.0,
            Par::Seq,
        );
        c
    };
    let parts: Vec<Mat<f64>> = match par {
        Par::Seq => starts.into_iter().map(part).collect(),
        _ => starts.into_par_iter().map(part).collect(),
    };
    let mut sum = Mat::<f64>::zeros(a.ncols(), b.ncols());
    for p in &parts {
        sum += p;
    }
    sum
}

/// `C = beta C + alpha A B` for tall `C` (`n x q`) and `A` (`n x p`).
fn gemm_nn(
    c: MatMut<'_, f64>,
    beta: Accum,
    a: MatRef<'_, f64>,
    b: MatRef<'_, f64>,
    alpha: f64,
    par: Par,
) {
    let slabs = row_slabs(c);
    let job = |(s, mut cs): (usize, MatMut<'_, f64>)| {
        let rows = cs.nrows();
        matmul(
            cs.rb_mut(),
            beta,
            a.subrows(s * SLAB, rows),
            b,
            alpha,
            Par::Seq,
        );
    };
    match par {
        Par::Seq => slabs.into_iter().enumerate().for_each(job),
        _ => slabs.into_par_iter().enumerate().for_each(job),
    }
}

/// `A[:, :q] = A B` in place for tall `A` (`n x p`) and `B` (`p x q`, `q <= p`).
fn right_multiply_in_place(a: MatMut<'_, f64>, b: MatRef<'_, f64>, par: Par) {
    let q = b.ncols();
    let job = |s: MatMut<'_, f64>| {
        let mut t = Mat::<f64>::zeros(s.nrows(), q);
        matmul(t.as_mut(), Accum::Replace, s.rb(), b, 1.0, Par::Seq);
        s.subcols_mut(0, q).copy_from(&t);
    };
    match par {
        Par::Seq => row_slabs(a).into_iter().for_each(job),
        _ => row_slabs(a).into_par_iter().for_each(job),
    }
}

impl Krylov<'_> {
    /// `w = Op V[:, j..j + b] = M^1/2 (L - sigma M)^-1 M^1/2 V[:, j..j + b]`.
    fn apply(&mut self, j: usize) {
        let (n, b) = (self.n, self.b);
        let y = self.v.as_ref().subcols(j, b);
        for c in 0..b {
            for i in 0..n {
                self.w[(i, c)] = self.sqrt_m[i] * y[(i, c)];
            }
        }
        self.factor.solve_in_place_unchecked(self.w.as_mut());
        for c in 0..b {
            for i in 0..n {
                self.w[(i, c)] *= self.sqrt_m[i];
            }
        }
        self.solves += b;
    }

    /// Passes of block Gram-Schmidt of `w` against `V[:, :nk]`; returns the
    /// accumulated coefficients (`nk x ncols(w)`).
    fn orthogonalize(
        v: MatRef<'_, f64>,
        mut w: MatMut<'_, f64>,
        passes: usize,
        par: Par,
    ) -> Mat<f64> {
        let mut coef = Mat::<f64>::zeros(v.ncols(), w.ncols());
        for _ in 0..passes {
            let c = gemm_tn(v, w.rb(), par);
            gemm_nn(w.rb_mut(), Accum::Add, v, c.as_ref(), -1.0, par);
            coef += &c;
        }
        coef
    }

    /// Expands the basis from `j` columns by whole blocks while it fits in
    /// `mmax`; returns the new dimension `m`.
    fn expand(&mut self, mut j: usize) -> usize {
        let b = self.b;
        while j + b <= self.mmax {
            let nk = j + b;
            self.apply(j);
            let mut w = std::mem::replace(&mut self.w, Mat::new());
            let norms: Vec<f64> = (0..b).map(|c| w.col(c).norm_l2()).collect();
            let mut coef =
                Self::orthogonalize(self.v.as_ref().subcols(0, nk), w.as_mut(), 2, self.par);
            let r = self.block_qr(nk, w.as_mut(), &norms, &mut coef);
            self.h.as_mut().submatrix_mut(0, j, nk, b).copy_from(&coef);
            self.v.as_mut().subcols_mut(nk, b).copy_from(&w);
            self.h.as_mut().submatrix_mut(nk, j, b, b).copy_from(&r);
            self.w = w;
            j += b;
        }
        j
    }

    /// Orthonormalizes `w` in place (`w_in = w_out R + V[:, :nk] dcoef`, with
    /// `dcoef` added to `coef`), returning `R` (`b x b`, upper triangular).
    ///
    /// Shifted Cholesky QR three times (matrix-matrix products only). When the
    /// block is nearly rank deficient relative to the norms it had before
    /// orthogonalization (`norms`), it is reorthogonalized against the basis
    /// once more; when it is rank deficient to working precision, modified
    /// Gram-Schmidt replaces the dependent columns by random directions.
    fn block_qr(
        &mut self,
        nk: usize,
        mut w: MatMut<'_, f64>,
        norms: &[f64],
        coef: &mut Mat<f64>,
    ) -> Mat<f64> {
        let b = w.ncols();
        let scale = norms.iter().cloned().fold(0.0, f64::max);
        self.w_copy.copy_from(w.rb());
        if let Some(r) = self.shifted_chol_qr3(w.rb_mut()) {
            let rmin = (0..b)
                .map(|i| r[(i, i)].abs())
                .fold(f64::INFINITY, f64::min);
            if rmin > 1e-8 * scale {
                return r;
            }
            if rmin > 1e-13 * scale {
                // Q may have lost orthogonality to V: one more pass, then QR again
                let c =
                    Self::orthogonalize(self.v.as_ref().subcols(0, nk), w.rb_mut(), 1, self.par);
                if let Some(r2) = self.chol_qr(w.rb_mut(), 0.0).and_then(|r2| {
                    self.chol_qr(w.rb_mut(), 0.0)
                        .map(|r3| mul(r3.as_ref(), r2.as_ref()))
                }) {
                    // W = (Q' R' + V c) R  =>  R_total = R' R, coef += c R
                    let cr = mul(c.as_ref(), r.as_ref());
                    *coef += &cr;
                    return mul(r2.as_ref(), r.as_ref());
                }
            }
        }
        w.copy_from(&self.w_copy);
        self.gram_schmidt(nk, w, norms)
    }

    /// Three Cholesky QR steps, the first one shifted so that it succeeds for
    /// any conditioning (Fukaya et al.'s shifted CholeskyQR3).
    fn shifted_chol_qr3(&self, mut w: MatMut<'_, f64>) -> Option<Mat<f64>> {
        let (n, b) = (w.nrows() as f64, w.ncols() as f64);
        let frob2: f64 = (0..w.ncols())
            .map(|c| w.rb().col(c).squared_norm_l2())
            .sum();
        let shift = 11.0 * (n * b + b * (b + 1.0)) * f64::EPSILON * frob2;
        let r1 = self.chol_qr(w.rb_mut(), shift)?;
        let r2 = self.chol_qr(w.rb_mut(), 0.0)?;
        let r3 = self.chol_qr(w.rb_mut(), 0.0)?;
        Some(mul(r3.as_ref(), mul(r2.as_ref(), r1.as_ref()).as_ref()))
    }

    /// One Cholesky QR step on `W^T W + shift I`; `None` if the Cholesky
    /// factorization fails (then `w` is untouched).
    fn chol_qr(&self, w: MatMut<'_, f64>, shift: f64) -> Option<Mat<f64>> {
        let b = w.ncols();
        let mut g = gemm_tn(w.rb(), w.rb(), self.par);
        for i in 0..b {
            g[(i, i)] += shift;
        }
        let llt = g.llt(Side::Lower).ok()?;
        let r = llt.L().transpose().to_owned();
        let mut rinv = Mat::<f64>::identity(b, b);
        solve_upper_triangular_in_place(r.as_ref(), rinv.as_mut(), Par::Seq);
        right_multiply_in_place(w, rinv.as_ref(), self.par);
        Some(r)
    }

    /// Modified Gram-Schmidt (twice) inside the block; columns that vanish
    /// are replaced by random unit vectors orthogonal to the basis and to the
    /// previous columns (with a zero diagonal entry in `R`).
    fn gram_schmidt(&mut self, nk: usize, mut w: MatMut<'_, f64>, norms: &[f64]) -> Mat<f64> {
        let (n, b) = (self.n, w.ncols());
        let mut r = Mat::<f64>::zeros(b, b);
        for c in 0..b {
            let (left, mut right) = w.rb_mut().split_at_col_mut(c);
            let left = left.rb();
            let mut col = right.rb_mut().subcols_mut(0, 1);
            if c > 0 {
                let coef = Self::orthogonalize(left, col.rb_mut(), 2, Par::Seq);
                r.as_mut().submatrix_mut(0, c, c, 1).copy_from(&coef);
            }
            let nrm = col.rb().col(0).norm_l2();
            if nrm > 1e-13 * norms[c] && nrm > 0.0 {
                r[(c, c)] = nrm;
                col.rb_mut().col_mut(0).iter_mut().for_each(|x| *x /= nrm);
                continue;
            }
            // dependent column: a random direction orthogonal to V and w[:, :c]
            for i in 0..n {
                col[(i, 0)] = self.rng.next_f64();
            }
            let _ = Self::orthogonalize(self.v.as_ref().subcols(0, nk), col.rb_mut(), 2, self.par);
            if c > 0 {
                let _ = Self::orthogonalize(left, col.rb_mut(), 2, Par::Seq);
            }
            let nrm = col.rb().col(0).norm_l2();
            col.rb_mut().col_mut(0).iter_mut().for_each(|x| *x /= nrm);
        }
        r
    }

    /// `V[:, :p] = V[:, :m] S` in place.
    fn rotate(&mut self, m: usize, s: MatRef<'_, f64>) {
        right_multiply_in_place(self.v.as_mut().subcols_mut(0, m), s, self.par);
    }
}

fn mul(a: MatRef<'_, f64>, b: MatRef<'_, f64>) -> Mat<f64> {
    let mut c = Mat::<f64>::zeros(a.nrows(), b.ncols());
    matmul(c.as_mut(), Accum::Replace, a, b, 1.0, Par::Seq);
    c
}

/// Sparse path: shift-invert block Krylov-Schur.
fn sparse(
    l: &SparseColMat<usize, f64>,
    mass: &[f64],
    k: usize,
    b: usize,
    mmax: usize,
    opts: &EigenOptions,
) -> Result<Eigenpairs> {
    let n = l.nrows();
    let (factor, sigma) = shifted_factor(l, mass, opts)?;
    let mut kr = Krylov {
        n,
        b,
        mmax,
        factor: &factor,
        sqrt_m: mass.iter().map(|m| m.sqrt()).collect(),
        v: Mat::zeros(n, mmax + b),
        h: Mat::zeros(mmax + b, mmax),
        w: Mat::zeros(n, b),
        w_copy: Mat::zeros(n, b),
        rng: SplitMix(opts.seed),
        solves: 0,
        par: Par::rayon(0),
    };
    // random orthonormal starting block
    {
        let mut w = Mat::<f64>::zeros(n, b);
        for c in 0..b {
            for i in 0..n {
                w[(i, c)] = kr.rng.next_f64();
            }
        }
        let norms: Vec<f64> = (0..b).map(|c| w.col(c).norm_l2()).collect();
        let _ = kr.gram_schmidt(0, w.as_mut(), &norms);
        kr.v.as_mut().subcols_mut(0, b).copy_from(&w);
    }
    let mut j = 0;
    let mut restarts = 0;
    loop {
        let m = kr.expand(j);
        // Rayleigh-Ritz on the symmetric part of the projected operator
        let h = kr.h.as_ref();
        let t = Mat::from_fn(m, m, |r, c| 0.5 * (h[(r, c)] + h[(c, r)]));
        let (eigvals, u) = symmetric_eigen(t.as_ref(), "Rayleigh-Ritz eigendecomposition")?;
        // descending theta
        let theta: Vec<f64> = eigvals.iter().rev().copied().collect();
        let s = Mat::from_fn(m, m, |r, c| u[(r, m - 1 - c)]);
        // residuals ||E s_i|| with E = H[m..m + b, :m]
        let e = h.submatrix(m, 0, b, m);
        let es = mul(e, s.as_ref());
        let resid: Vec<f64> = (0..m)
            .map(|i| es.col(i).norm_l2() / theta[i].abs().max(f64::MIN_POSITIVE))
            .collect();
        let converged = resid[..k].iter().filter(|&&r| r <= opts.tol).count();
        if converged == k || restarts >= opts.max_restarts {
            if converged < k {
                let worst = resid[..k].iter().cloned().fold(0.0, f64::max);
                return Err(SolverError::NotConverged {
                    converged,
                    k,
                    restarts,
                    tol: opts.tol,
                    worst_residual: worst,
                });
            }
            // phi = M^-1/2 V S[:, :k], eigenvalues ascending (theta descending)
            let mut y = Mat::<f64>::zeros(n, k);
            gemm_nn(
                y.as_mut(),
                Accum::Replace,
                kr.v.as_ref().subcols(0, m),
                s.as_ref().subcols(0, k),
                1.0,
                kr.par,
            );
            let vectors = Mat::from_fn(n, k, |i, c| y[(i, c)] / kr.sqrt_m[i]);
            let values = theta[..k].iter().map(|t| sigma + 1.0 / t).collect();
            return Ok(Eigenpairs {
                values,
                vectors,
                info: EigenInfo {
                    method: EigenMethod::Sparse,
                    sigma,
                    restarts,
                    solves: kr.solves,
                },
            });
        }
        // thick restart: keep the p best Ritz vectors and the residual block
        let p = (k + (m - k) / 2).clamp(k, m - b);
        kr.rotate(m, s.as_ref().subcols(0, p));
        let residual_block = kr.v.as_ref().subcols(m, b).to_owned();
        kr.v.as_mut().subcols_mut(p, b).copy_from(&residual_block);
        kr.h.fill(0.0);
        for (i, &th) in theta.iter().enumerate().take(p) {
            kr.h[(i, i)] = th;
        }
        kr.h.as_mut()
            .submatrix_mut(p, 0, b, p)
            .copy_from(es.as_ref().subcols(0, p));
        j = p;
        restarts += 1;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn auto_block_and_subspace_sizes_are_consistent() {
        let o = EigenOptions::default();
        for k in [1, 10, 64, 200, 512] {
            let b = block_size(&o, k);
            let m = subspace_size(&o, k, b);
            assert_eq!(m % b, 0);
            assert!(m >= k + 2 * b, "k {k} b {b} m {m}");
        }
    }

    #[test]
    fn signs_are_normalized_to_a_positive_largest_entry() {
        let mut v = Mat::from_fn(3, 2, |i, j| {
            if j == 0 {
                [-3.0, 1.0, 2.0][i]
            } else {
                [0.5, -0.1, 0.2][i]
            }
        });
        normalize_signs(v.as_mut());
        assert_eq!(v[(0, 0)], 3.0);
        assert_eq!(v[(1, 0)], -1.0);
        assert_eq!(v[(0, 1)], 0.5);
    }
}
