//! The authors' pretrained models as mfm runs, and mfm's weights in the
//! authors' format.
//!
//! The official Matérn-FM code saves PyTorch Lightning checkpoints
//! (`.ckpt`, the zip + pickle format of `torch.save`) next to a YAML
//! configuration. [`import_official`] reads both, without Python, and writes
//! an ordinary run folder (`config.toml`, `flow.json`, `model.safetensors`,
//! `model.json`, `model.state.json` with the checksums, and `import.json`
//! saying where it came from) that `mfm sample` and `mfm eval` use as they
//! use a trained run. [`export_official`] writes a run's weights under the
//! official names as a `{"state_dict": ...}` checkpoint the authors' code
//! loads with `model.load_state_dict(torch.load(path)["state_dict"])`.
//!
//! ## What the configuration maps to
//! | official (YAML) | mfm |
//! |---|---|
//! | `model.hidden_dim`, `num_blocks`, `extra_configs.cmlp_nlayers` | `model.width`, `blocks`, `vector_layers` |
//! | `model.head_type: njf`, `extra_configs.cmlp_modulate` | `model.head = "njf"`, `modulation` |
//! | `model.extra_features: ['v_source', 't']` | `condition_on_xyz = true` (`['t']`: false) |
//! | `model.x0_dist`: `sigma`, screened solve with `screening_term` | noise `matern:<screening_term>` times `sigma` |
//! | `train.center_target_data` | `train.center` (noise and targets centred by their mass-weighted means) |
//! | `ode_solver.method`, `step_size` | `sample.method`, `sample.steps = 1 / step_size` |
//!
//! The authors train on their meshes as they are (the official meshes have a
//! largest extent of about 1), so the run's frame is the identity
//! (`dataset.frame = "as-is"`), no dataset mean is added
//! (`model.mean_offset = false`), and the signals are vertex positions.
//! Sampling needs the template mesh the model was trained on, or a
//! remeshing of it in the same place and units: the network is conditioned
//! on the mesh's vertex positions. An x0 drawn without the screened solver
//! (`screened_solver_for_x0: False`, a solve with `L + 1e-6 I`) maps to
//! `matern:0` (the pseudo-inverse, mean-free), which it approximates.
//!
//! Options mfm does not implement are refused naming them: `mlp_norm`,
//! `inner_prod_features`, `mass_norm`, another `outputs_at` than
//! `vertices`, a head other than `njf`, other extra features, other ODE
//! methods. Dropout and drop-path act only in training and are ignored.
//! `use_source_xyz_grad` has no effect in the official network (its
//! argument is never read) and is accepted either way.
//! The arbitrary-source model (`type: Matern_FM_arbitrary_source`, the flow
//! with its eigenvector predictor) is imported by `mfm_arbitrary::official`
//! (which this crate does not depend on) with the readers made public here:
//! [`OfficialCheckpoint`], [`x0_noise`], [`ode_steps`],
//! [`check_extra_configs`], [`check_finite`].

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use mfm_geometry::TriMesh;
use mfm_geometry::frame::{CanonicalFrame, SurfaceSize};
use mfm_net::official::{OFFICIAL_PREFIX, OfficialTensor, load_official, official_state_dict};
use mfm_net::{HeadKind, PoissonNet, PoissonNetConfig};
use mfm_noise::NoiseKind;
use mfm_torchfile::{Checkpoint, TensorData, Value};
use serde::{Deserialize, Serialize};

use mfm_train::checkpoint::{self, FINAL_RECORD_FILE, NET_CONFIG_FILE, WEIGHTS_FILE};

use crate::checkpoint::{CONFIG_FILE, FLOW_FILE, FlowSpec, Prediction};
use crate::config::{FrameChoice, OdeMethod, RunConfig};
use crate::error::{FmError, Result};

/// The provenance file of an imported run.
pub const IMPORT_FILE: &str = "import.json";

/// The `model:` section of an official configuration (the single-source
/// `Matern_FM` model). Unknown keys are refused.
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OfficialModel {
    /// `Matern_FM` (the arbitrary-source types are refused).
    #[serde(rename = "type")]
    pub kind: String,
    /// `PoissonNet`.
    pub model_type: String,
    /// `vertices`.
    #[serde(default = "vertices")]
    pub outputs_at: String,
    /// The noise the flow starts from.
    #[serde(default)]
    pub x0_dist: Option<OfficialX0>,
    /// Signal channels (3: positions).
    pub in_dim: usize,
    /// Unused by the NJF head (it outputs `in_dim` channels); accepted.
    pub out_dim: usize,
    /// Width `W`.
    pub hidden_dim: usize,
    /// Blocks `K`.
    pub num_blocks: usize,
    /// `njf`.
    pub head_type: String,
    /// No effect in the official network; accepted.
    #[serde(default)]
    pub use_source_xyz_grad: Option<bool>,
    /// Not read by the official model; accepted.
    #[serde(default)]
    pub use_extra_features: Option<bool>,
    /// `['v_source', 't']` or `['t']` (either order).
    pub extra_features: Vec<String>,
    /// The block options.
    #[serde(default)]
    pub extra_configs: OfficialExtraConfigs,
}

