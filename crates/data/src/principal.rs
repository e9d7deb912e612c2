//! The **principal components** of a set of signals of one mesh: their mean
//! and the directions in which they vary most, under a vertex-weighted
//! inner product.
//!
//! Signals are `V x C` values (vertex-major, as in [`InMemorySignals`]);
//! with vertex weights `w` (the lumped masses over their sum) they are
//! compared by
//!
//! ```text
//! <a, b> = sum_v w_v sum_c a_vc b_vc
//! ```
//!
//! so the components do not depend on how finely a region is
//! triangulated. With `mu` the mean of the whole set and the fitted
//! signals `x_1 .. x_n` (all of them, or a subset chosen by the caller),
//! the directions `u_k` are the eigenvectors of the fitted signals'
//! scatter `sum_i (x_i - mu)(x_i - mu)^T` under `<., .>`, found through the
//! `n x n` Gram matrix `G_ij = <x_i - mu, x_j - mu>`: its eigenvectors
//! `a_k` with eigenvalues `g_k` give `u_k = sum_i a_ik (x_i - mu) /
//! sqrt(g_k)`, of unit norm, and `g_k = sum_i <x_i - mu, u_k>^2` is the
//! scatter along `u_k` ([`PrincipalComponents::scatter`]; the sample
//! variance along it is `g_k / (n - 1)`).
//!
//! Directions come in decreasing scatter; those with `g_k` below `1e-12`
//! of the total scatter (`trace(G)`) are left out, so a set of one signal,
//! or of identical ones, has none. Each direction's sign is fixed so that
//! the first fitted signal has a non-negative coordinate along it.
//!
//! Cost: `O(n^2 V C)` for the Gram matrix (parallel over rows), `O(n^3)`
//! for its eigenvectors, `O(n V C)` per direction kept.
//!
//! # Example
//! ```
//! use mfm_data::InMemorySignals;
//! use mfm_data::principal::PrincipalComponents;
//!
//! // three one-vertex, two-channel signals on a line through (1, 1)
//! let set = InMemorySignals::new(vec![0.0, 0.0, 1.0, 1.0, 2.0, 2.0], 3, 1, 2).unwrap();
//! let pc = PrincipalComponents::fit(&set, &[0, 1, 2], &[1.0], 8).unwrap();
//! assert_eq!(pc.mean(), &[1.0, 1.0]);
//! assert_eq!(pc.len(), 1);
//! let u = pc.direction(0);
//! // the diagonal, pointing away from the first signal (which sits below the mean)
//! assert!((u[0] + 0.5f64.sqrt()).abs() < 1e-12 && (u[1] + 0.5f64.sqrt()).abs() < 1e-12);
//! assert!((pc.scatter()[0] - 4.0).abs() < 1e-12);
//! ```

use faer::{Mat, Side};
use rayon::prelude::*;

use crate::{DataError, InMemorySignals, Result, SignalSource};

/// Scatter below this share of the total is no direction.
const NEGLIGIBLE_SCATTER: f64 = 1e-12;

/// The mean of a signal set and its leading principal directions (see the
/// [module docs](self)).
#[derive(Clone, Debug, PartialEq)]
pub struct PrincipalComponents {
    weights: Vec<f64>,
    channels: usize,
    mean: Vec<f64>,
    directions: Vec<Vec<f64>>,
    scatter: Vec<f64>,
    total: f64,
    fitted_on: usize,
}

