//! Atomic file output: a file appears complete at its path, or not at all.
//!
//! [`AtomicFile::create`] opens an exclusive temporary file
//! (`.NAME.PID.N.tmp`, created with `O_EXCL`) in the target's folder;
//! [`AtomicFile::commit`] flushes it, syncs it to disk, renames it over the
//! target and syncs the folder. Dropping an uncommitted `AtomicFile` (an
//! error, a panic) removes the temporary file, so a failed write leaves the
//! previous file untouched and no debris behind.
//!
//! ## What is refused, and what is followed
//! - An existing target that is not a regular file — a folder, a device such
//!   as `/dev/full`, a FIFO, a socket — is refused with
//!   [`FileError::NotRegular`]: renaming over it would replace the node
//!   itself.
//! - A symbolic link is followed (through chains of links, relative links
//!   resolved from the link's folder): the file it points to is replaced and
//!   the link stays a link. A dangling link creates its target.
//! - An existing target's permission bits carry over to the new file.

use crate::error::FileError;
use std::fs::{self, File, OpenOptions};
use std::io::{self, BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

/// Links followed before giving up (the limit of Linux's `ELOOP`).
const MAX_LINKS: usize = 40;

/// A file being written atomically; see the [module docs](self).
///
/// # Example
/// ```
/// use std::io::Write;
/// let dir = tempfile::tempdir().unwrap();
/// let path = dir.path().join("out.txt");
/// let mut f = mfm_files::AtomicFile::create(&path).unwrap();
/// writeln!(f, "hello").unwrap();
/// assert!(!path.exists()); // nothing at the path until commit
/// f.commit().unwrap();
/// assert_eq!(std::fs::read_to_string(&path).unwrap(), "hello\n");
/// ```
#[derive(Debug)]
pub struct AtomicFile {
    shown: PathBuf,
    target: PathBuf,
    tmp: PathBuf,
    writer: Option<BufWriter<File>>,
    /// Its entry in [`crate::interrupt`].
    id: u64,
}

impl AtomicFile {
    /// Opens a temporary file next to the file `path` resolves to.
    ///
    /// # Errors
    /// [`FileError::NotRegular`] when `path` (after following links) exists
    /// and is not a regular file; [`FileError::Io`] when the folder does not
    /// exist or is not writable.
    pub fn create(path: impl AsRef<Path>) -> Result<Self, FileError> {
        let shown = path.as_ref().to_path_buf();
        let target = resolve_target(&shown)?;
        let name = target
            .file_name()
            .ok_or_else(|| {
                FileError::io(
                    &shown,
                    io::Error::new(io::ErrorKind::InvalidInput, "the path does not name a file"),
                )
            })?
            .to_owned();
        let dir = match target.parent() {
            Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
            _ => PathBuf::from("."),
        };
        // what a killed earlier writer of this file left
        crate::interrupt::remove_stale_temporaries(&dir, name.to_str());
        static COUNTER: AtomicU64 = AtomicU64::new(0);
        let (tmp, file) = loop {
            let mut tmp_name = std::ffi::OsString::from(".");
            tmp_name.push(&name);
            tmp_name.push(format!(
                ".{}.{}.tmp",
                std::process::id(),
                COUNTER.fetch_add(1, Ordering::Relaxed)
            ));
            let candidate = dir.join(tmp_name);
            match OpenOptions::new()
                .write(true)
                .create_new(true)
                .open(&candidate)
            {
                Ok(f) => break (candidate, f),
                Err(e) if e.kind() == io::ErrorKind::AlreadyExists => continue,
                Err(e) => return Err(FileError::io(&shown, e)),
            }
        };
        if let Ok(meta) = fs::metadata(&target) {
            // best effort: a file system without permission bits still works
            let _ = file.set_permissions(meta.permissions());
        }
        let id = crate::interrupt::register(crate::interrupt::Pending::File(tmp.clone()));
        Ok(Self {
            shown,
            target,
            tmp,
            writer: Some(BufWriter::new(file)),
            id,
        })
    }

    /// The path as given to [`AtomicFile::create`].
    pub fn path(&self) -> &Path {
        &self.shown
    }

    /// Makes the written bytes the file's contents: flush, sync, rename over
    /// the target, sync the folder.
    ///
    /// # Errors
    /// [`FileError::Io`] naming the path; the temporary file is removed and
    /// the target keeps its previous contents.
    pub fn commit(mut self) -> Result<(), FileError> {
        crate::interrupt::forget(self.id);
        let Some(writer) = self.writer.take() else {
            return Ok(());
        };
        let result = (|| -> io::Result<()> {
            let file = writer.into_inner().map_err(|e| e.into_error())?;
            file.sync_all()?;
            drop(file);
            fs::rename(&self.tmp, &self.target)?;
            if let Some(dir) = self.target.parent().filter(|d| !d.as_os_str().is_empty()) {
                // best effort: durability of the rename itself
                if let Ok(d) = File::open(dir) {
                    let _ = d.sync_all();
                }
            }
            Ok(())
        })();
        if let Err(e) = result {
            let _ = fs::remove_file(&self.tmp);
            return Err(FileError::io(&self.shown, e));
        }
        Ok(())
    }

    fn writer(&mut self) -> io::Result<&mut BufWriter<File>> {
        self.writer
            .as_mut()
            .ok_or_else(|| io::Error::other("the file was already committed"))
    }
}

impl Write for AtomicFile {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        self.writer()?.write(buf)
    }

    fn write_all(&mut self, buf: &[u8]) -> io::Result<()> {
        self.writer()?.write_all(buf)
    }

    fn flush(&mut self) -> io::Result<()> {
        self.writer()?.flush()
    }
}

