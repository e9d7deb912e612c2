//! The differentiable mesh operators and the Poisson solve: values against
//! independent computations, adjointness, and finite-difference gradients.
#![allow(clippy::unwrap_used)]

mod common;

use std::sync::Arc;

use common::{check_directional, randn, rel_max_diff, scalar};
use mfm_geometry::operators::Operators;
use mfm_geometry::procedural;
use mfm_kernels::mesh::{Backend, MeshTensors};
use tch::{Device, Kind, Tensor};

fn sphere(level: u32) -> (mfm_geometry::TriMesh, MeshTensors) {
    let mesh = procedural::icosphere(level);
    let mt = MeshTensors::new(&mesh).unwrap();
    (mesh, mt)
}

/// Dense `G` from the sparse operator (the independent reference).
fn dense_gradient(ops: &Operators) -> Tensor {
    let g = &ops.gradient;
    let (r, c) = (g.nrows(), g.ncols());
    let mut d = vec![0.0f64; r * c];
    let cp = g.symbolic().col_ptr();
    let ri = g.symbolic().row_idx();
    for j in 0..c {
        for k in cp[j]..cp[j + 1] {
            d[ri[k] * c + j] += g.val()[k];
        }
    }
    Tensor::from_slice(&d).reshape([r as i64, c as i64])
}

fn dense_laplacian(ops: &Operators) -> Tensor {
    let l = &ops.laplacian;
    let n = l.nrows();
    let mut d = vec![0.0f64; n * n];
    let cp = l.symbolic().col_ptr();
    let ri = l.symbolic().row_idx();
    for j in 0..n {
        for k in cp[j]..cp[j + 1] {
            d[ri[k] * n + j] += l.val()[k];
        }
    }
    Tensor::from_slice(&d).reshape([n as i64, n as i64])
}

#[test]
fn gradient_and_adjoint_match_dense_operator_on_both_backends() {
    let (mesh, mt) = sphere(2);
    let ops = Operators::new(&mesh).unwrap();
    let g = dense_gradient(&ops);
    let v = mt.num_vertices() as i64;
    let f2 = 2 * mt.num_faces() as i64;
    let x = randn(&[3, v, 5]);
    let y = randn(&[3, f2, 5]);
    for backend in [Backend::Native, Backend::Torch] {
        let m = mt.with_backend(backend);
        let gx = m.gradient(&x).unwrap();
        assert!(rel_max_diff(&gx, &g.matmul(&x)) < 1e-13, "{backend:?} G x");
        let gty = m.gradient_adjoint(&y).unwrap();
        assert!(
            rel_max_diff(&gty, &g.tr().matmul(&y)) < 1e-13,
            "{backend:?} G^T y"
        );
        let a2 = Tensor::from_slice(&ops.face_areas_interleaved).unsqueeze(-1);
        let div = m.divergence(&y).unwrap();
        assert!(
            rel_max_diff(&div, &g.tr().matmul(&(&y * &a2))) < 1e-13,
            "{backend:?} G^T A2 y"
        );
        // the divergence of i y, with i y = (-y_im, y_re) built by hand
        let yf = y.reshape([3, f2 / 2, 2, 5]);
        let iy = Tensor::stack(&[-yf.select(2, 1), yf.select(2, 0)], 2).reshape([3, f2, 5]);
        let rot = m.rotated_divergence(&y).unwrap();
        assert!(
            rel_max_diff(&rot, &g.tr().matmul(&(&iy * &a2))) < 1e-13,
            "{backend:?} G^T A2 (i y)"
        );
        // both side by side in one pass, in f64 and f32, and its adjoint:
        // <paired(y), [p | q]> = <y, A2 G p + A2 G_rot q> (the backward)
        let paired = m.paired_divergence(&y).unwrap();
        assert_eq!(paired.size(), vec![3, v, 10]);
        assert!(rel_max_diff(&paired, &Tensor::cat(&[&div, &rot], -1)) < 1e-13);
        let p32 = m.paired_divergence(&y.to_kind(Kind::Float)).unwrap();
        assert!(rel_max_diff(&p32.to_kind(Kind::Double), &paired) < 1e-5);
        let pq = randn(&[3, v, 10]);
        let yt = y.detach().set_requires_grad(true);
        let lhs = (m.paired_divergence(&yt).unwrap() * &pq).sum(Kind::Double);
        lhs.backward();
        let (p, q) = (pq.narrow(-1, 0, 5), pq.narrow(-1, 5, 5));
        let pf = (g.matmul(&p) * &a2).reshape([3, f2 / 2, 2, 5]);
        let qf = (g.matmul(&q) * &a2).reshape([3, f2 / 2, 2, 5]);
        // A2 G_rot q: rows (x, y) -> (y, -x) of A2 G q
        let qrot = Tensor::stack(&[qf.select(2, 1), -qf.select(2, 0)], 2);
        let expected = (pf + qrot).reshape([3, f2, 5]);
        assert!(
            rel_max_diff(&yt.grad(), &expected) < 1e-13,
            "{backend:?} adjoint of the paired divergence"
        );
        // f32 kernels agree with f64 to single precision
        let gx32 = m.gradient(&x.to_kind(Kind::Float)).unwrap();
        assert_eq!(gx32.kind(), Kind::Float);
        assert!(rel_max_diff(&gx32.to_kind(Kind::Double), &gx) < 1e-5);
    }
    // unbatched input keeps its rank
    let x2 = randn(&[v, 2]);
    assert_eq!(mt.gradient(&x2).unwrap().size(), vec![f2, 2]);
}

