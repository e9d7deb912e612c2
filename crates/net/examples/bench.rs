//! Training-step and inference timings of PoissonNet presets on a mesh.
//!
//! ```text
//! cargo run --release -p mfm-net --features bench --example bench -- [MESH] [--preset NAME] [--batch B]
//!     [--steps S] [--warmup W] [--threads T] [--profile]
//! ```
//! `MESH` defaults to `../shared/meshes/bunny.off` and falls back to
//! `icosphere(4)` when that file is missing. Prints the median step time
//! (forward, backward, Adam), the batch-1 inference time and, with
//! `--profile`, the time per section.
#![allow(clippy::unwrap_used)]

use mfm_geometry::{procedural, test_support};
use mfm_net::PoissonNetConfig;
use mfm_net::bench::{BenchOptions, bench_training_step};

fn main() {
    let mut args = std::env::args().skip(1);
    let mut mesh_path = None;
    let mut preset = "small".to_owned();
    let mut opts = BenchOptions {
        batch: 4,
        steps: 3,
        warmup: 1,
        inference_runs: 5,
        ..Default::default()
    };
    while let Some(a) = args.next() {
        let mut value = || args.next().expect("missing value");
        match a.as_str() {
            "--preset" => preset = value(),
            "--batch" => opts.batch = value().parse().unwrap(),
            "--steps" => opts.steps = value().parse().unwrap(),
            "--warmup" => opts.warmup = value().parse().unwrap(),
            "--threads" => opts.threads = Some(value().parse().unwrap()),
            "--inference" => opts.inference_runs = value().parse().unwrap(),
            "--profile" => opts.profile = true,
            "--no-tune" => opts.tune_allocator = false,
            other => mesh_path = Some(other.to_owned()),
        }
    }
    let mesh = match mesh_path {
        Some(p) => mfm_meshio::read_mesh(&p).unwrap(),
        None => match test_support::shared_mesh("bunny.off") {
            Some(p) => mfm_meshio::read_mesh(p).unwrap(),
            None => procedural::icosphere(4),
        },
    };
    let config = PoissonNetConfig::preset(&preset).unwrap();
    println!("preset {preset}: {config:?}");
    let report = bench_training_step(&mesh, &config, &opts).unwrap();
    println!("{report}");
}
