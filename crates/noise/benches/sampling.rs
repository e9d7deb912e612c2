//! Matérn sampling (tau = 100, as in the reference numbers of docs/BENCHMARKS.md): a batch of 64 scalar samples,
//! in f64 and f32, on icospheres of 2.6k, 10k and 41k vertices and on the
//! bunny (3.5k vertices) when the shared meshes are present; plus the
//! per-mesh setup (operators + factorization) and the normals alone (white
//! noise), which bound what the solve costs on top.
//!
//! ```text
//! cargo bench -p mfm-noise --bench sampling
//! ```

use std::hint::black_box;
use std::time::Duration;

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use mfm_geometry::{TriMesh, procedural};
use mfm_noise::{NoiseKind, NoiseSampler};

fn meshes() -> Vec<(String, TriMesh)> {
    let mut out = Vec::new();
    for level in [4, 5, 6] {
        out.push((format!("ico{level}"), procedural::icosphere(level)));
    }
    let bunny =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/meshes/bunny.off");
    match mfm_meshio::read_mesh(&bunny) {
        Ok(m) => out.push(("bunny".to_owned(), m)),
        Err(e) => eprintln!("bunny not available ({e}); skipping it"),
    }
    out
}

fn bench(c: &mut Criterion) {
    let matern = NoiseKind::Matern { tau: 100.0 };
    let mut g = c.benchmark_group("matern");
    g.sample_size(10)
        .measurement_time(Duration::from_secs(4))
        .warm_up_time(Duration::from_secs(1));
    for (name, mesh) in meshes() {
        let id = format!("{name}/{}", mesh.num_vertices());
        g.bench_function(BenchmarkId::new("setup", &id), |b| {
            b.iter(|| NoiseSampler::new(black_box(&mesh), matern).expect("sampler"))
        });
        let sampler = NoiseSampler::new(&mesh, matern).expect("sampler");
        g.bench_function(BenchmarkId::new("batch64_f64", &id), |b| {
            b.iter(|| sampler.sample(64, 1, black_box(7)).expect("sample"))
        });
        g.bench_function(BenchmarkId::new("batch64_f32", &id), |b| {
            b.iter(|| sampler.sample_f32(64, 1, black_box(7)).expect("sample"))
        });
        let white = NoiseSampler::new(&mesh, NoiseKind::White).expect("sampler");
        g.bench_function(BenchmarkId::new("white_batch64", &id), |b| {
            b.iter(|| white.sample(64, 1, black_box(7)).expect("sample"))
        });
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
