#![doc = include_str!("../README.md")]

pub mod export;
mod gltf;
mod obj;
mod off;
mod ply;
pub mod spec;
mod text;

use mfm_files::fmt_f64;
use mfm_geometry::mesh::{MeshError, TriMesh};
use std::fmt;
use std::io::Write;
use std::path::{Path, PathBuf};
use thiserror::Error;

pub use ply::PlyEncoding;

/// Named per-vertex scalar fields, in file order: `(name, one value per vertex)`.
pub type VertexScalars = Vec<(String, Vec<f64>)>;

/// A mesh file format.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum MeshFormat {
    /// Wavefront OBJ (text).
    Obj,
    /// Geomview OFF (text).
    Off,
    /// Stanford PLY: ASCII, binary little endian or binary big endian
    /// (detected from the header).
    Ply,
    /// glTF 2.0, JSON (`.gltf`) or binary (`.glb`), detected from the content.
    Gltf,
}

impl MeshFormat {
    /// The format for a file extension (without the dot), case-insensitively:
    /// `obj`, `off`, `ply`, `gltf` or `glb`.
    pub fn from_extension(extension: &str) -> Option<Self> {
        match extension.to_ascii_lowercase().as_str() {
            "obj" => Some(Self::Obj),
            "off" => Some(Self::Off),
            "ply" => Some(Self::Ply),
            "gltf" | "glb" => Some(Self::Gltf),
            _ => None,
        }
    }

    /// The format of a path, from its extension.
    pub fn from_path(path: &Path) -> Option<Self> {
        path.extension()
            .and_then(|e| e.to_str())
            .and_then(Self::from_extension)
    }
}

impl fmt::Display for MeshFormat {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::Obj => "OBJ",
            Self::Off => "OFF",
            Self::Ply => "PLY",
            Self::Gltf => "glTF",
        })
    }
}

/// A mesh file could not be read: which file, and what is wrong with it.
///
/// The message always starts with the path (`<memory>` for
/// [`read_mesh_from_bytes`]); [`ReadError::kind`] gives the details.
#[derive(Debug, Error)]
#[error("cannot read mesh `{}`: {kind}", path.display())]
pub struct ReadError {
    path: PathBuf,
    kind: ReadErrorKind,
}

impl ReadError {
    /// Attaches a path to a problem.
    pub fn new(path: impl Into<PathBuf>, kind: ReadErrorKind) -> Self {
        Self {
            path: path.into(),
            kind,
        }
    }

    /// The file that could not be read.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// What is wrong with it.
    pub fn kind(&self) -> &ReadErrorKind {
        &self.kind
    }

    /// Consumes the error, returning the problem.
    pub fn into_kind(self) -> ReadErrorKind {
        self.kind
    }
}

