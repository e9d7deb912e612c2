//! Sample quality: measures that a flat, noise-like or collapsed sample set
//! cannot pass, beside the distribution metrics of [`crate::metrics`]
//! (which such sets can: docs/metrics.md, "Distribution metrics").
//!
//! - **GMM signals** ([`fit_bumps`], [`GmmQuality`]): every sample is fitted
//!   with the generator's own family, `K` bumps
//!   `exp(-d(x, c)^2 / (2 sigma^2))` of the dataset's width centred at
//!   vertices, heights free (greedy orthogonal matching pursuit: at each of
//!   `K` rounds the candidate centre that most lowers the least-squares
//!   residual after a joint refit of all heights is kept; candidates are the
//!   highest vertices of the current residual, at most [`CANDIDATES`], at
//!   least one bump width apart; then each centre may move to a vertex
//!   within one bump width when that lowers the residual, which repairs the
//!   greedy choice where bumps overlap). Reported per sample: the relative residual
//!   `||f - fit||_M / ||f||_M` (mass-weighted L2), the peak value, and the
//!   number of fitted bumps higher than half the data's height (the
//!   generator's bumps have height 1). A signal of the family fits with a
//!   residual of a few percent (the floor, measured on the reference set);
//!   noise, flat or smeared samples leave most of their norm.
//! - **Collapse** ([`diversity`]): the median distance between two samples
//!   of the set over the same for the reference set; about 1 for data-like
//!   variety, 0 for a set of copies.
//! - **Deformations** ([`ParamSpread`]): the spread of the handle parameters
//!   of the projections onto the deformation space
//!   ([`crate::plausibility`]); a model that collapses onto
//!   the rest pose has none.
//!
//! Aggregates are [`Quartiles`] (the distribution of the per-sample numbers)
//! and the fraction of data-like samples: residual within twice the
//! reference set's median residual (or [`DATA_LIKE_MIN`], whichever is
//! larger).

use mfm_deform::DeformParams;
use mfm_geometry::TriMesh;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use mfm_data::gmm::GmmGenerator;
use mfm_data::{DataError, InMemorySignals, Result, SignalSource};

use crate::metrics::MassWeighted;

/// Candidate centres tried per round of [`fit_bumps`].
pub const CANDIDATES: usize = 16;

/// Passes of local refinement in [`fit_bumps`].
pub const REFINE_PASSES: usize = 3;

/// Height above which a fitted bump counts (half the generator's height 1).
pub const HALF_HEIGHT: f64 = 0.5;

/// Smallest residual bound of a "data-like" sample: the fit is exact on
/// signals generated on the evaluation mesh itself (floor 0), where twice
/// the floor would be no bound; a residual of 0.1 leaves 1% of a signal's
/// energy unexplained, which no picture shows.
pub const DATA_LIKE_MIN: f64 = 0.1;

/// First quartile, median and third quartile of a set of numbers (linear
/// interpolation between order statistics; NaN for an empty set).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Quartiles {
    /// 25th percentile.
    pub q1: f64,
    /// 50th percentile.
    pub median: f64,
    /// 75th percentile.
    pub q3: f64,
}

impl Quartiles {
    /// The quartiles of `values` (NaNs sort last).
    pub fn of(values: &[f64]) -> Self {
        let mut v = values.to_vec();
        v.sort_by(f64::total_cmp);
        let at = |q: f64| -> f64 {
            if v.is_empty() {
                return f64::NAN;
            }
            let x = q * (v.len() - 1) as f64;
            let (i, frac) = (x.floor() as usize, x - x.floor());
            let j = (i + 1).min(v.len() - 1);
            v[i] + frac * (v[j] - v[i])
        };
        Self {
            q1: at(0.25),
            median: at(0.5),
            q3: at(0.75),
        }
    }
}

/// The fit of one signal by [`fit_bumps`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BumpFit {
    /// `||f - fit||_M / ||f||_M` (1 for a zero signal).
    pub residual: f64,
    /// Largest value of the signal.
    pub peak: f64,
    /// Fitted bumps with height above [`HALF_HEIGHT`].
    pub bumps_above_half: usize,
    /// Centre vertices of the fitted bumps, in the order chosen.
    pub centers: Vec<usize>,
    /// Their fitted heights.
    pub heights: Vec<f64>,
}

