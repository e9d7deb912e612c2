//! The eigenvector predictor: a PoissonNet with a linear head that maps a
//! source mesh's vertex positions (in its own canonical frame, or as they
//! are for a [`SourceFrame::AsIs`] predictor) to the
//! template's first `k` Laplacian eigenvectors
//! ([`mfm_data::eigenbasis::Eigenbasis`], signs fixed by its rule),
//! trained on every mesh of a dataset of template shapes with the
//! mass-weighted MSE of the source.
//!
//! Run folder: [`PREDICTOR_SPEC`] (configuration, dataset, eigenvalues and
//! sign margins), [`TARGETS_FILE`] (the targets `[V, k]`), the log,
//! checkpoints and, when finished, `model.safetensors` + `model.json`.

use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;

use mfm_data::SignalSource;
use mfm_data::dataset::Dataset;
use mfm_data::eigenbasis::Eigenbasis;
use mfm_geometry::TriMesh;
use mfm_net::{HeadKind, MeshTensors, PoissonNet, PoissonNetConfig, loss};
use mfm_noise::NoiseKind;
use rand::Rng;
use rand_distr::{Distribution, StandardNormal};
use serde::{Deserialize, Serialize};
use tch::{Device, Kind, Tensor};

use crate::error::{ArbitraryError, Result};
use crate::markers::{FolderKind, PREDICTOR_SPEC};
use crate::run::{start_or_resume, train_to_end};
use crate::sources::SourceSet;
use crate::{
    AUGMENT_SCALE, AUGMENT_SHIFT, Schedule, SourceFrame, finished_weights, read_json, same_config,
};
use mfm_net::mesh::positions_tensor;
use mfm_train::TrainSummary;
use mfm_train::seeding::derived_rng;

/// The training targets, `[V, k]` f64.
pub const TARGETS_FILE: &str = "targets.npy";

const PURPOSE_ITEMS: u64 = 11;

/// The predictor's network and training settings.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PredictorConfig {
    /// `k`, eigenvectors predicted (the official 64).
    pub eigenvectors: usize,
    /// Network width.
    pub width: usize,
    /// Poisson blocks.
    pub blocks: usize,
    /// Optimization.
    pub schedule: Schedule,
    /// Where sources are put before the network sees them (absent in the
    /// description: [`SourceFrame::Own`]).
    #[serde(default, skip_serializing_if = "SourceFrame::is_own")]
    pub frame: SourceFrame,
}

/// Preset names of [`PredictorConfig::preset`].
pub const PRESETS: [&str; 2] = ["paper", "cpu"];

impl PredictorConfig {
    /// The official configuration (`moyo_eigenvecs_predictor.yaml`): 64
    /// vectors, width 128, 3 blocks, lr 1e-3 x 0.1 at 20k/80k/200k,
    /// batch 8, 240k steps, clip 1, augmentation.
    pub fn paper() -> Self {
        Self {
            eigenvectors: 64,
            width: 128,
            blocks: 3,
            schedule: Schedule::step_decay(
                1e-3,
                8,
                240_000,
                vec![20_000, 80_000, 200_000],
                0.1,
                1.0,
                true,
                42,
                10_000,
            ),
            frame: SourceFrame::Own,
        }
    }

    /// A CPU-scale configuration: width 32, 3 blocks, 1500 steps of batch
    /// 4 (lr 1e-3, x 0.1 at 1000).
    pub fn cpu() -> Self {
        let mut c = Self::paper();
        c.width = 32;
        c.schedule.batch = 4;
        c.schedule.steps = 1500;
        c.schedule.milestones = vec![1000];
        c.schedule.checkpoint_every = 250;
        c
    }

    /// A preset by name ([`PRESETS`]).
    ///
    /// # Errors
    /// [`ArbitraryError::Config`] for another name.
    pub fn preset(name: &str) -> Result<Self> {
        match name {
            "paper" => Ok(Self::paper()),
            "cpu" => Ok(Self::cpu()),
            other => Err(ArbitraryError::Config(format!(
                "unknown predictor preset {other:?}; expected one of {}",
                PRESETS.join(", ")
            ))),
        }
    }

    /// The network: positions in, `k` channels out, linear head, no
    /// conditioning.
    pub fn net_config(&self) -> PoissonNetConfig {
        PoissonNetConfig {
            width: self.width,
            blocks: self.blocks,
            vector_layers: 3,
            in_channels: 3,
            out_channels: self.eigenvectors,
            cond_channels: 0,
            modulation: true,
            head: HeadKind::Linear,
            global_context: false,
        }
    }
}

