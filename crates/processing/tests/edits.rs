//! Edge flips, holes and connected components.

mod support;

use mfm_geometry::mesh::{norm, sub};
use mfm_geometry::{Topology, TriMesh, procedural};
use mfm_processing::flips::{FlipAmount, random_edge_flips};
use mfm_processing::holes::{
    HoleMetric, connected_components, edge_path_distances, largest_component, punch_holes,
};
use proptest::prelude::*;
use support::{check_valid, mean_quality, mesh_cases, signed_volume};

// ---------------------------------------------------------------- flips

proptest! {
    #![proptest_config(ProptestConfig::with_cases(32))]

    #[test]
    fn flips_keep_counts_topology_and_orientation(
        c in mesh_cases(),
        fraction in 0.0f64..1.0,
        seed in any::<u64>(),
    ) {
        let m = &c.mesh;
        let t0 = Topology::new(m.num_vertices(), m.faces());
        let out = random_edge_flips(m, FlipAmount::Fraction(fraction), seed);
        prop_assert_eq!(out.mesh.positions(), m.positions());
        prop_assert_eq!(out.mesh.num_faces(), m.num_faces());
        let t = check_valid(&out.mesh);
        prop_assert_eq!(t.euler_characteristic(), t0.euler_characteristic());
        prop_assert_eq!(t.genus(), Some(c.genus));
        prop_assert_eq!(t.boundary_loops().len(), t0.boundary_loops().len());
        let interior = t0.edges().len() - t0.boundary_edges().len();
        prop_assert!(out.flips <= (fraction * interior as f64).round() as usize);
        // exactly `flips` edges were replaced by new ones
        let gone = t0
            .edges()
            .iter()
            .filter(|&&[a, b]| t.find_edge(a, b).is_none())
            .count();
        prop_assert_eq!(gone, out.flips);
        if c.closed {
            prop_assert!(signed_volume(&out.mesh) > 0.0);
        }
        // reproducible
        let again = random_edge_flips(m, FlipAmount::Fraction(fraction), seed);
        prop_assert_eq!(again.mesh, out.mesh);
    }
}

#[test]
fn flips_worsen_a_good_triangulation() {
    let s = procedural::icosphere(3);
    let interior = 3 * s.num_faces() / 2;
    let out = random_edge_flips(&s, FlipAmount::Fraction(0.3), 1);
    // nearly all requested flips are possible on a fine sphere
    assert!(out.flips as f64 > 0.25 * interior as f64, "{}", out.flips);
    check_valid(&out.mesh);
    let (q0, q1) = (mean_quality(&s), mean_quality(&out.mesh));
    assert!(q1 < q0 - 0.1, "quality {q0} -> {q1}");
    // flips never fold the surface: every face still points outward
    for f in 0..out.mesh.num_faces() {
        let p = out.mesh.face_positions(f);
        let n = mfm_geometry::mesh::triangle_normal(&p);
        assert!(mfm_geometry::mesh::dot(n, p[0]) > 0.0);
    }
    let other = random_edge_flips(&s, FlipAmount::Fraction(0.3), 2);
    assert_ne!(other.mesh, out.mesh, "seeds must matter");
    let counted = random_edge_flips(&s, FlipAmount::Count(10), 1);
    assert_eq!(counted.flips, 10);
    let none = random_edge_flips(&s, FlipAmount::Fraction(f64::NAN), 1);
    assert_eq!((none.flips, &none.mesh), (0, &s));
}

#[test]
fn flat_grid_flips_keep_it_flat_and_unfolded() {
    let g = procedural::plane_grid(12, 9, 2.0, 1.5).expect("valid");
    let out = random_edge_flips(&g, FlipAmount::Fraction(1.0), 5);
    assert!(out.flips > 50);
    check_valid(&out.mesh);
    // same area means no two faces overlap
    assert!((out.mesh.total_area() - 3.0).abs() < 1e-12);
    for f in 0..out.mesh.num_faces() {
        assert!(mfm_geometry::mesh::triangle_normal(&out.mesh.face_positions(f))[2] > 0.0);
    }
}

// ---------------------------------------------------------------- holes

fn topo(m: &TriMesh) -> Topology {
    Topology::new(m.num_vertices(), m.faces())
}

#[test]
fn antipodal_holes_make_a_tube() {
    let s = procedural::icosphere(3);
    // vertex 0 and its antipode (the icosahedron's vertices come in pairs)
    let p0 = s.positions()[0];
    let anti = (0..s.num_vertices())
        .min_by(|&a, &b| {
            let d = |v: usize| norm(sub(s.positions()[v], [-p0[0], -p0[1], -p0[2]]));
            d(a).total_cmp(&d(b))
        })
        .expect("vertices");
    for metric in [HoleMetric::Euclidean, HoleMetric::Geodesic] {
        let out = punch_holes(&s, &[0, anti], 0.4, metric).expect("ok");
        let t = check_valid(&out.mesh);
        assert_eq!(t.boundary_loops().len(), 2);
        assert_eq!(t.euler_characteristic(), 0);
        assert_eq!(t.genus(), Some(0));
        assert_eq!(out.original_vertex.len(), out.mesh.num_vertices());
        for (v, &o) in out.original_vertex.iter().enumerate() {
            assert_eq!(out.mesh.positions()[v], s.positions()[o as usize]);
        }
        assert_eq!(out.removed_faces, s.num_faces() - out.mesh.num_faces(),);
        // no remaining vertex is inside a hole
        let dist = edge_path_distances(&s, &[0, anti]).expect("ok");
        if metric == HoleMetric::Geodesic {
            assert!(out.original_vertex.iter().all(|&o| dist[o as usize] >= 0.4));
        }
    }
}

