//! The arbitrary-source flow: target positions generated as a signal over
//! the source mesh, with the source's own operators, noise and Poisson
//! solves, every block conditioned on `[source xyz, t, predicted
//! eigenvectors]` (`3 + 1 + k` channels).
//!
//! Training pairs come from a pairs dataset ([`mfm_data::pairs`]). Per
//! pair: both shapes go into the source's frame (and augmentation); the
//! target `x1` and the noise `x0 = sigma * (Matérn noise on the source)`
//! lose their mass-weighted means (the source's masses);
//! `x_t = (1 - t) x0 + t x1`; the loss is the flow-matching loss against
//! `x1 - x0` (vertex and Jacobian terms). Sampling integrates the velocity from noise on the
//! source with the midpoint rule, adds the source's mass-weighted centroid
//! and maps back to the source's units (with [`SourceFrame::AsIs`], the
//! imported official model's convention: no frame, no centroid, targets
//! mass-mean zero).
//!
//! Run folder: [`ARBITRARY_SPEC`], a copy of the predictor
//! ([`PREDICTOR_WEIGHTS`], its `.json`, [`PREDICTOR_COPY_SPEC`], their checksums in [`PREDICTOR_RECORD`]), the log,
//! checkpoints and, when finished, `model.safetensors` + `model.json`.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

use mfm_data::dataset::Dataset;
use mfm_data::pairs::training_pairs;
use mfm_geometry::TriMesh;
use mfm_geometry::frame::SurfaceSize;
use mfm_net::{HeadKind, PoissonNet, PoissonNetConfig, loss};
use mfm_noise::NoiseKind;
use rand::Rng;
use serde::{Deserialize, Serialize};
use tch::{Device, Kind, Tensor};

use crate::error::{ArbitraryError, Result};
use crate::markers::{ARBITRARY_SPEC, FolderKind};
use crate::predictor::{EigenPredictor, PredictorSpec, prepared};
use crate::run::{start_or_resume, train_to_end};
use crate::sources::SourceSet;
use crate::{Schedule, SourceFrame, finished_weights, read_json, same_config};
use mfm_fm::FmError;
use mfm_fm::config::OdeMethod;
use mfm_fm::context::MeshContext;
use mfm_fm::path::{ode_step, rectified_path};
use mfm_net::mesh::positions_tensor;
use mfm_train::TrainSummary;
use mfm_train::checkpoint::{NET_CONFIG_FILE, WEIGHTS_FILE};
use mfm_train::seeding::derived_rng;

/// The frozen predictor's weights, copied into the flow run.
pub const PREDICTOR_WEIGHTS: &str = "predictor.safetensors";
/// The copied predictor's description.
pub const PREDICTOR_COPY_SPEC: &str = "predictor.spec.json";
/// The checksums of the copied predictor's files (checked on every load).
pub const PREDICTOR_RECORD: &str = "predictor.state.json";
/// The copied predictor's network configuration (written beside
/// [`PREDICTOR_WEIGHTS`]).
pub const PREDICTOR_NET_CONFIG: &str = "predictor.json";

const PURPOSE_ITEMS: u64 = 21;

/// The flow's network, noise and training settings.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FlowConfig {
    /// Network width.
    pub width: usize,
    /// Poisson blocks.
    pub blocks: usize,
    /// The noise of the source distribution (on each source).
    #[serde(with = "mfm_noise::kind::as_text")]
    pub noise: NoiseKind,
    /// The noise amplitude `sigma`.
    pub sigma: f64,
    /// Midpoint steps of the sampler.
    pub ode_steps: usize,
    /// Condition on the predicted eigenvectors (the official model). With
    /// `false` their channels are zeros: the same network without the
    /// positional encoding, for ablations.
    #[serde(default = "yes")]
    pub eigenvectors: bool,
    /// Optimization.
    pub schedule: Schedule,
    /// Where sources are put before the networks see them and where the
    /// targets end up (absent in the description: [`SourceFrame::Own`]).
    #[serde(default, skip_serializing_if = "SourceFrame::is_own")]
    pub frame: SourceFrame,
}

fn yes() -> bool {
    true
}

/// Preset names of [`FlowConfig::preset`].
pub const PRESETS: [&str; 2] = ["paper", "cpu"];