#[test]
fn divergence_of_gradient_is_the_laplacian() {
    let (mesh, mt) = sphere(2);
    let ops = Operators::new(&mesh).unwrap();
    let l = dense_laplacian(&ops);
    let v = mt.num_vertices() as i64;
    let u = randn(&[2, v, 3]);
    let lu = mt.divergence(&mt.gradient(&u).unwrap()).unwrap();
    assert!(rel_max_diff(&lu, &l.matmul(&u)) < 1e-12);
}

#[test]
fn face_mean_and_its_adjoint() {
    let (mesh, mt) = sphere(1);
    let v = mt.num_vertices() as i64;
    let x = randn(&[2, v, 4]);
    let fm = mt.face_mean(&x).unwrap();
    for (f, t) in mesh.faces().iter().enumerate().step_by(7) {
        let want =
            (x.get(1).get(t[0] as i64) + x.get(1).get(t[1] as i64) + x.get(1).get(t[2] as i64))
                / 3.0;
        assert!(rel_max_diff(&fm.get(1).get(f as i64), &want) < 1e-14);
    }
    // <face_mean x, y> = <x, face_mean^T y>
    let y = randn(&[2, mt.num_faces() as i64, 4]);
    let lhs = scalar(&(&fm * &y).sum(Kind::Double));
    let rhs = scalar(&(&x * mt.face_mean_adjoint(&y).unwrap()).sum(Kind::Double));
    assert!((lhs - rhs).abs() < 1e-12 * lhs.abs().max(1.0));
}

