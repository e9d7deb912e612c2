"""Noise: bit identity with `mfm noise`, determinism, and its covariance
against the closed-form spectrum (projected with scipy's own eigenpairs)."""

import json
import os
import subprocess
import sys

import numpy as np
import pytest
import scipy.sparse.linalg as spla

import mfm
from conftest import grid, jittered_sphere

KINDS = ["matern", "matern:30", "white", "naive", "explicit:16:50", "matern-normalized:1e-3", "matern:0",
         "matern-smooth:30:2"]


@pytest.mark.parametrize("kind", KINDS)
def test_float64_samples_equal_the_cli_bit_for_bit(tmp_path, cli, kind):
    V, F = jittered_sphere()
    mfm.write_mesh(tmp_path / "m.ply", V, F)
    out = tmp_path / "noise.npy"
    cli("noise", tmp_path / "m.ply", "--noise", kind, "--samples", 5, "--channels", 3, "--seed", 11, "--out", out)
    x = mfm.MaternNoise(V, F, kind=kind, frame="as-is").sample(5, channels=3, seed=11, dtype=np.float64)
    ref = np.load(out)
    assert x.dtype == np.float64 and x.shape == ref.shape == (5, V.shape[0], 3)
    assert np.array_equal(x, ref)


def test_long_form_keywords_equal_the_short_form():
    V, F = grid()
    a = mfm.MaternNoise(V, F, kind="explicit", k_noise=16, tau=50.0).sample(3, seed=2, dtype=np.float64)
    b = mfm.MaternNoise(V, F, kind="explicit:16:50").sample(3, seed=2, dtype=np.float64)
    assert np.array_equal(a, b)
    n = mfm.MaternNoise(V, F, kind="matern-normalized", c=1e-3)
    assert n.kind.startswith("matern-normalized") and n.tau == pytest.approx(1e-3 * n.gamma)


def test_first_continues_the_sequence_and_float32_is_its_own_stream():
    V, F = grid()
    noise = mfm.MaternNoise(V, F)
    whole = noise.sample(6, channels=2, seed=5, dtype=np.float64)
    assert np.array_equal(noise.sample(2, channels=2, seed=5, first=4, dtype=np.float64), whole[4:])
    x32 = noise.sample(6, channels=2, seed=5)
    assert x32.dtype == np.float32 and x32.shape == whole.shape
    assert np.array_equal(noise.sample(2, channels=2, seed=5, first=4), x32[4:])
    # the same law: the two streams have matching scales, not matching bits
    assert not np.array_equal(x32, whole.astype(np.float32))
    assert 0.8 < x32.std() / whole.std() < 1.25


def test_the_canonical_frame_is_the_as_is_noise_of_the_canonical_mesh():
    V, F = jittered_sphere()
    noise = mfm.MaternNoise(V, F, tau=100.0)
    scale, shift = noise.frame
    lo, hi = V.min(0), V.max(0)
    assert scale == pytest.approx(1.0 / (hi - lo).max())
    Vc = np.ascontiguousarray(V * scale + np.array(shift))
    ref = mfm.MaternNoise(Vc, F, tau=100.0, frame="as-is").sample(3, seed=4, dtype=np.float64)
    assert np.array_equal(noise.sample(3, seed=4, dtype=np.float64), ref)
    # and tau means "a tenth of the shape" at any scale: the noise does not change
    big = mfm.MaternNoise(np.ascontiguousarray(V * 1000.0), F, tau=100.0)
    assert np.allclose(big.sample(3, seed=4, dtype=np.float64), ref, rtol=1e-9, atol=1e-12)


def test_sigma_scales_every_sample():
    V, F = grid()
    a = mfm.MaternNoise(V, F, sigma=2.5).sample(2, seed=9, dtype=np.float64)
    b = mfm.MaternNoise(V, F).sample(2, seed=9, dtype=np.float64)
    assert np.array_equal(a, b * 2.5)


def test_a_seed_gives_the_same_bits_on_any_thread_count(tmp_path):
    code = (
        "import sys, numpy as np, mfm;"
        "V, F = mfm.read_mesh('builtin:icosphere:4');"
        "x = mfm.MaternNoise(V, F).sample(40, channels=3, seed=3);"
        "sys.stdout.buffer.write(x.tobytes())"
    )
    outs = []
    for threads in ("1", "2", "3"):
        env = dict(os.environ, RAYON_NUM_THREADS=threads)
        outs.append(subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, check=True).stdout)
    assert len(outs[0]) == 40 * 2562 * 3 * 4
    assert outs[0] == outs[1] == outs[2]


