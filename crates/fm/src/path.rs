//! The rectified-flow path and its integration, for every flow of mfm (one
//! training mesh, [`crate::train`] and [`crate::sample`]; arbitrary
//! sources, `mfm-arbitrary`): what training regresses on and what sampling
//! integrates.
//!
//! The path from noise `x0` to data `x1` is `x_t = (1 - t) x0 + t x1`, with
//! the constant velocity `x1 - x0`; sampling integrates a learned velocity
//! `v(x, t)` from `t = 0` to `1` in steps of `h` ([`ode_step`]). Training
//! draws the time of each item from a [`TimeSampling`].

use std::fmt;
use std::ops::{Mul, Sub};

use serde::{Deserialize, Deserializer, Serialize, Serializer};
use tch::Tensor;

use crate::config::OdeMethod;

/// The point of the path at time `t` and the path's velocity: `((1 - t) x0
/// + t x1, x1 - x0)`. `t` is a number (one time for the batch) or a tensor
/// that broadcasts against `x0` (one time per item, e.g. `[B, 1, 1]`).
pub fn rectified_path<T, S>(x0: &Tensor, x1: &Tensor, t: T) -> (Tensor, Tensor)
where
    T: Copy,
    f64: Sub<T, Output = S>,
    for<'a> &'a Tensor: Mul<S, Output = Tensor> + Mul<T, Output = Tensor>,
{
    let xt = x0 * (1.0 - t) + x1 * t;
    (xt, x1 - x0)
}

/// One step of the ODE `dx/dt = velocity(x, t)` from `(x, t)` to `t + h`:
/// Euler `x + h v(x, t)`, or the explicit midpoint `x + h v(x + h/2 v(x,
/// t), t + h/2)` (second order, two evaluations; the paper's).
///
/// # Errors
/// Those of `velocity`.
pub fn ode_step<E>(
    method: OdeMethod,
    x: &Tensor,
    t: f64,
    h: f64,
    mut velocity: impl FnMut(&Tensor, f64) -> Result<Tensor, E>,
) -> Result<Tensor, E> {
    Ok(match method {
        OdeMethod::Euler => x + velocity(x, t)? * h,
        OdeMethod::Midpoint => {
            let mid = x + velocity(x, t)? * (h / 2.0);
            x + velocity(&mid, t + h / 2.0)? * h
        }
    })
}

/// The path time of each training item is drawn from a [`TimeSampling`]
/// (`train.time`).
/// The distribution of the path time `t` in training.
///
/// In TOML: `"uniform"`, `"logit-normal"` (mean 0, standard deviation 1),
/// `"logit-normal:M:S"`, or `"late:P"`. Draws come from the step's own
/// random stream, so they are a pure function of the seed and the step.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub enum TimeSampling {
    /// `t ~ U[0, 1)`.
    #[default]
    Uniform,
    /// `t = sigmoid(m + s z)`, `z ~ N(0, 1)`: more weight on the middle of
    /// the path, where the velocity is hardest to predict.
    LogitNormal {
        /// `m`.
        mean: f64,
        /// `s > 0`.
        std: f64,
    },
    /// `t = 1 - (1 - u)^p`, `p > 0`: `p > 1` puts more weight near the data
    /// end (`t -> 1`), where a sample's detail is decided.
    Late {
        /// `p`.
        power: f64,
    },
}

impl TimeSampling {
    /// Draws one path time in `[0, 1]` from `rng`: one uniform `f32` for
    /// `uniform` (the draw training has always made), one uniform `f64` for
    /// `late`, one standard normal (`rand_distr`) for `logit-normal`; the
    /// last two are computed in `f64`.
    pub fn draw(&self, rng: &mut impl rand::Rng) -> f32 {
        match *self {
            Self::Uniform => rng.random::<f32>(),
            Self::LogitNormal { mean, std } => {
                let z: f64 = rng.sample(rand_distr::StandardNormal);
                (1.0 / (1.0 + (-(mean + std * z)).exp())) as f32
            }
            Self::Late { power } => (1.0 - (1.0 - rng.random::<f64>()).powf(power)) as f32,
        }
    }

