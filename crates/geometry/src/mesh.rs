//! The triangle mesh type.
//!
//! A [`TriMesh`] is an indexed face set: `V` vertex positions (`f64`, xyz) and
//! `F` triangles given as three vertex indices (`u32`), counter-clockwise when
//! seen from outside (so the face normal `(p1 - p0) x (p2 - p0)` points out).
//!
//! Construction through [`TriMesh::new`] checks only what every other routine
//! relies on to not misbehave: at least one face, indices in range, finite
//! coordinates. Deeper problems (degenerate faces, non-manifold edges,
//! inconsistent orientation, ...) are found by [`crate::validate::MeshReport`].

use thiserror::Error;

/// A triangle mesh: vertex positions and counter-clockwise triangles.
///
/// # Example
/// ```
/// use mfm_geometry::TriMesh;
/// let mesh = TriMesh::new(
///     vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
///     vec![[0, 1, 2]],
/// ).unwrap();
/// assert_eq!(mesh.num_vertices(), 3);
/// assert!((mesh.total_area() - 0.5).abs() < 1e-15);
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct TriMesh {
    positions: Vec<[f64; 3]>,
    faces: Vec<[u32; 3]>,
}

/// Why a vertex/face list is not a usable triangle mesh.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum MeshError {
    /// The mesh has no faces (or no vertices).
    #[error("the mesh is empty ({vertices} vertices, {faces} faces)")]
    Empty {
        /// Number of vertices found.
        vertices: usize,
        /// Number of faces found.
        faces: usize,
    },
    /// A face refers to a vertex index that does not exist.
    #[error("face {face} refers to vertex {index}, but the mesh has only {num_vertices} vertices")]
    IndexOutOfRange {
        /// Face number (0-based).
        face: usize,
        /// The offending vertex index.
        index: u64,
        /// Number of vertices in the mesh.
        num_vertices: usize,
    },
    /// A vertex coordinate is NaN or infinite.
    #[error("vertex {vertex} has a non-finite coordinate {coords:?}")]
    NonFinite {
        /// Vertex number (0-based).
        vertex: usize,
        /// Its coordinates.
        coords: [f64; 3],
    },
    /// A face uses the same vertex twice.
    #[error("face {face} repeats a vertex: {indices:?}")]
    RepeatedVertex {
        /// Face number (0-based).
        face: usize,
        /// Its three indices.
        indices: [u32; 3],
    },
    /// New positions for a mesh do not match its vertex count.
    #[error("expected {expected} vertex positions, found {found}")]
    VertexCountMismatch {
        /// Vertex count of the mesh.
        expected: usize,
        /// Number of positions given.
        found: usize,
    },
    /// More vertices than `u32` indices can address.
    #[error("the mesh has {0} vertices; at most 2^32 - 1 are supported")]
    TooManyVertices(usize),
    /// All vertices coincide: the mesh has no size.
    #[error("the mesh has zero size: its bounding box's largest extent is {extent}")]
    ZeroSize {
        /// The largest bounding-box extent found.
        extent: f64,
    },
}

impl TriMesh {
    /// Builds a mesh, checking that it has faces, that every index is in range
    /// and not repeated within a face, and that every coordinate is finite.
    ///
    /// Cost: `O(V + F)`.
    pub fn new(positions: Vec<[f64; 3]>, faces: Vec<[u32; 3]>) -> Result<Self, MeshError> {
        if positions.is_empty() || faces.is_empty() {
            return Err(MeshError::Empty {
                vertices: positions.len(),
                faces: faces.len(),
            });
        }
        if positions.len() >= u32::MAX as usize {
            return Err(MeshError::TooManyVertices(positions.len()));
        }
        if let Some((vertex, p)) = positions
            .iter()
            .enumerate()
            .find(|(_, p)| p.iter().any(|c| !c.is_finite()))
        {
            return Err(MeshError::NonFinite { vertex, coords: *p });
        }
        let n = positions.len();
        for (face, f) in faces.iter().enumerate() {
            for &index in f {
                if index as usize >= n {
                    return Err(MeshError::IndexOutOfRange {
                        face,
                        index: index.into(),
                        num_vertices: n,
                    });
                }
            }
            if f[0] == f[1] || f[1] == f[2] || f[0] == f[2] {
                return Err(MeshError::RepeatedVertex { face, indices: *f });
            }
        }
        Ok(Self { positions, faces })
    }

    /// Vertex positions, `V x 3`.
    pub fn positions(&self) -> &[[f64; 3]] {
        &self.positions
    }

