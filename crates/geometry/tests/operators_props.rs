//! Properties of the intrinsic operators that hold on every mesh: the
//! identity `G^T diag(A2) G = L`, the gradient of linear functions, the
//! Laplacian's null space, symmetry and sparsity, scale behaviour, and
//! hand-computed values on small meshes.
//!
//! Nothing here needs Python; the shared meshes are read with `mfm_meshio`.

use std::collections::HashMap;

use faer::sparse::SparseColMat;
use mfm_geometry::operators::{self, Operators};
use mfm_geometry::test_support::shared_mesh;
use mfm_geometry::{Topology, TriMesh, mesh, procedural};
use proptest::prelude::*;

type Sparse = SparseColMat<usize, f64>;

const SHARED: [&str; 11] = [
    "3holes.off",
    "alien.obj",
    "bumpy.off",
    "bunny.off",
    "camel_b.obj",
    "cheburashka.off",
    "cow.off",
    "decimated-knight.off",
    "elephant.obj",
    "fertility.off",
    "lion.off",
];

fn shared_meshes() -> Vec<(&'static str, TriMesh)> {
    SHARED
        .iter()
        .filter_map(|name| {
            let path = shared_mesh(name)?;
            let mesh =
                mfm_meshio::read_mesh(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
            Some((*name, mesh))
        })
        .collect()
}

/// An `nx x ny` grid of unit cells in the xy plane, displaced by `jitter`
/// (3 numbers per vertex, scaled: xy by `0.15`, z by `1`), cells split along
/// alternating diagonals.
fn grid(nx: usize, ny: usize, jitter: &[f64]) -> TriMesh {
    let id = |i: usize, j: usize| (j * (nx + 1) + i) as u32;
    let mut positions = Vec::new();
    for j in 0..=ny {
        for i in 0..=nx {
            let k = 3 * (j * (nx + 1) + i);
            let d = |c: usize| jitter.get(k + c).copied().unwrap_or(0.0);
            positions.push([i as f64 + 0.15 * d(0), j as f64 + 0.15 * d(1), d(2)]);
        }
    }
    let mut faces = Vec::new();
    for j in 0..ny {
        for i in 0..nx {
            let (a, b, c, d) = (id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1));
            if (i + j) % 2 == 0 {
                faces.extend([[a, b, c], [a, c, d]]);
            } else {
                faces.extend([[a, b, d], [b, c, d]]);
            }
        }
    }
    TriMesh::new(positions, faces).expect("valid grid")
}

fn entries(m: &Sparse) -> impl Iterator<Item = (usize, usize, f64)> + '_ {
    let (cp, ri, v) = (m.symbolic().col_ptr(), m.symbolic().row_idx(), m.val());
    (0..m.ncols()).flat_map(move |j| (cp[j]..cp[j + 1]).map(move |k| (ri[k], j, v[k])))
}

fn max_abs(m: &Sparse) -> f64 {
    m.val().iter().fold(0.0f64, |a, x| a.max(x.abs()))
}

/// `max |G^T diag(A2) G - L| / max |L|`, with the product formed row by row
/// of `G` (independently of how `L` is assembled).
fn identity_error(ops: &Operators) -> f64 {
    let g = &ops.gradient;
    let mut rows: Vec<Vec<(usize, f64)>> = vec![Vec::new(); g.nrows()];
    for (r, v, x) in entries(g) {
        rows[r].push((v, x));
    }
    let mut product: HashMap<(usize, usize), f64> = HashMap::new();
    for (r, row) in rows.iter().enumerate() {
        let w = ops.face_areas_interleaved[r];
        for &(i, xi) in row {
            for &(j, xj) in row {
                *product.entry((i, j)).or_insert(0.0) += w * xi * xj;
            }
        }
    }
    let mut diff = 0.0f64;
    let mut seen = 0;
    for (i, j, x) in entries(&ops.laplacian) {
        let p = product.get(&(i, j)).copied().unwrap_or(0.0);
        seen += usize::from(product.contains_key(&(i, j)));
        diff = diff.max((p - x).abs());
    }
    // entries of the product outside the pattern of L
    assert_eq!(
        seen,
        product.len(),
        "G^T A2 G has entries outside the pattern of L"
    );
    diff / max_abs(&ops.laplacian)
}

