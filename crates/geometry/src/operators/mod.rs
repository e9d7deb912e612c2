//! Intrinsic differential operators of a triangle mesh: face areas, lumped
//! mass, cotangent Laplacian and the per-face gradient.
//!
//! Everything here is computed from the **edge lengths** of each face (the
//! intrinsic geometry), in `f64`. Sparse matrices are
//! [`faer::sparse::SparseColMat<usize, f64>`] in compressed-column form with
//! sorted row indices.
//!
//! ## Conventions
//! - `A` ([`face_areas`]): one area per face, by a numerically stable form of
//!   Heron's formula. `A2` ([`face_areas_interleaved`]) repeats each area twice,
//!   `[A0, A0, A1, A1, ...]`, to weight the `2F` rows of `G`.
//! - `M` ([`lumped_mass`]): the diagonal of the lumped (barycentric) mass matrix,
//!   `M_ii = sum over faces at i of A_f / 3`. It sums to the surface area.
//! - `L` ([`cotangent_laplacian`]): the cotangent Laplacian in the **positive
//!   semi-definite** convention, `L_ij = -(cot a_ij + cot b_ij) / 2` for an edge
//!   `ij` (`a_ij`, `b_ij` the angles opposite the edge; a boundary edge has one),
//!   `L_ii = -sum_j L_ij`. libigl's `cotmatrix` is `-L`. `L` is exactly
//!   symmetric (both triangles of the matrix are stored, bit-identical) and
//!   `L 1 = 0` to round-off.
//! - `G` ([`intrinsic_gradient`]): the `2F x V` gradient of piecewise-linear
//!   functions. Rows `2f` and `2f + 1` are the two components of the (constant)
//!   gradient on face `f` in the face frame described below. With it,
//!   `G^T diag(A2) G = L` to round-off.
//! - `Gamma` ([`gamma`]) `= ||M^-1 L||_F`; under a global scale by `k`, `L` is
//!   unchanged, `M -> k^2 M` and `Gamma -> Gamma / k^2`.
//!
//! ## The frame of `G` (the one place it is defined)
//! For a face `f = [i0, i1, i2]` with edge lengths `l0 = |p1 - p2|`,
//! `l1 = |p2 - p0|`, `l2 = |p0 - p1|` (`l_c` is opposite corner `c`), the face
//! is laid out in the plane with corner 0 at the origin, corner 1 on the
//! positive x axis at `(l2, 0)` and corner 2 above the axis at
//! `(x2, y2) = ((l1^2 + l2^2 - l0^2) / (2 l2), 2 A / l2)`. In 3D this is the
//! orthonormal frame `ex = (p1 - p0) / l2`, `ey = n x ex` with
//! `n = (p1 - p0) x (p2 - p0) / |...|` the unit normal of the counter-clockwise
//! face. In that frame the gradients of the three hat functions are
//!
//! ```text
//! grad phi_0 = (-1/l2, -cot_1/l2)
//! grad phi_1 = ( 1/l2, -cot_0/l2)
//! grad phi_2 = (    0, (cot_0 + cot_1)/l2)
//! ```
//!
//! (`cot_c` the cotangent of the angle at corner `c`). The zero x-component of
//! corner 2 is not stored, so `G` has `5F` structural non-zeros. Nothing else
//! in mfm depends on this choice: any per-face rotation of the frame gives the
//! same `G^T diag(A2) G`.
//!
//! ## Degenerate faces
//! A face is *degenerate* when its area, computed from its (rounded) edge
//! lengths, is not resolved by floating point: `2 A <= f64::EPSILON * l_max^2`
//! (`l_max` its longest edge). This covers collinear corners, repeated
//! positions, overflowing coordinates, and slivers whose height is below about
//! `1e-8` of their length (their edge lengths round to a flat triangle).
//! [`Operators::new`] refuses such a mesh with
//! [`OperatorError::DegenerateFace`] naming the first one. The free functions
//! and [`Operators::new_lenient`] never produce NaN or infinity: a degenerate
//! face keeps its (tiny) area in `A` and `M`, but contributes **zero** to `L`
//! and has zero rows in `G`, so `G^T diag(A2) G = L` still holds.
//!
//! ## Structure and cost
//! The sparsity pattern depends only on the connectivity: column `j` of `L`
//! holds the diagonal and every vertex sharing an edge with `j` (explicit zeros
//! are kept for edges whose faces are all degenerate), so `nnz(L) = V + 2E`; a
//! vertex that no face references has an empty row and column (and zero mass).
//! Column `v` of `G` holds rows `2f, 2f + 1` for each face `f` at `v` (only
//! `2f + 1` where `v` is corner 2).
//!
//! Every operator is `O(V + F)` work and memory, with no global sort: the
//! faces are bucketed by blocks of consecutive vertices (a counting sort) and
//! the blocks are assembled independently, in parallel (rayon), each in cache
//! (the private `assembly` module; this file holds the math per face).
//! Results are deterministic: bit-identical for any number of threads.
//! Timings against libigl's `cotmatrix`, `massmatrix` and `grad` are in
//! `docs/BENCHMARKS.md` (`cargo xtask bench operators`).
//!
//! ## Example
//! ```
//! use mfm_geometry::{operators, TriMesh};
//! // a unit square split along its diagonal
//! let mesh = TriMesh::new(
//!     vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]],
//!     vec![[0, 1, 2], [0, 2, 3]],
//! ).unwrap();
//! let ops = operators::Operators::new(&mesh).unwrap();
//! // the two right angles sit opposite the diagonal: its weight is zero
//! let l = &ops.laplacian;
//! let l01 = l.get(0, 1).copied().unwrap_or(0.0);
//! assert!((l01 + 0.5).abs() < 1e-15); // -cot(45 deg)/2: the edge has one face
//! assert!(l.get(0, 2).copied().unwrap_or(0.0).abs() < 1e-15);
//! assert!((ops.mass.iter().sum::<f64>() - 1.0).abs() < 1e-15);
//! assert_eq!(ops.gradient.nrows(), 2 * mesh.num_faces());
//! ```

