//! On-disk datasets of signals over one mesh.
//!
//! A dataset is a folder with three files:
//!
//! | file | contents |
//! |---|---|
//! | [`MESH_FILE`] (`mesh.ply`) | the mesh, binary little-endian PLY with `double` coordinates (exact round trip; readable by [`mfm_meshio::read_mesh`], MeshLab, ParaView, PyVista) |
//! | [`SIGNALS_FILE`] (`signals.npy`) | the signals: NumPy `.npy`, dtype `<f4` (little-endian `f32`), C order, shape `[N, V, C]` (`V` the mesh's vertex count, `C` channels per vertex) |
//! | [`MANIFEST_FILE`] (`manifest.json`) | a [`Manifest`]: format version, generator name and parameters, `N`/`V`/`C`, seed, the version of the tool that wrote it, free-form provenance |
//!
//! [`Dataset::write`] writes all three into a temporary folder next to the
//! destination and renames it into place, so a failed or interrupted write
//! never leaves a half-written dataset; it refuses to replace an existing,
//! non-empty folder unless [`WriteOptions::overwrite`] is set.
//! [`Dataset::open`] checks everything before returning: that the files
//! exist, that the manifest parses and has a known format version, that the
//! mesh reads, that the `.npy` header has the right dtype, order and rank,
//! that its shape agrees with the mesh and the manifest, and that the file is
//! long enough to hold the array. Errors name the file at fault.
//!
//! A [`Dataset`] does not keep the signals in memory: as a
//! [`SignalSource`] it reads only the requested rows, seeking to
//! `header length + row * V * C * 4` (runs of consecutive rows are read in
//! one go), so training can stream batches from a dataset larger than RAM.
//! [`Dataset::load_all`] reads everything when that is what is wanted.
//!
//! # Example
//! ```
//! use mfm_data::dataset::{Dataset, Manifest};
//! use mfm_data::{InMemorySignals, SignalSource};
//! use mfm_geometry::procedural;
//! let dir = std::env::temp_dir().join(format!("mfm-dataset-doc-{}", std::process::id()));
//! let mesh = procedural::icosphere(1); // 42 vertices
//! let signals = InMemorySignals::new(vec![0.5; 3 * 42], 3, 42, 1).unwrap();
//! let manifest = Manifest::new("constant", serde_json::json!({ "value": 0.5 })).with_seed(7);
//! let ds = Dataset::write(&dir, &mesh, &signals, manifest).unwrap();
//! assert_eq!((ds.len(), ds.num_vertices(), ds.channels()), (3, 42, 1));
//! let reopened = Dataset::open(&dir).unwrap();
//! let mut row = vec![0.0f32; 42];
//! reopened.read_into(&[2], &mut row).unwrap();
//! assert_eq!(row, vec![0.5; 42]);
//! std::fs::remove_dir_all(&dir).unwrap();
//! ```

