//! Sampling and spectral analysis behind the statistics figures: the
//! per-frequency histograms on three resolutions, and the spectra.

use anyhow::{Context, Result, ensure};
use mfm_geometry::operators::Operators;
use mfm_noise::spectrum::{self, Eigenpairs, MeshSpectrum, SpectrumReport, SpectrumRequest};
use mfm_noise::{NoiseKind, NoiseSampler, stream};
use serde::Serialize;
use std::time::Instant;

/// Samples drawn and projected together (bounds the memory to
/// `CHUNK x V` values).
const CHUNK: usize = 500;

/// A mesh with its operators and `k` smallest eigenpairs.
pub struct Analyzed {
    /// Short label.
    pub label: String,
    /// How it was made.
    pub how: String,
    /// Vertex count.
    pub vertices: usize,
    /// Face count.
    pub faces: usize,
    /// `L` and `M` of the mesh.
    pub ops: Operators,
    /// The eigenpairs.
    pub pairs: Eigenpairs,
    /// Seconds spent in the eigensolve.
    pub eigen_seconds: f64,
}

impl Analyzed {
    /// Operators and the `k` smallest eigenpairs of `mesh` (all of them when
    /// `k >= V`, by the dense solver).
    pub fn new(label: &str, how: &str, mesh: &mfm_geometry::TriMesh, k: usize) -> Result<Self> {
        let ops = Operators::new(mesh).with_context(|| format!("operators of the {label} mesh"))?;
        let t = Instant::now();
        let k = k.min(mesh.num_vertices());
        let pairs = spectrum::eigenpairs(&ops.laplacian, &ops.mass, k)
            .with_context(|| format!("{k} eigenpairs of the {label} mesh"))?;
        let eigen_seconds = t.elapsed().as_secs_f64();
        eprintln!(
            "xtask:   {label}: {} vertices, {k} eigenpairs in {eigen_seconds:.1} s",
            mesh.num_vertices()
        );
        Ok(Self {
            label: label.to_owned(),
            how: how.to_owned(),
            vertices: mesh.num_vertices(),
            faces: mesh.num_faces(),
            ops,
            pairs,
            eigen_seconds,
        })
    }
}

/// Statistics of one kept coefficient `c_i`.
#[derive(Debug, Clone, Serialize)]
pub struct Kept {
    /// Frequency index `i` (0-based: `c_0` is the constant mode).
    pub index: usize,
    /// `lambda_i` on this mesh.
    pub eigenvalue: f64,
    /// Empirical standard deviation of `c_i`.
    pub std: f64,
    /// Its closed form, `sqrt(Var(c_i))` of [`spectrum::Theory`].
    pub theory_std: f64,
}

/// Mean total energy `f^T M f` over the samples.
#[derive(Debug, Clone, Serialize)]
pub struct Energy {
    /// Sample mean of `f^T M f`.
    pub mean: f64,
    /// Its standard error (sample standard deviation / sqrt(N)).
    pub std_error: f64,
    /// `E[f^T M f]` in closed form where known: naive `sum m_v` (the area),
    /// white `V`, any kind when all `V` eigenpairs were computed (`sum` of
    /// the theoretical variances).
    pub theory: Option<f64>,
}

/// Per-frequency arrays of a [`KindStats`].
#[derive(Debug, Clone, Serialize)]
pub struct PerFrequency {
    /// `lambda_i`, ascending.
    pub eigenvalues: Vec<f64>,
    /// Empirical `Var(c_i)` (second moment about 0).
    pub variance: Vec<f64>,
    /// Closed-form `Var(c_i)`.
    pub theory: Vec<f64>,
}

/// One noise kind sampled and analysed on one mesh.
#[derive(Debug, Clone, Serialize)]
pub struct KindStats {
    /// Mesh label.
    pub mesh: String,
    /// Noise kind (command-line form, e.g. `matern:100`).
    pub kind: String,
    /// Vertex count.
    pub vertices: usize,
    /// Samples analysed.
    pub samples: usize,
    /// Largest `|Var / theory - 1|` over the analysed frequencies.
    pub max_relative_error: Option<f64>,
    /// The same over the first 64 frequencies.
    pub max_relative_error_first_64: Option<f64>,
    /// Largest normalized off-diagonal second moment of the coefficients.
    pub max_abs_correlation: f64,
    /// The level sampling error alone gives for independent coefficients.
    pub correlation_reference: f64,
    /// Mean total energy.
    pub energy: Energy,
    /// The kept coefficients.
    pub kept: Vec<Kept>,
    /// Seconds spent sampling.
    pub sample_seconds: f64,
    /// Seconds spent projecting on the eigenvectors and accumulating.
    pub analysis_seconds: f64,
    /// Per-frequency `lambda_i`, empirical and theoretical `Var(c_i)`.
    pub per_frequency: PerFrequency,
    /// The full report.
    #[serde(skip)]
    pub report: SpectrumReport,
    /// Every value of each kept coefficient, in the order of `kept`.
    #[serde(skip)]
    pub coefficients: Vec<Vec<f64>>,
}

