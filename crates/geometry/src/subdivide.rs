//! Uniform 1-to-4 subdivision: [`midpoint`] (new vertices at edge midpoints,
//! the surface is unchanged) and [`loop_subdivision`] (Loop's smoothing scheme).
//!
//! Both split every face `[a, b, c]` into four by adding one vertex per edge:
//! with `mab, mbc, mca` the new vertices of the edges, the children are
//! `[a, mab, mca]`, `[mab, b, mbc]`, `[mca, mbc, c]` and `[mab, mbc, mca]`, in
//! that order (child `4f + k` comes from face `f`), so orientation is kept.
//! The old vertices keep their indices `0..V`; the vertex of edge `e` (in the
//! sorted edge order of [`Topology::edges`]) gets index `V + e`. So
//! `V' = V + E` and `F' = 4F`.
//!
//! [`SubdivisionMap`] records which two vertices each new vertex was inserted
//! between, which is enough to carry piecewise-linear data to the finer mesh
//! ([`SubdivisionMap::prolong`]); `mfm_processing::refine` returns the same map.
//!
//! # Example
//! ```
//! use mfm_geometry::{procedural, subdivide};
//! let coarse = procedural::icosphere(0);
//! let (fine, map) = subdivide::midpoint_with_map(&coarse).unwrap();
//! assert_eq!(fine.num_vertices(), 12 + 30);
//! assert_eq!(fine.num_faces(), 80);
//! // data on the coarse vertices, interpolated linearly to the fine ones
//! let x: Vec<f64> = coarse.positions().iter().map(|p| p[0]).collect();
//! let fine_x = map.prolong(&x).unwrap();
//! assert!((fine_x[20] - fine.positions()[20][0]).abs() < 1e-12);
//! ```

use std::f64::consts::PI;

use crate::mesh::{MeshError, TriMesh, add, scale};
use crate::topology::Topology;

/// Where the vertices of a refined mesh come from: the first
/// `num_coarse_vertices` are the coarse mesh's vertices (same indices), and
/// every later vertex `num_coarse_vertices + i` was inserted at the midpoint
/// of the edge between `parents()[i][0]` and `parents()[i][1]`, two vertices
/// with smaller indices (coarse ones, or earlier new ones after
/// `mfm_processing::refine`).
///
/// For [`loop_subdivision`] the new positions are smoothed, but the map still
/// says which edge each new vertex belongs to.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct SubdivisionMap {
    num_coarse_vertices: usize,
    parents: Vec<[u32; 2]>,
}

impl SubdivisionMap {
    /// Builds a map; every parent index must be smaller than its child's
    /// index (`num_coarse_vertices + i`) for [`Self::prolong`] to be meaningful.
    pub fn new(num_coarse_vertices: usize, parents: Vec<[u32; 2]>) -> Self {
        debug_assert!(
            parents
                .iter()
                .enumerate()
                .all(|(i, p)| (p[0].max(p[1]) as usize) < num_coarse_vertices + i)
        );
        Self {
            num_coarse_vertices,
            parents,
        }
    }

    /// Number of vertices of the coarse mesh.
    pub fn num_coarse_vertices(&self) -> usize {
        self.num_coarse_vertices
    }

    /// Number of vertices of the fine mesh.
    pub fn num_fine_vertices(&self) -> usize {
        self.num_coarse_vertices + self.parents.len()
    }

    /// The two parents of each new vertex, in the order of the new vertices.
    pub fn parents(&self) -> &[[u32; 2]] {
        &self.parents
    }

    /// Interpolates one value per coarse vertex linearly onto the fine mesh:
    /// coarse vertices keep their value, a new vertex gets the mean of its
    /// parents'. For [`midpoint`] and `mfm_processing::refine` this is exact for
    /// functions that are linear on each coarse face. `O(V')`.
    ///
    /// # Errors
    /// [`MeshError::VertexCountMismatch`] if `values.len()` is not
    /// [`Self::num_coarse_vertices`].
    pub fn prolong(&self, values: &[f64]) -> Result<Vec<f64>, MeshError> {
        if values.len() != self.num_coarse_vertices {
            return Err(MeshError::VertexCountMismatch {
                expected: self.num_coarse_vertices,
                found: values.len(),
            });
        }
        let mut out = Vec::with_capacity(self.num_fine_vertices());
        out.extend_from_slice(values);
        for &[a, b] in &self.parents {
            let v = 0.5 * (out[a as usize] + out[b as usize]);
            out.push(v);
        }
        Ok(out)
    }
}

/// Children of face `[a, b, c]` given the new vertices on its edges
/// (`m[e]` on the edge opposite corner `e`).
#[inline]
fn split4([a, b, c]: [u32; 3], m: [u32; 3]) -> [[u32; 3]; 4] {
    let (mbc, mca, mab) = (m[0], m[1], m[2]);
    [[a, mab, mca], [mab, b, mbc], [mca, mbc, c], [mab, mbc, mca]]
}

