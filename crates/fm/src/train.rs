//! Training a PoissonNet velocity field by rectified flow matching
//! (DESIGN.md section 6, paper section 4).
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
//!    `t ~ U[0, 1)` per batch item (or another `train.time` distribution);
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
//! 6. backward, clip the global gradient norm, one [`Adam`] step at the
//!    scheduled learning rate, then (with `train.ema`) the weight average
//!    moves towards the new weights. Everything is `f32`.
//!
//! ## Determinism and resuming
//! Every random choice is a pure function of the seed and the step `s`:
//! - batch: positions `s B .. s B + B` of an endless sequence of epochs, each
//!   a permutation of the dataset drawn from the ChaCha8 stream `e` of a key
//!   derived from `(seed, "epoch")`;
//! - times: `B` draws from stream `s` of a key derived from `(seed,
//!   "time")` (uniform `f32`, or `train.time`'s distribution);
//! - noise: samples `s B .. s B + B` of the noise sequence of `seed`
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
//! use mfm_fm::{InMemorySignals, config::RunConfig, train::Trainer};
//! let mesh = mfm_geometry::procedural::icosphere(2);
//! let v = mesh.num_vertices();
//! let signals = Arc::new(InMemorySignals::new(vec![0.5; 4 * v], 4, v, 1).unwrap());
//! let cfg = RunConfig::preset("cpu").unwrap();
//! let mut trainer = Trainer::new("runs/demo", cfg, &mesh, signals).unwrap();
//! let summary = trainer.run(&AtomicBool::new(false), true).unwrap();
//! println!("{:.3} s/step", summary.seconds_per_step);
//! ```

use std::collections::BTreeMap;
use std::fs::OpenOptions;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use mfm_geometry::TriMesh;
use mfm_geometry::frame::{CanonicalFrame, SurfaceSize};
use mfm_net::{MeshTensors, PoissonNet, loss};
use mfm_noise::NoiseSampler;
use rand::Rng;
use tch::{Device, Tensor};

pub use crate::adam::Adam;
use crate::checkpoint::{
    self, CONFIG_FILE, CheckpointState, EMA_FILE, FLOW_FILE, FlowSpec, LOG_FILE, LogAccumulator,
    OPTIMIZER_FILE, Prediction, WEIGHTS_FILE,
};
use crate::config::{CLEAN_WEIGHT_MAX, DeviceChoice, FrameChoice, NoiseScale, RunConfig};
use crate::context::MeshContext;
use crate::error::{FmError, Result};
use crate::sample::{conditioning, offset_tensor, positions_tensor};
use crate::seeding::{INIT_LOCK, derived_rng};
use crate::signals::{FramedPositions, SignalSource};

/// Header of the training log.
pub const LOG_HEADER: &str = "step,loss,lr,grad_norm,seconds";

/// Description of the randomness recorded in every checkpoint.
const RNG_DESCRIPTION: &str = "ChaCha8 streams keyed by (seed, purpose), stream = step or epoch; \
     noise = NoiseSampler::sample_range_f32(step * batch, batch, C, seed); no state beyond the step";

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

/// What a call of [`Trainer::run`] did.
#[derive(Clone, Debug, PartialEq)]
pub struct TrainSummary {
    /// Step the call started at.
    pub start_step: u64,
    /// Step it ended at.
    pub end_step: u64,
    /// The run's total steps.
    pub total_steps: u64,
    /// Whether the run reached its total (the final model was written).
    pub finished: bool,
    /// Whether the stop flag ended the call.
    pub stopped: bool,
    /// Wall seconds of this call's steps (checkpoints included).
    pub seconds: f64,
    /// `seconds / (end_step - start_step)` (0 when no step ran).
    pub seconds_per_step: f64,
    /// Loss of the last step, if any ran in the run so far.
    pub last_loss: Option<f64>,
    /// The newest checkpoint written by this call.
    pub checkpoint: Option<PathBuf>,
    /// The final model, when finished.
    pub model: Option<PathBuf>,
}

