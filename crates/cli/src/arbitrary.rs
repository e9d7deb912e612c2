//! `mfm train --mode predictor|arbitrary`, `mfm sample --source` and
//! `mfm eval-arbitrary` for an arbitrary-source run: the wiring around
//! `mfm_arbitrary`.

use crate::mesh_arg::{load_mesh_checked, mesh_path};
use crate::output::{ensure_empty, prepare_outputs};
use crate::pictures::save_grid;
use anyhow::{Context, Result, bail};
use mfm_arbitrary::TrainReport;
use mfm_arbitrary::flow::{self, ARBITRARY_SPEC, ArbitrarySampler, FlowConfig};
use mfm_arbitrary::predictor::{self, PREDICTOR_SPEC, PredictorConfig};
use mfm_geometry::TriMesh;
use mfm_render::{ColorRange, Panel};
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;

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

/// The options of `mfm train` these modes read.
pub struct ArbitraryTrain<'a> {
    pub mode: TrainMode,
    pub preset: Option<&'a str>,
    pub dataset: Option<&'a Path>,
    pub predictor: Option<&'a Path>,
    pub eigenvectors: bool,
    pub out: &'a Path,
    pub steps: Option<u64>,
    pub seed: Option<u64>,
    pub resume: bool,
    pub quiet: bool,
}

fn stored<T: serde::de::DeserializeOwned>(path: &Path) -> Result<T> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    serde_json::from_str(&text).with_context(|| format!("{} is not readable", path.display()))
}

/// Runs `mfm train --mode predictor|arbitrary`.
pub fn train(a: ArbitraryTrain<'_>, stop: &AtomicBool) -> Result<()> {
    let spec_file = match a.mode {
        TrainMode::Predictor => PREDICTOR_SPEC,
        TrainMode::Arbitrary => ARBITRARY_SPEC,
        TrainMode::Flow => unreachable!("the flow mode is `mfm train`'s own"),
    };
    let spec_path = a.out.join(spec_file);
    if a.resume {
        if a.preset.is_some() || a.seed.is_some() || a.steps.is_some() || !a.eigenvectors {
            bail!(
                "--resume continues with the run's own {spec_file}; drop --preset/--seed/--steps/--no-eigenvectors"
            );
        }
        if !spec_path.is_file() {
            bail!(
                "--out {}: no {spec_file} there (--resume continues a run this mode started)",
                a.out.display()
            );
        }
    } else {
        ensure_empty(a.out)?;
    }
    let fresh_dir = !a.resume && !a.out.exists();
    let result = run_training(&a, &spec_path, stop);
    if result.is_err() && !a.resume {
        // a fresh run that failed before its first checkpoint leaves nothing
        let has_checkpoint =
            mfm_fm::checkpoint::list_checkpoints(a.out).is_ok_and(|c| !c.is_empty());
        if !has_checkpoint {
            if fresh_dir {
                let _ = std::fs::remove_dir_all(a.out);
            } else if let Ok(entries) = std::fs::read_dir(a.out) {
                // the folder was empty before: what is in it now is ours
                for e in entries.flatten() {
                    let p = e.path();
                    let _ = if p.is_dir() {
                        std::fs::remove_dir_all(&p)
                    } else {
                        std::fs::remove_file(&p)
                    };
                }
            }
        }
    }
    let report = result?;
    for s in &report.skipped_checkpoints {
        eprintln!("warning: passed over a damaged checkpoint: {s}");
    }
    println!(
        "steps {}..{} of {} in {:.1} s, last loss {}",
        report.start_step,
        report.end_step,
        report.total_steps,
        report.seconds,
        report
            .last_loss
            .map_or_else(|| "-".to_owned(), |l| format!("{l:.5}"))
    );
    match &report.model {
        Some(m) => println!("final model: {}", m.display()),
        None => println!(
            "stopped; continue with --resume --mode {} --out {}",
            if a.mode == TrainMode::Predictor {
                "predictor"
            } else {
                "arbitrary"
            },
            a.out.display()
        ),
    }
    if report.stopped {
        std::process::exit(130);
    }
    Ok(())
}

