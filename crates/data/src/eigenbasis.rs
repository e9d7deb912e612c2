//! The canonical mesh's first Laplacian eigenvectors with deterministic
//! signs: the positional encoding that the arbitrary-source model's
//! eigenvector predictor learns to produce on any posed or reshaped variant
//! of the template (the paper's supplementary, "Arbitrary 3D human shapes
//! model").
//!
//! ## Conventions
//! The mesh is first moved into its canonical frame
//! ([`mfm_geometry::frame`]: bounding box centred, largest extent 1), so the
//! basis does not depend on the user's units. The eigenpairs are the `k`
//! smallest of `L phi = lambda M phi` (cotangent Laplacian, lumped mass),
//! ascending, `M`-orthonormal (`Phi^T M Phi = I`) in that frame.
//!
//! An eigenvector is defined up to its sign; the sign is fixed so that its
//! `M`-inner product with the reference function
//! `w(p) = exp(a . p)` ([`SIGN_DIRECTION`] `a`, `p` in the canonical frame)
//! is positive. `w` is positive, smooth and has no symmetry a mesh is likely
//! to share, so the inner product is far from 0 for a smooth eigenvector,
//! and it is a surface integral, which a remeshing of the same surface
//! changes only by its discretization error: the rule gives the same signs
//! on every triangulation (tested on a mesh and its refinement).
//! [`Eigenbasis::margins`] reports `|<phi, w>_M| / |w|_M` per vector: a
//! margin near 0 means the sign is fragile. (The first vector is the
//! constant `1 / sqrt(area)` on a connected mesh, with a positive sign.)
//!
//! Eigenvectors of (nearly) repeated eigenvalues are not determined by the
//! surface at all, whatever the sign rule; meshes with symmetries have them.

use mfm_geometry::TriMesh;
use mfm_geometry::frame::CanonicalFrame;
use mfm_geometry::operators::Operators;
use serde::{Deserialize, Serialize};

use crate::error::{DataError, Result};

/// The direction `a` of the sign rule's reference function
/// `exp(a . p)` (see the [module docs](self)): generic irrational-looking
/// components of length about 2.3.
pub const SIGN_DIRECTION: [f64; 3] = [0.917, 1.373, 1.529];

/// The first `k` eigenpairs of a mesh in its canonical frame, with fixed
/// signs; see the [module docs](self).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Eigenbasis {
    /// Eigenvalues, ascending (canonical frame units).
    pub values: Vec<f64>,
    /// The eigenvectors, vertex-major: `vectors[v * k + i]` is vector `i`
    /// at vertex `v`.
    pub vectors: Vec<f64>,
    /// `k`.
    pub k: usize,
    /// Per vector, `|<phi, w>_M| / |w|_M`: how far the sign rule is from
    /// a tie.
    pub margins: Vec<f64>,
    /// The frame the basis was computed in.
    pub frame: CanonicalFrame,
}

