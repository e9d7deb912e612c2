//! Signals carried from a template mesh to another triangulation of its
//! surface: every vertex of the target mesh sits on a face of the template
//! (its closest point) with barycentric weights, and a vertex signal on the
//! template is interpolated there. An imported experiment stores the
//! transfer of its reference mesh ([`crate::import::TRANSFER`]) so that
//! training shapes, held-out shapes and samples are compared on one mesh.
//!
//! File form: a NumPy `.npy` array `[V_target, 6]` of float64: per target
//! vertex, three template vertex indices (exact integers) then their three
//! weights (non-negative, summing to 1).
//!
//! # Example
//! ```
//! use mfm_data::transfer::Transfer;
//! use mfm_geometry::procedural;
//! let coarse = procedural::icosphere(1);
//! let fine = mfm_geometry::subdivide::midpoint(&coarse).unwrap();
//! let t = Transfer::locate(&coarse, &fine).unwrap();
//! assert!(t.max_distance() < 1e-12);
//! // the coarse mesh's positions, carried to the fine mesh, are its positions
//! let xyz: Vec<f32> = coarse.positions().iter().flat_map(|p| p.map(|x| x as f32)).collect();
//! let carried = t.apply(&xyz, 3).unwrap();
//! assert!((carried[0] - fine.positions()[0][0] as f32).abs() < 1e-6);
//! ```

use std::path::Path;

use mfm_geometry::TriMesh;
use mfm_geometry::closest::SurfaceLocator;

use crate::error::{DataError, Result};
use crate::signals::{InMemorySignals, SignalSource};

/// The vertices of a target mesh as barycentric combinations of a
/// template's vertices; see the [module docs](self).
#[derive(Clone, Debug, PartialEq)]
pub struct Transfer {
    template_vertices: usize,
    corners: Vec<[u32; 3]>,
    weights: Vec<[f64; 3]>,
    distances: Vec<f64>,
}

impl Transfer {
    /// Locates every vertex of `target` on `template`'s surface by closest
    /// point.
    ///
    /// Cost: a bounding-volume hierarchy over the template's faces, then a
    /// query per target vertex (parallel).
    ///
    /// # Errors
    /// None at present (a [`TriMesh`] always has faces); kept fallible for
    /// the callers' sake.
    pub fn locate(template: &TriMesh, target: &TriMesh) -> Result<Self> {
        let locator = SurfaceLocator::new(template);
        let found = locator.closest_all(target.positions());
        Ok(Self {
            template_vertices: template.num_vertices(),
            corners: found.iter().map(|s| s.vertices(template)).collect(),
            weights: found.iter().map(|s| s.weights).collect(),
            distances: found.iter().map(|s| s.squared_distance.sqrt()).collect(),
        })
    }

    /// Vertices of the target mesh.
    pub fn target_vertices(&self) -> usize {
        self.corners.len()
    }

    /// Vertices of the template.
    pub fn template_vertices(&self) -> usize {
        self.template_vertices
    }

    /// Largest distance of a target vertex from the template's surface (0
    /// for a transfer read from a file, which does not keep distances).
    pub fn max_distance(&self) -> f64 {
        self.distances.iter().copied().fold(0.0, f64::max)
    }

    /// The target vertex farthest from the template's surface and its
    /// distance.
    pub fn farthest(&self) -> (usize, f64) {
        self.distances
            .iter()
            .copied()
            .enumerate()
            .fold(
                (0, 0.0),
                |best, (i, d)| if d > best.1 { (i, d) } else { best },
            )
    }

    /// One signal of `channels` values per template vertex, carried to the
    /// target's vertices.
    ///
    /// # Errors
    /// [`DataError::SizeMismatch`] when `signal` is not `V_template x
    /// channels` values.
    pub fn apply(&self, signal: &[f32], channels: usize) -> Result<Vec<f32>> {
        if channels == 0 || signal.len() != self.template_vertices * channels {
            return Err(DataError::SizeMismatch {
                what: "values of a signal carried to the reference mesh".into(),
                expected: self.template_vertices * channels.max(1),
                found: signal.len(),
            });
        }
        let mut out = Vec::with_capacity(self.corners.len() * channels);
        for (corners, weights) in self.corners.iter().zip(&self.weights) {
            for k in 0..channels {
                let x: f64 = corners
                    .iter()
                    .zip(weights)
                    .map(|(&v, &w)| w * f64::from(signal[v as usize * channels + k]))
                    .sum();
                out.push(x as f32);
            }
        }
        Ok(out)
    }

    /// Every signal of `set` carried to the target's vertices.
    ///
    /// # Errors
    /// As [`Transfer::apply`].
    pub fn apply_set(&self, set: &InMemorySignals) -> Result<InMemorySignals> {
        let c = set.channels();
        let mut data = Vec::with_capacity(set.len() * self.corners.len() * c);
        for i in 0..set.len() {
            data.extend(self.apply(set.signal(i), c)?);
        }
        InMemorySignals::new(data, set.len(), self.corners.len(), c)
    }

    /// Writes the transfer as `.npy` (see the [module docs](self)),
    /// atomically.
    ///
    /// # Errors
    /// [`DataError::Files`] naming the file.
    pub fn write(&self, path: &Path) -> Result<()> {
        let values: Vec<f64> = self
            .corners
            .iter()
            .zip(&self.weights)
            .flat_map(|(c, w)| {
                [
                    f64::from(c[0]),
                    f64::from(c[1]),
                    f64::from(c[2]),
                    w[0],
                    w[1],
                    w[2],
                ]
            })
            .collect();
        Ok(mfm_files::npy::write(
            path,
            &values,
            &[self.corners.len() as u64, 6],
        )?)
    }

    /// Reads a transfer written by [`Transfer::write`] onto a template of
    /// `template_vertices` vertices.
    ///
    /// # Errors
    /// [`DataError::Files`] (`Format`) naming the file for another shape,
    /// an index that is not a template vertex, or weights that are negative
    /// or do not sum to 1.
    pub fn read(path: &Path, template_vertices: usize) -> Result<Self> {
        let a = mfm_files::npy::read::<f64>(path)?;
        let [n, 6] = a.shape[..] else {
            return Err(DataError::format(
                path,
                format!(
                    "shape {:?}: a transfer is [V_reference, 6] (three template vertices, three weights)",
                    a.shape
                ),
            ));
        };
        let mut corners = Vec::with_capacity(n);
        let mut weights = Vec::with_capacity(n);
        for (row, r) in a.values.chunks_exact(6).enumerate() {
            let mut c = [0u32; 3];
            for k in 0..3 {
                let x = r[k];
                if !(x >= 0.0 && x.fract() == 0.0 && (x as usize) < template_vertices) {
                    return Err(DataError::format(
                        path,
                        format!(
                            "row {row}: {x} is not a vertex of the template ({template_vertices} vertices)"
                        ),
                    ));
                }
                c[k] = x as u32;
            }
            let w = [r[3], r[4], r[5]];
            let sum: f64 = w.iter().sum();
            let barycentric = w.iter().all(|x| *x >= -1e-9) && (sum - 1.0).abs() <= 1e-6;
            if !barycentric {
                return Err(DataError::format(
                    path,
                    format!("row {row}: weights {w:?} are not barycentric (>= 0, sum 1)"),
                ));
            }
            corners.push(c);
            weights.push(w);
        }
        Ok(Self {
            template_vertices,
            corners,
            weights,
            distances: vec![0.0; n],
        })
    }
}