    /// Checks the parameters: a finite mean and a finite `std > 0`, a
    /// finite `power > 0`.
    ///
    /// # Errors
    /// What is wrong, in words.
    pub fn validate(&self) -> std::result::Result<(), String> {
        match *self {
            Self::Uniform => Ok(()),
            Self::LogitNormal { mean, std } => {
                if mean.is_finite() && std.is_finite() && std > 0.0 {
                    Ok(())
                } else {
                    Err(format!(
                        "logit-normal needs a finite mean and a finite std > 0, found {mean}, {std}"
                    ))
                }
            }
            Self::Late { power } => {
                if power.is_finite() && power > 0.0 {
                    Ok(())
                } else {
                    Err(format!("late needs a finite power > 0, found {power}"))
                }
            }
        }
    }
}

impl fmt::Display for TimeSampling {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Uniform => f.write_str("uniform"),
            Self::LogitNormal { mean, std } => write!(f, "logit-normal:{mean}:{std}"),
            Self::Late { power } => write!(f, "late:{power}"),
        }
    }
}

impl std::str::FromStr for TimeSampling {
    type Err = String;

    fn from_str(s: &str) -> std::result::Result<Self, String> {
        let parts: Vec<&str> = s.trim().split(':').collect();
        let num = |x: &str| {
            x.parse::<f64>()
                .map_err(|_| format!("time sampling {s:?}: {x:?} is not a number"))
        };
        let t = match parts.as_slice() {
            ["uniform"] => Self::Uniform,
            ["logit-normal"] => Self::LogitNormal {
                mean: 0.0,
                std: 1.0,
            },
            ["logit-normal", m, sd] => Self::LogitNormal {
                mean: num(m)?,
                std: num(sd)?,
            },
            ["late", p] => Self::Late { power: num(p)? },
            _ => {
                return Err(format!(
                    "unknown time sampling {s:?}; expected \"uniform\", \"logit-normal\", \"logit-normal:M:S\" or \"late:P\""
                ));
            }
        };
        t.validate()
            .map_err(|e| format!("time sampling {s:?}: {e}"))?;
        Ok(t)
    }
}

impl Serialize for TimeSampling {
    fn serialize<S: Serializer>(&self, s: S) -> std::result::Result<S::Ok, S::Error> {
        s.serialize_str(&self.to_string())
    }
}

impl<'de> Deserialize<'de> for TimeSampling {
    fn deserialize<D: Deserializer<'de>>(d: D) -> std::result::Result<Self, D::Error> {
        let s = String::deserialize(d)?;
        s.parse().map_err(serde::de::Error::custom)
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn the_path_and_the_steps_are_exact_where_they_must_be() {
        let x0 = Tensor::from_slice(&[1.0f64, -2.0]);
        let x1 = Tensor::from_slice(&[3.0f64, 2.0]);
        let (xt, v) = rectified_path(&x0, &x1, 0.25);
        assert_eq!(Vec::<f64>::try_from(xt).unwrap(), [1.5, -1.0]);
        assert_eq!(Vec::<f64>::try_from(&v).unwrap(), [2.0, 4.0]);
        // a time per item broadcasts, and agrees with the number
        let t = Tensor::from_slice(&[0.25f64]);
        let (xt, _) = rectified_path(&x0, &x1, &t);
        assert_eq!(Vec::<f64>::try_from(xt).unwrap(), [1.5, -1.0]);
        // dx/dt = 2 t: Euler from 0 by 1 stays, the midpoint is exact
        let f = |_: &Tensor, t: f64| -> Result<Tensor, ()> { Ok(Tensor::from(2.0 * t)) };
        let x = Tensor::from(1.0f64);
        let euler = ode_step(OdeMethod::Euler, &x, 0.0, 1.0, f).unwrap();
        let midpoint = ode_step(OdeMethod::Midpoint, &x, 0.0, 1.0, f).unwrap();
        assert_eq!(euler.double_value(&[]), 1.0);
        assert_eq!(midpoint.double_value(&[]), 2.0);
    }
}