#[test]
fn solve_inverts_shifted_laplacian_and_matches_dense_solve() {
    let (mesh, mt) = sphere(2);
    let ops = Operators::new(&mesh).unwrap();
    let n = mt.num_vertices() as i64;
    let eps = mt.solver().eps();
    let a = dense_laplacian(&ops) + Tensor::eye(n, (Kind::Double, Device::Cpu)) * eps;
    let b = randn(&[3, n, 2]);
    let x = mt.solve(&b).unwrap();
    // residual of the sparse solve against the dense matrix
    let res = rel_max_diff(&a.matmul(&x), &b);
    assert!(res < 1e-8, "relative residual {res}");
    // f32 tensors use the f32 factor. With a zero-sum right-hand side (as
    // PoissonNet's divergences) f32 round-off still feeds the constant mode,
    // amplified by 1/eps; after the mean removal that PoissonNet applies the
    // two agree to single precision times the conditioning of the
    // zero-mean problem
    let b0 = &b - b.mean_dim([-2i64].as_slice(), true, Kind::Double);
    let x64 = mt.remove_mass_mean(&mt.solve(&b0).unwrap()).unwrap();
    let x32 = mt.solve(&b0.to_kind(Kind::Float)).unwrap();
    assert_eq!(x32.kind(), Kind::Float);
    let x32 = mt.remove_mass_mean(&x32).unwrap().to_kind(Kind::Double);
    let err = rel_max_diff(&x32, &x64);
    assert!(err < 1e-3, "f32 vs f64 solve after mean removal: {err}");
}

#[test]
fn solve_of_many_channels_matches_the_dense_solve_and_names_a_bad_entry() {
    // 45 channels: each batch item is solved as a 32-channel chunk and a
    // 13-channel one, read and written in place in the [B, V, C] layout
    let (mesh, mt) = sphere(2);
    let ops = Operators::new(&mesh).unwrap();
    let n = mt.num_vertices() as i64;
    let a = dense_laplacian(&ops) + Tensor::eye(n, (Kind::Double, Device::Cpu)) * mt.solver().eps();
    let b = randn(&[2, n, 45]);
    let x = mt.solve(&b).unwrap();
    assert_eq!(x.size(), b.size());
    let res = rel_max_diff(&a.matmul(&x), &b);
    assert!(res < 1e-8, "relative residual {res}");
    // a NaN at item 1, vertex 7, channel 40 is reported as row 7 and
    // column 1 * 45 + 40 = 85 (one right-hand side per item and channel)
    let bad = b.copy();
    let _ = bad.get(1).get(7).get(40).fill_(f64::NAN);
    let err = mt.solve(&bad).unwrap_err().to_string();
    assert!(
        err.contains("non-finite") && err.contains("row 7, column 85"),
        "{err}"
    );
}

#[test]
fn solve_gradient_is_the_same_solve_and_matches_finite_differences() {
    let (_, mt) = sphere(1);
    let n = mt.num_vertices() as i64;
    let b = randn(&[2, n, 3]).set_requires_grad(true);
    let w = randn(&[2, n, 3]);
    let x = mt.solve(&b).unwrap();
    (&x * &w).sum(Kind::Double).backward();
    // d/db <w, A^-1 b> = A^-T w = A^-1 w
    let expected = mt.solve(&w).unwrap();
    assert!(rel_max_diff(&b.grad(), &expected) < 1e-12);

    // the constant mode is amplified by 1/eps (round-off included): give the
    // right-hand side zero sum and remove the mean of the solution inside the
    // test function, as PoissonNet does, so the nonlinearity sees O(1) values
    let f = |xs: &[Tensor]| {
        let b = &xs[0] - xs[0].mean_dim([-2i64].as_slice(), true, Kind::Double);
        let u = mt.remove_mass_mean(&mt.solve(&b).unwrap()).unwrap();
        (u.sin() * &w).sum(Kind::Double)
    };
    let err = check_directional(&[randn(&[2, n, 3])], &f, 4, 1e-6);
    assert!(err < 1e-6, "solve: relative FD error {err}");
}

