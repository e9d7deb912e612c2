//! Generating signals with a trained model on any triangulation.
//!
//! A sample starts from noise `f_0` drawn **on the target mesh** with the
//! run's noise kind and scale ([`FlowSpec`]) and integrates the learned
//! velocity `df/dt = v(f, t)` from `t = 0` to `t = 1` with `S` steps of size
//! `h = 1 / S`:
//! - midpoint (the paper's): `f <- f + h v(f + h/2 v(f, t), t + h/2)`, two
//!   network evaluations per step, error `O(h^2)`;
//! - Euler: `f <- f + h v(f, t)`, one evaluation, error `O(h)`.
//!
//! `v(f, t)` is the network's vertex output, with the network conditioned
//! on `t` (and the target mesh's vertex positions when the run was trained
//! that way).
//!
//! The frame: the target mesh is first moved by the run's training frame
//! ([`FlowSpec::frame`]; the map fixed on the training mesh, so the target
//! must be in the units of the training data), the noise is drawn and the
//! ODE integrated there, and position samples are mapped back to the
//! target's units at the end; values are left as they are.
//! [`Sampler::surface_warnings`] tells when a target's size does not match
//! the training surface's.
//!
//! The prior: a run trained with `noise.prior` ([`crate::prior`]) adds to
//! every noise sample a draw of its data prior, made on the training mesh
//! and carried to the target's vertices ([`Sampler::prepare`] locates them
//! once), before the centring below.
//!
//! The mean: for a centred run ([`FlowSpec::centered`], the default) the
//! noise is centred by its mass-weighted mean and the dataset's mean
//! ([`FlowSpec::velocity_offset`]) is added after the last step; for an
//! uncentred run it is added to the velocity at every step.
//!
//! Entry points: [`Sampler::load`] (a run folder: its final model, or its
//! newest valid checkpoint), [`Sampler::sample`] (`[N, V, C]` values for a
//! mesh), and the lower-level [`Sampler::prepare`],
//! [`Sampler::sample_on`], [`Sampler::noise`], [`Sampler::integrate`].
//!
//! Sample `i` of seed `s` starts from noise sample `i` of the noise sequence
//! of `s` on the target mesh, whatever the batch it is generated in. Cost per
//! sample: `S` (Euler) or `2 S` (midpoint) network forward passes, batched
//! `batch` samples at a time (memory grows linearly with the batch).

use std::path::Path;
use std::time::Instant;

use mfm_geometry::TriMesh;
use mfm_geometry::frame::SurfaceSize;
use mfm_net::mesh::positions_tensor;
use mfm_net::{MeshTensors, PoissonNet};
use mfm_noise::NoiseSampler;
use tch::{Device, Kind, Tensor};

use mfm_train::checkpoint::{self, EMA_FILE, WEIGHTS_FILE};

use crate::checkpoint::{FLOW_FILE, FlowSpec};
use crate::config::{OdeMethod, SampleConfig};
use crate::context::sampling_parts;
use crate::device::DeviceChoice;
use crate::error::{FmError, Result};
use crate::prior::{GaussianPrior, read_prior};
use mfm_data::InMemorySignals;
use mfm_data::transfer::Transfer;

/// Relative size difference above which [`Sampler::surface_warnings`]
/// speaks up.
pub const SURFACE_TOLERANCE: f64 = 0.05;

/// How to integrate: steps, method, batch size.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SampleOptions {
    /// ODE steps `S` (at least 1).
    pub steps: usize,
    /// Integrator.
    pub method: OdeMethod,
    /// Samples integrated together (at least 1).
    pub batch: usize,
}

impl Default for SampleOptions {
    fn default() -> Self {
        Self::from(&SampleConfig::default())
    }
}

impl From<&SampleConfig> for SampleOptions {
    fn from(c: &SampleConfig) -> Self {
        Self {
            steps: c.steps,
            method: c.method,
            batch: c.batch,
        }
    }
}

/// The fixed names `mfm sample` writes into its output folder, besides the
/// [`sample_ply_name`] files: the samples (`.npy`), the mesh, a picture and
/// the [`SampleTiming`].
pub const SAMPLE_FILES: [&str; 4] = ["samples.npy", "mesh.ply", "samples.png", "timing.json"];

/// The PLY file of sample `i` in a sample folder (`sample_007.ply`).
pub fn sample_ply_name(i: usize) -> String {
    format!("sample_{i:03}.ply")
}

/// Whether `name` is a [`sample_ply_name`] (`sample_` digits `.ply`).
pub fn is_sample_ply(name: &str) -> bool {
    name.strip_prefix("sample_")
        .and_then(|r| r.strip_suffix(".ply"))
        .is_some_and(|d| !d.is_empty() && d.bytes().all(|b| b.is_ascii_digit()))
}

/// How long a sampling run took (`timing.json` of a sample folder).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SampleTiming {
    /// Samples drawn.
    pub samples: usize,
    /// Vertices of the target mesh.
    pub vertices: usize,
    /// Channels per vertex.
    pub channels: usize,
    /// ODE steps per sample.
    pub ode_steps: usize,
    /// The ODE method (`euler`, `midpoint`...).
    pub method: String,
    /// Wall seconds for everything.
    pub seconds: f64,
    /// Of which drawing the noise.
    pub noise_seconds: f64,
    /// `seconds / samples`.
    pub seconds_per_sample: f64,
}

