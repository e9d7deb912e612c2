"""Time "factor + a batch of Matérn samples" end to end from Python: mfm's
wheel against the mfm command line and the Python sparse Cholesky stack
(CHOLMOD through scikit-sparse, cholespy), in one process, round by round.

Usage: bench_python.py [--subdiv 4] [--runs 3] [--batch 64] [--tau 100]
                       --work DIR --cli MFM MESH

The mesh is read with igl.read_triangle_mesh, refined --subdiv times with
igl.upsample and written to DIR as OFF (17 significant digits), so that every
pipeline works on the same vertex and face arrays. Each round times, in this
order (wall time, milliseconds):

  mfm_py_f64   mfm.MaternNoise(V, F, tau, frame="as-is") (operators and the
               factor of L + tau M) + .sample(batch, dtype=float64): the
               [batch, V, 1] array a user receives
  mfm_py_f32   the same with dtype=float32
  mfm_py_file  mfm.read_mesh(OFF) + mfm_py_f64: what `mfm noise` does, minus
               writing the .npy file
  cli          `mfm noise OFF --tau TAU --samples BATCH --out DIR/cli.npy`:
               the whole command (read, setup, sample, write the f64 .npy)
  cholmod      libigl operators (L = -cotmatrix, barycentric M), A = L + tau M,
               sksparse.cholmod.cholesky(A), a V x batch block of numpy
               normals scaled by M^1/2, one solve
  cholespy     the same with cholespy.CholeskySolverD

after one warm-up round. It prints JSON with the median and the fastest of
the timed rounds, the peak resident memory of this process after the mfm
rounds (to show that sample() makes no second copy of its result), and the
largest difference between mfm's float64 samples and the CLI's file (0:
the same bits).
"""

import json
import os
import resource
import subprocess
import sys
import time
from importlib import metadata

import igl
import numpy as np
import scipy.sparse as sp
from cholespy import CholeskySolverD, MatrixType
from sksparse.cholmod import cholesky

import mfm
from bench_noise import loaded_libraries, write_off  # sibling module; scripts run by path


def parse_args(argv):
    opts = {"subdiv": 4, "runs": 3, "batch": 64, "tau": 100.0, "work": None, "cli": None}
    paths = []
    it = iter(argv[1:])
    for a in it:
        if a in ("--subdiv", "--runs", "--batch"):
            opts[a[2:]] = max(0 if a == "--subdiv" else 1, int(next(it)))
        elif a == "--tau":
            opts["tau"] = float(next(it))
        elif a in ("--work", "--cli"):
            opts[a[2:]] = next(it)
        else:
            paths.append(a)
    if len(paths) != 1 or opts["work"] is None or opts["cli"] is None:
        sys.exit("usage: bench_python.py [--subdiv 4] [--runs 3] [--batch 64] [--tau 100] --work DIR --cli MFM MESH")
    return opts, paths[0]


def peak_rss_mb():
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def main(argv):
    opts, path = parse_args(argv)
    os.makedirs(opts["work"], exist_ok=True)
    v, f = igl.read_triangle_mesh(path)
    if opts["subdiv"] > 0:
        v, f = igl.upsample(v, f, opts["subdiv"])
    v = np.ascontiguousarray(v, dtype=np.float64)
    f = np.ascontiguousarray(f, dtype=np.int64)
    off = os.path.join(opts["work"], "mesh.off")
    write_off(off, v, f)
    # the pipelines read the mesh as the others do: from the same file
    v, f = mfm.read_mesh(off)
    batch, tau = opts["batch"], opts["tau"]
    n = v.shape[0]
    cli_npy = os.path.join(opts["work"], "cli.npy")
    print(f"bench_python.py: {n} vertices, {f.shape[0]} faces, batch {batch}", file=sys.stderr)

    def mfm_f64():
        return mfm.MaternNoise(v, f, tau=tau, frame="as-is").sample(batch, dtype=np.float64)

    def mfm_f32():
        return mfm.MaternNoise(v, f, tau=tau, frame="as-is").sample(batch, dtype=np.float32)

    def mfm_file():
        vv, ff = mfm.read_mesh(off)
        return mfm.MaternNoise(vv, ff, tau=tau, frame="as-is").sample(batch, dtype=np.float64)

    def cli():
        subprocess.run(
            [opts["cli"], "noise", off, "--tau", str(tau), "--samples", str(batch), "--out", cli_npy],
            check=True,
            stdout=subprocess.DEVNULL,
        )

    bary = igl.MASSMATRIX_TYPE_BARYCENTRIC
    rng = np.random.default_rng(0)

    def peer(factorize, solve):
        def run():
            L = -igl.cotmatrix(v, f)
            M = igl.massmatrix(v, f, bary)
            A = sp.csc_matrix(L + tau * M)
            A.sort_indices()
            factor = factorize(A)
            b = rng.standard_normal((n, batch)) * np.sqrt(M.diagonal())[:, None]
            return solve(factor, b)

        return run

    def cholespy_solve(s, b):
        b = np.ascontiguousarray(b)
        x = np.empty_like(b)
        s.solve(b, x)
        return x

    pipelines = {
        "mfm_py_f64": mfm_f64,
        "mfm_py_f32": mfm_f32,
        "mfm_py_file": mfm_file,
        "cli": cli,
        "cholmod": peer(cholesky, lambda fac, b: fac(np.asfortranarray(b))),
        "cholespy": peer(
            lambda A: CholeskySolverD(A.shape[0], A.indptr, A.indices, A.data, MatrixType.CSC),
            cholespy_solve,
        ),
    }
    times = {k: [] for k in pipelines}
    rss_after_mfm = None
    for r in range(opts["runs"] + 1):
        for name, fn in pipelines.items():
            t0 = time.perf_counter()
            out = fn()
            ms = (time.perf_counter() - t0) * 1e3
            del out
            if r > 0:
                times[name].append(ms)
            if name == "mfm_py_file" and rss_after_mfm is None:
                rss_after_mfm = peak_rss_mb()
        print(f"bench_python.py: round {r} done", file=sys.stderr)

    x = mfm_f64()
    ref = np.load(cli_npy)
    bits = float(np.abs(x - ref).max())
    result_mb = x.nbytes / 2**20
    del x, ref

    def stats(t):
        t = sorted(t)
        return {"median_ms": round(t[len(t) // 2], 1), "min_ms": round(t[0], 1)}

    report = {
        "mesh": os.path.basename(path),
        "subdiv": opts["subdiv"],
        "vertices": int(n),
        "faces": int(f.shape[0]),
        "batch": batch,
        "tau": tau,
        "runs": opts["runs"],
        "rayon_threads": os.environ.get("RAYON_NUM_THREADS", "all cores"),
        "tool": "mfm %s (wheel), CHOLMOD via scikit-sparse %s, cholespy %s, libigl %s, numpy %s"
        % (
            mfm.__version__,
            metadata.version("scikit-sparse"),
            metadata.version("cholespy"),
            metadata.version("libigl"),
            np.__version__,
        ),
        "blas": loaded_libraries(["blas", "cholmod"]),
        "timings": {k: stats(t) for k, t in times.items()},
        "f64_result_mb": round(result_mb, 1),
        "peak_rss_mb_after_mfm_rounds": round(rss_after_mfm, 1),
        "max_abs_difference_python_vs_cli": bits,
    }
    print(json.dumps(report, indent=2))


if __name__ == "__main__":
    main(sys.argv)
