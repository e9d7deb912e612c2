"""Mesh files: round trips, scalars, and the CLI's messages as exceptions."""

import numpy as np
import pytest

import mfm
from conftest import grid


@pytest.mark.parametrize("ext", ["obj", "ply"])
def test_write_then_read_gives_the_same_bits(tmp_path, ext):
    V, F = grid()
    path = tmp_path / f"m.{ext}"
    mfm.write_mesh(path, V, F)
    V2, F2 = mfm.read_mesh(path)
    assert V2.dtype == np.float64 and F2.dtype == np.int64
    assert np.array_equal(V, V2) and np.array_equal(F, F2)
    mfm.write_mesh(str(path), V, F.astype(np.int32))  # str paths and int32 faces too
    assert np.array_equal(mfm.read_mesh(str(path))[1], F)


def test_ply_scalars_are_vertex_properties(tmp_path):
    V, F = grid()
    h = np.ascontiguousarray(V[:, 2])
    path = tmp_path / "s.ply"
    mfm.write_mesh(path, V, F, scalars={"height": h, "twice": 2 * h})
    data = path.read_bytes()
    header = data[: data.index(b"end_header\n")].decode()
    assert "property double height" in header and "property double twice" in header
    # binary little endian: x y z height twice per vertex, right after the header
    body = np.frombuffer(data[len(header) + len("end_header\n"):], dtype="<f8", count=5 * V.shape[0])
    rows = body.reshape(-1, 5)
    assert np.array_equal(rows[:, 3], h) and np.array_equal(rows[:, 4], 2 * h)
    assert np.array_equal(mfm.read_mesh(path)[0], V)
    with pytest.raises(ValueError, match="scalars.*only .ply"):
        mfm.write_mesh(tmp_path / "s.obj", V, F, scalars={"height": h})
    with pytest.raises(ValueError, match=r"scalars\['short'\]|scalars\[\"short\"\]"):
        mfm.write_mesh(path, V, F, scalars={"short": h[:-1].copy()})


def test_builtins_read_as_the_cli_names_them():
    V, F = mfm.read_mesh("builtin:icosphere:1")
    assert V.shape == (42, 3) and F.shape == (80, 3)


def test_bad_files_raise_the_cli_message(tmp_path, cli):
    bad = tmp_path / "bad.obj"
    bad.write_text("v 0 0 0\nv 1 0 0\nf 1 2\n")
    with pytest.raises(ValueError) as err:
        mfm.read_mesh(bad)
    proc = cli("info", bad, check=False)
    assert proc.returncode != 0
    assert str(err.value) in proc.stderr
    with pytest.raises(FileNotFoundError, match="missing.off"):
        mfm.read_mesh(tmp_path / "missing.off")
    (tmp_path / "m.xyz").write_text("1 2 3\n")
    with pytest.raises(ValueError, match="extension"):
        mfm.read_mesh(tmp_path / "m.xyz")


def test_a_failed_write_leaves_the_old_file(tmp_path):
    V, F = grid()
    path = tmp_path / "keep.ply"
    mfm.write_mesh(path, V, F)
    before = path.read_bytes()
    with pytest.raises(ValueError):
        mfm.write_mesh(path, V, F, scalars={"x": np.ascontiguousarray(V[:, 0])})  # reserved name
    assert path.read_bytes() == before
    with pytest.raises(ValueError, match="obj or .ply"):
        mfm.write_mesh(tmp_path / "m.stl", V, F)


def test_mesh_problems_are_warnings(tmp_path):
    V, F = grid()
    V = np.concatenate([V, [[5.0, 5.0, 5.0]]])  # a vertex no face uses
    with pytest.warns(UserWarning, match="(V, F)"):
        mfm.face_areas(V, F)
