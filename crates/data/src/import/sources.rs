//! Where imported signals come from: mesh files of one connectivity, PLY
//! files' vertex properties, a NumPy array, or the tensors of the authors'
//! dataset files. Each is a [`SignalFiles`]: a template mesh and `N`
//! signals of `C` values per template vertex, read one at a time, each
//! with the name a user knows it by.

use std::io::{BufReader, Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};

use mfm_geometry::TriMesh;

use crate::error::{DataError, Result};

/// `N` signals of `C` values per vertex of a template mesh, read one at a
/// time (so that an import never holds every shape at once).
pub trait SignalFiles: Sync {
    /// The number of signals `N`.
    fn len(&self) -> usize;
    /// Whether there are no signals.
    fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// Channels per vertex `C` (3 for shapes).
    fn channels(&self) -> usize;
    /// Whether the signals are vertex positions of the template.
    fn positions(&self) -> bool;
    /// What a user calls signal `i` (a file name, `ARRAY[i]`).
    fn name(&self, i: usize) -> String;
    /// Signal `i`: `V x C` values, vertex-major, as read (finite or not:
    /// the importer checks).
    ///
    /// # Errors
    /// A file that cannot be read or does not fit the template, naming it.
    fn read(&self, i: usize, template: &TriMesh) -> Result<Vec<f32>>;
}

/// Shapes as mesh files of the template's connectivity: signal `i` is the
/// vertex positions of file `i`, or with `properties`, those per-vertex
/// PLY properties of it.
#[derive(Clone, Debug)]
pub struct MeshFiles {
    /// The files, in order.
    pub files: Vec<PathBuf>,
    /// PLY vertex properties to read as channels instead of the positions
    /// (empty: positions).
    pub properties: Vec<String>,
}

impl SignalFiles for MeshFiles {
    fn len(&self) -> usize {
        self.files.len()
    }

    fn channels(&self) -> usize {
        if self.properties.is_empty() {
            3
        } else {
            self.properties.len()
        }
    }

    fn positions(&self) -> bool {
        self.properties.is_empty()
    }

    fn name(&self, i: usize) -> String {
        self.files[i].display().to_string()
    }

    fn read(&self, i: usize, template: &TriMesh) -> Result<Vec<f32>> {
        let path = &self.files[i];
        let (mesh, scalars) = mfm_meshio::read_mesh_with_scalars(path)?;
        same_connectivity(template, &mesh, path)?;
        if self.properties.is_empty() {
            return Ok(mesh
                .positions()
                .iter()
                .flat_map(|p| p.map(|x| x as f32))
                .collect());
        }
        let columns = self
            .properties
            .iter()
            .map(|name| {
                scalars
                    .iter()
                    .find(|(n, _)| n == name)
                    .map(|(_, values)| values)
                    .ok_or_else(|| {
                        let found: Vec<&str> = scalars.iter().map(|(n, _)| n.as_str()).collect();
                        DataError::format(
                            path,
                            format!(
                                "has no vertex property {name:?} (it has: {})",
                                if found.is_empty() {
                                    "none".to_owned()
                                } else {
                                    found.join(", ")
                                }
                            ),
                        )
                    })
            })
            .collect::<Result<Vec<_>>>()?;
        let v = mesh.num_vertices();
        let mut out = Vec::with_capacity(v * columns.len());
        for vertex in 0..v {
            out.extend(columns.iter().map(|c| c[vertex] as f32));
        }
        Ok(out)
    }
}

