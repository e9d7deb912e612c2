//! The files that mark what an arbitrary-source folder is: the run
//! descriptions, the kinds of folder they tell apart, and the refusal to
//! train over a model imported from the authors' code. A leaf of the
//! crate: the trainings ([`crate::predictor`], [`crate::flow`]) and the
//! folders ([`crate::folders`]) all read it.

use std::path::Path;

use crate::error::{ArbitraryError, Result};
use mfm_data::dataset::MANIFEST_FILE;
use mfm_data::layout::{HOLDOUT, PAIR_SPACE, REFERENCE, SPACE, TRAIN};
use mfm_fm::checkpoint::{CONFIG_FILE, FLOW_FILE};

/// The predictor run's description.
pub const PREDICTOR_SPEC: &str = mfm_files::owned::RUN_SPECS[0];
/// The flow run's description.
pub const ARBITRARY_SPEC: &str = mfm_files::owned::RUN_SPECS[1];

/// Which of the two networks a run trains.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RunKind {
    /// The eigenvector predictor ([`crate::predictor`]).
    Predictor,
    /// The arbitrary-source flow ([`crate::flow`]).
    Flow,
}

impl RunKind {
    /// The file that marks a run folder of this kind.
    pub fn spec_file(self) -> &'static str {
        match self {
            Self::Predictor => PREDICTOR_SPEC,
            Self::Flow => ARBITRARY_SPEC,
        }
    }
}

/// What an mfm folder holds, as its marker files show: for messages that
/// say what a folder given to a flag is and what the flag expects.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FolderKind {
    /// Nothing at the path.
    Missing,
    /// A file, not a folder.
    File,
    /// A flow run of `mfm train` (`config.toml` or `flow.json`).
    FlowRun,
    /// An eigenvector predictor run (`mfm train --mode predictor`:
    /// [`PREDICTOR_SPEC`] without [`ARBITRARY_SPEC`]).
    PredictorRun,
    /// An arbitrary-source run (`mfm train --mode arbitrary`:
    /// [`ARBITRARY_SPEC`]).
    ArbitraryRun,
    /// A dataset (`manifest.json`), e.g. one set of an experiment.
    Dataset,
    /// An experiment of `mfm dataset gmm|deform|pairs` (a `train/`,
    /// `reference/` or `holdout/` set, or a deformation or pair space).
    Experiment,
    /// A folder with none of these.
    Other,
}

impl FolderKind {
    /// The kind of `dir`. Cost: a few `stat` calls.
    pub fn of(dir: &Path) -> Self {
        if !dir.exists() {
            return Self::Missing;
        }
        if !dir.is_dir() {
            return Self::File;
        }
        let has = |rel: &str| dir.join(rel).exists();
        if has(ARBITRARY_SPEC) {
            Self::ArbitraryRun
        } else if has(PREDICTOR_SPEC) {
            Self::PredictorRun
        } else if has(CONFIG_FILE) || has(FLOW_FILE) {
            Self::FlowRun
        } else if has(MANIFEST_FILE) {
            Self::Dataset
        } else if [TRAIN, REFERENCE, HOLDOUT]
            .iter()
            .any(|set| has(&format!("{set}/{MANIFEST_FILE}")))
            || has(SPACE)
            || has(PAIR_SPACE)
        {
            Self::Experiment
        } else {
            Self::Other
        }
    }

    /// What the folder is, for a message: "an eigenvector predictor run
    /// (mfm train --mode predictor)".
    pub fn describe(self) -> &'static str {
        match self {
            Self::Missing => "nothing (no such folder)",
            Self::File => "a file, not a folder",
            Self::FlowRun => "a flow run (mfm train)",
            Self::PredictorRun => "an eigenvector predictor run (mfm train --mode predictor)",
            Self::ArbitraryRun => "an arbitrary-source run (mfm train --mode arbitrary)",
            Self::Dataset => "a dataset folder",
            Self::Experiment => "an experiment folder (mfm dataset gmm|deform|pairs)",
            Self::Other => "not a folder mfm wrote",
        }
    }

    /// The kind as a predicate, for a message: "is a dataset folder", or
    /// "does not exist".
    pub fn is(self) -> String {
        match self {
            Self::Missing => "does not exist".to_owned(),
            other => format!("is {}", other.describe()),
        }
    }

    /// The `mfm train` flags that continue a run of this kind, for a run
    /// kind.
    pub fn resume_flags(self) -> Option<&'static str> {
        match self {
            Self::FlowRun => Some("--resume"),
            Self::PredictorRun => Some("--resume --mode predictor"),
            Self::ArbitraryRun => Some("--resume --mode arbitrary"),
            _ => None,
        }
    }
}

/// The error for training in `run_dir` when it holds an imported model
/// ([`crate::official`]): it has no training state (no dataset, optimizer
/// or checkpoints) to continue from.
///
/// # Errors
/// [`ArbitraryError::RunFolder`] saying what to do instead.
pub fn refuse_imported(run_dir: &Path) -> Result<()> {
    let record = run_dir.join(mfm_fm::official::IMPORT_FILE);
    if record.is_file() {
        return Err(ArbitraryError::RunFolder(format!(
            "{} holds a model imported from the authors' checkpoint ({}): it has no training \
             state to resume (no dataset, optimizer or checkpoints); sample it with \
             mfm sample --run {} --source MESH, or train a new run into another folder",
            run_dir.display(),
            record.display(),
            run_dir.display()
        )));
    }
    Ok(())
}
