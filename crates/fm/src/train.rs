//! Training a PoissonNet velocity field by rectified flow matching
//! (docs/conventions.md, "Flow matching"; paper section 4).
//!
//! Before anything else the training mesh goes to the run's frame
//! ([`crate::config::FrameChoice`], by default the canonical frame of
//! [`mfm_geometry::frame`]: bounding box centred, largest extent 1), and so do
//! position signals; the map is stored in `flow.json`.
//!
//! One step on a batch of `B` signals `f_1` (`[B, V, C]`) of the training
//! mesh, all in the frame:
//! 1. `f_0`: noise on the training mesh (the run's kind, times its scale
//!    `sigma`: by linearity `solve(L + tau M, sigma sqrt(m) n)`),
//!    plus, with `noise.prior`, a draw of the data prior
//!    ([`crate::prior`]) of the same index;
//!    `t ~ U[0, 1)` per batch item (or another `train.time` distribution);
//!    the noise samples are paired with the signals independently, or with
//!    `train.coupling = "ot:P"` by the least-cost assignment within a pool
//!    of `P` of each ([`crate::coupling`]);
//! 2. with `train.center` (the default), `f_0` and `f_1` each minus its
//!    mass-weighted mean per channel and connected component;
//! 3. `f_t = (1 - t) f_0 + t f_1`, target `delta = f_1 - f_0`;
//! 4. `(v, J) = net(f_t | t [, source xyz])`, `v` plus the run's constant
//!    velocity offset when not centring;
//! 5. loss: [`mfm_net::loss::weighted_flow_matching_loss`] (mass-weighted
//!    MSE of `v` against `delta` plus `train.jacobian_weight` times the
//!    area-weighted MSE of `J` against `G delta`); for clean-signal
//!    prediction (`model.prediction = "clean"`, the output read as `f_1`)
//!    the same loss of `v = (out - f_t) / (1 - t)`, i.e. `|out - f_1|^2 /
//!    (1 - t)^2` with the weight clipped at
//!    [`CLEAN_WEIGHT_MAX`];
//! 6. backward; then the training loop every mfm network shares
//!    ([`mfm_train::TrainingLoop`], this module's [`Objective`] being steps
//!    1-5) clips the global gradient norm, takes one [`mfm_train::Adam`]
//!    step at the scheduled learning rate and (with `train.ema`) moves the
//!    weight average towards the new weights. Everything is `f32`.
//!
//! ## Determinism and resuming
//! Every random choice is a pure function of the seed and the step `s`:
//! - batch: positions `s B .. s B + B` (with a pool, `s P .. s P + P`, of
//!   which the first `B` are trained on) of an endless sequence of epochs, each
//!   a permutation of the dataset drawn from the ChaCha8 stream `e` of a key
//!   derived from `(seed, "epoch")`;
//! - times: `B` draws from stream `s` of a key derived from `(seed,
//!   "time")` (uniform `f32`, or `train.time`'s distribution);
//! - noise: samples `s B .. s B + B` (with a pool, `s P .. s P + P`) of the
//!   noise sequence of `seed`
//!   (`NoiseSampler::sample_range_f32`), which do not depend on the batch;
//! - initial weights: libtorch's generator seeded with `seed` (under a
//!   process-wide lock, see [`Trainer::new`]).
//!
//! So a checkpoint needs no generator state beyond its step, and a resumed
//! run repeats exactly the computation of an uninterrupted one: its weights
//! and log are bit-identical (on the CPU, with the same thread count;
//! CUDA kernels that accumulate with atomics are not bit-reproducible).
//!
//! ## Files
//! See [`crate::checkpoint`] for the run folder. The log `train_log.csv` has
//! the columns `step,loss,lr,grad_norm,seconds`: after `step` steps, the mean
//! loss and mean unclipped gradient norm over the steps since the previous
//! row, the learning rate of the last of them, and training seconds so far.
//! A resumed run first drops rows after its checkpoint, so rows are never
//! duplicated.
//!
//! # Example
//! ```no_run
//! use std::sync::Arc;
//! use std::sync::atomic::AtomicBool;
//! use mfm_data::InMemorySignals;
//! use mfm_fm::{config::RunConfig, train::Trainer};
//! let mesh = mfm_geometry::procedural::icosphere(2);
//! let v = mesh.num_vertices();
//! let signals = Arc::new(InMemorySignals::new(vec![0.5; 4 * v], 4, v, 1).unwrap());
//! let cfg = RunConfig::preset("cpu").unwrap();
//! let mut trainer = Trainer::new("runs/demo", cfg, &mesh, signals).unwrap();
//! let summary = trainer.run(&AtomicBool::new(false), true).unwrap();
//! println!("{:.3} s/step", summary.seconds_per_step);
//! ```

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

use mfm_geometry::TriMesh;
use mfm_geometry::frame::{CanonicalFrame, SurfaceSize};
use mfm_net::mesh::positions_tensor;
use mfm_net::{MeshTensors, PoissonNet, loss};
use mfm_noise::NoiseSampler;
use mfm_train::checkpoint::{self, WEIGHTS_FILE};
use mfm_train::resume::{self, ConfigChange, ResumePolicy};
use mfm_train::seeding::derived_rng;
use mfm_train::{LoopConfig, Objective, RunNames, TrainingLoop};
use rand::Rng;
use tch::{Device, Tensor};

