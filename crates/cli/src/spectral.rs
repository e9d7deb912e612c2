//! `mfm eigs`, `mfm noise`, `mfm spectrum`: eigenpairs, noise samples and
//! their spectral statistics.

use crate::mesh_arg::{load_mesh_checked, mesh_path};
use crate::output::{prepare_outputs, write_json, write_npy};
use anyhow::{Context, Result, bail};
use indicatif::{ProgressBar, ProgressStyle};
use mfm_geometry::operators::Operators;
use mfm_noise::spectrum::{MeshSpectrum, SpectrumFile, compare};
use mfm_noise::stream;
use mfm_noise::{NoiseKind, NoiseSampler, SpectralAnalyzer, SpectrumComparison};
use mfm_render::plots::{self, HistogramPanel, VarianceSeries};
use mfm_render::{ColorRange, Colormap, RenderOptions, render_mesh, save_png};
use mfm_solver::{EigenOptions, generalized_eigenpairs};
use std::path::Path;
use std::time::Instant;

#[derive(serde::Serialize)]
struct EigsSummary {
    mesh: String,
    vertices: usize,
    k: usize,
    method: String,
    seconds: f64,
    eigenvalues: Vec<f64>,
    files: [&'static str; 2],
    conventions: &'static str,
}

/// Computes the `k` smallest eigenpairs of `L phi = lambda M phi` and writes
/// `eigenvalues.npy` `[k]`, `eigenvectors.npy` `[V, k]` (row-major, columns
/// `M`-orthonormal) and `summary.json` into `out`.
pub fn eigs(spec: &str, k: usize, out: &Path) -> Result<()> {
    if k == 0 {
        bail!("--k must be at least 1");
    }
    let mesh = load_mesh_checked(spec)?;
    let n = mesh.num_vertices();
    if k > n {
        bail!("{spec}: --k {k} exceeds the vertex count {n}");
    }
    let outputs: Vec<std::path::PathBuf> = ["eigenvalues.npy", "eigenvectors.npy", "summary.json"]
        .iter()
        .map(|f| out.join(f))
        .collect();
    let undo = prepare_outputs(&[mesh_path(spec)], &outputs)?;
    let ops = Operators::new(&mesh).with_context(|| format!("{spec}: cannot build operators"))?;
    let start = Instant::now();
    let pairs = generalized_eigenpairs(&ops.laplacian, &ops.mass, k, &EigenOptions::default())
        .with_context(|| format!("{spec}: eigensolve failed"))?;
    let seconds = start.elapsed().as_secs_f64();
    let mut vectors = Vec::with_capacity(n * k);
    for v in 0..n {
        for j in 0..k {
            vectors.push(pairs.vectors[(v, j)]);
        }
    }
    write_npy(&out.join("eigenvalues.npy"), &pairs.values, &[k as u64])?;
    write_npy(
        &out.join("eigenvectors.npy"),
        &vectors,
        &[n as u64, k as u64],
    )?;
    let summary = EigsSummary {
        mesh: spec.to_owned(),
        vertices: n,
        k,
        method: format!("{:?}", pairs.info.method),
        seconds,
        eigenvalues: pairs.values.clone(),
        files: ["eigenvalues.npy", "eigenvectors.npy"],
        conventions: "L phi = lambda M phi with L the PSD cotangent Laplacian and M the lumped mass; \
eigenvalues ascending; eigenvectors are the columns of the [V, k] array, phi^T M phi = 1",
    };
    write_json(&out.join("summary.json"), &summary)?;
    undo.keep();
    println!(
        "{k} eigenpairs of {spec} ({n} vertices) in {seconds:.2} s ({:?}); lambda in [{:.4e}, {:.4e}]; wrote {}",
        pairs.info.method,
        pairs.values[0],
        pairs.values[k - 1],
        out.display()
    );
    Ok(())
}

/// The noise kinds of `mfm noise --kind` (parameters come from `--tau`,
/// `--c` and `--k`).
#[derive(Clone, Copy, Debug, clap::ValueEnum)]
pub enum KindName {
    /// Matérn: solve `(L + tau M) f = M^1/2 n` (uses `--tau`).
    Matern,
    /// Scale-normalized Matérn: `tau = c Gamma`, output times `sqrt(Gamma)` (uses `--c`).
    MaternNormalized,
    /// Discrete white noise `M^-1/2 n`.
    White,
    /// iid `N(0, 1)` per vertex (mesh dependent; a baseline).
    Naive,
    /// Matérn spectrum truncated to the `k` lowest eigenpairs (uses `--k`, `--tau`).
    Explicit,
}

/// Noise parameters shared by `mfm noise` and `mfm spectrum`: the grammar
/// of `mfm train --noise` (`--noise matern:100`), or the same spelled out
/// (`--kind matern --tau 100`).
#[derive(clap::Args, Clone, Debug)]
pub struct KindArgs {
    /// Noise, as for `mfm train --noise`: matern or matern:TAU,
    /// matern-normalized:C, white, naive, explicit:K or explicit:K:TAU.
    #[arg(long, conflicts_with_all = ["kind", "tau", "c", "k_noise"])]
    pub noise: Option<NoiseKind>,
    /// Noise kind (the long form of --noise; parameters from --tau, --c, --k-noise).
    #[arg(long, value_enum, default_value = "matern")]
    pub kind: KindName,
    /// Screening weight of matern and explicit (1/length^2; default 100; 0 = no screening).
    #[arg(long)]
    pub tau: Option<f64>,
    /// Dimensionless factor of matern-normalized (tau = c Gamma; default 1e-4).
    #[arg(long)]
    pub c: Option<f64>,
    /// Number of eigenpairs of explicit noise (default 64).
    #[arg(long = "k-noise", value_name = "K")]
    pub k_noise: Option<usize>,
}

impl KindArgs {
    /// The [`NoiseKind`] these flags describe ([`NoiseKind::from_parts`]
    /// for the long form); flags that the kind does not use are an error
    /// rather than silently ignored.
    pub fn to_kind(&self) -> Result<NoiseKind> {
        if let Some(kind) = self.noise {
            return Ok(kind);
        }
        let name = match self.kind {
            KindName::Matern => mfm_noise::KindName::Matern,
            KindName::MaternNormalized => mfm_noise::KindName::MaternNormalized,
            KindName::White => mfm_noise::KindName::White,
            KindName::Naive => mfm_noise::KindName::Naive,
            KindName::Explicit => mfm_noise::KindName::Explicit,
        };
        NoiseKind::from_parts(name, self.tau, self.c, self.k_noise).map_err(|e| match e {
            // the library names the parameter; the user typed its flag
            mfm_noise::NoiseError::UnusedParameter {
                kind,
                parameter,
                hint,
            } => {
                let flag = if parameter == "k" {
                    "k-noise"
                } else {
                    parameter
                };
                anyhow::anyhow!("--{flag} does not apply to --kind {kind}{hint}")
            }
            e => e.into(),
        })
    }
}

fn progress(total: u64, what: &str) -> ProgressBar {
    let bar = ProgressBar::new(total);
    bar.set_style(
        ProgressStyle::with_template("{msg} [{bar:30}] {pos}/{len} samples ({eta} left)")
            .unwrap_or_else(|_| ProgressStyle::default_bar())
            .progress_chars("=> "),
    );
    bar.set_message(what.to_owned());
    bar
}

#[derive(serde::Serialize)]
struct NoiseSummary<'a> {
    mesh: &'a str,
    kind: NoiseKind,
    samples: usize,
    vertices: usize,
    channels: usize,
    seed: u64,
    gamma: f64,
    tau: Option<f64>,
    layout: &'static str,
    mean_energy: f64,
}

