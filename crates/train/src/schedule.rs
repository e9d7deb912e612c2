//! Learning-rate schedules: the rate of every step as a function of the
//! step, the base rate and the run's length; written in run descriptions as
//! one TOML (or JSON) table.

use serde::{Deserialize, Serialize};

/// The learning rate as a function of the step.
///
/// In TOML: `{ milestones = [[STEP, LR], ...] }` (from step `STEP` on, the
/// rate is `LR`; steps ascending; an empty list is a constant rate) or
/// `{ decay = FACTOR, at = [STEP, ...] }` (the base rate times
/// `FACTOR^(number of listed steps <= step)`) or `{ warmup = W, cosine =
/// END, floor = LR }` (linear warm-up over the first `W` steps, then a
/// half cosine from the base rate down to `LR` at step `END`, `LR` after)
/// or `{ warmup_fraction = F, floor = LR }` (the same over the whole run:
/// warm-up over the first `round(F * train.steps)` steps, the cosine
/// reaching `LR` at `train.steps`, so the schedule follows `--steps`).
/// Steps count from 0.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "LrScheduleRepr", into = "LrScheduleRepr")]
pub enum LrSchedule {
    /// `(step, lr)` pairs, ascending in step.
    Milestones(Vec<(u64, f64)>),
    /// Multiply by `factor` at each of the steps `at` (ascending).
    Decay {
        /// The factor.
        factor: f64,
        /// The steps.
        at: Vec<u64>,
    },
    /// Step `s < warmup`: `base (s + 1) / warmup`; then
    /// `floor + (base - floor) (1 + cos(pi (s - warmup) / (end - warmup))) / 2`
    /// until `end`, and `floor` from `end` on.
    Cosine {
        /// Warm-up steps (0: none).
        warmup: u64,
        /// The step the cosine reaches `floor` (`> warmup`).
        end: u64,
        /// The final rate (`>= 0`).
        floor: f64,
    },
    /// [`LrSchedule::Cosine`] stretched over the run: warm-up over the
    /// first `round(warmup_fraction * steps)` steps, the cosine ending at
    /// `steps` (the run's `train.steps`).
    CosineOverRun {
        /// The warm-up's share of the run, in `[0, 1)`.
        warmup_fraction: f64,
        /// The final rate (`>= 0`).
        floor: f64,
    },
}

impl Default for LrSchedule {
    /// The paper's: `1e-4` from step 40,000 on.
    fn default() -> Self {
        Self::Milestones(vec![(40_000, 1e-4)])
    }
}

impl LrSchedule {
    /// A constant rate.
    pub fn constant() -> Self {
        Self::Milestones(Vec::new())
    }

    /// The rate at `step` (0-based) for the base rate `base` in a run of
    /// `steps` steps (only [`LrSchedule::CosineOverRun`] depends on it).
    pub fn lr(&self, base: f64, step: u64, steps: u64) -> f64 {
        match self {
            Self::Milestones(m) => m
                .iter()
                .take_while(|(s, _)| *s <= step)
                .last()
                .map_or(base, |(_, lr)| *lr),
            Self::Decay { factor, at } => {
                let n = at.iter().filter(|&&s| s <= step).count();
                base * factor.powi(n as i32)
            }
            Self::Cosine { warmup, end, floor } => warm_cosine(base, step, *warmup, *end, *floor),
            Self::CosineOverRun {
                warmup_fraction,
                floor,
            } => {
                let warmup = (warmup_fraction * steps as f64).round() as u64;
                warm_cosine(base, step, warmup, steps, *floor)
            }
        }
    }

