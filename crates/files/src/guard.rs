//! The check a command runs before writing anything: outputs must not be
//! inputs, lie inside input folders, collide with each other, or be
//! something other than a regular file.
//!
//! Paths are compared by identity, not by spelling: an existing path is
//! canonicalized (symbolic links, `..`, relative paths resolved) and, on
//! Unix, also compared by device and inode (so a hard link to an input is
//! caught); a path that does not exist yet is its nearest existing ancestor,
//! canonicalized, joined with the rest.

use crate::atomic::resolve_target;
use crate::error::FileError;
use crate::undo::Undo;
use std::fs;
use std::path::{Component, Path, PathBuf};

/// The inputs and outputs of one command; see the [module docs](self).
///
/// # Example
/// ```
/// let dir = tempfile::tempdir().unwrap();
/// let mesh = dir.path().join("in.off");
/// std::fs::write(&mesh, "OFF\n0 0 0\n").unwrap();
/// let err = mfm_files::Outputs::new()
///     .input(&mesh)
///     .output(dir.path().join("./in.off"))
///     .check()
///     .unwrap_err();
/// assert!(err.to_string().contains("is also an input"));
/// assert!(mfm_files::Outputs::new().input(&mesh).output(dir.path().join("out.npy")).check().is_ok());
/// ```
#[derive(Clone, Debug, Default)]
pub struct Outputs {
    inputs: Vec<PathBuf>,
    outputs: Vec<PathBuf>,
    /// (companion, the named output it goes with)
    implicit: Vec<(PathBuf, PathBuf)>,
    /// Outputs that are folders a command fills (may exist as folders).
    folders: Vec<PathBuf>,
}

impl Outputs {
    /// No inputs, no outputs.
    pub fn new() -> Self {
        Self::default()
    }

    /// Adds an input: a file, or a folder whose contents are inputs.
    /// Built-in names that are not paths (`builtin:...`) may be passed; a
    /// path that does not exist is not an input and is ignored.
    pub fn input(mut self, path: impl AsRef<Path>) -> Self {
        self.inputs.push(path.as_ref().to_path_buf());
        self
    }

    /// Adds a file the command will write.
    pub fn output(mut self, path: impl AsRef<Path>) -> Self {
        self.outputs.push(path.as_ref().to_path_buf());
        self
    }

    /// Adds a folder the command fills (a run, a dataset): an output under
    /// every rule but that it may exist as a folder (whether it may hold
    /// anything is the command's own check, e.g. [`ensure_empty_dir`]).
    /// [`Outputs::prepare`] leaves it to the command.
    ///
    /// ```
    /// let dir = tempfile::tempdir().unwrap();
    /// let data = dir.path().join("data");
    /// std::fs::create_dir(&data).unwrap();
    /// let inside = mfm_files::Outputs::new().input(&data).folder(data.join("run"));
    /// assert!(inside.check().unwrap_err().to_string().contains("inside the input folder"));
    /// assert!(mfm_files::Outputs::new().folder(&data).check().is_ok());
    /// ```
    pub fn folder(mut self, path: impl AsRef<Path>) -> Self {
        self.folders.push(path.as_ref().to_path_buf());
        self.output(path)
    }

    /// Adds a file the command writes without the user naming it (a
    /// summary beside `--out`, a plot of a fixed name) as the companion of
    /// the named output `of`: it is an output, and it may replace an
    /// existing file only when `of` exists too (the same command run again
    /// over its own earlier result); otherwise an existing file there is
    /// someone else's, and the check refuses.
    ///
    /// ```
    /// let dir = tempfile::tempdir().unwrap();
    /// let (npy, json) = (dir.path().join("x.npy"), dir.path().join("x.json"));
    /// std::fs::write(&json, "mine").unwrap();
    /// let guard = mfm_files::Outputs::new().output(&npy).implicit(&json, &npy);
    /// let err = guard.check().unwrap_err();
    /// assert!(err.to_string().contains("x.json exists"));
    /// // x.npy's own summary, written by an earlier run, is replaced with it
    /// std::fs::write(&npy, "an earlier result").unwrap();
    /// assert!(guard.check().is_ok());
    /// ```
    pub fn implicit(mut self, path: impl AsRef<Path>, of: impl AsRef<Path>) -> Self {
        self.implicit
            .push((path.as_ref().to_path_buf(), of.as_ref().to_path_buf()));
        self.output(path)
    }

    /// Adds every path of `paths` as an input ([`Outputs::input`]); an
    /// `Option` adds nothing when it is `None`.
    pub fn inputs<P: AsRef<Path>>(self, paths: impl IntoIterator<Item = P>) -> Self {
        paths.into_iter().fold(self, Self::input)
    }

    /// Adds every path of `paths` as an output ([`Outputs::output`]).
    pub fn outputs<P: AsRef<Path>>(self, paths: impl IntoIterator<Item = P>) -> Self {
        paths.into_iter().fold(self, Self::output)
    }

