//! Sample quality of generated **shapes** when there is no generator to fit
//! them with: every measure compares the samples with real shapes (training
//! and held-out), all given as vertex positions (3 channels, `[N, V, 3]`) of
//! one mesh, the *reference mesh* (the rest / template triangulation).
//!
//! ## The distance
//! Shapes are compared by the **centred distance**: the mass-weighted RMS
//! vertex distance (the [`crate::metrics`] distance) after removing each
//! shape's mass-weighted mean, in units of the template's bounding-box
//! diagonal `D`:
//!
//! ```text
//! c(x)    = sum_v m_v x_v / sum_v m_v                     (mass-weighted mean)
//! d(a, b) = sqrt( sum_v m_v |(a_v - c(a)) - (b_v - c(b))|^2 / sum_v m_v ) / D
//! ```
//!
//! with `m` the lumped mass of the **rest** mesh (the same weights for every
//! shape). Translation is removed, rotation is not (shapes of a dataset are
//! aligned). `d` is a metric on shapes modulo translation (symmetric, zero on
//! a shape and its translate, triangle inequality).
//!
//! ## The measures
//! With training shapes `T`, held-out shapes `H`, real shapes `R = T ∪ H`
//! and samples `S` (medians are [`Quartiles`] medians, the mean of the two
//! middle values for an even count):
//!
//! - **floor** = `median_{h in H} min_{t in T} d(h, t)`: how far a real
//!   shape the model never saw is from the training set; the unit of the
//!   next measures. A floor of 0 (held-out shapes that are training shapes)
//!   is refused.
//! - **plausibility** = `median_{s in S} min_{r in R} d(s, r) / floor`:
//!   about 1 or below for samples like the data, far above 1 for shapes no
//!   real shape resembles (a mean shape, a blend of poses, a broken surface).
//! - **coverage** = `median_{h in H} min_{s in S} d(h, s)` over the same
//!   with, instead of `S`, `min(|S|, |T|)` training shapes drawn at random
//!   without replacement (`rand_chacha::ChaCha8Rng` seeded with
//!   [`ShapeSets::seed`]): about 1 when the samples cover the held-out
//!   shapes as well as as many training shapes do, far above 1 when they
//!   miss parts of the data (collapse). With `|S| >= |T|` the baseline is
//!   the whole training set and its median is the floor.
//! - **roughness** = `median_{s in S} E(s) / E(r(s))` with `r(s)` the
//!   nearest real shape of `s` and the bending energy of a shape `x`,
//!   `E(x) = sum_i m_i |(M^-1 L x)_i|^2 = sum_i |(L x)_i|^2 / m_i` with the
//!   lumped mass `M` and the cotangent Laplacian `L` **of the shape
//!   itself** (the mesh moved to `x`; `L` positive semi-definite, so
//!   `M^-1 L x` is minus the discrete Laplace-Beltrami of the positions,
//!   `2 H n` on a smooth surface: `E` is the discrete `4 * integral of H^2`,
//!   blind to translation, rotation and scale; vertices without mass are
//!   left out, degenerate faces add nothing). About 1 for data-like detail;
//!   far below 1: detail lost (over-smoothed); far above 1: a noise
//!   texture or folds. Every energy is measured on the reference mesh,
//!   the real shapes carried there as the samples are: a real shape
//!   carried from a coarser template is piecewise flat between the
//!   template's edges, and on a finer mesh that crease holds more energy
//!   than the template's own discretization of the shape (1.75 times for
//!   the shared horse's held-out frames on the default reference mesh,
//!   whose half is refined twice), so comparing with the energy measured
//!   on the template would read a data-like sample as rough. Real shapes
//!   as samples read exactly 1 on any reference mesh. (With the *rest*
//!   mesh's operators instead of each shape's own, a real sequence's
//!   frames read a median of 25 times the rest shape's energy, nearly all
//!   of it at a handful of vertices whose rest cotangent weights are huge:
//!   the shared galloping horse does; with their own, every frame is
//!   within 12% of the rest shape.) `0 / 0` counts as 1 and `x / 0` as
//!   infinity (`null` in JSON).
//! - **novelty** = `median_{s in S} min_{t in T} d(s, t) / floor`: near 0 for
//!   copies of training shapes, about 1 for new shapes as far from the
//!   training set as unseen real ones.
//! - **spread** = `median_{s in S} d(s, mu) / median_{r in R} d(r, mu)`
//!   with `mu` the mean of the (centred) training shapes: about 1 when the
//!   samples vary about the mean shape as much as the data; below 1 when
//!   they are pulled toward it (averages or blends of shapes: on a motion
//!   cycle, poses cut across the cycle), 0 for the mean shape repeated;
//!   above 1 beyond the data. Beside it, every shape's place in the
//!   training shapes' principal plane ([`crate::principal_plane`]), which
//!   `mfm eval --png` draws.
//! - **Gaussian baseline**: plausibility, coverage and spread of `|S|`
//!   draws of the Gaussian with the training shapes' mean and covariance
//!   ([`crate::gaussian_baseline`], seeded with [`ShapeSets::seed`]),
//!   measured as the samples' are: what a model that learned only the
//!   data's first two moments would read. Absent for one training shape.
//! - **flipped faces**: per sample, the fraction of faces whose normal (the
//!   unnormalised cross product `(p1 - p0) x (p2 - p0)`) has a negative dot
//!   product with the same face's normal on the sample's nearest real shape
//!   (a degenerate face, with zero normal, never counts); reported as the
//!   median, mean and maximum over samples. It counts folds, and also parts
//!   turned by more than a right angle from the nearest real shape (a
//!   hoof, a hand): beside it, the same fractions of the held-out shapes
//!   against their nearest training shapes are the data's own (the shared
//!   horse's held-out frames on its reference mesh: 0.0% median, 0.2% at most).
//! - **MMD / COV / 1-NNA** ([`metrics::mmd`], [`metrics::coverage`],
//!   [`metrics::one_nna`]) of the samples against the **held-out** shapes
//!   under `d` (MMD in units of `D`).
//!
//! Ties in nearest-shape searches go to the lowest index, training shapes
//! before held-out ones.
//!
//! The floor is a median over the held-out shapes, and every ratio to it is
//! as noisy as that median: hold out at least 20 shapes. On a
//! one-parameter family of 160 shapes (the tests'), data-like samples gave
//! plausibility and novelty between 0.5 and 2.5 over 12 draws of the
//! family with 20 held out; with 5 held out the floor itself varied by a
//! factor of 19.
//!
//! Cost: the distance matrices samples x `R` and `H` x `R` are
//! `O((N_s + N_h) (N_t + N_h) V)`, plus samples x samples for 1-NNA,
//! `O(N_s^2 V)` (parallel over rows); the bending energies one sparse
//! product per shape, `O((N_s + N_t + N_h) (V + E))`; the flips `O(N_s F)`.
//! Memory: the centred copies of the sets and the matrices,
//! `8 (N_s + N_h) (N_s + N_t + N_h)` bytes.
//!
//! # Example
//! ```
//! use mfm_data::InMemorySignals;
//! use mfm_eval::shape_quality::{ShapeSets, shape_quality};
//! use mfm_geometry::procedural;
//!
//! let mesh = procedural::icosphere(1);
//! // ellipsoids stretched along x by 1 + k / 10, shifted by k along z
//! let shapes = |ks: &[usize]| {
//!     let mut data = Vec::new();
//!     for &k in ks {
//!         for p in mesh.positions() {
//!             let s = 1.0 + k as f64 / 10.0;
//!             data.extend([(s * p[0]) as f32, p[1] as f32, (p[2] + k as f64) as f32]);
//!         }
//!     }
//!     InMemorySignals::new(data, ks.len(), mesh.num_vertices(), 3).unwrap()
//! };
//! let (train, held_out) = (shapes(&[0, 2, 4, 6]), shapes(&[1, 5]));
//! let sets = ShapeSets {
//!     mesh: &mesh,
//!     train: &train,
//!     held_out: &held_out,
//!     samples: &train, // the training shapes themselves
//!     diagonal: mesh.bounding_box_diagonal(),
//!     seed: 0,
//! };
//! let q = shape_quality(&sets).unwrap();
//! assert_eq!((q.plausibility, q.novelty, q.roughness), (0.0, 0.0, 1.0));
//! assert!(q.floor > 0.0 && q.coverage == 1.0);
//! ```

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use mfm_data::{DataError, InMemorySignals, Result, SignalSource};
use mfm_geometry::TriMesh;
use mfm_geometry::mesh::{dot, triangle_normal};
use mfm_geometry::operators::Operators;

