//! A seeded space of deformations: random rigid motions of the moving
//! handles, realized by ARAP and aligned to the rest shape.
//!
//! A [`DeformSpace`] is everything needed to regenerate a dataset: the
//! handles, the ranges of the random motions, the length scale they are
//! measured in, the up axis of the alignment and the ARAP stopping rule. It
//! is serde-serializable so it can be stored in a dataset manifest.
//!
//! ## Sampling
//! The parameters of sample `index` under `seed` are a pure function of
//! `(seed, index)`: a ChaCha8 stream keyed by `seed`, on stream number
//! `index`, reads six uniforms per moving handle (in handle order): a
//! rotation axis uniform on the sphere, an angle uniform in
//! `[0, max_angle]`, and a translation uniform in the ball of radius
//! `max_shift * diagonal`. The anchor does not move.
//!
//! ## Generation
//! [`DeformSpace::generate`] builds one [`Arap`] for the mesh and realizes a
//! range of samples in parallel (rayon): each is ARAP-deformed
//! ([`DeformSpace::arap`] options) and aligned to the rest shape
//! ([`align_to_rest`] about [`DeformSpace::up`]). Results come back in index
//! order and are bit-identical for any number of threads. The same space
//! and seed on another triangulation of the surface (same handles, same
//! length scale) gives the same parameters, hence corresponding shapes.

use std::ops::Range;
use std::sync::atomic::{AtomicUsize, Ordering};

use mfm_geometry::TriMesh;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::align::align_to_rest;
use crate::arap::{Arap, ArapOptions};
use crate::error::{DeformError, Result};
use crate::handles::{DeformParams, HandleSet, RigidParams};

/// Default largest rotation angle of a moving handle, in radians.
pub const DEFAULT_MAX_ANGLE: f64 = 0.5;

/// Default largest translation of a moving handle, as a fraction of
/// [`DeformSpace::diagonal`].
pub const DEFAULT_MAX_SHIFT: f64 = 0.12;

fn default_up() -> usize {
    1
}

/// A space of deformations; see the [module docs](self).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DeformSpace {
    /// The handles (the anchor stays fixed).
    pub handles: HandleSet,
    /// Largest rotation angle of a moving handle (radians). Default 0.5.
    pub max_angle: f64,
    /// Largest translation of a moving handle, as a fraction of `diagonal`.
    /// Default 0.12.
    pub max_shift: f64,
    /// The length scale of `max_shift`: the bounding-box diagonal of the rest
    /// mesh the space was made for (1 for a mesh from
    /// [`crate::normalize_rest`]). Kept here so that every triangulation gets
    /// the same parameters.
    pub diagonal: f64,
    /// Axis index (0 = x, 1 = y, 2 = z) about which shapes are aligned to
    /// the rest shape. Default 1 (y up).
    #[serde(default = "default_up")]
    pub up: usize,
    /// ARAP stopping rule.
    #[serde(default)]
    pub arap: ArapOptions,
}

/// One generated sample: its parameters and its aligned vertex positions.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Shape {
    /// The parameters of the sample.
    pub params: DeformParams,
    /// ARAP-deformed positions, aligned to the rest shape (`V`).
    pub positions: Vec<[f64; 3]>,
}

impl DeformSpace {
    /// A space with the default ranges ([`DEFAULT_MAX_ANGLE`],
    /// [`DEFAULT_MAX_SHIFT`]), y up, default [`ArapOptions`], and the
    /// bounding-box diagonal of `rest` as length scale.
    pub fn new(rest: &TriMesh, handles: HandleSet) -> Self {
        Self {
            handles,
            max_angle: DEFAULT_MAX_ANGLE,
            max_shift: DEFAULT_MAX_SHIFT,
            diagonal: rest.bounding_box_diagonal(),
            up: default_up(),
            arap: ArapOptions::default(),
        }
    }

    /// Checks the ranges: `max_angle` finite and `>= 0`, `max_shift` in
    /// `[0, 1]`,
    /// `diagonal` finite and `> 0`, `up <= 2`.
    ///
    /// # Errors
    /// [`DeformError::InvalidParameter`] naming the field.
    pub fn validate(&self) -> Result<()> {
        let bad = |name: &'static str, expected: &'static str, found: String| {
            Err(DeformError::InvalidParameter {
                name,
                expected,
                found,
            })
        };
        if !(self.max_angle.is_finite() && self.max_angle >= 0.0) {
            return bad(
                "max_angle",
                "a finite angle >= 0 (radians)",
                self.max_angle.to_string(),
            );
        }
        if !(self.max_shift.is_finite() && (0.0..=1.0).contains(&self.max_shift)) {
            return bad(
                "max_shift",
                "a fraction of the bounding-box diagonal in [0, 1] (0.05 to 0.2 pose a shape; a \
                 handle moved farther than the shape's size tears it apart)",
                self.max_shift.to_string(),
            );
        }
        if !(self.diagonal.is_finite() && self.diagonal > 0.0) {
            return bad("diagonal", "a finite length > 0", self.diagonal.to_string());
        }
        if self.up > 2 {
            return bad("up", "an axis index 0, 1 or 2", self.up.to_string());
        }
        Ok(())
    }

