//! Validation: every problem from a file in `fixtures/bad`, the documented
//! numbers of the shared meshes, libigl as an oracle for the measurements, a
//! brute-force oracle for random triangle soups, and the repairs.

// the mesh strategies and bad-file fixtures shared with the mesh I/O tests
#[path = "../../meshio/tests/io_support/mod.rs"]
mod io_support;

use io_support::{bad_fixture, coordinate, triangle};
use mfm_geometry::validate::{self, MeshProblem, MeshReport, repair};
use mfm_geometry::{TriMesh, procedural, test_support};
use proptest::prelude::*;
use std::collections::{BTreeMap, BTreeSet};

fn report_of(name: &str) -> MeshReport {
    MeshReport::new(&mfm_meshio::read_mesh(bad_fixture(name)).expect("fixture reads"))
}

#[test]
fn each_problem_fixture_reports_its_problem() {
    let r = report_of("degenerate_faces.off");
    assert_eq!(
        r.problems,
        vec![MeshProblem::DegenerateFaces {
            count: 1,
            first: vec![2]
        }]
    );
    assert_eq!(r.min_angle_degrees, 0.0);
    assert_eq!(r.max_angle_degrees, 180.0);

    let r = report_of("unreferenced_vertices.off");
    assert_eq!(
        r.problems,
        vec![MeshProblem::UnreferencedVertices {
            count: 1,
            first: vec![4]
        }]
    );
    assert_eq!((r.components, r.boundary_loops, r.genus), (1, 1, Some(0)));

    let r = report_of("non_manifold_edges.off");
    assert!(r.problems.contains(&MeshProblem::NonManifoldEdges {
        count: 1,
        first: vec![[0, 1]]
    }));
    assert!(r.problems.contains(&MeshProblem::NonManifoldVertices {
        count: 2,
        first: vec![0, 1]
    }));
    assert_eq!(r.genus, None);

    let r = report_of("non_manifold_vertices.off");
    assert_eq!(
        r.problems,
        vec![MeshProblem::NonManifoldVertices {
            count: 1,
            first: vec![0]
        }]
    );
    assert_eq!((r.components, r.genus), (1, None));

    let r = report_of("inconsistent_orientation.off");
    assert_eq!(
        r.problems,
        vec![MeshProblem::InconsistentOrientation {
            count: 1,
            first: vec![[1, 2]]
        }]
    );
    assert_eq!(r.genus, None);

    let r = report_of("duplicate_faces.off");
    assert!(r.problems.contains(&MeshProblem::DuplicateFaces {
        count: 1,
        first: vec![[2, 0]]
    }));

    // the strict check refuses each of them with the same list
    for name in [
        "degenerate_faces.off",
        "unreferenced_vertices.off",
        "non_manifold_edges.off",
        "non_manifold_vertices.off",
        "inconsistent_orientation.off",
        "duplicate_faces.off",
    ] {
        let mesh = mfm_meshio::read_mesh(bad_fixture(name)).expect("reads");
        let err = validate::validate(&mesh).expect_err(name);
        assert_eq!(err.problems, MeshReport::new(&mesh).problems);
        assert!(err.to_string().starts_with("the mesh is not valid: "));
    }
}

#[test]
fn display_and_json() {
    let r = report_of("unreferenced_vertices.off");
    let text = r.to_string();
    for line in [
        "vertices        5\n",
        "faces           2\n",
        "edges           5\n",
        "boundary loops  1\n",
        "Euler char.     1\n",
        "genus           0\n",
        "surface area    1.00000\n",
        "bounding box    [0, 0, 0] to [5.00000, 5.00000, 5.00000] (diagonal 8.66025)\n",
        "angles          min 45.000 deg, max 90.000 deg\n",
        "problems        1\n  - 1 unreferenced vertex (used by no face), e.g. vertex 4\n",
    ] {
        assert!(text.contains(line), "`{line}` not in\n{text}");
    }
    let clean = MeshReport::new(&procedural::icosphere(1));
    assert!(clean.to_string().ends_with("problems        none\n"));

    let json = serde_json::to_value(&r).expect("serializes");
    assert_eq!(json["num_vertices"], 5);
    assert_eq!(json["genus"], 0);
    assert_eq!(json["bounding_box_max"], serde_json::json!([5.0, 5.0, 5.0]));
    assert_eq!(
        json["problems"],
        serde_json::json!([{"kind": "unreferenced_vertices", "count": 1, "first": [4]}])
    );
    let json = serde_json::to_value(report_of("inconsistent_orientation.off")).expect("serializes");
    assert_eq!(json["genus"], serde_json::Value::Null);
    assert_eq!(json["problems"][0]["kind"], "inconsistent_orientation");
    assert_eq!(json["problems"][0]["first"], serde_json::json!([[1, 2]]));
}

