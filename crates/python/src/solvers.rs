//! Cached sparse Cholesky solvers: factor once, solve many right-hand sides.
//!
//! `PoissonSolver` factors `L + eps I` (PoissonNet's Poisson solve, the
//! matrix the authors hand to cholespy's `CholeskySolverF`, with `eps`
//! grown x10 until the factorization succeeds); `ScreenedSolver` factors
//! `L + tau M` (the Matérn operator). Both solve `[n]` or `[n, K]`
//! right-hand sides in `float64` (the `f64` factor) or `float32` (an `f32`
//! copy of the factor, made once on the first `float32` solve).

use crate::arrays::{self, describe, has_dtype, ndarray, require_contiguous};
use crate::errors::{bad_argument, runtime_error};
use crate::memory::require_memory;
use crate::operators::require_nondegenerate;
use crate::sparse::from_scipy;
use faer::sparse::SparseColMat;
use faer::{Mat, MatMut};
use mfm_geometry::operators;
use mfm_solver::{LaplacianSolver, ScreenedPoisson, Shift, ShiftOptions, SolverError};
use numpy::ndarray::{Array1, Array2};
use numpy::{PyArray1, PyArray2, PyUntypedArray, PyUntypedArrayMethods};
use pyo3::prelude::*;

/// Right-hand sides read into a column-major matrix, and how to give the
/// solution back (the input's shape and dtype).
struct Rhs<T> {
    columns: Mat<T>,
    vector: bool,
}

fn read_rhs<T: Scalar>(arr: &Bound<'_, PyUntypedArray>, n: usize) -> PyResult<Rhs<T>> {
    let k = if arr.ndim() == 1 { 1 } else { arr.shape()[1] };
    let flat = arrays::elements::<T>(arr, "rhs")?;
    if let Some((i, _)) = flat.iter().enumerate().find(|(_, x)| !x.finite()) {
        let (row, col) = (i / k, i % k);
        return Err(bad_argument(
            "rhs",
            format!("entry ({row}, {col}) is not finite"),
        ));
    }
    let columns = Mat::from_fn(n, k, |i, j| flat[i * k + j]);
    Ok(Rhs {
        columns,
        vector: arr.ndim() == 1,
    })
}

/// The element types a right-hand side may have.
trait Scalar: numpy::Element + Copy {
    fn finite(self) -> bool;
}

impl Scalar for f64 {
    fn finite(self) -> bool {
        self.is_finite()
    }
}

impl Scalar for f32 {
    fn finite(self) -> bool {
        self.is_finite()
    }
}

fn write_back<'py, T: numpy::Element + Copy>(
    py: Python<'py>,
    rhs: Rhs<T>,
) -> PyResult<Bound<'py, PyAny>> {
    let (n, k) = (rhs.columns.nrows(), rhs.columns.ncols());
    if rhs.vector {
        let v: Vec<T> = (0..n).map(|i| rhs.columns[(i, 0)]).collect();
        return Ok(PyArray1::from_owned_array(py, Array1::from_vec(v)).into_any());
    }
    let m = Array2::from_shape_fn((n, k), |(i, j)| rhs.columns[(i, j)]);
    Ok(PyArray2::from_owned_array(py, m).into_any())
}