/// Basic facts about `L` and `M` that any correct assembly satisfies.
fn check_laplacian_and_mass(name: &str, mesh: &TriMesh, ops: &Operators) {
    let l = &ops.laplacian;
    let n = mesh.num_vertices();
    let scale = max_abs(l);
    // L 1 = 0
    let mut row_sums = vec![0.0; n];
    for (i, _, x) in entries(l) {
        row_sums[i] += x;
    }
    let worst = row_sums.iter().fold(0.0f64, |a, x| a.max(x.abs()));
    assert!(worst < 1e-13 * scale, "{name}: |L 1| = {worst:e}");
    // exact symmetry
    let map: HashMap<(usize, usize), f64> = entries(l).map(|(i, j, x)| ((i, j), x)).collect();
    for (&(i, j), &x) in &map {
        assert_eq!(
            map.get(&(j, i)).copied(),
            Some(x),
            "{name}: L[{i},{j}] != L[{j},{i}]"
        );
    }
    // one entry per vertex and two per edge
    let topo = Topology::new(n, mesh.faces());
    let referenced = topo.referenced_vertices().iter().filter(|&&r| r).count();
    assert_eq!(
        l.val().len(),
        referenced + 2 * topo.edges().len(),
        "{name}: nnz(L)"
    );
    for e in topo.edges() {
        assert!(
            map.contains_key(&(e[0] as usize, e[1] as usize)),
            "{name}: edge {e:?} missing"
        );
    }
    // positive diagonal, mass sums to the area
    for v in 0..n {
        assert!(
            map.get(&(v, v)).copied().unwrap_or(1.0) > 0.0,
            "{name}: L[{v},{v}] <= 0"
        );
    }
    let area = mesh.total_area();
    let mass: f64 = ops.mass.iter().sum();
    assert!(
        (mass - area).abs() < 1e-12 * area,
        "{name}: mass {mass} vs area {area}"
    );
    let a: f64 = ops.face_areas.iter().sum();
    assert!(
        (a - area).abs() < 1e-12 * area,
        "{name}: face areas {a} vs area {area}"
    );
    assert_eq!(ops.face_areas_interleaved.len(), 2 * mesh.num_faces());
    for (f, &x) in ops.face_areas.iter().enumerate() {
        assert_eq!([x, x], ops.face_areas_interleaved[2 * f..2 * f + 2]);
    }
}

/// For `u(x) = a . x`, `G u` on each face is the projection of `a` onto the
/// face plane, written in the documented frame (`ex` along corner 0 -> 1,
/// `ey = n x ex`). Returns the largest error relative to `|a|`.
fn linear_function_error(mesh: &TriMesh, ops: &Operators, a: [f64; 3]) -> f64 {
    let u: Vec<f64> = mesh.positions().iter().map(|&p| mesh::dot(a, p)).collect();
    let mut gu = vec![0.0; ops.gradient.nrows()];
    for (r, v, x) in entries(&ops.gradient) {
        gu[r] += x * u[v];
    }
    let mut worst = 0.0f64;
    for f in 0..mesh.num_faces() {
        let p = mesh.face_positions(f);
        let n = mesh::triangle_normal(&p);
        let n = mesh::scale(n, 1.0 / mesh::norm(n));
        let tangential = mesh::sub(a, mesh::scale(n, mesh::dot(a, n)));
        let (gx, gy) = (gu[2 * f], gu[2 * f + 1]);
        let norm_err = ((gx * gx + gy * gy).sqrt() - mesh::norm(tangential)).abs();
        let e = mesh::sub(p[1], p[0]);
        let ex = mesh::scale(e, 1.0 / mesh::norm(e));
        let ey = mesh::cross(n, ex);
        let rebuilt = mesh::add(mesh::scale(ex, gx), mesh::scale(ey, gy));
        let vec_err = mesh::norm(mesh::sub(rebuilt, tangential));
        worst = worst.max(norm_err.max(vec_err));
    }
    worst / mesh::norm(a)
}

#[test]
fn shared_meshes_satisfy_the_identities() {
    for (name, mesh) in shared_meshes() {
        let ops = Operators::new(&mesh).unwrap_or_else(|e| panic!("{name}: {e}"));
        let id = identity_error(&ops);
        assert!(id < 1e-14, "{name}: |G^T A2 G - L| / |L| = {id:e}");
        check_laplacian_and_mass(name, &mesh, &ops);
        // gradients of linear functions, with the extent of the mesh as unit
        for a in [
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, 0.0, 1.0],
            [0.3, -1.2, 0.7],
        ] {
            let err = linear_function_error(&mesh, &ops, a);
            assert!(
                err < 1e-10,
                "{name}: gradient of a linear function off by {err:e} (relative)"
            );
        }
        // G annihilates constants (each row sums to zero up to one rounding)
        let mut g1 = vec![0.0; ops.gradient.nrows()];
        let mut row_max = vec![0.0f64; ops.gradient.nrows()];
        for (r, _, x) in entries(&ops.gradient) {
            g1[r] += x;
            row_max[r] = row_max[r].max(x.abs());
        }
        for (r, (s, m)) in g1.iter().zip(&row_max).enumerate() {
            assert!(
                s.abs() <= 2.0 * f64::EPSILON * m,
                "{name}: row {r} of G 1 is {s:e}"
            );
        }
    }
}

