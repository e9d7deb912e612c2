//! The authors' pretrained arbitrary-source model as an mfm arbitrary-source
//! run.
//!
//! The official Matérn-FM code trains the arbitrary-source flow
//! (`model.type: Matern_FM_arbitrary_source`, e.g.
//! `configs/moyo_arbitrary_source.yaml`) with a frozen eigenvector predictor
//! inside it, and saves both in one PyTorch Lightning checkpoint: the flow's
//! PoissonNet under `base_model.*`, the predictor's under
//! `eigenvecs_predictor.*`. [`import_official_arbitrary`] reads the
//! checkpoint and its YAML configuration without Python and writes an
//! ordinary arbitrary-source run folder ([`crate::markers::ARBITRARY_SPEC`],
//! `model.safetensors` + `model.json` + `model.state.json`, the predictor's
//! `predictor.safetensors` + `predictor.json` + `predictor.spec.json` +
//! `predictor.state.json`, and [`IMPORT_FILE`] saying where it came from)
//! that `mfm sample --run RUN --source MESH` uses as it uses a trained one.
//! The predictor's own checkpoint (the official `Eigenvec_Predictor`
//! module's, `base_model.*`) may be given as well: it must hold the same
//! tensors as the flow checkpoint's copy.
//!
//! ## What the configuration maps to
//! | official (YAML) | mfm |
//! |---|---|
//! | `model.hidden_dim`, `num_blocks` | [`FlowConfig`] `width`, `blocks` |
//! | `model.extra_features: ['v_source', 't']` + the predictor's `out_dim` `k` | conditioning `[xyz, t, k eigenvectors]` (`['t', 'v_source']` is reordered) |
//! | `model.x0_dist`: `sigma`, `screening_term` | `sigma`, noise `matern:<screening_term>` |
//! | `ode_solver.step_size` (midpoint) | `ode_steps = 1 / step_size` |
//! | `model.eigenvecs_predictor`: `out_dim`, `hidden_dim`, `num_blocks` | [`PredictorConfig`] `eigenvectors`, `width`, `blocks` |
//! | `train:` (lr, iterations, batch, milestones, gamma, clipping), `dataset.use_data_augmentation`, `manual_seed` | the flow's [`Schedule`], a record only |
//!
//! The official model takes meshes as they are (the MOYO/SMPL-X bodies in
//! metres) and its targets are mass-mean zero, so the run's frame is
//! [`SourceFrame::AsIs`]: sample it on sources in the units and place of
//! the official data. mfm's arbitrary-source networks have three complex
//! layers per vector MLP and modulation on, as the official configurations;
//! everything else is refused naming the option: `use_predicted_eigenvecs:
//! False`, another `cmlp_nlayers` or `cmlp_modulate: False`, `mlp_norm`,
//! `inner_prod_features`, `mass_norm`, other heads, extra features or
//! `outputs_at`, the euler ODE (mfm's arbitrary-source sampler integrates
//! with the midpoint rule), `center_target_data: False`. Missing, extra
//! and mis-shaped tensors are refused naming the tensor, and nothing is
//! written when anything fails.
//!
//! An imported run has no training state: `mfm train --resume` refuses it,
//! and `mfm eval-arbitrary` does not measure its predictor against mfm's
//! eigenbasis ([`crate::evaluate::predictor_error_skipped`]).

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use crate::error::{ArbitraryError, Result};
use mfm_fm::config::OdeMethod;
use mfm_fm::official::{
    OfficialCheckpoint, OfficialExtraConfigs, OfficialOde, OfficialX0, check_extra_configs,
    check_finite, ode_steps, x0_noise,
};
use mfm_geometry::TriMesh;
use mfm_geometry::frame::SurfaceSize;
use mfm_net::PoissonNet;
use mfm_net::official::{OFFICIAL_PREFIX, OfficialTensor, load_official};
use mfm_train::checkpoint::{self, FileRecord, WEIGHTS_FILE};
use serde::{Deserialize, Serialize};

use crate::flow::{
    ArbitrarySpec, FlowConfig, PREDICTOR_COPY_SPEC, PREDICTOR_NET_CONFIG, PREDICTOR_RECORD,
    PREDICTOR_WEIGHTS,
};
use crate::markers::ARBITRARY_SPEC;
use crate::predictor::{PredictorConfig, PredictorSpec};
use crate::{Schedule, SourceFrame};

