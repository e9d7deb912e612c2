//! Spectral diagnostics: the paper's three properties of a noise
//! distribution, measured on samples (docs/conventions.md, "Noise").
//!
//! A signal `f` (one value per vertex) has spectral coefficients
//! `c_i = phi_i^T M f` on the generalized eigenpairs `L phi_i = lambda_i M phi_i`
//! (`phi^T M phi = 1`, eigenvalues ascending) computed by
//! [`mfm_solver::generalized_eigenpairs`]. Every channel of every sample of a
//! [`NoiseBatch`] is one signal. Over a set of `N` signals this module
//! measures, for the first `K` frequencies (the eigenpairs given):
//!
//! 1. **independence**: the largest normalized off-diagonal entry
//!    `|S_ij| / sqrt(S_ii S_jj)` of the empirical second-moment matrix
//!    `S = (1/N) sum c c^T`, next to the level expected from sampling error
//!    alone for independent coefficients, `sqrt(2 ln(P) / N)` for `P` pairs
//!    (each sample correlation has a standard deviation of about
//!    `1 / sqrt(N)`, and the largest of `P` such values is about
//!    `sqrt(2 ln P)` of them);
//! 2. **mesh-invariant frequency statistics**: the empirical `Var(c_i)` next
//!    to its closed form ([`NoiseKind::spectral_variance`]; the ratio should be 1),
//!    and across two meshes ([`compare`]) the 2-Wasserstein distance between
//!    `N(0, s_a^2)` and `N(0, s_b^2)`, which is `|s_a - s_b|`, frequency by
//!    frequency (matched by index, with the eigenvalue gap);
//! 3. **bounded high-frequency content**: the mean total energy
//!    `E[f^T M f] = sum_i Var(c_i)` (over all `V` frequencies), next to the
//!    part captured by the first `K`.
//!
//! The mean of the noise is known to be zero, so "variance" here is the
//! second moment about zero, `(1/N) sum_n c_i^2` (unbiased, relative standard
//! deviation `sqrt(2 / N)` for Gaussian coefficients).
//!
//! # Example
//! ```
//! use mfm_geometry::{operators, procedural};
//! use mfm_noise::{NoiseKind, NoiseSampler, spectrum};
//!
//! let mesh = procedural::icosphere(2);
//! let sampler = NoiseSampler::new(&mesh, NoiseKind::Matern { tau: 10.0 }).unwrap();
//! let l = operators::cotangent_laplacian(&mesh);
//! let pairs = spectrum::eigenpairs(&l, sampler.mass(), 16).unwrap();
//! let theory = sampler.theory(&pairs).unwrap();
//! let batch = sampler.sample(2000, 1, 7).unwrap();
//! let report = spectrum::analyze(&pairs, sampler.mass(), &batch, Some(&theory)).unwrap();
//! // empirical variances within ~4.5 standard errors (sqrt(2/2000) = 3.2%) of 1/(lambda+tau)^2
//! assert!(report.max_relative_error.unwrap() < 0.15);
//! assert!(report.independence.max_abs_correlation < 2.0 * report.independence.reference);
//! ```

use faer::linalg::matmul::matmul;
use faer::sparse::SparseColMat;
use faer::{Accum, Mat, MatRef, Par};
pub use mfm_solver::Eigenpairs;
use mfm_solver::{EigenOptions, generalized_eigenpairs};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::error::{NoiseError, Result};
use crate::kind::NoiseKind;
use crate::sampler::{NoiseBatch, NoiseSampler};

/// Signals projected together by one task of the analysis (a fixed size, so
/// the sums do not depend on the thread count).
const CHUNK: usize = 256;

/// The `k` smallest generalized eigenpairs `L phi = lambda M phi` of a mesh
/// (`l` the PSD cotangent Laplacian, `mass` the lumped mass), ascending and
/// `M`-orthonormal: [`mfm_solver::generalized_eigenpairs`] with its default
/// options (dense up to 1000 vertices, shift-invert Krylov beyond).
///
/// # Errors
/// [`NoiseError::Solver`] (e.g. `k > V`, or no convergence).
pub fn eigenpairs(l: &SparseColMat<usize, f64>, mass: &[f64], k: usize) -> Result<Eigenpairs> {
    Ok(generalized_eigenpairs(
        l,
        mass,
        k,
        &EigenOptions::default(),
    )?)
}

