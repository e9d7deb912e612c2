//! `mfm train` and `mfm sample`: the commands that run the network (built
//! with the `network` feature).

use crate::mesh_arg::{load_mesh_checked, mesh_path};
use crate::output::{ensure_empty, prepare_outputs, write_json};
use crate::pictures::save_grid;
use anyhow::{Context, Result, bail};
use clap::Args;
use mfm_data::dataset::Dataset;
use mfm_fm::SignalSource;
use mfm_fm::checkpoint::CONFIG_FILE;
use mfm_fm::config::{DeviceChoice, OdeMethod, RunConfig};
use mfm_fm::sample::{
    SAMPLE_FILES, SampleOptions, SampleRequest, SampleTiming, Sampler, is_sample_ply,
    sample_ply_name,
};
use mfm_fm::train::Trainer;
use mfm_geometry::TriMesh;
use mfm_render::{ColorRange, Panel};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

/// Arguments of `mfm train`.
#[derive(Args)]
pub struct TrainArgs {
    /// Run configuration (TOML; every field has a default, unknown fields
    /// are an error). Without it, --preset gives the configuration.
    #[arg(long, conflicts_with = "preset")]
    config: Option<PathBuf>,
    /// Named configuration: `cpu` (scalar signals, minutes on a laptop),
    /// `cpu-deform` (`cpu` conditioned on the source xyz, for `mfm dataset
    /// deform` data), `paper` (the authors' human-pose recipe, for a GPU) or
    /// `paper-elastic` (their elastic-deformation recipe). With --mode
    /// predictor or arbitrary: `cpu` (default) or `paper` (the official
    /// arbitrary-source configurations).
    #[arg(long)]
    preset: Option<String>,
    /// What to train: flow (one mesh, the default), predictor (the
    /// arbitrary-source model's eigenvector predictor, on OUT/train of
    /// `mfm dataset pairs`) or arbitrary (the arbitrary-source flow, on the
    /// same dataset, with --predictor).
    #[arg(long, value_enum, default_value = "flow")]
    mode: crate::arbitrary::TrainMode,
    /// The finished predictor run the arbitrary-source flow conditions on
    /// (--mode arbitrary).
    #[arg(long)]
    predictor: Option<PathBuf>,
    /// --mode arbitrary without the predicted eigenvectors (zeros in their
    /// conditioning channels): an ablation of the positional encoding.
    #[arg(long)]
    no_eigenvectors: bool,
    /// Dataset folder (overrides the configuration's dataset.path).
    #[arg(long)]
    dataset: Option<PathBuf>,
    /// Run folder: config, log, checkpoints, final model.
    #[arg(long)]
    out: PathBuf,
    /// Total training steps (overrides train.steps).
    #[arg(long)]
    steps: Option<u64>,
    /// Seed (overrides train.seed).
    #[arg(long)]
    seed: Option<u64>,
    /// Noise the flow starts from (overrides noise.kind): matern:TAU,
    /// matern-normalized:C, white, naive, explicit:K:TAU.
    #[arg(long)]
    noise: Option<mfm_noise::NoiseKind>,
    /// Where to train: auto (a GPU when libtorch sees one), cpu or cuda
    /// (overrides train.device; with --resume, continues the run there).
    #[arg(long)]
    pub device: Option<DeviceChoice>,
    /// Continue the run in --out from its newest valid checkpoint.
    #[arg(long)]
    resume: bool,
    /// No progress bar.
    #[arg(long)]
    quiet: bool,
}

/// Arguments of `mfm sample`.
#[derive(Args)]
pub struct SampleArgs {
    /// Run folder written by `mfm train` (its final model, or its newest
    /// checkpoint).
    #[arg(long)]
    run: PathBuf,
    /// Mesh to generate on: any triangulation of the training surface.
    #[arg(long, required_unless_present = "source", conflicts_with = "source")]
    mesh: Option<String>,
    /// Source mesh of an arbitrary-source run (`mfm train --mode
    /// arbitrary`): any mesh of a shape like the template's, of any
    /// triangulation; targets are generated over it.
    #[arg(long)]
    source: Option<String>,
    /// Number of samples.
    #[arg(long, default_value_t = 16)]
    n: usize,
    /// ODE steps (default: the run's sample.steps).
    #[arg(long)]
    steps: Option<usize>,
    /// Integrator: midpoint or euler (default: the run's).
    #[arg(long)]
    method: Option<OdeMethod>,
    /// Where to run the network: auto (a GPU when libtorch sees one), cpu
    /// or cuda. Samples agree across devices up to round-off.
    #[arg(long, default_value = "auto")]
    device: DeviceChoice,
    /// Seed of the initial noise.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Output folder: samples.npy [N, V, C] (f32), mesh.ply, the first
    /// --ply samples as PLY, samples.png, timing.json.
    #[arg(long)]
    out: PathBuf,
    /// How many samples to also write as PLY files.
    #[arg(long, default_value_t = 4)]
    ply: usize,
    /// Write into a non-empty --out folder: replaces only what `mfm sample`
    /// writes (samples.npy, mesh.ply, samples.png, timing.json,
    /// sample_NNN.ply, stale ones of an earlier run included).
    #[arg(long)]
    force: bool,
}