fn check_size(num_vertices: usize, num_edges: usize) -> Result<(), MeshError> {
    let total = num_vertices + num_edges;
    if total >= u32::MAX as usize {
        Err(MeshError::TooManyVertices(total))
    } else {
        Ok(())
    }
}

/// Connectivity of the 1-to-4 split (no size check: the caller makes sure
/// `V + E < 2^32 - 1`).
fn split_faces(num_vertices: usize, topo: &Topology) -> Vec<[u32; 3]> {
    let base = num_vertices as u32;
    topo.faces()
        .iter()
        .zip(topo.face_edges())
        .flat_map(|(&f, fe)| split4(f, [base + fe[0], base + fe[1], base + fe[2]]))
        .collect()
}

/// Midpoint subdivision of raw parts (used by [`crate::procedural::icosphere`],
/// whose sizes are bounded so indices cannot overflow).
pub(crate) fn midpoint_parts(
    positions: &[[f64; 3]],
    faces: &[[u32; 3]],
) -> (Vec<[f64; 3]>, Vec<[u32; 3]>) {
    let topo = Topology::new(positions.len(), faces);
    let mut out = Vec::with_capacity(positions.len() + topo.edges().len());
    out.extend_from_slice(positions);
    out.extend(
        topo.edges()
            .iter()
            .map(|&[a, b]| scale(add(positions[a as usize], positions[b as usize]), 0.5)),
    );
    (out, split_faces(positions.len(), &topo))
}

/// Midpoint (1-to-4) subdivision: one new vertex at the midpoint of each edge,
/// the surface itself is unchanged (same area, same volume).
///
/// `V' = V + E`, `F' = 4F`; see the [module docs](self) for the numbering.
/// Works on any input (non-manifold edges get a single midpoint).
/// Cost: `O(F log F)`.
///
/// # Errors
/// [`MeshError::TooManyVertices`] if `V + E` does not fit in `u32` indices.
pub fn midpoint(mesh: &TriMesh) -> Result<TriMesh, MeshError> {
    midpoint_with_map(mesh).map(|(m, _)| m)
}

/// [`midpoint`], also returning which edge each new vertex sits on.
///
/// # Errors
/// [`MeshError::TooManyVertices`] if `V + E` does not fit in `u32` indices.
pub fn midpoint_with_map(mesh: &TriMesh) -> Result<(TriMesh, SubdivisionMap), MeshError> {
    let topo = Topology::new(mesh.num_vertices(), mesh.faces());
    check_size(mesh.num_vertices(), topo.edges().len())?;
    let (positions, faces) = midpoint_parts(mesh.positions(), mesh.faces());
    let map = SubdivisionMap::new(mesh.num_vertices(), topo.edges().to_vec());
    Ok((TriMesh::new(positions, faces)?, map))
}

/// Loop's weight `β(n)` for an interior vertex of valence `n`:
/// `β = (5/8 - (3/8 + cos(2π/n)/4)²) / n` (Loop 1987; `1/16` for `n = 6`).
pub fn loop_beta(n: usize) -> f64 {
    if n == 0 {
        return 0.0;
    }
    let nf = n as f64;
    let c = 3.0 / 8.0 + 0.25 * (2.0 * PI / nf).cos();
    (5.0 / 8.0 - c * c) / nf
}

/// Weights for the interior vertices of [`loop_subdivision_with`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum LoopWeights {
    /// Loop's original `β(n)`, see [`loop_beta`] (the default).
    #[default]
    Loop,
    /// Warren's simplification `β = 3/(8n)` (`3/16` for `n = 3`), as libigl's `loop`.
    Warren,
}

impl LoopWeights {
    /// `β` for an interior vertex of valence `n`.
    pub fn beta(self, n: usize) -> f64 {
        match self {
            Self::Loop => loop_beta(n),
            Self::Warren if n == 3 => 3.0 / 16.0,
            Self::Warren if n == 0 => 0.0,
            Self::Warren => 3.0 / (8.0 * n as f64),
        }
    }
}

/// One step of Loop subdivision (Loop 1987) with Loop's original weights:
/// [`loop_subdivision_with`]`(mesh, LoopWeights::Loop)`.
///
/// # Errors
/// [`MeshError::TooManyVertices`] if `V + E` does not fit in `u32` indices.
///
/// # Example
/// ```
/// use mfm_geometry::{procedural, subdivide};
/// let smooth = subdivide::loop_subdivision(&procedural::icosphere(0)).unwrap();
/// assert_eq!(smooth.num_faces(), 80);
/// ```
pub fn loop_subdivision(mesh: &TriMesh) -> Result<TriMesh, MeshError> {
    loop_subdivision_with(mesh, LoopWeights::Loop)
}

