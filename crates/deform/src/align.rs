//! Putting shapes in a common frame: normalizing a rest mesh, aligning a
//! deformed shape to its rest shape about the up axis, and full rigid
//! alignment.
//!
//! ## Why Procrustes to the rest shape, not PCA
//! The paper removes the global rotation about the up axis (e.g. with PCA)
//! and centers each shape. Principal axes are only defined up to sign (and
//! swap places when two variances cross), so a PCA frame can flip by 180
//! degrees between two similar poses, which would put nearby poses far
//! apart in the dataset. Here every shape is rotated about the up axis by
//! the angle that best matches it to the **rest** shape (a closed-form 1-D
//! weighted Procrustes problem): the answer is unique whenever the shape is
//! not rotationally symmetric about the up axis, varies continuously with
//! the pose, and is the identity for the rest shape itself.
//!
//! Weights are the lumped mass of the rest mesh, so the result does not
//! depend on how densely a part of the surface is triangulated.
//!
//! # Example
//! ```
//! use mfm_deform::{align_to_rest, normalize_rest};
//! use mfm_deform::rigid::axis_angle_to_matrix;
//! use mfm_geometry::procedural;
//!
//! let (rest, scale, shift) = normalize_rest(&procedural::blob(2).unwrap()).unwrap();
//! assert!((rest.bounding_box_diagonal() - 1.0).abs() < 1e-12);
//! assert!(scale > 0.0 && shift.iter().all(|s| s.is_finite()));
//! // turn the rest shape about y and move it: alignment undoes both
//! let r = axis_angle_to_matrix([0.0, 0.7, 0.0]);
//! let moved: Vec<[f64; 3]> = rest.positions().iter().map(|p| {
//!     let q = mfm_deform::rigid::mat_vec(&r, *p);
//!     [q[0] + 1.0, q[1] - 2.0, q[2] + 0.5]
//! }).collect();
//! let aligned = align_to_rest(&rest, &moved, 1).unwrap();
//! for (a, p) in aligned.iter().zip(rest.positions()) {
//!     assert!((0..3).all(|k| (a[k] - p[k]).abs() < 1e-12));
//! }
//! ```

use mfm_geometry::{TriMesh, operators};

use crate::error::{DeformError, Result};
use crate::rigid::{axis_angle_to_matrix, fit_rigid, mat_vec, weighted_centroid};

/// Centers `mesh` at its area centroid (mass-weighted vertex centroid with
/// the lumped mass, which equals the area-weighted centroid of the faces)
/// and scales it to a unit bounding-box diagonal.
///
/// Returns the normalized mesh and the map `p -> scale * p + shift` that
/// produced it; apply the **same** map to another triangulation of the
/// surface (e.g. a decimated copy) with
/// [`TriMesh::transformed`]`(scale, shift)` so that both stay in one frame.
///
/// # Errors
/// [`DeformError::ZeroMass`] for a mesh with zero area;
/// [`DeformError::InvalidParameter`] for a zero bounding box.
pub fn normalize_rest(mesh: &TriMesh) -> Result<(TriMesh, f64, [f64; 3])> {
    let mass = operators::lumped_mass(mesh);
    let total: f64 = mass.iter().sum();
    if !(total.is_finite() && total > 0.0) {
        return Err(DeformError::ZeroMass {
            what: "mesh to normalize",
            mass: total,
        });
    }
    let diagonal = mesh.bounding_box_diagonal();
    if !(diagonal.is_finite() && diagonal > 0.0) {
        return Err(DeformError::InvalidParameter {
            name: "bounding-box diagonal",
            expected: "a finite diagonal > 0",
            found: diagonal.to_string(),
        });
    }
    let centroid = weighted_centroid(mesh.positions(), &mass);
    let scale = 1.0 / diagonal;
    let shift = [
        -scale * centroid[0],
        -scale * centroid[1],
        -scale * centroid[2],
    ];
    Ok((mesh.transformed(scale, shift), scale, shift))
}

