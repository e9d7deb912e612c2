"""Cached solvers against scipy's spsolve, and the autograd wrapper."""

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla

import mfm
from conftest import grid, jittered_sphere, need


def rel(a, b):
    return np.abs(a - b).max() / np.abs(b).max()


@pytest.mark.parametrize("make", [grid, jittered_sphere])
def test_poisson_solver_solves_l_plus_eps_i_as_spsolve_does(make):
    V, F = make()
    n = V.shape[0]
    solver = mfm.PoissonSolver(V, F, eps=1e-4)
    assert solver.dim == n and solver.eps == 1e-4
    A = (mfm.cotan_laplacian(V, F) + 1e-4 * sp.identity(n)).tocsc()
    rng = np.random.default_rng(0)
    b = rng.standard_normal((n, 5))
    x = solver.solve(b)
    assert x.dtype == np.float64 and x.shape == (n, 5)
    assert rel(x, spla.spsolve(A, b)) < 1e-9
    x1 = solver.solve(np.ascontiguousarray(b[:, 2]))
    assert x1.shape == (n,) and np.array_equal(x1, x[:, 2])
    x32 = solver.solve(b.astype(np.float32))
    assert x32.dtype == np.float32 and rel(x32, x) < 1e-3


def test_from_laplacian_is_the_mesh_solver():
    V, F = grid()
    a = mfm.PoissonSolver(V, F, eps=1e-6)
    b = mfm.PoissonSolver.from_laplacian(mfm.cotan_laplacian(V, F).tocoo(), eps=1e-6)
    rhs = np.linspace(-1, 1, V.shape[0])
    assert np.array_equal(a.solve(rhs), b.solve(rhs))


def test_screened_solver_solves_l_plus_tau_m_as_spsolve_does():
    V, F = jittered_sphere()
    L, M = mfm.cotan_laplacian(V, F), mfm.mass_matrix(V, F)
    s = mfm.ScreenedSolver(L, M, 100.0)
    assert s.tau == 100.0 and s.dim == V.shape[0]
    b = np.random.default_rng(1).standard_normal((V.shape[0], 3))
    ref = spla.spsolve((L + 100.0 * M).tocsc(), b)
    assert rel(s.solve(b), ref) < 1e-9
    # the mass as the array of its diagonal gives the same factor
    s2 = mfm.ScreenedSolver(L.tocsr(), np.ascontiguousarray(M.diagonal()), 100.0)
    assert np.array_equal(s2.solve(b), s.solve(b))


def test_matern_noise_is_the_screened_solve_of_scaled_normals():
    """f = (L + tau M)^-1 M^1/2 n, the definition, through the public solver."""
    V, F = grid()
    L, M = mfm.cotan_laplacian(V, F), mfm.mass_matrix(V, F)
    x = mfm.MaternNoise(V, F, tau=100.0, frame="as-is").sample(2000, seed=8, dtype=np.float64)[:, :, 0]
    # the empirical covariance against A^-1 M A^-1, A = L + tau M
    A = (L + 100.0 * M).toarray()
    Ainv = np.linalg.inv(A)
    cov = Ainv @ M.toarray() @ Ainv
    emp = x.T @ x / x.shape[0]
    assert np.abs(emp - cov).max() < 0.15 * np.abs(cov).max()


def test_poisson_solve_is_differentiable_and_passes_gradcheck():
    torch = need("torch")
    from mfm.torch import poisson_solve

    V, F = grid(6)
    solver = mfm.PoissonSolver(V, F, eps=1e-2)
    rhs = torch.randn(V.shape[0], 3, dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(lambda b: poisson_solve(solver, b), (rhs,), eps=1e-6, atol=1e-6)
    vec = torch.randn(V.shape[0], dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(lambda b: poisson_solve(solver, b), (vec,), eps=1e-6, atol=1e-6)
    # float32 keeps its dtype, and the values are the numpy solve's
    x = poisson_solve(solver, rhs.detach().float())
    assert x.dtype == torch.float32
    assert np.allclose(x.numpy(), solver.solve(rhs.detach().numpy()), rtol=1e-3, atol=1e-4)
    screened = mfm.ScreenedSolver(mfm.cotan_laplacian(V, F), mfm.mass_matrix(V, F), 10.0)
    assert torch.autograd.gradcheck(lambda b: poisson_solve(screened, b), (rhs,), eps=1e-6, atol=1e-6)
    with pytest.raises(ValueError, match="rhs"):
        poisson_solve(solver, rhs.detach().to(torch.int64))