    /// The parameters of sample `index`: a pure function of `(seed, index)`
    /// and the space's ranges (see the [module docs](self)). Cost: `O(handles)`.
    pub fn sample_params(&self, seed: u64, index: usize) -> DeformParams {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        rng.set_stream(index as u64);
        let max_shift = self.max_shift * self.diagonal;
        let handles = (0..self.handles.num_moving())
            .map(|_| {
                let axis = unit_vector(&mut rng);
                let angle = self.max_angle * rng.random::<f64>();
                let direction = unit_vector(&mut rng);
                let radius = max_shift * rng.random::<f64>().cbrt();
                RigidParams {
                    rotation: [angle * axis[0], angle * axis[1], angle * axis[2]],
                    translation: [
                        radius * direction[0],
                        radius * direction[1],
                        radius * direction[2],
                    ],
                }
            })
            .collect();
        DeformParams { handles }
    }

    /// The aligned shape of `params` on the mesh of `arap`: ARAP deformation
    /// with [`DeformSpace::arap`], then [`align_to_rest`] about
    /// [`DeformSpace::up`]. This is what [`DeformSpace::generate`] stores.
    ///
    /// # Errors
    /// As [`Arap::deform`] and [`align_to_rest`].
    pub fn realize(&self, arap: &Arap, params: &DeformParams) -> Result<Vec<[f64; 3]>> {
        let out = arap.deform(params, &self.arap)?;
        align_to_rest(arap.rest(), &out.positions, self.up)
    }

    /// Generates samples `range` under `seed` on `rest`: builds one
    /// [`Arap`] with [`DeformSpace::handles`], then as
    /// [`DeformSpace::generate_with`].
    ///
    /// # Errors
    /// As [`Arap::new`] and [`DeformSpace::generate_with`].
    ///
    /// # Example
    /// ```
    /// use mfm_deform::{DeformSpace, HandleSet};
    /// use mfm_geometry::procedural;
    /// use std::sync::atomic::{AtomicUsize, Ordering};
    ///
    /// let mesh = procedural::blob(2).unwrap();
    /// let space = DeformSpace::new(&mesh, HandleSet::auto(&mesh, 3, 0.1).unwrap());
    /// let done = AtomicUsize::new(0);
    /// let shapes = space
    ///     .generate(&mesh, 42, 0..4, |_| { done.fetch_add(1, Ordering::Relaxed); })
    ///     .unwrap();
    /// assert_eq!(shapes.len(), 4);
    /// assert_eq!(done.load(Ordering::Relaxed), 4);
    /// // a stored sample is reproduced from its parameters
    /// assert_eq!(shapes[2].params, space.sample_params(42, 2));
    /// let again = space.generate(&mesh, 42, 2..3, |_| {}).unwrap();
    /// assert_eq!(again[0], shapes[2]);
    /// ```
    pub fn generate(
        &self,
        rest: &TriMesh,
        seed: u64,
        range: Range<usize>,
        progress: impl Fn(usize) + Sync,
    ) -> Result<Vec<Shape>> {
        self.validate()?;
        let arap = Arap::new(rest, &self.handles)?;
        self.generate_with(&arap, seed, range, progress)
    }

    /// Generates samples `range` under `seed` with an existing solver (its
    /// handle set must equal [`DeformSpace::handles`]), in parallel on the
    /// current rayon pool. `progress` is called once per finished sample,
    /// from worker threads, with the number of samples of this call finished
    /// so far (`1..=range.len()`, in completion order). Results are in index
    /// order and bit-identical for any thread count.
    ///
    /// # Errors
    /// [`DeformError::InvalidParameter`] for invalid ranges or a solver built
    /// with other handles; the first error of any sample otherwise.
    pub fn generate_with(
        &self,
        arap: &Arap,
        seed: u64,
        range: Range<usize>,
        progress: impl Fn(usize) + Sync,
    ) -> Result<Vec<Shape>> {
        self.validate()?;
        if arap.handles() != &self.handles {
            return Err(DeformError::InvalidParameter {
                name: "arap",
                expected: "a solver built with the space's handle set",
                found: "a solver with another handle set".to_string(),
            });
        }
        let done = AtomicUsize::new(0);
        range
            .into_par_iter()
            .with_max_len(1)
            .map(|index| {
                let params = self.sample_params(seed, index);
                let positions = self.realize(arap, &params)?;
                progress(done.fetch_add(1, Ordering::Relaxed) + 1);
                Ok(Shape { params, positions })
            })
            .collect()
    }
}

/// A direction uniform on the unit sphere from two uniforms (`z` uniform in
/// `[-1, 1]` and an azimuth: Archimedes' hat-box theorem).
fn unit_vector(rng: &mut ChaCha8Rng) -> [f64; 3] {
    let z = 2.0 * rng.random::<f64>() - 1.0;
    let phi = std::f64::consts::TAU * rng.random::<f64>();
    let r = (1.0 - z * z).max(0.0).sqrt();
    [r * phi.cos(), r * phi.sin(), z]
}
