//! Mesh validation: a readable [`MeshReport`] of a mesh's size, topology and
//! geometry, the [`MeshProblem`]s that make it unfit for the intrinsic
//! operators, a strict [`validate`] for consumers that must refuse such meshes,
//! and explicit, opt-in [`repair`]s.
//!
//! What counts as a problem (each a [`MeshProblem`] variant):
//! - **degenerate faces**: zero area up to round-off, i.e.
//!   `area <= DEGENERATE_ABSOLUTE_TOLERANCE * d^2` with `d` the bounding box
//!   diagonal (the face is negligible at the scale of the mesh) **or**
//!   `area <= DEGENERATE_RELATIVE_TOLERANCE * l^2` with `l` the face's longest
//!   edge (its corners are collinear up to round-off, whatever its size); see
//!   [`DEGENERATE_ABSOLUTE_TOLERANCE`] and [`DEGENERATE_RELATIVE_TOLERANCE`];
//! - **unreferenced vertices**: used by no face;
//! - **non-manifold edges**: shared by more than two faces;
//! - **non-manifold vertices**: the faces around the vertex do not form one
//!   fan (a disk or half-disk), e.g. two cones touching at their tips; this
//!   includes the endpoints of non-manifold edges (see
//!   [`Topology::non_manifold_vertices`]);
//! - **inconsistent orientation**: an edge whose two faces traverse it in the
//!   same direction (one of them is flipped);
//! - **duplicate faces**: a face with the same three vertices as an earlier
//!   one, in any order.
//!
//! Boundaries and several connected components are *not* problems.
//!
//! # Example
//! ```
//! use mfm_geometry::{TriMesh, validate::{MeshProblem, MeshReport, repair}};
//! // a square (two triangles) plus a stray fifth vertex
//! let mesh = TriMesh::new(
//!     vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [1.0, 1.0, 0.0], [5.0, 5.0, 5.0]],
//!     vec![[0, 1, 2], [2, 1, 3]],
//! ).unwrap();
//! let report = MeshReport::new(&mesh);
//! assert_eq!(report.boundary_loops, 1);
//! assert_eq!(report.genus, Some(0));
//! assert_eq!(
//!     report.problems,
//!     vec![MeshProblem::UnreferencedVertices { count: 1, first: vec![4] }]
//! );
//! assert!(mfm_geometry::validate::validate(&mesh).is_err());
//! let (clean, old_to_new) = repair::drop_unreferenced_vertices(&mesh);
//! assert_eq!(old_to_new[4], u32::MAX);
//! assert!(MeshReport::new(&clean).is_valid());
//! ```

use crate::mesh::{TriMesh, cross, dot, norm, sub, triangle_area};
use crate::topology::Topology;
use std::collections::HashMap;
use std::fmt;
use thiserror::Error;

/// A face is degenerate when its area is at most this times the squared
/// bounding-box diagonal of the mesh.
pub const DEGENERATE_ABSOLUTE_TOLERANCE: f64 = 1e-14;

/// A face is degenerate when its area is at most this times its squared
/// longest edge (for a triangle `area / l^2 <= sin(smallest angle) / 2`, so
/// this flags angles below about `2e-12` radians: collinear up to round-off).
pub const DEGENERATE_RELATIVE_TOLERANCE: f64 = 1e-12;

/// How many examples each [`MeshProblem`] lists.
pub const MAX_EXAMPLES: usize = 5;

/// Size, topology and geometry of a mesh, with its problems.
///
/// Built by [`MeshReport::new`] in `O(F log F)`. `Display` prints a readable
/// multi-line summary (what `mfm info` shows); `serde::Serialize` gives the
/// same fields as JSON (`mfm info --json`).
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct MeshReport {
    /// Number of vertices `V` (referenced or not).
    pub num_vertices: usize,
    /// Number of faces `F`.
    pub num_faces: usize,
    /// Number of distinct undirected edges `E`.
    pub num_edges: usize,
    /// Connected components of the surface (vertices connected through faces;
    /// unreferenced vertices are not counted).
    pub components: usize,
    /// Number of closed boundary loops (0 for a closed surface).
    pub boundary_loops: usize,
    /// `V - E + F`, counting referenced vertices only.
    pub euler_characteristic: i64,
    /// Total genus from `chi = sum_c (2 - 2 g_c - b_c)`; `None` when the mesh
    /// has non-manifold edges or vertices or inconsistent orientation (the
    /// formula then means nothing).
    pub genus: Option<u64>,
    /// Sum of the face areas.
    pub surface_area: f64,
    /// Smallest coordinates of the axis-aligned bounding box (all vertices).
    pub bounding_box_min: [f64; 3],
    /// Largest coordinates of the axis-aligned bounding box.
    pub bounding_box_max: [f64; 3],
    /// Smallest interior angle of any face, in degrees (0 for a face with two
    /// coincident corners).
    pub min_angle_degrees: f64,
    /// Largest interior angle of any face, in degrees.
    pub max_angle_degrees: f64,
    /// Everything that makes the mesh unfit for the operators; empty when
    /// [`MeshReport::is_valid`].
    pub problems: Vec<MeshProblem>,
}

