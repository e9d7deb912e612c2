"""Every bad input raises ValueError naming the argument: never a crash,
never a Rust panic message."""

import numpy as np
import pytest
import scipy.sparse as sp

import mfm
from conftest import grid

V0, F0 = grid(5)
N = V0.shape[0]


def nan_vertices():
    V = V0.copy()
    V[3, 1] = np.nan
    return V


def out_of_range():
    F = F0.copy()
    F[2, 1] = N
    return F


def negative():
    F = F0.copy()
    F[0, 0] = -1
    return F


def repeated():
    F = F0.copy()
    F[1] = [4, 4, 5]
    return F


def duplicate_faces():
    return np.ascontiguousarray(np.concatenate([F0, F0[:2]]))


BAD_MESHES = [
    ("float32 V", V0.astype(np.float32), F0, "V", "float64"),
    ("int V", V0.astype(np.int64), F0, "V", "float64"),
    ("V as a list", V0.tolist(), F0, "V", "numpy array"),
    ("2-column V", np.ascontiguousarray(V0[:, :2]), F0, "V", "shape"),
    ("non-contiguous V", V0[::-1], F0, "V", "contiguous"),
    ("Fortran-order V", np.asfortranarray(V0), F0, "V", "contiguous"),
    ("empty V", np.zeros((0, 3)), F0, "V", "no vertices"),
    ("NaN vertex", nan_vertices(), F0, "V", "non-finite"),
    ("float F", V0, F0.astype(np.float64), "F", "integer"),
    ("4-column F", V0, np.zeros((3, 4), dtype=np.int64), "F", "shape"),
    ("non-contiguous F", V0, F0[::2], "F", "contiguous"),
    ("empty F", V0, np.zeros((0, 3), dtype=np.int64), "F", "no faces"),
    ("out-of-range face", V0, out_of_range(), "F", "refers to vertex"),
    ("negative index", V0, negative(), "F", "refers to vertex -1"),
    ("repeated vertex", V0, repeated(), "F", "repeats"),
    ("duplicate faces", V0, duplicate_faces(), "F", "twice"),
]

MESH_FUNCTIONS = [
    mfm.cotan_laplacian,
    mfm.mass_matrix,
    mfm.face_gradients,
    mfm.face_areas,
    lambda V, F: mfm.eigs(V, F, 3),
    mfm.MaternNoise,
    mfm.PoissonSolver,
    lambda V, F: mfm.spectrum(V, F, samples=10, k=3),
    lambda V, F: mfm.write_mesh("/tmp/never-written-by-mfm-tests.obj", V, F),
]


@pytest.mark.parametrize("what,V,F,argument,words", BAD_MESHES, ids=[b[0] for b in BAD_MESHES])
@pytest.mark.parametrize("fn", MESH_FUNCTIONS)
def test_bad_meshes_raise_value_errors_naming_the_argument(fn, what, V, F, argument, words):
    with pytest.raises(ValueError) as err:
        fn(V, F)
    message = str(err.value)
    assert message.startswith(f"{argument}:"), message
    assert words in message, message
    assert "panicked" not in message


def degenerate():
    V = V0.copy()
    a, b, c = F0[0]
    V[c] = (V[a] + V[b]) / 2  # a zero-area face
    return V


@pytest.mark.parametrize("fn", [mfm.cotan_laplacian, mfm.face_gradients, mfm.PoissonSolver,
                                lambda V, F: mfm.eigs(V, F, 3)])
def test_degenerate_faces_are_refused_where_the_operators_are_undefined(fn):
    with pytest.warns(UserWarning):
        with pytest.raises(ValueError, match="^F: .*degenerate"):
            fn(degenerate(), F0)


