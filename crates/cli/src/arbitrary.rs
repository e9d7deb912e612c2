//! `mfm train --mode predictor|arbitrary`, `mfm sample --source` and
//! `mfm eval-arbitrary` for an arbitrary-source run: the wiring around
//! `mfm_arbitrary`.

use crate::mesh::{load_mesh_checked, mesh_path};
use crate::sample::SampleArgs;
use crate::train::TrainArgs;
use anyhow::{Context, Result, bail};
use mfm_arbitrary::flow::ArbitrarySampler;
use mfm_arbitrary::folders::{
    EvalFolder, FreshRun, SampleFolder, TrainingRun, evaluate_experiment, write_sample_folder,
};
use mfm_arbitrary::markers::{ARBITRARY_SPEC, FolderKind, RunKind};
use mfm_fm::config::OdeMethod;
use mfm_fm::device::DeviceChoice;
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;

/// Runs `mfm train --mode predictor|arbitrary`; returns whether `stop`
/// ended it (the caller exits with 130).
pub fn train(a: &TrainArgs, kind: RunKind, stop: &AtomicBool) -> Result<bool> {
    if a.noise.is_some() || a.noise_scale.is_some() || a.prior.is_some() {
        bail!(
            "--noise, --noise-scale and --prior are options of --mode flow (the arbitrary-source flow's noise is its configuration's)"
        );
    }
    if kind == RunKind::Predictor && (a.predictor.is_some() || a.no_eigenvectors) {
        bail!("--predictor and --no-eigenvectors are options of --mode arbitrary");
    }
    let spec_file = kind.spec_file();
    let fresh = if a.resume {
        if a.preset.is_some()
            || a.config.is_some()
            || a.seed.is_some()
            || a.steps.is_some()
            || a.device.is_some()
            || a.no_eigenvectors
        {
            bail!(
                "--resume continues with the run's own {spec_file}; drop --config/--preset/--seed/--steps/--device/--no-eigenvectors                  (its config.schedule.steps and .device may be edited there)"
            );
        }
        if !a.out.join(spec_file).is_file() {
            let found = FolderKind::of(&a.out);
            let wanted = match kind {
                RunKind::Predictor => FolderKind::PredictorRun,
                RunKind::Flow => FolderKind::ArbitraryRun,
            };
            match found.resume_flags() {
                Some(flags) => bail!(
                    "--out {}: {}, not {}: continue it with {flags}",
                    a.out.display(),
                    found.is(),
                    wanted.describe()
                ),
                None => bail!(
                    "--out {}: {}, with no {spec_file} (--resume continues {})",
                    a.out.display(),
                    found.is(),
                    wanted.describe()
                ),
            }
        }
        None
    } else {
        let need = |p: &Option<PathBuf>, flag: &str| {
            p.clone()
                .with_context(|| format!("this mode needs {flag} DIR"))
        };
        Some(FreshRun {
            preset: a.preset.clone().unwrap_or_else(|| "cpu".to_owned()),
            config: a.config.clone(),
            device: a.device,
            steps: a.steps,
            seed: a.seed,
            dataset: need(&a.dataset, "--dataset")?,
            predictor: match kind {
                RunKind::Flow => {
                    let p = need(&a.predictor, "--predictor")?;
                    let found = FolderKind::of(&p);
                    if found != FolderKind::PredictorRun {
                        bail!(
                            "--predictor {}: {}; --predictor takes a finished eigenvector \
                             predictor run (the --out folder of mfm train --mode predictor)",
                            p.display(),
                            found.is()
                        );
                    }
                    Some(p)
                }
                RunKind::Predictor => None,
            },
            eigenvectors: !a.no_eigenvectors,
        })
    };
    let run = TrainingRun::prepare(kind, &a.out, fresh.as_ref())?;
    println!("{}", run.description());
    let report = run.train(stop, !a.quiet)?;
    println!("{}", report.line());
    match &report.model {
        Some(m) => println!("final model: {}", m.display()),
        None => println!(
            "stopped; continue with --resume --mode {} --out {}",
            match kind {
                RunKind::Predictor => "predictor",
                RunKind::Flow => "arbitrary",
            },
            a.out.display()
        ),
    }
    Ok(report.stopped)
}