use std::fs::File;
use std::io::{self, BufReader, Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

use mfm_geometry::TriMesh;
use mfm_geometry::frame::CanonicalFrame;
use mfm_meshio::{read_mesh, write_ply};
use serde::{Deserialize, Serialize};

use crate::error::{DataError, Result};
use crate::signals::{InMemorySignals, SignalSource};

/// Name of the mesh file inside a dataset folder.
pub const MESH_FILE: &str = "mesh.ply";
/// Name of the signal array inside a dataset folder.
pub const SIGNALS_FILE: &str = "signals.npy";
/// Name of the manifest inside a dataset folder.
pub const MANIFEST_FILE: &str = mfm_files::owned::MANIFEST;
/// The manifest format version this code writes (and the newest it reads).
pub const FORMAT_VERSION: u32 = 1;

/// The `.npy` dtype of the signals: little-endian `f32`.
const DTYPE: &str = "<f4";
/// Bytes per value.
const VALUE_BYTES: u64 = 4;
/// Largest number of bytes read at once by [`Dataset::read_into`].
const READ_CHUNK_BYTES: usize = 1 << 22;

/// What a dataset is and where it came from, stored as `manifest.json`.
///
/// `num_signals`, `num_vertices` and `channels` are filled in by
/// [`Dataset::write`] from the data; the rest is the caller's.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Manifest {
    /// Version of this format ([`FORMAT_VERSION`] when written by this code).
    pub format_version: u32,
    /// Name of the generator that made the signals (e.g. `"gmm"`).
    pub generator: String,
    /// The generator's parameters, as JSON (e.g. a serialized
    /// [`GmmConfig`](crate::gmm::GmmConfig)).
    #[serde(default)]
    pub generator_params: serde_json::Value,
    /// `N`: number of signals.
    pub num_signals: usize,
    /// `V`: vertices per signal (the mesh's vertex count).
    pub num_vertices: usize,
    /// `C`: channels per vertex.
    pub channels: usize,
    /// The random seed the generator used, if any.
    #[serde(default)]
    pub seed: Option<u64>,
    /// The software that wrote the dataset and its version
    /// (`"mfm-fm <version>"` by default).
    pub tool_version: String,
    /// Free-form provenance (command line, source mesh, date, notes).
    #[serde(default)]
    pub provenance: String,
    /// The canonical frame of the experiment's training surface
    /// ([`mfm_geometry::frame`]), in the units of this dataset's mesh:
    /// training moves the surface (and position signals) through it first.
    /// Recorded by the dataset generators; absent in older datasets.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub frame: Option<CanonicalFrame>,
}

impl Manifest {
    /// A manifest for `generator` with `generator_params`, no seed, empty
    /// provenance, this crate as the tool, and sizes to be filled in by
    /// [`Dataset::write`].
    pub fn new(generator: impl Into<String>, generator_params: serde_json::Value) -> Self {
        Self {
            format_version: FORMAT_VERSION,
            generator: generator.into(),
            generator_params,
            num_signals: 0,
            num_vertices: 0,
            channels: 0,
            seed: None,
            tool_version: concat!("mfm-fm ", env!("CARGO_PKG_VERSION")).to_string(),
            provenance: String::new(),
            frame: None,
        }
    }

    /// Records the training surface's canonical frame.
    #[must_use]
    pub fn with_frame(mut self, frame: CanonicalFrame) -> Self {
        self.frame = Some(frame);
        self
    }

    /// Sets the seed.
    #[must_use]
    pub fn with_seed(mut self, seed: u64) -> Self {
        self.seed = Some(seed);
        self
    }

    /// Sets the free-form provenance text.
    #[must_use]
    pub fn with_provenance(mut self, provenance: impl Into<String>) -> Self {
        self.provenance = provenance.into();
        self
    }
}

/// Options of [`Dataset::write_with`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct WriteOptions {
    /// Replace an existing non-empty destination folder (its contents are
    /// deleted once the new dataset is in place). Default `false`.
    pub overwrite: bool,
}

/// An opened, validated dataset folder (see the [module docs](self)).
///
/// Holds the mesh and the manifest; reads signals from disk on demand.
#[derive(Clone, Debug)]
pub struct Dataset {
    dir: PathBuf,
    mesh: TriMesh,
    manifest: Manifest,
    signals_path: PathBuf,
    data_offset: u64,
    len: usize,
    vertices: usize,
    channels: usize,
}

/// The identity of a mesh, for telling whether two folders hold the same
/// template: `V{vertices}-F{faces}-{hash}` with a 64-bit FNV-1a hash of the
/// positions' bits and the face indices. Two meshes with one value are, up
/// to hash collisions, the same vertices in the same order with the same
/// faces; another triangulation or a moved vertex gives another value.
///
/// Cost: `O(V + F)`.
pub fn mesh_identity(mesh: &TriMesh) -> String {
    let mut h = Fnv1a::new();
    for p in mesh.positions() {
        for x in p {
            h.feed(&x.to_bits().to_le_bytes());
        }
    }
    for f in mesh.faces() {
        for i in f {
            h.feed(&i.to_le_bytes());
        }
    }
    let h = h.finish();
    format!("V{}-F{}-{h:016x}", mesh.num_vertices(), mesh.num_faces())
}

