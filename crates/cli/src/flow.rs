//! Flow matching from the command line: `mfm dataset gmm`, `mfm train`,
//! `mfm sample`, `mfm eval`.

use crate::mesh_arg::{load_mesh_checked, mesh_path};
use crate::output::{prepare_outputs, write_json};
use anyhow::{Context, Result, bail};
use clap::{Args, Subcommand};
use mfm_fm::checkpoint::CONFIG_FILE;
use mfm_fm::config::{DeviceChoice, OdeMethod, RunConfig};
use mfm_fm::dataset::{Dataset, Manifest};
use mfm_fm::deformations::{self, DeformManifest, DeformMeshes};
use mfm_fm::experiment::GmmMeshes;
use mfm_fm::gmm::{GenerateOptions, GmmConfig, GmmDistance, GmmGenerator};
use mfm_fm::metrics::Metrics;
use mfm_fm::quality::{GmmQualityReport, ParamSpread, Quartiles};
use mfm_fm::sample::{SampleOptions, Sampler};
use mfm_fm::train::Trainer;
use mfm_fm::{InMemorySignals, SignalSource};
use mfm_geometry::frame::CanonicalFrame;
use mfm_geometry::render::{ColorRange, Colormap, GridOptions, Panel, RenderOptions};
use mfm_geometry::{TriMesh, io, operators, render};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

/// `mfm dataset ...`.
#[derive(Subcommand)]
pub enum DatasetCommand {
    /// The GMM experiment (after Manifold Diffusion Fields): signals made of
    /// Gaussian bumps at centers drawn in proportion to vertex mass.
    /// Writes OUT/train (the training set on the training mesh) and
    /// OUT/reference (a reference set on a non-uniform test triangulation of
    /// the same surface), each a dataset folder (mesh, signals.npy,
    /// manifest.json), and OUT/preview.png.
    Gmm(GmmArgs),
    /// Elastic-looking poses of a mesh: as-rigid-as-possible deformations
    /// driven by random rigid motions of a few handle regions (feet, trunk,
    /// tail... picked automatically at the extremities) around a fixed
    /// anchor. The mesh is normalized (unit bounding-box diagonal) and
    /// decimated to the training resolution. Writes OUT/train (shapes on the
    /// coarse mesh), OUT/reference (held-out shapes on a finer, non-uniform
    /// triangulation: the coarse mesh with one half refined twice),
    /// OUT/holdout (the same held-out parameters on the coarse mesh),
    /// OUT/{original,coarse,eval}.ply, OUT/space.json (handles and ranges)
    /// and OUT/preview.png. Each dataset folder has params.json with every
    /// sample's handle parameters.
    Deform(DeformArgs),
}

/// Arguments of `mfm dataset deform`.
#[derive(Args)]
pub struct DeformArgs {
    /// The mesh to deform (a file or builtin:NAME), e.g.
    /// ../shared/meshes/elephant.obj.
    #[arg(long)]
    mesh: String,
    /// Output folder (must not exist or be empty).
    #[arg(long)]
    out: PathBuf,
    /// Training shapes.
    #[arg(long, default_value_t = 400)]
    n: usize,
    /// Held-out shapes (reference set on the evaluation mesh, and the same
    /// parameters on the coarse mesh).
    #[arg(long, default_value_t = 100)]
    reference: usize,
    /// Moving handles (the anchor comes on top).
    #[arg(long, default_value_t = 5)]
    handles: usize,
    /// Handle radius as a fraction of the bounding-box diagonal.
    #[arg(long, default_value_t = 0.08)]
    radius: f64,
    /// Largest handle rotation, in radians.
    #[arg(long, default_value_t = 0.5)]
    max_angle: f64,
    /// Largest handle translation, as a fraction of the bounding-box diagonal.
    #[arg(long, default_value_t = 0.12)]
    max_shift: f64,
    /// Faces of the coarse training mesh.
    #[arg(long, default_value_t = 3000)]
    coarse_faces: usize,
    /// Seed (held-out shapes use their own stream of the same seed).
    #[arg(long, default_value_t = 0)]
    seed: u64,
}

/// Arguments of `mfm dataset gmm`.
#[derive(Args)]
pub struct GmmArgs {
    /// Output folder (must not exist or be empty).
    #[arg(long)]
    out: PathBuf,
    /// Training mesh, a file or builtin:NAME (default: the built-in blob,
    /// 2562 vertices, with its test mesh whose x < centroid half is refined
    /// twice).
    #[arg(long)]
    mesh: Option<String>,
    /// Test mesh for the reference set (default: the training mesh with the
    /// half x < centroid refined twice).
    #[arg(long)]
    test_mesh: Option<String>,
    /// Training signals.
    #[arg(long, default_value_t = 1000)]
    n: usize,
    /// Reference signals on the test mesh (0: no reference set).
    #[arg(long, default_value_t = 200)]
    reference: usize,
    /// Bumps per signal.
    #[arg(long, default_value_t = 3)]
    bumps: usize,
    /// Bump width relative to sqrt(surface area).
    #[arg(long, default_value_t = 0.06)]
    sigma: f64,
    /// Smallest center separation, in bump widths.
    #[arg(long, default_value_t = 4.0)]
    min_separation: f64,
    /// Use straight-line instead of geodesic (heat method) distance.
    #[arg(long)]
    euclidean: bool,
    /// Seed (the reference set uses its own stream of the same seed).
    #[arg(long, default_value_t = 0)]
    seed: u64,
}