/// Fits `signal` (one value per vertex of `mesh`, the generator's mesh)
/// with `generator.config().bumps` bumps of the generator's width; see the
/// [module docs](self).
///
/// Cost: `O(K^2 (CANDIDATES + R) V)` with `R` the vertices within one bump
/// width of the centres (refinement), plus one distance field per distinct
/// candidate (cached by the generator).
///
/// # Errors
/// [`DataError::SizeMismatch`] when `signal` or `mass` do not have one value
/// per vertex; distance-field errors.
pub fn fit_bumps(
    generator: &GmmGenerator,
    mesh: &TriMesh,
    mass: &[f64],
    signal: &[f64],
) -> Result<BumpFit> {
    let v = mesh.num_vertices();
    for (what, n) in [
        ("signal values", signal.len()),
        ("vertex masses", mass.len()),
        ("generator vertices", generator.num_vertices()),
    ] {
        if n != v {
            return Err(DataError::SizeMismatch {
                what: format!("{what} for the bump fit (one per mesh vertex)"),
                expected: v,
                found: n,
            });
        }
    }
    let dot = |a: &[f64], b: &[f64]| -> f64 {
        a.iter().zip(b).zip(mass).map(|((x, y), m)| m * x * y).sum()
    };
    let norm2 = dot(signal, signal);
    let peak = signal.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let positions = mesh.positions();
    let width = generator.sigma();
    let k_max = generator.config().bumps;
    let mut centers: Vec<usize> = Vec::new();
    let mut basis: Vec<Vec<f64>> = Vec::new();
    let mut heights: Vec<f64> = Vec::new();
    let mut residual: Vec<f64> = signal.to_vec();
    let mut best_err = norm2;
    for _ in 0..k_max {
        let mut order: Vec<usize> = (0..v).collect();
        order.sort_by(|&a, &b| residual[b].total_cmp(&residual[a]));
        let mut candidates: Vec<usize> = Vec::with_capacity(CANDIDATES);
        for &i in &order {
            if candidates.len() == CANDIDATES {
                break;
            }
            let far = candidates
                .iter()
                .chain(&centers)
                .all(|&c| dist(positions[i], positions[c]) > width);
            if far {
                candidates.push(i);
            }
        }
        let mut round: Option<(f64, usize, Vec<f64>, Vec<f64>)> = None;
        for &c in &candidates {
            let b = generator.bump(c)?;
            let mut set: Vec<&[f64]> = basis.iter().map(Vec::as_slice).collect();
            set.push(&b);
            let Some((err, h)) = joint_fit(&set, signal, norm2, &dot) else {
                continue;
            };
            if round.as_ref().is_none_or(|r| err < r.0) {
                round = Some((err, c, b, h));
            }
        }
        let Some((err, c, b, h)) = round else {
            break;
        };
        centers.push(c);
        basis.push(b);
        heights = h;
        best_err = err;
        residual = residual_of(signal, &basis, &heights);
    }
    // local refinement: greedy choices go wrong where bumps overlap (the top
    // of a sum of two bumps is between their centres), so each centre in turn
    // may move to any vertex within one bump width when that lowers the
    // residual of the joint fit; repeated while something moves (at most
    // REFINE_PASSES times)
    for _ in 0..REFINE_PASSES {
        let mut moved = false;
        for k in 0..centers.len() {
            let here = positions[centers[k]];
            let mut best: Option<(f64, usize, Vec<f64>, Vec<f64>)> = None;
            for (c, &pc) in positions.iter().enumerate() {
                if c == centers[k] || dist(pc, here) > width {
                    continue;
                }
                let b = generator.bump(c)?;
                let set: Vec<&[f64]> = (0..basis.len())
                    .map(|j| {
                        if j == k {
                            b.as_slice()
                        } else {
                            basis[j].as_slice()
                        }
                    })
                    .collect();
                let Some((err, h)) = joint_fit(&set, signal, norm2, &dot) else {
                    continue;
                };
                let bar = best.as_ref().map_or(best_err, |b| b.0);
                if err < bar - 1e-12 * norm2 {
                    best = Some((err, c, b, h));
                }
            }
            if let Some((err, c, b, h)) = best {
                centers[k] = c;
                basis[k] = b;
                heights = h;
                best_err = err;
                moved = true;
            }
        }
        if !moved {
            break;
        }
    }
    let residual = residual_of(signal, &basis, &heights);
    // the direct residual norm (the Gram identity loses digits near 0)
    let direct = dot(&residual, &residual);
    let err = if direct.is_finite() { direct } else { best_err };
    let relative = if norm2 > 0.0 {
        (err.max(0.0) / norm2).sqrt()
    } else {
        1.0
    };
    Ok(BumpFit {
        residual: relative,
        peak,
        bumps_above_half: heights.iter().filter(|&&h| h > HALF_HEIGHT).count(),
        centers,
        heights,
    })
}

