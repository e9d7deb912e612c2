//! Local, conforming refinement by longest-edge bisection.
//!
//! [`refine_region`] splits the faces whose centroid lies in a region given
//! by a predicate, leaving the rest of the mesh as it is except for the few
//! neighbours that must be split to keep the mesh conforming (no T-junctions:
//! every new vertex is a vertex of all the faces around it).
//!
//! The scheme is Rivara's longest-edge propagation path (LEPP) bisection. To
//! bisect a face, its longest edge is bisected; if the face across that edge
//! has a longer edge, that one is bisected first, and so on. The path is
//! strictly increasing in edge length (ties are broken by vertex indices,
//! so the order is total), hence finite, and it ends at an edge that is the
//! longest of all its faces: bisecting it splits each of its faces into two.
//! Longest-edge bisection never lets the smallest angle fall below half of
//! the input's, and the conforming closure stays local.
//!
//! New vertices are edge midpoints (no smoothing), so the surface, its area
//! and its enclosed volume are unchanged. Faces that are never split keep
//! their index; each split keeps one child at the parent's index and appends
//! the other.
//!
//! # Example
//! ```
//! use mfm_geometry::procedural;
//! use mfm_processing::refine::{refine_region, RefineCriterion};
//! let grid = procedural::plane_grid(8, 8, 2.0, 2.0).unwrap();
//! // refine the right half until its edges are at most 0.1 long
//! let fine = refine_region(&grid, |c| c[0] > 0.0, RefineCriterion::MaxEdgeLength(0.1)).unwrap();
//! assert!(fine.num_faces() > 4 * grid.num_faces());
//! assert!((fine.total_area() - 4.0).abs() < 1e-12);
//! ```

use std::collections::HashMap;

use thiserror::Error;

use mfm_geometry::mesh::{MeshError, TriMesh, add, dot, scale, sub};
use mfm_geometry::subdivide::SubdivisionMap;

/// When to stop refining.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum RefineCriterion {
    /// Refine until every face whose centroid is in the region has all its
    /// edges at most this long (the closure may split outside faces too, but
    /// only along edges longer than this).
    MaxEdgeLength(f64),
    /// Run this many rounds; each round bisects the longest edge of every face
    /// that is in the region at the start of the round (and has not been split
    /// yet in that round). Two rounds roughly quarter the faces' areas.
    Rounds(u32),
}

/// Why a mesh could not be refined.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum RefineError {
    /// [`RefineCriterion::MaxEdgeLength`] needs a finite, positive length.
    #[error("the maximum edge length must be finite and > 0, found {found}")]
    InvalidEdgeLength {
        /// The length given.
        found: f64,
    },
    /// An edge has more than two faces, so bisection is not defined.
    #[error("edge ({a}, {b}) has {faces} faces; refinement needs at most 2 per edge")]
    NonManifoldEdge {
        /// First vertex of the edge.
        a: u32,
        /// Second vertex of the edge.
        b: u32,
        /// Number of faces found on it.
        faces: usize,
    },
    /// The refined mesh would be too large or otherwise invalid.
    #[error(transparent)]
    Mesh(#[from] MeshError),
}

const NONE: u32 = u32::MAX;

#[inline]
fn key(a: u32, b: u32) -> u64 {
    let (lo, hi) = if a < b { (a, b) } else { (b, a) };
    (u64::from(lo) << 32) | u64::from(hi)
}

/// Mutable mesh with edge-to-face adjacency, for bisection.
struct Bisector {
    positions: Vec<[f64; 3]>,
    faces: Vec<[u32; 3]>,
    /// Up to two faces per edge (`NONE` for a missing second face).
    edge_faces: HashMap<u64, [u32; 2]>,
    parents: Vec<[u32; 2]>,
    /// Faces split (or created) in the current round.
    touched: Vec<bool>,
    /// Faces changed by the last call to [`Self::refine_edge`].
    changed: Vec<u32>,
}