pub use mfm_fm::official::IMPORT_FILE;

/// The official model type this module imports.
pub const ARBITRARY_MODEL_TYPE: &str = "Matern_FM_arbitrary_source";

/// The prefix of the frozen eigenvector predictor's parameters in the
/// official arbitrary-source checkpoint (the flow's are under
/// [`OFFICIAL_PREFIX`]).
pub const PREDICTOR_PREFIX: &str = "eigenvecs_predictor.";

/// Complex layers per vector MLP in mfm's arbitrary-source networks
/// ([`FlowConfig::net_config`], [`PredictorConfig::net_config`]): the
/// official configurations' `cmlp_nlayers`.
pub const VECTOR_LAYERS: usize = 3;

fn vertices() -> String {
    "vertices".into()
}

/// `model:` of an official arbitrary-source configuration. Unknown keys
/// are refused.
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OfficialArbitraryModel {
    /// [`ARBITRARY_MODEL_TYPE`].
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
    /// Signal channels: 3 (positions).
    pub in_dim: usize,
    /// Unused by the NJF head (it outputs 3 channels); accepted.
    pub out_dim: usize,
    /// Width.
    pub hidden_dim: usize,
    /// Blocks.
    pub num_blocks: usize,
    /// `njf`.
    pub head_type: String,
    /// No effect in the official network; accepted.
    #[serde(default)]
    pub use_source_xyz_grad: Option<bool>,
    /// Not read by the official model; accepted.
    #[serde(default)]
    pub use_extra_features: Option<bool>,
    /// `['v_source', 't']` or `['t', 'v_source']`.
    pub extra_features: Vec<String>,
    /// Must be True (the official default).
    #[serde(default)]
    pub use_predicted_eigenvecs: Option<bool>,
    /// The flow's block options.
    #[serde(default)]
    pub extra_configs: OfficialExtraConfigs,
    /// The frozen predictor.
    pub eigenvecs_predictor: OfficialPredictorModel,
}

/// `model.eigenvecs_predictor` of an official arbitrary-source
/// configuration. Unknown keys are refused.
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OfficialPredictorModel {
    /// Where the official code loads the predictor from; recorded only
    /// (the weights are read from the flow's checkpoint).
    #[serde(default)]
    pub checkpoint_path: Option<String>,
    /// 3 (source positions).
    pub in_dim: usize,
    /// `k`, the eigenvectors predicted.
    pub out_dim: usize,
    /// Width.
    pub hidden_dim: usize,
    /// Blocks.
    pub num_blocks: usize,
    /// `linear`.
    pub head_type: String,
    /// `vertices`.
    #[serde(default = "vertices")]
    pub outputs_at: String,
    /// The predictor's block options.
    #[serde(default)]
    pub extra_configs: OfficialExtraConfigs,
}

/// What mfm takes from an official arbitrary-source configuration file.
#[derive(Clone, Debug, PartialEq)]
pub struct OfficialArbitraryConfig {
    /// The file.
    pub path: PathBuf,
    /// `model:`.
    pub model: OfficialArbitraryModel,
    /// `ode_solver:` (default: 20 midpoint steps).
    pub ode: Option<OfficialOde>,
    /// The flow's training schedule as far as the file states it (the
    /// rest from [`FlowConfig::paper`]); a record, not used to sample.
    pub schedule: Schedule,
    /// The keys that change the model's output which the file does not
    /// give, with the defaults taken ([`mfm_fm::official::assumed_defaults`]).
    pub assumed: Vec<String>,
}

impl OfficialArbitraryConfig {
    /// Reads an official arbitrary-source YAML configuration.
    ///
    /// # Errors
    /// [`mfm_fm::FmError::Files`] naming the file and the option: unreadable, not
    /// YAML, another model type, an unknown key in `model:`,
    /// `model.eigenvecs_predictor:` or `ode_solver:`, or an option mfm does
    /// not implement (see the [module docs](self)).
    pub fn read(path: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(path).map_err(|e| ArbitraryError::io(path, e))?;
        Self::parse(path, &text)
    }

