//! # mfm-deform
//!
//! Elastic-looking deformations of a triangle mesh with a known parameter
//! space, for mfm's deformation experiments (DESIGN.md §8, issue 6): handle
//! regions defined in ambient space, an as-rigid-as-possible (ARAP) solver
//! on mfm-solver's sparse Cholesky cache, a seeded deformation space with
//! parallel, thread-count-independent generation, alignment of shapes to
//! their rest shape, and the projection (plausibility) metric that stands in
//! for the paper's SMPL regression error.
//!
//! - [`handles`]: [`Handle`] (a ball), [`HandleSet`] (an anchor plus moving
//!   handles, [`HandleSet::auto`] at the extremities), [`RigidParams`] and
//!   [`DeformParams`] (one rigid motion per moving handle).
//! - [`arap`]: [`Arap`] (factor once, deform many times), [`ArapOptions`],
//!   [`Deformation`]. Classic cotangent ARAP plus a smoothness term on the
//!   rotation field ([`ArapOptions::smoothness`], on by default): pure
//!   surface ARAP buckles into folds as narrow as the mesh allows, so its
//!   shapes differ between a mesh and its refinement; with the term they
//!   agree to a few percent of the displacement.
//! - [`space`]: [`DeformSpace`] (`sample_params(seed, index)`,
//!   [`DeformSpace::generate`]) and [`Shape`].
//! - [`shape`]: [`ShapeFamily`] (smooth region-wise anisotropic scalings
//!   of a template, a stand-in for a body-shape space), [`ShapeParams`],
//!   and the posing of a member with the template's handles
//!   ([`ShapeFamily::pose_space`], [`Arap::with_regions`]).
//! - [`align`]: [`normalize_rest`], [`align_to_rest`] (centroid + rotation
//!   about the up axis, Procrustes to the rest), [`align_rigid`].
//! - [`projection`]: [`project`] and [`Projection`] (mass-weighted MSE).
//! - [`rigid`]: rotations (axis-angle, quaternions), best rotation of a
//!   cross-covariance, weighted Kabsch fit.
//!
//! ## Conventions
//! - Positions are `[f64; 3]` per vertex, in the vertex order of the mesh;
//!   a *shape* is new positions for the vertices of a rest mesh.
//! - `L` is mfm's PSD cotangent Laplacian (`L_ij = -(cot a + cot b)/2`), so
//!   the ARAP edge weights are `w_ij = -L_ij`; `M` is the lumped mass, and
//!   every weighted mean or error here is weighted by the lumped mass of the
//!   **rest** mesh.
//! - A handle motion is a rotation (axis-angle, radians) about the handle's
//!   center, then a translation. Handles are numbered anchor first.
//! - Randomness: one ChaCha8 stream per `(seed, sample index)`; results are
//!   bit-identical for any number of threads.
//!
//! This crate depends on neither libtorch nor Python.
//!
//! ## Example
//! ```
//! use mfm_deform::{normalize_rest, project, Arap, DeformSpace, HandleSet};
//! use mfm_geometry::procedural;
//!
//! let (rest, _scale, _shift) = normalize_rest(&procedural::blob(2).unwrap()).unwrap();
//! let handles = HandleSet::auto(&rest, 3, 0.1).unwrap();
//! let space = DeformSpace::new(&rest, handles);
//! let shapes = space.generate(&rest, 1, 0..3, |_| {}).unwrap();
//! // a generated shape lies in the space: it projects onto itself
//! let arap = Arap::new(&rest, &space.handles).unwrap();
//! let p = project(&arap, &space, &shapes[0].positions).unwrap();
//! assert!(p.mse < 1e-12);
//! ```

pub mod align;
mod anderson;
pub mod arap;
pub mod error;
pub mod handles;
pub mod projection;
pub mod rigid;
pub mod shape;
pub mod space;

pub use align::{align_rigid, align_to_rest, normalize_rest};
pub use arap::{Arap, ArapOptions, Deformation};
pub use error::{DeformError, Result};
pub use handles::{DEFAULT_RADIUS_FRACTION, DeformParams, Handle, HandleSet, RigidParams};
pub use projection::{Projection, project};
pub use shape::{ShapeFamily, ShapeParams, ShapeRegion};
pub use space::{DEFAULT_MAX_ANGLE, DEFAULT_MAX_SHIFT, DeformSpace, Shape};