impl PrincipalComponents {
    /// The mean of all of `set` and at most `max_directions` principal
    /// directions of its signals `fitted` (indices into `set`), with vertex
    /// weights `weights` (one per vertex, any positive scale: they are
    /// divided by their sum).
    ///
    /// # Errors
    /// [`DataError::Config`] for an empty set or no fitted signal, an
    /// index out of range, or weights whose sum is not finite and positive
    /// (or a negative weight); [`DataError::SizeMismatch`] for weights that
    /// are not one per vertex.
    pub fn fit(
        set: &InMemorySignals,
        fitted: &[usize],
        weights: &[f64],
        max_directions: usize,
    ) -> Result<Self> {
        if set.is_empty() || fitted.is_empty() {
            return Err(DataError::Config(format!(
                "principal components need at least one signal, found {} to fit of {}",
                fitted.len(),
                set.len()
            )));
        }
        if let Some(&i) = fitted.iter().find(|&&i| i >= set.len()) {
            return Err(DataError::Config(format!(
                "principal components: signal {i} to fit is beyond the set's {}",
                set.len()
            )));
        }
        if weights.len() != set.num_vertices() {
            return Err(DataError::SizeMismatch {
                what: "vertex weights (one per vertex of the signals)".into(),
                expected: set.num_vertices(),
                found: weights.len(),
            });
        }
        let sum: f64 = weights.iter().sum();
        if !(sum.is_finite() && sum > 0.0) || weights.iter().any(|&w| w < 0.0) {
            return Err(DataError::Config(format!(
                "principal components need non-negative vertex weights with a finite positive \
                 sum, found the sum {sum}"
            )));
        }
        let c = set.channels();
        let weights: Vec<f64> = weights.iter().map(|w| w / sum).collect();
        let mean = mean_signal(set);
        let n = fitted.len();
        // the fitted signals minus the mean, times sqrt(w), so that the
        // inner product is the plain dot product
        let scaled: Vec<Vec<f64>> = fitted
            .par_iter()
            .map(|&i| {
                set.signal(i)
                    .iter()
                    .zip(&mean)
                    .enumerate()
                    .map(|(j, (&x, m))| (f64::from(x) - m) * weights[j / c].sqrt())
                    .collect()
            })
            .collect();
        let rows: Vec<Vec<f64>> = (0..n)
            .into_par_iter()
            .map(|i| (0..=i).map(|j| dot(&scaled[i], &scaled[j])).collect())
            .collect();
        let gram = Mat::from_fn(n, n, |i, j| if j <= i { rows[i][j] } else { rows[j][i] });
        let total: f64 = (0..n).map(|i| rows[i][i]).sum();
        let eigen = gram.self_adjoint_eigen(Side::Lower).map_err(|e| {
            DataError::Config(format!(
                "the eigendecomposition of the {n} x {n} Gram matrix of the signals failed: {e:?}"
            ))
        })?;
        let (values, vectors) = (eigen.S(), eigen.U());
        let mut directions = Vec::new();
        let mut scatter = Vec::new();
        // eigenvalues ascend: the k-th largest is at n - 1 - k
        for col in (0..n).rev().take(max_directions) {
            let g = values[col];
            if !(total > 0.0 && g > NEGLIGIBLE_SCATTER * total) {
                break;
            }
            let sign = if vectors[(0, col)] < 0.0 { -1.0 } else { 1.0 };
            let scale = sign / g.sqrt();
            let mut u = vec![0.0; mean.len()];
            for (i, row) in scaled.iter().enumerate() {
                let a = vectors[(i, col)] * scale;
                // u = sum_i a_i (x_i - mu): undo the sqrt(w) of `scaled`
                for (j, (uj, x)) in u.iter_mut().zip(row).enumerate() {
                    let root = weights[j / c].sqrt();
                    if root > 0.0 {
                        *uj += a * x / root;
                    }
                }
            }
            directions.push(u);
            scatter.push(g);
        }
        Ok(Self {
            weights,
            channels: c,
            mean,
            directions,
            scatter,
            total,
            fitted_on: n,
        })
    }

    /// `mu`: the mean of the whole set, `V x C` values.
    pub fn mean(&self) -> &[f64] {
        &self.mean
    }

    /// Directions kept.
    pub fn len(&self) -> usize {
        self.directions.len()
    }

    /// Whether no direction was kept (one signal, or all alike).
    pub fn is_empty(&self) -> bool {
        self.directions.is_empty()
    }

    /// `u_k`, `V x C` values of unit norm under the weighted inner product
    /// (`k < len()`; panics otherwise).
    pub fn direction(&self, k: usize) -> &[f64] {
        &self.directions[k]
    }

    /// `g_k`: the fitted signals' scatter `sum_i <x_i - mu, u_k>^2` along
    /// each kept direction, decreasing.
    pub fn scatter(&self) -> &[f64] {
        &self.scatter
    }

    /// `trace(G)`: the fitted signals' total scatter about the mean (over
    /// all directions, kept or not).
    pub fn total_scatter(&self) -> f64 {
        self.total
    }

    /// How many signals the directions were fitted on.
    pub fn fitted_on(&self) -> usize {
        self.fitted_on
    }

    /// The vertex weights (summing to 1).
    pub fn weights(&self) -> &[f64] {
        &self.weights
    }

    /// `<y - mu, u_k>` for a signal `y` of the set's size (unchecked
    /// length; `k < len()`).
    pub fn coordinate(&self, signal: &[f32], k: usize) -> f64 {
        let c = self.channels;
        signal
            .iter()
            .zip(&self.mean)
            .zip(&self.directions[k])
            .enumerate()
            .map(|(j, ((&x, m), u))| self.weights[j / c] * (f64::from(x) - m) * u)
            .sum()
    }
}

/// The plain (unweighted) mean of a set's signals, value by value, in
/// `f64`; zeros for an empty set.
pub fn mean_signal(set: &InMemorySignals) -> Vec<f64> {
    let n = set.len();
    let mut mean = vec![0.0f64; set.num_vertices() * set.channels()];
    for i in 0..n {
        for (m, &x) in mean.iter_mut().zip(set.signal(i)) {
            *m += f64::from(x);
        }
    }
    mean.iter_mut().for_each(|m| *m /= n.max(1) as f64);
    mean
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}
