//! The mesh operators and eigenpairs, named as a libigl user guesses them,
//! with the conventions of `mfm operators` and `mfm eigs`.

use crate::arrays;
use crate::errors::{bad_argument, runtime_error};
use crate::sparse::to_scipy;
use faer::sparse::{SparseColMat, Triplet};
use mfm_geometry::TriMesh;
use mfm_geometry::operators::{self, Operators};
use mfm_solver::{EigenOptions, generalized_eigenpairs};
use numpy::ndarray::Array2;
use numpy::{PyArray1, PyArray2};
use pyo3::prelude::*;

/// `(eigenvalues [k], eigenvectors [n, k])` as numpy arrays.
pub type Eigenpairs<'py> = (Bound<'py, PyArray1<f64>>, Bound<'py, PyArray2<f64>>);

/// Refuses a mesh with a degenerate face (no resolvable area), where the
/// cotangent weights and the gradient are undefined, as `mfm operators`
/// does.
pub fn require_nondegenerate(py: Python<'_>, mesh: &TriMesh) -> PyResult<()> {
    py.detach(|| Operators::new(mesh).map(drop))
        .map_err(|e| bad_argument("F", format!("{e}; the operators are undefined there")))
}

/// The operator `op` of the mesh `(V, F)` as a scipy matrix, computed
/// with the GIL released; `undefined_on_degenerate` refuses meshes with a
/// degenerate face first.
fn sparse_operator<'py>(
    py: Python<'py>,
    v: &Bound<'py, PyAny>,
    f: &Bound<'py, PyAny>,
    undefined_on_degenerate: bool,
    op: impl Fn(&TriMesh) -> Result<SparseColMat<usize, f64>, String> + Send + Sync,
) -> PyResult<Bound<'py, PyAny>> {
    let mesh = arrays::mesh(py, v, f)?;
    if undefined_on_degenerate {
        require_nondegenerate(py, &mesh)?;
    }
    let m = py.detach(|| op(&mesh)).map_err(runtime_error)?;
    to_scipy(py, &m)
}

/// The cotangent Laplacian `L` of `(V, F)`: a `scipy.sparse.csc_matrix`
/// `[n, n]`, **positive semi-definite** (`L = -igl.cotmatrix(V, F)`; rows sum
/// to zero), symmetric with both triangles stored.
///
/// Example:
///
/// >>> import mfm, numpy as np
/// >>> V, F = mfm.read_mesh("builtin:icosphere:2")
/// >>> L = mfm.cotan_laplacian(V, F)
/// >>> bool(abs(L.sum(axis=1)).max() < 1e-12 and L.diagonal().min() > 0)
/// True
#[pyfunction]
#[pyo3(signature = (V, F))]
#[allow(non_snake_case)]
pub fn cotan_laplacian<'py>(
    py: Python<'py>,
    V: &Bound<'py, PyAny>,
    F: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyAny>> {
    sparse_operator(py, V, F, true, |m| Ok(operators::cotangent_laplacian(m)))
}

/// The lumped (barycentric) mass matrix `M` of `(V, F)`: a diagonal
/// `scipy.sparse.csc_matrix` `[n, n]`, a third of the area of the faces
/// around each vertex (`igl.massmatrix(V, F, igl.MASSMATRIX_TYPE_BARYCENTRIC)`).
///
/// Example:
///
/// >>> import mfm
/// >>> V, F = mfm.read_mesh("builtin:icosphere:2")
/// >>> M = mfm.mass_matrix(V, F)
/// >>> bool(abs(M.sum() - mfm.face_areas(V, F).sum()) < 1e-12)
/// True
#[pyfunction]
#[pyo3(signature = (V, F))]
#[allow(non_snake_case)]
pub fn mass_matrix<'py>(
    py: Python<'py>,
    V: &Bound<'py, PyAny>,
    F: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyAny>> {
    sparse_operator(py, V, F, false, |mesh| {
        let mass = operators::lumped_mass(mesh);
        let n = mass.len();
        let diagonal: Vec<Triplet<usize, usize, f64>> = mass
            .iter()
            .enumerate()
            .map(|(i, &m)| Triplet::new(i, i, m))
            .collect();
        SparseColMat::try_new_from_triplets(n, n, &diagonal)
            .map_err(|e| format!("mass matrix: {e:?}"))
    })
}