/// What is wrong with a mesh file. Line numbers are 1-based, byte offsets
/// 0-based from the start of the file, face numbers 0-based in file order
/// (before polygons are triangulated).
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum ReadErrorKind {
    /// The file extension is not one of the supported formats.
    #[error("unsupported file extension {found}; expected .obj, .off, .ply, .gltf or .glb")]
    UnknownFormat {
        /// The extension found (with its dot), or `(none)`.
        found: String,
    },
    /// The operating system could not read the file.
    #[error("{0}")]
    Io(std::io::Error),
    /// The path names a device, FIFO, socket or folder (read until memory
    /// runs out, or forever); refused before anything is read.
    #[error("this is {kind}, not a regular file; meshes are read from regular files only")]
    NotRegular {
        /// What it is: "a device", "a FIFO", "a socket", "a folder".
        kind: &'static str,
    },
    /// A text line (or a PLY header line) does not parse.
    #[error("line {line}: {message}")]
    Syntax {
        /// 1-based line number.
        line: usize,
        /// What was expected and what was found.
        message: String,
    },
    /// Binary data (binary PLY body, GLB container) does not parse, e.g. the
    /// file ends in the middle of an element.
    #[error("at byte {offset}: {message}")]
    Binary {
        /// 0-based byte offset where reading failed.
        offset: usize,
        /// What was expected and what was found.
        message: String,
    },
    /// A header declares more elements than the rest of the file can hold
    /// (a corrupt or hostile header); rejected before allocating anything.
    #[error(
        "the header declares {declared} {element}, but the remaining {available_bytes} bytes can hold at most {max_possible}"
    )]
    CountTooLarge {
        /// What is counted (`vertices`, `faces`, `elements "edge"`, ...).
        element: String,
        /// The declared count.
        declared: u64,
        /// An upper bound on how many the remaining bytes can encode.
        max_possible: u64,
        /// Bytes left after the header.
        available_bytes: usize,
    },
    /// A face has fewer than three corners.
    #[error("face {face}{} has {arity} corner(s); a face needs at least 3", line_suffix(.line))]
    FaceArity {
        /// 0-based face number in the file.
        face: usize,
        /// Its number of corners.
        arity: usize,
        /// The line it is on, for text formats.
        line: Option<usize>,
    },
    /// A valid file uses a feature this reader does not support (glTF lines or
    /// points, sparse accessors, 4D OFF, ...).
    #[error("unsupported: {0}")]
    Unsupported(String),
    /// The glTF document is invalid: JSON syntax or schema (as reported by the
    /// `gltf` crate), or buffers, views and accessors that do not fit together.
    #[error("invalid glTF: {0}")]
    Gltf(String),
    /// The file parsed, but its vertices and faces are not a valid [`TriMesh`].
    /// Face numbers in this error count triangles, after polygons were split.
    #[error("{0}")]
    Mesh(MeshError),
}

fn line_suffix(line: &Option<usize>) -> String {
    match line {
        Some(l) => format!(" (line {l})"),
        None => String::new(),
    }
}

/// What a format parser hands back before the mesh is checked.
#[derive(Debug, Default)]
pub(crate) struct Parsed {
    pub positions: Vec<[f64; 3]>,
    pub faces: Vec<[u32; 3]>,
    pub scalars: VertexScalars,
}

impl Parsed {
    fn into_mesh(self) -> Result<(TriMesh, VertexScalars), ReadErrorKind> {
        let mesh = TriMesh::new(self.positions, self.faces).map_err(ReadErrorKind::Mesh)?;
        Ok((mesh, self.scalars))
    }
}

/// Appends the fan triangulation `(c0, c_i, c_{i+1})` of a polygon with at
/// least three corners.
pub(crate) fn push_fan(faces: &mut Vec<[u32; 3]>, corners: &[u32]) {
    if let Some((&first, rest)) = corners.split_first() {
        for w in rest.windows(2) {
            faces.push([first, w[0], w[1]]);
        }
    }
}

fn parse(
    bytes: &[u8],
    format: MeshFormat,
    base: Option<&Path>,
) -> Result<(TriMesh, VertexScalars), ReadErrorKind> {
    // a UTF-8 byte-order mark some editors put before a text header
    // (`\u{feff}OFF`) is not part of it
    let bytes = bytes.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(bytes);
    let parsed = match format {
        MeshFormat::Obj => obj::parse(bytes)?,
        MeshFormat::Off => off::parse(bytes)?,
        MeshFormat::Ply => ply::parse(bytes)?,
        MeshFormat::Gltf => gltf::parse(bytes, base)?,
    };
    parsed.into_mesh()
}

fn format_of(path: &Path) -> Result<MeshFormat, ReadError> {
    MeshFormat::from_path(path).ok_or_else(|| {
        let found = match path.extension() {
            Some(e) => format!("`.{}`", e.to_string_lossy()),
            None => "(none)".to_owned(),
        };
        ReadError::new(path, ReadErrorKind::UnknownFormat { found })
    })
}

/// Reads a triangle mesh, choosing the format from the file extension
/// (case-insensitive: `.obj`, `.off`, `.ply`, `.gltf`, `.glb`). See the
/// [module docs](self) for what each reader accepts.
///
/// Cost: linear in the file size (plus `O(F)` for the mesh checks).
///
/// # Errors
/// [`ReadError`] naming the path, with the line (text) or byte offset
/// (binary) of the problem where there is one; a file that parses but is not a
/// valid [`TriMesh`] gives [`ReadErrorKind::Mesh`].
pub fn read_mesh(path: impl AsRef<Path>) -> Result<TriMesh, ReadError> {
    read_mesh_with_scalars(path).map(|(mesh, _)| mesh)
}

