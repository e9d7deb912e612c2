//! `mfm import` and `mfm export-weights`: the authors' pretrained models as
//! mfm runs, and mfm's weights in the authors' format
//! ([`mfm_fm::official`]).

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use clap::Args;
use mfm_arbitrary::official::{
    ARBITRARY_MODEL_TYPE, IMPORTED_FILES as ARBITRARY_FILES, import_official_arbitrary,
    official_model_type,
};
use mfm_fm::official::{IMPORTED_FILES, export_official, import_official};

use crate::mesh::load_mesh_checked;

/// `mfm import`.
#[derive(Args)]
pub struct ImportArgs {
    /// The official checkpoint: a PyTorch Lightning `.ckpt` of the
    /// Matérn-FM code (or a `torch.save`d state dict). Only tensors and
    /// plain containers are read; a file holding other pickled objects is
    /// refused.
    #[arg(long)]
    checkpoint: PathBuf,
    /// The checkpoint's YAML configuration (configs/*.yaml of the official
    /// code, or the config.yaml of its results folder). Its model.type
    /// chooses the import: Matern_FM (one mesh) or
    /// Matern_FM_arbitrary_source (any source mesh; the checkpoint holds
    /// the eigenvector predictor too).
    #[arg(long)]
    config: PathBuf,
    /// The template mesh the model was trained on (e.g. the official
    /// demo/meshes/stanford_bunny/bunny_10k.obj); recorded as the training
    /// surface, so sampling on a mesh of another size or place warns.
    /// Required for a single-source model; optional for an arbitrary-source
    /// one (sources unlike it are then reported).
    #[arg(long)]
    mesh: Option<crate::mesh::MeshSpec>,
    /// Arbitrary-source models only: the eigenvector predictor's own
    /// checkpoint (e.g. ckpts/smpl_eigenvecs_predictor.ckpt), checked to
    /// hold the same weights as the predictor inside --checkpoint.
    #[arg(long)]
    predictor_checkpoint: Option<PathBuf>,
    /// The run folder to write (missing or empty): config.toml, flow.json,
    /// model.safetensors, model.json, model.state.json, import.json (an
    /// arbitrary-source model: arbitrary.json, the model and predictor
    /// files, import.json).
    #[arg(long)]
    out: PathBuf,
}

/// `mfm export-weights`.
#[derive(Args)]
pub struct ExportArgs {
    /// A run folder with a final model (`mfm train` or `mfm import`).
    #[arg(long)]
    run: PathBuf,
    /// The checkpoint to write: `{"state_dict": {"base_model.<name>": tensor}}`
    /// in the format of `torch.save`, which the official code loads with
    /// `model.load_state_dict(torch.load(path)["state_dict"])`.
    #[arg(long)]
    out: PathBuf,
    /// Replace an existing --out file.
    #[arg(long)]
    force: bool,
}

/// Runs `mfm import`: routes on the configuration's `model.type`.
pub fn import(a: ImportArgs) -> Result<()> {
    let kind = official_model_type(&a.config).context("reading --config")?;
    if kind == ARBITRARY_MODEL_TYPE {
        return import_arbitrary(a);
    }
    if kind != "Matern_FM" {
        // the single-source reader says what the type is and what to do
        mfm_fm::official::OfficialConfig::read(&a.config)
            .with_context(|| format!("importing {}", a.checkpoint.display()))?;
    }
    if a.predictor_checkpoint.is_some() {
        bail!(
            "--predictor-checkpoint is for arbitrary-source models; {} is a {kind} model",
            a.config.display()
        );
    }
    let Some(mesh_name) = a.mesh.clone() else {
        bail!(
            "importing a single-source model ({kind}, {}) needs --mesh: the template mesh it was \
             trained on",
            a.config.display()
        );
    };
    let mesh = load_mesh_checked(&mesh_name)?;
    let _lock = claim_run_folder(&a.out, &IMPORTED_FILES)?;
    let record = import_official(
        &a.checkpoint,
        &a.config,
        &mesh,
        std::path::Path::new(&mesh_name),
        &a.out,
    )
    .with_context(|| {
        format!(
            "importing {} with {}; nothing was written",
            a.checkpoint.display(),
            a.config.display()
        )
    })?;
    println!(
        "imported {} parameters{} from {} -> {}",
        record.parameters,
        record
            .global_step
            .map(|s| format!(" (step {s})"))
            .unwrap_or_default(),
        a.checkpoint.display(),
        a.out.display()
    );
    if !record.ignored_entries.is_empty() {
        println!(
            "not read (training state): {}",
            record.ignored_entries.join(", ")
        );
    }
    for key in &record.assumed {
        eprintln!(
            "note: {} leaves out {key}; make sure that is what the model was trained with",
            a.config.display()
        );
    }
    println!(
        "sample it with: mfm sample --run {} --mesh {} --out SAMPLES",
        a.out.display(),
        mesh_name
    );
    Ok(())
}