/// The 64-bit FNV-1a hash of a stream of bytes: [`mesh_identity`]'s, and
/// how an import tells a copy of an earlier signal.
pub(crate) struct Fnv1a(u64);

impl Fnv1a {
    /// The hash of no bytes.
    pub(crate) fn new() -> Self {
        Self(0xcbf2_9ce4_8422_2325)
    }

    /// Hashes `bytes` in.
    pub(crate) fn feed(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.0 ^= u64::from(b);
            self.0 = self.0.wrapping_mul(0x0100_0000_01b3);
        }
    }

    /// The hash so far.
    pub(crate) fn finish(&self) -> u64 {
        self.0
    }
}

impl Dataset {
    /// Writes `mesh`, `signals` and `manifest` as a dataset folder `dir`
    /// (atomically; refuses a non-empty existing `dir`) and opens it.
    ///
    /// The manifest's sizes are set from `signals`.
    ///
    /// # Errors
    /// [`DataError::SizeMismatch`] if the signals are not on the mesh;
    /// [`DataError::Files`] (`Io`) if `dir` is a non-empty folder (or not a folder), or a
    /// file cannot be written; [`DataError::WriteMesh`].
    pub fn write(
        dir: impl AsRef<Path>,
        mesh: &TriMesh,
        signals: &InMemorySignals,
        manifest: Manifest,
    ) -> Result<Self> {
        Self::write_with(dir, mesh, signals, manifest, WriteOptions::default())
    }

    /// [`Dataset::write`] with explicit [`WriteOptions`].
    ///
    /// # Errors
    /// As [`Dataset::write`] (a non-empty `dir` is replaced when
    /// `options.overwrite` is set).
    pub fn write_with(
        dir: impl AsRef<Path>,
        mesh: &TriMesh,
        signals: &InMemorySignals,
        mut manifest: Manifest,
        options: WriteOptions,
    ) -> Result<Self> {
        let dir = dir.as_ref();
        if signals.num_vertices() != mesh.num_vertices() {
            return Err(DataError::SizeMismatch {
                what: "vertices per signal".into(),
                expected: mesh.num_vertices(),
                found: signals.num_vertices(),
            });
        }
        manifest.num_signals = signals.len();
        manifest.num_vertices = signals.num_vertices();
        manifest.channels = signals.channels();

        let existing = inspect_destination(dir)?;
        if existing == Destination::NonEmpty && !options.overwrite {
            return Err(DataError::io(
                dir,
                io::Error::new(
                    io::ErrorKind::AlreadyExists,
                    "the folder exists and is not empty; refusing to overwrite it \
                     (ask for overwrite to replace it)",
                ),
            ));
        }
        let parent = parent_of(dir);
        std::fs::create_dir_all(&parent).map_err(|e| DataError::io(&parent, e))?;
        let temp = sibling(dir, "tmp");
        std::fs::create_dir(&temp).map_err(|e| DataError::io(&temp, e))?;
        if let Err(e) = write_files(&temp, mesh, signals, &manifest) {
            let _ = std::fs::remove_dir_all(&temp);
            return Err(e);
        }
        let swapped = match existing {
            Destination::Missing => std::fs::rename(&temp, dir).map_err(|e| DataError::io(dir, e)),
            Destination::Empty => std::fs::remove_dir(dir)
                .and_then(|()| std::fs::rename(&temp, dir))
                .map_err(|e| DataError::io(dir, e)),
            Destination::NonEmpty => {
                let old = sibling(dir, "old");
                std::fs::rename(dir, &old)
                    .map_err(|e| DataError::io(dir, e))
                    .and_then(|()| {
                        std::fs::rename(&temp, dir).map_err(|e| {
                            // put the previous dataset back
                            let _ = std::fs::rename(&old, dir);
                            DataError::io(dir, e)
                        })
                    })
                    .map(|()| {
                        let _ = std::fs::remove_dir_all(&old);
                    })
            }
        };
        if let Err(e) = swapped {
            let _ = std::fs::remove_dir_all(&temp);
            return Err(e);
        }
        if let Ok(p) = File::open(&parent) {
            // make the rename durable where the platform allows syncing a folder
            let _ = p.sync_all();
        }
        Self::open(dir)
    }