/// One kind of defect, with how often it occurs and the first (lowest-index)
/// examples, at most [`MAX_EXAMPLES`].
///
/// Serialized with a `kind` tag in snake case, e.g.
/// `{"kind": "degenerate_faces", "count": 2, "first": [4, 9]}`.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum MeshProblem {
    /// Faces with zero area up to round-off (see the [module docs](self)).
    DegenerateFaces {
        /// Number of degenerate faces.
        count: usize,
        /// Their indices, lowest first.
        first: Vec<usize>,
    },
    /// Vertices no face uses.
    UnreferencedVertices {
        /// Number of unreferenced vertices.
        count: usize,
        /// Their indices, lowest first.
        first: Vec<usize>,
    },
    /// Edges shared by more than two faces.
    NonManifoldEdges {
        /// Number of such edges.
        count: usize,
        /// Their endpoints `[a, b]`, `a < b`.
        first: Vec<[u32; 2]>,
    },
    /// Vertices whose faces do not form a single fan.
    NonManifoldVertices {
        /// Number of such vertices.
        count: usize,
        /// Their indices, lowest first.
        first: Vec<usize>,
    },
    /// Interior edges traversed in the same direction by both their faces.
    InconsistentOrientation {
        /// Number of such edges.
        count: usize,
        /// Their endpoints `[a, b]`, `a < b`.
        first: Vec<[u32; 2]>,
    },
    /// Faces of a sound shape whose size is out of `f64`'s range for the
    /// operators: coordinates so small (about `1e-160`) or so large
    /// (`1e150`) that squared edge lengths underflow or overflow
    /// ([`crate::operators::degenerate_for_operators`]). The only problem
    /// that depends on the mesh's scale.
    OutOfRange {
        /// Number of such faces.
        count: usize,
        /// Their indices, lowest first.
        first: Vec<usize>,
    },
    /// Faces with the same vertex set as an earlier face.
    DuplicateFaces {
        /// Number of faces that repeat an earlier one (what
        /// [`repair::drop_duplicate_faces`] removes).
        count: usize,
        /// Pairs `[duplicate, original]` of face indices.
        first: Vec<[usize; 2]>,
    },
}

fn plural(n: usize, one: &str, many: &str) -> String {
    format!("{n} {}", if n == 1 { one } else { many })
}

fn list<T>(items: &[T], show: impl Fn(&T) -> String) -> String {
    items.iter().map(show).collect::<Vec<_>>().join(", ")
}

impl fmt::Display for MeshProblem {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let edge = |e: &[u32; 2]| format!("edge {}-{}", e[0], e[1]);
        match self {
            Self::OutOfRange { count, first } => write!(
                f,
                "{} too small or too large for f64 arithmetic (squared edge lengths underflow or \
                 overflow; rescale the mesh), e.g. {}",
                plural(*count, "face", "faces"),
                list(first, |i| format!("face {i}"))
            ),
            Self::DegenerateFaces { count, first } => write!(
                f,
                "{} (zero area up to round-off), e.g. {}",
                plural(*count, "degenerate face", "degenerate faces"),
                list(first, |i| format!("face {i}"))
            ),
            Self::UnreferencedVertices { count, first } => write!(
                f,
                "{} (used by no face), e.g. {}",
                plural(*count, "unreferenced vertex", "unreferenced vertices"),
                list(first, |i| format!("vertex {i}"))
            ),
            Self::NonManifoldEdges { count, first } => write!(
                f,
                "{} (shared by more than two faces), e.g. {}",
                plural(*count, "non-manifold edge", "non-manifold edges"),
                list(first, edge)
            ),
            Self::NonManifoldVertices { count, first } => write!(
                f,
                "{} (their faces do not form one fan), e.g. {}",
                plural(*count, "non-manifold vertex", "non-manifold vertices"),
                list(first, |i| format!("vertex {i}"))
            ),
            Self::InconsistentOrientation { count, first } => write!(
                f,
                "{} (both faces traverse them in the same direction: a face is flipped), e.g. {}",
                plural(
                    *count,
                    "inconsistently oriented edge",
                    "inconsistently oriented edges"
                ),
                list(first, edge)
            ),
            Self::DuplicateFaces { count, first } => write!(
                f,
                "{} (same vertices as an earlier face), e.g. {}",
                plural(*count, "duplicate face", "duplicate faces"),
                list(first, |p| format!("face {} repeats face {}", p[0], p[1]))
            ),
        }
    }
}