use faer::sparse::SparseColMat;
use rayon::prelude::*;
use thiserror::Error;

use crate::mesh::TriMesh;

/// Why operators could not be built or evaluated.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum OperatorError {
    /// A face has no resolvable area (see the module docs for the criterion).
    #[error(
        "face {face} (vertices {vertices:?}) is degenerate: area {area:e} with edge lengths {edge_lengths:?}; \
expected twice the area above f64::EPSILON * (longest edge)^2"
    )]
    DegenerateFace {
        /// Face number (0-based).
        face: usize,
        /// Its vertex indices.
        vertices: [u32; 3],
        /// The area computed from the edge lengths.
        area: f64,
        /// Edge lengths `[l0, l1, l2]`, `l_c` opposite corner `c`.
        edge_lengths: [f64; 3],
    },
    /// A mass vector does not have one entry per row of the Laplacian.
    #[error(
        "expected a mass vector of length {expected} (the Laplacian is {expected} x {expected}), found {found}"
    )]
    MassLength {
        /// Number of rows of `L`.
        expected: usize,
        /// Length of the mass vector.
        found: usize,
    },
    /// The Laplacian is not square.
    #[error("expected a square Laplacian, found {rows} x {cols}")]
    NotSquare {
        /// Rows.
        rows: usize,
        /// Columns.
        cols: usize,
    },
    /// A vertex has a non-zero row of `L` but a mass that is not positive.
    #[error(
        "vertex {vertex} has mass {mass:e} but a non-zero Laplacian row; expected a positive mass"
    )]
    NonPositiveMass {
        /// Vertex number (0-based).
        vertex: usize,
        /// Its mass.
        mass: f64,
    },
}

/// One face's two rows of `G`, by corner: `[[gx0, gx1, gx2], [gy0, gy1,
/// gy2]]`, the gradients of the face's three hat functions in its frame (see
/// the [module docs](self); `gx2` is always zero).
pub type FaceGradient = [[f64; 3]; 2];

