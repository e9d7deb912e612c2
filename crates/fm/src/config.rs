//! [`RunConfig`]: everything a training run needs besides its data, as one
//! TOML file: the schema, its defaults, its checks and its TOML form. The
//! pieces it names live with their concepts: the rate schedule
//! ([`mfm_train::LrSchedule`]), the path times ([`crate::path::TimeSampling`]),
//! the device ([`crate::device::DeviceChoice`]), the presets
//! ([`crate::presets`]), what a resumed run may change
//! ([`crate::train::RESUMABLE_FIELDS`]).
//!
//! A run folder holds the configuration it was started with
//! (`config.toml`, written by [`RunConfig::write_toml_file`]); every
//! checkpoint carries a copy. Every field has a default, so a file only
//! names what differs from it, and unknown fields are errors (a typo never
//! silently falls back to a default).
//!
//! ## The file
//! ```toml
//! [dataset]
//! path = "data/gmm"            # read by the caller (CLI); recorded here
//! frame = "canonical"          # or "as-is"
//! positions = true             # optional; default: 3 channels are positions
//!
//! [model]
//! preset = "paper"             # PoissonNet preset: paper, medium, small
//! width = 64                   # optional overrides of the preset's sizes
//! blocks = 4
//! vector_layers = 3
//! head = "njf"                 # or "linear", "njf_no_input_gradient"
//! modulation = true
//! condition_on_xyz = false     # condition on t only (true: source xyz and t)
//! mean_offset = true
//! displacements = false        # true: shapes as displacements of the sampled mesh
//!
//! [noise]
//! kind = "matern:100"          # any form NoiseKind parses
//! scale = 3.0                  # sigma: a factor, or "unit", or "data"
//! prior = "none"               # or "gaussian": start from a Gaussian fit of the data plus the noise
//! prior_directions = 64        # principal directions the Gaussian prior keeps
//!
//! [train]
//! steps = 160000
//! batch = 32
//! lr = 5e-4
//! lr_schedule = { milestones = [[40000, 1e-4]] }   # or { decay = 0.2, at = [40000, 160000] }
//! grad_clip = 1.0
//! checkpoint_every = 1000
//! log_every = 100
//! seed = 0
//! threads = 0
//! device = "auto"
//! center = true                # centred noise and targets
//!
//! [sample]
//! steps = 20
//! method = "midpoint"
//! batch = 8
//! seed = 0
//! ```
//!
//! [`RunConfig::default`] is the official training recipe (paper section 4,
//! its implementation details and the authors' configs: canonical frame,
//! `matern:100` noise with `sigma = 3`, centred noise and targets, 20
//! midpoint sampling steps) on the paper's network, conditioned on `t`
//! only; [`RunConfig::preset`] ([`crate::presets`]) gives the named presets `paper` and
//! `paper-elastic` (the official human-pose and elastic models, conditioned
//! on source xyz and `t`), `cpu` and `cpu-deform` (a small network and a
//! few thousand steps, minutes on two cores).
//!
//! # Example
//! ```
//! use mfm_fm::config::RunConfig;
//! let cfg = RunConfig::from_toml_str("[train]\nsteps = 10\n", "inline").unwrap();
//! assert_eq!(cfg.train.steps, 10);
//! assert_eq!(cfg.train.batch, 32); // the default
//! let err = RunConfig::from_toml_str("[train]\nstep = 10\n", "inline").unwrap_err();
//! assert!(err.to_string().contains("step"));
//! let back = RunConfig::from_toml_str(&cfg.to_toml_string().unwrap(), "inline").unwrap();
//! assert_eq!(back, cfg);
//! ```

use std::fmt;
use std::path::{Path, PathBuf};

use mfm_net::{HeadKind, PoissonNetConfig};
use mfm_noise::NoiseKind;
use serde::{Deserialize, Deserializer, Serialize, Serializer};

use mfm_train::LrSchedule;

use crate::coupling::Coupling;
use crate::device::DeviceChoice;
use crate::error::{FmError, Result};
use crate::path::TimeSampling;
pub use crate::prior::PriorKind;

/// A training run: data, network, noise, optimization and sampling settings.
///
/// Every section and field has a default (see each field); `RunConfig::default()`
/// is the paper's recipe with `t`-only conditioning.
#[derive(Clone, Debug, PartialEq, Default, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RunConfig {
    /// Where the signals come from.
    pub dataset: DatasetConfig,
    /// The PoissonNet denoiser.
    pub model: ModelConfig,
    /// The noise the flow starts from.
    pub noise: NoiseConfig,
    /// Optimization.
    pub train: TrainConfig,
    /// ODE sampling.
    pub sample: SampleConfig,
}