    /// Checks every rule; the first broken one is the error. Besides the
    /// rules of the [module docs](self), no output goes into a folder
    /// another command owns ([`crate::owned::refuse_writing_into`]) and no
    /// implicit output ([`Outputs::implicit`]) exists.
    ///
    /// # Errors
    /// [`FileError::InsideOwnedFolder`], [`FileError::ImplicitExists`],
    /// [`FileError::NotRegular`], [`FileError::OutputIsInput`],
    /// [`FileError::OutputInsideInput`] or [`FileError::SameOutput`], each
    /// naming the paths as given.
    pub fn check(&self) -> Result<(), FileError> {
        let inputs: Vec<(&PathBuf, Identity)> = self
            .inputs
            .iter()
            .filter(|p| p.exists())
            .map(|p| (p, Identity::of(p)))
            .collect();
        let mut seen: Vec<(&PathBuf, Identity)> = Vec::new();
        for out in &self.outputs {
            if !self.folders.contains(out) {
                resolve_target(out)?;
            } else if out.exists() && !out.is_dir() {
                return Err(FileError::NotAFolder { path: out.clone() });
            }
            let id = Identity::of(out);
            for (input, input_id) in &inputs {
                if id.same_file(input_id) {
                    return Err(FileError::OutputIsInput {
                        output: out.clone(),
                        input: (*input).clone(),
                    });
                }
                if input_id.is_dir && id.path.starts_with(&input_id.path) {
                    return Err(FileError::OutputInsideInput {
                        output: out.clone(),
                        input: (*input).clone(),
                    });
                }
            }
            if let Some((first, _)) = seen.iter().find(|(_, s)| s.same_file(&id)) {
                return Err(FileError::SameOutput {
                    first: (*first).clone(),
                    second: out.clone(),
                });
            }
            seen.push((out, id));
        }
        // after the input rules, which name the more precise problem
        for out in &self.outputs {
            crate::owned::refuse_writing_into(out)?;
        }
        if let Some((existing, _)) = self
            .implicit
            .iter()
            .find(|(p, of)| p.symlink_metadata().is_ok() && of.symlink_metadata().is_err())
        {
            return Err(FileError::ImplicitExists {
                path: existing.clone(),
            });
        }
        Ok(())
    }

    /// [`Outputs::check`], then creates the outputs' folders and returns an
    /// [`Undo`] that removes those folders and the output files the command
    /// creates, unless it succeeds ([`Undo::keep`]). This is what a command
    /// calls before it writes anything.
    ///
    /// # Errors
    /// Those of [`Outputs::check`], and [`FileError::Io`] for a folder that
    /// cannot be created.
    pub fn prepare(&self) -> Result<Undo, FileError> {
        self.check()?;
        let mut undo = Undo::new();
        for out in self.outputs.iter().filter(|o| !self.folders.contains(o)) {
            if let Some(dir) = out.parent().filter(|p| !p.as_os_str().is_empty()) {
                undo.create_dir_all(dir)?;
            }
            undo.file(out);
        }
        Ok(undo)
    }
}

/// Refuses a folder that exists and is not empty (a missing or empty one
/// is fine): commands that fill a folder of their own call it first. The
/// temporaries a killed mfm process left in it are removed first
/// ([`crate::interrupt::remove_stale_temporaries`]), so they do not make it
/// non-empty.
///
/// # Errors
/// [`FileError::NotEmpty`]; [`FileError::NotAFolder`] for a file (or
/// anything but a folder) at `dir`.
pub fn ensure_empty_dir(dir: &Path) -> Result<(), FileError> {
    if dir.symlink_metadata().is_ok() && !dir.is_dir() {
        return Err(FileError::NotAFolder {
            path: dir.to_path_buf(),
        });
    }
    crate::interrupt::remove_stale_temporaries(dir, None);
    if let Ok(mut entries) = fs::read_dir(dir)
        && entries.next().is_some()
    {
        return Err(FileError::NotEmpty {
            path: dir.to_path_buf(),
        });
    }
    Ok(())
}

/// What a path refers to.
#[derive(Clone, Debug)]
struct Identity {
    path: PathBuf,
    is_dir: bool,
    /// (device, inode) of an existing file.
    inode: Option<(u64, u64)>,
}

impl Identity {
    fn of(path: &Path) -> Self {
        let meta = fs::metadata(path).ok();
        Self {
            path: absolute_resolved(path),
            is_dir: meta.as_ref().is_some_and(fs::Metadata::is_dir),
            inode: meta.as_ref().and_then(inode),
        }
    }

    fn same_file(&self, other: &Self) -> bool {
        match (self.inode, other.inode) {
            (Some(a), Some(b)) => a == b,
            _ => self.path == other.path,
        }
    }
}

#[cfg(unix)]
fn inode(m: &fs::Metadata) -> Option<(u64, u64)> {
    use std::os::unix::fs::MetadataExt;
    Some((m.dev(), m.ino()))
}

#[cfg(not(unix))]
fn inode(_: &fs::Metadata) -> Option<(u64, u64)> {
    None
}

/// `path` absolute with links resolved as far as it exists, the rest
/// normalized lexically.
pub fn absolute_resolved(path: &Path) -> PathBuf {
    if let Ok(p) = fs::canonicalize(path) {
        return p;
    }
    let absolute = std::path::absolute(path).unwrap_or_else(|_| path.to_path_buf());
    let mut existing = absolute.as_path();
    let mut rest: Vec<Component<'_>> = Vec::new();
    loop {
        if let Ok(base) = fs::canonicalize(existing) {
            let mut out = base;
            for c in rest.iter().rev() {
                match c {
                    Component::ParentDir => {
                        out.pop();
                    }
                    Component::CurDir => {}
                    other => out.push(other.as_os_str()),
                }
            }
            return out;
        }
        match (existing.parent(), existing.components().next_back()) {
            (Some(parent), Some(last)) => {
                rest.push(last);
                existing = parent;
            }
            _ => return absolute,
        }
    }
}
