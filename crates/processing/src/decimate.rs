//! Edge-collapse decimation with the quadric error metric (Garland & Heckbert 1997).
//!
//! [`decimate`] repeatedly collapses the edge whose merged vertex would be
//! closest (in the squared-distance-to-planes sense) to the planes of the
//! faces it replaces, until the face count drops to the target. Each vertex
//! carries a quadric: the area-weighted sum of the squared distances to the
//! planes of its incident input faces, plus
//! - a small point term pulling towards the input vertices (weight
//!   `1e-3` per vertex, relative to a face of mean area), which makes the
//!   optimal position unique on flat parts and favours short edges there;
//! - for boundary edges, a heavily weighted plane through the edge,
//!   perpendicular to its face ([`DecimateOptions::boundary_weight`]), so the
//!   boundary curve keeps its shape.
//!
//! A collapse `(u, v) -> x` is only done when the result stays a consistently
//! oriented 2-manifold with the same topology and sound geometry:
//! - link condition: the common neighbours of `u` and `v` are exactly the
//!   vertices opposite the edge (two inside, one on the boundary), and no two
//!   faces end up on the same three vertices (a tetrahedron is not collapsed);
//! - an interior edge between two boundary vertices is never collapsed (it
//!   would pinch the surface); when exactly one endpoint is on the boundary,
//!   `x` is that endpoint, and a boundary edge collapses to whichever endpoint
//!   costs less: boundary vertices are removed but never moved, so the
//!   boundary becomes a sub-polygon of the input's (corners are kept, as
//!   removing them costs the heavy boundary planes);
//! - no surviving face's normal turns by more than
//!   [`DecimateOptions::max_normal_change_degrees`], and none becomes a sliver
//!   (quality `4√3·area / Σ edge²` below [`DecimateOptions::min_triangle_quality`],
//!   unless it was already that bad and does not get worse).
//!
//! Candidates live in a binary heap with lazy invalidation: each vertex has a
//! version number, bumped whenever its neighbourhood changes, and an entry
//! whose versions are stale is dropped when popped. After a collapse, the
//! edges around the merged vertex and its neighbours are re-queued, so a
//! rejected collapse can be retried once its surroundings change. Cost:
//! `O(F log F)` overall.
//!
//! Euler characteristic, genus and the number of boundary loops are kept.
//!
//! # Example
//! ```
//! use mfm_geometry::procedural;
//! use mfm_processing::decimate;
//! let fine = procedural::icosphere(4); // 5120 faces
//! let out = decimate::decimate(&fine, 1000, None).unwrap();
//! assert!(out.target_reached);
//! assert!(out.mesh.num_faces() <= 1000 && out.mesh.num_faces() >= 998);
//! ```

use std::cmp::Ordering;
use std::collections::BinaryHeap;

use thiserror::Error;

use mfm_geometry::mesh::{MeshError, TriMesh, add, cross, dot, norm, scale, sub, triangle_area};
use mfm_geometry::topology::Topology;

/// Tunable limits of [`decimate_with`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DecimateOptions {
    /// Largest angle, in degrees, by which one collapse may turn the normal of
    /// a surviving face. Must be in `(0, 180)`. Default 60.
    pub max_normal_change_degrees: f64,
    /// Smallest accepted triangle quality `4√3·area / (l0² + l1² + l2²)`
    /// (1 for an equilateral triangle, 0 for a degenerate one) of a face
    /// changed by a collapse. Must be in `[0, 1)`. Default 0.05.
    pub min_triangle_quality: f64,
    /// Weight of the boundary-preserving planes, relative to the face planes
    /// (which weigh `area / mean area`). Must be finite and `>= 0`. Default 100.
    pub boundary_weight: f64,
}

impl Default for DecimateOptions {
    fn default() -> Self {
        Self {
            max_normal_change_degrees: 60.0,
            min_triangle_quality: 0.05,
            boundary_weight: 100.0,
        }
    }
}

/// Result of a decimation.
#[derive(Clone, Debug)]
pub struct Decimation {
    /// The decimated mesh: surviving vertices keep their relative order,
    /// unreferenced input vertices are dropped.
    pub mesh: TriMesh,
    /// Whether the face count reached the target. When it did not (every
    /// remaining collapse would break manifoldness, flip a face or leave the
    /// region), `mesh` is the smallest mesh reached.
    pub target_reached: bool,
    /// Number of edge collapses performed.
    pub collapses: usize,
}