use crate::gaussian_baseline::{GaussianBaseline, gaussian_shapes};
use crate::metrics::{self, DistanceMatrix, MassWeighted};
use crate::principal_plane::{PlaneProjector, PrincipalPlane};
use crate::quality::Quartiles;

/// The shapes [`shape_quality`] judges, all vertex positions of one mesh.
#[derive(Clone, Copy, Debug)]
pub struct ShapeSets<'a> {
    /// The reference mesh: its connectivity is every shape's, and its
    /// (rest) positions define the lumped mass and cotangent Laplacian the
    /// measures use.
    pub mesh: &'a TriMesh,
    /// Training shapes (at least one).
    pub train: &'a InMemorySignals,
    /// Held-out real shapes (at least one), not in the training set.
    pub held_out: &'a InMemorySignals,
    /// Generated shapes (at least one).
    pub samples: &'a InMemorySignals,
    /// The template's bounding-box diagonal: the unit of distances (finite,
    /// positive).
    pub diagonal: f64,
    /// Seed of the random training subset of the coverage baseline.
    pub seed: u64,
}

/// Which real set a shape belongs to.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RealSet {
    /// [`ShapeSets::train`].
    Train,
    /// [`ShapeSets::held_out`].
    HeldOut,
}

/// One real shape: its set and its index in that set.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct RealShape {
    /// The set.
    pub set: RealSet,
    /// Index in the set.
    pub index: usize,
}