impl FlowConfig {
    /// The official configuration (`moyo_arbitrary_source.yaml`): width
    /// 128, 5 blocks, `matern:100` noise of sigma 5, lr 5e-4 x 0.2 at
    /// 40k/160k, batch 32, 240k steps, clip 1, augmentation, 20 midpoint
    /// steps.
    pub fn paper() -> Self {
        Self {
            width: 128,
            blocks: 5,
            noise: NoiseKind::Matern { tau: 100.0 },
            sigma: 5.0,
            ode_steps: 20,
            eigenvectors: true,
            schedule: Schedule::step_decay(
                5e-4,
                32,
                240_000,
                vec![40_000, 160_000],
                0.2,
                1.0,
                true,
                42,
                10_000,
            ),
            frame: SourceFrame::Own,
        }
    }

    /// A CPU-scale configuration: width 32, 3 blocks, 1500 steps of batch
    /// 4 at lr 1e-3 (x 0.2 at 1000).
    pub fn cpu() -> Self {
        let mut c = Self::paper();
        c.width = 32;
        c.blocks = 3;
        c.schedule.lr = 1e-3;
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
                "unknown arbitrary-source preset {other:?}; expected one of {}",
                PRESETS.join(", ")
            ))),
        }
    }

    /// The network for `k` predicted eigenvectors: positions in and out,
    /// NJF head, `3 + 1 + k` conditioning channels.
    pub fn net_config(&self, k: usize) -> PoissonNetConfig {
        PoissonNetConfig {
            width: self.width,
            blocks: self.blocks,
            vector_layers: 3,
            in_channels: 3,
            out_channels: 3,
            cond_channels: 4 + k,
            modulation: true,
            head: HeadKind::Njf,
            global_context: false,
        }
    }
}

/// What [`ARBITRARY_SPEC`] holds.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ArbitrarySpec {
    /// The configuration.
    pub config: FlowConfig,
    /// The pairs dataset trained on.
    pub dataset: PathBuf,
    /// The predictor run it was trained with (its files are copied here).
    pub predictor: PathBuf,
    /// Vertices of the template.
    pub vertices: usize,
    /// The template's size and topology in its own frame (largest extent
    /// 1), which sources are compared with; `None` in runs trained before
    /// it was recorded.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub template_surface: Option<SurfaceSize>,
    /// The template's identity ([`mfm_data::dataset::mesh_identity`]): an
    /// experiment evaluated with the run must be of it; `None` in runs
    /// trained before it was recorded.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub template: Option<String>,
}

/// Relative difference in area (in its own frame) beyond which a source is
/// reported as unlike the template: the template's shapes vary by less.
pub const SOURCE_AREA_TOLERANCE: f64 = 0.5;

/// The conditioning `[1, V, 3 + 1 + k]` of a source at time `t`.
fn conditioning(source: &Tensor, t: f64, eigen: &Tensor) -> Tensor {
    let v = source.size()[1];
    let tt = Tensor::full([1, v, 1], t, (Kind::Float, source.device()));
    Tensor::cat(&[source, &tt, eigen], 2)
}

