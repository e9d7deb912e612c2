//! The pictures of an evaluation: data above samples with their bump-fit
//! captions, generated shapes beside their projections, and the point-wise
//! means with their difference. Each is one PNG grid on one colour scale,
//! drawn with the panels of [`mfm_data::pictures`]. For shapes, also the
//! principal plane: every shape and sample as a dot
//! ([`mfm_render::plots::scatter_plot`]).

use crate::plausibility::Plausibility;
use crate::quality::GmmQualityReport;
use crate::shape_quality::{RealSet, ShapeQuality, ShapeSets, weighted_mean};
use mfm_data::pictures::{SHOWN, Shown, save};
use mfm_data::{InMemorySignals, Result, SignalSource};
use mfm_geometry::TriMesh;
use mfm_render::plots::{ScatterPlot, ScatterSeries, scatter_plot};
use mfm_render::{ColorRange, Colormap, GridOptions, Panel, RenderOptions};
use std::path::{Path, PathBuf};

/// The first [`SHOWN`] reference signals above the first [`SHOWN`]
/// generated ones, on one colour scale, each captioned with its bump-fit
/// residual and peak ([`GmmQualityReport`]).
///
/// # Errors
/// A set whose vertex count is not the mesh's; the renderer's errors.
pub fn data_and_samples(
    mesh: &TriMesh,
    reference: &InMemorySignals,
    generated: &InMemorySignals,
    q: &GmmQualityReport,
    path: &Path,
) -> Result<()> {
    let mut items = Vec::new();
    for (set, fits, name) in [
        (reference, &q.reference.fits, "data"),
        (generated, &q.generated.fits, "sample"),
    ] {
        for (i, f) in fits.iter().enumerate().take(set.len().min(SHOWN)) {
            let caption = format!(
                "{name} {i}\nres {:.2} peak {:.2} bumps {}",
                f.residual, f.peak, f.bumps_above_half
            );
            items.push(Shown::Values(set.channel(i, 0), caption));
        }
    }
    let title = format!(
        "data (top) and generated (bottom), one colour scale; residual median {:.2} (data {:.2})",
        q.generated.residual.median, q.floor
    );
    save(mesh, &items, 4, &title, path)
}

/// The generated shapes whose projections `p` kept, each beside its
/// projection onto the deformation space.
///
/// # Errors
/// A set whose vertex count is not the mesh's; the renderer's errors.
pub fn projections(
    mesh: &TriMesh,
    generated: &InMemorySignals,
    p: &Plausibility,
    path: &Path,
) -> Result<()> {
    let mut items = Vec::new();
    for (i, projection) in p.projections.iter().enumerate() {
        let caption = format!("sample {i} (MSE {:.1e})", p.mse[i]);
        items.push(Shown::Shape(
            mesh.with_positions(generated.positions(i))?,
            caption,
        ));
        let caption = format!("its projection {i}");
        items.push(Shown::Shape(
            mesh.with_positions(projection.clone())?,
            caption,
        ));
    }
    let title = format!(
        "generated shapes and their projections, mean MSE {:.2e}",
        p.mean
    );
    save(mesh, &items, 4, &title, path)
}

/// The first samples of `sets` (at most [`SHOWN`] / 2), each beside its
/// nearest real shape (`q`, of these sets), captioned with the distance
/// (over the floor), the roughness and the flipped faces, 4 panels to a
/// row. Every shape is centred (its mass-weighted mean, with the rest
/// mesh's lumped mass, removed) and all are drawn with one camera fitted to
/// them together, so sizes compare across panels (the grid of
/// [`mfm_data::pictures::save`] frames each panel on its own, which would
/// blow a shrunken sample up to its neighbour's size).
///
/// # Errors
/// [`mfm_data::DataError::SizeMismatch`] when `q` names a real shape that
/// the sets do not hold or a set is not positions of the mesh's vertices;
/// the renderer's errors.
pub fn nearest_real(sets: &ShapeSets, q: &ShapeQuality, path: &Path) -> Result<()> {
    let mesh = sets.mesh;
    let v = mesh.num_vertices();
    if sets.samples.channels() != 3 || sets.samples.num_vertices() != v {
        return Err(mfm_data::DataError::SizeMismatch {
            what: "values per sample (positions of the mesh's vertices)".into(),
            expected: 3 * v,
            found: sets.samples.channels() * sets.samples.num_vertices(),
        });
    }
    let mut weights = mfm_geometry::operators::lumped_mass(mesh);
    let total: f64 = weights.iter().sum();
    weights.iter_mut().for_each(|m| *m /= total);
    let centred = |mut p: Vec<[f64; 3]>| -> Result<TriMesh> {
        let mean = weighted_mean(&weights, p.iter().copied());
        if mean.iter().all(|c| c.is_finite()) {
            p.iter_mut()
                .for_each(|x| (0..3).for_each(|k| x[k] -= mean[k]));
        }
        Ok(mesh.with_positions(p)?)
    };
    let mut shown = Vec::new();
    for (i, s) in q
        .per_sample
        .iter()
        .enumerate()
        .take((SHOWN / 2).min(sets.samples.len()))
    {
        let caption = format!(
            "sample {i}: d/floor {:.2}\nrough {:.2} flips {:.1}%",
            s.distance / q.floor,
            s.roughness,
            100.0 * s.flipped
        );
        shown.push((centred(sets.samples.positions(i))?, caption));
        let set = match s.nearest.set {
            RealSet::Train => "training",
            RealSet::HeldOut => "held-out",
        };
        let caption = format!(
            "its nearest: {set} {}\nd {:.4}",
            s.nearest.index, s.distance
        );
        shown.push((centred(sets.real_positions(s.nearest)?)?, caption));
    }
    let panels: Vec<Panel<'_>> = shown
        .iter()
        .map(|(m, c)| Panel::new(m, None, c.clone()))
        .collect();
    let opts = GridOptions {
        title: Some(format!(
            "samples beside their nearest real shapes (centred, one scale); plausibility {:.2}, \
             roughness {:.2}",
            q.plausibility, q.roughness
        )),
        shared_camera: true,
        ..GridOptions::default()
    };
    let img = mfm_render::render_grid(&panels, 4, &opts)?;
    Ok(mfm_render::save_png(&img, path)?)
}