/// The most bytes of samples [`Sampler::sample_to_npy`] computes before
/// writing them.
pub const SAMPLE_CHUNK_BYTES: usize = 64 << 20;

/// The activation memory a batch of samples may take
/// ([`Sampler::batch_on`]): 3 GiB.
pub const SAMPLE_BATCH_BYTES: usize = 3 << 30;

/// Bytes of activations one sample's network evaluation takes per face and
/// channel of the network's width, measured: the `cpu-deform` network (W32
/// K3) on 1.08M faces peaked at 4.98 GB with one sample and 9.14 GB with two
/// (docs/BENCHMARKS.md, "Generation at a million faces"), 4.2 GB per
/// sample, 120 bytes per face and channel; rounded up.
pub const SAMPLE_BYTES_PER_FACE_CHANNEL: usize = 128;

/// What [`Sampler::sample_to_npy`] draws.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SampleRequest {
    /// Samples `0..count` of the seed's sequence.
    pub count: usize,
    /// The seed.
    pub seed: u64,
    /// How many of the first samples to return in memory.
    pub keep: usize,
    /// Show a progress bar over the ODE steps of every sample.
    pub progress: bool,
}

/// What [`Sampler::sample_to_npy`] returns.
#[derive(Clone, Debug)]
pub struct StreamedSamples {
    /// The first samples (as many as asked to keep).
    pub first: InMemorySignals,
    /// Wall seconds for everything (noise and integration).
    pub seconds: f64,
    /// Of which drawing the noise.
    pub noise_seconds: f64,
}

/// Generated signals and how long they took.
#[derive(Clone, Debug, PartialEq)]
pub struct Samples {
    /// Values, row-major `[samples, vertices, channels]`.
    pub data: Vec<f32>,
    /// Number of samples `N`.
    pub samples: usize,
    /// Vertices `V` of the target mesh.
    pub vertices: usize,
    /// Channels `C`.
    pub channels: usize,
    /// Wall seconds for everything (noise and integration).
    pub seconds: f64,
    /// Of which drawing the noise.
    pub noise_seconds: f64,
}

impl Samples {
    /// Wall seconds per sample (`seconds / samples`; 0 for no samples).
    pub fn seconds_per_sample(&self) -> f64 {
        if self.samples == 0 {
            0.0
        } else {
            self.seconds / self.samples as f64
        }
    }

    /// Sample `i` (`V x C` values).
    pub fn sample(&self, i: usize) -> &[f32] {
        let n = self.vertices * self.channels;
        &self.data[i * n..(i + 1) * n]
    }
}

/// A target mesh prepared for sampling: the network's operators (a
/// factorization of `L + eps I`), the noise sampler (a factorization for
/// Matérn kinds) and the vertex positions. Reuse it for several calls.
#[derive(Debug)]
pub struct TargetMesh {
    mesh: MeshTensors,
    /// Face blocks the network runs over on a very fine mesh
    /// ([`faces_per_block`]); `None` when the mesh fits one block.
    blocks: Option<Vec<MeshTensors>>,
    /// `None` when the sampler starts from given noise ([`Sampler::with_start_noise`]):
    /// its factor would go unused.
    noise: Option<NoiseSampler>,
    /// The run's prior carried from the training mesh to this one (`None`
    /// for a run without a prior, or a sampler with starting noise).
    prior: Option<Transfer>,
    xyz: Tensor,
}

impl TargetMesh {
    /// The network's view of the mesh.
    pub fn mesh_tensors(&self) -> &MeshTensors {
        &self.mesh
    }

    /// The same target with the network run over blocks of at most
    /// `max_faces` faces ([`MeshTensors::face_blocks`]), or over the whole
    /// mesh at once for `None`. [`Sampler::prepare`] chooses blocks of
    /// [`faces_per_block`] faces when the mesh has more; the samples are the
    /// same up to the order of sums over faces.
    pub fn with_face_blocks(mut self, max_faces: Option<usize>) -> Self {
        self.blocks = max_faces.map(|m| self.mesh.face_blocks(m));
        self
    }

    /// How many face blocks the network runs over (1: the whole mesh).
    pub fn face_block_count(&self) -> usize {
        self.blocks.as_ref().map_or(1, Vec::len)
    }

    /// The noise sampler of the mesh (`None` when it was prepared by a
    /// sampler with starting noise, which draws none).
    pub fn noise_sampler(&self) -> Option<&NoiseSampler> {
        self.noise.as_ref()
    }

    /// Number of vertices.
    pub fn num_vertices(&self) -> usize {
        self.mesh.num_vertices()
    }
}

/// The face activations one block of faces may take in a network
/// evaluation while sampling: 1 GiB.
pub const SAMPLE_BLOCK_BYTES: usize = 1 << 30;