fn vertices() -> String {
    "vertices".into()
}

/// `model.x0_dist`.
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OfficialX0 {
    /// `poisson_solve`.
    #[serde(rename = "type")]
    pub kind: String,
    /// Factor on the white noise (default 1).
    #[serde(default = "one")]
    pub sigma: f64,
    /// Whether the solve is screened (`L + tau M`).
    #[serde(default)]
    pub screened_solver_for_x0: bool,
    /// `tau` (default 1).
    #[serde(default = "one")]
    pub screening_term: f64,
}

fn one() -> f64 {
    1.0
}

/// `model.extra_configs`.
#[derive(Clone, Debug, PartialEq, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OfficialExtraConfigs {
    /// Training only; ignored.
    #[serde(default)]
    pub dropout_p: Option<f64>,
    /// Training only; ignored.
    #[serde(default)]
    pub drop_path: Option<f64>,
    /// Must be false (mfm has no PoissonNetNorm).
    #[serde(default)]
    pub mlp_norm: Option<bool>,
    /// Must be false.
    #[serde(default)]
    pub inner_prod_features: Option<bool>,
    /// Must be false.
    #[serde(default)]
    pub mass_norm: Option<bool>,
    /// Modulation of the vector MLPs: must be given (the official blocks
    /// default it on and the NJF head off).
    #[serde(default)]
    pub cmlp_modulate: Option<bool>,
    /// Complex layers per vector MLP (default 2).
    #[serde(default)]
    pub cmlp_nlayers: Option<usize>,
    /// Read by no official layer; ignored.
    #[serde(default)]
    pub cmlp_dropout: Option<f64>,
}

/// `ode_solver`.
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OfficialOde {
    /// `midpoint` or `euler`.
    #[serde(default = "midpoint")]
    pub method: String,
    /// `1 / steps`.
    pub step_size: f64,
}

fn midpoint() -> String {
    "midpoint".into()
}

/// What mfm takes from an official configuration file.
#[derive(Clone, Debug, PartialEq)]
pub struct OfficialConfig {
    /// The file.
    pub path: PathBuf,
    /// `model:`.
    pub model: OfficialModel,
    /// `train.center_target_data` (default true).
    pub center: bool,
    /// `ode_solver:` (default: 20 midpoint steps, the paper's).
    pub ode: Option<OfficialOde>,
    /// The keys that change the model's output which the file does not
    /// give, each with the default taken ([`assumed_defaults`]).
    pub assumed: Vec<String>,
}

/// The keys of an official configuration `doc` that change what the
/// imported model generates and that the file leaves out, each with the
/// default mfm (as the official code) takes: "model.x0_dist.screening_term
/// (1; the authors' configurations give 100)". A user told nothing would
/// get a different model than the one they trained.
pub fn assumed_defaults(doc: &serde_norway::Value) -> Vec<String> {
    let mut out = Vec::new();
    let mut say = |key: &str, value: &str| out.push(format!("{key} (taken as {value})"));
    match doc.get("model").and_then(|m| m.get("x0_dist")) {
        None => say("model.x0_dist", "an unscreened Poisson solve of sigma 1"),
        Some(x0) => {
            if x0.get("sigma").is_none() {
                say("model.x0_dist.sigma", "1");
            }
            let screened = x0
                .get("screened_solver_for_x0")
                .and_then(serde_norway::Value::as_bool)
                .unwrap_or(false);
            if screened && x0.get("screening_term").is_none() {
                say(
                    "model.x0_dist.screening_term",
                    "1; the authors' configurations give 100",
                );
            }
        }
    }
    if doc
        .get("train")
        .and_then(|t| t.get("center_target_data"))
        .is_none()
    {
        say("train.center_target_data", "True");
    }
    match doc.get("ode_solver") {
        None => say("ode_solver", "20 midpoint steps"),
        Some(ode) if ode.get("method").is_none() => say("ode_solver.method", "midpoint"),
        Some(_) => {}
    }
    out
}

