//! The files `mfm` writes that the reproductions read, as types: `mfm
//! eval`'s reports ([`EvalReport`], [`PlausibilityReport`]) and `mfm
//! eval-arbitrary`'s ([`SetEvaluation`]) are mfm-eval's own; a sample
//! folder's `timing.json` is read into [`SampleTiming`] (its type in
//! mfm-fm links libtorch); a run folder's checkpoints and log are
//! `mfm_files::run_folder`'s.

use anyhow::{Context, Result};
use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};
use std::path::Path;

pub use mfm_eval::arbitrary::SetEvaluation;
pub use mfm_eval::evaluation::{EvalReport, PlausibilityReport};

/// Reads the JSON file `path` as a `T`.
///
/// # Errors
/// When it cannot be read, or is not a `T` (the message names the file).
pub fn read<T: DeserializeOwned>(path: &Path) -> Result<T> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))?;
    serde_json::from_str(&text).with_context(|| {
        format!(
            "{}: not the {} it should be",
            path.display(),
            std::any::type_name::<T>()
        )
    })
}

/// Writes `value` to `path` as pretty JSON.
///
/// # Errors
/// When it cannot be written.
pub fn write<T: Serialize>(path: &Path, value: &T) -> Result<()> {
    std::fs::write(path, serde_json::to_string_pretty(value)?)
        .with_context(|| format!("cannot write {}", path.display()))
}

/// An evaluation of generated samples: `mfm eval`'s report, or, when
/// sampling broke down (a result of an experiment, not a crash), the
/// failure recorded in its place as `{"error": MESSAGE}`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum EvalOutcome {
    /// Sampling failed: why.
    Failed {
        /// The error, with its causes.
        error: String,
    },
    /// The report.
    Report(Box<EvalReport>),
}

impl EvalOutcome {
    /// The failure of `error`.
    pub fn failed(error: &anyhow::Error) -> Self {
        Self::Failed {
            error: format!("{error:#}"),
        }
    }

    /// The report, unless sampling failed.
    pub fn report(&self) -> Option<&EvalReport> {
        match self {
            Self::Report(r) => Some(r),
            Self::Failed { .. } => None,
        }
    }
}

/// What the reproductions read of a sample folder's `timing.json`
/// (`mfm_fm::sample::SampleTiming`, written by `mfm sample`).
#[derive(Clone, Copy, Debug, PartialEq, Deserialize)]
pub struct SampleTiming {
    /// Vertices of the target mesh.
    pub vertices: usize,
    /// Wall seconds per sample.
    pub seconds_per_sample: f64,
}

impl SampleTiming {
    /// Reads `timing.json` of the sample folder `dir`.
    ///
    /// # Errors
    /// As [`read`].
    pub fn of(dir: &Path) -> Result<Self> {
        read(&dir.join("timing.json"))
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn a_failure_and_a_report_read_back_as_what_they_are() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("metrics.json");
        let failed = EvalOutcome::failed(&anyhow::anyhow!("no samples").context("sampling"));
        write(&path, &failed).unwrap();
        assert_eq!(
            std::fs::read_to_string(&path).unwrap(),
            "{\n  \"error\": \"sampling: no samples\"\n}"
        );
        assert_eq!(read::<EvalOutcome>(&path).unwrap(), failed);
        assert!(failed.report().is_none());
        let report = r#"{"mmd": 0.5, "cov": 0.25, "one_nna": 0.75, "test_error": 0.125,
            "num_generated": 4, "num_reference": 8}"#;
        std::fs::write(&path, report).unwrap();
        let read_back = read::<EvalOutcome>(&path).unwrap();
        let r = read_back.report().unwrap();
        assert_eq!((r.metrics.mmd, r.metrics.num_reference), (0.5, 8));
        assert!(r.quality.is_none() && r.shapes.is_none());
        std::fs::write(&path, "{\"mmd\": 1}").unwrap();
        let e = format!("{:#}", read::<EvalOutcome>(&path).unwrap_err());
        assert!(e.contains("metrics.json"), "{e}");
    }

    #[test]
    fn timing_reads_the_fields_it_needs() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(
            dir.path().join("timing.json"),
            r#"{"samples": 2, "vertices": 10, "channels": 3, "ode_steps": 5, "method": "midpoint",
                "seconds": 1.0, "noise_seconds": 0.1, "seconds_per_sample": 0.5}"#,
        )
        .unwrap();
        let t = SampleTiming::of(dir.path()).unwrap();
        assert_eq!((t.vertices, t.seconds_per_sample), (10, 0.5));
    }
}
