//! `cargo xtask reproduce-figures spectral`: the noise figures of paper
//! section 3, regenerated from scratch, with the numbers behind them.
//!
//! Figures (PNG, in the output folder):
//! 1. `per_frequency_statistics.png`: histograms of `c_2, c_50, c_500` over
//!    many samples on three resolutions of one surface, Matérn (top) vs naive
//!    (bottom) (paper: "Empirical per-frequency statistics");
//!    `spectrum_resolutions.png`: the same runs as variance per frequency;
//! 2. `spectrum.png`: variance per frequency against the eigenvalue, white vs
//!    Matérn, coarse vs fine mesh, complete spectra with the theory curves
//!    (paper: "Spectra of the different noise choices");
//! 3. `fixed_vs_normalized_tau.png`: one seed on the surface scaled by 0.1,
//!    1 and 2, fixed `tau` vs normalized `tau = c Gamma`;
//! 4. `nonuniform_triangulation.png`: naive vs Matérn noise on meshes with
//!    one refined half, next to their wireframes (paper Fig. 2).
//!
//! Numbers: `numbers.json` (everything, with per-frequency arrays) and CSV
//! tables; `README.md` lists the figures and what to look for.
//!
//! Conventions: the surface is scaled to unit area (so `lambda_k ~ 4 pi k`);
//! frequency indices are 0-based (`c_0` is the constant mode).

mod pictures;
mod statistics;
mod surfaces;
mod tables;

use anyhow::{Context, Result, ensure};
use clap::Args;
use mfm_noise::NoiseKind;
use mfm_render::plots::{HistogramPanel, VarianceSeries, coefficient_histograms, variance_plot};
use mfm_render::{View, save_png};
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::time::Instant;

use statistics::{Agreement, Analyzed, EnergyRow, KindStats};

/// Arguments of `reproduce-figures spectral`.
#[derive(Args, Debug, Clone)]
pub struct SpectralArgs {
    /// Output folder (relative paths are relative to the workspace root).
    #[arg(long, default_value = "out/figures/spectral")]
    pub out: PathBuf,
    /// Smoke run: fewer samples, smaller meshes, `c_200` instead of `c_500`.
    #[arg(long)]
    pub quick: bool,
    /// Input surface (default: ../shared/meshes/bunny.off, else a procedural blob).
    #[arg(long)]
    pub mesh: Option<PathBuf>,
    /// Samples per mesh and kind for the histograms (overrides the default).
    #[arg(long)]
    pub samples: Option<usize>,
    /// Base random seed.
    #[arg(long, default_value_t = 2024)]
    pub seed: u64,
}

/// Sizes and parameters of one run.
#[derive(Debug, Clone, Serialize)]
pub struct SpectralConfig {
    /// Matérn screening weight (the paper uses 100 throughout).
    pub tau: f64,
    /// Base seed; each (mesh, kind) gets its own seed derived from it.
    pub seed: u64,
    /// Coefficients whose histograms are drawn (0-based indices).
    pub frequencies: Vec<usize>,
    /// Eigenpairs computed on each of the three resolutions.
    pub eigenpairs: usize,
    /// The middle resolution is the input midpoint-subdivided until it has
    /// at least this many vertices.
    pub base_min_vertices: usize,
    /// Samples per mesh and kind for the histograms.
    pub samples: usize,
    /// Histogram bins.
    pub bins: usize,
    /// Vertices of the coarse mesh of the complete-spectrum figure.
    pub spectrum_coarse_vertices: usize,
    /// Samples per mesh and kind for the complete spectra.
    pub spectrum_samples: usize,
    /// Global scales of the fixed-vs-normalized figure.
    pub scales: Vec<f64>,
    /// Cells per side of the square of the non-uniform figure.
    pub plane_cells: u32,
    /// Bisection rounds on the refined half of the square.
    pub plane_rounds: u32,
    /// Bisection rounds on the refined half of the surface.
    pub surface_rounds: u32,
    /// Eigenpairs for the uniform-vs-non-uniform agreement numbers.
    pub agreement_eigenpairs: usize,
    /// Samples per mesh and kind for those numbers.
    pub agreement_samples: usize,
    /// Side of one rendered panel, in pixels.
    pub panel_px: u32,
}

