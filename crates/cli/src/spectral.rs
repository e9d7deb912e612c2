//! `mfm eigs`, `mfm noise`, `mfm spectrum`: eigenpairs, noise samples and
//! their spectral statistics.

use crate::mesh::{load_mesh_checked, mesh_path};
use crate::output::prepare_outputs;
use anyhow::{Context, Result, bail};
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use mfm_geometry::operators::Operators;
use mfm_noise::spectrum::{MeshSpectrum, SpectrumFile, SpectrumRequest};
use mfm_noise::stream;
use mfm_noise::{KindName, KindParameters, NoiseError, NoiseKind, NoiseSampler};
use mfm_render::plots::{self, HistogramPanel, VarianceSeries};
use mfm_render::{ColorRange, Colormap, RenderOptions, render_mesh, save_png};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Arguments of `mfm eigs`.
#[derive(Args)]
pub struct EigsArgs {
    /// Mesh file or builtin:NAME.
    mesh: crate::mesh::MeshSpec,
    /// Number of eigenpairs.
    #[arg(long, default_value_t = 64)]
    k: usize,
    /// Output folder (created if missing).
    #[arg(long)]
    out: PathBuf,
}

impl EigsArgs {
    /// Writes the eigenpair folder ([`mfm_meshio::export::write_eigen_folder`]).
    pub fn run(self) -> Result<()> {
        let (spec, k) = (&self.mesh, self.k);
        if k == 0 {
            bail!("--k must be at least 1");
        }
        let mesh = load_mesh_checked(spec)?;
        let n = mesh.num_vertices();
        if k > n {
            bail!("{spec}: --k {k} exceeds the vertex count {n}");
        }
        let s = mfm_meshio::export::write_eigen_folder(&spec.to_string(), &mesh, k, &self.out)?;
        println!(
            "{k} eigenpairs of {spec} ({n} vertices) in {:.2} s ({}); lambda in [{:.4e}, {:.4e}]; wrote {}",
            s.seconds,
            s.method,
            s.eigenvalues[0],
            s.eigenvalues[k - 1],
            self.out.display()
        );
        Ok(())
    }
}

/// Noise parameters shared by `mfm noise` and `mfm spectrum`: the grammar
/// of `mfm train --noise` (`--noise matern:100`), or the same spelled out
/// (`--kind matern --tau 100`).
#[derive(Args, Clone, Debug)]
pub struct KindArgs {
    /// Noise, as for `mfm train --noise`: matern or matern:TAU,
    /// matern-normalized:C, matern-smooth, matern-smooth:TAU or
    /// matern-smooth:TAU:P, white, naive,
    /// explicit:K or explicit:K:TAU.
    #[arg(long, conflicts_with_all = ["kind", "tau", "c", "k_noise", "order"])]
    pub noise: Option<NoiseKind>,
    /// Noise kind, the long form of --noise: matern (uses --tau),
    /// matern-normalized (--c), matern-smooth (--tau, --order), white, naive
    /// or explicit (--k-noise, --tau).
    #[arg(long, default_value = "matern")]
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
    /// Order of matern-smooth noise: solves per sample, 2 to 4 (default 2).
    #[arg(long)]
    pub order: Option<u32>,
}

