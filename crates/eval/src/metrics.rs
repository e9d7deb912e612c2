//! Evaluation metrics for sets of signals on one mesh (docs/metrics.md,
//! the paper's supplementary "Evaluation Metrics").
//!
//! Every metric is built on the **mass-weighted L2 distance** between two
//! signals `a`, `b` (each `V x C`, vertex-major) on a mesh with lumped vertex
//! masses `m`:
//!
//! ```text
//! d(a, b) = sqrt( sum_v m_v |a_v - b_v|^2 / sum_v m_v )
//! ```
//!
//! (`|.|` the Euclidean norm over the `C` channels). It is the root mean
//! square difference over the *surface*, so it does not depend on how finely
//! a region is triangulated. With generated samples `g_1..g_n` and reference
//! samples `r_1..r_k`:
//!
//! - **MMD** (minimum matching distance, lower is better):
//!   `mean_i min_j d(g_i, r_j)`, the mean over *generated* samples of the
//!   distance to the closest reference sample, as the paper states it.
//! - **COV** (coverage, higher is better): the fraction of reference samples
//!   that are the nearest reference sample of at least one generated sample.
//! - **1-NNA** (1-nearest-neighbour accuracy; 0.5 is ideal): on the union of
//!   both sets, each sample is classified by the set its nearest *other*
//!   sample belongs to (leave-one-out); the score is the fraction classified
//!   correctly. Near 1 when the sets are easy to tell apart; near 0 when every
//!   generated sample duplicates a reference one (memorization).
//! - **GMM test error** (lower is better): the mass-weighted mean absolute
//!   difference between the point-wise means of the two sets,
//!   `sum_v m_v |mean_i g_i,v - mean_j r_j,v| / sum_v m_v`.
//!
//! Ties in nearest-neighbour searches go to the lowest index (generated
//! samples before reference samples for 1-NNA), so results are deterministic.
//!
//! Costs: the pairwise distances are `O(n k V C)` (parallel over rows with
//! rayon); 1-NNA also needs both within-set matrices, `O((n + k)^2 V C)` in
//! all. Memory: the matrices themselves, `8 (n + k)^2` bytes.
//!
//! # Example
//! ```
//! use mfm_eval::metrics::{evaluate, mass_weighted_distance};
//! use mfm_data::InMemorySignals;
//! let mass = [1.0, 1.0, 2.0];
//! // one channel, 3 vertices: d = sqrt((1*1 + 0 + 2*0) / 4) = 0.5
//! assert_eq!(mass_weighted_distance(&mass, 1, &[1.0, 0.0, 0.0], &[0.0, 0.0, 0.0]).unwrap(), 0.5);
//! let set = InMemorySignals::new(vec![0.0, 0.0, 0.0, 1.0, 1.0, 1.0], 2, 3, 1).unwrap();
//! let m = evaluate(&mass, &set, &set).unwrap();
//! assert_eq!((m.mmd, m.cov, m.test_error), (0.0, 1.0, 0.0));
//! ```

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use mfm_data::{DataError, InMemorySignals, Result, SignalSource};

/// All metrics of one evaluation (see the [module docs](self) for the
/// definitions).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Metrics {
    /// Minimum matching distance (mean over generated samples of the distance
    /// to the closest reference sample). Lower is better.
    pub mmd: f64,
    /// Coverage: fraction of reference samples that are the nearest
    /// reference of some generated sample, in `[0, 1]`. Higher is better.
    pub cov: f64,
    /// Leave-one-out 1-nearest-neighbour accuracy on the union, in `[0, 1]`;
    /// 0.5 is ideal.
    pub one_nna: f64,
    /// GMM test error: mass-weighted mean absolute difference of the
    /// point-wise means. Lower is better.
    pub test_error: f64,
    /// Number of generated samples.
    pub num_generated: usize,
    /// Number of reference samples.
    pub num_reference: usize,
}

/// Mass-weighted distances between signals on one mesh: the masses
/// normalized to sum to 1, and the channel count.
#[derive(Clone, Debug)]
pub struct MassWeighted {
    weights: Vec<f64>,
    channels: usize,
}