/// Arguments of `mfm train`.
#[derive(Args)]
pub struct TrainArgs {
    /// Run configuration (TOML; every field has a default, unknown fields
    /// are an error). Without it, --preset gives the configuration.
    #[arg(long, conflicts_with = "preset")]
    config: Option<PathBuf>,
    /// Named configuration: `cpu` (scalar signals, minutes on a laptop),
    /// `cpu-deform` (`cpu` conditioned on the source xyz, for `mfm dataset
    /// deform` data), `paper` (the authors' human-pose recipe, for a GPU) or
    /// `paper-elastic` (their elastic-deformation recipe).
    #[arg(long)]
    preset: Option<String>,
    /// Dataset folder (overrides the configuration's dataset.path).
    #[arg(long)]
    dataset: Option<PathBuf>,
    /// Run folder: config, log, checkpoints, final model.
    #[arg(long)]
    out: PathBuf,
    /// Total training steps (overrides train.steps).
    #[arg(long)]
    steps: Option<u64>,
    /// Seed (overrides train.seed).
    #[arg(long)]
    seed: Option<u64>,
    /// Noise the flow starts from (overrides noise.kind): matern:TAU,
    /// matern-normalized:C, white, naive, explicit:K:TAU.
    #[arg(long)]
    noise: Option<mfm_noise::NoiseKind>,
    /// Where to train: auto (a GPU when libtorch sees one), cpu or cuda
    /// (overrides train.device; with --resume, continues the run there).
    #[arg(long)]
    pub device: Option<DeviceChoice>,
    /// Continue the run in --out from its newest valid checkpoint.
    #[arg(long)]
    resume: bool,
    /// No progress bar.
    #[arg(long)]
    quiet: bool,
}

/// Arguments of `mfm sample`.
#[derive(Args)]
pub struct SampleArgs {
    /// Run folder written by `mfm train` (its final model, or its newest
    /// checkpoint).
    #[arg(long)]
    run: PathBuf,
    /// Mesh to generate on: any triangulation of the training surface.
    #[arg(long)]
    mesh: String,
    /// Number of samples.
    #[arg(long, default_value_t = 16)]
    n: usize,
    /// ODE steps (default: the run's sample.steps).
    #[arg(long)]
    steps: Option<usize>,
    /// Integrator: midpoint or euler (default: the run's).
    #[arg(long)]
    method: Option<OdeMethod>,
    /// Where to run the network: auto (a GPU when libtorch sees one), cpu
    /// or cuda. Samples agree across devices up to round-off.
    #[arg(long, default_value = "auto")]
    device: DeviceChoice,
    /// Seed of the initial noise.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Output folder: samples.npy [N, V, C] (f32), mesh.ply, the first
    /// --ply samples as PLY, samples.png, timing.json.
    #[arg(long)]
    out: PathBuf,
    /// How many samples to also write as PLY files.
    #[arg(long, default_value_t = 4)]
    ply: usize,
    /// Write into a non-empty --out folder: replaces only what `mfm sample`
    /// writes (samples.npy, mesh.ply, samples.png, timing.json,
    /// sample_NNN.ply, stale ones of an earlier run included).
    #[arg(long)]
    force: bool,
}

/// Arguments of `mfm eval`.
#[derive(Args)]
pub struct EvalArgs {
    /// Generated samples (.npy [N, V, C], e.g. from `mfm sample`).
    #[arg(long)]
    samples: PathBuf,
    /// Reference dataset folder (its mesh is the mesh the samples live on).
    #[arg(long, required_unless_present = "space")]
    reference: Option<PathBuf>,
    /// Without a reference set: the space.json of `mfm dataset deform`; only
    /// the projection (plausibility) error is computed, on --mesh.
    #[arg(long, requires = "mesh", conflicts_with = "reference")]
    space: Option<PathBuf>,
    /// The mesh the samples live on (with --space).
    #[arg(long)]
    mesh: Option<String>,
    /// Write the metrics as JSON here.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Render the point-wise means (generated vs reference) to this PNG; for
    /// a deformation reference set (`mfm dataset deform`), the first
    /// generated shapes beside their projections onto the deformation space.
    #[arg(long)]
    png: Option<PathBuf>,
}

/// Runs `mfm dataset ...`.
pub fn dataset(cmd: DatasetCommand) -> Result<()> {
    match cmd {
        DatasetCommand::Gmm(a) => dataset_gmm(a),
        DatasetCommand::Deform(a) => dataset_deform(a),
    }
}