#[test]
fn procedural_surfaces() {
    let r = MeshReport::new(&procedural::icosphere(2));
    assert!(r.is_valid(), "{r}");
    assert_eq!(
        (
            r.genus,
            r.components,
            r.boundary_loops,
            r.euler_characteristic
        ),
        (Some(0), 1, 0, 2)
    );
    assert_eq!(r.num_edges, 3 * r.num_faces / 2);
    let r = MeshReport::new(&procedural::torus(1.0, 0.3, 24, 12).expect("torus"));
    assert!(r.is_valid(), "{r}");
    assert_eq!((r.genus, r.euler_characteristic), (Some(1), 0));
    let r = MeshReport::new(&procedural::plane_grid(4, 3, 2.0, 1.0).expect("grid"));
    assert!(r.is_valid(), "{r}");
    assert_eq!((r.genus, r.boundary_loops, r.components), (Some(0), 1, 1));
    assert!((r.surface_area - 2.0).abs() < 1e-12);
    assert!((r.max_angle_degrees - 90.0).abs() < 1e-9);
}

fn tri(p: [[f64; 3]; 3]) -> TriMesh {
    TriMesh::new(p.to_vec(), vec![[0, 1, 2]]).expect("triangle")
}

#[test]
fn angles_and_degeneracy_thresholds() {
    let s = 3f64.sqrt() / 2.0;
    let r = MeshReport::new(&tri([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.5, s, 0.0]]));
    assert!(
        (r.min_angle_degrees - 60.0).abs() < 1e-12 && (r.max_angle_degrees - 60.0).abs() < 1e-12
    );
    // collinear corners are degenerate at any scale (relative criterion)
    for scale in [1e-200, 1e-8, 1.0, 1e8, 1e200] {
        let r = MeshReport::new(&tri([[0.0; 3], [scale, 0.0, 0.0], [2.0 * scale, 0.0, 0.0]]));
        assert!(
            matches!(
                r.problems[..],
                [MeshProblem::DegenerateFaces { count: 1, .. }]
            ),
            "{scale}"
        );
        // a thin but honest sliver (angles ~1e-8 rad) is not degenerate
        let r = MeshReport::new(&tri([
            [0.0; 3],
            [scale, 0.0, 0.0],
            [0.5 * scale, 1e-8 * scale, 0.0],
        ]));
        // (at 1e-200 and 1e200 its squared edge lengths leave f64's range:
        // sound in shape, unusable by the operators, and said so)
        if (1e-100..1e100).contains(&scale) {
            assert!(r.is_valid(), "{scale}: {r}");
        } else {
            assert!(
                matches!(r.problems[..], [MeshProblem::OutOfRange { count: 1, .. }]),
                "{scale}: {r}"
            );
        }
        assert!(r.min_angle_degrees > 1e-7 && r.min_angle_degrees < 2e-6);
    }
    // a well-shaped face 1e-8 the size of the mesh has area 1e-16 of it: degenerate
    // (absolute criterion), while on its own it is fine
    let small = [[0.0, 0.0, 0.0], [1e-8, 0.0, 0.0], [0.0, 1e-8, 0.0]];
    assert!(MeshReport::new(&tri(small)).is_valid());
    let mesh = TriMesh::new(
        vec![
            small[0],
            small[1],
            small[2],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
        ],
        vec![[0, 1, 2], [0, 3, 4]],
    )
    .expect("mesh");
    let r = MeshReport::new(&mesh);
    assert!(
        r.problems.contains(&MeshProblem::DegenerateFaces {
            count: 1,
            first: vec![0]
        }),
        "{r}"
    );
    // the thresholds as documented
    let d2 = 1.0;
    let area = |h: f64| [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.5, 2.0 * h, 0.0]];
    assert!(validate::is_degenerate(
        &area(validate::DEGENERATE_RELATIVE_TOLERANCE * 0.99),
        d2
    ));
    assert!(!validate::is_degenerate(
        &area(validate::DEGENERATE_RELATIVE_TOLERANCE * 1.01),
        d2
    ));
}

