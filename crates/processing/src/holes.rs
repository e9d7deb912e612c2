//! Cutting holes into a mesh and splitting it into connected pieces.
//!
//! [`punch_holes`] removes the faces near given centre vertices: a face goes
//! when **any** of its three vertices is closer than `radius` to a centre
//! (strictly), so a positive radius always removes at least the centre's
//! star. Distance is either straight-line ([`HoleMetric::Euclidean`]) or
//! measured along mesh edges ([`HoleMetric::Geodesic`], Dijkstra on the edge
//! graph with Euclidean edge lengths: an upper bound of the true geodesic
//! distance, typically 5-15% too long on irregular meshes; see
//! [`edge_path_distances`]). Afterwards, vertices that the removal left
//! touching two separate fans of faces (a pinch, which is not a manifold)
//! keep only their largest fan; finally unreferenced vertices are dropped
//! and indices compacted.
//!
//! For `k` well separated holes, each a topological disk, the Euler
//! characteristic drops by `k` and `k` boundary loops appear.
//!
//! # Example
//! ```
//! use mfm_geometry::{procedural, Topology};
//! use mfm_processing::holes::{punch_holes, HoleMetric};
//! let sphere = procedural::icosphere(3);
//! let punched = punch_holes(&sphere, &[0, 3], 0.3, HoleMetric::Geodesic).unwrap();
//! let topo = Topology::new(punched.mesh.num_vertices(), punched.mesh.faces());
//! assert_eq!(topo.boundary_loops().len(), 2);
//! assert_eq!(topo.euler_characteristic(), 0);
//! ```

use std::cmp::Ordering;
use std::collections::BinaryHeap;

use thiserror::Error;

use mfm_geometry::mesh::{MeshError, TriMesh, norm, sub};
use mfm_geometry::topology::Topology;

/// How the distance from a hole centre to a vertex is measured.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum HoleMetric {
    /// Straight-line distance in space (a hole may reach across a thin part).
    Euclidean,
    /// Shortest path along mesh edges (see [`edge_path_distances`]).
    Geodesic,
}

/// Why holes could not be punched.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum HoleError {
    /// A centre is not a vertex of the mesh.
    #[error("hole centre {center} is not a vertex: the mesh has {num_vertices} vertices")]
    CenterOutOfRange {
        /// The centre index given.
        center: usize,
        /// Number of vertices in the mesh.
        num_vertices: usize,
    },
    /// The radius is NaN or negative.
    #[error("the hole radius must be >= 0, found {found}")]
    InvalidRadius {
        /// The radius given.
        found: f64,
    },
    /// The holes cover the whole mesh.
    #[error("the holes remove all {faces} faces of the mesh")]
    NothingLeft {
        /// Number of faces of the input.
        faces: usize,
    },
    /// The output could not be assembled (should not happen for valid input).
    #[error(transparent)]
    Mesh(#[from] MeshError),
}

/// Result of [`punch_holes`].
#[derive(Clone, Debug)]
pub struct Punched {
    /// The mesh with holes (vertices in input order, unreferenced ones dropped).
    pub mesh: TriMesh,
    /// For each vertex of `mesh`, its index in the input mesh.
    pub original_vertex: Vec<u32>,
    /// Number of input faces removed (including pinch repairs).
    pub removed_faces: usize,
}

