//! `mfm train` and `mfm sample`: the commands that run the network (built
//! with the `network` feature).

use crate::mesh::{load_mesh_checked, mesh_path};
use anyhow::{Context, Result, bail};
use clap::Args;
use mfm_fm::checkpoint::CONFIG_FILE;
use mfm_fm::config::{OdeMethod, RunConfig};
use mfm_fm::device::DeviceChoice;
use mfm_fm::run_folder::{Overrides, RunFolder};
use mfm_fm::sample::{SAMPLE_FILES, SampleOptions, Sampler};
use mfm_fm::sample_folder::{SampleFolder, check_output_folder, run_sample_options};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

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
    /// `cpu-deform` (shapes: `cpu` conditioned on the source xyz, 3000
    /// steps, for `mfm dataset deform` and `mfm dataset import` data), `paper` (the authors' human-pose recipe, for a GPU) or
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
    pub(crate) mode: crate::arbitrary::TrainMode,
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
    /// Where to train: auto (a GPU when libtorch sees one), cpu or cuda
    /// (overrides train.device; with --resume, continues the run there).
    #[arg(long)]
    pub(crate) device: Option<DeviceChoice>,
    /// Continue the run in --out from its newest valid checkpoint.
    #[arg(long)]
    pub(crate) resume: bool,
    /// No progress bar.
    #[arg(long)]
    pub(crate) quiet: bool,
}

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