impl Drop for AtomicFile {
    fn drop(&mut self) {
        crate::interrupt::forget(self.id);
        if self.writer.take().is_some() {
            let _ = fs::remove_file(&self.tmp);
        }
    }
}

/// Writes what `fill` produces to `path` atomically (see the
/// [module docs](self)).
///
/// # Errors
/// As [`AtomicFile::create`] and [`AtomicFile::commit`]; an error of `fill`
/// as [`FileError::Io`] naming `path`. On any error `path` is unchanged.
pub fn write_atomic(
    path: impl AsRef<Path>,
    fill: impl FnOnce(&mut dyn Write) -> io::Result<()>,
) -> Result<(), FileError> {
    let mut file = AtomicFile::create(path.as_ref())?;
    fill(&mut file).map_err(|e| FileError::io(path.as_ref(), e))?;
    file.commit()
}

/// Writes `value` as pretty-printed JSON with a final newline, through
/// [`write_atomic`].
///
/// # Errors
/// As [`write_atomic`]; a value serde cannot serialize is a
/// [`FileError::Io`] naming the file.
pub fn write_json(path: impl AsRef<Path>, value: &impl serde::Serialize) -> Result<(), FileError> {
    write_atomic(path, |w| {
        serde_json::to_writer_pretty(&mut *w, value).map_err(io::Error::other)?;
        w.write_all(b"\n")
    })
}

/// The regular file `path` names after following symbolic links, or the
/// path to create when nothing exists there.
///
/// # Errors
/// [`FileError::NotRegular`] for an existing folder, device, FIFO or socket;
/// [`FileError::Io`] for a loop of links or an unreadable link.
pub fn resolve_target(path: &Path) -> Result<PathBuf, FileError> {
    let mut p = path.to_path_buf();
    for _ in 0..MAX_LINKS {
        match fs::symlink_metadata(&p) {
            Err(e) if e.kind() == io::ErrorKind::NotFound => return Ok(p),
            Err(e) => return Err(FileError::io(path, e)),
            Ok(m) if m.file_type().is_symlink() => {
                let link = fs::read_link(&p).map_err(|e| FileError::io(path, e))?;
                p = if link.is_absolute() {
                    link
                } else {
                    p.parent().unwrap_or(Path::new("")).join(link)
                };
            }
            Ok(m) if m.is_file() => return Ok(p),
            Ok(m) => {
                return Err(FileError::NotRegular {
                    path: path.to_path_buf(),
                    kind: kind_of(&m.file_type()),
                });
            }
        }
    }
    Err(FileError::io(
        path,
        io::Error::other("too many levels of symbolic links"),
    ))
}

/// Opens the input `path` for reading when it is a regular file (after
/// following symbolic links): a device (`/dev/zero`, which never ends), a
/// FIFO (which blocks until someone writes), a socket or a folder is
/// refused before anything is read.
///
/// # Errors
/// [`FileError::InputNotRegular`] naming the path and what it is;
/// [`FileError::Io`] when it cannot be opened.
pub fn open_regular(path: &Path) -> Result<fs::File, FileError> {
    let meta = fs::metadata(path).map_err(|e| FileError::io(path, e))?;
    if !meta.is_file() {
        return Err(FileError::InputNotRegular {
            path: path.to_path_buf(),
            kind: kind_of(&meta.file_type()),
        });
    }
    fs::File::open(path).map_err(|e| FileError::io(path, e))
}

/// All of the regular file `path` ([`open_regular`]); at most the size
/// its metadata gave when opened.
///
/// # Errors
/// As [`open_regular`]; [`FileError::Io`] when reading fails.
pub fn read_regular(path: &Path) -> Result<Vec<u8>, FileError> {
    use std::io::Read;
    let file = open_regular(path)?;
    let size = file.metadata().map_err(|e| FileError::io(path, e))?.len();
    let mut bytes = Vec::with_capacity(usize::try_from(size).unwrap_or(0));
    file.take(size)
        .read_to_end(&mut bytes)
        .map_err(|e| FileError::io(path, e))?;
    Ok(bytes)
}

/// "a folder", "a device", ... for a file type that is not a regular file.
pub(crate) fn kind_of(t: &fs::FileType) -> &'static str {
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        if t.is_block_device() || t.is_char_device() {
            return "a device";
        }
        if t.is_fifo() {
            return "a FIFO";
        }
        if t.is_socket() {
            return "a socket";
        }
    }
    if t.is_dir() {
        "a folder"
    } else if t.is_symlink() {
        "a symbolic link"
    } else {
        "not a regular file"
    }
}