/// Problems found by plain, slow code: the oracle for the soups below.
fn brute_force(mesh: &TriMesh) -> (Vec<MeshProblem>, usize, i64, usize) {
    let faces = mesh.faces();
    let mut edge_faces: BTreeMap<[u32; 2], Vec<usize>> = BTreeMap::new();
    for (i, f) in faces.iter().enumerate() {
        for k in 0..3 {
            let (a, b) = (f[k], f[(k + 1) % 3]);
            edge_faces.entry([a.min(b), a.max(b)]).or_default().push(i);
        }
    }
    let traverses = |f: [u32; 3], a: u32, b: u32| (0..3).any(|k| f[k] == a && f[(k + 1) % 3] == b);
    let used: BTreeSet<u32> = faces.iter().flatten().copied().collect();
    let mut problems = Vec::new();
    let unref: Vec<usize> = (0..mesh.num_vertices())
        .filter(|v| !used.contains(&(*v as u32)))
        .collect();
    if !unref.is_empty() {
        problems.push(MeshProblem::UnreferencedVertices {
            count: unref.len(),
            first: unref.iter().take(5).copied().collect(),
        });
    }
    let nm: Vec<[u32; 2]> = edge_faces
        .iter()
        .filter(|(_, f)| f.len() > 2)
        .map(|(e, _)| *e)
        .collect();
    if !nm.is_empty() {
        problems.push(MeshProblem::NonManifoldEdges {
            count: nm.len(),
            first: nm.iter().take(5).copied().collect(),
        });
    }
    // a vertex is manifold when its faces are connected through its edges
    // that have exactly two faces, and none of its edges has more than two
    let mut nmv = Vec::new();
    for v in used.iter().copied() {
        let around: Vec<usize> = (0..faces.len())
            .filter(|&i| faces[i].contains(&v))
            .collect();
        let mut reached = vec![around[0]];
        let mut changed = true;
        while changed {
            changed = false;
            for (e, fs) in &edge_faces {
                if e.contains(&v) && fs.len() == 2 {
                    let (a, b) = (fs[0], fs[1]);
                    if reached.contains(&a) != reached.contains(&b) {
                        reached.push(if reached.contains(&a) { b } else { a });
                        changed = true;
                    }
                }
            }
        }
        let fin = edge_faces
            .iter()
            .any(|(e, fs)| e.contains(&v) && fs.len() > 2);
        if fin || reached.len() < around.len() {
            nmv.push(v as usize);
        }
    }
    if !nmv.is_empty() {
        problems.push(MeshProblem::NonManifoldVertices {
            count: nmv.len(),
            first: nmv.iter().take(5).copied().collect(),
        });
    }
    let flipped: Vec<[u32; 2]> = edge_faces
        .iter()
        .filter(|(e, fs)| {
            fs.len() == 2
                && traverses(faces[fs[0]], e[0], e[1]) == traverses(faces[fs[1]], e[0], e[1])
        })
        .map(|(e, _)| *e)
        .collect();
    if !flipped.is_empty() {
        problems.push(MeshProblem::InconsistentOrientation {
            count: flipped.len(),
            first: flipped.iter().take(5).copied().collect(),
        });
    }
    let same = |a: [u32; 3], b: [u32; 3]| {
        let (mut a, mut b) = (a, b);
        a.sort_unstable();
        b.sort_unstable();
        a == b
    };
    let dups: Vec<[usize; 2]> = (0..faces.len())
        .filter_map(|i| (0..i).find(|&j| same(faces[i], faces[j])).map(|j| [i, j]))
        .collect();
    if !dups.is_empty() {
        problems.push(MeshProblem::DuplicateFaces {
            count: dups.len(),
            first: dups.iter().take(5).copied().collect(),
        });
    }
    // components of referenced vertices, by repeated relaxation
    let mut label: Vec<usize> = (0..mesh.num_vertices()).collect();
    loop {
        let mut changed = false;
        for f in faces {
            let m = f.iter().map(|&v| label[v as usize]).min().unwrap_or(0);
            for &v in f {
                if label[v as usize] != m {
                    label[v as usize] = m;
                    changed = true;
                }
            }
        }
        if !changed {
            break;
        }
    }
    let components = used
        .iter()
        .map(|&v| label[v as usize])
        .collect::<BTreeSet<_>>()
        .len();
    let euler = used.len() as i64 - edge_faces.len() as i64 + faces.len() as i64;
    (problems, edge_faces.len(), euler, components)
}