/// Runs `mfm dataset deform`.
fn dataset_deform(a: DeformArgs) -> Result<()> {
    if a.n == 0 {
        bail!("--n must be at least 1");
    }
    ensure_empty(&a.out)?;
    let t0 = std::time::Instant::now();
    let input = load_mesh_checked(&a.mesh)?;
    let undo = dataset_undo(
        &a.out,
        &[
            "train",
            "reference",
            "holdout",
            "original.ply",
            "coarse.ply",
            "eval.ply",
            "space.json",
            "preview.png",
        ],
    )?;
    let meshes = DeformMeshes::from_mesh(&input, a.coarse_faces)
        .with_context(|| format!("preparing the meshes of {}", a.mesh))?;
    let space = deformations::space_for(
        &meshes.original,
        a.handles,
        a.radius,
        a.max_angle,
        a.max_shift,
    )
    .with_context(|| format!("placing {} handles on {}", a.handles, a.mesh))?;
    for (role, m) in [
        ("original", &meshes.original),
        ("coarse", &meshes.coarse),
        ("eval", &meshes.eval),
    ] {
        let regions = space.handles.regions(m)?;
        let sizes: Vec<String> = regions.iter().map(|r| r.len().to_string()).collect();
        println!(
            "{role:>8} mesh: {:>6} vertices, {:>6} faces; handle vertices (anchor first): {}",
            m.num_vertices(),
            m.num_faces(),
            sizes.join(", ")
        );
        io::write_ply(a.out.join(format!("{role}.ply")), m, &[])?;
    }
    write_json(&a.out.join("space.json"), &space)?;
    let norm = meshes.normalization;
    let held_out_seed = a.seed ^ 0x5eed_0f2e_f5e7;
    let train = deformations::write_dataset(
        &a.out.join("train"),
        &meshes.coarse,
        &space,
        a.seed,
        0..a.n,
        norm,
        meshes.frame,
        "coarse",
        &format!(
            "mfm dataset deform: training shapes on the coarse mesh of {}",
            a.mesh
        ),
        true,
    )?;
    if a.reference > 0 {
        deformations::write_dataset(
            &a.out.join("reference"),
            &meshes.eval,
            &space,
            held_out_seed,
            0..a.reference,
            norm,
            meshes.frame,
            "eval",
            &format!(
                "mfm dataset deform: held-out shapes on the evaluation mesh of {}",
                a.mesh
            ),
            true,
        )?;
        deformations::write_dataset(
            &a.out.join("holdout"),
            &meshes.coarse,
            &space,
            held_out_seed,
            0..a.reference,
            norm,
            meshes.frame,
            "coarse",
            &format!(
                "mfm dataset deform: held-out shapes on the coarse mesh of {}",
                a.mesh
            ),
            true,
        )?;
    }
    let preview = train.load_all()?;
    let shapes: Vec<TriMesh> = (0..preview.len().min(8))
        .map(|i| meshes.coarse.with_positions(preview.positions(i)))
        .collect::<Result<_, _>>()?;
    let mut panels = vec![Panel::new(&meshes.coarse, None, "rest")];
    panels.extend(
        shapes
            .iter()
            .enumerate()
            .map(|(i, m)| Panel::new(m, None, format!("shape {i}"))),
    );
    save_grid(
        &panels,
        3,
        "deformation training shapes",
        ColorRange::Auto,
        &a.out.join("preview.png"),
    )?;
    undo.keep();
    println!(
        "wrote {} ({} training shapes, {} held out) in {:.1} s",
        a.out.display(),
        a.n,
        a.reference,
        t0.elapsed().as_secs_f64()
    );
    Ok(())
}

/// Runs `mfm dataset gmm`.
fn dataset_gmm(a: GmmArgs) -> Result<()> {
    let config = GmmConfig {
        bumps: a.bumps,
        sigma: a.sigma,
        min_separation: a.min_separation,
        distance: if a.euclidean {
            GmmDistance::Euclidean
        } else {
            GmmDistance::Geodesic
        },
        ..GmmConfig::default()
    };
    config.validate()?;
    if a.n == 0 {
        bail!("--n must be at least 1");
    }
    ensure_empty(&a.out)?;
    let (train_mesh, test_mesh, source) = match (&a.mesh, &a.test_mesh) {
        (None, None) => {
            let m = GmmMeshes::builtin()?;
            (m.train, m.test, "builtin:blob".to_owned())
        }
        (Some(spec), None) => {
            let m = GmmMeshes::from_base(load_mesh_checked(spec)?, Default::default())?;
            (m.train, m.test, spec.clone())
        }
        (Some(spec), Some(test)) => (
            load_mesh_checked(spec)?,
            load_mesh_checked(test)?,
            spec.clone(),
        ),
        (None, Some(_)) => bail!("--test-mesh needs --mesh (the training mesh)"),
    };
    println!(
        "train mesh: {} vertices, {} faces; test mesh: {} vertices, {} faces",
        train_mesh.num_vertices(),
        train_mesh.num_faces(),
        test_mesh.num_vertices(),
        test_mesh.num_faces()
    );
    let progress = GenerateOptions {
        progress_bar: true,
        on_progress: None,
    };
    let frame = CanonicalFrame::of(&train_mesh)
        .with_context(|| format!("placing the training mesh {source} in the canonical frame"))?;
    let write = |dir: &Path, mesh: &TriMesh, n: usize, seed: u64, role: &str| -> Result<Dataset> {
        let generator = GmmGenerator::new(mesh, &config)?;
        let signals = generator.generate_with(n, seed, &progress)?;
        let manifest = Manifest::new("gmm", config.manifest_params())
            .with_seed(seed)
            .with_provenance(format!("mfm dataset gmm: {role} set on {source}"))
            .with_frame(frame);
        Ok(Dataset::write(dir, mesh, &signals, manifest)?)
    };
    let undo = dataset_undo(
        &a.out,
        &["train", "reference", "test_mesh.ply", "preview.png"],
    )?;
    let t0 = std::time::Instant::now();
    let train = write(&a.out.join("train"), &train_mesh, a.n, a.seed, "training")?;
    // A different seed stream for the reference set: its signals are not
    // copies of training signals on another mesh.
    let reference_seed = a.seed ^ 0x5eed_0f2e_f5e7;
    if a.reference > 0 {
        write(
            &a.out.join("reference"),
            &test_mesh,
            a.reference,
            reference_seed,
            "reference",
        )?;
    } else {
        io::write_ply(a.out.join("test_mesh.ply"), &test_mesh, &[])?;
    }
    let preview = train.load_all()?;
    let k = preview.len().min(8);
    let values: Vec<Vec<f64>> = (0..k).map(|i| channel(&preview, i, 0)).collect();
    let panels: Vec<Panel<'_>> = values
        .iter()
        .enumerate()
        .map(|(i, v)| Panel::new(&train_mesh, Some(v.as_slice()), format!("signal {i}")))
        .collect();
    save_grid(
        &panels,
        4,
        "GMM training signals",
        ColorRange::Auto,
        &a.out.join("preview.png"),
    )?;
    undo.keep();
    println!(
        "wrote {} ({} training signals, {} reference) in {:.1} s",
        a.out.display(),
        a.n,
        a.reference,
        t0.elapsed().as_secs_f64()
    );
    Ok(())
}