/// All intrinsic operators of a mesh, computed together so that the per-face
/// work (edge lengths, areas, cotangents) and the per-vertex counts are shared.
///
/// See the [module docs](self) for the conventions.
///
/// Cost: `O(V + F)` work, parallel over faces and vertices.
///
/// # Example
/// ```
/// use mfm_geometry::{operators::Operators, procedural};
/// let mesh = procedural::icosphere(3);
/// let ops = Operators::new(&mesh).unwrap();
/// let (v, f) = (mesh.num_vertices(), mesh.num_faces());
/// assert_eq!((ops.laplacian.nrows(), ops.gradient.nrows()), (v, 2 * f));
/// assert_eq!(ops.face_areas_interleaved.len(), 2 * f);
/// assert_eq!(ops.face_gradients.len(), f);
/// assert!(ops.degenerate_faces.is_empty());
/// ```
#[derive(Clone, Debug)]
pub struct Operators {
    /// Cotangent Laplacian `L`, `V x V`, positive semi-definite.
    pub laplacian: SparseColMat<usize, f64>,
    /// Lumped barycentric mass (diagonal of `M`), length `V`.
    pub mass: Vec<f64>,
    /// Face areas `A`, length `F`.
    pub face_areas: Vec<f64>,
    /// Face areas interleaved twice, `A2 = [A0, A0, A1, A1, ...]`, length `2F`.
    pub face_areas_interleaved: Vec<f64>,
    /// Intrinsic gradient `G`, `2F x V`, in the frame of the module docs.
    pub gradient: SparseColMat<usize, f64>,
    /// `G` face by face, length `F`: `face_gradients[f][r][c]` is the entry
    /// of row `2f + r` (`r = 0` the x, `1` the y component of the face
    /// frame) in the column of corner `c` of face `f` (`faces[f][c]`), zero
    /// for the x component of corner 2 and for degenerate faces. Equal, bit
    /// for bit, to the entries of [`Operators::gradient`], which is this
    /// table scattered into columns; code that edits one edits both.
    pub face_gradients: Vec<FaceGradient>,
    /// Faces treated as degenerate (zero contribution to `L` and `G`); always
    /// empty for [`Operators::new`], sorted for [`Operators::new_lenient`].
    pub degenerate_faces: Vec<usize>,
}

impl Operators {
    /// Builds `L`, `M`, `A`, `A2` and `G`, or reports the first degenerate face.
    ///
    /// # Errors
    /// [`OperatorError::DegenerateFace`] if a face has no resolvable area.
    pub fn new(mesh: &TriMesh) -> Result<Self, OperatorError> {
        let (data, areas) = face_data_and_areas(mesh);
        if let Some(face) = data.iter().position(FaceData::is_degenerate) {
            return Err(degenerate_error(mesh, face));
        }
        Ok(Self::assemble(mesh, &data, areas))
    }

    /// Like [`Operators::new`], but degenerate faces contribute zero to `L`
    /// and `G` (see the module docs) and are listed in
    /// [`Operators::degenerate_faces`].
    pub fn new_lenient(mesh: &TriMesh) -> Self {
        let (data, areas) = face_data_and_areas(mesh);
        Self::assemble(mesh, &data, areas)
    }

    fn assemble(mesh: &TriMesh, data: &[FaceData], face_areas: Vec<f64>) -> Self {
        let (assembled, (face_areas_interleaved, face_gradients)) = rayon::join(
            || assemble(mesh, data, &face_areas, Want::ALL),
            || {
                rayon::join(
                    || interleave(&face_areas),
                    || {
                        data.par_iter()
                            .with_min_len(FACE_CHUNK)
                            .map(FaceData::gradient_rows)
                            .collect()
                    },
                )
            },
        );
        let degenerate_faces = data
            .par_iter()
            .with_min_len(FACE_CHUNK)
            .enumerate()
            .filter(|(_, d)| d.is_degenerate())
            .map(|(f, _)| f)
            .collect();
        let Assembled {
            laplacian,
            gradient,
            mass,
        } = assembled;
        Self {
            laplacian: laplacian.unwrap_or_else(|| unreachable_operator("L")),
            mass: mass.unwrap_or_else(|| unreachable_operator("M")),
            face_areas,
            face_areas_interleaved,
            gradient: gradient.unwrap_or_else(|| unreachable_operator("G")),
            face_gradients,
            degenerate_faces,
        }
    }
}