@pytest.mark.parametrize("tau", [30.0, 300.0])
def test_matern_covariance_matches_the_closed_form_spectrum(tau):
    """Var(phi_i^T M f) = 1 / (lambda_i + tau)^2, with scipy's eigenpairs."""
    V, F = jittered_sphere()
    L, M = mfm.cotan_laplacian(V, F), mfm.mass_matrix(V, F)
    k = 24
    lam, phi = spla.eigsh(L, k=k, M=M, sigma=-1e-3, which="LM")
    n = 4000
    x = mfm.MaternNoise(V, F, tau=tau, frame="as-is").sample(n, seed=21, dtype=np.float64)[:, :, 0]
    c = x @ (M @ phi)  # [n, k]
    var = (c**2).mean(axis=0)
    theory = 1.0 / (lam + tau) ** 2
    # chi-square sampling error of a variance from n draws: ~sqrt(2 / n) = 2.2%
    assert np.abs(var / theory - 1).max() < 6 * np.sqrt(2 / n)
    corr = np.corrcoef(c.T)
    assert np.abs(corr - np.eye(k)).max() < 6 / np.sqrt(n)


def test_smooth_matern_covariance_matches_the_closed_form_spectrum():
    """Var(phi_i^T M f) = tau^2 / (lambda_i + tau)^4 for matern-smooth:tau:2,
    with scipy's eigenpairs; and one such sample solves (L + tau M) f_2 =
    tau M f_1 for the Matérn sample f_1 of the same normals."""
    V, F = jittered_sphere()
    L, M = mfm.cotan_laplacian(V, F), mfm.mass_matrix(V, F)
    tau, k, n = 30.0, 24, 4000
    lam, phi = spla.eigsh(L, k=k, M=M, sigma=-1e-3, which="LM")
    smooth = mfm.MaternNoise(V, F, kind=f"matern-smooth:{tau:g}:2", frame="as-is")
    x = smooth.sample(n, seed=21, dtype=np.float64)[:, :, 0]
    c = x @ (M @ phi)
    var = (c**2).mean(axis=0)
    theory = tau**2 / (lam + tau) ** 4
    assert np.abs(var / theory - 1).max() < 6 * np.sqrt(2 / n)
    f1 = mfm.MaternNoise(V, F, kind=f"matern:{tau:g}", frame="as-is").sample(3, seed=5, dtype=np.float64)[:, :, 0]
    f2 = smooth.sample(3, seed=5, dtype=np.float64)[:, :, 0]
    for a, b in zip(f1, f2):
        r = (L + tau * M) @ b - tau * (M @ a)
        assert np.linalg.norm(r) < 1e-10 * np.linalg.norm(tau * (M @ a))


def test_spectrum_reports_what_mfm_spectrum_reports(tmp_path, cli):
    cli("spectrum", "builtin:blob:1", "--noise", "matern:50", "--samples", 300, "--k", 16, "--seed", 2,
        "--out", tmp_path / "s.json")
    ref = json.loads((tmp_path / "s.json").read_text())["meshes"][0]
    V, F = mfm.read_mesh("builtin:blob:1")
    s = mfm.spectrum(V, F, kind="matern:50", samples=300, k=16, seed=2, frame="as-is")
    r = ref["report"]
    assert s["vertices"] == ref["vertices"] and s["gamma"] == ref["gamma"]
    for key in ("eigenvalues", "mean", "variance", "theory"):
        assert np.array_equal(s[key], np.array(r[key])), key
    assert s["max_relative_error"] == r["max_relative_error"]
    assert s["mean_energy"] == r["mean_energy"]
    assert s["max_abs_correlation"] == r["independence"]["max_abs_correlation"]
    assert np.nanmax(np.abs(s["ratio"] - 1)) == pytest.approx(s["max_relative_error"])


def test_the_noise_method_spectrum_is_the_module_function():
    V, F = grid()
    a = mfm.MaternNoise(V, F, tau=80.0).spectrum(samples=200, k=10, seed=1)
    b = mfm.spectrum(V, F, tau=80.0, samples=200, k=10, seed=1)
    assert np.array_equal(a["variance"], b["variance"])


def test_sampling_releases_the_gil():
    """Python threads keep running while a batch is sampled."""
    import threading
    import time

    V, F = mfm.read_mesh("builtin:icosphere:6")
    noise = mfm.MaternNoise(V, F)
    # how fast this loop runs alone
    ticks, t0 = 0, time.perf_counter()
    while time.perf_counter() - t0 < 0.05:
        ticks += 1
    rate = ticks / (time.perf_counter() - t0)
    done = threading.Event()
    worker = threading.Thread(target=lambda: (noise.sample(64, channels=3), done.set()))
    ticks, t0 = 0, time.perf_counter()
    worker.start()
    while not done.is_set():
        ticks += 1
        time.perf_counter()
    elapsed = time.perf_counter() - t0
    worker.join()
    # holding the GIL for the whole call would leave the loop one switch
    # interval (5 ms) of the call's duration; released, it runs throughout
    # (sharing the cores with the solver's threads)
    assert elapsed > 0.1 and ticks > 0.05 * rate * elapsed, (ticks, rate, elapsed)