/// Runs `mfm train`.
pub fn train(a: TrainArgs) -> Result<()> {
    let stop = Arc::new(AtomicBool::new(false));
    {
        let stop = Arc::clone(&stop);
        // A second Ctrl-C while the final checkpoint is written kills the
        // process as usual.
        let installed = ctrlc::set_handler(move || {
            if stop.swap(true, Ordering::SeqCst) {
                std::process::exit(130);
            }
            eprintln!(
                "\nmfm: stopping after this step and writing a checkpoint (Ctrl-C again to kill)"
            );
        });
        if let Err(e) = installed {
            eprintln!(
                "mfm: warning: cannot install the Ctrl-C handler ({e}); Ctrl-C will lose the steps since the last checkpoint"
            );
        }
    }
    // A fresh run that fails before its first checkpoint leaves nothing.
    let mut fresh: Option<mfm_files::Undo> = None;
    let mut trainer = if a.resume {
        if a.config.is_some() || a.preset.is_some() || a.noise.is_some() || a.seed.is_some() {
            bail!(
                "--resume continues with the run's own {CONFIG_FILE}; drop --config/--preset/--noise/--seed"
            );
        }
        if !a.out.is_dir() {
            bail!(
                "--out {}: no such run folder (--resume continues a run `mfm train --out` started)",
                a.out.display()
            );
        }
        let stored = RunConfig::from_toml_file(a.out.join(CONFIG_FILE))
            .with_context(|| format!("{} is not a run folder", a.out.display()))?;
        let dir = match (a.dataset.as_deref(), &stored.dataset.path) {
            (None, Some(p)) if !p.is_dir() => {
                let found = mfm_fm::config::locate_dataset(p, &a.out).with_context(|| {
                    format!(
                        "the run's dataset {} is gone (moved?); pass --dataset DIR",
                        p.display()
                    )
                })?;
                eprintln!(
                    "note: the run's dataset {} is not there; using {} (found beside the run folder)",
                    p.display(),
                    found.display()
                );
                found
            }
            (flag, _) => dataset_dir(flag, &stored)?,
        };
        let data = Dataset::open(&dir)?;
        let mesh = data.mesh().clone();
        let mut t = match a.device {
            Some(d) => Trainer::resume_on(&a.out, &mesh, Arc::new(data), d)?,
            None => Trainer::resume(&a.out, &mesh, Arc::new(data))?,
        };
        if let Some(r) = t.resumed() {
            match &r.checkpoint {
                Some(c) => println!("resuming from {} (step {})", c.display(), r.step),
                None => println!("no checkpoint yet: starting over"),
            }
        }
        if let Some(steps) = a.steps {
            t.set_total_steps(steps)?;
        }
        t
    } else {
        let mut config = match (&a.config, &a.preset) {
            (Some(path), _) => RunConfig::from_toml_file(path)?,
            (None, Some(name)) => RunConfig::preset(name)?,
            (None, None) => {
                bail!("give --config run.toml or --preset cpu|cpu-deform|paper|paper-elastic")
            }
        };
        if let Some(d) = &a.dataset {
            config.dataset.path = Some(d.clone());
        }
        // stored absolute, so `--resume` works from any working directory
        if let Some(p) = &config.dataset.path {
            config.dataset.path = Some(
                std::path::absolute(p).with_context(|| format!("dataset path {}", p.display()))?,
            );
        }
        if let Some(s) = a.steps {
            config.train.steps = s;
        }
        if let Some(s) = a.seed {
            config.train.seed = s;
        }
        if let Some(k) = a.noise {
            config.noise.kind = k;
        }
        if let Some(d) = a.device {
            config.train.device = d;
        }
        let dir = dataset_dir(None, &config)?;
        let data = Dataset::open(&dir)?;
        let mesh = data.mesh().clone();
        println!(
            "dataset {}: {} signals, {} vertices, {} channels",
            dir.display(),
            data.len(),
            data.num_vertices(),
            data.channels()
        );
        ensure_empty(&a.out)?;
        let mut undo = mfm_files::Undo::new();
        undo.create_dir_all(&a.out)?;
        for f in [
            CONFIG_FILE,
            mfm_fm::checkpoint::FLOW_FILE,
            mfm_fm::checkpoint::LOG_FILE,
        ] {
            undo.file(a.out.join(f));
        }
        let trainer = Trainer::new(&a.out, config, &mesh, Arc::new(data))?;
        fresh = Some(undo);
        trainer
    };
    println!(
        "training {} parameters on {:?}, step {} of {}",
        trainer.net().num_parameters(),
        trainer.device(),
        trainer.step(),
        trainer.config().train.steps
    );
    let flow = trainer.flow();
    if !flow.frame.is_identity() {
        let sh = flow.frame.shift;
        println!(
            "frame: p -> {:.4} p + [{:.4}, {:.4}, {:.4}] (bounding box centred, largest extent 1){}; noise {} x {}{}",
            flow.frame.scale,
            sh[0],
            sh[1],
            sh[2],
            if flow.positions {
                ", positions moved with it"
            } else {
                ""
            },
            flow.noise,
            flow.noise_scale,
            if flow.centered {
                ", noise and targets centred"
            } else {
                ""
            }
        );
    }
    let summary = match trainer.run(&stop, !a.quiet) {
        Ok(s) => s,
        Err(e) => {
            let has_checkpoint =
                mfm_fm::checkpoint::list_checkpoints(&a.out).is_ok_and(|c| !c.is_empty());
            if has_checkpoint {
                // the checkpoints are the user's progress: keep the run
                if let Some(u) = fresh.take() {
                    u.keep();
                }
            }
            return Err(e.into());
        }
    };
    if let Some(u) = fresh.take() {
        u.keep();
    }
    println!(
        "steps {}..{} in {:.1} s ({:.3} s/step), last loss {}",
        summary.start_step,
        summary.end_step,
        summary.seconds,
        summary.seconds_per_step,
        summary
            .last_loss
            .map_or_else(|| "-".to_owned(), |l| format!("{l:.5}"))
    );
    if let Some(m) = &summary.model {
        println!("final model: {}", m.display());
    } else if let Some(c) = &summary.checkpoint {
        println!(
            "checkpoint: {} (continue with --resume --out {})",
            c.display(),
            a.out.display()
        );
    }
    if summary.stopped {
        std::process::exit(130);
    }
    Ok(())
}

