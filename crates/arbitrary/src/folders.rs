//! The folders the arbitrary-source commands write: a training run of the
//! predictor or the flow (`mfm train --mode predictor|arbitrary`), the
//! targets generated over a source (`mfm sample --source`) and the
//! evaluation of a run on a pairs experiment (`mfm eval-arbitrary`).
//!
//! Each checks its outputs before writing and leaves nothing behind when
//! it fails; a training run keeps its folder once a checkpoint exists.

use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;

use crate::error::{ArbitraryError, Result};
use mfm_data::layout::{HOLDOUT, REFERENCE};
use mfm_data::pictures::SHOWN;
use mfm_fm::FmError;
use mfm_fm::run_folder::keep_if_progress;
use mfm_fm::sample::sample_ply_name;
use mfm_geometry::TriMesh;
use mfm_render::{ColorRange, Panel, save_grid};
use mfm_train::checkpoint::WEIGHTS_FILE;

use crate::evaluate::{SetEvaluation, evaluate_set};
use crate::flow::{self, ArbitrarySampler, FlowConfig, PREDICTOR_WEIGHTS};
use crate::markers::{ARBITRARY_SPEC, FolderKind, RunKind};
use crate::predictor::{self, PredictorConfig};
use mfm_train::TrainSummary;

/// What a fresh run is made of.
#[derive(Clone, Debug)]
pub struct FreshRun {
    /// The preset, `cpu` or `paper`.
    pub preset: String,
    /// A configuration file instead of the preset: the `config` object of
    /// a run description ([`PredictorConfig`] or [`FlowConfig`]), as JSON
    /// (`.json`) or TOML (any other name); its schedule may use every
    /// setting of the training loop ([`crate::Schedule`]).
    pub config: Option<PathBuf>,
    /// Total steps instead of the preset's.
    pub steps: Option<u64>,
    /// Seed instead of the preset's.
    pub seed: Option<u64>,
    /// Where the network trains, instead of the configuration's.
    pub device: Option<mfm_fm::device::DeviceChoice>,
    /// The pairs dataset (`mfm dataset pairs` OUT/train).
    pub dataset: PathBuf,
    /// The finished predictor run (the flow only).
    pub predictor: Option<PathBuf>,
    /// Whether the flow is conditioned on the predicted eigenvectors.
    pub eigenvectors: bool,
}

/// The configuration of a run, ready to train.
#[derive(Clone, Debug)]
enum Plan {
    Predictor(PredictorConfig, PathBuf),
    Flow(FlowConfig, PathBuf, PathBuf),
}

/// A training run in its folder, ready to [`TrainingRun::train`].
#[derive(Debug)]
pub struct TrainingRun {
    out: PathBuf,
    plan: Plan,
    /// For a fresh run, the folder taken ([`mfm_files::Undo::empty_folder`]).
    fresh: Option<mfm_files::Undo>,
}

fn stored<T: serde::de::DeserializeOwned>(path: &Path) -> Result<T> {
    let text = std::fs::read_to_string(path).map_err(|e| ArbitraryError::io(path, e))?;
    serde_json::from_str(&text).map_err(|e| {
        ArbitraryError::format(path, format!("not readable as a run specification: {e}"))
    })
}

/// A run's configuration from `path`: JSON for a `.json` file, TOML
/// otherwise; the schedule checked.
fn config_file<T>(path: &Path) -> Result<T>
where
    T: serde::de::DeserializeOwned + HasSchedule,
{
    let text = std::fs::read_to_string(path).map_err(|e| ArbitraryError::io(path, e))?;
    let json = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("json"));
    let config: T = if json {
        serde_json::from_str(&text).map_err(|e| {
            ArbitraryError::format(path, format!("not readable as a configuration: {e}"))
        })?
    } else {
        toml::from_str(&text).map_err(|e| {
            ArbitraryError::format(path, format!("not readable as a configuration: {e}"))
        })?
    };
    config
        .schedule()
        .validate()
        .map_err(|e| ArbitraryError::format(path, e.to_string()))?;
    Ok(config)
}

/// The configurations that hold a [`crate::Schedule`].
trait HasSchedule {
    fn schedule(&self) -> &crate::Schedule;
}

impl HasSchedule for PredictorConfig {
    fn schedule(&self) -> &crate::Schedule {
        &self.schedule
    }
}

impl HasSchedule for FlowConfig {
    fn schedule(&self) -> &crate::Schedule {
        &self.schedule
    }
}

fn absolute(p: &Path) -> Result<PathBuf> {
    std::path::absolute(p).map_err(|e| ArbitraryError::io(p, e))
}