/// Interior angles of a triangle, in radians, computed as
/// `atan2(|u x v|, u . v)` (accurate for tiny and near-straight angles).
fn angles(p: &[[f64; 3]; 3]) -> [f64; 3] {
    let mut a = [0.0; 3];
    for (i, out) in a.iter_mut().enumerate() {
        let u = sub(p[(i + 1) % 3], p[i]);
        let v = sub(p[(i + 2) % 3], p[i]);
        *out = norm(cross(u, v)).atan2(dot(u, v));
    }
    a
}

/// `|v|` without overflow or underflow in the squares.
fn robust_norm(v: [f64; 3]) -> f64 {
    let s = v.iter().fold(0.0f64, |m, c| m.max(c.abs()));
    if s == 0.0 || !s.is_finite() {
        return s;
    }
    s * norm(v.map(|c| c / s))
}

/// The face moved so that corner 0 is at the origin and scaled so that its
/// longest edge has length 1, with the factor `l` (the longest edge length)
/// it was divided by; `None` when all three corners coincide. Shape measures
/// (area / l^2, angles) computed on it do not underflow or overflow, whatever
/// the size of the face or its distance from the origin.
fn unit_shape(p: &[[f64; 3]; 3]) -> Option<([[f64; 3]; 3], f64)> {
    let edges = |q: &[[f64; 3]; 3]| [sub(q[1], q[0]), sub(q[2], q[0]), sub(q[2], q[1])];
    let mut e = edges(p);
    let mut factor = 1.0;
    if e.iter().flatten().any(|c| !c.is_finite()) {
        // differences of coordinates near f64::MAX overflow: halve (exactly)
        e = edges(&p.map(|c| c.map(|x| x * 0.5)));
        factor = 2.0;
    }
    let s = e.iter().flatten().fold(0.0f64, |m, c| m.max(c.abs()));
    if s == 0.0 {
        return None;
    }
    let e = e.map(|v| v.map(|c| c / s));
    let l = e.iter().map(|&v| norm(v)).fold(0.0f64, f64::max);
    let unit = [[0.0; 3], e[0].map(|c| c / l), e[1].map(|c| c / l)];
    Some((unit, factor * s * l))
}

/// Whether a face is degenerate (see the [module docs](self)), given the
/// bounding-box diagonal of the mesh: `area <= DEGENERATE_RELATIVE_TOLERANCE * l^2`
/// (`l` its longest edge) or `area <= DEGENERATE_ABSOLUTE_TOLERANCE * diagonal^2`.
/// Evaluated on the face rescaled to unit longest edge, so the answer does not
/// change when the whole mesh is scaled (no underflow for tiny meshes).
pub fn is_degenerate(p: &[[f64; 3]; 3], bounding_box_diagonal: f64) -> bool {
    let Some((unit, l)) = unit_shape(p) else {
        return true;
    };
    // area / l^2
    let relative_area = triangle_area(&unit);
    let ratio = bounding_box_diagonal / l;
    relative_area <= DEGENERATE_RELATIVE_TOLERANCE
        || relative_area <= DEGENERATE_ABSOLUTE_TOLERANCE * ratio * ratio
}

/// Indices of faces with the same vertex set as an earlier face, as pairs
/// `[duplicate, first occurrence]`, in increasing order of the duplicate.
fn duplicate_faces(faces: &[[u32; 3]]) -> Vec<[usize; 2]> {
    let mut seen: HashMap<[u32; 3], usize> = HashMap::with_capacity(faces.len());
    let mut dups = Vec::new();
    for (i, f) in faces.iter().enumerate() {
        let mut key = *f;
        key.sort_unstable();
        match seen.get(&key) {
            Some(&j) => dups.push([i, j]),
            None => {
                seen.insert(key, i);
            }
        }
    }
    dups
}

fn first<T: Clone>(items: &[T]) -> Vec<T> {
    items[..items.len().min(MAX_EXAMPLES)].to_vec()
}