impl TrainSummary {
    /// The call on one line: steps, seconds, seconds per step, last loss.
    pub fn line(&self) -> String {
        format!(
            "steps {}..{} in {:.1} s ({:.3} s/step), last loss {}",
            self.start_step,
            self.end_step,
            self.seconds,
            self.seconds_per_step,
            self.last_loss
                .map_or_else(|| "-".to_owned(), |l| format!("{l:.5}"))
        )
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

/// Statistics of one step.
#[derive(Clone, Copy, Debug)]
struct StepStats {
    loss: f64,
    grad_norm: f64,
    lr: f64,
}

/// A training run in a run folder. See the [module docs](self).
pub struct Trainer {
    run_dir: PathBuf,
    config: RunConfig,
    flow: FlowSpec,
    device: Device,
    mesh: MeshTensors,
    xyz: Tensor,
    /// The velocity offset added in training (uncentred runs only).
    offset: Option<Tensor>,
    signals: Arc<dyn SignalSource>,
    noise: NoiseSampler,
    net: PoissonNet,
    /// The moving average of the weights (`train.ema > 0`).
    ema: Option<PoissonNet>,
    adam: Adam,
    order: EpochOrder,
    step: u64,
    elapsed: f64,
    log: LogAccumulator,
    last_loss: Option<f64>,
    last_checkpoint_step: Option<u64>,
    resumed: Option<ResumeInfo>,
}

impl std::fmt::Debug for Trainer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Trainer")
            .field("run_dir", &self.run_dir)
            .field("step", &self.step)
            .field("total_steps", &self.config.train.steps)
            .field("device", &self.device)
            .field("flow", &self.flow)
            .finish()
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
        Ok(Self {
            frame,
            positions,
            size: SurfaceSize::of(mesh),
        })
    }
}

/// The training mesh and signals in `frame` (signals move only when they
/// are `positions`).
fn in_frame(
    frame: CanonicalFrame,
    positions: bool,
    mesh: &TriMesh,
    signals: Arc<dyn SignalSource>,
) -> Result<(TriMesh, Arc<dyn SignalSource>)> {
    let framed = frame.apply(mesh);
    if positions && !frame.is_identity() {
        let s: Arc<dyn SignalSource> = Arc::new(FramedPositions::new(signals, frame)?);
        Ok((framed, s))
    } else {
        Ok((framed, signals))
    }
}

/// The configuration a resumed run goes on with: the checkpoint's, with the
/// edits made since to the run folder's `config.toml` when they are all in
/// [`RESUMABLE_FIELDS`](crate::config::RESUMABLE_FIELDS).
fn with_resumable_edits(run_dir: &Path, saved: RunConfig, step: u64) -> Result<RunConfig> {
    let path = run_dir.join(CONFIG_FILE);
    if !path.exists() {
        return Ok(saved);
    }
    let edited = RunConfig::from_toml_file(&path)?;
    let changes = saved.changes_to(&edited)?;
    let refused: Vec<String> = changes
        .iter()
        .filter(|c| !crate::config::RESUMABLE_FIELDS.contains(&c.field.as_str()))
        .map(ToString::to_string)
        .collect();
    if !refused.is_empty() {
        return Err(FmError::Config(format!(
            "{} was edited after the checkpoint at step {step}: {}; a resumed run cannot change \
             these (only {} can): undo the edit, or start a new run with --config",
            path.display(),
            refused.join(", "),
            crate::config::RESUMABLE_FIELDS.join(", ")
        )));
    }
    if edited.train.steps < step {
        return Err(FmError::Config(format!(
            "{}: train.steps = {} is below the checkpoint's step {step}",
            path.display(),
            edited.train.steps
        )));
    }
    edited.validate()?;
    Ok(edited)
}

