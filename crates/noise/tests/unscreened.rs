//! Matérn noise without screening (`tau = 0`): the pseudo-inverse
//! `f = L^+ P M^1/2 n`, checked against its defining equation with
//! independent arithmetic (a sparse matvec and a projection built from the
//! known components of the test mesh), against a dense eigendecomposition,
//! and statistically against `Var(c_i) = 1 / lambda_i^2`.
#![allow(clippy::unwrap_used, clippy::needless_range_loop)]

mod common;

use faer::sparse::{SparseColMat, Triplet};
use mfm_geometry::operators::Operators;
use mfm_geometry::{TriMesh, procedural};
use mfm_noise::sampler::ZERO_TAU_REGULARIZATION;
use mfm_noise::spectrum::SpectralAnalyzer;
use mfm_noise::{NoiseError, NoiseKind, NoiseSampler};

const UNSCREENED: NoiseKind = NoiseKind::Matern { tau: 0.0 };

/// Two disjoint closed surfaces of different areas: the blob of `level`
/// (first `V1` vertices) and a half-size icosphere of `level - 1` moved away
/// from it (the rest). Returns the mesh and `V1`.
fn two_components(level: u32) -> (TriMesh, usize) {
    let a = common::blob(level);
    let b = procedural::icosphere(level - 1).transformed(0.5, [4.0, 0.5, -1.0]);
    let v1 = a.num_vertices();
    let (mut p, mut f) = a.into_parts();
    let (pb, fb) = b.into_parts();
    p.extend(pb);
    f.extend(fb.iter().map(|t| t.map(|i| i + v1 as u32)));
    (TriMesh::new(p, f).unwrap(), v1)
}

/// `y = L x` from the CSC arrays (both triangles are stored).
fn matvec(l: &SparseColMat<usize, f64>, x: &[f64]) -> Vec<f64> {
    let mut y = vec![0.0; x.len()];
    let (cp, ri, val) = (l.symbolic().col_ptr(), l.symbolic().row_idx(), l.val());
    for (j, xj) in x.iter().enumerate() {
        for p in cp[j]..cp[j + 1] {
            y[ri[p]] += val[p] * xj;
        }
    }
    y
}

fn norm(v: &[f64]) -> f64 {
    v.iter().map(|x| x * x).sum::<f64>().sqrt()
}

/// The vertex ranges of the two components.
fn parts(v1: usize, v: usize) -> [std::ops::Range<usize>; 2] {
    [0..v1, v1..v]
}

/// `P b`: `b_v - m_v * (sum_{u in c} b_u) / area_c` on each component `c`.
fn project(b: &[f64], m: &[f64], v1: usize) -> Vec<f64> {
    let mut out = b.to_vec();
    for r in parts(v1, b.len()) {
        let area: f64 = m[r.clone()].iter().sum();
        let s: f64 = b[r.clone()].iter().sum::<f64>() / area;
        for v in r {
            out[v] -= m[v] * s;
        }
    }
    out
}

/// Every sample has zero mass-weighted mean on each of the two components
/// (a single global projection would leave opposite means on them), both
/// components carry noise, and `L f = P M^1/2 n` holds to the regularization
/// bias, with the normals `n` read from naive noise of the same seed (all
/// kinds share the streams). The residual `L f - P b` is `-eps M f` (the
/// regularization, `eps = 1e-10 Gamma`), which the test checks to round-off,
/// and about `5e-8` of `|P b|` here.
#[test]
fn samples_are_mean_free_per_component_and_solve_the_projected_equation() {
    let (mesh, v1) = two_components(3);
    let v = mesh.num_vertices();
    let ops = Operators::new(&mesh).unwrap();
    let (l, m) = (&ops.laplacian, &ops.mass);
    let sampler = NoiseSampler::new(&mesh, UNSCREENED).unwrap();
    assert_eq!(sampler.tau(), Some(0.0));
    let eps = sampler.screened_poisson().unwrap().tau();
    assert_eq!(eps, ZERO_TAU_REGULARIZATION * sampler.gamma());
    let (ns, ch, seed) = (6, 3, 2024);
    let batch = sampler.sample(ns, ch, seed).unwrap();
    let naive = NoiseSampler::new(&mesh, NoiseKind::Naive)
        .unwrap()
        .sample(ns, ch, seed)
        .unwrap();
    let (mut worst_mean, mut worst_res, mut worst_reg) = (0.0f64, 0.0f64, 0.0f64);
    for s in 0..ns {
        for c in 0..ch {
            let f = batch.signal(s, c);
            let rms = (f.iter().zip(m).map(|(x, m)| m * x * x).sum::<f64>()
                / m.iter().sum::<f64>())
            .sqrt();
            for r in parts(v1, v) {
                let area: f64 = m[r.clone()].iter().sum();
                let mean = r.clone().map(|u| m[u] * f[u]).sum::<f64>() / area;
                worst_mean = worst_mean.max(mean.abs() / rms);
                let part_rms = (r.clone().map(|u| m[u] * f[u] * f[u]).sum::<f64>() / area).sqrt();
                assert!(part_rms > 0.1 * rms, "a component without noise");
            }
            let n = naive.signal(s, c);
            let b: Vec<f64> = n.iter().zip(m).map(|(n, m)| m.sqrt() * n).collect();
            let pb = project(&b, m, v1);
            let lf = matvec(l, &f);
            let r: Vec<f64> = (0..v).map(|u| lf[u] - pb[u]).collect();
            worst_res = worst_res.max(norm(&r) / norm(&pb));
            // the part of the residual that is not the regularization itself
            let r: Vec<f64> = (0..v).map(|u| lf[u] + eps * m[u] * f[u] - pb[u]).collect();
            worst_reg = worst_reg.max(norm(&r) / norm(&pb));
        }
    }
    eprintln!(
        "tau = 0 on {v} vertices: |mean| / rms {worst_mean:.1e}, \
         |L f - P b| / |P b| {worst_res:.1e}, |(L + eps M) f - P b| / |P b| {worst_reg:.1e}"
    );
    assert!(worst_mean < 1e-13, "mean / rms {worst_mean:e}");
    assert!(worst_res < 1e-7, "relative residual {worst_res:e}");
    assert!(
        worst_reg < 1e-12,
        "relative residual with eps {worst_reg:e}"
    );
}

