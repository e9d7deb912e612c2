//! Screened Poisson and shifted Laplacian solvers.

mod common;

use faer::Mat;
use faer::sparse::{SparseColMat, Triplet};
use mfm_solver::{LaplacianSolver, ScreenedPoisson, Shift, ShiftOptions, SolverError};
use proptest::prelude::*;

fn rhs(n: usize, k: usize, seed: u64) -> Mat<f64> {
    let mut s = seed.wrapping_mul(0x9e37_79b9_7f4a_7c15).wrapping_add(1);
    Mat::from_fn(n, k, |_, _| {
        s = s
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (s >> 11) as f64 / (1u64 << 53) as f64 - 0.5
    })
}

/// `(L + tau M) X` with `L` full symmetric and `M` diagonal.
fn apply(l: &SparseColMat<usize, f64>, mass: &[f64], tau: f64, x: &Mat<f64>) -> Mat<f64> {
    let lx = l * x;
    Mat::from_fn(x.nrows(), x.ncols(), |i, j| {
        lx[(i, j)] + tau * mass[i] * x[(i, j)]
    })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(12))]
    #[test]
    fn screened_poisson_residual_is_tiny(n in 50usize..1500, log_tau in -3.0f64..4.0, k in 1usize..70, seed in any::<u64>()) {
        let (l, m) = common::torus_operators(n);
        let tau = 10f64.powf(log_tau);
        let sp = ScreenedPoisson::new(&l, &m, tau).expect("SPD");
        let b = rhs(l.nrows(), k, seed);
        let x = sp.solve_many(b.as_ref()).expect("solve");
        let r = (&apply(&l, &m, tau, &x) - &b).norm_l2() / b.norm_l2();
        prop_assert!(r < 1e-10, "relative residual {:e}", r);
    }
}

#[test]
fn constant_rhs_gives_constant_over_tau_on_a_closed_mesh() {
    // L 1 = 0, so (L + tau M) x = tau M c has the solution x = c
    let (l, m) = common::torus_operators(1200);
    let tau = 3.5;
    let sp = ScreenedPoisson::new(&l, &m, tau).expect("SPD");
    let b: Vec<f64> = m.iter().map(|mi| tau * mi * 2.0).collect();
    let x = sp.solve(&b).expect("solve");
    assert!(x.iter().all(|v| (v - 2.0).abs() < 1e-10), "{:?}", &x[..4]);
}

#[test]
fn with_tau_and_shared_symbolic_match_a_fresh_operator() {
    let (l, m) = common::torus_operators(900);
    let sp1 = ScreenedPoisson::new(&l, &m, 1.0).expect("SPD");
    let sp2 = sp1.with_tau(50.0).expect("SPD");
    let sp3 = ScreenedPoisson::with_symbolic(sp1.symbolic(), &l, &m, 50.0).expect("SPD");
    let fresh = ScreenedPoisson::new(&l, &m, 50.0).expect("SPD");
    assert_eq!(sp2.tau(), 50.0);
    let b = rhs(l.nrows(), 4, 1);
    let x1 = sp1.solve_many(b.as_ref()).expect("solve");
    let x2 = sp2.solve_many(b.as_ref()).expect("solve");
    let x3 = sp3.solve_many(b.as_ref()).expect("solve");
    let xf = fresh.solve_many(b.as_ref()).expect("solve");
    // the same ordering and values give the same bits
    assert_eq!((&x2 - &xf).norm_max(), 0.0);
    assert_eq!((&x3 - &xf).norm_max(), 0.0);
    // and tau matters
    assert!((&x1 - &xf).norm_l2() > 1e-3 * xf.norm_l2());
}

#[test]
fn screened_poisson_rejects_bad_inputs() {
    let (l, m) = common::torus_operators(300);
    let n = l.nrows();
    assert_eq!(
        ScreenedPoisson::new(&l, &m[..n - 1], 1.0).expect_err("must fail"),
        SolverError::SizeMismatch {
            what: "mass",
            expected: n,
            found: n - 1
        }
    );
    let mut bad = m.clone();
    bad[17] = 0.0;
    assert_eq!(
        ScreenedPoisson::new(&l, &bad, 1.0).expect_err("must fail"),
        SolverError::NonPositiveMass {
            index: 17,
            value: 0.0
        }
    );
    bad[17] = f64::NAN;
    assert!(matches!(
        ScreenedPoisson::new(&l, &bad, 1.0),
        Err(SolverError::NonFinite {
            what: "mass",
            row: 17,
            ..
        })
    ));
    for tau in [0.0, -1.0, f64::NAN, f64::INFINITY] {
        assert!(matches!(
            ScreenedPoisson::new(&l, &m, tau),
            Err(SolverError::InvalidParameter { name: "tau", .. })
        ));
    }
    let sp = ScreenedPoisson::new(&l, &m, 1.0).expect("SPD");
    assert!(matches!(
        sp.solve(&vec![0.0; n + 1]),
        Err(SolverError::SizeMismatch { .. })
    ));
    let mut b = vec![0.0; n];
    b[3] = f64::NAN;
    assert!(matches!(
        sp.solve(&b),
        Err(SolverError::NonFinite { row: 3, .. })
    ));
    // an indefinite "Laplacian" (negated) fails to factor for small tau
    let neg = SparseColMat::<usize, f64>::try_new_from_triplets(
        n,
        n,
        &l.triplet_iter()
            .map(|e| Triplet::new(e.row, e.col, -*e.val))
            .collect::<Vec<_>>(),
    )
    .expect("valid");
    assert!(matches!(
        ScreenedPoisson::new(&neg, &m, 1e-3),
        Err(SolverError::NotPositiveDefinite { .. })
    ));
}