/// `[dataset]`: where the signals are.
#[derive(Clone, Debug, PartialEq, Default, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DatasetConfig {
    /// The dataset folder (default: none). The training code receives the
    /// signals and the mesh from its caller; this records where they came
    /// from so a run folder documents itself and the CLI can resume it.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub path: Option<PathBuf>,
    /// Where training puts the surface before anything else (default
    /// `canonical`): see [`FrameChoice`].
    pub frame: FrameChoice,
    /// Whether the signals are vertex positions (shapes), which move with
    /// the frame and are mapped back to the dataset's units after sampling,
    /// or values (scalars, colours), which the frame leaves alone. Default:
    /// positions exactly when the signals have 3 channels.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub positions: Option<bool>,
}

impl DatasetConfig {
    /// [`DatasetConfig::positions`], or its default for `channels`.
    pub fn signals_are_positions(&self, channels: usize) -> bool {
        self.positions.unwrap_or(channels == 3)
    }
}

/// The frame a run trains in ([`mfm_geometry::frame`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum FrameChoice {
    /// The training mesh's bounding box centred at the origin with largest
    /// extent 1, the frame of the official meshes, in which the paper's
    /// `tau = 100` means a correlation length of a tenth of the shape. The
    /// same map is applied to every sampling mesh.
    #[default]
    Canonical,
    /// The mesh as the dataset stores it (`tau` then depends on its units).
    AsIs,
}

/// `[model]`: the PoissonNet. Input and output channels follow the
/// dataset's channel count `C`; conditioning is `t` (1 channel) or source
/// xyz and `t` (4 channels, `[x, y, z, t]` per vertex).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ModelConfig {
    /// A [`PoissonNetConfig::preset`] name giving the sizes: `paper`
    /// (`W = 128, K = 5, nl = 3`), `medium` (`64, 4, 3`) or `small`
    /// (`32, 3, 3`). Default `paper`.
    pub preset: String,
    /// Hidden width `W`, overriding the preset's (default: the preset's).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub width: Option<usize>,
    /// Number of Poisson blocks `K`, overriding the preset's.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub blocks: Option<usize>,
    /// Complex layers per vector MLP `nl`, overriding the preset's.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub vector_layers: Option<usize>,
    /// Output head: `njf` (the paper's; vertex and Jacobian velocities),
    /// `njf_no_input_gradient` (the same without adding the input's
    /// gradients to the Jacobian output, an ablation) or `linear`. Default
    /// `njf`.
    pub head: HeadKind,
    /// Whether the vector MLPs are modulated (default `true`, the paper's).
    pub modulation: bool,
    /// Condition every block on the source vertex positions as well as on
    /// `t` (default `false`; the paper's deformation models use `true`).
    /// When sampling on another mesh, its positions are the source xyz.
    pub condition_on_xyz: bool,
    /// Restore the dataset's mean: the per-channel mean of the signals
    /// (mass-weighted over the surface, averaged over up to 256 evenly
    /// spaced signals, in the training frame) is added to every sample
    /// (default `true`).
    ///
    /// The NJF head removes the mass-weighted mean of its output, so the
    /// flow cannot move a sample's mean: without this, a sample keeps the
    /// (zero or near zero) mean of its noise and can never reach data whose
    /// mean is not zero (a field of positive bumps, a shape away from the
    /// origin). With [`TrainConfig::center`] (the default) the flow runs
    /// between centred noise and centred targets and the mean is added once,
    /// after the last ODE step; without it the mean is added to the
    /// network's vertex velocity at every step (integrating to the same
    /// constant). For the linear head, whose output can carry a mean, only
    /// with centring.
    pub mean_offset: bool,
    /// What the network outputs: `velocity` (default, the paper's) or
    /// `clean`, the clean signal `x1_hat`, from which the velocity is
    /// `(x1_hat - x_t) / (1 - t)`. The loss stays in velocity space:
    /// `|x1_hat - x1|^2 / (1 - t)^2`, the weight clipped at
    /// [`CLEAN_WEIGHT_MAX`], for the vertex and the Jacobian terms alike.
    /// Needs `train.center` (the velocity offset of uncentred runs has no
    /// clean-signal form).
    pub prediction: crate::checkpoint::Prediction,
    /// Generate shapes as displacements of the mesh they are sampled on
    /// instead of as positions (default `false`, the paper's): training
    /// targets are each shape minus the training mesh's vertices (in the
    /// training frame), and a sample is the generated displacement field
    /// plus the sampling mesh's own vertices. Any triangulation of the rest
    /// surface carries its rest positions, so the model stays
    /// triangulation-agnostic; the network generates how the shape moves
    /// rather than its whole geometry. The sampling mesh must then be a
    /// triangulation of the rest shape (as it is for conditioning on xyz).
    /// Measured against positions with everything else the same, it is no
    /// better on the shared horse and crane nor on the elephant's ARAP
    /// poses (docs/BENCHMARKS.md, "Shapes as displacements"): an option
    /// for data whose shapes stay close to their rest mesh, not a default.
    /// Needs position signals (3 channels) and no `train.augment`.
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    pub displacements: bool,
    /// Give every Poisson block a global view of the shape
    /// ([`PoissonNetConfig::global_context`]: the surface mean of its hidden
    /// vertex features, mapped back to every vertex). Default `false`, the
    /// paper's network; not written to configs when `false`.
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    pub global_context: bool,
}