/// Like [`read_mesh`], and also returns the per-vertex scalar properties of a
/// PLY file (every scalar property of the `vertex` element other than
/// `x`, `y`, `z`, e.g. normals, colors or fields written by [`write_ply`]), as
/// `f64`, in file order. Other formats return an empty list.
///
/// # Errors
/// As [`read_mesh`].
pub fn read_mesh_with_scalars(
    path: impl AsRef<Path>,
) -> Result<(TriMesh, VertexScalars), ReadError> {
    let path = path.as_ref();
    let format = format_of(path)?;
    let bytes = mfm_files::read_regular(path).map_err(|e| {
        let kind = match e {
            mfm_files::FileError::InputNotRegular { kind, .. } => {
                ReadErrorKind::NotRegular { kind }
            }
            mfm_files::FileError::Io { source, .. } => ReadErrorKind::Io(source),
            other => ReadErrorKind::Io(std::io::Error::other(other.to_string())),
        };
        ReadError::new(path, kind)
    })?;
    let base = path.parent().map(|p| {
        if p.as_os_str().is_empty() {
            Path::new(".")
        } else {
            p
        }
    });
    parse(&bytes, format, base).map_err(|kind| ReadError::new(path, kind))
}

/// Parses a mesh held in memory. Errors name the path `<memory>`. A glTF
/// document read this way cannot refer to external buffer files (embedded
/// `data:` URIs and GLB binary chunks are fine).
///
/// # Errors
/// As [`read_mesh`]; never panics, whatever the bytes.
pub fn read_mesh_from_bytes(bytes: &[u8], format: MeshFormat) -> Result<TriMesh, ReadError> {
    read_mesh_with_scalars_from_bytes(bytes, format).map(|(mesh, _)| mesh)
}

/// In-memory version of [`read_mesh_with_scalars`].
///
/// # Errors
/// As [`read_mesh_from_bytes`].
pub fn read_mesh_with_scalars_from_bytes(
    bytes: &[u8],
    format: MeshFormat,
) -> Result<(TriMesh, VertexScalars), ReadError> {
    parse(bytes, format, None).map_err(|kind| ReadError::new("<memory>", kind))
}

/// A mesh file could not be written: which file, and why. Nothing at that
/// path was changed.
#[derive(Debug, Error)]
#[error("cannot write mesh `{}`: {kind}", path.display())]
pub struct WriteError {
    path: PathBuf,
    kind: WriteErrorKind,
}

impl WriteError {
    fn new(path: &Path, kind: WriteErrorKind) -> Self {
        Self {
            path: path.to_owned(),
            kind,
        }
    }

    /// The file that was to be written.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Why it was not.
    pub fn kind(&self) -> &WriteErrorKind {
        &self.kind
    }
}

/// Why a mesh file could not be written.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum WriteErrorKind {
    /// Creating, writing, syncing or renaming the file failed.
    #[error("{0}")]
    Io(std::io::Error),
    /// The path names something that must not be replaced (a folder, a
    /// device, a FIFO).
    #[error("{0}")]
    Refused(String),
    /// The file name's extension names no format mfm writes.
    #[error("the name must end in .obj or .ply (found {found:?})")]
    UnsupportedExtension {
        /// The extension found (empty when there is none).
        found: String,
    },
    /// A scalar property name is not usable in a PLY header.
    #[error("scalar property name {name:?} is invalid: {reason}")]
    InvalidScalarName {
        /// The name given.
        name: String,
        /// What is wrong with it.
        reason: &'static str,
    },
    /// A scalar property does not have one value per vertex.
    #[error("scalar property `{name}` has {found} values; expected one per vertex ({expected})")]
    ScalarLength {
        /// The property.
        name: String,
        /// The number of vertices.
        expected: usize,
        /// The number of values given.
        found: usize,
    },
}

