//! The **principal plane** of a set of shapes: the two directions in which
//! the training shapes vary most, and every shape's coordinates in them, so
//! that samples can be seen against the data in one picture
//! ([`crate::pictures::principal_plane`]).
//!
//! Shapes are vertex positions (`V x 3` values) already centred by their
//! mass-weighted mean ([`crate::shape_quality::CentredDistance::centre`]),
//! compared with the inner product of the centred distance:
//!
//! ```text
//! <a, b> = sum_v w_v a_v . b_v        (w: lumped masses summing to 1)
//! ```
//!
//! so that `d(a, b) = sqrt(<a - b, a - b>) / D` with `D` the template's
//! diagonal. With `mu` the mean of the training shapes, the directions
//! `u_1, u_2` are the leading eigenvectors of the training shapes'
//! covariance under `<., .>`, found through the Gram matrix
//! `G_ij = <x_i - mu, x_j - mu>` ([`mfm_data::principal`]; its eigenvectors `a_k` with eigenvalues
//! `g_k` give `u_k = sum_i a_ik (x_i - mu) / sqrt(g_k)`, of unit norm). A
//! shape `y` sits at `c_k(y) = <y - mu, u_k> / D`, in units of the
//! diagonal: distances in the plane are never longer than the centred
//! distance, and equal to it for shapes that differ only in the plane.
//! [`PrincipalPlane::explained`] is each direction's share of the total
//! variance, `g_k / trace(G)`.
//!
//! Signs are fixed so that the first shape the plane is fitted on has a
//! non-negative coordinate along each direction. With more than
//! [`PLANE_FIT_SHAPES`] training shapes the Gram matrix is that of a
//! seeded random subset of them (its cost is quadratic in the shapes):
//! the plane of a large random subset is the data's up to sampling
//! noise. A direction without variance (one training shape, or all alike)
//! is zero, and every coordinate along it 0.
//!
//! Cost: `O(n^2 V)` for the Gram matrix of `n <= 512` shapes (parallel over
//! rows), `O(n^3)` for its eigenvectors, `O(V)` per shape placed.
//!
//! # Example
//! ```
//! use mfm_data::InMemorySignals;
//! use mfm_eval::principal_plane::PlaneProjector;
//!
//! // four "shapes" of two vertices with equal mass, moving one vertex on
//! // a circle of radius 1 in the xy plane
//! let mut data = Vec::new();
//! for k in 0..4 {
//!     let a = k as f32 * std::f32::consts::FRAC_PI_2;
//!     data.extend([a.cos(), a.sin(), 0.0, 0.0, 0.0, 0.0]);
//! }
//! let shapes = InMemorySignals::new(data, 4, 2, 3).unwrap();
//! let plane = PlaneProjector::fit(&shapes, &[0.5, 0.5], 1.0, 0).unwrap();
//! let radius = |c: [f64; 2]| (c[0] * c[0] + c[1] * c[1]).sqrt();
//! for i in 0..4 {
//!     // sqrt(0.5): the moving vertex carries half the mass
//!     assert!((radius(plane.coordinates(shapes.signal(i))) - 0.5f64.sqrt()).abs() < 1e-6);
//! }
//! // a circle: half the variance along each direction (up to f32 rounding)
//! assert!((plane.explained()[0] - 0.5).abs() < 1e-6);
//! ```

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use mfm_data::principal::PrincipalComponents;
use mfm_data::{DataError, InMemorySignals, Result, SignalSource};

/// Most training shapes whose Gram matrix the plane is fitted on; beyond,
/// a seeded random subset of this many.
pub const PLANE_FIT_SHAPES: usize = 512;

/// Where the training shapes, the held-out shapes and the samples sit in
/// the training shapes' principal plane (see the [module docs](self)).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PrincipalPlane {
    /// Share of the training shapes' variance along each direction.
    pub explained: [f64; 2],
    /// Training shapes the directions were fitted on (all of them, or
    /// [`PLANE_FIT_SHAPES`] drawn at random).
    pub fitted_on: usize,
    /// Coordinates of the training shapes, in units of the diagonal.
    pub train: Vec<[f64; 2]>,
    /// Coordinates of the held-out shapes.
    pub held_out: Vec<[f64; 2]>,
    /// Coordinates of the samples.
    pub samples: Vec<[f64; 2]>,
}