/// Closed-form spectral statistics of a [`NoiseKind`] on one mesh.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Theory {
    /// The kind these numbers describe.
    pub kind: NoiseKind,
    /// `Var(c_i)` for each eigenpair given (see [`NoiseKind::spectral_variance`]).
    pub variance: Vec<f64>,
    /// `E[f^T M f]` where a closed form exists without all `V` eigenpairs:
    /// naive `sum_v m_v` (the surface area), white `V`, explicit
    /// `sum_{i<k} 1 / (lambda_i + tau)^2` (needs `k` pairs); `None` for the
    /// Matérn kinds.
    pub energy: Option<f64>,
}

/// `E[f^T M f]` of the kinds whose expected energy needs no eigenpairs:
/// naive `sum_v m_v` (the surface area), white `V`; `None` for the others.
pub fn eigenpair_free_energy(kind: NoiseKind, mass: &[f64]) -> Option<f64> {
    match kind {
        NoiseKind::Naive => Some(mass.iter().sum()),
        NoiseKind::White => Some(mass.len() as f64),
        _ => None,
    }
}

impl Theory {
    /// The closed forms of `kind` on the mesh with eigenpairs `pairs`, mass
    /// `mass` and `gamma = ||M^-1 L||_F`.
    ///
    /// # Errors
    /// As [`NoiseKind::spectral_variance`].
    pub fn new(kind: NoiseKind, pairs: &Eigenpairs, mass: &[f64], gamma: f64) -> Result<Self> {
        let variance = kind.spectral_variance(pairs, mass, gamma)?;
        let energy = match kind {
            NoiseKind::Explicit { k, .. } if k <= pairs.values.len() => {
                Some(variance.iter().take(k).sum())
            }
            _ => eigenpair_free_energy(kind, mass),
        };
        Ok(Self {
            kind,
            variance,
            energy,
        })
    }
}

pub(crate) fn check_vertices(pairs: &Eigenpairs, vertices: usize) -> Result<()> {
    if pairs.vectors.nrows() != vertices {
        return Err(NoiseError::SizeMismatch {
            what: "eigenvector length (vertices)",
            expected: vertices,
            found: pairs.vectors.nrows(),
        });
    }
    if pairs.vectors.ncols() != pairs.values.len() {
        return Err(NoiseError::SizeMismatch {
            what: "eigenvector count",
            expected: pairs.values.len(),
            found: pairs.vectors.ncols(),
        });
    }
    Ok(())
}

/// Spectral coefficients `c_i = phi_i^T M f` of one signal `f` (one value
/// per vertex) on every eigenpair of `pairs`. Cost `O(V K)`.
///
/// # Errors
/// [`NoiseError::SizeMismatch`] if the lengths disagree.
pub fn project(pairs: &Eigenpairs, mass: &[f64], signal: &[f64]) -> Result<Vec<f64>> {
    check_vertices(pairs, mass.len())?;
    if signal.len() != mass.len() {
        return Err(NoiseError::SizeMismatch {
            what: "signal length",
            expected: mass.len(),
            found: signal.len(),
        });
    }
    Ok((0..pairs.values.len())
        .map(|i| {
            pairs
                .vectors
                .col(i)
                .iter()
                .zip(mass.iter().zip(signal))
                .map(|(p, (m, f))| p * m * f)
                .sum()
        })
        .collect())
}

/// Independence of the coefficients (property 1).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Independence {
    /// Largest `|S_ij| / sqrt(S_ii S_jj)` over pairs `i < j` of active
    /// frequencies (those with a nonzero theoretical variance when a theory
    /// is given, else those whose empirical variance exceeds `1e-20` of the
    /// largest).
    pub max_abs_correlation: f64,
    /// The pair `[i, j]` where it occurs (`None` with fewer than two active
    /// frequencies).
    pub pair: Option<[usize; 2]>,
    /// Number of pairs examined.
    pub pairs: usize,
    /// Level expected from sampling error for independent coefficients,
    /// `sqrt(2 ln(max(pairs, 2)) / N)`.
    pub reference: f64,
}