/// `mfm noise`: writes `[N, V, C]` noise samples as `.npy` (f64), a JSON
/// summary beside it, and optionally a PNG of the first sample's first channel.
pub fn noise(
    spec: &str,
    kind: &KindArgs,
    samples: usize,
    channels: usize,
    seed: u64,
    out: &Path,
    png: Option<&Path>,
) -> Result<()> {
    if samples == 0 || channels == 0 {
        bail!("--samples and --channels must be at least 1");
    }
    let kind = kind.to_kind()?;
    if out
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("json"))
    {
        bail!(
            "--out {}: the samples go to --out and their JSON summary beside it with the extension .json; give --out a .npy name",
            out.display()
        );
    }
    let json = out.with_extension("json");
    let mut outputs = vec![out.to_path_buf(), json.clone()];
    outputs.extend(png.map(Path::to_path_buf));
    let mesh = load_mesh_checked(spec)?;
    let v = mesh.num_vertices();
    let shape = [samples as u64, v as u64, channels as u64];
    let bytes = mfm_files::npy::file_bytes(&shape, 8);
    let undo = prepare_outputs(&[mesh_path(spec)], &outputs)?;
    mfm_files::space::ensure_space(out, bytes).with_context(|| {
        format!("{samples} samples x {v} vertices x {channels} channels of f64")
    })?;
    let start = Instant::now();
    let sampler = NoiseSampler::new(&mesh, kind)
        .with_context(|| format!("{spec}: cannot set up {kind} noise"))?;
    let setup = start.elapsed().as_secs_f64();
    // Streamed to disk a chunk at a time: memory stays at one chunk whatever
    // the output's size.
    let bar = progress(samples as u64, "sampling");
    let written = stream::write_npy(&sampler, out, samples, channels, seed, |done| {
        bar.set_position(done as u64)
    })?;
    bar.finish_and_clear();
    let mean_energy = written.mean_energy;
    let summary = NoiseSummary {
        mesh: spec,
        kind,
        samples,
        vertices: v,
        channels,
        seed,
        gamma: sampler.gamma(),
        tau: sampler.tau(),
        layout: "[samples, vertices, channels], row-major f64",
        mean_energy,
    };
    write_json(&json, &summary)?;
    println!(
        "{samples} x {channels} {kind} samples on {spec} ({v} vertices; setup {setup:.3} s, total {:.3} s); \
mean f^T M f = {mean_energy:.4e}; wrote {} and {}",
        start.elapsed().as_secs_f64(),
        out.display(),
        json.display()
    );
    if let Some(png) = png {
        let opts = RenderOptions {
            width: 800,
            height: 800,
            colorbar: true,
            colormap: Colormap::CoolWarm,
            range: ColorRange::Symmetric,
            ..Default::default()
        };
        let img = render_mesh(&mesh, Some(&written.first_signal), &opts)?;
        save_png(&img, png)?;
        println!("wrote {}", png.display());
    }
    undo.keep();
    Ok(())
}

