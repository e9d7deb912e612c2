//! Sparse Cholesky cache: residuals, symbolic reuse, f32 path, thread safety,
//! error reporting.

mod common;

use std::sync::Arc;

use faer::sparse::{SparseColMat, Triplet};
use faer::{Mat, MatRef};
use mfm_solver::{CholeskyFactor, FactorOptions, SolverError, SymbolicAnalysis};
use proptest::prelude::*;
use rayon::prelude::*;

/// Symmetric sparse matrix from (row, col, value) entries of the lower
/// triangle, mirrored to a full symmetric matrix.
fn symmetric(n: usize, lower: &[(usize, usize, f64)]) -> SparseColMat<usize, f64> {
    let mut t = Vec::new();
    for &(i, j, v) in lower {
        t.push(Triplet::new(i, j, v));
        if i != j {
            t.push(Triplet::new(j, i, v));
        }
    }
    SparseColMat::try_new_from_triplets(n, n, &t).expect("valid triplets")
}

/// `L + tau diag(m)` assembled from triplets (independently of the
/// solver's own assembly).
fn screened(l: &SparseColMat<usize, f64>, m: &[f64], tau: f64) -> SparseColMat<usize, f64> {
    let n = l.nrows();
    let mut t: Vec<_> = l
        .triplet_iter()
        .map(|e| Triplet::new(e.row, e.col, *e.val))
        .collect();
    t.extend(
        m.iter()
            .enumerate()
            .map(|(i, &mi)| Triplet::new(i, i, tau * mi)),
    );
    SparseColMat::try_new_from_triplets(n, n, &t).expect("valid triplets")
}

/// Relative residual `||A X - B||_F / ||B||_F` (full symmetric `A`).
fn rel_residual(a: &SparseColMat<usize, f64>, x: MatRef<'_, f64>, b: MatRef<'_, f64>) -> f64 {
    let ax = a * x;
    (&ax - b).norm_l2() / b.norm_l2()
}

/// A random SPD matrix: a weighted graph Laplacian on random edges plus a
/// positive diagonal, given by proptest-chosen edges/weights.
fn spd_from(n: usize, edges: &[(usize, usize, f64)], diag: &[f64]) -> SparseColMat<usize, f64> {
    let mut lower = Vec::new();
    let mut d = diag.iter().map(|x| x + 1e-3).collect::<Vec<_>>();
    for &(a, b, w) in edges {
        let (a, b) = (a % n, b % n);
        if a == b {
            continue;
        }
        let (i, j) = if a > b { (a, b) } else { (b, a) };
        lower.push((i, j, -w));
        d[i] += w;
        d[j] += w;
    }
    for (i, &di) in d.iter().enumerate() {
        lower.push((i, i, di));
    }
    symmetric(n, &lower)
}

fn rhs(n: usize, k: usize, seed: u64) -> Mat<f64> {
    let mut s = seed
        .wrapping_mul(6364136223846793005)
        .wrapping_add(1442695040888963407);
    Mat::from_fn(n, k, |_, _| {
        s = s
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (s >> 11) as f64 / (1u64 << 53) as f64 - 0.5
    })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]
    #[test]
    fn solves_random_spd_systems(
        n in 1usize..60,
        edges in prop::collection::vec((0usize..60, 0usize..60, 0.01f64..10.0), 0..200),
        diag in prop::collection::vec(0.0f64..2.0, 60),
        k in 1usize..70,
        seed in any::<u64>(),
    ) {
        let a = spd_from(n, &edges, &diag[..n]);
        let factor = CholeskyFactor::new(a.as_ref()).expect("SPD by construction");
        let b = rhs(n, k, seed);
        let x = factor.solve_many(b.as_ref()).expect("valid block");
        prop_assert!(rel_residual(&a, x.as_ref(), b.as_ref()) < 1e-10);
        // one column alone gives exactly the same bits as inside the block
        let j = seed as usize % k;
        let xj = factor.solve(b.col(j).try_as_col_major().expect("contiguous").as_slice()).expect("valid rhs");
        for i in 0..n {
            prop_assert_eq!(xj[i].to_bits(), x[(i, j)].to_bits());
        }
    }

    #[test]
    fn symbolic_reuse_matches_fresh_factorization(
        n in 2usize..50,
        edges in prop::collection::vec((0usize..50, 0usize..50, 0.01f64..10.0), 1..150),
        diag1 in prop::collection::vec(0.0f64..2.0, 50),
        diag2 in prop::collection::vec(0.0f64..2.0, 50),
        scale in 0.1f64..10.0,
    ) {
        let a1 = spd_from(n, &edges, &diag1[..n]);
        let scaled: Vec<_> = edges.iter().map(|&(a, b, w)| (a, b, w * scale)).collect();
        let a2 = spd_from(n, &scaled, &diag2[..n]);
        let f1 = CholeskyFactor::new(a1.as_ref()).expect("SPD");
        let reused = f1.refactor(a2.as_ref()).expect("same pattern");
        prop_assert!(Arc::ptr_eq(f1.symbolic(), reused.symbolic()));
        let fresh = CholeskyFactor::new(a2.as_ref()).expect("SPD");
        let b = rhs(n, 3, 7);
        let x_reused = reused.solve_many(b.as_ref()).expect("solve");
        let x_fresh = fresh.solve_many(b.as_ref()).expect("solve");
        prop_assert!((&x_reused - &x_fresh).norm_l2() <= 1e-12 * x_fresh.norm_l2());
        prop_assert!(rel_residual(&a2, x_reused.as_ref(), b.as_ref()) < 1e-10);
    }
}

