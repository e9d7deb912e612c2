//! Normalization and alignment.
#![allow(clippy::unwrap_used)]

mod common;

use common::{max_diff, unit_blob};
use mfm_deform::rigid::{axis_angle_to_matrix, mat_vec};
use mfm_deform::{DeformError, align_rigid, align_to_rest, normalize_rest};
use mfm_geometry::{procedural, subdivide};

fn moved(points: &[[f64; 3]], rot: [f64; 3], shift: [f64; 3]) -> Vec<[f64; 3]> {
    let r = axis_angle_to_matrix(rot);
    points
        .iter()
        .map(|p| {
            let q = mat_vec(&r, *p);
            [q[0] + shift[0], q[1] + shift[1], q[2] + shift[2]]
        })
        .collect()
}

#[test]
fn align_to_rest_undoes_a_rotation_about_each_up_axis() {
    let rest = unit_blob(2);
    for up in 0..3 {
        for angle in [-2.5, -0.3, 0.8, 3.0] {
            let mut axis = [0.0; 3];
            axis[up] = angle;
            let shape = moved(rest.positions(), axis, [0.4, -1.0, 2.0]);
            let aligned = align_to_rest(&rest, &shape, up).unwrap();
            let err = max_diff(&aligned, rest.positions());
            assert!(err < 1e-12, "up {up}, angle {angle}: {err}");
        }
    }
}

#[test]
fn align_to_rest_angle_is_optimal() {
    // for a shape that is not a rotated copy, the residual grows whichever
    // way the aligned shape is turned further about the up axis
    let rest = unit_blob(2);
    let shape: Vec<[f64; 3]> = moved(rest.positions(), [0.2, 1.1, -0.1], [0.0; 3])
        .into_iter()
        .map(|p| [p[0] * 1.1, p[1], p[2] + 0.1 * p[0]])
        .collect();
    let aligned = align_to_rest(&rest, &shape, 1).unwrap();
    let mse = |s: &[[f64; 3]]| common::mass_mse(&rest, s, rest.positions());
    let best = mse(&aligned);
    // turn about the up axis through the rest centroid (the aligned shape's centroid)
    let m = mfm_geometry::operators::lumped_mass(&rest);
    let total: f64 = m.iter().sum();
    let c: [f64; 3] =
        std::array::from_fn(|k| aligned.iter().zip(&m).map(|(p, w)| w * p[k]).sum::<f64>() / total);
    for d in [-1e-3, 1e-3, -0.1, 0.1] {
        let centered: Vec<[f64; 3]> = aligned
            .iter()
            .map(|p| [p[0] - c[0], p[1] - c[1], p[2] - c[2]])
            .collect();
        let turned = moved(&centered, [0.0, d, 0.0], c);
        assert!(mse(&turned) > best, "turning by {d} improved the fit");
    }
}

#[test]
fn align_rigid_matches_a_rigidly_moved_copy() {
    let rest = unit_blob(2);
    let shape = moved(rest.positions(), [0.7, -0.4, 1.9], [1.0, 2.0, -3.0]);
    let aligned = align_rigid(&rest, rest.positions(), &shape).unwrap();
    assert!(max_diff(&aligned, &shape) < 1e-12);
}

#[test]
fn normalize_rest_gives_a_transform_that_applies_to_other_triangulations() {
    let mesh = procedural::blob(2)
        .unwrap()
        .transformed(3.0, [1.0, -2.0, 0.5]);
    let (unit, scale, shift) = normalize_rest(&mesh).unwrap();
    assert!((unit.bounding_box_diagonal() - 1.0).abs() < 1e-12);
    let m = mfm_geometry::operators::lumped_mass(&unit);
    for k in 0..3 {
        let c: f64 = unit.positions().iter().zip(&m).map(|(p, w)| w * p[k]).sum();
        assert!(c.abs() < 1e-12);
    }
    // a refinement (same surface) normalized by the same map is the
    // refinement of the normalized mesh
    let fine = subdivide::midpoint(&mesh)
        .unwrap()
        .transformed(scale, shift);
    let expected = subdivide::midpoint(&unit).unwrap();
    assert!(max_diff(fine.positions(), expected.positions()) < 1e-12);
}

#[test]
fn alignment_errors() {
    let rest = unit_blob(2);
    assert!(matches!(
        align_to_rest(&rest, rest.positions(), 3),
        Err(DeformError::InvalidParameter { name: "up", .. })
    ));
    assert!(matches!(
        align_to_rest(&rest, &rest.positions()[1..], 1),
        Err(DeformError::SizeMismatch { .. })
    ));
    let mut bad = rest.positions().to_vec();
    bad[7][1] = f64::INFINITY;
    assert!(matches!(
        align_to_rest(&rest, &bad, 1),
        Err(DeformError::NonFinite { index: 7, .. })
    ));
}
