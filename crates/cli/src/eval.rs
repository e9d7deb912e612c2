//! `mfm eval`: distribution metrics, sample-quality fits and pictures of
//! generated samples against a reference dataset or a deformation space.

use crate::mesh_arg::{load_mesh_checked, mesh_path};
use crate::output::{prepare_outputs, write_json};
use crate::pictures::save_grid;
use anyhow::{Context, Result, bail};
use clap::Args;
use mfm_data::dataset::Dataset;
use mfm_data::deformations;
use mfm_data::evaluation;
use mfm_data::layout;
use mfm_data::quality::GmmQualityReport;
use mfm_data::{InMemorySignals, SignalSource};
use mfm_geometry::TriMesh;
use mfm_render::{ColorRange, Colormap, Panel, RenderOptions};
use std::path::{Path, PathBuf};

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
    let e = evaluation::evaluate(&reference, &generated)
        .with_context(|| format!("evaluating against {}", reference_dir.display()))?;
    println!("{}", e.report.summary());
    if let Some(out) = &a.out {
        write_json(out, &e.report)?;
    }
    let Some(png) = &a.png else {
        undo.keep();
        return Ok(());
    };
    let mesh = &e.mesh;
    if let Some(q) = &e.report.quality {
        save_data_and_samples(
            mesh,
            &e.reference,
            &generated,
            q,
            &sibling_png(png, "samples"),
        )?;
    }
    if let Some(p) = &e.projections {
        save_projection_grid(mesh, &generated, p, png)?;
    } else {
        let mean_gen = pointwise_mean(&generated);
        let mean_ref = pointwise_mean(&e.reference);
        let diff: Vec<f64> = mean_gen.iter().zip(&mean_ref).map(|(g, r)| g - r).collect();
        let panels = [
            Panel::new(mesh, Some(mean_gen.as_slice()), "generated mean"),
            Panel::new(mesh, Some(mean_ref.as_slice()), "reference mean"),
        ];
        save_grid(
            &panels,
            2,
            &format!(
                "point-wise means, test error {:.4}",
                e.report.metrics.test_error
            ),
            ColorRange::Auto,
            png,
        )?;
        let mut opts = RenderOptions::with_size(400, 400);
        opts.colormap = Colormap::CoolWarm;
        opts.range = ColorRange::Symmetric;
        opts.colorbar = true;
        let img = mfm_render::render_mesh(mesh, Some(&diff), &opts)?;
        mfm_render::save_png(&img, sibling_png(png, "difference"))?;
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
    let space = layout::read_space(space_path)?;
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
    let (report, p) = evaluation::plausibility_only(&space, &mesh, generated)?;
    println!(
        "projection MSE (plausibility): mean {:.3e} median {:.3e} ({} samples on {} vertices)",
        report.projection_mse, report.projection_mse_median, report.num_generated, report.vertices
    );
    if let Some(out) = &a.out {
        write_json(out, &report)?;
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
                set.channel(i, 0),
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
