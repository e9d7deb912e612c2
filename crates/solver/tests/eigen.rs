//! Generalized eigenpairs `L phi = lambda M phi`: analytic spectra, dense vs
//! sparse agreement, residuals, M-orthonormality, the scipy oracle on bunny.

mod common;

use faer::Mat;
use faer::sparse::{SparseColMat, Triplet};
use mfm_solver::{EigenMethod, EigenOptions, Eigenpairs, SolverError, generalized_eigenpairs};

fn opts(method: EigenMethod) -> EigenOptions {
    EigenOptions {
        method,
        ..EigenOptions::default()
    }
}

/// Max over pairs of `||L phi - lambda M phi|| / (||L|| ||phi||)`-style
/// relative residual, and `max |Phi^T M Phi - I|`.
fn check_pairs(l: &SparseColMat<usize, f64>, mass: &[f64], p: &Eigenpairs) -> (f64, f64) {
    let n = l.nrows();
    let k = p.values.len();
    let lphi = l * &p.vectors;
    let lnorm = (0..n).map(|i| l[(i, i)] / mass[i]).fold(0.0, f64::max) * 2.0;
    let mut res = 0.0f64;
    for j in 0..k {
        let mut r2 = 0.0;
        let mut p2 = 0.0;
        for i in 0..n {
            let r = lphi[(i, j)] - p.values[j] * mass[i] * p.vectors[(i, j)];
            r2 += r * r / mass[i];
            p2 += mass[i] * p.vectors[(i, j)].powi(2);
        }
        res = res.max(r2.sqrt() / (lnorm * p2.sqrt()));
    }
    let mphi = Mat::from_fn(n, k, |i, j| mass[i] * p.vectors[(i, j)]);
    let gram = p.vectors.transpose() * &mphi;
    let orth = (&gram - Mat::<f64>::identity(k, k)).norm_max();
    (res, orth)
}

#[test]
fn dense_path_matches_the_path_graph_spectrum() {
    // path graph P_n: eigenvalues 2 - 2 cos(pi j / n), j = 0..n-1
    let n = 30;
    let mut t = Vec::new();
    for i in 0..n - 1 {
        t.extend([
            Triplet::new(i, i, 1.0),
            Triplet::new(i + 1, i + 1, 1.0),
            Triplet::new(i, i + 1, -1.0),
            Triplet::new(i + 1, i, -1.0),
        ]);
    }
    let l = SparseColMat::<usize, f64>::try_new_from_triplets(n, n, &t).expect("valid");
    // a mass of 2 everywhere halves the spectrum
    let mass = vec![2.0; n];
    let p = generalized_eigenpairs(&l, &mass, n, &opts(EigenMethod::Dense)).expect("dense");
    assert_eq!(p.info.method, EigenMethod::Dense);
    for (j, v) in p.values.iter().enumerate() {
        let exact = (2.0 - 2.0 * (std::f64::consts::PI * j as f64 / n as f64).cos()) / 2.0;
        assert!((v - exact).abs() < 1e-13, "j {j}: {v} vs {exact}");
    }
    let (res, orth) = check_pairs(&l, &mass, &p);
    assert!(res < 1e-14 && orth < 1e-13, "res {res:e} orth {orth:e}");
    // eigenvector j is cos(pi j (i + 1/2) / n) up to normalization
    for j in [1usize, 5] {
        let c: Vec<f64> = (0..n)
            .map(|i| (std::f64::consts::PI * j as f64 * (i as f64 + 0.5) / n as f64).cos())
            .collect();
        let dot: f64 = (0..n).map(|i| mass[i] * c[i] * p.vectors[(i, j)]).sum();
        let cn: f64 = (0..n).map(|i| mass[i] * c[i] * c[i]).sum::<f64>().sqrt();
        assert!((dot.abs() / cn - 1.0).abs() < 1e-12);
    }
}

