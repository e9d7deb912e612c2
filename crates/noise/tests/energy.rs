//! Acceptance: bounded high-frequency content (paper §3.3 property 3,
//! docs/conventions.md, "Noise"). Matérn noise's expected total energy `E[f^T M f]`
//! converges under refinement; white noise's is `V`, so it grows about 4x
//! per midpoint subdivision.
//!
//! # Refinement
//! Midpoint subdivision ([`subdivide::midpoint`]): the new vertices are edge
//! midpoints, so every level is a triangulation of the *same* piecewise-flat
//! surface (same area, same shape). Any change of the energy between levels
//! is then due to the triangulation alone, which is the property under test.
//! Loop subdivision would also move the vertices (it smooths and shrinks the
//! surface toward its limit surface), mixing a geometric change into the
//! comparison; tried, it gives changes of the same size (bunny, `tau = 1e4`:
//! 2.6% against midpoint's 2.1% with the same seeds).
//!
//! # Estimator
//! With `M`-orthonormal eigenpairs `(lambda_i, phi_i)` of `L phi = lambda M phi`
//! and `c_i = phi_i^T M f`, a signal splits into its first `K` modes and an
//! `M`-orthogonal remainder `r = f - sum_{i<K} c_i phi_i`, so
//! `f^T M f = sum_{i<K} c_i^2 + r^T M r` exactly. Hence
//!
//! `E[f^T M f] = sum_{i<K} Var(c_i) + E[r^T M r]`.
//!
//! The first term is the closed form (`1 / (lambda_i + tau)^2` for Matérn,
//! `1` for white; the per-frequency variances themselves are checked against
//! it by `spectral_statistics.rs`, and here once more through their sum), the
//! second is the Monte Carlo mean of `r^T M r` over `N` samples drawn by
//! [`NoiseSampler`]. Both are exact in expectation, so the estimate is
//! unbiased; its standard error is `sd(r^T M r) / sqrt(N)`. This is plain
//! Monte Carlo with the control variate `sum_{i<K} c_i^2` (coefficient 1,
//! known mean). It removes the variance of the lowest modes, where Matérn
//! noise keeps most of its energy: there plain Monte Carlo has a relative
//! standard error of about `sqrt(2 / N)` when one term dominates (the
//! bunny's constant mode at `tau = 100`; 7% at `N = 400`), while `r^T M r`
//! is a sum of many small independent chi-square terms with a relative
//! spread of a few percent per sample.
//!
//! Every estimate asserts its standard error is below 1% of the total
//! (measured: 0.002-0.3% with 128-256 samples). On
//! the procedural surface, where it is cheap, an exact oracle checks the
//! estimator itself: `E[f^T M f] = trace(M^1/2 A^-1 M A^-1 M^1/2) =
//! ||M^1/2 A^-1 M^1/2||_F^2` with `A = L + tau M`, summed column by column
//! from `V` solves.
#![allow(clippy::unwrap_used)]

mod common;

use faer::{Mat, MatRef};
use mfm_geometry::operators::Operators;
use mfm_geometry::{TriMesh, subdivide};
use mfm_noise::spectrum::{self, Eigenpairs};
use mfm_noise::{DEFAULT_TAU, NoiseKind, NoiseSampler};

/// Eigenpairs whose energy is taken from the closed form.
const K: usize = 64;

/// Screening weight of the procedural test (see its docs).
const BLOB_TAU: f64 = 30.0;

/// One energy estimate and its parts.
#[derive(Debug, Clone, Copy)]
struct Energy {
    /// Vertices of the mesh.
    vertices: usize,
    /// `sum_{i<K} Var(c_i)`, closed form.
    low: f64,
    /// Empirical `mean(sum_{i<K} c_i^2)` (plain Monte Carlo, a check).
    low_empirical: f64,
    /// Standard error of `low_empirical`.
    low_stderr: f64,
    /// Empirical `mean(r^T M r)`.
    remainder: f64,
    /// Standard error of `remainder` (and of the estimate).
    stderr: f64,
}

impl Energy {
    /// The estimate of `E[f^T M f]`.
    fn total(&self) -> f64 {
        self.low + self.remainder
    }

    /// Standard error relative to the estimate.
    fn rel_stderr(&self) -> f64 {
        self.stderr / self.total()
    }
}

fn mean_and_stderr(x: &[f64]) -> (f64, f64) {
    let n = x.len() as f64;
    let mean = x.iter().sum::<f64>() / n;
    let var = x.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0);
    (mean, (var / n).sqrt())
}

