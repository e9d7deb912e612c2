//! `mfm net summary` and `mfm net bench`: the PoissonNet presets, their
//! parameter tables, and their training-step and inference times on a mesh.

use crate::mesh::load_mesh;
use anyhow::{Context, Result, bail};
use clap::{Args, Subcommand};
use mfm_fm::device::DeviceChoice;
use mfm_net::bench::{BenchOptions, bench_training_step};
use mfm_net::model::PresetReport;
use mfm_net::{PoissonNet, PoissonNetConfig};

/// `mfm net ...`.
#[derive(Subcommand)]
pub enum NetCommand {
    /// Print a preset's layer table (every variable, its shape and size) and
    /// its parameter count.
    Summary {
        /// Preset: paper (W128 K5 nl3), medium (W64 K4) or small (W32 K3).
        #[arg(long, default_value = "paper")]
        preset: String,
        /// Print the configuration and the parameter count as JSON instead.
        #[arg(long)]
        json: bool,
    },
    /// Time flow-matching training steps (forward, backward, Adam) and
    /// batch-1 inference on a mesh with synthetic inputs (noisy xyz in,
    /// source xyz and t as conditioning). Prints the medians.
    Bench(BenchArgs),
}

/// Arguments of `mfm net bench`.
#[derive(Args)]
pub struct BenchArgs {
    /// Mesh file or builtin:NAME.
    mesh: crate::mesh::MeshSpec,
    /// Preset: paper, medium or small.
    #[arg(long, default_value = "small")]
    preset: String,
    /// Batch size of the training steps.
    #[arg(long, default_value_t = 4)]
    batch: usize,
    /// Timed training steps (the median is printed).
    #[arg(long, default_value_t = 5)]
    steps: usize,
    /// Untimed warm-up steps first.
    #[arg(long, default_value_t = 1)]
    warmup: usize,
    /// Timed batch-1 forward passes (0 skips them).
    #[arg(long, default_value_t = 5)]
    inference: usize,
    /// libtorch threads (default: libtorch's choice, one per core).
    #[arg(long)]
    threads: Option<i32>,
    /// Also print the time per network section.
    #[arg(long)]
    profile: bool,
    /// Where to run: auto (a GPU when libtorch sees one), cpu or cuda.
    #[arg(long, default_value = "auto")]
    device: DeviceChoice,
}

/// Runs one `mfm net` subcommand.
pub fn run(cmd: NetCommand) -> Result<()> {
    match cmd {
        NetCommand::Summary { preset, json } => summary(&preset, json),
        NetCommand::Bench(a) => bench(a),
    }
}

fn bench(a: BenchArgs) -> Result<()> {
    if a.batch == 0 || a.steps == 0 {
        bail!("--batch and --steps must be at least 1");
    }
    if a.threads.is_some_and(|t| t < 1) {
        bail!("--threads must be at least 1");
    }
    let config = preset_config(&a.preset)?;
    let mesh = load_mesh(&a.mesh)?;
    let opts = BenchOptions {
        batch: a.batch,
        steps: a.steps,
        warmup: a.warmup,
        inference_runs: a.inference,
        threads: a.threads,
        device: a.device.resolve()?,
        profile: a.profile,
        ..BenchOptions::default()
    };
    let (w, k, nl) = (config.width, config.blocks, config.vector_layers);
    println!(
        "preset {} (W{w} K{k} nl{nl}) on {:?}; OpenMP workers wait with {}",
        a.preset,
        opts.device,
        crate::openmp::describe()
    );
    let report =
        bench_training_step(&mesh, &config, &opts).context("benchmarking the training step")?;
    print!("{report}");
    Ok(())
}

fn preset_config(name: &str) -> Result<PoissonNetConfig> {
    PoissonNetConfig::preset(name).map_err(|e| anyhow::anyhow!("--preset: {e}"))
}

fn summary(preset: &str, json: bool) -> Result<()> {
    let config = preset_config(preset)?;
    let net = PoissonNet::new(&config, tch::Device::Cpu).context("building the network")?;
    let summary = net.summary();
    if json {
        let report = PresetReport {
            config: &config,
            parameters: summary.total,
            preset,
        };
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        println!(
            "preset {preset}: width {}, blocks {}, vector layers {}, in {}, out {}, conditioning {}, head {:?}",
            config.width,
            config.blocks,
            config.vector_layers,
            config.in_channels,
            config.out_channels,
            config.cond_channels,
            config.head
        );
        println!("{summary}");
    }
    Ok(())
}