/// Per-frequency statistics of a set of signals on one mesh (serializable to
/// JSON). See the [module docs](self) for the definitions.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SpectrumReport {
    /// The noise kind of the theory the variances were compared with.
    pub kind: Option<NoiseKind>,
    /// Vertices of the mesh.
    pub num_vertices: usize,
    /// Signals analysed (samples times channels).
    pub num_signals: usize,
    /// `lambda_i`, ascending.
    pub eigenvalues: Vec<f64>,
    /// Empirical mean of `c_i`.
    pub mean: Vec<f64>,
    /// Empirical `Var(c_i)` (second moment about zero).
    pub variance: Vec<f64>,
    /// Theoretical `Var(c_i)`, when a theory was given.
    pub theory: Option<Vec<f64>>,
    /// `variance / theory` where the theory is positive (`None` entries
    /// where it is zero).
    pub ratio: Option<Vec<Option<f64>>>,
    /// `max_i |ratio_i - 1|` over the frequencies with a ratio.
    pub max_relative_error: Option<f64>,
    /// Property 1: independence.
    pub independence: Independence,
    /// Property 3: mean `f^T M f` over the signals.
    pub mean_energy: f64,
    /// `sum_i variance_i` over the `K` analysed frequencies: the part of the
    /// energy they carry.
    pub captured_energy: f64,
    /// Closed-form `E[f^T M f]`, when known (see [`Theory::energy`]).
    pub theory_energy: Option<f64>,
}

/// Streaming spectral analysis: add batches of signals, then read a
/// [`SpectrumReport`]. Keeps `K x K` sums, plus every coefficient of the
/// frequencies chosen with [`SpectralAnalyzer::keep`] (for histograms).
///
/// Cost per signal: `O(V K + K^2)` (a dense product, parallel over fixed
/// chunks of 256 signals; the sums are combined in a fixed order, so the
/// result does not depend on the thread count).
#[derive(Debug, Clone)]
pub struct SpectralAnalyzer<'a> {
    pairs: &'a Eigenpairs,
    mass: &'a [f64],
    count: usize,
    sum: Vec<f64>,
    second: Mat<f64>,
    energy: f64,
    keep: Vec<usize>,
    kept: Vec<Vec<f64>>,
}

impl<'a> SpectralAnalyzer<'a> {
    /// An empty analysis on `pairs` (eigenpairs of the mesh) and `mass`.
    ///
    /// # Errors
    /// [`NoiseError::SizeMismatch`] if the vertex counts disagree.
    pub fn new(pairs: &'a Eigenpairs, mass: &'a [f64]) -> Result<Self> {
        check_vertices(pairs, mass.len())?;
        let k = pairs.values.len();
        Ok(Self {
            pairs,
            mass,
            count: 0,
            sum: vec![0.0; k],
            second: Mat::zeros(k, k),
            energy: 0.0,
            keep: Vec::new(),
            kept: Vec::new(),
        })
    }

    /// Also records every coefficient `c_i` for `i` in `frequencies` (those
    /// at or beyond `K` are ignored), from the next batch on.
    pub fn keep(mut self, frequencies: &[usize]) -> Self {
        for &i in frequencies {
            if i < self.pairs.values.len() && !self.keep.contains(&i) {
                self.keep.push(i);
                self.kept.push(Vec::new());
            }
        }
        self
    }

    /// Number of signals added so far.
    pub fn num_signals(&self) -> usize {
        self.count
    }

    /// The recorded coefficients of frequency `i` (`None` if not kept).
    pub fn coefficients(&self, i: usize) -> Option<&[f64]> {
        self.keep
            .iter()
            .position(|&j| j == i)
            .map(|p| self.kept[p].as_slice())
    }

    /// Adds every channel of every sample of `batch` as a signal.
    ///
    /// # Errors
    /// [`NoiseError::SizeMismatch`] if the batch has another vertex count.
    pub fn add(&mut self, batch: &NoiseBatch) -> Result<()> {
        let v = self.mass.len();
        if batch.vertices() != v {
            return Err(NoiseError::SizeMismatch {
                what: "batch vertex count",
                expected: v,
                found: batch.vertices(),
            });
        }
        let total = batch.samples() * batch.channels();
        let k = self.pairs.values.len();
        let partials: Vec<Partial> = (0..total.div_ceil(CHUNK))
            .into_par_iter()
            .map(|chunk| {
                let lo = chunk * CHUNK;
                let hi = (lo + CHUNK).min(total);
                self.partial(batch, lo, hi, k)
            })
            .collect();
        for p in partials {
            self.count += p.count;
            self.energy += p.energy;
            self.sum.iter_mut().zip(&p.sum).for_each(|(a, b)| *a += b);
            self.second += &p.second;
            for (dst, src) in self.kept.iter_mut().zip(p.kept) {
                dst.extend(src);
            }
        }
        Ok(())
    }