pub use mfm_train::TrainSummary;

use crate::checkpoint::{CONFIG_FILE, FLOW_FILE, FlowSpec, Prediction};
use crate::config::{CLEAN_WEIGHT_MAX, FrameChoice, NoiseScale, RunConfig};
use crate::context::MeshContext;
use crate::coupling::{Coupling, least_cost_assignment, squared_distances};
use crate::device::DeviceChoice;
use crate::error::{FmError, Result};
use crate::path::rectified_path;
use crate::prior::{GaussianPrior, PRIOR_FILE, PriorKind, read_prior};
use crate::sample::{conditioning, offset_tensor};
use mfm_data::signals::{Displacements, FramedPositions, SignalSource};

/// Description of the randomness recorded in every checkpoint.
const RNG_DESCRIPTION: &str = "ChaCha8 streams keyed by (seed, purpose), stream = step or epoch; \
     noise = NoiseSampler::sample_range_f32(step * P, P, C, seed), P the batch or train.coupling's pool; \
     no state beyond the step";

/// Purposes of derived random keys.
const PURPOSE_EPOCH: u64 = 1;
const PURPOSE_TIME: u64 = 2;
const PURPOSE_STATS: u64 = 3;
const PURPOSE_AUGMENT: u64 = 4;

/// Signals read (at most) to estimate data statistics.
const STATS_SIGNALS: usize = 256;
/// Noise samples drawn to estimate the noise's magnitude.
const STATS_NOISE: usize = 64;

/// Batch order: an endless sequence of epochs, each a permutation of
/// `0..n` that depends only on `(seed, epoch)`.
#[derive(Debug)]
struct EpochOrder {
    seed: u64,
    n: usize,
    cache: Vec<(u64, Vec<usize>)>,
}

impl EpochOrder {
    fn new(seed: u64, n: usize) -> Self {
        Self {
            seed,
            n,
            cache: Vec::new(),
        }
    }

    fn permutation(&mut self, epoch: u64) -> &[usize] {
        if let Some(i) = self.cache.iter().position(|(e, _)| *e == epoch) {
            return &self.cache[i].1;
        }
        let mut rng = derived_rng(self.seed, PURPOSE_EPOCH, epoch);
        let mut p: Vec<usize> = (0..self.n).collect();
        for i in (1..self.n).rev() {
            let j = rng.random_range(0..=i);
            p.swap(i, j);
        }
        if self.cache.len() >= 2 {
            self.cache.remove(0);
        }
        self.cache.push((epoch, p));
        &self.cache[self.cache.len() - 1].1
    }

    /// Signal indices of step `step` with `batch` signals.
    fn indices(&mut self, step: u64, batch: usize) -> Vec<usize> {
        let n = self.n as u64;
        (0..batch as u64)
            .map(|j| {
                let pos = step * batch as u64 + j;
                let (epoch, within) = (pos / n, (pos % n) as usize);
                self.permutation(epoch)[within]
            })
            .collect()
    }
}

/// How [`Trainer::resume`] found the run.
#[derive(Debug)]
pub struct ResumeInfo {
    /// The checkpoint resumed from (`None`: none existed, started at 0).
    pub checkpoint: Option<PathBuf>,
    /// Its step.
    pub step: u64,
    /// Newer checkpoints that failed their integrity check, with the reason.
    pub skipped: Vec<(PathBuf, FmError)>,
}

/// What one flow-matching step computes: the training data, the noise
/// and the mesh operators in the run's frame (the [`Objective`] of a
/// [`Trainer`]'s loop).
struct FlowObjective {
    config: RunConfig,
    flow: FlowSpec,
    device: Device,
    mesh: MeshTensors,
    xyz: Tensor,
    /// The velocity offset added in training (uncentred runs only).
    offset: Option<Tensor>,
    signals: Arc<dyn SignalSource>,
    noise: NoiseSampler,
    /// The data prior added to every noise sample (`noise.prior`).
    prior: Option<GaussianPrior>,
    order: EpochOrder,
}

/// A training run in a run folder. See the [module docs](self).
pub struct Trainer {
    objective: FlowObjective,
    run: TrainingLoop,
    resumed: Option<ResumeInfo>,
}

impl std::fmt::Debug for Trainer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Trainer")
            .field("run_dir", &self.run.run_dir())
            .field("step", &self.run.step())
            .field("total_steps", &self.objective.config.train.steps)
            .field("device", &self.objective.device)
            .field("flow", &self.objective.flow)
            .finish()
    }
}

/// The loop's settings of a flow run's `[train]` table.
fn loop_config(config: &RunConfig) -> LoopConfig {
    let t = &config.train;
    LoopConfig {
        steps: t.steps,
        lr: t.lr,
        lr_schedule: t.lr_schedule.clone(),
        grad_clip: t.grad_clip,
        adam_beta1: t.adam_beta1,
        adam_beta2: t.adam_beta2,
        adam_eps: t.adam_eps,
        seed: t.seed,
        checkpoint_every: t.checkpoint_every,
        keep_checkpoints: t.keep_checkpoints,
        keep_at: t.keep_at.clone(),
        log_every: t.log_every,
        ema: t.ema,
    }
}