/// Face areas `A` (length `F`), from the edge lengths by a stable Heron formula.
///
/// Cost: `O(F)`, parallel.
pub fn face_areas(mesh: &TriMesh) -> Vec<f64> {
    let pos = mesh.positions();
    mesh.faces()
        .par_iter()
        .with_min_len(FACE_CHUNK)
        .map(|t| face_area(pos, t).0)
        .collect()
}

/// Face areas interleaved twice, `A2 = [A0, A0, A1, A1, ...]` (length `2F`),
/// the row weights of [`intrinsic_gradient`].
///
/// Cost: `O(F)`, parallel.
pub fn face_areas_interleaved(mesh: &TriMesh) -> Vec<f64> {
    interleave(&face_areas(mesh))
}

/// Lumped barycentric mass: for each vertex, a third of the total area of the
/// faces using it (zero for unreferenced vertices). Sums to the surface area.
///
/// Cost: `O(V + F)`, parallel.
///
/// # Example
/// ```
/// use mfm_geometry::{operators, procedural};
/// let mesh = procedural::icosphere(2);
/// let m = operators::lumped_mass(&mesh);
/// assert!((m.iter().sum::<f64>() - mesh.total_area()).abs() < 1e-12);
/// ```
pub fn lumped_mass(mesh: &TriMesh) -> Vec<f64> {
    mass_from_areas(mesh, &face_areas(mesh))
}

/// Cotangent Laplacian `L` (`V x V`), positive semi-definite:
/// `L_ij = -(cot a_ij + cot b_ij) / 2`, `L_ii = -sum_j L_ij`
/// (libigl's `cotmatrix` is `-L`). Degenerate faces contribute zero.
///
/// Cost: `O(V + F)`, parallel.
///
/// # Example
/// ```
/// use mfm_geometry::{operators, procedural};
/// let mesh = procedural::icosphere(2);
/// let l = operators::cotangent_laplacian(&mesh);
/// // constants are in the kernel: every column sums to zero
/// let cp = l.symbolic().col_ptr();
/// for j in 0..l.ncols() {
///     let s: f64 = l.val()[cp[j]..cp[j + 1]].iter().sum();
///     assert!(s.abs() < 1e-12);
/// }
/// ```
pub fn cotangent_laplacian(mesh: &TriMesh) -> SparseColMat<usize, f64> {
    let want = Want {
        laplacian: true,
        ..Want::NONE
    };
    assemble(mesh, &face_data(mesh), &[], want)
        .laplacian
        .unwrap_or_else(|| unreachable_operator("L"))
}

/// Intrinsic gradient `G` (`2F x V`): rows `2f`, `2f + 1` are the gradient
/// of a piecewise-linear function on face `f` in the face frame defined in the
/// [module docs](self). Degenerate faces have zero rows.
///
/// Cost: `O(V + F)`, parallel.
///
/// # Example
/// ```
/// use mfm_geometry::{operators, TriMesh};
/// // one right triangle in the xy plane; u = x has gradient (1, 0) along
/// // the first edge (the frame's x axis)
/// let mesh = TriMesh::new(
///     vec![[0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
///     vec![[0, 1, 2]],
/// ).unwrap();
/// let g = operators::intrinsic_gradient(&mesh);
/// let u = [0.0, 2.0, 0.0];
/// let mut gu = [0.0; 2];
/// let cp = g.symbolic().col_ptr();
/// for v in 0..3 {
///     for k in cp[v]..cp[v + 1] {
///         gu[g.symbolic().row_idx()[k]] += g.val()[k] * u[v];
///     }
/// }
/// assert!((gu[0] - 1.0).abs() < 1e-15 && gu[1].abs() < 1e-15);
/// ```
pub fn intrinsic_gradient(mesh: &TriMesh) -> SparseColMat<usize, f64> {
    let want = Want {
        gradient: true,
        ..Want::NONE
    };
    assemble(mesh, &face_data(mesh), &[], want)
        .gradient
        .unwrap_or_else(|| unreachable_operator("G"))
}