/// What [`shape_quality`] finds of one sample.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SampleQuality {
    /// Its nearest real shape (training or held-out).
    pub nearest: RealShape,
    /// The centred distance to it, in units of the diagonal.
    pub distance: f64,
    /// The centred distance to the nearest training shape (novelty's).
    pub training_distance: f64,
    /// Its bending energy over its nearest real shape's.
    pub roughness: f64,
    /// Fraction of faces whose normal opposes the nearest real shape's.
    pub flipped: f64,
}

/// Fractions of flipped faces over the samples.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct FlippedFaces {
    /// Median over samples.
    pub median: f64,
    /// Mean over samples.
    pub mean: f64,
    /// Largest over samples.
    pub max: f64,
}

impl FlippedFaces {
    /// The median, mean and largest of `fractions` (all 0 for none).
    fn of(fractions: &[f64]) -> Self {
        if fractions.is_empty() {
            return Self {
                median: 0.0,
                mean: 0.0,
                max: 0.0,
            };
        }
        Self {
            median: median(fractions),
            mean: fractions.iter().sum::<f64>() / fractions.len() as f64,
            max: fractions.iter().copied().fold(0.0, f64::max),
        }
    }
}

/// The distribution metrics of the samples against the held-out shapes
/// under the centred distance.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ShapeMetrics {
    /// Minimum matching distance ([`metrics::mmd`]), in units of the
    /// diagonal. Lower is better.
    pub mmd: f64,
    /// Coverage ([`metrics::coverage`]): fraction of held-out shapes that
    /// are some sample's nearest. Higher is better.
    pub cov: f64,
    /// Leave-one-out 1-nearest-neighbour accuracy ([`metrics::one_nna`]);
    /// 0.5 is ideal.
    pub one_nna: f64,
}

/// The sample quality of a set of shapes; see the [module docs](self) for
/// the definitions. Distances are centred distances in units of the
/// template's diagonal.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ShapeQuality {
    /// Median distance of a held-out shape to the nearest training shape.
    pub floor: f64,
    /// Median distance of a sample to the nearest real shape, over the floor.
    pub plausibility: f64,
    /// `held_out_to_samples / held_out_to_baseline`.
    pub coverage: f64,
    /// Median distance of a held-out shape to the nearest sample.
    pub held_out_to_samples: f64,
    /// Median distance of a held-out shape to the nearest shape of the
    /// baseline (`baseline_size` random training shapes).
    pub held_out_to_baseline: f64,
    /// Training shapes in the coverage baseline: `min(samples, training)`.
    pub baseline_size: usize,
    /// Median over samples of the bending-energy ratio to the nearest real
    /// shape.
    pub roughness: f64,
    /// Median distance of a sample to the nearest training shape, over the
    /// floor.
    pub novelty: f64,
    /// Median distance of a sample to the training shapes' mean over the
    /// same for the real shapes (absent in reports written before it was
    /// measured).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub spread: Option<f64>,
    /// Where the training shapes, held-out shapes and samples sit in the
    /// training shapes' principal plane (absent in reports written before
    /// it was measured).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub plane: Option<PrincipalPlane>,
    /// The same measures for as many draws of the Gaussian fitted to the
    /// training shapes ([`crate::gaussian_baseline`]): what the data's
    /// mean and covariance alone achieve (absent with one training shape,
    /// and in reports written before it was measured).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gaussian: Option<GaussianBaseline>,
    /// Fractions of faces flipped against the nearest real shape.
    pub flipped: FlippedFaces,
    /// The same fractions for the held-out shapes against their nearest
    /// training shapes: the data's own (absent in reports written before
    /// it was measured).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub held_out_flipped: Option<FlippedFaces>,
    /// MMD, COV and 1-NNA against the held-out shapes.
    pub metrics: ShapeMetrics,
    /// Number of samples.
    pub num_samples: usize,
    /// Number of training shapes.
    pub num_train: usize,
    /// Number of held-out shapes.
    pub num_held_out: usize,
    /// Every sample's values, in order.
    pub per_sample: Vec<SampleQuality>,
}