/// What a flow run's messages and checkpoints call things.
fn run_names() -> RunNames {
    RunNames {
        what: "training".into(),
        lr_setting: "train.lr".into(),
        steps_setting: "train.steps".into(),
        randomness: RNG_DESCRIPTION.into(),
    }
}

fn check_signals(mesh: &TriMesh, signals: &dyn SignalSource) -> Result<()> {
    if signals.is_empty() {
        return Err(FmError::Config("the dataset has no signals".into()));
    }
    if signals.channels() == 0 {
        return Err(FmError::Config(
            "the dataset's signals have 0 channels".into(),
        ));
    }
    if signals.num_vertices() != mesh.num_vertices() {
        return Err(FmError::SizeMismatch {
            what: "vertices per signal (the training mesh's vertex count is expected)".into(),
            expected: mesh.num_vertices(),
            found: signals.num_vertices(),
        });
    }
    Ok(())
}

/// Mass-weighted statistics of up to [`STATS_SIGNALS`] evenly spaced
/// signals: per-channel mean of the surface means, and the root-mean-square
/// deviation from each signal's own channel means.
fn data_statistics(signals: &dyn SignalSource, mass: &[f64]) -> Result<(Vec<f64>, f64)> {
    let (n, v, c) = (signals.len(), signals.num_vertices(), signals.channels());
    let k = n.min(STATS_SIGNALS);
    let indices: Vec<usize> = (0..k).map(|i| i * n / k).collect();
    let area: f64 = mass.iter().sum();
    let mut mean = vec![0.0f64; c];
    let mut sq = 0.0f64;
    let mut buf = Vec::new();
    for chunk in indices.chunks(32) {
        buf.resize(chunk.len() * v * c, 0.0f32);
        signals.read_into(chunk, &mut buf)?;
        for sig in buf.chunks(v * c) {
            let mut mu = vec![0.0f64; c];
            for (vi, m) in mass.iter().enumerate() {
                for ch in 0..c {
                    mu[ch] += m * f64::from(sig[vi * c + ch]);
                }
            }
            mu.iter_mut().for_each(|x| *x /= area);
            for (vi, m) in mass.iter().enumerate() {
                for ch in 0..c {
                    let d = f64::from(sig[vi * c + ch]) - mu[ch];
                    sq += m * d * d;
                }
            }
            for ch in 0..c {
                mean[ch] += mu[ch] / k as f64;
            }
        }
    }
    let rms = (sq / (area * (k * c) as f64)).sqrt();
    Ok((mean, rms))
}

/// Root-mean-square value (mass-weighted over the surface) of the unscaled
/// noise, from [`STATS_NOISE`] samples of a seed derived from `seed`.
fn noise_rms(noise: &NoiseSampler, seed: u64) -> Result<f64> {
    let stats_seed = derived_rng(seed, PURPOSE_STATS, 0).random::<u64>();
    let batch = noise.sample(STATS_NOISE, 1, stats_seed)?;
    let mass = noise.mass();
    let area: f64 = mass.iter().sum();
    let mut sq = 0.0;
    for s in 0..STATS_NOISE {
        sq += batch
            .sample(s)
            .iter()
            .zip(mass)
            .map(|(x, m)| m * x * x)
            .sum::<f64>();
    }
    Ok((sq / (area * STATS_NOISE as f64)).sqrt())
}

/// Resolves the flow spec of a new run on its training data.
fn resolve_flow(
    config: &RunConfig,
    noise: &NoiseSampler,
    signals: &dyn SignalSource,
    frame: TrainingFrame,
) -> Result<FlowSpec> {
    let c = signals.channels();
    let (mean, data_rms) = data_statistics(signals, noise.mass())?;
    let positive = |what: &str, x: f64| {
        if x.is_finite() && x > 0.0 {
            Ok(x)
        } else {
            Err(FmError::Config(format!(
                "noise.scale = \"{}\": the {what} is {x}, so no finite positive scale exists",
                config.noise.scale
            )))
        }
    };
    let noise_scale = match config.noise.scale {
        NoiseScale::Factor(x) => x,
        NoiseScale::Unit => 1.0 / positive("noise's RMS", noise_rms(noise, config.train.seed)?)?,
        NoiseScale::Data => {
            positive("data's RMS (about each signal's mean)", data_rms)?
                / positive("noise's RMS", noise_rms(noise, config.train.seed)?)?
        }
    };
    // the NJF head's output has zero mean, so the mean must come from the
    // offset; a linear head learns it unless the targets are centred
    let offset_on = config.model.mean_offset && (config.model.head.is_njf() || config.train.center);
    Ok(FlowSpec {
        channels: c,
        noise: config.noise.kind,
        noise_scale,
        condition_on_xyz: config.model.condition_on_xyz,
        velocity_offset: if offset_on { mean } else { vec![0.0; c] },
        frame: frame.frame,
        positions: frame.positions,
        centered: config.train.center,
        training_surface: Some(frame.size),
        prediction: config.model.prediction,
        displacements: config.model.displacements,
        prior: None,
    })
}

