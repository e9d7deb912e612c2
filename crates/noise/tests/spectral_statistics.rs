//! Acceptance: the spectral coefficients `c_i = phi_i^T M f` of sampled noise
//! have the per-frequency variances of docs/conventions.md, "Noise", and are independent.
//!
//! How the tolerances follow from the sample count (they hold for any seed
//! with overwhelming probability, so the fixed seeds are not tuned):
//! - With `N` samples, the empirical `Var(c_i)` (second moment about the known
//!   zero mean) of a Gaussian coefficient has a relative standard deviation of
//!   `sqrt(2 / N)`: 2.0% for `N = 5000`. The 10% tolerance is 5 standard
//!   deviations; the chance that any of 64 frequencies exceeds it is below
//!   `64 * 6e-7 = 4e-5` (and the variance of a sum of Gaussians is exactly
//!   Gaussian-chi-square, so the normal tail is accurate here).
//! - For independent coefficients, each sample correlation `r_ij` has a
//!   standard deviation of `1 / sqrt(N)`. The largest of the `P = K(K-1)/2 =
//!   2016` pairs is about `sqrt(2 ln P / N)` (the report's `reference`,
//!   0.055 for `N = 5000`). The test allows `1.5 * reference`, i.e.
//!   `1.5 * sqrt(2 ln 2016) = 5.85` standard deviations per pair: by a union
//!   bound the chance of a false failure is below `2016 * 2 Phi(-5.85) = 1e-5`.
#![allow(clippy::unwrap_used, clippy::needless_range_loop)]

mod common;

use mfm_geometry::TriMesh;
use mfm_noise::{NoiseKind, NoiseSampler, SpectralAnalyzer, SpectrumReport};
use mfm_solver::Eigenpairs;

const SAMPLES: usize = 5000;
const FREQUENCIES: usize = 64;
const TOLERANCE: f64 = 0.10;

/// Samples `kind` (in pieces of 1000, which `sample_range` makes equivalent
/// to one batch) and returns the report against the theory.
fn report(
    mesh: &TriMesh,
    mass: &[f64],
    pairs: &Eigenpairs,
    kind: NoiseKind,
    seed: u64,
) -> SpectrumReport {
    let sampler = NoiseSampler::new(mesh, kind).unwrap();
    let theory = sampler.theory(pairs).unwrap();
    let mut analyzer = SpectralAnalyzer::new(pairs, mass).unwrap();
    for first in (0..SAMPLES).step_by(1000) {
        analyzer
            .add(&sampler.sample_range(first, 1000, 1, seed).unwrap())
            .unwrap();
    }
    analyzer.report(Some(&theory)).unwrap()
}

fn assert_variances_match(name: &str, kind: NoiseKind, r: &SpectrumReport) {
    let ratio = r.ratio.as_ref().unwrap();
    assert_eq!(ratio.len(), FREQUENCIES);
    for (i, q) in ratio.iter().enumerate() {
        let q = q.unwrap_or_else(|| panic!("{name} {kind}: no theory at frequency {i}"));
        assert!(
            (q - 1.0).abs() < TOLERANCE,
            "{name} {kind}: Var(c_{i}) = {:e} but theory {:e} (ratio {q:.4}, lambda {:.4})",
            r.variance[i],
            r.theory.as_ref().unwrap()[i],
            r.eigenvalues[i]
        );
    }
}

fn assert_independent(name: &str, kind: NoiseKind, r: &SpectrumReport) {
    let ind = &r.independence;
    assert_eq!(ind.pairs, FREQUENCIES * (FREQUENCIES - 1) / 2);
    assert!(
        ind.max_abs_correlation < 1.5 * ind.reference,
        "{name} {kind}: correlation {:.4} between c_{:?} exceeds 1.5 x {:.4}",
        ind.max_abs_correlation,
        ind.pair,
        ind.reference
    );
}

/// Matérn, normalized Matérn, smooth Matérn and white noise against their
/// closed forms, independence for all four; naive against `phi^T M^2 phi`.
fn check_mesh(name: &str, mesh: &TriMesh) {
    let (mass, pairs) = common::eigen(mesh, FREQUENCIES);
    let kinds = [
        (NoiseKind::Matern { tau: 100.0 }, 11),
        // a c that puts tau = c Gamma among the first eigenvalues
        (NoiseKind::MaternNormalized { c: 1e-5 }, 12),
        (NoiseKind::White, 13),
        (NoiseKind::Naive, 14),
        (
            NoiseKind::MaternSmooth {
                tau: 100.0,
                order: 2,
            },
            15,
        ),
        (
            NoiseKind::MaternSmooth {
                tau: 30.0,
                order: 3,
            },
            16,
        ),
    ];
    for (kind, seed) in kinds {
        let r = report(mesh, &mass, &pairs, kind, seed);
        eprintln!(
            "{name} {kind}: max |ratio - 1| = {:.4}, max corr {:.4} (reference {:.4})",
            r.max_relative_error.unwrap(),
            r.independence.max_abs_correlation,
            r.independence.reference
        );
        assert_variances_match(name, kind, &r);
        if kind != NoiseKind::Naive {
            assert_independent(name, kind, &r);
        }
        // property 3 for the kinds with a closed-form energy: naive carries
        // the surface area, white one unit per vertex (each a mean of 5000
        // samples whose relative standard deviation is below 1% here)
        if let Some(e) = r.theory_energy {
            assert!(
                (r.mean_energy / e - 1.0).abs() < 0.05,
                "{name} {kind}: mean energy {} vs {e}",
                r.mean_energy
            );
        }
    }
}

