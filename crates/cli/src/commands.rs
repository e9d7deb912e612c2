//! The subcommands.

use crate::mesh_arg::{load_mesh, load_mesh_checked, mesh_path};
use crate::output::{prepare_outputs, write_json, write_matrix_market, write_npy};
use anyhow::{Context, Result, bail};
use clap::{Subcommand, ValueEnum};
use mfm_geometry::{MeshReport, operators};
use std::path::PathBuf;

/// Every `mfm` subcommand.
#[derive(Subcommand)]
pub enum Command {
    /// Print a report of a mesh: counts, topology, area, quality, problems found.
    Info {
        /// Mesh file or builtin:NAME.
        mesh: String,
        /// Print the report as JSON.
        #[arg(long)]
        json: bool,
    },
    /// Write the mesh operators: L.mtx, G.mtx (Matrix Market), mass.npy,
    /// face_areas.npy and summary.json (with Gamma = ||M^-1 L||_F).
    Operators {
        /// Mesh file or builtin:NAME.
        mesh: String,
        /// Output folder (created if missing).
        #[arg(long)]
        out: PathBuf,
    },
    /// Convert a mesh to OBJ or PLY (by the output extension).
    Convert {
        /// Mesh file or builtin:NAME.
        mesh: String,
        /// Output file, .obj or .ply.
        out: PathBuf,
    },
    /// Render a mesh to PNG, optionally colored by a per-vertex scalar.
    Render {
        /// Mesh file or builtin:NAME.
        mesh: String,
        /// Output PNG.
        #[arg(long)]
        out: PathBuf,
        /// Color by a built-in per-vertex quantity.
        #[arg(long, value_enum, conflicts_with = "scalars")]
        scalar: Option<Quantity>,
        /// Color by values from a .npy file with one value per vertex.
        #[arg(long)]
        scalars: Option<PathBuf>,
        /// Image width and height in pixels.
        #[arg(long, default_value_t = 800)]
        size: u32,
    },
    /// The K smallest eigenpairs of L phi = lambda M phi: eigenvalues.npy (K
    /// values), eigenvectors.npy (V x K, M-orthonormal columns), summary.json.
    Eigs {
        /// Mesh file or builtin:NAME.
        mesh: String,
        /// Number of eigenpairs.
        #[arg(long, default_value_t = 64)]
        k: usize,
        /// Output folder (created if missing).
        #[arg(long)]
        out: PathBuf,
    },
    /// Sample noise on a mesh: OUT.npy [samples, vertices, channels] (f64),
    /// OUT.json (parameters, Gamma, mean energy) and optionally a PNG of the
    /// first sample.
    Noise {
        /// Mesh file or builtin:NAME.
        mesh: String,
        #[command(flatten)]
        kind: crate::spectral::KindArgs,
        /// Number of samples.
        #[arg(long, default_value_t = 1)]
        samples: usize,
        /// Channels per sample (e.g. 3 for xyz).
        #[arg(long, default_value_t = 1)]
        channels: usize,
        /// Seed: the same seed gives bit-identical samples on any thread count.
        #[arg(long, default_value_t = 0)]
        seed: u64,
        /// Output .npy file.
        #[arg(long)]
        out: PathBuf,
        /// Render the first sample's first channel to this PNG.
        #[arg(long)]
        png: Option<PathBuf>,
    },
    /// Spectral statistics of noise on one or several meshes: per-frequency
    /// variance against theory, independence, energy, and (from the second
    /// mesh on) per-frequency W2 against the first mesh.
    Spectrum {
        /// Mesh files or builtin:NAME (several triangulations of one surface
        /// to compare them).
        #[arg(required = true)]
        meshes: Vec<String>,
        #[command(flatten)]
        kind: crate::spectral::KindArgs,
        /// Samples per mesh.
        #[arg(long, default_value_t = 2000)]
        samples: usize,
        /// Eigenpairs (frequencies) per mesh.
        #[arg(long, default_value_t = 64)]
        k: usize,
        /// Seed.
        #[arg(long, default_value_t = 0)]
        seed: u64,
        /// JSON report.
        #[arg(long)]
        out: PathBuf,
        /// Folder for PNG plots (variance vs eigenvalue, coefficient histograms).
        #[arg(long)]
        plots: Option<PathBuf>,
        /// Frequencies whose coefficient histograms are plotted.
        #[arg(long, value_delimiter = ',', default_value = "2,10,50")]
        coefficients: Vec<usize>,
    },
    /// Generate a dataset of signals over a mesh.
    #[command(subcommand)]
    Dataset(crate::dataset::DatasetCommand),
    /// Train a flow-matching model on a dataset (checkpoints, resumable;
    /// Ctrl-C writes a checkpoint).
    #[cfg(feature = "network")]
    Train(crate::flow::TrainArgs),
    /// Train a flow-matching model (needs the `network` feature).
    #[cfg(not(feature = "network"))]
    Train(crate::unavailable::Unavailable),
    /// Generate signals with a trained run on any triangulation of the
    /// training surface.
    #[cfg(feature = "network")]
    Sample(crate::flow::SampleArgs),
    /// Generate signals with a trained run (needs the `network` feature).
    #[cfg(not(feature = "network"))]
    Sample(crate::unavailable::Unavailable),
    /// Metrics of generated samples against a reference dataset: MMD, COV,
    /// 1-NNA, GMM test error.
    Eval(crate::eval::EvalArgs),
    /// Evaluate an arbitrary-source run on the held-out shapes of a pairs
    /// experiment (`mfm dataset pairs` OUT): projection onto each source's
    /// own deformation space, displacement, pose spread, MMD/COV, the
    /// predictor's error; on OUT/holdout (the template's triangulation) and
    /// OUT/reference (another triangulation), with pictures.
    #[cfg(feature = "network")]
    EvalArbitrary(crate::arbitrary::EvalArgs),
    /// Evaluate an arbitrary-source run (needs the `network` feature).
    #[cfg(not(feature = "network"))]
    EvalArbitrary(crate::unavailable::Unavailable),
    /// PoissonNet: layer tables of the presets and training-step benchmarks.
    #[cfg(feature = "network")]
    #[command(subcommand)]
    Net(crate::net::NetCommand),
    /// PoissonNet tables and benchmarks (needs the `network` feature).
    #[cfg(not(feature = "network"))]
    Net(crate::unavailable::Unavailable),
    /// Another triangulation of a mesh's surface: midpoint subdivision, and
    /// damage (holes, a partial cut, edge flips) that spares the handle
    /// regions of a deformation space.
    Remesh(crate::remesh::RemeshArgs),
}