/// Why a mesh could not be decimated.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum DecimateError {
    /// The input has edges with more than two faces or vertices whose faces do
    /// not form one fan.
    #[error(
        "decimation needs a manifold mesh, found {edges} non-manifold edges and {vertices} non-manifold vertices (first vertex: {first_vertex:?})"
    )]
    NonManifold {
        /// Number of non-manifold edges.
        edges: usize,
        /// Number of non-manifold vertices.
        vertices: usize,
        /// The first non-manifold vertex, if any.
        first_vertex: Option<usize>,
    },
    /// Neighbouring faces disagree on orientation.
    #[error(
        "decimation needs consistently oriented faces, found {count} edges traversed the same way by both faces (first: {first:?})"
    )]
    InconsistentOrientation {
        /// Number of such edges.
        count: usize,
        /// The first one, as a vertex pair.
        first: [u32; 2],
    },
    /// An option is out of its range.
    #[error("option `{option}` must be {requirement}, found {found}")]
    InvalidOption {
        /// Field name in [`DecimateOptions`].
        option: &'static str,
        /// The accepted range, in words.
        requirement: &'static str,
        /// The value given.
        found: f64,
    },
    /// The output could not be assembled (should not happen for valid input).
    #[error(transparent)]
    Mesh(#[from] MeshError),
}

/// Symmetric 4x4 quadric `[A b; b^T c]`, stored as
/// `a00 a01 a02 a11 a12 a22 b0 b1 b2 c`; error `x^T A x + 2 b^T x + c`.
#[derive(Clone, Copy, Debug, Default)]
struct Quadric([f64; 10]);

impl Quadric {
    /// `w · (n·x + d)²` for a unit normal `n`.
    fn plane(n: [f64; 3], d: f64, w: f64) -> Self {
        Self([
            w * n[0] * n[0],
            w * n[0] * n[1],
            w * n[0] * n[2],
            w * n[1] * n[1],
            w * n[1] * n[2],
            w * n[2] * n[2],
            w * d * n[0],
            w * d * n[1],
            w * d * n[2],
            w * d * d,
        ])
    }

    /// `w · |x - p|²`.
    fn point(p: [f64; 3], w: f64) -> Self {
        Self([
            w,
            0.0,
            0.0,
            w,
            0.0,
            w,
            -w * p[0],
            -w * p[1],
            -w * p[2],
            w * dot(p, p),
        ])
    }

    fn add(&self, o: &Self) -> Self {
        let mut q = self.0;
        for (a, b) in q.iter_mut().zip(o.0) {
            *a += b;
        }
        Self(q)
    }

    fn eval(&self, x: [f64; 3]) -> f64 {
        let q = &self.0;
        let ax = [
            q[0] * x[0] + q[1] * x[1] + q[2] * x[2],
            q[1] * x[0] + q[3] * x[1] + q[4] * x[2],
            q[2] * x[0] + q[4] * x[1] + q[5] * x[2],
        ];
        (dot(x, ax) + 2.0 * (q[6] * x[0] + q[7] * x[1] + q[8] * x[2]) + q[9]).max(0.0)
    }

    /// Minimizer `-A^{-1} b`, if `A` is comfortably invertible.
    fn minimizer(&self) -> Option<[f64; 3]> {
        let q = &self.0;
        let (a, b, c, d, e, f) = (q[0], q[1], q[2], q[3], q[4], q[5]);
        // cofactors of the symmetric matrix [[a b c] [b d e] [c e f]]
        let c00 = d * f - e * e;
        let c01 = c * e - b * f;
        let c02 = b * e - c * d;
        let c11 = a * f - c * c;
        let c12 = b * c - a * e;
        let c22 = a * d - b * b;
        let det = a * c00 + b * c01 + c * c02;
        let trace = a + d + f;
        if !(det.is_finite() && det > 1e-12 * trace * trace * trace) {
            return None;
        }
        let r = [-q[6], -q[7], -q[8]];
        let x = [
            (c00 * r[0] + c01 * r[1] + c02 * r[2]) / det,
            (c01 * r[0] + c11 * r[1] + c12 * r[2]) / det,
            (c02 * r[0] + c12 * r[1] + c22 * r[2]) / det,
        ];
        x.iter().all(|v| v.is_finite()).then_some(x)
    }
}

