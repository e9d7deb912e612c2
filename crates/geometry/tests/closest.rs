//! Closest points on a mesh (`mfm_geometry::closest`): the hierarchy's answer
//! against brute force over every face on random meshes, points of the
//! surface (vertices, vertices of midpoint subdivisions) located at distance
//! zero with weights that reproduce them, the Voronoi regions of one
//! triangle, degenerate faces, far and non-finite queries, and answers that
//! do not depend on the thread count.
//!
//! The timing on a 20k-face mesh is an ignored test:
//! `cargo test -p mfm-geometry --test closest -- --ignored --nocapture`.

use std::time::Instant;

use mfm_geometry::closest::{
    SurfaceLocator, SurfacePoint, closest_point_on_triangle, closest_points,
};
use mfm_geometry::mesh::{dot, sub};
use mfm_geometry::{MeshError, TriMesh, procedural, subdivide};
use proptest::prelude::*;

/// The closest point by checking every face in order (the first of equally
/// close faces wins).
fn brute_force(mesh: &TriMesh, point: [f64; 3]) -> SurfacePoint {
    let mut best = SurfacePoint {
        face: usize::MAX,
        weights: [f64::NAN; 3],
        squared_distance: f64::INFINITY,
    };
    for face in 0..mesh.num_faces() {
        let candidate = closest_point_on_triangle(point, &mesh.face_positions(face));
        if candidate.squared_distance < best.squared_distance {
            best = SurfacePoint {
                face,
                weights: candidate.weights,
                squared_distance: candidate.squared_distance,
            };
        }
    }
    best
}

fn squared_distance(a: [f64; 3], b: [f64; 3]) -> f64 {
    let d = sub(a, b);
    dot(d, d)
}

fn squared_diagonal(mesh: &TriMesh) -> f64 {
    mesh.bounding_box_diagonal().powi(2)
}

/// Weights are non-negative and sum to 1, and the point they give is at the
/// reported squared distance from the query.
fn assert_consistent(mesh: &TriMesh, query: [f64; 3], located: &SurfacePoint) {
    assert!(located.face < mesh.num_faces(), "{located:?}");
    assert!(
        located.weights.iter().all(|&w| w >= 0.0),
        "negative weight: {located:?}"
    );
    let sum: f64 = located.weights.iter().sum();
    assert!(
        (sum - 1.0).abs() <= 1e-12,
        "weights sum to {sum}: {located:?}"
    );
    let measured = squared_distance(located.position(mesh), query);
    let scale = located.squared_distance + 1e-12 * squared_diagonal(mesh);
    assert!(
        (measured - located.squared_distance).abs() <= 1e-12 * scale,
        "position at {measured}, reported {}",
        located.squared_distance
    );
}

/// A small deterministic generator (splitmix64) for the tests that are not
/// property tests.
struct Random(u64);