/// A factor that solves blocks of right-hand sides in place, in `f64` and
/// `f32`.
trait CachedFactor: Sync {
    fn dim(&self) -> usize;
    fn solve_f64(&self, b: MatMut<'_, f64>) -> Result<(), SolverError>;
    fn solve_f32(&self, b: MatMut<'_, f32>) -> Result<(), SolverError>;
}

impl CachedFactor for LaplacianSolver {
    fn dim(&self) -> usize {
        LaplacianSolver::dim(self)
    }
    fn solve_f64(&self, b: MatMut<'_, f64>) -> Result<(), SolverError> {
        self.solve_many_in_place(b)
    }
    fn solve_f32(&self, b: MatMut<'_, f32>) -> Result<(), SolverError> {
        self.solve_many_f32_in_place(b)
    }
}

impl CachedFactor for ScreenedPoisson {
    fn dim(&self) -> usize {
        ScreenedPoisson::dim(self)
    }
    fn solve_f64(&self, b: MatMut<'_, f64>) -> Result<(), SolverError> {
        self.solve_many_in_place(b)
    }
    fn solve_f32(&self, b: MatMut<'_, f32>) -> Result<(), SolverError> {
        self.solve_many_f32_in_place(b)
    }
}

/// Solves `rhs` (`[n]` or `[n, K]`, float32 or float64) with `factor`, in
/// the precision of `rhs`.
fn solve<'py>(
    py: Python<'py>,
    rhs: &Bound<'py, PyAny>,
    factor: &impl CachedFactor,
) -> PyResult<Bound<'py, PyAny>> {
    let n = factor.dim();
    let arr = ndarray(rhs, "rhs")?;
    let shape_ok = match arr.ndim() {
        1 => arr.shape()[0] == n,
        2 => arr.shape()[0] == n && arr.shape()[1] > 0,
        _ => false,
    };
    let f64 = has_dtype::<f64>(arr);
    if !shape_ok || !(f64 || has_dtype::<f32>(arr)) {
        return Err(bad_argument(
            "rhs",
            format!(
                "expected a float32 or float64 array of shape ({n},) or ({n}, K), got a {}",
                describe(arr)
            ),
        ));
    }
    require_contiguous(arr, "rhs")?;
    // the input is copied twice (into columns, and back): twice its size
    require_memory(
        "the right-hand sides and their solutions",
        arr.len() as u128 * 2,
        if f64 { 8 } else { 4 },
    )?;
    let failed = |e: SolverError| runtime_error(format!("solve failed: {e}"));
    if f64 {
        let mut b = read_rhs::<f64>(arr, n)?;
        py.detach(|| factor.solve_f64(b.columns.as_mut()))
            .map_err(failed)?;
        write_back(py, b)
    } else {
        let mut b = read_rhs::<f32>(arr, n)?;
        py.detach(|| factor.solve_f32(b.columns.as_mut()))
            .map_err(failed)?;
        write_back(py, b)
    }
}

/// The factorization's error as a Python exception.
fn factor_error(e: SolverError) -> PyErr {
    match e {
        SolverError::NotPositiveDefinite { .. } | SolverError::ShiftExhausted { .. } => {
            runtime_error(format!("cannot factor the matrix: {e}"))
        }
        e => bad_argument("L", e),
    }
}

/// A cached factor of `L + eps I`, `L` the PSD cotangent Laplacian of
/// `(V, F)`: `PoissonSolver(V, F, eps=1e-6)`, or
/// `PoissonSolver.from_laplacian(L, eps=1e-6)` for a Laplacian of your own
/// (a symmetric PSD `scipy.sparse` matrix). `eps` starts at the given value
/// and grows x10 until the factorization succeeds (`.eps` says which was
/// used), as PoissonNet's training code does around cholespy.
///
/// `solve(rhs)` solves `(L + eps I) x = rhs` for `rhs` `[n]` or `[n, K]`,
/// `float32` or `float64`, and returns `x` in the same shape and dtype.
/// `mfm.torch.poisson_solve(solver, rhs)` is its differentiable form.
///
/// Example:
///
/// >>> import mfm, numpy as np
/// >>> V, F = mfm.read_mesh("builtin:icosphere:2")
/// >>> solver = mfm.PoissonSolver(V, F, eps=1e-6)
/// >>> b = np.random.default_rng(0).standard_normal((V.shape[0], 4))
/// >>> b -= b.mean(axis=0)
/// >>> x = solver.solve(b)
/// >>> L = mfm.cotan_laplacian(V, F)
/// >>> bool(np.abs(L @ x + 1e-6 * x - b).max() < 1e-9)
/// True
#[pyclass(module = "mfm", frozen)]
pub struct PoissonSolver {
    solver: LaplacianSolver,
}

