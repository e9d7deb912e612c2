//! The rectified-flow path and its integration, for every flow of mfm (one
//! training mesh, [`crate::train`] and [`crate::sample`]; arbitrary
//! sources, `mfm-arbitrary`): what training regresses on and what sampling
//! integrates.
//!
//! The path from noise `x0` to data `x1` is `x_t = (1 - t) x0 + t x1`, with
//! the constant velocity `x1 - x0`; sampling integrates a learned velocity
//! `v(x, t)` from `t = 0` to `1` in steps of `h` ([`ode_step`]).

use std::ops::{Mul, Sub};

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