#[test]
fn sparse_path_matches_the_flat_torus_spectrum_with_multiplicities() {
    // periodic 40 x 30 grid with mass h^2: closed-form spectrum with
    // multiplicities 2 and 4 (a stress test for the block Krylov method)
    let (nx, ny, h) = (40usize, 30usize, 0.05f64);
    let l = common::periodic_grid_laplacian(nx, ny);
    let mass = vec![h * h; nx * ny];
    let k = 40;
    let p = generalized_eigenpairs(&l, &mass, k, &opts(EigenMethod::Sparse)).expect("sparse");
    assert_eq!(p.info.method, EigenMethod::Sparse);
    let mut exact = Vec::new();
    for a in 0..nx {
        for b in 0..ny {
            let sa = (std::f64::consts::PI * a as f64 / nx as f64).sin();
            let sb = (std::f64::consts::PI * b as f64 / ny as f64).sin();
            exact.push(4.0 / (h * h) * (sa * sa + sb * sb));
        }
    }
    exact.sort_by(f64::total_cmp);
    let scale = exact[1];
    for (j, (v, e)) in p.values.iter().zip(&exact).enumerate() {
        assert!((v - e).abs() <= 1e-11 * e.max(scale), "j {j}: {v} vs {e}");
    }
    let (res, orth) = check_pairs(&l, &mass, &p);
    assert!(res < 1e-9 && orth < 1e-10, "res {res:e} orth {orth:e}");
}

#[test]
fn sparse_and_dense_agree_on_a_small_mesh() {
    let (l, m) = common::torus_operators(900);
    let k = 30;
    let d = generalized_eigenpairs(&l, &m, k, &opts(EigenMethod::Dense)).expect("dense");
    let s = generalized_eigenpairs(&l, &m, k, &opts(EigenMethod::Sparse)).expect("sparse");
    let scale = d.values[1];
    for j in 0..k {
        assert!(
            (d.values[j] - s.values[j]).abs() <= 1e-10 * d.values[j].max(scale),
            "j {j}"
        );
    }
    // ascending, first ~0 with a constant eigenvector (closed mesh)
    assert!(s.values.windows(2).all(|w| w[0] <= w[1]));
    assert!(s.values[0].abs() < 1e-10 * scale);
    let area: f64 = m.iter().sum();
    for i in 0..l.nrows() {
        assert!(
            (s.vectors[(i, 0)] - 1.0 / area.sqrt()).abs() < 1e-8,
            "constant eigenvector"
        );
    }
    for p in [&d, &s] {
        let (res, orth) = check_pairs(&l, &m, p);
        assert!(res < 1e-10 && orth < 1e-10, "res {res:e} orth {orth:e}");
    }
    // the jittered torus has simple eigenvalues here: eigenvectors agree up to
    // sign, and the sign convention makes them agree exactly
    for j in 1..k {
        let gap = (d.values[j] - d.values[j - 1]).min(if j + 1 < k {
            d.values[j + 1] - d.values[j]
        } else {
            f64::MAX
        });
        if gap < 1e-3 * scale {
            continue;
        }
        let diff: f64 = (0..l.nrows())
            .map(|i| m[i] * (d.vectors[(i, j)] - s.vectors[(i, j)]).powi(2))
            .sum();
        assert!(
            diff.sqrt() < 1e-6,
            "eigenvector {j} differs by {:e}",
            diff.sqrt()
        );
    }
}

#[test]
fn eigenvalues_scale_as_one_over_s_squared() {
    // scaling the surface by s: L unchanged, M -> s^2 M, lambda -> lambda / s^2
    let (l, m) = common::torus_operators(2500);
    let s = 7.0;
    let m2: Vec<f64> = m.iter().map(|x| x * s * s).collect();
    let a = generalized_eigenpairs(&l, &m, 12, &opts(EigenMethod::Sparse)).expect("sparse");
    let b = generalized_eigenpairs(&l, &m2, 12, &opts(EigenMethod::Sparse)).expect("sparse");
    assert!(
        (a.info.sigma / b.info.sigma - s * s).abs() < 1e-9 * s * s,
        "automatic shift follows the scale"
    );
    for j in 1..12 {
        assert!((a.values[j] / b.values[j] - s * s).abs() < 1e-9 * s * s);
    }
}