/// Faces per block for a network of `width` channels: as many as take
/// [`SAMPLE_BLOCK_BYTES`] at [`SAMPLE_BYTES_PER_FACE_CHANNEL`] (262,144 for
/// `W = 32`), at least 1. A target mesh with more faces runs the network
/// block by block ([`mfm_net::PoissonNet::forward_blocks`]): its memory
/// then grows with the vertices (the vertex features and the factors), not
/// with the faces times the width. Measured (docs/BENCHMARKS.md,
/// "Generation at a million faces"): at 3.07M faces 69 s and 14.3 GB a
/// sample instead of 104 s and 17.1 GB; at 1.08M faces 4.6 GB instead of
/// 5.2-6.1 GB, for 13% more time.
pub fn faces_per_block(width: usize) -> usize {
    (SAMPLE_BLOCK_BYTES / (width.max(1) * SAMPLE_BYTES_PER_FACE_CHANNEL)).max(1)
}

/// `batch`, or the most samples of a network of `width` channels on a mesh
/// of `faces` faces that fit [`SAMPLE_BATCH_BYTES`] (at least 1): see
/// [`Sampler::batch_on`].
pub fn batch_within_memory(faces: usize, width: usize, batch: usize) -> usize {
    let per_sample = faces
        .saturating_mul(width.max(1))
        .saturating_mul(SAMPLE_BYTES_PER_FACE_CHANNEL)
        .max(1);
    batch.min(SAMPLE_BATCH_BYTES / per_sample).max(1)
}

/// The largest distance, over the bounding-box diagonal of the mesh it is
/// carried to, of a vertex from the surface noise is carried from
/// ([`Sampler::carried_noise`]).
pub const CARRY_TOLERANCE: f64 = 0.01;

/// The vertices of `to` located on `from`'s surface ([`Transfer::locate`]),
/// refused when one lies farther than [`CARRY_TOLERANCE`] of `to`'s
/// bounding-box diagonal from it (`what` names `from` in the message).
fn locate_within_tolerance(from: &TriMesh, to: &TriMesh, what: &str) -> Result<Transfer> {
    let transfer = Transfer::locate(from, to)?;
    let diagonal = to.bounding_box_diagonal();
    let (vertex, distance) = transfer.farthest();
    if distance > CARRY_TOLERANCE * diagonal {
        return Err(FmError::Config(format!(
            "vertex {vertex} of the mesh to sample lies {distance:.3e} from {what}, {:.1}% of its \
             bounding-box diagonal (at most {}%): not a triangulation of the same surface in the \
             same units",
            100.0 * distance / diagonal,
            100.0 * CARRY_TOLERANCE
        )));
    }
    Ok(transfer)
}

/// The conditioning of a batch: `t: [B]` broadcast to `[B, V, 1]`, preceded
/// by the positions `xyz: [1, V, 3]` when the flow is conditioned on them
/// (`[B, V, 4]` = `[x, y, z, t]`).
pub(crate) fn conditioning(flow: &FlowSpec, xyz: &Tensor, t: &Tensor) -> Tensor {
    let s = xyz.size();
    let (b, v) = (t.size()[0], s[1]);
    let tt = t.reshape([b, 1, 1]).expand([b, v, 1], false);
    if flow.condition_on_xyz {
        Tensor::cat(&[&xyz.expand([b, v, 3], false), &tt], 2)
    } else {
        tt.contiguous()
    }
}

/// The velocity offset as `[1, 1, C]` on `device` (`None` when all zero).
pub(crate) fn offset_tensor(flow: &FlowSpec, device: Device) -> Option<Tensor> {
    if flow.velocity_offset.iter().all(|&x| x == 0.0) {
        return None;
    }
    let c = flow.velocity_offset.len() as i64;
    Some(
        Tensor::from_slice(&flow.velocity_offset)
            .to_kind(Kind::Float)
            .reshape([1, 1, c])
            .to_device(device),
    )
}

/// A trained model ready to generate: the network and its [`FlowSpec`].
#[derive(Debug)]
pub struct Sampler {
    net: PoissonNet,
    flow: FlowSpec,
    offset: Option<Tensor>,
    start: Option<StartNoise>,
    prior: Option<GaussianPrior>,
}

/// Starting states given by the user ([`Sampler::with_start_noise`]) in
/// place of drawn noise: `[samples, vertices, channels]` values.
#[derive(Clone, Debug, PartialEq)]
pub struct StartNoise {
    /// Row-major values.
    pub values: Vec<f32>,
    /// `[samples, vertices, channels]`.
    pub shape: [usize; 3],
}

impl Sampler {
    /// Wraps a network and the flow it was trained with.
    ///
    /// # Errors
    /// [`FmError::SizeMismatch`] when the network's input/output or
    /// conditioning channels do not fit the spec.
    pub fn new(net: PoissonNet, flow: FlowSpec) -> Result<Self> {
        let cfg = net.config();
        let cond = if flow.condition_on_xyz { 4 } else { 1 };
        for (what, found, expected) in [
            ("network input channels", cfg.in_channels, flow.channels),
            ("network output channels", cfg.out_channels, flow.channels),
            ("network conditioning channels", cfg.cond_channels, cond),
            (
                "velocity offset values",
                flow.velocity_offset.len(),
                flow.channels,
            ),
        ] {
            if found != expected {
                return Err(FmError::SizeMismatch {
                    what: what.into(),
                    expected,
                    found,
                });
            }
        }
        let offset = offset_tensor(&flow, net.device());
        Ok(Self {
            net,
            flow,
            offset,
            start: None,
            prior: None,
        })
    }

