//! `cargo xtask pretrain gmm` and `cargo xtask pretrain elephant`: the
//! pretrained models the demo samples.
//!
//! Trains the GMM blob model that `cargo xtask demo` samples from first
//! (the demo's dataset: Gaussian-bump signals on the built-in blob, seed 0)
//! with [`pretrain_config`], evaluates it on the demo's test mesh, and
//! installs the run into `fixtures/pretrained/gmm-blob/`: `config.toml`,
//! `flow.json`, `model.safetensors` with `model.json` and the checksums in
//! `model.state.json`, `train_log.csv`, and `README.md` with the command,
//! the training time and the measured quality. The folder is replaced whole
//! (written beside it, then renamed), so an interrupted pretraining leaves
//! the shipped model as it was. Training resumes when the scratch run
//! folder (`out/pretrain/gmm/run`) already holds checkpoints.

use crate::flow_steps::{Quality, arg, train_args};
use crate::mfm::Mfm;
use crate::reports::EvalReport;
use crate::workspace::{self, in_root};
use anyhow::{Context, Result, bail};
use mfm_files::run_folder;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// Where the pretrained model lives, relative to the workspace root.
pub const PRETRAINED_DIR: &str = "fixtures/pretrained/gmm-blob";

/// The files of a run folder that make up the pretrained model.
pub const MODEL_FILES: [&str; 6] = [
    "config.toml",
    "flow.json",
    "model.safetensors",
    "model.json",
    "model.state.json",
    "train_log.csv",
];

/// Training signals of the pretraining dataset: the demo's 1000 (the same
/// generator, seed and count).
pub const PRETRAIN_SIGNALS: usize = 1000;

/// Steps of the pretrained GMM model.
pub const PRETRAIN_STEPS: u64 = 5000;

/// The GMM blob recipe, the pretrained model's and the demo's run
/// configuration, trained for `steps` steps: the `cpu` preset's recipe (see
/// `RunConfig::preset("cpu")`: the official loss, sampling with the weight
/// average, and the two changes that won the controlled runs of
/// docs/BENCHMARKS.md, "Training beyond the paper") at width 32, 3 blocks:
/// a linear warm-up over 250 steps to a peak rate of 4e-3, then a cosine
/// decay to 1e-5 at the last step, and path times drawn from a
/// logit-normal instead of the uniform. `threads` pins the thread count (a
/// run is a pure function of its seed, data and thread count, so a pinned
/// run makes the same weights again); `comment` is the file's first line.
pub fn gmm_config(comment: &str, steps: u64, threads: Option<usize>) -> String {
    let threads = threads.map_or_else(String::new, |t| format!("threads = {t}\n"));
    format!(
        "\
# {comment}
[model]
preset = \"small\"
width = 32
blocks = 3
vector_layers = 3

[train]
steps = {steps}
batch = 4
lr = 4e-3
lr_schedule = {{ warmup = 250, cosine = {steps}, floor = 1e-5 }}
ema = 0.999
time = \"logit-normal\"
{threads}checkpoint_every = 500
log_every = 100
"
    )
}

/// The pretrained model's run configuration: [`gmm_config`] for
/// [`PRETRAIN_STEPS`] steps on one thread, so that the command makes the
/// same weights again.
pub fn pretrain_config() -> String {
    gmm_config(
        "cargo xtask pretrain gmm: the pretrained demo model",
        PRETRAIN_STEPS,
        Some(1),
    )
}

/// Arguments of `cargo xtask pretrain gmm` (and `elephant`).
// the field's doc is also its `--help` text, where `<model>` reads as meant
#[allow(rustdoc::invalid_html_tags)]
#[derive(clap::Args)]
pub struct PretrainArgs {
    /// Scratch folder of the dataset and the run (default:
    /// out/pretrain/<model>).
    #[arg(long)]
    pub out: Option<PathBuf>,
}