impl MeshReport {
    /// Measures `mesh` and lists its problems. Cost: `O(F log F)` (the
    /// [`Topology`] build dominates).
    pub fn new(mesh: &TriMesh) -> Self {
        let topo = Topology::new(mesh.num_vertices(), mesh.faces());
        let (lo, hi) = mesh.bounding_box();
        let diagonal = diagonal(lo, hi);

        let mut area = 0.0;
        let mut min_angle = f64::INFINITY;
        let mut max_angle = 0.0f64;
        let mut degenerate = Vec::new();
        let mut out_of_range = Vec::new();
        for f in 0..mesh.num_faces() {
            let p = mesh.face_positions(f);
            area += triangle_area(&p);
            // angles of a face whose corners coincide count as 0
            let shape = unit_shape(&p);
            for a in shape.map_or([0.0; 3], |(unit, _)| angles(&unit)) {
                min_angle = min_angle.min(a);
                max_angle = max_angle.max(a);
            }
            if is_degenerate(&p, diagonal) {
                degenerate.push(f);
            } else if crate::operators::degenerate_for_operators(&p) {
                out_of_range.push(f);
            }
        }

        let mut problems = Vec::new();
        if !degenerate.is_empty() {
            problems.push(MeshProblem::DegenerateFaces {
                count: degenerate.len(),
                first: first(&degenerate),
            });
        }
        if !out_of_range.is_empty() {
            problems.push(MeshProblem::OutOfRange {
                count: out_of_range.len(),
                first: first(&out_of_range),
            });
        }
        let unreferenced = topo.unreferenced_vertices();
        if !unreferenced.is_empty() {
            problems.push(MeshProblem::UnreferencedVertices {
                count: unreferenced.len(),
                first: first(&unreferenced),
            });
        }
        let edge_ends = |edges: &[usize]| -> Vec<[u32; 2]> {
            edges
                .iter()
                .take(MAX_EXAMPLES)
                .map(|&e| topo.edges()[e])
                .collect()
        };
        let nm_edges = topo.non_manifold_edges();
        if !nm_edges.is_empty() {
            problems.push(MeshProblem::NonManifoldEdges {
                count: nm_edges.len(),
                first: edge_ends(&nm_edges),
            });
        }
        let nm_vertices = topo.non_manifold_vertices();
        if !nm_vertices.is_empty() {
            problems.push(MeshProblem::NonManifoldVertices {
                count: nm_vertices.len(),
                first: first(&nm_vertices),
            });
        }
        let flipped = topo.inconsistently_oriented_edges();
        if !flipped.is_empty() {
            problems.push(MeshProblem::InconsistentOrientation {
                count: flipped.len(),
                first: edge_ends(&flipped),
            });
        }
        let dups = duplicate_faces(mesh.faces());
        if !dups.is_empty() {
            problems.push(MeshProblem::DuplicateFaces {
                count: dups.len(),
                first: first(&dups),
            });
        }

        let manifold = nm_edges.is_empty() && nm_vertices.is_empty() && flipped.is_empty();
        Self {
            num_vertices: mesh.num_vertices(),
            num_faces: mesh.num_faces(),
            num_edges: topo.edges().len(),
            components: topo.vertex_components().1,
            boundary_loops: topo.boundary_loops().len(),
            euler_characteristic: topo.euler_characteristic(),
            genus: if manifold { topo.genus() } else { None },
            surface_area: area,
            bounding_box_min: lo,
            bounding_box_max: hi,
            min_angle_degrees: min_angle.to_degrees(),
            max_angle_degrees: max_angle.to_degrees(),
            problems,
        }
    }

    /// Whether no [`MeshProblem`] was found.
    pub fn is_valid(&self) -> bool {
        self.problems.is_empty()
    }

    /// Length of the bounding box diagonal.
    pub fn bounding_box_diagonal(&self) -> f64 {
        diagonal(self.bounding_box_min, self.bounding_box_max)
    }
}

/// `|hi - lo|`, finite for any finite corners whose distance is representable.
fn diagonal(lo: [f64; 3], hi: [f64; 3]) -> f64 {
    2.0 * robust_norm(sub(hi.map(|c| c * 0.5), lo.map(|c| c * 0.5)))
}

/// Formats with about six significant digits, in plain or scientific notation.
fn sig(x: f64) -> String {
    let a = x.abs();
    if a == 0.0 {
        "0".to_owned()
    } else if !(1e-4..1e6).contains(&a) {
        format!("{x:.5e}")
    } else {
        let decimals = (5 - a.log10().floor() as i32).max(0) as usize;
        format!("{x:.decimals$}")
    }
}