#[test]
fn eigensolver_rejects_bad_inputs() {
    let (l, m) = common::torus_operators(300);
    let n = l.nrows();
    assert_eq!(
        generalized_eigenpairs(&l, &m, n + 1, &EigenOptions::default()).expect_err("must fail"),
        SolverError::KTooLarge {
            k: n + 1,
            max: n,
            n
        }
    );
    let max = match generalized_eigenpairs(&l, &m, n - 2, &opts(EigenMethod::Sparse)) {
        Err(SolverError::KTooLarge { max, .. }) => max,
        other => panic!("expected KTooLarge, got {:?}", other.map(|p| p.info)),
    };
    // the largest k the sparse method accepts works, and matches the dense path
    // (the Krylov basis then nearly fills the space)
    let s = generalized_eigenpairs(&l, &m, max, &opts(EigenMethod::Sparse)).expect("k = max");
    let d = generalized_eigenpairs(&l, &m, max, &opts(EigenMethod::Dense)).expect("dense");
    for (j, (a, b)) in s.values.iter().zip(&d.values).enumerate() {
        assert!(
            (a - b).abs() <= 1e-9 * b.max(d.values[1]),
            "j {j}: {a} vs {b}"
        );
    }
    let o = EigenOptions {
        max_subspace: 20,
        ..opts(EigenMethod::Sparse)
    };
    assert!(matches!(
        generalized_eigenpairs(&l, &m, 20, &o),
        Err(SolverError::InvalidParameter {
            name: "max_subspace",
            ..
        })
    ));
    assert!(matches!(
        generalized_eigenpairs(&l, &m[1..], 4, &EigenOptions::default()),
        Err(SolverError::SizeMismatch { what: "mass", .. })
    ));
    let mut bad = m.clone();
    bad[5] = -1.0;
    assert!(matches!(
        generalized_eigenpairs(&l, &bad, 4, &EigenOptions::default()),
        Err(SolverError::NonPositiveMass { index: 5, .. })
    ));
    let nan = SparseColMat::<usize, f64>::try_new_from_triplets(
        n,
        n,
        &l.triplet_iter()
            .map(|e| {
                Triplet::new(
                    e.row,
                    e.col,
                    if e.row == 4 && e.col == 4 {
                        f64::NAN
                    } else {
                        *e.val
                    },
                )
            })
            .collect::<Vec<_>>(),
    )
    .expect("valid");
    assert!(matches!(
        generalized_eigenpairs(&nan, &m, 4, &EigenOptions::default()),
        Err(SolverError::NonFinite { row: 4, col: 4, .. })
    ));
    // a shift above the smallest eigenvalues makes L - sigma M indefinite
    let d = generalized_eigenpairs(&l, &m, 6, &opts(EigenMethod::Dense)).expect("dense");
    let o = EigenOptions {
        method: EigenMethod::Sparse,
        sigma: Some(d.values[3]),
        ..EigenOptions::default()
    };
    assert!(matches!(
        generalized_eigenpairs(&l, &m, 6, &o),
        Err(SolverError::NotPositiveDefinite { .. })
    ));
    // k = 0 is an empty result
    let e = generalized_eigenpairs(&l, &m, 0, &EigenOptions::default()).expect("empty");
    assert!(e.values.is_empty() && e.vectors.ncols() == 0 && e.vectors.nrows() == n);
}