impl ShapeQuality {
    /// The lines `mfm eval` prints: each measure with what it means.
    pub fn summary(&self) -> String {
        let f = &self.flipped;
        let m = &self.metrics;
        let data_flips = self.held_out_flipped.map_or(String::new(), |d| {
            format!(
                "; the held-out shapes against their nearest training shapes: {:.1}% median, \
                 {:.1}% max",
                100.0 * d.median,
                100.0 * d.max
            )
        });
        [
            format!(
                "shape quality of {} samples against {} training and {} held-out shapes \
                 (distances: mass-weighted RMS after centring, over the template's diagonal)",
                self.num_samples, self.num_train, self.num_held_out
            ),
            format!(
                "floor {:.4} (median distance of a held-out shape to the nearest training shape)",
                self.floor
            ),
            format!(
                "plausibility {:.2} (median distance of a sample to the nearest real shape over \
                 the floor; about 1 or below is data-like, far above 1: shapes unlike any real \
                 one)",
                self.plausibility
            ),
            format!(
                "coverage {:.2} (median distance of a held-out shape to the nearest sample {:.4} \
                 over the same for {} random training shapes {:.4}; about 1 when the samples \
                 cover the data, far above 1: parts of it missed)",
                self.coverage,
                self.held_out_to_samples,
                self.baseline_size,
                self.held_out_to_baseline
            ),
            format!(
                "novelty {:.2} (median distance of a sample to the nearest training shape over \
                 the floor; near 0: copies of training shapes)",
                self.novelty
            ),
            format!(
                "roughness {:.2} (median bending energy of a sample over its nearest real \
                 shape's; about 1 is data-like, far below: detail lost, far above: noise)",
                self.roughness
            ),
            spread_line(self.spread, self.plane.as_ref()),
            self.gaussian.map_or(String::new(), |g| {
                format!(
                    "the Gaussian fit of the training shapes ({} draws from their mean and \
                     covariance, measured alike): plausibility {:.2}, coverage {:.2}, spread \
                     {:.2}; samples should do better",
                    g.draws, g.plausibility, g.coverage, g.spread
                )
            }),
            format!(
                "flipped faces {:.1}% median, {:.1}% mean, {:.1}% max (faces whose normal \
                 opposes the nearest real shape's: folds, or parts turned by more than a right \
                 angle{data_flips})",
                100.0 * f.median,
                100.0 * f.mean,
                100.0 * f.max
            ),
            format!(
                "against the held-out shapes: MMD {:.4}  COV {:.3}  1-NNA {:.3}",
                m.mmd, m.cov, m.one_nna
            ),
        ]
        .into_iter()
        .filter(|line| !line.is_empty())
        .collect::<Vec<_>>()
        .join("\n")
    }
}

/// The summary's spread line with the plane's radii (empty when the
/// report has no spread).
fn spread_line(spread: Option<f64>, plane: Option<&PrincipalPlane>) -> String {
    let Some(spread) = spread else {
        return String::new();
    };
    let in_plane = plane.map_or(String::new(), |p| {
        let radius = |c: &[f64; 2]| c[0].hypot(c[1]);
        let real: Vec<f64> = p.train.iter().chain(&p.held_out).map(radius).collect();
        let samples: Vec<f64> = p.samples.iter().map(radius).collect();
        format!(
            "; in the training shapes' principal plane ({:.0}% and {:.0}% of their variance) \
             the median distance from the mean is {:.4} for the samples, {:.4} for the real \
             shapes",
            100.0 * p.explained[0],
            100.0 * p.explained[1],
            median(&samples),
            median(&real)
        )
    });
    format!(
        "spread {spread:.2} (median distance of a sample to the training shapes' mean over the \
         same for the real shapes; about 1 when the samples vary as the data does, below 1: \
         pulled toward the mean shape, blends of shapes{in_plane})"
    )
}

/// The centred distance of the [module docs](self): shapes (3-channel
/// signals) centred by the mass-weighted mean, compared by
/// [`MassWeighted`], divided by the diagonal.
#[derive(Clone, Debug)]
pub struct CentredDistance {
    /// Masses normalized to sum to 1 (the centring weights).
    weights: Vec<f64>,
    metric: MassWeighted,
    diagonal: f64,
}

impl CentredDistance {
    /// The distance with lumped vertex masses `mass` (of the rest mesh) and
    /// distance unit `diagonal`.
    ///
    /// # Errors
    /// [`DataError::Config`] for a diagonal that is not finite and positive,
    /// and as [`MassWeighted::new`].
    pub fn new(mass: &[f64], diagonal: f64) -> Result<Self> {
        if !(diagonal.is_finite() && diagonal > 0.0) {
            return Err(DataError::Config(format!(
                "the template's bounding-box diagonal (the distance unit) must be finite and \
                 positive, found {diagonal}"
            )));
        }
        let metric = MassWeighted::new(mass, 3)?;
        let total: f64 = mass.iter().sum();
        Ok(Self {
            weights: mass.iter().map(|m| m / total).collect(),
            metric,
            diagonal,
        })
    }

    /// Number of vertices.
    pub fn num_vertices(&self) -> usize {
        self.weights.len()
    }