    /// Opens and validates the dataset folder `dir` (see the
    /// [module docs](self) for what is checked). Reads the manifest, the mesh
    /// and the `.npy` header; not the signals.
    ///
    /// # Errors
    /// [`DataError::Files`] (`Io`) for a missing or unreadable file, [`DataError::Files`] (`Format`)
    /// (naming the file) for a malformed manifest, an unsupported format
    /// version, a wrong dtype, order or shape, sizes that disagree between the
    /// files, or a truncated array; [`DataError::ReadMesh`] for a bad mesh.
    pub fn open(dir: impl AsRef<Path>) -> Result<Self> {
        let dir = dir.as_ref().to_path_buf();
        if dir.is_file() {
            return Err(DataError::format(
                &dir,
                format!(
                    "this is a file, not a dataset folder (a folder with {MANIFEST_FILE}, {MESH_FILE} and {SIGNALS_FILE}, as `mfm dataset` writes)"
                ),
            ));
        }
        if !dir.is_dir() {
            return Err(DataError::io(
                &dir,
                io::Error::new(io::ErrorKind::NotFound, "no such dataset folder"),
            ));
        }
        let manifest_path = dir.join(MANIFEST_FILE);
        if !manifest_path.exists() {
            // the set names of an experiment folder (`crate::layout` writes
            // them; they live in the leaf `mfm_files::owned`)
            let sets: Vec<String> = mfm_files::owned::SETS
                .iter()
                .filter(|s| dir.join(s).join(MANIFEST_FILE).is_file())
                .map(|s| dir.join(s).display().to_string())
                .collect();
            if !sets.is_empty() {
                return Err(DataError::format(
                    &dir,
                    format!(
                        "this is an experiment folder, not a dataset folder: its datasets are {} \
                         (give one of them, e.g. {})",
                        sets.join(", "),
                        sets[0]
                    ),
                ));
            }
        }
        let text = std::fs::read(&manifest_path).map_err(|e| DataError::io(&manifest_path, e))?;
        let manifest: Manifest = serde_json::from_slice(&text).map_err(|e| {
            DataError::format(&manifest_path, format!("not a valid dataset manifest: {e}"))
        })?;
        if manifest.format_version == 0 || manifest.format_version > FORMAT_VERSION {
            return Err(DataError::format(
                &manifest_path,
                format!(
                    "format version {} is not supported (this build reads versions 1 to {FORMAT_VERSION})",
                    manifest.format_version
                ),
            ));
        }

        let mesh_path = dir.join(MESH_FILE);
        if !mesh_path.is_file() {
            return Err(DataError::io(
                &mesh_path,
                io::Error::new(
                    io::ErrorKind::NotFound,
                    "the dataset's mesh file is missing",
                ),
            ));
        }
        let mesh = read_mesh(&mesh_path)?;

        let signals_path = dir.join(SIGNALS_FILE);
        let header = read_npy_header(&signals_path)?;
        let [len, vertices, channels] = header.shape;
        let fmt = |message: String| DataError::format(&signals_path, message);
        if vertices != mesh.num_vertices() {
            return Err(fmt(format!(
                "the array has shape [{len}, {vertices}, {channels}], but {MESH_FILE} has {} vertices",
                mesh.num_vertices()
            )));
        }
        if [len, vertices, channels]
            != [
                manifest.num_signals,
                manifest.num_vertices,
                manifest.channels,
            ]
        {
            return Err(fmt(format!(
                "the array has shape [{len}, {vertices}, {channels}], but {MANIFEST_FILE} says [{}, {}, {}]",
                manifest.num_signals, manifest.num_vertices, manifest.channels
            )));
        }
        Ok(Self {
            dir,
            mesh,
            manifest,
            signals_path,
            data_offset: header.data_offset,
            len,
            vertices,
            channels,
        })
    }