/// Trains, evaluates and installs the pretrained GMM model.
///
/// # Errors
/// When a step fails.
pub fn gmm(mfm: &Mfm, args: &PretrainArgs) -> Result<()> {
    let out = in_root(args.out.as_deref().unwrap_or(Path::new("out/pretrain/gmm")));
    std::fs::create_dir_all(&out).with_context(|| format!("cannot create {}", out.display()))?;
    mfm.exe()?;
    let data = out.join("data");
    mfm.ensure_gmm_dataset(&data, PRETRAIN_SIGNALS)?;
    let config = out.join("run.toml");
    std::fs::write(&config, pretrain_config())
        .with_context(|| format!("cannot write {}", config.display()))?;
    let run = out.join("run");
    let train_seconds = train_or_resume(mfm, &config, &data.join("train"), &run)?;

    // the demo's evaluation: 64 samples on the test mesh, seed 7
    let samples = out.join("samples");
    if samples.exists() {
        std::fs::remove_dir_all(&samples)
            .with_context(|| format!("cannot remove {}", samples.display()))?;
    }
    let test_mesh = data.join("reference/mesh.ply");
    mfm.sample(&run, &test_mesh, 64, 7, &samples, &["--ply", "0"])?;
    let reference = arg(&data.join("reference"));
    let metrics: EvalReport = mfm.eval(
        &samples.join("samples.npy"),
        &["--reference", &reference],
        &out.join("metrics.json"),
        Some(&out.join("means.png")),
    )?;
    let q = Quality::of(Quality::section(&metrics)?);

    let target = install(&run, PRETRAINED_DIR, &|| -> Result<String> {
        let mut md = String::new();
        writeln!(md, "# Pretrained GMM model on the built-in blob\n")?;
        writeln!(
            md,
            "Made by `cargo xtask pretrain gmm` ({PRETRAIN_SIGNALS} training signals of \
             `mfm dataset gmm --seed 0` on `builtin:blob`, the run configuration in \
             `config.toml`, the log in `train_log.csv`): {train_seconds:.0} s of training \
             on the project's 2-core machine. `cargo xtask demo` samples from it first.\n"
        )?;
        writeln!(
            md,
            "Quality of 64 samples (seed 7) on the demo's 6635-vertex test mesh, by \
             `mfm eval` against 100 reference signals:\n"
        )?;
        writeln!(
            md,
            "| residual median [q1, q3] | peak median | bumps > 1/2 | data-like | diversity | MMD | COV | 1-NNA | test error |\n|---|---|---|---|---|---|---|---|---|"
        )?;
        writeln!(
            md,
            "| {} | {:.4} | {:.3} | {:.3} | {:.4} |",
            q.cells(),
            metrics.metrics.mmd,
            metrics.metrics.cov,
            metrics.metrics.one_nna,
            metrics.metrics.test_error
        )?;
        Ok(md)
    })?;
    println!(
        "pretrained model installed in {} (residual {:.3}, peak {:.2}, {:.2} bumps per sample)",
        target.display(),
        q.residual[1],
        q.peak[1],
        q.bumps
    );
    Ok(())
}

/// Copies the model files of `run` and the `README.md` that `readme`
/// writes into `fixtures/pretrained/<dir>` (a path relative to the
/// workspace root), replacing the folder whole: it is filled beside it,
/// then renamed, so an interruption leaves the shipped model as it was.
fn install(run: &Path, dir: &str, readme: &dyn Fn() -> Result<String>) -> Result<PathBuf> {
    let target = workspace::root().join(dir);
    let parent = target
        .parent()
        .context("the pretrained folder has a parent")?;
    let name = target
        .file_name()
        .context("the pretrained folder has a name")?
        .to_string_lossy()
        .into_owned();
    std::fs::create_dir_all(parent)
        .with_context(|| format!("cannot create {}", parent.display()))?;
    let staging = parent.join(format!(".{name}.tmp-{}", std::process::id()));
    if staging.exists() {
        std::fs::remove_dir_all(&staging)?;
    }
    std::fs::create_dir(&staging)
        .with_context(|| format!("cannot create {}", staging.display()))?;
    let fill = || -> Result<()> {
        for name in MODEL_FILES {
            std::fs::copy(run.join(name), staging.join(name))
                .with_context(|| format!("cannot copy {} from {}", name, run.display()))?;
        }
        std::fs::write(staging.join("README.md"), readme()?)?;
        Ok(())
    };
    if let Err(e) = fill() {
        let _ = std::fs::remove_dir_all(&staging);
        return Err(e);
    }
    if target.exists() {
        std::fs::remove_dir_all(&target)
            .with_context(|| format!("cannot replace {}", target.display()))?;
    }
    std::fs::rename(&staging, &target)
        .with_context(|| format!("cannot install {}", target.display()))?;
    Ok(target)
}

