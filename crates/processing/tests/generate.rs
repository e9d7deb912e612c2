//! Procedural meshes, uniform subdivision and local refinement: counts,
//! topology, orientation, and geometry against analytic values and libigl.

mod support;

use std::collections::HashSet;
use std::f64::consts::PI;
use std::io::Write;

use mfm_geometry::mesh::{add, norm, scale, sub};
use mfm_geometry::subdivide::{self, LoopWeights};
use mfm_geometry::test_support::{python_oracle, shared_mesh};
use mfm_geometry::{Topology, TriMesh, procedural};
use mfm_processing::refine::{RefineCriterion, refine_region, refine_region_with_map};
use proptest::prelude::*;
use support::{Case, check_valid, mesh_cases, min_angle, read_off, signed_volume};

fn rel(a: f64, b: f64) -> f64 {
    (a - b).abs() / b.abs()
}

// ---------------------------------------------------------------- procedural

#[test]
fn icosphere_counts_radius_and_area() {
    let mut last_area = 0.0;
    for n in 0..=4u32 {
        let m = procedural::icosphere(n);
        let k = 4usize.pow(n);
        assert_eq!((m.num_vertices(), m.num_faces()), (10 * k + 2, 20 * k));
        let t = check_valid(&m);
        assert!(t.boundary_loops().is_empty());
        assert_eq!(t.genus(), Some(0));
        assert!(signed_volume(&m) > 0.0);
        for p in m.positions() {
            assert!((norm(*p) - 1.0).abs() < 1e-14);
        }
        // inscribed polyhedra: area grows towards 4 pi from below
        let a = m.total_area();
        assert!(a > last_area && a < 4.0 * PI);
        last_area = a;
    }
    // error ~ 1/F: level 4 (5120 faces) is within 0.3%
    assert!(rel(last_area, 4.0 * PI) < 3e-3, "{last_area}");
}

#[test]
fn fine_meshes_approach_analytic_areas_and_volumes() {
    let sphere = procedural::uv_sphere(64, 128).expect("valid");
    assert!(rel(sphere.total_area(), 4.0 * PI) < 2e-3);
    assert!(rel(signed_volume(&sphere), 4.0 / 3.0 * PI) < 3e-3);
    let (big, small) = (2.0, 0.5);
    let torus = procedural::torus(big, small, 128, 48).expect("valid");
    assert!(rel(torus.total_area(), 4.0 * PI * PI * big * small) < 2e-3);
    assert!(rel(signed_volume(&torus), 2.0 * PI * PI * big * small * small) < 4e-3);
    let (r, h) = (0.5, 1.0);
    let cap = procedural::capsule(r, h, 24, 128).expect("valid");
    assert!(rel(cap.total_area(), 4.0 * PI * r * r + 4.0 * PI * r * h) < 2e-3);
    let (lo, hi) = cap.bounding_box();
    assert!((lo[2] + r + h).abs() < 1e-14 && (hi[2] - r - h).abs() < 1e-14);
}

#[test]
fn plane_grid_is_flat_and_open() {
    let g = procedural::plane_grid(5, 3, 2.5, 1.5).expect("valid");
    let t = check_valid(&g);
    assert_eq!(t.euler_characteristic(), 1);
    let loops = t.boundary_loops();
    assert_eq!(loops.len(), 1);
    assert_eq!(loops[0].len(), 2 * (5 + 3));
    assert!((g.total_area() - 2.5 * 1.5).abs() < 1e-12);
    assert_eq!(g.bounding_box(), ([-1.25, -0.75, 0.0], [1.25, 0.75, 0.0]));
    for f in 0..g.num_faces() {
        let n = mfm_geometry::mesh::triangle_normal(&g.face_positions(f));
        assert!(n[2] > 0.0, "face {f} is not counter-clockwise from +z");
    }
}

