//! Meshes and helpers shared by the integration tests of mfm-noise.
#![allow(dead_code, clippy::unwrap_used)]

use mfm_geometry::operators::Operators;
use mfm_geometry::{TriMesh, procedural, test_support};
use mfm_solver::{EigenOptions, Eigenpairs, generalized_eigenpairs};

/// A smooth, asymmetric closed surface: the icosphere with `level`
/// subdivisions, pushed radially by a few low-frequency bumps so that the
/// Laplacian has no symmetry-forced repeated eigenvalues. Deterministic.
/// Unlike `procedural::blob` (relaxed to a uniform triangulation), the
/// displacement stretches some triangles more than others; the tests'
/// thresholds were set on this surface.
pub fn blob(level: u32) -> TriMesh {
    let sphere = procedural::icosphere(level);
    let positions = sphere
        .positions()
        .iter()
        .map(|&[x, y, z]| {
            let r = 1.0
                + 0.22 * (2.0 * x + 0.7).sin() * (1.5 * y).cos()
                + 0.12 * (3.0 * z - 0.4).sin()
                + 0.08 * x * y;
            [1.3 * r * x, r * y, 0.8 * r * z]
        })
        .collect();
    sphere.with_positions(positions).unwrap()
}

/// The shared Stanford bunny (3485 vertices), or `None` (with a printed skip
/// reason) when the shared meshes are not there.
pub fn bunny() -> Option<TriMesh> {
    test_support::shared_mesh("bunny.off").map(|p| mfm_meshio::read_mesh(p).unwrap())
}

/// Lumped mass and the `k` smallest eigenpairs of `mesh`.
pub fn eigen(mesh: &TriMesh, k: usize) -> (Vec<f64>, Eigenpairs) {
    let ops = Operators::new(mesh).unwrap();
    let pairs =
        generalized_eigenpairs(&ops.laplacian, &ops.mass, k, &EigenOptions::default()).unwrap();
    (ops.mass, pairs)
}

/// Largest `|a_i - b_i| / max_j |a_j|`.
pub fn max_rel_diff(a: &[f64], b: &[f64]) -> f64 {
    assert_eq!(a.len(), b.len());
    let scale = a.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    a.iter()
        .zip(b)
        .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()))
        / scale
}
