//! `mfm train`: its arguments, the interrupt handler, and the dispatch to
//! the kind of run ([`crate::flow`], [`crate::arbitrary`]).

use std::path::PathBuf;

use anyhow::Result;
use clap::Args;
use mfm_arbitrary::markers::RunKind;
use mfm_fm::device::DeviceChoice;

/// What `mfm train` trains.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum TrainMode {
    /// A flow on one mesh (the default; `--config`/`--preset`).
    Flow,
    /// The eigenvector predictor of the arbitrary-source model, on a
    /// dataset of template shapes (`mfm dataset pairs` OUT/train).
    Predictor,
    /// The arbitrary-source flow, on a pairs dataset with a finished
    /// `--predictor` run.
    Arbitrary,
}

/// Arguments of `mfm train`.
#[derive(Args)]
pub struct TrainArgs {
    /// Run configuration (TOML; every field has a default, unknown fields
    /// are an error). Without it, --preset gives the configuration. With
    /// --mode predictor or arbitrary: the `config` object of a run's
    /// predictor.json / arbitrary.json (JSON for a .json file, else TOML),
    /// whose schedule takes every setting of the training loop (lr_schedule,
    /// ema, adam_beta1/2, adam_eps, keep_checkpoints, keep_at, log_every).
    #[arg(long, conflicts_with = "preset")]
    pub(crate) config: Option<PathBuf>,
    /// Named configuration: `cpu` (scalar signals, minutes on a laptop),
    /// `cpu-deform` (shapes: `cpu` conditioned on the source xyz, starting
    /// from the data's Gaussian fit plus fainter noise, sigma 1, 3000 steps, for `mfm
    /// dataset deform` and `mfm dataset import` data), `paper` (the
    /// authors' human-pose recipe, for a GPU) or
    /// `paper-elastic` (their elastic-deformation recipe). With --mode
    /// predictor or arbitrary: `cpu` (default) or `paper` (the official
    /// arbitrary-source configurations).
    #[arg(long)]
    pub(crate) preset: Option<String>,
    /// What to train: flow (one mesh, the default), predictor (the
    /// arbitrary-source model's eigenvector predictor, on OUT/train of
    /// `mfm dataset pairs`) or arbitrary (the arbitrary-source flow, on the
    /// same dataset, with --predictor).
    #[arg(long, value_enum, default_value = "flow")]
    pub(crate) mode: TrainMode,
    /// The finished predictor run the arbitrary-source flow conditions on
    /// (--mode arbitrary).
    #[arg(long)]
    pub(crate) predictor: Option<PathBuf>,
    /// --mode arbitrary without the predicted eigenvectors (zeros in their
    /// conditioning channels): an ablation of the positional encoding.
    #[arg(long)]
    pub(crate) no_eigenvectors: bool,
    /// Dataset folder (overrides the configuration's dataset.path).
    #[arg(long)]
    pub(crate) dataset: Option<PathBuf>,
    /// Run folder: config, log, checkpoints, final model.
    #[arg(long)]
    pub(crate) out: PathBuf,
    /// Total training steps (overrides train.steps).
    #[arg(long)]
    pub(crate) steps: Option<u64>,
    /// Seed (overrides train.seed).
    #[arg(long)]
    pub(crate) seed: Option<u64>,
    /// Noise the flow starts from (overrides noise.kind): matern:TAU,
    /// matern-normalized:C, matern-smooth:TAU:P (smoother: for sampling on
    /// much finer meshes), white, naive, explicit:K:TAU.
    #[arg(long)]
    pub(crate) noise: Option<mfm_noise::NoiseKind>,
    /// Noise amplitude sigma (overrides noise.scale): a number > 0, unit
    /// (noise of unit RMS) or data (the data's RMS).
    #[arg(long)]
    pub(crate) noise_scale: Option<mfm_fm::config::NoiseScale>,
    /// A distribution added to the noise, fitted on the training data
    /// (overrides noise.prior): none, or gaussian (the data's mean plus a
    /// draw with its covariance; the flow then learns only what that
    /// Gaussian gets wrong; README, "Train on your own shapes").
    #[arg(long)]
    pub(crate) prior: Option<mfm_fm::prior::PriorKind>,
    /// Where to train: auto (a GPU when libtorch sees one), cpu or cuda
    /// (overrides train.device; with --resume, continues the run there).
    /// With --mode predictor or arbitrary: the schedule's device, for a new
    /// run.
    #[arg(long)]
    pub(crate) device: Option<DeviceChoice>,
    /// Continue the run in --out from its newest valid checkpoint.
    #[arg(long)]
    pub(crate) resume: bool,
    /// No progress bar.
    #[arg(long)]
    pub(crate) quiet: bool,
}

/// Runs `mfm train`: the outputs checked, the folder locked, Ctrl-C
/// turned into a stop after the current step ([`crate::interrupt`]), then
/// the run of `--mode`. Exits with 130 when stopped.
pub fn train(a: TrainArgs) -> Result<()> {
    let stop = crate::interrupt::stop_training_on_interrupt(&a.out);
    if !a.resume {
        // never inside the dataset it reads, nor in a folder another command owns
        mfm_files::Outputs::new()
            .inputs(a.dataset.as_deref())
            .folder(&a.out)
            .check()?;
    }
    let lock = crate::output::lock_folder(&a.out)?;
    let stopped = match a.mode {
        TrainMode::Flow => crate::flow::train(&a, &stop)?,
        TrainMode::Predictor => crate::arbitrary::train(&a, RunKind::Predictor, &stop)?,
        TrainMode::Arbitrary => crate::arbitrary::train(&a, RunKind::Flow, &stop)?,
    };
    if stopped {
        drop(lock);
        std::process::exit(130);
    }
    Ok(())
}