/// On a small two-component mesh, the sample equals the pseudo-inverse
/// computed from all `V` dense eigenpairs, `sum_{lambda_i > 0} (phi_i^T b) /
/// lambda_i phi_i` with `b = M^1/2 n`, up to the regularization bias.
#[test]
fn samples_equal_the_dense_pseudo_inverse() {
    let (mesh, _) = two_components(1);
    let v = mesh.num_vertices();
    let (m, pairs) = common::eigen(&mesh, v);
    // two zero modes (one per component), then a clear gap
    let lmax = pairs.values[v - 1];
    assert!(pairs.values[1].abs() < 1e-10 * lmax);
    assert!(pairs.values[2] > 1e-3 * lmax);
    let sampler = NoiseSampler::new(&mesh, UNSCREENED).unwrap();
    let (ns, seed) = (4, 31);
    let batch = sampler.sample(ns, 1, seed).unwrap();
    let naive = NoiseSampler::new(&mesh, NoiseKind::Naive)
        .unwrap()
        .sample(ns, 1, seed)
        .unwrap();
    let mut worst = 0.0f64;
    for s in 0..ns {
        let b: Vec<f64> = naive
            .signal(s, 0)
            .iter()
            .zip(&m)
            .map(|(n, m)| m.sqrt() * n)
            .collect();
        let mut want = vec![0.0; v];
        for i in 2..v {
            let phi = pairs.vectors.col(i);
            let coef = phi.iter().zip(&b).map(|(p, b)| p * b).sum::<f64>() / pairs.values[i];
            for u in 0..v {
                want[u] += coef * phi[u];
            }
        }
        worst = worst.max(common::max_rel_diff(&want, &batch.signal(s, 0)));
    }
    eprintln!("tau = 0 against the dense pseudo-inverse: {worst:.1e}");
    assert!(worst < 1e-7, "relative difference {worst:e}");
}

/// `Var(c_i)` over 8000 samples is within 10% of `1 / lambda_i^2` for
/// `i = 1..32` (6 standard errors of `sqrt(2 / 8000) = 1.6%`) and vanishes
/// for the constant mode; the theory says so too.
#[test]
fn coefficient_variances_are_inverse_squared_eigenvalues() {
    let mesh = common::blob(2);
    let sampler = NoiseSampler::new(&mesh, UNSCREENED).unwrap();
    let (mass, pairs) = common::eigen(&mesh, 33);
    let theory = sampler.theory(&pairs).unwrap();
    assert_eq!(theory.variance[0], 0.0);
    for i in 1..33 {
        let want = pairs.values[i].powi(-2);
        assert!((theory.variance[i] / want - 1.0).abs() < 1e-14, "mode {i}");
    }
    let mut analyzer = SpectralAnalyzer::new(&pairs, &mass).unwrap();
    analyzer.add(&sampler.sample(8000, 1, 5).unwrap()).unwrap();
    let report = analyzer.report(Some(&theory)).unwrap();
    let ratio = report.ratio.as_ref().unwrap();
    assert_eq!(ratio[0], None);
    for i in 1..33 {
        let r = ratio[i].unwrap();
        assert!((r - 1.0).abs() < 0.1, "mode {i}: ratio {r}");
    }
    let worst = report.max_relative_error.unwrap();
    let zero = report.variance[0] / report.variance[1];
    eprintln!("tau = 0 spectrum: max relative error {worst:.3}, Var(c_0) / Var(c_1) {zero:.1e}");
    assert!(zero < 1e-24, "constant mode variance ratio {zero:e}");
    assert!(report.independence.max_abs_correlation < 2.0 * report.independence.reference);
}

