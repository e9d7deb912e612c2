//! numpy arguments in, checked: each reader names the argument in its
//! `ValueError` and says what was expected and what was given.
//!
//! Every array argument must be a numpy array (not a list), C-contiguous
//! (`np.ascontiguousarray` makes one) and of the dtype the function states;
//! nothing is converted silently, so that a `float32` mesh or a transposed
//! view cannot lose precision or be read in the wrong order unnoticed.

use crate::errors::bad_argument;
use mfm_geometry::{MeshError, TriMesh};
use mfm_meshio::spec::MeshSpecError;
use numpy::{
    Element, PyArrayDescrMethods, PyArrayDyn, PyArrayMethods, PyUntypedArray, PyUntypedArrayMethods,
};
use pyo3::prelude::*;

/// `argument` as a numpy array, or a `ValueError` naming its Python type.
pub fn ndarray<'a, 'py>(
    obj: &'a Bound<'py, PyAny>,
    argument: &str,
) -> PyResult<&'a Bound<'py, PyUntypedArray>> {
    obj.cast::<PyUntypedArray>().map_err(|_| {
        let kind = obj
            .get_type()
            .name()
            .map(|n| n.to_string())
            .unwrap_or_else(|_| "an unknown type".to_owned());
        bad_argument(
            argument,
            format!("expected a numpy array, got {kind} (use np.asarray)"),
        )
    })
}

/// `float64 array of shape (4, 3)`: how an array is described in messages.
pub fn describe(arr: &Bound<'_, PyUntypedArray>) -> String {
    let shape: Vec<String> = arr.shape().iter().map(usize::to_string).collect();
    let shape = match shape.len() {
        1 => format!("({},)", shape[0]),
        _ => format!("({})", shape.join(", ")),
    };
    format!("{} array of shape {shape}", arr.dtype())
}

/// Whether `arr` holds elements of type `T`.
pub fn has_dtype<T: Element>(arr: &Bound<'_, PyUntypedArray>) -> bool {
    arr.dtype().is_equiv_to(&numpy::dtype::<T>(arr.py()))
}

/// Refuses a non-C-contiguous array, naming the argument.
pub fn require_contiguous(arr: &Bound<'_, PyUntypedArray>, argument: &str) -> PyResult<()> {
    if arr.is_c_contiguous() {
        Ok(())
    } else {
        Err(bad_argument(
            argument,
            format!(
                "the {} is not C-contiguous (pass np.ascontiguousarray({argument}))",
                describe(arr)
            ),
        ))
    }
}

/// The elements of a C-contiguous array of element type `T`, copied out in
/// C order (the caller has checked the dtype).
pub fn elements<T: Element + Copy>(
    arr: &Bound<'_, PyUntypedArray>,
    argument: &str,
) -> PyResult<Vec<T>> {
    require_contiguous(arr, argument)?;
    let typed = arr
        .cast::<PyArrayDyn<T>>()
        .map_err(|_| bad_argument(argument, format!("unexpected {}", describe(arr))))?;
    let view = typed.readonly();
    let slice = view
        .as_slice()
        .map_err(|e| bad_argument(argument, format!("{e} ({})", describe(arr))))?;
    Ok(slice.to_vec())
}

/// Vertex positions `V`: a non-empty C-contiguous `float64` array `[n, 3]`.
pub fn vertices(obj: &Bound<'_, PyAny>, argument: &str) -> PyResult<Vec<[f64; 3]>> {
    let arr = ndarray(obj, argument)?;
    if arr.ndim() != 2 || arr.shape()[1] != 3 || !has_dtype::<f64>(arr) {
        return Err(bad_argument(
            argument,
            format!(
                "expected a float64 array of shape (n, 3), got a {}",
                describe(arr)
            ),
        ));
    }
    if arr.shape()[0] == 0 {
        return Err(bad_argument(argument, "the mesh has no vertices"));
    }
    let flat = elements::<f64>(arr, argument)?;
    Ok(flat.chunks_exact(3).map(|p| [p[0], p[1], p[2]]).collect())
}