impl Random {
    fn next_unit(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^= z >> 31;
        (z >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Uniform in `[-1, 1)³`.
    fn next_offset(&mut self) -> [f64; 3] {
        [
            2.0 * self.next_unit() - 1.0,
            2.0 * self.next_unit() - 1.0,
            2.0 * self.next_unit() - 1.0,
        ]
    }
}

fn mean_edge_length(mesh: &TriMesh) -> f64 {
    let mut total = 0.0;
    for face in 0..mesh.num_faces() {
        let [a, b, c] = mesh.face_positions(face);
        total += squared_distance(a, b).sqrt()
            + squared_distance(b, c).sqrt()
            + squared_distance(c, a).sqrt();
    }
    total / (3 * mesh.num_faces()) as f64
}

/// `mesh` with every vertex moved by `amplitude` mean edge lengths times an
/// offset in `[-1, 1]³` (taken from `offsets` in turn).
fn perturbed(mesh: &TriMesh, offsets: &[[f64; 3]], amplitude: f64) -> TriMesh {
    let step = amplitude * mean_edge_length(mesh);
    let positions = mesh
        .positions()
        .iter()
        .zip(offsets.iter().cycle())
        .map(|(p, o)| [p[0] + step * o[0], p[1] + step * o[1], p[2] + step * o[2]])
        .collect();
    mesh.with_positions(positions)
        .expect("a perturbed mesh is valid")
}

fn randomly_perturbed(mesh: &TriMesh, amplitude: f64, seed: u64) -> TriMesh {
    let mut random = Random(seed);
    let offsets: Vec<[f64; 3]> = (0..mesh.num_vertices())
        .map(|_| random.next_offset())
        .collect();
    perturbed(mesh, &offsets, amplitude)
}

fn grid(nx: u32, ny: u32) -> TriMesh {
    procedural::plane_grid(nx, ny, 2.0, 1.5).expect("valid grid")
}

/// Meshes of several kinds: closed, open, non-convex, genus 1, perturbed.
fn test_meshes() -> Vec<(&'static str, TriMesh)> {
    vec![
        ("icosphere(2)", procedural::icosphere(2)),
        (
            "perturbed icosphere(2)",
            randomly_perturbed(&procedural::icosphere(2), 0.2, 1),
        ),
        ("perturbed grid", randomly_perturbed(&grid(7, 5), 0.2, 2)),
        ("blob(1)", procedural::blob(1).expect("valid blob")),
        (
            "torus",
            procedural::torus(1.0, 0.3, 12, 8).expect("valid torus"),
        ),
    ]
}

fn random_mesh() -> impl Strategy<Value = TriMesh> {
    (
        0u32..4,
        1u32..7,
        1u32..7,
        0.0f64..0.4,
        prop::collection::vec(prop::array::uniform3(-1.0f64..1.0), 64),
        prop::collection::vec((any::<usize>(), any::<usize>()), 0..3),
    )
        .prop_map(|(kind, nx, ny, amplitude, offsets, collapses)| {
            let base = match kind {
                0 => procedural::icosphere(0),
                1 => procedural::icosphere(1),
                2 => procedural::icosphere(2),
                _ => grid(nx, ny),
            };
            let mesh = perturbed(&base, &offsets, amplitude);
            // Moving a vertex onto another makes faces of zero area.
            let mut positions = mesh.positions().to_vec();
            let n = positions.len();
            for (target, source) in collapses {
                positions[target % n] = positions[source % n];
            }
            mesh.with_positions(positions)
                .expect("collapsing vertices keeps the mesh valid")
        })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    /// The hierarchy finds exactly what brute force finds, for points inside
    /// and around the bounding box and for points of the faces.
    #[test]
    fn bvh_matches_brute_force(
        mesh in random_mesh(),
        around in prop::collection::vec(prop::array::uniform3(-1.0f64..1.0), 1..40),
        on_faces in prop::collection::vec((any::<usize>(), 0.0f64..1.0, 0.0f64..1.0), 0..10),
    ) {
        let locator = SurfaceLocator::new(&mesh);
        prop_assert_eq!(locator.num_faces(), mesh.num_faces());
        let (lower, upper) = mesh.bounding_box();
        let margin = 0.25 * mesh.bounding_box_diagonal();
        let mut queries: Vec<[f64; 3]> = around
            .iter()
            .map(|u| {
                std::array::from_fn(|k| {
                    let centre = 0.5 * (lower[k] + upper[k]);
                    let half = 0.5 * (upper[k] - lower[k]) + margin;
                    centre + u[k] * half
                })
            })
            .collect();
        let first_on_face = queries.len();
        for &(face, s, t) in &on_faces {
            let (s, t) = if s + t > 1.0 { (1.0 - s, 1.0 - t) } else { (s, t) };
            let [a, b, c] = mesh.face_positions(face % mesh.num_faces());
            queries.push(std::array::from_fn(|k| {
                (1.0 - s - t) * a[k] + s * b[k] + t * c[k]
            }));
        }
        let diagonal_squared = squared_diagonal(&mesh);
        for (i, &query) in queries.iter().enumerate() {
            let located = locator.closest(query);
            let expected = brute_force(&mesh, query);
            prop_assert_eq!(located, expected, "query {:?}", query);
            assert_consistent(&mesh, query, &located);
            if i >= first_on_face {
                prop_assert!(located.squared_distance <= 1e-24 * diagonal_squared,
                    "a point of a face at squared distance {}", located.squared_distance);
            }
        }
        prop_assert_eq!(locator.closest_all(&queries),
            queries.iter().map(|&q| locator.closest(q)).collect::<Vec<_>>());
    }
}

/// A vertex is its own closest point, found on the lowest-numbered face
/// around it (all of them are at distance exactly zero).
#[test]
fn every_vertex_locates_onto_itself() {
    for (name, mesh) in test_meshes() {
        let mut first_face_at = vec![usize::MAX; mesh.num_vertices()];
        for (face, corners) in mesh.faces().iter().enumerate().rev() {
            for &v in corners {
                first_face_at[v as usize] = face;
            }
        }
        let located = SurfaceLocator::new(&mesh).closest_all(mesh.positions());
        for (vertex, (point, position)) in located.iter().zip(mesh.positions()).enumerate() {
            assert_eq!(point.squared_distance, 0.0, "{name}: vertex {vertex}");
            assert_eq!(point.position(&mesh), *position, "{name}: vertex {vertex}");
            assert_eq!(point.face, first_face_at[vertex], "{name}: vertex {vertex}");
            let corner = point
                .vertices(&mesh)
                .iter()
                .position(|&v| v as usize == vertex)
                .expect("the face is around the vertex");
            assert_eq!(point.weights[corner], 1.0, "{name}: vertex {vertex}");
        }
    }
}

/// Two midpoint subdivisions put every new vertex on the coarse surface (on
/// edges and inside faces): each is located at distance zero, and a vertex
/// signal, or a deformed copy of the coarse mesh, interpolated at the located
/// points equals what the subdivision itself carries over.
#[test]
fn midpoint_subdivision_vertices_lie_on_the_coarse_surface() {
    for (name, coarse) in test_meshes() {
        let (middle, first_map) = subdivide::midpoint_with_map(&coarse).expect("subdivides");
        let (fine, second_map) = subdivide::midpoint_with_map(&middle).expect("subdivides");
        let prolong_twice = |values: &[f64]| -> Vec<f64> {
            let once = first_map.prolong(values).expect("one value per vertex");
            second_map.prolong(&once).expect("one value per vertex")
        };

        // A smooth deformation of the template, as a training shape would be.
        let deformed = coarse
            .with_positions(
                coarse
                    .positions()
                    .iter()
                    .map(|p| [p[0] + 0.3 * p[1] * p[1], 1.2 * p[1], p[2] - 0.5 * p[0]])
                    .collect(),
            )
            .expect("valid deformation");
        let deformed_fine: Vec<Vec<f64>> = (0..3)
            .map(|k| {
                let coordinate: Vec<f64> = deformed.positions().iter().map(|p| p[k]).collect();
                prolong_twice(&coordinate)
            })
            .collect();
        let signal: Vec<f64> = coarse
            .positions()
            .iter()
            .map(|p| (2.0 * p[0]).sin() + p[1] * p[2])
            .collect();
        let signal_fine = prolong_twice(&signal);

        let diagonal = coarse.bounding_box_diagonal();
        let located = SurfaceLocator::new(&coarse).closest_all(fine.positions());
        for (vertex, (point, position)) in located.iter().zip(fine.positions()).enumerate() {
            assert_consistent(&coarse, *position, point);
            assert!(
                point.squared_distance <= 1e-24 * diagonal * diagonal,
                "{name}: vertex {vertex} at squared distance {}",
                point.squared_distance
            );
            let reproduced = point.position(&coarse);
            assert!(
                squared_distance(reproduced, *position).sqrt() <= 1e-12 * diagonal,
                "{name}: vertex {vertex}: {reproduced:?} vs {position:?}"
            );
            let carried = point.position(&deformed);
            for (k, carried_k) in carried.iter().enumerate() {
                assert!(
                    (carried_k - deformed_fine[k][vertex]).abs() <= 1e-12 * diagonal,
                    "{name}: deformed vertex {vertex}"
                );
            }
            let value = point.interpolate(&coarse, &signal).expect("one per vertex");
            assert!(
                (value - signal_fine[vertex]).abs() <= 1e-12,
                "{name}: signal at vertex {vertex}: {value} vs {}",
                signal_fine[vertex]
            );
        }
    }
}

/// Each Voronoi region of a right triangle in `z = 0`, from above the plane.
#[test]
fn closest_point_on_triangle_in_each_region() {
    let triangle = [[0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [0.0, 2.0, 0.0]];
    let height = 0.5;
    // (query in the plane, expected weights, expected closest point)
    let cases = [
        ([-1.0, -1.0], [1.0, 0.0, 0.0], [0.0, 0.0]),  // corner a
        ([3.0, -0.5], [0.0, 1.0, 0.0], [2.0, 0.0]),   // corner b
        ([-0.5, 3.0], [0.0, 0.0, 1.0], [0.0, 2.0]),   // corner c
        ([0.5, -1.0], [0.75, 0.25, 0.0], [0.5, 0.0]), // edge ab
        ([2.0, 1.0], [0.0, 0.75, 0.25], [1.5, 0.5]),  // edge bc
        ([-1.0, 1.5], [0.25, 0.0, 0.75], [0.0, 1.5]), // edge ca
        ([0.5, 0.5], [0.5, 0.25, 0.25], [0.5, 0.5]),  // interior
    ];
    for (query, weights, closest) in cases {
        let point = [query[0], query[1], height];
        let found = closest_point_on_triangle(point, &triangle);
        for (found_weight, weight) in found.weights.iter().zip(weights) {
            assert!(
                (found_weight - weight).abs() < 1e-15,
                "{query:?}: {found:?}"
            );
        }
        let expected = squared_distance(point, [closest[0], closest[1], 0.0]);
        assert!(
            (found.squared_distance - expected).abs() < 1e-14,
            "{query:?}: {found:?}, expected {expected}"
        );
    }
}

/// Queries exactly at a corner, on an edge and inside a face of a mesh are
/// at distance zero, with the weights that give them.
#[test]
fn points_at_a_vertex_on_an_edge_and_in_a_face() {
    let mesh = grid(2, 2);
    let locator = SurfaceLocator::new(&mesh);
    let [a, b, c] = mesh.face_positions(3);

    let at_corner = locator.closest(b);
    assert_eq!(at_corner.squared_distance, 0.0);
    assert_eq!(at_corner.position(&mesh), b);

    let midpoint: [f64; 3] = std::array::from_fn(|k| 0.5 * (a[k] + b[k]));
    let on_edge = locator.closest(midpoint);
    assert_eq!(on_edge.squared_distance, 0.0);
    assert_eq!(on_edge.position(&mesh), midpoint);
    assert_eq!(on_edge.weights.iter().filter(|&&w| w == 0.5).count(), 2);

    let inside: [f64; 3] = std::array::from_fn(|k| 0.2 * a[k] + 0.3 * b[k] + 0.5 * c[k]);
    let in_face = locator.closest(inside);
    assert_eq!(in_face.face, 3);
    assert!(in_face.squared_distance < 1e-30);
    for (w, expected) in in_face.weights.iter().zip([0.2, 0.3, 0.5]) {
        assert!((w - expected).abs() < 1e-14, "{in_face:?}");
    }
}

/// Points far from the mesh still get the exact closest face.
#[test]
fn far_away_points() {
    let mesh = procedural::icosphere(2);
    let locator = SurfaceLocator::new(&mesh);
    let mut random = Random(7);
    for _ in 0..50 {
        let direction = random.next_offset();
        let query = direction.map(|c| 1e6 * c);
        let located = locator.closest(query);
        assert_eq!(located, brute_force(&mesh, query));
        assert_consistent(&mesh, query, &located);
        let distance_to_centre = dot(query, query).sqrt();
        let distance = located.squared_distance.sqrt();
        assert!(distance <= distance_to_centre - 0.9 && distance >= distance_to_centre - 1.0);
    }
}

/// Faces of zero area (collinear or coincident corners) are their edges:
/// finite, non-negative weights and the distance to the nearest edge.
#[test]
fn degenerate_faces() {
    let collinear = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [3.0, 0.0, 0.0]];
    let found = closest_point_on_triangle([2.0, 1.0, 0.0], &collinear);
    assert!((found.squared_distance - 1.0).abs() < 1e-15, "{found:?}");
    assert!(found.weights.iter().all(|&w| w >= 0.0));
    assert!((found.weights.iter().sum::<f64>() - 1.0).abs() < 1e-15);
    let position: [f64; 3] =
        std::array::from_fn(|k| (0..3).map(|i| found.weights[i] * collinear[i][k]).sum());
    assert!(squared_distance(position, [2.0, 0.0, 0.0]) < 1e-30);

    let two_coincident = [[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [1.0, 1.0, 0.0]];
    let found = closest_point_on_triangle([1.0, 0.0, 0.0], &two_coincident);
    assert!((found.squared_distance - 0.5).abs() < 1e-15, "{found:?}");
    assert!((found.weights[2] - 0.5).abs() < 1e-15, "{found:?}");

    let one_point = [[1.0, 2.0, 3.0]; 3];
    let found = closest_point_on_triangle([1.0, 2.0, 5.0], &one_point);
    assert_eq!(found.squared_distance, 4.0);
    assert!(found.weights.iter().all(|&w| w >= 0.0));
    assert!((found.weights.iter().sum::<f64>() - 1.0).abs() < 1e-15);

    // A sliver far thinner than the threshold is treated as its edges too.
    let sliver = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.5, 1e-15, 0.0]];
    let found = closest_point_on_triangle([0.5, 0.0, 1.0], &sliver);
    assert!((found.squared_distance - 1.0).abs() < 1e-14, "{found:?}");

    // A grid with one vertex moved onto its neighbour: its faces that now
    // have two coincident corners still answer every query.
    let mesh = grid(3, 3);
    let mut positions = mesh.positions().to_vec();
    positions[5] = positions[6];
    let collapsed = mesh.with_positions(positions).expect("valid mesh");
    let locator = SurfaceLocator::new(&collapsed);
    let mut random = Random(3);
    for _ in 0..200 {
        let query = random.next_offset();
        let located = locator.closest(query);
        assert_eq!(located, brute_force(&collapsed, query));
        assert_consistent(&collapsed, query, &located);
    }
    for vertex in collapsed.positions() {
        assert_eq!(locator.closest(*vertex).squared_distance, 0.0);
    }
}

/// A query with a NaN or infinite coordinate has no closest point, and
/// neither has any query on a mesh with non-finite coordinates.
#[test]
fn non_finite_queries() {
    let locator = SurfaceLocator::new(&procedural::icosphere(1));
    for query in [
        [f64::NAN, 0.0, 0.0],
        [0.0, f64::INFINITY, 0.0],
        [0.0, 0.0, f64::NEG_INFINITY],
    ] {
        let located = locator.closest(query);
        assert_eq!(located.face, 0);
        assert_eq!(located.weights, [1.0, 0.0, 0.0]);
        assert!(located.squared_distance.is_nan());
    }
    // Only `transformed` can give a mesh non-finite coordinates; its queries
    // do not panic and say that there is no closest point.
    let mesh = procedural::icosphere(1);
    for broken in [
        mesh.transformed(f64::NAN, [0.0; 3]),
        mesh.transformed(1.0, [f64::INFINITY, 0.0, 0.0]),
    ] {
        let located = SurfaceLocator::new(&broken).closest([0.5, 0.0, 0.0]);
        assert_eq!(located.face, 0);
        assert!(located.squared_distance.is_nan(), "{located:?}");
    }
}

/// Interpolation checks that there is one value per vertex.
#[test]
fn interpolate_needs_one_value_per_vertex() {
    let mesh = procedural::icosphere(1);
    let point = SurfaceLocator::new(&mesh).closest([0.0, 0.0, 2.0]);
    assert_eq!(
        point.interpolate(&mesh, &[1.0; 3]),
        Err(MeshError::VertexCountMismatch {
            expected: mesh.num_vertices(),
            found: 3
        })
    );
    let ones = vec![1.0; mesh.num_vertices()];
    let one = point.interpolate(&mesh, &ones).expect("one per vertex");
    assert!((one - 1.0).abs() < 1e-15);
}

/// The batch answers are the same with one thread or several, and the same
/// as one query at a time and as `closest_points`.
#[test]
fn answers_do_not_depend_on_the_thread_count() {
    let mesh = randomly_perturbed(&procedural::icosphere(3), 0.2, 11);
    let mut random = Random(5);
    let queries: Vec<[f64; 3]> = (0..3000)
        .map(|_| random.next_offset().map(|c| 1.5 * c))
        .collect();
    let locator = SurfaceLocator::new(&mesh);
    let with_threads = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .expect("thread pool")
            .install(|| locator.closest_all(&queries))
    };
    let one_thread = with_threads(1);
    assert_eq!(one_thread, with_threads(4));
    assert_eq!(
        one_thread,
        queries
            .iter()
            .map(|&q| locator.closest(q))
            .collect::<Vec<_>>()
    );
    assert_eq!(one_thread, closest_points(&mesh, &queries));
}