    /// Statistics of signals `lo..hi` of `batch` (signal `j` is sample
    /// `j / C`, channel `j % C`).
    fn partial(&self, batch: &NoiseBatch, lo: usize, hi: usize, k: usize) -> Partial {
        let v = self.mass.len();
        let ch = batch.channels();
        let b = hi - lo;
        let mut weighted = vec![0.0; v * b];
        let mut energy = 0.0;
        for (j, col) in weighted.chunks_mut(v.max(1)).enumerate() {
            let (s, c) = ((lo + j) / ch, (lo + j) % ch);
            let signal = batch.sample(s).iter().skip(c).step_by(ch);
            let mut e = 0.0;
            for ((dst, &m), f) in col.iter_mut().zip(self.mass).zip(signal) {
                *dst = m * f;
                e += m * f * f;
            }
            energy += e;
        }
        let weighted = MatRef::from_column_major_slice(&weighted, v, b);
        let mut coef = Mat::<f64>::zeros(k, b);
        matmul(
            coef.as_mut(),
            Accum::Replace,
            self.pairs.vectors.transpose(),
            weighted,
            1.0,
            Par::Seq,
        );
        let mut second = Mat::<f64>::zeros(k, k);
        matmul(
            second.as_mut(),
            Accum::Replace,
            coef.as_ref(),
            coef.transpose(),
            1.0,
            Par::Seq,
        );
        let sum = (0..k).map(|i| coef.row(i).iter().sum()).collect();
        let kept = self
            .keep
            .iter()
            .map(|&i| coef.row(i).iter().copied().collect())
            .collect();
        Partial {
            count: b,
            energy,
            sum,
            second,
            kept,
        }
    }

    /// The report so far, compared with `theory` when given.
    ///
    /// # Errors
    /// [`NoiseError::SizeMismatch`] if `theory` does not have one variance
    /// per eigenpair; [`NoiseError::InvalidParameter`] if no signal was added.
    pub fn report(&self, theory: Option<&Theory>) -> Result<SpectrumReport> {
        let k = self.pairs.values.len();
        if let Some(t) = theory
            && t.variance.len() != k
        {
            return Err(NoiseError::SizeMismatch {
                what: "theoretical variance count",
                expected: k,
                found: t.variance.len(),
            });
        }
        if self.count == 0 {
            return Err(NoiseError::InvalidParameter {
                name: "signals",
                expected: "at least one signal added before the report",
                found: "0".to_owned(),
            });
        }
        let n = self.count as f64;
        let mean: Vec<f64> = self.sum.iter().map(|s| s / n).collect();
        let variance: Vec<f64> = (0..k).map(|i| self.second[(i, i)] / n).collect();
        let (ratio, max_relative_error) = match theory {
            Some(t) => {
                let r: Vec<Option<f64>> = variance
                    .iter()
                    .zip(&t.variance)
                    .map(|(e, t)| (*t > 0.0).then(|| e / t))
                    .collect();
                let worst = r.iter().flatten().map(|x| (x - 1.0).abs()).reduce(f64::max);
                (Some(r), worst)
            }
            None => (None, None),
        };
        let vmax = variance.iter().copied().fold(0.0, f64::max);
        let active: Vec<usize> = (0..k)
            .filter(|&i| match theory {
                Some(t) => t.variance[i] > 0.0,
                None => variance[i] > 1e-20 * vmax,
            })
            .filter(|&i| variance[i] > 0.0)
            .collect();
        let mut best = (0.0, None);
        for (a, &i) in active.iter().enumerate() {
            for &j in &active[a + 1..] {
                let r = (self.second[(i, j)] / (self.second[(i, i)] * self.second[(j, j)]).sqrt())
                    .abs();
                if r > best.0 {
                    best = (r, Some([i, j]));
                }
            }
        }
        let pairs = active.len() * active.len().saturating_sub(1) / 2;
        let independence = Independence {
            max_abs_correlation: best.0,
            pair: best.1,
            pairs,
            reference: (2.0 * (pairs.max(2) as f64).ln() / n).sqrt(),
        };
        Ok(SpectrumReport {
            kind: theory.map(|t| t.kind),
            num_vertices: self.mass.len(),
            num_signals: self.count,
            eigenvalues: self.pairs.values.clone(),
            mean,
            captured_energy: variance.iter().sum(),
            variance,
            theory: theory.map(|t| t.variance.clone()),
            ratio,
            max_relative_error,
            independence,
            mean_energy: self.energy / n,
            theory_energy: theory.and_then(|t| t.energy),
        })
    }
}

