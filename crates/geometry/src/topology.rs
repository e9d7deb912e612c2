//! Combinatorial structure of a triangle mesh: edges, edge-face incidence,
//! boundary loops, connected components, manifoldness and orientation.
//!
//! Conventions: an undirected edge is stored as `[a, b]` with `a < b`. For a
//! face `[i, j, k]`, its local edge `e` (0, 1, 2) is the edge *opposite* corner
//! `e`, i.e. between corners `e+1` and `e+2` (mod 3); [`Topology::face_edges`]
//! follows that order. This is the order cotangent formulas want: the angle at
//! corner `e` is the one opposite edge `e`.

use rayon::prelude::*;

/// Edges and incidence of a face list.
///
/// Built in `O(F log F)` (a parallel sort of the `3F` half-edges).
///
/// # Example
/// ```
/// use mfm_geometry::{procedural, Topology};
/// let mesh = procedural::icosphere(1);
/// let topo = Topology::new(mesh.num_vertices(), mesh.faces());
/// assert_eq!(topo.euler_characteristic(), 2);
/// assert!(topo.boundary_loops().is_empty());
/// ```
#[derive(Clone, Debug)]
pub struct Topology {
    num_vertices: usize,
    faces: Vec<[u32; 3]>,
    edges: Vec<[u32; 2]>,
    face_edges: Vec<[u32; 3]>,
    edge_face_offsets: Vec<u32>,
    edge_face_list: Vec<u32>,
}

impl Topology {
    /// Builds the topology of `faces` over `num_vertices` vertices. Indices must
    /// be in range (as guaranteed by [`crate::TriMesh`]).
    pub fn new(num_vertices: usize, faces: &[[u32; 3]]) -> Self {
        // (edge key, face * 3 + local edge)
        let mut half: Vec<(u64, u32)> = faces
            .par_iter()
            .enumerate()
            .flat_map_iter(|(f, t)| {
                (0..3).map(move |e| {
                    let a = t[(e + 1) % 3];
                    let b = t[(e + 2) % 3];
                    let (lo, hi) = if a < b { (a, b) } else { (b, a) };
                    (((lo as u64) << 32) | hi as u64, (3 * f + e) as u32)
                })
            })
            .collect();
        half.par_sort_unstable();
        let mut edges: Vec<[u32; 2]> = Vec::with_capacity(half.len() / 2 + 1);
        let mut face_edges = vec![[0u32; 3]; faces.len()];
        let mut edge_face_offsets = Vec::with_capacity(half.len() / 2 + 2);
        let mut edge_face_list = Vec::with_capacity(half.len());
        let mut prev = u64::MAX;
        for &(key, slot) in &half {
            if key != prev {
                edge_face_offsets.push(edge_face_list.len() as u32);
                edges.push([(key >> 32) as u32, key as u32]);
                prev = key;
            }
            let e = (edges.len() - 1) as u32;
            let f = slot / 3;
            face_edges[f as usize][(slot % 3) as usize] = e;
            edge_face_list.push(f);
        }
        edge_face_offsets.push(edge_face_list.len() as u32);
        Self {
            num_vertices,
            faces: faces.to_vec(),
            edges,
            face_edges,
            edge_face_offsets,
            edge_face_list,
        }
    }

    /// Number of vertices the topology was built over (referenced or not).
    pub fn num_vertices(&self) -> usize {
        self.num_vertices
    }

    /// The faces.
    pub fn faces(&self) -> &[[u32; 3]] {
        &self.faces
    }

    /// Unique undirected edges `[a, b]`, `a < b`, sorted.
    pub fn edges(&self) -> &[[u32; 2]] {
        &self.edges
    }

    /// For each face, the edge index opposite each corner.
    pub fn face_edges(&self) -> &[[u32; 3]] {
        &self.face_edges
    }