/// Largest loss weight `1 / (1 - t)^2` of clean-signal prediction
/// ([`ModelConfig::prediction`]): reached at `t = 0.9`.
pub const CLEAN_WEIGHT_MAX: f64 = 100.0;

impl Default for ModelConfig {
    fn default() -> Self {
        Self {
            preset: "paper".into(),
            width: None,
            blocks: None,
            vector_layers: None,
            head: HeadKind::Njf,
            modulation: true,
            condition_on_xyz: false,
            mean_offset: true,
            prediction: crate::checkpoint::Prediction::Velocity,
            displacements: false,
            global_context: false,
        }
    }
}

impl ModelConfig {
    /// Conditioning channels per vertex: 4 with source xyz, 1 otherwise.
    pub fn cond_channels(&self) -> usize {
        if self.condition_on_xyz { 4 } else { 1 }
    }

    /// The network configuration for signals of `channels` channels.
    ///
    /// # Errors
    /// [`FmError::Config`] for an unknown preset, `channels == 0` or sizes
    /// the network rejects.
    pub fn net_config(&self, channels: usize) -> Result<PoissonNetConfig> {
        let base = PoissonNetConfig::preset(&self.preset)
            .map_err(|e| FmError::Config(format!("model.preset: {e}")))?;
        let cfg = PoissonNetConfig {
            width: self.width.unwrap_or(base.width),
            blocks: self.blocks.unwrap_or(base.blocks),
            vector_layers: self.vector_layers.unwrap_or(base.vector_layers),
            in_channels: channels,
            out_channels: channels,
            cond_channels: self.cond_channels(),
            modulation: self.modulation,
            head: self.head,
            global_context: self.global_context,
        };
        cfg.validate()
            .map_err(|e| FmError::Config(format!("model: {e}")))?;
        Ok(cfg)
    }
}

/// How noise samples are scaled before training and sampling.
///
/// In TOML: a number (a fixed factor), `"unit"` or `"data"`. The named
/// forms are resolved to a factor once, on the training mesh, when training
/// starts, and that factor is stored with the run (`flow.json`), so sampling
/// on any other mesh uses the same one.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum NoiseScale {
    /// Multiply every sample by this factor (`> 0`).
    Factor(f64),
    /// Scale so the noise has unit root-mean-square value over the training
    /// surface (mass-weighted, estimated from 64 samples).
    Unit,
    /// Scale so the noise's root-mean-square value equals that of the data
    /// after removing each signal's per-channel mean (the part the network
    /// models; mass-weighted, up to 256 signals).
    Data,
}

impl Default for NoiseScale {
    /// `3.0`: the official recipe's `sigma` for elastic data.
    fn default() -> Self {
        Self::Factor(DEFAULT_SIGMA)
    }
}

/// The default noise amplitude `sigma` ([`NoiseConfig::scale`]).
pub const DEFAULT_SIGMA: f64 = 3.0;

impl fmt::Display for NoiseScale {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Factor(x) => write!(f, "{x}"),
            Self::Unit => f.write_str("unit"),
            Self::Data => f.write_str("data"),
        }
    }
}

impl std::str::FromStr for NoiseScale {
    type Err = String;

    /// A positive number, `unit` or `data` (the TOML forms).
    fn from_str(s: &str) -> std::result::Result<Self, Self::Err> {
        match s {
            "unit" => Ok(Self::Unit),
            "data" => Ok(Self::Data),
            other => match other.parse::<f64>() {
                Ok(x) if x.is_finite() && x > 0.0 => Ok(Self::Factor(x)),
                _ => Err(format!(
                    "unknown noise scale {other:?}; expected a finite number > 0, \"unit\" or \"data\""
                )),
            },
        }
    }
}

