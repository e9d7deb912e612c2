//! How training pairs noise samples with data signals (`train.coupling`).
//!
//! Flow matching trains on pairs `(x0, x1)` of a noise sample and a data
//! signal and the straight path between them. With the **independent**
//! coupling (the paper's, the default) the pairs are drawn independently:
//! paths cross, and the velocity the network must learn at a point is the
//! average over every pair whose path passes there. With **minibatch
//! optimal transport** (`"ot:P"`), each step draws a pool of `P` data
//! signals and `P` noise samples and pairs them by the assignment of least
//! total squared distance (the mass-weighted vertex distance of the run,
//! after centring when the run centres); the step then trains on the pairs
//! of the first `B` data signals of the pool (`B` the batch). Both
//! marginals stay what they were (every pool is `P` independent noise
//! samples and `P` positions of the data order, and the trained data are a
//! uniform part of the pool), while paths cross less: each noise sample
//! goes to a data signal near it.
//!
//! Measured on the shared horse gallop (`--preset cpu-deform` with `ot:42`,
//! a pool of the whole training set): no better than independent pairs
//! (docs/BENCHMARKS.md, "What the samples are"); in the noise's thousands
//! of dimensions the least-cost pairing of 42 is only 3% shorter than a
//! random one. No preset uses it.
//!
//! With a pool, the data order advances by `P` positions a step and the
//! noise stream by `P` samples (noise samples `s P .. s P + P` of the run's
//! seed at step `s`), so a run stays a pure function of its seed and step.
//!
//! # Example
//! ```
//! use mfm_fm::coupling::{Coupling, least_cost_assignment};
//! let c: Coupling = "ot:32".parse().unwrap();
//! assert_eq!(c, Coupling::MinibatchOt { pool: 32 });
//! assert_eq!(c.to_string(), "ot:32");
//! // costs[i][j]: noise i against data j; the cheapest pairing is 0-1, 1-0
//! let assignment = least_cost_assignment(&[5.0, 1.0, 1.0, 5.0], 2).unwrap();
//! assert_eq!(assignment, vec![1, 0]);
//! ```

use std::fmt;

use pathfinding::kuhn_munkres::kuhn_munkres_min;
use pathfinding::matrix::Matrix;
use rayon::prelude::*;
use serde::{Deserialize, Deserializer, Serialize, Serializer};

/// Largest pool of minibatch optimal transport: the assignment is cubic in
/// the pool and the pool's noise and data are drawn every step.
pub const MAX_POOL: usize = 1024;

/// How noise samples are paired with data signals in training (see the
/// [module docs](self)). In TOML: `"independent"` or `"ot:P"`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Coupling {
    /// Independent draws (the paper's).
    #[default]
    Independent,
    /// Least-cost assignment within a pool of `pool` noise samples and
    /// `pool` data signals; the step trains on the first `batch` pairs.
    MinibatchOt {
        /// `P`, at least the batch, at most [`MAX_POOL`].
        pool: usize,
    },
}

impl Coupling {
    /// `true` for the default, independent coupling.
    pub fn is_independent(&self) -> bool {
        *self == Self::Independent
    }

    /// Checks the pool against the run's batch.
    ///
    /// # Errors
    /// What is wrong, in words.
    pub fn validate(&self, batch: usize) -> std::result::Result<(), String> {
        match *self {
            Self::Independent => Ok(()),
            Self::MinibatchOt { pool } if pool < batch.max(2) || pool > MAX_POOL => Err(format!(
                "a pool of {pool}: it needs at least the batch ({batch}) and 2, at most {MAX_POOL}"
            )),
            Self::MinibatchOt { .. } => Ok(()),
        }
    }
}

impl fmt::Display for Coupling {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Independent => f.write_str("independent"),
            Self::MinibatchOt { pool } => write!(f, "ot:{pool}"),
        }
    }
}

impl std::str::FromStr for Coupling {
    type Err = String;

