//! [`SignalSource`]: where training reads its signals from, one batch at a
//! time, without holding a large dataset in memory.

use std::path::Path;

use mfm_geometry::TriMesh;

use crate::error::{DataError, Result};

/// A set of `len()` signals over one mesh, each `num_vertices() x channels()`
/// values (vertex-major, like a `V x 3` position array when `channels == 3`).
///
/// Implemented by the on-disk [`Dataset`](crate::dataset::Dataset), which reads
/// only the requested rows, and by [`InMemorySignals`].
pub trait SignalSource: Send + Sync {
    /// Number of signals.
    fn len(&self) -> usize;
    /// Whether there are no signals.
    fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// Vertices per signal.
    fn num_vertices(&self) -> usize;
    /// Channels per vertex.
    fn channels(&self) -> usize;
    /// Writes signals `indices` (in that order) into `out`, row-major
    /// `[indices.len(), V, C]`.
    ///
    /// # Errors
    /// [`DataError::SizeMismatch`] if `out` has the wrong length or an index is
    /// out of range; I/O or format errors of the backing storage.
    fn read_into(&self, indices: &[usize], out: &mut [f32]) -> Result<()>;
}

/// Checks a [`SignalSource::read_into`] request against a source of `len`
/// signals of `row_values` values each: `out_len` must be
/// `indices.len() * row_values` and every index below `len`.
///
/// # Errors
/// [`DataError::SizeMismatch`] naming the output buffer or the first bad index.
pub(crate) fn check_read_request(
    len: usize,
    row_values: usize,
    indices: &[usize],
    out_len: usize,
) -> Result<()> {
    if out_len != indices.len() * row_values {
        return Err(DataError::SizeMismatch {
            what: "output buffer".into(),
            expected: indices.len() * row_values,
            found: out_len,
        });
    }
    if let Some(&bad) = indices.iter().find(|&&i| i >= len) {
        return Err(DataError::SizeMismatch {
            what: "signal index".into(),
            expected: len,
            found: bad,
        });
    }
    Ok(())
}

/// Signals held in memory: row-major `[N, V, C]` `f32` values.
///
/// # Example
/// ```
/// use mfm_data::signals::{InMemorySignals, SignalSource};
/// let s = InMemorySignals::new(vec![1.0, 2.0, 3.0, 4.0], 2, 2, 1).unwrap();
/// let mut out = [0.0f32; 2];
/// s.read_into(&[1], &mut out).unwrap();
/// assert_eq!(out, [3.0, 4.0]);
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct InMemorySignals {
    data: Vec<f32>,
    len: usize,
    vertices: usize,
    channels: usize,
}

/// The first NaN or infinite value of row-major `[N, vertices, channels]`
/// values, as `(signal, vertex, channel, value)` in storage order; `None`
/// when all are finite.
pub fn first_non_finite(
    values: &[f32],
    vertices: usize,
    channels: usize,
) -> Option<(usize, usize, usize, f32)> {
    let k = values.iter().position(|x| !x.is_finite())?;
    let row = (vertices * channels).max(1);
    let channels = channels.max(1);
    Some((k / row, (k % row) / channels, k % channels, values[k]))
}

impl InMemorySignals {
    /// Wraps `data`, row-major `[len, vertices, channels]`.
    ///
    /// # Errors
    /// [`DataError::SizeMismatch`] if the length is not the product of the sizes.
    pub fn new(data: Vec<f32>, len: usize, vertices: usize, channels: usize) -> Result<Self> {
        let expected = len
            .checked_mul(vertices)
            .and_then(|x| x.checked_mul(channels))
            .ok_or_else(|| DataError::Config("signal array size overflows usize".into()))?;
        if data.len() != expected {
            return Err(DataError::SizeMismatch {
                what: format!("signal data for [{len}, {vertices}, {channels}]"),
                expected,
                found: data.len(),
            });
        }
        Ok(Self {
            data,
            len,
            vertices,
            channels,
        })
    }

    /// Reads a `.npy` array of shape `[N, V, C]` or `[N, V]` (one channel),
    /// `f32` or `f64` (narrowed to `f32`), such as `mfm sample` writes.
    ///
    /// # Errors
    /// The reader's [`DataError::Files`]; [`DataError::Files`] (`Format`) for any
    /// other rank.
    pub fn read_npy(path: &std::path::Path) -> Result<Self> {
        let a = mfm_files::npy::read::<f32>(path)?;
        let (n, v, c) = match a.shape[..] {
            [n, v] => (n, v, 1),
            [n, v, c] => (n, v, c),
            _ => {
                return Err(DataError::format(
                    path,
                    format!("expected shape [N, V] or [N, V, C], found {:?}", a.shape),
                ));
            }
        };
        Self::new(a.values, n, v, c)
    }