/// Reads or builds the configuration of the mode and trains.
fn run_training(
    a: &ArbitraryTrain<'_>,
    spec_path: &Path,
    stop: &AtomicBool,
) -> Result<TrainReport> {
    let preset = a.preset.unwrap_or("cpu");
    let report: TrainReport = match a.mode {
        TrainMode::Predictor if !a.eigenvectors => {
            bail!("--no-eigenvectors is an option of --mode arbitrary")
        }
        TrainMode::Predictor => {
            let (config, dataset) = if a.resume {
                let s: predictor::PredictorSpec = stored(spec_path)?;
                (s.config, s.dataset)
            } else {
                let mut c = PredictorConfig::preset(preset)?;
                if let Some(s) = a.steps {
                    c.schedule.steps = s;
                }
                if let Some(s) = a.seed {
                    c.schedule.seed = s;
                }
                (c, absolute(need(a.dataset, "--dataset")?)?)
            };
            println!(
                "eigenvector predictor: {} vectors, width {}, {} blocks, {} steps of {} meshes",
                config.eigenvectors,
                config.width,
                config.blocks,
                config.schedule.steps,
                config.schedule.batch
            );
            predictor::train(a.out, &dataset, &config, stop, !a.quiet)?
        }
        _ => {
            let (config, dataset, predictor_dir) = if a.resume {
                let s: flow::ArbitrarySpec = stored(spec_path)?;
                (s.config, s.dataset, s.predictor)
            } else {
                let mut c = FlowConfig::preset(preset)?;
                c.eigenvectors = a.eigenvectors;
                if let Some(s) = a.steps {
                    c.schedule.steps = s;
                }
                if let Some(s) = a.seed {
                    c.schedule.seed = s;
                }
                (
                    c,
                    absolute(need(a.dataset, "--dataset")?)?,
                    absolute(need(a.predictor, "--predictor")?)?,
                )
            };
            println!(
                "arbitrary-source flow: width {}, {} blocks, noise {} x {}, {} steps of {} pairs",
                config.width,
                config.blocks,
                config.noise,
                config.sigma,
                config.schedule.steps,
                config.schedule.batch
            );
            flow::train(a.out, &dataset, &predictor_dir, &config, stop, !a.quiet)?
        }
    };
    Ok(report)
}

fn need<'a>(p: Option<&'a Path>, flag: &str) -> Result<&'a Path> {
    p.with_context(|| format!("this mode needs {flag} DIR"))
}

fn absolute(p: &Path) -> Result<PathBuf> {
    std::path::absolute(p).with_context(|| format!("path {}", p.display()))
}

/// Whether `run` is an arbitrary-source run.
pub fn is_arbitrary_run(run: &Path) -> bool {
    run.join(ARBITRARY_SPEC).is_file()
}

/// The options of `mfm sample` an arbitrary-source run reads.
pub struct ArbitrarySample<'a> {
    pub run: &'a Path,
    pub source: &'a str,
    pub n: usize,
    pub steps: Option<usize>,
    pub seed: u64,
    pub out: &'a Path,
    pub ply: usize,
}

/// What `mfm sample` writes for an arbitrary-source run.
const FILES: [&str; 4] = [
    "samples.npy",
    "source.ply",
    "samples.png",
    "eigenvectors.png",
];

