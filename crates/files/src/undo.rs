//! Removing what a failed command created, and only that.

use crate::error::FileError;
use std::fs;
use std::path::{Path, PathBuf};

/// Records the folders and files a command creates; unless
/// [`Undo::keep`] is called, dropping it removes them again (newest first).
/// Paths that existed before they were recorded are never removed.
///
/// # Example
/// ```
/// let dir = tempfile::tempdir().unwrap();
/// let out = dir.path().join("run");
/// {
///     let mut undo = mfm_files::Undo::new();
///     undo.create_dir_all(&out).unwrap();
///     undo.file(out.join("config.toml"));
///     std::fs::write(out.join("config.toml"), "x").unwrap();
///     // the command fails here: `undo` is dropped without keep()
/// }
/// assert!(!out.exists());
/// ```
#[derive(Debug, Default)]
#[must_use = "dropping an Undo removes what it recorded; call keep() on success"]
pub struct Undo {
    created: Vec<PathBuf>,
    /// A folder that was missing or empty when taken: all in it is ours.
    owned: Option<PathBuf>,
    kept: bool,
    /// Its entry in [`crate::interrupt`] (0 while nothing is recorded).
    id: u64,
}

impl Undo {
    /// Nothing recorded.
    pub fn new() -> Self {
        Self::default()
    }

    /// Tells [`crate::interrupt`] what an interrupt must remove now.
    fn announce(&mut self) {
        let what = crate::interrupt::Pending::Undo {
            owned: self.owned.clone(),
            created: self.created.clone(),
        };
        if self.id == 0 {
            self.id = crate::interrupt::register(what);
        } else {
            crate::interrupt::update(self.id, what);
        }
    }

    /// Creates `dir` and its missing parents, recording the outermost folder
    /// that did not exist.
    ///
    /// # Errors
    /// [`FileError::Io`] naming the folder.
    pub fn create_dir_all(&mut self, dir: &Path) -> Result<(), FileError> {
        let mut first_missing = None;
        let mut p = Some(dir);
        while let Some(q) = p {
            if q.as_os_str().is_empty() || q.exists() {
                break;
            }
            first_missing = Some(q.to_path_buf());
            p = q.parent();
        }
        // recorded (and told to an interrupt) before it exists, so that no
        // moment leaves a folder of ours unrecorded
        if let Some(d) = first_missing {
            self.created.push(d);
            self.announce();
        }
        fs::create_dir_all(dir).map_err(|e| FileError::io(dir, e))
    }

    /// Records a file the command is about to create; a file that exists
    /// already is not recorded (it is the user's).
    pub fn file(&mut self, path: impl AsRef<Path>) {
        let path = path.as_ref();
        if fs::symlink_metadata(path).is_err() {
            self.created.push(path.to_path_buf());
            self.announce();
        }
    }

    /// Takes the folder `dir` for a command to fill: it must be missing or
    /// empty ([`crate::ensure_empty_dir`]); it is created, and unless
    /// [`Undo::keep`] is called everything in it is removed again, whatever
    /// the command wrote there, and the folder too if it was created here.
    ///
    /// # Errors
    /// [`FileError::NotEmpty`]; [`FileError::Io`] naming the folder.
    pub fn empty_folder(dir: &Path) -> Result<Self, FileError> {
        crate::guard::ensure_empty_dir(dir)?;
        let mut undo = Self::new();
        undo.create_dir_all(dir)?;
        undo.owned = Some(dir.to_path_buf());
        undo.announce();
        Ok(undo)
    }

    /// The command succeeded: keep everything.
    pub fn keep(mut self) {
        self.kept = true;
    }
}

impl Drop for Undo {
    fn drop(&mut self) {
        if self.id != 0 {
            crate::interrupt::forget(self.id);
        }
        if self.kept {
            return;
        }
        remove(self.owned.as_deref(), &self.created);
    }
}

/// Empties the taken folder `owned` and removes `created`, newest first:
/// what a dropped [`Undo`] and an interrupt ([`crate::interrupt`]) do.
pub(crate) fn remove(owned: Option<&Path>, created: &[PathBuf]) {
    let listing = owned.and_then(|d| fs::read_dir(d).ok());
    for e in listing.into_iter().flatten().flatten() {
        let p = e.path();
        let _ = match e.file_type() {
            Ok(t) if t.is_dir() => fs::remove_dir_all(&p),
            _ => fs::remove_file(&p),
        };
    }
    for p in created.iter().rev() {
        match fs::symlink_metadata(p) {
            Ok(m) if m.is_dir() => {
                let _ = fs::remove_dir_all(p);
            }
            Ok(_) => {
                let _ = fs::remove_file(p);
            }
            Err(_) => {}
        }
    }
}