/// Checks lengths and the total rest mass; returns the mass.
fn rest_mass(rest: &TriMesh, positions: &[[f64; 3]]) -> Result<Vec<f64>> {
    check_shape(rest.num_vertices(), positions)?;
    let mass = operators::lumped_mass(rest);
    let total: f64 = mass.iter().sum();
    if !(total.is_finite() && total > 0.0) {
        return Err(DeformError::ZeroMass {
            what: "rest mesh",
            mass: total,
        });
    }
    Ok(mass)
}

/// Checks that `positions` has `n` finite points.
pub(crate) fn check_shape(n: usize, positions: &[[f64; 3]]) -> Result<()> {
    if positions.len() != n {
        return Err(DeformError::SizeMismatch {
            what: "shape positions",
            expected: n,
            found: positions.len(),
        });
    }
    if let Some((index, value)) = positions
        .iter()
        .enumerate()
        .find(|(_, p)| !p.iter().all(|c| c.is_finite()))
    {
        return Err(DeformError::NonFinite {
            what: "shape positions",
            index,
            value: *value,
        });
    }
    Ok(())
}

/// Aligns a shape (new positions for the vertices of `rest`) to `rest`:
/// translates it so its mass-weighted centroid is the rest's, then rotates
/// it about the axis `up` (0 = x, 1 = y, 2 = z) through that centroid by
/// the angle minimizing `sum_v m_v |R shape_v - rest_v|^2` (both centered;
/// `m` the lumped mass of `rest`). See the [module docs](self) for why.
///
/// The angle is `atan2(S, C)` with, in the plane `(a, b)` orthogonal to
/// `up` (`a = up + 1`, `b = up + 2`, cyclically), `C = sum m (p_a q_a + p_b q_b)`
/// and `S = sum m (p_b q_a - p_a q_b)` (`q` the centered shape, `p` the
/// centered rest). Cost: `O(V)`.
///
/// # Errors
/// [`DeformError::InvalidParameter`] for `up > 2`,
/// [`DeformError::SizeMismatch`], [`DeformError::NonFinite`],
/// [`DeformError::ZeroMass`].
pub fn align_to_rest(rest: &TriMesh, positions: &[[f64; 3]], up: usize) -> Result<Vec<[f64; 3]>> {
    if up > 2 {
        return Err(DeformError::InvalidParameter {
            name: "up",
            expected: "an axis index 0, 1 or 2 (x, y, z)",
            found: up.to_string(),
        });
    }
    let mass = rest_mass(rest, positions)?;
    let cr = weighted_centroid(rest.positions(), &mass);
    let cs = weighted_centroid(positions, &mass);
    let (a, b) = ((up + 1) % 3, (up + 2) % 3);
    let (mut c, mut s) = (0.0, 0.0);
    for ((q, p), &m) in positions.iter().zip(rest.positions()).zip(&mass) {
        let (qa, qb) = (q[a] - cs[a], q[b] - cs[b]);
        let (pa, pb) = (p[a] - cr[a], p[b] - cr[b]);
        c += m * (pa * qa + pb * qb);
        s += m * (pb * qa - pa * qb);
    }
    let mut axis = [0.0; 3];
    axis[up] = s.atan2(c);
    let r = axis_angle_to_matrix(axis);
    Ok(positions
        .iter()
        .map(|q| {
            let v = mat_vec(&r, [q[0] - cs[0], q[1] - cs[1], q[2] - cs[2]]);
            [v[0] + cr[0], v[1] + cr[1], v[2] + cr[2]]
        })
        .collect())
}

/// Moves `positions` by the rigid motion (rotation and translation) that
/// best matches them to `target`, weighted by the lumped mass of `rest`
/// (mass-weighted Kabsch, [`crate::rigid::fit_rigid`]). Cost: `O(V)`.
///
/// # Errors
/// [`DeformError::SizeMismatch`], [`DeformError::NonFinite`],
/// [`DeformError::ZeroMass`].
pub fn align_rigid(
    rest: &TriMesh,
    positions: &[[f64; 3]],
    target: &[[f64; 3]],
) -> Result<Vec<[f64; 3]>> {
    let mass = rest_mass(rest, positions)?;
    rest_mass(rest, target)?;
    let fit = fit_rigid(positions, target, &mass).ok_or(DeformError::ZeroMass {
        what: "rest mesh",
        mass: 0.0,
    })?;
    Ok(positions.iter().map(|p| fit.apply(*p)).collect())
}
