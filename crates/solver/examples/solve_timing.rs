//! Prints a table of screened Poisson timings (`L + tau M`, tau = 100):
//! symbolic analysis, numeric factorization, a batch of 64 right-hand sides in
//! f64 and f32 (per sample), and a single right-hand side, best of 5.
//!
//! ```text
//! cargo run --release -p mfm-solver --example solve_timing -- [MESH...]
//! ```
//! `MESH` is a mesh file, `icoN` (icosphere with N subdivisions) or
//! `FILE@S` (the file Loop-subdivided S times). Default: the shared bunny and
//! icospheres 6, 7 and 8 (41k, 164k, 655k vertices).

use std::time::Instant;

use faer::Mat;
use mfm_geometry::{TriMesh, operators, procedural, subdivide};
use mfm_solver::ScreenedPoisson;

fn load(spec: &str) -> TriMesh {
    if let Some(s) = spec.strip_prefix("ico") {
        return procedural::icosphere(s.parse().expect("icosphere level"));
    }
    let (path, times) = match spec.split_once('@') {
        Some((p, t)) => (p, t.parse::<usize>().expect("subdivision count")),
        None => (spec, 0),
    };
    let mut mesh = mfm_meshio::read_mesh(path).expect("readable mesh");
    for _ in 0..times {
        mesh = subdivide::loop_subdivision(&mesh).expect("subdivision");
    }
    mesh
}

fn best_of(reps: usize, mut f: impl FnMut()) -> f64 {
    (0..reps)
        .map(|_| {
            let t = Instant::now();
            f();
            t.elapsed().as_secs_f64()
        })
        .fold(f64::INFINITY, f64::min)
}

fn main() {
    let mut specs: Vec<String> = std::env::args().skip(1).collect();
    if specs.is_empty() {
        let bunny = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../../../shared/meshes/bunny.off"
        );
        specs = vec![bunny.into(), "ico6".into(), "ico7".into(), "ico8".into()];
    }
    println!(
        "| mesh | V | symbolic | numeric | batch 64 f64 (per sample) | batch 64 f32 (per sample) | single f64 |"
    );
    println!("|---|---|---|---|---|---|---|");
    for spec in specs {
        let mesh = load(&spec);
        let l = operators::cotangent_laplacian(&mesh);
        let m = operators::lumped_mass(&mesh);
        let n = l.nrows();
        let reps = if n > 300_000 { 3 } else { 5 };
        let t_sym = best_of(reps, || {
            drop(ScreenedPoisson::analyse(&l).expect("analyse"))
        });
        let sym = ScreenedPoisson::analyse(&l).expect("analyse");
        let t_num = best_of(reps, || {
            drop(ScreenedPoisson::with_symbolic(&sym, &l, &m, 100.0).expect("factor"))
        });
        let sp = ScreenedPoisson::with_symbolic(&sym, &l, &m, 100.0).expect("factor");
        let b = Mat::<f64>::from_fn(n, 64, |i, j| ((i * 7 + j * 13) % 17) as f64 - 8.0);
        let t64 = best_of(reps, || {
            let mut x = b.clone();
            sp.solve_many_in_place(x.as_mut()).expect("solve");
        });
        let b32 = Mat::<f32>::from_fn(n, 64, |i, j| b[(i, j)] as f32);
        let _ = sp.factor_f32();
        let t32 = best_of(reps, || {
            drop(sp.solve_many_f32(b32.as_ref()).expect("solve"))
        });
        let b1: Vec<f64> = (0..n).map(|i| b[(i, 0)]).collect();
        let t1 = best_of(reps, || drop(sp.solve(&b1).expect("solve")));
        let name = std::path::Path::new(&spec)
            .file_name()
            .map_or(spec.clone(), |f| f.to_string_lossy().into_owned());
        println!(
            "| {name} | {n} | {:.2}M | {:.1} ms | {:.1} ms | {:.1} ms ({:.3} ms) | {:.1} ms ({:.3} ms) | {:.2} ms |",
            sym.factor_len() as f64 / 1e6,
            t_sym * 1e3,
            t_num * 1e3,
            t64 * 1e3,
            t64 * 1e3 / 64.0,
            t32 * 1e3,
            t32 * 1e3 / 64.0,
            t1 * 1e3
        );
    }
}