impl Eigenbasis {
    /// Computes the basis of `mesh` (see the [module docs](self)).
    ///
    /// Cost: the operators, then [`mfm_solver::generalized_eigenpairs`]
    /// (dense up to 1000 vertices, shift-invert Krylov above).
    ///
    /// # Errors
    /// [`DataError::Config`] for `k == 0` or `k > V`; geometry and solver
    /// errors (a degenerate mesh, no convergence).
    pub fn of(mesh: &TriMesh, k: usize) -> Result<Self> {
        if k == 0 || k > mesh.num_vertices() {
            return Err(DataError::Config(format!(
                "an eigenbasis of {k} vectors on a mesh of {} vertices: expected 1..={}",
                mesh.num_vertices(),
                mesh.num_vertices()
            )));
        }
        let frame = CanonicalFrame::of(mesh)
            .map_err(|e| DataError::Config(format!("the mesh has no canonical frame: {e}")))?;
        let canonical = frame.apply(mesh);
        let ops = Operators::new(&canonical)
            .map_err(|e| DataError::Config(format!("operators of the canonical mesh: {e}")))?;
        let pairs = mfm_noise::spectrum::eigenpairs(&ops.laplacian, &ops.mass, k)?;
        let n = mesh.num_vertices();
        let w: Vec<f64> = canonical
            .positions()
            .iter()
            .map(|p| {
                (SIGN_DIRECTION[0] * p[0] + SIGN_DIRECTION[1] * p[1] + SIGN_DIRECTION[2] * p[2])
                    .exp()
            })
            .collect();
        let w_norm = w
            .iter()
            .zip(&ops.mass)
            .map(|(x, m)| m * x * x)
            .sum::<f64>()
            .sqrt();
        let mut vectors = vec![0.0; n * k];
        let mut margins = Vec::with_capacity(k);
        for i in 0..k {
            let col = pairs.vectors.col(i);
            let inner: f64 = (0..n).map(|v| ops.mass[v] * col[v] * w[v]).sum();
            let sign = if inner < 0.0 { -1.0 } else { 1.0 };
            margins.push(inner.abs() / w_norm);
            for v in 0..n {
                vectors[v * k + i] = sign * col[v];
            }
        }
        Ok(Self {
            values: pairs.values,
            vectors,
            k,
            margins,
            frame,
        })
    }

    /// Vector `i` as one value per vertex.
    ///
    /// # Panics
    /// If `i >= k`.
    pub fn vector(&self, i: usize) -> Vec<f64> {
        assert!(i < self.k, "eigenvector {i} of {}", self.k);
        self.vectors
            .iter()
            .skip(i)
            .step_by(self.k)
            .copied()
            .collect()
    }

    /// The vectors as `f32`, vertex-major (`[V, k]`), the network's layout.
    pub fn to_f32(&self) -> Vec<f32> {
        self.vectors.iter().map(|&x| x as f32).collect()
    }
}