    /// Checks the values: ascending steps, finite positive rates and
    /// factors, a cosine's end after its warm-up, a floor `>= 0`.
    ///
    /// # Errors
    /// What is wrong, in words.
    pub fn validate(&self) -> std::result::Result<(), String> {
        let ascending = |steps: &mut dyn Iterator<Item = u64>| {
            let v: Vec<u64> = steps.collect();
            v.windows(2).all(|w| w[0] < w[1])
        };
        match self {
            Self::Milestones(m) => {
                if !ascending(&mut m.iter().map(|(s, _)| *s)) {
                    return Err("milestone steps must be strictly ascending".into());
                }
                if let Some((s, lr)) = m.iter().find(|(_, lr)| !(lr.is_finite() && *lr > 0.0)) {
                    return Err(format!(
                        "milestone at step {s}: lr must be finite and > 0, found {lr}"
                    ));
                }
            }
            Self::Decay { factor, at } => {
                if !(factor.is_finite() && *factor > 0.0) {
                    return Err(format!("decay must be finite and > 0, found {factor}"));
                }
                if !ascending(&mut at.iter().copied()) {
                    return Err("decay steps `at` must be strictly ascending".into());
                }
            }
            Self::CosineOverRun {
                warmup_fraction,
                floor,
            } => {
                if !(warmup_fraction.is_finite() && (0.0..1.0).contains(warmup_fraction)) {
                    return Err(format!(
                        "cosine: `warmup_fraction` must be in [0, 1), found {warmup_fraction}"
                    ));
                }
                if !(floor.is_finite() && *floor >= 0.0) {
                    return Err(format!(
                        "cosine: `floor` must be finite and >= 0, found {floor}"
                    ));
                }
            }
            Self::Cosine { warmup, end, floor } => {
                if end <= warmup {
                    return Err(format!(
                        "cosine: `cosine` (the end step, {end}) must be above `warmup` ({warmup})"
                    ));
                }
                if !(floor.is_finite() && *floor >= 0.0) {
                    return Err(format!(
                        "cosine: `floor` must be finite and >= 0, found {floor}"
                    ));
                }
            }
        }
        Ok(())
    }
}

/// Linear warm-up over `warmup` steps to `base`, then a half cosine down to
/// `floor` at step `end`, `floor` from `end` on (and right after a warm-up
/// that fills the run).
fn warm_cosine(base: f64, step: u64, warmup: u64, end: u64, floor: f64) -> f64 {
    if step < warmup {
        base * (step + 1) as f64 / warmup as f64
    } else if step >= end {
        floor
    } else {
        let f = (step - warmup) as f64 / (end - warmup) as f64;
        floor + (base - floor) * 0.5 * (1.0 + (std::f64::consts::PI * f).cos())
    }
}

/// The TOML form of [`LrSchedule`] (one table, checked on conversion).
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct LrScheduleRepr {
    #[serde(default, skip_serializing_if = "Option::is_none")]
    milestones: Option<Vec<(u64, f64)>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    decay: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    at: Option<Vec<u64>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    warmup: Option<u64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    cosine: Option<u64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    warmup_fraction: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    floor: Option<f64>,
}

impl TryFrom<LrScheduleRepr> for LrSchedule {
    type Error = String;

    fn try_from(r: LrScheduleRepr) -> std::result::Result<Self, String> {
        if r.warmup.is_some()
            || r.cosine.is_some()
            || r.floor.is_some()
            || r.warmup_fraction.is_some()
        {
            if r.milestones.is_some() || r.decay.is_some() || r.at.is_some() {
                return Err(
                    "lr_schedule: `warmup`/`warmup_fraction`/`cosine`/`floor` go alone, without `milestones`, `decay` or `at`"
                        .into(),
                );
            }
            if let Some(warmup_fraction) = r.warmup_fraction {
                if r.warmup.is_some() || r.cosine.is_some() {
                    return Err(
                        "lr_schedule: `warmup_fraction` spans the run: give it without `warmup` or `cosine` (those fix the steps)"
                            .into(),
                    );
                }
                let s = Self::CosineOverRun {
                    warmup_fraction,
                    floor: r.floor.unwrap_or(0.0),
                };
                s.validate().map_err(|e| format!("lr_schedule: {e}"))?;
                return Ok(s);
            }
            let Some(end) = r.cosine else {
                return Err(
                    "lr_schedule: a cosine schedule needs `cosine = END_STEP`, or `warmup_fraction = F` to span the run"
                        .into(),
                );
            };
            let s = Self::Cosine {
                warmup: r.warmup.unwrap_or(0),
                end,
                floor: r.floor.unwrap_or(0.0),
            };
            s.validate().map_err(|e| format!("lr_schedule: {e}"))?;
            return Ok(s);
        }
        let s = match (r.milestones, r.decay, r.at) {
            (Some(m), None, None) => Self::Milestones(m),
            (None, Some(factor), Some(at)) => Self::Decay { factor, at },
            (None, Some(_), None) => return Err("lr_schedule: `decay` needs `at`".into()),
            (None, None, Some(_)) => return Err("lr_schedule: `at` needs `decay`".into()),
            (None, None, None) => {
                return Err(
                    "lr_schedule: expected `milestones = [[step, lr], ...]` or `decay` with `at`"
                        .into(),
                );
            }
            _ => {
                return Err(
                    "lr_schedule: give either `milestones` or `decay` with `at`, not both".into(),
                );
            }
        };
        s.validate().map_err(|e| format!("lr_schedule: {e}"))?;
        Ok(s)
    }
}

