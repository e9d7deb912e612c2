//! `mfm sample`: its arguments, the starting noise of `--x0`, and the
//! dispatch to the kind of run ([`crate::flow`], [`crate::arbitrary`]).

use std::path::{Path, PathBuf};

use anyhow::{Result, bail};
use clap::Args;
use mfm_fm::config::OdeMethod;
use mfm_fm::device::DeviceChoice;
use mfm_fm::sample::SAMPLE_FILES;
use mfm_fm::sample_folder::check_output_folder;

/// Arguments of `mfm sample`.
#[derive(Args)]
pub struct SampleArgs {
    /// Run folder written by `mfm train` (its final model, or its newest
    /// checkpoint).
    #[arg(long)]
    pub(crate) run: PathBuf,
    /// Mesh to generate on: any triangulation of the training surface.
    #[arg(long, required_unless_present = "source", conflicts_with = "source")]
    pub(crate) mesh: Option<crate::mesh::MeshSpec>,
    /// Source mesh of an arbitrary-source run (`mfm train --mode
    /// arbitrary`): any mesh of a shape like the template's, of any
    /// triangulation; targets are generated over it.
    #[arg(long)]
    pub(crate) source: Option<crate::mesh::MeshSpec>,
    /// Number of samples (with --x0: the file's count).
    #[arg(long, default_value_t = 16)]
    pub(crate) n: usize,
    /// Start the ODE from these noises instead of drawing them: a .npy of
    /// shape [N, V, C] (float32 or float64; V the --mesh's vertices, C the
    /// run's channels), used as given (not scaled or centred), in the run's
    /// training frame (the identity for `mfm import`ed runs). Gives N
    /// samples; --seed is then unused.
    #[arg(long, conflicts_with_all = ["n", "source", "seed"])]
    pub(crate) x0: Option<PathBuf>,
    /// Draw the starting noise on this mesh (the run's training mesh, or any
    /// coarser triangulation of the --mesh surface, in the same units) and
    /// carry it to --mesh (closest point, barycentric weights): samples on
    /// a fine mesh that start from the very noise of the same seed's
    /// samples on the coarse one, without the frequencies the coarse mesh
    /// cannot hold.
    #[arg(long, value_name = "MESH", conflicts_with_all = ["x0", "source"])]
    pub(crate) noise_from: Option<crate::mesh::MeshSpec>,
    /// ODE steps (default: the run's sample.steps).
    #[arg(long)]
    pub(crate) steps: Option<usize>,
    /// Integrator: midpoint or euler (default: the run's).
    #[arg(long)]
    pub(crate) method: Option<OdeMethod>,
    /// Where to run the network: auto (a GPU when libtorch sees one), cpu
    /// or cuda. Samples agree across devices up to round-off.
    #[arg(long, default_value = "auto")]
    pub(crate) device: DeviceChoice,
    /// Seed of the initial noise.
    #[arg(long, default_value_t = 0)]
    pub(crate) seed: u64,
    /// Output folder: samples.npy [N, V, C] (f32), mesh.ply, the first
    /// --ply samples as PLY, samples.png, timing.json.
    #[arg(long)]
    pub(crate) out: PathBuf,
    /// How many samples to also write as PLY files.
    #[arg(long, default_value_t = 4)]
    pub(crate) ply: usize,
    /// Sample from the run's checkpoint of this step (its weight average
    /// when the run has one) instead of its final model: the snapshots
    /// `train.keep_at` keeps, for curves of quality against training.
    #[arg(long)]
    pub(crate) step: Option<u64>,
    /// With --step: the checkpoint's trained weights, not its weight
    /// average (runs with train.ema keep both).
    #[arg(long, requires = "step")]
    pub(crate) raw_weights: bool,
    /// Write into a non-empty --out folder: replaces only what `mfm sample`
    /// writes (samples.npy, mesh.ply, samples.png, timing.json,
    /// sample_NNN.ply, stale ones of an earlier run included).
    #[arg(long)]
    pub(crate) force: bool,
}

/// Reads the `--x0` starting noise: a float `[N, V, C]` `.npy`.
fn read_start_noise(path: &Path) -> Result<mfm_fm::sample::StartNoise> {
    let array = mfm_files::npy::read::<f32>(path)?;
    let shape = array.shape.clone();
    let [n, v, c] = shape[..] else {
        bail!(
            "--x0 {}: shape {shape:?}; starting noise must be [samples, vertices, channels]",
            path.display()
        );
    };
    if n == 0 || v == 0 || c == 0 {
        bail!("--x0 {}: shape {shape:?} holds no noise", path.display());
    }
    let values = array.values;
    if let Some(i) = values.iter().position(|x| !x.is_finite()) {
        bail!(
            "--x0 {}: value {} (sample {}, vertex {}, channel {}) is not finite",
            path.display(),
            values[i],
            i / (v * c),
            (i / c) % v,
            i % c
        );
    }
    Ok(mfm_fm::sample::StartNoise {
        values,
        shape: [n, v, c],
    })
}

/// Runs `mfm sample`: the arguments and the output folder checked and
/// locked, then the run's kind samples ([`crate::flow`],
/// [`crate::arbitrary`]).
pub fn sample(a: SampleArgs) -> Result<()> {
    if a.n == 0 {
        bail!("--n must be at least 1");
    }
    let start = match &a.x0 {
        Some(path) => Some(read_start_noise(path)?),
        None => None,
    };
    let _lock = crate::output::lock_folder(&a.out)?;
    check_output_folder(&a.out, a.force, "mfm sample", &SAMPLE_FILES)?;
    if crate::arbitrary::is_arbitrary_run(&a.run) {
        if a.step.is_some() {
            bail!(
                "--step samples a flow run's checkpoint; {} is an arbitrary-source run, which samples its final model",
                a.run.display()
            );
        }
        return crate::arbitrary::sample(&a);
    }
    if a.run.join(mfm_arbitrary::markers::PREDICTOR_SPEC).is_file() {
        bail!(
            "--run {}: is an eigenvector predictor run (mfm train --mode predictor), which \
             generates nothing itself: train an arbitrary-source flow with it \
             (mfm train --mode arbitrary --predictor {}) and sample that run with --source",
            a.run.display(),
            a.run.display()
        );
    }
    crate::flow::sample(&a, start)
}