    /// [`OfficialArbitraryConfig::read`] of `text` (as from `path`).
    ///
    /// # Errors
    /// As [`OfficialArbitraryConfig::read`].
    pub fn parse(path: &Path, text: &str) -> Result<Self> {
        let doc: serde_norway::Value = serde_norway::from_str(text)
            .map_err(|e| config_error(path, format!("not YAML: {e}")))?;
        let model = doc
            .get("model")
            .ok_or_else(|| config_error(path, "no `model:` section"))?;
        let kind = model.get("type").and_then(|v| v.as_str()).unwrap_or("");
        if kind != ARBITRARY_MODEL_TYPE {
            return Err(config_error(
                path,
                format!("model.type {kind:?}: expected {ARBITRARY_MODEL_TYPE}"),
            ));
        }
        let model: OfficialArbitraryModel = serde_norway::from_value(model.clone())
            .map_err(|e| config_error(path, format!("model: {e}")))?;
        match doc.get("train").and_then(|t| t.get("center_target_data")) {
            None => {}
            Some(v) => match v.as_bool() {
                Some(true) => {}
                Some(false) => {
                    return Err(config_error(
                        path,
                        "train.center_target_data: False is not implemented in mfm's \
                         arbitrary-source flow (its targets are centred; only True)",
                    ));
                }
                None => {
                    return Err(config_error(
                        path,
                        "train.center_target_data must be True or False",
                    ));
                }
            },
        }
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
            ode,
            schedule: schedule_of(&doc),
            assumed: mfm_fm::official::assumed_defaults(&doc),
        };
        cfg.check()?;
        Ok(cfg)
    }

    fn check(&self) -> Result<()> {
        let m = &self.model;
        let p = &m.eigenvecs_predictor;
        let fail = |msg: String| Err(config_error(&self.path, msg));
        if m.model_type != "PoissonNet" {
            return fail(format!(
                "model.model_type {:?}: expected PoissonNet",
                m.model_type
            ));
        }
        if m.use_predicted_eigenvecs == Some(false) {
            return fail(
                "model.use_predicted_eigenvecs: False is not implemented in mfm (its \
                 arbitrary-source flow is conditioned on the predicted eigenvectors; only True)"
                    .into(),
            );
        }
        for (at, outputs) in [
            ("model.outputs_at", &m.outputs_at),
            ("model.eigenvecs_predictor.outputs_at", &p.outputs_at),
        ] {
            if outputs != "vertices" {
                return fail(format!(
                    "{at} {outputs:?}: mfm's networks output at vertices"
                ));
            }
        }
        if m.head_type != "njf" {
            return fail(format!(
                "model.head_type {:?}: the arbitrary-source flow runs the njf head",
                m.head_type
            ));
        }
        if p.head_type != "linear" {
            return fail(format!(
                "model.eigenvecs_predictor.head_type {:?}: the eigenvector predictor runs the \
                 linear head",
                p.head_type
            ));
        }
        for (at, dim) in [
            ("model.in_dim", m.in_dim),
            ("model.eigenvecs_predictor.in_dim", p.in_dim),
        ] {
            if dim != 3 {
                return fail(format!(
                    "{at} {dim}: the arbitrary-source networks read vertex positions (3 channels)"
                ));
            }
        }
        for (at, n) in [
            ("model.hidden_dim", m.hidden_dim),
            ("model.num_blocks", m.num_blocks),
            ("model.eigenvecs_predictor.hidden_dim", p.hidden_dim),
            ("model.eigenvecs_predictor.num_blocks", p.num_blocks),
            ("model.eigenvecs_predictor.out_dim", p.out_dim),
        ] {
            if n == 0 {
                return fail(format!("{at} must be positive"));
            }
        }
        check_extra_configs(&self.path, "model.extra_configs", &m.extra_configs)?;
        // the predictor has no NJF head: an absent switch is the blocks' default, True
        let mut pe = p.extra_configs.clone();
        pe.cmlp_modulate.get_or_insert(true);
        let at_p = "model.eigenvecs_predictor.extra_configs";
        check_extra_configs(&self.path, at_p, &pe)?;
        for (at, e) in [("model.extra_configs", &m.extra_configs), (at_p, &pe)] {
            if e.cmlp_modulate == Some(false) {
                return fail(format!(
                    "{at}.cmlp_modulate: False is not implemented in mfm's arbitrary-source \
                     networks (only True)"
                ));
            }
            // the official blocks' default is 2 layers
            let layers = e.cmlp_nlayers.unwrap_or(2);
            if layers != VECTOR_LAYERS {
                return fail(format!(
                    "{at}.cmlp_nlayers {layers}: mfm's arbitrary-source networks have \
                     {VECTOR_LAYERS} complex layers per vector MLP (the official configurations')"
                ));
            }
        }
        self.cond_columns()?;
        x0_noise(&self.path, m.x0_dist.as_ref())?;
        self.ode_steps()?;
        Ok(())
    }

    /// For each mfm conditioning column (`x, y, z, t, e_1..e_k`) the
    /// official one.
    fn cond_columns(&self) -> Result<Vec<usize>> {
        let k = self.model.eigenvecs_predictor.out_dim;
        let f: Vec<&str> = self
            .model
            .extra_features
            .iter()
            .map(String::as_str)
            .collect();
        let head: Vec<usize> = match f.as_slice() {
            ["v_source", "t"] => vec![0, 1, 2, 3],
            ["t", "v_source"] => vec![1, 2, 3, 0],
            other => {
                return Err(config_error(
                    &self.path,
                    format!(
                        "model.extra_features {other:?}: mfm's arbitrary-source flow conditions \
                         on ['v_source', 't'] (and the predicted eigenvectors)"
                    ),
                ));
            }
        };
        Ok(head.into_iter().chain(4..4 + k).collect())
    }

    /// The number of midpoint steps.
    fn ode_steps(&self) -> Result<usize> {
        let (steps, method) = ode_steps(&self.path, self.ode.as_ref())?;
        if method != OdeMethod::Midpoint {
            return Err(config_error(
                &self.path,
                "ode_solver.method 'euler': mfm's arbitrary-source sampler integrates with the \
                 midpoint rule only",
            ));
        }
        Ok(steps)
    }

    /// The flow's configuration in mfm ([`SourceFrame::AsIs`]).
    ///
    /// # Errors
    /// As [`OfficialArbitraryConfig::read`]'s checks.
    pub fn flow_config(&self) -> Result<FlowConfig> {
        let (noise, sigma) = x0_noise(&self.path, self.model.x0_dist.as_ref())?;
        Ok(FlowConfig {
            width: self.model.hidden_dim,
            blocks: self.model.num_blocks,
            noise,
            sigma,
            ode_steps: self.ode_steps()?,
            eigenvectors: true,
            schedule: self.schedule.clone(),
            frame: SourceFrame::AsIs,
        })
    }

    /// The predictor's configuration in mfm ([`SourceFrame::AsIs`]; the
    /// schedule of [`PredictorConfig::paper`], which the flow's file does
    /// not state).
    pub fn predictor_config(&self) -> PredictorConfig {
        let p = &self.model.eigenvecs_predictor;
        PredictorConfig {
            eigenvectors: p.out_dim,
            width: p.hidden_dim,
            blocks: p.num_blocks,
            schedule: PredictorConfig::paper().schedule,
            frame: SourceFrame::AsIs,
        }
    }
}