#[test]
fn flat_grid_gives_the_five_point_stencil() {
    // unit right triangles: axis edges get weight -1, diagonals 0, interior
    // diagonal entries 4; masses are a third of 1/2 per incident face
    let mesh = grid(4, 4, &[]);
    let ops = Operators::new(&mesh).expect("valid");
    let l: HashMap<(usize, usize), f64> = entries(&ops.laplacian)
        .map(|(i, j, x)| ((i, j), x))
        .collect();
    let v = 2 * 5 + 2; // the centre vertex (2, 2)
    assert!((l[&(v, v)] - 4.0).abs() < 1e-14);
    for w in [v - 1, v + 1, v - 5, v + 5] {
        assert!(
            (l[&(v, w)] + 1.0).abs() < 1e-14,
            "L[{v},{w}] = {}",
            l[&(v, w)]
        );
    }
    let diagonal_neighbours: Vec<usize> = [v - 6, v + 6, v - 4, v + 4]
        .into_iter()
        .filter(|w| l.contains_key(&(v, *w)))
        .collect();
    assert_eq!(
        diagonal_neighbours.len(),
        4,
        "the centre has valence 8 with alternating diagonals"
    );
    for w in diagonal_neighbours {
        assert!(l[&(v, w)].abs() < 1e-14);
    }
    assert!((ops.mass[v] - 8.0 / 6.0).abs() < 1e-14);
    let w = v + 1; // valence 4: no diagonal through (3, 2)
    assert!((ops.mass[w] - 4.0 / 6.0).abs() < 1e-14);
    assert!((l[&(w, w)] - 4.0).abs() < 1e-14);
    // a corner vertex with one face: weight -1/2 on both legs, 0 on the diagonal
    assert!((l[&(0, 1)] + 0.5).abs() < 1e-14 && (l[&(0, 0)] - 1.0).abs() < 1e-14);
}

#[test]
fn non_manifold_edge_sums_all_its_faces() {
    // three unit right triangles hinged on the edge 0-1 (a "book")
    let mesh = TriMesh::new(
        vec![
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, 0.0, 1.0],
            [0.0, -1.0, 0.0],
        ],
        vec![[0, 1, 2], [1, 0, 3], [0, 1, 4]],
    )
    .expect("valid");
    let ops = Operators::new(&mesh).expect("valid");
    // each face has 45 degrees opposite the hinge: -3 * cot(45)/2
    let l01 = ops.laplacian.get(0, 1).copied().expect("hinge entry");
    assert!((l01 + 1.5).abs() < 1e-14, "{l01}");
    assert!(identity_error(&ops) < 1e-14);
    check_laplacian_and_mass("book", &mesh, &ops);
}

#[test]
fn operators_do_not_depend_on_the_thread_count() {
    let mesh = procedural::torus(1.0, 0.3, 160, 80).expect("valid torus");
    let one = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .expect("pool");
    let three = rayon::ThreadPoolBuilder::new()
        .num_threads(3)
        .build()
        .expect("pool");
    let a = one.install(|| Operators::new(&mesh).expect("valid"));
    let b = three.install(|| Operators::new(&mesh).expect("valid"));
    assert_eq!(a.laplacian.val(), b.laplacian.val());
    assert_eq!(
        a.laplacian.symbolic().row_idx(),
        b.laplacian.symbolic().row_idx()
    );
    assert_eq!(a.gradient.val(), b.gradient.val());
    assert_eq!(a.mass, b.mass);
    let ga = one.install(|| operators::gamma(&a.laplacian, &a.mass));
    let gb = three.install(|| operators::gamma(&b.laplacian, &b.mass));
    assert_eq!(ga.to_bits(), gb.to_bits());
}

#[test]
fn gamma_is_the_frobenius_norm_of_inverse_mass_times_laplacian() {
    let mesh = grid(3, 2, &[0.1, -0.3, 0.2, 0.5, 0.0, -0.7, 0.9, 0.4, 0.1]);
    let ops = Operators::new(&mesh).expect("valid");
    let mut dense = vec![vec![0.0; mesh.num_vertices()]; mesh.num_vertices()];
    for (i, j, x) in entries(&ops.laplacian) {
        dense[i][j] = x / ops.mass[i];
    }
    let expected = dense.iter().flatten().map(|x| x * x).sum::<f64>().sqrt();
    let g = operators::gamma(&ops.laplacian, &ops.mass);
    assert!((g - expected).abs() < 1e-13 * expected, "{g} vs {expected}");
}

fn grid_strategy() -> impl Strategy<Value = TriMesh> {
    (1usize..6, 1usize..6).prop_flat_map(|(nx, ny)| {
        let n = 3 * (nx + 1) * (ny + 1);
        proptest::collection::vec(-1.0f64..1.0, n).prop_map(move |j| grid(nx, ny, &j))
    })
}