#[test]
fn holes_in_a_torus_and_a_grid() {
    let t = procedural::torus(1.0, 0.35, 32, 12).expect("valid");
    let out = punch_holes(&t, &[0], 0.3, HoleMetric::Geodesic).expect("ok");
    let tp = check_valid(&out.mesh);
    assert_eq!(tp.boundary_loops().len(), 1);
    assert_eq!(tp.euler_characteristic(), -1);
    assert_eq!(tp.genus(), Some(1));

    let g = procedural::plane_grid(10, 10, 1.0, 1.0).expect("valid");
    let centre = 5 + 5 * 11;
    let out = punch_holes(&g, &[centre], 0.15, HoleMetric::Euclidean).expect("ok");
    let tg = check_valid(&out.mesh);
    assert_eq!(tg.boundary_loops().len(), 2);
    assert_eq!(tg.euler_characteristic(), 0);
    // a ball of radius 0.15 around the centre catches the vertices at
    // distance 0.1 (4 of them) and 0.1414 (4 diagonal ones): 9 vertices
    let removed_vertices = g.num_vertices() - out.mesh.num_vertices();
    assert_eq!(removed_vertices, 9);
}

#[test]
fn edge_path_distances_match_bellman_ford() {
    let s = procedural::uv_sphere(7, 9).expect("valid");
    let sources = [3usize, 40];
    let fast = edge_path_distances(&s, &sources).expect("ok");
    let t = topo(&s);
    let mut slow = vec![f64::INFINITY; s.num_vertices()];
    for &v in &sources {
        slow[v] = 0.0;
    }
    for _ in 0..s.num_vertices() {
        for &[a, b] in t.edges() {
            let l = norm(sub(s.positions()[a as usize], s.positions()[b as usize]));
            let (a, b) = (a as usize, b as usize);
            slow[a] = slow[a].min(slow[b] + l);
            slow[b] = slow[b].min(slow[a] + l);
        }
    }
    for (x, y) in fast.iter().zip(&slow) {
        assert!((x - y).abs() < 1e-12);
    }
}

#[test]
fn a_belt_splits_the_sphere_into_two_caps() {
    let s = procedural::uv_sphere(16, 24).expect("valid");
    let belt: Vec<usize> = (0..s.num_vertices())
        .filter(|&v| s.positions()[v][2].abs() < 0.1)
        .collect();
    assert!(!belt.is_empty());
    let cut = punch_holes(&s, &belt, 0.05, HoleMetric::Euclidean).expect("ok");
    let parts = connected_components(&cut.mesh);
    assert_eq!(parts.len(), 2);
    for p in &parts {
        let t = check_valid(p);
        assert_eq!(t.boundary_loops().len(), 1);
        assert_eq!(t.genus(), Some(0));
    }
    let big = largest_component(&cut.mesh);
    assert_eq!(
        big.num_faces(),
        parts.iter().map(TriMesh::num_faces).max().unwrap_or(0)
    );
    assert_eq!(
        parts.iter().map(TriMesh::num_faces).sum::<usize>(),
        cut.mesh.num_faces()
    );
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(32))]

    #[test]
    fn punched_spheres_stay_valid(
        centres in prop::collection::vec(0usize..642, 1..5),
        radius in 0.05f64..0.6,
        geodesic in any::<bool>(),
    ) {
        let s = procedural::icosphere(3); // 642 vertices
        let metric = if geodesic { HoleMetric::Geodesic } else { HoleMetric::Euclidean };
        let out = punch_holes(&s, &centres, radius, metric).expect("small holes leave faces");
        let t = check_valid(&out.mesh);
        // any manifold piece of a sphere is a sphere with holes
        prop_assert_eq!(t.genus(), Some(0));
        // well separated holes are disjoint disks: chi drops by one per hole
        let max_edge = 0.2; // icosphere(3) edges are about 0.16 long
        let d = |a: usize, b: usize| norm(sub(s.positions()[a], s.positions()[b]));
        let mut distinct = centres.clone();
        distinct.sort_unstable();
        distinct.dedup();
        let separated = distinct
            .iter()
            .enumerate()
            .all(|(i, &a)| distinct[..i].iter().all(|&b| d(a, b) > 2.0 * radius + 4.0 * max_edge));
        if separated {
            let k = distinct.len();
            prop_assert_eq!(t.boundary_loops().len(), k);
            prop_assert_eq!(t.euler_characteristic(), 2 - k as i64);
            prop_assert_eq!(t.face_components().1, 1);
        }
    }
}

#[test]
fn bad_hole_requests_are_errors() {
    let s = procedural::icosphere(1);
    assert!(punch_holes(&s, &[42], 0.1, HoleMetric::Geodesic).is_err());
    assert!(punch_holes(&s, &[0], -1.0, HoleMetric::Geodesic).is_err());
    assert!(punch_holes(&s, &[0], 10.0, HoleMetric::Euclidean).is_err());
}