impl MassWeighted {
    /// Normalizes `mass` (one non-negative value per vertex, positive sum).
    ///
    /// # Errors
    /// [`DataError::Config`] for an empty mass, a negative or non-finite mass,
    /// a zero total, or zero channels.
    pub fn new(mass: &[f64], channels: usize) -> Result<Self> {
        if channels == 0 {
            return Err(DataError::Config(
                "signals must have at least one channel".into(),
            ));
        }
        if mass.is_empty() {
            return Err(DataError::Config("the vertex mass is empty".into()));
        }
        if let Some(v) = mass.iter().position(|m| !(m.is_finite() && *m >= 0.0)) {
            return Err(DataError::Config(format!(
                "vertex mass must be finite and >= 0, found {} at vertex {v}",
                mass[v]
            )));
        }
        let total: f64 = mass.iter().sum();
        if !(total > 0.0 && total.is_finite()) {
            return Err(DataError::Config(format!(
                "the total vertex mass must be positive and finite, found {total}"
            )));
        }
        Ok(Self {
            weights: mass.iter().map(|m| m / total).collect(),
            channels,
        })
    }

    /// Number of vertices.
    pub fn num_vertices(&self) -> usize {
        self.weights.len()
    }

    /// Values per signal (`V x C`).
    fn signal_len(&self) -> usize {
        self.weights.len() * self.channels
    }

    /// Checks that `signals` lives on this mesh.
    fn check(&self, signals: &InMemorySignals, what: &str) -> Result<()> {
        if signals.num_vertices() != self.num_vertices() {
            return Err(DataError::SizeMismatch {
                what: format!("vertices of the {what} signals"),
                expected: self.num_vertices(),
                found: signals.num_vertices(),
            });
        }
        if signals.channels() != self.channels {
            return Err(DataError::SizeMismatch {
                what: format!("channels of the {what} signals"),
                expected: self.channels,
                found: signals.channels(),
            });
        }
        Ok(())
    }

    /// `d(a, b)` for two signals of `V x C` values (unchecked lengths).
    fn distance_unchecked(&self, a: &[f32], b: &[f32]) -> f64 {
        let c = self.channels;
        let sum: f64 = self
            .weights
            .iter()
            .zip(a.chunks_exact(c).zip(b.chunks_exact(c)))
            .map(|(w, (x, y))| {
                let sq: f64 = x
                    .iter()
                    .zip(y)
                    .map(|(p, q)| {
                        let d = f64::from(*p) - f64::from(*q);
                        d * d
                    })
                    .sum();
                w * sq
            })
            .sum();
        sum.sqrt()
    }

    /// `d(a, b)` for two signals of `V x C` values.
    ///
    /// # Errors
    /// [`DataError::SizeMismatch`] if a signal does not have `V x C` values.
    pub fn distance(&self, a: &[f32], b: &[f32]) -> Result<f64> {
        for (s, what) in [(a, "first signal"), (b, "second signal")] {
            if s.len() != self.signal_len() {
                return Err(DataError::SizeMismatch {
                    what: what.into(),
                    expected: self.signal_len(),
                    found: s.len(),
                });
            }
        }
        Ok(self.distance_unchecked(a, b))
    }

    /// The `x.len() x y.len()` matrix of distances `d(x_i, y_j)`, row-major.
    ///
    /// # Errors
    /// [`DataError::SizeMismatch`] if a set is not on this mesh.
    pub fn pairwise(&self, x: &InMemorySignals, y: &InMemorySignals) -> Result<DistanceMatrix> {
        self.check(x, "first")?;
        self.check(y, "second")?;
        let (rows, cols) = (x.len(), y.len());
        let mut values = vec![0.0; rows * cols];
        if cols > 0 {
            values
                .par_chunks_mut(cols)
                .enumerate()
                .for_each(|(i, row)| {
                    let a = x.signal(i);
                    for (j, out) in row.iter_mut().enumerate() {
                        *out = self.distance_unchecked(a, y.signal(j));
                    }
                });
        }
        Ok(DistanceMatrix { rows, cols, values })
    }