impl fmt::Display for MeshReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let point = |p: &[f64; 3]| format!("[{}, {}, {}]", sig(p[0]), sig(p[1]), sig(p[2]));
        writeln!(f, "vertices        {}", self.num_vertices)?;
        writeln!(f, "faces           {}", self.num_faces)?;
        writeln!(f, "edges           {}", self.num_edges)?;
        writeln!(f, "components      {}", self.components)?;
        writeln!(f, "boundary loops  {}", self.boundary_loops)?;
        writeln!(f, "Euler char.     {}", self.euler_characteristic)?;
        match self.genus {
            Some(g) => writeln!(f, "genus           {g}")?,
            None => writeln!(f, "genus           undefined (not an oriented manifold)")?,
        }
        writeln!(f, "surface area    {}", sig(self.surface_area))?;
        writeln!(
            f,
            "bounding box    {} to {} (diagonal {})",
            point(&self.bounding_box_min),
            point(&self.bounding_box_max),
            sig(self.bounding_box_diagonal())
        )?;
        writeln!(
            f,
            "angles          min {:.3} deg, max {:.3} deg",
            self.min_angle_degrees, self.max_angle_degrees
        )?;
        if self.problems.is_empty() {
            writeln!(f, "problems        none")
        } else {
            writeln!(f, "problems        {}", self.problems.len())?;
            for p in &self.problems {
                writeln!(f, "  - {p}")?;
            }
            Ok(())
        }
    }
}

/// The mesh has problems that a strict consumer refuses.
#[derive(Clone, Debug, Error, PartialEq)]
#[error("the mesh is not valid: {}", join_problems(&self.problems))]
pub struct ValidationError {
    /// Everything found, as in [`MeshReport::problems`].
    pub problems: Vec<MeshProblem>,
}

fn join_problems(problems: &[MeshProblem]) -> String {
    problems
        .iter()
        .map(|p| p.to_string())
        .collect::<Vec<_>>()
        .join("; ")
}

/// `Ok(())` when [`MeshReport::new`] finds no problem, otherwise the list of
/// problems. Cost: as [`MeshReport::new`].
///
/// # Errors
/// [`ValidationError`] with every [`MeshProblem`] found.
pub fn validate(mesh: &TriMesh) -> Result<(), ValidationError> {
    let report = MeshReport::new(mesh);
    if report.is_valid() {
        Ok(())
    } else {
        Err(ValidationError {
            problems: report.problems,
        })
    }
}

/// Explicit repairs. Nothing in mfm repairs a mesh silently: call these, look
/// at what they return, and decide.
pub mod repair {
    use super::duplicate_faces;
    use crate::mesh::TriMesh;

    /// Removes the vertices no face uses, keeping the others in order.
    ///
    /// Returns the new mesh and the map `old index -> new index`, with
    /// `u32::MAX` for removed vertices (use it to carry per-vertex data over).
    /// Cost: `O(V + F)`.
    pub fn drop_unreferenced_vertices(mesh: &TriMesh) -> (TriMesh, Vec<u32>) {
        let mut map = vec![u32::MAX; mesh.num_vertices()];
        for f in mesh.faces() {
            for &v in f {
                map[v as usize] = 0;
            }
        }
        let mut positions = Vec::with_capacity(mesh.num_vertices());
        for (v, slot) in map.iter_mut().enumerate() {
            if *slot == 0 {
                *slot = positions.len() as u32;
                positions.push(mesh.positions()[v]);
            }
        }
        let faces = mesh
            .faces()
            .iter()
            .map(|f| [map[f[0] as usize], map[f[1] as usize], map[f[2] as usize]])
            .collect();
        // faces are unchanged up to renumbering, so every check still holds
        let out = TriMesh::new(positions, faces).expect("renumbering keeps the mesh valid");
        (out, map)
    }

    /// Removes every face whose vertex set (in any order) equals that of an
    /// earlier face, keeping the first occurrence and the order of the rest.
    /// Vertices are unchanged. Returns the new mesh and how many faces were
    /// removed. Cost: `O(F)` expected.
    pub fn drop_duplicate_faces(mesh: &TriMesh) -> (TriMesh, usize) {
        let dups = duplicate_faces(mesh.faces());
        if dups.is_empty() {
            return (mesh.clone(), 0);
        }
        let mut keep = vec![true; mesh.num_faces()];
        for d in &dups {
            keep[d[0]] = false;
        }
        let faces = mesh
            .faces()
            .iter()
            .zip(&keep)
            .filter(|(_, k)| **k)
            .map(|(f, _)| *f)
            .collect();
        // the first occurrence of every face stays, so the mesh keeps a face
        let out = TriMesh::new(mesh.positions().to_vec(), faces)
            .expect("a subset of valid faces is valid");
        (out, dups.len())
    }
}