/// Heap entry: a possible collapse of `u` and `v` into `target`.
#[derive(Clone, Copy, Debug)]
struct Candidate {
    cost: f64,
    u: u32,
    v: u32,
    version_u: u32,
    version_v: u32,
    /// Position in the shifted frame (see `State::origin`).
    target: [f64; 3],
}

impl PartialEq for Candidate {
    fn eq(&self, other: &Self) -> bool {
        self.cmp(other) == Ordering::Equal
    }
}
impl Eq for Candidate {}
impl PartialOrd for Candidate {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for Candidate {
    /// Reversed, so that `BinaryHeap` pops the cheapest collapse first.
    fn cmp(&self, other: &Self) -> Ordering {
        other
            .cost
            .total_cmp(&self.cost)
            .then_with(|| (other.u, other.v).cmp(&(self.u, self.v)))
    }
}

/// Quality `4√3·area / Σ l²` of a triangle with unnormalized normal `n`.
fn quality(p: &[[f64; 3]; 3], n: [f64; 3]) -> f64 {
    let s: f64 = (0..3)
        .map(|k| {
            let d = sub(p[(k + 1) % 3], p[k]);
            dot(d, d)
        })
        .sum();
    if s > 0.0 {
        2.0 * 3.0_f64.sqrt() * norm(n) / s
    } else {
        0.0
    }
}

struct State<'a> {
    /// Positions relative to `origin` (the bounding-box center), for accuracy.
    pos: Vec<[f64; 3]>,
    faces: Vec<[u32; 3]>,
    face_alive: Vec<bool>,
    alive_faces: usize,
    vertex_faces: Vec<Vec<u32>>,
    quadric: Vec<Quadric>,
    boundary: Vec<bool>,
    allowed: Vec<bool>,
    version: Vec<u32>,
    moved: Vec<bool>,
    opts: &'a DecimateOptions,
    cos_max: f64,
}