    /// Faces incident to edge `e` (1 on the boundary, 2 inside, more if non-manifold).
    pub fn edge_faces(&self, e: usize) -> &[u32] {
        let lo = self.edge_face_offsets[e] as usize;
        let hi = self.edge_face_offsets[e + 1] as usize;
        &self.edge_face_list[lo..hi]
    }

    /// Index of edge `{a, b}`, if it exists. `O(log E)`.
    pub fn find_edge(&self, a: u32, b: u32) -> Option<usize> {
        let key = if a < b { [a, b] } else { [b, a] };
        self.edges.binary_search(&key).ok()
    }

    /// Edges with exactly one incident face.
    pub fn boundary_edges(&self) -> Vec<usize> {
        (0..self.edges.len())
            .filter(|&e| self.edge_faces(e).len() == 1)
            .collect()
    }

    /// Edges with more than two incident faces.
    pub fn non_manifold_edges(&self) -> Vec<usize> {
        (0..self.edges.len())
            .filter(|&e| self.edge_faces(e).len() > 2)
            .collect()
    }

    /// Vertices referenced by at least one face.
    pub fn referenced_vertices(&self) -> Vec<bool> {
        let mut used = vec![false; self.num_vertices];
        for f in &self.faces {
            for &v in f {
                used[v as usize] = true;
            }
        }
        used
    }

    /// Vertices that no face uses.
    pub fn unreferenced_vertices(&self) -> Vec<usize> {
        self.referenced_vertices()
            .iter()
            .enumerate()
            .filter(|(_, u)| !**u)
            .map(|(v, _)| v)
            .collect()
    }

    /// Vertex-to-face incidence in CSR form: `(offsets, faces)`.
    pub fn vertex_faces(&self) -> (Vec<u32>, Vec<u32>) {
        let mut count = vec![0u32; self.num_vertices + 1];
        for f in &self.faces {
            for &v in f {
                count[v as usize + 1] += 1;
            }
        }
        for i in 0..self.num_vertices {
            count[i + 1] += count[i];
        }
        let mut fill = count.clone();
        let mut list = vec![0u32; 3 * self.faces.len()];
        for (fi, f) in self.faces.iter().enumerate() {
            for &v in f {
                list[fill[v as usize] as usize] = fi as u32;
                fill[v as usize] += 1;
            }
        }
        (count, list)
    }

    /// Vertices whose incident faces do not form a single fan (a disk or a
    /// half-disk) connected through edges shared by exactly two faces — e.g. two
    /// cones touching at their tips. Vertices on non-manifold edges are included.
    pub fn non_manifold_vertices(&self) -> Vec<usize> {
        let (off, list) = self.vertex_faces();
        let mut bad = Vec::new();
        let mut parent: Vec<usize> = Vec::new();
        for v in 0..self.num_vertices {
            let inc = &list[off[v] as usize..off[v + 1] as usize];
            if inc.is_empty() {
                continue;
            }
            // union-find over the incident faces, joined through edges at v
            parent.clear();
            parent.extend(0..inc.len());
            let mut nonmanifold_edge = false;
            for (i, &f) in inc.iter().enumerate() {
                let t = self.faces[f as usize];
                for (e, &corner) in t.iter().enumerate() {
                    // the two edges of f that touch v are those opposite the other corners
                    if corner == v as u32 {
                        continue;
                    }
                    let edge = self.face_edges[f as usize][e] as usize;
                    let nb = self.edge_faces(edge);
                    if nb.len() > 2 {
                        nonmanifold_edge = true;
                    }
                    if nb.len() == 2 {
                        let g = if nb[0] == f { nb[1] } else { nb[0] };
                        if let Some(j) = inc.iter().position(|&x| x == g) {
                            let (ri, rj) = (find(&mut parent, i), find(&mut parent, j));
                            parent[ri] = rj;
                        }
                    }
                }
            }
            let roots = (0..inc.len())
                .filter(|&i| find(&mut parent, i) == i)
                .count();
            if roots > 1 || nonmanifold_edge {
                bad.push(v);
            }
        }
        bad
    }