/// One step of Loop subdivision, same connectivity as [`midpoint`].
///
/// Rules (`β` from `weights`):
/// - interior edge `ab` with opposite vertices `c, d`: `3/8 (a + b) + 1/8 (c + d)`;
/// - boundary edge: its midpoint (also used for non-manifold edges);
/// - interior vertex of valence `n`: `(1 - nβ) v + β Σ neighbours`;
/// - boundary vertex with exactly two boundary edges to `b1, b2`:
///   `3/4 v + 1/8 (b1 + b2)` (the boundary curve is a cubic B-spline of its own
///   polygon, so a plane stays a plane and boundaries stay on their lines);
/// - vertices on non-manifold edges, or with more than two boundary edges,
///   keep their position.
///
/// Cost: `O(F log F)`.
///
/// # Errors
/// [`MeshError::TooManyVertices`] if `V + E` does not fit in `u32` indices.
pub fn loop_subdivision_with(mesh: &TriMesh, weights: LoopWeights) -> Result<TriMesh, MeshError> {
    let n = mesh.num_vertices();
    let topo = Topology::new(n, mesh.faces());
    check_size(n, topo.edges().len())?;
    let p = mesh.positions();
    let faces = mesh.faces();
    let edges = topo.edges();

    // neighbour sums and counts, boundary neighbours, non-manifold marks
    let mut nb_sum = vec![[0.0; 3]; n];
    let mut nb_count = vec![0usize; n];
    let mut bd_sum = vec![[0.0; 3]; n];
    let mut bd_count = vec![0usize; n];
    let mut fixed = vec![false; n];
    for (e, &[a, b]) in edges.iter().enumerate() {
        let (a, b) = (a as usize, b as usize);
        nb_sum[a] = add(nb_sum[a], p[b]);
        nb_sum[b] = add(nb_sum[b], p[a]);
        nb_count[a] += 1;
        nb_count[b] += 1;
        match topo.edge_faces(e).len() {
            1 => {
                bd_sum[a] = add(bd_sum[a], p[b]);
                bd_sum[b] = add(bd_sum[b], p[a]);
                bd_count[a] += 1;
                bd_count[b] += 1;
            }
            2 => {}
            _ => {
                fixed[a] = true;
                fixed[b] = true;
            }
        }
    }

    let mut out = Vec::with_capacity(n + edges.len());
    for v in 0..n {
        let q = if fixed[v] || nb_count[v] == 0 {
            p[v]
        } else if bd_count[v] == 0 {
            let beta = weights.beta(nb_count[v]);
            add(
                scale(p[v], 1.0 - nb_count[v] as f64 * beta),
                scale(nb_sum[v], beta),
            )
        } else if bd_count[v] == 2 {
            add(scale(p[v], 0.75), scale(bd_sum[v], 0.125))
        } else {
            p[v]
        };
        out.push(q);
    }
    for (e, &[a, b]) in edges.iter().enumerate() {
        let ab = add(p[a as usize], p[b as usize]);
        let nbf = topo.edge_faces(e);
        let q = if nbf.len() == 2 {
            let opposite = |f: u32| {
                let t = faces[f as usize];
                t.into_iter().find(|&v| v != a && v != b).unwrap_or(a)
            };
            let cd = add(p[opposite(nbf[0]) as usize], p[opposite(nbf[1]) as usize]);
            add(scale(ab, 3.0 / 8.0), scale(cd, 1.0 / 8.0))
        } else {
            scale(ab, 0.5)
        };
        out.push(q);
    }
    TriMesh::new(out, split_faces(n, &topo))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::procedural;

    #[test]
    fn regular_beta_is_one_sixteenth() {
        assert!((loop_beta(6) - 1.0 / 16.0).abs() < 1e-15);
        // Loop's beta for valence 3 is 3/16 like Warren's
        assert!((loop_beta(3) - 3.0 / 16.0).abs() < 1e-15);
    }

    #[test]
    fn midpoint_numbering() {
        let m = procedural::plane_grid(1, 1, 1.0, 1.0).expect("valid grid");
        let (fine, map) = midpoint_with_map(&m).expect("small");
        assert_eq!(fine.num_vertices(), 4 + 5);
        assert_eq!(map.parents().len(), 5);
        for (i, &[a, b]) in map.parents().iter().enumerate() {
            let mid = scale(
                add(m.positions()[a as usize], m.positions()[b as usize]),
                0.5,
            );
            assert_eq!(fine.positions()[4 + i], mid);
        }
        assert!(map.prolong(&[1.0; 3]).is_err());
    }
}