impl State<'_> {
    fn neighbours(&self, v: u32, out: &mut Vec<u32>) {
        out.clear();
        for &f in &self.vertex_faces[v as usize] {
            out.extend(self.faces[f as usize].iter().copied().filter(|&w| w != v));
        }
        out.sort_unstable();
        out.dedup();
    }

    fn candidate(&self, u: u32, v: u32) -> Option<Candidate> {
        let (ui, vi) = (u as usize, v as usize);
        if !(self.allowed[ui] && self.allowed[vi]) {
            return None;
        }
        let q = self.quadric[ui].add(&self.quadric[vi]);
        let target = match (self.boundary[ui], self.boundary[vi]) {
            (true, false) => self.pos[ui],
            (false, true) => self.pos[vi],
            // along the boundary: keep the cheaper endpoint, so boundary
            // vertices never move (straight boundaries and corners stay exact)
            (true, true) => {
                if q.eval(self.pos[ui]) <= q.eval(self.pos[vi]) {
                    self.pos[ui]
                } else {
                    self.pos[vi]
                }
            }
            (false, false) => {
                let mid = scale(add(self.pos[ui], self.pos[vi]), 0.5);
                let mut best = q.minimizer().unwrap_or(mid);
                let mut best_cost = q.eval(best);
                for x in [self.pos[ui], self.pos[vi], mid] {
                    let c = q.eval(x);
                    if c < best_cost {
                        (best, best_cost) = (x, c);
                    }
                }
                best
            }
        };
        Some(Candidate {
            cost: q.eval(target),
            u,
            v,
            version_u: self.version[ui],
            version_v: self.version[vi],
            target,
        })
    }

    /// Checks every condition of the module docs; `scratch` are reusable buffers.
    fn collapse_ok(&self, c: &Candidate, nu: &mut Vec<u32>, nv: &mut Vec<u32>) -> bool {
        let (u, v) = (c.u, c.v);
        let shared: Vec<u32> = self.vertex_faces[u as usize]
            .iter()
            .copied()
            .filter(|&f| self.faces[f as usize].contains(&v))
            .collect();
        match shared.len() {
            1 => {}
            2 if !(self.boundary[u as usize] && self.boundary[v as usize]) => {}
            _ => return false,
        }
        // link condition
        self.neighbours(u, nu);
        self.neighbours(v, nv);
        let common = nu
            .iter()
            .filter(|&&w| w != v && nv.binary_search(&w).is_ok())
            .count();
        if common != shared.len() {
            return false;
        }
        let survivors = self.vertex_faces[u as usize].len() + self.vertex_faces[v as usize].len()
            - 2 * shared.len();
        if survivors == 0 {
            return false;
        }
        // no two faces on the same vertex set after the merge
        let sorted = |t: [u32; 3]| {
            let mut s = t.map(|w| if w == v { u } else { w });
            s.sort_unstable();
            s
        };
        for &f in &self.vertex_faces[v as usize] {
            if shared.contains(&f) {
                continue;
            }
            let sf = sorted(self.faces[f as usize]);
            for &g in &self.vertex_faces[u as usize] {
                if !shared.contains(&g) && sorted(self.faces[g as usize]) == sf {
                    return false;
                }
            }
        }
        // geometry of every face that survives and moves
        let faces_u = self.vertex_faces[u as usize].iter();
        let faces_v = self.vertex_faces[v as usize].iter();
        for &f in faces_u.chain(faces_v) {
            if shared.contains(&f) {
                continue;
            }
            let t = self.faces[f as usize];
            let old = t.map(|w| self.pos[w as usize]);
            let new = t.map(|w| {
                if w == u || w == v {
                    c.target
                } else {
                    self.pos[w as usize]
                }
            });
            let n_old = cross(sub(old[1], old[0]), sub(old[2], old[0]));
            let n_new = cross(sub(new[1], new[0]), sub(new[2], new[0]));
            let (l_old, l_new) = (norm(n_old), norm(n_new));
            if l_new == 0.0 || !l_new.is_finite() {
                return false;
            }
            if l_old > 0.0 && dot(n_old, n_new) < self.cos_max * l_old * l_new {
                return false;
            }
            let q_new = quality(&new, n_new);
            if q_new < self.opts.min_triangle_quality && q_new < quality(&old, n_old) {
                return false;
            }
        }
        true
    }

    /// Merges `v` into `u` at `target`. Returns the vertices whose edges must
    /// be re-queued (`u` and its new neighbours).
    fn collapse(&mut self, c: &Candidate, ring: &mut Vec<u32>) {
        let (u, v) = (c.u, c.v);
        let (ui, vi) = (u as usize, v as usize);
        let vf = std::mem::take(&mut self.vertex_faces[vi]);
        for &f in &vf {
            let t = self.faces[f as usize];
            if t.contains(&u) {
                self.face_alive[f as usize] = false;
                self.alive_faces -= 1;
                for w in t {
                    if w != v {
                        self.vertex_faces[w as usize].retain(|&g| g != f);
                    }
                }
            } else {
                self.faces[f as usize] = t.map(|w| if w == v { u } else { w });
                self.vertex_faces[ui].push(f);
            }
        }
        self.pos[ui] = c.target;
        self.moved[ui] = true;
        self.quadric[ui] = self.quadric[ui].add(&self.quadric[vi]);
        self.boundary[ui] |= self.boundary[vi];
        self.version[vi] = self.version[vi].wrapping_add(1);
        self.neighbours(u, ring);
        ring.push(u);
        for &w in ring.iter() {
            self.version[w as usize] = self.version[w as usize].wrapping_add(1);
        }
    }
}

/// [`decimate_with`] using [`DecimateOptions::default`].
///
/// # Errors
/// See [`decimate_with`].
pub fn decimate(
    mesh: &TriMesh,
    target_faces: usize,
    region: Option<&dyn Fn([f64; 3]) -> bool>,
) -> Result<Decimation, DecimateError> {
    decimate_with(mesh, target_faces, region, &DecimateOptions::default())
}