#[test]
fn laplacian_solver_grows_the_shift_on_a_singular_laplacian() {
    let (l, m) = common::torus_operators(1000);
    let n = l.nrows();
    // eps = 0: the pure Laplacian is singular, the first attempt must fail
    let opts = ShiftOptions {
        initial: Shift::Absolute(0.0),
        ..ShiftOptions::default()
    };
    let ls = LaplacianSolver::with_options(&l, &opts).expect("eventually SPD");
    assert!(ls.attempts() >= 2, "attempts {}", ls.attempts());
    assert!(ls.eps() > 0.0);
    // default: 1e-6 absolute works at once
    let ls = LaplacianSolver::new(&l).expect("SPD");
    assert_eq!((ls.attempts(), ls.eps()), (1, 1e-6));
    // relative shift scales with L
    let opts = ShiftOptions {
        initial: Shift::Relative(1e-6),
        ..ShiftOptions::default()
    };
    let rel = LaplacianSolver::with_options(&l, &opts).expect("SPD");
    let mean_diag = (0..n).map(|i| l[(i, i)]).sum::<f64>() / n as f64;
    assert!((rel.eps() - 1e-6 * mean_diag).abs() < 1e-18);
    // a zero-mean rhs gives a solution of (L + eps I) x = b
    let mut b: Vec<f64> = (0..n).map(|i| ((i * 37) % 11) as f64 - 5.0).collect();
    let mean = b.iter().sum::<f64>() / n as f64;
    b.iter_mut().for_each(|v| *v -= mean);
    let x = ls.solve(&b).expect("solve");
    let xm = Mat::from_fn(n, 1, |i, _| x[i]);
    let lx = &l * &xm;
    let r: f64 = (0..n)
        .map(|i| (lx[(i, 0)] + ls.eps() * x[i] - b[i]).powi(2))
        .sum::<f64>()
        .sqrt();
    let bn: f64 = b.iter().map(|v| v * v).sum::<f64>().sqrt();
    assert!(r / bn < 1e-9, "relative residual {:e}", r / bn);
    let _ = m;
}

#[test]
fn laplacian_solver_with_a_shared_symbolic_analysis_is_the_same_factor() {
    let (l, m) = common::torus_operators(900);
    let screened = ScreenedPoisson::new(&l, &m, 100.0).expect("SPD");
    let opts = ShiftOptions {
        initial: Shift::Absolute(0.0),
        ..ShiftOptions::default()
    };
    let shared = LaplacianSolver::with_symbolic(screened.symbolic(), &l, &opts).expect("SPD");
    let fresh = LaplacianSolver::with_options(&l, &opts).expect("SPD");
    // the analysis is reused, not copied, and the shift search is the same
    assert!(std::sync::Arc::ptr_eq(
        shared.symbolic(),
        screened.symbolic()
    ));
    assert_eq!(
        (shared.eps(), shared.attempts()),
        (fresh.eps(), fresh.attempts())
    );
    let b = rhs(l.nrows(), 3, 5);
    let xs = shared.solve_many(b.as_ref()).expect("solve");
    let xf = fresh.solve_many(b.as_ref()).expect("solve");
    assert_eq!((&xs - &xf).norm_max(), 0.0);
    // another shape of the same connectivity (a posed copy of a mesh): the
    // analysis of the first serves, with the bits of a fresh one
    let (p, f) = common::torus(30, 15, 1.3, 0.5, 0.1);
    let (p0, _) = common::torus(30, 15, 1.0, 0.4, 0.3);
    let (l1, l0) = (
        common::cotan_laplacian(&p, &f),
        common::cotan_laplacian(&p0, &f),
    );
    let first = LaplacianSolver::new(&l0).expect("SPD");
    let posed = LaplacianSolver::with_symbolic(first.symbolic(), &l1, &opts).expect("SPD");
    let alone = LaplacianSolver::with_options(&l1, &opts).expect("SPD");
    let b = rhs(l1.nrows(), 2, 8);
    let xp = posed.solve_many(b.as_ref()).expect("solve");
    let xa = alone.solve_many(b.as_ref()).expect("solve");
    assert_eq!((&xp - &xa).norm_max(), 0.0);
    assert!((&xp - &first.solve_many(b.as_ref()).expect("solve")).norm_l2() > 1e-6 * xa.norm_l2());
    // an analysis of another pattern is refused
    let (other, _) = common::torus_operators(400);
    let foreign = ScreenedPoisson::analyse(&other).expect("square");
    assert!(matches!(
        LaplacianSolver::with_symbolic(&foreign, &l, &opts),
        Err(SolverError::SizeMismatch { .. } | SolverError::PatternMismatch { .. })
    ));
}