impl TrainingRun {
    /// A fresh run of `kind` in `out` (missing or empty) from `fresh`, or,
    /// without it, the run `out` holds, with its stored configuration.
    ///
    /// # Errors
    /// [`mfm_files::FileError::NotEmpty`] for a fresh run in a folder
    /// with anything in it; [`ArbitraryError::Config`] for an unknown
    /// preset, [`ArbitraryError::RunFolder`] for a
    /// flow without a predictor, or resuming a run imported from the
    /// authors' checkpoint ([`crate::official`]); an unreadable stored
    /// specification.
    pub fn prepare(kind: RunKind, out: &Path, fresh: Option<&FreshRun>) -> Result<Self> {
        let Some(f) = fresh else {
            crate::markers::refuse_imported(out)?;
            let spec = out.join(kind.spec_file());
            let plan = match kind {
                RunKind::Predictor => {
                    let s: predictor::PredictorSpec = stored(&spec)?;
                    Plan::Predictor(s.config, s.dataset)
                }
                RunKind::Flow => {
                    let s: flow::ArbitrarySpec = stored(&spec)?;
                    Plan::Flow(s.config, s.dataset, s.predictor)
                }
            };
            return Ok(Self {
                out: out.to_path_buf(),
                plan,
                fresh: None,
            });
        };
        let undo = mfm_files::Undo::empty_folder(out)?;
        let dataset = absolute(&f.dataset)?;
        let plan = match kind {
            RunKind::Predictor => {
                let mut c = match &f.config {
                    Some(path) => config_file::<PredictorConfig>(path)?,
                    None => PredictorConfig::preset(&f.preset)?,
                };
                c.schedule.steps = f.steps.unwrap_or(c.schedule.steps);
                c.schedule.seed = f.seed.unwrap_or(c.schedule.seed);
                c.schedule.device = f.device.unwrap_or(c.schedule.device);
                Plan::Predictor(c, dataset)
            }
            RunKind::Flow => {
                let mut c = match &f.config {
                    Some(path) => config_file::<FlowConfig>(path)?,
                    None => FlowConfig::preset(&f.preset)?,
                };
                c.eigenvectors = f.eigenvectors;
                c.schedule.steps = f.steps.unwrap_or(c.schedule.steps);
                c.schedule.seed = f.seed.unwrap_or(c.schedule.seed);
                c.schedule.device = f.device.unwrap_or(c.schedule.device);
                let predictor = f.predictor.as_deref().ok_or_else(|| {
                    ArbitraryError::RunFolder(
                        "the arbitrary-source flow needs a finished predictor run".into(),
                    )
                })?;
                Plan::Flow(c, dataset, absolute(predictor)?)
            }
        };
        Ok(Self {
            out: out.to_path_buf(),
            plan,
            fresh: Some(undo),
        })
    }

    /// One line on the network and the schedule.
    pub fn description(&self) -> String {
        match &self.plan {
            Plan::Predictor(c, _) => format!(
                "eigenvector predictor: {} vectors, width {}, {} blocks, {} steps of {} meshes",
                c.eigenvectors, c.width, c.blocks, c.schedule.steps, c.schedule.batch
            ),
            Plan::Flow(c, ..) => format!(
                "arbitrary-source flow: width {}, {} blocks, noise {} x {}, {} steps of {} pairs",
                c.width, c.blocks, c.noise, c.sigma, c.schedule.steps, c.schedule.batch
            ),
        }
    }

    /// Trains until the total or `stop`. A fresh run that fails before its
    /// first checkpoint removes what it wrote, and the folder if it made it
    /// ([`mfm_fm::run_folder::keep_if_progress`]).
    ///
    /// # Errors
    /// The training's ([`predictor::train`], [`flow::train`]).
    pub fn train(mut self, stop: &AtomicBool, progress: bool) -> Result<TrainSummary> {
        let out = &self.out;
        let result = match &self.plan {
            Plan::Predictor(c, dataset) => predictor::train(out, dataset, c, stop, progress),
            Plan::Flow(c, dataset, p) => flow::train(out, dataset, p, c, stop, progress),
        };
        if let Some(undo) = self.fresh.take() {
            keep_if_progress(undo, out, result.is_ok());
        }
        result
    }
}

/// What [`write_sample_folder`] writes, besides the [`sample_ply_name`]
/// files.
pub const SAMPLE_FILES: [&str; 4] = [
    "samples.npy",
    "source.ply",
    "samples.png",
    "eigenvectors.png",
];