/// The error for what an official configuration file `path` holds:
/// [`FmError::Files`] naming the file, "official configuration: `message`".
pub fn config_error(path: &Path, message: impl std::fmt::Display) -> FmError {
    FmError::format(path, format!("official configuration: {message}"))
}

impl OfficialConfig {
    /// Reads an official YAML configuration.
    ///
    /// # Errors
    /// [`FmError::Files`] naming the file: unreadable, not YAML, no
    /// `model:` section, an unknown key in `model:` or `ode_solver:`, a
    /// model type other than `Matern_FM`.
    pub fn read(path: impl AsRef<Path>) -> Result<Self> {
        let path = path.as_ref();
        let text = std::fs::read_to_string(path).map_err(|e| FmError::io(path, e))?;
        Self::parse(path, &text)
    }

    /// [`OfficialConfig::read`] of `text` (as from `path`).
    ///
    /// # Errors
    /// As [`OfficialConfig::read`].
    pub fn parse(path: &Path, text: &str) -> Result<Self> {
        let doc: serde_norway::Value = serde_norway::from_str(text)
            .map_err(|e| config_error(path, format!("not YAML: {e}")))?;
        let model = doc
            .get("model")
            .ok_or_else(|| config_error(path, "no `model:` section"))?;
        let kind = model.get("type").and_then(|v| v.as_str()).unwrap_or("");
        match kind {
            "Matern_FM" => {}
            "Matern_FM_arbitrary_source" => {
                return Err(config_error(
                    path,
                    format!(
                        "model.type {kind}: an arbitrary-source model, which this single-source \
                         reader does not take; `mfm import` routes it to the arbitrary-source \
                         importer (mfm_arbitrary::official)"
                    ),
                ));
            }
            "eigenvecs_predictor" => {
                return Err(config_error(
                    path,
                    format!(
                        "model.type {kind}: an eigenvector predictor alone generates nothing; import \
                         the arbitrary-source flow's checkpoint (its configuration has model.type \
                         Matern_FM_arbitrary_source), which holds the predictor, and pass this one \
                         as --predictor-checkpoint to cross-check it"
                    ),
                ));
            }
            other => {
                return Err(config_error(
                    path,
                    format!("model.type {other:?}: expected Matern_FM"),
                ));
            }
        }
        let model: OfficialModel = serde_norway::from_value(model.clone())
            .map_err(|e| config_error(path, format!("model: {e}")))?;
        let center = match doc.get("train").and_then(|t| t.get("center_target_data")) {
            None => true,
            Some(v) => v.as_bool().ok_or_else(|| {
                config_error(path, "train.center_target_data must be True or False")
            })?,
        };
        let ode = match doc.get("ode_solver") {
            None => None,
            Some(v) => Some(
                serde_norway::from_value(v.clone())
                    .map_err(|e| config_error(path, format!("ode_solver: {e}")))?,
            ),
        };
        let cfg = Self {
            path: path.to_path_buf(),
            model,
            center,
            ode,
            assumed: assumed_defaults(&doc),
        };
        cfg.check()?;
        Ok(cfg)
    }

    fn check(&self) -> Result<()> {
        let m = &self.model;
        let fail = |msg: String| Err(config_error(&self.path, msg));
        if m.model_type != "PoissonNet" {
            return fail(format!(
                "model.model_type {:?}: expected PoissonNet",
                m.model_type
            ));
        }
        if m.outputs_at != "vertices" {
            return fail(format!(
                "model.outputs_at {:?}: mfm's networks output at vertices",
                m.outputs_at
            ));
        }
        if m.head_type != "njf" {
            return fail(format!(
                "model.head_type {:?}: the official Matern_FM model runs only the njf head",
                m.head_type
            ));
        }
        if m.in_dim != 3 {
            return fail(format!(
                "model.in_dim {}: the official NJF head outputs 3 channels, so the signals must have 3",
                m.in_dim
            ));
        }
        if m.hidden_dim == 0 || m.num_blocks == 0 {
            return fail("model.hidden_dim and num_blocks must be positive".into());
        }
        check_extra_configs(&self.path, "model.extra_configs", &m.extra_configs)?;
        self.cond_columns()?;
        self.noise()?;
        self.sample_steps()?;
        Ok(())
    }

    /// Whether the network is conditioned on the source xyz, and for each
    /// mfm conditioning column (`x, y, z, t` or `t`) the official one.
    fn cond_columns(&self) -> Result<(bool, Vec<usize>)> {
        let f: Vec<&str> = self
            .model
            .extra_features
            .iter()
            .map(String::as_str)
            .collect();
        Ok(match f.as_slice() {
            ["v_source", "t"] => (true, vec![0, 1, 2, 3]),
            ["t", "v_source"] => (true, vec![1, 2, 3, 0]),
            ["t"] => (false, vec![0]),
            other => {
                return Err(config_error(
                    &self.path,
                    format!(
                        "model.extra_features {other:?}: mfm conditions on ['v_source', 't'] or ['t']"
                    ),
                ));
            }
        })
    }