/// Whether `run` is an arbitrary-source run.
pub fn is_arbitrary_run(run: &Path) -> bool {
    run.join(ARBITRARY_SPEC).is_file()
}

/// Runs `mfm sample --run ARBITRARY_RUN --source MESH`
/// ([`mfm_arbitrary::folders::write_sample_folder`]).
pub fn sample(a: &SampleArgs) -> Result<()> {
    if a.method.is_some_and(|m| m != OdeMethod::Midpoint) {
        bail!("an arbitrary-source run integrates with the midpoint rule only");
    }
    if a.device == DeviceChoice::Cuda {
        bail!("an arbitrary-source run samples on the CPU (drop --device cuda)");
    }
    let Some(source_spec) = a.source.as_ref().or(a.mesh.as_ref()) else {
        bail!("give the source shape with --source MESH");
    };
    let mesh = load_mesh_checked(source_spec)?;
    let source_name = source_spec.to_string();
    let source = source_name.as_str();
    let mut sampler = ArbitrarySampler::load(&a.run)?;
    for w in sampler.source_warnings(&mesh) {
        eprintln!("warning: {source}: {w}; the run generates poses of shapes like its template's");
    }
    if let Some(s) = a.steps {
        if s == 0 {
            bail!("--steps must be at least 1");
        }
        sampler.set_ode_steps(s);
    }
    let folder = SampleFolder {
        run: &a.run,
        source_name: source,
        source_file: mesh_path(source_spec),
        out: &a.out,
        count: a.n,
        seed: a.seed,
        ply: a.ply,
    };
    let seconds = write_sample_folder(&sampler, &mesh, &folder).with_context(|| {
        format!(
            "sampling the model in {}; nothing was written",
            a.run.display()
        )
    })?;
    println!(
        "wrote {} ({} targets over {} vertices in {seconds:.1} s, {:.2} s each)",
        a.out.display(),
        a.n,
        mesh.num_vertices(),
        seconds / a.n as f64
    );
    Ok(())
}

/// Arguments of `mfm eval-arbitrary`.
#[derive(clap::Args)]
pub struct EvalArgs {
    /// A finished run of `mfm train --mode arbitrary`.
    #[arg(long)]
    run: PathBuf,
    /// The experiment folder of `mfm dataset pairs` (its holdout and
    /// reference sets are evaluated).
    #[arg(long)]
    experiment: PathBuf,
    /// Held-out shapes used as sources (at most the sets' shape count).
    #[arg(long, default_value_t = 8)]
    sources: usize,
    /// Targets generated per source.
    #[arg(long, default_value_t = 4)]
    per_source: usize,
    /// Noise seed.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Output folder: report.json and, per set, SET.png (sources, generated
    /// targets and a true other pose).
    #[arg(long)]
    out: PathBuf,
    /// Write into a non-empty --out folder: replaces only what
    /// `mfm eval-arbitrary` writes (report.json, holdout.png, reference.png).
    #[arg(long)]
    force: bool,
}

/// The files `mfm eval-arbitrary` writes into its --out folder.
const EVAL_FILES: [&str; 3] = ["report.json", "holdout.png", "reference.png"];

/// Runs `mfm eval-arbitrary`.
pub fn eval(a: EvalArgs) -> Result<()> {
    for (value, flag) in [(a.sources, "--sources"), (a.per_source, "--per-source")] {
        if value == 0 {
            bail!("{flag} must be at least 1 (metrics need at least one generated target)");
        }
    }
    let _lock = crate::output::lock_folder(&a.out)?;
    mfm_fm::sample_folder::check_output_folder(&a.out, a.force, "mfm eval-arbitrary", &EVAL_FILES)?;
    let sampler = ArbitrarySampler::load(&a.run)?;
    if let Some(why) = mfm_arbitrary::evaluate::predictor_error_skipped(&sampler) {
        println!("predictor error against the sets' eigenbases: skipped ({why})");
    }
    let folder = EvalFolder {
        run: &a.run,
        experiment: &a.experiment,
        sources: a.sources,
        per_source: a.per_source,
        seed: a.seed,
        out: &a.out,
    };
    evaluate_experiment(&sampler, &folder, |_, r| println!("{}", r.summary()))?;
    println!("wrote {}", a.out.display());
    Ok(())
}