/// Checks that `mesh` (read from `path`) has the template's vertex count
/// and faces, naming the first difference.
///
/// # Errors
/// [`DataError::Files`] (`Format`) naming `path`: the vertex count, the
/// face count or the first differing face.
pub fn same_connectivity(template: &TriMesh, mesh: &TriMesh, path: &Path) -> Result<()> {
    if mesh.num_vertices() != template.num_vertices() {
        return Err(DataError::format(
            path,
            format!(
                "has {} vertices, the template has {}: every shape must have the template's \
                 vertices and faces",
                mesh.num_vertices(),
                template.num_vertices()
            ),
        ));
    }
    if mesh.num_faces() != template.num_faces() {
        return Err(DataError::format(
            path,
            format!(
                "has {} faces, the template has {}: every shape must have the template's \
                 vertices and faces",
                mesh.num_faces(),
                template.num_faces()
            ),
        ));
    }
    if let Some((f, (a, b))) = mesh
        .faces()
        .iter()
        .zip(template.faces())
        .enumerate()
        .find(|(_, (a, b))| a != b)
    {
        return Err(DataError::format(
            path,
            format!(
                "face {f} is {a:?}, the template's is {b:?}: every shape must have the \
                 template's faces, in its order"
            ),
        ));
    }
    Ok(())
}

/// Signals in a NumPy `.npy` array `[N, V]` or `[N, V, C]` of little-endian
/// `float32` or `float64`, C order, read row by row (never whole).
#[derive(Clone, Debug)]
pub struct NpyRows {
    path: PathBuf,
    len: usize,
    vertices: usize,
    channels: usize,
    value_bytes: usize,
    data_offset: u64,
    positions: bool,
}

impl NpyRows {
    /// Opens the array at `path` and checks its header against the file's
    /// length. `positions` says whether 3-channel rows are vertex positions
    /// of the template.
    ///
    /// # Errors
    /// [`DataError::Files`] naming the file: unreadable, not a `.npy` array,
    /// a dtype other than little-endian `float32`/`float64`, Fortran order,
    /// another rank, or fewer bytes than the shape needs.
    pub fn open(path: &Path, positions: bool) -> Result<Self> {
        let file = mfm_files::open_regular(path)?;
        let file_len = file.metadata().map_err(|e| DataError::io(path, e))?.len();
        let mut reader = BufReader::new(file);
        let header = npyz::NpyHeader::from_reader(&mut reader)
            .map_err(|e| DataError::format(path, format!("not a .npy array ({e})")))?;
        let data_offset = reader
            .stream_position()
            .map_err(|e| DataError::io(path, e))?;
        let dtype = header.dtype().descr();
        let value_bytes = match dtype.trim_matches('\'') {
            "<f4" => 4,
            "<f8" => 8,
            other => {
                return Err(DataError::format(
                    path,
                    format!(
                        "dtype {other}: expected little-endian float32 or float64 ('<f4', '<f8')"
                    ),
                ));
            }
        };
        if header.order() != npyz::Order::C {
            return Err(DataError::format(
                path,
                "the array is in Fortran order; save it in C order (numpy.ascontiguousarray)",
            ));
        }
        let shape = header.shape().to_vec();
        let (n, v, c) = match shape[..] {
            [n, v] => (n, v, 1),
            [n, v, c] => (n, v, c),
            _ => {
                return Err(DataError::format(
                    path,
                    format!("the array has shape {shape:?}, expected [N, V] or [N, V, C]"),
                ));
            }
        };
        let needed = n
            .checked_mul(v)
            .and_then(|x| x.checked_mul(c))
            .and_then(|x| x.checked_mul(value_bytes))
            .ok_or_else(|| DataError::format(path, format!("shape {shape:?} overflows")))?;
        let have = file_len.saturating_sub(data_offset);
        if have != needed {
            return Err(DataError::format(
                path,
                format!(
                    "the shape {shape:?} needs {needed} bytes of data after the header, the file \
                     has {have}"
                ),
            ));
        }
        let size = |x: u64| {
            usize::try_from(x).map_err(|_| DataError::format(path, "the array is too large"))
        };
        Ok(Self {
            path: path.to_path_buf(),
            len: size(n)?,
            vertices: size(v)?,
            channels: size(c)?,
            value_bytes: value_bytes as usize,
            data_offset,
            positions,
        })
    }

    /// Vertices per row `V`.
    pub fn num_vertices(&self) -> usize {
        self.vertices
    }
}

impl SignalFiles for NpyRows {
    fn len(&self) -> usize {
        self.len
    }

    fn channels(&self) -> usize {
        self.channels
    }

    fn positions(&self) -> bool {
        self.positions
    }