/// The error of training step `step` that failed with `e`, read as the
/// divergence it is: after a step with a learning rate far too large the
/// weights are NaN or inf, or so large that the network's values overflow
/// and a non-finite value reaches its Poisson solves. Such an error becomes
/// [`FmError::Diverged`], "`what` diverged at step N: ...; lower `lr`",
/// naming the weights or their largest magnitude. Any other error, and any
/// error at step 0 (weights not yet trained), is returned unchanged.
///
/// Cost: one pass over the weights, on the error path only.
pub fn divergence(net: &PoissonNet, step: u64, what: &str, lr: &str, e: FmError) -> FmError {
    if step == 0 || !matches!(e, FmError::Net(_) | FmError::Torch(_)) {
        return e;
    }
    let mut largest = 0.0f64;
    for (name, w) in net.var_store().variables() {
        if !bool::try_from(w.isfinite().all()).unwrap_or(false) {
            return FmError::Diverged(format!(
                "{what} diverged at step {step}: the weights `{name}` are NaN or inf; lower {lr} \
                 (the last checkpoint is intact)"
            ));
        }
        let m = w.abs().max().double_value(&[]);
        largest = largest.max(m);
    }
    if e.to_string().contains("non-finite") {
        return FmError::Diverged(format!(
            "{what} diverged at step {step}: the weights grew to {largest:.2e} and the network's \
             values overflowed ({e}); lower {lr} (the last checkpoint is intact)"
        ));
    }
    e
}