/// Decimates `mesh` by quadric-error edge collapses (see the [module docs](self))
/// until it has at most `target_faces` faces.
///
/// With `region`, an edge may collapse only if the predicate holds at the
/// input positions of both its endpoints; so vertices outside the region
/// never move and faces with no vertex in the region are kept unchanged.
/// Each interior collapse removes two faces and each boundary collapse one,
/// so a reached target is met exactly or undershot by one.
///
/// If no valid collapse is left before the target, the smallest mesh reached
/// is returned with [`Decimation::target_reached`] `false` (not an error: it
/// is still a valid, decimated mesh).
///
/// # Errors
/// [`DecimateError::NonManifold`] or [`DecimateError::InconsistentOrientation`]
/// for input the collapse checks cannot handle, and
/// [`DecimateError::InvalidOption`] for out-of-range options.
pub fn decimate_with(
    mesh: &TriMesh,
    target_faces: usize,
    region: Option<&dyn Fn([f64; 3]) -> bool>,
    options: &DecimateOptions,
) -> Result<Decimation, DecimateError> {
    let deg = options.max_normal_change_degrees;
    if !(deg > 0.0 && deg < 180.0) {
        return Err(DecimateError::InvalidOption {
            option: "max_normal_change_degrees",
            requirement: "in (0, 180)",
            found: deg,
        });
    }
    let mq = options.min_triangle_quality;
    if !(0.0..1.0).contains(&mq) {
        return Err(DecimateError::InvalidOption {
            option: "min_triangle_quality",
            requirement: "in [0, 1)",
            found: mq,
        });
    }
    let bw = options.boundary_weight;
    if !(bw.is_finite() && bw >= 0.0) {
        return Err(DecimateError::InvalidOption {
            option: "boundary_weight",
            requirement: "finite and >= 0",
            found: bw,
        });
    }
    let n = mesh.num_vertices();
    let topo = Topology::new(n, mesh.faces());
    let bad_edges = topo.non_manifold_edges();
    let bad_vertices = topo.non_manifold_vertices();
    if !bad_edges.is_empty() || !bad_vertices.is_empty() {
        return Err(DecimateError::NonManifold {
            edges: bad_edges.len(),
            vertices: bad_vertices.len(),
            first_vertex: bad_vertices.first().copied(),
        });
    }
    let flipped = topo.inconsistently_oriented_edges();
    if let Some(&e) = flipped.first() {
        return Err(DecimateError::InconsistentOrientation {
            count: flipped.len(),
            first: topo.edges()[e],
        });
    }

    let (lo, hi) = mesh.bounding_box();
    let origin = scale(add(lo, hi), 0.5);
    let pos: Vec<[f64; 3]> = mesh.positions().iter().map(|&p| sub(p, origin)).collect();
    let faces = mesh.faces().to_vec();
    let mean_area = (mesh.total_area() / mesh.num_faces() as f64).max(f64::MIN_POSITIVE);

    let mut quadric: Vec<Quadric> = pos.iter().map(|&p| Quadric::point(p, 1e-3)).collect();
    let mut vertex_faces: Vec<Vec<u32>> = vec![Vec::new(); n];
    for (f, t) in faces.iter().enumerate() {
        let p = t.map(|w| pos[w as usize]);
        let nrm = cross(sub(p[1], p[0]), sub(p[2], p[0]));
        let len = norm(nrm);
        if len > 0.0 {
            let nu = scale(nrm, 1.0 / len);
            let q = Quadric::plane(nu, -dot(nu, p[0]), triangle_area(&p) / mean_area);
            for &w in t {
                quadric[w as usize] = quadric[w as usize].add(&q);
            }
        }
        for &w in t {
            vertex_faces[w as usize].push(f as u32);
        }
    }
    let mut boundary = vec![false; n];
    for e in topo.boundary_edges() {
        let [a, b] = topo.edges()[e];
        boundary[a as usize] = true;
        boundary[b as usize] = true;
        let f = topo.edge_faces(e)[0] as usize;
        let p = mesh.face_positions(f);
        let fnrm = cross(sub(p[1], p[0]), sub(p[2], p[0]));
        let (pa, pb) = (pos[a as usize], pos[b as usize]);
        let side = cross(sub(pb, pa), fnrm);
        let len = norm(side);
        if len > 0.0 && bw > 0.0 {
            let nu = scale(side, 1.0 / len);
            let q = Quadric::plane(nu, -dot(nu, pa), bw);
            quadric[a as usize] = quadric[a as usize].add(&q);
            quadric[b as usize] = quadric[b as usize].add(&q);
        }
    }
    let allowed: Vec<bool> = match region {
        Some(pred) => mesh.positions().iter().map(|&p| pred(p)).collect(),
        None => vec![true; n],
    };

    let mut state = State {
        pos,
        faces,
        face_alive: vec![true; mesh.num_faces()],
        alive_faces: mesh.num_faces(),
        vertex_faces,
        quadric,
        boundary,
        allowed,
        version: vec![0; n],
        moved: vec![false; n],
        opts: options,
        cos_max: deg.to_radians().cos(),
    };

    let mut heap: BinaryHeap<Candidate> = topo
        .edges()
        .iter()
        .filter_map(|&[a, b]| state.candidate(a, b))
        .collect();
    let (mut nu, mut nv, mut ring, mut around) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let mut requeue: Vec<(u32, u32)> = Vec::new();
    let mut collapses = 0usize;
    while state.alive_faces > target_faces {
        let Some(c) = heap.pop() else { break };
        let (ui, vi) = (c.u as usize, c.v as usize);
        if state.version[ui] != c.version_u || state.version[vi] != c.version_v {
            continue;
        }
        if state.vertex_faces[ui].is_empty() || state.vertex_faces[vi].is_empty() {
            continue;
        }
        if !state.collapse_ok(&c, &mut nu, &mut nv) {
            continue;
        }
        state.collapse(&c, &mut ring);
        collapses += 1;
        requeue.clear();
        for &w in &ring {
            state.neighbours(w, &mut around);
            requeue.extend(around.iter().map(|&x| (w.min(x), w.max(x))));
        }
        requeue.sort_unstable();
        requeue.dedup();
        heap.extend(requeue.iter().filter_map(|&(a, b)| state.candidate(a, b)));
    }

    // compact: surviving, referenced vertices in input order
    let mut new_index = vec![u32::MAX; n];
    let mut positions = Vec::new();
    for (v, slot) in new_index.iter_mut().enumerate() {
        if !state.vertex_faces[v].is_empty() {
            *slot = positions.len() as u32;
            positions.push(if state.moved[v] {
                add(state.pos[v], origin)
            } else {
                mesh.positions()[v]
            });
        }
    }
    let out_faces: Vec<[u32; 3]> = state
        .faces
        .iter()
        .zip(&state.face_alive)
        .filter(|(_, alive)| **alive)
        .map(|(t, _)| t.map(|w| new_index[w as usize]))
        .collect();
    let target_reached = out_faces.len() <= target_faces;
    Ok(Decimation {
        mesh: TriMesh::new(positions, out_faces)?,
        target_reached,
        collapses,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quadric_minimizer_of_three_planes_is_their_corner() {
        let q = Quadric::plane([1.0, 0.0, 0.0], -1.0, 1.0)
            .add(&Quadric::plane([0.0, 1.0, 0.0], -2.0, 1.0))
            .add(&Quadric::plane([0.0, 0.0, 1.0], 3.0, 1.0));
        let x = q.minimizer().expect("invertible");
        for (a, b) in x.iter().zip([1.0, 2.0, -3.0]) {
            assert!((a - b).abs() < 1e-12);
        }
        assert!(q.eval(x) < 1e-20);
        assert!((q.eval([0.0, 2.0, -3.0]) - 1.0).abs() < 1e-12);
        // a single plane leaves a 2D family of minimizers
        assert!(
            Quadric::plane([0.0, 0.0, 1.0], 0.0, 1.0)
                .minimizer()
                .is_none()
        );
    }

    #[test]
    fn rejects_bad_options_and_input() {
        let m = mfm_geometry::procedural::icosphere(1);
        let bad = DecimateOptions {
            max_normal_change_degrees: 0.0,
            ..Default::default()
        };
        assert!(matches!(
            decimate_with(&m, 10, None, &bad),
            Err(DecimateError::InvalidOption { .. })
        ));
        let (p, mut f) = m.into_parts();
        f[0] = [f[0][0], f[0][2], f[0][1]];
        let flipped = TriMesh::new(p, f).expect("valid");
        assert!(matches!(
            decimate(&flipped, 10, None),
            Err(DecimateError::InconsistentOrientation { count: 3, .. })
        ));
    }

    #[test]
    fn tetrahedron_cannot_collapse() {
        let tet = TriMesh::new(
            vec![
                [0.0, 0.0, 0.0],
                [1.0, 0.0, 0.0],
                [0.0, 1.0, 0.0],
                [0.0, 0.0, 1.0],
            ],
            vec![[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]],
        )
        .expect("valid");
        let out = decimate(&tet, 2, None).expect("manifold");
        assert!(!out.target_reached);
        assert_eq!(out.mesh.num_faces(), 4);
        assert_eq!(out.collapses, 0);
    }
}