/// What [`PREDICTOR_SPEC`] holds.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PredictorSpec {
    /// The configuration.
    pub config: PredictorConfig,
    /// The dataset trained on.
    pub dataset: PathBuf,
    /// Vertices of the template.
    pub vertices: usize,
    /// The template's eigenvalues (its canonical frame); empty for a
    /// predictor imported from the authors' checkpoint, whose targets mfm
    /// did not compute ([`PredictorSpec::has_own_basis`]).
    pub eigenvalues: Vec<f64>,
    /// The sign rule's margins ([`Eigenbasis::margins`]).
    pub margins: Vec<f64>,
    /// The template's identity ([`mfm_data::dataset::mesh_identity`]), which
    /// a flow trained with this predictor must share; `None` in runs
    /// trained before it was recorded (they compare vertex counts only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub template: Option<String>,
}

impl PredictorSpec {
    /// Whether the predictor was trained here on a basis mfm computed (its
    /// eigenvalues are recorded), so that its output can be compared with
    /// that basis on a mesh; `false` for an imported predictor, trained on
    /// the authors' own basis (their sign and normalization conventions).
    pub fn has_own_basis(&self) -> bool {
        !self.eigenvalues.is_empty()
    }
}

/// A source moved into `frame` (and the same map applied to `also`),
/// then scaled and shifted by the step's augmentation.
pub(crate) fn prepared(
    mut positions: Vec<[f64; 3]>,
    mut also: Option<&mut Vec<[f64; 3]>>,
    augment: Option<&mut rand_chacha::ChaCha8Rng>,
    frame: SourceFrame,
) -> Result<Vec<[f64; 3]>> {
    frame.apply(
        &mut positions,
        also.as_deref_mut().map(|v| v.as_mut_slice()),
    )?;
    if let Some(rng) = augment {
        let (lo, hi) = AUGMENT_SCALE;
        let s = lo + (hi - lo) * rng.random::<f64>();
        let shift: [f64; 3] = std::array::from_fn(|_| {
            AUGMENT_SHIFT * <StandardNormal as Distribution<f64>>::sample(&StandardNormal, rng)
        });
        let map = |p: &mut [f64; 3]| *p = std::array::from_fn(|a| s * p[a] + shift[a]);
        positions.iter_mut().for_each(map);
        if let Some(q) = also {
            q.iter_mut().for_each(map);
        }
    }
    Ok(positions)
}

/// Trains (or resumes) an eigenvector predictor in `run_dir` on the meshes
/// of `dataset` (3-channel position signals on the template; a pairs
/// dataset's sources and targets alike).
///
/// A fresh run computes the template's basis and writes [`PREDICTOR_SPEC`]
/// and [`TARGETS_FILE`]; a run folder that has them resumes from its newest
/// valid checkpoint (with the stored configuration; `config` must equal
/// it).
///
/// Cost per step: `batch` forward and backward passes, each on its own
/// source's operators (numeric factorizations only; cached per mesh when
/// not augmenting).
///
/// # Errors
/// [`ArbitraryError::Dataset`] for a dataset that is not shapes of its
/// mesh, [`ArbitraryError::Mismatch`] for a
/// configuration that differs from the stored one; data, network and I/O
/// errors.
pub fn train(
    run_dir: &Path,
    dataset: &Path,
    config: &PredictorConfig,
    stop: &AtomicBool,
    progress: bool,
) -> Result<TrainSummary> {
    let data = Dataset::open(dataset)?;
    if data.manifest().channels != 3 {
        return Err(ArbitraryError::Dataset(format!(
            "{}: the predictor learns from shapes (3-channel position signals), the dataset has {} channels",
            dataset.display(),
            data.manifest().channels
        )));
    }
    let template = data.mesh().clone();
    if template.num_vertices() < config.eigenvectors {
        return Err(ArbitraryError::Dataset(format!(
            "{}: the template has {} vertices, fewer than the {} eigenvectors the predictor \
             learns: make the dataset from a finer mesh (mfm dataset pairs --mesh, refined with \
             mfm remesh --subdivide 1, or a larger --coarse-faces)",
            dataset.display(),
            template.num_vertices(),
            config.eigenvectors
        )));
    }
    crate::markers::refuse_imported(run_dir)?;
    std::fs::create_dir_all(run_dir).map_err(|e| ArbitraryError::io(run_dir, e))?;
    let spec_path = run_dir.join(PREDICTOR_SPEC);
    let targets_path = run_dir.join(TARGETS_FILE);
    let targets: Vec<f64> = if spec_path.is_file() {
        let spec: PredictorSpec = read_json(&spec_path, "a predictor run's description")?;
        same_config(run_dir, &spec.config, config)?;
        let t = mfm_files::npy::read::<f64>(&targets_path)?;
        if t.shape != [template.num_vertices(), config.eigenvectors] {
            return Err(ArbitraryError::format(
                &targets_path,
                format!("shape {:?} does not fit the dataset's template", t.shape),
            ));
        }
        t.values
    } else {
        let basis = Eigenbasis::of(&template, config.eigenvectors)?;
        let spec = PredictorSpec {
            config: config.clone(),
            dataset: dataset.to_path_buf(),
            vertices: template.num_vertices(),
            eigenvalues: basis.values.clone(),
            margins: basis.margins.clone(),
            template: Some(mfm_data::dataset::mesh_identity(&template)),
        };
        mfm_files::npy::write(
            &targets_path,
            &basis.vectors,
            &[template.num_vertices() as u64, config.eigenvectors as u64],
        )?;
        mfm_files::write_json(&spec_path, &spec)?;
        basis.vectors
    };
    let device = config.schedule.device.resolve()?;
    let k = config.eigenvectors as i64;
    let v = template.num_vertices() as i64;
    let target = Tensor::from_slice(&targets.iter().map(|&x| x as f32).collect::<Vec<_>>())
        .reshape([1, v, k])
        .to_device(device);
    let meshes = data.load_all()?;
    let sources = SourceSet::new(&template, NoiseKind::Naive)?;
    let schedule = &config.schedule;
    let batch = schedule.batch;
    let run = start_or_resume(
        run_dir,
        PREDICTOR_SPEC,
        &config.net_config(),
        schedule,
        "predictor",
        device,
    )?;
    let n = meshes.len();
    train_to_end(run, PREDICTOR_SPEC, stop, progress, |net, step| {
        let mut rng = derived_rng(schedule.seed, PURPOSE_ITEMS, step);
        let mut total = 0.0;
        for _ in 0..batch {
            let i = rng.random_range(0..n);
            let p = prepared(
                meshes.positions(i),
                None,
                schedule.augment.then_some(&mut rng),
                config.frame,
            )?;
            let ctx = if schedule.augment {
                std::sync::Arc::new(sources.build(p.clone())?)
            } else {
                sources.cached(i, p.clone())?
            };
            let out = net.forward(&ctx.tensors, &positions_tensor(&p, device), None)?;
            let l = loss::mass_weighted_mse(&ctx.tensors, &out.vertex, &target)? / batch as f64;
            total += l.double_value(&[]);
            l.f_backward()?;
        }
        Ok(total)
    })
}