impl SpectralConfig {
    /// The default run: `c_2, c_50, c_500` with 10k samples on meshes of
    /// about 7k, 14k and 32k vertices (from the bunny).
    pub fn full() -> Self {
        Self {
            tau: mfm_noise::DEFAULT_TAU,
            seed: 2024,
            frequencies: vec![2, 50, 500],
            eigenpairs: 512,
            base_min_vertices: 10_000,
            samples: 10_000,
            bins: 60,
            spectrum_coarse_vertices: 600,
            spectrum_samples: 4000,
            scales: vec![0.1, 1.0, 2.0],
            plane_cells: 40,
            plane_rounds: 4,
            surface_rounds: 2,
            agreement_eigenpairs: 64,
            agreement_samples: 3000,
            panel_px: 400,
        }
    }

    /// A smoke run (well under a minute): the input mesh as the middle
    /// resolution, `c_200` for the highest coefficient, 1000 samples.
    pub fn quick() -> Self {
        Self {
            frequencies: vec![2, 50, 200],
            eigenpairs: 208,
            base_min_vertices: 0,
            samples: 1000,
            bins: 30,
            spectrum_coarse_vertices: 300,
            spectrum_samples: 1000,
            plane_cells: 24,
            agreement_eigenpairs: 32,
            agreement_samples: 1000,
            panel_px: 256,
            ..Self::full()
        }
    }
}

/// A mesh used by a figure.
#[derive(Debug, Clone, Serialize)]
pub struct MeshInfo {
    /// Figure it belongs to.
    pub figure: &'static str,
    /// Label used in legends and tables.
    pub label: String,
    /// How it was made.
    pub how: String,
    /// Vertices.
    pub vertices: usize,
    /// Faces.
    pub faces: usize,
    /// Eigenpairs computed.
    pub eigenpairs: usize,
    /// Seconds of the eigensolve.
    pub eigen_seconds: f64,
}

impl MeshInfo {
    fn of(figure: &'static str, a: &Analyzed) -> Self {
        Self {
            figure,
            label: a.label.clone(),
            how: a.how.clone(),
            vertices: a.vertices,
            faces: a.faces,
            eigenpairs: a.pairs.values.len(),
            eigen_seconds: a.eigen_seconds,
        }
    }
}

/// Numbers of the uniform-vs-non-uniform comparison.
#[derive(Debug, Clone, Serialize)]
pub struct NonUniform {
    /// Per rendered surface.
    pub panels: Vec<pictures::NonUniformPanel>,
    /// Per-frequency agreement between the uniform and the non-uniform mesh.
    pub agreement: Vec<Agreement>,
}

/// Everything `numbers.json` holds.
#[derive(Debug, Clone, Serialize)]
pub struct Summary {
    /// Input surface.
    pub surface: String,
    /// The run's parameters.
    pub config: SpectralConfig,
    /// Meshes of every figure.
    pub meshes: Vec<MeshInfo>,
    /// Figure 1: per (resolution, kind) statistics.
    pub statistics: Vec<KindStats>,
    /// Figure 1: agreement between resolutions.
    pub agreement: Vec<Agreement>,
    /// Figure 2: per (mesh, kind) statistics over the complete spectra.
    pub spectrum: Vec<KindStats>,
    /// Mean total energies `f^T M f` (figures 1 and 2).
    pub energies: Vec<EnergyRow>,
    /// Figure 3: fixed vs normalized tau.
    pub scale: Vec<pictures::ScaleRow>,
    /// Figure 3: `c` of the normalized kind (`tau / Gamma` at scale 1).
    pub normalized_c: f64,
    /// Figure 4.
    pub nonuniform: NonUniform,
    /// Seconds per stage.
    pub timings: Vec<(String, f64)>,
    /// Files written.
    pub files: Vec<String>,
}

/// Runs `reproduce-figures spectral` from the command line.
///
/// # Errors
/// When the surface cannot be read or a stage fails.
pub fn spectral(args: &SpectralArgs) -> Result<()> {
    let start = Instant::now();
    let root = crate::workspace::root();
    let out = crate::workspace::in_root(&args.out);
    let mut config = if args.quick {
        SpectralConfig::quick()
    } else {
        SpectralConfig::full()
    };
    config.seed = args.seed;
    if let Some(n) = args.samples {
        config.samples = n;
    }
    let mesh = args.mesh.as_deref().map(crate::workspace::in_root);
    let surface = surfaces::load(mesh.as_deref(), &root)?;
    let summary = run(&config, &surface, &out)?;
    println!(
        "reproduce-figures spectral: {} files in {} ({:.1} s)",
        summary.files.len(),
        out.display(),
        start.elapsed().as_secs_f64()
    );
    Ok(())
}