/// Trains `config` on `dataset` into `run`, resuming a run that has
/// checkpoints and leaving a finished one alone; returns the training's
/// seconds from its log.
fn train_or_resume(mfm: &Mfm, config: &Path, dataset: &Path, run: &Path) -> Result<f64> {
    if run.join("model.safetensors").is_file() {
        println!("{} is trained already", run.display());
    } else {
        mfm.run(&train_args(run, config, dataset))?;
    }
    let log = run_folder::read_log(run)?;
    let last = log
        .last()
        .with_context(|| format!("the log of {} has no rows", run.display()))?;
    Ok(last.seconds)
}

/// Where the pretrained shape model lives, relative to the workspace root.
pub const ELEPHANT_DIR: &str = "fixtures/pretrained/elephant";

/// The shape the elephant model is trained on, relative to the workspace
/// root (the shared meshes are not part of the repository).
pub const ELEPHANT_MESH: &str = "../shared/meshes/elephant.obj";

/// The elephant model's run configuration: the `cpu-deform` preset (W32
/// K3 conditioned on the source xyz, warm-up and cosine decay to 1e-5,
/// logit-normal times, weight average, 5 midpoint steps to sample) as it
/// was before its data prior (the model starts from noise alone), with
/// smooth Matérn noise, whose samples keep no noise texture on meshes many
/// times finer (docs/BENCHMARKS.md, "Noise texture and cost against
/// resolution"), for 6000 steps instead of the preset's 3000 (the poses
/// come closer to the deformation space and keep their spread: "The
/// pretrained shape model and the elephant's coverage"), on one thread so
/// that the command makes the same weights again.
pub const ELEPHANT_CONFIG: &str = "\
# cargo xtask pretrain elephant: the pretrained shape model
[model]
preset = \"small\"
width = 32
blocks = 3
vector_layers = 3
condition_on_xyz = true

[noise]
kind = \"matern-smooth:100:2\"
scale = 3.0

[train]
steps = 6000
batch = 4
lr = 4e-3
lr_schedule = { warmup_fraction = 0.05, floor = 1e-5 }
ema = 0.999
time = \"logit-normal\"
threads = 1
checkpoint_every = 1000
log_every = 10

[sample]
steps = 5
";

