"""Shared fixtures of the mfm package's tests.

The tests run against an installed wheel (``cargo xtask test`` builds it,
installs it into a folder of its own and puts that folder on PYTHONPATH).
``MFM_CLI`` names the ``mfm`` command-line binary the bit-identity tests
compare with; ``MFM_REQUIRE_ORACLES=1`` (set by ``cargo xtask test``) turns
a missing oracle (libigl, torch, the CLI) into a failure instead of a skip.
"""

import os
import shutil
import subprocess

import numpy as np
import pytest

import mfm

REQUIRE = os.environ.get("MFM_REQUIRE_ORACLES") == "1"


def need(module):
    """Imports an oracle module, or skips (fails under MFM_REQUIRE_ORACLES)."""
    try:
        return __import__(module)
    except ImportError as e:
        if REQUIRE:
            raise
        pytest.skip(f"{module} is not installed: {e}")


@pytest.fixture(scope="session")
def cli():
    """Runs the ``mfm`` binary: ``cli("noise", ...)`` returns the completed process."""
    exe = os.environ.get("MFM_CLI") or shutil.which("mfm")
    if not exe or not os.path.exists(exe):
        if REQUIRE:
            pytest.fail("MFM_CLI does not name the mfm binary")
        pytest.skip("no mfm binary: set MFM_CLI")

    def run(*args, check=True):
        proc = subprocess.run([exe, *map(str, args)], capture_output=True, text=True)
        if check and proc.returncode != 0:
            raise AssertionError(f"mfm {' '.join(map(str, args))} failed:\n{proc.stderr}")
        return proc

    return run


def grid(n=12, seed=3):
    """An open, irregular mesh: a jittered n x n grid of a bumpy height field."""
    rng = np.random.default_rng(seed)
    u, v = np.meshgrid(np.linspace(0, 1, n), np.linspace(0, 1, n), indexing="ij")
    u = u + rng.uniform(-0.2, 0.2, u.shape) / n
    v = v + rng.uniform(-0.2, 0.2, v.shape) / n
    V = np.stack([u, v, 0.1 * np.sin(3 * u) * np.cos(2 * v)], axis=-1).reshape(-1, 3)
    idx = np.arange(n * n).reshape(n, n)
    a, b, c, d = idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]
    F = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)])
    return np.ascontiguousarray(V), np.ascontiguousarray(F.astype(np.int64))


def jittered_sphere(seed=1):
    """A closed mesh with unequal triangles: icosphere 3 with jittered vertices."""
    V, F = mfm.read_mesh("builtin:icosphere:3")
    rng = np.random.default_rng(seed)
    V = V * (1.0 + 0.05 * rng.standard_normal((V.shape[0], 1)))
    return np.ascontiguousarray(V * 2.5 + np.array([0.3, -1.0, 2.0])), F


@pytest.fixture(params=["grid", "sphere"])
def mesh(request):
    """An open and a closed test mesh, made by the tests."""
    return grid() if request.param == "grid" else jittered_sphere()
