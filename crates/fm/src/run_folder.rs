//! A training run's folder as `mfm train` uses it: a fresh run in a new or
//! empty folder, or the continuation of the run a folder holds, with its
//! dataset found again when the run and its data moved together.
//!
//! A fresh run that fails before its first checkpoint leaves nothing
//! behind ([`RunFolder::train`]); once a checkpoint exists, the folder is
//! the user's progress and stays.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

use mfm_data::dataset::Dataset;
use mfm_noise::NoiseKind;

use crate::checkpoint::{self, CONFIG_FILE};
use crate::config::RunConfig;
use crate::device::DeviceChoice;
use crate::error::{FmError, Result};
use crate::train::{TrainSummary, Trainer};

/// Settings given on top of a configuration for a fresh run.
#[derive(Clone, Debug, Default)]
pub struct Overrides {
    /// The dataset folder (`dataset.path`).
    pub dataset: Option<PathBuf>,
    /// Total steps (`train.steps`).
    pub steps: Option<u64>,
    /// Seed (`train.seed`).
    pub seed: Option<u64>,
    /// Noise the flow starts from (`noise.kind`).
    pub noise: Option<NoiseKind>,
    /// The noise amplitude (`noise.scale`).
    pub noise_scale: Option<crate::config::NoiseScale>,
    /// The data prior added to the noise (`noise.prior`).
    pub prior: Option<crate::prior::PriorKind>,
    /// Where to train (`train.device`).
    pub device: Option<DeviceChoice>,
}

impl Overrides {
    /// `config` with these settings applied and its dataset path made
    /// absolute (so that a later resume works from any folder).
    ///
    /// # Errors
    /// [`FmError::Files`] (`Io`) when the dataset path cannot be made absolute.
    pub fn apply(&self, mut config: RunConfig) -> Result<RunConfig> {
        if let Some(d) = &self.dataset {
            config.dataset.path = Some(d.clone());
        }
        if let Some(p) = &config.dataset.path {
            config.dataset.path = Some(std::path::absolute(p).map_err(|e| FmError::io(p, e))?);
        }
        if let Some(s) = self.steps {
            config.train.steps = s;
        }
        if let Some(s) = self.seed {
            config.train.seed = s;
        }
        if let Some(k) = self.noise {
            config.noise.kind = k;
        }
        if let Some(x) = self.noise_scale {
            config.noise.scale = x;
        }
        if let Some(p) = self.prior {
            config.noise.prior = p;
        }
        if let Some(d) = self.device {
            config.train.device = d;
        }
        Ok(config)
    }
}

/// A trainer on the run folder it writes, ready to [`RunFolder::train`].
pub struct RunFolder {
    /// The trainer.
    pub trainer: Trainer,
    /// The dataset folder it trains on.
    pub dataset: PathBuf,
    /// The dataset's size: signals, vertices, channels.
    pub dataset_shape: [usize; 3],
    /// For a resumed run whose stored dataset path is gone: that path (the
    /// run trains on the copy found beside the run folder, `dataset`).
    pub moved_from: Option<PathBuf>,
    /// What a fresh run created, removed unless a checkpoint exists when
    /// training ends.
    fresh: Option<mfm_files::Undo>,
}

impl std::fmt::Debug for RunFolder {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RunFolder")
            .field("run", &self.trainer.run_dir())
            .field("dataset", &self.dataset)
            .field("fresh", &self.fresh.is_some())
            .finish()
    }
}

/// The dataset folder: `flag`, else the configuration's.
///
/// # Errors
/// [`FmError::Config`] when neither names one.
pub fn dataset_dir(flag: Option<&Path>, config: &RunConfig) -> Result<PathBuf> {
    match (flag, &config.dataset.path) {
        (Some(p), _) => Ok(p.to_path_buf()),
        (None, Some(p)) => Ok(p.clone()),
        (None, None) => Err(FmError::Config(
            "no dataset: pass --dataset DIR or set [dataset] path in the configuration".into(),
        )),
    }
}

/// Opens a dataset as the trainer takes it, with its shape.
fn open(dir: &Path) -> Result<(Arc<Dataset>, [usize; 3])> {
    use mfm_data::SignalSource;
    let data = Dataset::open(dir)?;
    let shape = [data.len(), data.num_vertices(), data.channels()];
    Ok((Arc::new(data), shape))
}

impl RunFolder {
    /// A fresh run of `config` in `out` (missing or empty), on the
    /// configuration's dataset.
    ///
    /// # Errors
    /// [`mfm_files::FileError::NotEmpty`] for a folder with anything in
    /// it; [`dataset_dir`]'s; the dataset's and [`Trainer::new`]'s errors
    /// (nothing is left behind).
    pub fn start(out: &Path, config: RunConfig) -> Result<Self> {
        let undo = mfm_files::Undo::empty_folder(out)?;
        let dataset = dataset_dir(None, &config)?;
        let (data, dataset_shape) = open(&dataset)?;
        let mesh = data.mesh().clone();
        let trainer = Trainer::new(out, config, &mesh, data)?;
        Ok(Self {
            trainer,
            dataset,
            dataset_shape,
            moved_from: None,
            fresh: Some(undo),
        })
    }