fn dataset_dir(flag: Option<&Path>, config: &RunConfig) -> Result<PathBuf> {
    match (flag, &config.dataset.path) {
        (Some(p), _) => Ok(p.to_path_buf()),
        (None, Some(p)) => Ok(p.clone()),
        (None, None) => {
            bail!("no dataset: pass --dataset DIR or set [dataset] path in the configuration")
        }
    }
}

/// The fixed names `mfm sample` writes into its folder (besides
/// `sample_NNN.ply`).
const SAMPLE_FILES: [&str; 4] = ["samples.npy", "mesh.ply", "samples.png", "timing.json"];

/// Whether `name` is one of the `sample_NNN.ply` files of `mfm sample`.
fn is_sample_ply(name: &str) -> bool {
    name.strip_prefix("sample_")
        .and_then(|r| r.strip_suffix(".ply"))
        .is_some_and(|d| !d.is_empty() && d.bytes().all(|b| b.is_ascii_digit()))
}

/// Output values kept in memory at once while sampling (the rest goes
/// straight to disk).
const SAMPLE_CHUNK_BYTES: usize = 64 << 20;

/// Runs `mfm sample`.
pub fn sample(a: SampleArgs) -> Result<()> {
    if a.n == 0 {
        bail!("--n must be at least 1");
    }
    if a.out.exists() && !a.out.is_dir() {
        bail!("--out {}: exists and is not a folder", a.out.display());
    }
    let existing: Vec<String> = std::fs::read_dir(&a.out)
        .map(|d| {
            d.filter_map(|e| e.ok())
                .map(|e| e.file_name().to_string_lossy().into_owned())
                .collect()
        })
        .unwrap_or_default();
    if !existing.is_empty() && !a.force {
        bail!(
            "{} exists and is not empty; choose another --out, or add --force to replace what \
`mfm sample` writes there ({}, sample_NNN.ply; nothing else is touched)",
            a.out.display(),
            SAMPLE_FILES.join(", ")
        );
    }
    let mesh = load_mesh_checked(&a.mesh)?;
    let sampler = Sampler::load(&a.run, Some(a.device.resolve()?))?;
    for w in sampler.surface_warnings(&mesh) {
        eprintln!(
            "warning: {}: {w}; the run's frame assumes the sampling mesh is the training surface in the dataset's units",
            a.mesh
        );
    }
    let run_config = RunConfig::from_toml_file(a.run.join(CONFIG_FILE)).ok();
    let mut opts = run_config
        .as_ref()
        .map(|c| SampleOptions::from(&c.sample))
        .unwrap_or_default();
    if let Some(s) = a.steps {
        if s == 0 {
            bail!("--steps must be at least 1");
        }
        opts.steps = s;
    }
    if let Some(m) = a.method {
        opts.method = m;
    }
    let (v, c) = (mesh.num_vertices(), sampler.flow().channels);
    let n = a.n;
    let plys = a.ply.min(n);
    let mut outputs: Vec<PathBuf> = SAMPLE_FILES.iter().map(|f| a.out.join(f)).collect();
    outputs.extend((0..plys).map(|i| a.out.join(format!("sample_{i:03}.ply"))));
    let run_files = [
        CONFIG_FILE,
        mfm_fm::checkpoint::FLOW_FILE,
        mfm_fm::checkpoint::WEIGHTS_FILE,
        mfm_fm::checkpoint::NET_CONFIG_FILE,
        mfm_fm::checkpoint::CHECKPOINTS_DIR,
    ]
    .map(|f| a.run.join(f));
    let mut inputs: Vec<Option<&Path>> = run_files.iter().map(|p| Some(p.as_path())).collect();
    inputs.push(mesh_path(&a.mesh));
    let undo = prepare_outputs(&inputs, &outputs)?;
    let shape = [n as u64, v as u64, c as u64];
    mfm_files::space::ensure_space(
        &a.out.join(SAMPLE_FILES[0]),
        mfm_files::npy::file_bytes(&shape, 4),
    )
    .with_context(|| format!("{n} samples x {v} vertices x {c} channels of f32"))?;
    // stale sample_NNN.ply of an earlier run (--force): removed, nothing else
    for name in existing.iter().filter(|f| is_sample_ply(f)) {
        let path = a.out.join(name);
        if !outputs.contains(&path) {
            std::fs::remove_file(&path)
                .with_context(|| format!("cannot remove the stale {}", path.display()))?;
        }
    }
    let target = sampler.prepare(&mesh)?;
    let row = v * c;
    let keep = n.min(a.ply.max(8));
    let chunk = (SAMPLE_CHUNK_BYTES / (row * 4).max(1))
        .max(opts.batch)
        .min(n);
    let mut file = mfm_files::npy::NpyStream::<f32>::create(&outputs[0], &shape)?;
    let bar = if n > chunk {
        indicatif::ProgressBar::new(n as u64)
    } else {
        indicatif::ProgressBar::hidden()
    };
    let mut kept: Vec<f32> = Vec::with_capacity(keep * row);
    let (mut seconds, mut noise_seconds) = (0.0, 0.0);
    let mut first = 0;
    while first < n {
        let count = chunk.min(n - first);
        let part = sampler.sample_on(&target, first, count, a.seed, &opts)?;
        if let Some((i, vertex, channel, x)) =
            InMemorySignals::new(part.data.clone(), count, v, c)?.first_non_finite()
        {
            bail!(
                "sample {} is not finite ({x} at vertex {vertex}, channel {channel}): the model in {} diverged; nothing was written",
                first + i,
                a.run.display()
            );
        }
        let take = keep.saturating_sub(first).min(count);
        kept.extend_from_slice(&part.data[..take * row]);
        file.append(&part.data)?;
        seconds += part.seconds;
        noise_seconds += part.noise_seconds;
        first += count;
        bar.set_position(first as u64);
    }
    bar.finish_and_clear();
    file.finish()?;
    io::write_ply(a.out.join("mesh.ply"), &mesh, &[])?;
    let signals = InMemorySignals::new(kept, keep, v, c)?;
    for i in 0..plys {
        let path = a.out.join(format!("sample_{i:03}.ply"));
        if c == 3 {
            // Three channels are vertex positions: write the deformed mesh.
            io::write_ply(&path, &mesh.with_positions(signals.positions(i))?, &[])?;
        } else {
            let columns: Vec<Vec<f64>> = (0..c).map(|k| channel(&signals, i, k)).collect();
            let names: Vec<String> = (0..c)
                .map(|k| {
                    if c == 1 {
                        "signal".into()
                    } else {
                        format!("signal_{k}")
                    }
                })
                .collect();
            let scalars: Vec<(&str, &[f64])> = names
                .iter()
                .zip(&columns)
                .map(|(name, col)| (name.as_str(), col.as_slice()))
                .collect();
            io::write_ply(&path, &mesh, &scalars)?;
        }
    }
    let k = keep.min(8);
    let values: Vec<Vec<f64>> = (0..k).map(|i| channel(&signals, i, 0)).collect();
    let deformed: Vec<TriMesh> = if c == 3 {
        (0..k)
            .map(|i| mesh.with_positions(signals.positions(i)))
            .collect::<Result<_, _>>()?
    } else {
        Vec::new()
    };
    let panels: Vec<Panel<'_>> = (0..k)
        .map(|i| {
            if c == 3 {
                Panel::new(&deformed[i], None, format!("sample {i}"))
            } else {
                Panel::new(&mesh, Some(values[i].as_slice()), format!("sample {i}"))
            }
        })
        .collect();
    save_grid(
        &panels,
        4,
        &format!("{n} samples on {} vertices", mesh.num_vertices()),
        ColorRange::Auto,
        &a.out.join("samples.png"),
    )?;
    let per_sample = seconds / n as f64;
    let timing = serde_json::json!({
        "samples": n,
        "vertices": v,
        "channels": c,
        "ode_steps": opts.steps,
        "method": format!("{:?}", opts.method).to_lowercase(),
        "seconds": seconds,
        "noise_seconds": noise_seconds,
        "seconds_per_sample": per_sample,
    });
    write_json(&a.out.join("timing.json"), &timing)?;
    undo.keep();
    println!(
        "{n} samples on {} vertices in {:.2} s ({:.1} ms per sample, {} {:?} steps) -> {}",
        v,
        seconds,
        per_sample * 1e3,
        opts.steps,
        opts.method,
        a.out.display()
    );
    Ok(())
}

