//! Folders that belong to an mfm command: a dataset, an experiment (sets
//! and spaces of `mfm dataset`), a training run. No other command writes
//! into them (their files would be replaced behind the owner's back and
//! the run would no longer sample, the dataset no longer train), and
//! `--force` never clears them. The names here are the ones the owners
//! write (`mfm_data` and `mfm_fm` use these constants).

use std::path::Path;

use crate::error::FileError;

/// A dataset folder's manifest.
pub const MANIFEST: &str = "manifest.json";
/// The sets of an experiment folder, each a dataset folder.
pub const SETS: [&str; 3] = ["train", "reference", "holdout"];
/// The deformation space of an experiment of `mfm dataset deform`.
pub const SPACE: &str = "space.json";
/// The pair space of an experiment of `mfm dataset pairs`.
pub const PAIR_SPACE: &str = "pair_space.json";
/// A training run's configuration.
pub const RUN_CONFIG: &str = "config.toml";
/// A flow run's description of its noise and frame.
pub const RUN_FLOW: &str = "flow.json";
/// A flow run's data prior (`noise.prior`), written once when training
/// starts.
pub const RUN_PRIOR: &str = "prior.safetensors";
/// A training run's log.
pub const RUN_LOG: &str = "train_log.csv";
/// A training run's checkpoints folder.
pub const RUN_CHECKPOINTS: &str = "checkpoints";
/// The descriptions of the arbitrary-source model's two runs (the
/// eigenvector predictor, the flow).
pub const RUN_SPECS: [&str; 2] = ["predictor.json", "arbitrary.json"];

/// What kind of mfm folder `dir` is, when it is one no other command may
/// write into, and the entry that shows it: a dataset ([`MANIFEST`]), an
/// experiment (a set of [`SETS`] that is a dataset, [`SPACE`] or
/// [`PAIR_SPACE`]), or a training run of any mode ([`RUN_FLOW`],
/// [`RUN_LOG`], [`RUN_CHECKPOINTS`], [`RUN_SPECS`]). A lone
/// [`RUN_CONFIG`] is not taken as a run (a folder where a user keeps the
/// configuration they train with is theirs).
///
/// Cost: a few `stat` calls.
///
/// # Example
/// ```
/// let dir = tempfile::tempdir().unwrap();
/// assert_eq!(mfm_files::owned::owned_folder_kind(dir.path()), None);
/// std::fs::write(dir.path().join("flow.json"), "{}").unwrap();
/// let (kind, marker) = mfm_files::owned::owned_folder_kind(dir.path()).unwrap();
/// assert_eq!((kind, marker.as_str()), ("a training run folder", "flow.json"));
/// ```
pub fn owned_folder_kind(dir: &Path) -> Option<(&'static str, String)> {
    let has = |rel: &str| dir.join(rel).exists().then(|| rel.to_owned());
    let dataset = || has(MANIFEST).map(|m| ("a dataset folder", m));
    let experiment = || {
        SETS.iter()
            .find_map(|set| has(&format!("{set}/{MANIFEST}")))
            .or_else(|| has(SPACE))
            .or_else(|| has(PAIR_SPACE))
            .map(|m| ("an experiment folder", m))
    };
    let run = || {
        [RUN_FLOW, RUN_LOG, RUN_CHECKPOINTS]
            .iter()
            .chain(RUN_SPECS.iter())
            .find_map(|f| has(f))
            .map(|m| ("a training run folder", m))
    };
    dataset().or_else(experiment).or_else(run)
}

/// Refuses to write the file or folder `path` into a folder another
/// command owns: its parent is one ([`owned_folder_kind`]), or it lies
/// anywhere inside a run's [`RUN_CHECKPOINTS`]. A path that does not exist
/// is judged by where it would be created.
///
/// # Errors
/// [`FileError::InsideOwnedFolder`] naming the path, the folder, what the
/// folder is and the entry that shows it.
///
/// # Example
/// ```
/// let run = tempfile::tempdir().unwrap();
/// std::fs::create_dir(run.path().join("checkpoints")).unwrap();
/// let err = mfm_files::owned::refuse_writing_into(&run.path().join("noise.npy")).unwrap_err();
/// assert!(err.to_string().contains("a training run folder"));
/// assert!(mfm_files::owned::refuse_writing_into(&run.path().join("samples/x.npy")).is_ok());
/// ```
pub fn refuse_writing_into(path: &Path) -> Result<(), FileError> {
    let absolute = crate::guard::absolute_resolved(path);
    let mut folders = absolute.ancestors().skip(1);
    if let Some(parent) = folders.next()
        && let Some((kind, marker)) = owned_folder_kind(parent)
    {
        return Err(FileError::InsideOwnedFolder {
            path: path.to_path_buf(),
            folder: parent.to_path_buf(),
            kind,
            marker,
        });
    }
    for folder in absolute.ancestors().skip(1) {
        if folder.file_name().is_some_and(|n| n == RUN_CHECKPOINTS)
            && let Some(run) = folder.parent()
            && let Some(("a training run folder", _)) = owned_folder_kind(run)
        {
            return Err(FileError::InsideOwnedFolder {
                path: path.to_path_buf(),
                folder: folder.to_path_buf(),
                kind: "a training run's checkpoints folder",
                marker: RUN_CHECKPOINTS.to_owned(),
            });
        }
    }
    Ok(())
}
