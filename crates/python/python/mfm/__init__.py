"""mfm: triangulation-agnostic noise on triangle meshes, from Python.

Mesh files, the cotangent operators, eigenpairs, Matérn noise and cached
Poisson solvers of the ``mfm`` command line, numpy in and out (scipy.sparse
for matrices). No libtorch and no Rust toolchain are needed; ``mfm.torch``
adds a differentiable solve for PyTorch users.

Conventions (the command line's):

- ``V`` is a C-contiguous ``float64`` array ``[n, 3]``; ``F`` a C-contiguous
  integer array ``[m, 3]`` (int32/int64/uint32/uint64) of 0-based indices.
  Anything else raises ``ValueError`` naming the argument.
- ``L`` is the positive semi-definite cotangent Laplacian (``-igl.cotmatrix``),
  ``M`` the lumped barycentric mass, ``G`` the ``2m x n`` intrinsic gradient;
  eigenpairs solve ``L phi = lambda M phi`` with ``phi.T @ M @ phi = I``.
- Work runs on Rust threads with the GIL released; ``RAYON_NUM_THREADS``
  sets how many. A seed gives the same bits on any number of threads.

Example::

    >>> import numpy as np, mfm
    >>> V, F = mfm.read_mesh("builtin:icosphere:3")
    >>> noise = mfm.MaternNoise(V, F, tau=100.0)
    >>> x = noise.sample(16, seed=7)          # [16, n, 1] float32
    >>> x.shape == (16, V.shape[0], 1)
    True
"""

from ._mfm import (
    MaternNoise,
    PoissonSolver,
    ScreenedSolver,
    __version__,
    cotan_laplacian,
    eigs,
    face_areas,
    face_gradients,
    mass_matrix,
    read_mesh,
    spectrum,
    write_mesh,
)

__all__ = [
    "MaternNoise",
    "PoissonSolver",
    "ScreenedSolver",
    "__version__",
    "cotan_laplacian",
    "eigs",
    "face_areas",
    "face_gradients",
    "mass_matrix",
    "read_mesh",
    "spectrum",
    "write_mesh",
]
