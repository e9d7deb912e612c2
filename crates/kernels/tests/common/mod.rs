//! Helpers shared by the integration tests: finite-difference gradient checks.
#![allow(dead_code, clippy::unwrap_used)]

use tch::{Device, Kind, Tensor};

/// Scalar value of a 0-d (or 1-element) tensor.
pub fn scalar(t: &Tensor) -> f64 {
    t.double_value(&[])
}

pub fn randn(shape: &[i64]) -> Tensor {
    Tensor::randn(shape, (Kind::Double, Device::Cpu))
}

/// Checks d/ds f(x + s d) at s = 0 by central differences against the autograd
/// gradients, for `dirs` random directions over all `inputs` at once.
/// `f` must be a scalar function; returns the worst relative error.
pub fn check_directional(
    inputs: &[Tensor],
    f: &dyn Fn(&[Tensor]) -> Tensor,
    dirs: usize,
    h: f64,
) -> f64 {
    let leaves: Vec<Tensor> = inputs
        .iter()
        .map(|t| t.detach().set_requires_grad(true))
        .collect();
    let y = f(&leaves);
    let grads = Tensor::run_backward(&[&y], &leaves, false, false);
    let mut worst = 0.0f64;
    for _ in 0..dirs {
        let d: Vec<Tensor> = inputs.iter().map(|t| randn(&t.size())).collect();
        let analytic: f64 = grads
            .iter()
            .zip(&d)
            .map(|(g, d)| scalar(&(g * d).sum(Kind::Double)))
            .sum();
        let plus: Vec<Tensor> = inputs
            .iter()
            .zip(&d)
            .map(|(x, d)| x.detach() + d * h)
            .collect();
        let minus: Vec<Tensor> = inputs
            .iter()
            .zip(&d)
            .map(|(x, d)| x.detach() - d * h)
            .collect();
        let numeric = tch::no_grad(|| (scalar(&f(&plus)) - scalar(&f(&minus))) / (2.0 * h));
        let err = relative_error(analytic, numeric, &grads, &d);
        worst = worst.max(err);
    }
    worst
}

/// Same check over parameters held in place (e.g. a VarStore's variables):
/// perturbs them under no_grad and restores them.
pub fn check_parameters(params: &[Tensor], f: &dyn Fn() -> Tensor, dirs: usize, h: f64) -> f64 {
    for p in params {
        let mut g = p.grad();
        if g.defined() {
            let _ = g.zero_();
        }
    }
    let y = f();
    let grads = Tensor::run_backward(&[&y], params, false, false);
    let mut worst = 0.0f64;
    for _ in 0..dirs {
        let d: Vec<Tensor> = params
            .iter()
            .map(|t| randn(&t.size()).to_kind(t.kind()))
            .collect();
        let analytic: f64 = grads
            .iter()
            .zip(&d)
            .map(|(g, d)| scalar(&(g * d).sum(Kind::Double)))
            .sum();
        let shift = |s: f64| {
            tch::no_grad(|| {
                for (p, d) in params.iter().zip(&d) {
                    let mut p = p.shallow_clone();
                    let _ = p.g_add_(&(d * s));
                }
            })
        };
        shift(h);
        let fp = tch::no_grad(|| scalar(&f()));
        shift(-2.0 * h);
        let fm = tch::no_grad(|| scalar(&f()));
        shift(h);
        let numeric = (fp - fm) / (2.0 * h);
        let err = relative_error(analytic, numeric, &grads, &d);
        worst = worst.max(err);
    }
    worst
}

/// `|analytic - numeric|` relative to the larger of the two and of the
/// typical size of a directional derivative along a random direction,
/// `|g| |d| / sqrt(n)` (`n` entries in all): a direction that happens to be
/// nearly orthogonal to the gradient makes both derivatives tiny, and
/// dividing by them alone turns finite-difference round-off into a large
/// "relative" error.
fn relative_error(analytic: f64, numeric: f64, grads: &[Tensor], dirs: &[Tensor]) -> f64 {
    let norm2 = |ts: &[Tensor]| -> f64 {
        ts.iter()
            .map(|t| scalar(&t.to_kind(Kind::Double).square().sum(Kind::Double)))
            .sum()
    };
    let n: usize = dirs.iter().map(|t| t.numel()).sum();
    let typical = (norm2(grads) * norm2(dirs)).sqrt() / (n.max(1) as f64).sqrt();
    (analytic - numeric).abs() / analytic.abs().max(numeric.abs()).max(typical).max(1e-12)
}

/// Max |a - b| / max |b|.
pub fn rel_max_diff(a: &Tensor, b: &Tensor) -> f64 {
    let num = scalar(&(a - b).abs().max().to_kind(Kind::Double));
    let den = scalar(&b.abs().max().to_kind(Kind::Double)).max(1e-300);
    num / den
}