/// Indices of the degenerate faces (see the module docs), sorted.
///
/// Cost: `O(F)`, parallel.
pub fn degenerate_faces(mesh: &TriMesh) -> Vec<usize> {
    let pos = mesh.positions();
    mesh.faces()
        .par_iter()
        .with_min_len(FACE_CHUNK)
        .enumerate()
        .filter(|(_, t)| face_area(pos, t).1)
        .map(|(f, _)| f)
        .collect()
}

/// `Gamma = ||M^-1 L||_F = sqrt(sum_ij (L_ij / m_i)^2)` for a Laplacian `l`
/// and the diagonal `mass` of `M`.
///
/// Rows that are entirely zero are skipped whatever their mass (unreferenced
/// vertices). A vertex with a non-zero row and a non-positive mass makes the
/// result infinite; use [`try_gamma`] to get an error instead. The sum is taken
/// in a fixed order, so the result does not depend on the number of threads.
///
/// Cost: `O(nnz(L))`, parallel.
///
/// # Panics
/// If `mass.len()` differs from the size of `l` or `l` is not square (a
/// programming error; [`try_gamma`] reports it as an error).
///
/// # Example
/// ```
/// use mfm_geometry::{operators, procedural};
/// let mesh = procedural::icosphere(2);
/// let (l, m) = (operators::cotangent_laplacian(&mesh), operators::lumped_mass(&mesh));
/// let big = mesh.transformed(10.0, [0.0; 3]);
/// let (lb, mb) = (operators::cotangent_laplacian(&big), operators::lumped_mass(&big));
/// // Gamma scales like 1 / k^2
/// let ratio = operators::gamma(&l, &m) / operators::gamma(&lb, &mb);
/// assert!((ratio - 100.0).abs() < 1e-9);
/// ```
pub fn gamma(l: &SparseColMat<usize, f64>, mass: &[f64]) -> f64 {
    match try_gamma(l, mass) {
        Ok(g) => g,
        Err(OperatorError::NonPositiveMass { .. }) => f64::INFINITY,
        Err(e) => panic!("gamma: {e}"),
    }
}

/// Checked [`gamma`].
///
/// # Errors
/// [`OperatorError::NotSquare`], [`OperatorError::MassLength`], or
/// [`OperatorError::NonPositiveMass`] for the first vertex (in column order)
/// with a non-zero Laplacian entry and a mass that is not positive.
pub fn try_gamma(l: &SparseColMat<usize, f64>, mass: &[f64]) -> Result<f64, OperatorError> {
    let (rows, cols) = (l.nrows(), l.ncols());
    if rows != cols {
        return Err(OperatorError::NotSquare { rows, cols });
    }
    if mass.len() != rows {
        return Err(OperatorError::MassLength {
            expected: rows,
            found: mass.len(),
        });
    }
    let col_ptr = l.symbolic().col_ptr();
    let row_idx = l.symbolic().row_idx();
    let val = l.val();
    let partial: Vec<Result<f64, OperatorError>> = block_ranges(cols, VBLOCK)
        .into_par_iter()
        .map(|range| {
            let mut sum = 0.0;
            for j in range {
                for k in col_ptr[j]..col_ptr[j + 1] {
                    let (i, v) = (row_idx[k], val[k]);
                    if v == 0.0 {
                        continue;
                    }
                    let m = mass[i];
                    if m.is_nan() || m <= 0.0 {
                        return Err(OperatorError::NonPositiveMass { vertex: i, mass: m });
                    }
                    let r = v / m;
                    sum += r * r;
                }
            }
            Ok(sum)
        })
        .collect();
    let mut total = 0.0;
    for p in partial {
        total += p?;
    }
    Ok(total.sqrt())
}

mod assembly;

use assembly::{Assembled, VBLOCK, Want, assemble, block_ranges, mass_from_areas};

// ---------------------------------------------------------------------------
// Per-face data
// ---------------------------------------------------------------------------

/// Faces per parallel task of the per-face passes.
const FACE_CHUNK: usize = 4096;

/// What the assembly of `L` and `G` needs from one face, computed from its
/// edge lengths (the area is kept apart). 32 bytes, aligned so that a face
/// never straddles two cache lines.
#[derive(Clone, Copy, Debug, Default)]
#[repr(align(32))]
struct FaceData {
    /// Half the cotangent of the angle at each corner: the weight this face
    /// gives the opposite edge (zero when degenerate).
    half_cot: [f64; 3],
    /// `1 / l2`, the inverse length of the edge from corner 0 to corner 1;
    /// zero exactly when the face is degenerate.
    inv_l2: f64,
}