/// The flow's schedule as the official `train:` section (and
/// `dataset.use_data_augmentation`, `manual_seed`) states it; what is
/// absent or not a number is [`FlowConfig::paper`]'s.
fn schedule_of(doc: &serde_norway::Value) -> Schedule {
    let mut s = FlowConfig::paper().schedule;
    let at = |path: &[&str]| -> Option<&serde_norway::Value> {
        path.iter().try_fold(doc, |v, k| v.get(*k))
    };
    let number = |path: &[&str]| at(path).and_then(serde_norway::Value::as_f64);
    let whole = |path: &[&str]| at(path).and_then(serde_norway::Value::as_u64);
    if let Some(v) = number(&["train", "lr"]) {
        s.lr = v;
    }
    if let Some(v) = whole(&["train", "iterations"]) {
        s.steps = v;
    }
    if let Some(v) = whole(&["train", "batch_size"]) {
        s.batch = v as usize;
    }
    if let Some(v) = at(&["train", "lr_scheduler", "milestones"]).and_then(|m| {
        m.as_sequence()
            .and_then(|q| q.iter().map(serde_norway::Value::as_u64).collect())
    }) {
        s.milestones = v;
    }
    if let Some(v) = number(&["train", "lr_scheduler", "gamma"]) {
        s.gamma = v;
    }
    if let Some(v) = number(&["train", "gradient_clipping", "max_norm"]) {
        s.grad_clip = v;
    }
    if let Some(v) = whole(&["train", "save_every_n_steps"]) {
        s.checkpoint_every = v;
    }
    if let Some(v) = at(&["dataset", "use_data_augmentation"]).and_then(|v| v.as_bool()) {
        s.augment = v;
    }
    if let Some(v) = whole(&["manual_seed"]) {
        s.seed = v;
    }
    s
}