fn expected_counts(c: &Case) -> Option<(usize, usize)> {
    let nums: Vec<f64> = c
        .name
        .split(|ch: char| !(ch.is_ascii_digit() || ch == '.'))
        .filter(|s| !s.is_empty())
        .filter_map(|s| s.parse().ok())
        .collect();
    let u = |i: usize| nums[i] as usize;
    if c.name.starts_with("uv_sphere") {
        Some(((u(0) - 1) * u(1) + 2, 2 * (u(0) - 1) * u(1)))
    } else if c.name.starts_with("torus") {
        Some((u(2) * u(3), 2 * u(2) * u(3)))
    } else if c.name.starts_with("capsule") {
        Some((2 * u(2) * u(3) + 2, 4 * u(2) * u(3)))
    } else if c.name.starts_with("plane_grid") {
        Some(((u(0) + 1) * (u(1) + 1), 2 * u(0) * u(1)))
    } else {
        None
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    #[test]
    fn procedural_meshes_are_valid(c in mesh_cases()) {
        let m = &c.mesh;
        let t = check_valid(m);
        prop_assert_eq!(t.genus(), Some(c.genus), "{}", c.name);
        prop_assert_eq!(t.boundary_loops().is_empty(), c.closed);
        if c.closed {
            prop_assert!(signed_volume(m) > 0.0, "{} is inside out", c.name);
        }
        if let Some(counts) = expected_counts(&c) {
            prop_assert_eq!((m.num_vertices(), m.num_faces()), counts, "{}", c.name);
        }
        // no duplicated seam or pole vertices
        let d = m.bounding_box_diagonal();
        for i in 0..m.num_vertices() {
            for j in 0..i {
                let gap = norm(sub(m.positions()[i], m.positions()[j]));
                prop_assert!(gap > 1e-9 * d, "{}: vertices {} and {} coincide", c.name, i, j);
            }
        }
    }

    #[test]
    fn bad_parameters_never_panic(a in -2.0f64..2.0, b in -2.0f64..2.0, n in 0u32..5, k in 0u32..5) {
        // every combination is either a valid mesh or an error
        let results = [
            procedural::torus(a, b, n, k),
            procedural::capsule(a, b, n, k),
            procedural::plane_grid(n, k, a, b),
            procedural::uv_sphere(n, k),
        ];
        for m in results.iter().flatten() {
            check_valid(m);
        }
    }
}

// ---------------------------------------------------------------- subdivision

proptest! {
    #![proptest_config(ProptestConfig::with_cases(32))]

    #[test]
    fn subdivision_keeps_topology(c in mesh_cases(), use_loop in any::<bool>()) {
        let m = &c.mesh;
        let t0 = Topology::new(m.num_vertices(), m.faces());
        let s = if use_loop {
            subdivide::loop_subdivision(m).expect("small mesh")
        } else {
            subdivide::midpoint(m).expect("small mesh")
        };
        prop_assert_eq!(s.num_vertices(), m.num_vertices() + t0.edges().len());
        prop_assert_eq!(s.num_faces(), 4 * m.num_faces());
        let t = check_valid(&s);
        prop_assert_eq!(t.euler_characteristic(), t0.euler_characteristic());
        prop_assert_eq!(t.genus(), Some(c.genus));
        prop_assert_eq!(t.boundary_loops().len(), t0.boundary_loops().len());
        if !use_loop {
            // midpoints do not change the surface
            prop_assert!(rel(s.total_area(), m.total_area()) < 1e-12);
            if c.closed {
                prop_assert!(rel(signed_volume(&s), signed_volume(m)) < 1e-12);
            }
        } else if c.closed {
            // Loop smoothing shrinks convex shapes but keeps them outward
            prop_assert!(signed_volume(&s) > 0.0);
        }
    }
}

#[test]
fn loop_keeps_a_plane_flat_and_a_regular_grid_regular() {
    let g = procedural::plane_grid(10, 8, 3.0, 2.0).expect("valid");
    let once = subdivide::loop_subdivision(&g).expect("small");
    let twice = subdivide::loop_subdivision(&once).expect("small");
    assert!(twice.positions().iter().all(|p| p[2] == 0.0));
    check_valid(&twice);
    // away from the boundary, Loop on a regular grid is the midpoint rule:
    // affine weights on a translation-invariant lattice
    let mid = subdivide::midpoint(&g).expect("small");
    let t = Topology::new(g.num_vertices(), g.faces());
    let mut near_boundary = vec![false; g.num_vertices()];
    for e in t.boundary_edges() {
        for v in t.edges()[e] {
            near_boundary[v as usize] = true;
        }
    }
    let on_boundary = near_boundary.clone();
    for &[a, b] in t.edges() {
        if on_boundary[a as usize] || on_boundary[b as usize] {
            for v in [a, b] {
                near_boundary[v as usize] = true;
            }
        }
    }
    let mut checked = 0;
    for (v, &near) in near_boundary.iter().enumerate().take(g.num_vertices()) {
        if !near {
            assert!(norm(sub(once.positions()[v], mid.positions()[v])) < 1e-14);
            checked += 1;
        }
    }
    for (e, &[a, b]) in t.edges().iter().enumerate() {
        if !near_boundary[a as usize] && !near_boundary[b as usize] {
            let i = g.num_vertices() + e;
            assert!(norm(sub(once.positions()[i], mid.positions()[i])) < 1e-14);
            checked += 1;
        }
    }
    assert!(checked > 20);
}

/// `(max r - min r) / mean r` of the vertex radii.
fn radial_spread(m: &TriMesh) -> f64 {
    let r: Vec<f64> = m.positions().iter().map(|p| norm(*p)).collect();
    let (lo, hi) = r
        .iter()
        .fold((f64::INFINITY, 0.0f64), |(a, b), &x| (a.min(x), b.max(x)));
    (hi - lo) / (r.iter().sum::<f64>() / r.len() as f64)
}

#[test]
fn loop_smooths_the_icosahedron_towards_a_sphere() {
    let mut m = procedural::icosahedron();
    let midpoint_spread = radial_spread(&subdivide::midpoint(&m).expect("small"));
    let mut spreads = Vec::new();
    for _ in 0..5 {
        m = subdivide::loop_subdivision(&m).expect("small");
        spreads.push(radial_spread(&m));
    }
    // the midpoint mesh is 15% out of round; Loop's limit surface of the
    // icosahedron is round to about 1.2%, and the steps converge to it
    assert!(midpoint_spread > 0.15, "{midpoint_spread}");
    assert!(spreads.iter().all(|&s| s < 0.015), "{spreads:?}");
    let steps: Vec<f64> = spreads.windows(2).map(|w| (w[1] - w[0]).abs()).collect();
    assert!(steps[3] < steps[2] && steps[2] < steps[1], "{spreads:?}");
    check_valid(&m);
}

/// Writes an OFF file for the oracle.
fn write_off(path: &std::path::Path, m: &TriMesh) {
    let mut f = std::fs::File::create(path).expect("temp file");
    writeln!(f, "OFF\n{} {} 0", m.num_vertices(), m.num_faces()).expect("write");
    for p in m.positions() {
        writeln!(f, "{:.17e} {:.17e} {:.17e}", p[0], p[1], p[2]).expect("write");
    }
    for t in m.faces() {
        writeln!(f, "3 {} {} {}", t[0], t[1], t[2]).expect("write");
    }
}

#[test]
fn warren_loop_matches_libigl() {
    let Some(python) = python_oracle() else {
        return;
    };
    let mut meshes = vec![
        procedural::torus(1.0, 0.4, 9, 7).expect("valid"),
        procedural::plane_grid(4, 3, 2.0, 1.0).expect("valid"),
    ];
    if let Some(p) = shared_mesh("decimated-knight.off") {
        meshes.push(read_off(&p));
    }
    let dir = tempfile::tempdir().expect("temp dir");
    for (i, m) in meshes.iter().enumerate() {
        let input = dir.path().join(format!("in{i}.off"));
        let output = dir.path().join(format!("out{i}.txt"));
        write_off(&input, m);
        let script = format!(
            "import igl, numpy as np\nV, F = igl.read_triangle_mesh(r'{}')\nV2, F2 = igl.loop(V, F)\nnp.savetxt(r'{}', V2, fmt='%.17e')\n",
            input.display(),
            output.display()
        );
        let status = std::process::Command::new(&python)
            .args(["-c", &script])
            .status()
            .expect("python runs");
        assert!(status.success());
        let theirs: Vec<[f64; 3]> = std::fs::read_to_string(&output)
            .expect("oracle output")
            .lines()
            .map(|l| {
                let v: Vec<f64> = l
                    .split_whitespace()
                    .map(|x| x.parse().expect("float"))
                    .collect();
                [v[0], v[1], v[2]]
            })
            .collect();
        let ours = subdivide::loop_subdivision_with(m, LoopWeights::Warren).expect("small");
        assert_eq!(ours.num_vertices(), theirs.len());
        // old vertices keep their indices in both; new ones are compared as sets
        let tol = 1e-12 * m.bounding_box_diagonal();
        let n = m.num_vertices();
        for (v, (p, q)) in ours.positions().iter().zip(&theirs).take(n).enumerate() {
            assert!(norm(sub(*p, *q)) < tol, "mesh {i} vertex {v}");
        }
        let mut used = vec![false; theirs.len()];
        for p in &ours.positions()[n..] {
            let j = (n..theirs.len())
                .filter(|&j| !used[j])
                .min_by(|&a, &b| norm(sub(*p, theirs[a])).total_cmp(&norm(sub(*p, theirs[b]))))
                .expect("a match");
            assert!(
                norm(sub(*p, theirs[j])) < tol,
                "mesh {i}: edge vertex {p:?}"
            );
            used[j] = true;
        }
    }
}

#[test]
fn subdivision_map_carries_linear_data() {
    let m = procedural::torus(1.0, 0.3, 8, 5).expect("valid");
    let (fine, map) = subdivide::midpoint_with_map(&m).expect("small");
    let (refined, rmap) =
        refine_region_with_map(&m, |c| c[0] > 0.0, RefineCriterion::Rounds(3)).expect("manifold");
    for (mesh, map) in [(&fine, &map), (&refined, &rmap)] {
        assert_eq!(map.num_fine_vertices(), mesh.num_vertices());
        for k in 0..3 {
            let coarse: Vec<f64> = m.positions().iter().map(|p| p[k]).collect();
            let lifted = map.prolong(&coarse).expect("right length");
            for (v, p) in mesh.positions().iter().enumerate() {
                assert!((lifted[v] - p[k]).abs() < 1e-14);
            }
        }
    }
}

// ---------------------------------------------------------------- refinement

/// Conformity: every split edge is gone from the result (a face still
/// having it would have the midpoint hanging on its side: a T-junction).
fn assert_conforming(mesh: &TriMesh, map: &subdivide::SubdivisionMap) {
    let t = Topology::new(mesh.num_vertices(), mesh.faces());
    for (i, &[a, b]) in map.parents().iter().enumerate() {
        let m = (map.num_coarse_vertices() + i) as u32;
        assert!(
            t.find_edge(a, b).is_none(),
            "T-junction: edge {a}-{b} survives its midpoint {m}"
        );
    }
}

#[test]
fn refining_half_a_grid_touches_only_that_half() {
    let g = procedural::plane_grid(16, 16, 2.0, 2.0).expect("valid"); // cells of 0.125
    let h = 0.05;
    let (r, map) =
        refine_region_with_map(&g, |c| c[0] > 0.0, RefineCriterion::MaxEdgeLength(h)).expect("ok");
    let t = check_valid(&r);
    assert_conforming(&r, &map);
    assert_eq!(t.boundary_loops().len(), 1);
    assert_eq!(t.euler_characteristic(), 1);
    assert!((r.total_area() - 4.0).abs() < 1e-12);
    // the boundary polygon still has perimeter 8 (no cracks)
    let perimeter: f64 = t
        .boundary_edges()
        .iter()
        .map(|&e| {
            let [a, b] = t.edges()[e];
            norm(sub(r.positions()[a as usize], r.positions()[b as usize]))
        })
        .sum();
    assert!((perimeter - 8.0).abs() < 1e-12);
    let centroid = |m: &TriMesh, f: usize| {
        let p = m.face_positions(f);
        scale(add(add(p[0], p[1]), p[2]), 1.0 / 3.0)
    };
    let longest = |m: &TriMesh, f: usize| {
        let p = m.face_positions(f);
        (0..3)
            .map(|k| norm(sub(p[k], p[(k + 1) % 3])))
            .fold(0.0, f64::max)
    };
    for f in 0..r.num_faces() {
        if centroid(&r, f)[0] > 0.0 {
            assert!(longest(&r, f) <= h, "face {f} in the region is too long");
        }
    }
    // the closure only splits the column of cells next to the region
    let mut kept = 0;
    for f in 0..g.num_faces() {
        if g.face_positions(f).iter().all(|p| p[0] <= -0.125) {
            assert_eq!(r.faces()[f], g.faces()[f]);
            kept += 1;
        }
    }
    assert_eq!(kept, 2 * 7 * 16);
    // the region got many more faces, the far side none
    assert!(r.num_faces() > 8 * g.num_faces());
    // longest-edge bisection keeps angles >= half the input's smallest
    assert!(min_angle(&r) >= 0.5 * min_angle(&g) - 1e-12);
}

#[test]
fn refining_half_a_sphere_keeps_it_closed() {
    let s = procedural::icosphere(2);
    let (r, map) =
        refine_region_with_map(&s, |c| c[2] > 0.0, RefineCriterion::Rounds(4)).expect("ok");
    let t = check_valid(&r);
    assert_conforming(&r, &map);
    assert!(t.boundary_loops().is_empty());
    assert_eq!(t.genus(), Some(0));
    assert!(rel(r.total_area(), s.total_area()) < 1e-12);
    assert!(rel(signed_volume(&r), signed_volume(&s)) < 1e-12);
    let south: HashSet<[u32; 3]> = (0..s.num_faces())
        .filter(|&f| s.face_positions(f).iter().all(|p| p[2] < -0.3))
        .map(|f| s.faces()[f])
        .collect();
    for f in &south {
        assert!(r.faces().contains(f), "southern face {f:?} was modified");
    }
    // 4 rounds: about 2^4 times more faces in the north
    assert!(r.num_faces() > 6 * s.num_faces(), "{}", r.num_faces());
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(32))]

    #[test]
    fn refinement_is_conforming_and_keeps_the_surface(
        c in mesh_cases(),
        dir in prop::array::uniform3(-1.0f64..1.0),
        offset in -0.5f64..0.5,
        by_length in any::<bool>(),
        frac in 0.25f64..0.9,
        rounds in 1u32..4,
    ) {
        let m = &c.mesh;
        let t0 = Topology::new(m.num_vertices(), m.faces());
        let d = m.bounding_box_diagonal();
        let region = |p: [f64; 3]| dir[0] * p[0] + dir[1] * p[1] + dir[2] * p[2] > offset * d;
        let mean_edge = t0
            .edges()
            .iter()
            .map(|&[a, b]| norm(sub(m.positions()[a as usize], m.positions()[b as usize])))
            .sum::<f64>()
            / t0.edges().len() as f64;
        let h = frac * mean_edge;
        let criterion = if by_length {
            RefineCriterion::MaxEdgeLength(h)
        } else {
            RefineCriterion::Rounds(rounds)
        };
        let (r, map) = refine_region_with_map(m, region, criterion).expect("manifold input");
        let t = check_valid(&r);
        assert_conforming(&r, &map);
        prop_assert_eq!(t.euler_characteristic(), t0.euler_characteristic());
        prop_assert_eq!(t.boundary_loops().len(), t0.boundary_loops().len());
        prop_assert!(rel(r.total_area(), m.total_area()) < 1e-12);
        if c.closed {
            prop_assert!(rel(signed_volume(&r), signed_volume(m)) < 1e-10);
        }
        prop_assert!(min_angle(&r) >= 0.5 * min_angle(m) - 1e-12, "{}", c.name);
        // faces out of the region are never split on purpose: with an empty
        // region nothing changes
        let same = refine_region(m, |_| false, criterion).expect("ok");
        prop_assert_eq!(&same, m);
    }
}