impl Serialize for NoiseScale {
    fn serialize<S: Serializer>(&self, s: S) -> std::result::Result<S::Ok, S::Error> {
        match self {
            Self::Factor(x) => s.serialize_f64(*x),
            Self::Unit => s.serialize_str("unit"),
            Self::Data => s.serialize_str("data"),
        }
    }
}

impl<'de> Deserialize<'de> for NoiseScale {
    fn deserialize<D: Deserializer<'de>>(d: D) -> std::result::Result<Self, D::Error> {
        struct V;
        impl serde::de::Visitor<'_> for V {
            type Value = NoiseScale;
            fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                f.write_str(r#"a positive number, "unit" or "data""#)
            }
            fn visit_f64<E: serde::de::Error>(self, v: f64) -> std::result::Result<NoiseScale, E> {
                if v.is_finite() && v > 0.0 {
                    Ok(NoiseScale::Factor(v))
                } else {
                    Err(E::custom(format!(
                        "noise scale must be a finite number > 0, found {v}"
                    )))
                }
            }
            fn visit_i64<E: serde::de::Error>(self, v: i64) -> std::result::Result<NoiseScale, E> {
                self.visit_f64(v as f64)
            }
            fn visit_u64<E: serde::de::Error>(self, v: u64) -> std::result::Result<NoiseScale, E> {
                self.visit_f64(v as f64)
            }
            fn visit_str<E: serde::de::Error>(self, v: &str) -> std::result::Result<NoiseScale, E> {
                match v {
                    "unit" => Ok(NoiseScale::Unit),
                    "data" => Ok(NoiseScale::Data),
                    other => Err(E::custom(format!(
                        r#"unknown noise scale {other:?}; expected a positive number, "unit" or "data""#
                    ))),
                }
            }
        }
        d.deserialize_any(V)
    }
}

/// `[noise]`: the distribution `f_0` is drawn from.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct NoiseConfig {
    /// The noise kind, in [`NoiseKind`]'s command-line form (`matern:100`,
    /// `matern-normalized:0.5`, `matern-smooth:100:2`, `white`, `naive`,
    /// `explicit:64:100`).
    ///
    /// Default `matern:100`, the paper's `tau = 100` (used for all its
    /// experiments). `tau` has units of 1 / length²: the noise is smooth
    /// over distances below about `1 / sqrt(tau) = 0.1`, a tenth of the
    /// shape in the canonical frame every run trains in
    /// ([`FrameChoice::Canonical`], largest bounding-box extent 1, as the
    /// official meshes). With `dataset.frame = "as-is"` it is a tenth of a
    /// mesh unit, whatever the mesh's size; `matern-normalized:C` adapts
    /// `tau` to each mesh instead and needs no frame.
    #[serde(with = "mfm_noise::kind::as_text")]
    pub kind: NoiseKind,
    /// The noise amplitude `sigma`: every sample is `solve(L + tau M,
    /// sigma sqrt(m) n)`, i.e. the unit-amplitude noise times `sigma` (the
    /// solve is linear). Default `3.0`, the official recipe's value for its
    /// elastic-deformation data (bunny and fish; `5.0` for human poses, the
    /// `paper` preset; `1.0` in the `cpu-deform` preset, whose data prior
    /// already varies the start as the data does).
    ///
    /// Magnitudes: Matérn noise on a smooth closed surface has pointwise
    /// variance close to `1 / (4 pi tau)` (the continuous Matérn field's), so
    /// `matern:100` at `sigma = 1` has a root-mean-square value of about
    /// `0.028` and `sigma = 3` about `0.085`, well below signals of amplitude
    /// ~1 (the path starts close to zero); naive noise has 1 and white noise
    /// `1 / sqrt(m_v)`, which grows with the vertex count. `"unit"` gives
    /// noise of unit root-mean-square value and `"data"` matches the data's
    /// spread. See [`NoiseScale`].
    pub scale: NoiseScale,
    /// A distribution added to every noise sample, fitted on the training
    /// data when training starts and stored with the run
    /// ([`crate::prior`]): `"none"` (the default, the paper's start) or
    /// `"gaussian"`, the training signals' mean plus a draw with their
    /// covariance, so the flow starts near a plausible signal and learns
    /// only what the Gaussian gets wrong. On another triangulation the draw
    /// is carried from the training mesh. Not written when `"none"`.
    #[serde(skip_serializing_if = "PriorKind::is_none")]
    pub prior: PriorKind,
    /// Most principal directions of the training signals the Gaussian prior
    /// keeps (default [`DEFAULT_PRIOR_DIRECTIONS`]; it keeps all there are
    /// when the data has fewer, at most one less than the signals fitted
    /// on). Not written at its default.
    #[serde(skip_serializing_if = "is_default_prior_directions")]
    pub prior_directions: usize,
}

