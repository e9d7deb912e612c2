//! `mfm dataset gmm`, `mfm dataset deform` and `mfm dataset pairs`:
//! training and reference sets written as dataset folders.

use crate::mesh::{MeshSpec, load_mesh_checked};
use anyhow::{Context, Result, bail};
use clap::{Args, Subcommand};
use mfm_data::deformations::{self, DeformMeshes};
use mfm_data::experiment::GmmMeshes;
use mfm_data::gmm::{GenerateOptions, GmmConfig, GmmDistance};
use mfm_data::layout::{DeformExperiment, GmmExperiment, PairsExperiment};
use mfm_data::pairs::PairSpace;
use mfm_deform::{DeformSpace, ShapeFamily};
use std::path::{Path, PathBuf};

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
    /// Posed body shapes of a template, for the arbitrary-source model:
    /// each shape is a smooth region-wise anisotropic scaling of the
    /// normalized, decimated mesh (the stand-in for a body-shape space),
    /// shown in several ARAP poses of the automatic handles; a training
    /// pair is two poses of one shape. Writes OUT/train (shapes on the
    /// coarse mesh, POSES meshes per shape), OUT/holdout (unseen shapes on
    /// the coarse mesh), OUT/reference (the same unseen shapes on the finer
    /// evaluation triangulation), OUT/{original,coarse,eval}.ply,
    /// OUT/pair_space.json and OUT/preview.png; each dataset folder has
    /// params.json with every shape's and pose's parameters.
    Pairs(PairsArgs),
    /// Your own data: shapes of one connectivity (mesh files, or folders of
    /// them in natural order: 2.obj before 10.obj), per-vertex signals
    /// (--signals X.npy --mesh T, or PLY vertex properties with
    /// --property), or the authors' dataset file (a .pt with src_verts,
    /// tar_verts, faces; with one src_verts per target, the (source,
    /// target) pairs of the arbitrary-source model). Writes OUT/train (a dataset folder on the
    /// template that `mfm train` uses as it is) and, with --holdout,
    /// OUT/holdout (held-out signals on the template), OUT/reference (the
    /// same on another triangulation of its surface) and OUT/transfer.npy;
    /// OUT/import.json (what was read, the split, warnings) and
    /// OUT/preview.png. Signals stay in your units and place.
    Import(ImportArgs),
}

/// Arguments of `mfm dataset import`.
#[derive(Args)]
pub struct ImportArgs {
    /// Output folder (must not exist or be empty).
    #[arg(long)]
    out: PathBuf,
    /// Mesh files (OBJ, OFF, PLY, glTF/GLB), folders of them, or one
    /// authors' dataset file (.pt): every mesh one shape, all of the
    /// template's connectivity.
    #[arg(required_unless_present = "signals")]
    inputs: Vec<PathBuf>,
    /// The rest shape every input must match (vertex count and faces);
    /// default: the first input.
    #[arg(long, conflicts_with = "signals")]
    template: Option<PathBuf>,
    /// Held-out signals: a count (8), a percentage (12.5%) drawn with
    /// --seed, or every:K (inputs K-1, 2K-1, ...: every K-th frame of a
    /// sequence); whole pairs of an arbitrary-source file. Default: none.
    #[arg(long)]
    holdout: Option<String>,
    /// The reference mesh for the held-out signals: another triangulation
    /// of the template's surface, in its units and place (each vertex is
    /// located on the template by closest point). Default: the template
    /// with its x < centroid half refined twice.
    #[arg(long, requires = "holdout")]
    reference_mesh: Option<PathBuf>,
    /// A NumPy array [N, V] or [N, V, C] (float32/float64) of per-vertex
    /// signals on --mesh.
    #[arg(long, requires = "mesh", conflicts_with = "inputs")]
    signals: Option<PathBuf>,
    /// The mesh --signals lives on.
    #[arg(long, requires = "signals")]
    mesh: Option<crate::mesh::MeshSpec>,
    /// Read this PLY vertex property of every input as a signal channel
    /// instead of the positions (repeatable, in channel order).
    #[arg(long = "property")]
    properties: Vec<String>,
    /// With --signals: the 3 channels are values (colours...), not vertex
    /// positions.
    #[arg(long)]
    values: bool,
    /// Refuse input folders holding anything but mesh files (default:
    /// skip it, with a count).
    #[arg(long)]
    strict: bool,
    /// Turn each shape to face as the template does, its centroid kept:
    /// none (default), up:x|y|z (about that vertical axis: a performer
    /// turning around) or rigid (any rotation, Kabsch). Samples then face
    /// as the template does.
    #[arg(long, default_value = "none")]
    align: String,
    /// Seed of the held-out draw.
    #[arg(long, default_value_t = 0)]
    seed: u64,
}