/// The least-squares fit of `signal` by the bumps `set` (heights free,
/// `dot` the mass inner product, `norm2 = dot(signal, signal)`): the squared
/// residual norm and the heights; `None` when the bumps are (numerically)
/// dependent.
fn joint_fit(
    set: &[&[f64]],
    signal: &[f64],
    norm2: f64,
    dot: &dyn Fn(&[f64], &[f64]) -> f64,
) -> Option<(f64, Vec<f64>)> {
    let n = set.len();
    let gram: Vec<Vec<f64>> = (0..n)
        .map(|i| (0..n).map(|j| dot(set[i], set[j])).collect())
        .collect();
    let rhs: Vec<f64> = set.iter().map(|b| dot(b, signal)).collect();
    let h = solve_small(gram, rhs.clone())?;
    let err = norm2 - h.iter().zip(&rhs).map(|(a, b)| a * b).sum::<f64>();
    Some((err, h))
}

/// `signal - sum_k heights[k] basis[k]`.
fn residual_of(signal: &[f64], basis: &[Vec<f64>], heights: &[f64]) -> Vec<f64> {
    let mut r = signal.to_vec();
    for (b, h) in basis.iter().zip(heights) {
        r.iter_mut().zip(b).for_each(|(r, x)| *r -= h * x);
    }
    r
}

fn dist(a: [f64; 3], b: [f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

/// Solves the small symmetric system `a x = b` by Gaussian elimination with
/// partial pivoting; `None` when it is (numerically) singular.
fn solve_small(mut a: Vec<Vec<f64>>, mut b: Vec<f64>) -> Option<Vec<f64>> {
    let n = b.len();
    let scale = (0..n).map(|i| a[i][i].abs()).fold(0.0f64, f64::max);
    for col in 0..n {
        let pivot = (col..n).max_by(|&i, &j| a[i][col].abs().total_cmp(&a[j][col].abs()))?;
        let p = a[pivot][col].abs();
        if p.is_nan() || p <= 1e-10 * scale {
            return None;
        }
        a.swap(col, pivot);
        b.swap(col, pivot);
        let pivot_row = a[col].clone();
        for row in col + 1..n {
            let f = a[row][col] / pivot_row[col];
            for (x, p) in a[row][col..].iter_mut().zip(&pivot_row[col..]) {
                *x -= f * p;
            }
            b[row] -= f * b[col];
        }
    }
    let mut x = vec![0.0; n];
    for row in (0..n).rev() {
        let s: f64 = (row + 1..n).map(|k| a[row][k] * x[k]).sum();
        x[row] = (b[row] - s) / a[row][row];
    }
    Some(x)
}

/// [`fit_bumps`] over a set of one-channel signals, and its aggregates.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GmmQuality {
    /// Relative residuals of the fits.
    pub residual: Quartiles,
    /// Peak values.
    pub peak: Quartiles,
    /// Mean number of fitted bumps above half height per sample.
    pub bumps_above_half: f64,
    /// Every sample's fit, in order.
    pub fits: Vec<BumpFit>,
}

impl GmmQuality {
    /// Fits every signal of `signals` (one channel, on `mesh`) in parallel.
    ///
    /// # Errors
    /// [`DataError::SizeMismatch`] for signals that are not one channel on
    /// `mesh`; as [`fit_bumps`].
    pub fn of(
        generator: &GmmGenerator,
        mesh: &TriMesh,
        mass: &[f64],
        signals: &InMemorySignals,
    ) -> Result<Self> {
        if signals.channels() != 1 || signals.num_vertices() != mesh.num_vertices() {
            return Err(DataError::SizeMismatch {
                what: "values per GMM signal (one channel per vertex of the mesh)".into(),
                expected: mesh.num_vertices(),
                found: signals.num_vertices() * signals.channels(),
            });
        }
        let fits = (0..signals.len())
            .into_par_iter()
            .map(|i| {
                let s: Vec<f64> = signals.signal(i).iter().map(|&x| f64::from(x)).collect();
                fit_bumps(generator, mesh, mass, &s)
            })
            .collect::<Result<Vec<_>>>()?;
        let residuals: Vec<f64> = fits.iter().map(|f| f.residual).collect();
        let peaks: Vec<f64> = fits.iter().map(|f| f.peak).collect();
        let bumps =
            fits.iter().map(|f| f.bumps_above_half as f64).sum::<f64>() / fits.len().max(1) as f64;
        Ok(Self {
            residual: Quartiles::of(&residuals),
            peak: Quartiles::of(&peaks),
            bumps_above_half: bumps,
            fits,
        })
    }

    /// Fraction of samples whose residual is at most
    /// `max(2 * floor, DATA_LIKE_MIN)`.
    pub fn fraction_within_twice(&self, floor: f64) -> f64 {
        let bound = (2.0 * floor).max(DATA_LIKE_MIN);
        let n = self.fits.iter().filter(|f| f.residual <= bound).count();
        n as f64 / self.fits.len().max(1) as f64
    }
}

/// The GMM sample-quality report: generated and reference sets side by
/// side, the floor (the reference's median residual), the fraction of
/// generated samples within twice the floor, and the set's
/// [`diversity`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GmmQualityReport {
    /// The generated set.
    pub generated: GmmQuality,
    /// The reference set (the data's own values: the floor).
    pub reference: GmmQuality,
    /// Median residual of the reference set.
    pub floor: f64,
    /// Fraction of generated samples with residual at most
    /// `max(2 * floor, DATA_LIKE_MIN)`.
    pub within_twice_floor: f64,
    /// [`diversity`] of the generated set against the reference set (NaN,
    /// `null` in JSON, when either set has a single signal).
    pub diversity: f64,
}

