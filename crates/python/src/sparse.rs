//! Sparse matrices across the boundary: faer's column-major
//! `SparseColMat` out as `scipy.sparse.csc_matrix`, and any scipy sparse
//! matrix in (through its COO form, duplicates summed).

use crate::arrays::{describe, ndarray};
use crate::errors::bad_argument;
use faer::sparse::{SparseColMat, Triplet};
use numpy::{PyArray1, PyArrayMethods, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyTuple;

/// `scipy.sparse`, or an `ImportError` saying that the matrix functions
/// need scipy.
fn scipy_sparse(py: Python<'_>) -> PyResult<Bound<'_, PyModule>> {
    py.import("scipy.sparse").map_err(|e| {
        pyo3::exceptions::PyImportError::new_err(format!(
            "mfm returns sparse matrices as scipy.sparse.csc_matrix: install scipy ({e})"
        ))
    })
}

/// `m` as a `scipy.sparse.csc_matrix` (`float64` values, `int64`
/// indices), the same entries in the same order.
pub fn to_scipy<'py>(py: Python<'py>, m: &SparseColMat<usize, f64>) -> PyResult<Bound<'py, PyAny>> {
    let sym = m.symbolic();
    let indptr: Vec<i64> = sym.col_ptr().iter().map(|&p| p as i64).collect();
    let indices: Vec<i64> = sym.row_idx().iter().map(|&r| r as i64).collect();
    let data = PyArray1::from_slice(py, m.val());
    let parts = PyTuple::new(
        py,
        [
            data.into_any(),
            PyArray1::from_vec(py, indices).into_any(),
            PyArray1::from_vec(py, indptr).into_any(),
        ],
    )?;
    let shape = (m.nrows(), m.ncols());
    scipy_sparse(py)?
        .getattr("csc_matrix")?
        .call1((parts, shape))
}

/// A square scipy sparse matrix (any format) as a `SparseColMat`, with
/// duplicate entries summed; `n` is the expected size when known.
pub fn from_scipy(
    obj: &Bound<'_, PyAny>,
    argument: &str,
    n: Option<usize>,
) -> PyResult<SparseColMat<usize, f64>> {
    let py = obj.py();
    let sparse = scipy_sparse(py)?;
    if !sparse.getattr("issparse")?.call1((obj,))?.is_truthy()? {
        let kind = obj
            .get_type()
            .name()
            .map(|n| n.to_string())
            .unwrap_or_default();
        return Err(bad_argument(
            argument,
            format!("expected a scipy.sparse matrix, got {kind}"),
        ));
    }
    let (rows, cols): (usize, usize) = obj.getattr("shape")?.extract()?;
    if rows != cols || n.is_some_and(|n| n != rows) {
        let expected = n.map_or("square".to_owned(), |n| format!("{n} x {n}"));
        return Err(bad_argument(
            argument,
            format!("expected a {expected} matrix, got {rows} x {cols}"),
        ));
    }
    let coo = obj.call_method0("tocoo")?;
    let row = index_array(&coo.getattr("row")?, argument)?;
    let col = index_array(&coo.getattr("col")?, argument)?;
    let data = coo.getattr("data")?.call_method1("astype", ("float64",))?;
    let data = ndarray(&data, argument)?;
    let values = data
        .cast::<PyArray1<f64>>()
        .map_err(|_| bad_argument(argument, format!("unexpected values: {}", describe(data))))?
        .to_vec()
        .map_err(|e| bad_argument(argument, e))?;
    let mut triplets = Vec::with_capacity(values.len());
    for ((&r, &c), &v) in row.iter().zip(&col).zip(&values) {
        if !v.is_finite() {
            return Err(bad_argument(argument, format!("entry ({r}, {c}) is {v}")));
        }
        triplets.push(Triplet::new(r, c, v));
    }
    SparseColMat::try_new_from_triplets(rows, cols, &triplets)
        .map_err(|e| bad_argument(argument, format!("{e:?}")))
}

fn index_array(obj: &Bound<'_, PyAny>, argument: &str) -> PyResult<Vec<usize>> {
    let arr = obj.call_method1("astype", ("int64",))?;
    let arr = ndarray(&arr, argument)?;
    let len = arr.len();
    let values = arr
        .cast::<PyArray1<i64>>()
        .map_err(|_| bad_argument(argument, format!("unexpected indices: {}", describe(arr))))?
        .to_vec()
        .map_err(|e| bad_argument(argument, e))?;
    debug_assert_eq!(values.len(), len);
    Ok(values.into_iter().map(|i| i.max(0) as usize).collect())
}