/// Locks `out` and checks it is missing or empty: `mfm import` writes a
/// new run folder of `files`. The lock is held while the guard lives.
fn claim_run_folder(out: &std::path::Path, files: &[&str]) -> Result<mfm_files::FolderLock> {
    let lock = crate::output::lock_folder(out)?;
    crate::output::ensure_empty(out)
        .with_context(|| format!("mfm import writes a new run folder ({})", files.join(", ")))?;
    Ok(lock)
}

/// `mfm import` of an arbitrary-source model
/// ([`mfm_arbitrary::official`]).
fn import_arbitrary(a: ImportArgs) -> Result<()> {
    let mesh = match &a.mesh {
        Some(name) => Some((load_mesh_checked(name)?, PathBuf::from(name))),
        None => None,
    };
    let _lock = claim_run_folder(&a.out, &ARBITRARY_FILES)?;
    let record = import_official_arbitrary(
        &a.checkpoint,
        &a.config,
        a.predictor_checkpoint.as_deref(),
        mesh.as_ref().map(|(m, p)| (m, p.as_path())),
        &a.out,
    )
    .with_context(|| {
        format!(
            "importing the arbitrary-source model {} with {}{}; nothing was written",
            a.checkpoint.display(),
            a.config.display(),
            a.predictor_checkpoint
                .as_ref()
                .map(|p| format!(" and the predictor {}", p.display()))
                .unwrap_or_default()
        )
    })?;
    println!(
        "imported the arbitrary-source flow ({} parameters) and its eigenvector predictor ({} \
         parameters){} from {} -> {}",
        record.flow_parameters,
        record.predictor_parameters,
        record
            .global_step
            .map(|s| format!(" (step {s})"))
            .unwrap_or_default(),
        a.checkpoint.display(),
        a.out.display()
    );
    if let Some(p) = &record.predictor_checkpoint {
        println!(
            "the predictor checkpoint {} holds the same weights",
            p.display()
        );
    }
    if !record.ignored_entries.is_empty() {
        println!(
            "not read (training state): {}",
            record.ignored_entries.join(", ")
        );
    }
    for key in &record.assumed {
        eprintln!(
            "note: {} leaves out {key}; make sure that is what the model was trained with",
            a.config.display()
        );
    }
    println!(
        "sources are used as they are (the official data's units and place) and the targets are \
         mass-mean zero; sample it with: mfm sample --run {} --source MESH --out SAMPLES",
        a.out.display()
    );
    Ok(())
}

/// Runs `mfm export-weights`.
pub fn export(a: ExportArgs) -> Result<()> {
    if a.out.exists() && !a.force {
        bail!(
            "--out {} exists; pass --force to replace it",
            a.out.display()
        );
    }
    if a.out.is_dir() {
        bail!(
            "--out {} is a folder; give a file name such as model.ckpt",
            a.out.display()
        );
    }
    let run_files: Vec<PathBuf> = [
        "config.toml",
        "flow.json",
        "model.safetensors",
        "model.json",
        "model.state.json",
    ]
    .iter()
    .map(|f| a.run.join(f))
    .collect();
    let inputs: Vec<Option<&std::path::Path>> =
        run_files.iter().map(|p| Some(p.as_path())).collect();
    let undo = crate::output::prepare_outputs(&inputs, std::slice::from_ref(&a.out), &[])?;
    let n = export_official(&a.run, &a.out)
        .with_context(|| format!("exporting the weights of {}", a.run.display()))?;
    undo.keep();
    println!(
        "{n} tensors under the official names -> {} (load with model.load_state_dict(torch.load(path)[\"state_dict\"]))",
        a.out.display()
    );
    Ok(())
}