    /// Interior edges whose two faces traverse them in the same direction
    /// (so one of the two faces is flipped relative to the other).
    pub fn inconsistently_oriented_edges(&self) -> Vec<usize> {
        (0..self.edges.len())
            .filter(|&e| {
                let nb = self.edge_faces(e);
                if nb.len() != 2 {
                    return false;
                }
                let [a, b] = self.edges[e];
                directed(self.faces[nb[0] as usize], a, b)
                    == directed(self.faces[nb[1] as usize], a, b)
            })
            .collect()
    }

    /// Connected components of faces (two faces are connected when they share
    /// an edge). Returns a component label per face and the number of components.
    pub fn face_components(&self) -> (Vec<u32>, usize) {
        let nf = self.faces.len();
        let mut parent: Vec<usize> = (0..nf).collect();
        for e in 0..self.edges.len() {
            let nb = self.edge_faces(e);
            for w in nb.windows(2) {
                let (a, b) = (
                    find(&mut parent, w[0] as usize),
                    find(&mut parent, w[1] as usize),
                );
                if a != b {
                    parent[a] = b;
                }
            }
        }
        relabel(&mut parent)
    }

    /// Connected components of referenced vertices through faces. Unreferenced
    /// vertices get the label `u32::MAX` and are not counted.
    pub fn vertex_components(&self) -> (Vec<u32>, usize) {
        let (face_label, count) = self.face_components();
        let mut label = vec![u32::MAX; self.num_vertices];
        // faces joined only at a vertex are different face components but one
        // vertex component: merge through a union-find over face labels
        let mut parent: Vec<usize> = (0..count).collect();
        for (f, t) in self.faces.iter().enumerate() {
            for &v in t {
                let l = label[v as usize];
                if l == u32::MAX {
                    label[v as usize] = face_label[f];
                } else {
                    let (a, b) = (
                        find(&mut parent, l as usize),
                        find(&mut parent, face_label[f] as usize),
                    );
                    if a != b {
                        parent[a] = b;
                    }
                }
            }
        }
        let (map, n) = relabel(&mut parent);
        for l in label.iter_mut() {
            if *l != u32::MAX {
                *l = map[*l as usize];
            }
        }
        (label, n)
    }

    /// Closed boundary loops as vertex cycles, each oriented like its faces
    /// (the face lies to the left when walking the loop). Loops through a
    /// non-manifold boundary vertex are split arbitrarily but every boundary edge
    /// appears in exactly one loop.
    pub fn boundary_loops(&self) -> Vec<Vec<u32>> {
        // directed boundary half-edges a -> b, as the face traverses them
        let mut next: std::collections::HashMap<u32, Vec<u32>> = Default::default();
        let mut count = 0usize;
        for e in self.boundary_edges() {
            let f = self.edge_faces(e)[0];
            let [a, b] = self.edges[e];
            let (s, t) = if directed(self.faces[f as usize], a, b) {
                (a, b)
            } else {
                (b, a)
            };
            next.entry(s).or_default().push(t);
            count += 1;
        }
        let mut loops = Vec::new();
        let mut starts: Vec<u32> = next.keys().copied().collect();
        starts.sort_unstable();
        let mut used = 0usize;
        for start in starts {
            while next.get(&start).is_some_and(|v| !v.is_empty()) {
                let mut lp = vec![start];
                let mut cur = start;
                while let Some(t) = next.get_mut(&cur).and_then(|v| v.pop()) {
                    used += 1;
                    if t == start {
                        break;
                    }
                    lp.push(t);
                    cur = t;
                }
                loops.push(lp);
            }
        }
        debug_assert_eq!(used, count);
        loops
    }

    /// Euler characteristic `V - E + F`, counting only referenced vertices.
    pub fn euler_characteristic(&self) -> i64 {
        let v = self.referenced_vertices().iter().filter(|u| **u).count() as i64;
        v - self.edges.len() as i64 + self.faces.len() as i64
    }

