//! The subcommands.

use anyhow::Result;
use clap::Subcommand;

/// Every `mfm` subcommand.
#[derive(Subcommand)]
pub enum Command {
    /// Print a report of a mesh: counts, topology, area, quality, problems found.
    Info(crate::mesh::InfoArgs),
    /// Write the mesh operators: L.mtx, G.mtx (Matrix Market), mass.npy,
    /// face_areas.npy and summary.json (with Gamma = ||M^-1 L||_F).
    Operators(crate::mesh::OperatorsArgs),
    /// Convert a mesh to OBJ or PLY (by the output extension).
    Convert(crate::mesh::ConvertArgs),
    /// Render a mesh to PNG, optionally colored by a per-vertex scalar.
    Render(crate::mesh::RenderArgs),
    /// The K smallest eigenpairs of L phi = lambda M phi: eigenvalues.npy (K
    /// values), eigenvectors.npy (V x K, M-orthonormal columns), summary.json.
    Eigs(crate::spectral::EigsArgs),
    /// Sample noise on a mesh: OUT.npy [samples, vertices, channels] (f64),
    /// OUT.json (parameters, Gamma, mean energy) and optionally a PNG of the
    /// first sample.
    Noise(crate::spectral::NoiseArgs),
    /// Spectral statistics of noise on one or several meshes: per-frequency
    /// variance against theory, independence, energy, and (from the second
    /// mesh on) per-frequency W2 against the first mesh.
    Spectrum(crate::spectral::SpectrumArgs),
    /// Generate a dataset of signals over a mesh.
    #[command(subcommand)]
    Dataset(crate::dataset::DatasetCommand),
    /// Train a flow-matching model on a dataset (checkpoints, resumable;
    /// Ctrl-C writes a checkpoint).
    #[cfg(feature = "network")]
    Train(crate::train::TrainArgs),
    /// Train a flow-matching model (needs the `network` feature).
    #[cfg(not(feature = "network"))]
    Train(crate::unavailable::Unavailable),
    /// Generate signals with a trained run on any triangulation of the
    /// training surface.
    #[cfg(feature = "network")]
    Sample(crate::sample::SampleArgs),
    /// Generate signals with a trained run (needs the `network` feature).
    #[cfg(not(feature = "network"))]
    Sample(crate::unavailable::Unavailable),
    /// Metrics of generated samples against a reference dataset: MMD, COV,
    /// 1-NNA, GMM test error.
    Eval(crate::eval::EvalArgs),
    /// Evaluate an arbitrary-source run on the held-out shapes of a pairs
    /// experiment (`mfm dataset pairs` OUT): projection onto each source's
    /// own deformation space, displacement, pose spread, MMD/COV, the
    /// predictor's error; on OUT/holdout (the template's triangulation) and
    /// OUT/reference (another triangulation), with pictures.
    #[cfg(feature = "network")]
    EvalArbitrary(crate::arbitrary::EvalArgs),
    /// Evaluate an arbitrary-source run (needs the `network` feature).
    #[cfg(not(feature = "network"))]
    EvalArbitrary(crate::unavailable::Unavailable),
    /// PoissonNet: layer tables of the presets and training-step benchmarks.
    #[cfg(feature = "network")]
    #[command(subcommand)]
    Net(crate::net::NetCommand),
    /// PoissonNet tables and benchmarks (needs the `network` feature).
    #[cfg(not(feature = "network"))]
    Net(crate::unavailable::Unavailable),
    /// Import a pretrained model of the official Matérn-FM code (a Lightning
    /// .ckpt and its YAML config) as an mfm run folder that `mfm sample` and
    /// `mfm eval` use.
    #[cfg(feature = "network")]
    Import(crate::official::ImportArgs),
    /// Import an official checkpoint (needs the `network` feature).
    #[cfg(not(feature = "network"))]
    Import(crate::unavailable::Unavailable),
    /// Write a run's weights under the official names, as a checkpoint the
    /// official Matérn-FM code loads.
    #[cfg(feature = "network")]
    ExportWeights(crate::official::ExportArgs),
    /// Export a run's weights (needs the `network` feature).
    #[cfg(not(feature = "network"))]
    ExportWeights(crate::unavailable::Unavailable),
    /// Another triangulation of a mesh's surface: midpoint subdivision, and
    /// damage (holes, a partial cut, edge flips) that spares the handle
    /// regions of a deformation space.
    Remesh(crate::mesh::RemeshArgs),
}

/// Runs one subcommand.
pub fn run(cmd: Command) -> Result<()> {
    if !matches!(cmd, Command::Train(_)) {
        crate::output::clean_up_on_interrupt();
    }
    match cmd {
        Command::Info(a) => a.run(),
        Command::Operators(a) => a.run(),
        Command::Convert(a) => a.run(),
        Command::Render(a) => a.run(),
        Command::Eigs(a) => a.run(),
        Command::Noise(a) => a.run(),
        Command::Spectrum(a) => a.run(),
        Command::Dataset(cmd) => crate::dataset::dataset(cmd),
        Command::Eval(args) => crate::eval::eval(args),
        Command::Remesh(a) => a.run(),
        #[cfg(feature = "network")]
        Command::Train(args) => crate::train::train(args),
        #[cfg(feature = "network")]
        Command::Sample(args) => crate::sample::sample(args),
        #[cfg(feature = "network")]
        Command::Net(cmd) => crate::net::run(cmd),
        #[cfg(feature = "network")]
        Command::EvalArbitrary(args) => crate::arbitrary::eval(args),
        #[cfg(feature = "network")]
        Command::Import(args) => crate::official::import(args),
        #[cfg(feature = "network")]
        Command::ExportWeights(args) => crate::official::export(args),
        #[cfg(not(feature = "network"))]
        Command::Train(_) => crate::unavailable::fail("train"),
        #[cfg(not(feature = "network"))]
        Command::Sample(_) => crate::unavailable::fail("sample"),
        #[cfg(not(feature = "network"))]
        Command::Net(_) => crate::unavailable::fail("net"),
        #[cfg(not(feature = "network"))]
        Command::EvalArbitrary(_) => crate::unavailable::fail("eval-arbitrary"),
        #[cfg(not(feature = "network"))]
        Command::Import(_) => crate::unavailable::fail("import"),
        #[cfg(not(feature = "network"))]
        Command::ExportWeights(_) => crate::unavailable::fail("export-weights"),
    }
}