/// The training shapes' mean and principal directions: places any shape
/// of the same mesh in the plane ([module docs](self)).
#[derive(Clone, Debug)]
pub struct PlaneProjector {
    /// `mu` and the leading directions (at most two) under the weights.
    components: PrincipalComponents,
    diagonal: f64,
}

impl PlaneProjector {
    /// Fits the plane to `train` (centred shapes, `V x 3` values each)
    /// with vertex masses `mass` (any positive scale) and distance unit
    /// `diagonal`; `seed` draws the subset beyond [`PLANE_FIT_SHAPES`].
    ///
    /// # Errors
    /// [`DataError::Config`] for no training shape, masses that do not sum
    /// to a finite positive number, or a diagonal that is not finite and
    /// positive; [`DataError::SizeMismatch`] for shapes that are not 3
    /// channels of `mass.len()` vertices.
    pub fn fit(train: &InMemorySignals, mass: &[f64], diagonal: f64, seed: u64) -> Result<Self> {
        if train.is_empty() {
            return Err(DataError::Config(
                "the principal plane needs at least one training shape".into(),
            ));
        }
        if train.channels() != 3 || train.num_vertices() != mass.len() {
            return Err(DataError::SizeMismatch {
                what: "values per training shape (positions of the mesh's vertices)".into(),
                expected: 3 * mass.len(),
                found: train.channels() * train.num_vertices(),
            });
        }
        let total: f64 = mass.iter().sum();
        if !(total.is_finite() && total > 0.0) {
            return Err(DataError::Config(format!(
                "the principal plane needs masses with a finite positive sum, found {total}"
            )));
        }
        if !(diagonal.is_finite() && diagonal > 0.0) {
            return Err(DataError::Config(format!(
                "the distance unit (the template's diagonal) must be finite and positive, \
                 found {diagonal}"
            )));
        }
        let mut fitted: Vec<usize> = (0..train.len()).collect();
        if train.len() > PLANE_FIT_SHAPES {
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            fitted = rand::seq::index::sample(&mut rng, train.len(), PLANE_FIT_SHAPES).into_vec();
            fitted.sort_unstable();
        }
        let components = PrincipalComponents::fit(train, &fitted, mass, 2)?;
        Ok(Self {
            components,
            diagonal,
        })
    }

    /// `c(y)`: where the centred shape `y` (`V x 3` values, unchecked
    /// length) sits in the plane, in units of the diagonal (0 along a
    /// direction without variance).
    pub fn coordinates(&self, shape: &[f32]) -> [f64; 2] {
        let mut c = [0.0; 2];
        for (k, ck) in c.iter_mut().enumerate().take(self.components.len()) {
            *ck = self.components.coordinate(shape, k) / self.diagonal;
        }
        c
    }

    /// The centred distance `d(y, mu)` of the centred shape `y` to the
    /// training shapes' mean, in units of the diagonal.
    pub fn distance_to_mean(&self, shape: &[f32]) -> f64 {
        let weights = self.components.weights();
        let sq: f64 = shape
            .iter()
            .zip(self.components.mean())
            .enumerate()
            .map(|(j, (&x, m))| weights[j / 3] * (f64::from(x) - m).powi(2))
            .sum();
        sq.sqrt() / self.diagonal
    }

    /// Each direction's share of the training shapes' variance (0 for a
    /// direction without variance).
    pub fn explained(&self) -> [f64; 2] {
        let mut e = [0.0; 2];
        let total = self.components.total_scatter();
        for (ek, g) in e.iter_mut().zip(self.components.scatter()) {
            *ek = g / total;
        }
        e
    }

    /// How many training shapes the directions were fitted on.
    pub fn fitted_on(&self) -> usize {
        self.components.fitted_on()
    }

    /// The [`PrincipalPlane`] of three sets of centred shapes.
    pub fn place(
        &self,
        train: &InMemorySignals,
        held_out: &InMemorySignals,
        samples: &InMemorySignals,
    ) -> PrincipalPlane {
        let all = |set: &InMemorySignals| -> Vec<[f64; 2]> {
            (0..set.len())
                .into_par_iter()
                .map(|i| self.coordinates(set.signal(i)))
                .collect()
        };
        PrincipalPlane {
            explained: self.explained(),
            fitted_on: self.fitted_on(),
            train: all(train),
            held_out: all(held_out),
            samples: all(samples),
        }
    }
}