    /// The first value that is NaN or infinite, as `(signal, vertex,
    /// channel, value)`, scanning in storage order; `None` when all are
    /// finite.
    pub fn first_non_finite(&self) -> Option<(usize, usize, usize, f32)> {
        first_non_finite(&self.data, self.vertices, self.channels)
    }

    /// The values, row-major `[N, V, C]`.
    pub fn data(&self) -> &[f32] {
        &self.data
    }

    /// Signal `i` (`V x C` values).
    pub fn signal(&self, i: usize) -> &[f32] {
        let n = self.vertices * self.channels;
        &self.data[i * n..(i + 1) * n]
    }

    /// Signal `i` of a 3-channel set read as vertex positions, in `f64`
    /// (`V` points). Callers check [`SignalSource::channels`] `== 3`; with
    /// another channel count the values are regrouped by threes.
    pub fn positions(&self, i: usize) -> Vec<[f64; 3]> {
        self.signal(i)
            .chunks_exact(3)
            .map(|p| [f64::from(p[0]), f64::from(p[1]), f64::from(p[2])])
            .collect()
    }

    /// Channel `k` of signal `i` as `f64` (`V` values), e.g. to colour a
    /// mesh by.
    pub fn channel(&self, i: usize, k: usize) -> Vec<f64> {
        self.signal(i)
            .chunks(self.channels)
            .map(|x| f64::from(x[k]))
            .collect()
    }

    /// Writes signal `i` on `mesh` as a PLY file: a 3-channel signal as the
    /// mesh moved to those positions, any other as per-vertex properties
    /// `signal` (one channel) or `signal_0, signal_1, ...`.
    ///
    /// # Errors
    /// [`DataError::SizeMismatch`] when `mesh` does not have the signals'
    /// vertices; the writer's errors.
    pub fn write_ply(&self, i: usize, mesh: &TriMesh, path: &Path) -> Result<()> {
        if mesh.num_vertices() != self.vertices {
            return Err(DataError::SizeMismatch {
                what: "vertices of the mesh the signals are written on".into(),
                expected: self.vertices,
                found: mesh.num_vertices(),
            });
        }
        let c = self.channels;
        if c == 3 {
            let moved =
                mesh.with_positions(self.positions(i))
                    .map_err(|e| DataError::MeshProcessing {
                        what: format!("signal {i} as positions"),
                        source: Box::new(e),
                    })?;
            mfm_meshio::write_ply(path, &moved, &[])?;
        } else {
            let columns: Vec<Vec<f64>> = (0..c).map(|k| self.channel(i, k)).collect();
            let names: Vec<String> = (0..c)
                .map(|k| {
                    if c == 1 {
                        "signal".into()
                    } else {
                        format!("signal_{k}")
                    }
                })
                .collect();
            let scalars: Vec<(&str, &[f64])> = names
                .iter()
                .zip(&columns)
                .map(|(name, col)| (name.as_str(), col.as_slice()))
                .collect();
            mfm_meshio::write_ply(path, mesh, &scalars)?;
        }
        Ok(())
    }
}

impl SignalSource for InMemorySignals {
    fn len(&self) -> usize {
        self.len
    }

    fn num_vertices(&self) -> usize {
        self.vertices
    }

    fn channels(&self) -> usize {
        self.channels
    }

    fn read_into(&self, indices: &[usize], out: &mut [f32]) -> Result<()> {
        let n = self.vertices * self.channels;
        check_read_request(self.len, n, indices, out.len())?;
        for (chunk, &i) in out.chunks_mut(n.max(1)).zip(indices) {
            chunk.copy_from_slice(self.signal(i));
        }
        Ok(())
    }
}

/// Position signals (3 channels) read through a similarity: every vertex
/// `p` of a signal of `inner` comes out as `frame.to_canonical(p)`. What
/// training reads when a dataset of shapes is put in the canonical frame
/// ([`mfm_geometry::frame`]); the values are converted in `f64` and rounded
/// once to `f32`.
pub struct FramedPositions {
    inner: std::sync::Arc<dyn SignalSource>,
    frame: mfm_geometry::frame::CanonicalFrame,
}

