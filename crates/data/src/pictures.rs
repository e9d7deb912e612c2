//! Pictures of signal sets: the preview of a dataset, the samples of a run,
//! and the pictures of an evaluation, each one PNG grid on one colour scale
//! ([`mfm_render::save_grid`]).
//!
//! A set with 3 channels is shown as shapes (the mesh with its vertices
//! moved to the signal's positions), any other set as its first channel
//! coloured on the mesh.

use crate::deformations::Plausibility;
use crate::quality::GmmQualityReport;
use crate::{InMemorySignals, Result, SignalSource};
use mfm_geometry::TriMesh;
use mfm_render::{ColorRange, Colormap, Panel, RenderOptions, save_grid};
use std::path::{Path, PathBuf};

/// Signals a picture shows at most.
pub const SHOWN: usize = 8;

/// One panel's content.
enum Shown {
    /// A scalar on the picture's mesh.
    Values(Vec<f64>, String),
    /// A shape of the mesh.
    Shape(TriMesh, String),
}

impl Shown {
    /// Signal `i` of `set` on `mesh`, as a shape for 3 channels.
    fn of(mesh: &TriMesh, set: &InMemorySignals, i: usize, caption: String) -> Result<Self> {
        Ok(if set.channels() == 3 {
            Self::Shape(mesh.with_positions(set.positions(i))?, caption)
        } else {
            Self::Values(set.channel(i, 0), caption)
        })
    }
}

/// Writes `items` on `mesh` as one grid.
fn save(mesh: &TriMesh, items: &[Shown], columns: usize, title: &str, path: &Path) -> Result<()> {
    let panels: Vec<Panel<'_>> = items
        .iter()
        .map(|item| match item {
            Shown::Values(v, c) => Panel::new(mesh, Some(v.as_slice()), c.clone()),
            Shown::Shape(m, c) => Panel::new(m, None, c.clone()),
        })
        .collect();
    Ok(save_grid(&panels, columns, title, ColorRange::Auto, path)?)
}

/// The first [`SHOWN`] signals of `set` on `mesh`, 4 to a row, captioned
/// `"{name} {i}"`, under `title`.
///
/// # Errors
/// A set whose vertex count is not the mesh's; the renderer's errors.
pub fn signals(
    mesh: &TriMesh,
    set: &InMemorySignals,
    name: &str,
    title: &str,
    path: &Path,
) -> Result<()> {
    let items = (0..set.len().min(SHOWN))
        .map(|i| Shown::of(mesh, set, i, format!("{name} {i}")))
        .collect::<Result<Vec<_>>>()?;
    save(mesh, &items, 4, title, path)
}

/// The preview of a deformation training set: the rest shape, then the
/// first [`SHOWN`] shapes, 3 to a row.
///
/// # Errors
/// As [`signals`].
pub fn deform_preview(coarse: &TriMesh, train: &InMemorySignals, path: &Path) -> Result<()> {
    let mut items = vec![Shown::Shape(coarse.clone(), "rest".to_owned())];
    for i in 0..train.len().min(SHOWN) {
        items.push(Shown::of(coarse, train, i, format!("shape {i}"))?);
    }
    save(coarse, &items, 3, "deformation training shapes", path)
}

/// The preview of a pairs training set: the poses (columns) of its first
/// two body shapes (rows).
///
/// # Errors
/// As [`signals`].
pub fn pairs_preview(
    coarse: &TriMesh,
    train: &InMemorySignals,
    poses: usize,
    path: &Path,
) -> Result<()> {
    let items = (0..train.len().min(2 * poses))
        .map(|i| {
            Shown::of(
                coarse,
                train,
                i,
                format!("shape {} pose {}", i / poses, i % poses),
            )
        })
        .collect::<Result<Vec<_>>>()?;
    save(
        coarse,
        &items,
        poses,
        "pairs: poses (columns) of body shapes (rows)",
        path,
    )
}

/// The first [`SHOWN`] reference signals above the first [`SHOWN`]
/// generated ones, on one colour scale, each captioned with its bump-fit
/// residual and peak ([`GmmQualityReport`]).
///
/// # Errors
/// As [`signals`].
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
/// As [`signals`].
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
/// As [`signals`].
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

    fn set(mesh: &TriMesh, channels: usize, n: usize) -> Result<InMemorySignals> {
        let v = mesh.num_vertices();
        let data: Vec<f32> = (0..n * v * channels)
            .map(|k| {
                let (i, rest) = (k / (v * channels), k % (v * channels));
                let p = mesh.positions()[rest / channels];
                (p[rest % channels] * (1.0 + 0.1 * i as f64)) as f32
            })
            .collect();
        InMemorySignals::new(data, n, v, channels)
    }

    #[test]
    fn pictures_of_scalars_and_shapes_are_written()
    -> std::result::Result<(), Box<dyn std::error::Error>> {
        let dir = tempfile::tempdir()?;
        let mesh = procedural::icosphere(1);
        let (scalars, shapes) = (set(&mesh, 1, 3)?, set(&mesh, 3, 12)?);
        signals(&mesh, &scalars, "signal", "t", &dir.path().join("a.png"))?;
        deform_preview(&mesh, &shapes, &dir.path().join("b.png"))?;
        pairs_preview(&mesh, &shapes, 4, &dir.path().join("c.png"))?;
        let m = dir.path().join("m.png");
        means(
            &mesh,
            &scalars,
            &scalars,
            0.0,
            &m,
            &sibling_png(&m, "difference"),
        )?;
        for f in ["a.png", "b.png", "c.png", "m.png", "m_difference.png"] {
            let img = image::open(dir.path().join(f))?;
            assert!(img.width() > 100, "{f}");
        }
        // a set on another mesh is refused, not drawn
        let other = procedural::icosphere(2);
        assert!(deform_preview(&other, &shapes, &dir.path().join("d.png")).is_err());
        assert!(!dir.path().join("d.png").exists());
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
