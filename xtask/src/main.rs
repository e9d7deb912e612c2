//! Project automation: `cargo xtask <command>`.
//!
//! - `setup`: create (once) the Python environment with the pinned torch whose
//!   libtorch `tch` links against, and the test oracles; print the variables to
//!   export for plain `cargo` use.
//! - `test`: setup, then every test of the workspace (oracle tests may not skip);
//!   without arguments also the `no-network` check.
//! - `lint`: `cargo fmt --check` and `cargo clippy --all-targets -D warnings`.
//! - `no-network`: `mfm` built without libtorch links none and runs.
//! - `demo`: the main job on a built-in default.
//! - `bench operators`: operator assembly times, ours and libigl's, in one run.
//! - `bench noise`: Matérn sampling, ours against CHOLMOD and cholespy, in one run.
//! - `bench net`: PoissonNet training steps and inference at the three presets, in
//!   interleaved rounds (optionally against a baseline `mfm`), next to the reference times.
//! - `bench import`: `mfm dataset import` of many shapes, seconds and peak
//!   memory.
//! - `reproduce-figures gmm`: the paper's GMM table at CPU scale (noise
//!   kinds compared on a non-uniform test mesh).
//! - `reproduce-figures deform`: the paper's deformation experiments at CPU
//!   scale (noise ablation, generalization, resolutions, robustness).
//! - `reproduce-figures spectral`: the paper's noise figures (per-frequency
//!   statistics, spectrum, fixed vs normalized tau, noise on a non-uniform
//!   triangulation) and the numbers behind them, from scratch.
//! - `reproduce-figures own`: the own-data path (import, train, sample on a
//!   finer mesh, evaluate without a generator) on folders of shapes.
//! - `mfm ARGS...`: build the release `mfm` with the project's libtorch and
//!   run it.
//! - `visual-check DIR`: PNG contact sheets of the PLY files under DIR,
//!   rendered offscreen with pyvista.

mod bench;
mod bench_import;
mod bench_net;
mod bench_noise;
mod demo;
mod figures;
mod figures_arbitrary;
mod figures_deform;
mod figures_gmm;
mod figures_own;
mod figures_scale;
mod flow_steps;
mod no_network;
mod pretrain;
mod pyenv;
mod python_package;
mod time_to_quality;
mod visual_check;

use anyhow::{Context, Result, bail};
use clap::{Parser, Subcommand};
use std::path::{Path, PathBuf};
use std::process::Command;

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
    /// Run the demo: the main job on a built-in default mesh.
    Demo {
        /// Output folder.
        #[arg(long, default_value = "out/demo")]
        out: PathBuf,
    },
    /// Benchmarks against the Python reference stack, in one run.
    #[command(subcommand)]
    Bench(BenchCmd),
    /// Regenerate the paper's figures (PNGs plus the numbers behind them).
    #[command(subcommand)]
    ReproduceFigures(FiguresCmd),
    /// Build the release `mfm` binary with the project's libtorch and run it
    /// with the given arguments (e.g. `cargo xtask mfm -- net summary`), in
    /// the current folder.
    Mfm {
        /// Arguments passed to `mfm`.
        #[arg(trailing_var_arg = true, allow_hyphen_values = true)]
        args: Vec<String>,
    },
    /// Train and install a pretrained model shipped in fixtures/pretrained.
    #[command(subcommand)]
    Pretrain(PretrainCmd),
    /// Sample quality against training time: the demo's GMM experiment
    /// trained per network size (and recipe variant) for a time budget,
    /// sampled and evaluated at log-spaced checkpoints; resumable.
    TimeToQuality(time_to_quality::TimeToQualityArgs),
    /// Render the PLY files under DIR offscreen with pyvista into PNG contact
    /// sheets (one per folder; signals as colors, plain meshes shaded).
    VisualCheck(visual_check::VisualCheckArgs),
}

#[derive(Subcommand)]
enum PretrainCmd {
    /// The demo's GMM model on the built-in blob
    /// (fixtures/pretrained/gmm-blob/), sampled first by `cargo xtask demo`.
    Gmm(pretrain::PretrainArgs),
    /// The shape model: ARAP poses of ../shared/meshes/elephant.obj with
    /// smooth Matérn noise (fixtures/pretrained/elephant/), sampled by
    /// `cargo xtask demo` on a fine refinement.
    Elephant(pretrain::PretrainArgs),
}