    /// The network's configuration.
    pub fn net_config(&self) -> PoissonNetConfig {
        let m = &self.model;
        let xyz = matches!(self.cond_columns(), Ok((true, _)));
        PoissonNetConfig {
            width: m.hidden_dim,
            blocks: m.num_blocks,
            vector_layers: m.extra_configs.cmlp_nlayers.unwrap_or(2),
            in_channels: m.in_dim,
            out_channels: m.in_dim,
            cond_channels: if xyz { 4 } else { 1 },
            modulation: m.extra_configs.cmlp_modulate.unwrap_or(true),
            head: HeadKind::Njf,
            global_context: false,
        }
    }

    /// The noise kind and scale.
    fn noise(&self) -> Result<(NoiseKind, f64)> {
        x0_noise(&self.path, self.model.x0_dist.as_ref())
    }

    /// ODE steps and method.
    fn sample_steps(&self) -> Result<(usize, OdeMethod)> {
        ode_steps(&self.path, self.ode.as_ref())
    }

    /// The flow spec of the imported run on the template `mesh`.
    ///
    /// # Errors
    /// As [`OfficialConfig::read`]'s checks.
    pub fn flow_spec(&self, template: &TriMesh) -> Result<FlowSpec> {
        let (noise, noise_scale) = self.noise()?;
        let (xyz, _) = self.cond_columns()?;
        Ok(FlowSpec {
            channels: self.model.in_dim,
            noise,
            noise_scale,
            condition_on_xyz: xyz,
            velocity_offset: vec![0.0; self.model.in_dim],
            frame: CanonicalFrame::identity(),
            positions: true,
            centered: self.center,
            training_surface: Some(SurfaceSize::of(template)),
            prediction: Prediction::Velocity,
            displacements: false,
            prior: None,
        })
    }

    /// The run configuration recorded in the imported run.
    ///
    /// # Errors
    /// As [`OfficialConfig::read`]'s checks.
    pub fn run_config(&self) -> Result<RunConfig> {
        let net = self.net_config();
        let (noise, scale) = self.noise()?;
        let (steps, method) = self.sample_steps()?;
        let mut c = RunConfig::preset("paper")?;
        c.dataset.path = None;
        c.dataset.frame = FrameChoice::AsIs;
        c.dataset.positions = Some(true);
        c.model.width = Some(net.width);
        c.model.blocks = Some(net.blocks);
        c.model.vector_layers = Some(net.vector_layers);
        c.model.head = HeadKind::Njf;
        c.model.modulation = net.modulation;
        c.model.condition_on_xyz = net.cond_channels == 4;
        c.model.mean_offset = false;
        c.model.prediction = Prediction::Velocity;
        c.noise.kind = noise;
        c.noise.scale = crate::config::NoiseScale::Factor(scale);
        c.train.center = self.center;
        c.sample.steps = steps;
        c.sample.method = method;
        Ok(c)
    }
}

/// Checks the block options `e` of an official configuration (`at`: where
/// they are in the file, e.g. `model.extra_configs`): refuses `mlp_norm`,
/// `inner_prod_features` and `mass_norm` set to True (not implemented in
/// mfm), an absent `cmlp_modulate` (the official code's defaults differ
/// between the blocks and the NJF head, which mfm's one switch cannot
/// express) and `cmlp_nlayers: 0`.
///
/// # Errors
/// [`FmError::Files`] naming the file `path` and the option.
pub fn check_extra_configs(path: &Path, at: &str, e: &OfficialExtraConfigs) -> Result<()> {
    for (name, on) in [
        ("mlp_norm", e.mlp_norm),
        ("inner_prod_features", e.inner_prod_features),
        ("mass_norm", e.mass_norm),
    ] {
        if on == Some(true) {
            return Err(config_error(
                path,
                format!("{at}.{name}: True is not implemented in mfm (only False)"),
            ));
        }
    }
    if e.cmlp_modulate.is_none() {
        return Err(config_error(
            path,
            format!(
                "{at}.cmlp_modulate must be given: the official code defaults it to True \
                 in the blocks and False in the NJF head, which mfm's one switch cannot express"
            ),
        ));
    }
    if e.cmlp_nlayers == Some(0) {
        return Err(config_error(
            path,
            format!("{at}.cmlp_nlayers must be at least 1"),
        ));
    }
    Ok(())
}