/// Runs `mfm train`.
pub fn train(a: TrainArgs) -> Result<()> {
    let stop = Arc::new(AtomicBool::new(false));
    {
        let stop = Arc::clone(&stop);
        let out = a.out.clone();
        // A second Ctrl-C (or SIGTERM, SIGHUP) ends the process at once:
        // its temporaries (a checkpoint or model half written) and its lock
        // go; a run folder this command created goes too unless it holds a
        // checkpoint, the user's progress.
        let installed = ctrlc::set_handler(move || {
            if stop.swap(true, Ordering::SeqCst) {
                let progress =
                    mfm_train::checkpoint::list_checkpoints(&out).is_ok_and(|c| !c.is_empty());
                if progress {
                    mfm_files::interrupt::clean_up_temporaries();
                    eprintln!(
                        "\nmfm: killed; removed this command's temporaries, the run's checkpoints are intact"
                    );
                } else {
                    mfm_files::interrupt::clean_up();
                    eprintln!("\nmfm: killed; removed what this command had written");
                }
                mfm_files::interrupt::exit_now(130);
            }
            eprintln!(
                "\nmfm: stopping after this step and writing a checkpoint (Ctrl-C again to kill)"
            );
        });
        if let Err(e) = installed {
            eprintln!(
                "mfm: warning: cannot install the Ctrl-C handler ({e}); Ctrl-C will lose the steps since the last checkpoint"
            );
        }
    }
    if !a.resume {
        // never inside the dataset it reads, nor in a folder another command owns
        mfm_files::Outputs::new()
            .inputs(a.dataset.as_deref())
            .folder(&a.out)
            .check()?;
    }
    let lock = crate::output::lock_folder(&a.out)?;
    if a.mode != crate::arbitrary::TrainMode::Flow {
        if a.config.is_some() || a.noise.is_some() || a.device.is_some() {
            bail!("--config, --noise and --device are options of --mode flow");
        }
        if crate::arbitrary::train(&a, &stop)? {
            drop(lock);
            std::process::exit(130);
        }
        return Ok(());
    }
    if a.predictor.is_some() || a.no_eigenvectors {
        bail!("--predictor and --no-eigenvectors are options of --mode arbitrary");
    }
    let run = if a.resume {
        if a.config.is_some() || a.preset.is_some() || a.noise.is_some() || a.seed.is_some() {
            bail!(
                "--resume continues with the run's own {CONFIG_FILE}; drop --config/--preset/--noise/--seed"
            );
        }
        if !a.out.is_dir() {
            bail!(
                "--out {}: no such run folder (--resume continues a run `mfm train --out` started)",
                a.out.display()
            );
        }
        use mfm_arbitrary::markers::FolderKind;
        if a.out.join(mfm_fm::official::IMPORT_FILE).is_file() {
            bail!(
                "--out {}: a model imported from the authors' checkpoint (mfm import): it has no \
                 training state to resume (no dataset, optimizer or checkpoints); sample it, or \
                 train a new run into another folder",
                a.out.display()
            );
        }
        let found = FolderKind::of(&a.out);
        if let (FolderKind::PredictorRun | FolderKind::ArbitraryRun, Some(flags)) =
            (found, found.resume_flags())
        {
            bail!(
                "--out {}: {}, not a flow run: continue it with {flags}",
                a.out.display(),
                found.is()
            );
        }
        let run = RunFolder::resume(&a.out, a.dataset.as_deref(), a.device, a.steps)?;
        if let Some(p) = &run.moved_from {
            eprintln!(
                "note: the run's dataset {} is not there; using {} (found beside the run folder)",
                p.display(),
                run.dataset.display()
            );
        }
        if let Some(r) = run.trainer.resumed() {
            match &r.checkpoint {
                Some(c) => println!("resuming from {} (step {})", c.display(), r.step),
                None => println!("no checkpoint yet: starting over"),
            }
        }
        run
    } else {
        let config = match (&a.config, &a.preset) {
            (Some(path), _) => RunConfig::from_toml_file(path)?,
            (None, Some(name)) => RunConfig::preset(name)?,
            (None, None) => {
                bail!("give --config run.toml or --preset cpu|cpu-deform|paper|paper-elastic")
            }
        };
        let overrides = Overrides {
            dataset: a.dataset.clone(),
            steps: a.steps,
            seed: a.seed,
            noise: a.noise,
            device: a.device,
        };
        let run = RunFolder::start(&a.out, overrides.apply(config)?)?;
        let [n, v, c] = run.dataset_shape;
        println!(
            "dataset {}: {n} signals, {v} vertices, {c} channels",
            run.dataset.display()
        );
        run
    };
    let t = &run.trainer;
    println!(
        "training {} parameters on {:?}, step {} of {}",
        t.net().num_parameters(),
        t.device(),
        t.step(),
        t.config().train.steps
    );
    if let Some(line) = t.flow().frame_summary() {
        println!("{line}");
    }
    let summary = run.train(&stop, !a.quiet)?;
    println!("{}", summary.line());
    if let Some(m) = &summary.model {
        println!("final model: {}", m.display());
    } else if let Some(c) = &summary.checkpoint {
        println!(
            "checkpoint: {} (continue with --resume --out {})",
            c.display(),
            a.out.display()
        );
    }
    if summary.stopped {
        drop(lock);
        std::process::exit(130);
    }
    Ok(())
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

/// Runs `mfm sample`.
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
    let Some(mesh_arg) = a.mesh.as_ref() else {
        bail!(
            "--source is for arbitrary-source runs (mfm train --mode arbitrary); {} is a flow on one mesh: pass --mesh",
            a.run.display()
        );
    };
    let mesh = load_mesh_checked(mesh_arg)?;
    let device = Some(a.device.resolve()?);
    let mut sampler = match a.step {
        None => Sampler::load(&a.run, device)?,
        Some(step) => {
            let dir = mfm_train::checkpoint::checkpoint_dir(&a.run, step);
            if !dir.is_dir() {
                let have: Vec<String> = mfm_train::checkpoint::list_checkpoints(&a.run)?
                    .iter()
                    .map(|c| c.step.to_string())
                    .collect();
                bail!(
                    "--step {step}: {} has no checkpoint of that step (it has {}); \
                     train.keep_at keeps checkpoints of chosen steps",
                    a.run.display(),
                    if have.is_empty() {
                        "none".to_owned()
                    } else {
                        have.join(", ")
                    }
                );
            }
            Sampler::load_checkpoint_weights(&dir, device, !a.raw_weights)?
        }
    };
    let count = match start {
        None => a.n,
        Some(start) => {
            let [n, v, c] = start.shape;
            let (mv, rc) = (mesh.num_vertices(), sampler.flow().channels);
            if v != mv || c != rc {
                bail!(
                    "--x0 {}: shape [{n}, {v}, {c}], but --mesh {mesh_arg} with this run needs [{n}, {mv}, {rc}] \
                     ([samples, the mesh's vertices, the run's channels])",
                    a.x0.as_deref().unwrap_or(Path::new("")).display()
                );
            }
            sampler = sampler.with_start_noise(start)?;
            n
        }
    };
    if let Some(from_arg) = &a.noise_from {
        let from = load_mesh_checked(from_arg)?;
        let start = sampler
            .carried_noise(&from, &mesh, count, a.seed)
            .with_context(|| {
                format!("--noise-from {from_arg}: carrying its noise to --mesh {mesh_arg}")
            })?;
        sampler = sampler.with_start_noise(start)?;
    }
    for w in sampler.surface_warnings(&mesh) {
        eprintln!(
            "warning: {mesh_arg}: {w}; the run's frame assumes the sampling mesh is the training surface in the dataset's units"
        );
    }
    let mut opts = match run_sample_options(&a.run)? {
        Some(o) => o,
        None => {
            let d = SampleOptions::default();
            eprintln!(
                "warning: {} has no {CONFIG_FILE}: integrating with the defaults ({} {} steps; \
                 --steps and --method choose others)",
                a.run.display(),
                d.steps,
                format!("{:?}", d.method).to_lowercase()
            );
            d
        }
    };
    if let Some(s) = a.steps {
        if s == 0 {
            bail!("--steps must be at least 1");
        }
        opts.steps = s;
    }
    if let Some(m) = a.method {
        opts.method = m;
    }
    let folder = SampleFolder {
        run: &a.run,
        mesh_file: mesh_path(mesh_arg),
        start_file: a.x0.as_deref(),
        out: &a.out,
        count,
        seed: a.seed,
        ply: a.ply,
        progress: true,
    };
    let t = folder.write(&sampler, &mesh, &opts).with_context(|| {
        format!(
            "sampling the model in {}; nothing was written",
            a.run.display()
        )
    })?;
    println!(
        "{} samples on {} vertices in {:.2} s ({:.1} ms per sample, {} {:?} steps) -> {}",
        t.samples,
        t.vertices,
        t.seconds,
        t.seconds_per_sample * 1e3,
        opts.steps,
        opts.method,
        a.out.display()
    );
    Ok(())
}