    /// The dataset folder.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// The mesh every signal lives on.
    pub fn mesh(&self) -> &TriMesh {
        &self.mesh
    }

    /// The manifest's `generator_params` as `T` when `generator` made the
    /// dataset (`None` for another generator).
    ///
    /// # Errors
    /// [`DataError::Files`] (`Format`) naming the manifest when they do not parse.
    pub fn generator_params<T: serde::de::DeserializeOwned>(
        &self,
        generator: &str,
    ) -> Result<Option<T>> {
        if self.manifest.generator != generator {
            return Ok(None);
        }
        serde_json::from_value(self.manifest.generator_params.clone())
            .map(Some)
            .map_err(|e| {
                DataError::format(
                    self.dir.join("manifest.json"),
                    format!("generator_params of a {generator} dataset: {e}"),
                )
            })
    }

    /// The manifest.
    pub fn manifest(&self) -> &Manifest {
        &self.manifest
    }

    /// Reads every signal into memory.
    ///
    /// # Errors
    /// As [`SignalSource::read_into`].
    pub fn load_all(&self) -> Result<InMemorySignals> {
        let total = self
            .len
            .checked_mul(self.row_values())
            .ok_or_else(|| DataError::format(&self.signals_path, "the array is too large"))?;
        let mut data = vec![0.0f32; total];
        self.read_run(0, &mut data)?;
        InMemorySignals::new(data, self.len, self.vertices, self.channels)
    }

    /// Values per signal (`V x C`).
    fn row_values(&self) -> usize {
        self.vertices * self.channels
    }

    /// Reads `out.len() / (V C)` consecutive rows from `first` on.
    fn read_run_from(&self, file: &mut File, first: usize, out: &mut [f32]) -> Result<()> {
        let offset = self.data_offset + first as u64 * self.row_values() as u64 * VALUE_BYTES;
        file.seek(SeekFrom::Start(offset))
            .map_err(|e| DataError::io(&self.signals_path, e))?;
        let mut bytes = vec![0u8; (out.len() * VALUE_BYTES as usize).min(READ_CHUNK_BYTES)];
        for chunk in out.chunks_mut(READ_CHUNK_BYTES / VALUE_BYTES as usize) {
            let buf = &mut bytes[..chunk.len() * VALUE_BYTES as usize];
            file.read_exact(buf).map_err(|e| {
                if e.kind() == io::ErrorKind::UnexpectedEof {
                    DataError::format(
                        &self.signals_path,
                        "the file ended before the requested rows (truncated after it was opened?)",
                    )
                } else {
                    DataError::io(&self.signals_path, e)
                }
            })?;
            for (x, b) in chunk.iter_mut().zip(buf.chunks_exact(VALUE_BYTES as usize)) {
                *x = f32::from_le_bytes([b[0], b[1], b[2], b[3]]);
            }
        }
        if let Some((i, vertex, channel, x)) =
            crate::signals::first_non_finite(out, self.vertices, self.channels)
        {
            return Err(DataError::format(
                &self.signals_path,
                format!(
                    "signal {}, vertex {vertex}, channel {channel} is {x} (a dataset must hold finite values)",
                    first + i
                ),
            ));
        }
        Ok(())
    }

    /// [`Dataset::read_run_from`] on a freshly opened file.
    fn read_run(&self, first: usize, out: &mut [f32]) -> Result<()> {
        let mut file =
            File::open(&self.signals_path).map_err(|e| DataError::io(&self.signals_path, e))?;
        self.read_run_from(&mut file, first, out)
    }
}

impl SignalSource for Dataset {
    fn len(&self) -> usize {
        self.len
    }

    fn num_vertices(&self) -> usize {
        self.vertices
    }

    fn channels(&self) -> usize {
        self.channels
    }

