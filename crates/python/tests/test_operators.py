"""Operators and eigenpairs against libigl and scipy (independent oracles)."""

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

import mfm
from conftest import need


def rel(a, b):
    a, b = np.asarray(a), np.asarray(b)
    return np.abs(a - b).max() / max(np.abs(b).max(), 1e-300)


def test_cotan_laplacian_is_minus_libigl_cotmatrix(mesh):
    igl = need("igl")
    V, F = mesh
    L = mfm.cotan_laplacian(V, F)
    assert isinstance(L, sp.csc_matrix) and L.shape == (V.shape[0],) * 2
    assert abs(L + igl.cotmatrix(V, F)).max() < 1e-9 * abs(L).max()
    # PSD convention: symmetric, rows sum to zero, non-negative diagonal
    assert abs(L - L.T).max() == 0.0
    assert abs(L.sum(axis=1)).max() < 1e-12 * abs(L).max()
    assert L.diagonal().min() > 0


def test_mass_and_areas_match_libigl(mesh):
    igl = need("igl")
    V, F = mesh
    M = mfm.mass_matrix(V, F)
    Mi = igl.massmatrix(V, F, igl.MASSMATRIX_TYPE_BARYCENTRIC)
    assert abs(M - Mi).max() < 1e-9 * M.diagonal().max()
    assert M.nnz == V.shape[0]
    A = mfm.face_areas(V, F)
    assert rel(A, igl.doublearea(V, F) / 2) < 1e-9


def test_face_gradients_factor_the_laplacian_and_match_libigl_norms(mesh):
    igl = need("igl")
    V, F = mesh
    G = mfm.face_gradients(V, F)
    m, n = F.shape[0], V.shape[0]
    assert G.shape == (2 * m, n)
    A2 = np.repeat(mfm.face_areas(V, F), 2)
    L = mfm.cotan_laplacian(V, F)
    assert abs(G.T @ sp.diags(A2) @ G - L).max() < 1e-9 * abs(L).max()
    # the gradient of a function: same length per face as libigl's extrinsic one
    u = np.sin(3 * V[:, 0]) + V[:, 1] * V[:, 2]
    g = (G @ u).reshape(m, 2)
    gi = (igl.grad(V, F) @ u).reshape(3, m).T
    assert rel(np.linalg.norm(g, axis=1), np.linalg.norm(gi, axis=1)) < 1e-9


def test_eigs_are_m_orthonormal_generalized_eigenpairs_as_scipy_finds(mesh):
    V, F = mesh
    k = 12
    lam, phi = mfm.eigs(V, F, k)
    assert lam.shape == (k,) and phi.shape == (V.shape[0], k)
    L, M = mfm.cotan_laplacian(V, F), mfm.mass_matrix(V, F)
    assert np.all(np.diff(lam) >= -1e-12)
    assert np.abs(phi.T @ (M @ phi) - np.eye(k)).max() < 1e-9
    assert np.abs(L @ phi - (M @ phi) * lam).max() < 1e-7 * max(lam.max(), 1.0)
    ref = np.sort(spla.eigsh(L, k=k, M=M, sigma=-1e-3, which="LM")[0])
    assert np.abs(lam - ref).max() < 1e-8 * ref.max()


def test_eigs_agree_with_the_cli(tmp_path, cli):
    V, F = mfm.read_mesh("builtin:blob:1")
    lam, phi = mfm.eigs(V, F, 8)
    cli("eigs", "builtin:blob:1", "--k", 8, "--out", tmp_path / "e")
    assert np.array_equal(lam, np.load(tmp_path / "e" / "eigenvalues.npy"))
    assert np.array_equal(phi, np.load(tmp_path / "e" / "eigenvectors.npy"))


def test_operators_agree_with_the_cli_bit_for_bit(tmp_path, cli):
    V, F = mfm.read_mesh("builtin:blob:1")
    cli("operators", "builtin:blob:1", "--out", tmp_path / "ops")
    mass = np.load(tmp_path / "ops" / "mass.npy")
    assert np.array_equal(mfm.mass_matrix(V, F).diagonal(), mass)
    assert np.array_equal(mfm.face_areas(V, F), np.load(tmp_path / "ops" / "face_areas.npy"))