/// The training shapes, held-out shapes and samples of `q` as dots in the
/// training shapes' principal plane ([`crate::principal_plane`]), one
/// scale on both axes, in units of the template's diagonal.
///
/// # Errors
/// [`mfm_data::DataError::Config`] for a report without a plane (written
/// before planes were measured); the plot's errors.
pub fn principal_plane(q: &ShapeQuality, path: &Path) -> Result<()> {
    let Some(plane) = &q.plane else {
        return Err(mfm_data::DataError::Config(
            "the shape-quality report has no principal plane to draw".into(),
        ));
    };
    let series = |label: &str, points: &[[f64; 2]], radius: u32| ScatterSeries {
        label: format!("{label} ({})", points.len()),
        points: points.iter().map(|c| (c[0], c[1])).collect(),
        radius,
    };
    let spread = q
        .spread
        .map_or(String::new(), |s| format!("; spread {s:.2}"));
    let plot = ScatterPlot {
        title: format!(
            "shapes in the training shapes' principal plane ({:.0}% + {:.0}% of their \
             variance){spread}",
            100.0 * plane.explained[0],
            100.0 * plane.explained[1]
        ),
        x_label: "direction 1 (units of the template's diagonal)".into(),
        y_label: "direction 2".into(),
        series: vec![
            series("training", &plane.train, 5),
            series("held out", &plane.held_out, 6),
            series("samples", &plane.samples, 4),
        ],
    };
    Ok(scatter_plot(path, &plot)?)
}

/// The point-wise means of channel 0 (generated beside reference) to
/// `path`, and their difference (cool-warm, symmetric about 0) to
/// `difference`.
///
/// # Errors
/// A set whose vertex count is not the mesh's; the renderer's errors.
pub fn means(
    mesh: &TriMesh,
    generated: &InMemorySignals,
    reference: &InMemorySignals,
    test_error: f64,
    path: &Path,
    difference: &Path,
) -> Result<()> {
    let mean_gen = pointwise_mean(generated);
    let mean_ref = pointwise_mean(reference);
    let diff: Vec<f64> = mean_gen.iter().zip(&mean_ref).map(|(g, r)| g - r).collect();
    let items = [
        Shown::Values(mean_gen, "generated mean".to_owned()),
        Shown::Values(mean_ref, "reference mean".to_owned()),
    ];
    let title = format!("point-wise means, test error {test_error:.4}");
    save(mesh, &items, 2, &title, path)?;
    let mut opts = RenderOptions::with_size(400, 400);
    opts.colormap = Colormap::CoolWarm;
    opts.range = ColorRange::Symmetric;
    opts.colorbar = true;
    let img = mfm_render::render_mesh(mesh, Some(&diff), &opts)?;
    Ok(mfm_render::save_png(&img, difference)?)
}

/// `dir/STEM_SUFFIX.png` for `dir/STEM.png`: the names of the pictures
/// written beside a requested one.
pub fn sibling_png(png: &Path, suffix: &str) -> PathBuf {
    png.with_file_name(format!(
        "{}_{suffix}.png",
        png.file_stem().and_then(|s| s.to_str()).unwrap_or("means")
    ))
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

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use mfm_geometry::procedural;

    #[test]
    fn the_means_and_their_difference_are_written()
    -> std::result::Result<(), Box<dyn std::error::Error>> {
        let dir = tempfile::tempdir()?;
        let mesh = procedural::icosphere(1);
        let v = mesh.num_vertices();
        let data: Vec<f32> = (0..3 * v)
            .map(|k| (mesh.positions()[k % v][0] * (1.0 + 0.1 * (k / v) as f64)) as f32)
            .collect();
        let scalars = InMemorySignals::new(data, 3, v, 1)?;
        let m = dir.path().join("m.png");
        means(
            &mesh,
            &scalars,
            &scalars,
            0.0,
            &m,
            &sibling_png(&m, "difference"),
        )?;
        for f in ["m.png", "m_difference.png"] {
            let img = image::open(dir.path().join(f))?;
            assert!(img.width() > 100, "{f}");
        }
        Ok(())
    }

    #[test]
    fn the_mean_is_per_vertex_over_the_set() -> Result<()> {
        let s = InMemorySignals::new(vec![1.0, 10.0, 2.0, 20.0, 3.0, 30.0, 4.0, 40.0], 2, 2, 2)?;
        assert_eq!(pointwise_mean(&s), vec![2.0, 3.0]);
        assert_eq!(
            sibling_png(Path::new("/a/eval.png"), "samples"),
            PathBuf::from("/a/eval_samples.png")
        );
        Ok(())
    }
}
