//! `mfm train --mode flow` and `mfm sample` of a flow run: a flow on one
//! training mesh (built with the `network` feature).

use std::path::Path;
use std::sync::atomic::AtomicBool;

use anyhow::{Context, Result, bail};
use mfm_fm::checkpoint::CONFIG_FILE;
use mfm_fm::config::RunConfig;
use mfm_fm::run_folder::{Overrides, RunFolder};
use mfm_fm::sample::{SampleOptions, Sampler};
use mfm_fm::sample_folder::{SampleFolder, run_sample_options};

use crate::mesh::{load_mesh_checked, mesh_path};
use crate::sample::SampleArgs;
use crate::train::TrainArgs;

/// Runs `mfm train --mode flow` (the checks and the interrupt handler of
/// [`crate::train::train`] done); returns whether `stop` ended it.
pub fn train(a: &TrainArgs, stop: &AtomicBool) -> Result<bool> {
    if a.predictor.is_some() || a.no_eigenvectors {
        bail!("--predictor and --no-eigenvectors are options of --mode arbitrary");
    }
    let run = if a.resume {
        if a.config.is_some()
            || a.preset.is_some()
            || a.noise.is_some()
            || a.noise_scale.is_some()
            || a.prior.is_some()
            || a.seed.is_some()
        {
            bail!(
                "--resume continues with the run's own {CONFIG_FILE}; drop --config/--preset/--noise/--noise-scale/--prior/--seed"
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
            noise_scale: a.noise_scale,
            prior: a.prior,
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
    if let Some(p) = &t.flow().prior {
        println!(
            "prior: a Gaussian fit of {} training signals, {} principal directions ({}) added to every noise sample",
            p.fitted_on,
            p.directions,
            mfm_fm::prior::PRIOR_FILE
        );
    }
    let summary = run.train(stop, !a.quiet)?;
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
    Ok(summary.stopped)
}

/// Runs `mfm sample` of a flow run (the checks of [`crate::sample::sample`]
/// done; `start` the `--x0` noise).
pub fn sample(a: &SampleArgs, start: Option<mfm_fm::sample::StartNoise>) -> Result<()> {
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