/// Estimates `E[f^T M f]` of `kind` on a mesh with operators `ops` and its
/// `K` lowest eigenpairs `pairs`, from `samples` samples of `seed`.
fn estimate(
    ops: &Operators,
    pairs: &Eigenpairs,
    kind: NoiseKind,
    samples: usize,
    seed: u64,
) -> Energy {
    let mass = &ops.mass;
    let v = mass.len();
    let sampler = NoiseSampler::from_operators(&ops.laplacian, mass, kind).unwrap();
    let low: f64 = sampler.theory(pairs).unwrap().variance.iter().sum();
    let batch = sampler.sample(samples, 1, seed).unwrap();
    // [N, V, 1] row-major is the column-major V x N matrix of the signals
    let f = MatRef::from_column_major_slice(batch.data(), v, samples);
    let mf = Mat::from_fn(v, samples, |i, j| mass[i] * f[(i, j)]);
    let c = pairs.vectors.transpose() * &mf; // K x N coefficients
    let r = f - &pairs.vectors * &c; // M-orthogonal remainders
    let mut rem = Vec::with_capacity(samples);
    let mut lows = Vec::with_capacity(samples);
    for j in 0..samples {
        rem.push((0..v).map(|i| mass[i] * r[(i, j)] * r[(i, j)]).sum::<f64>());
        lows.push((0..c.nrows()).map(|i| c[(i, j)] * c[(i, j)]).sum::<f64>());
    }
    let (remainder, stderr) = mean_and_stderr(&rem);
    let (low_empirical, low_stderr) = mean_and_stderr(&lows);
    Energy {
        vertices: v,
        low,
        low_empirical,
        low_stderr,
        remainder,
        stderr,
    }
}

/// Exact Matérn energy `||M^1/2 (L + tau M)^-1 M^1/2||_F^2`, by solving for
/// the columns `sqrt(m_j) e_j` in blocks. Cost `V` solves.
fn exact_matern_energy(ops: &Operators, tau: f64) -> f64 {
    let sampler =
        NoiseSampler::from_operators(&ops.laplacian, &ops.mass, NoiseKind::Matern { tau }).unwrap();
    let poisson = sampler.screened_poisson().unwrap();
    let mass = &ops.mass;
    let v = mass.len();
    let block = 256;
    let mut total = 0.0;
    for start in (0..v).step_by(block) {
        let cols = block.min(v - start);
        let mut b = Mat::<f64>::zeros(v, cols);
        for j in 0..cols {
            b[(start + j, j)] = mass[start + j].sqrt();
        }
        poisson.solve_many_in_place(b.as_mut()).unwrap();
        for j in 0..cols {
            total += (0..v).map(|i| mass[i] * b[(i, j)] * b[(i, j)]).sum::<f64>();
        }
    }
    total
}

/// The mesh and `levels` midpoint subdivisions of it, finest last.
fn levels(mesh: TriMesh, levels: usize) -> Vec<TriMesh> {
    let mut out = vec![mesh];
    for _ in 0..levels {
        let next = subdivide::midpoint(out.last().unwrap()).unwrap();
        out.push(next);
    }
    out
}

/// Per level: the Matérn estimates (one per `tau`) and the white one.
struct LevelEnergies {
    matern: Vec<Energy>,
    white: Energy,
}

/// Matérn (for each of `taus`) and white estimates on each mesh, with one
/// eigensolve (`k` pairs) per mesh.
fn energies(meshes: &[TriMesh], taus: &[f64], k: usize, samples: usize) -> Vec<LevelEnergies> {
    meshes
        .iter()
        .enumerate()
        .map(|(level, mesh)| {
            let ops = Operators::new(mesh).unwrap();
            let pairs = spectrum::eigenpairs(&ops.laplacian, &ops.mass, k).unwrap();
            let seed = 1000 + 10 * level as u64;
            let matern = taus
                .iter()
                .enumerate()
                .map(|(t, &tau)| {
                    estimate(
                        &ops,
                        &pairs,
                        NoiseKind::Matern { tau },
                        samples,
                        seed + t as u64,
                    )
                })
                .collect();
            let white = estimate(&ops, &pairs, NoiseKind::White, samples, seed + 9);
            LevelEnergies { matern, white }
        })
        .collect()
}