/// How a new run's training mesh and signals enter the training frame.
#[derive(Clone, Copy, Debug)]
struct TrainingFrame {
    frame: CanonicalFrame,
    positions: bool,
    size: SurfaceSize,
}

impl TrainingFrame {
    fn resolve(config: &RunConfig, mesh: &TriMesh, channels: usize) -> Result<Self> {
        let frame = match config.dataset.frame {
            FrameChoice::Canonical => CanonicalFrame::of(mesh).map_err(|e| {
                FmError::Config(format!("the training mesh has no canonical frame: {e}"))
            })?,
            FrameChoice::AsIs => CanonicalFrame::identity(),
        };
        let positions = config.dataset.signals_are_positions(channels);
        if positions && channels != 3 {
            return Err(FmError::Config(format!(
                "dataset.positions = true needs 3-channel signals, the dataset has {channels}"
            )));
        }
        if config.model.displacements && !positions {
            return Err(FmError::Config(format!(
                "model.displacements = true needs position signals (3 channels, dataset.positions not false); the dataset has {channels} channel(s) of values"
            )));
        }
        Ok(Self {
            frame,
            positions,
            size: SurfaceSize::of(mesh),
        })
    }
}

/// The training mesh and signals in `frame` (signals move only when they
/// are `positions`), as displacements of the framed mesh when the flow
/// generates those.
fn in_frame(
    frame: CanonicalFrame,
    positions: bool,
    displacements: bool,
    mesh: &TriMesh,
    signals: Arc<dyn SignalSource>,
) -> Result<(TriMesh, Arc<dyn SignalSource>)> {
    let framed = frame.apply(mesh);
    let mut s = signals;
    if positions && !frame.is_identity() {
        s = Arc::new(FramedPositions::new(s, frame)?);
    }
    if displacements {
        s = Arc::new(Displacements::new(s, framed.positions().to_vec())?);
    }
    Ok((framed, s))
}

/// Fields of a run's configuration that may change when it is resumed:
/// how long it runs, how it checkpoints, where it runs and where its data
/// now lives. Every other field shapes the model or the optimisation.
pub const RESUMABLE_FIELDS: &[&str] = &[
    "dataset.path",
    "train.steps",
    "train.checkpoint_every",
    "train.keep_checkpoints",
    "train.keep_at",
    "train.threads",
    "train.device",
];

/// The fields in which `after` differs from `before`, in TOML order of
/// their dotted paths.
///
/// # Errors
/// As [`RunConfig::to_toml_string`].
fn config_changes(before: &RunConfig, after: &RunConfig) -> Result<Vec<ConfigChange>> {
    let value = |c: &RunConfig| -> Result<serde_json::Value> {
        let v: toml::Value = toml::from_str(&c.to_toml_string()?).map_err(|e| {
            FmError::Config(format!("internal: a configuration does not read back: {e}"))
        })?;
        serde_json::to_value(v).map_err(|e| {
            FmError::Config(format!(
                "internal: a configuration is not a JSON value: {e}"
            ))
        })
    };
    Ok(resume::changes(&value(before)?, &value(after)?))
}

/// The configuration a resumed run goes on with: the checkpoint's, with the
/// edits made since to the run folder's `config.toml` when they are all in
/// [`RESUMABLE_FIELDS`].
fn with_resumable_edits(run_dir: &Path, saved: RunConfig, step: u64) -> Result<RunConfig> {
    let path = run_dir.join(CONFIG_FILE);
    if !path.exists() {
        return Ok(saved);
    }
    let edited = RunConfig::from_toml_file(&path)?;
    let changes = config_changes(&saved, &edited)?;
    resume::refuse_edits(
        &path,
        step,
        &changes,
        Some(edited.train.steps),
        ResumePolicy {
            resumable: RESUMABLE_FIELDS,
            steps_field: "train.steps",
            otherwise: "start a new run with --config",
        },
    )?;
    edited.validate()?;
    Ok(edited)
}

impl Trainer {
    /// Starts a new run in `run_dir` (created if needed): writes
    /// `config.toml`, resolves and writes `flow.json` (noise scale, mean
    /// offset; reads up to 256 signals), starts `train_log.csv`, builds the
    /// mesh operators, the noise sampler and the network (initial weights
    /// from `config.train.seed`).
    ///
    /// Also sets libtorch's thread count when `train.threads > 0` and tunes
    /// the allocator ([`mfm_net::runtime::tune_allocator`]); both are
    /// process-wide.
    ///
    /// # Errors
    /// [`FmError::Config`] when `run_dir` already holds checkpoints or a
    /// final model (use [`Trainer::resume`]), for an invalid configuration,
    /// or a dataset that does not fit the mesh; mesh, noise and I/O errors.
    pub fn new(
        run_dir: impl AsRef<Path>,
        config: RunConfig,
        mesh: &TriMesh,
        signals: Arc<dyn SignalSource>,
    ) -> Result<Self> {
        let run_dir = run_dir.as_ref().to_path_buf();
        config.validate()?;
        check_signals(mesh, signals.as_ref())?;
        if !checkpoint::list_checkpoints(&run_dir)?.is_empty()
            || run_dir.join(WEIGHTS_FILE).exists()
        {
            return Err(FmError::Config(format!(
                "{} already holds a trained run (checkpoints or {WEIGHTS_FILE}); resume it or choose another folder",
                run_dir.display()
            )));
        }
        let frame = TrainingFrame::resolve(&config, mesh, signals.channels())?;
        std::fs::create_dir_all(&run_dir).map_err(|e| FmError::io(&run_dir, e))?;
        config.write_toml_file(run_dir.join(CONFIG_FILE))?;
        Self::start(run_dir, config, frame, mesh, signals)
    }