/// Draws `samples` scalar samples of `kind` on `mesh` from `seed` (in chunks)
/// and analyses them on its eigenpairs ([`MeshSpectrum::measure_on`]),
/// keeping every value of the coefficients in `keep` (indices at or beyond
/// the eigenpair count are dropped) and the energy of every sample.
pub fn sample_and_analyze(
    mesh: &Analyzed,
    kind: NoiseKind,
    samples: usize,
    seed: u64,
    keep: &[usize],
) -> Result<KindStats> {
    ensure!(samples >= 2, "need at least 2 samples, got {samples}");
    let k = mesh.pairs.values.len();
    let keep: Vec<usize> = keep.iter().copied().filter(|&i| i < k).collect();
    let mass = &mesh.ops.mass;
    let sampler = NoiseSampler::from_operators(&mesh.ops.laplacian, mass, kind)
        .with_context(|| format!("{kind} sampler on the {} mesh", mesh.label))?;
    let request = SpectrumRequest {
        samples,
        k,
        seed,
        keep: keep.clone(),
    };
    let mut energies = Vec::with_capacity(samples);
    let measured = MeshSpectrum::measure_on(
        &mesh.label,
        &mesh.ops,
        &mesh.pairs,
        &sampler,
        &request,
        CHUNK,
        |batch, _| {
            energies.extend((0..batch.samples()).map(|s| energy(batch.sample(s), mass)));
            Ok(())
        },
    )?;
    let (sample_seconds, analysis_seconds) = (measured.sample_seconds, measured.analysis_seconds);
    let report = measured.spectrum.report;
    let theory = report
        .theory
        .clone()
        .context("internal: a measured spectrum has its theory")?;

    let full = k == mesh.vertices;
    let energy = energy_of(
        &energies,
        if full {
            Some(theory.iter().sum())
        } else {
            report.theory_energy
        },
    );
    let kept_stats = keep
        .iter()
        .map(|&i| Kept {
            index: i,
            eigenvalue: report.eigenvalues[i],
            std: report.variance[i].sqrt(),
            theory_std: theory[i].sqrt(),
        })
        .collect();
    let coefficients = measured.kept.into_iter().map(|(_, c)| c).collect();
    let first_64 = report.ratio.as_ref().map(|r| {
        r.iter()
            .take(64)
            .flatten()
            .map(|x| (x - 1.0).abs())
            .fold(0.0, f64::max)
    });
    eprintln!(
        "xtask:     {kind} on {}: {samples} samples ({sample_seconds:.1} s), analysis \
         {analysis_seconds:.1} s, max |Var/theory - 1| {:.3}, energy {:.4e} +- {:.1e}",
        mesh.label,
        report.max_relative_error.unwrap_or(f64::NAN),
        energy.mean,
        energy.std_error,
    );
    Ok(KindStats {
        mesh: mesh.label.clone(),
        kind: kind.to_string(),
        vertices: mesh.vertices,
        samples,
        max_relative_error: report.max_relative_error,
        max_relative_error_first_64: first_64,
        max_abs_correlation: report.independence.max_abs_correlation,
        correlation_reference: report.independence.reference,
        energy,
        kept: kept_stats,
        sample_seconds,
        analysis_seconds,
        per_frequency: PerFrequency {
            eigenvalues: report.eigenvalues.clone(),
            variance: report.variance.clone(),
            theory,
        },
        report,
        coefficients,
    })
}

/// Mean and standard error of per-sample energies.
fn energy_of(energies: &[f64], theory: Option<f64>) -> Energy {
    let n = energies.len() as f64;
    let mean = energies.iter().sum::<f64>() / n;
    let var = energies.iter().map(|e| (e - mean).powi(2)).sum::<f64>() / (n - 1.0).max(1.0);
    Energy {
        mean,
        std_error: (var / n).sqrt(),
        theory,
    }
}

/// `f^T M f` of one signal.
fn energy(f: &[f64], mass: &[f64]) -> f64 {
    f.iter().zip(mass).map(|(f, m)| m * f * f).sum()
}

/// One row of the energy table.
#[derive(Debug, Clone, Serialize)]
pub struct EnergyRow {
    /// Figure the mesh belongs to.
    pub figure: String,
    /// Mesh label.
    pub mesh: String,
    /// Vertex count.
    pub vertices: usize,
    /// Noise kind.
    pub kind: String,
    /// Samples.
    pub samples: usize,
    /// The energy.
    #[serde(flatten)]
    pub energy: Energy,
}