/// The noise kind and scale of an official `model.x0_dist` (`None`: the
/// official default, an unscreened solve of sigma 1): a screened solve
/// with `screening_term` tau maps to `matern:tau`, an unscreened one to
/// `matern:0`; the scale is `sigma`.
///
/// # Errors
/// [`FmError::Files`] naming the file `path` and the option: another
/// `type` than `poisson_solve`, a `sigma` that is not positive, a negative
/// or non-finite `screening_term`.
pub fn x0_noise(path: &Path, x0: Option<&OfficialX0>) -> Result<(NoiseKind, f64)> {
    let x0 = x0.cloned().unwrap_or(OfficialX0 {
        kind: "poisson_solve".into(),
        sigma: 1.0,
        screened_solver_for_x0: false,
        screening_term: 1.0,
    });
    if x0.kind != "poisson_solve" {
        return Err(config_error(
            path,
            format!("model.x0_dist.type {:?}: expected poisson_solve", x0.kind),
        ));
    }
    if !(x0.sigma.is_finite() && x0.sigma > 0.0) {
        return Err(config_error(
            path,
            format!("model.x0_dist.sigma {}: must be positive", x0.sigma),
        ));
    }
    let tau = if x0.screened_solver_for_x0 {
        x0.screening_term
    } else {
        0.0
    };
    if !(tau.is_finite() && tau >= 0.0) {
        return Err(config_error(
            path,
            format!("model.x0_dist.screening_term {tau}: must be >= 0"),
        ));
    }
    Ok((NoiseKind::Matern { tau }, x0.sigma))
}

/// The most ODE steps an imported configuration may ask for.
pub const MAX_ODE_STEPS: usize = 10_000;

/// The steps and method of an official `ode_solver` section (`None`: 20
/// midpoint steps, the paper's); `step_size` must be `1 / n` for a whole
/// `n`.
///
/// # Errors
/// [`FmError::Files`] naming the file `path` and the option: a method
/// other than `midpoint` or `euler`, a step size that is not `1 / n`.
pub fn ode_steps(path: &Path, ode: Option<&OfficialOde>) -> Result<(usize, OdeMethod)> {
    let Some(ode) = ode else {
        return Ok((20, OdeMethod::Midpoint));
    };
    let method = match ode.method.as_str() {
        "midpoint" => OdeMethod::Midpoint,
        "euler" => OdeMethod::Euler,
        other => {
            return Err(config_error(
                path,
                format!("ode_solver.method {other:?}: mfm integrates with midpoint or euler"),
            ));
        }
    };
    let steps = 1.0 / ode.step_size;
    let rounded = steps.round();
    if rounded > MAX_ODE_STEPS as f64 {
        return Err(config_error(
            path,
            format!(
                "ode_solver.step_size {}: {rounded} steps per sample; at most {MAX_ODE_STEPS} are \
                 taken (the paper integrates with 20)",
                ode.step_size
            ),
        ));
    }
    if !(ode.step_size > 0.0 && rounded >= 1.0 && (steps - rounded).abs() < 1e-6 * rounded) {
        return Err(config_error(
            path,
            format!(
                "ode_solver.step_size {}: must be 1 / (a whole number of steps)",
                ode.step_size
            ),
        ));
    }
    Ok((rounded as usize, method))
}

/// `import.json` of an imported run: where it came from.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ImportRecord {
    /// The checkpoint file, as given.
    pub checkpoint: PathBuf,
    /// Its size and CRC-32.
    pub checkpoint_record: checkpoint::FileRecord,
    /// The YAML configuration, as given.
    pub config: PathBuf,
    /// The template mesh, as given.
    pub template: PathBuf,
    /// `global_step` of a Lightning checkpoint.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub global_step: Option<i64>,
    /// Parameters imported.
    pub parameters: usize,
    /// Top-level entries of the checkpoint that were not read (a
    /// Lightning checkpoint's optimizer and loop states...).
    pub ignored_entries: Vec<String>,
    /// Keys the configuration leaves out, with the defaults taken
    /// ([`assumed_defaults`]).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub assumed: Vec<String>,
}

/// The tensors of an official checkpoint file, read without Python: the
/// `state_dict` of a Lightning checkpoint, or the whole file when it is a
/// state dict itself, with the Lightning entries that were not read.
#[derive(Clone, Debug)]
pub struct OfficialCheckpoint {
    path: PathBuf,
    entries: Vec<(String, TensorData)>,
    lightning: bool,
    ignored_entries: Vec<String>,
    global_step: Option<i64>,
}