/// Trains (or resumes) the flow in `run_dir` on the pairs of `dataset`
/// with the finished predictor run `predictor`.
///
/// # Errors
/// [`ArbitraryError::Dataset`] for a dataset that is not a pairs dataset,
/// [`ArbitraryError::RunFolder`] for an unfinished predictor,
/// [`ArbitraryError::Mismatch`] for a predictor of another template or a
/// configuration that differs from the stored one; data, noise, network
/// and I/O errors.
pub fn train(
    run_dir: &Path,
    dataset: &Path,
    predictor_dir: &Path,
    config: &FlowConfig,
    stop: &AtomicBool,
    progress: bool,
) -> Result<TrainSummary> {
    let data = Dataset::open(dataset)?;
    let Some(pairs) = training_pairs(&data)? else {
        return Err(ArbitraryError::Dataset(format!(
            "{} is not a pairs dataset (made by `mfm dataset pairs`, or imported from the \
             authors' arbitrary-source file by `mfm dataset import`); the arbitrary-source \
             model trains on (source, target) pairs",
            dataset.display()
        )));
    };
    let template = data.mesh().clone();
    let identity = mfm_data::dataset::mesh_identity(&template);
    crate::markers::refuse_imported(run_dir)?;
    std::fs::create_dir_all(run_dir).map_err(|e| ArbitraryError::io(run_dir, e))?;
    let spec_path = run_dir.join(ARBITRARY_SPEC);
    if spec_path.is_file() {
        let spec: ArbitrarySpec = read_json(&spec_path, "an arbitrary-source run's description")?;
        same_config(run_dir, &spec.config, config)?;
    } else {
        let source = EigenPredictor::load(predictor_dir)?;
        if let Some(theirs) = &source.spec().template
            && *theirs != identity
        {
            return Err(ArbitraryError::Mismatch(format!(
                "the predictor in {} was trained on another template (the mesh of {}, {theirs}) \
                 than the dataset {} (its mesh: {identity}): train a predictor on this dataset",
                predictor_dir.display(),
                source.spec().dataset.display(),
                dataset.display()
            )));
        }
        if source.spec().config.frame != config.frame {
            return Err(ArbitraryError::Mismatch(format!(
                "the predictor in {} puts sources in the {:?} frame, the flow's configuration in \
                 the {:?} frame: they must agree",
                predictor_dir.display(),
                source.spec().config.frame,
                config.frame
            )));
        }
        if source.spec().vertices != template.num_vertices() {
            return Err(ArbitraryError::Mismatch(format!(
                "the predictor in {} was trained on a template of {} vertices, the dataset's has {}",
                predictor_dir.display(),
                source.spec().vertices,
                template.num_vertices()
            )));
        }
        for (from, to) in [
            (WEIGHTS_FILE, PREDICTOR_WEIGHTS),
            (NET_CONFIG_FILE, PREDICTOR_NET_CONFIG),
        ] {
            let (a, b) = (predictor_dir.join(from), run_dir.join(to));
            let bytes = std::fs::read(&a).map_err(|e| ArbitraryError::io(&a, e))?;
            mfm_train::checkpoint::write_atomic(&b, &bytes)?;
        }
        mfm_files::write_json(run_dir.join(PREDICTOR_COPY_SPEC), source.spec())?;
        mfm_files::write_json(
            &spec_path,
            &ArbitrarySpec {
                config: config.clone(),
                dataset: dataset.to_path_buf(),
                predictor: predictor_dir.to_path_buf(),
                vertices: template.num_vertices(),
                template_surface: Some(SurfaceSize::of(&template).normalized()),
                template: Some(identity.clone()),
            },
        )?;
        mfm_train::checkpoint::write_file_record(
            run_dir,
            PREDICTOR_RECORD,
            &[PREDICTOR_WEIGHTS, PREDICTOR_NET_CONFIG, PREDICTOR_COPY_SPEC],
        )?;
    }
    let predictor = load_copied_predictor(run_dir)?;
    let k = predictor.eigenvectors();
    let meshes = data.load_all()?;
    if pairs.is_empty() {
        return Err(ArbitraryError::Dataset(format!(
            "{} has no pairs (one pose per shape?)",
            dataset.display()
        )));
    }
    let sources = SourceSet::new(&template, config.noise)?;
    let schedule = &config.schedule;
    let (batch, sigma) = (schedule.batch, config.sigma as f32);
    let device = schedule.device.resolve()?;
    let mut eigen_cache: HashMap<usize, Tensor> = HashMap::new();
    let run = start_or_resume(
        run_dir,
        ARBITRARY_SPEC,
        &config.net_config(k),
        schedule,
        "arbitrary-source flow",
        device,
    )?;
    train_to_end(run, ARBITRARY_SPEC, stop, progress, |net, step| {
        let mut rng = derived_rng(schedule.seed, PURPOSE_ITEMS, step);
        let mut total = 0.0;
        for j in 0..batch {
            let (si, ti) = pairs[rng.random_range(0..pairs.len())];
            let t = rng.random::<f64>();
            let mut target = meshes.positions(ti);
            let src = prepared(
                meshes.positions(si),
                Some(&mut target),
                schedule.augment.then_some(&mut rng),
                config.frame,
            )?;
            let ctx = if schedule.augment {
                Arc::new(sources.build(src.clone())?)
            } else {
                sources.cached(si, src.clone())?
            };
            let x_src = positions_tensor(&src, device);
            let eigen = match (schedule.augment, eigen_cache.get(&si)) {
                _ if !config.eigenvectors => {
                    Tensor::zeros([1, x_src.size()[1], k as i64], (Kind::Float, device))
                }
                (false, Some(e)) => e.shallow_clone(),
                _ => {
                    let e = predictor.predict_tensor(&ctx.tensors, &x_src)?;
                    if !schedule.augment {
                        eigen_cache.insert(si, e.shallow_clone());
                    }
                    e
                }
            };
            let item = step as usize * batch + j;
            let noise = ctx
                .noise
                .sample_range_f32(item, 1, 3, schedule.seed)?
                .into_data();
            let v = template.num_vertices() as i64;
            let x0 = Tensor::from_slice(&noise)
                .reshape([1, v, 3])
                .to_device(device)
                * f64::from(sigma);
            let x0 = ctx.tensors.remove_mass_mean(&x0)?;
            let x1 = ctx
                .tensors
                .remove_mass_mean(&positions_tensor(&target, device))?;
            let (xt, delta) = rectified_path(&x0, &x1, t);
            let cond = conditioning(&x_src, t, &eigen);
            let out = net.forward(&ctx.tensors, &xt, Some(&cond))?;
            let l = loss::flow_matching_loss(&ctx.tensors, &out, &delta)? / batch as f64;
            total += l.double_value(&[]);
            l.f_backward()?;
        }
        Ok(total)
    })
}