struct Partial {
    count: usize,
    energy: f64,
    sum: Vec<f64>,
    second: Mat<f64>,
    kept: Vec<Vec<f64>>,
}

/// One-shot analysis of `batch` ([`SpectralAnalyzer`] with a single batch).
///
/// # Errors
/// As [`SpectralAnalyzer::new`], [`SpectralAnalyzer::add`] and
/// [`SpectralAnalyzer::report`].
pub fn analyze(
    pairs: &Eigenpairs,
    mass: &[f64],
    batch: &NoiseBatch,
    theory: Option<&Theory>,
) -> Result<SpectrumReport> {
    let mut a = SpectralAnalyzer::new(pairs, mass)?;
    a.add(batch)?;
    a.report(theory)
}

/// The spectrum of one mesh (one entry of the `mfm spectrum` report).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MeshSpectrum {
    /// The mesh as the user named it (a path or a builtin).
    pub mesh: String,
    /// Its vertex count.
    pub vertices: usize,
    /// `Gamma = ||M^-1 L||_F` of the mesh.
    pub gamma: f64,
    /// The empirical spectrum against the theory.
    pub report: SpectrumReport,
}

/// The coefficients [`MeshSpectrum::measure`] keeps: `(frequency, c_i of
/// every sample)`.
pub type KeptCoefficients = Vec<(usize, Vec<f64>)>;

/// What [`MeshSpectrum::measure`] draws and keeps.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct SpectrumRequest {
    /// Samples `0..samples` of the seed (at least 2).
    pub samples: usize,
    /// Eigenpairs (frequencies), at most the mesh's vertices.
    pub k: usize,
    /// The seed (the same sample indices on every mesh).
    pub seed: u64,
    /// Frequencies whose coefficients are returned (for histograms).
    pub keep: Vec<usize>,
}

/// A [`MeshSpectrum::measure_on`] result: the spectrum, the kept
/// coefficients, and where the time went.
#[derive(Debug, Clone)]
pub struct Measured {
    /// The spectrum.
    pub spectrum: MeshSpectrum,
    /// The coefficients of the requested frequencies.
    pub kept: KeptCoefficients,
    /// Seconds spent drawing the samples.
    pub sample_seconds: f64,
    /// Seconds spent projecting them on the eigenvectors, in the caller's
    /// `each` and in the report.
    pub analysis_seconds: f64,
}

impl MeshSpectrum {
    /// Streams one channel of samples of `sampler` (built from `ops`, the
    /// operators of the mesh named `name`, e.g. with
    /// [`NoiseSampler::from_operators`]) through a [`SpectralAnalyzer`] on
    /// the `k` lowest eigenpairs ([`eigenpairs`]) and reports against the
    /// kind's [`Theory`]. Returns the spectrum and the coefficients of the
    /// `keep` frequencies below `k` (in the order given, others left out);
    /// `progress(done)` is called after each chunk.
    ///
    /// Cost: one eigensolve, then `O(samples (V k))`.
    ///
    /// # Errors
    /// [`NoiseError::InvalidParameter`] for fewer than 2 samples or `k`
    /// outside `1..=V`; eigensolver and sampler errors.
    pub fn measure(
        name: &str,
        ops: &mfm_geometry::operators::Operators,
        sampler: &NoiseSampler,
        request: &SpectrumRequest,
        mut progress: impl FnMut(usize),
    ) -> Result<(Self, KeptCoefficients)> {
        let v = ops.mass.len();
        if request.samples < 2 || request.k == 0 || request.k > v {
            return Err(NoiseError::InvalidParameter {
                name: "samples, k",
                expected: "at least 2 samples and 1..=V eigenpairs",
                found: format!(
                    "{} samples, k = {} on {v} vertices",
                    request.samples, request.k
                ),
            });
        }
        let pairs = eigenpairs(&ops.laplacian, &ops.mass, request.k)?;
        let measured = Self::measure_on(
            name,
            ops,
            &pairs,
            sampler,
            request,
            crate::stream::CHUNK,
            |b, first| {
                progress(first + b.samples());
                Ok(())
            },
        )?;
        Ok((measured.spectrum, measured.kept))
    }