impl OfficialCheckpoint {
    /// Reads the checkpoint at `path` (only tensors and plain containers;
    /// a file holding other pickled objects is refused).
    ///
    /// # Errors
    /// [`FmError::Files`] naming the file: unreadable, not a `torch.save`
    /// archive, objects other than tensors and containers, no state dict.
    pub fn open(path: &Path) -> Result<Self> {
        let fail = |e: mfm_torchfile::TorchFileError| FmError::format(path, e.without_path());
        let mut ckpt = Checkpoint::open(path).map_err(fail)?;
        let root = ckpt.root().clone();
        let global_step = match root.get("global_step") {
            Some(Value::Int(s)) => Some(*s),
            _ => None,
        };
        let lightning = root.get("state_dict").is_some();
        let ignored_entries = match (&root, lightning) {
            (Value::Dict(items), true) => items
                .iter()
                .filter_map(|(k, _)| match k {
                    Value::Str(s) if s != "state_dict" => Some(s.clone()),
                    _ => None,
                })
                .collect(),
            _ => Vec::new(),
        };
        let entry = if lightning { "state_dict" } else { "" };
        let entries = ckpt.state_dict(entry).map_err(fail)?;
        Ok(Self {
            path: path.to_path_buf(),
            entries,
            lightning,
            ignored_entries,
            global_step,
        })
    }

    /// The file.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Every tensor's name, in the file's order.
    pub fn names(&self) -> impl Iterator<Item = &str> {
        self.entries.iter().map(|(n, _)| n.as_str())
    }

    /// `global_step` of a Lightning checkpoint.
    pub fn global_step(&self) -> Option<i64> {
        self.global_step
    }

    /// The top-level entries of a Lightning checkpoint other than its
    /// `state_dict` (optimizer and loop states...), which are not read.
    pub fn ignored_entries(&self) -> &[String] {
        &self.ignored_entries
    }

    /// The tensors whose names start with `prefix` (names kept whole), as
    /// `f32`.
    ///
    /// # Errors
    /// [`FmError::Files`] naming the file and the tensor for one that is
    /// not floating point.
    pub fn tensors(&self, prefix: &str) -> Result<HashMap<String, OfficialTensor>> {
        let mut out = HashMap::new();
        for (name, t) in self.entries.iter().filter(|(n, _)| n.starts_with(prefix)) {
            let values = t.to_f32().ok_or_else(|| {
                FmError::format(
                    &self.path,
                    format!(
                        "entry {}{name} is a {} tensor, not floating point",
                        if self.lightning { "state_dict." } else { "" },
                        t.dtype
                    ),
                )
            })?;
            out.insert(
                name.clone(),
                OfficialTensor {
                    shape: t.shape.clone(),
                    values,
                },
            );
        }
        Ok(out)
    }
}

/// Refuses official weights `tensors` of the file `source` holding a
/// non-finite value, naming the parameter.
///
/// # Errors
/// [`FmError::Diverged`] naming the file and the parameter.
pub fn check_finite(tensors: &HashMap<String, OfficialTensor>, source: &Path) -> Result<()> {
    let mut names: Vec<&String> = tensors.keys().collect();
    names.sort();
    for name in names {
        if let Some(bad) = tensors[name].values.iter().find(|v| !v.is_finite()) {
            return Err(FmError::Diverged(format!(
                "{}: parameter {name} holds {bad}: the checkpoint's weights are not finite",
                source.display()
            )));
        }
    }
    Ok(())
}