/// Trains, evaluates and installs the pretrained elephant model: ARAP
/// poses of `../shared/meshes/elephant.obj` (`mfm dataset deform`, its
/// defaults: 400 training shapes on a 3000-face mesh, 100 held out),
/// [`ELEPHANT_CONFIG`], judged by 32 samples on the non-uniform evaluation
/// mesh against the held-out shapes.
///
/// # Errors
/// When the shared elephant mesh is not there, or a step fails.
pub fn elephant(mfm: &Mfm, args: &PretrainArgs) -> Result<()> {
    let mesh = workspace::root().join(ELEPHANT_MESH);
    if !mesh.is_file() {
        bail!(
            "{} not found: the elephant model is trained on the shared meshes, \
             which are not part of the repository",
            mesh.display()
        );
    }
    let out = in_root(
        args.out
            .as_deref()
            .unwrap_or(Path::new("out/pretrain/elephant")),
    );
    std::fs::create_dir_all(&out).with_context(|| format!("cannot create {}", out.display()))?;
    mfm.exe()?;
    let data = out.join("data");
    if !data.join("train").is_dir() {
        mfm.run(&[
            "dataset",
            "deform",
            "--mesh",
            &arg(&mesh),
            "--out",
            &arg(&data),
        ])?;
    }
    let config = out.join("run.toml");
    std::fs::write(&config, ELEPHANT_CONFIG)
        .with_context(|| format!("cannot write {}", config.display()))?;
    let run = out.join("run");
    let train_seconds = train_or_resume(mfm, &config, &data.join("train"), &run)?;
    let samples = out.join("samples");
    if samples.exists() {
        std::fs::remove_dir_all(&samples)
            .with_context(|| format!("cannot remove {}", samples.display()))?;
    }
    mfm.sample(
        &run,
        &data.join("eval.ply"),
        32,
        7,
        &samples,
        &["--ply", "0"],
    )?;
    let metrics: EvalReport = mfm.eval(
        &samples.join("samples.npy"),
        &["--reference", &arg(&data)],
        &out.join("metrics.json"),
        Some(&out.join("eval.png")),
    )?;
    let shapes = metrics.shapes.as_ref().with_context(|| {
        format!(
            "{}: the evaluation has no projection (mfm eval on a deformation set writes one)",
            out.join("metrics.json").display()
        )
    })?;
    let target = install(&run, ELEPHANT_DIR, &|| -> Result<String> {
        let mut md = String::new();
        writeln!(md, "# Pretrained shape model: elephant poses\n")?;
        writeln!(
            md,
            "Made by `cargo xtask pretrain elephant`: `mfm dataset deform` of \
             `../shared/meshes/elephant.obj` (its defaults: 400 as-rigid-as-possible poses \
             on a 3000-face mesh, seed 0), the run configuration in `config.toml` (the \
             `cpu-deform` recipe with `matern-smooth:100:2` noise, for 6000 steps), the log in \
             `train_log.csv`: {train_seconds:.0} s of training on one thread of the \
             project's 2-core machine. `cargo xtask demo` samples it on the training \
             mesh and on a 768k-face refinement of it when the shared meshes are there.\n"
        )?;
        writeln!(
            md,
            "Quality of 32 samples (seed 7) on the dataset's non-uniform evaluation mesh, by \
             `mfm eval` against the 100 held-out poses:\n"
        )?;
        writeln!(
            md,
            "| projection MSE (median) | rotation spread / data's | translation spread / data's | MMD | COV | 1-NNA |\n|---|---|---|---|---|---|"
        )?;
        writeln!(
            md,
            "| {:.3e} | {:.2} | {:.2} | {:.4} | {:.3} | {:.3} |",
            shapes.projection_mse_median,
            shapes.spread_ratio.rotation,
            shapes.spread_ratio.translation,
            metrics.metrics.mmd,
            metrics.metrics.cov,
            metrics.metrics.one_nna,
        )?;
        Ok(md)
    })?;
    println!("pretrained shape model installed in {}", target.display());
    Ok(())
}

/// The shipped pretrained GMM model folder, checked for its files.
///
/// # Errors
/// When a file of [`MODEL_FILES`] is missing.
pub fn shipped() -> Result<PathBuf> {
    shipped_at(PRETRAINED_DIR, "gmm")
}

/// The pretrained model folder `dir` (relative to the workspace root),
/// checked for its files; `model` names the `cargo xtask pretrain`
/// subcommand that makes it.
///
/// # Errors
/// When a file of [`MODEL_FILES`] is missing.
pub fn shipped_at(dir: &str, model: &str) -> Result<PathBuf> {
    let dir = workspace::root().join(dir);
    for name in MODEL_FILES {
        if !dir.join(name).is_file() {
            bail!(
                "the pretrained model {} lacks {name}: run `cargo xtask pretrain {model}`",
                dir.display()
            );
        }
    }
    Ok(dir)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_demo_and_the_pretrained_model_share_one_recipe() {
        let (demo, pretrained) = (crate::demo::demo_config(), pretrain_config());
        assert!(pretrained.contains("\nthreads = 1\n") && !demo.contains("threads"));
        assert!(
            pretrained.contains("\nlr_schedule = { warmup = 250, cosine = 5000, floor = 1e-5 }\n")
        );
        // besides the thread count, only the first line and the step count
        // (where the decay ends) differ
        let pretrained = pretrained.replace("threads = 1\n", "");
        let differing: Vec<(&str, &str)> = demo
            .lines()
            .zip(pretrained.lines())
            .filter(|(a, b)| a != b)
            .collect();
        assert_eq!(demo.lines().count(), pretrained.lines().count());
        assert_eq!(
            differing[1..],
            [
                ("steps = 2000", "steps = 5000"),
                (
                    "lr_schedule = { warmup = 250, cosine = 2000, floor = 1e-5 }",
                    "lr_schedule = { warmup = 250, cosine = 5000, floor = 1e-5 }"
                )
            ]
        );
        assert!(differing[0].0.starts_with("# mfm demo run"));
    }
}