/// Runs `mfm eval`.
pub fn eval(a: EvalArgs) -> Result<()> {
    let mut outputs: Vec<PathBuf> = a.out.iter().cloned().collect();
    if let Some(png) = &a.png {
        outputs.push(png.clone());
        outputs.push(sibling_png(png, "samples"));
        outputs.push(sibling_png(png, "difference"));
    }
    let undo = prepare_outputs(
        &[
            Some(a.samples.as_path()),
            a.reference.as_deref(),
            a.space.as_deref(),
            a.mesh.as_deref().and_then(mesh_path),
        ],
        &outputs,
    )?;
    let generated = read_npy_f32(&a.samples)?;
    if let Some((i, vertex, channel, x)) = generated.first_non_finite() {
        bail!(
            "{}: sample {i} is not finite ({x} at vertex {vertex}, channel {channel}); metrics need finite samples",
            a.samples.display()
        );
    }
    let Some(reference_dir) = &a.reference else {
        eval_plausibility_only(&a, &generated)?;
        undo.keep();
        return Ok(());
    };
    let reference = Dataset::open(reference_dir)?;
    if generated.num_vertices() != reference.num_vertices() {
        bail!(
            "{}: samples have {} vertices but the reference mesh ({}) has {}; sample on the reference's mesh",
            a.samples.display(),
            generated.num_vertices(),
            reference_dir.display(),
            reference.num_vertices()
        );
    }
    if generated.channels() != reference.channels() {
        bail!(
            "{}: samples have {} channels but the reference set {} has {}",
            a.samples.display(),
            generated.channels(),
            reference_dir.display(),
            reference.channels()
        );
    }
    let mesh = reference.mesh().clone();
    let deform = DeformManifest::of(&reference)?;
    let gmm = (reference.manifest().generator == mfm_fm::gmm::GENERATOR_NAME)
        .then(|| GmmConfig::from_manifest_params(&reference.manifest().generator_params))
        .transpose()
        .with_context(|| format!("{}: the GMM parameters", reference_dir.display()))?;
    let ops = operators::Operators::new(&mesh)?;
    let mass: Vec<f64> = ops.mass.clone();
    let reference = reference.load_all()?;
    let metrics = Metrics::evaluate(&mass, &generated, &reference)?;
    let mut report = serde_json::to_value(&metrics)?;
    if let (Some(config), 1) = (&gmm, generated.channels()) {
        let generator = GmmGenerator::new(&mesh, config)?;
        let q = GmmQualityReport::of(&generator, &mesh, &mass, &generated, &reference)?;
        println!("{}", q.summary());
        report["quality"] = serde_json::to_value(&q)?;
        if let Some(png) = &a.png {
            let side = sibling_png(png, "samples");
            save_data_and_samples(&mesh, &reference, &generated, &q, &side)?;
        }
    }
    if let Some(d) = &deform {
        let p = deformations::plausibility(&d.space, &mesh, &generated, 4)?;
        let r = deformations::plausibility(&d.space, &mesh, &reference, 0)?;
        let q = Quartiles::of(&p.mse);
        let (gs, rs) = (ParamSpread::of(&p.params), ParamSpread::of(&r.params));
        println!(
            "projection MSE (plausibility): generated median {:.3e} [{:.3e}, {:.3e}], mean {:.3e}; reference mean {:.3e}",
            q.median, q.q1, q.q3, p.mean, r.mean
        );
        println!(
            "handle-parameter spread of the projections: rotation {:.3} rad (data {:.3}), translation {:.4} (data {:.4})",
            gs.rotation, rs.rotation, gs.translation, rs.translation
        );
        report["projection_mse"] = p.mean.into();
        report["projection_mse_median"] = p.median.into();
        report["projection_mse_quartiles"] = serde_json::to_value(q)?;
        report["reference_projection_mse"] = r.mean.into();
        report["param_spread"] = serde_json::to_value(gs)?;
        report["reference_param_spread"] = serde_json::to_value(rs)?;
        report["spread_ratio"] = serde_json::json!({
            "rotation": gs.rotation / rs.rotation,
            "translation": gs.translation / rs.translation,
        });
        if let Some(png) = &a.png {
            save_projection_grid(&mesh, &generated, &p, png)?;
        }
    }
    println!(
        "MMD {:.5}  COV {:.3}  1-NNA {:.3}  test error {:.5}  ({} generated, {} reference)",
        metrics.mmd,
        metrics.cov,
        metrics.one_nna,
        metrics.test_error,
        metrics.num_generated,
        metrics.num_reference
    );
    if let Some(out) = &a.out {
        write_json(out, &report)?;
    }
    if let (Some(png), None) = (&a.png, &deform) {
        let mean_gen = pointwise_mean(&generated);
        let mean_ref = pointwise_mean(&reference);
        let diff: Vec<f64> = mean_gen.iter().zip(&mean_ref).map(|(g, r)| g - r).collect();
        let panels = [
            Panel::new(&mesh, Some(mean_gen.as_slice()), "generated mean"),
            Panel::new(&mesh, Some(mean_ref.as_slice()), "reference mean"),
        ];
        save_grid(
            &panels,
            2,
            &format!("point-wise means, test error {:.4}", metrics.test_error),
            ColorRange::Auto,
            png,
        )?;
        let diff_png = sibling_png(png, "difference");
        let mut opts = RenderOptions::with_size(400, 400);
        opts.colormap = Colormap::CoolWarm;
        opts.range = ColorRange::Symmetric;
        opts.colorbar = true;
        let img = render::render_mesh(&mesh, Some(&diff), &opts)?;
        render::save_png(&img, &diff_png)?;
    }
    undo.keep();
    Ok(())
}