/// Asserts the precision of every estimate, the low-mode sums against
/// their closed form, white noise's `E = V`, and then, between the 1st and
/// the 2nd refinement (levels 1 and 2), a Matérn change below 5% (for each
/// `tau`) and a white growth within `[3.5, 4.5]`.
fn check(name: &str, taus: &[f64], e: &[LevelEnergies]) {
    for (level, le) in e.iter().enumerate() {
        let w = &le.white;
        eprintln!(
            "{name} level {level}: V = {:>6}, white E = {:.1} (se {:.3}%)",
            w.vertices,
            w.total(),
            100.0 * w.rel_stderr()
        );
        for (tau, m) in taus.iter().zip(&le.matern) {
            eprintln!(
                "    matern tau {tau:>7}: E = {:.6e} (se {:.3}%; first {} modes: {:.1}% of it)",
                m.total(),
                100.0 * m.rel_stderr(),
                K,
                100.0 * m.low / m.total()
            );
        }
        for (what, x) in le
            .matern
            .iter()
            .map(|m| ("matern", m))
            .chain([("white", w)])
        {
            assert!(
                x.rel_stderr() < 0.01,
                "{name} {what} level {level}: standard error {:.3}% >= 1%",
                100.0 * x.rel_stderr()
            );
            // the sampler's low modes carry their closed-form energy (plain
            // Monte Carlo, 5 standard errors)
            assert!(
                (x.low_empirical - x.low).abs() < 5.0 * x.low_stderr,
                "{name} {what} level {level}: low modes {} vs closed form {} (se {})",
                x.low_empirical,
                x.low,
                x.low_stderr
            );
        }
        // white noise: f^T M f = n^T n, so E = V exactly (5 standard errors)
        assert!(
            (w.total() - w.vertices as f64).abs() < 5.0 * w.stderr,
            "{name} white level {level}: {} vs V = {}",
            w.total(),
            w.vertices
        );
    }
    for (t, tau) in taus.iter().enumerate() {
        let (m1, m2) = (e[1].matern[t], e[2].matern[t]);
        let change = (m2.total() - m1.total()).abs() / m1.total();
        eprintln!(
            "{name} matern tau {tau}: 1st -> 2nd refinement changes E by {:.3}%",
            100.0 * change
        );
        assert!(
            change < 0.05,
            "{name} matern tau {tau}: energy changed by {:.2}% (>= 5%) between the 1st and 2nd refinement",
            100.0 * change
        );
    }
    let growth = e[2].white.total() / e[1].white.total();
    eprintln!("{name} white: 1st -> 2nd refinement grows E x{growth:.3}");
    assert!(
        (3.5..=4.5).contains(&growth),
        "{name} white energy grew x{growth} (expected ~4)"
    );
}

/// Procedural surface of unit size (always runs; 2562, 10242, 40962
/// vertices) with `tau = 30`: about thirty modes lie below `tau`, and the
/// first `K = 64` modes hold only ~62% of the energy, so the Monte Carlo
/// remainder matters. The exact trace checks the estimator on the two
/// smaller levels.
///
/// Measured (768 samples): the energy drops 4.7% from level 0 to 1 and 2.2%
/// from 1 to 2; the change about halves per refinement (first order in the
/// edge length). With `tau = 100` (a hundred modes below `tau` on this
/// surface) the drops are 6.9% and 4.1%: converging too, but too close to
/// the 5% bar at these sizes for a robust test; with `tau = 10`, 2.5% and
/// 0.9%.
#[test]
fn matern_energy_converges_white_grows_procedural() {
    let meshes = levels(common::blob(4), 2);
    let e = energies(&meshes, &[BLOB_TAU], K, 256);
    for (level, mesh) in meshes.iter().enumerate().take(2) {
        let exact = exact_matern_energy(&Operators::new(mesh).unwrap(), BLOB_TAU);
        let m = e[level].matern[0];
        eprintln!(
            "blob level {level}: exact E = {exact:.6e}, estimate {:.6e} ({:+.2} standard errors)",
            m.total(),
            (m.total() - exact) / m.stderr
        );
        assert!(
            (m.total() - exact).abs() < 4.0 * m.stderr,
            "level {level}: estimate {} vs exact {exact} (se {})",
            m.total(),
            m.stderr
        );
    }
    check("blob", &[BLOB_TAU], &e);
}

/// The shared bunny (3485 vertices, about 0.15 units across) and two
/// midpoint subdivisions (13.9k, 55.7k vertices); skipped when the shared
/// meshes are missing. At the paper's `tau = 100` this small mesh's first
/// nonzero eigenvalue is far above `tau`, so the constant mode (`1 / tau^2`)
/// holds most of the energy and it barely moves (measured 0.005%); at
/// `tau = 1e4`, comparable to the low eigenvalues, the first `K` modes hold
/// about 57% of it (measured change 1.4% and 2.1% with two sets of seeds).
#[test]
fn matern_energy_converges_white_grows_bunny() {
    let Some(bunny) = common::bunny() else {
        return;
    };
    let meshes = levels(bunny, 2);
    let taus = [DEFAULT_TAU, 1e4];
    let e = energies(&meshes, &taus, K, 128);
    check("bunny", &taus, &e);
}
