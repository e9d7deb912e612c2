//! Pictures of signal sets: the preview of a dataset and the samples of a
//! run, each one PNG grid on one colour scale ([`mfm_render::save_grid`]);
//! [`Shown`] and [`save`] are the panels and the grid writer that the
//! evaluation's pictures (`mfm_eval::pictures`) build on.
//!
//! A set with 3 channels is shown as shapes (the mesh with its vertices
//! moved to the signal's positions), any other set as its first channel
//! coloured on the mesh.

use crate::{InMemorySignals, Result, SignalSource};
use mfm_geometry::TriMesh;
use mfm_render::{ColorRange, Panel, save_grid};
use std::path::Path;

/// Signals a picture shows at most.
pub const SHOWN: usize = 8;

/// One panel's content: a scalar coloured on the picture's mesh, or a
/// shape (the mesh with moved vertices), each with its caption.
pub enum Shown {
    /// A scalar on the picture's mesh.
    Values(Vec<f64>, String),
    /// A shape of the mesh.
    Shape(TriMesh, String),
}

impl Shown {
    /// Signal `i` of `set` on `mesh`, as a shape for 3 channels.
    ///
    /// # Errors
    /// A 3-channel set whose vertex count is not the mesh's.
    pub fn of(mesh: &TriMesh, set: &InMemorySignals, i: usize, caption: String) -> Result<Self> {
        Ok(if set.channels() == 3 {
            Self::Shape(mesh.with_positions(set.positions(i))?, caption)
        } else {
            Self::Values(set.channel(i, 0), caption)
        })
    }
}

/// Writes `items` on `mesh` as one grid of `columns` columns under `title`,
/// on one colour scale (the range of all scalar panels).
///
/// # Errors
/// A scalar panel whose length is not the mesh's vertex count; the
/// renderer's errors.
pub fn save(
    mesh: &TriMesh,
    items: &[Shown],
    columns: usize,
    title: &str,
    path: &Path,
) -> Result<()> {
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
        for f in ["a.png", "b.png", "c.png"] {
            let img = image::open(dir.path().join(f))?;
            assert!(img.width() > 100, "{f}");
        }
        // a set on another mesh is refused, not drawn
        let other = procedural::icosphere(2);
        assert!(deform_preview(&other, &shapes, &dir.path().join("d.png")).is_err());
        assert!(!dir.path().join("d.png").exists());
        Ok(())
    }
}