    fn name(&self, i: usize) -> String {
        format!("{}[{i}]", self.path.display())
    }

    fn read(&self, i: usize, template: &TriMesh) -> Result<Vec<f32>> {
        if template.num_vertices() != self.vertices {
            return Err(DataError::format(
                &self.path,
                format!(
                    "rows have {} vertices, the mesh has {}",
                    self.vertices,
                    template.num_vertices()
                ),
            ));
        }
        let row = self.vertices * self.channels;
        let mut bytes = vec![0u8; row * self.value_bytes];
        let mut file = mfm_files::open_regular(&self.path)?;
        file.seek(SeekFrom::Start(
            self.data_offset + (i * row * self.value_bytes) as u64,
        ))
        .and_then(|_| file.read_exact(&mut bytes))
        .map_err(|e| DataError::io(&self.path, e))?;
        Ok(if self.value_bytes == 4 {
            bytes
                .chunks_exact(4)
                .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
                .collect()
        } else {
            bytes
                .chunks_exact(8)
                .map(|b| {
                    let mut a = [0u8; 8];
                    a.copy_from_slice(b);
                    f64::from_le_bytes(a) as f32
                })
                .collect()
        })
    }
}

/// Shapes held in memory (the `tar_verts` of the authors' dataset file,
/// read with [`mfm_torchfile`]): `N` rows of `V x 3` positions.
#[derive(Clone, Debug)]
pub struct ShapesInMemory {
    /// What the rows are called (`FILE:tar_verts`).
    pub source: String,
    /// `N x V x 3` values.
    pub values: Vec<f32>,
    /// Vertices per shape.
    pub vertices: usize,
}

impl SignalFiles for ShapesInMemory {
    fn len(&self) -> usize {
        self.values.len() / (3 * self.vertices).max(1)
    }

    fn channels(&self) -> usize {
        3
    }

    fn positions(&self) -> bool {
        true
    }

    fn name(&self, i: usize) -> String {
        format!("{}[{i}]", self.source)
    }

    fn read(&self, i: usize, _template: &TriMesh) -> Result<Vec<f32>> {
        let row = 3 * self.vertices;
        Ok(self.values[i * row..(i + 1) * row].to_vec())
    }
}

/// (source, target) shape pairs held in memory (the authors'
/// arbitrary-source file: `src_verts` and `tar_verts`, both `[N, V, 3]`),
/// read as `2 N` shapes: shape `2 i` is the source of pair `i`, shape
/// `2 i + 1` its target (see [`super::ImportManifest::pairs`]).
#[derive(Clone, Debug)]
pub struct PairedShapes {
    /// The sources, one per pair.
    pub sources: ShapesInMemory,
    /// The targets, one per pair.
    pub targets: ShapesInMemory,
}

impl PairedShapes {
    /// Pairs `sources[i]` with `targets[i]`.
    ///
    /// # Errors
    /// [`DataError::Config`] when the two hold different numbers of shapes
    /// or of vertices.
    pub fn new(sources: ShapesInMemory, targets: ShapesInMemory) -> Result<Self> {
        if sources.len() != targets.len() || sources.vertices != targets.vertices {
            return Err(DataError::Config(format!(
                "{} holds {} shapes of {} vertices and {} holds {} of {}: pairs need one source \
                 per target",
                sources.source,
                sources.len(),
                sources.vertices,
                targets.source,
                targets.len(),
                targets.vertices
            )));
        }
        Ok(Self { sources, targets })
    }

    fn side(&self, i: usize) -> &ShapesInMemory {
        if i % 2 == 0 {
            &self.sources
        } else {
            &self.targets
        }
    }
}

impl SignalFiles for PairedShapes {
    fn len(&self) -> usize {
        2 * self.targets.len()
    }

    fn channels(&self) -> usize {
        3
    }

    fn positions(&self) -> bool {
        true
    }

    fn name(&self, i: usize) -> String {
        self.side(i).name(i / 2)
    }

    fn read(&self, i: usize, template: &TriMesh) -> Result<Vec<f32>> {
        self.side(i).read(i / 2, template)
    }
}
