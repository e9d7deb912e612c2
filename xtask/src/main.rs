//! Project automation: `cargo xtask <command>`.
//!
//! - `setup`: create (once) the Python environment with the pinned torch whose
//!   libtorch `tch` links against, and the test oracles; print the variables to
//!   export for plain `cargo` use.
//! - `test`: setup, then every test of the workspace (oracle tests may not skip);
//!   without arguments also the `no-network` check.
//! - `lint`: `cargo fmt --check` and `cargo clippy --all-targets -D warnings`.
//! - `no-network`: `mfm` built without libtorch links none and runs.
//! - `bench operators`: operator assembly times, ours and libigl's, in one run.
//! - `bench noise`: Matérn sampling, ours against CHOLMOD and cholespy, in one run.
//! - `bench net`: PoissonNet training steps and inference at the three presets, in
//!   interleaved rounds (optionally against a baseline `mfm`), next to the reference times.
//! - `bench import`: `mfm dataset import` of many shapes, seconds and peak
//!   memory.
//! - `demo`, `pretrain`, `time-to-quality`, `reproduce-figures`: the
//!   reproductions of [`mfm_reproduce`] (also its `mfm-reproduce` binary),
//!   with the same arguments.
//! - `mfm ARGS...`: build the release `mfm` with the project's libtorch and
//!   run it.
//! - `visual-check DIR`: PNG contact sheets of the PLY files under DIR,
//!   rendered offscreen with pyvista.

mod bench;
mod bench_import;
mod bench_net;
mod bench_noise;
mod bench_train;
mod no_network;
mod python_package;
mod visual_check;

use anyhow::{Context, Result};
use clap::{Parser, Subcommand};
use mfm_reproduce::mfm::Mfm;
use mfm_reproduce::pyenv;
use mfm_reproduce::workspace::{cargo, root, run};
use std::path::{Path, PathBuf};

#[derive(Parser)]
#[command(name = "cargo xtask", about = "mfm project automation")]
struct Cli {
    #[command(subcommand)]
    command: Cmd,
}

#[derive(Subcommand)]
enum Cmd {
    /// Create the Python/libtorch environment if missing and print its variables.
    Setup,
    /// Set up, then run all tests of the workspace (extra args go to `cargo test`).
    Test {
        /// Arguments passed through to `cargo test`.
        #[arg(trailing_var_arg = true, allow_hyphen_values = true)]
        args: Vec<String>,
    },
    /// Formatting and clippy checks (warnings are errors), and a packaging
    /// dry run of every publishable crate (`cargo publish --dry-run
    /// --workspace --no-verify`).
    Lint,
    /// Build the `mfm` Python package's wheel (release, abi3) into
    /// target/wheels/.
    Wheel,
    /// Only the Python package's tests: build its wheel (dev profile),
    /// install it into a folder of its own and run pytest on
    /// crates/python/tests (extra args go to pytest; without them a fresh
    /// venv also installs the wheel and samples noise with it).
    Pytest {
        /// Arguments passed through to pytest.
        #[arg(trailing_var_arg = true, allow_hyphen_values = true)]
        args: Vec<String>,
    },
    /// Build `mfm` without its network feature and check that it links no
    /// libtorch (ldd) and runs without it (run after `cargo xtask test`: only
    /// the cli crate compiles again).
    NoNetwork,
    /// Benchmarks against the Python reference stack, in one run.
    #[command(subcommand)]
    Bench(BenchCmd),
    /// Build the release `mfm` binary with the project's libtorch and run it
    /// with the given arguments (e.g. `cargo xtask mfm -- net summary`), in
    /// the current folder.
    Mfm {
        /// Arguments passed to `mfm`.
        #[arg(trailing_var_arg = true, allow_hyphen_values = true)]
        args: Vec<String>,
    },
    /// The reproductions (mfm-reproduce): demo, pretrain, time-to-quality,
    /// reproduce-figures.
    #[command(flatten)]
    Reproduce(mfm_reproduce::Command),
    /// Render the PLY files under DIR offscreen with pyvista into PNG contact
    /// sheets (one per folder; signals as colors, plain meshes shaded).
    VisualCheck(visual_check::VisualCheckArgs),
}