/// Options of `mfm spectrum`.
pub struct SpectrumArgs<'a> {
    /// Mesh specs (files or builtins), at least one.
    pub meshes: &'a [String],
    /// Noise kind.
    pub kind: NoiseKind,
    /// Samples per mesh.
    pub samples: usize,
    /// Eigenpairs per mesh.
    pub k: usize,
    /// Seed.
    pub seed: u64,
    /// Report path.
    pub out: &'a Path,
    /// Folder for PNG plots.
    pub plots: Option<&'a Path>,
    /// Frequencies whose coefficient histograms are plotted.
    pub coefficients: &'a [usize],
}

/// `mfm spectrum`: per-frequency statistics of noise on one or several
/// meshes, as JSON (and PNG plots).
pub fn spectrum(args: &SpectrumArgs<'_>) -> Result<()> {
    if args.meshes.is_empty() {
        bail!("give at least one mesh");
    }
    if args.samples < 2 || args.k == 0 {
        bail!("--samples must be at least 2 and --k at least 1");
    }
    let mut outputs = vec![args.out.to_path_buf()];
    if let Some(dir) = args.plots {
        outputs.push(dir.join("variance.png"));
        outputs.push(dir.join("coefficients.png"));
    }
    let inputs: Vec<Option<&Path>> = args.meshes.iter().map(|m| mesh_path(m)).collect();
    let undo = prepare_outputs(&inputs, &outputs)?;
    let mut meshes = Vec::new();
    let mut series = Vec::new();
    let mut histograms: Vec<Vec<(String, Vec<f64>)>> = vec![Vec::new(); args.coefficients.len()];
    for spec in args.meshes {
        let mesh = load_mesh_checked(spec)?;
        let v = mesh.num_vertices();
        if args.k > v {
            bail!("{spec}: --k {} exceeds the vertex count {v}", args.k);
        }
        let sampler = NoiseSampler::new(&mesh, args.kind)
            .with_context(|| format!("{spec}: cannot set up {} noise", args.kind))?;
        let ops =
            Operators::new(&mesh).with_context(|| format!("{spec}: cannot build operators"))?;
        let pairs = mfm_noise::spectrum::eigenpairs(&ops.laplacian, &ops.mass, args.k)
            .with_context(|| format!("{spec}: eigensolve failed"))?;
        let theory = sampler.theory(&pairs)?;
        let mut analyzer = SpectralAnalyzer::new(&pairs, &ops.mass)?.keep(args.coefficients);
        let bar = progress(args.samples as u64, spec);
        stream::for_each_chunk(
            &sampler,
            args.samples,
            1,
            args.seed,
            stream::CHUNK,
            |batch, first| {
                analyzer.add(batch)?;
                bar.set_position((first + batch.samples()) as u64);
                Ok(())
            },
        )?;
        bar.finish_and_clear();
        let report = analyzer.report(Some(&theory))?;
        println!(
            "{spec}: {v} vertices, {} samples, {} frequencies; largest |Var/theory - 1| = {:.3}; \
max |corr| = {:.3} (sampling level {:.3}); mean f^T M f = {:.4e}",
            args.samples,
            args.k,
            report.max_relative_error.unwrap_or(f64::NAN),
            report.independence.max_abs_correlation,
            report.independence.reference,
            report.mean_energy
        );
        for (slot, &i) in histograms.iter_mut().zip(args.coefficients) {
            if let Some(c) = analyzer.coefficients(i) {
                slot.push((spec.clone(), c.to_vec()));
            }
        }
        series.push(VarianceSeries::new(
            spec.clone(),
            &report.eigenvalues,
            &report.variance,
            report.theory.as_deref(),
        ));
        meshes.push(MeshSpectrum {
            mesh: spec.clone(),
            vertices: v,
            gamma: sampler.gamma(),
            report,
        });
    }
    let comparisons: Vec<SpectrumComparison> = meshes
        .iter()
        .skip(1)
        .map(|m| compare(&meshes[0].report, &m.report))
        .collect();
    for (m, c) in meshes.iter().skip(1).zip(&comparisons) {
        println!(
            "{} vs {}: max W2 = {:.3e}, max |std ratio - 1| = {:.3}",
            m.mesh, meshes[0].mesh, c.max_w2, c.max_relative_std_difference
        );
    }
    write_json(
        args.out,
        &SpectrumFile {
            kind: args.kind,
            samples: args.samples,
            k: args.k,
            seed: args.seed,
            meshes,
            comparisons,
        },
    )?;
    println!("wrote {}", args.out.display());
    if let Some(dir) = args.plots {
        let variance = dir.join("variance.png");
        plots::variance_plot(
            &variance,
            &format!("Var(c_i), {} noise", args.kind),
            &series,
        )?;
        println!("wrote {}", variance.display());
        let panels: Vec<HistogramPanel> = args
            .coefficients
            .iter()
            .zip(histograms)
            .filter(|(_, s)| !s.is_empty())
            .map(|(i, series)| HistogramPanel {
                title: format!("c_{i}"),
                series,
                bins: 40,
            })
            .collect();
        if !panels.is_empty() {
            let hist = dir.join("coefficients.png");
            plots::coefficient_histograms(&hist, &panels)?;
            println!("wrote {}", hist.display());
        }
    }
    undo.keep();
    Ok(())
}