/// The default of [`NoiseConfig::prior_directions`].
pub const DEFAULT_PRIOR_DIRECTIONS: usize = 64;

fn is_default_prior_directions(n: &usize) -> bool {
    *n == DEFAULT_PRIOR_DIRECTIONS
}

impl Default for NoiseConfig {
    fn default() -> Self {
        Self {
            kind: NoiseKind::Matern {
                tau: mfm_noise::kind::DEFAULT_TAU,
            },
            scale: NoiseScale::default(),
            prior: PriorKind::None,
            prior_directions: DEFAULT_PRIOR_DIRECTIONS,
        }
    }
}

/// `[train]`: optimization. Defaults are the paper's recipe.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TrainConfig {
    /// Number of optimizer steps (default 160,000).
    pub steps: u64,
    /// Signals per step (default 32).
    pub batch: usize,
    /// Base learning rate (default `5e-4`).
    pub lr: f64,
    /// Learning-rate schedule (default: `1e-4` from step 40,000 on).
    pub lr_schedule: LrSchedule,
    /// Clip the global gradient norm to this value (default 1; 0 disables).
    pub grad_clip: f64,
    /// Adam's `beta1` (default 0.9).
    pub adam_beta1: f64,
    /// Adam's `beta2` (default 0.999).
    pub adam_beta2: f64,
    /// Adam's `epsilon` (default `1e-8`).
    pub adam_eps: f64,
    /// Write a checkpoint every this many steps (default 1000); one is
    /// always written at the end and when stopped.
    pub checkpoint_every: u64,
    /// Checkpoints kept in the run folder (default 2, at least 1).
    pub keep_checkpoints: usize,
    /// Write a log row every this many steps (default 100), with the mean
    /// loss and gradient norm since the previous row.
    pub log_every: u64,
    /// Seed of every random choice of the run (default 0): initial weights,
    /// batch order, times and noise.
    pub seed: u64,
    /// libtorch intra-op threads (default 0: libtorch's default).
    pub threads: usize,
    /// `auto` (default), `cpu` or `cuda`.
    pub device: DeviceChoice,
    /// Random global scale and shift of the data (`[train.augment]`; off by
    /// default, as in the official single-source recipe). For position
    /// signals (deformations).
    pub augment: Augment,
    /// Centre every noise sample and every training target by its
    /// mass-weighted mean, per channel and connected component (as the NJF
    /// head centres its output; default `true`, the official recipe): the flow then carries no constant part, which the NJF head
    /// cannot produce anyway, and the dataset's mean is added back after
    /// sampling ([`ModelConfig::mean_offset`]). `false` keeps the raw noise
    /// and targets and adds the mean as a constant velocity instead.
    pub center: bool,
    /// Decay of an exponential moving average of the weights, the weights
    /// that sampling uses (default 0: off, the official recipe). After step
    /// `k` (1-based) every averaged weight `w` becomes `d w + (1 - d) p`
    /// with `d = min(ema, (1 + k) / (10 + k))` (the usual warm-up, so early
    /// checkpoints are not dominated by the initial weights) and `p` the
    /// trained weight. With it on, checkpoints also hold `ema.safetensors`
    /// and the final `model.safetensors` is the average.
    pub ema: f64,
    /// Weight of the Jacobian term of the loss against the vertex term
    /// (default 1, the official `lambda_g = lambda_v = 1`; 0 drops it). The
    /// Jacobian term compares gradients, whose magnitudes are about
    /// `1 / (feature size)` times the values': for bumps a tenth of the
    /// shape across it is ~100 times the vertex term.
    pub jacobian_weight: f64,
    /// How the path time `t` of each training signal is drawn (default
    /// `uniform`, the official recipe): see [`TimeSampling`].
    pub time: TimeSampling,
    /// How noise samples are paired with data signals (default
    /// `independent`, the paper's; `ot:P` pairs a pool of `P` of each by
    /// least total distance): see [`crate::coupling`].
    #[serde(skip_serializing_if = "Coupling::is_independent")]
    pub coupling: Coupling,
    /// Steps whose checkpoints are kept whatever `keep_checkpoints` says
    /// (default none), written even when off the `checkpoint_every` grid:
    /// snapshots for curves of sample quality against training time.
    pub keep_at: Vec<u64>,
}