/// `mfm eval --space S --mesh M`: the projection error of 3-channel samples
/// on `M`, with no reference set.
fn eval_plausibility_only(a: &EvalArgs, generated: &InMemorySignals) -> Result<()> {
    let (Some(space_path), Some(mesh_spec)) = (&a.space, &a.mesh) else {
        bail!("give --reference DIR, or --space space.json with --mesh MESH");
    };
    let text = std::fs::read_to_string(space_path)
        .with_context(|| format!("cannot read {}", space_path.display()))?;
    let space: mfm_deform::DeformSpace = serde_json::from_str(&text).with_context(|| {
        format!(
            "{}: not a deformation space (space.json of mfm dataset deform)",
            space_path.display()
        )
    })?;
    let mesh = load_mesh_checked(mesh_spec)?;
    if generated.num_vertices() != mesh.num_vertices() || generated.channels() != 3 {
        bail!(
            "{}: samples are [{}, {}, {}] but {mesh_spec} has {} vertices (positions need 3 channels)",
            a.samples.display(),
            generated.len(),
            generated.num_vertices(),
            generated.channels(),
            mesh.num_vertices()
        );
    }
    let p = deformations::plausibility(&space, &mesh, generated, 4)?;
    println!(
        "projection MSE (plausibility): mean {:.3e} median {:.3e} ({} samples on {} vertices)",
        p.mean,
        p.median,
        generated.len(),
        mesh.num_vertices()
    );
    if let Some(out) = &a.out {
        write_json(
            out,
            &serde_json::json!({
                "projection_mse": p.mean,
                "projection_mse_median": p.median,
                "num_generated": generated.len(),
                "vertices": mesh.num_vertices(),
            }),
        )?;
    }
    if let Some(png) = &a.png {
        save_projection_grid(&mesh, generated, &p, png)?;
    }
    Ok(())
}