/// What `mfm dataset deform` and `mfm dataset pairs` share: the pose
/// handles, the training mesh's size and the seed.
#[derive(Args)]
pub struct PoseArgs {
    /// Moving pose handles (the anchor comes on top).
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

impl PoseArgs {
    /// The normalized, coarse and evaluation meshes of the mesh `spec`,
    /// with the pose space on the normalized one.
    fn meshes_and_space(&self, spec: &MeshSpec) -> Result<(DeformMeshes, DeformSpace)> {
        let input = load_mesh_checked(spec)?;
        let meshes = DeformMeshes::from_mesh(&input, self.coarse_faces)
            .with_context(|| format!("preparing the meshes of {spec}"))?;
        let (h, r, a, s) = (self.handles, self.radius, self.max_angle, self.max_shift);
        let space = deformations::space_for(&meshes.original, h, r, a, s)
            .with_context(|| format!("placing {h} handles on {spec}"))?;
        Ok((meshes, space))
    }
}

/// Arguments of `mfm dataset pairs`.
#[derive(Args)]
pub struct PairsArgs {
    /// The template mesh (a file or builtin:NAME); default
    /// ../shared/meshes/alien.obj when it exists.
    #[arg(long)]
    mesh: Option<crate::mesh::MeshSpec>,
    /// Output folder (must not exist or be empty).
    #[arg(long)]
    out: PathBuf,
    /// Training shapes.
    #[arg(long, default_value_t = 40)]
    shapes: usize,
    /// Poses per shape (at least 2; each shape gives POSES x (POSES - 1)
    /// ordered pairs).
    #[arg(long, default_value_t = 4)]
    poses: usize,
    /// Held-out shapes (on the coarse mesh and on the evaluation mesh).
    #[arg(long, default_value_t = 8)]
    reference: usize,
    /// Shape regions scaled independently (one at the centroid, the others
    /// at extremities).
    #[arg(long, default_value_t = 6)]
    regions: usize,
    /// Largest log-scale of a region along an axis.
    #[arg(long, default_value_t = mfm_deform::shape::DEFAULT_MAX_REGION)]
    max_region_scale: f64,
    /// Largest log-scale of the whole shape along an axis.
    #[arg(long, default_value_t = mfm_deform::shape::DEFAULT_MAX_GLOBAL)]
    max_global_scale: f64,
    #[command(flatten)]
    pose: PoseArgs,
}

/// The template `mfm dataset pairs` uses without `--mesh`.
const DEFAULT_PAIRS_MESH: &str = "../shared/meshes/alien.obj";

/// Arguments of `mfm dataset deform`.
#[derive(Args)]
pub struct DeformArgs {
    /// The mesh to deform (a file or builtin:NAME), e.g.
    /// ../shared/meshes/elephant.obj.
    #[arg(long)]
    mesh: crate::mesh::MeshSpec,
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
    #[command(flatten)]
    pose: PoseArgs,
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
    mesh: Option<crate::mesh::MeshSpec>,
    /// Test mesh for the reference set (default: the training mesh with the
    /// half x < centroid refined twice).
    #[arg(long)]
    test_mesh: Option<crate::mesh::MeshSpec>,
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

/// Runs `mfm dataset ...`.
pub fn dataset(cmd: DatasetCommand) -> Result<()> {
    match cmd {
        DatasetCommand::Gmm(a) => dataset_gmm(a),
        DatasetCommand::Deform(a) => dataset_deform(a),
        DatasetCommand::Pairs(a) => dataset_pairs(a),
        DatasetCommand::Import(a) => dataset_import(a),
    }
}

/// Prints the vertex and face counts of the experiment's meshes.
fn print_meshes(meshes: &DeformMeshes, space: Option<&DeformSpace>) -> Result<()> {
    let all = [
        ("original", &meshes.original),
        ("coarse", &meshes.coarse),
        ("eval", &meshes.eval),
    ];
    for (role, m) in &all[usize::from(space.is_none())..] {
        let (v, f) = (m.num_vertices(), m.num_faces());
        let Some(space) = space else {
            println!("{role:>8} mesh: {v:>6} vertices, {f:>6} faces");
            continue;
        };
        let sizes: Vec<String> = space
            .handles
            .regions(m)?
            .iter()
            .map(|r| r.len().to_string())
            .collect();
        println!(
            "{role:>8} mesh: {v:>6} vertices, {f:>6} faces; handle vertices (anchor first): {}",
            sizes.join(", ")
        );
    }
    Ok(())
}

/// Runs `mfm dataset pairs`.
fn dataset_pairs(a: PairsArgs) -> Result<()> {
    if a.shapes == 0 {
        bail!("--shapes must be at least 1");
    }
    if a.poses < 2 {
        bail!("--poses must be at least 2 (a pair is two poses of one shape)");
    }
    let spec = match &a.mesh {
        Some(m) => m.clone(),
        None if Path::new(DEFAULT_PAIRS_MESH).is_file() => MeshSpec::from(DEFAULT_PAIRS_MESH),
        None => bail!(
            "no --mesh given and the default template {DEFAULT_PAIRS_MESH} is not here; \
             pass --mesh FILE or --mesh builtin:NAME"
        ),
    };
    let _lock = crate::output::claim_dataset_folder(&a.out)?;
    let t0 = std::time::Instant::now();
    let (meshes, poses) = a.pose.meshes_and_space(&spec)?;
    let mut family = ShapeFamily::auto(&meshes.original, a.regions)
        .with_context(|| format!("placing {} shape regions on {spec}", a.regions))?;
    family.max_region = a.max_region_scale;
    family.max_global = a.max_global_scale;
    let space = PairSpace {
        family,
        poses,
        poses_per_shape: a.poses,
    };
    space.validate()?;
    print_meshes(&meshes, None)?;
    PairsExperiment {
        meshes: &meshes,
        space: &space,
        source: &spec.to_string(),
        train: a.shapes,
        reference: a.reference,
        seed: a.pose.seed,
        progress: true,
    }
    .write(&a.out)?;
    println!(
        "wrote {} ({} training shapes x {} poses = {} pairs, {} held-out shapes) in {:.1} s",
        a.out.display(),
        a.shapes,
        a.poses,
        a.shapes * a.poses * (a.poses - 1),
        a.reference,
        t0.elapsed().as_secs_f64()
    );
    Ok(())
}

/// Runs `mfm dataset deform`.
fn dataset_deform(a: DeformArgs) -> Result<()> {
    if a.n == 0 {
        bail!("--n must be at least 1");
    }
    let _lock = crate::output::claim_dataset_folder(&a.out)?;
    let t0 = std::time::Instant::now();
    let (meshes, space) = a.pose.meshes_and_space(&a.mesh)?;
    print_meshes(&meshes, Some(&space))?;
    DeformExperiment {
        meshes: &meshes,
        space: &space,
        source: &a.mesh.to_string(),
        train: a.n,
        reference: a.reference,
        seed: a.pose.seed,
        progress: true,
    }
    .write(&a.out)?;
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
    let distance = if a.euclidean {
        GmmDistance::Euclidean
    } else {
        GmmDistance::Geodesic
    };
    let config = GmmConfig {
        bumps: a.bumps,
        sigma: a.sigma,
        min_separation: a.min_separation,
        distance,
        ..GmmConfig::default()
    };
    config.validate()?;
    if a.n == 0 {
        bail!("--n must be at least 1");
    }
    let _lock = crate::output::claim_dataset_folder(&a.out)?;
    let (train_mesh, test_mesh, source) = match (&a.mesh, &a.test_mesh) {
        (None, None) => {
            let m = GmmMeshes::builtin()?;
            (m.train, m.test, "builtin:blob".to_owned())
        }
        (Some(spec), None) => {
            let base = with_areas(load_mesh_checked(spec)?, "--mesh", spec)?;
            let m = GmmMeshes::from_base(base, Default::default())?;
            (m.train, m.test, spec.to_string())
        }
        (Some(spec), Some(test)) => (
            with_areas(load_mesh_checked(spec)?, "--mesh", spec)?,
            with_areas(load_mesh_checked(test)?, "--test-mesh", test)?,
            spec.to_string(),
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
    let t0 = std::time::Instant::now();
    let progress = GenerateOptions {
        progress_bar: true,
        on_progress: None,
    };
    GmmExperiment {
        config: &config,
        train_mesh: &train_mesh,
        test_mesh: &test_mesh,
        source: &source,
        train: a.n,
        reference: a.reference,
        seed: a.seed,
    }
    .write(&a.out, &progress)?;
    println!(
        "wrote {} ({} training signals, {} reference) in {:.1} s",
        a.out.display(),
        a.n,
        a.reference,
        t0.elapsed().as_secs_f64()
    );
    Ok(())
}

/// `mesh` (given to `flag` as `spec`) when every face has an area: the
/// GMM bumps' geodesic distances need one; else the error naming the file
/// and its first degenerate face.
fn with_areas(
    mesh: mfm_geometry::TriMesh,
    flag: &str,
    spec: &MeshSpec,
) -> Result<mfm_geometry::TriMesh> {
    let bad = mfm_geometry::operators::degenerate_faces(&mesh);
    if let Some(first) = bad.first() {
        bail!(
            "{flag} {spec}: {} degenerate face{} (zero area), e.g. face {first}: the GMM bumps' \
             geodesic distances need every face to have an area (`mfm info {spec}` lists the \
             mesh's problems)",
            bad.len(),
            if bad.len() == 1 { "" } else { "s" }
        );
    }
    Ok(mesh)
}

/// Runs `mfm dataset import`.
fn dataset_import(a: ImportArgs) -> Result<()> {
    use mfm_data::import::authors::read_authors_dataset;
    use mfm_data::import::inputs::list_mesh_files;
    use mfm_data::import::sources::{MeshFiles, NpyRows, PairedShapes};
    use mfm_data::import::{Align, Holdout, ImportExperiment, SignalFiles};
    let holdout: Holdout = match &a.holdout {
        Some(h) => h.parse()?,
        None => Holdout::None,
    };
    let align: Align = a.align.parse()?;
    let is_torch = |p: &Path| {
        p.extension()
            .and_then(|e| e.to_str())
            .is_some_and(|e| e.eq_ignore_ascii_case("pt") || e.eq_ignore_ascii_case("pth"))
    };
    let mut inputs_read: Vec<PathBuf> = a.inputs.clone();
    inputs_read.extend(a.template.clone());
    inputs_read.extend(a.signals.clone());
    inputs_read.extend(a.reference_mesh.clone());
    inputs_read.extend(
        a.mesh
            .as_ref()
            .and_then(crate::mesh::mesh_path)
            .map(Path::to_path_buf),
    );
    mfm_files::Outputs::new()
        .inputs(&inputs_read)
        .folder(&a.out)
        .check()?;
    let _lock = crate::output::claim_dataset_folder(&a.out)?;
    let mut skipped = 0;
    let mut paired = false;
    let (template, template_name, source): (mfm_geometry::TriMesh, String, Box<dyn SignalFiles>) =
        if let Some(array) = &a.signals {
            let Some(spec) = a.mesh.as_ref() else {
                bail!("--signals needs --mesh: the mesh the signals live on");
            };
            let mesh = load_mesh_checked(spec)?;
            let rows = NpyRows::open(array, false)?;
            let positions = rows.channels() == 3 && !a.values;
            let rows = NpyRows::open(array, positions)?;
            if rows.num_vertices() != mesh.num_vertices() {
                bail!(
                    "{}: rows have {} vertices, but --mesh {spec} has {}",
                    array.display(),
                    rows.num_vertices(),
                    mesh.num_vertices()
                );
            }
            (mesh, spec.to_string(), Box::new(rows))
        } else if a.inputs.len() == 1 && is_torch(&a.inputs[0]) {
            let path = &a.inputs[0];
            if !a.properties.is_empty() {
                bail!(
                    "--property reads PLY files; {} is a torch file",
                    path.display()
                );
            }
            let data = read_authors_dataset(path)?;
            let name = format!("{}:src_verts", path.display());
            match data.sources {
                // the arbitrary-source format: one source per target
                Some(sources) => {
                    paired = true;
                    let name = format!("{name}[0]");
                    let pairs = PairedShapes::new(sources, data.targets)?;
                    (data.template, name, Box::new(pairs))
                }
                None => (data.template, name, Box::new(data.targets)),
            }
        } else {
            if let Some(p) = a.inputs.iter().find(|p| is_torch(p)) {
                bail!(
                    "{}: an authors' dataset file is imported alone (one .pt input)",
                    p.display()
                );
            }
            let list = list_mesh_files(&a.inputs, a.strict)?;
            skipped = list.skipped.len();
            if skipped > 0 {
                eprintln!(
                    "warning: skipped {skipped} entr{} of the input folders that are not mesh files \
                     (first: {}; --strict refuses them)",
                    if skipped == 1 { "y" } else { "ies" },
                    list.skipped[0].display()
                );
            }
            let template_path = a.template.clone().unwrap_or_else(|| list.files[0].clone());
            let spec = template_path.display().to_string();
            let template = load_mesh_checked(&MeshSpec::from(template_path.into_os_string()))?;
            let files = MeshFiles {
                files: list.files,
                properties: a.properties.clone(),
            };
            (template, spec, Box::new(files))
        };
    let reference = match &a.reference_mesh {
        Some(p) => {
            let spec = p.display().to_string();
            Some((
                load_mesh_checked(&MeshSpec::from(p.clone().into_os_string()))?,
                spec,
            ))
        }
        None => None,
    };
    if paired {
        println!(
            "template {template_name}: {} vertices, {} faces; {} (source, target) pairs",
            template.num_vertices(),
            template.num_faces(),
            source.len() / 2
        );
    } else {
        println!(
            "template {template_name}: {} vertices, {} faces; {} signal{} of {} channel{}",
            template.num_vertices(),
            template.num_faces(),
            source.len(),
            if source.len() == 1 { "" } else { "s" },
            source.channels(),
            if source.channels() == 1 { "" } else { "s" }
        );
    }
    let summary = ImportExperiment {
        source: source.as_ref(),
        template: &template,
        template_name: &template_name,
        holdout,
        reference_mesh: reference.as_ref().map(|(m, s)| (m, s.as_str())),
        seed: a.seed,
        align,
        pairs: paired,
        skipped,
        progress: true,
    }
    .write(&a.out)
    .with_context(|| format!("importing into {}", a.out.display()))?;
    for w in &summary.warnings {
        eprintln!("warning: {w}");
    }
    if let (Some([v, f]), Some(name)) = (summary.reference_size, &summary.reference_mesh) {
        println!("reference mesh ({name}): {v} vertices, {f} faces");
    }
    if paired {
        println!(
            "wrote {} ({} training pairs, {} held out) in {:.1} s; train the arbitrary-source \
             model on {}/train (`mfm train --mode predictor`, then `--mode arbitrary`)",
            a.out.display(),
            summary.train / 2,
            summary.held_out / 2,
            summary.seconds,
            a.out.display()
        );
    } else {
        println!(
            "wrote {} ({} training, {} held out) in {:.1} s",
            a.out.display(),
            summary.train,
            summary.held_out,
            summary.seconds
        );
    }
    Ok(())
}
