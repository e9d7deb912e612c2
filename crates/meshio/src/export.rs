//! A mesh's operators and eigenpairs as a folder of files, for use outside
//! mfm (scipy, MATLAB, libigl): Matrix Market matrices, `.npy` vectors and
//! a JSON summary stating the conventions.
//!
//! Both writers check their outputs first ([`mfm_files::Outputs`]: not an
//! input, not one file twice), write every file atomically, and remove
//! what they created if any step fails.

use faer::sparse::SparseColMat;
use mfm_files::matrix_market::{self, CscView};
use mfm_files::{FileError, Outputs, npy};
use mfm_geometry::TriMesh;
use mfm_geometry::operators::{self, OperatorError, Operators};
use mfm_solver::{EigenOptions, SolverError, generalized_eigenpairs};
use std::path::Path;
use std::time::Instant;
use thiserror::Error;

/// Why an operator or eigenpair folder was not written. Messages start
/// with the mesh's name or the file's path.
#[derive(Debug, Error)]
pub enum ExportError {
    /// Reading or writing a file.
    #[error(transparent)]
    File(#[from] FileError),
    /// The operators could not be built.
    #[error("{mesh}: cannot build operators: {source}")]
    Operators {
        /// The mesh's name as given.
        mesh: String,
        /// Why.
        #[source]
        source: OperatorError,
    },
    /// The eigensolver failed.
    #[error("{mesh}: eigensolve failed: {source}")]
    Eigen {
        /// The mesh's name as given.
        mesh: String,
        /// Why.
        #[source]
        source: SolverError,
    },
    /// No eigenpairs, or more than the mesh has vertices.
    #[error(
        "{mesh}: {k} eigenpairs asked for, but a mesh of {vertices} vertices has 1 to {vertices}"
    )]
    EigenpairCount {
        /// The mesh's name as given.
        mesh: String,
        /// Eigenpairs asked for.
        k: usize,
        /// Vertices of the mesh.
        vertices: usize,
    },
}

/// The files [`write_operator_folder`] writes.
pub const OPERATOR_FILES: [&str; 5] = [
    "L.mtx",
    "G.mtx",
    "mass.npy",
    "face_areas.npy",
    "summary.json",
];

/// The files [`write_eigen_folder`] writes.
pub const EIGEN_FILES: [&str; 3] = ["eigenvalues.npy", "eigenvectors.npy", "summary.json"];

/// `summary.json` of an operator folder.
#[derive(Clone, Debug, serde::Serialize)]
pub struct OperatorSummary {
    /// The mesh's name as given (a path or `builtin:NAME`).
    pub mesh: String,
    /// Vertices.
    pub vertices: usize,
    /// Faces.
    pub faces: usize,
    /// Stored entries of `L`.
    pub laplacian_nonzeros: usize,
    /// Stored entries of `G`.
    pub gradient_nonzeros: usize,
    /// Total surface area.
    pub total_area: f64,
    /// `Gamma = ||M^-1 L||_F`.
    pub gamma: f64,
    /// The data files beside the summary.
    pub files: Vec<&'static str>,
    /// What the matrices are, in words.
    pub conventions: &'static str,
}

