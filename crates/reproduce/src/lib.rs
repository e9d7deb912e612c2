//! # mfm-reproduce
//!
//! The paper's experiments and the demo, reproduced by driving the `mfm`
//! binary, and the workspace tooling they share with xtask. Nothing here
//! links libtorch: `mfm` trains and samples; this crate makes the data,
//! runs it, and reads its reports with the libtorch-free crates' types
//! (`mfm_eval`'s evaluation reports, `mfm_files::run_folder`'s checkpoints
//! and log).
//!
//! Commands ([`Command`]; `cargo xtask COMMAND` and `mfm-reproduce
//! COMMAND` take the same arguments):
//!
//! - `demo`: the main job on a built-in default ([`demo`]).
//! - `pretrain gmm|elephant`: the pretrained models shipped in
//!   `fixtures/pretrained` ([`pretrain`]).
//! - `time-to-quality`: sample quality against training time
//!   ([`time_to_quality`]).
//! - `reproduce-figures spectral|gmm|deform|arbitrary|own|scale`: the
//!   paper's figures and tables at CPU scale ([`figures`],
//!   [`figures_gmm`], [`figures_deform`], [`figures_arbitrary`],
//!   [`figures_own`], [`figures_scale`]).
//!
//! Tooling: [`workspace`] (the root, cargo's target folder, running
//! programs), [`pyenv`] (the Python environment with the pinned torch),
//! [`mfm`] (the release `mfm` binary, built and run).
//!
//! The command bodies are the binary's edge: they return [`anyhow`] errors
//! with the context of what failed.

pub mod demo;
pub mod figures;
pub mod figures_arbitrary;
pub mod figures_deform;
pub mod figures_gmm;
pub mod figures_own;
pub mod figures_scale;
pub mod flow_steps;
pub mod mfm;
pub mod pretrain;
pub mod pyenv;
pub mod reports;
pub mod time_to_quality;
pub mod workspace;

use anyhow::Result;
use clap::Subcommand;
use std::path::PathBuf;

/// The reproduction commands (a subcommand set of `cargo xtask` and of
/// `mfm-reproduce`).
#[derive(Subcommand)]
pub enum Command {
    /// Run the demo: the main job on a built-in default mesh.
    Demo {
        /// Output folder.
        #[arg(long, default_value = "out/demo")]
        out: PathBuf,
    },
    /// Regenerate the paper's figures (PNGs plus the numbers behind them).
    #[command(subcommand)]
    ReproduceFigures(FiguresCmd),
    /// Train and install a pretrained model shipped in fixtures/pretrained.
    #[command(subcommand)]
    Pretrain(PretrainCmd),
    /// Sample quality against training time: the demo's GMM experiment
    /// trained per network size (and recipe variant) for a time budget,
    /// sampled and evaluated at log-spaced checkpoints; resumable.
    TimeToQuality(time_to_quality::TimeToQualityArgs),
}

/// The pretrained models.
#[derive(Subcommand)]
pub enum PretrainCmd {
    /// The demo's GMM model on the built-in blob
    /// (fixtures/pretrained/gmm-blob/), sampled first by `cargo xtask demo`.
    Gmm(pretrain::PretrainArgs),
    /// The shape model: ARAP poses of ../shared/meshes/elephant.obj with
    /// smooth Matérn noise (fixtures/pretrained/elephant/), sampled by
    /// `cargo xtask demo` on a fine refinement.
    Elephant(pretrain::PretrainArgs),
}

/// The figure reproductions.
#[derive(Subcommand)]
pub enum FiguresCmd {
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

/// Runs a reproduction command; all but `reproduce-figures spectral`
/// first make sure of the Python environment ([`pyenv::ensure`]) whose
/// libtorch the release `mfm` ([`mfm::Mfm::build`]) is built against.
///
/// # Errors
/// The command's.
pub fn run(command: Command) -> Result<()> {
    if let Command::ReproduceFigures(FiguresCmd::Spectral(args)) = &command {
        return figures::spectral(args);
    }
    let env = pyenv::ensure()?;
    let mfm = mfm::Mfm::build(&env);
    match command {
        // the demo's console shows mfm's output without the command lines
        Command::Demo { out } => demo::run(&mfm.quiet(), &out),
        Command::Pretrain(PretrainCmd::Gmm(args)) => pretrain::gmm(&mfm, &args),
        Command::Pretrain(PretrainCmd::Elephant(args)) => pretrain::elephant(&mfm, &args),
        Command::TimeToQuality(args) => time_to_quality::run(&mfm, &args),
        Command::ReproduceFigures(figures) => match figures {
            FiguresCmd::Spectral(args) => figures::spectral(&args),
            FiguresCmd::Gmm(args) => figures_gmm::gmm(&mfm, &args),
            FiguresCmd::Deform(args) => figures_deform::deform(&mfm, &args),
            FiguresCmd::Arbitrary(args) => figures_arbitrary::arbitrary(&mfm, &args),
            FiguresCmd::Own(args) => figures_own::own(&mfm, &args),
            FiguresCmd::Scale(args) => figures_scale::scale(&mfm, &args),
        },
    }
}