/// Small soups with shared vertices: many duplicate, flipped and fin faces.
fn soup() -> impl Strategy<Value = TriMesh> {
    (3u32..9).prop_flat_map(|v| {
        (
            prop::collection::vec([coordinate(), coordinate(), coordinate()], v as usize),
            prop::collection::vec(triangle(v), 1..14),
        )
            .prop_map(|(p, f)| TriMesh::new(p, f).expect("valid"))
    })
}

/// Soups with moderate coordinates, often small integers (so that exactly
/// collinear and coincident corners occur).
fn tame_soup() -> impl Strategy<Value = TriMesh> {
    let c = prop_oneof![-1e3..1e3f64, (-2i32..3).prop_map(f64::from)];
    (3u32..9).prop_flat_map(move |v| {
        (
            prop::collection::vec([c.clone(), c.clone(), c.clone()], v as usize),
            prop::collection::vec(triangle(v), 1..14),
        )
            .prop_map(|(p, f)| TriMesh::new(p, f).expect("valid"))
    })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    #[test]
    fn combinatorial_checks_match_brute_force(mesh in soup()) {
        let r = MeshReport::new(&mesh);
        let (want, edges, euler, components) = brute_force(&mesh);
        let got: Vec<MeshProblem> = r
            .problems
            .iter()
            .filter(|p| {
                !matches!(
                    p,
                    MeshProblem::DegenerateFaces { .. } | MeshProblem::OutOfRange { .. }
                )
            })
            .cloned()
            .collect();
        prop_assert_eq!(got, want);
        prop_assert_eq!(r.num_edges, edges);
        prop_assert_eq!(r.euler_characteristic, euler);
        prop_assert_eq!(r.components, components);
        prop_assert_eq!(r.is_valid(), r.problems.is_empty());
        prop_assert_eq!(validate::validate(&mesh).is_ok(), r.is_valid());
    }

    /// Scaling by a power of two changes no problem (but whether faces are
    /// within f64's range for the operators) and no count, even far beyond
    /// the range where squared lengths underflow or overflow.
    #[test]
    fn report_is_scale_invariant(mesh in tame_soup(), e in -600i32..600) {
        let scaled = mesh.transformed(2f64.powi(e), [0.0; 3]);
        let a = MeshReport::new(&mesh);
        let b = MeshReport::new(&scaled);
        // every problem but the range of f64 (the one that depends on scale)
        let shape = |r: &MeshReport| -> Vec<MeshProblem> {
            r.problems
                .iter()
                .filter(|p| !matches!(p, MeshProblem::OutOfRange { .. }))
                .cloned()
                .collect()
        };
        prop_assert_eq!(shape(&a), shape(&b));
        prop_assert_eq!((a.num_edges, a.components, a.genus), (b.num_edges, b.components, b.genus));
        prop_assert!((a.min_angle_degrees - b.min_angle_degrees).abs() < 1e-9);
        prop_assert!((a.max_angle_degrees - b.max_angle_degrees).abs() < 1e-9);
    }

    /// Flipping a subset of the faces of a closed sphere flags exactly the
    /// edges between a flipped and an unflipped face.
    #[test]
    fn flipped_faces_are_found(flip in prop::collection::vec(any::<bool>(), 80)) {
        let sphere = procedural::icosphere(1);
        let faces: Vec<[u32; 3]> = sphere
            .faces()
            .iter()
            .zip(&flip)
            .map(|(f, &x)| if x { [f[0], f[2], f[1]] } else { *f })
            .collect();
        let mesh = TriMesh::new(sphere.positions().to_vec(), faces).expect("valid");
        let topo = mfm_geometry::Topology::new(mesh.num_vertices(), mesh.faces());
        let between = (0..topo.edges().len())
            .filter(|&e| {
                let f = topo.edge_faces(e);
                flip[f[0] as usize] != flip[f[1] as usize]
            })
            .count();
        let r = MeshReport::new(&mesh);
        let found = r.problems.iter().find_map(|p| match p {
            MeshProblem::InconsistentOrientation { count, .. } => Some(*count),
            _ => None,
        });
        prop_assert_eq!(found.unwrap_or(0), between);
        prop_assert_eq!(r.genus.is_some(), between == 0);
    }

    #[test]
    fn repairs_remove_exactly_their_problem(mesh in soup()) {
        let before = MeshReport::new(&mesh);
        let used: BTreeSet<u32> = mesh.faces().iter().flatten().copied().collect();
        let (clean, map) = repair::drop_unreferenced_vertices(&mesh);
        prop_assert_eq!(clean.num_vertices(), used.len());
        prop_assert_eq!(map.len(), mesh.num_vertices());
        for (v, &new) in map.iter().enumerate() {
            if used.contains(&(v as u32)) {
                prop_assert_eq!(clean.positions()[new as usize], mesh.positions()[v]);
            } else {
                prop_assert_eq!(new, u32::MAX);
            }
        }
        // the map is increasing on kept vertices (order is preserved)
        let kept: Vec<u32> = map.iter().copied().filter(|&m| m != u32::MAX).collect();
        prop_assert!(kept.windows(2).all(|w| w[0] + 1 == w[1]));
        for (f, g) in mesh.faces().iter().zip(clean.faces()) {
            prop_assert_eq!(f.map(|v| map[v as usize]), *g);
        }
        let after = MeshReport::new(&clean);
        let unreferenced_left = after.problems.iter().any(|p| matches!(p, MeshProblem::UnreferencedVertices { .. }));
        prop_assert!(!unreferenced_left);

        let (dedup, removed) = repair::drop_duplicate_faces(&mesh);
        let want = before.problems.iter().find_map(|p| match p {
            MeshProblem::DuplicateFaces { count, .. } => Some(*count),
            _ => None,
        });
        prop_assert_eq!(removed, want.unwrap_or(0));
        prop_assert_eq!(dedup.num_faces() + removed, mesh.num_faces());
        prop_assert_eq!(dedup.positions(), mesh.positions());
        let after = MeshReport::new(&dedup);
        let duplicates_left = after.problems.iter().any(|p| matches!(p, MeshProblem::DuplicateFaces { .. }));
        prop_assert!(!duplicates_left);
        // kept faces are the first occurrences, in order
        let mut seen = BTreeSet::new();
        let expect: Vec<[u32; 3]> = mesh
            .faces()
            .iter()
            .filter(|f| {
                let mut k = **f;
                k.sort_unstable();
                seen.insert(k)
            })
            .copied()
            .collect();
        prop_assert_eq!(dedup.faces(), &expect[..]);
    }
}

