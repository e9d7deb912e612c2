"""Type stubs of mfm's extension module (re-exported by ``mfm``).

The runtime docstrings (``help(mfm.MaternNoise)``) carry a runnable example each.
"""

from os import PathLike
from typing import Any, Dict, Optional, Tuple, Union

import numpy as np
import numpy.typing as npt
import scipy.sparse

__version__: str

_Path = Union[str, "PathLike[str]"]
_F64 = npt.NDArray[np.float64]
_I64 = npt.NDArray[np.int64]
_Faces = npt.NDArray[np.integer]
_Real = Union[npt.NDArray[np.float32], npt.NDArray[np.float64]]

def read_mesh(path: _Path) -> Tuple[_F64, _I64]:
    """Reads ``.obj``/``.off``/``.ply``/``.gltf``/``.glb`` or ``"builtin:NAME"``.

    Returns ``(V float64 [n, 3], F int64 [m, 3])`` in file order. Raises
    ``FileNotFoundError``/``OSError`` for unreadable files and ``ValueError``
    (the command line's message) for invalid meshes; other problems warn.
    """

def write_mesh(
    path: _Path, V: _F64, F: _Faces, scalars: Optional[Dict[str, _F64]] = None
) -> None:
    """Writes ``.obj`` or binary ``.ply`` atomically; ``scalars`` (``.ply``
    only) adds per-vertex ``float64`` properties.
    """

def cotan_laplacian(V: _F64, F: _Faces) -> scipy.sparse.csc_matrix:
    """PSD cotangent Laplacian ``[n, n]`` (``-igl.cotmatrix(V, F)``).
    """

def mass_matrix(V: _F64, F: _Faces) -> scipy.sparse.csc_matrix:
    """Lumped barycentric mass, diagonal ``[n, n]``.
    """

def face_gradients(V: _F64, F: _Faces) -> scipy.sparse.csc_matrix:
    """Intrinsic gradient ``[2m, n]``: rows ``2f, 2f+1`` in an orthonormal
    frame of face ``f`` whose first axis runs along ``F[f,0] -> F[f,1]``.
    """

def face_areas(V: _F64, F: _Faces) -> _F64:
    """Face areas ``[m]`` (``igl.doublearea(V, F) / 2``).
    """

def eigs(V: _F64, F: _Faces, k: int) -> Tuple[_F64, _F64]:
    """The ``k`` smallest pairs of ``L phi = lambda M phi``: eigenvalues
    ``[k]`` ascending, eigenvectors ``[n, k]`` with ``phi.T @ M @ phi = I``.
    """

def spectrum(
    V: _F64,
    F: _Faces,
    kind: str = "matern",
    tau: Optional[float] = None,
    c: Optional[float] = None,
    k_noise: Optional[int] = None,
    samples: int = 2000,
    k: int = 64,
    seed: int = 0,
    frame: str = "canonical",
) -> Dict[str, Any]:
    """Per-frequency statistics of noise, as ``mfm spectrum`` reports them:
    ``eigenvalues``, ``mean``, ``variance``, ``theory``, ``ratio`` (arrays
    ``[k]``), ``max_relative_error``, ``max_abs_correlation``,
    ``correlation_pair``, ``correlation_reference``, ``mean_energy``,
    ``captured_energy``, ``theory_energy``, ``gamma``, ``vertices``,
    ``num_signals``.
    """

class MaternNoise:
    """Noise on a mesh, factored once, sampled many times.

    ``kind``: ``"matern"`` (``tau``, default 100), ``"matern-normalized"``
    (``c``, default 1e-4), ``"matern-smooth"`` (``tau``; order 2, or the
    short form ``"matern-smooth:100:3"``), ``"white"``, ``"naive"``, ``"explicit"``
    (``k_noise``, default 64, and ``tau``), or the command line's short form
    (``"matern:50"``, ``"explicit:32:100"``). ``frame="canonical"`` moves the
    mesh into the canonical frame first (as ``mfm train``); ``"as-is"`` uses
    it as given (as ``mfm noise``). Every sample is multiplied by ``sigma``.
    """

    def __init__(
        self,
        V: _F64,
        F: _Faces,
        tau: Optional[float] = None,
        sigma: float = 1.0,
        kind: str = "matern",
        frame: str = "canonical",
        c: Optional[float] = None,
        k_noise: Optional[int] = None,
    ) -> None: ...
    def sample(
        self,
        n: int,
        channels: int = 1,
        seed: int = 0,
        first: int = 0,
        dtype: Any = None,
    ) -> _Real:
        """Samples ``first .. first + n`` of ``seed`` as ``[n, V, channels]``
        (``float32`` by default; ``float64`` equals ``mfm noise`` bit for bit)."""
    def spectrum(self, samples: int = 2000, k: int = 64, seed: int = 0) -> Dict[str, Any]:
        """``mfm.spectrum`` of this noise."""
    @property
    def vertices(self) -> int: ...
    @property
    def kind(self) -> str: ...
    @property
    def tau(self) -> Optional[float]: ...
    @property
    def gamma(self) -> float: ...
    @property
    def sigma(self) -> float: ...
    @property
    def frame(self) -> Tuple[float, Tuple[float, float, float]]: ...

class PoissonSolver:
    """Cached factor of ``L + eps I`` (``eps`` grown x10 until it factors).
    """

    def __init__(self, V: _F64, F: _Faces, eps: float = 1e-6) -> None: ...
    @staticmethod
    def from_laplacian(L: Any, eps: float = 1e-6) -> "PoissonSolver":
        """The solver of ``L + eps I`` for a symmetric PSD scipy.sparse ``L``."""
    def solve(self, rhs: _Real) -> _Real:
        """``(L + eps I)^-1 rhs`` for ``rhs`` ``[n]`` or ``[n, K]``, same dtype."""
    @property
    def eps(self) -> float: ...
    @property
    def dim(self) -> int: ...

class ScreenedSolver:
    """Cached factor of ``L + tau M`` (``M`` a 1-D array or diagonal matrix).
    """

    def __init__(self, L: Any, M: Any, tau: float) -> None: ...
    def solve(self, rhs: _Real) -> _Real:
        """``(L + tau M)^-1 rhs`` for ``rhs`` ``[n]`` or ``[n, K]``, same dtype."""
    @property
    def tau(self) -> float: ...
    @property
    def dim(self) -> int: ...