#[derive(Subcommand)]
enum BenchCmd {
    /// Operator assembly (L, M, areas, G): libigl vs mfm-geometry on the same arrays.
    Operators {
        /// Mesh file to time (and its midpoint subdivisions).
        #[arg(long, default_value = "../shared/meshes/bunny.off")]
        mesh: PathBuf,
        /// Comma-separated subdivision levels (each multiplies the faces by 4).
        #[arg(long, default_value = "0,2,3,4")]
        levels: String,
        /// Timed runs per operator (the median is reported).
        #[arg(long, default_value_t = 9)]
        runs: u32,
    },
    /// Matérn noise: factorization and batch sampling, CHOLMOD (scikit-sparse)
    /// and cholespy vs mfm-noise on the same arrays. Installs the Python peers
    /// into their own cached environment on first use.
    Noise {
        /// Mesh file to time (and its midpoint subdivisions).
        #[arg(long, default_value = "../shared/meshes/bunny.off")]
        mesh: PathBuf,
        /// Comma-separated subdivision levels (each multiplies the faces by 4).
        #[arg(long, default_value = "0,1,2,3,4")]
        levels: String,
        /// Samples per batch (one solve with this many right-hand sides).
        #[arg(long, default_value_t = 64)]
        batch: usize,
        /// Screening weight tau of L + tau M.
        #[arg(long, default_value_t = 100.0)]
        tau: f64,
        /// Timed runs per measurement (the fastest is tabulated).
        #[arg(long, default_value_t = 3)]
        runs: usize,
    },
    /// Factor + a batch of Matérn samples end to end from Python: the `mfm`
    /// wheel against the `mfm` command line, CHOLMOD (scikit-sparse) and
    /// cholespy, in one process, round by round (the peers' cached
    /// environment of `bench noise`).
    Python {
        /// Mesh file to subdivide and time.
        #[arg(long, default_value = "../shared/meshes/bunny.off")]
        mesh: PathBuf,
        /// Midpoint subdivisions (each multiplies the faces by 4; 4 turns
        /// the bunny into 892k vertices, 1.78M faces).
        #[arg(long, default_value_t = 4)]
        subdiv: u32,
        /// Samples per batch.
        #[arg(long, default_value_t = 64)]
        batch: usize,
        /// Screening weight tau of L + tau M.
        #[arg(long, default_value_t = 100.0)]
        tau: f64,
        /// Timed rounds after a warm-up round (the fastest is tabulated).
        #[arg(long, default_value_t = 3)]
        runs: usize,
    },
    /// PoissonNet training step (forward, backward, Adam) and batch-1
    /// inference at the presets (`mfm net bench`), in rounds; with
    /// `--baseline`, interleaved with another `mfm` binary. Compared with the
    /// reference PyTorch times of docs/BENCHMARKS.md, "Reference numbers".
    Net {
        /// Mesh file or builtin:NAME.
        #[arg(long, default_value = "../shared/meshes/bunny.off")]
        mesh: String,
        /// Comma-separated presets (batch 8 for paper and medium, 4 for small).
        #[arg(long, default_value = "small,medium,paper")]
        presets: String,
        /// Rounds; each runs every preset once per binary.
        #[arg(long, default_value_t = 3)]
        rounds: usize,
        /// Timed training steps per run.
        #[arg(long, default_value_t = 4)]
        steps: usize,
        /// libtorch threads (the reference was timed with 2).
        #[arg(long, default_value_t = 2)]
        threads: usize,
        /// Another `mfm` binary (e.g. built from an older commit) to
        /// interleave with.
        #[arg(long)]
        baseline: Option<PathBuf>,
    },
    /// `mfm dataset import` of many shapes: seconds and peak memory for a
    /// folder of mesh files and for one .npy array of the same shapes.
    Import(bench_import::ImportBenchArgs),
    /// `mfm train`'s seconds per step (the whole training loop) at the
    /// `cpu` and `cpu-deform` presets on generated datasets, in rounds and,
    /// with `--baseline`, interleaved with another `mfm` binary, whose
    /// final models are compared byte for byte.
    Train {
        /// Comma-separated presets.
        #[arg(long, default_value = "cpu,cpu-deform")]
        presets: String,
        /// Rounds; each trains every preset once per binary.
        #[arg(long, default_value_t = 3)]
        rounds: usize,
        /// Training steps per run.
        #[arg(long, default_value_t = 150)]
        steps: u64,
        /// Another `mfm` binary (e.g. built from an older commit) to
        /// interleave with.
        #[arg(long)]
        baseline: Option<PathBuf>,
    },
}