    /// `V` positions with their mass-weighted mean subtracted (`V x 3`
    /// values, unchecked length).
    fn centre_one(&self, x: &[f32]) -> Vec<f32> {
        let points = x
            .chunks_exact(3)
            .map(|p| [f64::from(p[0]), f64::from(p[1]), f64::from(p[2])]);
        let mean = weighted_mean(&self.weights, points);
        x.chunks_exact(3)
            .flat_map(|p| (0..3).map(move |k| (f64::from(p[k]) - mean[k]) as f32))
            .collect()
    }

    /// `set` with every shape centred (mass-weighted mean removed).
    ///
    /// # Errors
    /// [`DataError::SizeMismatch`] unless `set` holds 3-channel signals of
    /// this mesh's vertex count.
    pub fn centre(&self, set: &InMemorySignals) -> Result<InMemorySignals> {
        self.check(set, "shapes")?;
        let data: Vec<f32> = (0..set.len())
            .into_par_iter()
            .flat_map_iter(|i| self.centre_one(set.signal(i)))
            .collect();
        InMemorySignals::new(data, set.len(), set.num_vertices(), 3)
    }

    /// `d(a, b)` for two shapes of `V x 3` values.
    ///
    /// # Errors
    /// [`DataError::SizeMismatch`] if a shape does not have `V x 3` values.
    pub fn distance(&self, a: &[f32], b: &[f32]) -> Result<f64> {
        for (s, what) in [(a, "first shape"), (b, "second shape")] {
            if s.len() != 3 * self.num_vertices() {
                return Err(DataError::SizeMismatch {
                    what: format!("values of the {what} (V x 3)"),
                    expected: 3 * self.num_vertices(),
                    found: s.len(),
                });
            }
        }
        let d = self
            .metric
            .distance(&self.centre_one(a), &self.centre_one(b))?;
        Ok(d / self.diagonal)
    }

    /// The matrix of distances `d(x_i, y_j)`, row-major.
    ///
    /// # Errors
    /// As [`CentredDistance::centre`].
    pub fn pairwise(&self, x: &InMemorySignals, y: &InMemorySignals) -> Result<DistanceMatrix> {
        self.pairwise_centred(&self.centre(x)?, &self.centre(y)?)
    }

    /// [`CentredDistance::pairwise`] of sets already centred.
    fn pairwise_centred(&self, x: &InMemorySignals, y: &InMemorySignals) -> Result<DistanceMatrix> {
        let mut m = self.metric.pairwise(x, y)?;
        m.values.iter_mut().for_each(|d| *d /= self.diagonal);
        Ok(m)
    }

    fn check(&self, set: &InMemorySignals, what: &str) -> Result<()> {
        check_shapes(set, self.num_vertices(), what)
    }
}

/// `sum_v w_v p_v` over the points `p` (the mass-weighted mean for weights
/// summing to 1).
pub(crate) fn weighted_mean(weights: &[f64], points: impl Iterator<Item = [f64; 3]>) -> [f64; 3] {
    let mut mean = [0.0f64; 3];
    for (w, p) in weights.iter().zip(points) {
        for k in 0..3 {
            mean[k] += w * p[k];
        }
    }
    mean
}

/// Checks that `set` holds positions (3 channels) of `vertices` vertices.
fn check_shapes(set: &InMemorySignals, vertices: usize, what: &str) -> Result<()> {
    if set.channels() != 3 {
        return Err(DataError::SizeMismatch {
            what: format!("channels of the {what} (vertex positions need 3)"),
            expected: 3,
            found: set.channels(),
        });
    }
    if set.num_vertices() != vertices {
        return Err(DataError::SizeMismatch {
            what: format!("vertices of the {what} (the reference mesh's)"),
            expected: vertices,
            found: set.num_vertices(),
        });
    }
    Ok(())
}

impl ShapeSets<'_> {
    /// The positions of real shape `r`.
    ///
    /// # Errors
    /// [`DataError::SizeMismatch`] for an index outside its set (a
    /// [`ShapeQuality`] of other sets).
    pub fn real_positions(&self, r: RealShape) -> Result<Vec<[f64; 3]>> {
        let (set, what) = match r.set {
            RealSet::Train => (self.train, "training shape index"),
            RealSet::HeldOut => (self.held_out, "held-out shape index"),
        };
        if r.index >= set.len() {
            return Err(DataError::SizeMismatch {
                what: what.into(),
                expected: set.len(),
                found: r.index,
            });
        }
        Ok(set.positions(r.index))
    }

    /// Checks sizes, counts, the diagonal and finiteness.
    fn validate(&self) -> Result<()> {
        if !(self.diagonal.is_finite() && self.diagonal > 0.0) {
            return Err(DataError::Config(format!(
                "the template's bounding-box diagonal (the distance unit) must be finite and \
                 positive, found {}",
                self.diagonal
            )));
        }
        let v = self.mesh.num_vertices();
        for (set, what) in [
            (self.train, "training shapes"),
            (self.held_out, "held-out shapes"),
            (self.samples, "samples"),
        ] {
            if set.is_empty() {
                return Err(DataError::Config(format!(
                    "shape quality needs at least one of the {what}, found none"
                )));
            }
            check_shapes(set, v, what)?;
            if let Some((i, vertex, channel, x)) = set.first_non_finite() {
                return Err(DataError::Config(format!(
                    "shape {i} of the {what} is not finite ({x} at vertex {vertex}, channel \
                     {channel})"
                )));
            }
        }
        Ok(())
    }
}