#[test]
fn factor_and_analysis_are_send_and_sync() {
    fn check<T: Send + Sync>() {}
    check::<SymbolicAnalysis>();
    check::<CholeskyFactor<f64>>();
    check::<CholeskyFactor<f32>>();
    check::<mfm_solver::ScreenedPoisson>();
    check::<mfm_solver::LaplacianSolver>();
}

#[test]
fn parallel_solves_from_many_threads_are_bit_identical_to_serial() {
    let (l, m) = common::torus_operators(2000);
    let n = l.nrows();
    let a = screened(&l, &m, 10.0);
    let factor = Arc::new(CholeskyFactor::new(a.as_ref()).expect("SPD"));
    let blocks: Vec<Mat<f64>> = (0..8).map(|s| rhs(n, 5 + 9 * s, s as u64)).collect();
    let serial: Vec<Mat<f64>> = blocks
        .iter()
        .map(|b| factor.solve_many(b.as_ref()).expect("solve"))
        .collect();
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(4)
        .build()
        .expect("pool");
    let parallel: Vec<Mat<f64>> = pool.install(|| {
        blocks
            .par_iter()
            .map(|b| factor.solve_many(b.as_ref()).expect("solve"))
            .collect()
    });
    // plain OS threads sharing the factor too
    let threaded: Vec<Mat<f64>> = std::thread::scope(|s| {
        let handles: Vec<_> = blocks
            .iter()
            .map(|b| {
                let f = Arc::clone(&factor);
                s.spawn(move || f.solve_many(b.as_ref()).expect("solve"))
            })
            .collect();
        handles
            .into_iter()
            .map(|h| h.join().expect("thread"))
            .collect()
    });
    for ((s, p), t) in serial.iter().zip(&parallel).zip(&threaded) {
        for j in 0..s.ncols() {
            for i in 0..n {
                assert_eq!(s[(i, j)].to_bits(), p[(i, j)].to_bits());
                assert_eq!(s[(i, j)].to_bits(), t[(i, j)].to_bits());
            }
        }
    }
    // and the residuals are right
    for (b, x) in blocks.iter().zip(&serial) {
        assert!(rel_residual(&a, x.as_ref(), b.as_ref()) < 1e-10);
    }
}

#[test]
fn f32_factor_solves_to_single_precision_accuracy() {
    let (l, m) = common::torus_operators(3000);
    let sp = mfm_solver::ScreenedPoisson::new(&l, &m, 100.0).expect("SPD");
    let n = l.nrows();
    let b = rhs(n, 40, 3);
    let x64 = sp.solve_many(b.as_ref()).expect("solve");
    let b32 = Mat::<f32>::from_fn(n, 40, |i, j| b[(i, j)] as f32);
    let x32 = sp.solve_many_f32(b32.as_ref()).expect("solve");
    let diff = Mat::<f64>::from_fn(n, 40, |i, j| x32[(i, j)] as f64 - x64[(i, j)]);
    let rel = diff.norm_l2() / x64.norm_l2();
    assert!(rel < 1e-5, "f32 relative error {rel:e}");
    // it is a genuinely different (rounded) computation, not the f64 result
    assert!(rel > 1e-12, "f32 path suspiciously exact: {rel:e}");
}

#[test]
fn non_positive_definite_names_the_failing_column() {
    let n = 12;
    let mut lower: Vec<_> = (0..n).map(|i| (i, i, 2.0 + i as f64)).collect();
    lower[7].2 = -1.0;
    let a = symmetric(n, &lower);
    match CholeskyFactor::new(a.as_ref()) {
        Err(SolverError::NotPositiveDefinite {
            column, diagonal, ..
        }) => {
            assert_eq!(column, 7);
            assert_eq!(diagonal, -1.0);
        }
        other => panic!("expected NotPositiveDefinite, got {other:?}"),
    }
    // coupled case: [[1, 2], [2, 1]] is indefinite; the failing pivot is 1 - 4 = -3
    let a = symmetric(2, &[(0, 0, 1.0), (1, 1, 1.0), (1, 0, 2.0)]);
    let err = CholeskyFactor::new(a.as_ref()).expect_err("indefinite");
    assert!(
        matches!(err, SolverError::NotPositiveDefinite { .. }),
        "{err:?}"
    );
    assert!(err.to_string().contains("not positive definite"), "{err}");
}

