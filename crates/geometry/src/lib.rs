//! # mfm-geometry
//!
//! The mesh core of mfm: the triangle mesh type, its topology, validation
//! with a readable [`MeshReport`], the intrinsic operators every other mfm
//! crate is built on, heat-method geodesic distances, the canonical frame, procedural meshes, uniform
//! subdivision and closest points on a mesh's surface ([`closest`]). Mesh
//! files are read and written by `mfm-meshio`, remeshing
//! (refinement, decimation, edge flips, holes) is `mfm-processing`, and
//! pictures are `mfm-render`; this crate has no file-format, image or font
//! dependency. Its only mfm dependency is `mfm-solver` (sparse Cholesky), with
//! which [`geodesic::HeatGeodesics`] factors its two systems.
//!
//! ## Conventions
//! - A mesh is `V x 3` `f64` positions and `F x 3` `u32` counter-clockwise faces.
//! - `L` is the cotangent Laplacian in the **positive semi-definite** convention
//!   (`L_ij = -(cot a + cot b)/2`, `L_ii = -sum_j L_ij`); libigl's `cotmatrix` is `-L`.
//! - `M` is the lumped (barycentric) mass: a third of the incident face areas.
//! - `G` is the intrinsic gradient (`2F x V`), rows `2f, 2f+1` the components in
//!   a per-face orthonormal frame built from edge lengths; `G^T diag(A2) G = L`.
//!
//! This crate depends on neither libtorch nor Python.
//!
//! ## Example
//! ```
//! use mfm_geometry::{operators, procedural};
//! let mesh = procedural::icosphere(2);
//! let l = operators::cotangent_laplacian(&mesh);
//! let m = operators::lumped_mass(&mesh);
//! assert_eq!(l.nrows(), mesh.num_vertices());
//! // the lumped mass sums to the surface area
//! assert!((m.iter().sum::<f64>() - mesh.total_area()).abs() < 1e-12);
//! ```

pub mod closest;
pub mod frame;
pub mod geodesic;
pub mod mesh;
pub mod operators;
pub mod procedural;
pub mod subdivide;
#[doc(hidden)]
pub mod test_support;
pub mod topology;
pub mod validate;

pub use mesh::{MeshError, TriMesh};
pub use topology::Topology;
pub use validate::MeshReport;