/// Judges `sets.samples` against the real shapes; see the [module
/// docs](self) for the measures and their cost.
///
/// # Errors
/// [`DataError::Config`] for an empty set, a diagonal that is not finite
/// and positive, a non-finite shape, or a floor of 0 (the held-out shapes
/// are, up to translation, training shapes);
/// [`DataError::SizeMismatch`] for shapes that are not 3-channel positions
/// of the mesh's vertices; [`DataError::Operators`] for a mesh with a
/// degenerate face.
pub fn shape_quality(sets: &ShapeSets) -> Result<ShapeQuality> {
    sets.validate()?;
    let ops = Operators::new(sets.mesh)?;
    let centred = CentredDistance::new(&ops.mass, sets.diagonal)?;
    let (n_t, n_h, n_s) = (sets.train.len(), sets.held_out.len(), sets.samples.len());
    let v = sets.mesh.num_vertices();

    // real = training shapes, then held-out shapes (all centred)
    let mut real_data = centred.centre(sets.train)?.data().to_vec();
    let held = centred.centre(sets.held_out)?;
    real_data.extend_from_slice(held.data());
    let real = InMemorySignals::new(real_data, n_t + n_h, v, 3)?;
    let samples = centred.centre(sets.samples)?;
    let train = InMemorySignals::new(real.data()[..n_t * v * 3].to_vec(), n_t, v, 3)?;
    let plane = PlaneProjector::fit(&train, &ops.mass, sets.diagonal, sets.seed)?;
    let to_mean = |set: &InMemorySignals| -> Vec<f64> {
        (0..set.len())
            .into_par_iter()
            .map(|i| plane.distance_to_mean(set.signal(i)))
            .collect()
    };
    let spread = ratio(median(&to_mean(&samples)), median(&to_mean(&real)));

    let sample_real = centred.pairwise_centred(&samples, &real)?;
    let held_real = centred.pairwise_centred(&held, &real)?;
    let sample_sample = centred.pairwise_centred(&samples, &samples)?;

    let floor = median(
        &(0..n_h)
            .map(|h| min_over(&held_real, h, 0..n_t))
            .collect::<Vec<_>>(),
    );
    if floor <= 0.0 {
        return Err(DataError::Config(format!(
            "the floor (median distance of a held-out shape to the nearest training shape) is \
             0: at least half of the {n_h} held-out shapes are, up to translation, training \
             shapes; hold out shapes that are not in the training set"
        )));
    }

    // coverage: held-out to samples, and to as many random training shapes
    let to_samples: Vec<f64> = (0..n_h)
        .map(|h| min_over_rows(&sample_real, 0..n_s, n_t + h))
        .collect();
    let baseline_size = n_s.min(n_t);
    let mut rng = ChaCha8Rng::seed_from_u64(sets.seed);
    let subset = rand::seq::index::sample(&mut rng, n_t, baseline_size).into_vec();
    let to_baseline: Vec<f64> = (0..n_h)
        .map(|h| min_over(&held_real, h, subset.iter().copied()))
        .collect();
    let (held_out_to_samples, held_out_to_baseline) = (median(&to_samples), median(&to_baseline));

    // the Gaussian fitted to the training shapes, as many draws as samples
    let gaussian = if n_t >= 2 {
        let draws = gaussian_shapes(&train, n_s, sets.seed)?;
        let draw_real = centred.pairwise_centred(&draws, &real)?;
        let nearest: Vec<f64> = (0..n_s)
            .map(|s| draw_real.row_min(s).map_or(f64::NAN, |(_, d)| d))
            .collect();
        Some(GaussianBaseline {
            plausibility: median(&nearest) / floor,
            coverage: median(
                &(0..n_h)
                    .map(|h| min_over_rows(&draw_real, 0..n_s, n_t + h))
                    .collect::<Vec<_>>(),
            ) / held_out_to_baseline,
            spread: ratio(median(&to_mean(&draws)), median(&to_mean(&real))),
            draws: n_s,
        })
    } else {
        None
    };

    // bending energies of every real shape and sample
    let real_energy = bending_energies(sets.mesh, &real)?;
    let sample_energy = bending_energies(sets.mesh, &samples)?;

    let per_sample: Vec<SampleQuality> = (0..n_s)
        .into_par_iter()
        .map(|s| {
            let (j, distance) = sample_real.row_min(s).unwrap_or((0, f64::NAN));
            let training_distance = min_over(&sample_real, s, 0..n_t);
            let nearest = if j < n_t {
                RealShape {
                    set: RealSet::Train,
                    index: j,
                }
            } else {
                RealShape {
                    set: RealSet::HeldOut,
                    index: j - n_t,
                }
            };
            SampleQuality {
                nearest,
                distance,
                training_distance,
                roughness: ratio(sample_energy[s], real_energy[j]),
                flipped: flipped_fraction(sets.mesh, samples.signal(s), real.signal(j)),
            }
        })
        .collect();

    let column = |f: fn(&SampleQuality) -> f64| -> Vec<f64> { per_sample.iter().map(f).collect() };
    let flipped = FlippedFaces::of(&column(|q| q.flipped));
    // the data's own: each held-out shape against its nearest training shape
    let held_out_flips: Vec<f64> = (0..n_h)
        .into_par_iter()
        .map(|h| {
            let t = (0..n_t)
                .min_by(|&a, &b| held_real.get(h, a).total_cmp(&held_real.get(h, b)))
                .unwrap_or(0);
            flipped_fraction(sets.mesh, held.signal(h), real.signal(t))
        })
        .collect();

    let gen_ref = columns(&sample_real, n_t..n_t + n_h);
    let ref_ref = columns(&held_real, n_t..n_t + n_h);
    let metrics = ShapeMetrics {
        mmd: metrics::mmd(&gen_ref)?,
        cov: metrics::coverage(&gen_ref)?,
        one_nna: metrics::one_nna(&sample_sample, &gen_ref, &ref_ref)?,
    };

    Ok(ShapeQuality {
        floor,
        plausibility: median(&column(|q| q.distance)) / floor,
        coverage: held_out_to_samples / held_out_to_baseline,
        held_out_to_samples,
        held_out_to_baseline,
        baseline_size,
        roughness: median(&column(|q| q.roughness)),
        novelty: median(&column(|q| q.training_distance)) / floor,
        spread: Some(spread),
        plane: Some(plane.place(&train, &held, &samples)),
        gaussian,
        flipped,
        held_out_flipped: Some(FlippedFaces::of(&held_out_flips)),
        metrics,
        num_samples: n_s,
        num_train: n_t,
        num_held_out: n_h,
        per_sample,
    })
}

