//! The local-step rotation and the Kabsch fit against independent oracles:
//! faer's SVD (`R = U diag(1, 1, det(U V^T)) V^T`), brute-force perturbation,
//! and exact recovery of known rigid motions.
#![allow(clippy::unwrap_used)]

use faer::Mat;
use mfm_deform::rigid::{
    Mat3, axis_angle_to_matrix, best_rotation, determinant, fit_rigid, mat_mul, mat_vec, transpose,
};
use proptest::prelude::*;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn frob(a: &Mat3, b: &Mat3) -> f64 {
    (0..3)
        .flat_map(|r| (0..3).map(move |c| (r, c)))
        .map(|(r, c)| a[r][c] * b[r][c])
        .sum()
}

/// The SVD recipe: `K = U S V^T`, `R = U diag(1, 1, d) V^T`, `d = det(U V^T)`.
fn svd_oracle(k: &Mat3) -> (Mat3, [f64; 3]) {
    let m = Mat::<f64>::from_fn(3, 3, |r, c| k[r][c]);
    let svd = m.svd().unwrap();
    let (u, v) = (svd.U(), svd.V());
    let s = svd.S().column_vector();
    let um: Mat3 = std::array::from_fn(|r| std::array::from_fn(|c| u[(r, c)]));
    let vm: Mat3 = std::array::from_fn(|r| std::array::from_fn(|c| v[(r, c)]));
    let d = determinant(&mat_mul(&um, &transpose(&vm))).signum();
    let mut ud = um;
    for row in ud.iter_mut() {
        row[2] *= d;
    }
    (mat_mul(&ud, &transpose(&vm)), [s[0], s[1], s[2]])
}

fn random_k(rng: &mut ChaCha8Rng, kind: usize) -> Mat3 {
    // cross-covariance of a few edge pairs; kind picks the degenerate cases
    let n = match kind {
        0 => 6,
        1 => 6, // planar source vectors (a flat one-ring)
        2 => 4, // with negative weights (obtuse cotangents)
        _ => 3, // reflected target (det K < 0)
    };
    let truth = axis_angle_to_matrix([
        rng.random_range(-2.0..2.0),
        rng.random_range(-2.0..2.0),
        rng.random_range(-2.0..2.0),
    ]);
    let mut k = [[0.0; 3]; 3];
    for _ in 0..n {
        let mut a = [
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
        ];
        if kind == 1 {
            a[2] = 0.0;
        }
        let mut b = mat_vec(&truth, a);
        for x in b.iter_mut() {
            *x += 0.3 * rng.random_range(-1.0..1.0);
        }
        if kind == 3 {
            b[0] = -b[0];
        }
        let w = if kind == 2 {
            rng.random_range(-0.3..1.0)
        } else {
            rng.random_range(0.1..1.0)
        };
        for r in 0..3 {
            for c in 0..3 {
                k[r][c] += w * b[r] * a[c];
            }
        }
    }
    k
}

#[test]
fn best_rotation_matches_the_svd_oracle() {
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let mut compared_matrices = 0;
    for trial in 0..400 {
        let k = random_k(&mut rng, trial % 4);
        let r = best_rotation(&k);
        assert!(
            (determinant(&r) - 1.0).abs() < 1e-12,
            "not a proper rotation"
        );
        let rtr = mat_mul(&transpose(&r), &r);
        for (i, row) in rtr.iter().enumerate() {
            for (j, x) in row.iter().enumerate() {
                assert!((x - f64::from(u8::from(i == j))).abs() < 1e-12);
            }
        }
        let (oracle, s) = svd_oracle(&k);
        let scale = s[0].max(1e-300);
        // same optimal value, whatever the case
        let (got, want) = (frob(&r, &k), frob(&oracle, &k));
        assert!(
            (got - want).abs() <= 1e-12 * scale,
            "trial {trial}: <R,K> = {got}, oracle {want}"
        );
        // and the same matrix when the optimum is well separated
        if s[1] + s[2] > 1e-3 * scale {
            let diff = (0..3)
                .flat_map(|a| (0..3).map(move |b| (a, b)))
                .map(|(a, b)| (r[a][b] - oracle[a][b]).abs())
                .fold(0.0, f64::max);
            assert!(diff < 1e-9, "trial {trial}: rotation differs by {diff}");
            compared_matrices += 1;
        }
    }
    assert!(compared_matrices > 300);
}

#[test]
fn best_rotation_is_a_local_maximum() {
    // brute force: no small rotation applied to R increases <R, K>
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    for trial in 0..50 {
        let k = random_k(&mut rng, trial % 4);
        let r = best_rotation(&k);
        let best = frob(&r, &k);
        for _ in 0..200 {
            let d = axis_angle_to_matrix([
                rng.random_range(-0.05..0.05),
                rng.random_range(-0.05..0.05),
                rng.random_range(-0.05..0.05),
            ]);
            let other = frob(&mat_mul(&d, &r), &k);
            assert!(other <= best + 1e-12 * best.abs().max(1.0), "trial {trial}");
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]
    /// A known random rigid motion is recovered exactly (to round-off) from
    /// weighted correspondences.
    #[test]
    fn kabsch_recovers_a_rigid_motion(
        rot in prop::array::uniform3(-3.0f64..3.0),
        shift in prop::array::uniform3(-10.0f64..10.0),
        seed in 0u64..1000,
    ) {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let src: Vec<[f64; 3]> = (0..20)
            .map(|_| [rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0)])
            .collect();
        let w: Vec<f64> = (0..20).map(|_| rng.random_range(0.01..2.0)).collect();
        let truth = mfm_deform::rigid::RigidTransform {
            rotation: axis_angle_to_matrix(rot),
            translation: shift,
        };
        let dst: Vec<[f64; 3]> = src.iter().map(|&p| truth.apply(p)).collect();
        let fit = fit_rigid(&src, &dst, &w).unwrap();
        for r in 0..3 {
            for c in 0..3 {
                prop_assert!((fit.rotation[r][c] - truth.rotation[r][c]).abs() < 1e-12);
            }
            prop_assert!((fit.translation[r] - truth.translation[r]).abs() < 1e-11);
        }
    }
}

#[test]
fn kabsch_rejects_bad_input() {
    let p = [[0.0; 3], [1.0, 0.0, 0.0]];
    assert!(fit_rigid(&p, &p[..1], &[1.0, 1.0]).is_none());
    assert!(fit_rigid(&p, &p, &[0.0, 0.0]).is_none());
    assert!(fit_rigid(&p, &p, &[1.0]).is_none());
}
