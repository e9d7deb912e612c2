//! `mfm eigs`: eigenpairs of a mesh's Laplacian.

use crate::mesh_arg::load_mesh;
use crate::output::{write_json, write_npy};
use anyhow::{Context, Result, bail};
use mfm_geometry::operators::Operators;
use mfm_solver::{EigenOptions, generalized_eigenpairs};
use std::path::Path;
use std::time::Instant;

#[derive(serde::Serialize)]
struct EigsSummary {
    mesh: String,
    vertices: usize,
    k: usize,
    method: String,
    seconds: f64,
    eigenvalues: Vec<f64>,
    files: [&'static str; 2],
    conventions: &'static str,
}

/// Computes the `k` smallest eigenpairs of `L phi = lambda M phi` and writes
/// `eigenvalues.npy` `[k]`, `eigenvectors.npy` `[V, k]` (row-major, columns
/// `M`-orthonormal) and `summary.json` into `out`.
pub fn eigs(spec: &str, k: usize, out: &Path) -> Result<()> {
    if k == 0 {
        bail!("--k must be at least 1");
    }
    let mesh = load_mesh(spec)?;
    let n = mesh.num_vertices();
    if k > n {
        bail!("{spec}: --k {k} exceeds the vertex count {n}");
    }
    let ops = Operators::new(&mesh).with_context(|| format!("{spec}: cannot build operators"))?;
    let start = Instant::now();
    let pairs = generalized_eigenpairs(&ops.laplacian, &ops.mass, k, &EigenOptions::default())
        .with_context(|| format!("{spec}: eigensolve failed"))?;
    let seconds = start.elapsed().as_secs_f64();
    std::fs::create_dir_all(out)
        .with_context(|| format!("cannot create folder {}", out.display()))?;
    let mut vectors = Vec::with_capacity(n * k);
    for v in 0..n {
        for j in 0..k {
            vectors.push(pairs.vectors[(v, j)]);
        }
    }
    write_npy(&out.join("eigenvalues.npy"), &pairs.values, &[k as u64])?;
    write_npy(
        &out.join("eigenvectors.npy"),
        &vectors,
        &[n as u64, k as u64],
    )?;
    let summary = EigsSummary {
        mesh: spec.to_owned(),
        vertices: n,
        k,
        method: format!("{:?}", pairs.info.method),
        seconds,
        eigenvalues: pairs.values.clone(),
        files: ["eigenvalues.npy", "eigenvectors.npy"],
        conventions: "L phi = lambda M phi with L the PSD cotangent Laplacian and M the lumped mass; \
eigenvalues ascending; eigenvectors are the columns of the [V, k] array, phi^T M phi = 1",
    };
    write_json(&out.join("summary.json"), &summary)?;
    println!(
        "{k} eigenpairs of {spec} ({n} vertices) in {seconds:.2} s ({:?}); lambda in [{:.4e}, {:.4e}]; wrote {}",
        pairs.info.method,
        pairs.values[0],
        pairs.values[k - 1],
        out.display()
    );
    Ok(())
}