/// Stage timer.
struct Clock {
    stages: Vec<(String, f64)>,
    t: Instant,
}

impl Clock {
    fn new() -> Self {
        Self {
            stages: Vec::new(),
            t: Instant::now(),
        }
    }
    fn lap(&mut self, name: &str) {
        let s = self.t.elapsed().as_secs_f64();
        eprintln!("xtask: {name}: {s:.1} s");
        self.stages.push((name.to_owned(), s));
        self.t = Instant::now();
    }
}

/// Seed of kind `k` on mesh `m` of figure `fig`.
fn seed_of(base: u64, fig: u64, m: usize, k: u64) -> u64 {
    base.wrapping_add(1_000 * fig + 10 * m as u64 + k)
}

/// Generates every figure and table of `surface` (already normalized) into
/// `out`, returning the numbers.
pub fn run(config: &SpectralConfig, surface: &surfaces::Surface, out: &Path) -> Result<Summary> {
    let total = Instant::now();
    std::fs::create_dir_all(out).with_context(|| format!("cannot create {}", out.display()))?;
    let mut clock = Clock::new();
    let mut files: Vec<String> = Vec::new();
    let tau = config.tau;
    let matern = NoiseKind::Matern { tau };
    let keep = &config.frequencies;
    let mut meshes = Vec::new();

    // ---- figure 1: per-frequency statistics on three resolutions
    eprintln!(
        "xtask: [1/4] per-frequency statistics on three resolutions of {}",
        surface.name
    );
    let ladder = surfaces::ladder(&surface.mesh, config.base_min_vertices)?;
    let needed = keep.iter().copied().max().unwrap_or(0) + 1;
    ensure!(
        config.eigenpairs >= needed,
        "{} eigenpairs cannot show c_{}",
        config.eigenpairs,
        needed - 1
    );
    let mut analyzed = Vec::new();
    for l in &ladder {
        ensure!(
            l.mesh.num_vertices() >= needed,
            "the {} mesh has too few vertices for c_{}",
            l.label,
            needed - 1
        );
        analyzed.push(Analyzed::new(&l.label, &l.how, &l.mesh, config.eigenpairs)?);
    }
    clock.lap("resolutions: meshes and eigenpairs");
    let mut stats: Vec<KindStats> = Vec::new();
    for (m, a) in analyzed.iter().enumerate() {
        meshes.push(MeshInfo::of("per_frequency_statistics", a));
        for (k, kind) in [matern, NoiseKind::Naive].into_iter().enumerate() {
            let seed = seed_of(config.seed, 1, m, k as u64);
            stats.push(statistics::sample_and_analyze(
                a,
                kind,
                config.samples,
                seed,
                keep,
            )?);
        }
    }
    let mut energies: Vec<EnergyRow> = stats
        .iter()
        .map(|s| EnergyRow::of("per_frequency_statistics", s))
        .collect();
    // white noise: energy only (its per-frequency law is the spectrum figure's)
    for (m, a) in analyzed.iter().enumerate() {
        energies.push(statistics::energy_only(
            "per_frequency_statistics",
            a,
            NoiseKind::White,
            config.samples.min(2000),
            seed_of(config.seed, 1, m, 2),
        )?);
    }
    clock.lap("resolutions: sampling and analysis");
    let by = |kind: &str, m: &str| {
        stats
            .iter()
            .find(|s| s.kind == kind && s.mesh == m)
            .with_context(|| format!("internal: no {kind} run on {m}"))
    };
    let mut agreement = Vec::new();
    for kind in [matern.to_string(), NoiseKind::Naive.to_string()] {
        for (i, j) in [(1, 0), (1, 2), (0, 2)] {
            let a = by(&kind, &analyzed[i].label)?;
            let b = by(&kind, &analyzed[j].label)?;
            agreement.push(statistics::agreement(a, b, keep));
        }
    }
    drop(analyzed);
    let mut rows = Vec::new();
    for kind in [matern, NoiseKind::Naive] {
        let runs: Vec<&KindStats> = stats
            .iter()
            .filter(|s| s.kind == kind.to_string())
            .collect();
        let panels: Vec<HistogramPanel> = keep
            .iter()
            .enumerate()
            .map(|(j, &i)| HistogramPanel {
                title: format!("{} c_{i}", kind.name()),
                series: runs
                    .iter()
                    .map(|s| {
                        (
                            format!("{} (lambda {:.0})", s.mesh, s.kept[j].eigenvalue),
                            s.coefficients[j].clone(),
                        )
                    })
                    .collect(),
                bins: config.bins,
            })
            .collect();
        let name = format!("per_frequency_{}.png", kind.name());
        coefficient_histograms(out.join(&name), &panels)?;
        files.push(name.clone());
        rows.push(image::open(out.join(&name))?.to_rgb8());
    }
    let combined = pictures::titled(
        &pictures::stack(&rows, false, 16),
        &format!(
            "Per-frequency statistics: {} samples on three resolutions of {}\n\
             top: matern (tau = {tau}), the same distribution on every mesh\n\
             bottom: naive (iid per vertex), a different one per mesh",
            config.samples, surface.name
        ),
        2,
    );
    save_png(&combined, out.join("per_frequency_statistics.png"))?;
    files.push("per_frequency_statistics.png".into());
    let series: Vec<VarianceSeries> = [matern.to_string(), NoiseKind::Naive.to_string()]
        .iter()
        .flat_map(|k| stats.iter().filter(move |s| &s.kind == k))
        .map(|s| {
            let r = &s.report;
            let label = format!("{} {}", s.kind, s.mesh);
            VarianceSeries::new(label, &r.eigenvalues, &r.variance, r.theory.as_deref())
        })
        .collect();
    variance_plot(
        out.join("spectrum_resolutions.png"),
        &format!(
            "Var(c_i), first {} frequencies, 3 resolutions",
            config.eigenpairs
        ),
        &series,
    )?;
    files.push("spectrum_resolutions.png".into());
    clock.lap("resolutions: plots");

    // ---- figure 2: complete spectra, white vs matern, coarse vs fine
    eprintln!("xtask: [2/4] complete spectra, white vs matern, coarse vs fine");
    let pair = surfaces::spectrum_pair(&surface.mesh, config.spectrum_coarse_vertices)?;
    let mut spectrum = Vec::new();
    for (m, l) in pair.iter().enumerate() {
        let a = Analyzed::new(&l.label, &l.how, &l.mesh, l.mesh.num_vertices())?;
        meshes.push(MeshInfo::of("spectrum", &a));
        for (k, kind) in [NoiseKind::White, matern, NoiseKind::Naive]
            .into_iter()
            .enumerate()
        {
            spectrum.push(statistics::sample_and_analyze(
                &a,
                kind,
                config.spectrum_samples,
                seed_of(config.seed, 2, m, k as u64),
                &[],
            )?);
        }
    }
    energies.extend(spectrum.iter().map(|s| EnergyRow::of("spectrum", s)));
    // fine first, so that the coarse mesh's dots are drawn on top and its
    // spectrum visibly ends where the fine mesh's new frequencies begin
    let series: Vec<VarianceSeries> = [1, 0]
        .into_iter()
        .flat_map(|m| {
            [NoiseKind::White, matern].map(|k| {
                spectrum
                    .iter()
                    .find(|s| s.kind == k.to_string() && s.mesh == pair[m].label)
            })
        })
        .flatten()
        .map(|s| {
            let r = &s.report;
            let label = format!(
                "{} {} [energy {}]",
                s.kind,
                s.mesh,
                pictures::sci(s.energy.mean)
            );
            VarianceSeries::new(label, &r.eigenvalues, &r.variance, r.theory.as_deref())
        })
        .collect();
    variance_plot(
        out.join("spectrum.png"),
        "Complete spectra: white vs matern, fine vs coarse",
        &series,
    )?;
    files.push("spectrum.png".into());
    clock.lap("complete spectra");

    // ---- figure 3: fixed vs normalized tau
    eprintln!(
        "xtask: [3/4] fixed vs normalized tau at scales {:?}",
        config.scales
    );
    let (img, scale, normalized_c) = pictures::fixed_vs_normalized(
        &surface.mesh,
        &config.scales,
        tau,
        seed_of(config.seed, 3, 0, 0),
        config.panel_px,
    )?;
    save_png(&img, out.join("fixed_vs_normalized_tau.png"))?;
    files.push("fixed_vs_normalized_tau.png".into());
    clock.lap("fixed vs normalized tau");

    // ---- figure 4: noise on a non-uniform triangulation
    eprintln!("xtask: [4/4] noise on non-uniform triangulations");
    let [plane, plane_half] = surfaces::plane_pair(config.plane_cells, config.plane_rounds)?;
    let half = surfaces::half_refined(&surface.mesh, config.surface_rounds)?;
    let (lo, hi) = surface.mesh.bounding_box();
    let centre = 0.5 * (lo[0] + hi[0]);
    let seed4 = seed_of(config.seed, 4, 0, 0);
    let (row_a, panel_a) = pictures::nonuniform_row(
        "square",
        &plane_half.mesh,
        |p| p[0] > 0.0,
        tau,
        seed4,
        config.panel_px,
        View::default().front(),
    )?;
    let (row_b, panel_b) = pictures::nonuniform_row(
        "surface",
        &half.mesh,
        |p| p[0] > centre,
        tau,
        seed4,
        config.panel_px,
        View::default(),
    )?;
    let img = pictures::titled(
        &pictures::stack(&[row_a, row_b], false, 16),
        "Noise on non-uniform triangulations (right half refined)\n\
         naive noise shows the triangulation, matern noise does not",
        2,
    );
    save_png(&img, out.join("nonuniform_triangulation.png"))?;
    files.push("nonuniform_triangulation.png".into());
    let mut nonuniform_agreement = Vec::new();
    let uniform_surface = surfaces::Labeled {
        label: format!(
            "surface {}",
            surfaces::count_label(surface.mesh.num_vertices())
        ),
        how: "the input".into(),
        mesh: surface.mesh.clone(),
    };
    for (m, (a, b)) in [(&plane, &plane_half), (&uniform_surface, &half)]
        .into_iter()
        .enumerate()
    {
        let aa = Analyzed::new(&a.label, &a.how, &a.mesh, config.agreement_eigenpairs)?;
        let bb = Analyzed::new(&b.label, &b.how, &b.mesh, config.agreement_eigenpairs)?;
        meshes.push(MeshInfo::of("nonuniform_triangulation", &aa));
        meshes.push(MeshInfo::of("nonuniform_triangulation", &bb));
        for (k, kind) in [matern, NoiseKind::Naive].into_iter().enumerate() {
            let n = config.agreement_samples;
            let sa = statistics::sample_and_analyze(
                &aa,
                kind,
                n,
                seed_of(config.seed, 5, m, k as u64),
                &[],
            )?;
            let sb = statistics::sample_and_analyze(
                &bb,
                kind,
                n,
                seed_of(config.seed, 6, m, k as u64),
                &[],
            )?;
            nonuniform_agreement.push(statistics::agreement(&sa, &sb, &[]));
        }
    }
    clock.lap("non-uniform triangulations");

    let mut summary = Summary {
        surface: surface.name.clone(),
        config: config.clone(),
        meshes,
        statistics: stats,
        agreement,
        spectrum,
        energies,
        scale,
        normalized_c,
        nonuniform: NonUniform {
            panels: vec![panel_a, panel_b],
            agreement: nonuniform_agreement,
        },
        timings: Vec::new(),
        files,
    };
    tables::write_all(&mut summary, out)?;
    clock.lap("tables");
    summary.timings = clock.stages.clone();
    summary
        .timings
        .push(("total".into(), total.elapsed().as_secs_f64()));
    tables::write_json_and_readme(&mut summary, out)?;
    Ok(summary)
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    /// The quick path end to end on a tiny procedural surface: every file is
    /// written, and the numbers are what the theory says.
    #[test]
    fn tiny_run_writes_every_file_with_sane_numbers() {
        let config = SpectralConfig {
            frequencies: vec![2, 10, 40],
            eigenpairs: 48,
            base_min_vertices: 300,
            samples: 2000,
            bins: 20,
            spectrum_coarse_vertices: 80,
            spectrum_samples: 1000,
            plane_cells: 8,
            plane_rounds: 2,
            surface_rounds: 1,
            agreement_eigenpairs: 16,
            agreement_samples: 1000,
            panel_px: 96,
            ..SpectralConfig::quick()
        };
        let surface = surfaces::Surface {
            name: "blob".into(),
            mesh: surfaces::unit_area(&surfaces::blob(2).unwrap()),
        };
        let dir = tempfile::tempdir().unwrap();
        let summary = run(&config, &surface, dir.path()).unwrap();
        for f in &summary.files {
            let len = std::fs::metadata(dir.path().join(f)).unwrap().len();
            assert!(len > 100, "{f}: {len} bytes");
        }
        for f in [
            "numbers.json",
            "README.md",
            "per_frequency_statistics.png",
            "spectrum.png",
            "fixed_vs_normalized_tau.png",
            "nonuniform_triangulation.png",
            "per_frequency.csv",
        ] {
            assert!(summary.files.iter().any(|g| g == f), "{f} not listed");
        }
        let json: serde_json::Value =
            serde_json::from_slice(&std::fs::read(dir.path().join("numbers.json")).unwrap())
                .unwrap();
        // matern variances within 20% of 1/(lambda + tau)^2 on every resolution
        // (2000 samples: relative standard error 3.2%, 48 frequencies)
        let stats = json["statistics"].as_array().unwrap();
        let materns: Vec<_> = stats.iter().filter(|s| s["kind"] == "matern:100").collect();
        assert_eq!(materns.len(), 3);
        for s in &materns {
            let e = s["max_relative_error"].as_f64().unwrap();
            assert!(e < 0.2, "{}: max |Var/theory - 1| = {e}", s["mesh"]);
            for k in s["kept"].as_array().unwrap() {
                let r = k["std"].as_f64().unwrap() / k["theory_std"].as_f64().unwrap();
                assert!((r - 1.0).abs() < 0.1, "{}: {k}", s["mesh"]);
            }
        }
        // white energy is V (to sampling error), naive the area (1)
        for s in json["energies"].as_array().unwrap() {
            let e = s["mean"].as_f64().unwrap();
            match s["kind"].as_str().unwrap() {
                "white" => {
                    let v = s["vertices"].as_f64().unwrap();
                    assert!((e / v - 1.0).abs() < 0.05, "white energy {e} vs V = {v}");
                }
                "naive" => assert!((e - 1.0).abs() < 0.1, "naive energy {e}"),
                _ => {}
            }
        }
        // complete spectra: theory energies are exact sums; matern converges
        let spec = json["spectrum"].as_array().unwrap();
        let energy = |kind: &str, i: usize| {
            spec.iter().filter(|s| s["kind"] == kind).nth(i).unwrap()["energy"]["theory"]
                .as_f64()
                .unwrap()
        };
        assert!(energy("white", 1) / energy("white", 0) > 3.5);
        assert!((energy("matern:100", 1) / energy("matern:100", 0) - 1.0).abs() < 0.1);
        // normalized: identical to round-off at every scale; fixed: not
        for row in json["scale"].as_array().unwrap() {
            let d = row["relative_difference"].as_f64().unwrap();
            let s = row["scale"].as_f64().unwrap();
            if row["kind"]
                .as_str()
                .unwrap()
                .starts_with("matern-normalized")
            {
                assert!(d < 1e-9, "normalized differs by {d} at scale {s}");
            } else if s != 1.0 {
                assert!(d > 0.1, "fixed tau differs only by {d} at scale {s}");
            }
        }
        // the non-uniform meshes: naive's per-frequency std moves, matern's does not
        for a in json["nonuniform"]["agreement"].as_array().unwrap() {
            let r = a["median_std_ratio"].as_f64().unwrap();
            if a["kind"] == "naive" {
                assert!(r < 0.9, "naive median std ratio {r}");
            } else {
                assert!((r - 1.0).abs() < 0.1, "matern median std ratio {r}");
            }
        }
        let readme = std::fs::read_to_string(dir.path().join("README.md")).unwrap();
        assert!(readme.contains("per_frequency_statistics.png"));
    }
}