    /// [`MeshSpectrum::measure`] on eigenpairs computed before (one
    /// eigensolve shared by several kinds on one mesh), in chunks of
    /// `chunk` samples (statistics summed per chunk depend on its size in
    /// their last bits, see [`crate::stream`]); `each(batch, first)` sees
    /// every chunk after the analyzer has, for statistics the report does
    /// not hold. `request.k` must be the number of `pairs`.
    ///
    /// Cost: `O(samples (V k))`.
    ///
    /// # Errors
    /// [`NoiseError::InvalidParameter`] for fewer than 2 samples or a `k`
    /// other than the pairs'; sampler errors and those `each` returns.
    #[allow(clippy::too_many_arguments)]
    pub fn measure_on(
        name: &str,
        ops: &mfm_geometry::operators::Operators,
        pairs: &Eigenpairs,
        sampler: &NoiseSampler,
        request: &SpectrumRequest,
        chunk: usize,
        mut each: impl FnMut(&NoiseBatch, usize) -> Result<()>,
    ) -> Result<Measured> {
        if request.samples < 2 || request.k != pairs.values.len() {
            return Err(NoiseError::InvalidParameter {
                name: "samples, k",
                expected: "at least 2 samples and k = the number of eigenpairs",
                found: format!(
                    "{} samples, k = {} with {} eigenpairs",
                    request.samples,
                    request.k,
                    pairs.values.len()
                ),
            });
        }
        let theory = sampler.theory(pairs)?;
        let mut analyzer = SpectralAnalyzer::new(pairs, &ops.mass)?.keep(&request.keep);
        let (samples, seed) = (request.samples, request.seed);
        // the consumer times itself; the rest of the loop is sampling
        let mut analysis_seconds = 0.0;
        let start = std::time::Instant::now();
        crate::stream::for_each_chunk(sampler, samples, 1, seed, chunk, |b, first| {
            let t = std::time::Instant::now();
            analyzer.add(b)?;
            each(b, first)?;
            analysis_seconds += t.elapsed().as_secs_f64();
            Ok(())
        })?;
        let sample_seconds = start.elapsed().as_secs_f64() - analysis_seconds;
        let t = std::time::Instant::now();
        let report = analyzer.report(Some(&theory))?;
        analysis_seconds += t.elapsed().as_secs_f64();
        let kept = request
            .keep
            .iter()
            .filter_map(|&i| analyzer.coefficients(i).map(|c| (i, c.to_vec())))
            .collect();
        let spectrum = Self {
            mesh: name.to_owned(),
            vertices: ops.mass.len(),
            gamma: sampler.gamma(),
            report,
        };
        Ok(Measured {
            spectrum,
            kept,
            sample_seconds,
            analysis_seconds,
        })
    }
}

#[cfg(feature = "cli-output")]
impl MeshSpectrum {
    /// The spectrum on one line: sizes, the largest relative variance
    /// error, the largest correlation against its sampling level, the
    /// mean energy (what `mfm spectrum` prints per mesh).
    pub fn summary(&self) -> String {
        let r = &self.report;
        format!(
            "{}: {} vertices, {} samples, {} frequencies; largest |Var/theory - 1| = {:.3}; \
max |corr| = {:.3} (sampling level {:.3}); mean f^T M f = {:.4e}",
            self.mesh,
            self.vertices,
            r.num_signals,
            r.eigenvalues.len(),
            r.max_relative_error.unwrap_or(f64::NAN),
            r.independence.max_abs_correlation,
            r.independence.reference,
            r.mean_energy
        )
    }
}

#[cfg(feature = "cli-output")]
impl SpectrumFile {
    /// One line per later mesh against the first: the largest `W2` and
    /// relative standard-deviation difference over the frequencies.
    pub fn comparison_lines(&self) -> Vec<String> {
        let first = self.meshes.first().map_or("", |m| m.mesh.as_str());
        self.meshes
            .iter()
            .skip(1)
            .zip(&self.comparisons)
            .map(|(m, c)| {
                format!(
                    "{} vs {first}: max W2 = {:.3e}, max |std ratio - 1| = {:.3}",
                    m.mesh, c.max_w2, c.max_relative_std_difference
                )
            })
            .collect()
    }

