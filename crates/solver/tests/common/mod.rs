//! Test matrices and oracle helpers shared by the integration tests and the
//! benchmark of mfm-solver (built without mfm-geometry so the solver tests
//! stand alone).
#![allow(dead_code)]

use std::path::PathBuf;

use faer::sparse::{SparseColMat, Triplet};

/// A closed triangulated torus: `nu x nv` vertices on the surface of
/// revolution with radii `big_r > small_r`, each grid quad split in two
/// counter-clockwise triangles. Optional deterministic jitter of the angles
/// (fraction of a cell) makes the triangles irregular.
pub fn torus(
    nu: usize,
    nv: usize,
    big_r: f64,
    small_r: f64,
    jitter: f64,
) -> (Vec<[f64; 3]>, Vec<[usize; 3]>) {
    let mut pos = Vec::with_capacity(nu * nv);
    let mut state = 0x9e37_79b9_7f4a_7c15_u64;
    let mut rnd = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f64 / (1u64 << 53) as f64 - 0.5
    };
    for i in 0..nu {
        for j in 0..nv {
            let u = (i as f64 + jitter * rnd()) / nu as f64 * std::f64::consts::TAU;
            let v = (j as f64 + jitter * rnd()) / nv as f64 * std::f64::consts::TAU;
            let rr = big_r + small_r * v.cos();
            pos.push([rr * u.cos(), rr * u.sin(), small_r * v.sin()]);
        }
    }
    let id = |i: usize, j: usize| (i % nu) * nv + (j % nv);
    let mut faces = Vec::with_capacity(2 * nu * nv);
    for i in 0..nu {
        for j in 0..nv {
            let (a, b, c, d) = (id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1));
            faces.push([a, b, c]);
            faces.push([a, c, d]);
        }
    }
    (pos, faces)
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}
fn norm(a: [f64; 3]) -> f64 {
    dot(a, a).sqrt()
}

/// Cotangent Laplacian in the PSD convention (`L_ij = -(cot a + cot b)/2`).
pub fn cotan_laplacian(pos: &[[f64; 3]], faces: &[[usize; 3]]) -> SparseColMat<usize, f64> {
    let mut t = Vec::with_capacity(faces.len() * 12);
    for f in faces {
        for k in 0..3 {
            let (o, a, b) = (f[k], f[(k + 1) % 3], f[(k + 2) % 3]);
            let ea = sub(pos[a], pos[o]);
            let eb = sub(pos[b], pos[o]);
            let w = 0.5 * dot(ea, eb) / norm(cross(ea, eb));
            t.push(Triplet::new(a, b, -w));
            t.push(Triplet::new(b, a, -w));
            t.push(Triplet::new(a, a, w));
            t.push(Triplet::new(b, b, w));
        }
    }
    SparseColMat::try_new_from_triplets(pos.len(), pos.len(), &t).expect("valid triplets")
}

/// Barycentric lumped mass: a third of the incident triangle areas.
pub fn lumped_mass(pos: &[[f64; 3]], faces: &[[usize; 3]]) -> Vec<f64> {
    let mut m = vec![0.0; pos.len()];
    for f in faces {
        let area = 0.5 * norm(cross(sub(pos[f[1]], pos[f[0]]), sub(pos[f[2]], pos[f[0]])));
        for &v in f {
            m[v] += area / 3.0;
        }
    }
    m
}

/// Operators of a torus with about `n` vertices (aspect 2:1 grid).
pub fn torus_operators(n: usize) -> (SparseColMat<usize, f64>, Vec<f64>) {
    let nv = ((n as f64 / 2.0).sqrt().round() as usize).max(3);
    let nu = (n / nv).max(3);
    let (p, f) = torus(nu, nv, 1.0, 0.4, 0.3);
    (cotan_laplacian(&p, &f), lumped_mass(&p, &f))
}

/// Python oracle interpreter (`$MFM_PYTHON`), or `None` with a printed skip
/// reason; a missing oracle fails the test when `MFM_REQUIRE_ORACLES=1`.
pub fn python_oracle() -> Option<PathBuf> {
    match std::env::var_os("MFM_PYTHON").map(PathBuf::from) {
        Some(p) if p.exists() => Some(p),
        _ => {
            let reason =
                "MFM_PYTHON is not set to the oracle environment (run through `cargo xtask test`)";
            if std::env::var("MFM_REQUIRE_ORACLES").is_ok_and(|v| v == "1") {
                panic!("{reason} (MFM_REQUIRE_ORACLES=1, so this is a failure)");
            }
            eprintln!("SKIPPED: {reason}");
            None
        }
    }
}

/// A shared test mesh (`$MFM_SHARED_MESHES` or `<workspace>/../shared/meshes`),
/// or `None` (with a printed reason) when it is missing.
pub fn shared_mesh(name: &str) -> Option<PathBuf> {
    let dir = std::env::var_os("MFM_SHARED_MESHES")
        .map(PathBuf::from)
        .unwrap_or_else(|| {
            PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared/meshes")
        });
    let path = dir.join(name);
    if path.is_file() {
        Some(path)
    } else {
        // A fresh clone without ../shared must pass: missing meshes always skip.
        eprintln!("SKIPPED: shared mesh {} not found", path.display());
        None
    }
}

/// Reads `i j value` triplet lines (0-based) into an `n x n` sparse matrix,
/// `n` being one more than the largest index.
pub fn read_triplets(path: &std::path::Path) -> SparseColMat<usize, f64> {
    let text = std::fs::read_to_string(path).expect("readable triplet file");
    let mut t = Vec::new();
    let mut n = 0;
    for line in text.lines().filter(|l| !l.trim().is_empty()) {
        let mut it = line.split_whitespace();
        let i = it.next().expect("row").parse::<f64>().expect("row index") as usize;
        let j = it.next().expect("col").parse::<f64>().expect("col index") as usize;
        let v: f64 = it.next().expect("value").parse().expect("value");
        n = n.max(i + 1).max(j + 1);
        t.push(Triplet::new(i, j, v));
    }
    SparseColMat::try_new_from_triplets(n, n, &t).expect("valid triplets")
}

/// Reads one number per line.
pub fn read_column(path: &std::path::Path) -> Vec<f64> {
    std::fs::read_to_string(path)
        .expect("readable file")
        .lines()
        .filter(|l| !l.trim().is_empty())
        .map(|l| l.trim().parse().expect("number"))
        .collect()
}

/// Graph Laplacian of the periodic `nx x ny` grid (unit weights, 5-point).
/// With mass `h^2` it is the flat-torus Laplacian with eigenvalues
/// `(4 / h^2) (sin^2(pi a / nx) + sin^2(pi b / ny))`.
pub fn periodic_grid_laplacian(nx: usize, ny: usize) -> SparseColMat<usize, f64> {
    let id = |i: usize, j: usize| (i % nx) * ny + (j % ny);
    let mut t = Vec::new();
    for i in 0..nx {
        for j in 0..ny {
            for (a, b) in [(id(i, j), id(i + 1, j)), (id(i, j), id(i, j + 1))] {
                t.extend([
                    Triplet::new(a, a, 1.0),
                    Triplet::new(b, b, 1.0),
                    Triplet::new(a, b, -1.0),
                    Triplet::new(b, a, -1.0),
                ]);
            }
        }
    }
    SparseColMat::try_new_from_triplets(nx * ny, nx * ny, &t).expect("valid triplets")
}