/// The mass-weighted relative error of predicted vectors against a basis,
/// per vector: `|p_i - phi_i|_M / |phi_i|_M` with `M` the lumped mass of
/// `mesh` in its canonical frame (`phi_i` has norm 1 there). `predicted` is
/// vertex-major `[V, k]` like [`Eigenbasis::vectors`].
///
/// # Errors
/// [`DataError::SizeMismatch`] when the sizes do not fit.
pub fn relative_errors(mesh: &TriMesh, basis: &Eigenbasis, predicted: &[f32]) -> Result<Vec<f64>> {
    let (n, k) = (mesh.num_vertices(), basis.k);
    if predicted.len() != n * k || basis.vectors.len() != n * k {
        return Err(DataError::SizeMismatch {
            what: "predicted eigenvectors (vertices x vectors)".into(),
            expected: n * k,
            found: predicted.len(),
        });
    }
    let mass = mfm_geometry::operators::lumped_mass(&basis.frame.apply(mesh));
    Ok((0..k)
        .map(|i| {
            let (mut num, mut den) = (0.0, 0.0);
            for v in 0..n {
                let t = basis.vectors[v * k + i];
                let d = f64::from(predicted[v * k + i]) - t;
                num += mass[v] * d * d;
                den += mass[v] * t * t;
            }
            (num / den.max(f64::MIN_POSITIVE)).sqrt()
        })
        .collect())
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use mfm_geometry::procedural;
    use mfm_geometry::subdivide::midpoint;

    /// An ellipsoid-like blob with distinct axes, so its low spectrum has
    /// no repeated eigenvalues.
    fn lumpy() -> TriMesh {
        let m = procedural::blob(3).unwrap();
        let p: Vec<[f64; 3]> = m
            .positions()
            .iter()
            .map(|p| [1.6 * p[0], 1.0 * p[1] + 0.1 * p[0] * p[0], 0.7 * p[2]])
            .collect();
        m.with_positions(p).unwrap()
    }

    #[test]
    fn vectors_are_mass_orthonormal_in_the_canonical_frame() {
        let mesh = lumpy();
        let basis = Eigenbasis::of(&mesh, 10).unwrap();
        let mass = mfm_geometry::operators::lumped_mass(&basis.frame.apply(&mesh));
        for i in 0..10 {
            for j in 0..10 {
                let (a, b) = (basis.vector(i), basis.vector(j));
                let ip: f64 = (0..a.len()).map(|v| mass[v] * a[v] * b[v]).sum();
                let want = if i == j { 1.0 } else { 0.0 };
                assert!((ip - want).abs() < 1e-8, "<{i},{j}> = {ip}");
            }
        }
        assert!(basis.values.windows(2).all(|w| w[0] <= w[1]));
        assert!(basis.values[0].abs() < 1e-8);
        // the constant vector has a positive sign
        assert!(basis.vector(0).iter().all(|&x| x > 0.0));
        // the same mesh in other units gives the same basis
        let scaled = mesh
            .with_positions(
                mesh.positions()
                    .iter()
                    .map(|p| p.map(|x| 37.0 * x + 2.0))
                    .collect(),
            )
            .unwrap();
        let again = Eigenbasis::of(&scaled, 10).unwrap();
        let diff = again
            .vectors
            .iter()
            .zip(&basis.vectors)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        assert!(diff < 1e-6, "{diff}");
        assert!(Eigenbasis::of(&mesh, 0).is_err());
    }

    /// The signs are stable under remeshing: the basis of a midpoint
    /// subdivision (a finer triangulation of the same surface), read at the
    /// coarse vertices, matches the coarse basis in sign for every vector of
    /// a simple eigenvalue, and in value to 5% (mass-weighted) for the first
    /// eight.
    #[test]
    fn signs_agree_between_a_mesh_and_its_refinement() {
        let coarse = lumpy();
        let fine = midpoint(&coarse).unwrap();
        let k = 12;
        let a = Eigenbasis::of(&coarse, k).unwrap();
        let b = Eigenbasis::of(&fine, k).unwrap();
        let n = coarse.num_vertices();
        let mass = mfm_geometry::operators::lumped_mass(&a.frame.apply(&coarse));
        for i in 1..k {
            let gap = [i - 1, i + 1]
                .iter()
                .filter(|&&j| j < k)
                .map(|&j| (a.values[j] - a.values[i]).abs() / a.values[i])
                .fold(f64::INFINITY, f64::min);
            if gap < 0.05 {
                continue; // nearly repeated: not determined by the surface
            }
            let (x, y) = (a.vector(i), b.vector(i));
            let ip: f64 = (0..n).map(|v| mass[v] * x[v] * y[v]).sum();
            assert!(
                ip > 0.0,
                "vector {i}: inner product {ip}, margin {}",
                a.margins[i]
            );
            if i < 8 {
                let err: f64 = (0..n).map(|v| mass[v] * (x[v] - y[v]).powi(2)).sum();
                assert!(err.sqrt() < 0.05, "vector {i}: error {}", err.sqrt());
            }
        }
        // a smooth reference function meets high frequencies weakly: the
        // margins fall from ~1 (the constant) to ~1e-3 by the 12th vector,
        // still well above the inner products' change under refinement
        assert!(a.margins.iter().all(|&m| m > 1e-4), "{:?}", a.margins);
    }

    #[test]
    fn relative_errors_are_zero_for_the_basis_and_one_for_zeros() {
        let mesh = lumpy();
        let basis = Eigenbasis::of(&mesh, 4).unwrap();
        let exact = relative_errors(&mesh, &basis, &basis.to_f32()).unwrap();
        assert!(exact.iter().all(|&e| e < 1e-6), "{exact:?}");
        let zeros = vec![0.0f32; basis.vectors.len()];
        let e = relative_errors(&mesh, &basis, &zeros).unwrap();
        assert!(e.iter().all(|&x| (x - 1.0).abs() < 1e-12));
        assert!(relative_errors(&mesh, &basis, &zeros[1..]).is_err());
    }
}