/// The intrinsic gradient `G` of `(V, F)`: a `scipy.sparse.csc_matrix`
/// `[2 m, n]`; rows `2f` and `2f + 1` are the two components of the
/// gradient of a piecewise-linear function on face `f`, in an orthonormal
/// frame of the face whose first axis runs along its first edge
/// (`F[f, 0] -> F[f, 1]`). `G.T @ diag(A2) @ G == L` with `A2` the face
/// areas each repeated twice (`face_areas`).
///
/// Example:
///
/// >>> import mfm, numpy as np, scipy.sparse as sp
/// >>> V, F = mfm.read_mesh("builtin:icosphere:2")
/// >>> G = mfm.face_gradients(V, F)
/// >>> A2 = sp.diags(np.repeat(mfm.face_areas(V, F), 2))
/// >>> bool(abs(G.T @ A2 @ G - mfm.cotan_laplacian(V, F)).max() < 1e-12)
/// True
#[pyfunction]
#[pyo3(signature = (V, F))]
#[allow(non_snake_case)]
pub fn face_gradients<'py>(
    py: Python<'py>,
    V: &Bound<'py, PyAny>,
    F: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyAny>> {
    sparse_operator(py, V, F, true, |m| Ok(operators::intrinsic_gradient(m)))
}

/// The face areas of `(V, F)`, `float64 [m]` (`igl.doublearea(V, F) / 2`).
///
/// Example:
///
/// >>> import mfm
/// >>> V, F = mfm.read_mesh("builtin:icosphere:1")
/// >>> mfm.face_areas(V, F).shape
/// (80,)
#[pyfunction]
#[pyo3(signature = (V, F))]
#[allow(non_snake_case)]
pub fn face_areas<'py>(
    py: Python<'py>,
    V: &Bound<'py, PyAny>,
    F: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyArray1<f64>>> {
    let mesh = arrays::mesh(py, V, F)?;
    let areas = py.detach(|| operators::face_areas(&mesh));
    Ok(PyArray1::from_vec(py, areas))
}

/// The `k` smallest eigenpairs of `L phi = lambda M phi` on `(V, F)`
/// (`L` the PSD cotangent Laplacian, `M` the lumped mass), as `mfm eigs`
/// computes them: `(eigenvalues float64 [k], ascending; eigenvectors
/// float64 [n, k], M-orthonormal columns: phi.T @ M @ phi == I)`. The sign
/// of each eigenvector is arbitrary.
///
/// Example:
///
/// >>> import mfm, numpy as np
/// >>> V, F = mfm.read_mesh("builtin:icosphere:2")
/// >>> lam, phi = mfm.eigs(V, F, 8)
/// >>> M = mfm.mass_matrix(V, F)
/// >>> bool(abs(lam[0]) < 1e-9 and np.allclose(phi.T @ (M @ phi), np.eye(8)))
/// True
#[pyfunction]
#[pyo3(signature = (V, F, k))]
#[allow(non_snake_case)]
pub fn eigs<'py>(
    py: Python<'py>,
    V: &Bound<'py, PyAny>,
    F: &Bound<'py, PyAny>,
    k: i64,
) -> PyResult<Eigenpairs<'py>> {
    let mesh = arrays::mesh(py, V, F)?;
    let n = mesh.num_vertices();
    if k < 1 || k as u64 > n as u64 {
        return Err(bad_argument(
            "k",
            format!("{k} eigenpairs asked, but the mesh has {n} vertices (1 <= k <= {n})"),
        ));
    }
    let k = k as usize;
    let ops = py
        .detach(|| Operators::new(&mesh))
        .map_err(|e| bad_argument("F", format!("{e}; the operators are undefined there")))?;
    let pairs = py
        .detach(|| generalized_eigenpairs(&ops.laplacian, &ops.mass, k, &EigenOptions::default()))
        .map_err(|e| runtime_error(format!("eigs: {e}")))?;
    let mut vectors = Vec::with_capacity(n * k);
    for v in 0..n {
        for j in 0..k {
            vectors.push(pairs.vectors[(v, j)]);
        }
    }
    let vectors =
        Array2::from_shape_vec((n, k), vectors).map_err(|e| runtime_error(format!("eigs: {e}")))?;
    Ok((
        PyArray1::from_vec(py, pairs.values),
        PyArray2::from_owned_array(py, vectors),
    ))
}