/// What [`write_sample_folder`] draws and where.
#[derive(Clone, Copy, Debug)]
pub struct SampleFolder<'a> {
    /// The run folder the sampler was loaded from.
    pub run: &'a Path,
    /// The source's name as given (a path or `builtin:NAME`).
    pub source_name: &'a str,
    /// The source's file, `None` for a built-in mesh.
    pub source_file: Option<&'a Path>,
    /// The output folder.
    pub out: &'a Path,
    /// Targets `0..count` of the seed's sequence.
    pub count: usize,
    /// The noise seed.
    pub seed: u64,
    /// How many targets to also write as PLY.
    pub ply: usize,
}

/// Generates `count` targets over `source` and writes them into `out`:
/// `samples.npy` `[N, V, 3]` (`f32`), `source.ply`, the first `ply` as
/// [`sample_ply_name`] files, `samples.png` (the source beside its
/// targets) and `eigenvectors.png` (the predicted vectors 1..8 on the
/// source). Returns the seconds the sampling took.
///
/// # Errors
/// The output guard's; the sampler's (nothing is written); the writers'.
pub fn write_sample_folder(
    sampler: &ArbitrarySampler,
    source: &TriMesh,
    f: &SampleFolder<'_>,
) -> Result<f64> {
    let (n, out) = (f.count, f.out);
    let mut outputs: Vec<PathBuf> = SAMPLE_FILES.iter().map(|s| out.join(s)).collect();
    outputs.extend((0..f.ply.min(n)).map(|i| out.join(sample_ply_name(i))));
    let run_files = [ARBITRARY_SPEC, WEIGHTS_FILE, PREDICTOR_WEIGHTS];
    let undo = mfm_files::Outputs::new()
        .inputs(run_files.map(|file| f.run.join(file)))
        .inputs(f.source_file)
        .outputs(&outputs)
        .prepare()?;
    let v = source.num_vertices();
    // every target is held as f64 positions and written as f32
    mfm_files::space::ensure_memory(
        &format!("{n} targets x {v} vertices x 3 coordinates"),
        (n as u128) * (v as u128) * 3,
        12,
    )?;
    mfm_files::space::ensure_space(
        &outputs[0],
        mfm_files::npy::file_bytes(&[n as u64, v as u64, 3], 4),
    )?;
    let t0 = std::time::Instant::now();
    let shapes = sampler.sample(source, 0, n, f.seed)?;
    let seconds = t0.elapsed().as_secs_f64();
    let flat: Vec<f32> = shapes
        .iter()
        .flat_map(|s| s.iter().flat_map(|p| p.map(|x| x as f32)))
        .collect();
    mfm_files::npy::write(&outputs[0], &flat, &[n as u64, v as u64, 3])?;
    mfm_meshio::write_ply(&outputs[1], source, &[])?;
    let generated: Vec<TriMesh> = shapes
        .iter()
        .map(|s| source.with_positions(s.clone()))
        .collect::<std::result::Result<_, _>>()
        .map_err(mesh_error)?;
    for (g, path) in generated.iter().zip(&outputs[SAMPLE_FILES.len()..]) {
        mfm_meshio::write_ply(path, g, &[])?;
    }
    let mut panels = vec![Panel::new(source, None, "source")];
    panels.extend(
        generated
            .iter()
            .take(SHOWN - 1)
            .enumerate()
            .map(|(i, g)| Panel::new(g, None, format!("target {i}"))),
    );
    let title = format!("{n} targets generated over {}", f.source_name);
    save_grid(&panels, 4, &title, ColorRange::Auto, &outputs[2]).map_err(render_error)?;
    let k = sampler.predictor().eigenvectors();
    let eigen = sampler.eigenvectors_on(source)?;
    let shown: Vec<Vec<f64>> = (1..k.min(SHOWN + 1))
        .map(|i| (0..v).map(|u| f64::from(eigen[u * k + i])).collect())
        .collect();
    let panels: Vec<Panel<'_>> = shown
        .iter()
        .enumerate()
        .map(|(i, e)| {
            Panel::new(
                source,
                Some(e.as_slice()),
                format!("predicted phi_{}", i + 1),
            )
        })
        .collect();
    let title = "predicted eigenvectors on the source";
    save_grid(&panels, 4, title, ColorRange::Auto, &outputs[3]).map_err(render_error)?;
    undo.keep();
    Ok(seconds)
}

/// What [`evaluate_experiment`] measures and where it writes.
#[derive(Clone, Copy, Debug)]
pub struct EvalFolder<'a> {
    /// The run folder the sampler was loaded from.
    pub run: &'a Path,
    /// The pairs experiment (`mfm dataset pairs` OUT).
    pub experiment: &'a Path,
    /// Held-out shapes used as sources.
    pub sources: usize,
    /// Targets per source.
    pub per_source: usize,
    /// The noise seed.
    pub seed: u64,
    /// The output folder: `report.json` and `SET.png` per set.
    pub out: &'a Path,
}