/// Per-vertex quantities `mfm render --scalar` can show.
#[derive(Clone, Copy, ValueEnum)]
pub enum Quantity {
    /// x coordinate.
    X,
    /// y coordinate.
    Y,
    /// z coordinate.
    Z,
    /// Lumped (barycentric) vertex mass.
    Mass,
}

/// Runs one subcommand.
pub fn run(cmd: Command) -> Result<()> {
    match cmd {
        Command::Info { mesh, json } => info(&mesh, json),
        Command::Operators { mesh, out } => write_operators(&mesh, &out),
        Command::Convert { mesh, out } => convert(&mesh, &out),
        Command::Render {
            mesh,
            out,
            scalar,
            scalars,
            size,
        } => render_png(&mesh, &out, scalar, scalars.as_deref(), size),
        Command::Eigs { mesh, k, out } => crate::spectral::eigs(&mesh, k, &out),
        Command::Noise {
            mesh,
            kind,
            samples,
            channels,
            seed,
            out,
            png,
        } => crate::spectral::noise(&mesh, &kind, samples, channels, seed, &out, png.as_deref()),
        Command::Spectrum {
            meshes,
            kind,
            samples,
            k,
            seed,
            out,
            plots,
            coefficients,
        } => crate::spectral::spectrum(&crate::spectral::SpectrumArgs {
            meshes: &meshes,
            kind: kind.to_kind()?,
            samples,
            k,
            seed,
            out: &out,
            plots: plots.as_deref(),
            coefficients: &coefficients,
        }),
        Command::Dataset(cmd) => crate::dataset::dataset(cmd),
        #[cfg(feature = "network")]
        Command::Train(args) => crate::flow::train(args),
        #[cfg(feature = "network")]
        Command::Sample(args) => crate::flow::sample(args),
        #[cfg(feature = "network")]
        Command::Net(cmd) => crate::net::run(cmd),
        #[cfg(not(feature = "network"))]
        Command::Train(_) => crate::unavailable::fail("train"),
        #[cfg(not(feature = "network"))]
        Command::Sample(_) => crate::unavailable::fail("sample"),
        #[cfg(not(feature = "network"))]
        Command::Net(_) => crate::unavailable::fail("net"),
        #[cfg(feature = "network")]
        Command::EvalArbitrary(args) => crate::arbitrary::eval(args),
        #[cfg(not(feature = "network"))]
        Command::EvalArbitrary(_) => crate::unavailable::fail("eval-arbitrary"),
        Command::Eval(args) => crate::eval::eval(args),
        Command::Remesh(args) => crate::remesh::run(args),
    }
}

fn info(spec: &str, json: bool) -> Result<()> {
    let mesh = load_mesh(spec)?;
    let report = MeshReport::new(&mesh);
    if json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        print!("{report}");
    }
    Ok(())
}