/// Writes `mesh` in the format its name's extension says (case-insensitive):
/// `.obj` as [`write_obj`], `.ply` as [`write_ply`] without scalars.
///
/// # Errors
/// [`WriteErrorKind::UnsupportedExtension`] for any other name (nothing is
/// written), else those of the writer.
pub fn write_mesh(path: impl AsRef<Path>, mesh: &TriMesh) -> Result<(), WriteError> {
    let path = path.as_ref();
    let ext = path
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default();
    match ext.as_str() {
        "obj" => write_obj(path, mesh),
        "ply" => write_ply(path, mesh, &[]),
        _ => Err(WriteError::new(
            path,
            WriteErrorKind::UnsupportedExtension { found: ext },
        )),
    }
}

/// Writes `mesh` as Wavefront OBJ text: a comment line, `v x y z` lines and
/// 1-based `f a b c` lines. Coordinates use the shortest decimal form that
/// parses back to the same `f64`. The write is atomic (see the
/// [module docs](self)).
///
/// Cost: `O(V + F)`.
///
/// # Errors
/// [`WriteErrorKind::Io`] when the file cannot be created, written or renamed
/// into place; the destination is then unchanged.
pub fn write_obj(path: impl AsRef<Path>, mesh: &TriMesh) -> Result<(), WriteError> {
    let path = path.as_ref();
    write_atomically(path, |mut w| obj::write(&mut w, mesh)).map_err(|k| WriteError::new(path, k))
}

/// Writes `mesh` as binary little-endian PLY with `double` coordinates, a
/// `list uchar uint vertex_indices` face property, and one
/// `property double NAME` per entry of `scalars` (one value per vertex).
/// MeshLab and numpy-based readers (plyfile, `cargo xtask visual-check`) see
/// them as vertex fields; VTK's PLY reader (PyVista's `pyvista.read`,
/// ParaView) keeps only the geometry and drops extra vertex properties
/// (checked with VTK 9.7). Equivalent to
/// [`write_ply_with`] with [`PlyEncoding::BinaryLittleEndian`].
///
/// # Errors
/// See [`write_ply_with`].
pub fn write_ply(
    path: impl AsRef<Path>,
    mesh: &TriMesh,
    scalars: &[(&str, &[f64])],
) -> Result<(), WriteError> {
    write_ply_with(path, mesh, scalars, PlyEncoding::BinaryLittleEndian)
}

/// Writes `mesh` and its per-vertex `scalars` as PLY in the given encoding
/// (see [`write_ply`] for the layout). Scalar names must be non-empty, start
/// with an ASCII letter or `_`, contain only ASCII letters, digits, `_`, `-`
/// and `.`, be unique, and not be `x`, `y` or `z`. Everything is checked before
/// the file is touched; the write is atomic.
///
/// Cost: `O(V (3 + S) + F)` for `S` scalar fields.
///
/// # Errors
/// [`WriteErrorKind::InvalidScalarName`], [`WriteErrorKind::ScalarLength`],
/// [`WriteErrorKind::Io`].
pub fn write_ply_with(
    path: impl AsRef<Path>,
    mesh: &TriMesh,
    scalars: &[(&str, &[f64])],
    encoding: PlyEncoding,
) -> Result<(), WriteError> {
    let path = path.as_ref();
    ply::check_scalars(mesh, scalars).map_err(|k| WriteError::new(path, k))?;
    write_atomically(path, |mut w| ply::write(&mut w, mesh, scalars, encoding))
        .map_err(|k| WriteError::new(path, k))
}

/// Writes through `body` with [`mfm_files::write_atomic`]: a temporary
/// file next to `path`, synced and renamed over it; on any failure `path` is
/// left as it was. Folders, devices and FIFOs at `path` are refused; a
/// symbolic link is followed.
fn write_atomically(
    path: &Path,
    body: impl FnOnce(&mut dyn Write) -> std::io::Result<()>,
) -> Result<(), WriteErrorKind> {
    mfm_files::write_atomic(path, body).map_err(|e| match e {
        mfm_files::FileError::Io { source, .. } => WriteErrorKind::Io(source),
        other => WriteErrorKind::Refused(other.to_string()),
    })
}