/// `[train.augment]`: data augmentation by a random global scale and shift
/// per training signal, as the paper does for deformations.
///
/// Signal `i` of a batch becomes `s_i f_i + b_i` with `s_i` uniform in
/// `[1 - scale, 1 + scale]` and `b_i` uniform in `[-shift, shift]^3`; the
/// source xyz the network is conditioned on (when
/// [`ModelConfig::condition_on_xyz`]) gets the same `s_i` and `b_i`, so the
/// pair stays consistent. The draws are a pure function of (seed, step),
/// like every other random choice of training, so resumed runs stay
/// bit-identical. Only for 3-channel (position) signals.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Augment {
    /// Largest relative scale change, in `[0, 1)` (default 0: no scaling).
    pub scale: f64,
    /// Largest shift per axis, in the signal's units, `>= 0` (default 0).
    pub shift: f64,
}

impl Augment {
    /// Whether any augmentation is applied.
    pub fn is_active(&self) -> bool {
        self.scale != 0.0 || self.shift != 0.0
    }
}

impl Default for TrainConfig {
    fn default() -> Self {
        Self {
            steps: 160_000,
            batch: 32,
            lr: 5e-4,
            lr_schedule: LrSchedule::default(),
            grad_clip: 1.0,
            adam_beta1: 0.9,
            adam_beta2: 0.999,
            adam_eps: 1e-8,
            checkpoint_every: 1000,
            keep_checkpoints: 2,
            log_every: 100,
            seed: 0,
            threads: 0,
            device: DeviceChoice::Auto,
            augment: Augment::default(),
            center: true,
            ema: 0.0,
            jacobian_weight: 1.0,
            time: TimeSampling::Uniform,
            coupling: Coupling::Independent,
            keep_at: Vec::new(),
        }
    }
}

impl TrainConfig {
    /// The learning rate of step `step` (0-based).
    pub fn lr_at(&self, step: u64) -> f64 {
        self.lr_schedule.lr(self.lr, step, self.steps)
    }
}

/// ODE integrator for sampling.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum OdeMethod {
    /// Explicit midpoint (second order, two network evaluations per step;
    /// the paper's).
    #[default]
    Midpoint,
    /// Forward Euler (first order, one evaluation per step).
    Euler,
}

impl std::str::FromStr for OdeMethod {
    type Err = FmError;

    /// `midpoint` or `euler`.
    fn from_str(s: &str) -> Result<Self> {
        match s.trim().to_ascii_lowercase().as_str() {
            "midpoint" => Ok(Self::Midpoint),
            "euler" => Ok(Self::Euler),
            other => Err(FmError::Config(format!(
                "unknown ODE method {other:?}; expected midpoint or euler"
            ))),
        }
    }
}

/// `[sample]`: generation.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SampleConfig {
    /// ODE steps from `t = 0` to `t = 1` (default 20: the official step
    /// size 0.05).
    pub steps: usize,
    /// Integrator (default `midpoint`).
    pub method: OdeMethod,
    /// Samples integrated together (default 8); bounds memory.
    pub batch: usize,
    /// Noise seed of generated samples (default 0).
    pub seed: u64,
}

impl Default for SampleConfig {
    fn default() -> Self {
        Self {
            steps: 20,
            method: OdeMethod::Midpoint,
            batch: 8,
            seed: 0,
        }
    }
}