impl PoissonSolver {
    fn factor(py: Python<'_>, l: &SparseColMat<usize, f64>, eps: f64) -> PyResult<Self> {
        if !(eps.is_finite() && eps >= 0.0) {
            return Err(bad_argument(
                "eps",
                format!("must be finite and >= 0, got {eps}"),
            ));
        }
        let opts = ShiftOptions {
            initial: Shift::Absolute(eps),
            ..ShiftOptions::default()
        };
        let solver = py
            .detach(|| LaplacianSolver::with_options(l, &opts))
            .map_err(factor_error)?;
        Ok(Self { solver })
    }
}

#[pymethods]
impl PoissonSolver {
    #[new]
    #[pyo3(signature = (V, F, eps = 1e-6))]
    #[allow(non_snake_case)]
    fn new(py: Python<'_>, V: &Bound<'_, PyAny>, F: &Bound<'_, PyAny>, eps: f64) -> PyResult<Self> {
        let mesh = arrays::mesh(py, V, F)?;
        require_nondegenerate(py, &mesh)?;
        let l = py.detach(|| operators::cotangent_laplacian(&mesh));
        Self::factor(py, &l, eps)
    }

    /// The solver of `L + eps I` for a Laplacian `L` of your own (symmetric,
    /// positive semi-definite, any `scipy.sparse` format).
    #[staticmethod]
    #[pyo3(name = "from_laplacian", signature = (L, eps = 1e-6))]
    #[allow(non_snake_case)]
    fn from_laplacian(py: Python<'_>, L: &Bound<'_, PyAny>, eps: f64) -> PyResult<Self> {
        let l = from_scipy(L, "L", None)?;
        require_symmetric(&l, "L")?;
        Self::factor(py, &l, eps)
    }

    /// Solves `(L + eps I) x = rhs`; `rhs` `[n]` or `[n, K]`, float32 or
    /// float64; `x` has the shape and dtype of `rhs`. Releases the GIL.
    fn solve<'py>(&self, py: Python<'py>, rhs: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyAny>> {
        solve(py, rhs, &self.solver)
    }

    /// The shift `eps` that was used.
    #[getter]
    fn eps(&self) -> f64 {
        self.solver.eps()
    }

    /// The size `n` of the system.
    #[getter]
    fn dim(&self) -> usize {
        self.solver.dim()
    }

    fn __repr__(&self) -> String {
        format!(
            "PoissonSolver(dim={}, eps={:e})",
            self.solver.dim(),
            self.solver.eps()
        )
    }
}

/// A cached factor of the screened Poisson operator `L + tau M`:
/// `ScreenedSolver(L, M, tau)` with `L` a symmetric PSD `scipy.sparse`
/// matrix (e.g. `mfm.cotan_laplacian(V, F)`), `M` the lumped mass as a
/// `float64 [n]` array of its diagonal or a diagonal `scipy.sparse` matrix
/// (`mfm.mass_matrix(V, F)`), and `tau > 0`.
///
/// `solve(rhs)` solves `(L + tau M) x = rhs` for `rhs` `[n]` or `[n, K]`,
/// `float32` or `float64`, and returns `x` in the same shape and dtype.
///
/// Example:
///
/// >>> import mfm, numpy as np
/// >>> V, F = mfm.read_mesh("builtin:icosphere:2")
/// >>> L, M = mfm.cotan_laplacian(V, F), mfm.mass_matrix(V, F)
/// >>> s = mfm.ScreenedSolver(L, M, 100.0)
/// >>> x = s.solve((M @ np.ones(V.shape[0])).astype(np.float32))  # L 1 = 0, so x = 1 / tau
/// >>> x.dtype.name, bool(np.allclose(x, 0.01, rtol=1e-4))
/// ('float32', True)
#[pyclass(module = "mfm", frozen)]
pub struct ScreenedSolver {
    solver: ScreenedPoisson,
}