    /// Reads the rows `indices` from `signals.npy` (opening it once per call,
    /// one seek and one read per run of consecutive indices).
    fn read_into(&self, indices: &[usize], out: &mut [f32]) -> Result<()> {
        let n = self.row_values();
        crate::signals::check_read_request(self.len, n, indices, out.len())?;
        if indices.is_empty() || n == 0 {
            return Ok(());
        }
        let mut file =
            File::open(&self.signals_path).map_err(|e| DataError::io(&self.signals_path, e))?;
        let mut start = 0;
        while start < indices.len() {
            let mut end = start + 1;
            while end < indices.len() && indices[end] == indices[end - 1] + 1 {
                end += 1;
            }
            self.read_run_from(&mut file, indices[start], &mut out[start * n..end * n])?;
            start = end;
        }
        Ok(())
    }
}

/// What is at a write destination.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Destination {
    Missing,
    Empty,
    NonEmpty,
}

fn inspect_destination(dir: &Path) -> Result<Destination> {
    match std::fs::metadata(dir) {
        Err(e) if e.kind() == io::ErrorKind::NotFound => Ok(Destination::Missing),
        Err(e) => Err(DataError::io(dir, e)),
        Ok(meta) if !meta.is_dir() => Err(DataError::io(
            dir,
            io::Error::new(
                io::ErrorKind::AlreadyExists,
                "exists and is not a folder; a dataset is written as a folder",
            ),
        )),
        Ok(_) => {
            let mut entries = std::fs::read_dir(dir).map_err(|e| DataError::io(dir, e))?;
            Ok(if entries.next().is_some() {
                Destination::NonEmpty
            } else {
                Destination::Empty
            })
        }
    }
}

/// The folder that holds `dir` (`.` for a bare name).
fn parent_of(dir: &Path) -> PathBuf {
    match dir.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    }
}

/// A fresh hidden path next to `dir`: `.NAME.KIND-PID-COUNTER`.
fn sibling(dir: &Path, kind: &str) -> PathBuf {
    static COUNTER: AtomicU64 = AtomicU64::new(0);
    let name = dir
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "dataset".into());
    let count = COUNTER.fetch_add(1, Ordering::Relaxed);
    parent_of(dir).join(format!(".{name}.{kind}-{}-{count}", std::process::id()))
}

/// Writes the three files into `dir` (an empty folder).
fn write_files(
    dir: &Path,
    mesh: &TriMesh,
    signals: &InMemorySignals,
    manifest: &Manifest,
) -> Result<()> {
    write_ply(dir.join(MESH_FILE), mesh, &[])?;
    let shape = [
        signals.len() as u64,
        signals.num_vertices() as u64,
        signals.channels() as u64,
    ];
    let mut stream = mfm_files::npy::NpyStream::<f32>::create(dir.join(SIGNALS_FILE), &shape)?;
    stream.append(signals.data())?;
    stream.finish()?;
    write_manifest(dir, manifest)
}

/// Writes `manifest` as [`MANIFEST_FILE`] in `dir`, atomically.
fn write_manifest(dir: &Path, manifest: &Manifest) -> Result<()> {
    Ok(mfm_files::write_json(dir.join(MANIFEST_FILE), manifest)?)
}

/// A dataset folder written signal by signal, for sets larger than memory
/// (`mfm dataset import`): the mesh and the `.npy` header first, then the
/// signals in order, then the manifest; the folder appears at its path
/// only when [`DatasetWriter::finish`] succeeds.
///
/// It is written as a hidden sibling `.NAME.tmp-PID-N` (removed by an
/// interrupt, see [`mfm_files::interrupt`], by [`Drop`] when the writer is
/// not finished, and by the next writer when a killed process left it) and
/// renamed into place.
///
/// # Example
/// ```
/// use mfm_data::dataset::{Dataset, DatasetWriter, Manifest};
/// use mfm_data::SignalSource;
/// use mfm_geometry::procedural;
/// let dir = tempfile::tempdir().unwrap();
/// let mesh = procedural::icosphere(1); // 42 vertices
/// let manifest = Manifest::new("constant", serde_json::json!({}));
/// let mut w = DatasetWriter::create(dir.path().join("set"), &mesh, manifest, 2, 1).unwrap();
/// w.append(&[0.5; 42]).unwrap();
/// w.append(&[1.5; 42]).unwrap();
/// let ds: Dataset = w.finish().unwrap();
/// assert_eq!((ds.len(), ds.num_vertices(), ds.channels()), (2, 42, 1));
/// ```
#[derive(Debug)]
pub struct DatasetWriter {
    dir: PathBuf,
    temp: PathBuf,
    signals: Option<mfm_files::npy::NpyStream<f32>>,
    manifest: Manifest,
    finished: bool,
    _registered: mfm_files::interrupt::TemporaryDir,
}