/// Rewrites the log keeping the header and the rows with `step <= keep`
/// (creates it with only the header when missing).
pub fn truncate_log(path: &Path, keep: u64) -> Result<()> {
    let text = match std::fs::read_to_string(path) {
        Ok(t) => t,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => String::new(),
        Err(e) => return Err(FmError::io(path, e)),
    };
    let mut out = String::from(LOG_HEADER);
    out.push('\n');
    let complete = text.ends_with('\n');
    let lines: Vec<&str> = text.lines().skip(1).collect();
    for (i, line) in lines.iter().enumerate() {
        // a torn last line (a killed run) or anything malformed is dropped
        let torn = i + 1 == lines.len() && !complete;
        let fields: Vec<&str> = line.split(',').collect();
        let well_formed = fields.len() == 5 && fields.iter().all(|f| f.parse::<f64>().is_ok());
        let step = fields.first().and_then(|s| s.parse::<u64>().ok());
        if let (false, true, Some(s)) = (torn, well_formed, step) {
            if s <= keep {
                out.push_str(line);
                out.push('\n');
            }
        }
    }
    checkpoint::write_atomic(path, out.as_bytes())
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
        let (framed_mesh, framed_signals) = in_frame(frame.frame, frame.positions, mesh, signals)?;
        let context = MeshContext::new(&framed_mesh, config.noise.kind)?;
        let flow = resolve_flow(&config, &context.noise, framed_signals.as_ref(), frame)?;
        flow.write(run_dir.join(FLOW_FILE))?;
        truncate_log(&run_dir.join(LOG_FILE), 0)?;
        Self::build(run_dir, config, flow, &framed_mesh, framed_signals, context)
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
        let (best, skipped) = checkpoint::newest_valid_checkpoint(&run_dir)?;
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
        let (framed_mesh, framed_signals) = in_frame(flow.frame, flow.positions, mesh, signals)?;
        let context = MeshContext::new(&framed_mesh, config.noise.kind)?;
        let mut t = Self::build(run_dir, config, flow, &framed_mesh, framed_signals, context)?;
        t.net.load_weights(info.dir.join(WEIGHTS_FILE))?;
        if let Some(avg) = &mut t.ema {
            let path = info.dir.join(EMA_FILE);
            if !path.is_file() {
                return Err(FmError::format(
                    &path,
                    "train.ema is on but the checkpoint has no moving average (it was written \
                     by a run without train.ema)",
                ));
            }
            avg.load_weights(&path)?;
        }
        t.adam.load(&info.dir.join(OPTIMIZER_FILE), state.step)?;
        t.step = state.step;
        t.elapsed = state.elapsed_seconds;
        t.log = state.log;
        t.last_loss = state.last_loss;
        t.last_checkpoint_step = Some(state.step);
        truncate_log(&t.run_dir.join(LOG_FILE), state.step)?;
        t.resumed = Some(ResumeInfo {
            checkpoint: Some(info.dir),
            step: state.step,
            skipped,
        });
        Ok(t)
    }

    /// Builds a run from its flow spec; `mesh`, `signals` and `context` are
    /// already in the flow's frame.
    ///
    /// Every constructor ends here: [`Trainer::new`] (and a resumed folder
    /// without checkpoints) through `start`, which resolves and writes the
    /// flow spec; [`Trainer::resume`] and [`Trainer::resume_on`] with the
    /// checkpoint's spec, loading the weights and the optimizer after.
    fn build(
        run_dir: PathBuf,
        config: RunConfig,
        flow: FlowSpec,
        mesh: &TriMesh,
        signals: Arc<dyn SignalSource>,
        context: MeshContext,
    ) -> Result<Self> {
        mfm_net::runtime::tune_allocator();
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
        let (net, ema) = {
            let _guard = INIT_LOCK.lock().unwrap_or_else(|p| p.into_inner());
            // libtorch seeds are i64; the bits of the u64 seed are kept
            tch::manual_seed(config.train.seed as i64);
            let net = PoissonNet::new(&net_config, device)?;
            // the average starts as a copy; building it draws from libtorch's
            // generator too, so it happens under the same lock (another
            // thread's seeded initialization must not see those draws)
            let ema = if config.train.ema > 0.0 {
                let mut avg = PoissonNet::new(&net_config, device)?;
                avg.var_store_mut().copy(net.var_store())?;
                Some(avg)
            } else {
                None
            };
            (net, ema)
        };
        let t = &config.train;
        let adam = Adam::new(&net, t.adam_beta1, t.adam_beta2, t.adam_eps);
        let MeshContext {
            noise,
            tensors: mesh_tensors,
        } = context;
        let order = EpochOrder::new(t.seed, signals.len());
        Ok(Self {
            xyz: positions_tensor(mesh, device),
            offset: if flow.centered {
                None
            } else {
                offset_tensor(&flow, device)
            },
            run_dir,
            flow,
            device,
            mesh: mesh_tensors,
            signals,
            noise,
            net,
            ema,
            adam,
            order,
            step: 0,
            elapsed: 0.0,
            log: LogAccumulator::default(),
            last_loss: None,
            last_checkpoint_step: None,
            resumed: None,
            config,
        })
    }

    /// The run folder.
    pub fn run_dir(&self) -> &Path {
        &self.run_dir
    }

    /// The configuration.
    pub fn config(&self) -> &RunConfig {
        &self.config
    }

    /// The resolved flow spec.
    pub fn flow(&self) -> &FlowSpec {
        &self.flow
    }

    /// The network being trained.
    pub fn net(&self) -> &PoissonNet {
        &self.net
    }

    /// The device training runs on.
    pub fn device(&self) -> Device {
        self.device
    }

    /// Steps completed.
    pub fn step(&self) -> u64 {
        self.step
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
        if steps == 0 || steps < self.step {
            return Err(FmError::Config(format!(
                "train.steps must be at least 1 and at least the current step {}, found {steps}",
                self.step
            )));
        }
        self.config.train.steps = steps;
        self.config.write_toml_file(self.run_dir.join(CONFIG_FILE))
    }

    /// Signal indices, times and noise sample range of step `step` (a pure
    /// function of the seed and the step).
    fn step_inputs(&mut self, step: u64) -> (Vec<usize>, Vec<f32>) {
        let b = self.config.train.batch;
        let idx = self.order.indices(step, b);
        let mut rng = derived_rng(self.config.train.seed, PURPOSE_TIME, step);
        let time = self.config.train.time;
        let t: Vec<f32> = (0..b).map(|_| time.draw(&mut rng)).collect();
        (idx, t)
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

    /// Runs optimizer step `self.step`.
    fn train_step(&mut self) -> Result<StepStats> {
        let s = self.step;
        let b = self.config.train.batch;
        let (v, c) = (self.signals.num_vertices(), self.flow.channels);
        let (idx, times) = self.step_inputs(s);
        let mut data = vec![0.0f32; b * v * c];
        self.signals.read_into(&idx, &mut data)?;
        let first = usize::try_from(s)
            .ok()
            .and_then(|s| s.checked_mul(b))
            .ok_or_else(|| FmError::Config(format!("step {s} times batch {b} overflows")))?;
        let mut noise = self
            .noise
            .sample_range_f32(first, b, c, self.config.train.seed)?
            .into_data();
        let scale = self.flow.noise_scale as f32;
        if scale != 1.0 {
            noise.iter_mut().for_each(|x| *x *= scale);
        }
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
        let xt = &x0 * (1.0 - &tb) + &x1 * &tb;
        let delta = &x1 - &x0;
        let cond = conditioning(&self.flow, &xyz, &t);

        self.adam.zero_grad();
        let mut out = self.net.forward(&self.mesh, &xt, Some(&cond))?;
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
        if !loss.is_finite() {
            return Err(FmError::Diverged(format!(
                "training diverged at step {s}: the loss is {loss}; lower train.lr or check the data (the last checkpoint is intact)"
            )));
        }
        loss_t.f_backward()?;
        let grad_norm = self.adam.clip_grad_norm(self.config.train.grad_clip)?;
        let lr = self.config.train.lr_at(s);
        self.adam.step(lr)?;
        self.update_ema(s + 1)?;
        Ok(StepStats {
            loss,
            grad_norm,
            lr,
        })
    }

    /// Moves the weight average towards the weights after step `k`
    /// (1-based): `w <- d w + (1 - d) p`, `d = min(ema, (1 + k) / (10 + k))`.
    fn update_ema(&mut self, k: u64) -> Result<()> {
        let Some(avg) = &mut self.ema else {
            return Ok(());
        };
        let warm = (1.0 + k as f64) / (10.0 + k as f64);
        let d = self.config.train.ema.min(warm);
        let trained = self.net.var_store().variables();
        tch::no_grad(|| -> Result<()> {
            for (name, mut w) in avg.var_store().variables() {
                let p = trained.get(&name).ok_or_else(|| {
                    FmError::Config(format!(
                        "the weight average has a variable {name} the network lacks"
                    ))
                })?;
                let _ = w.f_mul_scalar_(d)?;
                let _ = w.f_add_(&(p * (1.0 - d)))?;
            }
            Ok(())
        })
    }

    /// The weights sampling uses: the moving average when `train.ema` is
    /// on, else the trained weights.
    pub fn sampling_net(&self) -> &PoissonNet {
        self.ema.as_ref().unwrap_or(&self.net)
    }

    /// Writes the checkpoint of the current step and prunes old ones.
    fn write_checkpoint(&mut self) -> Result<PathBuf> {
        let state = CheckpointState {
            format: checkpoint::STATE_FORMAT,
            step: self.step,
            seed: self.config.train.seed,
            rng: RNG_DESCRIPTION.into(),
            elapsed_seconds: self.elapsed,
            last_loss: self.last_loss,
            log: self.log,
            files: BTreeMap::new(),
        };
        let (net, adam, config, flow) = (&self.net, &self.adam, &self.config, &self.flow);
        let ema = self.ema.as_ref();
        let dir = checkpoint::write_checkpoint(&self.run_dir, state, |tmp| {
            net.save(tmp.join(WEIGHTS_FILE))?;
            if let Some(avg) = ema {
                avg.save(tmp.join(EMA_FILE))?;
            }
            adam.save(&tmp.join(OPTIMIZER_FILE))?;
            config.write_toml_file(tmp.join(CONFIG_FILE))?;
            flow.write(tmp.join(FLOW_FILE))
        })?;
        checkpoint::prune_checkpoints_keeping(
            &self.run_dir,
            self.config.train.keep_checkpoints,
            &self.config.train.keep_at,
        )?;
        self.last_checkpoint_step = Some(self.step);
        Ok(dir)
    }

    /// Trains to the configured total; see [`Trainer::run_until`].
    ///
    /// # Errors
    /// See [`Trainer::run_until`].
    pub fn run(&mut self, stop: &AtomicBool, progress: bool) -> Result<TrainSummary> {
        self.run_until(self.config.train.steps, stop, progress)
    }

    /// Trains until step `until` (capped at the total), `stop` is set, or an
    /// error occurs. Checkpoints every `checkpoint_every` steps; at the
    /// end of the call (target reached or stopped) a checkpoint of the
    /// current step is written if there is none yet; at the total, the final
    /// model goes to `run_dir/model.safetensors` (+ `model.json`). `progress`
    /// shows a progress bar on standard error with the loss and steps/s.
    ///
    /// # Errors
    /// Data, noise, network and I/O errors; [`FmError::Config`] when the
    /// loss stops being finite (nothing is written for that step).
    pub fn run_until(
        &mut self,
        until: u64,
        stop: &AtomicBool,
        progress: bool,
    ) -> Result<TrainSummary> {
        let total = self.config.train.steps;
        let end = until.min(total);
        let start_step = self.step;
        let target = if progress {
            ProgressDrawTarget::stderr()
        } else {
            ProgressDrawTarget::hidden()
        };
        let bar = ProgressBar::with_draw_target(Some(total), target).with_position(start_step);
        if let Ok(style) =
            ProgressStyle::with_template("{elapsed_precise} [{bar:30}] {pos}/{len} eta {eta} {msg}")
        {
            bar.set_style(style.progress_chars("=> "));
        }
        bar.reset_eta();
        let log_path = self.run_dir.join(LOG_FILE);
        let mut log_file = OpenOptions::new()
            .append(true)
            .create(true)
            .open(&log_path)
            .map_err(|e| FmError::io(&log_path, e))?;
        let session = Instant::now();
        let base_elapsed = self.elapsed;
        let mut stopped = false;
        let mut checkpoint_dir = None;
        let (every, log_every) = (
            self.config.train.checkpoint_every,
            self.config.train.log_every,
        );
        while self.step < end {
            if stop.load(Ordering::Relaxed) {
                stopped = true;
                break;
            }
            let stats = self
                .train_step()
                .map_err(|e| divergence(&self.net, self.step, "training", "train.lr", e))?;
            self.step += 1;
            self.last_loss = Some(stats.loss);
            self.log.loss_sum += stats.loss;
            self.log.grad_norm_sum += stats.grad_norm;
            self.log.count += 1;
            self.elapsed = base_elapsed + session.elapsed().as_secs_f64();
            if self.step % log_every == 0 || self.step == total {
                let n = self.log.count.max(1) as f64;
                let row = format!(
                    "{},{},{},{},{:.3}\n",
                    self.step,
                    self.log.loss_sum / n,
                    stats.lr,
                    self.log.grad_norm_sum / n,
                    self.elapsed
                );
                log_file
                    .write_all(row.as_bytes())
                    .and_then(|()| log_file.flush())
                    .map_err(|e| FmError::io(&log_path, e))?;
                self.log = LogAccumulator::default();
            }
            let done = (self.step - start_step) as f64;
            bar.set_position(self.step);
            bar.set_message(format!(
                "loss {:.4e} lr {:.1e} {:.2} steps/s",
                stats.loss,
                stats.lr,
                done / session.elapsed().as_secs_f64().max(1e-9)
            ));
            if self.step % every == 0
                || self.step == total
                || self.config.train.keep_at.contains(&self.step)
            {
                checkpoint_dir = Some(self.write_checkpoint()?);
            }
        }
        if self.last_checkpoint_step != Some(self.step) {
            checkpoint_dir = Some(self.write_checkpoint()?);
        }
        let finished = self.step >= total;
        let model = if finished {
            let path = self.run_dir.join(WEIGHTS_FILE);
            self.sampling_net().save(&path)?;
            checkpoint::write_final_record(&self.run_dir)?;
            Some(path)
        } else {
            None
        };
        bar.finish_and_clear();
        let seconds = session.elapsed().as_secs_f64();
        let ran = self.step - start_step;
        Ok(TrainSummary {
            start_step,
            end_step: self.step,
            total_steps: total,
            finished,
            stopped,
            seconds,
            seconds_per_step: if ran > 0 { seconds / ran as f64 } else { 0.0 },
            last_loss: self.last_loss,
            checkpoint: checkpoint_dir,
            model,
        })
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

    #[test]
    fn log_truncation_keeps_rows_up_to_the_step() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join(LOG_FILE);
        std::fs::write(
            &p,
            format!("{LOG_HEADER}\n5,1,1,1,0\n10,1,1,1,0\n15,1,1,1,0\n1"),
        )
        .unwrap();
        truncate_log(&p, 10).unwrap();
        assert_eq!(
            std::fs::read_to_string(&p).unwrap(),
            format!("{LOG_HEADER}\n5,1,1,1,0\n10,1,1,1,0\n")
        );
    }
}