fn load_copied_predictor(run_dir: &Path) -> Result<EigenPredictor> {
    mfm_train::checkpoint::verify_file_record(run_dir, PREDICTOR_RECORD)?;
    let spec: PredictorSpec = read_json(
        &run_dir.join(PREDICTOR_COPY_SPEC),
        "the copied predictor's description",
    )?;
    EigenPredictor::from_files(&run_dir.join(PREDICTOR_WEIGHTS), spec)
}

/// A finished arbitrary-source run, ready to generate on any source mesh.
#[derive(Debug)]
pub struct ArbitrarySampler {
    net: PoissonNet,
    predictor: EigenPredictor,
    spec: ArbitrarySpec,
}

impl ArbitrarySampler {
    /// Loads a finished run.
    ///
    /// # Errors
    /// Missing or unreadable files, named; an unfinished run.
    pub fn load(run_dir: &Path) -> Result<Self> {
        let kind = FolderKind::of(run_dir);
        if kind != FolderKind::ArbitraryRun {
            return Err(ArbitraryError::RunFolder(format!(
                "{}: {}, not an arbitrary-source run (mfm train --mode arbitrary)",
                run_dir.display(),
                kind.is()
            )));
        }
        let spec: ArbitrarySpec = read_json(
            &run_dir.join(ARBITRARY_SPEC),
            "an arbitrary-source run's description",
        )?;
        let weights = finished_weights(run_dir, "model")?;
        let predictor = load_copied_predictor(run_dir)?;
        if predictor.spec().config.frame != spec.config.frame {
            return Err(ArbitraryError::format(
                run_dir.join(ARBITRARY_SPEC),
                format!(
                    "the flow's source frame ({:?}) is not its predictor's ({:?}, in {PREDICTOR_COPY_SPEC})",
                    spec.config.frame,
                    predictor.spec().config.frame
                ),
            ));
        }
        let mut net = PoissonNet::new(
            &spec.config.net_config(predictor.eigenvectors()),
            Device::Cpu,
        )?;
        net.load_weights(&weights)?;
        Ok(Self {
            net,
            predictor,
            spec,
        })
    }

    /// The run's description.
    pub fn spec(&self) -> &ArbitrarySpec {
        &self.spec
    }

    /// Samples with `steps` midpoint steps instead of the run's
    /// `ode_steps` (at least 1).
    pub fn set_ode_steps(&mut self, steps: usize) {
        self.spec.config.ode_steps = steps.max(1);
    }