impl DatasetWriter {
    /// Starts the dataset `dir` (missing or an empty folder) of `len`
    /// signals of `channels` values per vertex of `mesh`: writes the mesh
    /// and the array's header. The manifest's sizes are set here.
    ///
    /// # Errors
    /// [`DataError::Files`] (`Io`) when `dir` exists and is not an empty
    /// folder, or a file cannot be written; [`DataError::WriteMesh`].
    pub fn create(
        dir: impl AsRef<Path>,
        mesh: &TriMesh,
        mut manifest: Manifest,
        len: usize,
        channels: usize,
    ) -> Result<Self> {
        let dir = dir.as_ref().to_path_buf();
        if inspect_destination(&dir)? == Destination::NonEmpty {
            return Err(DataError::io(
                &dir,
                io::Error::new(
                    io::ErrorKind::AlreadyExists,
                    "the folder exists and is not empty; refusing to overwrite it",
                ),
            ));
        }
        manifest.num_signals = len;
        manifest.num_vertices = mesh.num_vertices();
        manifest.channels = channels;
        let parent = parent_of(&dir);
        std::fs::create_dir_all(&parent).map_err(|e| DataError::io(&parent, e))?;
        if let Some(name) = dir.file_name().and_then(|n| n.to_str()) {
            mfm_files::interrupt::remove_stale_temporaries(&parent, Some(name));
        }
        let temp = sibling(&dir, "tmp");
        // registered before it exists: no moment leaves it unregistered
        let registered = mfm_files::interrupt::TemporaryDir::register(&temp);
        std::fs::create_dir(&temp).map_err(|e| DataError::io(&temp, e))?;
        let mut writer = Self {
            dir,
            temp,
            signals: None,
            manifest,
            finished: false,
            _registered: registered,
        };
        write_ply(writer.temp.join(MESH_FILE), mesh, &[])?;
        let shape = [len as u64, mesh.num_vertices() as u64, channels as u64];
        writer.signals = Some(mfm_files::npy::NpyStream::create(
            writer.temp.join(SIGNALS_FILE),
            &shape,
        )?);
        Ok(writer)
    }

    /// Appends whole signals (`V x C` values each, vertex-major), in order.
    ///
    /// # Errors
    /// [`DataError::Files`] (`Format`) for a length that is not a whole
    /// number of signals or more signals than announced, or a non-finite
    /// value (naming the signal, vertex and channel); (`Io`) for a failed
    /// write.
    pub fn append(&mut self, values: &[f32]) -> Result<()> {
        let row = self.manifest.num_vertices * self.manifest.channels;
        let path = self.temp.join(SIGNALS_FILE);
        if row == 0 || values.len() % row != 0 {
            return Err(DataError::format(
                &path,
                format!(
                    "{} values are not a whole number of signals of {row}",
                    values.len()
                ),
            ));
        }
        let Some(stream) = self.signals.as_mut() else {
            return Err(DataError::format(&path, "the writer is finished"));
        };
        let first = (stream.written() / row as u64) as usize;
        if let Some((i, vertex, channel, x)) = crate::signals::first_non_finite(
            values,
            self.manifest.num_vertices,
            self.manifest.channels,
        ) {
            return Err(DataError::format(
                &self.dir,
                format!(
                    "signal {}, vertex {vertex}, channel {channel} is {x} (a dataset must hold finite values)",
                    first + i
                ),
            ));
        }
        Ok(stream.append(values)?)
    }

