//! Screened Poisson `L + tau M` (tau = 100, as in the reference numbers of docs/BENCHMARKS.md): factorization
//! (symbolic + numeric, and numeric only) and a batch of 64 right-hand sides
//! (f64 and f32), on the bunny (3.5k vertices) and icospheres of 41k and 164k
//! vertices.
//!
//! ```text
//! cargo bench -p mfm-solver --bench solve
//! ```

use std::hint::black_box;
use std::time::Duration;

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use faer::Mat;
use mfm_geometry::{TriMesh, operators, procedural};
use mfm_solver::ScreenedPoisson;

fn meshes() -> Vec<(String, TriMesh)> {
    let bunny =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/meshes/bunny.off");
    let mut out = Vec::new();
    match mfm_meshio::read_mesh(&bunny) {
        Ok(m) => out.push(("bunny".to_owned(), m)),
        Err(e) => eprintln!("bunny not available ({e}); using icosphere(5)"),
    }
    if out.is_empty() {
        out.push(("ico5".to_owned(), procedural::icosphere(5)));
    }
    out.push(("ico6".to_owned(), procedural::icosphere(6)));
    out.push(("ico7".to_owned(), procedural::icosphere(7)));
    out
}

fn rhs<T: Copy>(n: usize, k: usize, f: impl Fn(f64) -> T) -> Mat<T> {
    Mat::from_fn(n, k, |i, j| f(((i * 7 + j * 13) % 17) as f64 - 8.0))
}

fn bench(c: &mut Criterion) {
    for (name, mesh) in meshes() {
        let l = operators::cotangent_laplacian(&mesh);
        let m = operators::lumped_mass(&mesh);
        let n = l.nrows();
        let id = format!("{name}/{n}");
        let mut g = c.benchmark_group("screened_poisson");
        g.sample_size(10)
            .measurement_time(Duration::from_secs(4))
            .warm_up_time(Duration::from_secs(1));
        g.bench_function(BenchmarkId::new("factor", &id), |b| {
            b.iter(|| ScreenedPoisson::new(black_box(&l), &m, 100.0).expect("SPD"))
        });
        let sp = ScreenedPoisson::new(&l, &m, 100.0).expect("SPD");
        g.bench_function(BenchmarkId::new("refactor_numeric", &id), |b| {
            b.iter(|| sp.with_tau(black_box(100.0)).expect("SPD"))
        });
        let b64 = rhs(n, 64, |x| x);
        g.bench_function(BenchmarkId::new("solve_batch64_f64", &id), |b| {
            b.iter_batched_ref(
                || b64.clone(),
                |x| sp.solve_many_in_place(x.as_mut()).expect("solve"),
                criterion::BatchSize::LargeInput,
            )
        });
        let b32 = rhs(n, 64, |x| x as f32);
        let _ = sp.factor_f32();
        g.bench_function(BenchmarkId::new("solve_batch64_f32", &id), |b| {
            b.iter(|| sp.solve_many_f32(black_box(b32.as_ref())).expect("solve"))
        });
        let b1 = rhs(n, 1, |x| x);
        let b1 = b1
            .col(0)
            .try_as_col_major()
            .expect("contiguous")
            .as_slice()
            .to_vec();
        g.bench_function(BenchmarkId::new("solve_single_f64", &id), |b| {
            b.iter(|| sp.solve(black_box(&b1)).expect("solve"))
        });
        g.finish();
    }
}

criterion_group!(benches, bench);
criterion_main!(benches);