    /// Adds the run's data prior ([`crate::prior`]) to every start drawn:
    /// what [`Sampler::load`] does for a run whose `flow.json` records one.
    ///
    /// # Errors
    /// [`FmError::Config`] when the flow records no prior or its channels
    /// differ from the prior's.
    pub fn with_prior(mut self, prior: GaussianPrior) -> Result<Self> {
        if self.flow.prior.is_none() || prior.channels() != self.flow.channels {
            return Err(FmError::Config(format!(
                "a prior of {} channels given to a run {}",
                prior.channels(),
                if self.flow.prior.is_none() {
                    "whose flow.json records no prior".to_owned()
                } else {
                    format!("of {} channels", self.flow.channels)
                }
            )));
        }
        self.prior = Some(prior);
        Ok(self)
    }

    /// The run's data prior (`None` without one).
    pub fn prior(&self) -> Option<&GaussianPrior> {
        self.prior.as_ref()
    }

    /// Starts the ODE of sample `i` from `start`'s sample `i` instead of
    /// drawing noise: the values are the integration's initial state as
    /// given, in the run's training frame (the identity for imported runs),
    /// neither scaled nor centred. The seed is then unused.
    ///
    /// # Errors
    /// [`FmError::Config`] when the values do not fill the shape or the
    /// channels differ from the run's.
    pub fn with_start_noise(mut self, start: StartNoise) -> Result<Self> {
        let [n, v, c] = start.shape;
        if n.checked_mul(v).and_then(|x| x.checked_mul(c)) != Some(start.values.len()) {
            return Err(FmError::Config(format!(
                "starting noise of shape {:?} holds {} values",
                start.shape,
                start.values.len()
            )));
        }
        if c != self.flow.channels {
            return Err(FmError::Config(format!(
                "starting noise has shape [{n}, {v}, {c}]: {c} channels where the run's signals have {}",
                self.flow.channels
            )));
        }
        self.start = Some(start);
        Ok(self)
    }

    /// The starting noise given with [`Sampler::with_start_noise`].
    pub fn start_noise(&self) -> Option<&StartNoise> {
        self.start.as_ref()
    }

    /// Loads a trained run: `run_dir/model.safetensors` (the final model)
    /// with `run_dir/flow.json` when present, otherwise the newest checkpoint
    /// that passes its integrity check (a warning on standard error names
    /// each newer one that does not). `device`: `None` picks CUDA when
    /// available.
    ///
    /// # Errors
    /// [`FmError::Files`] (`Format`) / [`FmError::Files`] (`Io`) naming the file at fault, or
    /// [`FmError::Config`] when the folder has neither a final model nor a
    /// checkpoint.
    pub fn load(run_dir: impl AsRef<Path>, device: Option<Device>) -> Result<Self> {
        let run_dir = run_dir.as_ref();
        if !run_dir.is_dir() {
            return Err(FmError::io(
                run_dir,
                std::io::Error::new(
                    std::io::ErrorKind::NotFound,
                    if run_dir.exists() {
                        "not a folder (a run folder is what `mfm train --out` writes)"
                    } else {
                        "no such run folder"
                    },
                ),
            ));
        }
        let weights = run_dir.join(WEIGHTS_FILE);
        if weights.is_file() {
            checkpoint::verify_final_model(run_dir)?;
            return Self::load_files(&weights, &run_dir.join(FLOW_FILE), device);
        }
        let (best, rejected) = crate::checkpoint::newest_valid_checkpoint(run_dir)?;
        for (dir, err) in &rejected {
            eprintln!("warning: skipping checkpoint {}: {err}", dir.display());
        }
        match best {
            Some((info, _)) => Self::load_checkpoint(&info.dir, device),
            None => match rejected.into_iter().next() {
                Some((_, err)) => Err(err.into()),
                None => Err(FmError::Config(format!(
                    "{} has no final model ({WEIGHTS_FILE}) and no checkpoint",
                    run_dir.display()
                ))),
            },
        }
    }

    /// Loads one checkpoint folder after checking its files' checksums: its
    /// weight average (`ema.safetensors`) when it has one, else its weights.
    ///
    /// # Errors
    /// As [`crate::checkpoint::verify_checkpoint`], and network loading errors.
    pub fn load_checkpoint(dir: impl AsRef<Path>, device: Option<Device>) -> Result<Self> {
        Self::load_checkpoint_weights(dir, device, true)
    }

    /// [`Sampler::load_checkpoint`] with the choice of weights: the weight
    /// average when `average` and the checkpoint has one, else the trained
    /// weights (to compare the two at one step).
    ///
    /// # Errors
    /// As [`Sampler::load_checkpoint`].
    pub fn load_checkpoint_weights(
        dir: impl AsRef<Path>,
        device: Option<Device>,
        average: bool,
    ) -> Result<Self> {
        let dir = dir.as_ref();
        let state = crate::checkpoint::verify_checkpoint(dir)?;
        let weights = if average && state.files.contains_key(EMA_FILE) {
            EMA_FILE
        } else {
            WEIGHTS_FILE
        };
        Self::load_files(&dir.join(weights), &dir.join(FLOW_FILE), device)
    }