/// The first generated shapes beside their projections onto the
/// deformation space.
fn save_projection_grid(
    mesh: &TriMesh,
    generated: &InMemorySignals,
    p: &deformations::Plausibility,
    png: &Path,
) -> Result<()> {
    let shapes: Vec<TriMesh> = (0..p.projections.len())
        .flat_map(|i| {
            [
                mesh.with_positions(generated.positions(i)),
                mesh.with_positions(p.projections[i].clone()),
            ]
        })
        .collect::<Result<_, _>>()?;
    let panels: Vec<Panel<'_>> = shapes
        .iter()
        .enumerate()
        .map(|(k, m)| {
            let caption = if k % 2 == 0 {
                format!("sample {} (MSE {:.1e})", k / 2, p.mse[k / 2])
            } else {
                format!("its projection {}", k / 2)
            };
            Panel::new(m, None, caption)
        })
        .collect();
    save_grid(
        &panels,
        4,
        &format!(
            "generated shapes and their projections, mean MSE {:.2e}",
            p.mean
        ),
        ColorRange::Auto,
        png,
    )
}

/// `dir/STEM_SUFFIX.png` for `dir/STEM.png`.
fn sibling_png(png: &Path, suffix: &str) -> PathBuf {
    png.with_file_name(format!(
        "{}_{suffix}.png",
        png.file_stem().and_then(|s| s.to_str()).unwrap_or("means")
    ))
}

/// The first 8 reference signals above the first 8 generated ones, on one
/// colour scale, each captioned with its bump-fit residual and peak.
fn save_data_and_samples(
    mesh: &TriMesh,
    reference: &InMemorySignals,
    generated: &InMemorySignals,
    q: &GmmQualityReport,
    png: &Path,
) -> Result<()> {
    let k = 8;
    let mut values: Vec<(Vec<f64>, String)> = Vec::new();
    for (set, fits, name) in [
        (reference, &q.reference.fits, "data"),
        (generated, &q.generated.fits, "sample"),
    ] {
        for (i, f) in fits.iter().enumerate().take(set.len().min(k)) {
            values.push((
                channel(set, i, 0),
                format!(
                    "{name} {i}\nres {:.2} peak {:.2} bumps {}",
                    f.residual, f.peak, f.bumps_above_half
                ),
            ));
        }
    }
    let panels: Vec<Panel<'_>> = values
        .iter()
        .map(|(v, c)| Panel::new(mesh, Some(v.as_slice()), c.clone()))
        .collect();
    save_grid(
        &panels,
        4,
        &format!(
            "data (top) and generated (bottom), one colour scale; residual median {:.2} (data {:.2})",
            q.generated.residual.median, q.floor
        ),
        ColorRange::Auto,
        png,
    )
}

/// Point-wise mean of channel 0 over all signals.
fn pointwise_mean(s: &InMemorySignals) -> Vec<f64> {
    let (v, c) = (s.num_vertices(), s.channels());
    let mut mean = vec![0.0; v];
    for i in 0..s.len() {
        for (m, x) in mean.iter_mut().zip(s.signal(i).chunks(c)) {
            *m += f64::from(x[0]);
        }
    }
    let n = s.len().max(1) as f64;
    mean.iter_mut().for_each(|m| *m /= n);
    mean
}

/// Channel `k` of signal `i` as f64.
fn channel(s: &InMemorySignals, i: usize, k: usize) -> Vec<f64> {
    s.signal(i)
        .chunks(s.channels())
        .map(|x| f64::from(x[k]))
        .collect()
}

fn save_grid(
    panels: &[Panel<'_>],
    columns: usize,
    title: &str,
    range: ColorRange,
    path: &Path,
) -> Result<()> {
    let mut opts = GridOptions {
        title: Some(title.to_owned()),
        ..GridOptions::default()
    };
    opts.panel.range = range;
    opts.panel.colorbar = true;
    let img = render::render_grid(panels, columns, &opts)?;
    render::save_png(&img, path)?;
    Ok(())
}

/// Creates the (empty or missing) dataset folder `out` and records it and
/// the entries a `mfm dataset` command writes there for removal on failure.
fn dataset_undo(out: &Path, entries: &[&str]) -> Result<mfm_files::Undo> {
    let mut undo = mfm_files::Undo::new();
    undo.create_dir_all(out)?;
    for e in entries {
        undo.file(out.join(e));
    }
    Ok(undo)
}

fn ensure_empty(dir: &Path) -> Result<()> {
    if let Ok(mut entries) = std::fs::read_dir(dir)
        && entries.next().is_some()
    {
        bail!(
            "{} exists and is not empty; choose another --out (nothing was overwritten)",
            dir.display()
        );
    }
    Ok(())
}

/// Reads a `.npy` of shape `[N, V, C]` or `[N, V]` (f32 or f64) as signals.
fn read_npy_f32(path: &Path) -> Result<InMemorySignals> {
    let a = mfm_files::npy::read::<f32>(path)?;
    let (n, v, c) = match a.shape[..] {
        [n, v] => (n, v, 1),
        [n, v, c] => (n, v, c),
        _ => bail!(
            "{}: expected shape [N, V] or [N, V, C], found {:?}",
            path.display(),
            a.shape
        ),
    };
    InMemorySignals::new(a.values, n, v, c).with_context(|| format!("{}", path.display()))
}