    /// Total genus for an orientable manifold mesh, from
    /// `chi = sum over components (2 - 2 g_c - b_c)`:
    /// `g = (2 C - chi - B) / 2` with `C` components and `B` boundary loops.
    /// `None` when that number is not a non-negative integer (the mesh is not
    /// an orientable manifold).
    pub fn genus(&self) -> Option<u64> {
        let (_, c) = self.face_components();
        let b = self.boundary_loops().len() as i64;
        let twice = 2 * c as i64 - self.euler_characteristic() - b;
        (twice >= 0 && twice % 2 == 0).then_some((twice / 2) as u64)
    }
}

/// Whether face `t` traverses `a -> b` (as opposed to `b -> a`).
fn directed(t: [u32; 3], a: u32, b: u32) -> bool {
    (0..3).any(|i| t[i] == a && t[(i + 1) % 3] == b)
}

fn find(parent: &mut [usize], mut i: usize) -> usize {
    while parent[i] != i {
        parent[i] = parent[parent[i]];
        i = parent[i];
    }
    i
}

/// Labels `0..n` for the union-find roots, in order of first appearance.
fn relabel(parent: &mut [usize]) -> (Vec<u32>, usize) {
    let mut root_label = vec![u32::MAX; parent.len()];
    let mut labels = vec![0u32; parent.len()];
    let mut n = 0u32;
    for (i, label) in labels.iter_mut().enumerate() {
        let r = find(parent, i);
        if root_label[r] == u32::MAX {
            root_label[r] = n;
            n += 1;
        }
        *label = root_label[r];
    }
    (labels, n as usize)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two triangles sharing edge 1-2, consistently oriented.
    fn quad() -> Vec<[u32; 3]> {
        vec![[0, 1, 2], [2, 1, 3]]
    }

    #[test]
    fn quad_topology() {
        let t = Topology::new(4, &quad());
        assert_eq!(t.edges().len(), 5);
        assert_eq!(t.boundary_edges().len(), 4);
        assert_eq!(t.euler_characteristic(), 1);
        assert_eq!(t.genus(), Some(0));
        let loops = t.boundary_loops();
        assert_eq!(loops.len(), 1);
        assert_eq!(loops[0].len(), 4);
        assert!(t.inconsistently_oriented_edges().is_empty());
        assert!(t.non_manifold_vertices().is_empty());
        // face_edges: edge opposite corner 0 of face 0 is {1, 2}
        let e = t.face_edges()[0][0] as usize;
        assert_eq!(t.edges()[e], [1, 2]);
        assert_eq!(t.edge_faces(e).len(), 2);
    }

    #[test]
    fn flipped_face_is_found() {
        let t = Topology::new(4, &[[0, 1, 2], [1, 2, 3]]);
        assert_eq!(t.inconsistently_oriented_edges().len(), 1);
    }

    #[test]
    fn bowtie_vertex_is_non_manifold() {
        // two triangles touching at vertex 0 only
        let t = Topology::new(5, &[[0, 1, 2], [0, 3, 4]]);
        assert_eq!(t.non_manifold_vertices(), vec![0]);
        assert_eq!(t.face_components().1, 2);
        assert_eq!(t.vertex_components().1, 1);
    }

    #[test]
    fn fin_edge_is_non_manifold() {
        let t = Topology::new(5, &[[0, 1, 2], [1, 0, 3], [0, 1, 4]]);
        assert_eq!(t.non_manifold_edges().len(), 1);
        assert!(t.non_manifold_vertices().contains(&0));
    }

    #[test]
    fn unreferenced_vertex() {
        let t = Topology::new(4, &[[0, 1, 2]]);
        assert_eq!(t.unreferenced_vertices(), vec![3]);
        assert_eq!(t.vertex_components().0[3], u32::MAX);
    }
}