    /// Resolves and writes the flow spec of a fresh run (from
    /// [`Trainer::new`], or [`Trainer::resume`] on a folder without
    /// checkpoints), then builds it.
    fn start(
        run_dir: PathBuf,
        config: RunConfig,
        frame: TrainingFrame,
        mesh: &TriMesh,
        signals: Arc<dyn SignalSource>,
    ) -> Result<Self> {
        let (framed_mesh, framed_signals) = in_frame(
            frame.frame,
            frame.positions,
            config.model.displacements,
            mesh,
            signals,
        )?;
        let context = MeshContext::new(&framed_mesh, config.noise.kind)?;
        let mut flow = resolve_flow(&config, &context.noise, framed_signals.as_ref(), frame)?;
        let prior = match config.noise.prior {
            PriorKind::None => None,
            PriorKind::Gaussian => {
                let prior = GaussianPrior::fit(
                    &framed_mesh,
                    framed_signals.as_ref(),
                    config.noise.prior_directions,
                )?;
                flow.prior = Some(prior.write(&run_dir.join(PRIOR_FILE))?);
                Some(prior)
            }
        };
        flow.write(run_dir.join(FLOW_FILE))?;
        let t = Self::build(
            run_dir,
            config,
            flow,
            (&framed_mesh, framed_signals),
            context,
            prior,
        )?;
        t.run.start_log()?;
        Ok(t)
    }

    /// Continues the run in `run_dir` from its newest valid checkpoint, with
    /// the configuration stored in that checkpoint; `mesh` and `signals`
    /// must be the run's training data.
    ///
    /// Checkpoints that fail their integrity check are skipped with a
    /// warning on standard error (and listed in [`Trainer::resumed`]); the
    /// log is cut back to the checkpoint's step. A run folder without any
    /// checkpoint starts over from step 0 with its `config.toml`.
    ///
    /// # Errors
    /// The error of the newest checkpoint when none is valid; configuration,
    /// data and loading errors naming their file.
    pub fn resume(
        run_dir: impl AsRef<Path>,
        mesh: &TriMesh,
        signals: Arc<dyn SignalSource>,
    ) -> Result<Self> {
        Self::resume_with_device(run_dir, mesh, signals, None)
    }

    /// [`Trainer::resume`] on another device than the stored configuration's
    /// `train.device` (checkpoints hold CPU tensors, so a run started on a
    /// GPU can go on on the CPU and back). The steps after the checkpoint
    /// differ from an uninterrupted run only by the devices' round-off; the
    /// next checkpoints store the new choice.
    ///
    /// # Errors
    /// As [`Trainer::resume`]; [`FmError::Config`] for
    /// [`DeviceChoice::Cuda`] without a GPU.
    pub fn resume_on(
        run_dir: impl AsRef<Path>,
        mesh: &TriMesh,
        signals: Arc<dyn SignalSource>,
        device: DeviceChoice,
    ) -> Result<Self> {
        Self::resume_with_device(run_dir, mesh, signals, Some(device))
    }