#[test]
fn bunny_spectrum_matches_scipy_eigsh() {
    let Some(python) = common::python_oracle() else {
        return;
    };
    let Some(mesh) = common::shared_mesh("bunny.off") else {
        return;
    };
    let script =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../xtask/python/scipy_eigs.py");
    let dir = std::env::temp_dir().join(format!("mfm-solver-eigs-{}", std::process::id()));
    let k = 64;
    let status = std::process::Command::new(python)
        .arg(&script)
        .arg("--mesh")
        .arg(&mesh)
        .arg(&dir)
        .arg(k.to_string())
        .status()
        .expect("python runs");
    assert!(status.success(), "scipy oracle failed");
    let l = common::read_triplets(&dir.join("L.txt"));
    let m = common::read_column(&dir.join("M.txt"));
    let reference = common::read_column(&dir.join("eigs.txt"));
    let _ = std::fs::remove_dir_all(&dir);
    assert_eq!(reference.len(), k);
    let p = generalized_eigenpairs(&l, &m, k, &opts(EigenMethod::Sparse)).expect("sparse");
    let scale = reference[1];
    for (j, (v, r)) in p.values.iter().zip(&reference).enumerate() {
        let err = (v - r).abs() / r.max(scale);
        assert!(
            err < 1e-10,
            "eigenvalue {j}: {v} vs scipy {r} (rel {err:e})"
        );
    }
    let (res, orth) = check_pairs(&l, &m, &p);
    assert!(res < 1e-10 && orth < 1e-10, "res {res:e} orth {orth:e}");
}

#[test]
fn sparse_eigenpairs_do_not_depend_on_the_thread_count() {
    let (l, m) = common::torus_operators(5000);
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .expect("pool");
        pool.install(|| {
            generalized_eigenpairs(&l, &m, 24, &opts(EigenMethod::Sparse)).expect("sparse")
        })
    };
    let a = run(1);
    let b = run(3);
    assert_eq!(
        a.values.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
        b.values.iter().map(|v| v.to_bits()).collect::<Vec<_>>()
    );
    assert_eq!((&a.vectors - &b.vectors).norm_max(), 0.0);
}

#[test]
fn two_components_give_two_zero_eigenvalues() {
    // block-diagonal L and M: two disjoint tori of different sizes
    let (l1, m1) = common::torus_operators(300);
    let (l2, m2) = common::torus_operators(450);
    let (n1, n2) = (l1.nrows(), l2.nrows());
    let mut t: Vec<_> = l1
        .triplet_iter()
        .map(|e| Triplet::new(e.row, e.col, *e.val))
        .collect();
    t.extend(
        l2.triplet_iter()
            .map(|e| Triplet::new(e.row + n1, e.col + n1, *e.val)),
    );
    let l = SparseColMat::<usize, f64>::try_new_from_triplets(n1 + n2, n1 + n2, &t).expect("valid");
    let m: Vec<f64> = m1.iter().chain(&m2).copied().collect();
    let p = generalized_eigenpairs(&l, &m, 10, &opts(EigenMethod::Sparse)).expect("sparse");
    let d = generalized_eigenpairs(&l, &m, 10, &opts(EigenMethod::Dense)).expect("dense");
    let scale = d.values[2];
    assert!(p.values[0].abs() < 1e-10 * scale && p.values[1].abs() < 1e-10 * scale);
    assert!(p.values[2] > 1e-3 * scale);
    for j in 0..10 {
        assert!(
            (p.values[j] - d.values[j]).abs() <= 1e-10 * d.values[j].max(scale),
            "j {j}"
        );
    }
    let (res, orth) = check_pairs(&l, &m, &p);
    assert!(res < 1e-10 && orth < 1e-10, "res {res:e} orth {orth:e}");
}

#[test]
fn too_few_restarts_is_reported_as_not_converged() {
    let (l, m) = common::torus_operators(3000);
    let o = EigenOptions {
        method: EigenMethod::Sparse,
        max_restarts: 0,
        max_subspace: 48,
        block_size: 8,
        ..EigenOptions::default()
    };
    match generalized_eigenpairs(&l, &m, 30, &o) {
        Err(SolverError::NotConverged {
            converged,
            k: 30,
            restarts: 0,
            worst_residual,
            ..
        }) => {
            assert!(converged < 30 && worst_residual > o.tol);
        }
        other => panic!("expected NotConverged, got {:?}", other.map(|p| p.info)),
    }
}