    /// Triangles, `F x 3`, counter-clockwise.
    pub fn faces(&self) -> &[[u32; 3]] {
        &self.faces
    }

    /// Number of vertices `V`.
    pub fn num_vertices(&self) -> usize {
        self.positions.len()
    }

    /// Number of faces `F`.
    pub fn num_faces(&self) -> usize {
        self.faces.len()
    }

    /// Consumes the mesh and returns `(positions, faces)`.
    pub fn into_parts(self) -> (Vec<[f64; 3]>, Vec<[u32; 3]>) {
        (self.positions, self.faces)
    }

    /// The three corner positions of face `f`.
    #[inline]
    pub fn face_positions(&self, f: usize) -> [[f64; 3]; 3] {
        let [a, b, c] = self.faces[f];
        [
            self.positions[a as usize],
            self.positions[b as usize],
            self.positions[c as usize],
        ]
    }

    /// Returns a copy with new vertex positions (same connectivity), e.g. a
    /// deformed shape. Errors if the count differs or a coordinate is not finite.
    pub fn with_positions(&self, positions: Vec<[f64; 3]>) -> Result<Self, MeshError> {
        if positions.len() != self.positions.len() {
            return Err(MeshError::VertexCountMismatch {
                expected: self.positions.len(),
                found: positions.len(),
            });
        }
        Self::new(positions, self.faces.clone())
    }

    /// Applies `p -> scale * p + shift` to every vertex.
    pub fn transformed(&self, scale: f64, shift: [f64; 3]) -> Self {
        let positions = self
            .positions
            .iter()
            .map(|p| {
                [
                    scale * p[0] + shift[0],
                    scale * p[1] + shift[1],
                    scale * p[2] + shift[2],
                ]
            })
            .collect();
        Self {
            positions,
            faces: self.faces.clone(),
        }
    }

    /// Sum of the face areas.
    pub fn total_area(&self) -> f64 {
        (0..self.num_faces())
            .map(|f| triangle_area(&self.face_positions(f)))
            .sum()
    }

    /// Axis-aligned bounding box `(min, max)`.
    pub fn bounding_box(&self) -> ([f64; 3], [f64; 3]) {
        bounding_box(&self.positions)
    }

    /// Length of the bounding box diagonal.
    pub fn bounding_box_diagonal(&self) -> f64 {
        let (lo, hi) = self.bounding_box();
        norm(sub(hi, lo))
    }
}

/// The axis-aligned bounding box `(min, max)` of `points` (infinities for
/// none). `O(n)`.
pub fn bounding_box(points: &[[f64; 3]]) -> ([f64; 3], [f64; 3]) {
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for p in points {
        for k in 0..3 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    (lo, hi)
}

/// `a - b`.
#[inline]
pub fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

/// `a + b`.
#[inline]
pub fn add(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

/// `s * a`.
#[inline]
pub fn scale(a: [f64; 3], s: f64) -> [f64; 3] {
    [a[0] * s, a[1] * s, a[2] * s]
}

/// Dot product.
#[inline]
pub fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// Cross product `a x b`.
#[inline]
pub fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// Euclidean norm.
#[inline]
pub fn norm(a: [f64; 3]) -> f64 {
    dot(a, a).sqrt()
}

/// Area of a triangle from its corners.
#[inline]
pub fn triangle_area(p: &[[f64; 3]; 3]) -> f64 {
    0.5 * norm(cross(sub(p[1], p[0]), sub(p[2], p[0])))
}

/// Unnormalized normal `(p1 - p0) x (p2 - p0)` (length = twice the area).
#[inline]
pub fn triangle_normal(p: &[[f64; 3]; 3]) -> [f64; 3] {
    cross(sub(p[1], p[0]), sub(p[2], p[0]))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rejects_bad_input() {
        assert!(matches!(
            TriMesh::new(vec![], vec![]),
            Err(MeshError::Empty { .. })
        ));
        let p = vec![[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
        assert!(matches!(
            TriMesh::new(p.clone(), vec![[0, 1, 3]]),
            Err(MeshError::IndexOutOfRange { index: 3, .. })
        ));
        assert!(matches!(
            TriMesh::new(p.clone(), vec![[0, 1, 1]]),
            Err(MeshError::RepeatedVertex { .. })
        ));
        let mut q = p.clone();
        q[1][2] = f64::NAN;
        assert!(matches!(
            TriMesh::new(q, vec![[0, 1, 2]]),
            Err(MeshError::NonFinite { vertex: 1, .. })
        ));
        assert!(TriMesh::new(p, vec![[0, 1, 2]]).is_ok());
    }
}