    /// The mass-weighted mean over vertices of `|mean(x)_v - mean(y)_v|`.
    ///
    /// # Errors
    /// [`DataError::SizeMismatch`] if a set is not on this mesh,
    /// [`DataError::Config`] if a set is empty.
    pub fn mean_abs_difference(&self, x: &InMemorySignals, y: &InMemorySignals) -> Result<f64> {
        self.check(x, "first")?;
        self.check(y, "second")?;
        let mx = pointwise_mean(x)?;
        let my = pointwise_mean(y)?;
        let c = self.channels;
        Ok(self
            .weights
            .iter()
            .zip(mx.chunks_exact(c).zip(my.chunks_exact(c)))
            .map(|(w, (a, b))| {
                let sq: f64 = a.iter().zip(b).map(|(p, q)| (p - q) * (p - q)).sum();
                w * sq.sqrt()
            })
            .sum())
    }
}

/// A dense, row-major matrix of distances.
#[derive(Clone, Debug, PartialEq)]
pub struct DistanceMatrix {
    /// Number of rows (samples of the first set).
    pub rows: usize,
    /// Number of columns (samples of the second set).
    pub cols: usize,
    /// `rows x cols` values, row-major.
    pub values: Vec<f64>,
}

impl DistanceMatrix {
    /// Entry `(i, j)`.
    pub fn get(&self, i: usize, j: usize) -> f64 {
        self.values[i * self.cols + j]
    }

    /// Row `i`.
    pub fn row(&self, i: usize) -> &[f64] {
        &self.values[i * self.cols..(i + 1) * self.cols]
    }

    /// Index and value of the smallest entry of row `i` (lowest index on
    /// ties), or `None` for an empty row.
    pub fn row_min(&self, i: usize) -> Option<(usize, f64)> {
        argmin(self.row(i).iter().copied().enumerate())
    }
}

/// The smallest value and its index; the first one on ties.
fn argmin(items: impl Iterator<Item = (usize, f64)>) -> Option<(usize, f64)> {
    items.fold(None, |best, (j, d)| match best {
        Some((_, b)) if b <= d => best,
        _ => Some((j, d)),
    })
}

/// Point-wise mean of a set of signals (`V x C` values, in `f64`).
fn pointwise_mean(x: &InMemorySignals) -> Result<Vec<f64>> {
    if x.is_empty() {
        return Err(DataError::Config(
            "cannot average an empty set of signals".into(),
        ));
    }
    let n = x.num_vertices() * x.channels();
    let mut mean = vec![0.0; n];
    for i in 0..x.len() {
        for (m, &v) in mean.iter_mut().zip(x.signal(i)) {
            *m += f64::from(v);
        }
    }
    let inv = 1.0 / x.len() as f64;
    mean.iter_mut().for_each(|m| *m *= inv);
    Ok(mean)
}

/// `d(a, b)` (see the [module docs](self)) for two signals of
/// `mass.len() x channels` values.
///
/// # Errors
/// As [`MassWeighted::new`] and [`MassWeighted::distance`].
pub fn mass_weighted_distance(mass: &[f64], channels: usize, a: &[f32], b: &[f32]) -> Result<f64> {
    MassWeighted::new(mass, channels)?.distance(a, b)
}

/// Minimum matching distance from a generated-by-reference distance matrix:
/// the mean over rows of the row minimum.
///
/// # Errors
/// [`DataError::Config`] if the matrix has no rows or no columns.
pub fn mmd(gen_ref: &DistanceMatrix) -> Result<f64> {
    check_non_empty(gen_ref)?;
    let total: f64 = (0..gen_ref.rows)
        .filter_map(|i| gen_ref.row_min(i).map(|(_, d)| d))
        .sum();
    Ok(total / gen_ref.rows as f64)
}