impl Bisector {
    fn new(mesh: &TriMesh) -> Result<Self, RefineError> {
        let mut edge_faces: HashMap<u64, [u32; 2]> =
            HashMap::with_capacity(3 * mesh.num_faces() / 2 + 8);
        for (f, t) in mesh.faces().iter().enumerate() {
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                let slot = edge_faces.entry(key(a, b)).or_insert([NONE, NONE]);
                if slot[0] == NONE {
                    slot[0] = f as u32;
                } else if slot[1] == NONE {
                    slot[1] = f as u32;
                } else {
                    let faces = mesh
                        .faces()
                        .iter()
                        .filter(|s| s.contains(&a) && s.contains(&b))
                        .count();
                    return Err(RefineError::NonManifoldEdge {
                        a: a.min(b),
                        b: a.max(b),
                        faces,
                    });
                }
            }
        }
        Ok(Self {
            positions: mesh.positions().to_vec(),
            faces: mesh.faces().to_vec(),
            edge_faces,
            parents: Vec::new(),
            touched: vec![false; mesh.num_faces()],
            changed: Vec::new(),
        })
    }

    fn len2(&self, a: u32, b: u32) -> f64 {
        let d = sub(self.positions[a as usize], self.positions[b as usize]);
        dot(d, d)
    }

    /// Whether edge `(a, b)` comes after `(c, d)` in the total order
    /// (squared length, then sorted vertex pair).
    fn longer(&self, (a, b): (u32, u32), (c, d): (u32, u32)) -> bool {
        let (l1, l2) = (self.len2(a, b), self.len2(c, d));
        if l1 != l2 {
            return l1 > l2;
        }
        key(a, b) > key(c, d)
    }

    /// The longest edge of face `f` in the total order.
    fn longest(&self, f: u32) -> (u32, u32) {
        let t = self.faces[f as usize];
        let mut best = (t[0], t[1]);
        for k in 1..3 {
            let e = (t[k], t[(k + 1) % 3]);
            if self.longer(e, best) {
                best = e;
            }
        }
        best
    }

    fn centroid(&self, f: u32) -> [f64; 3] {
        let [a, b, c] = self.faces[f as usize];
        let s = add(
            add(self.positions[a as usize], self.positions[b as usize]),
            self.positions[c as usize],
        );
        scale(s, 1.0 / 3.0)
    }

    /// Bisects edge `(a, b)` after bisecting whatever its longest-edge
    /// propagation path requires. Records changed faces in `self.changed`.
    fn refine_edge(&mut self, a: u32, b: u32) -> Result<(), RefineError> {
        self.changed.clear();
        let mut stack = vec![(a, b)];
        while let Some(&(a, b)) = stack.last() {
            let Some(&adj) = self.edge_faces.get(&key(a, b)) else {
                // already split (cannot happen along a strictly increasing path)
                stack.pop();
                continue;
            };
            let pending = adj
                .iter()
                .filter(|&&f| f != NONE)
                .map(|&f| self.longest(f))
                .find(|&(p, q)| key(p, q) != key(a, b));
            match pending {
                Some(e) => stack.push(e),
                None => {
                    self.split(a, b, adj)?;
                    stack.pop();
                }
            }
        }
        Ok(())
    }

    /// Inserts the midpoint `m` of `(a, b)` and splits each face on the edge.
    fn split(&mut self, a: u32, b: u32, adj: [u32; 2]) -> Result<(), RefineError> {
        let m = self.positions.len();
        if m >= u32::MAX as usize - 1 {
            return Err(MeshError::TooManyVertices(m + 1).into());
        }
        let m = m as u32;
        self.positions.push(scale(
            add(self.positions[a as usize], self.positions[b as usize]),
            0.5,
        ));
        self.parents.push([a, b]);
        self.edge_faces.remove(&key(a, b));
        for f in adj.into_iter().filter(|&f| f != NONE) {
            let t = self.faces[f as usize];
            // rotate to [p, q, r] with p -> q the split edge
            let k = (0..3)
                .find(|&k| {
                    let (p, q) = (t[k], t[(k + 1) % 3]);
                    (p == a && q == b) || (p == b && q == a)
                })
                .unwrap_or(0);
            let (p, q, r) = (t[k], t[(k + 1) % 3], t[(k + 2) % 3]);
            let g = self.faces.len() as u32;
            self.faces[f as usize] = [p, m, r];
            self.faces.push([m, q, r]);
            self.touched[f as usize] = true;
            self.touched.push(true);
            self.changed.push(f);
            self.changed.push(g);
            self.attach(key(p, m), f);
            self.attach(key(m, q), g);
            self.attach(key(m, r), f);
            self.attach(key(m, r), g);
            if let Some(slot) = self.edge_faces.get_mut(&key(q, r)) {
                for s in slot.iter_mut() {
                    if *s == f {
                        *s = g;
                    }
                }
            }
        }
        Ok(())
    }

    fn attach(&mut self, k: u64, f: u32) {
        let slot = self.edge_faces.entry(k).or_insert([NONE, NONE]);
        if slot[0] == NONE {
            slot[0] = f;
        } else {
            slot[1] = f;
        }
    }
}