/// [`IMPORT_FILE`] of an imported arbitrary-source run: where it came from.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ArbitraryImportRecord {
    /// The official model type, [`ARBITRARY_MODEL_TYPE`].
    pub model_type: String,
    /// The flow checkpoint, as given.
    pub checkpoint: PathBuf,
    /// Its size and CRC-32.
    pub checkpoint_record: FileRecord,
    /// The YAML configuration, as given.
    pub config: PathBuf,
    /// The predictor's own checkpoint, as given, when it was cross-checked.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub predictor_checkpoint: Option<PathBuf>,
    /// Its size and CRC-32.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub predictor_checkpoint_record: Option<FileRecord>,
    /// The template mesh, as given, when one was.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub template: Option<PathBuf>,
    /// `global_step` of the Lightning checkpoint.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub global_step: Option<i64>,
    /// The flow's parameters.
    pub flow_parameters: usize,
    /// The predictor's parameters.
    pub predictor_parameters: usize,
    /// Top-level entries of the checkpoint that were not read (Lightning's
    /// optimizer and loop states...).
    pub ignored_entries: Vec<String>,
    /// Keys the configuration leaves out, with the defaults taken.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub assumed: Vec<String>,
}

/// The files an imported arbitrary-source run holds.
pub const IMPORTED_FILES: [&str; 9] = [
    ARBITRARY_SPEC,
    WEIGHTS_FILE,
    checkpoint::NET_CONFIG_FILE,
    checkpoint::FINAL_RECORD_FILE,
    PREDICTOR_WEIGHTS,
    PREDICTOR_NET_CONFIG,
    PREDICTOR_COPY_SPEC,
    PREDICTOR_RECORD,
    IMPORT_FILE,
];

/// Strips `prefix` from the names of `tensors`.
fn unprefixed(tensors: &HashMap<String, OfficialTensor>, prefix: &str) -> Vec<(String, usize)> {
    let mut v: Vec<(String, usize)> = tensors
        .iter()
        .filter_map(|(n, t)| Some((n.strip_prefix(prefix)?.to_owned(), t.values.len())))
        .collect();
    v.sort();
    v
}

/// Checks that the predictor checkpoint `theirs` (its own, `base_model.*`)
/// holds exactly the tensors of the flow checkpoint's copy `ours`
/// (`eigenvecs_predictor.*`).
fn cross_check(
    ours: &HashMap<String, OfficialTensor>,
    theirs: &HashMap<String, OfficialTensor>,
    flow_path: &Path,
    predictor_path: &Path,
) -> Result<()> {
    let fail = |detail: String| {
        ArbitraryError::format(
            predictor_path,
            format!(
                "the predictor checkpoint is not the predictor inside {}: {detail}",
                flow_path.display()
            ),
        )
    };
    let a = unprefixed(ours, PREDICTOR_PREFIX);
    let b = unprefixed(theirs, OFFICIAL_PREFIX);
    let names_a: Vec<&String> = a.iter().map(|(n, _)| n).collect();
    let names_b: Vec<&String> = b.iter().map(|(n, _)| n).collect();
    if let Some(n) = names_a.iter().find(|n| !names_b.contains(n)) {
        return Err(fail(format!(
            "{OFFICIAL_PREFIX}{n} is missing (the flow checkpoint has {PREDICTOR_PREFIX}{n})"
        )));
    }
    if let Some(n) = names_b.iter().find(|n| !names_a.contains(n)) {
        return Err(fail(format!(
            "{OFFICIAL_PREFIX}{n} is not in the flow checkpoint ({PREDICTOR_PREFIX}{n})"
        )));
    }
    for (name, _) in &a {
        let x = &ours[&format!("{PREDICTOR_PREFIX}{name}")];
        let y = &theirs[&format!("{OFFICIAL_PREFIX}{name}")];
        if x.shape != y.shape {
            return Err(fail(format!(
                "{OFFICIAL_PREFIX}{name} has shape {:?}, {PREDICTOR_PREFIX}{name} {:?}",
                y.shape, x.shape
            )));
        }
        let same = x
            .values
            .iter()
            .zip(&y.values)
            .all(|(p, q)| p.to_bits() == q.to_bits());
        if !same {
            return Err(fail(format!(
                "{OFFICIAL_PREFIX}{name} holds other values than {PREDICTOR_PREFIX}{name}"
            )));
        }
    }
    Ok(())
}