impl EnergyRow {
    /// The energy row of an analysed run.
    pub fn of(figure: &str, s: &KindStats) -> Self {
        Self {
            figure: figure.to_owned(),
            mesh: s.mesh.clone(),
            vertices: s.vertices,
            kind: s.kind.clone(),
            samples: s.samples,
            energy: s.energy.clone(),
        }
    }
}

/// Mean energy `f^T M f` of `samples` samples of `kind` on `mesh`, without
/// the spectral projection (cheap for white and naive noise).
pub fn energy_only(
    figure: &str,
    mesh: &Analyzed,
    kind: NoiseKind,
    samples: usize,
    seed: u64,
) -> Result<EnergyRow> {
    let mass = &mesh.ops.mass;
    let sampler = NoiseSampler::from_operators(&mesh.ops.laplacian, mass, kind)?;
    let mut energies = Vec::with_capacity(samples);
    stream::for_each_chunk(&sampler, samples, 1, seed, CHUNK, |batch, _| {
        energies.extend((0..batch.samples()).map(|s| energy(batch.sample(s), mass)));
        Ok(())
    })?;
    let theory = spectrum::eigenpair_free_energy(kind, mass);
    Ok(EnergyRow {
        figure: figure.to_owned(),
        mesh: mesh.label.clone(),
        vertices: mesh.vertices,
        kind: kind.to_string(),
        samples,
        energy: energy_of(&energies, theory),
    })
}

/// Per-frequency agreement of one kind between two meshes (frequencies
/// matched by index).
#[derive(Debug, Clone, Serialize)]
pub struct Agreement {
    /// Noise kind.
    pub kind: String,
    /// Label of mesh a.
    pub mesh_a: String,
    /// Label of mesh b.
    pub mesh_b: String,
    /// Frequencies compared.
    pub frequencies: usize,
    /// Largest `|std_b / std_a - 1|` over the first `min(64, K)` frequencies.
    pub max_relative_std_difference_first_64: f64,
    /// Median `std_b / std_a` over all compared frequencies.
    pub median_std_ratio: f64,
    /// Largest `W2 = |std_a - std_b|` relative to `std_a`, over all compared.
    pub max_relative_w2: f64,
    /// Largest `|lambda_a - lambda_b| / lambda_a` over the compared nonzero
    /// frequencies (the discretization's share of any difference).
    pub max_relative_eigenvalue_gap: f64,
    /// Per kept frequency: `(index, W2, std_b / std_a)`.
    pub kept: Vec<(usize, f64, f64)>,
    /// The full comparison (written to the CSV).
    #[serde(skip)]
    pub comparison: spectrum::SpectrumComparison,
}

/// Compares `a` and `b` (the same kind on two meshes) with [`spectrum::compare`].
pub fn agreement(a: &KindStats, b: &KindStats, keep: &[usize]) -> Agreement {
    let c = spectrum::compare(&a.report, &b.report);
    let ratio = |f: &spectrum::FrequencyComparison| f.std_ratio.unwrap_or(f64::NAN);
    let mut ratios: Vec<f64> = c.frequencies.iter().map(ratio).collect();
    ratios.sort_by(f64::total_cmp);
    let median = ratios.get(ratios.len() / 2).copied().unwrap_or(f64::NAN);
    let first = c
        .frequencies
        .iter()
        .take(64)
        .map(|f| (ratio(f) - 1.0).abs())
        .fold(0.0, f64::max);
    let rel_w2 = c
        .frequencies
        .iter()
        .filter(|f| f.std_a > 0.0)
        .map(|f| f.w2 / f.std_a)
        .fold(0.0, f64::max);
    // the zero modes (constants) have no meaningful relative gap
    let top = c
        .frequencies
        .iter()
        .map(|f| f.eigenvalue_a)
        .fold(0.0, f64::max);
    let gap = c
        .frequencies
        .iter()
        .filter(|f| f.eigenvalue_a > 1e-8 * top)
        .map(|f| f.eigenvalue_gap / f.eigenvalue_a)
        .fold(0.0, f64::max);
    let kept = keep
        .iter()
        .filter_map(|&i| c.frequencies.get(i).map(|f| (i, f.w2, ratio(f))))
        .collect();
    Agreement {
        kind: a.kind.clone(),
        mesh_a: a.mesh.clone(),
        mesh_b: b.mesh.clone(),
        frequencies: c.frequencies.len(),
        max_relative_std_difference_first_64: first,
        median_std_ratio: median,
        max_relative_w2: rel_w2,
        max_relative_eigenvalue_gap: gap,
        kept,
        comparison: c,
    }
}
