//! The projection (plausibility) metric: dataset shapes project onto
//! themselves, perturbed ones do not.
#![allow(clippy::unwrap_used)]

mod common;

use common::{mass_mse, max_diff, smooth_noise, space_on, unit_blob};
use mfm_deform::rigid::{axis_angle_to_matrix, mat_vec};
use mfm_deform::{Arap, DeformError, HandleSet, project};
use mfm_geometry::subdivide;

#[test]
fn dataset_shapes_project_onto_themselves() {
    let mesh = unit_blob(3);
    let space = space_on(&mesh);
    let diag2 = space.diagonal * space.diagonal;
    let arap = Arap::new(&mesh, &space.handles).unwrap();
    for shape in space.generate(&mesh, 11, 0..3, |_| {}).unwrap() {
        let p = project(&arap, &space, &shape.positions).unwrap();
        eprintln!("self-projection mse / diag^2 = {:e}", p.mse / diag2);
        assert!(p.mse < 1e-6 * diag2, "mse {:e}", p.mse);
        // the fitted parameters are the stored ones
        for (fit, truth) in p.params.handles.iter().zip(&shape.params.handles) {
            for k in 0..3 {
                assert!((fit.rotation[k] - truth.rotation[k]).abs() < 1e-8);
                assert!((fit.translation[k] - truth.translation[k]).abs() < 1e-8);
            }
        }
        // a rigid motion of the shape does not change the metric
        let r = axis_angle_to_matrix([0.3, -2.0, 0.9]);
        let moved: Vec<[f64; 3]> = shape
            .positions
            .iter()
            .map(|x| {
                let y = mat_vec(&r, *x);
                [y[0] + 5.0, y[1], y[2] - 1.0]
            })
            .collect();
        let q = project(&arap, &space, &moved).unwrap();
        assert!(q.mse < 1e-6 * diag2, "moved: mse {:e}", q.mse);
    }
}

#[test]
fn perturbed_shapes_do_not_project_onto_themselves() {
    // smooth noise of amplitude 1% of the diagonal on the free vertices
    let mesh = unit_blob(3);
    let space = space_on(&mesh);
    let diag = space.diagonal;
    let arap = Arap::new(&mesh, &space.handles).unwrap();
    let mut constrained = vec![false; mesh.num_vertices()];
    for region in arap.regions() {
        for &v in region {
            constrained[v] = true;
        }
    }
    for shape in space.generate(&mesh, 12, 0..3, |_| {}).unwrap() {
        let clean = project(&arap, &space, &shape.positions).unwrap().mse;
        let noisy: Vec<[f64; 3]> = shape
            .positions
            .iter()
            .zip(mesh.positions())
            .zip(&constrained)
            .map(|((x, p), &c)| {
                if c {
                    *x
                } else {
                    let n = smooth_noise(*p, 0.01 * diag);
                    [x[0] + n[0], x[1] + n[1], x[2] + n[2]]
                }
            })
            .collect();
        let noise_energy = mass_mse(&mesh, &noisy, &shape.positions);
        let p = project(&arap, &space, &noisy).unwrap();
        eprintln!(
            "perturbed: mse / diag^2 = {:e} (noise {:e}, clean {:e})",
            p.mse / (diag * diag),
            noise_energy / (diag * diag),
            clean / (diag * diag)
        );
        // the handles did not move, so the projection is (nearly) the clean
        // shape and the metric sees (nearly) all of the noise
        assert!(p.mse > 0.5 * noise_energy);
        assert!(p.mse > 30.0 * 1e-6 * diag * diag);
        assert!(p.mse > 1e6 * clean.max(1e-30));
    }
}

#[test]
fn shapes_stored_in_single_precision_still_project_onto_themselves() {
    // datasets store f32: the fitted parameters move by ~1e-7 relatively,
    // which may change the ARAP iteration count, so the projection is only
    // as close as the ARAP stopping rule; still far below a perturbation
    let mesh = unit_blob(3);
    let space = space_on(&mesh);
    let arap = Arap::new(&mesh, &space.handles).unwrap();
    for shape in space.generate(&mesh, 13, 0..3, |_| {}).unwrap() {
        let rounded: Vec<[f64; 3]> = shape
            .positions
            .iter()
            .map(|p| p.map(|x| f64::from(x as f32)))
            .collect();
        let p = project(&arap, &space, &rounded).unwrap();
        eprintln!(
            "f32 shape: mse / diag^2 = {:e}",
            p.mse / (space.diagonal * space.diagonal)
        );
        assert!(
            p.mse < 1e-6 * space.diagonal * space.diagonal,
            "{:e}",
            p.mse
        );
    }
}

#[test]
fn projection_works_on_another_triangulation() {
    // the space made on the coarse mesh, its handles reused on the refinement
    let mesh = unit_blob(2);
    let space = space_on(&mesh);
    let fine = subdivide::midpoint(&mesh).unwrap();
    let arap = Arap::new(&fine, &space.handles).unwrap();
    let shapes = space.generate(&fine, 4, 0..2, |_| {}).unwrap();
    for s in &shapes {
        let p = project(&arap, &space, &s.positions).unwrap();
        assert!(p.mse < 1e-6 * space.diagonal * space.diagonal);
        assert!(max_diff(&p.positions, &s.positions) < 1e-6);
    }
}

#[test]
fn projection_errors() {
    let mesh = unit_blob(2);
    let space = space_on(&mesh);
    let other = HandleSet::auto(&mesh, 2, 0.1).unwrap();
    let arap = Arap::new(&mesh, &other).unwrap();
    let err = project(&arap, &space, mesh.positions()).unwrap_err();
    assert!(
        matches!(err, DeformError::InvalidParameter { name: "arap", .. }),
        "{err}"
    );
    let arap = Arap::new(&mesh, &space.handles).unwrap();
    assert!(matches!(
        project(&arap, &space, &mesh.positions()[2..]),
        Err(DeformError::SizeMismatch { .. })
    ));
}