/// Builds the operators of `mesh` (named `name`, a path or `builtin:NAME`)
/// and writes [`OPERATOR_FILES`] into `dir`: `L.mtx` (the PSD cotangent
/// Laplacian) and `G.mtx` (the `2F x V` intrinsic gradient) as Matrix
/// Market, `mass.npy` `[V]` (lumped) and `face_areas.npy` `[F]` as `f64`,
/// and `summary.json` ([`OperatorSummary`]). `O(nnz)` beyond the assembly.
///
/// # Errors
/// [`ExportError::Operators`] for a mesh with degenerate faces; the file
/// errors of the guard and the writers (nothing is left behind).
pub fn write_operator_folder(
    name: &str,
    mesh: &TriMesh,
    dir: &Path,
) -> Result<OperatorSummary, ExportError> {
    let ops = Operators::new(mesh).map_err(|source| ExportError::Operators {
        mesh: name.to_owned(),
        source,
    })?;
    let undo = guard(name, dir, &OPERATOR_FILES)?;
    let comment = format!("written by mfm {}", env!("CARGO_PKG_VERSION"));
    matrix_market::write(&dir.join("L.mtx"), csc(&ops.laplacian), &comment)?;
    matrix_market::write(&dir.join("G.mtx"), csc(&ops.gradient), &comment)?;
    npy::write(dir.join("mass.npy"), &ops.mass, &[ops.mass.len() as u64])?;
    npy::write(
        dir.join("face_areas.npy"),
        &ops.face_areas,
        &[ops.face_areas.len() as u64],
    )?;
    let summary = OperatorSummary {
        mesh: name.to_owned(),
        vertices: mesh.num_vertices(),
        faces: mesh.num_faces(),
        laplacian_nonzeros: ops.laplacian.val().len(),
        gradient_nonzeros: ops.gradient.val().len(),
        total_area: ops.face_areas.iter().sum(),
        gamma: operators::gamma(&ops.laplacian, &ops.mass),
        files: OPERATOR_FILES[..4].to_vec(),
        conventions: "L: cotangent Laplacian, positive semi-definite (libigl cotmatrix negated); \
mass: lumped barycentric; G: 2F x V intrinsic gradient, rows 2f,2f+1 in a per-face orthonormal frame; \
gamma = ||M^-1 L||_F",
    };
    mfm_files::write_json(dir.join("summary.json"), &summary)?;
    undo.keep();
    Ok(summary)
}