/// Coverage from a generated-by-reference distance matrix: the fraction of
/// columns that are the minimum of at least one row.
///
/// # Errors
/// [`DataError::Config`] if the matrix has no rows or no columns.
pub fn coverage(gen_ref: &DistanceMatrix) -> Result<f64> {
    check_non_empty(gen_ref)?;
    let mut hit = vec![false; gen_ref.cols];
    for i in 0..gen_ref.rows {
        if let Some((j, _)) = gen_ref.row_min(i) {
            hit[j] = true;
        }
    }
    Ok(hit.iter().filter(|&&h| h).count() as f64 / gen_ref.cols as f64)
}

/// Leave-one-out 1-nearest-neighbour accuracy from the three distance
/// matrices: generated x generated, generated x reference, reference x
/// reference.
///
/// # Errors
/// [`DataError::SizeMismatch`] if the shapes disagree, [`DataError::Config`] if
/// either set is empty.
pub fn one_nna(
    gen_gen: &DistanceMatrix,
    gen_ref: &DistanceMatrix,
    ref_ref: &DistanceMatrix,
) -> Result<f64> {
    check_non_empty(gen_ref)?;
    let (n, k) = (gen_ref.rows, gen_ref.cols);
    for (m, what, size) in [(gen_gen, "generated", n), (ref_ref, "reference", k)] {
        if m.rows != size || m.cols != size {
            return Err(DataError::SizeMismatch {
                what: format!("{what} x {what} distance matrix side"),
                expected: size,
                found: if m.rows != size { m.rows } else { m.cols },
            });
        }
    }
    // union order: generated 0..n, then reference n..n+k
    let correct_gen = (0..n)
        .filter(|&i| {
            let within = gen_gen
                .row(i)
                .iter()
                .copied()
                .enumerate()
                .filter(|&(j, _)| j != i);
            let across = gen_ref
                .row(i)
                .iter()
                .copied()
                .enumerate()
                .map(|(j, d)| (n + j, d));
            matches!(argmin(within.chain(across)), Some((j, _)) if j < n)
        })
        .count();
    let correct_ref = (0..k)
        .filter(|&i| {
            let across = (0..n).map(|j| (j, gen_ref.get(j, i)));
            let within = ref_ref
                .row(i)
                .iter()
                .copied()
                .enumerate()
                .filter(|&(j, _)| j != i)
                .map(|(j, d)| (n + j, d));
            matches!(argmin(across.chain(within)), Some((j, _)) if j >= n)
        })
        .count();
    Ok((correct_gen + correct_ref) as f64 / (n + k) as f64)
}

fn check_non_empty(m: &DistanceMatrix) -> Result<()> {
    if m.rows == 0 || m.cols == 0 {
        return Err(DataError::Config(format!(
            "metrics need non-empty generated and reference sets, found {} and {}",
            m.rows, m.cols
        )));
    }
    Ok(())
}

/// Computes every [`Metrics`] field for `generated` against `reference`, both
/// on the mesh whose lumped vertex masses are `mass`.
///
/// Cost: three distance matrices, `O((n + k)^2 V C)` (parallel).
///
/// # Errors
/// [`DataError::Config`] for an invalid mass or an empty set,
/// [`DataError::SizeMismatch`] if the sets do not live on the mesh or differ in
/// channels.
pub fn evaluate(
    mass: &[f64],
    generated: &InMemorySignals,
    reference: &InMemorySignals,
) -> Result<Metrics> {
    let metric = MassWeighted::new(mass, reference.channels())?;
    let gen_ref = metric.pairwise(generated, reference)?;
    let gen_gen = metric.pairwise(generated, generated)?;
    let ref_ref = metric.pairwise(reference, reference)?;
    Ok(Metrics {
        mmd: mmd(&gen_ref)?,
        cov: coverage(&gen_ref)?,
        one_nna: one_nna(&gen_gen, &gen_ref, &ref_ref)?,
        test_error: metric.mean_abs_difference(generated, reference)?,
        num_generated: generated.len(),
        num_reference: reference.len(),
    })
}

impl Metrics {
    /// [`evaluate`] as an associated function.
    ///
    /// # Errors
    /// As [`evaluate`].
    pub fn evaluate(
        mass: &[f64],
        generated: &InMemorySignals,
        reference: &InMemorySignals,
    ) -> Result<Self> {
        evaluate(mass, generated, reference)
    }
}