#[pymethods]
impl ScreenedSolver {
    #[new]
    #[pyo3(signature = (L, M, tau))]
    #[allow(non_snake_case)]
    fn new(py: Python<'_>, L: &Bound<'_, PyAny>, M: &Bound<'_, PyAny>, tau: f64) -> PyResult<Self> {
        if !(tau.is_finite() && tau > 0.0) {
            return Err(bad_argument(
                "tau",
                format!("must be finite and > 0, got {tau}"),
            ));
        }
        let l = from_scipy(L, "L", None)?;
        require_symmetric(&l, "L")?;
        let mass = mass_diagonal(M, l.nrows())?;
        let solver = py
            .detach(|| ScreenedPoisson::new(&l, &mass, tau))
            .map_err(|e| match e {
                SolverError::NonPositiveMass { .. } | SolverError::SizeMismatch { .. } => {
                    bad_argument("M", e)
                }
                e => factor_error(e),
            })?;
        Ok(Self { solver })
    }

    /// Solves `(L + tau M) x = rhs`; `rhs` `[n]` or `[n, K]`, float32 or
    /// float64; `x` has the shape and dtype of `rhs`. Releases the GIL.
    fn solve<'py>(&self, py: Python<'py>, rhs: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyAny>> {
        solve(py, rhs, &self.solver)
    }

    /// The screening weight `tau`.
    #[getter]
    fn tau(&self) -> f64 {
        self.solver.tau()
    }

    /// The size `n` of the system.
    #[getter]
    fn dim(&self) -> usize {
        self.solver.dim()
    }

    fn __repr__(&self) -> String {
        format!(
            "ScreenedSolver(dim={}, tau={})",
            self.solver.dim(),
            self.solver.tau()
        )
    }
}

/// The diagonal of a lumped mass given as a 1-D array or a diagonal sparse
/// matrix.
fn mass_diagonal(m: &Bound<'_, PyAny>, n: usize) -> PyResult<Vec<f64>> {
    if m.cast::<PyUntypedArray>().is_ok() {
        return arrays::vector(m, "M", Some(n));
    }
    let sparse = from_scipy(m, "M", Some(n))?;
    let sym = sparse.symbolic();
    let mut diagonal = vec![0.0; n];
    for (j, d) in diagonal.iter_mut().enumerate() {
        for p in sym.col_ptr()[j]..sym.col_ptr()[j + 1] {
            let i = sym.row_idx()[p];
            let v = sparse.val()[p];
            if i == j {
                *d += v;
            } else if v != 0.0 {
                return Err(bad_argument(
                    "M",
                    format!("expected the lumped (diagonal) mass, but entry ({i}, {j}) is {v}"),
                ));
            }
        }
    }
    Ok(diagonal)
}

/// Refuses a matrix that is not symmetric (the factor reads only its lower
/// triangle, so an asymmetric input would be solved as another matrix).
fn require_symmetric(l: &SparseColMat<usize, f64>, argument: &str) -> PyResult<()> {
    let sym = l.symbolic();
    let scale = l.val().iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let entry = |i: usize, j: usize| -> f64 {
        let (start, end) = (sym.col_ptr()[j], sym.col_ptr()[j + 1]);
        let rows = &sym.row_idx()[start..end];
        rows.binary_search(&i).map_or(0.0, |p| l.val()[start + p])
    };
    for j in 0..l.ncols() {
        for p in sym.col_ptr()[j]..sym.col_ptr()[j + 1] {
            let i = sym.row_idx()[p];
            let (a, b) = (l.val()[p], entry(j, i));
            if (a - b).abs() > 1e-12 * scale {
                return Err(bad_argument(
                    argument,
                    format!(
                        "the matrix is not symmetric: entry ({i}, {j}) is {a} but ({j}, {i}) is {b}"
                    ),
                ));
            }
        }
    }
    Ok(())
}