BAD_CALLS = [
    ("k > V", lambda: mfm.eigs(V0, F0, N + 1), "k"),
    ("k = 0", lambda: mfm.eigs(V0, F0, 0), "k"),
    ("unknown kind", lambda: mfm.MaternNoise(V0, F0, kind="pink"), "kind"),
    ("tau for white", lambda: mfm.MaternNoise(V0, F0, kind="white", tau=3.0), "tau"),
    ("negative tau", lambda: mfm.MaternNoise(V0, F0, tau=-1.0), "tau"),
    ("tau given twice", lambda: mfm.MaternNoise(V0, F0, kind="matern:5", tau=3.0), "tau"),
    ("k_noise for matern", lambda: mfm.MaternNoise(V0, F0, k_noise=4), "k_noise"),
    ("k_noise > V", lambda: mfm.MaternNoise(V0, F0, kind="explicit", k_noise=N + 1), "k_noise"),
    ("zero sigma", lambda: mfm.MaternNoise(V0, F0, sigma=0.0), "sigma"),
    ("NaN sigma", lambda: mfm.MaternNoise(V0, F0, sigma=float("nan")), "sigma"),
    ("bad frame", lambda: mfm.MaternNoise(V0, F0, frame="world"), "frame"),
    ("n = 0", lambda: mfm.MaternNoise(V0, F0).sample(0), "n"),
    ("channels = 0", lambda: mfm.MaternNoise(V0, F0).sample(1, channels=0), "channels"),
    ("negative seed", lambda: mfm.MaternNoise(V0, F0).sample(1, seed=-1), "seed"),
    ("seed >= 2^64", lambda: mfm.MaternNoise(V0, F0).sample(1, seed=2**64), "seed"),
    ("negative first", lambda: mfm.MaternNoise(V0, F0).sample(1, first=-3), "first"),
    ("int dtype", lambda: mfm.MaternNoise(V0, F0).sample(1, dtype=np.int32), "dtype"),
    ("nonsense dtype", lambda: mfm.MaternNoise(V0, F0).sample(1, dtype="banana"), "dtype"),
    ("spectrum k > V", lambda: mfm.spectrum(V0, F0, k=N + 1, samples=10), "k"),
    ("spectrum 1 sample", lambda: mfm.spectrum(V0, F0, k=3, samples=1), "samples"),
    ("rhs wrong length", lambda: mfm.PoissonSolver(V0, F0).solve(np.ones(N + 1)), "rhs"),
    ("rhs 3-D", lambda: mfm.PoissonSolver(V0, F0).solve(np.ones((N, 2, 2))), "rhs"),
    ("rhs int", lambda: mfm.PoissonSolver(V0, F0).solve(np.ones(N, dtype=np.int64)), "rhs"),
    ("rhs NaN", lambda: mfm.PoissonSolver(V0, F0).solve(np.full(N, np.nan)), "rhs"),
    ("rhs non-contiguous", lambda: mfm.PoissonSolver(V0, F0).solve(np.ones((2, N)).T), "rhs"),
    ("rhs empty K", lambda: mfm.PoissonSolver(V0, F0).solve(np.ones((N, 0))), "rhs"),
    ("rhs list", lambda: mfm.PoissonSolver(V0, F0).solve([1.0] * N), "rhs"),
    ("negative eps", lambda: mfm.PoissonSolver(V0, F0, eps=-1.0), "eps"),
    ("dense L", lambda: mfm.PoissonSolver.from_laplacian(np.eye(N)), "L"),
    ("asymmetric L", lambda: mfm.PoissonSolver.from_laplacian(sp.csc_matrix(np.triu(np.ones((N, N))) + N * np.eye(N))), "L"),
    ("non-square L", lambda: mfm.ScreenedSolver(sp.csc_matrix((N, N + 1)), np.ones(N), 1.0), "L"),
    ("M wrong length", lambda: mfm.ScreenedSolver(mfm.cotan_laplacian(V0, F0), np.ones(N - 1), 1.0), "M"),
    ("M not diagonal", lambda: mfm.ScreenedSolver(mfm.cotan_laplacian(V0, F0), mfm.cotan_laplacian(V0, F0), 1.0), "M"),
    ("M negative", lambda: mfm.ScreenedSolver(mfm.cotan_laplacian(V0, F0), -np.ones(N), 1.0), "M"),
    ("zero tau", lambda: mfm.ScreenedSolver(mfm.cotan_laplacian(V0, F0), np.ones(N), 0.0), "tau"),
    ("scalars not a dict value array", lambda: mfm.write_mesh("/tmp/x.ply", V0, F0, scalars={"h": [0.0] * N}), "scalars"),
]


@pytest.mark.parametrize("what,call,argument", BAD_CALLS, ids=[b[0] for b in BAD_CALLS])
def test_bad_arguments_raise_value_errors_naming_them(what, call, argument):
    with pytest.raises(ValueError) as err:
        call()
    message = str(err.value)
    assert message.startswith(argument), message
    assert "panicked" not in message


def test_a_result_larger_than_memory_is_refused_before_allocating():
    noise = mfm.MaternNoise(V0, F0)
    with pytest.raises(MemoryError, match="samples"):
        noise.sample(10**15)