/// `summary.json` of an eigenpair folder.
#[derive(Clone, Debug, serde::Serialize)]
pub struct EigenSummary {
    /// The mesh's name as given.
    pub mesh: String,
    /// Vertices.
    pub vertices: usize,
    /// Eigenpairs.
    pub k: usize,
    /// The solver's method (`Dense`, `ShiftInvert`...).
    pub method: String,
    /// Seconds of the eigensolve.
    pub seconds: f64,
    /// The eigenvalues, ascending.
    pub eigenvalues: Vec<f64>,
    /// The data files beside the summary.
    pub files: [&'static str; 2],
    /// The conventions, in words.
    pub conventions: &'static str,
}

/// The `k` smallest eigenpairs of `L phi = lambda M phi` on `mesh`, written
/// into `dir` as [`EIGEN_FILES`]: `eigenvalues.npy` `[k]`,
/// `eigenvectors.npy` `[V, k]` (row-major, `M`-orthonormal columns) and
/// `summary.json` ([`EigenSummary`]).
///
/// # Errors
/// [`ExportError::EigenpairCount`] for `k` outside `1..=V`,
/// [`ExportError::Operators`], [`ExportError::Eigen`], and file errors
/// (nothing is left behind).
pub fn write_eigen_folder(
    name: &str,
    mesh: &TriMesh,
    k: usize,
    dir: &Path,
) -> Result<EigenSummary, ExportError> {
    let n = mesh.num_vertices();
    if k == 0 || k > n {
        return Err(ExportError::EigenpairCount {
            mesh: name.to_owned(),
            k,
            vertices: n,
        });
    }
    let undo = guard(name, dir, &EIGEN_FILES)?;
    let ops = Operators::new(mesh).map_err(|source| ExportError::Operators {
        mesh: name.to_owned(),
        source,
    })?;
    let start = Instant::now();
    let pairs = generalized_eigenpairs(&ops.laplacian, &ops.mass, k, &EigenOptions::default())
        .map_err(|source| ExportError::Eigen {
            mesh: name.to_owned(),
            source,
        })?;
    let seconds = start.elapsed().as_secs_f64();
    let mut vectors = Vec::with_capacity(n * k);
    for v in 0..n {
        for j in 0..k {
            vectors.push(pairs.vectors[(v, j)]);
        }
    }
    npy::write(dir.join(EIGEN_FILES[0]), &pairs.values, &[k as u64])?;
    npy::write(dir.join(EIGEN_FILES[1]), &vectors, &[n as u64, k as u64])?;
    let summary = EigenSummary {
        mesh: name.to_owned(),
        vertices: n,
        k,
        method: format!("{:?}", pairs.info.method),
        seconds,
        eigenvalues: pairs.values,
        files: [EIGEN_FILES[0], EIGEN_FILES[1]],
        conventions: "L phi = lambda M phi with L the PSD cotangent Laplacian and M the lumped mass; \
eigenvalues ascending; eigenvectors are the columns of the [V, k] array, phi^T M phi = 1",
    };
    mfm_files::write_json(dir.join(EIGEN_FILES[2]), &summary)?;
    undo.keep();
    Ok(summary)
}

/// The guard of a folder of `files` written from the mesh `name`.
fn guard(name: &str, dir: &Path, files: &[&str]) -> Result<mfm_files::Undo, FileError> {
    Outputs::new()
        .inputs(crate::spec::spec_path(name))
        .outputs(files.iter().map(|f| dir.join(f)))
        .prepare()
}

fn csc(m: &SparseColMat<usize, f64>) -> CscView<'_> {
    CscView {
        nrows: m.nrows(),
        ncols: m.ncols(),
        col_ptr: m.symbolic().col_ptr(),
        row_idx: m.symbolic().row_idx(),
        val: m.val(),
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use mfm_geometry::procedural;

    #[test]
    fn the_operator_folder_holds_the_operators() -> Result<(), Box<dyn std::error::Error>> {
        let dir = tempfile::tempdir()?;
        let out = dir.path().join("ops");
        let mesh = procedural::icosphere(1);
        let s = write_operator_folder("builtin:icosphere:1", &mesh, &out)?;
        let ops = Operators::new(&mesh)?;
        assert_eq!((s.vertices, s.faces), (42, 80));
        assert_eq!(s.laplacian_nonzeros, ops.laplacian.val().len());
        assert_eq!(npy::read::<f64>(&out.join("mass.npy"))?.values, ops.mass);
        let l = std::fs::read_to_string(out.join("L.mtx"))?;
        let header = l.lines().find(|l| !l.starts_with('%')).unwrap_or_default();
        assert_eq!(header, format!("42 42 {}", s.laplacian_nonzeros));
        for f in OPERATOR_FILES {
            assert!(out.join(f).is_file(), "{f}");
        }
        Ok(())
    }

    #[test]
    fn eigenpairs_are_m_orthonormal_and_a_bad_k_writes_nothing()
    -> Result<(), Box<dyn std::error::Error>> {
        let dir = tempfile::tempdir()?;
        let out = dir.path().join("eigs");
        let mesh = procedural::icosphere(1);
        let e = write_eigen_folder("m", &mesh, 43, &out)
            .map(|_| ())
            .unwrap_err();
        assert!(matches!(
            e,
            ExportError::EigenpairCount {
                k: 43,
                vertices: 42,
                ..
            }
        ));
        assert!(!out.exists());
        let s = write_eigen_folder("m", &mesh, 4, &out)?;
        assert!(s.eigenvalues[0].abs() < 1e-8 && s.eigenvalues[1] > 1.0);
        let vectors = npy::read::<f64>(&out.join("eigenvectors.npy"))?;
        assert_eq!(vectors.shape, vec![42, 4]);
        let mass = operators::lumped_mass(&mesh);
        for (a, b) in [(0, 0), (1, 1), (1, 2), (3, 3)] {
            let dot: f64 = (0..42)
                .map(|v| mass[v] * vectors.values[v * 4 + a] * vectors.values[v * 4 + b])
                .sum();
            let expected = if a == b { 1.0 } else { 0.0 };
            assert!(
                (dot - expected).abs() < 1e-8,
                "<phi_{a}, phi_{b}>_M = {dot}"
            );
        }
        Ok(())
    }
}