/// Refines the faces whose centroid satisfies `in_region` by conforming
/// longest-edge bisection (see the [module docs](self)), until `criterion`
/// is met.
///
/// The predicate is evaluated on current face centroids, so it decides for
/// the children of split faces too. Only faces in the region are refined on
/// purpose; the closure splits a few nearby faces outside it to avoid
/// T-junctions. Input and output have at most two faces per edge; a
/// consistently oriented manifold stays one, with the same boundary loops.
///
/// Cost: `O(F' log F')` expected, with `F'` the output face count (about
/// `area of the region / max_edge_length²` for [`RefineCriterion::MaxEdgeLength`]).
///
/// # Errors
/// [`RefineError::InvalidEdgeLength`], [`RefineError::NonManifoldEdge`], or
/// [`RefineError::Mesh`] if the result would exceed `u32` indices.
pub fn refine_region(
    mesh: &TriMesh,
    in_region: impl Fn([f64; 3]) -> bool,
    criterion: RefineCriterion,
) -> Result<TriMesh, RefineError> {
    refine_region_with_map(mesh, in_region, criterion).map(|(m, _)| m)
}

/// [`refine_region`], also returning the parents of each new vertex (new
/// vertex `V + i` is the midpoint of `parents()[i]`, two earlier vertices), so
/// piecewise-linear data can follow with [`SubdivisionMap::prolong`].
///
/// # Errors
/// As [`refine_region`].
pub fn refine_region_with_map(
    mesh: &TriMesh,
    in_region: impl Fn([f64; 3]) -> bool,
    criterion: RefineCriterion,
) -> Result<(TriMesh, SubdivisionMap), RefineError> {
    let mut bis = Bisector::new(mesh)?;
    match criterion {
        RefineCriterion::MaxEdgeLength(h) => {
            if !(h.is_finite() && h > 0.0) {
                return Err(RefineError::InvalidEdgeLength { found: h });
            }
            let h2 = h * h;
            let mut queue: Vec<u32> = (0..bis.faces.len() as u32).rev().collect();
            while let Some(f) = queue.pop() {
                let (p, q) = bis.longest(f);
                if bis.len2(p, q) <= h2 || !in_region(bis.centroid(f)) {
                    continue;
                }
                bis.refine_edge(p, q)?;
                queue.extend_from_slice(&bis.changed);
            }
        }
        RefineCriterion::Rounds(rounds) => {
            for _ in 0..rounds {
                bis.touched.clear();
                bis.touched.resize(bis.faces.len(), false);
                let marked: Vec<u32> = (0..bis.faces.len() as u32)
                    .filter(|&f| in_region(bis.centroid(f)))
                    .collect();
                if marked.is_empty() {
                    break;
                }
                for f in marked {
                    if bis.touched[f as usize] {
                        continue;
                    }
                    let (p, q) = bis.longest(f);
                    bis.refine_edge(p, q)?;
                }
            }
        }
    }
    let map = SubdivisionMap::new(mesh.num_vertices(), bis.parents);
    Ok((TriMesh::new(bis.positions, bis.faces)?, map))
}

#[cfg(test)]
mod tests {
    use super::*;
    use mfm_geometry::procedural;

    #[test]
    fn single_triangle_bisects_longest_edge() {
        let m = TriMesh::new(
            vec![[0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
            vec![[0, 1, 2]],
        )
        .expect("valid");
        let (r, map) =
            refine_region_with_map(&m, |_| true, RefineCriterion::Rounds(1)).expect("refines");
        assert_eq!(r.num_faces(), 2);
        // the hypotenuse (1, 2) is the longest edge
        assert_eq!(map.parents(), &[[1, 2]]);
        assert_eq!(r.positions()[3], [1.0, 0.5, 0.0]);
    }

    #[test]
    fn rejects_bad_input() {
        let m = procedural::icosphere(0);
        assert!(matches!(
            refine_region(&m, |_| true, RefineCriterion::MaxEdgeLength(0.0)),
            Err(RefineError::InvalidEdgeLength { .. })
        ));
        let fin = TriMesh::new(
            vec![
                [0.0; 3],
                [1.0, 0.0, 0.0],
                [0.0, 1.0, 0.0],
                [0.0, -1.0, 0.0],
                [0.0, 0.0, 1.0],
            ],
            vec![[0, 1, 2], [1, 0, 3], [0, 1, 4]],
        )
        .expect("valid");
        assert!(matches!(
            refine_region(&fin, |_| true, RefineCriterion::Rounds(1)),
            Err(RefineError::NonManifoldEdge {
                a: 0,
                b: 1,
                faces: 3
            })
        ));
    }
}