/// Runs `mfm sample --run ARBITRARY_RUN --source MESH`: `n` targets over
/// the source, as samples.npy `[N, V, 3]` f32, source.ply, the first `ply`
/// as sample_NNN.ply, samples.png (the source beside its targets) and
/// eigenvectors.png (the predictor's first vectors on the source).
pub fn sample(a: &ArbitrarySample<'_>) -> Result<()> {
    let (run, source, n, seed, out, ply) = (a.run, a.source, a.n, a.seed, a.out, a.ply);
    let mesh = load_mesh_checked(source)?;
    let mut sampler = ArbitrarySampler::load(run)?;
    if let Some(s) = a.steps {
        if s == 0 {
            bail!("--steps must be at least 1");
        }
        sampler.set_ode_steps(s);
    }
    let plys = ply.min(n);
    let mut outputs: Vec<PathBuf> = FILES.iter().map(|f| out.join(f)).collect();
    outputs.extend((0..plys).map(|i| out.join(mfm_fm::sample::sample_ply_name(i))));
    let run_files = [
        ARBITRARY_SPEC,
        mfm_fm::checkpoint::WEIGHTS_FILE,
        flow::PREDICTOR_WEIGHTS,
    ]
    .map(|f| run.join(f));
    let mut inputs: Vec<Option<&Path>> = run_files.iter().map(|p| Some(p.as_path())).collect();
    inputs.push(mesh_path(source));
    let undo = prepare_outputs(&inputs, &outputs)?;
    let t0 = std::time::Instant::now();
    let shapes = sampler.sample(&mesh, 0, n, seed).with_context(|| {
        format!(
            "sampling the model in {}; nothing was written",
            run.display()
        )
    })?;
    let seconds = t0.elapsed().as_secs_f64();
    let v = mesh.num_vertices();
    let flat: Vec<f32> = shapes
        .iter()
        .flat_map(|s| s.iter().flat_map(|p| p.map(|x| x as f32)))
        .collect();
    mfm_files::npy::write(&outputs[0], &flat, &[n as u64, v as u64, 3])?;
    mfm_meshio::write_ply(&outputs[1], &mesh, &[])?;
    let generated: Vec<TriMesh> = shapes
        .iter()
        .map(|s| mesh.with_positions(s.clone()))
        .collect::<Result<_, _>>()?;
    for (i, g) in generated.iter().take(plys).enumerate() {
        mfm_meshio::write_ply(out.join(mfm_fm::sample::sample_ply_name(i)), g, &[])?;
    }
    let mut panels = vec![Panel::new(&mesh, None, "source")];
    panels.extend(
        generated
            .iter()
            .take(7)
            .enumerate()
            .map(|(i, g)| Panel::new(g, None, format!("target {i}"))),
    );
    save_grid(
        &panels,
        4,
        &format!("{n} targets generated over {source}"),
        ColorRange::Auto,
        &outputs[2],
    )?;
    let k = sampler.predictor().eigenvectors();
    let eigen = sampler.eigenvectors_on(&mesh)?;
    let shown: Vec<Vec<f64>> = (1..k.min(9))
        .map(|i| (0..v).map(|u| f64::from(eigen[u * k + i])).collect())
        .collect();
    let panels: Vec<Panel<'_>> = shown
        .iter()
        .enumerate()
        .map(|(i, e)| {
            Panel::new(
                &mesh,
                Some(e.as_slice()),
                format!("predicted phi_{}", i + 1),
            )
        })
        .collect();
    save_grid(
        &panels,
        4,
        "predicted eigenvectors on the source",
        ColorRange::Auto,
        &outputs[3],
    )?;
    undo.keep();
    println!(
        "wrote {} ({n} targets over {v} vertices in {seconds:.1} s, {:.2} s each)",
        out.display(),
        seconds / n as f64
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
}

/// Runs `mfm eval-arbitrary`.
pub fn eval(a: EvalArgs) -> Result<()> {
    use mfm_arbitrary::evaluate::evaluate_set;
    use mfm_data::layout::{HOLDOUT, REFERENCE};
    let sets: Vec<&str> = [HOLDOUT, REFERENCE]
        .into_iter()
        .filter(|s| a.experiment.join(s).join("manifest.json").is_file())
        .collect();
    if sets.is_empty() {
        bail!(
            "{} has no {HOLDOUT} or {REFERENCE} set (write one with mfm dataset pairs --reference N)",
            a.experiment.display()
        );
    }
    let mut outputs = vec![a.out.join("report.json")];
    outputs.extend(sets.iter().map(|s| a.out.join(format!("{s}.png"))));
    let inputs = [Some(a.run.as_path()), Some(a.experiment.as_path())];
    let undo = prepare_outputs(&inputs, &outputs)?;
    let sampler = ArbitrarySampler::load(&a.run)?;
    let mut reports = Vec::new();
    for (set, png) in sets.iter().zip(&outputs[1..]) {
        let (r, examples) = evaluate_set(
            &sampler,
            &a.experiment.join(set),
            a.sources,
            a.per_source,
            a.seed,
        )?;
        println!(
            "{set:>9} ({} vertices, {} sources x {}): projection {:.2e} [{:.2e}, {:.2e}] (floor {:.2e}), \
             displacement ratio {:.2}, pose spread {:.2}/{:.2} of the data's, MMD {:.4}, COV {:.2}, \
             predictor error {:.3} (vectors 1-8: {:.3})",
            r.vertices,
            r.sources,
            r.samples_per_source,
            r.projection.median,
            r.projection.q1,
            r.projection.q3,
            r.projection_floor.median,
            r.displacement_ratio,
            r.pose_spread.rotation / r.reference_pose_spread.rotation.max(f64::MIN_POSITIVE),
            r.pose_spread.translation / r.reference_pose_spread.translation.max(f64::MIN_POSITIVE),
            r.mmd,
            r.cov,
            r.predictor_error.median,
            r.predictor_error_low.median
        );
        let rows = examples.len().min(4);
        let cols = 2 + a.per_source.min(3);
        let meshes: Vec<Vec<TriMesh>> = examples[..rows]
            .iter()
            .map(|e| {
                let mut row = vec![e.source.clone()];
                for g in e.generated.iter().take(cols - 2) {
                    row.push(e.source.with_positions(g.clone())?);
                }
                row.push(e.source.with_positions(e.truth.clone())?);
                Ok(row)
            })
            .collect::<Result<_>>()?;
        let panels: Vec<Panel<'_>> = meshes
            .iter()
            .enumerate()
            .flat_map(|(i, row)| {
                let last = row.len() - 1;
                row.iter().enumerate().map(move |(j, m)| {
                    let caption = match j {
                        0 => format!("source {i}"),
                        j if j == last => "a data pose".to_owned(),
                        j => format!("generated {}", j - 1),
                    };
                    Panel::new(m, None, caption)
                })
            })
            .collect();
        save_grid(
            &panels,
            cols,
            &format!("{set}: unseen shapes, generated targets, and a true pose"),
            ColorRange::Auto,
            png,
        )?;
        reports.push(r);
    }
    crate::output::write_json(&outputs[0], &reports)?;
    undo.keep();
    println!("wrote {}", a.out.display());
    Ok(())
}