impl FramedPositions {
    /// Wraps `inner`, whose signals must have 3 channels.
    ///
    /// # Errors
    /// [`DataError::SizeMismatch`] when `inner` does not have 3 channels.
    pub fn new(
        inner: std::sync::Arc<dyn SignalSource>,
        frame: mfm_geometry::frame::CanonicalFrame,
    ) -> Result<Self> {
        require_positions(inner.as_ref())?;
        Ok(Self { inner, frame })
    }
}

/// [`DataError::SizeMismatch`] unless `source` has 3 channels (positions).
fn require_positions(source: &dyn SignalSource) -> Result<()> {
    if source.channels() != 3 {
        return Err(DataError::SizeMismatch {
            what: "channels of position signals".into(),
            expected: 3,
            found: source.channels(),
        });
    }
    Ok(())
}

impl SignalSource for FramedPositions {
    fn len(&self) -> usize {
        self.inner.len()
    }

    fn num_vertices(&self) -> usize {
        self.inner.num_vertices()
    }

    fn channels(&self) -> usize {
        3
    }

    fn read_into(&self, indices: &[usize], out: &mut [f32]) -> Result<()> {
        self.inner.read_into(indices, out)?;
        for p in out.chunks_exact_mut(3) {
            let q = self
                .frame
                .to_canonical([f64::from(p[0]), f64::from(p[1]), f64::from(p[2])]);
            for k in 0..3 {
                p[k] = q[k] as f32;
            }
        }
        Ok(())
    }
}

/// Position signals (3 channels) as displacements from a rest shape:
/// every vertex `p_i` of a signal of `inner` comes out as `p_i - r_i`, with
/// `r_i` the rest shape's vertex `i` (in the same units and frame as
/// `inner`'s signals). What training reads for a run that generates shapes
/// as displacements of the mesh they are sampled on
/// (`model.displacements`); the difference is taken in `f64` and rounded
/// once to `f32`.
///
/// # Example
/// ```
/// use std::sync::Arc;
/// use mfm_data::signals::{Displacements, InMemorySignals, SignalSource};
/// let shapes = InMemorySignals::new(vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0], 1, 2, 3).unwrap();
/// let rest = vec![[1.0, 1.0, 1.0], [0.0, 0.0, 6.0]];
/// let d = Displacements::new(Arc::new(shapes), rest).unwrap();
/// let mut out = [0.0f32; 6];
/// d.read_into(&[0], &mut out).unwrap();
/// assert_eq!(out, [0.0, 1.0, 2.0, 4.0, 5.0, 0.0]);
/// ```
pub struct Displacements {
    inner: std::sync::Arc<dyn SignalSource>,
    rest: Vec<[f64; 3]>,
}

impl Displacements {
    /// Wraps `inner`, whose signals must have 3 channels and as many
    /// vertices as `rest`.
    ///
    /// # Errors
    /// [`DataError::SizeMismatch`] when `inner` does not have 3 channels or
    /// its vertex count is not `rest.len()`.
    pub fn new(inner: std::sync::Arc<dyn SignalSource>, rest: Vec<[f64; 3]>) -> Result<Self> {
        require_positions(inner.as_ref())?;
        if inner.num_vertices() != rest.len() {
            return Err(DataError::SizeMismatch {
                what: "vertices of the rest shape".into(),
                expected: inner.num_vertices(),
                found: rest.len(),
            });
        }
        Ok(Self { inner, rest })
    }
}

impl SignalSource for Displacements {
    fn len(&self) -> usize {
        self.inner.len()
    }

    fn num_vertices(&self) -> usize {
        self.rest.len()
    }

    fn channels(&self) -> usize {
        3
    }

    fn read_into(&self, indices: &[usize], out: &mut [f32]) -> Result<()> {
        self.inner.read_into(indices, out)?;
        for signal in out.chunks_exact_mut(3 * self.rest.len().max(1)) {
            for (p, r) in signal.chunks_exact_mut(3).zip(&self.rest) {
                for k in 0..3 {
                    p[k] = (f64::from(p[k]) - r[k]) as f32;
                }
            }
        }
        Ok(())
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn rejects_bad_sizes_and_indices() {
        assert!(InMemorySignals::new(vec![0.0; 5], 2, 2, 1).is_err());
        let s = InMemorySignals::new(vec![0.0, 1.0, 2.0, 3.0, 4.0, 5.0], 3, 1, 2).unwrap();
        let mut out = [0.0f32; 4];
        s.read_into(&[2, 0], &mut out).unwrap();
        assert_eq!(out, [4.0, 5.0, 0.0, 1.0]);
        assert!(s.read_into(&[3, 0], &mut out).is_err());
        assert!(s.read_into(&[0], &mut out).is_err());
    }
}