/// The smallest entry of column `j` of `m` among the rows `rows`
/// (infinity for none).
fn min_over_rows(m: &DistanceMatrix, rows: impl Iterator<Item = usize>, j: usize) -> f64 {
    rows.map(|i| m.get(i, j)).fold(f64::INFINITY, f64::min)
}

/// The smallest entry of row `i` of `m` among the columns `cols`
/// (infinity for none).
fn min_over(m: &DistanceMatrix, i: usize, cols: impl Iterator<Item = usize>) -> f64 {
    cols.map(|j| m.get(i, j)).fold(f64::INFINITY, f64::min)
}

/// The median of `values` ([`Quartiles`]).
fn median(values: &[f64]) -> f64 {
    Quartiles::of(values).median
}

/// `a / b`, with `0 / 0 = 1` (both flat) and `x / 0 = infinity`.
fn ratio(a: f64, b: f64) -> f64 {
    match (a == 0.0, b == 0.0) {
        (true, true) => 1.0,
        (false, true) => f64::INFINITY,
        _ => a / b,
    }
}

/// The columns `range` of `m`.
fn columns(m: &DistanceMatrix, range: std::ops::Range<usize>) -> DistanceMatrix {
    let values = (0..m.rows)
        .flat_map(|i| m.row(i)[range.clone()].iter().copied())
        .collect();
    DistanceMatrix {
        rows: m.rows,
        cols: range.len(),
        values,
    }
}

/// The bending energy `E` (see the [module docs](self)) of every shape of
/// `set` (positions of `mesh`'s vertices), each with its own operators
/// (`mesh` moved to the shape).
///
/// # Errors
/// [`DataError::SizeMismatch`] for shapes that are not positions of the
/// mesh's vertices.
pub fn bending_energies(mesh: &TriMesh, set: &InMemorySignals) -> Result<Vec<f64>> {
    check_shapes(set, mesh.num_vertices(), "shapes")?;
    Ok((0..set.len())
        .into_par_iter()
        .map(|i| bending_energy(mesh, set.signal(i)))
        .collect())
}