    fn resume_with_device(
        run_dir: impl AsRef<Path>,
        mesh: &TriMesh,
        signals: Arc<dyn SignalSource>,
        device: Option<DeviceChoice>,
    ) -> Result<Self> {
        let with_device = |mut config: RunConfig| {
            if let Some(d) = device {
                config.train.device = d;
            }
            config
        };
        let run_dir = run_dir.as_ref().to_path_buf();
        checkpoint::remove_stale_temporaries(&run_dir)?;
        let (best, skipped) = crate::checkpoint::newest_valid_checkpoint(&run_dir)?;
        let skipped: Vec<(PathBuf, FmError)> = skipped
            .into_iter()
            .map(|(dir, e)| (dir, FmError::from(e)))
            .collect();
        for (dir, err) in &skipped {
            eprintln!(
                "warning: skipping checkpoint {}: {err}; falling back to an older one",
                dir.display()
            );
        }
        let Some((info, state)) = best else {
            if let Some((_, err)) = skipped.into_iter().next() {
                return Err(err);
            }
            checkpoint::refuse_restart_over_final_model(&run_dir)?;
            let config = with_device(RunConfig::from_toml_file(run_dir.join(CONFIG_FILE))?);
            config.validate()?;
            check_signals(mesh, signals.as_ref())?;
            let frame = TrainingFrame::resolve(&config, mesh, signals.channels())?;
            let mut t = Self::start(run_dir, config, frame, mesh, signals)?;
            t.resumed = Some(ResumeInfo {
                checkpoint: None,
                step: 0,
                skipped: Vec::new(),
            });
            return Ok(t);
        };
        let saved = RunConfig::from_toml_file(info.dir.join(CONFIG_FILE))?;
        let config = with_device(with_resumable_edits(&run_dir, saved, state.step)?);
        let flow = FlowSpec::read(info.dir.join(FLOW_FILE))?;
        check_signals(mesh, signals.as_ref())?;
        if flow.channels != signals.channels() {
            return Err(FmError::SizeMismatch {
                what: format!(
                    "channels of the dataset (the run {} was trained on)",
                    run_dir.display()
                ),
                expected: flow.channels,
                found: signals.channels(),
            });
        }
        let (framed_mesh, framed_signals) = in_frame(
            flow.frame,
            flow.positions,
            flow.displacements,
            mesh,
            signals,
        )?;
        let context = MeshContext::new(&framed_mesh, config.noise.kind)?;
        let prior = read_prior(&info.dir.join(FLOW_FILE), &flow)?;
        if let Some(p) = &prior {
            if p.mesh().num_vertices() != framed_mesh.num_vertices() {
                return Err(FmError::SizeMismatch {
                    what: format!("vertices of the prior of {}", run_dir.display()),
                    expected: framed_mesh.num_vertices(),
                    found: p.mesh().num_vertices(),
                });
            }
        }
        let mut t = Self::build(
            run_dir,
            config,
            flow,
            (&framed_mesh, framed_signals),
            context,
            prior,
        )?;
        t.run.resume_from(&info.dir, &state)?;
        t.resumed = Some(ResumeInfo {
            checkpoint: Some(info.dir),
            step: state.step,
            skipped,
        });
        Ok(t)
    }

    /// Builds a run from its flow spec; `data` (the mesh and signals) and
    /// `context` are already in the flow's frame, `prior` is the flow's.
    ///
    /// Every constructor ends here: [`Trainer::new`] (and a resumed folder
    /// without checkpoints) through `start`, which resolves and writes the
    /// flow spec; [`Trainer::resume`] and [`Trainer::resume_on`] with the
    /// checkpoint's spec, loading the weights and the optimizer after.
    fn build(
        run_dir: PathBuf,
        config: RunConfig,
        flow: FlowSpec,
        data: (&TriMesh, Arc<dyn SignalSource>),
        context: MeshContext,
        prior: Option<GaussianPrior>,
    ) -> Result<Self> {
        let (mesh, signals) = data;
        if config.train.augment.is_active() && flow.channels != 3 {
            return Err(FmError::Config(format!(
                "train.augment scales and shifts positions: it needs 3-channel signals, the dataset has {}",
                flow.channels
            )));
        }
        if config.train.threads > 0 {
            tch::set_num_threads(config.train.threads as i32);
        }
        let device = config.train.device.resolve()?;
        let net_config = config.model.net_config(flow.channels)?;
        // weights, gradients, two Adam moments and a weight average
        net_config.ensure_fits(20)?;
        let run = TrainingLoop::new(
            &run_dir,
            &net_config,
            loop_config(&config),
            run_names(),
            device,
        )?;
        let MeshContext {
            noise,
            tensors: mesh_tensors,
        } = context;
        let order = EpochOrder::new(config.train.seed, signals.len());
        Ok(Self {
            objective: FlowObjective {
                xyz: positions_tensor(mesh.positions(), device),
                offset: if flow.centered {
                    None
                } else {
                    offset_tensor(&flow, device)
                },
                flow,
                device,
                mesh: mesh_tensors,
                signals,
                noise,
                prior,
                order,
                config,
            },
            run,
            resumed: None,
        })
    }

    /// The run folder.
    pub fn run_dir(&self) -> &Path {
        self.run.run_dir()
    }

    /// The configuration.
    pub fn config(&self) -> &RunConfig {
        &self.objective.config
    }

    /// The resolved flow spec.
    pub fn flow(&self) -> &FlowSpec {
        &self.objective.flow
    }

    /// The network being trained.
    pub fn net(&self) -> &PoissonNet {
        self.run.net()
    }

    /// The device training runs on.
    pub fn device(&self) -> Device {
        self.objective.device
    }

    /// Steps completed.
    pub fn step(&self) -> u64 {
        self.run.step()
    }

    /// How [`Trainer::resume`] found the run (`None` for a new run).
    pub fn resumed(&self) -> Option<&ResumeInfo> {
        self.resumed.as_ref()
    }

    /// Changes the run's total steps (e.g. to train a finished run longer)
    /// and rewrites `config.toml`; the schedule and randomness of the steps
    /// are unchanged.
    ///
    /// # Errors
    /// [`FmError::Config`] for 0 or a total below the current step; I/O
    /// errors.
    pub fn set_total_steps(&mut self, steps: u64) -> Result<()> {
        self.run.set_total_steps(steps)?;
        self.objective.config.train.steps = steps;
        self.objective
            .config
            .write_toml_file(self.run.run_dir().join(CONFIG_FILE))
    }

    /// The weights sampling uses: the moving average when `train.ema` is
    /// on, else the trained weights.
    pub fn sampling_net(&self) -> &PoissonNet {
        self.run.sampling_net()
    }

