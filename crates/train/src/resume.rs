//! What a resumed run may change of its description: the one check of
//! every kind of run.
//!
//! A run folder keeps its description (the flow's `config.toml`, the
//! arbitrary-source runs' `predictor.json` / `arbitrary.json`) and every
//! checkpoint a copy of it. Resuming compares the two field by field
//! ([`changes`], over dotted paths of the description as a JSON value) and
//! refuses edits outside the fields the kind of run lists as resumable
//! (how long it runs, how it checkpoints, where its data now lives), naming
//! each ([`refuse_edits`]).

use std::collections::{BTreeMap, BTreeSet};
use std::fmt;
use std::path::Path;

use crate::error::{Result, TrainError};

/// One field that differs between two descriptions of a run.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ConfigChange {
    /// Dotted path, e.g. `model.width`.
    pub field: String,
    /// The value before (JSON text; `-` when absent).
    pub before: String,
    /// The value after.
    pub after: String,
}

impl fmt::Display for ConfigChange {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{} {} -> {}", self.field, self.before, self.after)
    }
}

/// The scalar fields of `v` by dotted path (arrays whole).
fn flatten(prefix: &str, v: &serde_json::Value, out: &mut BTreeMap<String, String>) {
    match v {
        serde_json::Value::Object(map) => {
            for (k, x) in map {
                let key = if prefix.is_empty() {
                    k.clone()
                } else {
                    format!("{prefix}.{k}")
                };
                flatten(&key, x, out);
            }
        }
        other => {
            out.insert(prefix.to_owned(), other.to_string());
        }
    }
}

/// The fields in which `after` differs from `before`, in the order of
/// their dotted paths.
pub fn changes(before: &serde_json::Value, after: &serde_json::Value) -> Vec<ConfigChange> {
    let (mut a, mut b) = (BTreeMap::new(), BTreeMap::new());
    flatten("", before, &mut a);
    flatten("", after, &mut b);
    let keys: BTreeSet<&String> = a.keys().chain(b.keys()).collect();
    keys.into_iter()
        .filter(|k| a.get(*k) != b.get(*k))
        .map(|k| ConfigChange {
            field: k.clone(),
            before: a.get(k).cloned().unwrap_or_else(|| "-".into()),
            after: b.get(k).cloned().unwrap_or_else(|| "-".into()),
        })
        .collect()
}

/// What a kind of run lets a resumed run change.
#[derive(Clone, Copy, Debug)]
pub struct ResumePolicy<'a> {
    /// The fields that may change (dotted paths).
    pub resumable: &'a [&'a str],
    /// The dotted path of the run's total steps.
    pub steps_field: &'a str,
    /// What else the user may do, ending the refusal ("start a new run
    /// with --config").
    pub otherwise: &'a str,
}

/// Refuses to resume from the checkpoint of step `step` when the run's
/// description `file` was edited since (`changes`, from the checkpoint's
/// copy to the file) in a field outside `policy.resumable`, naming each
/// change, or when its total steps `steps` fall below the checkpoint's.
///
/// # Errors
/// [`TrainError::Config`] saying which edits, and what to do.
pub fn refuse_edits(
    file: &Path,
    step: u64,
    changes: &[ConfigChange],
    steps: Option<u64>,
    policy: ResumePolicy<'_>,
) -> Result<()> {
    let refused: Vec<String> = changes
        .iter()
        .filter(|c| !policy.resumable.contains(&c.field.as_str()))
        .map(ToString::to_string)
        .collect();
    if !refused.is_empty() {
        return Err(TrainError::Config(format!(
            "{} was edited after the checkpoint at step {step}: {}; a resumed run cannot change \
             these (only {} can): undo the edit, or {}",
            file.display(),
            refused.join(", "),
            policy.resumable.join(", "),
            policy.otherwise
        )));
    }
    if let Some(total) = steps.filter(|&t| t < step) {
        return Err(TrainError::Config(format!(
            "{}: {} = {total} is below the checkpoint's step {step}",
            file.display(),
            policy.steps_field
        )));
    }
    Ok(())
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn edits_are_named_and_only_the_resumable_pass() {
        let before = serde_json::json!({"model": {"width": 8, "blocks": 2}, "steps": 4});
        let after =
            serde_json::json!({"model": {"width": 16, "blocks": 2}, "steps": 6, "new": true});
        let c = changes(&before, &after);
        let shown: Vec<String> = c.iter().map(ToString::to_string).collect();
        assert_eq!(
            shown,
            ["model.width 8 -> 16", "new - -> true", "steps 4 -> 6"]
        );
        let policy = ResumePolicy {
            resumable: &["steps"],
            steps_field: "steps",
            otherwise: "start a new run",
        };
        let file = Path::new("run/config.toml");
        let e = refuse_edits(file, 3, &c, Some(6), policy)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("run/config.toml was edited after the checkpoint at step 3: model.width 8 -> 16, new - -> true;")
                && e.ends_with("undo the edit, or start a new run"),
            "{e}"
        );
        let only_steps: Vec<ConfigChange> = c.into_iter().filter(|c| c.field == "steps").collect();
        refuse_edits(file, 3, &only_steps, Some(6), policy).unwrap();
        let e = refuse_edits(file, 7, &only_steps, Some(6), policy)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("steps = 6 is below the checkpoint's step 7"),
            "{e}"
        );
    }
}
