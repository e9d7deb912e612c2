//! The pictures of an evaluation: data above samples with their bump-fit
//! captions, generated shapes beside their projections, and the point-wise
//! means with their difference. Each is one PNG grid on one colour scale,
//! drawn with the panels of [`mfm_data::pictures`].

use crate::plausibility::Plausibility;
use crate::quality::GmmQualityReport;
use mfm_data::pictures::{SHOWN, Shown, save};
use mfm_data::{InMemorySignals, Result, SignalSource};
use mfm_geometry::TriMesh;
use mfm_render::{ColorRange, Colormap, RenderOptions};
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