    fn from_str(s: &str) -> std::result::Result<Self, String> {
        let parts: Vec<&str> = s.trim().split(':').collect();
        match parts.as_slice() {
            ["independent"] => Ok(Self::Independent),
            ["ot", p] => p
                .parse()
                .map(|pool| Self::MinibatchOt { pool })
                .map_err(|_| format!("ot:P needs a whole number of pairs P, found {p:?}")),
            _ => Err(format!(
                "unknown coupling {s:?}; expected \"independent\" or \"ot:P\" (a pool of P)"
            )),
        }
    }
}

impl Serialize for Coupling {
    fn serialize<S: Serializer>(&self, s: S) -> std::result::Result<S::Ok, S::Error> {
        s.collect_str(self)
    }
}

impl<'de> Deserialize<'de> for Coupling {
    fn deserialize<D: Deserializer<'de>>(d: D) -> std::result::Result<Self, D::Error> {
        let s = String::deserialize(d)?;
        s.parse().map_err(serde::de::Error::custom)
    }
}

/// The assignment of least total cost of an `n x n` cost matrix (row-major,
/// `costs[i * n + j]` the cost of pairing row `i` with column `j`): the
/// column of every row. Exact up to the costs' rounding to 1e-12 of their
/// range (the solver, the Hungarian method of the `pathfinding` crate,
/// works on integers); ties go the same way on every run.
///
/// # Errors
/// What is wrong, in words: `costs` not `n x n`, or a cost that is not
/// finite.
pub fn least_cost_assignment(costs: &[f64], n: usize) -> std::result::Result<Vec<usize>, String> {
    if costs.len() != n * n {
        return Err(format!(
            "{} costs for a {n} x {n} assignment, expected {}",
            costs.len(),
            n * n
        ));
    }
    if let Some(c) = costs.iter().find(|c| !c.is_finite()) {
        return Err(format!("an assignment cost is not finite: {c}"));
    }
    if n == 0 {
        return Ok(Vec::new());
    }
    let lo = costs.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = costs.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let unit = if hi > lo { 1e12 / (hi - lo) } else { 1.0 };
    let weights: Vec<i64> = costs
        .iter()
        .map(|c| ((c - lo) * unit).round() as i64)
        .collect();
    let matrix = Matrix::from_vec(n, n, weights).map_err(|e| e.to_string())?;
    Ok(kuhn_munkres_min(&matrix).1)
}

/// The `n x n` matrix (row-major) of squared mass-weighted distances
/// `sum_v m_v |a_i(v) - b_j(v)|^2` between the `n` signals of `rows` and
/// the `n` of `columns`, each `m.len() x channels` values (vertex-major),
/// computed in `f64` (parallel over entries, each summed in vertex order,
/// so the same on any thread count).
///
/// # Errors
/// What is wrong, in words: sets that are not `n` signals of
/// `m.len() x channels` values.
pub fn squared_distances(
    rows: &[f32],
    columns: &[f32],
    n: usize,
    mass: &[f64],
    channels: usize,
) -> std::result::Result<Vec<f64>, String> {
    let item = mass.len() * channels;
    for (set, what) in [(rows, "rows"), (columns, "columns")] {
        if channels == 0 || set.len() != n * item {
            return Err(format!(
                "{} values of the {what}, expected {n} signals of {} vertices x {channels} channels",
                set.len(),
                mass.len()
            ));
        }
    }
    Ok((0..n * n)
        .into_par_iter()
        .map(|k| {
            let a = &rows[(k / n) * item..][..item];
            let b = &columns[(k % n) * item..][..item];
            a.chunks_exact(channels)
                .zip(b.chunks_exact(channels))
                .zip(mass)
                .map(|((p, q), m)| {
                    m * p
                        .iter()
                        .zip(q)
                        .map(|(x, y)| (f64::from(*x) - f64::from(*y)).powi(2))
                        .sum::<f64>()
                })
                .sum()
        })
        .collect())
}