    /// Trains to the configured total; see [`Trainer::run_until`].
    ///
    /// # Errors
    /// See [`Trainer::run_until`].
    pub fn run(&mut self, stop: &AtomicBool, progress: bool) -> Result<TrainSummary> {
        self.run_until(self.objective.config.train.steps, stop, progress)
    }

    /// Trains until step `until` (capped at the total), `stop` is set, or an
    /// error occurs ([`TrainingLoop::run_until`]). Checkpoints every
    /// `checkpoint_every` steps and at `keep_at`; at the end of the call
    /// (target reached or stopped) a checkpoint of the current step is
    /// written if there is none yet; at the total, the final model goes to
    /// `run_dir/model.safetensors` (+ `model.json`). `progress` shows a
    /// progress bar on standard error with the loss and steps/s.
    ///
    /// # Errors
    /// Data, noise, network and I/O errors; [`FmError::Diverged`] when the
    /// loss or the weights stop being finite (nothing is written for that
    /// step).
    pub fn run_until(
        &mut self,
        until: u64,
        stop: &AtomicBool,
        progress: bool,
    ) -> Result<TrainSummary> {
        self.run
            .run_until(until, &mut self.objective, stop, progress)
    }
}

impl FlowObjective {
    /// Path times of step `step` (a pure function of the seed and the
    /// step).
    fn step_times(&self, step: u64) -> Vec<f32> {
        let mut rng = derived_rng(self.config.train.seed, PURPOSE_TIME, step);
        let time = self.config.train.time;
        (0..self.config.train.batch)
            .map(|_| time.draw(&mut rng))
            .collect()
    }

    /// The data signals and noise samples (scaled) of step `s`, `B x V x
    /// C` values each, paired item by item as `train.coupling` says
    /// ([`crate::coupling`]): with a pool, `P` of each are drawn and the
    /// first `B` data signals come with the noise samples the least-cost
    /// assignment gives them.
    fn step_pairs(&mut self, s: u64) -> Result<(Vec<f32>, Vec<f32>)> {
        let b = self.config.train.batch;
        let (v, c) = (self.signals.num_vertices(), self.flow.channels);
        let pool = match self.config.train.coupling {
            Coupling::Independent => b,
            Coupling::MinibatchOt { pool } => pool,
        };
        let idx = self.order.indices(s, pool);
        let mut data = vec![0.0f32; pool * v * c];
        self.signals.read_into(&idx, &mut data)?;
        let first = usize::try_from(s)
            .ok()
            .and_then(|s| s.checked_mul(pool))
            .ok_or_else(|| FmError::Config(format!("step {s} times {pool} signals overflows")))?;
        let mut noise = self
            .noise
            .sample_range_f32(first, pool, c, self.config.train.seed)?
            .into_data();
        let scale = self.flow.noise_scale as f32;
        if scale != 1.0 {
            noise.iter_mut().for_each(|x| *x *= scale);
        }
        if let Some(prior) = &self.prior {
            prior.add_draws(&mut noise, first, pool, self.config.train.seed, None)?;
        }
        if self.config.train.coupling.is_independent() {
            return Ok((data, noise));
        }
        let column_of_row = self.transport_assignment(&noise, &data, pool)?;
        let mut noise_of_data = vec![0; pool];
        for (i, &j) in column_of_row.iter().enumerate() {
            noise_of_data[j] = i;
        }
        let item = v * c;
        let paired: Vec<f32> = noise_of_data[..b]
            .iter()
            .flat_map(|&i| noise[i * item..(i + 1) * item].iter().copied())
            .collect();
        data.truncate(b * item);
        Ok((data, paired))
    }

    /// The least-cost assignment of `pool` noise samples (rows) to `pool`
    /// data signals (columns) under the squared mass-weighted distance of
    /// the run's frame, both centred first when the run centres.
    fn transport_assignment(&self, noise: &[f32], data: &[f32], pool: usize) -> Result<Vec<usize>> {
        let (v, c) = (self.signals.num_vertices(), self.flow.channels);
        let centred = |x: &[f32]| -> Result<Vec<f32>> {
            if !self.flow.centered {
                return Ok(x.to_vec());
            }
            let t = Tensor::from_slice(x)
                .reshape([pool as i64, v as i64, c as i64])
                .to_device(self.device);
            let t = self.mesh.remove_mass_mean(&t)?.to_device(Device::Cpu);
            Ok(Vec::<f32>::try_from(t.flatten(0, -1))?)
        };
        let (x0, x1) = (centred(noise)?, centred(data)?);
        let costs = squared_distances(&x0, &x1, pool, self.noise.mass(), c)
            .map_err(|e| FmError::Config(format!("internal: {e}")))?;
        least_cost_assignment(&costs, pool).map_err(FmError::Config)
    }