#[test]
fn numerically_singular_matrix_is_rejected_by_the_pivot_tolerance() {
    // a closed-mesh Laplacian is PSD with the constant vector in its kernel
    let (l, _) = common::torus_operators(800);
    let err = CholeskyFactor::new(l.as_ref()).expect_err("singular");
    assert!(
        matches!(err, SolverError::NotPositiveDefinite { .. }),
        "{err:?}"
    );
    // the same matrix with a tiny shift factors fine
    let n = l.nrows();
    let mut t: Vec<_> = l
        .triplet_iter()
        .map(|e| Triplet::new(e.row, e.col, *e.val))
        .collect();
    t.extend((0..n).map(|i| Triplet::new(i, i, 1e-8)));
    let shifted = SparseColMat::<usize, f64>::try_new_from_triplets(n, n, &t).expect("valid");
    assert!(CholeskyFactor::new(shifted.as_ref()).is_ok());
    // and with a zero tolerance the unshifted one is accepted or fails on a
    // non-positive pivot, but never panics
    let opts = FactorOptions {
        pivot_tolerance: 0.0,
        ..FactorOptions::default()
    };
    let _ = CholeskyFactor::with_options(l.as_ref(), &opts);
}

#[test]
fn invalid_inputs_are_reported_with_their_position() {
    let rect = SparseColMat::<usize, f64>::try_new_from_triplets(3, 4, &[Triplet::new(0, 0, 1.0)])
        .expect("valid");
    assert_eq!(
        CholeskyFactor::new(rect.as_ref()).expect_err("must fail"),
        SolverError::NotSquare { nrows: 3, ncols: 4 }
    );

    let nan = symmetric(
        3,
        &[(0, 0, 1.0), (1, 1, 1.0), (2, 2, 1.0), (2, 1, f64::NAN)],
    );
    match CholeskyFactor::new(nan.as_ref()) {
        Err(SolverError::NonFinite { row, col, .. }) => {
            assert!((row, col) == (2, 1) || (row, col) == (1, 2))
        }
        other => panic!("expected NonFinite, got {other:?}"),
    }

    let a = symmetric(3, &[(0, 0, 2.0), (1, 1, 2.0), (2, 2, 2.0), (1, 0, -1.0)]);
    let f = CholeskyFactor::new(a.as_ref()).expect("SPD");
    assert_eq!(
        f.solve(&[1.0, 2.0]).expect_err("must fail"),
        SolverError::SizeMismatch {
            what: "right-hand side",
            expected: 3,
            found: 2
        }
    );
    match f.solve(&[1.0, f64::INFINITY, 0.0]) {
        Err(SolverError::NonFinite { row: 1, col: 0, .. }) => {}
        other => panic!("expected NonFinite at row 1, got {other:?}"),
    }
    // an entry outside the analysed pattern
    let b = symmetric(3, &[(0, 0, 2.0), (1, 1, 2.0), (2, 2, 2.0), (2, 0, -1.0)]);
    assert_eq!(
        f.refactor(b.as_ref()).expect_err("must fail"),
        SolverError::PatternMismatch { row: 2, col: 0 }
    );
    // a smaller pattern is fine (missing entries are zeros)
    let c = symmetric(3, &[(0, 0, 2.0), (1, 1, 2.0), (2, 2, 2.0)]);
    let fc = f.refactor(c.as_ref()).expect("subset pattern");
    let x = fc.solve(&[2.0, 4.0, 6.0]).expect("solve");
    for (xi, ei) in x.iter().zip([1.0, 2.0, 3.0]) {
        assert!((xi - ei).abs() < 1e-15 * ei, "{x:?}");
    }
}