impl GmmQualityReport {
    /// Fits both sets (on the reference's mesh) and compares them.
    ///
    /// # Errors
    /// As [`GmmQuality::of`] and [`diversity`].
    pub fn of(
        generator: &GmmGenerator,
        mesh: &TriMesh,
        mass: &[f64],
        generated: &InMemorySignals,
        reference: &InMemorySignals,
    ) -> Result<Self> {
        let g = GmmQuality::of(generator, mesh, mass, generated)?;
        let r = GmmQuality::of(generator, mesh, mass, reference)?;
        let floor = r.residual.median;
        // one sample (or one reference signal) has no pairs: no diversity
        let diversity = if generated.len() < 2 || reference.len() < 2 {
            f64::NAN
        } else {
            diversity(mass, generated, reference)?
        };
        Ok(Self {
            within_twice_floor: g.fraction_within_twice(floor),
            diversity,
            floor,
            generated: g,
            reference: r,
        })
    }

    /// One line: the generated set's medians, the floor, and the rest.
    pub fn summary(&self) -> String {
        let (g, r) = (&self.generated, &self.reference);
        format!(
            "bump fit: residual median {:.3} [{:.3}, {:.3}] (data {:.3}), peak median {:.2} (data {:.2}), \
             bumps above half height {:.2} per sample (data {:.2}), {:.0}% data-like (residual <= {:.2}), \
             diversity {}",
            g.residual.median,
            g.residual.q1,
            g.residual.q3,
            self.floor,
            g.peak.median,
            r.peak.median,
            g.bumps_above_half,
            r.bumps_above_half,
            100.0 * self.within_twice_floor,
            (2.0 * self.floor).max(DATA_LIKE_MIN),
            if self.diversity.is_nan() {
                "not measured (it needs at least 2 samples and 2 reference signals)".to_owned()
            } else {
                format!("{:.2}", self.diversity)
            }
        )
    }
}

