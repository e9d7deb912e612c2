//! Checks shared by the `processing_*` test suites.
#![allow(dead_code)]

use std::path::Path;

use mfm_geometry::mesh::{cross, dot, norm, sub, triangle_area};
use mfm_geometry::{Topology, TriMesh, procedural};
use proptest::prelude::*;

/// Asserts that `m` is a consistently oriented manifold with no degenerate
/// faces and no unreferenced vertices; returns its topology.
pub fn check_valid(m: &TriMesh) -> Topology {
    let t = Topology::new(m.num_vertices(), m.faces());
    assert!(t.non_manifold_edges().is_empty(), "non-manifold edges");
    assert_eq!(
        t.non_manifold_vertices(),
        Vec::<usize>::new(),
        "non-manifold vertices"
    );
    assert_eq!(
        t.inconsistently_oriented_edges(),
        Vec::<usize>::new(),
        "orientation"
    );
    assert_eq!(
        t.unreferenced_vertices(),
        Vec::<usize>::new(),
        "unreferenced vertices"
    );
    let d = m.bounding_box_diagonal();
    for f in 0..m.num_faces() {
        let a = triangle_area(&m.face_positions(f));
        assert!(a > 1e-12 * d * d, "face {f} is degenerate (area {a})");
    }
    t
}

/// Signed enclosed volume (positive for outward faces of a closed mesh).
pub fn signed_volume(m: &TriMesh) -> f64 {
    (0..m.num_faces())
        .map(|f| {
            let [a, b, c] = m.face_positions(f);
            dot(a, cross(b, c)) / 6.0
        })
        .sum()
}

/// Smallest interior angle over all faces, in radians.
pub fn min_angle(m: &TriMesh) -> f64 {
    let mut best = f64::INFINITY;
    for f in 0..m.num_faces() {
        let p = m.face_positions(f);
        for k in 0..3 {
            let u = sub(p[(k + 1) % 3], p[k]);
            let v = sub(p[(k + 2) % 3], p[k]);
            let c = (dot(u, v) / (norm(u) * norm(v))).clamp(-1.0, 1.0);
            best = best.min(c.acos());
        }
    }
    best
}

/// Mean of `4√3·area / Σ edge²` over the faces (1 = all equilateral).
pub fn mean_quality(m: &TriMesh) -> f64 {
    let total: f64 = (0..m.num_faces())
        .map(|f| {
            let p = m.face_positions(f);
            let s: f64 = (0..3)
                .map(|k| {
                    let d = sub(p[(k + 1) % 3], p[k]);
                    dot(d, d)
                })
                .sum();
            4.0 * 3.0_f64.sqrt() * triangle_area(&p) / s
        })
        .sum();
    total / m.num_faces() as f64
}

/// A minimal OFF reader for the shared meshes (the crate's own reader lives in
/// `io`; this one keeps the processing tests independent of it). Polygons are
/// fan-triangulated.
pub fn read_off(path: &Path) -> TriMesh {
    let text = std::fs::read_to_string(path).expect("readable OFF file");
    let mut tokens = text
        .lines()
        .map(|l| l.split('#').next().unwrap_or(""))
        .flat_map(str::split_whitespace);
    assert_eq!(tokens.next(), Some("OFF"), "OFF header");
    let mut num = || -> f64 { tokens.next().expect("token").parse().expect("number") };
    let (nv, nf) = (num() as usize, num() as usize);
    let _ = num();
    let positions: Vec<[f64; 3]> = (0..nv).map(|_| [num(), num(), num()]).collect();
    let mut faces = Vec::with_capacity(nf);
    for _ in 0..nf {
        let k = num() as usize;
        let poly: Vec<u32> = (0..k).map(|_| num() as u32).collect();
        for i in 1..k.saturating_sub(1) {
            faces.push([poly[0], poly[i], poly[i + 1]]);
        }
    }
    TriMesh::new(positions, faces).expect("valid OFF mesh")
}

/// Small procedural test meshes of every family, with their genus and
/// whether they are closed.
#[derive(Clone, Debug)]
pub struct Case {
    pub name: String,
    pub mesh: TriMesh,
    pub genus: u64,
    pub closed: bool,
}

pub fn mesh_cases() -> impl Strategy<Value = Case> {
    prop_oneof![
        (0u32..=2).prop_map(|n| Case {
            name: format!("icosphere({n})"),
            mesh: procedural::icosphere(n),
            genus: 0,
            closed: true,
        }),
        (3u32..9, 3u32..11).prop_map(|(r, s)| Case {
            name: format!("uv_sphere({r}, {s})"),
            mesh: procedural::uv_sphere(r, s).expect("valid parameters"),
            genus: 0,
            closed: true,
        }),
        (1.0f64..2.0, 0.2f64..0.6, 6u32..16, 4u32..10).prop_map(|(big, ratio, m, n)| Case {
            name: format!("torus({big}, {}, {m}, {n})", big * ratio),
            mesh: procedural::torus(big, big * ratio, m, n).expect("valid parameters"),
            genus: 1,
            closed: true,
        }),
        (0.2f64..1.0, 0.1f64..1.5, 1u32..4, 3u32..10).prop_map(|(r, h, k, s)| Case {
            name: format!("capsule({r}, {h}, {k}, {s})"),
            mesh: procedural::capsule(r, h, k, s).expect("valid parameters"),
            genus: 0,
            closed: true,
        }),
        (1u32..9, 1u32..9, 0.5f64..3.0, 0.5f64..3.0).prop_map(|(nx, ny, w, h)| Case {
            name: format!("plane_grid({nx}, {ny}, {w}, {h})"),
            mesh: procedural::plane_grid(nx, ny, w, h).expect("valid parameters"),
            genus: 0,
            closed: false,
        }),
    ]
}
