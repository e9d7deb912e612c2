//! The fused modulation and magnitude kernels and the faer linear layer
//! against torch reference implementations: values, gradients, and finite
//! differences.
#![allow(clippy::unwrap_used)]

mod common;

use common::{check_directional, randn, rel_max_diff};
use mfm_net::dense::linear;
use mfm_net::fused::{magnitude_gelu, magnitude_gelu_reference, modulate, modulate_reference};
use tch::{Kind, Tensor};

fn grads(f: &dyn Fn(&[Tensor]) -> Tensor, inputs: &[Tensor], w: &Tensor) -> (Tensor, Vec<Tensor>) {
    let leaves: Vec<Tensor> = inputs
        .iter()
        .map(|t| t.detach().set_requires_grad(true))
        .collect();
    let y = f(&leaves);
    let loss = (&y * w).sum(y.kind());
    let g = Tensor::run_backward(&[&loss], &leaves, false, false);
    (y.detach(), g)
}

#[test]
fn modulation_matches_reference_in_value_and_gradient() {
    tch::set_num_threads(1);
    for kind in [Kind::Double, Kind::Float] {
        let g = randn(&[2, 2 * 37, 5]).to_kind(kind);
        let ps = randn(&[2, 37, 10]).to_kind(kind);
        let w = randn(&[2, 2 * 37, 5]).to_kind(kind);
        let (ya, ga) = grads(
            &|x| modulate(&x[0], &x[1]).unwrap(),
            &[g.shallow_clone(), ps.shallow_clone()],
            &w,
        );
        let (yb, gb) = grads(&|x| modulate_reference(&x[0], &x[1]), &[g, ps], &w);
        let tol = if kind == Kind::Double { 1e-13 } else { 1e-5 };
        assert!(rel_max_diff(&ya, &yb) < tol, "{kind:?} value");
        for (a, b) in ga.iter().zip(&gb) {
            assert!(
                rel_max_diff(a, b) < tol,
                "{kind:?} gradient {}",
                rel_max_diff(a, b)
            );
        }
    }
    let f = |x: &[Tensor]| (modulate(&x[0], &x[1]).unwrap().tanh()).sum(Kind::Double);
    let err = check_directional(&[randn(&[1, 2 * 11, 3]), randn(&[1, 11, 6])], &f, 3, 1e-6);
    assert!(err < 1e-7, "FD {err}");
}

#[test]
fn magnitude_nonlinearity_matches_reference_in_value_and_gradient() {
    tch::set_num_threads(1);
    for kind in [Kind::Double, Kind::Float] {
        let g = randn(&[3, 2 * 41, 7]).to_kind(kind);
        let b = randn(&[7]).to_kind(kind);
        let w = randn(&[3, 2 * 41, 7]).to_kind(kind);
        let (ya, ga) = grads(
            &|x| magnitude_gelu(&x[0], &x[1]).unwrap(),
            &[g.shallow_clone(), b.shallow_clone()],
            &w,
        );
        let (yb, gb) = grads(&|x| magnitude_gelu_reference(&x[0], &x[1]), &[g, b], &w);
        let tol = if kind == Kind::Double { 1e-12 } else { 1e-5 };
        assert!(rel_max_diff(&ya, &yb) < tol, "{kind:?} value");
        for (a, b) in ga.iter().zip(&gb) {
            assert!(
                rel_max_diff(a, b) < tol,
                "{kind:?} gradient {}",
                rel_max_diff(a, b)
            );
        }
    }
    let f = |x: &[Tensor]| {
        (magnitude_gelu(&x[0], &x[1]).unwrap() * 1.3)
            .sin()
            .sum(Kind::Double)
    };
    let err = check_directional(&[randn(&[2, 2 * 9, 4]), randn(&[4])], &f, 3, 1e-6);
    assert!(err < 1e-7, "FD {err}");
    // the eps keeps a zero vector finite
    let z = Tensor::zeros([1, 2, 3], (Kind::Double, tch::Device::Cpu)).set_requires_grad(true);
    let y = magnitude_gelu(&z, &randn(&[3])).unwrap();
    y.sum(Kind::Double).backward();
    assert!(bool::try_from(z.grad().isfinite().all()).unwrap());
}

#[test]
fn shapes_are_checked() {
    assert!(modulate(&randn(&[1, 4, 3]), &randn(&[1, 2, 5])).is_err());
    assert!(magnitude_gelu(&randn(&[1, 3, 3]), &randn(&[3])).is_err());
    assert!(magnitude_gelu(&randn(&[1, 4, 3]), &randn(&[2])).is_err());
}

#[test]
fn faer_linear_matches_torch_linear_in_value_and_gradient() {
    for threads in [1, 2] {
        tch::set_num_threads(threads);
        for kind in [Kind::Double, Kind::Float] {
            // 3-d input, rows not a multiple of the block split
            let x = randn(&[3, 301, 7]).to_kind(kind);
            let w = randn(&[5, 7]).to_kind(kind);
            let b = randn(&[5]).to_kind(kind);
            let r = randn(&[3, 301, 5]).to_kind(kind);
            let ins = [x, w, b];
            let (ya, ga) = grads(&|t| linear(&t[0], &t[1], Some(&t[2])).unwrap(), &ins, &r);
            let (yb, gb) = grads(&|t| t[0].linear(&t[1], Some(&t[2])), &ins, &r);
            let tol = if kind == Kind::Double { 1e-12 } else { 1e-5 };
            assert!(rel_max_diff(&ya, &yb) < tol, "{kind:?} value");
            for (a, b) in ga.iter().zip(&gb) {
                assert!(
                    rel_max_diff(a, b) < tol,
                    "{kind:?} gradient {}",
                    rel_max_diff(a, b)
                );
            }
        }
    }
    tch::set_num_threads(1);
    let f = |t: &[Tensor]| linear(&t[0], &t[1], None).unwrap().tanh().sum(Kind::Double);
    let err = check_directional(&[randn(&[40, 6]), randn(&[3, 6])], &f, 3, 1e-6);
    assert!(err < 1e-7, "FD {err}");
    assert!(linear(&randn(&[4, 3]), &randn(&[2, 4]), None).is_err());
    assert!(linear(&randn(&[4, 3]), &randn(&[2, 3]), Some(&randn(&[3]))).is_err());
}
