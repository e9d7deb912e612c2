"""The README's Python example runs as written (on a mesh file of the test's
own, and without opening a window)."""

import pathlib
import re

import numpy as np

import mfm
from conftest import jittered_sphere, need

README = pathlib.Path(__file__).resolve().parents[3] / "README.md"


def test_the_readme_example_runs(tmp_path, monkeypatch):
    pv = need("pyvista")
    blocks = re.findall(r"```python\n(.*?)```", README.read_text(), re.S)
    example = next(b for b in blocks if "mfm.MaternNoise" in b)
    assert len(example.strip().splitlines()) <= 12
    V, F = jittered_sphere()
    mfm.write_mesh(tmp_path / "my_mesh.obj", V, F)
    monkeypatch.chdir(tmp_path)
    shown = {}
    monkeypatch.setattr(pv.PolyData, "plot", lambda self, **kw: shown.update(mesh=self, **kw))
    scope = {}
    exec(compile(example, str(README), "exec"), scope)
    x, mesh = scope["x"], shown["mesh"]
    assert x.shape == (16, V.shape[0], 1) and x.dtype == np.float32
    assert mesh.n_points == V.shape[0] and mesh.n_cells == F.shape[0]
    assert np.array_equal(shown["scalars"], x[0, :, 0])