#[test]
fn only_the_lower_triangle_is_read() {
    // full symmetric vs lower-only storage of the same matrix
    let lower = [
        (0, 0, 4.0),
        (1, 1, 5.0),
        (2, 2, 6.0),
        (1, 0, 1.0),
        (2, 1, -2.0),
    ];
    let full = symmetric(3, &lower);
    let t: Vec<_> = lower
        .iter()
        .map(|&(i, j, v)| Triplet::new(i, j, v))
        .collect();
    let lower_only = SparseColMat::<usize, f64>::try_new_from_triplets(3, 3, &t).expect("valid");
    // garbage in the upper triangle is ignored
    let mut tg = t.clone();
    tg.push(Triplet::new(0, 2, 1e6));
    let garbage = SparseColMat::<usize, f64>::try_new_from_triplets(3, 3, &tg).expect("valid");
    let b = [1.0, -2.0, 0.5];
    let x1 = CholeskyFactor::new(full.as_ref())
        .expect("SPD")
        .solve(&b)
        .expect("solve");
    let x2 = CholeskyFactor::new(lower_only.as_ref())
        .expect("SPD")
        .solve(&b)
        .expect("solve");
    let x3 = CholeskyFactor::new(garbage.as_ref())
        .expect("SPD")
        .solve(&b)
        .expect("solve");
    assert_eq!(x1, x2);
    assert_eq!(x1, x3);
    let r = rel_residual(
        &full,
        MatRef::from_column_major_slice(&x1, 3, 1),
        MatRef::from_column_major_slice(&b, 3, 1),
    );
    assert!(r < 1e-14);
}

#[test]
fn factor_and_solves_do_not_depend_on_the_thread_count() {
    // big enough for faer's parallel dense kernels to split the work
    let (l, m) = common::torus_operators(12_000);
    let n = l.nrows();
    let b = rhs(n, 70, 11);
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .expect("pool");
        pool.install(|| {
            let sp = mfm_solver::ScreenedPoisson::new(&l, &m, 100.0).expect("SPD");
            sp.solve_many(b.as_ref()).expect("solve")
        })
    };
    let one = run(1);
    for threads in [2, 3] {
        let x = run(threads);
        for j in 0..b.ncols() {
            for i in 0..n {
                assert_eq!(
                    one[(i, j)].to_bits(),
                    x[(i, j)].to_bits(),
                    "threads {threads}, entry ({i}, {j})"
                );
            }
        }
    }
}

#[test]
fn parallel_factorization_matches_the_sequential_one_bit_for_bit() {
    // faer's parallel dense kernels split work by output blocks only: the
    // factor is the same with any number of threads, and equal to the
    // sequential one
    let (l, m) = common::torus_operators(12_000);
    let n = l.nrows();
    let a = screened(&l, &m, 100.0);
    let b = rhs(n, 8, 5);
    let run = |threads: usize, parallel: bool| {
        let opts = FactorOptions {
            parallel,
            ..FactorOptions::default()
        };
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .expect("pool");
        pool.install(|| {
            CholeskyFactor::with_options(a.as_ref(), &opts)
                .expect("SPD")
                .solve_many(b.as_ref())
                .expect("solve")
        })
    };
    let seq = run(1, false);
    for threads in [1, 3] {
        assert_eq!(
            (&run(threads, true) - &seq).norm_max(),
            0.0,
            "{threads} threads"
        );
    }
}

#[test]
fn sequential_solves_of_row_major_blocks_match_the_parallel_solve() {
    let (l, m) = common::torus_operators(900);
    let n = l.nrows();
    let a = screened(&l, &m, 1.0);
    let factor = CholeskyFactor::new(a.as_ref()).expect("SPD");
    // 45 columns: one full chunk of SOLVE_CHUNK and a narrower one
    let b = rhs(n, 45, 7);
    let expected = factor.solve_many(b.as_ref()).expect("solve");
    // the same block stored row-major (a [V, C] signal), solved in place
    let mut rows: Vec<f64> = (0..n)
        .flat_map(|i| (0..45).map(move |j| (i, j)))
        .map(|(i, j)| b[(i, j)])
        .collect();
    let view = faer::MatMut::from_row_major_slice_mut(&mut rows, n, 45);
    factor.solve_in_place_sequential(view).expect("solve");
    for i in 0..n {
        for j in 0..45 {
            assert_eq!(
                rows[i * 45 + j].to_bits(),
                expected[(i, j)].to_bits(),
                "({i}, {j})"
            );
        }
    }
    // a column-major block through the same entry point
    let mut cm = b.clone();
    factor
        .solve_in_place_sequential(cm.as_mut())
        .expect("solve");
    assert!((&cm - &expected).norm_max() == 0.0);
    // a non-finite entry is reported at its row and column, nothing is written
    let mut bad: Vec<f64> = (0..n * 45).map(|i| i as f64).collect();
    bad[10 * 45 + 33] = f64::NAN;
    let before = bad.clone();
    let err = factor
        .solve_in_place_sequential(faer::MatMut::from_row_major_slice_mut(&mut bad, n, 45))
        .expect_err("NaN");
    assert!(
        matches!(
            err,
            SolverError::NonFinite {
                row: 10,
                col: 33,
                ..
            }
        ),
        "{err:?}"
    );
    assert!(
        bad.iter()
            .zip(&before)
            .all(|(x, y)| x.to_bits() == y.to_bits())
    );
}