/// Imports the official arbitrary-source checkpoint `checkpoint_path` with
/// its YAML configuration `config_path` into the run folder `out` (missing
/// or empty; removed again if anything fails, so nothing is written on an
/// error). `predictor_checkpoint`: the predictor's own checkpoint, checked
/// to hold the same tensors as the flow checkpoint's copy. `template`: the
/// template mesh (and its path) the model was trained on, recorded so that
/// sampling warns on sources unlike it; without it no template is recorded.
///
/// # Errors
/// [`mfm_fm::FmError::Files`] naming the checkpoint or the configuration for what
/// they hold that mfm refuses (objects in the checkpoint, options mfm does
/// not implement, non-float weights, tensors outside the flow's and the
/// predictor's, a predictor checkpoint that differs); [`mfm_fm::FmError::Net`]
/// ([`mfm_net::NetError::WeightsMismatch`]) naming a missing, extra or
/// mis-shaped parameter; [`mfm_fm::FmError::Diverged`] for non-finite weights; the
/// output folder's errors.
pub fn import_official_arbitrary(
    checkpoint_path: &Path,
    config_path: &Path,
    predictor_checkpoint: Option<&Path>,
    template: Option<(&TriMesh, &Path)>,
    out: &Path,
) -> Result<ArbitraryImportRecord> {
    let config = OfficialArbitraryConfig::read(config_path)?;
    let flow_config = config.flow_config()?;
    let predictor_config = config.predictor_config();
    let ckpt = OfficialCheckpoint::open(checkpoint_path)?;
    let outside: Vec<&str> = ckpt
        .names()
        .filter(|n| !n.starts_with(OFFICIAL_PREFIX) && !n.starts_with(PREDICTOR_PREFIX))
        .collect();
    if !outside.is_empty() {
        let shown: Vec<&str> = outside.iter().take(8).copied().collect();
        return Err(ArbitraryError::format(
            checkpoint_path,
            format!(
                "{} tensor(s) belong to neither the flow ({OFFICIAL_PREFIX}*) nor the eigenvector \
                 predictor ({PREDICTOR_PREFIX}*): {}{}",
                outside.len(),
                shown.join(", "),
                if outside.len() > shown.len() {
                    ", ..."
                } else {
                    ""
                }
            ),
        ));
    }
    let flow_tensors = ckpt.tensors(OFFICIAL_PREFIX)?;
    let predictor_tensors = ckpt.tensors(PREDICTOR_PREFIX)?;
    if predictor_tensors.is_empty() {
        return Err(ArbitraryError::format(
            checkpoint_path,
            format!(
                "no {PREDICTOR_PREFIX}* tensors: not a checkpoint of the official \
                 arbitrary-source model, which holds its eigenvector predictor"
            ),
        ));
    }
    let k = predictor_config.eigenvectors;
    let mut flow_net = PoissonNet::new(&flow_config.net_config(k), tch::Device::Cpu)?;
    load_official(
        &mut flow_net,
        &flow_tensors,
        OFFICIAL_PREFIX,
        &config.cond_columns()?,
        checkpoint_path,
    )?;
    let mut predictor_net = PoissonNet::new(&predictor_config.net_config(), tch::Device::Cpu)?;
    load_official(
        &mut predictor_net,
        &predictor_tensors,
        PREDICTOR_PREFIX,
        &[],
        checkpoint_path,
    )?;
    check_finite(&flow_tensors, checkpoint_path)?;
    check_finite(&predictor_tensors, checkpoint_path)?;
    let predictor_record = match predictor_checkpoint {
        None => None,
        Some(path) => {
            let theirs = OfficialCheckpoint::open(path)?;
            let tensors = theirs.tensors(OFFICIAL_PREFIX)?;
            if tensors.is_empty() {
                return Err(ArbitraryError::format(
                    path,
                    format!(
                        "no {OFFICIAL_PREFIX}* tensors: not a checkpoint of the official \
                         eigenvector predictor"
                    ),
                ));
            }
            cross_check(&predictor_tensors, &tensors, checkpoint_path, path)?;
            Some(checkpoint::file_record(path)?)
        }
    };
    let record = ArbitraryImportRecord {
        model_type: ARBITRARY_MODEL_TYPE.to_owned(),
        checkpoint: checkpoint_path.to_path_buf(),
        checkpoint_record: checkpoint::file_record(checkpoint_path)?,
        config: config_path.to_path_buf(),
        predictor_checkpoint: predictor_checkpoint.map(Path::to_path_buf),
        predictor_checkpoint_record: predictor_record,
        template: template.map(|(_, p)| p.to_path_buf()),
        global_step: ckpt.global_step(),
        flow_parameters: flow_net.num_parameters(),
        predictor_parameters: predictor_net.num_parameters(),
        ignored_entries: ckpt.ignored_entries().to_vec(),
        assumed: config.assumed.clone(),
    };
    let identity = template.map(|(m, _)| mfm_data::dataset::mesh_identity(m));
    let vertices = template.map_or(0, |(m, _)| m.num_vertices());
    let predictor_spec = PredictorSpec {
        config: predictor_config,
        dataset: config_path.to_path_buf(),
        vertices,
        eigenvalues: Vec::new(),
        margins: Vec::new(),
        template: identity.clone(),
    };
    let spec = ArbitrarySpec {
        config: flow_config,
        dataset: config_path.to_path_buf(),
        predictor: predictor_checkpoint
            .unwrap_or(checkpoint_path)
            .to_path_buf(),
        vertices,
        template_surface: template.map(|(m, _)| SurfaceSize::of(m).normalized()),
        template: identity,
    };
    let undo = mfm_files::Undo::empty_folder(out)?;
    predictor_net.save(out.join(PREDICTOR_WEIGHTS))?;
    mfm_files::write_json(out.join(PREDICTOR_COPY_SPEC), &predictor_spec)?;
    checkpoint::write_file_record(
        out,
        PREDICTOR_RECORD,
        &[PREDICTOR_WEIGHTS, PREDICTOR_NET_CONFIG, PREDICTOR_COPY_SPEC],
    )?;
    flow_net.save(out.join(WEIGHTS_FILE))?;
    checkpoint::write_final_record(out)?;
    mfm_files::write_json(out.join(ARBITRARY_SPEC), &spec)?;
    mfm_files::write_json(out.join(IMPORT_FILE), &record)?;
    undo.keep();
    Ok(record)
}

/// The `model.type` of an official YAML configuration, to route it to the
/// single-source importer (`Matern_FM`, [`mfm_fm::official`]) or this one
/// ([`ARBITRARY_MODEL_TYPE`]).
///
/// # Errors
/// [`mfm_fm::FmError::Files`] naming the file: unreadable, not YAML, no
/// `model.type`.
pub fn official_model_type(path: &Path) -> Result<String> {
    let text = std::fs::read_to_string(path).map_err(|e| ArbitraryError::io(path, e))?;
    let doc: serde_norway::Value =
        serde_norway::from_str(&text).map_err(|e| config_error(path, format!("not YAML: {e}")))?;
    doc.get("model")
        .and_then(|m| m.get("type"))
        .and_then(|t| t.as_str())
        .map(str::to_owned)
        .ok_or_else(|| config_error(path, "no `model.type`"))
}

/// The error of an official configuration file `path` that mfm cannot
/// take ([`mfm_fm::official::config_error`]).
fn config_error(path: &Path, message: impl std::fmt::Display) -> ArbitraryError {
    mfm_fm::official::config_error(path, message).into()
}