#[test]
fn variances_match_theory_on_procedural_blob() {
    check_mesh("blob(4)", &common::blob(4));
}

#[test]
fn variances_match_theory_on_bunny() {
    if let Some(bunny) = common::bunny() {
        check_mesh("bunny", &bunny);
    }
}

/// Explicit(k) has the Matérn variances below `k` and nothing beyond; the
/// Matérn sampler, analysed the same way, has content beyond `k`.
#[test]
fn explicit_matches_matern_below_k_and_is_empty_beyond() {
    let mesh = common::blob(3); // 642 vertices: dense, exact eigenpairs
    let (k, tau) = (24, 10.0);
    let (mass, pairs) = common::eigen(&mesh, 40);
    let explicit = report_k(&mesh, &mass, &pairs, NoiseKind::Explicit { k, tau }, 21);
    let matern = report_k(&mesh, &mass, &pairs, NoiseKind::Matern { tau }, 22);
    let th_e = explicit.theory.as_ref().unwrap();
    let th_m = matern.theory.as_ref().unwrap();
    let top = explicit.variance[0];
    for i in 0..40 {
        let qm = matern.ratio.as_ref().unwrap()[i].unwrap();
        assert!((qm - 1.0).abs() < TOLERANCE, "matern ratio {qm} at {i}");
        if i < k {
            assert!(
                (th_e[i] / th_m[i] - 1.0).abs() < 1e-13,
                "same closed form below k"
            );
            let qe = explicit.ratio.as_ref().unwrap()[i].unwrap();
            assert!((qe - 1.0).abs() < TOLERANCE, "explicit ratio {qe} at {i}");
        } else {
            assert_eq!(th_e[i], 0.0);
            assert!(explicit.ratio.as_ref().unwrap()[i].is_none());
            // round-off only: the eigenvectors are M-orthonormal to ~1e-14
            assert!(
                explicit.variance[i] < 1e-20 * top,
                "explicit has content {:e} at frequency {i} >= k",
                explicit.variance[i]
            );
            assert!(matern.variance[i] > 0.5 * th_m[i]);
        }
    }
    // all of the explicit energy sits in the first k frequencies
    let e = explicit.theory_energy.unwrap();
    assert!((explicit.mean_energy / e - 1.0).abs() < 0.05);
    assert!((explicit.captured_energy - explicit.mean_energy).abs() < 1e-9 * e);
    assert!(explicit.independence.max_abs_correlation < 1.5 * explicit.independence.reference);
}

fn report_k(
    mesh: &TriMesh,
    mass: &[f64],
    pairs: &Eigenpairs,
    kind: NoiseKind,
    seed: u64,
) -> SpectrumReport {
    let sampler = NoiseSampler::new(mesh, kind).unwrap();
    let theory = sampler.theory(pairs).unwrap();
    let batch = sampler.sample(SAMPLES, 1, seed).unwrap();
    mfm_noise::spectrum::analyze(pairs, mass, &batch, Some(&theory)).unwrap()
}

/// Explicit with `tau = 0` leaves the constant mode out instead of dividing
/// by zero: every sample has zero mass-weighted mean.
#[test]
fn explicit_with_zero_tau_drops_the_constant_mode() {
    let mesh = common::blob(2);
    let sampler = NoiseSampler::new(&mesh, NoiseKind::Explicit { k: 10, tau: 0.0 }).unwrap();
    let batch = sampler.sample(20, 2, 5).unwrap();
    let mass = sampler.mass();
    let area: f64 = mass.iter().sum();
    for s in 0..20 {
        for c in 0..2 {
            let f = batch.signal(s, c);
            let mean: f64 = f.iter().zip(mass).map(|(f, m)| f * m).sum::<f64>() / area;
            let rms = (f.iter().zip(mass).map(|(f, m)| f * f * m).sum::<f64>() / area).sqrt();
            assert!(
                rms > 0.0 && mean.abs() < 1e-10 * rms,
                "mean {mean} rms {rms}"
            );
        }
    }
    let pairs = sampler.eigenpairs().unwrap();
    let th = sampler.theory(pairs).unwrap();
    assert_eq!(th.variance[0], 0.0);
    assert!((th.variance[1] - pairs.values[1].powi(-2)).abs() < 1e-12 * th.variance[1]);
}
