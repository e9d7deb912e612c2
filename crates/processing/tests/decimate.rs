//! Quadric edge-collapse decimation: target counts, topology and geometry.

mod support;

use std::collections::HashSet;

use mfm_geometry::mesh::{add, dot, norm, triangle_normal};
use mfm_geometry::test_support::shared_mesh;
use mfm_geometry::{Topology, TriMesh, procedural};
use mfm_processing::decimate::{DecimateOptions, decimate, decimate_with};
use proptest::prelude::*;
use support::{check_valid, mesh_cases, read_off, signed_volume};

/// Asserts the decimation kept the topology and met (or honestly missed) the target.
fn check_against_input(input: &TriMesh, out: &mfm_processing::decimate::Decimation, target: usize) {
    let t0 = Topology::new(input.num_vertices(), input.faces());
    let t = check_valid(&out.mesh);
    assert_eq!(t.euler_characteristic(), t0.euler_characteristic());
    assert_eq!(t.genus(), t0.genus());
    assert_eq!(t.boundary_loops().len(), t0.boundary_loops().len());
    assert_eq!(t.face_components().1, t0.face_components().1);
    let f = out.mesh.num_faces();
    if out.target_reached {
        assert!(
            f <= target && f + 1 >= target,
            "{f} faces for target {target}"
        );
    } else {
        assert!(f > target);
    }
    // every collapse removes one or two faces
    let removed = input.num_faces() - f;
    assert!(out.collapses <= removed && removed <= 2 * out.collapses);
}

#[test]
fn sphere_stays_round_and_outward() {
    let s = procedural::icosphere(4); // 5120 faces
    let out = decimate(&s, 1280, None).expect("manifold");
    assert!(out.target_reached);
    check_against_input(&s, &out, 1280);
    for f in 0..out.mesh.num_faces() {
        let p = out.mesh.face_positions(f);
        let c = add(add(p[0], p[1]), p[2]);
        assert!(dot(triangle_normal(&p), c) > 0.0, "face {f} flipped");
    }
    for p in out.mesh.positions() {
        assert!(
            (norm(*p) - 1.0).abs() < 0.02,
            "vertex off the sphere: {}",
            norm(*p)
        );
    }
    // at a quarter of the faces the volume is still that of a fine sphere
    let v = signed_volume(&out.mesh);
    assert!((v - signed_volume(&s)).abs() < 0.01 * v);
}

#[test]
fn torus_keeps_its_handle() {
    let t = procedural::torus(1.0, 0.3, 64, 24).expect("valid"); // 3072 faces
    let out = decimate(&t, 400, None).expect("manifold");
    assert!(out.target_reached);
    check_against_input(&t, &out, 400);
    assert_eq!(
        Topology::new(out.mesh.num_vertices(), out.mesh.faces()).genus(),
        Some(1)
    );
}

#[test]
fn flat_grid_stays_flat_with_its_rectangle() {
    let g = procedural::plane_grid(30, 20, 3.0, 2.0).expect("valid");
    let out = decimate(&g, 200, None).expect("manifold");
    assert!(out.target_reached);
    check_against_input(&g, &out, 200);
    assert!(out.mesh.positions().iter().all(|p| p[2].abs() < 1e-12));
    // boundary vertices only slide along the boundary and the corners stay
    let ((lo, hi), (lo0, hi0)) = (out.mesh.bounding_box(), g.bounding_box());
    for (a, b) in lo.iter().chain(&hi).zip(lo0.iter().chain(&hi0)) {
        assert!((a - b).abs() < 1e-12);
    }
    assert!((out.mesh.total_area() - 6.0).abs() < 1e-9);
    for f in 0..out.mesh.num_faces() {
        assert!(triangle_normal(&out.mesh.face_positions(f))[2] > 0.0);
    }
}

#[test]
fn region_limits_what_changes() {
    let s = procedural::icosphere(4);
    let inside = |p: [f64; 3]| p[0] > 0.2;
    // the cap x > 0.2 holds 40% of the 5120 faces; remove 1100 of its ~2050
    let out = decimate(&s, 4020, Some(&inside)).expect("manifold");
    assert!(out.target_reached);
    check_against_input(&s, &out, 4020);
    // faces with no vertex in the region are all still there, at the same place
    let key = |p: [f64; 3]| p.map(f64::to_bits);
    let result: HashSet<[[u64; 3]; 3]> = (0..out.mesh.num_faces())
        .map(|f| out.mesh.face_positions(f).map(key))
        .collect();
    let mut outside = 0;
    for f in 0..s.num_faces() {
        let p = s.face_positions(f);
        if p.iter().all(|&q| !inside(q)) {
            assert!(
                result.contains(&p.map(key)),
                "face {f} outside the region changed"
            );
            outside += 1;
        }
    }
    assert!(outside > 2800);
    // and the region itself got coarser: about half the vertices with x > 0.2
    let count = |m: &TriMesh| m.positions().iter().filter(|p| inside(**p)).count() as f64;
    assert!(count(&out.mesh) < 0.6 * count(&s));
}

#[test]
fn unreachable_target_returns_the_best_mesh() {
    let ico = procedural::icosahedron();
    let out = decimate(&ico, 1, None).expect("manifold");
    assert!(!out.target_reached);
    check_against_input(&ico, &out, 1);
    // the smallest closed triangulation reachable is the tetrahedron
    assert_eq!(out.mesh.num_faces(), 4);
    // region that allows nothing
    let none = |_: [f64; 3]| false;
    let out = decimate(&ico, 10, Some(&none)).expect("manifold");
    assert_eq!((out.collapses, out.mesh.num_faces()), (0, 20));
}

#[test]
fn strict_options_are_respected() {
    let s = procedural::icosphere(3);
    let strict = DecimateOptions {
        max_normal_change_degrees: 5.0,
        min_triangle_quality: 0.6,
        ..Default::default()
    };
    let out = decimate_with(&s, 100, None, &strict).expect("manifold");
    check_against_input(&s, &out, 100);
    // such limits stop well before the target
    assert!(!out.target_reached);
    let loose = decimate(&s, 100, None).expect("manifold");
    assert!(loose.mesh.num_faces() < out.mesh.num_faces());
}

#[test]
fn shared_meshes_keep_their_genus() {
    // lion.off is open: its boundary loop must survive
    for (name, frac) in [
        ("bunny.off", 4),
        ("3holes.off", 10),
        ("fertility.off", 10),
        ("lion.off", 8),
    ] {
        let Some(path) = shared_mesh(name) else {
            continue;
        };
        let m = read_off(&path);
        let target = m.num_faces() / frac;
        let out = decimate(&m, target, None).expect("manifold");
        assert!(out.target_reached, "{name}");
        check_against_input(&m, &out, target);
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(32))]

    #[test]
    fn decimation_keeps_a_valid_manifold(c in mesh_cases(), frac in 0.05f64..0.9, half in any::<bool>()) {
        let m = &c.mesh;
        let target = (frac * m.num_faces() as f64) as usize;
        let region = |p: [f64; 3]| p[0] + 0.3 * p[1] > 0.0;
        let out = decimate(m, target, if half { Some(&region) } else { None })
            .expect("manifold input");
        check_against_input(m, &out, target);
        if c.closed {
            prop_assert!(signed_volume(&out.mesh) > 0.0, "{} turned inside out", c.name);
        }
    }
}
