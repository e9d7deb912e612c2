//! # mfm-processing
//!
//! Mesh processing for the remeshing experiments: operations that change a
//! triangulation while keeping (or, for holes, cutting) the surface, so that
//! a signal learned on one mesh can be tested on another.
//!
//! - [`refine`]: local, conforming refinement by longest-edge bisection, with
//!   the [`mfm_geometry::subdivide::SubdivisionMap`] that carries data along;
//! - [`decimate`]: quadric-error edge-collapse decimation to a face budget;
//! - [`flips`]: random edge flips, to make a triangulation worse on purpose;
//! - [`holes`]: holes cut around centre vertices, connected components,
//!   edge-path distances.
//!
//! Uniform subdivision (midpoint, Loop) is part of the mesh core
//! (`mfm_geometry::subdivide`), since procedural meshes are built with it.
//! Every operation returns a new [`mfm_geometry::TriMesh`] and leaves its
//! input untouched; randomized ones take a seed and give the same mesh for
//! it on any thread count.
//!
//! ## Example
//! ```
//! use mfm_geometry::procedural;
//! use mfm_processing::{flips, refine};
//! let sphere = procedural::icosphere(2);
//! // refine the cap z > 0.5 ...
//! let finer =
//!     refine::refine_region(&sphere, |c| c[2] > 0.5, refine::RefineCriterion::Rounds(2)).unwrap();
//! assert!(finer.num_faces() > sphere.num_faces());
//! // ... and flip 50 random edges of it, the same ones for the same seed
//! let a = flips::random_edge_flips(&finer, flips::FlipAmount::Count(50), 7);
//! assert_eq!(a.mesh, flips::random_edge_flips(&finer, flips::FlipAmount::Count(50), 7).mesh);
//! ```

pub mod decimate;
pub mod flips;
pub mod holes;
pub mod refine;