    /// The report of `meshes` (the first is the reference), with each later
    /// mesh [`compare`]d with the first.
    pub fn new(
        kind: NoiseKind,
        samples: usize,
        k: usize,
        seed: u64,
        meshes: Vec<MeshSpectrum>,
    ) -> Self {
        let comparisons = meshes
            .iter()
            .skip(1)
            .map(|m| compare(&meshes[0].report, &m.report))
            .collect();
        Self {
            kind,
            samples,
            k,
            seed,
            meshes,
            comparisons,
        }
    }
}

#[cfg(feature = "cli-output")]
/// The report of `mfm spectrum`: one noise kind's spectrum on several
/// meshes, each later mesh compared with the first.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SpectrumFile {
    /// The noise kind.
    pub kind: NoiseKind,
    /// Samples per mesh.
    pub samples: usize,
    /// Eigenpairs per mesh.
    pub k: usize,
    /// The seed (the same sample indices on every mesh).
    pub seed: u64,
    /// The meshes, in the order given.
    pub meshes: Vec<MeshSpectrum>,
    /// Each later mesh against the first, frequency by frequency.
    pub comparisons: Vec<SpectrumComparison>,
}

/// One frequency of a [`SpectrumComparison`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FrequencyComparison {
    /// Frequency index `i` (matched by index between the meshes).
    pub index: usize,
    /// `lambda_i` on mesh a.
    pub eigenvalue_a: f64,
    /// `lambda_i` on mesh b.
    pub eigenvalue_b: f64,
    /// `|lambda_a - lambda_b|`.
    pub eigenvalue_gap: f64,
    /// Empirical standard deviation of `c_i` on mesh a.
    pub std_a: f64,
    /// Empirical standard deviation of `c_i` on mesh b.
    pub std_b: f64,
    /// `std_b / std_a` (`None` when `std_a == 0`).
    pub std_ratio: Option<f64>,
    /// `W2(N(0, std_a^2), N(0, std_b^2)) = |std_a - std_b|`.
    pub w2: f64,
}

/// Per-frequency comparison of two meshes' spectra (property 2 across
/// triangulations).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SpectrumComparison {
    /// One entry per frequency present in both reports.
    pub frequencies: Vec<FrequencyComparison>,
    /// Largest `w2`.
    pub max_w2: f64,
    /// Largest `|std_ratio - 1|`.
    pub max_relative_std_difference: f64,
}

/// Compares two reports frequency by frequency (the first
/// `min(K_a, K_b)` frequencies).
///
/// # Example
/// ```
/// use mfm_noise::spectrum::{compare, SpectrumReport, Independence};
/// let report = |variance: Vec<f64>| SpectrumReport {
///     kind: None, num_vertices: 10, num_signals: 100,
///     eigenvalues: vec![0.0, 1.0], mean: vec![0.0; 2], variance,
///     theory: None, ratio: None, max_relative_error: None,
///     independence: Independence { max_abs_correlation: 0.0, pair: None, pairs: 1, reference: 0.1 },
///     mean_energy: 1.0, captured_energy: 1.0, theory_energy: None,
/// };
/// let c = compare(&report(vec![4.0, 1.0]), &report(vec![1.0, 1.0]));
/// assert_eq!(c.frequencies[0].w2, 1.0); // |2 - 1|
/// assert_eq!(c.max_relative_std_difference, 0.5);
/// ```
pub fn compare(a: &SpectrumReport, b: &SpectrumReport) -> SpectrumComparison {
    let k = a.variance.len().min(b.variance.len());
    let frequencies: Vec<FrequencyComparison> = (0..k)
        .map(|i| {
            let (sa, sb) = (a.variance[i].sqrt(), b.variance[i].sqrt());
            let (la, lb) = (a.eigenvalues[i], b.eigenvalues[i]);
            FrequencyComparison {
                index: i,
                eigenvalue_a: la,
                eigenvalue_b: lb,
                eigenvalue_gap: (la - lb).abs(),
                std_a: sa,
                std_b: sb,
                std_ratio: (sa > 0.0).then(|| sb / sa),
                w2: (sa - sb).abs(),
            }
        })
        .collect();
    let max_w2 = frequencies.iter().map(|f| f.w2).fold(0.0, f64::max);
    let max_relative_std_difference = frequencies
        .iter()
        .filter_map(|f| f.std_ratio)
        .map(|r| (r - 1.0).abs())
        .fold(0.0, f64::max);
    SpectrumComparison {
        frequencies,
        max_w2,
        max_relative_std_difference,
    }
}