impl RunConfig {
    /// Checks values the types cannot: positive sizes and rates, a valid
    /// noise kind and network.
    ///
    /// # Errors
    /// [`FmError::Config`] naming the field (`train.batch`, ...).
    pub fn validate(&self) -> Result<()> {
        let t = &self.train;
        let bad = |field: &str, expected: &str, found: String| {
            Err(FmError::Config(format!(
                "{field} must be {expected}, found {found}"
            )))
        };
        if t.steps == 0 {
            return bad("train.steps", "at least 1", "0".into());
        }
        if t.batch == 0 {
            return bad("train.batch", "at least 1", "0".into());
        }
        if !(t.lr.is_finite() && t.lr > 0.0) {
            return bad("train.lr", "finite and > 0", t.lr.to_string());
        }
        t.lr_schedule
            .validate()
            .map_err(|e| FmError::Config(format!("train.lr_schedule: {e}")))?;
        if !(t.grad_clip.is_finite() && t.grad_clip >= 0.0) {
            return bad(
                "train.grad_clip",
                "finite and >= 0",
                t.grad_clip.to_string(),
            );
        }
        for (name, b) in [
            ("train.adam_beta1", t.adam_beta1),
            ("train.adam_beta2", t.adam_beta2),
        ] {
            if !(0.0..1.0).contains(&b) {
                return bad(name, "in [0, 1)", b.to_string());
            }
        }
        if !(t.adam_eps.is_finite() && t.adam_eps > 0.0) {
            return bad("train.adam_eps", "finite and > 0", t.adam_eps.to_string());
        }
        if t.checkpoint_every == 0 {
            return bad("train.checkpoint_every", "at least 1", "0".into());
        }
        if t.keep_checkpoints == 0 {
            return bad("train.keep_checkpoints", "at least 1", "0".into());
        }
        if t.log_every == 0 {
            return bad("train.log_every", "at least 1", "0".into());
        }
        if !(0.0..1.0).contains(&t.augment.scale) {
            return bad(
                "train.augment.scale",
                "in [0, 1)",
                t.augment.scale.to_string(),
            );
        }
        if !(t.augment.shift.is_finite() && t.augment.shift >= 0.0) {
            return bad(
                "train.augment.shift",
                "finite and >= 0",
                t.augment.shift.to_string(),
            );
        }
        if !(0.0..1.0).contains(&t.ema) {
            return bad("train.ema", "in [0, 1) (0: off)", t.ema.to_string());
        }
        if !(t.jacobian_weight.is_finite() && t.jacobian_weight >= 0.0) {
            return bad(
                "train.jacobian_weight",
                "finite and >= 0",
                t.jacobian_weight.to_string(),
            );
        }
        t.time
            .validate()
            .map_err(|e| FmError::Config(format!("train.time: {e}")))?;
        t.coupling
            .validate(t.batch)
            .map_err(|e| FmError::Config(format!("train.coupling: {e}")))?;
        if self.sample.steps == 0 {
            return bad("sample.steps", "at least 1", "0".into());
        }
        if self.sample.batch == 0 {
            return bad("sample.batch", "at least 1", "0".into());
        }
        self.noise
            .kind
            .validate()
            .map_err(|e| FmError::Config(format!("noise.kind: {e}")))?;
        if let NoiseScale::Factor(x) = self.noise.scale {
            if !(x.is_finite() && x > 0.0) {
                return bad("noise.scale", "finite and > 0", x.to_string());
            }
        }
        if self.noise.prior != PriorKind::None && self.noise.prior_directions == 0 {
            return bad(
                "noise.prior_directions",
                "at least 1 with a prior",
                "0".into(),
            );
        }
        if self.noise.prior != PriorKind::None && t.augment.is_active() {
            return Err(FmError::Config(
                "noise.prior cannot be combined with train.augment (the prior is fitted to the shapes as they are, not scaled or shifted)".into(),
            ));
        }
        if self.model.prediction == crate::checkpoint::Prediction::Clean && !t.center {
            return Err(FmError::Config(
                "model.prediction = \"clean\" needs train.center = true".into(),
            ));
        }
        if self.model.displacements && t.augment.is_active() {
            return Err(FmError::Config(
                "model.displacements = true cannot be combined with train.augment (a scaled or shifted shape is no displacement of the rest mesh)".into(),
            ));
        }
        if self.model.displacements && self.dataset.positions == Some(false) {
            return Err(FmError::Config(
                "model.displacements = true needs position signals; dataset.positions is false"
                    .into(),
            ));
        }
        // sizes and head/channel consistency (with one channel as a stand-in)
        self.model.net_config(1)?;
        Ok(())
    }

    /// Parses TOML text; `origin` names the text in errors (a file name).
    ///
    /// # Errors
    /// [`FmError::Files`] (`Format`) with the parser's message (line, column, and the
    /// unknown or ill-typed field), or [`FmError::Config`] from
    /// [`RunConfig::validate`] prefixed with `origin`.
    pub fn from_toml_str(text: &str, origin: impl AsRef<Path>) -> Result<Self> {
        let origin = origin.as_ref();
        let cfg: Self = toml::from_str(text).map_err(|e| {
            FmError::format(
                origin,
                format!("invalid run configuration: {}", toml_error_line(text, &e)),
            )
        })?;
        cfg.validate().map_err(|e| match e {
            FmError::Config(m) => FmError::format(origin, m),
            other => other,
        })?;
        Ok(cfg)
    }

    /// Reads a TOML file.
    ///
    /// # Errors
    /// [`FmError::Files`] (`Io`) if it cannot be read; otherwise as
    /// [`RunConfig::from_toml_str`], naming the file.
    pub fn from_toml_file(path: impl AsRef<Path>) -> Result<Self> {
        let path = path.as_ref();
        let text = std::fs::read_to_string(path).map_err(|e| FmError::io(path, e))?;
        Self::from_toml_str(&text, path)
    }

    /// The configuration as TOML (every field written, defaults included).
    ///
    /// # Errors
    /// [`FmError::Config`] if a value cannot be written as TOML (a seed
    /// above `i64::MAX`).
    pub fn to_toml_string(&self) -> Result<String> {
        toml::to_string(self).map_err(|e| {
            FmError::Config(format!("cannot write the run configuration as TOML: {e}"))
        })
    }