    /// The augmentation of step `step` as `[B, 1, 1]` scales and `[B, 1, 3]`
    /// shifts (see [`crate::config::Augment`]); `None` when off.
    fn augmentation(&self, step: u64, b: usize) -> Option<(Tensor, Tensor)> {
        let aug = self.config.train.augment;
        if !aug.is_active() {
            return None;
        }
        let mut rng = derived_rng(self.config.train.seed, PURPOSE_AUGMENT, step);
        let mut scales = Vec::with_capacity(b);
        let mut shifts = Vec::with_capacity(3 * b);
        for _ in 0..b {
            scales.push((1.0 + aug.scale * (2.0 * rng.random::<f64>() - 1.0)) as f32);
            for _ in 0..3 {
                shifts.push((aug.shift * (2.0 * rng.random::<f64>() - 1.0)) as f32);
            }
        }
        let scales = Tensor::from_slice(&scales).reshape([b as i64, 1, 1]);
        let shifts = Tensor::from_slice(&shifts).reshape([b as i64, 1, 3]);
        Some((scales.to_device(self.device), shifts.to_device(self.device)))
    }

    /// The forward and backward passes of step `s` on `net`.
    fn train_step(&mut self, net: &PoissonNet, s: u64) -> Result<f64> {
        let b = self.config.train.batch;
        let (v, c) = (self.signals.num_vertices(), self.flow.channels);
        let times = self.step_times(s);
        let (data, noise) = self.step_pairs(s)?;
        let shape = [b as i64, v as i64, c as i64];
        let x1 = Tensor::from_slice(&data)
            .reshape(shape)
            .to_device(self.device);
        let x0 = Tensor::from_slice(&noise)
            .reshape(shape)
            .to_device(self.device);
        let t = Tensor::from_slice(&times).to_device(self.device);
        let tb = t.reshape([b as i64, 1, 1]);
        let (x1, xyz) = match self.augmentation(s, b) {
            Some((scale, shift)) => (&x1 * &scale + &shift, &self.xyz * &scale + &shift),
            None => (x1, self.xyz.shallow_clone()),
        };
        let (x0, x1) = if self.flow.centered {
            (
                self.mesh.remove_mass_mean(&x0)?,
                self.mesh.remove_mass_mean(&x1)?,
            )
        } else {
            (x0, x1)
        };
        let (xt, delta) = rectified_path(&x0, &x1, &tb);
        let cond = conditioning(&self.flow, &xyz, &t);

        let mut out = net.forward(&self.mesh, &xt, Some(&cond))?;
        if let Some(o) = &self.offset {
            out.vertex = &out.vertex + o;
        }
        let jw = self.config.train.jacobian_weight;
        let loss_t = match self.flow.prediction {
            Prediction::Velocity => {
                loss::weighted_flow_matching_loss(&self.mesh, &out, &delta, jw)?
            }
            Prediction::Clean => {
                // |x1_hat - x1|^2 / (1 - t)^2 per item, as the velocity
                // loss of v = (x1_hat - x_t) / (1 - t): both sides scaled
                // by the clipped 1 / (1 - t)
                let scale: Vec<f32> = times
                    .iter()
                    .map(|&t| {
                        (1.0 / (1.0 - f64::from(t)).max(1e-12)).min(CLEAN_WEIGHT_MAX.sqrt()) as f32
                    })
                    .collect();
                let s = Tensor::from_slice(&scale)
                    .reshape([b as i64, 1, 1])
                    .to_device(self.device);
                let scaled = mfm_net::PoissonNetOutput {
                    vertex: &out.vertex * &s,
                    jacobian: out.jacobian.as_ref().map(|j| j * &s),
                };
                loss::weighted_flow_matching_loss(&self.mesh, &scaled, &(&x1 * &s), jw)?
            }
        };
        let loss = loss_t.to_device(Device::Cpu).double_value(&[]);
        // a non-finite loss goes back without the backward pass: the loop
        // stops there, before any update
        if loss.is_finite() {
            loss_t.f_backward()?;
        }
        Ok(loss)
    }
}

impl Objective for FlowObjective {
    type Error = FmError;

    fn step(&mut self, net: &PoissonNet, step: u64) -> Result<f64> {
        self.train_step(net, step)
    }

    fn checkpoint_files(&self) -> Result<Vec<(String, Vec<u8>)>> {
        Ok(vec![
            (
                CONFIG_FILE.to_owned(),
                self.config.to_toml_string()?.into_bytes(),
            ),
            (FLOW_FILE.to_owned(), self.flow.to_json()?.into_bytes()),
        ])
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn epochs_are_permutations_and_pure_functions_of_the_step() {
        let mut a = EpochOrder::new(7, 10);
        // 3 signals per step over 10 signals: steps 0..10 cover 3 epochs
        let all: Vec<usize> = (0..10).flat_map(|s| a.indices(s, 3)).collect();
        for e in 0..3 {
            let mut epoch = all[e * 10..e * 10 + 10].to_vec();
            epoch.sort_unstable();
            assert_eq!(epoch, (0..10).collect::<Vec<_>>());
        }
        assert_ne!(all[..10], all[10..20]);
        // a fresh order (no cache) asked out of sequence agrees
        let mut b = EpochOrder::new(7, 10);
        assert_eq!(b.indices(7, 3), all[21..24]);
        assert_eq!(b.indices(2, 3), all[6..9]);
        assert_ne!(EpochOrder::new(8, 10).indices(0, 10), all[..10]);
    }
}