    fn load_files(weights: &Path, flow_path: &Path, device: Option<Device>) -> Result<Self> {
        let device = match device {
            Some(d) => d,
            None => DeviceChoice::Auto.resolve()?,
        };
        let flow = FlowSpec::read(flow_path)?;
        let prior = read_prior(flow_path, &flow)?;
        let net = PoissonNet::load(weights, device)?;
        // a run whose training blew up can leave NaN or inf weights; every
        // sample would then fail deep inside the network
        for (name, v) in net.var_store().variables() {
            if !bool::try_from(v.isfinite().all()).unwrap_or(false) {
                return Err(FmError::Diverged(format!(
                    "{}: the weights `{name}` are not finite (NaN or inf): the training run \
                     diverged; retrain with a lower train.lr",
                    weights.display()
                )));
            }
        }
        let sampler = Self::new(net, flow)?;
        match prior {
            Some(p) => sampler.with_prior(p),
            None => Ok(sampler),
        }
    }

    /// The flow spec.
    pub fn flow(&self) -> &FlowSpec {
        &self.flow
    }

    /// The network.
    pub fn net(&self) -> &PoissonNet {
        &self.net
    }

    /// Builds the operators (once, as [`MeshContext`](crate::context::MeshContext)
    /// does), the noise sampler and the network's tensors of a target mesh;
    /// without the noise sampler when this sampler starts from given noise
    /// ([`Sampler::with_start_noise`]), whose factor would go unused. Both
    /// factors keep only their `f32` copies, the precision sampling solves
    /// and draws in ([`mfm_solver::LaplacianSolver::release_f64_factor`]).
    ///
    /// Cost: the mesh operators and two sparse factorizations (one with
    /// starting noise).
    ///
    /// # Errors
    /// Operator, factorization or noise errors of the mesh.
    pub fn prepare(&self, mesh: &TriMesh) -> Result<TargetMesh> {
        let framed = self.flow.frame.apply(mesh);
        let noise = self.start.is_none().then_some(self.flow.noise);
        let (tensors, noise) = sampling_parts(&framed, noise)?;
        let per_block = faces_per_block(self.net.config().width);
        let blocks = (tensors.num_faces() > per_block).then(|| tensors.face_blocks(per_block));
        let prior = match (&self.prior, &self.start) {
            (Some(p), None) => Some(locate_within_tolerance(
                p.mesh(),
                &framed,
                "the training surface the prior is fitted on",
            )?),
            _ => None,
        };
        Ok(TargetMesh {
            mesh: tensors,
            blocks,
            noise,
            prior,
            xyz: positions_tensor(framed.positions(), self.net.device()),
        })
    }

    /// Why `mesh` may not be the training surface in the training data's
    /// units: one line per size measure (largest bounding-box extent, area)
    /// that differs by more than 5%, naming both values. Empty when they
    /// agree or the run does not record its training surface.
    pub fn surface_warnings(&self, mesh: &TriMesh) -> Vec<String> {
        match &self.flow.training_surface {
            Some(train) => train.mismatches(&SurfaceSize::of(mesh), SURFACE_TOLERANCE),
            None => Vec::new(),
        }
    }

    /// Generates `count` samples on `mesh` from `seed`: `[count, V, C]`.
    ///
    /// # Errors
    /// See [`Sampler::prepare`] and [`Sampler::sample_on`].
    pub fn sample(
        &self,
        mesh: &TriMesh,
        count: usize,
        seed: u64,
        options: &SampleOptions,
    ) -> Result<Samples> {
        let target = self.prepare(mesh)?;
        self.sample_on(&target, 0, count, seed, options)
    }

    /// The batch the samples on `target` are integrated in: `batch`, or
    /// fewer where that many would take more than [`SAMPLE_BATCH_BYTES`] of
    /// activations ([`SAMPLE_BYTES_PER_FACE_CHANNEL`] per face and channel
    /// of the network's width), at least 1. On a mesh of a million faces a
    /// sample of a small network takes GBs, and batching it saves nothing:
    /// the solves are as many per sample, and the factor is shared by every
    /// batch of one call anyway. Sample `i` does not depend on its batch
    /// (up to the round-off of differently blocked products).
    pub fn batch_on(&self, target: &TargetMesh, batch: usize) -> usize {
        batch_within_memory(target.mesh.num_faces(), self.net.config().width, batch)
    }

    /// Generates samples `first .. first + count` of `seed` on a prepared
    /// mesh, `options.batch` at a time ([`Sampler::batch_on`] fewer on a
    /// very fine mesh).
    ///
    /// # Errors
    /// [`FmError::Config`] for zero steps or batch; noise and network errors.
    pub fn sample_on(
        &self,
        target: &TargetMesh,
        first: usize,
        count: usize,
        seed: u64,
        options: &SampleOptions,
    ) -> Result<Samples> {
        self.sample_on_reporting(target, first, count, seed, options, &|_| {})
    }

