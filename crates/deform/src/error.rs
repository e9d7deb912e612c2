//! The error type shared by every fallible entry point of the crate.

use mfm_processing::holes::HoleError;
use mfm_solver::SolverError;
use thiserror::Error;

/// Everything that can go wrong when placing handles, building or running the
/// ARAP solver, sampling a deformation space, aligning or projecting a shape.
///
/// Each variant says what was expected, what was found and where. Handles are
/// named the way [`crate::HandleSet::name`] names them (`"anchor"`,
/// `"handle 0"`, `"handle 1"`, ...).
#[derive(Debug, Error)]
pub enum DeformError {
    /// A handle's ball contains no vertex of the mesh it is applied to.
    #[error(
        "{handle} (center {center:?}, radius {radius:e}) contains no vertex of the mesh \
         ({num_vertices} vertices); the nearest vertex is at distance {nearest:e}"
    )]
    EmptyHandle {
        /// Name of the handle.
        handle: String,
        /// Its center.
        center: [f64; 3],
        /// Its radius.
        radius: f64,
        /// Vertex count of the mesh.
        num_vertices: usize,
        /// Distance from the center to the nearest vertex.
        nearest: f64,
    },

    /// Two handle regions share a vertex of the mesh.
    #[error("{first} and {second} overlap: both contain vertex {vertex} of the mesh")]
    OverlappingHandles {
        /// Name of the first handle.
        first: String,
        /// Name of the second handle.
        second: String,
        /// A vertex in both regions.
        vertex: usize,
    },

    /// Deformation parameters do not have one transform per moving handle.
    #[error("expected {expected} handle transforms (one per moving handle), found {found}")]
    HandleCountMismatch {
        /// Moving handles of the handle set.
        expected: usize,
        /// Transforms given.
        found: usize,
    },

    /// Two sizes that must agree do not (e.g. a shape and a mesh).
    #[error("size mismatch: {what} has {found} entries, expected {expected}")]
    SizeMismatch {
        /// What was measured.
        what: &'static str,
        /// The size implied by the other inputs.
        expected: usize,
        /// The size found.
        found: usize,
    },

    /// A scalar parameter or option is out of range.
    #[error("invalid parameter {name}: expected {expected}, found {found}")]
    InvalidParameter {
        /// Name of the parameter.
        name: &'static str,
        /// What it must satisfy.
        expected: &'static str,
        /// The value given, as text.
        found: String,
    },

    /// A position or a transform parameter is NaN or infinite.
    #[error("{what} has a non-finite value at entry {index}: {value:?}")]
    NonFinite {
        /// Which input.
        what: &'static str,
        /// Index of the offending entry (vertex or handle).
        index: usize,
        /// The offending triple.
        value: [f64; 3],
    },

    /// Some free vertex is not connected (through mesh edges with a non-zero
    /// cotangent weight) to any handle vertex, so its position is not
    /// determined by the handles: a connected component without a handle, an
    /// unreferenced vertex, or a part cut off by degenerate faces.
    #[error(
        "vertex {vertex} is not connected to any handle vertex ({count} such vertices): every \
         connected component of the mesh needs a handle, and every vertex must be used by a face"
    )]
    UnconstrainedVertex {
        /// The first such vertex.
        vertex: usize,
        /// How many vertices are in that situation.
        count: usize,
    },

    /// The mesh has fewer vertices than automatic handle placement needs, or
    /// too few reachable vertices to pick the requested number of handles.
    #[error("cannot place {requested} handles: {reason}; use a smaller radius or fewer handles")]
    HandlePlacement {
        /// Number of handles requested (anchor included).
        requested: usize,
        /// What went wrong.
        reason: String,
    },

    /// Too few vertices lie far enough apart for the requested number of
    /// shape regions ([`crate::ShapeFamily::auto`]).
    #[error("cannot place {requested} shape regions: {reason}; use fewer regions (--regions)")]
    RegionPlacement {
        /// Number of regions requested (the centre one included).
        requested: usize,
        /// What went wrong.
        reason: String,
    },

    /// The total lumped mass of the vertices that are weighed is not positive.
    #[error("the {what} has total lumped mass {mass:e}; expected a positive mass")]
    ZeroMass {
        /// What was weighed.
        what: &'static str,
        /// The mass found.
        mass: f64,
    },

    /// The sparse solver failed (factorization of the free-free block of the
    /// cotangent Laplacian, or a solve).
    #[error("ARAP {context}: {source}")]
    Solver {
        /// What was being done.
        context: &'static str,
        /// The solver's error.
        #[source]
        source: SolverError,
    },

    /// A body-shape change ([`crate::shape`]) turned a face over: the
    /// parameters are too large for this mesh.
    #[error(
        "the shape change turns face {face} over (its normal turned by more than 90 degrees): \
         use smaller scale ranges"
    )]
    FoldedShape {
        /// The first folded face.
        face: usize,
    },

    /// Geodesic (edge-path) distances for handle placement failed.
    #[error("handle placement: {0}")]
    Geometry(#[from] HoleError),
}

/// Shorthand for results of this crate.
pub type Result<T, E = DeformError> = std::result::Result<T, E>;