impl FaceData {
    fn is_degenerate(&self) -> bool {
        self.inv_l2 == 0.0
    }

    /// The data and the area of face `t`.
    #[inline]
    fn of(pos: &[[f64; 3]], t: &[u32; 3]) -> (Self, f64) {
        let p = [pos[t[0] as usize], pos[t[1] as usize], pos[t[2] as usize]];
        data_from_squared_lengths(squared_edge_lengths(&p))
    }

    /// `[gx, gy]` of the hat functions of corners 0 and 1, and `gy` of corner 2
    /// (whose `gx` is zero), in the frame of the module docs.
    #[inline]
    fn gradients(&self) -> ([f64; 2], [f64; 2], f64) {
        let gy0 = -2.0 * self.half_cot[1] * self.inv_l2;
        let gy1 = -2.0 * self.half_cot[0] * self.inv_l2;
        // minus the other two, so G 1 = 0 up to one rounding per row
        ([-self.inv_l2, gy0], [self.inv_l2, gy1], -(gy0 + gy1))
    }

    /// The face's two rows of `G` by corner (see [`Operators::face_gradients`]).
    #[inline]
    fn gradient_rows(&self) -> FaceGradient {
        let ([gx0, gy0], [gx1, gy1], gy2) = self.gradients();
        [[gx0, gx1, 0.0], [gy0, gy1, gy2]]
    }
}

#[inline]
fn squared_edge_lengths(p: &[[f64; 3]; 3]) -> [f64; 3] {
    let d2 = |a: [f64; 3], b: [f64; 3]| {
        let (x, y, z) = (a[0] - b[0], a[1] - b[1], a[2] - b[2]);
        x * x + y * y + z * z
    };
    [d2(p[1], p[2]), d2(p[2], p[0]), d2(p[0], p[1])]
}

/// Area from edge lengths by Kahan's rearrangement of Heron's formula, which
/// stays accurate for needle-like triangles.
#[inline]
fn heron_area(l: [f64; 3]) -> f64 {
    // sort so that a >= b >= c (branch-free selections, exact)
    let (x, y, z) = (l[0], l[1], l[2]);
    let a = x.max(y).max(z);
    let c = x.min(y).min(z);
    let b = x.min(y).max(x.max(y).min(z));
    let p = (a + (b + c)) * (c - (a - b)) * (c + (a - b)) * (a + (b - c));
    if p > 0.0 { 0.25 * p.sqrt() } else { 0.0 }
}

/// Area from squared edge lengths, and whether the face is degenerate (see
/// the module docs): `2 A <= eps * l_max^2`, or not finite.
#[inline]
fn area_from_squared_lengths(sq: [f64; 3]) -> (f64, bool) {
    let area = heron_area([sq[0].sqrt(), sq[1].sqrt(), sq[2].sqrt()]);
    let longest = sq[0].max(sq[1]).max(sq[2]);
    // false for NaN too (overflowing coordinates)
    let resolved = 2.0 * area > f64::EPSILON * longest;
    let degenerate = !resolved || !area.is_finite() || !longest.is_finite();
    (area, degenerate)
}

/// Per-face data and area from squared edge lengths `[l0^2, l1^2, l2^2]`
/// (a degenerate face keeps its area, made finite, and gets zero data).
#[inline]
fn data_from_squared_lengths(sq: [f64; 3]) -> (FaceData, f64) {
    let (area, degenerate) = area_from_squared_lengths(sq);
    if degenerate {
        let area = if area.is_finite() { area } else { 0.0 };
        return (FaceData::default(), area);
    }
    let s = 0.125 / area;
    let data = FaceData {
        half_cot: [
            (sq[1] + sq[2] - sq[0]) * s,
            (sq[2] + sq[0] - sq[1]) * s,
            (sq[0] + sq[1] - sq[2]) * s,
        ],
        inv_l2: 1.0 / sq[2].sqrt(),
    };
    (data, area)
}

