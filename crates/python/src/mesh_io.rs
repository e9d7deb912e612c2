//! `read_mesh` and `write_mesh`: the command line's mesh files from Python.

use crate::arrays::{self, describe, ndarray};
use crate::errors::{bad_argument, file_error, value_error};
use mfm_geometry::TriMesh;
use mfm_meshio::spec::{MeshSpecError, load_mesh_spec_checked};
use mfm_meshio::{ReadErrorKind, WriteErrorKind};
use numpy::ndarray::Array2;
use numpy::{PyArray2, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::path::PathBuf;

/// `(V float64 [n, 3], F int64 [m, 3])` as numpy arrays.
pub type MeshArrays<'py> = (Bound<'py, PyArray2<f64>>, Bound<'py, PyArray2<i64>>);

/// Reads a triangle mesh file (`.obj`, `.off`, `.ply`, `.gltf`, `.glb`) or a
/// builtin (`"builtin:blob"`, `"builtin:icosphere:3"`), as `mfm` reads it.
///
/// Returns `(V, F)`: `V` `float64 [n, 3]`, `F` `int64 [m, 3]` (0-based),
/// in file order (vertices no face uses are kept). Raises
/// `FileNotFoundError` / `OSError` when the file cannot be read and
/// `ValueError` for a file that is not a valid mesh, with the command
/// line's message; the mesh's other problems are `UserWarning`s.
///
/// Example:
///
/// >>> import mfm
/// >>> V, F = mfm.read_mesh("builtin:icosphere:1")
/// >>> V.shape, F.shape, F.dtype.name
/// ((42, 3), (80, 3), 'int64')
#[pyfunction]
#[pyo3(signature = (path))]
pub fn read_mesh<'py>(py: Python<'py>, path: PathBuf) -> PyResult<MeshArrays<'py>> {
    let spec = path.to_string_lossy().into_owned();
    let checked = py.detach(|| load_mesh_spec_checked(&spec)).map_err(|e| {
        let io = match &e {
            MeshSpecError::Read(r) => match r.kind() {
                ReadErrorKind::Io(io) => Some(io),
                _ => None,
            },
            _ => None,
        };
        file_error(io, e.to_string())
    })?;
    for problem in &checked.warnings {
        let message = format!("{spec}: {problem} (`mfm info {spec}` shows the full report)");
        warn(py, &message)?;
    }
    Ok(mesh_arrays(py, checked.mesh))
}

/// Emits a `UserWarning`.
pub fn warn(py: Python<'_>, message: &str) -> PyResult<()> {
    let category = py.get_type::<pyo3::exceptions::PyUserWarning>();
    let text = std::ffi::CString::new(message.replace('\0', " ")).unwrap_or_default();
    PyErr::warn(py, &category, &text, 1)
}

/// `(V, F)` of `mesh` as numpy arrays.
pub fn mesh_arrays(
    py: Python<'_>,
    mesh: TriMesh,
) -> (Bound<'_, PyArray2<f64>>, Bound<'_, PyArray2<i64>>) {
    let (positions, faces) = mesh.into_parts();
    let (n, m) = (positions.len(), faces.len());
    let v: Vec<f64> = positions.into_iter().flatten().collect();
    let f: Vec<i64> = faces.into_iter().flatten().map(i64::from).collect();
    let v = Array2::from_shape_vec((n, 3), v).unwrap_or_else(|_| Array2::zeros((0, 3)));
    let f = Array2::from_shape_vec((m, 3), f).unwrap_or_else(|_| Array2::zeros((0, 3)));
    (
        PyArray2::from_owned_array(py, v),
        PyArray2::from_owned_array(py, f),
    )
}

/// Writes `(V, F)` to `path`: `.obj` (text) or `.ply` (binary, `double`
/// coordinates), atomically (a failed write leaves `path` as it was).
///
/// `scalars`, a dict `{name: float64 array [n]}`, adds per-vertex
/// properties to a `.ply` file (MeshLab and plyfile show them); other
/// formats cannot carry them and raise `ValueError`.
///
/// Example:
///
/// >>> import mfm, os, tempfile
/// >>> V, F = mfm.read_mesh("builtin:icosphere:1")
/// >>> path = os.path.join(tempfile.mkdtemp(), "ico.ply")
/// >>> mfm.write_mesh(path, V, F, scalars={"height": V[:, 2].copy()})
/// >>> bool((mfm.read_mesh(path)[0] == V).all())
/// True
#[pyfunction]
#[pyo3(signature = (path, V, F, scalars = None))]
#[allow(non_snake_case)]
pub fn write_mesh(
    py: Python<'_>,
    path: PathBuf,
    V: &Bound<'_, PyAny>,
    F: &Bound<'_, PyAny>,
    scalars: Option<&Bound<'_, PyDict>>,
) -> PyResult<()> {
    let mesh = arrays::mesh(py, V, F)?;
    let n = mesh.num_vertices();
    let mut fields: Vec<(String, Vec<f64>)> = Vec::new();
    for (key, value) in scalars.into_iter().flat_map(|d| d.iter()) {
        let name: String = key
            .extract()
            .map_err(|_| bad_argument("scalars", "keys must be strings"))?;
        let argument = format!("scalars[{name:?}]");
        let arr = ndarray(&value, &argument)?;
        if arr.ndim() != 1 || arr.shape()[0] != n {
            return Err(bad_argument(
                &argument,
                format!(
                    "expected one float64 value per vertex, shape ({n},), got a {}",
                    describe(arr)
                ),
            ));
        }
        fields.push((name, arrays::vector(&value, &argument, Some(n))?));
    }
    let ply = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("ply"));
    if !fields.is_empty() && !ply {
        return Err(bad_argument(
            "scalars",
            format!(
                "{}: only .ply files carry per-vertex scalars",
                path.display()
            ),
        ));
    }
    let result = py.detach(|| {
        if fields.is_empty() {
            mfm_meshio::write_mesh(&path, &mesh)
        } else {
            let named: Vec<(&str, &[f64])> = fields
                .iter()
                .map(|(k, v)| (k.as_str(), v.as_slice()))
                .collect();
            mfm_meshio::write_ply(&path, &mesh, &named)
        }
    });
    result.map_err(|e| match e.kind() {
        WriteErrorKind::Io(io) => file_error(Some(io), e.to_string()),
        _ => value_error(e.to_string()),
    })
}