/// Build a hierarchy on a ~20k-face mesh and locate ~80k points near it.
/// Prints the times; not a pass/fail timing.
#[test]
#[ignore = "timing: run with --ignored --nocapture"]
fn timing_20k_faces_80k_points() {
    let template = randomly_perturbed(&procedural::icosphere(5), 0.1, 13);
    let refined = subdivide::midpoint(&template).expect("subdivides");
    let mut random = Random(17);
    let queries: Vec<[f64; 3]> = (0..refined.num_faces())
        .map(|face| {
            let [a, b, c] = refined.face_positions(face);
            let noise = random.next_offset();
            std::array::from_fn(|k| (a[k] + b[k] + c[k]) / 3.0 + 0.01 * noise[k])
        })
        .collect();

    let start = Instant::now();
    let locator = SurfaceLocator::new(&template);
    let build = start.elapsed();
    let start = Instant::now();
    let located = locator.closest_all(&queries);
    let parallel = start.elapsed();
    let start = Instant::now();
    let sequential: Vec<SurfacePoint> = queries.iter().map(|&q| locator.closest(q)).collect();
    let one_thread = start.elapsed();
    assert_eq!(located, sequential);
    println!(
        "{} faces, {} points: build {:.1} ms, closest_all {:.1} ms ({} threads), one at a time {:.1} ms",
        template.num_faces(),
        queries.len(),
        build.as_secs_f64() * 1e3,
        parallel.as_secs_f64() * 1e3,
        rayon::current_num_threads(),
        one_thread.as_secs_f64() * 1e3,
    );
    for &i in &[0, queries.len() / 2, queries.len() - 1] {
        assert_eq!(located[i], brute_force(&template, queries[i]));
    }
}