#[test]
fn laplacian_solver_reports_exhaustion_with_the_last_shift() {
    // negative definite: no small shift helps
    let n = 10;
    let t: Vec<_> = (0..n).map(|i| Triplet::new(i, i, -1.0)).collect();
    let l = SparseColMat::<usize, f64>::try_new_from_triplets(n, n, &t).expect("valid");
    let opts = ShiftOptions {
        initial: Shift::Absolute(1e-3),
        growth: 10.0,
        max_attempts: 3,
        ..ShiftOptions::default()
    };
    match LaplacianSolver::with_options(&l, &opts) {
        Err(SolverError::ShiftExhausted {
            attempts,
            last_eps,
            last_error,
        }) => {
            assert_eq!(attempts, 3);
            assert!((last_eps - 1e-1).abs() < 1e-15);
            assert!(matches!(
                *last_error,
                SolverError::NotPositiveDefinite { .. }
            ));
        }
        other => panic!("expected ShiftExhausted, got {other:?}"),
    }
    // invalid options
    let bad = ShiftOptions {
        growth: 1.0,
        ..ShiftOptions::default()
    };
    assert!(matches!(
        LaplacianSolver::with_options(&l, &bad),
        Err(SolverError::InvalidParameter { name: "growth", .. })
    ));
    let bad = ShiftOptions {
        initial: Shift::Absolute(-1.0),
        ..ShiftOptions::default()
    };
    assert!(matches!(
        LaplacianSolver::with_options(&l, &bad),
        Err(SolverError::InvalidParameter { name: "eps", .. })
    ));
}

/// `X` of an `f32` block solve, as plain values.
fn f32_block(b: &Mat<f64>) -> Mat<f32> {
    Mat::from_fn(b.nrows(), b.ncols(), |i, j| b[(i, j)] as f32)
}

#[test]
fn releasing_the_f64_factor_keeps_f32_solves_bit_for_bit_and_refuses_f64_ones() {
    let (l, m) = common::torus_operators(700);
    let b = rhs(l.nrows(), 4, 11);
    let b32 = f32_block(&b);

    // the screened operator, its f32 copy made only by the release
    let mut sp = ScreenedPoisson::new(&l, &m, 30.0).expect("SPD");
    let kept = ScreenedPoisson::new(&l, &m, 30.0).expect("SPD");
    let symbolic = std::sync::Arc::clone(sp.symbolic());
    assert!(sp.holds_f64_factor());
    sp.release_f64_factor();
    assert!(!sp.holds_f64_factor());
    let after = sp.solve_many_f32(b32.as_ref()).expect("f32 solve");
    let before = kept.solve_many_f32(b32.as_ref()).expect("f32 solve");
    assert_eq!(after, before);
    assert!(after.norm_l2() > 0.0);
    assert!(std::sync::Arc::ptr_eq(sp.symbolic(), &symbolic));
    assert_eq!(sp.dim(), l.nrows());
    for e in [
        sp.solve(&vec![1.0; l.nrows()]).expect_err("released"),
        sp.solve_many(b.as_ref()).expect_err("released"),
        sp.factor().expect_err("released"),
    ] {
        assert_eq!(e, SolverError::FactorReleased { what: "L + tau M" });
        assert!(e.to_string().contains("only f32 solves remain"), "{e}");
    }
    // another tau on the same analysis still factors
    let other = sp.with_tau(5.0).expect("SPD");
    assert!(other.holds_f64_factor());
    assert!(other.solve_many(b.as_ref()).is_ok());

    // the shifted Laplacian, its f32 copy made before the release
    let mut ls = LaplacianSolver::new(&l).expect("SPD");
    let before = ls.solve_many_f32(b32.as_ref()).expect("f32 solve");
    ls.release_f64_factor();
    ls.release_f64_factor();
    assert!(!ls.holds_f64_factor());
    let mut in_place = b32.clone();
    ls.solve_many_f32_in_place(in_place.as_mut())
        .expect("f32 solve");
    assert_eq!(in_place, before);
    let mut x = b.clone();
    assert_eq!(
        ls.solve_many_in_place(x.as_mut()).expect_err("released"),
        SolverError::FactorReleased { what: "L + eps I" }
    );
    assert_eq!(x, b, "a refused solve leaves its block as it was");
}