#[test]
fn shared_meshes_have_the_documented_topology() {
    let check = |name: &str, f: &dyn Fn(&MeshReport)| {
        if let Some(path) = test_support::shared_mesh(name) {
            let r = MeshReport::new(&mfm_meshio::read_mesh(&path).expect("reads"));
            f(&r);
        }
    };
    check("bunny.off", &|r| {
        assert_eq!((r.num_vertices, r.num_faces), (3485, 6966));
        assert_eq!((r.genus, r.components, r.boundary_loops), (Some(0), 1, 0));
        assert_eq!(r.euler_characteristic, 2);
        assert!(r.is_valid(), "{r}");
    });
    check("camel_b.obj", &|r| {
        assert!(r.boundary_loops >= 1, "camel_b is open");
        assert_eq!((r.components, r.genus), (1, Some(0)));
        assert!(r.is_valid(), "{r}");
    });
    check("3holes.off", &|r| {
        assert_eq!(
            (r.genus, r.boundary_loops, r.euler_characteristic),
            (Some(3), 0, -4)
        );
        assert!(r.is_valid(), "{r}");
    });
    check("fertility.off", &|r| {
        assert_eq!(
            (r.genus, r.boundary_loops, r.euler_characteristic),
            (Some(4), 0, -6)
        );
        assert!(r.is_valid(), "{r}");
    });
}