#[test]
fn gradient_ops_pass_finite_difference_checks() {
    let (_, mt) = sphere(1);
    let n = mt.num_vertices() as i64;
    let f2 = 2 * mt.num_faces() as i64;
    let wg = randn(&[2, f2, 3]);
    let wv = randn(&[2, n, 3]);
    type Check<'a> = (&'a str, Tensor, Box<dyn Fn(&[Tensor]) -> Tensor + 'a>);
    let checks: Vec<Check> = vec![
        (
            "G",
            randn(&[2, n, 3]),
            Box::new(|x: &[Tensor]| (mt.gradient(&x[0]).unwrap().tanh() * &wg).sum(Kind::Double)),
        ),
        (
            "G^T",
            randn(&[2, f2, 3]),
            Box::new(|x: &[Tensor]| {
                (mt.gradient_adjoint(&x[0]).unwrap().tanh() * &wv).sum(Kind::Double)
            }),
        ),
        (
            "G^T A2",
            randn(&[2, f2, 3]),
            Box::new(|x: &[Tensor]| (mt.divergence(&x[0]).unwrap().tanh() * &wv).sum(Kind::Double)),
        ),
        (
            "G^T A2 i",
            randn(&[2, f2, 3]),
            Box::new(|x: &[Tensor]| {
                (mt.rotated_divergence(&x[0]).unwrap().tanh() * &wv).sum(Kind::Double)
            }),
        ),
        (
            "[G^T A2 | G^T A2 i]",
            randn(&[2, f2, 3]),
            Box::new(|x: &[Tensor]| {
                let wp = Tensor::cat(&[&wv, &wv.flip([0])], -1);
                (mt.paired_divergence(&x[0]).unwrap().tanh() * wp).sum(Kind::Double)
            }),
        ),
        (
            "face mean",
            randn(&[2, n, 3]),
            Box::new(|x: &[Tensor]| mt.face_mean(&x[0]).unwrap().tanh().sum(Kind::Double)),
        ),
        (
            "mass mean removal",
            randn(&[2, n, 3]),
            Box::new(|x: &[Tensor]| {
                (mt.remove_mass_mean(&x[0]).unwrap().tanh() * &wv).sum(Kind::Double)
            }),
        ),
    ];
    for (name, x, f) in &checks {
        let err = check_directional(std::slice::from_ref(x), f.as_ref(), 4, 1e-6);
        assert!(err < 1e-7, "{name}: relative FD error {err}");
    }
}

#[test]
fn second_derivatives_flow_through_linear_ops() {
    // f(x) = sum (G x)^2 A2 = x^T L x; its gradient 2 L x is computed through
    // the custom ops' backward, and differentiating <grad, w> again gives 2 L w
    let (_, mt) = sphere(1);
    let n = mt.num_vertices() as i64;
    let x = randn(&[n, 1]).set_requires_grad(true);
    let w = randn(&[n, 1]);
    let gx = mt.gradient(&x).unwrap();
    let a2 = mt.face_areas_interleaved().unsqueeze(-1);
    let f = (&gx * &gx * &a2).sum(Kind::Double);
    let g = Tensor::run_backward(&[&f], &[&x], true, true).remove(0);
    let lw = mt.divergence(&mt.gradient(&w).unwrap()).unwrap();
    assert!(rel_max_diff(&g, &(mt.divergence(&gx).unwrap() * 2.0)) < 1e-12);
    let h = Tensor::run_backward(&[&(&g * &w).sum(Kind::Double)], &[&x], false, false).remove(0);
    assert!(rel_max_diff(&h, &(lw * 2.0)) < 1e-12);
}

#[test]
fn several_solves_and_different_meshes_in_one_graph() {
    let (_, a) = sphere(1);
    let (_, b) = sphere(2);
    let (na, nb) = (a.num_vertices() as i64, b.num_vertices() as i64);
    let xa = randn(&[2, na, 2]).set_requires_grad(true);
    let xb = randn(&[3, nb, 2]).set_requires_grad(true);
    // two chained solves on mesh a (shared factor), one on mesh b
    let ua = a
        .solve(&a.remove_mass_mean(&a.solve(&xa).unwrap()).unwrap())
        .unwrap();
    let ub = b.solve(&xb).unwrap();
    let loss = a.remove_mass_mean(&ua).unwrap().square().sum(Kind::Double)
        + b.remove_mass_mean(&ub).unwrap().square().sum(Kind::Double);
    loss.backward();
    // independent reference: the same chain with the adjoints written out
    // x.grad = A^-1 P^T A^-1 P^T (2 q), q = P ua
    let pa = a.remove_mass_mean(&ua).unwrap().detach() * 2.0;
    let ga = a
        .solve(&mass_adjoint(&a, &a.solve(&mass_adjoint(&a, &pa)).unwrap()))
        .unwrap();
    assert!(rel_max_diff(&xa.grad(), &ga) < 1e-8, "mesh a");
    let pb = b.remove_mass_mean(&ub).unwrap().detach() * 2.0;
    let gb = b.solve(&mass_adjoint(&b, &pb)).unwrap();
    assert!(rel_max_diff(&xb.grad(), &gb) < 1e-8, "mesh b");
}

