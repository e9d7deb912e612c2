//! `mfm import` and `mfm export-weights`: the authors' pretrained models as
//! mfm runs, and mfm's weights in the authors' format
//! ([`mfm_fm::official`]).

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use clap::Args;
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
    /// code, or the config.yaml of its results folder).
    #[arg(long)]
    config: PathBuf,
    /// The template mesh the model was trained on (e.g. the official
    /// demo/meshes/stanford_bunny/bunny_10k.obj); recorded as the training
    /// surface, so sampling on a mesh of another size or place warns.
    #[arg(long)]
    mesh: String,
    /// The run folder to write (missing or empty): config.toml, flow.json,
    /// model.safetensors, model.json, model.state.json, import.json.
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

/// Runs `mfm import`.
pub fn import(a: ImportArgs) -> Result<()> {
    let mesh = load_mesh_checked(&a.mesh)?;
    let _lock = crate::output::lock_folder(&a.out)?;
    crate::output::ensure_empty(&a.out).with_context(|| {
        format!(
            "mfm import writes a new run folder ({})",
            IMPORTED_FILES.join(", ")
        )
    })?;
    let record = import_official(
        &a.checkpoint,
        &a.config,
        &mesh,
        std::path::Path::new(&a.mesh),
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
    println!(
        "sample it with: mfm sample --run {} --mesh {} --out SAMPLES",
        a.out.display(),
        a.mesh
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
    let undo = crate::output::prepare_outputs(&inputs, std::slice::from_ref(&a.out))?;
    let n = export_official(&a.run, &a.out)
        .with_context(|| format!("exporting the weights of {}", a.run.display()))?;
    undo.keep();
    println!(
        "{n} tensors under the official names -> {} (load with model.load_state_dict(torch.load(path)[\"state_dict\"]))",
        a.out.display()
    );
    Ok(())
}
