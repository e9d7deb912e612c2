//! Times Matérn noise sampling on mesh files and prints JSON, the mfm side
//! of `cargo xtask bench noise` (`xtask/python/bench_noise.py` prints the
//! same for CHOLMOD and cholespy).
//!
//! ```text
//! cargo run --release -p mfm-noise --example sampling_timings -- \
//!     [--runs 3] [--batch 64] [--tau 100] MESH [MESH ...]
//! ```
//!
//! For every mesh (OBJ/OFF/PLY/glTF, read with `mfm_meshio::read_mesh`)
//! the median wall time of `--runs` runs, after one warm-up run, in
//! milliseconds (`min_ms`: the fastest run):
//!
//! - `operators`: `Operators::new` (L, M, face areas, gradient);
//! - `factor`: `ScreenedPoisson::new(L, M, tau)`: symbolic analysis (AMD
//!   ordering, supernodes) and numeric factorization of `L + tau M`;
//! - `setup`: `NoiseSampler::new(mesh, Matern { tau })`: operators, `Gamma`
//!   and the factorization, what a user pays once per mesh;
//! - `sample_f64`, `sample_f32`: `NoiseSampler::sample(batch, 1, seed)` and
//!   `sample_f32`: the random normals, `M^1/2 n`, the block solve, the output;
//! - `solve_f64`, `solve_f32`: the block solve alone
//!   (`ScreenedPoisson::solve_many_in_place` / `solve_many_f32_in_place`) on
//!   a prepared `V x batch` right-hand side (its copy is not timed).
//!
//! Per-sample times are the batch times divided by `--batch`. `factor_len`
//! is the number of values stored in the supernodal factor.

use std::error::Error;
use std::time::Instant;

use faer::Mat;
use mfm_geometry::operators::Operators;
use mfm_meshio as io;
use mfm_noise::{NoiseKind, NoiseSampler};
use mfm_solver::ScreenedPoisson;

type Res<T> = Result<T, Box<dyn Error>>;

struct Opts {
    runs: usize,
    batch: usize,
    tau: f64,
    paths: Vec<String>,
}

fn parse() -> Res<Opts> {
    let mut o = Opts {
        runs: 3,
        batch: 64,
        tau: 100.0,
        paths: Vec::new(),
    };
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        let mut value = |name: &str| args.next().ok_or(format!("{name} expects a value"));
        match a.as_str() {
            "--runs" => o.runs = value("--runs")?.parse::<usize>()?.max(1),
            "--batch" => o.batch = value("--batch")?.parse::<usize>()?.max(1),
            "--tau" => o.tau = value("--tau")?.parse()?,
            "-h" | "--help" => {
                println!("usage: sampling_timings [--runs 3] [--batch 64] [--tau 100] MESH...");
                std::process::exit(0);
            }
            s if s.starts_with("--") => return Err(format!("unknown option {s}").into()),
            _ => o.paths.push(a),
        }
    }
    if o.paths.is_empty() {
        return Err("expected at least one mesh path".into());
    }
    Ok(o)
}

/// (median, min) milliseconds of `runs` calls of `f` after one warm-up call.
fn time_ms<R>(runs: usize, mut f: impl FnMut() -> Res<R>) -> Res<(f64, f64)> {
    drop(f()?);
    let mut t = Vec::with_capacity(runs);
    for _ in 0..runs {
        let start = Instant::now();
        let r = f()?;
        t.push(start.elapsed().as_secs_f64() * 1e3);
        drop(r);
    }
    t.sort_by(f64::total_cmp);
    Ok((t[t.len() / 2], t[0]))
}

/// As [`time_ms`], with an untimed `prepare` before each call.
fn time_prepared_ms<P>(
    runs: usize,
    mut prepare: impl FnMut() -> P,
    mut f: impl FnMut(P) -> Res<()>,
) -> Res<(f64, f64)> {
    f(prepare())?;
    let mut t = Vec::with_capacity(runs);
    for _ in 0..runs {
        let p = prepare();
        let start = Instant::now();
        f(p)?;
        t.push(start.elapsed().as_secs_f64() * 1e3);
    }
    t.sort_by(f64::total_cmp);
    Ok((t[t.len() / 2], t[0]))
}

fn time_mesh(path: &str, o: &Opts) -> Res<serde_json::Value> {
    let mesh = io::read_mesh(path).map_err(|e| format!("{path}: {e}"))?;
    let kind = NoiseKind::Matern { tau: o.tau };
    let (runs, batch, tau) = (o.runs, o.batch, o.tau);
    let ops = Operators::new(&mesh)?;
    let v = mesh.num_vertices();
    let mut timings = Vec::new();
    timings.push(("operators", time_ms(runs, || Ok(Operators::new(&mesh)?))?));
    timings.push((
        "factor",
        time_ms(runs, || {
            Ok(ScreenedPoisson::new(&ops.laplacian, &ops.mass, tau)?)
        })?,
    ));
    timings.push((
        "setup",
        time_ms(runs, || Ok(NoiseSampler::new(&mesh, kind)?))?,
    ));
    let sampler = NoiseSampler::new(&mesh, kind)?;
    let mut seed = 0u64;
    timings.push((
        "sample_f64",
        time_ms(runs, || {
            seed += 1;
            Ok(sampler.sample(batch, 1, seed)?)
        })?,
    ));
    timings.push((
        "sample_f32",
        time_ms(runs, || {
            seed += 1;
            Ok(sampler.sample_f32(batch, 1, seed)?)
        })?,
    ));
    let poisson = sampler
        .screened_poisson()
        .ok_or("a Matérn sampler has a factor")?;
    // a prepared V x batch right-hand side (any values of the right size)
    let rhs = sampler.sample(batch, 1, 12345)?.into_data();
    let rhs = Mat::from_fn(v, batch, |i, j| rhs[j * v + i]);
    let rhs32 = Mat::from_fn(v, batch, |i, j| rhs[(i, j)] as f32);
    timings.push((
        "solve_f64",
        time_prepared_ms(
            runs,
            || rhs.clone(),
            |mut b| Ok(poisson.solve_many_in_place(b.as_mut())?),
        )?,
    ));
    timings.push((
        "solve_f32",
        time_prepared_ms(
            runs,
            || rhs32.clone(),
            |mut b| Ok(poisson.solve_many_f32_in_place(b.as_mut())?),
        )?,
    ));
    let median: serde_json::Map<String, serde_json::Value> = timings
        .iter()
        .map(|(k, t)| ((*k).to_owned(), round4(t.0).into()))
        .collect();
    let min: serde_json::Map<String, serde_json::Value> = timings
        .iter()
        .map(|(k, t)| ((*k).to_owned(), round4(t.1).into()))
        .collect();
    Ok(serde_json::json!({
        "mesh": path,
        "vertices": v,
        "faces": mesh.num_faces(),
        "factor_len": poisson.symbolic().factor_len(),
        "median_ms": median,
        "min_ms": min,
    }))
}

fn round4(x: f64) -> f64 {
    (x * 1e4).round() / 1e4
}

fn main() -> Res<()> {
    let o = parse()?;
    let mut results = Vec::new();
    for path in &o.paths {
        eprintln!("sampling_timings: {path}");
        results.push(time_mesh(path, &o)?);
    }
    let report = serde_json::json!({
        "tool": "mfm-noise sampling_timings",
        "threads": rayon::current_num_threads(),
        "runs": o.runs,
        "batch": o.batch,
        "tau": o.tau,
        "results": results,
    });
    println!("{}", serde_json::to_string_pretty(&report)?);
    Ok(())
}