fn main() -> Result<()> {
    let cli = Cli::parse();
    match cli.command {
        Cmd::Setup => {
            let env = pyenv::ensure()?;
            println!("# mfm environment ready; for plain cargo use:");
            for (k, v) in env.cargo_env() {
                println!("export {k}={}", v.display());
            }
            Ok(())
        }
        Cmd::Test { args } => {
            let env = pyenv::ensure()?;
            run(cargo(&env)
                .args(["test", "--workspace"])
                .args(&args)
                .env("MFM_REQUIRE_ORACLES", "1"))?;
            // the whole suite also checks that `mfm` builds and runs without
            // libtorch (a selection of tests, with arguments, does not)
            if args.is_empty() {
                no_network::check()?;
                // and the Python package, from Python
                python_package::check(&env, &[])?;
            }
            Ok(())
        }
        Cmd::Wheel => python_package::wheel(&pyenv::ensure()?),
        Cmd::Pytest { args } => python_package::check(&pyenv::ensure()?, &args),
        Cmd::NoNetwork => no_network::check(),
        Cmd::Lint => {
            let env = pyenv::ensure()?;
            run(cargo(&env).args(["fmt", "--all", "--", "--check"]))?;
            run(cargo(&env).args([
                "clippy",
                "--workspace",
                "--all-targets",
                "--",
                "-D",
                "warnings",
            ]))?;
            // Every publishable crate packages, in dependency order, each
            // resolving its mfm dependencies against the ones packaged
            // before it: manifests (description, license, readme), the files
            // that go in, dependency versions. Seconds: nothing is compiled
            // (`--no-verify`).
            run(cargo(&env).args([
                "publish",
                "--dry-run",
                "--workspace",
                "--no-verify",
                "--allow-dirty",
            ]))
        }
        Cmd::Reproduce(command) => mfm_reproduce::run(command),
        Cmd::Bench(BenchCmd::Operators { mesh, levels, runs }) => {
            let env = pyenv::ensure()?;
            let mesh = if mesh.is_relative() {
                root().join(mesh)
            } else {
                mesh
            };
            bench::operators(&env, &mesh, &levels, runs)
        }
        Cmd::Bench(BenchCmd::Noise {
            mesh,
            levels,
            batch,
            tau,
            runs,
        }) => {
            let mesh = if mesh.is_relative() {
                root().join(mesh)
            } else {
                mesh
            };
            bench_noise::noise(&bench_noise::NoiseBench {
                mesh: &mesh,
                levels: &levels,
                batch,
                tau,
                runs,
            })
        }
        Cmd::Bench(BenchCmd::Python {
            mesh,
            subdiv,
            batch,
            tau,
            runs,
        }) => {
            let env = pyenv::ensure()?;
            let mesh = if mesh.is_relative() {
                root().join(mesh)
            } else {
                mesh
            };
            python_package::bench(
                &env,
                &python_package::PythonBench {
                    mesh: &mesh,
                    subdiv,
                    batch,
                    tau,
                    runs,
                },
            )
        }
        Cmd::Bench(BenchCmd::Train {
            presets,
            rounds,
            steps,
            baseline,
        }) => {
            let env = pyenv::ensure()?;
            let exe = mfm_reproduce::mfm::build_release(&env)?;
            bench_train::train_steps(
                &exe,
                &bench_train::TrainBench {
                    presets: &presets,
                    rounds,
                    steps,
                    baseline: baseline.as_deref(),
                },
                &bench_train::output_dir(),
            )
        }
        Cmd::Bench(BenchCmd::Net {
            mesh,
            presets,
            rounds,
            steps,
            threads,
            baseline,
        }) => {
            let env = pyenv::ensure()?;
            let exe = mfm_reproduce::mfm::build_release(&env)?;
            let mesh = if mesh.starts_with("builtin:") || Path::new(&mesh).is_absolute() {
                mesh
            } else {
                root().join(&mesh).to_string_lossy().into_owned()
            };
            if !mesh.starts_with("builtin:") && !Path::new(&mesh).is_file() {
                anyhow::bail!(
                    "{mesh}: mesh file not found (pass --mesh PATH or builtin:blob; the default needs ../shared/meshes)"
                );
            }
            bench_net::net(
                &exe,
                &bench_net::NetBench {
                    mesh: &mesh,
                    presets: &presets,
                    rounds,
                    steps,
                    threads,
                    baseline: baseline.as_deref(),
                },
                &bench_net::output_dir(),
            )
        }
        Cmd::Bench(BenchCmd::Import(args)) => {
            let env = pyenv::ensure()?;
            bench_import::import(&env, &args)
        }
        Cmd::Mfm { args } => {
            let env = pyenv::ensure()?;
            let mfm = Mfm::build(&env);
            let status = mfm
                .command(&args)?
                .status()
                .context("cannot run the release mfm")?;
            std::process::exit(status.code().unwrap_or(1));
        }
        Cmd::VisualCheck(args) => {
            let env = pyenv::ensure()?;
            visual_check::run(&env.python, &args)
        }
    }
}