#[test]
fn measurements_agree_with_libigl() {
    let Some(python) = test_support::python_oracle() else {
        return;
    };
    let names = [
        "bunny.off",
        "camel_b.obj",
        "3holes.off",
        "fertility.off",
        "lion.off",
        "elephant.obj",
    ];
    let mut paths = Vec::new();
    for n in names {
        match test_support::shared_mesh(n) {
            Some(p) => paths.push(p),
            None => return,
        }
    }
    let script = r#"
import sys, igl, numpy as np
for p in sys.argv[1:]:
    v, f = igl.read_triangle_mesh(p)
    a = np.degrees(igl.internal_angles(v, f))
    comps = igl.vertex_components(f).max() + 1
    print(len(v), len(f), len(igl.edges(f)), comps, len(igl.boundary_loop_all(f)),
          repr(igl.doublearea(v, f).sum() / 2), repr(a.min()), repr(a.max()),
          int(igl.is_edge_manifold(f)[0]), int(igl.is_vertex_manifold(f).all()),
          *[repr(x) for x in v.min(axis=0)], *[repr(x) for x in v.max(axis=0)])
"#;
    let out = std::process::Command::new(&python)
        .arg("-c")
        .arg(script)
        .args(&paths)
        .output()
        .expect("python runs");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8(out.stdout).expect("utf-8");
    for (path, line) in paths.iter().zip(text.lines()) {
        let w: Vec<f64> = line
            .split_whitespace()
            .map(|t| {
                t.trim_start_matches("np.float64(")
                    .trim_end_matches(')')
                    .parse()
                    .expect("number")
            })
            .collect();
        let r = MeshReport::new(&mfm_meshio::read_mesh(path).expect("reads"));
        let name = path.display();
        assert_eq!(
            [
                r.num_vertices,
                r.num_faces,
                r.num_edges,
                r.components,
                r.boundary_loops
            ],
            [w[0], w[1], w[2], w[3], w[4]].map(|x| x as usize),
            "{name}"
        );
        assert!(
            (r.surface_area - w[5]).abs() <= 1e-12 * w[5],
            "{name}: area {} vs {}",
            r.surface_area,
            w[5]
        );
        assert!(
            (r.min_angle_degrees - w[6]).abs() < 1e-9,
            "{name}: min angle {} vs {}",
            r.min_angle_degrees,
            w[6]
        );
        assert!(
            (r.max_angle_degrees - w[7]).abs() < 1e-9,
            "{name}: max angle {} vs {}",
            r.max_angle_degrees,
            w[7]
        );
        let edge_manifold = !r
            .problems
            .iter()
            .any(|p| matches!(p, MeshProblem::NonManifoldEdges { .. }));
        let vertex_manifold = !r
            .problems
            .iter()
            .any(|p| matches!(p, MeshProblem::NonManifoldVertices { .. }));
        assert_eq!(
            (edge_manifold, vertex_manifold),
            (w[8] == 1.0, w[9] == 1.0),
            "{name}"
        );
        assert_eq!(r.bounding_box_min, [w[10], w[11], w[12]], "{name}");
        assert_eq!(r.bounding_box_max, [w[13], w[14], w[15]], "{name}");
    }
    assert_eq!(text.lines().count(), paths.len());
}