/// Runs `mfm train`.
pub fn train(a: TrainArgs) -> Result<()> {
    let stop = Arc::new(AtomicBool::new(false));
    {
        let stop = Arc::clone(&stop);
        // A second Ctrl-C while the final checkpoint is written kills the
        // process as usual.
        let installed = ctrlc::set_handler(move || {
            if stop.swap(true, Ordering::SeqCst) {
                std::process::exit(130);
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
    if a.mode != crate::arbitrary::TrainMode::Flow {
        if a.config.is_some() || a.noise.is_some() || a.device.is_some() {
            bail!("--config, --noise and --device are options of --mode flow");
        }
        return crate::arbitrary::train(
            crate::arbitrary::ArbitraryTrain {
                mode: a.mode,
                preset: a.preset.as_deref(),
                dataset: a.dataset.as_deref(),
                predictor: a.predictor.as_deref(),
                eigenvectors: !a.no_eigenvectors,
                out: &a.out,
                steps: a.steps,
                seed: a.seed,
                resume: a.resume,
                quiet: a.quiet,
            },
            &stop,
        );
    }
    if a.predictor.is_some() || a.no_eigenvectors {
        bail!("--predictor and --no-eigenvectors are options of --mode arbitrary");
    }
    // A fresh run that fails before its first checkpoint leaves nothing.
    let mut fresh: Option<mfm_files::Undo> = None;
    let mut trainer = if a.resume {
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
        let stored = RunConfig::from_toml_file(a.out.join(CONFIG_FILE))
            .with_context(|| format!("{} is not a run folder", a.out.display()))?;
        let dir = match (a.dataset.as_deref(), &stored.dataset.path) {
            (None, Some(p)) if !p.is_dir() => {
                let found = mfm_fm::config::locate_dataset(p, &a.out).with_context(|| {
                    format!(
                        "the run's dataset {} is gone (moved?); pass --dataset DIR",
                        p.display()
                    )
                })?;
                eprintln!(
                    "note: the run's dataset {} is not there; using {} (found beside the run folder)",
                    p.display(),
                    found.display()
                );
                found
            }
            (flag, _) => dataset_dir(flag, &stored)?,
        };
        let data = Dataset::open(&dir)?;
        let mesh = data.mesh().clone();
        let mut t = match a.device {
            Some(d) => Trainer::resume_on(&a.out, &mesh, Arc::new(data), d)?,
            None => Trainer::resume(&a.out, &mesh, Arc::new(data))?,
        };
        if let Some(r) = t.resumed() {
            match &r.checkpoint {
                Some(c) => println!("resuming from {} (step {})", c.display(), r.step),
                None => println!("no checkpoint yet: starting over"),
            }
        }
        if let Some(steps) = a.steps {
            t.set_total_steps(steps)?;
        }
        t
    } else {
        let mut config = match (&a.config, &a.preset) {
            (Some(path), _) => RunConfig::from_toml_file(path)?,
            (None, Some(name)) => RunConfig::preset(name)?,
            (None, None) => {
                bail!("give --config run.toml or --preset cpu|cpu-deform|paper|paper-elastic")
            }
        };
        if let Some(d) = &a.dataset {
            config.dataset.path = Some(d.clone());
        }
        // stored absolute, so `--resume` works from any working directory
        if let Some(p) = &config.dataset.path {
            config.dataset.path = Some(
                std::path::absolute(p).with_context(|| format!("dataset path {}", p.display()))?,
            );
        }
        if let Some(s) = a.steps {
            config.train.steps = s;
        }
        if let Some(s) = a.seed {
            config.train.seed = s;
        }
        if let Some(k) = a.noise {
            config.noise.kind = k;
        }
        if let Some(d) = a.device {
            config.train.device = d;
        }
        let dir = dataset_dir(None, &config)?;
        let data = Dataset::open(&dir)?;
        let mesh = data.mesh().clone();
        println!(
            "dataset {}: {} signals, {} vertices, {} channels",
            dir.display(),
            data.len(),
            data.num_vertices(),
            data.channels()
        );
        ensure_empty(&a.out)?;
        let mut undo = mfm_files::Undo::new();
        undo.create_dir_all(&a.out)?;
        for f in [
            CONFIG_FILE,
            mfm_fm::checkpoint::FLOW_FILE,
            mfm_fm::checkpoint::LOG_FILE,
        ] {
            undo.file(a.out.join(f));
        }
        let trainer = Trainer::new(&a.out, config, &mesh, Arc::new(data))?;
        fresh = Some(undo);
        trainer
    };
    println!(
        "training {} parameters on {:?}, step {} of {}",
        trainer.net().num_parameters(),
        trainer.device(),
        trainer.step(),
        trainer.config().train.steps
    );
    if let Some(line) = trainer.flow().frame_summary() {
        println!("{line}");
    }
    let summary = match trainer.run(&stop, !a.quiet) {
        Ok(s) => s,
        Err(e) => {
            let has_checkpoint =
                mfm_fm::checkpoint::list_checkpoints(&a.out).is_ok_and(|c| !c.is_empty());
            if has_checkpoint {
                // the checkpoints are the user's progress: keep the run
                if let Some(u) = fresh.take() {
                    u.keep();
                }
            }
            return Err(e.into());
        }
    };
    if let Some(u) = fresh.take() {
        u.keep();
    }
    println!(
        "steps {}..{} in {:.1} s ({:.3} s/step), last loss {}",
        summary.start_step,
        summary.end_step,
        summary.seconds,
        summary.seconds_per_step,
        summary
            .last_loss
            .map_or_else(|| "-".to_owned(), |l| format!("{l:.5}"))
    );
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
        std::process::exit(130);
    }
    Ok(())
}

fn dataset_dir(flag: Option<&Path>, config: &RunConfig) -> Result<PathBuf> {
    match (flag, &config.dataset.path) {
        (Some(p), _) => Ok(p.to_path_buf()),
        (None, Some(p)) => Ok(p.clone()),
        (None, None) => {
            bail!("no dataset: pass --dataset DIR or set [dataset] path in the configuration")
        }
    }
}

/// Runs `mfm sample`.
pub fn sample(a: SampleArgs) -> Result<()> {
    if a.n == 0 {
        bail!("--n must be at least 1");
    }
    if a.out.exists() && !a.out.is_dir() {
        bail!("--out {}: exists and is not a folder", a.out.display());
    }
    let existing: Vec<String> = std::fs::read_dir(&a.out)
        .map(|d| {
            d.filter_map(|e| e.ok())
                .map(|e| e.file_name().to_string_lossy().into_owned())
                .collect()
        })
        .unwrap_or_default();
    if !existing.is_empty() && !a.force {
        bail!(
            "{} exists and is not empty; choose another --out, or add --force to replace what \
`mfm sample` writes there ({}, sample_NNN.ply; nothing else is touched)",
            a.out.display(),
            SAMPLE_FILES.join(", ")
        );
    }
    if crate::arbitrary::is_arbitrary_run(&a.run) {
        if a.method.is_some_and(|m| m != OdeMethod::Midpoint) {
            bail!("an arbitrary-source run integrates with the midpoint rule only");
        }
        if a.device == DeviceChoice::Cuda {
            bail!("an arbitrary-source run samples on the CPU (drop --device cuda)");
        }
        let source = a
            .source
            .as_deref()
            .or(a.mesh.as_deref())
            .unwrap_or_default();
        return crate::arbitrary::sample(&crate::arbitrary::ArbitrarySample {
            run: &a.run,
            source,
            n: a.n,
            steps: a.steps,
            seed: a.seed,
            out: &a.out,
            ply: a.ply,
        });
    }
    let Some(mesh_arg) = a.mesh.as_deref() else {
        bail!(
            "--source is for arbitrary-source runs (mfm train --mode arbitrary); {} is a flow on one mesh: pass --mesh",
            a.run.display()
        );
    };
    let mesh = load_mesh_checked(mesh_arg)?;
    let sampler = Sampler::load(&a.run, Some(a.device.resolve()?))?;
    for w in sampler.surface_warnings(&mesh) {
        eprintln!(
            "warning: {mesh_arg}: {w}; the run's frame assumes the sampling mesh is the training surface in the dataset's units"
        );
    }
    let run_config = RunConfig::from_toml_file(a.run.join(CONFIG_FILE)).ok();
    let mut opts = run_config
        .as_ref()
        .map(|c| SampleOptions::from(&c.sample))
        .unwrap_or_default();
    if let Some(s) = a.steps {
        if s == 0 {
            bail!("--steps must be at least 1");
        }
        opts.steps = s;
    }
    if let Some(m) = a.method {
        opts.method = m;
    }
    let (v, c) = (mesh.num_vertices(), sampler.flow().channels);
    let n = a.n;
    let plys = a.ply.min(n);
    let mut outputs: Vec<PathBuf> = SAMPLE_FILES.iter().map(|f| a.out.join(f)).collect();
    outputs.extend((0..plys).map(|i| a.out.join(sample_ply_name(i))));
    let run_files = [
        CONFIG_FILE,
        mfm_fm::checkpoint::FLOW_FILE,
        mfm_fm::checkpoint::WEIGHTS_FILE,
        mfm_fm::checkpoint::NET_CONFIG_FILE,
        mfm_fm::checkpoint::CHECKPOINTS_DIR,
    ]
    .map(|f| a.run.join(f));
    let mut inputs: Vec<Option<&Path>> = run_files.iter().map(|p| Some(p.as_path())).collect();
    inputs.push(mesh_path(mesh_arg));
    let undo = prepare_outputs(&inputs, &outputs)?;
    let shape = [n as u64, v as u64, c as u64];
    mfm_files::space::ensure_space(
        &a.out.join(SAMPLE_FILES[0]),
        mfm_files::npy::file_bytes(&shape, 4),
    )
    .with_context(|| format!("{n} samples x {v} vertices x {c} channels of f32"))?;
    // stale sample_NNN.ply of an earlier run (--force): removed, nothing else
    for name in existing.iter().filter(|f| is_sample_ply(f)) {
        let path = a.out.join(name);
        if !outputs.contains(&path) {
            std::fs::remove_file(&path)
                .with_context(|| format!("cannot remove the stale {}", path.display()))?;
        }
    }
    let target = sampler.prepare(&mesh)?;
    let keep = n.min(a.ply.max(8));
    let streamed = sampler
        .sample_to_npy(
            &target,
            &outputs[0],
            SampleRequest {
                count: n,
                seed: a.seed,
                keep,
                progress: true,
            },
            &opts,
        )
        .with_context(|| {
            format!(
                "sampling the model in {}; nothing was written",
                a.run.display()
            )
        })?;
    let (seconds, noise_seconds) = (streamed.seconds, streamed.noise_seconds);
    let signals = streamed.first;
    mfm_meshio::write_ply(a.out.join("mesh.ply"), &mesh, &[])?;
    for i in 0..plys {
        signals.write_ply(i, &mesh, &a.out.join(sample_ply_name(i)))?;
    }
    let k = keep.min(8);
    let values: Vec<Vec<f64>> = (0..k).map(|i| signals.channel(i, 0)).collect();
    let deformed: Vec<TriMesh> = if c == 3 {
        (0..k)
            .map(|i| mesh.with_positions(signals.positions(i)))
            .collect::<Result<_, _>>()?
    } else {
        Vec::new()
    };
    let panels: Vec<Panel<'_>> = (0..k)
        .map(|i| {
            if c == 3 {
                Panel::new(&deformed[i], None, format!("sample {i}"))
            } else {
                Panel::new(&mesh, Some(values[i].as_slice()), format!("sample {i}"))
            }
        })
        .collect();
    save_grid(
        &panels,
        4,
        &format!("{n} samples on {} vertices", mesh.num_vertices()),
        ColorRange::Auto,
        &a.out.join("samples.png"),
    )?;
    let per_sample = seconds / n as f64;
    let timing = SampleTiming {
        samples: n,
        vertices: v,
        channels: c,
        ode_steps: opts.steps,
        method: format!("{:?}", opts.method).to_lowercase(),
        seconds,
        noise_seconds,
        seconds_per_sample: per_sample,
    };
    write_json(&a.out.join(SAMPLE_FILES[3]), &timing)?;
    undo.keep();
    println!(
        "{n} samples on {} vertices in {:.2} s ({:.1} ms per sample, {} {:?} steps) -> {}",
        v,
        seconds,
        per_sample * 1e3,
        opts.steps,
        opts.method,
        a.out.display()
    );
    Ok(())
}
