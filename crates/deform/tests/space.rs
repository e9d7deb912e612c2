//! The deformation space: pure, seeded parameters and reproducible,
//! thread-count-independent generation of aligned shapes.
#![allow(clippy::unwrap_used)]

mod common;

use common::{space_on, unit_blob};
use mfm_deform::{DeformSpace, align_to_rest};

#[test]
fn sample_params_is_a_pure_function_of_seed_and_index() {
    let mesh = unit_blob(2);
    let space = space_on(&mesh);
    let a = space.sample_params(9, 17);
    // other draws in between do not matter
    let _ = space.sample_params(9, 16);
    let _ = space.sample_params(10, 17);
    assert_eq!(space.sample_params(9, 17), a);
    assert_ne!(space.sample_params(9, 18), a);
    assert_ne!(space.sample_params(10, 17), a);
    // a copy of the space (e.g. read back from a manifest) draws the same
    let copy: DeformSpace = serde_json::from_str(&serde_json::to_string(&space).unwrap()).unwrap();
    assert_eq!(copy, space);
    assert_eq!(copy.sample_params(9, 17), a);
}

#[test]
fn sample_params_follow_the_stated_distributions() {
    // angle uniform in [0, max_angle]: mean max/2; translation uniform in
    // the ball of radius R: |t|^3 / R^3 is uniform in [0, 1] (mean 1/2) and
    // each coordinate has mean 0 and variance R^2 / 5
    let mesh = unit_blob(2);
    let space = space_on(&mesh);
    let r = space.max_shift * space.diagonal;
    let (mut angle, mut cube, mut var, mut count) = (0.0, 0.0, 0.0, 0.0);
    for i in 0..4000 {
        for h in space.sample_params(1, i).handles {
            let a = h.rotation.iter().map(|x| x * x).sum::<f64>().sqrt();
            let t = h.translation.iter().map(|x| x * x).sum::<f64>().sqrt();
            assert!(a <= space.max_angle + 1e-12 && t <= r + 1e-12);
            angle += a / space.max_angle;
            cube += (t / r).powi(3);
            var += h.translation[1] * h.translation[1] / (r * r);
            count += 1.0;
        }
    }
    let (angle, cube, var) = (angle / count, cube / count, var / count);
    // 12000 draws: standard errors about 0.003
    assert!((angle - 0.5).abs() < 0.015, "{angle}");
    assert!((cube - 0.5).abs() < 0.015, "{cube}");
    assert!((var - 0.2).abs() < 0.01, "{var}");
}

#[test]
fn generation_is_reproducible_and_thread_count_independent() {
    let mesh = unit_blob(2);
    let space = space_on(&mesh);
    let run = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| space.generate(&mesh, 5, 0..4, |_| {}).unwrap())
    };
    let one = run(1);
    let four = run(4);
    assert_eq!(one, four, "1 vs 4 threads differ");
    assert_eq!(run(1), one, "two runs differ");
    // index order, and a sub-range reproduces the same samples
    let tail = space.generate(&mesh, 5, 2..4, |_| {}).unwrap();
    assert_eq!(tail[..], one[2..]);
    for (i, s) in one.iter().enumerate() {
        assert_eq!(s.params, space.sample_params(5, i));
    }
}

#[test]
fn stored_parameters_reproduce_the_stored_shape() {
    let mesh = unit_blob(2);
    let space = space_on(&mesh);
    let shapes = space.generate(&mesh, 21, 0..3, |_| {}).unwrap();
    let arap = mfm_deform::Arap::new(&mesh, &space.handles).unwrap();
    for s in &shapes {
        // through JSON, as a dataset manifest would store them
        let params = serde_json::from_str(&serde_json::to_string(&s.params).unwrap()).unwrap();
        assert_eq!(space.realize(&arap, &params).unwrap(), s.positions);
    }
}

#[test]
fn generated_shapes_are_aligned_to_the_rest_shape() {
    let mesh = unit_blob(2);
    let space = space_on(&mesh);
    let m = mfm_geometry::operators::lumped_mass(&mesh);
    let total: f64 = m.iter().sum();
    for s in space.generate(&mesh, 3, 0..3, |_| {}).unwrap() {
        let c: [f64; 3] = std::array::from_fn(|k| {
            s.positions
                .iter()
                .zip(&m)
                .map(|(p, w)| w * p[k])
                .sum::<f64>()
                / total
        });
        let cr: [f64; 3] = std::array::from_fn(|k| {
            mesh.positions()
                .iter()
                .zip(&m)
                .map(|(p, w)| w * p[k])
                .sum::<f64>()
                / total
        });
        for k in 0..3 {
            assert!((c[k] - cr[k]).abs() < 1e-14, "centroid {c:?} vs {cr:?}");
        }
        // aligning again is a no-op: the up-axis rotation is already optimal
        let again = align_to_rest(&mesh, &s.positions, 1).unwrap();
        assert!(common::max_diff(&again, &s.positions) < 1e-13);
        // and the shape really moved
        assert!(common::max_diff(&s.positions, mesh.positions()) > 0.02);
    }
}

#[test]
fn progress_counts_every_sample_and_bad_ranges_are_errors() {
    let mesh = unit_blob(2);
    let mut space = space_on(&mesh);
    let seen = std::sync::Mutex::new(Vec::new());
    space
        .generate(&mesh, 0, 3..8, |k| seen.lock().unwrap().push(k))
        .unwrap();
    let mut seen = seen.into_inner().unwrap();
    seen.sort_unstable();
    assert_eq!(seen, vec![1, 2, 3, 4, 5]);
    space.max_angle = f64::NAN;
    let err = space.generate(&mesh, 0, 0..1, |_| {}).unwrap_err();
    assert!(err.to_string().contains("max_angle"), "{err}");
}