    /// [`Sampler::sample_on`] that calls `on_step(b)` after every ODE step
    /// of a batch of `b` samples (for a progress bar over the steps: on a
    /// mesh of a million faces one step takes seconds). The samples are the
    /// same.
    ///
    /// # Errors
    /// As [`Sampler::sample_on`].
    pub fn sample_on_reporting(
        &self,
        target: &TargetMesh,
        first: usize,
        count: usize,
        seed: u64,
        options: &SampleOptions,
        on_step: &dyn Fn(usize),
    ) -> Result<Samples> {
        if options.steps == 0 || options.batch == 0 {
            return Err(FmError::Config(format!(
                "sampling needs at least one step and a batch of at least one, found steps = {} and batch = {}",
                options.steps, options.batch
            )));
        }
        let (v, c) = (target.num_vertices(), self.flow.channels);
        let start = Instant::now();
        let mut noise_seconds = 0.0;
        let mut data = Vec::with_capacity(count * v * c);
        let mut done = 0;
        let batch = self.batch_on(target, options.batch);
        while done < count {
            let b = batch.min(count - done);
            let t0 = Instant::now();
            let x0 = self.noise(target, first + done, b, seed)?;
            noise_seconds += t0.elapsed().as_secs_f64();
            let x1 = self.finish(
                target,
                &self.integrate_reporting(target, &x0, options, &|| on_step(b))?,
            );
            let flat = x1.to_device(Device::Cpu).contiguous().view([-1]);
            let values = Vec::<f32>::try_from(&flat)?;
            data.extend_from_slice(&values);
            done += b;
        }
        Ok(Samples {
            data,
            samples: count,
            vertices: v,
            channels: c,
            seconds: start.elapsed().as_secs_f64(),
            noise_seconds,
        })
    }

    /// Generates samples `0..request.count` of `request.seed` on `target`
    /// and streams them to the `.npy` file `path` (`[count, V, C]` `f32`,
    /// written atomically), at most [`SAMPLE_CHUNK_BYTES`] at a time (at
    /// least one batch), keeping the first `request.keep` in memory for
    /// pictures and meshes.
    ///
    /// A sample with a non-finite value stops the run before it is written
    /// and the file is not created.
    ///
    /// # Errors
    /// [`FmError::Diverged`] naming the sample, vertex and channel; the
    /// errors of [`Sampler::sample_on`] and of the file.
    pub fn sample_to_npy(
        &self,
        target: &TargetMesh,
        path: &Path,
        request: SampleRequest,
        options: &SampleOptions,
    ) -> Result<StreamedSamples> {
        let SampleRequest {
            count: n,
            seed,
            keep,
            progress,
        } = request;
        let (v, c) = (target.num_vertices(), self.flow.channels);
        let row = v * c;
        let keep = keep.min(n);
        let chunk = (SAMPLE_CHUNK_BYTES / (row * 4).max(1))
            .max(options.batch)
            .min(n)
            .max(1);
        let shape = [n as u64, v as u64, c as u64];
        let mut file = mfm_files::npy::NpyStream::<f32>::create(path, &shape)?;
        // over ODE steps of every sample: on a fine mesh one step of one
        // batch takes seconds, a chunk minutes
        let steps = options.steps as u64;
        let bar = if progress {
            indicatif::ProgressBar::new(n as u64 * steps)
        } else {
            indicatif::ProgressBar::hidden()
        };
        if let Ok(style) = indicatif::ProgressStyle::with_template(
            "sampling {elapsed_precise} [{bar:30}] {msg}, eta {eta}",
        ) {
            bar.set_style(style.progress_chars("=> "));
        }
        let mut kept: Vec<f32> = Vec::with_capacity(keep * row);
        let (mut seconds, mut noise_seconds) = (0.0, 0.0);
        let mut first = 0;
        while first < n {
            let count = chunk.min(n - first);
            bar.set_message(format!(
                "samples {first}..{} of {n}, {steps} ODE steps each",
                first + count
            ));
            let part = self
                .sample_on_reporting(target, first, count, seed, options, &|b| bar.inc(b as u64))?;
            if let Some((i, vertex, channel, value)) =
                mfm_data::signals::first_non_finite(&part.data, v, c)
            {
                return Err(FmError::Diverged(format!(
                    "sample {} is not finite ({value} at vertex {vertex}, channel {channel}): the model diverged",
                    first + i
                )));
            }
            let take = keep.saturating_sub(first).min(count);
            kept.extend_from_slice(&part.data[..take * row]);
            file.append(&part.data)?;
            seconds += part.seconds;
            noise_seconds += part.noise_seconds;
            first += count;
            bar.set_position(first as u64 * steps);
        }
        bar.finish_and_clear();
        file.finish()?;
        Ok(StreamedSamples {
            first: InMemorySignals::new(kept, keep, v, c)?,
            seconds,
            noise_seconds,
        })
    }

    /// The end of the ODE on `target` (`[B, V, C]`, in the training frame)
    /// as samples in the target's units: plus the dataset mean for a centred
    /// run, plus the target's own vertices for a run that generates
    /// displacements ([`FlowSpec::displacements`]), then, for positions,
    /// through the inverse of the frame.
    pub fn finish(&self, target: &TargetMesh, x: &Tensor) -> Tensor {
        let mut x = x.shallow_clone();
        if self.flow.centered
            && let Some(o) = &self.offset
        {
            x = &x + o;
        }
        if self.flow.displacements {
            x = &x + &target.xyz;
        }
        let frame = self.flow.frame;
        if self.flow.positions && !frame.is_identity() {
            let shift = Tensor::from_slice(&frame.shift.map(|v| v as f32))
                .reshape([1, 1, 3])
                .to_device(x.device());
            x = (x - shift) * (1.0 / frame.scale);
        }
        x
    }