    /// Why `source` does not look like a shape of the template the run was
    /// trained on: another Euler characteristic (genus, holes), another
    /// number of components, or an area (both scaled to a largest extent
    /// of one) off by more than [`SOURCE_AREA_TOLERANCE`]; empty when it
    /// does, or for a run that did not record its template.
    pub fn source_warnings(&self, source: &TriMesh) -> Vec<String> {
        match &self.spec.template_surface {
            Some(t) => t.mismatches_with(
                &SurfaceSize::of(source).normalized(),
                SOURCE_AREA_TOLERANCE,
                "the template",
            ),
            None => Vec::new(),
        }
    }

    /// The predictor the flow was trained with.
    pub fn predictor(&self) -> &EigenPredictor {
        &self.predictor
    }

    /// `count` targets generated over `source` (any mesh; its own frame,
    /// the result back in its units with the source's mass-weighted
    /// centroid; with [`SourceFrame::AsIs`] the source as it is and the
    /// result mass-mean zero), samples `first..first + count` of `seed`'s
    /// noise stream. Each sample's noise depends only on `(seed, index)`.
    ///
    /// Cost: the source's operators and factorizations once, the predictor
    /// once, then `2 ode_steps` network evaluations per sample.
    ///
    /// # Errors
    /// A degenerate source, noise and network errors;
    /// [`mfm_fm::FmError::Diverged`] for a non-finite result.
    pub fn sample(
        &self,
        source: &TriMesh,
        first: usize,
        count: usize,
        seed: u64,
    ) -> Result<Vec<Vec<[f64; 3]>>> {
        let mut positions = source.positions().to_vec();
        let frame = self.spec.config.frame.apply(&mut positions, None)?;
        let moved = source
            .with_positions(positions.clone())
            .map_err(|e| ArbitraryError::Source(e.to_string()))?;
        let ctx = MeshContext::new(&moved, self.spec.config.noise)?;
        let x_src = positions_tensor(&positions, Device::Cpu);
        let eigen = if self.spec.config.eigenvectors {
            self.predictor.predict_tensor(&ctx.tensors, &x_src)?
        } else {
            let k = self.predictor.eigenvectors() as i64;
            Tensor::zeros([1, x_src.size()[1], k], (Kind::Float, Device::Cpu))
        };
        // the official model's targets stay mass-mean zero (AsIs)
        let centroid = match frame {
            Some(_) => Some(ctx.tensors.mass_weighted_mean(&x_src)?),
            None => None,
        };
        let v = source.num_vertices() as i64;
        let steps = self.spec.config.ode_steps.max(1);
        let h = 1.0 / steps as f64;
        let velocity = |x: &Tensor, t: f64| -> Result<Tensor> {
            let cond = conditioning(&x_src, t, &eigen);
            Ok(tch::no_grad(|| self.net.forward(&ctx.tensors, x, Some(&cond)))?.vertex)
        };
        (first..first + count)
            .map(|i| {
                let noise = ctx.noise.sample_range_f32(i, 1, 3, seed)?.into_data();
                let x0 = Tensor::from_slice(&noise).reshape([1, v, 3]) * self.spec.config.sigma;
                let mut x = ctx.tensors.remove_mass_mean(&x0)?;
                for s in 0..steps {
                    x = ode_step(OdeMethod::Midpoint, &x, s as f64 * h, h, &velocity)?;
                }
                let x = match &centroid {
                    Some(c) => x + c,
                    None => x,
                };
                let x = x.to_kind(Kind::Double).flatten(0, -1);
                let flat = Vec::<f64>::try_from(x)?;
                if flat.iter().any(|y| !y.is_finite()) {
                    return Err(FmError::Diverged(format!(
                        "sample {i} on the source is not finite after {steps} ODE steps"
                    ))
                    .into());
                }
                Ok(flat
                    .chunks_exact(3)
                    .map(|c| {
                        let p = [c[0], c[1], c[2]];
                        frame.as_ref().map_or(p, |f| f.from_canonical(p))
                    })
                    .collect())
            })
            .collect()
    }

    /// The predictor's output on `source` (`[V, k]`, vertex-major).
    ///
    /// # Errors
    /// As [`EigenPredictor::predict`].
    pub fn eigenvectors_on(&self, source: &TriMesh) -> Result<Vec<f32>> {
        self.predictor.predict(source)
    }

    /// The flow network.
    pub fn net(&self) -> &PoissonNet {
        &self.net
    }
}