/// Imports the official checkpoint `checkpoint` with its YAML `config`
/// and the template mesh (`template`, read from `template_path`) into the
/// run folder `out` (missing or empty; removed again if anything fails).
///
/// # Errors
/// [`FmError::Files`] naming the checkpoint or configuration for what they
/// hold that mfm refuses (objects in the checkpoint, options mfm does not
/// implement, non-float weights); [`FmError::Net`]
/// ([`mfm_net::NetError::WeightsMismatch`]) naming a missing, extra or
/// mis-shaped parameter; [`FmError::Diverged`] for non-finite weights; the
/// output folder's errors.
pub fn import_official(
    checkpoint_path: &Path,
    config_path: &Path,
    template: &TriMesh,
    template_path: &Path,
    out: &Path,
) -> Result<ImportRecord> {
    let config = OfficialConfig::read(config_path)?;
    let flow = config.flow_spec(template)?;
    let run_config = config.run_config()?;
    let ckpt = OfficialCheckpoint::open(checkpoint_path)?;
    let prefix = if ckpt.names().any(|n| n.starts_with(OFFICIAL_PREFIX)) {
        OFFICIAL_PREFIX
    } else {
        ""
    };
    let tensors = ckpt.tensors(prefix)?;
    let net_config = config.net_config();
    let mut net = PoissonNet::new(&net_config, tch::Device::Cpu)?;
    let (_, columns) = config.cond_columns()?;
    load_official(&mut net, &tensors, prefix, &columns, checkpoint_path)?;
    check_finite(&tensors, checkpoint_path)?;
    let record = ImportRecord {
        checkpoint: checkpoint_path.to_path_buf(),
        checkpoint_record: checkpoint::file_record(checkpoint_path)?,
        config: config_path.to_path_buf(),
        template: template_path.to_path_buf(),
        global_step: ckpt.global_step(),
        parameters: net.num_parameters(),
        ignored_entries: ckpt.ignored_entries().to_vec(),
        assumed: config.assumed.clone(),
    };
    let undo = mfm_files::Undo::empty_folder(out)?;
    net.save(out.join(WEIGHTS_FILE))?;
    checkpoint::write_final_record(out)?;
    flow.write(out.join(FLOW_FILE))?;
    run_config.write_toml_file(out.join(CONFIG_FILE))?;
    mfm_files::write_json(out.join(IMPORT_FILE), &record)?;
    undo.keep();
    Ok(record)
}

/// Writes the final model of the run `run` under the official names as a
/// Lightning-style `{"state_dict": OrderedDict(base_model.* -> tensor)}`
/// checkpoint at `out` (atomically); returns the number of tensors.
///
/// # Errors
/// The final model's integrity check ([`checkpoint::verify_final_model`]);
/// [`FmError::Config`] for a run with a linear head, conditioning, a
/// global context or a data prior the official model does not have; the
/// file's errors.
pub fn export_official(run: &Path, out: &Path) -> Result<usize> {
    checkpoint::verify_final_model(run)?;
    let flow = FlowSpec::read(run.join(FLOW_FILE))?;
    if flow.prior.is_some() {
        return Err(FmError::Config(format!(
            "{}: this run starts from a data prior (noise.prior); the official Matern_FM model starts from noise alone",
            run.display()
        )));
    }
    if flow.displacements {
        return Err(FmError::Config(format!(
            "{}: this run generates displacements of the sampled mesh (model.displacements); the official Matern_FM model generates positions",
            run.display()
        )));
    }
    let net = PoissonNet::load(run.join(WEIGHTS_FILE), tch::Device::Cpu)?;
    let cfg = net.config();
    if cfg.global_context {
        return Err(FmError::Config(format!(
            "{}: this run's blocks read a global context (model.global_context); the official Matern_FM model has no such layer",
            run.display()
        )));
    }
    if cfg.head != HeadKind::Njf || cfg.in_channels != 3 {
        return Err(FmError::Config(format!(
            "{}: the official Matern_FM model has the njf head on 3-channel signals; this run has the {:?} head on {} channels",
            run.display(),
            cfg.head,
            cfg.in_channels
        )));
    }
    let sd = official_state_dict(&net, OFFICIAL_PREFIX)?;
    let tensors: Vec<(String, TensorData)> = sd
        .into_iter()
        .map(|(n, t)| (n, TensorData::from_f32(t.shape, &t.values)))
        .collect();
    let bytes = mfm_torchfile::state_dict_archive(&tensors, Some("state_dict"))
        .map_err(|e| FmError::format(out, e))?;
    checkpoint::write_atomic(out, &bytes)?;
    Ok(tensors.len())
}

/// The files an imported run holds (for the docs and the tests).
pub const IMPORTED_FILES: [&str; 6] = [
    CONFIG_FILE,
    FLOW_FILE,
    WEIGHTS_FILE,
    NET_CONFIG_FILE,
    FINAL_RECORD_FILE,
    IMPORT_FILE,
];

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    const BUNNY: &str = "
group: g
model:
  type: Matern_FM
  model_type: PoissonNet
  outputs_at: vertices
  x0_dist:
    type: 'poisson_solve'
    sigma: 3.0
    screened_solver_for_x0: True
    screening_term: 100.0
  in_dim: 3
  out_dim: 6
  hidden_dim: 128
  num_blocks: 5
  head_type: njf
  use_source_xyz_grad: True
  use_extra_features: True
  extra_features: ['v_source', 't']
  extra_configs:
    dropout_p: 0.0
    drop_path: 0.0
    mlp_norm: False
    inner_prod_features: False
    cmlp_modulate: True
    cmlp_nlayers: 3
    cmlp_dropout: 0.0
train:
  lr: 0.0005
  center_target_data: True
ode_solver:
  method: 'midpoint'
  step_size: 0.05