/// Median mass-weighted distance between two distinct samples of `set`,
/// over the same for `reference` (pairs among at most the first 200 of
/// each): about 1 for a set as varied as the data, 0 for copies of one
/// sample.
///
/// # Errors
/// [`DataError::SizeMismatch`] when the sets do not live on `mass`'s mesh or
/// have fewer than 2 samples; distance errors.
pub fn diversity(mass: &[f64], set: &InMemorySignals, reference: &InMemorySignals) -> Result<f64> {
    let median_pair = |s: &InMemorySignals| -> Result<f64> {
        if s.len() < 2 {
            return Err(DataError::SizeMismatch {
                what: "samples for the diversity measure (at least 2)".into(),
                expected: 2,
                found: s.len(),
            });
        }
        let n = s.len().min(200);
        let (v, c) = (s.num_vertices(), s.channels());
        let head = InMemorySignals::new(s.data()[..n * v * c].to_vec(), n, v, c)?;
        let d = MassWeighted::new(mass, c)?.pairwise(&head, &head)?;
        let mut pairs = Vec::with_capacity(n * (n - 1) / 2);
        for i in 0..n {
            for j in i + 1..n {
                pairs.push(d.get(i, j));
            }
        }
        Ok(Quartiles::of(&pairs).median)
    };
    let (a, b) = (median_pair(set)?, median_pair(reference)?);
    Ok(if b > 0.0 { a / b } else { f64::NAN })
}

/// Spread of deformation parameters over a set of shapes: the root mean
/// square, over moving handles and axes, of the standard deviation across
/// shapes of each handle's rotation vector (radians) and translation
/// (the shapes' units).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ParamSpread {
    /// Rotation spread, radians.
    pub rotation: f64,
    /// Translation spread.
    pub translation: f64,
}

impl ParamSpread {
    /// The spread of `params` (all with the same handle count; zero for
    /// fewer than 2 shapes).
    pub fn of(params: &[DeformParams]) -> Self {
        let n = params.len();
        let handles = params.first().map_or(0, |p| p.handles.len());
        if n < 2 || handles == 0 {
            return Self {
                rotation: 0.0,
                translation: 0.0,
            };
        }
        let spread = |get: &dyn Fn(&DeformParams, usize, usize) -> f64| -> f64 {
            let mut total = 0.0;
            for h in 0..handles {
                for k in 0..3 {
                    let mean = params.iter().map(|p| get(p, h, k)).sum::<f64>() / n as f64;
                    let var = params
                        .iter()
                        .map(|p| (get(p, h, k) - mean).powi(2))
                        .sum::<f64>()
                        / (n - 1) as f64;
                    total += var;
                }
            }
            (total / (3 * handles) as f64).sqrt()
        };
        Self {
            rotation: spread(&|p, h, k| p.handles[h].rotation[k]),
            translation: spread(&|p, h, k| p.handles[h].translation[k]),
        }
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn quartiles_interpolate_between_order_statistics() {
        let q = Quartiles::of(&[4.0, 1.0, 3.0, 2.0, 5.0]);
        assert_eq!((q.q1, q.median, q.q3), (2.0, 3.0, 4.0));
        let q = Quartiles::of(&[1.0, 2.0]);
        assert_eq!((q.q1, q.median, q.q3), (1.25, 1.5, 1.75));
        assert!(Quartiles::of(&[]).median.is_nan());
    }

    #[test]
    fn small_systems_solve_and_singular_ones_are_refused() {
        let x = solve_small(vec![vec![0.0, 2.0], vec![3.0, 1.0]], vec![4.0, 5.0]).unwrap();
        assert!(
            (x[0] - 1.0).abs() < 1e-12 && (x[1] - 2.0).abs() < 1e-12,
            "{x:?}"
        );
        assert!(solve_small(vec![vec![1.0, 1.0], vec![1.0, 1.0]], vec![1.0, 1.0]).is_none());
    }

    #[test]
    fn parameter_spread_is_the_rms_standard_deviation() {
        use mfm_deform::RigidParams;
        let p = |r: f64, t: f64| DeformParams {
            handles: vec![RigidParams {
                rotation: [r, 0.0, 0.0],
                translation: [t, t, t],
            }],
        };
        let s = ParamSpread::of(&[p(1.0, 0.0), p(-1.0, 2.0)]);
        // rotation: std sqrt(2) on one of three axes; translation: std sqrt(2) on all
        assert!((s.rotation - (2.0f64 / 3.0).sqrt()).abs() < 1e-12, "{s:?}");
        assert!((s.translation - 2.0f64.sqrt()).abs() < 1e-12, "{s:?}");
        assert_eq!(ParamSpread::of(&[p(1.0, 1.0)]).rotation, 0.0);
    }
}