    /// Writes [`RunConfig::to_toml_string`] to `path` atomically (a
    /// temporary file in the same folder, then a rename).
    ///
    /// # Errors
    /// [`FmError::Files`] (`Io`) naming the file.
    pub fn write_toml_file(&self, path: impl AsRef<Path>) -> Result<()> {
        Ok(mfm_train::checkpoint::write_atomic(
            path.as_ref(),
            self.to_toml_string()?.as_bytes(),
        )?)
    }
}

/// A TOML parse error on one line: "line L, column C: MESSAGE (`the
/// line's text`)" instead of the parser's multi-line drawing.
fn toml_error_line(text: &str, e: &toml::de::Error) -> String {
    let message = e
        .message()
        .lines()
        .map(str::trim)
        .filter(|l| !l.is_empty())
        .collect::<Vec<_>>()
        .join("; ");
    let Some(span) = e.span() else {
        return message;
    };
    let mut start = span.start.min(text.len());
    while !text.is_char_boundary(start) {
        start -= 1;
    }
    let before = &text[..start];
    let line = before.matches('\n').count() + 1;
    let line_start = before.rfind('\n').map_or(0, |i| i + 1);
    let column = text[line_start..start].chars().count() + 1;
    let shown = text[line_start..].lines().next().unwrap_or("").trim();
    if shown.is_empty() {
        format!("line {line}, column {column}: {message}")
    } else {
        format!("line {line}, column {column}: {message} (`{shown}`)")
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn schedules_read_from_toml_and_give_their_rates() {
        let paper = RunConfig::default().train;
        assert_eq!(paper.lr_at(0), 5e-4);
        assert_eq!(paper.lr_at(39_999), 5e-4);
        assert_eq!(paper.lr_at(40_000), 1e-4);
        let c = LrSchedule::Cosine {
            warmup: 10,
            end: 110,
            floor: 0.1,
        };
        // TOML, both ways, and its refusals
        let t = RunConfig::from_toml_str(
            "[train]\nlr_schedule = { warmup = 10, cosine = 110, floor = 0.1 }\n",
            "x.toml",
        )
        .unwrap();
        assert_eq!(t.train.lr_schedule, c);
        let again = RunConfig::from_toml_str(&t.to_toml_string().unwrap(), "x.toml").unwrap();
        assert_eq!(again.train.lr_schedule, c);
        for (bad, says) in [
            ("{ warmup = 10 }", "needs `cosine"),
            ("{ warmup_fraction = 1.0 }", "[0, 1)"),
            ("{ warmup_fraction = 0.1, cosine = 100 }", "spans the run"),
            ("{ warmup_fraction = 0.1, floor = -1.0 }", "floor"),
            ("{ warmup = 10, cosine = 10 }", "must be above"),
            ("{ cosine = 10, floor = -1.0 }", "floor"),
            ("{ cosine = 10, decay = 0.5, at = [3] }", "go alone"),
        ] {
            let e = RunConfig::from_toml_str(&format!("[train]\nlr_schedule = {bad}\n"), "x.toml")
                .unwrap_err()
                .to_string();
            assert!(e.contains(says), "{bad}: {e}");
        }

        // over the run: the fixed cosine with the run's length
        let r = LrSchedule::CosineOverRun {
            warmup_fraction: 0.05,
            floor: 1e-5,
        };
        let fixed = LrSchedule::Cosine {
            warmup: 250,
            end: 5000,
            floor: 1e-5,
        };
        let t = RunConfig::from_toml_str(
            "[train]\nsteps = 5000\nlr = 4e-3\nlr_schedule = { warmup_fraction = 0.05, floor = 1e-5 }\n",
            "x.toml",
        )
        .unwrap();
        assert_eq!(t.train.lr_schedule, r);
        assert_eq!(t.train.lr_at(2600), fixed.lr(4e-3, 2600, 0));
        let again = RunConfig::from_toml_str(&t.to_toml_string().unwrap(), "x.toml").unwrap();
        assert_eq!(again.train.lr_schedule, r);
    }

    #[test]
    fn device_choices_read_as_their_command_line_spelling() {
        for (text, choice) in [
            ("auto", DeviceChoice::Auto),
            ("cpu", DeviceChoice::Cpu),
            ("cuda", DeviceChoice::Cuda),
        ] {
            let c =
                RunConfig::from_toml_str(&format!("[train]\ndevice = {text:?}\n"), "x").unwrap();
            assert_eq!(c.train.device, choice);
            assert_eq!(text.parse::<DeviceChoice>().unwrap(), choice);
        }
    }
}