/// `E(x) = sum_i |(L_x x)_i|^2 / m_i` over the vertices with mass, for the
/// positions `x` (`V x 3` values) of `mesh`'s vertices, with the operators
/// of the shape itself (`L_x`, `M_x` of the mesh moved to `x`; a
/// degenerate face contributes nothing to either).
fn bending_energy(mesh: &TriMesh, x: &[f32]) -> f64 {
    let positions: Vec<[f64; 3]> = x
        .chunks_exact(3)
        .map(|p| [f64::from(p[0]), f64::from(p[1]), f64::from(p[2])])
        .collect();
    let Ok(shape) = mesh.with_positions(positions) else {
        return f64::NAN;
    };
    let l = mfm_geometry::operators::cotangent_laplacian(&shape);
    let mass = mfm_geometry::operators::lumped_mass(&shape);
    let (col_ptr, row_idx, val) = (l.symbolic().col_ptr(), l.symbolic().row_idx(), l.val());
    let mut lx = vec![[0.0f64; 3]; mass.len()];
    for (j, p) in shape.positions().iter().enumerate() {
        for k in col_ptr[j]..col_ptr[j + 1] {
            let (i, w) = (row_idx[k], val[k]);
            for c in 0..3 {
                lx[i][c] += w * p[c];
            }
        }
    }
    lx.iter()
        .zip(&mass)
        .filter(|(_, m)| **m > 0.0)
        .map(|(y, m)| dot(*y, *y) / m)
        .sum()
}

/// Fraction of `mesh`'s faces whose normal on `shape` has a negative dot
/// product with its normal on `real` (both `V x 3` values).
fn flipped_fraction(mesh: &TriMesh, shape: &[f32], real: &[f32]) -> f64 {
    let faces = mesh.faces();
    if faces.is_empty() {
        return 0.0;
    }
    let corner = |x: &[f32], v: u32| -> [f64; 3] {
        let i = 3 * v as usize;
        [f64::from(x[i]), f64::from(x[i + 1]), f64::from(x[i + 2])]
    };
    let normal = |x: &[f32], f: &[u32; 3]| triangle_normal(&f.map(|v| corner(x, v)));
    let flipped = faces
        .iter()
        .filter(|f| dot(normal(shape, f), normal(real, f)) < 0.0)
        .count();
    flipped as f64 / faces.len() as f64
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use mfm_geometry::procedural;

    #[test]
    fn the_bending_energy_of_the_unit_sphere_is_16_pi() {
        // M^-1 L x = 2 H n with H = 1: |.|^2 = 4 over an area of 4 pi
        let mesh = procedural::icosphere(3);
        let x: Vec<f32> = mesh
            .positions()
            .iter()
            .flat_map(|p| p.map(|c| c as f32))
            .collect();
        let e = bending_energy(&mesh, &x);
        let want = 16.0 * std::f64::consts::PI;
        assert!((e / want - 1.0).abs() < 0.02, "{e} vs {want}");
        // blind to scale and translation (the integral of H^2 is)
        let moved: Vec<f32> = x.iter().map(|c| 2.0 * c + 0.5).collect();
        let e2 = bending_energy(&mesh, &moved);
        assert!((e2 / e - 1.0).abs() < 1e-5, "{e2} vs {e}");
        // an ellipsoid bends more than the sphere
        let squashed: Vec<f32> = x
            .chunks_exact(3)
            .flat_map(|p| [p[0], p[1], 0.3 * p[2]])
            .collect();
        assert!(bending_energy(&mesh, &squashed) > 1.5 * e);
    }

    #[test]
    fn flips_count_faces_turned_over() {
        // a flat grid (normals +z) mirrored in x: every normal turns to -z
        let mesh = procedural::plane_grid(4, 4, 1.0, 1.0).unwrap();
        let x: Vec<f32> = mesh
            .positions()
            .iter()
            .flat_map(|p| p.map(|c| c as f32))
            .collect();
        assert_eq!(flipped_fraction(&mesh, &x, &x), 0.0);
        let mirrored: Vec<f32> = x
            .chunks_exact(3)
            .flat_map(|p| [-p[0], p[1], p[2]])
            .collect();
        assert_eq!(flipped_fraction(&mesh, &mirrored, &x), 1.0);
        // a point reflection keeps every (unnormalised) normal
        let reflected: Vec<f32> = x.iter().map(|c| -c).collect();
        assert_eq!(flipped_fraction(&mesh, &reflected, &x), 0.0);
    }

    #[test]
    fn ratios_of_flat_energies_are_defined() {
        assert_eq!(ratio(0.0, 0.0), 1.0);
        assert_eq!(ratio(1.0, 0.0), f64::INFINITY);
        assert_eq!(ratio(1.0, 4.0), 0.25);
    }

    #[test]
    fn columns_are_cut_from_every_row() {
        let m = DistanceMatrix {
            rows: 2,
            cols: 3,
            values: vec![0.0, 1.0, 2.0, 3.0, 4.0, 5.0],
        };
        let c = columns(&m, 1..3);
        assert_eq!((c.rows, c.cols, c.values), (2, 2, vec![1.0, 2.0, 4.0, 5.0]));
    }
}