/// Whether the operators treat the face with corners `p` as degenerate
/// (zero data): its area is not resolved in `f64` from its squared edge
/// lengths (collinear up to round-off, or coordinates so small the squares
/// underflow), or not finite. [`crate::validate::MeshReport`] reports the
/// faces this holds for that are not degenerate in shape as
/// [`crate::validate::MeshProblem::OutOfRange`], so that a report names
/// every face the operators cannot use.
pub fn degenerate_for_operators(p: &[[f64; 3]; 3]) -> bool {
    area_from_squared_lengths(squared_edge_lengths(p)).1
}

/// The area of face `t` (finite) and whether it is degenerate.
#[inline]
fn face_area(pos: &[[f64; 3]], t: &[u32; 3]) -> (f64, bool) {
    let p = [pos[t[0] as usize], pos[t[1] as usize], pos[t[2] as usize]];
    let (area, degenerate) = area_from_squared_lengths(squared_edge_lengths(&p));
    (if area.is_finite() { area } else { 0.0 }, degenerate)
}

/// Per-face data of every face, in parallel.
fn face_data(mesh: &TriMesh) -> Vec<FaceData> {
    let pos = mesh.positions();
    mesh.faces()
        .par_iter()
        .with_min_len(FACE_CHUNK)
        .map(|t| FaceData::of(pos, t).0)
        .collect()
}

/// Per-face data and areas of every face, in parallel.
fn face_data_and_areas(mesh: &TriMesh) -> (Vec<FaceData>, Vec<f64>) {
    let pos = mesh.positions();
    mesh.faces()
        .par_iter()
        .with_min_len(FACE_CHUNK)
        .map(|t| FaceData::of(pos, t))
        .unzip()
}

fn interleave(a: &[f64]) -> Vec<f64> {
    a.par_iter()
        .with_min_len(FACE_CHUNK)
        .flat_map_iter(|&x| [x, x])
        .collect()
}

fn degenerate_error(mesh: &TriMesh, face: usize) -> OperatorError {
    let sq = squared_edge_lengths(&mesh.face_positions(face));
    let edge_lengths = [sq[0].sqrt(), sq[1].sqrt(), sq[2].sqrt()];
    OperatorError::DegenerateFace {
        face,
        vertices: mesh.faces()[face],
        area: heron_area(edge_lengths),
        edge_lengths,
    }
}