/// Faces `F`: a non-empty C-contiguous integer array `[m, 3]` of indices in
/// `0..vertices`.
pub fn faces(obj: &Bound<'_, PyAny>, argument: &str, vertices: usize) -> PyResult<Vec<[u32; 3]>> {
    let arr = ndarray(obj, argument)?;
    let wrong = || {
        bad_argument(
            argument,
            format!(
                "expected an integer array (int32, int64, uint32 or uint64) of shape (m, 3), got a {}",
                describe(arr)
            ),
        )
    };
    if arr.ndim() != 2 || arr.shape()[1] != 3 {
        return Err(wrong());
    }
    if arr.shape()[0] == 0 {
        return Err(bad_argument(argument, "the mesh has no faces"));
    }
    let indices: Vec<i128> = if has_dtype::<i64>(arr) {
        widen(elements::<i64>(arr, argument)?)
    } else if has_dtype::<i32>(arr) {
        widen(elements::<i32>(arr, argument)?)
    } else if has_dtype::<u32>(arr) {
        widen(elements::<u32>(arr, argument)?)
    } else if has_dtype::<u64>(arr) {
        widen(elements::<u64>(arr, argument)?)
    } else {
        return Err(wrong());
    };
    let mut out = Vec::with_capacity(indices.len() / 3);
    for (face, f) in indices.chunks_exact(3).enumerate() {
        let mut tri = [0u32; 3];
        for (slot, &i) in tri.iter_mut().zip(f) {
            if i < 0 || i >= vertices as i128 {
                return Err(bad_argument(
                    argument,
                    format!("face {face} refers to vertex {i}, but V has only {vertices} vertices"),
                ));
            }
            *slot = i as u32;
        }
        out.push(tri);
    }
    Ok(out)
}

fn widen<T: Into<i128>>(v: Vec<T>) -> Vec<i128> {
    v.into_iter().map(Into::into).collect()
}

/// A 1-D C-contiguous `float64` array, of length `len` when given.
pub fn vector(obj: &Bound<'_, PyAny>, argument: &str, len: Option<usize>) -> PyResult<Vec<f64>> {
    let arr = ndarray(obj, argument)?;
    let ok_len = len.is_none_or(|n| arr.ndim() == 1 && arr.shape()[0] == n);
    if arr.ndim() != 1 || !has_dtype::<f64>(arr) || !ok_len {
        let expected = match len {
            Some(n) => format!("({n},)"),
            None => "(n,)".to_owned(),
        };
        return Err(bad_argument(
            argument,
            format!(
                "expected a float64 array of shape {expected}, got a {}",
                describe(arr)
            ),
        ));
    }
    elements::<f64>(arr, argument)
}

/// The mesh `(V, F)`, checked as the command line checks a mesh file: a
/// `ValueError` naming `V` or `F` for non-finite coordinates, out-of-range
/// or repeated indices, and for duplicate faces; the other problems
/// [`mfm_geometry::validate::MeshReport`] finds (degenerate faces,
/// unreferenced vertices, non-manifold edges...) are Python warnings.
pub fn mesh(py: Python<'_>, v: &Bound<'_, PyAny>, f: &Bound<'_, PyAny>) -> PyResult<TriMesh> {
    let positions = vertices(v, "V")?;
    let faces = faces(f, "F", positions.len())?;
    let mesh = TriMesh::new(positions, faces).map_err(|e| {
        let argument = match e {
            MeshError::NonFinite { .. } | MeshError::TooManyVertices(_) => "V",
            MeshError::IndexOutOfRange { .. } | MeshError::RepeatedVertex { .. } => "F",
            _ => "V, F",
        };
        bad_argument(argument, e)
    })?;
    let warnings = py
        .detach(|| mfm_meshio::spec::check_mesh("(V, F)", &mesh))
        .map_err(|e| match e {
            MeshSpecError::DuplicateFaces { problem, .. } => bad_argument(
                "F",
                format!(
                    "{problem}; every operator would count their area twice: remove them first"
                ),
            ),
            e => bad_argument("F", e),
        })?;
    for problem in warnings {
        crate::mesh_io::warn(py, &format!("(V, F): {problem}"))?;
    }
    Ok(mesh)
}