/// Evaluates `sampler` on the experiment's [`HOLDOUT`] and [`REFERENCE`]
/// sets ([`evaluate_set`]), calls `on_set` with each set's measures, and
/// writes `report.json` (the measures of both) and `SET.png` (rows of a
/// source, its generated targets and a true other pose).
///
/// # Errors
/// [`ArbitraryError::Dataset`] for an experiment with neither set; the output
/// guard's; [`evaluate_set`]'s; the writers'.
pub fn evaluate_experiment(
    sampler: &ArbitrarySampler,
    f: &EvalFolder<'_>,
    mut on_set: impl FnMut(&str, &SetEvaluation),
) -> Result<Vec<SetEvaluation>> {
    let sets: Vec<&str> = [HOLDOUT, REFERENCE]
        .into_iter()
        .filter(|s| f.experiment.join(s).join("manifest.json").is_file())
        .collect();
    if sets.is_empty() {
        let e = f.experiment.display();
        return Err(match FolderKind::of(f.experiment) {
            FolderKind::Missing => ArbitraryError::RunFolder(format!(
                "{e}: no such folder (expected the experiment folder of mfm dataset pairs)"
            )),
            FolderKind::Experiment => ArbitraryError::Dataset(format!(
                "{e} has no {HOLDOUT} or {REFERENCE} set (write one with mfm dataset pairs --reference N)"
            )),
            FolderKind::Dataset => ArbitraryError::RunFolder(format!(
                "{e}: is a dataset folder (one set of an experiment), not an experiment folder: \
                 give the folder of mfm dataset pairs that holds {HOLDOUT}/ and {REFERENCE}/"
            )),
            other => ArbitraryError::RunFolder(format!(
                "{e}: {}, not an experiment folder (the --out folder of mfm dataset pairs)",
                other.is()
            )),
        });
    }
    if let Some(trained) = &sampler.spec().template
        && sets.contains(&HOLDOUT)
    {
        // the held-out set is on the training connectivity: its mesh is the template
        let set = f.experiment.join(HOLDOUT);
        let theirs =
            mfm_data::dataset::mesh_identity(mfm_data::dataset::Dataset::open(&set)?.mesh());
        if theirs != *trained {
            return Err(ArbitraryError::Mismatch(format!(
                "{} is an experiment of another template ({theirs}) than the run {} was trained \
                 on (the mesh of {}, {trained}): evaluate it on its own experiment",
                f.experiment.display(),
                f.run.display(),
                sampler.spec().dataset.display()
            )));
        }
    }
    let mut outputs = vec![f.out.join("report.json")];
    outputs.extend(sets.iter().map(|s| f.out.join(format!("{s}.png"))));
    let undo = mfm_files::Outputs::new()
        .inputs([f.run, f.experiment])
        .outputs(&outputs)
        .prepare()?;
    let mut reports = Vec::new();
    for (set, png) in sets.iter().zip(&outputs[1..]) {
        let dir = f.experiment.join(set);
        let (r, examples) = evaluate_set(sampler, &dir, f.sources, f.per_source, f.seed)?;
        on_set(set, &r);
        let rows = examples.len().min(4);
        let cols = 2 + f.per_source.min(3);
        let mut meshes: Vec<(TriMesh, String)> = Vec::new();
        for (i, e) in examples[..rows].iter().enumerate() {
            meshes.push((e.source.clone(), format!("source {i}")));
            for (j, g) in e.generated.iter().take(cols - 2).enumerate() {
                let m = e.source.with_positions(g.clone()).map_err(mesh_error)?;
                meshes.push((m, format!("generated {j}")));
            }
            let truth = e
                .source
                .with_positions(e.truth.clone())
                .map_err(mesh_error)?;
            meshes.push((truth, "a data pose".to_owned()));
        }
        let panels: Vec<Panel<'_>> = meshes
            .iter()
            .map(|(m, c)| Panel::new(m, None, c.clone()))
            .collect();
        let title = format!("{set}: unseen shapes, generated targets, and a true pose");
        save_grid(&panels, cols, &title, ColorRange::Auto, png).map_err(render_error)?;
        reports.push(r);
    }
    mfm_files::write_json(&outputs[0], &reports)?;
    undo.keep();
    Ok(reports)
}

fn mesh_error(e: mfm_geometry::MeshError) -> FmError {
    FmError::MeshProcessing {
        what: "placing generated positions on the source".into(),
        source: Box::new(e),
    }
}

fn render_error(e: mfm_render::RenderError) -> FmError {
    FmError::Data(e.into())
}