#[derive(serde::Serialize)]
struct OperatorSummary {
    mesh: String,
    vertices: usize,
    faces: usize,
    laplacian_nonzeros: usize,
    gradient_nonzeros: usize,
    total_area: f64,
    gamma: f64,
    files: Vec<&'static str>,
    conventions: &'static str,
}

/// The files `mfm operators` writes into its folder.
const OPERATOR_FILES: [&str; 5] = [
    "L.mtx",
    "G.mtx",
    "mass.npy",
    "face_areas.npy",
    "summary.json",
];

fn write_operators(spec: &str, out: &std::path::Path) -> Result<()> {
    let outputs: Vec<PathBuf> = OPERATOR_FILES.iter().map(|f| out.join(f)).collect();
    let mesh = load_mesh_checked(spec)?;
    let ops = operators::Operators::new(&mesh)
        .with_context(|| format!("{spec}: cannot build operators"))?;
    let undo = prepare_outputs(&[mesh_path(spec)], &outputs)?;
    write_matrix_market(&out.join("L.mtx"), &ops.laplacian)?;
    write_matrix_market(&out.join("G.mtx"), &ops.gradient)?;
    write_npy(&out.join("mass.npy"), &ops.mass, &[ops.mass.len() as u64])?;
    write_npy(
        &out.join("face_areas.npy"),
        &ops.face_areas,
        &[ops.face_areas.len() as u64],
    )?;
    let gamma = operators::gamma(&ops.laplacian, &ops.mass);
    let summary = OperatorSummary {
        mesh: spec.to_owned(),
        vertices: mesh.num_vertices(),
        faces: mesh.num_faces(),
        laplacian_nonzeros: ops.laplacian.val().len(),
        gradient_nonzeros: ops.gradient.val().len(),
        total_area: ops.face_areas.iter().sum(),
        gamma,
        files: OPERATOR_FILES[..4].to_vec(),
        conventions: "L: cotangent Laplacian, positive semi-definite (libigl cotmatrix negated); \
mass: lumped barycentric; G: 2F x V intrinsic gradient, rows 2f,2f+1 in a per-face orthonormal frame; \
gamma = ||M^-1 L||_F",
    };
    write_json(&out.join("summary.json"), &summary)?;
    undo.keep();
    println!(
        "wrote L.mtx ({} nnz), G.mtx ({} nnz), mass.npy, face_areas.npy, summary.json to {}; Gamma = {:.6e}",
        summary.laplacian_nonzeros,
        summary.gradient_nonzeros,
        out.display(),
        gamma
    );
    Ok(())
}

fn convert(spec: &str, out: &std::path::Path) -> Result<()> {
    let mesh = load_mesh(spec)?;
    let undo = prepare_outputs(&[mesh_path(spec)], &[out.to_path_buf()])?;
    mfm_meshio::write_mesh(out, &mesh)?;
    undo.keep();
    println!(
        "wrote {} ({} vertices, {} faces)",
        out.display(),
        mesh.num_vertices(),
        mesh.num_faces()
    );
    Ok(())
}

fn render_png(
    spec: &str,
    out: &std::path::Path,
    scalar: Option<Quantity>,
    scalars: Option<&std::path::Path>,
    size: u32,
) -> Result<()> {
    if !(16..=8192).contains(&size) {
        bail!("--size {size}: expected 16..=8192 pixels");
    }
    let undo = prepare_outputs(&[mesh_path(spec), scalars], &[out.to_path_buf()])?;
    let mesh = load_mesh(spec)?;
    let values: Option<Vec<f64>> = match (scalar, scalars) {
        (Some(q), _) => Some(match q {
            Quantity::X => mesh.positions().iter().map(|p| p[0]).collect(),
            Quantity::Y => mesh.positions().iter().map(|p| p[1]).collect(),
            Quantity::Z => mesh.positions().iter().map(|p| p[2]).collect(),
            Quantity::Mass => operators::lumped_mass(&mesh),
        }),
        (None, Some(path)) => Some(read_vertex_scalars(path, mesh.num_vertices())?),
        (None, None) => None,
    };
    let opts = mfm_render::RenderOptions {
        width: size,
        height: size,
        colorbar: values.is_some(),
        ..Default::default()
    };
    let img = mfm_render::render_mesh(&mesh, values.as_deref(), &opts)?;
    mfm_render::save_png(&img, out)?;
    undo.keep();
    println!("wrote {}", out.display());
    Ok(())
}

fn read_vertex_scalars(path: &std::path::Path, n: usize) -> Result<Vec<f64>> {
    let a = mfm_files::npy::read::<f64>(path)?;
    if a.values.len() != n {
        bail!(
            "{}: expected {n} values (one per vertex), found shape {:?}",
            path.display(),
            a.shape
        );
    }
    Ok(a.values)
}
