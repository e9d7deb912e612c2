//! Criterion benchmarks of the intrinsic operators.
//!
//! `cargo bench -p mfm-geometry --bench operators`. Procedural icospheres of
//! 10k, 40k and 160k vertices always run; the shared bunny (3.5k vertices) is
//! added when `../shared/meshes/bunny.off` is present (else skipped). For the comparison with
//! libigl on large meshes see `examples/operator_timings.rs` and
//! `xtask/python/bench_operators.py`.

use std::hint::black_box;

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use mfm_geometry::operators::{self, Operators};
use mfm_geometry::test_support::shared_mesh;
use mfm_geometry::{TriMesh, procedural};

fn meshes() -> Vec<(String, TriMesh)> {
    let mut out = Vec::new();
    match shared_mesh("bunny.off").map(mfm_meshio::read_mesh) {
        Some(Ok(bunny)) => out.push(("bunny".to_owned(), bunny)),
        Some(Err(e)) => eprintln!("SKIPPED: bunny.off: {e}"),
        None => {}
    }
    for level in [5, 6, 7] {
        let mesh = procedural::icosphere(level);
        out.push((format!("icosphere{level}"), mesh));
    }
    out
}

fn bench(c: &mut Criterion) {
    let mut group = c.benchmark_group("operators");
    group.sample_size(20);
    for (name, mesh) in meshes() {
        let id = format!("{name}/{}v", mesh.num_vertices());
        group.throughput(Throughput::Elements(mesh.num_faces() as u64));
        group.bench_with_input(
            BenchmarkId::new("cotangent_laplacian", &id),
            &mesh,
            |b, m| b.iter(|| operators::cotangent_laplacian(black_box(m))),
        );
        group.bench_with_input(BenchmarkId::new("lumped_mass", &id), &mesh, |b, m| {
            b.iter(|| operators::lumped_mass(black_box(m)))
        });
        group.bench_with_input(
            BenchmarkId::new("intrinsic_gradient", &id),
            &mesh,
            |b, m| b.iter(|| operators::intrinsic_gradient(black_box(m))),
        );
        group.bench_with_input(BenchmarkId::new("operators_new", &id), &mesh, |b, m| {
            b.iter(|| Operators::new(black_box(m)))
        });
        let ops = Operators::new(&mesh).expect("benchmark meshes have no degenerate face");
        group.bench_with_input(BenchmarkId::new("gamma", &id), &ops, |b, o| {
            b.iter(|| operators::gamma(black_box(&o.laplacian), black_box(&o.mass)))
        });
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
