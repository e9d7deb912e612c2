//! `L`, `M`, `A` and `G` against libigl (through the Python oracle env).
//!
//! The Python side (`xtask/python/igl_operators.py`) reads the original mesh
//! file with `igl.read_triangle_mesh` and dumps `V`, `F` and libigl's operators
//! as text with 17 significant digits; the mesh built here comes from that
//! dump, so this test does not depend on mfm's own mesh reader.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;

use mfm_geometry::operators::{self, Operators};
use mfm_geometry::test_support::{python_oracle, shared_mesh, workspace_root};
use mfm_geometry::{TriMesh, mesh};

/// Relative tolerance, against the largest magnitude of each operator.
const TOL: f64 = 1e-10;

struct Dump {
    mesh: TriMesh,
    laplacian: BTreeMap<(usize, usize), f64>,
    mass: Vec<f64>,
    areas: Vec<f64>,
    /// libigl's `grad`: `3F x V`, row `d * F + f` for coordinate `d`.
    gradient: BTreeMap<(usize, usize), f64>,
}

fn read_rows(path: &Path) -> Vec<Vec<f64>> {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    text.lines()
        .filter(|l| !l.trim().is_empty())
        .map(|l| {
            l.split_whitespace()
                .map(|x| {
                    x.parse::<f64>()
                        .unwrap_or_else(|e| panic!("{}: {x:?}: {e}", path.display()))
                })
                .collect()
        })
        .collect()
}

fn read_triplets(path: &Path) -> BTreeMap<(usize, usize), f64> {
    let mut map = BTreeMap::new();
    for r in read_rows(path) {
        *map.entry((r[0] as usize, r[1] as usize)).or_insert(0.0) += r[2];
    }
    map
}

fn dump(name: &str) -> Option<Dump> {
    let python = python_oracle()?;
    let path = shared_mesh(name)?;
    let dir = tempfile::tempdir().expect("temp dir");
    let script: PathBuf = workspace_root().join("xtask/python/igl_operators.py");
    let status = Command::new(python)
        .arg(&script)
        .arg(&path)
        .arg(dir.path())
        .status()
        .expect("run the Python oracle");
    assert!(
        status.success(),
        "{} failed on {}",
        script.display(),
        path.display()
    );
    let positions = read_rows(&dir.path().join("V.txt"))
        .into_iter()
        .map(|r| [r[0], r[1], r[2]])
        .collect();
    let faces = read_rows(&dir.path().join("F.txt"))
        .into_iter()
        .map(|r| [r[0] as u32, r[1] as u32, r[2] as u32])
        .collect();
    Some(Dump {
        mesh: TriMesh::new(positions, faces).expect("libigl's mesh is valid"),
        laplacian: read_triplets(&dir.path().join("L.txt")),
        mass: read_rows(&dir.path().join("M.txt"))
            .into_iter()
            .map(|r| r[0])
            .collect(),
        areas: read_rows(&dir.path().join("A.txt"))
            .into_iter()
            .map(|r| r[0])
            .collect(),
        gradient: read_triplets(&dir.path().join("G.txt")),
    })
}

fn to_map(m: &faer::sparse::SparseColMat<usize, f64>) -> BTreeMap<(usize, usize), f64> {
    let (cp, ri, v) = (m.symbolic().col_ptr(), m.symbolic().row_idx(), m.val());
    let mut map = BTreeMap::new();
    for j in 0..m.ncols() {
        for k in cp[j]..cp[j + 1] {
            map.insert((ri[k], j), v[k]);
        }
    }
    map
}

/// `max |a - b| / max |b|` over the union of the two sparsity patterns.
fn sparse_rel_diff(a: &BTreeMap<(usize, usize), f64>, b: &BTreeMap<(usize, usize), f64>) -> f64 {
    let scale = b.values().fold(0.0f64, |m, x| m.max(x.abs()));
    let mut diff = 0.0f64;
    for (k, x) in a {
        diff = diff.max((x - b.get(k).copied().unwrap_or(0.0)).abs());
    }
    for (k, y) in b {
        diff = diff.max((a.get(k).copied().unwrap_or(0.0) - y).abs());
    }
    diff / scale
}