/// `G` rebuilt from [`Operators::face_gradients`] by scattering each face's
/// two rows into its corners' columns, as exact `(row, col) -> value`
/// entries (structural zeros left out).
fn scattered_face_gradients(mesh: &TriMesh, ops: &Operators) -> HashMap<(usize, usize), u64> {
    let mut out = HashMap::new();
    for (f, (t, rows)) in mesh.faces().iter().zip(&ops.face_gradients).enumerate() {
        for (r, row) in rows.iter().enumerate() {
            for (c, &x) in row.iter().enumerate() {
                if x != 0.0 {
                    out.insert((2 * f + r, t[c] as usize), x.to_bits());
                }
            }
        }
    }
    out
}

/// The face table and the sparse `G` agree bit for bit.
fn check_face_gradients(mesh: &TriMesh, ops: &Operators) {
    assert_eq!(ops.face_gradients.len(), mesh.num_faces());
    let sparse: HashMap<(usize, usize), u64> = entries(&ops.gradient)
        .filter(|&(_, _, x)| x != 0.0)
        .map(|(i, j, x)| ((i, j), x.to_bits()))
        .collect();
    assert_eq!(scattered_face_gradients(mesh, ops), sparse);
}

#[test]
fn face_gradients_are_the_entries_of_g() {
    // a grid, and the same grid with one face collapsed (lenient operators
    // give it zero rows in both forms)
    let mesh = grid(5, 4, &[0.3; 30]);
    check_face_gradients(&mesh, &Operators::new(&mesh).expect("valid grid"));
    let mut positions = mesh.positions().to_vec();
    let t = mesh.faces()[7];
    positions[t[2] as usize] = positions[t[0] as usize];
    let collapsed = mesh.with_positions(positions).expect("same vertex count");
    let lenient = Operators::new_lenient(&collapsed);
    assert!(!lenient.degenerate_faces.is_empty());
    assert_eq!(lenient.face_gradients[7], [[0.0; 3]; 2]);
    check_face_gradients(&collapsed, &lenient);
    for (name, mesh) in shared_meshes() {
        eprintln!("{name}");
        check_face_gradients(&mesh, &Operators::new_lenient(&mesh));
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    #[test]
    fn perturbed_grids_satisfy_the_gradient_identity(mesh in grid_strategy()) {
        let ops = Operators::new(&mesh).expect("perturbed grids have no degenerate face");
        let id = identity_error(&ops);
        prop_assert!(id < 1e-13, "|G^T A2 G - L| / |L| = {:e}", id);
        check_laplacian_and_mass("grid", &mesh, &ops);
        let err = linear_function_error(&mesh, &ops, [0.4, -0.8, 1.1]);
        prop_assert!(err < 1e-12, "gradient of a linear function off by {:e}", err);
        check_face_gradients(&mesh, &ops);
    }

    #[test]
    fn scaling_by_k(mesh in grid_strategy(), log_k in -3.0f64..3.0, shift in -10.0f64..10.0) {
        let k = 10f64.powf(log_k);
        let scaled = mesh.transformed(k, [shift, -shift, 0.5 * shift]);
        let a = Operators::new(&mesh).expect("valid");
        let b = Operators::new(&scaled).expect("valid");
        // L is scale invariant (same pattern, same values to round-off)
        prop_assert_eq!(a.laplacian.symbolic().row_idx(), b.laplacian.symbolic().row_idx());
        let scale = max_abs(&a.laplacian);
        for (x, y) in a.laplacian.val().iter().zip(b.laplacian.val()) {
            prop_assert!((x - y).abs() < 1e-11 * scale, "L changed: {} vs {}", x, y);
        }
        // M -> k^2 M, A -> k^2 A, G -> G / k
        for (x, y) in a.mass.iter().zip(&b.mass) {
            prop_assert!((k * k * x - y).abs() < 1e-11 * y.abs(), "M: {} vs {}", k * k * x, y);
        }
        for (x, y) in a.face_areas.iter().zip(&b.face_areas) {
            prop_assert!((k * k * x - y).abs() < 1e-11 * y.abs());
        }
        let gscale = a.gradient.val().iter().fold(0.0f64, |m, x| m.max(x.abs()));
        for (x, y) in a.gradient.val().iter().zip(b.gradient.val()) {
            prop_assert!((x / k - y).abs() < 1e-11 * gscale / k);
        }
        // Gamma -> Gamma / k^2
        let (ga, gb) = (operators::gamma(&a.laplacian, &a.mass), operators::gamma(&b.laplacian, &b.mass));
        prop_assert!((ga / (k * k) - gb).abs() < 1e-11 * gb, "Gamma: {} / k^2 vs {}", ga, gb);
    }
}