#[cold]
fn unreachable_operator(name: &str) -> ! {
    unreachable!("the assembly was asked for {name} and always builds it")
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tri(p: [[f64; 3]; 3]) -> TriMesh {
        TriMesh::new(p.to_vec(), vec![[0, 1, 2]]).expect("valid triangle")
    }

    #[test]
    fn heron_is_accurate_on_a_needle() {
        // a needle given by its lengths; the exact area of the triangle with
        // these (binary) lengths was computed in rational arithmetic. The
        // textbook formula sqrt(s(s-a)(s-b)(s-c)) is off by 3e-6 here.
        let l = [1.0, 0.7, 0.300_000_000_01];
        let exact = 1.024_692_274_891_228_2e-6;
        for perm in [[0, 1, 2], [1, 2, 0], [2, 0, 1], [1, 0, 2]] {
            let area = heron_area([l[perm[0]], l[perm[1]], l[perm[2]]]);
            assert!(
                (area - exact).abs() < 4.0 * f64::EPSILON * exact,
                "{area} vs {exact}"
            );
        }
        let s = 0.5 * (l[0] + l[1] + l[2]);
        let naive = (s * (s - l[0]) * (s - l[1]) * (s - l[2])).sqrt();
        assert!((naive - exact).abs() > 1e-7 * exact);
    }

    #[test]
    fn lengths_that_round_to_collinear_are_degenerate() {
        // height 1e-9 on a unit base: the edge lengths round to 1, 1/2, 1/2
        let p = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.5, 1e-9, 0.0]];
        assert!(area_from_squared_lengths(squared_edge_lengths(&p)).1);
        // height 1e-5 is resolved
        let p = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.5, 1e-5, 0.0]];
        let (g, area) = data_from_squared_lengths(squared_edge_lengths(&p));
        assert!(g.inv_l2 > 0.0 && !area_from_squared_lengths(squared_edge_lengths(&p)).1);
        assert!((area - 0.5e-5).abs() < 1e-6 * 0.5e-5, "{area}");
    }

    #[test]
    fn right_triangle_cotangents() {
        // right angle at corner 0, 45 degrees at corners 1 and 2
        let (g, area) = data_from_squared_lengths(squared_edge_lengths(&[
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
        ]));
        assert!((area - 0.5).abs() < 1e-15);
        assert!(g.half_cot[0].abs() < 1e-15);
        assert!((g.half_cot[1] - 0.5).abs() < 1e-15 && (g.half_cot[2] - 0.5).abs() < 1e-15);
        assert!((g.inv_l2 - 1.0).abs() < 1e-15);
    }

    #[test]
    fn degenerate_faces_are_reported_or_zeroed() {
        let mesh = tri([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]]);
        match Operators::new(&mesh) {
            Err(OperatorError::DegenerateFace { face, vertices, .. }) => {
                assert_eq!((face, vertices), (0, [0, 1, 2]));
            }
            other => panic!("expected a degenerate-face error, got {other:?}"),
        }
        let ops = Operators::new_lenient(&mesh);
        assert_eq!(ops.degenerate_faces, vec![0]);
        assert!(ops.laplacian.val().iter().all(|&x| x == 0.0));
        assert!(ops.gradient.val().iter().all(|&x| x == 0.0));
        assert_eq!(degenerate_faces(&mesh), vec![0]);
        // repeated positions
        let mesh = tri([[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 1.0, 0.0]]);
        assert!(Operators::new(&mesh).is_err());
        assert!(
            cotangent_laplacian(&mesh)
                .val()
                .iter()
                .all(|x| x.is_finite())
        );
        // coordinates whose squares overflow
        let mesh = tri([[0.0, 0.0, 0.0], [1e200, 0.0, 0.0], [0.0, 1e200, 0.0]]);
        assert!(Operators::new(&mesh).is_err());
        let ops = Operators::new_lenient(&mesh);
        assert!(ops.laplacian.val().iter().all(|x| x.is_finite()));
        assert!(ops.mass.iter().all(|x| x.is_finite()));
    }

    #[test]
    fn unreferenced_vertices_have_empty_columns() {
        let mesh = TriMesh::new(
            vec![
                [9.0, 9.0, 9.0],
                [0.0, 0.0, 0.0],
                [1.0, 0.0, 0.0],
                [0.0, 1.0, 0.0],
            ],
            vec![[1, 2, 3]],
        )
        .expect("valid mesh");
        let ops = Operators::new(&mesh).expect("no degenerate face");
        let cp = ops.laplacian.symbolic().col_ptr();
        assert_eq!(cp[1] - cp[0], 0);
        assert_eq!(cp[2] - cp[1], 3);
        assert_eq!(ops.mass[0], 0.0);
        assert_eq!(ops.gradient.symbolic().col_ptr()[1], 0);
        // the empty row is skipped by gamma
        assert!(gamma(&ops.laplacian, &ops.mass).is_finite());
    }

    #[test]
    fn gamma_errors() {
        let mesh = tri([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]);
        let ops = Operators::new(&mesh).expect("valid");
        assert_eq!(
            try_gamma(&ops.laplacian, &[1.0]),
            Err(OperatorError::MassLength {
                expected: 3,
                found: 1
            })
        );
        assert_eq!(
            try_gamma(&ops.laplacian, &[1.0, 0.0, 1.0]),
            Err(OperatorError::NonPositiveMass {
                vertex: 1,
                mass: 0.0
            })
        );
        assert_eq!(gamma(&ops.laplacian, &[1.0, 0.0, 1.0]), f64::INFINITY);
        // one triangle with unit masses: Gamma^2 is the sum of squared entries
        let ones = [1.0; 3];
        let fro: f64 = ops
            .laplacian
            .val()
            .iter()
            .map(|x| x * x)
            .sum::<f64>()
            .sqrt();
        assert!((gamma(&ops.laplacian, &ones) - fro).abs() < 1e-15);
    }
}