/// Adjoint of the mass-mean removal `P = I - 1 w^T` (w = m / sum m): `P^T y = y - w sum(y)`.
fn mass_adjoint(mt: &MeshTensors, y: &Tensor) -> Tensor {
    let m = mt.mass();
    let w = (&m / m.sum(Kind::Double)).unsqueeze(-1);
    y - &w * y.sum_dim_intlist([-2i64].as_slice(), true, Kind::Double)
}

#[test]
fn shape_errors_are_reported_not_panics() {
    let (_, mt) = sphere(1);
    let bad = randn(&[2, 7, 3]);
    let e = mt.gradient(&bad).unwrap_err().to_string();
    assert!(e.contains("V, C"), "{e}");
    let e = mt.solve(&bad).unwrap_err().to_string();
    assert!(e.contains("V=42"), "{e}");
    let n = mt.num_vertices() as i64;
    let ints = Tensor::zeros([1, n, 1], (Kind::Int64, Device::Cpu));
    let e = mt.solve(&ints).unwrap_err().to_string();
    assert!(e.contains("Int64"), "{e}");
}

#[test]
fn factor_is_shared_by_clones_and_backends() {
    let (_, mt) = sphere(1);
    let other = mt.with_backend(Backend::Torch);
    assert!(Arc::ptr_eq(mt.solver(), other.solver()));
    assert!(Arc::ptr_eq(mt.solver(), mt.clone().solver()));
}

#[test]
fn mean_removal_is_per_connected_component() {
    // two spheres of different sizes in one mesh
    let a = procedural::icosphere(1);
    let b = procedural::icosphere(2).transformed(0.5, [3.0, 0.0, 0.0]);
    let na = a.num_vertices() as u32;
    let mut pos = a.positions().to_vec();
    pos.extend_from_slice(b.positions());
    let mut faces = a.faces().to_vec();
    faces.extend(b.faces().iter().map(|t| t.map(|i| i + na)));
    let mesh = mfm_geometry::TriMesh::new(pos, faces).unwrap();
    let mt = MeshTensors::new(&mesh).unwrap();
    assert_eq!(mt.num_components(), 2);
    let n = mt.num_vertices() as i64;
    let u = randn(&[2, n, 3]) + 5.0;
    let p = mt.remove_mass_mean(&u).unwrap();
    let m = mt.mass().unsqueeze(-1);
    for (lo, len) in [(0, na as i64), (na as i64, n - na as i64)] {
        let part = (p.narrow(1, lo, len) * m.narrow(0, lo, len)).sum_dim_intlist(
            [1i64].as_slice(),
            false,
            Kind::Double,
        );
        assert!(
            part.abs().max().double_value(&[]) < 1e-12,
            "component mean not removed"
        );
    }
    // per-component means of the input come back from mass_weighted_mean
    let means = mt.mass_weighted_mean(&u).unwrap();
    assert_eq!(means.size(), vec![2, 2, 3]);
    // the solve of a divergence stays O(1) on both components
    let g = randn(&[2, 2 * mt.num_faces() as i64, 3]);
    let s = mt
        .remove_mass_mean(&mt.solve(&mt.divergence(&g).unwrap()).unwrap())
        .unwrap();
    assert!(s.abs().max().double_value(&[]) < 1e3);
}