impl KindArgs {
    /// The [`NoiseKind`] these flags describe ([`NoiseKind::from_parts`]
    /// for the long form); a flag the kind does not use is an error,
    /// naming the flag.
    pub fn to_kind(&self) -> Result<NoiseKind> {
        if let Some(kind) = self.noise {
            return Ok(kind);
        }
        let parameters = KindParameters {
            tau: self.tau,
            c: self.c,
            k: self.k_noise,
            order: self.order,
        };
        NoiseKind::from_parts(self.kind, parameters).map_err(|e| match e {
            NoiseError::UnusedParameter {
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

/// Arguments of `mfm noise`.
#[derive(Args)]
pub struct NoiseArgs {
    /// Mesh file or builtin:NAME.
    mesh: crate::mesh::MeshSpec,
    #[command(flatten)]
    kind: KindArgs,
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
}

impl NoiseArgs {
    /// `[N, V, C]` noise samples as `.npy` (f64) with a JSON summary beside
    /// it ([`stream::NoiseFiles`]), and optionally a PNG of the
    /// first sample's first channel.
    pub fn run(self) -> Result<()> {
        let (spec, samples, channels, seed) = (&self.mesh, self.samples, self.channels, self.seed);
        let (out, png) = (self.out.as_path(), self.png.as_deref());
        if samples == 0 || channels == 0 {
            bail!("--samples and --channels must be at least 1");
        }
        let kind = self.kind.to_kind()?;
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
        let mut outputs = vec![out.to_path_buf()];
        outputs.extend(png.map(Path::to_path_buf));
        let mesh = load_mesh_checked(spec)?;
        let v = mesh.num_vertices();
        let bytes = mfm_files::npy::file_bytes(&[samples as u64, v as u64, channels as u64], 8);
        let undo = prepare_outputs(&[mesh_path(spec)], &outputs, std::slice::from_ref(&json))?;
        mfm_files::space::ensure_space(out, bytes).with_context(|| {
            format!("{samples} samples x {v} vertices x {channels} channels of f64")
        })?;
        let start = Instant::now();
        let sampler = NoiseSampler::new(&mesh, kind)
            .with_context(|| format!("{spec}: cannot set up {kind} noise"))?;
        let setup = start.elapsed().as_secs_f64();
        let bar = progress(samples as u64, "sampling");
        let name = spec.to_string();
        let files = stream::NoiseFiles {
            mesh: &name,
            npy: out,
            json: &json,
            samples,
            channels,
            seed,
        };
        let (summary, written) = files.write(&sampler, |done| bar.set_position(done as u64))?;
        bar.finish_and_clear();
        println!(
            "{samples} x {channels} {kind} samples on {spec} ({v} vertices; setup {setup:.3} s, total {:.3} s); \
mean f^T M f = {:.4e}; wrote {} and {}",
            start.elapsed().as_secs_f64(),
            summary.mean_energy,
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
            save_png(
                &render_mesh(&mesh, Some(&written.first_signal), &opts)?,
                png,
            )?;
            println!("wrote {}", png.display());
        }
        undo.keep();
        Ok(())
    }
}

/// Arguments of `mfm spectrum`.
#[derive(Args)]
pub struct SpectrumArgs {
    /// Mesh files or builtin:NAME (several triangulations of one surface
    /// to compare them).
    #[arg(required = true)]
    meshes: Vec<crate::mesh::MeshSpec>,
    #[command(flatten)]
    kind: KindArgs,
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
    /// Frequencies whose coefficient histograms are plotted, each below
    /// --k (default: those of 2, 10, 50 below --k).
    #[arg(long, value_delimiter = ',')]
    coefficients: Option<Vec<usize>>,
}

/// The frequencies plotted without `--coefficients` (those below `--k`).
const DEFAULT_COEFFICIENTS: [usize; 3] = [2, 10, 50];

impl SpectrumArgs {
    /// Per-frequency statistics of noise on one or several meshes
    /// ([`MeshSpectrum::measure`]), as JSON (and PNG plots).
    pub fn run(self) -> Result<()> {
        let args = &self;
        let kind = self.kind.to_kind()?;
        if args.meshes.is_empty() {
            bail!("give at least one mesh");
        }
        if args.samples < 2 || args.k == 0 {
            bail!("--samples must be at least 2 and --k at least 1");
        }
        let coefficients: Vec<usize> = match &args.coefficients {
            Some(given) => {
                if let Some(i) = given.iter().find(|&&i| i >= args.k) {
                    bail!(
                        "--coefficients {i}: a frequency index must be below --k {} (the \
                         frequencies measured are 0..{})",
                        args.k,
                        args.k
                    );
                }
                given.clone()
            }
            None => DEFAULT_COEFFICIENTS
                .into_iter()
                .filter(|&i| i < args.k)
                .collect(),
        };
        // the coefficients of the plotted frequencies are kept for every sample
        let kept = (coefficients.len() * args.meshes.len()) as u128;
        mfm_files::space::ensure_memory(
            &format!(
                "--samples {} x {} kept coefficients (--coefficients) x {} mesh(es) of f64",
                args.samples,
                coefficients.len(),
                args.meshes.len()
            ),
            (args.samples as u128) * kept,
            8,
        )?;
        let outputs = vec![args.out.to_path_buf()];
        let mut plots = Vec::new();
        if let Some(dir) = args.plots.as_deref() {
            plots.push(dir.join("variance.png"));
            plots.push(dir.join("coefficients.png"));
        }
        let inputs: Vec<Option<&Path>> = args.meshes.iter().map(|m| mesh_path(m)).collect();
        let undo = prepare_outputs(&inputs, &outputs, &plots)?;
        let request = SpectrumRequest {
            samples: args.samples,
            k: args.k,
            seed: args.seed,
            keep: coefficients.clone(),
        };
        let (mut meshes, mut series) = (Vec::new(), Vec::new());
        let mut histograms: Vec<Vec<(String, Vec<f64>)>> = vec![Vec::new(); coefficients.len()];
        for spec in &args.meshes {
            let mesh = load_mesh_checked(spec)?;
            let v = mesh.num_vertices();
            if args.k > v {
                bail!("{spec}: --k {} exceeds the vertex count {v}", args.k);
            }
            // one assembly of the operators, for the sampler and the eigenpairs
            let setup = || format!("{spec}: cannot set up {kind} noise");
            let ops = Operators::new(&mesh).with_context(setup)?;
            let sampler = NoiseSampler::from_operators(&ops.laplacian, &ops.mass, kind)
                .with_context(setup)?;
            let name = spec.to_string();
            let bar = progress(args.samples as u64, &name);
            let (m, kept) = MeshSpectrum::measure(&name, &ops, &sampler, &request, |done| {
                bar.set_position(done as u64)
            })
            .with_context(|| format!("{spec}: spectrum"))?;
            bar.finish_and_clear();
            println!("{}", m.summary());
            for (slot, i) in histograms.iter_mut().zip(&coefficients) {
                match kept.iter().find(|(j, _)| j == i) {
                    Some((_, c)) => slot.push((name.clone(), c.clone())),
                    None => eprintln!(
                        "warning: {spec}: c_{i} is not plotted for this mesh: it has only {} \
                         frequencies",
                        m.report.eigenvalues.len()
                    ),
                }
            }
            let r = &m.report;
            series.push(VarianceSeries::new(
                name.clone(),
                &r.eigenvalues,
                &r.variance,
                r.theory.as_deref(),
            ));
            meshes.push(m);
        }
        let file = SpectrumFile::new(kind, args.samples, args.k, args.seed, meshes);
        for line in file.comparison_lines() {
            println!("{line}");
        }
        mfm_files::write_json(&args.out, &file)?;
        println!("wrote {}", args.out.display());
        if let Some(dir) = args.plots.as_deref() {
            let variance = dir.join("variance.png");
            plots::variance_plot(&variance, &format!("Var(c_i), {} noise", kind), &series)?;
            println!("wrote {}", variance.display());
            let panels: Vec<HistogramPanel> = coefficients
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
}