impl From<LrSchedule> for LrScheduleRepr {
    fn from(s: LrSchedule) -> Self {
        match s {
            LrSchedule::Milestones(m) => Self {
                milestones: Some(m),
                decay: None,
                at: None,
                warmup: None,
                cosine: None,
                warmup_fraction: None,
                floor: None,
            },
            LrSchedule::Decay { factor, at } => Self {
                milestones: None,
                decay: Some(factor),
                at: Some(at),
                warmup: None,
                cosine: None,
                warmup_fraction: None,
                floor: None,
            },
            LrSchedule::Cosine { warmup, end, floor } => Self {
                milestones: None,
                decay: None,
                at: None,
                warmup: Some(warmup),
                cosine: Some(end),
                warmup_fraction: None,
                floor: Some(floor),
            },
            LrSchedule::CosineOverRun {
                warmup_fraction,
                floor,
            } => Self {
                milestones: None,
                decay: None,
                at: None,
                warmup: None,
                cosine: None,
                warmup_fraction: Some(warmup_fraction),
                floor: Some(floor),
            },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn schedules_give_the_documented_rates() {
        let d = LrSchedule::Decay {
            factor: 0.2,
            at: vec![40, 160],
        };
        assert_eq!(d.lr(1.0, 39, 0), 1.0);
        assert_eq!(d.lr(1.0, 40, 0), 0.2);
        assert!((d.lr(1.0, 200, 0) - 0.04).abs() < 1e-15);
        assert_eq!(LrSchedule::constant().lr(3.0, 1_000_000, 0), 3.0);
        let c = LrSchedule::Cosine {
            warmup: 10,
            end: 110,
            floor: 0.1,
        };
        assert!((c.lr(2.0, 0, 0) - 0.2).abs() < 1e-15);
        assert!((c.lr(2.0, 9, 0) - 2.0).abs() < 1e-15);
        assert!((c.lr(2.0, 10, 0) - 2.0).abs() < 1e-15);
        // half way down the cosine: the mean of base and floor
        assert!((c.lr(2.0, 60, 0) - 1.05).abs() < 1e-12);
        assert_eq!(c.lr(2.0, 110, 0), 0.1);
        assert_eq!(c.lr(2.0, 10_000, 0), 0.1);
        // monotone after the warm-up
        let rates: Vec<f64> = (10..=110).map(|s| c.lr(2.0, s, 0)).collect();
        assert!(rates.windows(2).all(|w| w[1] <= w[0]));
        // over the run: the fixed cosine with the run's length
        let r = LrSchedule::CosineOverRun {
            warmup_fraction: 0.05,
            floor: 1e-5,
        };
        let fixed = LrSchedule::Cosine {
            warmup: 250,
            end: 5000,
            floor: 1e-5,
        };
        for step in [0, 1, 249, 250, 251, 2600, 4999, 5000] {
            assert_eq!(r.lr(4e-3, step, 5000), fixed.lr(4e-3, step, 0), "{step}");
        }
        // a 20-step run warms up over one step and ends near the floor
        assert_eq!(r.lr(4e-3, 0, 20), 4e-3);
        assert!(r.lr(4e-3, 19, 20) < 1e-4);
    }
}
