#![doc = include_str!("../README.md")]

pub mod closest;
pub mod frame;
pub mod geodesic;
pub mod mesh;
pub mod operators;
pub mod procedural;
pub mod subdivide;
/// Helpers of the mfm workspace's own test suites (shared meshes, the
/// Python oracle): with the non-default `test-support` feature only, and
/// not part of the crate's stable API.
#[cfg(feature = "test-support")]
#[doc(hidden)]
pub mod test_support;
pub mod topology;
pub mod validate;

pub use mesh::{MeshError, TriMesh};
pub use topology::Topology;
pub use validate::MeshReport;

/// The linear algebra crate of the operators' public API (sparse matrices),
/// re-exported so callers use the same version.
pub use faer;
