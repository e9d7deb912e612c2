//! Helpers shared by the integration tests of mfm-deform.
#![allow(dead_code, clippy::unwrap_used)]

use mfm_deform::{DeformSpace, HandleSet, normalize_rest};
use mfm_geometry::{TriMesh, procedural};

/// The procedural blob at `level`, normalized to a unit bounding-box diagonal.
pub fn unit_blob(level: u32) -> TriMesh {
    normalize_rest(&procedural::blob(level).unwrap()).unwrap().0
}

/// A space with 3 moving handles of radius 0.1 on `mesh`.
pub fn space_on(mesh: &TriMesh) -> DeformSpace {
    DeformSpace::new(mesh, HandleSet::auto(mesh, 3, 0.1).unwrap())
}

/// Largest coordinate difference between two shapes.
pub fn max_diff(a: &[[f64; 3]], b: &[[f64; 3]]) -> f64 {
    assert_eq!(a.len(), b.len());
    a.iter()
        .zip(b)
        .flat_map(|(p, q)| (0..3).map(move |k| (p[k] - q[k]).abs()))
        .fold(0.0, f64::max)
}

/// Mass-weighted mean squared distance between two shapes of `mesh`.
pub fn mass_mse(mesh: &TriMesh, a: &[[f64; 3]], b: &[[f64; 3]]) -> f64 {
    let m = mfm_geometry::operators::lumped_mass(mesh);
    let total: f64 = m.iter().sum();
    a.iter()
        .zip(b)
        .zip(&m)
        .map(|((p, q), w)| w * (0..3).map(|k| (p[k] - q[k]).powi(2)).sum::<f64>())
        .sum::<f64>()
        / total
}

/// A smooth vector field in space: each component `amplitude * sin(w . p + phase)`
/// with wave vectors of length about `2 pi * 3` (three waves per unit length).
pub fn smooth_noise(p: [f64; 3], amplitude: f64) -> [f64; 3] {
    let waves = [
        ([11.0, -9.0, 7.0], 0.3),
        ([-8.0, 13.0, 5.0], 1.7),
        ([6.0, 7.0, -14.0], 2.9),
    ];
    let mut out = [0.0; 3];
    for (k, (w, phase)) in waves.iter().enumerate() {
        out[k] = amplitude * (w[0] * p[0] + w[1] * p[1] + w[2] * p[2] + phase).sin();
    }
    out
}