";

    fn parse(text: &str) -> Result<OfficialConfig> {
        OfficialConfig::parse(Path::new("cfg.yaml"), text)
    }

    #[test]
    fn the_official_bunny_configuration_is_the_paper_network() {
        let c = parse(BUNNY).unwrap();
        let net = c.net_config();
        assert_eq!(net, PoissonNetConfig::paper());
        let r = c.run_config().unwrap();
        assert_eq!((r.sample.steps, r.sample.method), (20, OdeMethod::Midpoint));
        assert_eq!(r.noise.kind, NoiseKind::Matern { tau: 100.0 });
        assert!(r.train.center && !r.model.mean_offset && r.model.condition_on_xyz);
        let mesh = mfm_geometry::procedural::icosphere(1);
        let f = c.flow_spec(&mesh).unwrap();
        assert_eq!(f.noise_scale, 3.0);
        assert!(f.frame.is_identity() && f.positions && f.centered);
    }

    #[test]
    fn keys_left_out_are_named_with_the_defaults_taken() {
        assert!(parse(BUNNY).unwrap().assumed.is_empty());
        let sparse = BUNNY
            .replace("    screening_term: 100.0\n", "")
            .replace("    sigma: 3.0\n", "")
            .replace("  center_target_data: True\n", "")
            .replace("ode_solver:\n  method: 'midpoint'\n  step_size: 0.05\n", "");
        let c = parse(&sparse).unwrap();
        let keys: Vec<&str> = c
            .assumed
            .iter()
            .map(|a| a.split(' ').next().unwrap())
            .collect();
        assert_eq!(
            keys,
            [
                "model.x0_dist.sigma",
                "model.x0_dist.screening_term",
                "train.center_target_data",
                "ode_solver"
            ]
        );
        assert!(c.assumed[1].contains("taken as 1") && c.assumed[1].contains("100"));
        // a step size that asks for 10^12 steps is refused, not run
        let e = parse(&BUNNY.replace("step_size: 0.05", "step_size: 1.0e-12"))
            .and_then(|c| c.run_config())
            .unwrap_err()
            .to_string();
        assert!(e.contains("at most 10000"), "{e}");
    }

    #[test]
    fn options_mfm_does_not_implement_are_refused_by_name() {
        for (from, to, named) in [
            ("mlp_norm: False", "mlp_norm: True", "mlp_norm"),
            (
                "inner_prod_features: False",
                "inner_prod_features: True",
                "inner_prod_features",
            ),
            ("head_type: njf", "head_type: linear", "head_type"),
            ("outputs_at: vertices", "outputs_at: faces", "outputs_at"),
            ("['v_source', 't']", "['v_source']", "extra_features"),
            (
                "method: 'midpoint'",
                "method: 'dopri5'",
                "ode_solver.method",
            ),
            ("step_size: 0.05", "step_size: 0.03", "step_size"),
            ("    cmlp_modulate: True\n", "", "cmlp_modulate"),
            ("  in_dim: 3", "  in_dim: 1", "in_dim"),
            (
                "  head_type: njf",
                "  head_type: njf\n  dropout: 0.1",
                "dropout",
            ),
            (
                "type: Matern_FM\n",
                "type: Matern_FM_arbitrary_source\n",
                "arbitrary-source",
            ),
            (
                "    cmlp_dropout: 0.0",
                "    cmlp_dropout: 0.0\n    layer_scale: 2",
                "layer_scale",
            ),
        ] {
            assert!(BUNNY.contains(from), "{from}");
            let e = parse(&BUNNY.replacen(from, to, 1)).unwrap_err().to_string();
            assert!(e.contains(named) && e.contains("cfg.yaml"), "{to}: {e}");
        }
        let e = parse("model: [").unwrap_err().to_string();
        assert!(e.contains("not YAML"), "{e}");
        let e = parse("train: {}").unwrap_err().to_string();
        assert!(e.contains("no `model:`"), "{e}");
    }

    #[test]
    fn conditioning_order_and_the_unscreened_noise_map() {
        let c = parse(
            &BUNNY
                .replace("['v_source', 't']", "['t', 'v_source']")
                .replace(
                    "screened_solver_for_x0: True",
                    "screened_solver_for_x0: False",
                ),
        )
        .unwrap();
        assert_eq!(c.cond_columns().unwrap(), (true, vec![1, 2, 3, 0]));
        assert_eq!(c.noise().unwrap(), (NoiseKind::Matern { tau: 0.0 }, 3.0));
        let t = parse(&BUNNY.replace("['v_source', 't']", "['t']")).unwrap();
        assert_eq!(t.net_config().cond_channels, 1);
    }
}