#[derive(Subcommand)]
enum FiguresCmd {
    /// Noise figures of paper section 3: per-frequency statistics, spectrum,
    /// fixed vs normalized tau, noise on a non-uniform triangulation.
    Spectral(figures::SpectralArgs),
    /// The paper's GMM table at CPU scale: matern vs white vs naive noise,
    /// trained on a uniform mesh, evaluated on a non-uniform one.
    Gmm(figures_gmm::GmmArgs),
    /// The paper's deformation experiments at CPU scale: ARAP poses of a real
    /// mesh, noise ablation table, generalization, generation across
    /// resolutions, robustness to holes, partial meshes and edge flips.
    Deform(figures_deform::DeformArgs),
    /// The paper's arbitrary-source model at CPU scale: body shapes x
    /// poses of a humanoid, the eigenvector predictor and the conditioned
    /// flow, evaluated on unseen shapes of the template and of another
    /// triangulation (and on another object).
    Arbitrary(figures_arbitrary::ArbitraryArgs),
    /// Your own shapes, the path of the README's "Train on your own
    /// shapes": import a folder (default: the shared real sequences),
    /// train, sample on a finer mesh, evaluate without a generator; a
    /// report with pictures.
    Own(figures_own::OwnArgs),
    /// A shape model far beyond its training resolution: the shipped
    /// elephant model on its training mesh and up to 5 rounds of midpoint
    /// subdivision (3.07M faces), seconds per sample, peak memory and
    /// pictures of the same samples at every level.
    Scale(figures_scale::ScaleArgs),
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
}

/// The workspace root (parent of this crate's folder).
pub fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .map(Path::to_path_buf)
        .unwrap_or_else(|| PathBuf::from("."))
}

/// Cargo's target folder: `CARGO_TARGET_DIR` (relative to the workspace root)
/// or `target/` in the workspace root.
pub fn target_dir() -> PathBuf {
    match std::env::var_os("CARGO_TARGET_DIR") {
        Some(dir) => root().join(dir),
        None => root().join("target"),
    }
}

/// A `cargo` command in the workspace root with the environment applied.
pub fn cargo(env: &pyenv::PyEnv) -> Command {
    let mut cmd = Command::new(std::env::var("CARGO").unwrap_or_else(|_| "cargo".to_owned()));
    cmd.current_dir(root());
    for (k, v) in env.cargo_env() {
        cmd.env(k, v);
    }
    cmd
}

/// Runs a command, failing with its status.
pub fn run(cmd: &mut Command) -> Result<()> {
    let status = cmd
        .status()
        .with_context(|| format!("cannot run {cmd:?}"))?;
    if !status.success() {
        bail!("command failed ({status}): {cmd:?}");
    }
    Ok(())
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
        Cmd::Pretrain(PretrainCmd::Gmm(args)) => {
            let env = pyenv::ensure()?;
            pretrain::gmm(&env, &args)
        }
        Cmd::Pretrain(PretrainCmd::Elephant(args)) => {
            let env = pyenv::ensure()?;
            pretrain::elephant(&env, &args)
        }
        Cmd::TimeToQuality(args) => {
            let env = pyenv::ensure()?;
            time_to_quality::run(&env, &args)
        }
        Cmd::Demo { out } => {
            let env = pyenv::ensure()?;
            demo::run(&env, &out)
        }
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
        Cmd::Bench(BenchCmd::Net {
            mesh,
            presets,
            rounds,
            steps,
            threads,
            baseline,
        }) => {
            let env = pyenv::ensure()?;
            let exe = demo::mfm_binary(&env)?;
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
        Cmd::ReproduceFigures(FiguresCmd::Spectral(args)) => figures::spectral(&args),
        Cmd::ReproduceFigures(FiguresCmd::Gmm(args)) => {
            let env = pyenv::ensure()?;
            figures_gmm::gmm(&env, &args)
        }
        Cmd::ReproduceFigures(FiguresCmd::Deform(args)) => {
            let env = pyenv::ensure()?;
            figures_deform::deform(&env, &args)
        }
        Cmd::ReproduceFigures(FiguresCmd::Arbitrary(args)) => {
            let env = pyenv::ensure()?;
            figures_arbitrary::arbitrary(&env, &args)
        }
        Cmd::ReproduceFigures(FiguresCmd::Scale(args)) => {
            let env = pyenv::ensure()?;
            figures_scale::scale(&env, &args)
        }
        Cmd::ReproduceFigures(FiguresCmd::Own(args)) => {
            let env = pyenv::ensure()?;
            figures_own::own(&env, &args)
        }
        Cmd::Mfm { args } => {
            let env = pyenv::ensure()?;
            let exe = demo::mfm_binary(&env)?;
            let status = Command::new(&exe)
                .args(&args)
                .status()
                .with_context(|| format!("cannot run {}", exe.display()))?;
            std::process::exit(status.code().unwrap_or(1));
        }
        Cmd::VisualCheck(args) => {
            let env = pyenv::ensure()?;
            visual_check::run(&env.python, &args)
        }
    }
}