    /// The starting noise of samples `first .. first + count` of `seed` on
    /// the target: `[count, V, C]` `f32` on the network's device (the run's
    /// noise kind, times its scale, plus the run's prior draws when it has
    /// a prior, centred by its mass-weighted mean for a centred run), or
    /// those samples of the starting noise given with
    /// [`Sampler::with_start_noise`], as given.
    ///
    /// # Errors
    /// Noise sampling errors; [`FmError::Config`] when the given starting
    /// noise does not have these samples on this mesh.
    pub fn noise(
        &self,
        target: &TargetMesh,
        first: usize,
        count: usize,
        seed: u64,
    ) -> Result<Tensor> {
        let (v, c) = (target.num_vertices() as i64, self.flow.channels);
        if let Some(start) = &self.start {
            let [n, sv, sc] = start.shape;
            if sv as i64 != v || first + count > n {
                return Err(FmError::Config(format!(
                    "starting noise has shape [{n}, {sv}, {sc}]; samples {first}..{} on this mesh need [{}, {v}, {c}]",
                    first + count,
                    first + count
                )));
            }
            let row = sv * sc;
            let x = Tensor::from_slice(&start.values[first * row..(first + count) * row])
                .reshape([count as i64, v, c as i64])
                .to_device(self.net.device());
            return Ok(x);
        }
        let sampler = target.noise.as_ref().ok_or_else(|| {
            FmError::Config(
                "the target mesh was prepared by a sampler with starting noise, without a noise \
                 sampler: prepare it again with this one"
                    .into(),
            )
        })?;
        let batch = sampler.sample_range_f32(first, count, c, seed)?;
        let scale = self.flow.noise_scale as f32;
        let mut values = batch.into_data();
        if scale != 1.0 {
            values.iter_mut().for_each(|x| *x *= scale);
        }
        match (&self.prior, &target.prior) {
            (Some(prior), Some(transfer)) => {
                prior.add_draws(&mut values, first, count, seed, Some(transfer))?
            }
            (None, _) if self.flow.prior.is_some() => {
                return Err(FmError::Config(
                    "the run's flow.json records a prior that this sampler was not given \
                     (Sampler::with_prior; Sampler::load reads it)"
                        .into(),
                ));
            }
            (Some(_), None) => {
                return Err(FmError::Config(
                    "the target mesh was prepared without the run's prior: prepare it again \
                     with this sampler"
                        .into(),
                ));
            }
            (None, _) => {}
        }
        let x = Tensor::from_slice(&values)
            .reshape([count as i64, v, c as i64])
            .to_device(self.net.device());
        if self.flow.centered {
            Ok(target.mesh.remove_mass_mean(&x)?)
        } else {
            Ok(x)
        }
    }

    /// Starting noise for samples `0..count` of `seed` on `to`, drawn on
    /// `from` (as [`Sampler::noise`] draws it there) and carried to `to`'s
    /// vertices by closest point and barycentric weights
    /// ([`mfm_data::transfer::Transfer`]), then centred again with `to`'s
    /// lumped mass for a centred run. With `from` the training mesh and
    /// `to` a refinement of it, the samples on `to` start from the very
    /// noise of the samples on `from`, with no frequency `from` cannot
    /// hold: what is left of a difference between the two is the network's
    /// own behaviour at the new resolution. Give the result to
    /// [`Sampler::with_start_noise`] (call this first: a sampler with
    /// starting noise draws nothing).
    ///
    /// # Errors
    /// [`FmError::Config`] when a vertex of `to` lies farther than
    /// [`CARRY_TOLERANCE`] of `to`'s bounding-box diagonal from `from`'s
    /// surface (not two triangulations of one surface, or not in the same
    /// units); the errors of [`Sampler::prepare`] and [`Sampler::noise`].
    pub fn carried_noise(
        &self,
        from: &TriMesh,
        to: &TriMesh,
        count: usize,
        seed: u64,
    ) -> Result<StartNoise> {
        let transfer = locate_within_tolerance(from, to, "the surface the noise is drawn on")?;
        let source = self.prepare(from)?;
        let x = self.noise(&source, 0, count, seed)?;
        let drawn = Vec::<f32>::try_from(&x.to_device(Device::Cpu).contiguous().view([-1]))?;
        let c = self.flow.channels;
        let (vf, vt) = (from.num_vertices(), to.num_vertices());
        let mass = mfm_geometry::operators::lumped_mass(to);
        let total: f64 = mass.iter().sum();
        let mut values = Vec::with_capacity(count * vt * c);
        for sample in drawn.chunks(vf * c) {
            let mut carried = transfer.apply(sample, c)?;
            if self.flow.centered && total > 0.0 {
                for k in 0..c {
                    let mean = carried
                        .iter()
                        .skip(k)
                        .step_by(c)
                        .zip(&mass)
                        .map(|(&x, m)| f64::from(x) * m)
                        .sum::<f64>()
                        / total;
                    carried
                        .iter_mut()
                        .skip(k)
                        .step_by(c)
                        .for_each(|x| *x = (f64::from(*x) - mean) as f32);
                }
            }
            values.extend(carried);
        }
        Ok(StartNoise {
            values,
            shape: [count, vt, c],
        })
    }