/// The `f32` methods return the `f64` samples rounded, also for ranges and
/// several channels, on any thread count; `tau = -0.0` is `tau = 0`.
#[test]
fn f32_is_the_rounded_f64_sample() {
    let (mesh, _) = two_components(2);
    let sampler = NoiseSampler::new(&mesh, UNSCREENED).unwrap();
    let want = sampler.sample(20, 3, 9).unwrap().to_f32();
    for threads in [1, 3] {
        let got = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| sampler.sample_f32(20, 3, 9).unwrap());
        assert_eq!(got, want, "{threads} threads");
    }
    // -0 is zero too
    let negative_zero = NoiseSampler::new(&mesh, NoiseKind::Matern { tau: -0.0 }).unwrap();
    assert_eq!(negative_zero.sample_f32(20, 3, 9).unwrap(), want);
    let v = mesh.num_vertices();
    let part = sampler.sample_range_f32(7, 9, 3, 9).unwrap();
    assert_eq!(part.data(), &want.data()[7 * v * 3..16 * v * 3]);
}

/// Negative, NaN and infinite `tau`, and `tau` so large the noise vanishes
/// (beyond `MAX_TAU`), are rejected with a message that says what is
/// allowed; `tau = 0` on an operator without a Laplacian (nothing to
/// regularize against) is rejected too.
#[test]
fn invalid_tau_is_rejected() {
    let mesh = procedural::icosphere(1);
    for tau in [-1.0, -1e-300, f64::NAN, f64::INFINITY, 1.01e10, 1e300] {
        let e = NoiseSampler::new(&mesh, NoiseKind::Matern { tau }).unwrap_err();
        assert!(
            matches!(e, NoiseError::InvalidParameter { name: "tau", .. }),
            "{tau}: {e}"
        );
        assert!(e.to_string().contains("in [0, 1e10]"), "{e}");
    }
    assert!(NoiseSampler::new(&mesh, NoiseKind::Matern { tau: 1e10 }).is_ok());
    let zero = SparseColMat::<usize, f64>::try_new_from_triplets(3, 3, &[Triplet::new(0, 0, 0.0)])
        .unwrap();
    let e = NoiseSampler::from_operators(&zero, &[1.0; 3], UNSCREENED).unwrap_err();
    assert!(
        matches!(e, NoiseError::InvalidParameter { name: "tau", .. }),
        "{e}"
    );
    assert!(e.to_string().contains("Gamma"), "{e}");
}

/// Components come from the operator itself, in any vertex order: a graph
/// Laplacian on 7 vertices with the interleaved components `{0, 3, 5}`,
/// `{1, 4}` (linked only through the upper triangle's entries as well) and
/// the lone `{2, 6}` pair, plus a stored explicit zero between components that
/// must not join them.
#[test]
fn from_operators_finds_interleaved_components() {
    let edges = [
        (0, 3, 1.0),
        (3, 5, 2.0),
        (4, 1, 0.5),
        (6, 2, 3.0),
        (2, 5, 0.0),
    ];
    let mut t = Vec::new();
    for &(i, j, w) in &edges {
        t.extend([
            Triplet::new(i, i, w),
            Triplet::new(j, j, w),
            Triplet::new(i, j, -w),
            Triplet::new(j, i, -w),
        ]);
    }
    let l = SparseColMat::<usize, f64>::try_new_from_triplets(7, 7, &t).unwrap();
    let mass = [0.5, 1.0, 2.0, 0.25, 1.5, 0.75, 1.25];
    let sampler = NoiseSampler::from_operators(&l, &mass, UNSCREENED).unwrap();
    let batch = sampler.sample(5, 1, 3).unwrap();
    let naive = NoiseSampler::from_operators(&l, &mass, NoiseKind::Naive)
        .unwrap()
        .sample(5, 1, 3)
        .unwrap();
    let comps: [&[usize]; 3] = [&[0, 3, 5], &[1, 4], &[2, 6]];
    for s in 0..5 {
        let f = batch.signal(s, 0);
        let mut pb: Vec<f64> = naive
            .signal(s, 0)
            .iter()
            .zip(&mass)
            .map(|(n, m)| m.sqrt() * n)
            .collect();
        for c in comps {
            let area: f64 = c.iter().map(|&u| mass[u]).sum();
            let mean = c.iter().map(|&u| mass[u] * f[u]).sum::<f64>() / area;
            assert!(mean.abs() < 1e-14, "component {c:?}: mean {mean:e}");
            let sb = c.iter().map(|&u| pb[u]).sum::<f64>() / area;
            c.iter().for_each(|&u| pb[u] -= mass[u] * sb);
        }
        let lf = matvec(&l, &f);
        let r: Vec<f64> = (0..7).map(|u| lf[u] - pb[u]).collect();
        assert!(norm(&r) < 1e-8 * norm(&pb), "residual {:e}", norm(&r));
    }
}