/// `f64` ordered for a min-heap.
#[derive(Clone, Copy, PartialEq)]
struct MinDist(f64, u32);
impl Eq for MinDist {}
impl PartialOrd for MinDist {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for MinDist {
    fn cmp(&self, other: &Self) -> Ordering {
        other
            .0
            .total_cmp(&self.0)
            .then_with(|| other.1.cmp(&self.1))
    }
}

/// Length of the shortest edge path from each vertex to the nearest of
/// `sources` (multi-source Dijkstra, Euclidean edge lengths); `f64::INFINITY`
/// for vertices not connected to any source.
///
/// This approximates the geodesic distance from above: paths are forced
/// along edges, so on a regular grid the error reaches about 8% for
/// directions between two edge directions. Cost: `O((V + E) log V)`.
///
/// # Errors
/// [`HoleError::CenterOutOfRange`] for a source that is not a vertex.
pub fn edge_path_distances(mesh: &TriMesh, sources: &[usize]) -> Result<Vec<f64>, HoleError> {
    let n = mesh.num_vertices();
    check_centers(n, sources)?;
    let topo = Topology::new(n, mesh.faces());
    // CSR adjacency
    let mut offsets = vec![0usize; n + 1];
    for &[a, b] in topo.edges() {
        offsets[a as usize + 1] += 1;
        offsets[b as usize + 1] += 1;
    }
    for i in 0..n {
        offsets[i + 1] += offsets[i];
    }
    let mut fill = offsets.clone();
    let mut adj = vec![(0u32, 0.0f64); offsets[n]];
    let p = mesh.positions();
    for &[a, b] in topo.edges() {
        let len = norm(sub(p[a as usize], p[b as usize]));
        adj[fill[a as usize]] = (b, len);
        fill[a as usize] += 1;
        adj[fill[b as usize]] = (a, len);
        fill[b as usize] += 1;
    }
    let mut dist = vec![f64::INFINITY; n];
    let mut heap = BinaryHeap::new();
    for &s in sources {
        dist[s] = 0.0;
        heap.push(MinDist(0.0, s as u32));
    }
    while let Some(MinDist(d, v)) = heap.pop() {
        let v = v as usize;
        if d > dist[v] {
            continue;
        }
        for &(w, len) in &adj[offsets[v]..offsets[v + 1]] {
            let nd = d + len;
            if nd < dist[w as usize] {
                dist[w as usize] = nd;
                heap.push(MinDist(nd, w));
            }
        }
    }
    Ok(dist)
}

fn check_centers(num_vertices: usize, centers: &[usize]) -> Result<(), HoleError> {
    match centers.iter().find(|&&c| c >= num_vertices) {
        Some(&center) => Err(HoleError::CenterOutOfRange {
            center,
            num_vertices,
        }),
        None => Ok(()),
    }
}

/// Removes the faces having a vertex closer than `radius` to one of the
/// `centers` (vertex indices), repairs pinched vertices and compacts the
/// result; see the [module docs](self). Cost: `O(F log F)` per repair pass
/// (usually one or two).
///
/// Holes that overlap merge; a hole that wraps around a handle or a thin
/// part may split the mesh or change its genus (use
/// [`connected_components`] / [`largest_component`] afterwards if needed).
///
/// # Errors
/// [`HoleError::CenterOutOfRange`], [`HoleError::InvalidRadius`], or
/// [`HoleError::NothingLeft`] when no face survives.
pub fn punch_holes(
    mesh: &TriMesh,
    centers: &[usize],
    radius: f64,
    metric: HoleMetric,
) -> Result<Punched, HoleError> {
    let n = mesh.num_vertices();
    check_centers(n, centers)?;
    if radius.is_nan() || radius < 0.0 {
        return Err(HoleError::InvalidRadius { found: radius });
    }
    let dist = match metric {
        HoleMetric::Geodesic => edge_path_distances(mesh, centers)?,
        HoleMetric::Euclidean => {
            let p = mesh.positions();
            p.iter()
                .map(|&x| {
                    centers
                        .iter()
                        .map(|&c| norm(sub(x, p[c])))
                        .fold(f64::INFINITY, f64::min)
                })
                .collect()
        }
    };
    let inside: Vec<bool> = dist.iter().map(|&d| d < radius).collect();
    let mut keep: Vec<bool> = mesh
        .faces()
        .iter()
        .map(|t| !t.iter().any(|&v| inside[v as usize]))
        .collect();

    // repair vertices pinched by the removal (not those already non-manifold)
    let input_topo = Topology::new(n, mesh.faces());
    let mut was_bad = vec![false; n];
    for v in input_topo.non_manifold_vertices() {
        was_bad[v] = true;
    }
    loop {
        let kept: Vec<usize> = (0..keep.len()).filter(|&f| keep[f]).collect();
        let faces: Vec<[u32; 3]> = kept.iter().map(|&f| mesh.faces()[f]).collect();
        let topo = Topology::new(n, &faces);
        let pinched: Vec<usize> = topo
            .non_manifold_vertices()
            .into_iter()
            .filter(|&v| !was_bad[v])
            .collect();
        if pinched.is_empty() {
            break;
        }
        let (off, list) = topo.vertex_faces();
        for v in pinched {
            let fans = fans_around(&topo, v as u32, &list[off[v] as usize..off[v + 1] as usize]);
            let largest = fans.iter().map(Vec::len).max().unwrap_or(0);
            let mut kept_one = false;
            for fan in fans {
                if fan.len() == largest && !kept_one {
                    kept_one = true;
                    continue;
                }
                for f in fan {
                    keep[kept[f as usize]] = false;
                }
            }
        }
    }
    let removed_faces = keep.iter().filter(|k| !**k).count();
    match extract(mesh, &keep) {
        Some((mesh, original_vertex)) => Ok(Punched {
            mesh,
            original_vertex,
            removed_faces,
        }),
        None => Err(HoleError::NothingLeft {
            faces: mesh.num_faces(),
        }),
    }
}

/// The fans (groups of faces joined through two-face edges at `v`) among
/// `incident`, the faces of `topo` around `v`.
fn fans_around(topo: &Topology, v: u32, incident: &[u32]) -> Vec<Vec<u32>> {
    let mut parent: Vec<usize> = (0..incident.len()).collect();
    fn find(parent: &mut [usize], mut i: usize) -> usize {
        while parent[i] != i {
            parent[i] = parent[parent[i]];
            i = parent[i];
        }
        i
    }
    for (i, &f) in incident.iter().enumerate() {
        let t = topo.faces()[f as usize];
        for (&corner, &edge) in t.iter().zip(&topo.face_edges()[f as usize]) {
            if corner == v {
                continue; // the edge opposite v does not touch it
            }
            let nb = topo.edge_faces(edge as usize);
            if let [g, h] = nb {
                let other = if *g == f { *h } else { *g };
                if let Some(j) = incident.iter().position(|&x| x == other) {
                    let (ri, rj) = (find(&mut parent, i), find(&mut parent, j));
                    parent[ri] = rj;
                }
            }
        }
    }
    let mut groups: Vec<(usize, Vec<u32>)> = Vec::new();
    for (i, &f) in incident.iter().enumerate() {
        let r = find(&mut parent, i);
        match groups.iter_mut().find(|(root, _)| *root == r) {
            Some((_, g)) => g.push(f),
            None => groups.push((r, vec![f])),
        }
    }
    groups.into_iter().map(|(_, g)| g).collect()
}

/// The faces with `keep[f]`, over only the vertices they use (in input
/// order), and the input index of each kept vertex; `None` if no face is kept.
fn extract(mesh: &TriMesh, keep: &[bool]) -> Option<(TriMesh, Vec<u32>)> {
    let mut new_index = vec![u32::MAX; mesh.num_vertices()];
    for (t, _) in mesh.faces().iter().zip(keep).filter(|(_, k)| **k) {
        for &v in t {
            new_index[v as usize] = 0;
        }
    }
    let mut original = Vec::new();
    let mut positions = Vec::new();
    for (v, slot) in new_index.iter_mut().enumerate() {
        if *slot == 0 {
            *slot = original.len() as u32;
            original.push(v as u32);
            positions.push(mesh.positions()[v]);
        }
    }
    let faces: Vec<[u32; 3]> = mesh
        .faces()
        .iter()
        .zip(keep)
        .filter(|(_, k)| **k)
        .map(|(t, _)| t.map(|v| new_index[v as usize]))
        .collect();
    // a subset of a valid mesh's faces, re-indexed: valid whenever non-empty
    TriMesh::new(positions, faces).ok().map(|m| (m, original))
}

/// The edge-connected components of `mesh` (faces sharing an edge belong
/// together; faces touching at a vertex only do not), each as its own mesh
/// with compacted vertices, in the order of their first face.
/// Cost: `O(F log F)`.
pub fn connected_components(mesh: &TriMesh) -> Vec<TriMesh> {
    let topo = Topology::new(mesh.num_vertices(), mesh.faces());
    let (label, count) = topo.face_components();
    (0..count as u32)
        .filter_map(|c| {
            let keep: Vec<bool> = label.iter().map(|&l| l == c).collect();
            extract(mesh, &keep).map(|(m, _)| m)
        })
        .collect()
}

/// The edge-connected component with the most faces (the first such one on
/// ties), with compacted vertices. Cost: `O(F log F)`.
pub fn largest_component(mesh: &TriMesh) -> TriMesh {
    let topo = Topology::new(mesh.num_vertices(), mesh.faces());
    let (label, count) = topo.face_components();
    let mut sizes = vec![0usize; count];
    for &l in &label {
        sizes[l as usize] += 1;
    }
    let mut best = 0;
    for (c, &s) in sizes.iter().enumerate() {
        if s > sizes[best] {
            best = c;
        }
    }
    let keep: Vec<bool> = label.iter().map(|&l| l as usize == best).collect();
    match extract(mesh, &keep) {
        Some((m, _)) => m,
        // a mesh has at least one face, so its largest component is non-empty
        None => mesh.clone(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use mfm_geometry::procedural;

    #[test]
    fn edge_paths_on_a_grid_are_manhattan_or_diagonal() {
        let g = procedural::plane_grid(4, 4, 4.0, 4.0).expect("valid");
        let d = edge_path_distances(&g, &[0]).expect("in range");
        // (1, 0): one unit edge; (1, 1): the diagonal of the first cell
        assert!((d[1] - 1.0).abs() < 1e-12);
        assert!((d[6] - 2.0_f64.sqrt()).abs() < 1e-12);
        // (1, 2): diagonal then up, the true distance is sqrt(5)
        assert!((d[11] - (1.0 + 2.0_f64.sqrt())).abs() < 1e-12);
        assert!(edge_path_distances(&g, &[25]).is_err());
    }

    #[test]
    fn pinch_is_repaired() {
        // 6 x 4 cells; the stars of vertices (2, 2) and (4, 2) each take two
        // separate sectors of the faces around (3, 2), which would be a bowtie
        let g = procedural::plane_grid(6, 4, 6.0, 4.0).expect("valid");
        let out = punch_holes(&g, &[16, 18], 0.1, HoleMetric::Euclidean).expect("ok");
        assert_eq!(out.removed_faces, 13);
        let t = Topology::new(out.mesh.num_vertices(), out.mesh.faces());
        assert!(t.non_manifold_vertices().is_empty());
        // the two stars merged into one hole through the repair
        assert_eq!(t.boundary_loops().len(), 2);
        assert_eq!(t.euler_characteristic(), 0);
        // radius 0 removes nothing; a large one everything
        let same = punch_holes(&g, &[17], 0.0, HoleMetric::Euclidean).expect("ok");
        assert_eq!(same.mesh, g);
        assert!(matches!(
            punch_holes(&g, &[17], 10.0, HoleMetric::Geodesic),
            Err(HoleError::NothingLeft { faces: 48 })
        ));
        assert!(matches!(
            punch_holes(&g, &[17], f64::NAN, HoleMetric::Geodesic),
            Err(HoleError::InvalidRadius { .. })
        ));
    }

    #[test]
    fn components_split_and_largest() {
        let a = procedural::icosphere(1);
        let b = procedural::icosphere(0).transformed(1.0, [5.0, 0.0, 0.0]);
        let (pa, fa) = a.clone().into_parts();
        let (pb, fb) = b.clone().into_parts();
        let positions: Vec<_> = pb.iter().chain(pa.iter()).copied().collect();
        let faces: Vec<_> = fb
            .iter()
            .copied()
            .chain(fa.iter().map(|t| t.map(|v| v + pb.len() as u32)))
            .collect();
        let both = TriMesh::new(positions, faces).expect("valid");
        let parts = connected_components(&both);
        assert_eq!(parts.len(), 2);
        assert_eq!(parts[0], b);
        assert_eq!(parts[1], a);
        assert_eq!(largest_component(&both), a);
    }
}