    /// The velocity `v(x, t)` at time `t` for a batch `x: [B, V, C]` (no
    /// gradient is recorded).
    ///
    /// # Errors
    /// Network errors (shapes, solves).
    pub fn velocity(&self, target: &TargetMesh, x: &Tensor, t: f64) -> Result<Tensor> {
        let b = x.size()[0];
        let tt = Tensor::full([b], t, (Kind::Float, x.device()));
        let cond = conditioning(&self.flow, &target.xyz, &tt);
        let out = tch::no_grad(|| match &target.blocks {
            Some(blocks) => self
                .net
                .forward_blocks(&target.mesh, blocks, x, Some(&cond)),
            None => self.net.forward(&target.mesh, x, Some(&cond)),
        })?;
        if self.flow.prediction == crate::checkpoint::Prediction::Clean {
            // v = (x1_hat - x_t) / (1 - t); the ODE never evaluates t = 1
            return Ok((out.vertex - x) / (1.0 - t).max(1e-6));
        }
        Ok(match (&self.offset, self.flow.centered) {
            (Some(o), false) => out.vertex + o,
            _ => out.vertex,
        })
    }

    /// Integrates `x0: [B, V, C]` from `t = 0` to `t = 1` with
    /// `options.steps` steps of `options.method` (see the module docs).
    ///
    /// # Errors
    /// [`FmError::Config`] for zero steps; network errors.
    pub fn integrate(
        &self,
        target: &TargetMesh,
        x0: &Tensor,
        options: &SampleOptions,
    ) -> Result<Tensor> {
        self.integrate_reporting(target, x0, options, &|| {})
    }

    /// Integrates a state `x: [B, V, C]` at time `t0` (in `[0, 1)`) to
    /// `t = 1` with `options.steps` equal steps of `options.method`: the
    /// flow from a point part of the way along the path, e.g. a real shape
    /// noised to `t0` (`(1 - t0) x0 + t0 x1`, in the run's frame and
    /// centred as in training). `t0 = 0` is [`Sampler::integrate`].
    ///
    /// # Errors
    /// As [`Sampler::integrate`]; [`FmError::Config`] for `t0` outside
    /// `[0, 1)`.
    pub fn integrate_from(
        &self,
        target: &TargetMesh,
        x: &Tensor,
        t0: f64,
        options: &SampleOptions,
    ) -> Result<Tensor> {
        if !(0.0..1.0).contains(&t0) {
            return Err(FmError::Config(format!(
                "the ODE starts at a time in [0, 1), found {t0}"
            )));
        }
        self.integrate_over(target, x, t0, options, &|| {})
    }

    /// [`Sampler::integrate`] that calls `on_step()` after every step.
    ///
    /// # Errors
    /// As [`Sampler::integrate`].
    pub fn integrate_reporting(
        &self,
        target: &TargetMesh,
        x0: &Tensor,
        options: &SampleOptions,
        on_step: &dyn Fn(),
    ) -> Result<Tensor> {
        self.integrate_over(target, x0, 0.0, options, on_step)
    }

    /// The integration from `t0` to 1 behind [`Sampler::integrate_reporting`]
    /// and [`Sampler::integrate_from`].
    fn integrate_over(
        &self,
        target: &TargetMesh,
        x0: &Tensor,
        t0: f64,
        options: &SampleOptions,
        on_step: &dyn Fn(),
    ) -> Result<Tensor> {
        if options.steps == 0 {
            return Err(FmError::Config(
                "sampling needs at least one ODE step".into(),
            ));
        }
        let h = (1.0 - t0) / options.steps as f64;
        let mut x = x0.shallow_clone();
        // A state that overflowed would reach the Poisson solves as NaN; say
        // where the integration broke down instead.
        let velocity = |x: &Tensor, t: f64, k: usize| -> Result<Tensor> {
            let finite = bool::try_from(x.isfinite().all()).unwrap_or(false);
            if !finite {
                return Err(FmError::Diverged(format!(
                    "sampling diverged at ODE step {k} of {} (t = {t:.3}): the state is not finite; \
                     the model does not handle this mesh or noise (e.g. noise far larger than the \
                     training data)",
                    options.steps
                )));
            }
            self.velocity(target, x, t).map_err(|e| match e {
                FmError::Net(n) => FmError::Diverged(format!(
                    "sampling failed at ODE step {k} of {} (t = {t:.3}): {n}",
                    options.steps
                )),
                other => other,
            })
        };
        for k in 0..options.steps {
            let t = t0 + k as f64 * h;
            x = crate::path::ode_step(options.method, &x, t, h, |x, t| velocity(x, t, k))?;
            on_step();
        }
        if !bool::try_from(x.isfinite().all()).unwrap_or(false) {
            return Err(FmError::Diverged(format!(
                "sampling diverged: the final state after {} ODE steps is not finite",
                options.steps
            )));
        }
        Ok(x)
    }
}