    /// Signals appended so far.
    pub fn written(&self) -> usize {
        let row = (self.manifest.num_vertices * self.manifest.channels).max(1) as u64;
        self.signals
            .as_ref()
            .map_or(0, |s| (s.written() / row) as usize)
    }

    /// Commits the array, writes the manifest, moves the folder into place
    /// and opens it.
    ///
    /// # Errors
    /// [`DataError::Files`] (`Format`) when fewer signals were appended than
    /// announced; the writing and renaming errors (the temporary folder is
    /// then removed).
    pub fn finish(mut self) -> Result<Dataset> {
        if let Some(stream) = self.signals.take() {
            stream.finish()?;
        }
        write_manifest(&self.temp, &self.manifest)?;
        if inspect_destination(&self.dir)? == Destination::Empty {
            std::fs::remove_dir(&self.dir).map_err(|e| DataError::io(&self.dir, e))?;
        }
        std::fs::rename(&self.temp, &self.dir).map_err(|e| DataError::io(&self.dir, e))?;
        self.finished = true;
        if let Ok(p) = File::open(parent_of(&self.dir)) {
            let _ = p.sync_all();
        }
        Dataset::open(&self.dir)
    }
}

impl Drop for DatasetWriter {
    fn drop(&mut self) {
        if !self.finished {
            drop(self.signals.take());
            let _ = std::fs::remove_dir_all(&self.temp);
        }
    }
}

/// The parts of a `.npy` header a dataset needs.
struct NpyInfo {
    shape: [usize; 3],
    data_offset: u64,
}

/// Reads and checks the header of `signals.npy`: dtype `<f4`, C order,
/// rank 3, and a file long enough for the whole array.
fn read_npy_header(path: &Path) -> Result<NpyInfo> {
    let file = mfm_files::open_regular(path)?;
    let file_len = file.metadata().map_err(|e| DataError::io(path, e))?.len();
    let mut reader = BufReader::new(file);
    let header = npyz::NpyHeader::from_reader(&mut reader)
        .map_err(|e| DataError::format(path, format!("not a valid .npy file: {e}")))?;
    let data_offset = reader
        .stream_position()
        .map_err(|e| DataError::io(path, e))?;
    let dtype = header.dtype();
    let dtype_ok = matches!(&dtype, npyz::DType::Plain(t) if t.to_string() == DTYPE);
    if !dtype_ok {
        return Err(DataError::format(
            path,
            format!(
                "dtype is {}, expected '{DTYPE}' (little-endian float32)",
                dtype.descr()
            ),
        ));
    }
    if header.order() != npyz::Order::C {
        return Err(DataError::format(
            path,
            "the array is in Fortran order, expected C order",
        ));
    }
    let shape = header.shape();
    let &[n, v, c] = shape else {
        return Err(DataError::format(
            path,
            format!("the array has shape {shape:?}, expected 3 axes [N, V, C]"),
        ));
    };
    let to_usize = |x: u64| {
        usize::try_from(x)
            .map_err(|_| DataError::format(path, format!("axis length {x} is too large")))
    };
    let needed = n
        .checked_mul(v)
        .and_then(|x| x.checked_mul(c))
        .and_then(|x| x.checked_mul(VALUE_BYTES))
        .ok_or_else(|| DataError::format(path, format!("shape {shape:?} overflows")))?;
    let available = file_len.saturating_sub(data_offset);
    if available < needed {
        return Err(DataError::format(
            path,
            format!(
                "truncated: shape [{n}, {v}, {c}] needs {needed} bytes of data after the header, \
                 the file has {available}"
            ),
        ));
    }
    Ok(NpyInfo {
        shape: [to_usize(n)?, to_usize(v)?, to_usize(c)?],
        data_offset,
    })
}