/// A trained predictor, ready to run on any mesh.
#[derive(Debug)]
pub struct EigenPredictor {
    net: PoissonNet,
    spec: PredictorSpec,
}

impl EigenPredictor {
    /// Loads a finished predictor run (or a copy: `weights` with its
    /// `.json` beside it, and `spec`).
    ///
    /// # Errors
    /// Missing or unreadable files, named.
    pub fn load(run_dir: &Path) -> Result<Self> {
        let kind = FolderKind::of(run_dir);
        if kind != FolderKind::PredictorRun {
            return Err(ArbitraryError::RunFolder(format!(
                "{}: {}, not an eigenvector predictor run (mfm train --mode predictor)",
                run_dir.display(),
                kind.is()
            )));
        }
        let spec: PredictorSpec = read_json(
            &run_dir.join(PREDICTOR_SPEC),
            "a predictor run's description",
        )?;
        let weights = finished_weights(run_dir, "predictor")?;
        Self::from_files(&weights, spec)
    }

    pub(crate) fn from_files(weights: &Path, spec: PredictorSpec) -> Result<Self> {
        let mut net = PoissonNet::new(&spec.config.net_config(), Device::Cpu)?;
        net.load_weights(weights)?;
        Ok(Self { net, spec })
    }

    /// The run's description.
    pub fn spec(&self) -> &PredictorSpec {
        &self.spec
    }

    /// `k`.
    pub fn eigenvectors(&self) -> usize {
        self.spec.config.eigenvectors
    }

    /// The network.
    pub fn net(&self) -> &PoissonNet {
        &self.net
    }

    /// The prediction `[1, V, k]` for positions `x: [1, V, 3]` (already in
    /// the source's frame) on `mesh`'s tensors, without gradients, on the
    /// device of `x` (the predictor runs on its own).
    ///
    /// # Errors
    /// Shape errors of the network.
    pub fn predict_tensor(&self, mesh: &MeshTensors, x: &Tensor) -> Result<Tensor> {
        let on_net = x.to_device(self.net.device());
        let out = tch::no_grad(|| self.net.forward(mesh, &on_net, None))?;
        Ok(out.vertex.detach().to_device(x.device()))
    }

    /// The prediction on `mesh` (any triangulation; moved into the
    /// predictor's [`SourceFrame`] first: its own frame, or as it is),
    /// vertex-major `[V, k]`.
    ///
    /// # Errors
    /// A degenerate mesh, network errors.
    pub fn predict(&self, mesh: &TriMesh) -> Result<Vec<f32>> {
        let p = prepared(
            mesh.positions().to_vec(),
            None,
            None,
            self.spec.config.frame,
        )?;
        let moved = mesh
            .with_positions(p.clone())
            .map_err(|e| ArbitraryError::Source(e.to_string()))?;
        let tensors = MeshTensors::new(&moved)?;
        let y = self.predict_tensor(&tensors, &positions_tensor(&p, Device::Cpu))?;
        Ok(Vec::<f32>::try_from(y.to_kind(Kind::Float).flatten(0, -1))?)
    }
}