fn dense_rel_diff(a: &[f64], b: &[f64]) -> f64 {
    assert_eq!(a.len(), b.len());
    let scale = b.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max)
        / scale
}

/// Our `2F x V` gradient mapped to 3D (`gx ex + gy ey` with the frame of the
/// module docs), laid out like libigl's `grad` (`3F x V`, row `d * F + f`).
fn gradient_in_3d(
    mesh: &TriMesh,
    g: &faer::sparse::SparseColMat<usize, f64>,
) -> BTreeMap<(usize, usize), f64> {
    let nf = mesh.num_faces();
    let frames: Vec<([f64; 3], [f64; 3])> = (0..nf)
        .map(|f| {
            let p = mesh.face_positions(f);
            let e = mesh::sub(p[1], p[0]);
            let ex = mesh::scale(e, 1.0 / mesh::norm(e));
            let n = mesh::triangle_normal(&p);
            let n = mesh::scale(n, 1.0 / mesh::norm(n));
            (ex, mesh::cross(n, ex))
        })
        .collect();
    let mut per_face_vertex: BTreeMap<(usize, usize), [f64; 2]> = BTreeMap::new();
    for ((row, v), x) in to_map(g) {
        per_face_vertex.entry((row / 2, v)).or_insert([0.0; 2])[row % 2] = x;
    }
    let mut out = BTreeMap::new();
    for ((f, v), [gx, gy]) in per_face_vertex {
        let (ex, ey) = frames[f];
        for d in 0..3 {
            out.insert((d * nf + f, v), gx * ex[d] + gy * ey[d]);
        }
    }
    out
}

fn check(name: &str) {
    let Some(d) = dump(name) else { return };
    let ops = Operators::new(&d.mesh).expect("no degenerate faces");
    let l = sparse_rel_diff(&to_map(&ops.laplacian), &d.laplacian);
    let m = dense_rel_diff(&ops.mass, &d.mass);
    let a = dense_rel_diff(&ops.face_areas, &d.areas);
    let g = sparse_rel_diff(&gradient_in_3d(&d.mesh, &ops.gradient), &d.gradient);
    eprintln!("{name}: relative differences to libigl: L {l:.2e}, M {m:.2e}, A {a:.2e}, G {g:.2e}");
    assert!(
        l < TOL,
        "{name}: L differs from -igl.cotmatrix by {l:e} (relative)"
    );
    assert!(
        m < TOL,
        "{name}: M differs from igl.massmatrix by {m:e} (relative)"
    );
    assert!(
        a < TOL,
        "{name}: A differs from igl.doublearea/2 by {a:e} (relative)"
    );
    assert!(
        g < TOL,
        "{name}: G (mapped to 3D) differs from igl.grad by {g:e} (relative)"
    );
    // the free functions agree with the bundle bit for bit
    assert_eq!(operators::face_areas(&d.mesh), ops.face_areas);
    assert_eq!(operators::lumped_mass(&d.mesh), ops.mass);
    assert_eq!(
        to_map(&operators::cotangent_laplacian(&d.mesh)),
        to_map(&ops.laplacian)
    );
    assert_eq!(
        to_map(&operators::intrinsic_gradient(&d.mesh)),
        to_map(&ops.gradient)
    );
    assert_eq!(
        operators::face_areas_interleaved(&d.mesh),
        ops.face_areas_interleaved
    );
}

#[test]
fn bunny_matches_libigl() {
    check("bunny.off");
}

#[test]
fn open_camel_matches_libigl() {
    check("camel_b.obj");
}

#[test]
fn genus_three_matches_libigl() {
    check("3holes.off");
}