    /// Continues the run in `out` ([`Trainer::resume`], or
    /// [`Trainer::resume_on`] with `device`) on `dataset`, else the stored
    /// dataset, else a copy of it found beside the run ([`locate_dataset`]);
    /// `steps` changes the run's total.
    ///
    /// # Errors
    /// [`FmError::RunFolder`] for a folder without a run configuration or
    /// a dataset that is gone; the trainer's errors.
    pub fn resume(
        out: &Path,
        dataset: Option<&Path>,
        device: Option<DeviceChoice>,
        steps: Option<u64>,
    ) -> Result<Self> {
        let stored = RunConfig::from_toml_file(out.join(CONFIG_FILE)).map_err(|e| {
            FmError::RunFolder(format!("{} is not a run folder: {e}", out.display()))
        })?;
        let (dir, moved_from) = match (dataset, &stored.dataset.path) {
            (None, Some(p)) if !p.is_dir() => {
                let found = locate_dataset(p, out).ok_or_else(|| {
                    FmError::RunFolder(format!(
                        "the run's dataset {} is gone (moved?); pass --dataset DIR",
                        p.display()
                    ))
                })?;
                (found, Some(p.clone()))
            }
            (flag, _) => (dataset_dir(flag, &stored)?, None),
        };
        let (data, dataset_shape) = open(&dir)?;
        let flow_file = out.join(checkpoint::FLOW_FILE);
        if flow_file.is_file() {
            let trained = checkpoint::FlowSpec::read(&flow_file)?.channels;
            if trained != dataset_shape[2] {
                return Err(FmError::RunFolder(format!(
                    "the dataset {} has {}-channel signals, but the run {} was trained on \
                     {trained}-channel ones{}: resume on a dataset like its own, or train a \
                     new run on this one",
                    dir.display(),
                    dataset_shape[2],
                    out.display(),
                    stored
                        .dataset
                        .path
                        .as_ref()
                        .map(|p| format!(" (its dataset {})", p.display()))
                        .unwrap_or_default()
                )));
            }
        }
        let mesh = data.mesh().clone();
        let mut trainer = match device {
            Some(d) => Trainer::resume_on(out, &mesh, data, d)?,
            None => Trainer::resume(out, &mesh, data)?,
        };
        if let Some(steps) = steps {
            trainer.set_total_steps(steps)?;
        }
        Ok(Self {
            trainer,
            dataset: dir,
            dataset_shape,
            moved_from,
            fresh: None,
        })
    }

    /// Trains until the run's total or `stop` ([`Trainer::run`]). A fresh
    /// run's folder is removed on failure unless a checkpoint was written.
    ///
    /// # Errors
    /// The trainer's.
    pub fn train(mut self, stop: &AtomicBool, progress: bool) -> Result<TrainSummary> {
        let result = self.trainer.run(stop, progress);
        if let Some(undo) = self.fresh.take() {
            keep_if_progress(undo, self.trainer.run_dir(), result.is_ok());
        }
        result
    }
}

/// Settles the [`mfm_files::Undo`] of a fresh run's folder once training
/// ended: kept when training `succeeded` or the run holds a checkpoint (the
/// user's progress, to resume from); otherwise dropped, which removes the
/// run. Every kind of run (this crate's and the arbitrary-source model's)
/// follows this rule.
pub fn keep_if_progress(fresh: mfm_files::Undo, run_dir: &Path, succeeded: bool) {
    if succeeded || mfm_train::checkpoint::list_checkpoints(run_dir).is_ok_and(|c| !c.is_empty()) {
        fresh.keep();
    }
}

/// Where the dataset of a run is now: `stored` when it is a folder;
/// otherwise, for a run folder and its dataset moved together (a project
/// copied to another machine), the first folder holding a dataset manifest
/// among `A/T` for `A` an ancestor of `run_dir` (up to 3 levels) and `T` the
/// last 1 to 3 components of `stored`. `None` when nothing is found.
pub fn locate_dataset(stored: &Path, run_dir: &Path) -> Option<PathBuf> {
    if stored.is_dir() {
        return Some(stored.to_path_buf());
    }
    let run = std::path::absolute(run_dir).ok()?;
    let parts: Vec<&std::ffi::OsStr> = stored
        .components()
        .filter_map(|c| match c {
            std::path::Component::Normal(p) => Some(p),
            _ => None,
        })
        .collect();
    for ancestor in run.ancestors().skip(1).take(3) {
        for keep in 1..=parts.len().min(3) {
            let mut candidate = ancestor.to_path_buf();
            candidate.extend(&parts[parts.len() - keep..]);
            if candidate.join(mfm_data::dataset::MANIFEST_FILE).is_file() {
                return Some(candidate);
            }
        }
    }
    None
}
