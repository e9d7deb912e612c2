//! Timing of the sparse generalized eigensolver: the `k` smallest eigenpairs
//! of `L phi = lambda M phi` for a mesh (default: icosphere 6, 40962
//! vertices, and k = 512, the size of the scipy reference in
//! docs/BENCHMARKS.md, "Reference numbers": `eigsh` shift-invert, 512 pairs
//! of a 43k-vertex mesh in 58 s).
//!
//! ```text
//! cargo run --release -p mfm-solver --example eigs_timing -- [MESH] [k] [block] [subspace]
//! ```
//! `MESH` is a mesh file, `icoN` (icosphere with N subdivisions), `FILE@S`
//! (the file Loop-subdivided S times), `torusN` (a jittered torus with
//! about N vertices) or a folder written by `xtask/python/scipy_eigs.py`
//! (`L.txt`, `M.txt`; when it also holds scipy's `eigs.txt`, the largest
//! relative difference to it is printed).

#[path = "../tests/common/mod.rs"]
mod common;

use std::time::Instant;

use faer::sparse::SparseColMat;
use mfm_geometry::{operators, procedural, subdivide};
use mfm_solver::{EigenMethod, EigenOptions, generalized_eigenpairs};

fn load(spec: &str) -> (SparseColMat<usize, f64>, Vec<f64>) {
    let dir = std::path::Path::new(spec);
    if dir.join("L.txt").is_file() {
        return (
            common::read_triplets(&dir.join("L.txt")),
            common::read_column(&dir.join("M.txt")),
        );
    }
    if let Some(n) = spec.strip_prefix("torus") {
        return common::torus_operators(n.parse().expect("vertex count"));
    }
    let mesh = if let Some(s) = spec.strip_prefix("ico") {
        procedural::icosphere(s.parse().expect("icosphere level"))
    } else {
        let (path, times) = match spec.split_once('@') {
            Some((p, t)) => (p, t.parse::<usize>().expect("subdivision count")),
            None => (spec, 0),
        };
        let mut mesh = mfm_meshio::read_mesh(path).expect("readable mesh");
        for _ in 0..times {
            mesh = subdivide::loop_subdivision(&mesh).expect("subdivision");
        }
        mesh
    };
    (
        operators::cotangent_laplacian(&mesh),
        operators::lumped_mass(&mesh),
    )
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let spec = args.first().cloned().unwrap_or_else(|| "ico6".into());
    let k: usize = args.get(1).map(|s| s.parse().expect("k")).unwrap_or(512);
    let block: usize = args.get(2).map(|s| s.parse().expect("block")).unwrap_or(0);
    let subspace: usize = args
        .get(3)
        .map(|s| s.parse().expect("subspace"))
        .unwrap_or(0);
    let (l, m) = load(&spec);
    let opts = EigenOptions {
        method: EigenMethod::Sparse,
        block_size: block,
        max_subspace: subspace,
        ..EigenOptions::default()
    };
    let t = Instant::now();
    let pairs = generalized_eigenpairs(&l, &m, k, &opts).expect("eigensolve");
    let secs = t.elapsed().as_secs_f64();
    println!(
        "{spec}: n = {}, k = {k}: {secs:.2} s ({} restarts, {} solves, sigma {:.3e}); lambda_1 = {:.6e}, lambda_{} = {:.6e}",
        l.nrows(),
        pairs.info.restarts,
        pairs.info.solves,
        pairs.info.sigma,
        pairs.values[1.min(k - 1)],
        k - 1,
        pairs.values[k - 1]
    );
    let reference = std::path::Path::new(&spec).join("eigs.txt");
    if reference.is_file() {
        let r = common::read_column(&reference);
        let worst = pairs
            .values
            .iter()
            .zip(&r)
            .map(|(v, e)| (v - e).abs() / e.max(r[1]))
            .fold(0.0, f64::max);
        println!("largest relative difference to scipy's eigs.txt: {worst:.2e}");
    }
}
