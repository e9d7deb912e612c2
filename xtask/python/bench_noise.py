"""Time Matérn noise sampling with the Python sparse Cholesky stack, printing
JSON like mfm's `sampling_timings` example
(crates/noise/examples/sampling_timings.rs).

Usage: bench_noise.py [--subdiv 0,1,2] [--runs 3] [--batch 64] [--tau 100]
                      [--seed 0] [--write-off DIR] MESH

The mesh is read with igl.read_triangle_mesh and refined with igl.upsample
(1-to-4 midpoint subdivision, as mfm_geometry::subdivide::midpoint). On each
level, with libigl's operators (L = -igl.cotmatrix, the PSD cotangent
Laplacian; M = igl.massmatrix(..., BARYCENTRIC), the lumped mass) and
A = L + tau M (scipy CSC, double precision), it times, as the median wall
time of --runs runs after one warm-up run, in milliseconds:

  operators        igl.cotmatrix + igl.massmatrix, and forming A
  cholmod_factor   sksparse.cholmod.cholesky(A): CHOLMOD's symbolic analysis
                   (its default ordering) and numeric factorization
  cholespy_factor  cholespy.CholeskySolverD(n, indptr, indices, data, CSC)
                   (analysis and factorization, CPU)
  cholmod_sample   a batch of --batch Matérn samples: draw n ~ N(0, I) as a
                   V x batch array (numpy's default generator), b = M^1/2 n,
                   solve A x = b with the CHOLMOD factor (all columns at once)
  cholespy_sample  the same with cholespy's multi-right-hand-side solve
  cholmod_solve, cholespy_solve
                   the solve alone, on a prepared b

Each peer gets the right-hand-side layout it reads without a copy
(column-major for CHOLMOD, row-major for cholespy). The two solutions are
compared with each other (relative max difference, in the JSON) as a sanity
check. Per-sample times are the batch times divided by --batch (the caller
divides). With --write-off DIR every level is written to DIR/<name>_s<level>.off
(17 significant digits) so that mfm times exactly the same vertex and face
arrays (vertex order changes the fill-in and the memory locality).
"""

import json
import os
import sys
from importlib import metadata

import igl
import numpy as np
import scipy.sparse as sp
from cholespy import CholeskySolverD, MatrixType
from sksparse.cholmod import cholesky

from bench_timing import time_ms  # sibling module; scripts run by path


def parse_args(argv):
    opts = {"levels": [0], "runs": 3, "batch": 64, "tau": 100.0, "seed": 0, "out": None}
    paths = []
    it = iter(argv[1:])
    for a in it:
        if a == "--subdiv":
            opts["levels"] = sorted(int(x) for x in next(it).split(","))
        elif a == "--runs":
            opts["runs"] = max(1, int(next(it)))
        elif a == "--batch":
            opts["batch"] = max(1, int(next(it)))
        elif a == "--tau":
            opts["tau"] = float(next(it))
        elif a == "--seed":
            opts["seed"] = int(next(it))
        elif a == "--write-off":
            opts["out"] = next(it)
        else:
            paths.append(a)
    if len(paths) != 1:
        sys.exit(
            "usage: bench_noise.py [--subdiv 0,1,2] [--runs 3] [--batch 64] [--tau 100] "
            "[--seed 0] [--write-off DIR] MESH"
        )
    return opts, paths[0]


def write_off(path, v, f):
    with open(path, "w") as out:
        out.write("OFF\n%d %d 0\n" % (v.shape[0], f.shape[0]))
        np.savetxt(out, v, fmt="%.17g")
        np.savetxt(out, np.column_stack([np.full(f.shape[0], 3), f]), fmt="%d")


def loaded_libraries(pattern):
    """Shared libraries mapped into this process whose path contains one of `pattern`."""
    found = set()
    try:
        with open("/proc/self/maps") as maps:
            for line in maps:
                path = line.split()[-1] if line.strip() else ""
                name = os.path.basename(path)
                if path.startswith("/") and any(p in name for p in pattern):
                    found.add(os.path.realpath(path))
    except OSError:
        pass
    return sorted(found)


def version(dist):
    try:
        return metadata.version(dist)
    except metadata.PackageNotFoundError:
        return "?"


def time_level(v, f, opts):
    runs, batch, tau = opts["runs"], opts["batch"], opts["tau"]
    bary = igl.MASSMATRIX_TYPE_BARYCENTRIC

    def operators():
        L = -igl.cotmatrix(v, f)
        M = igl.massmatrix(v, f, bary)
        A = sp.csc_matrix(L + tau * M)
        A.sort_indices()
        return M, A

    t_ops = time_ms(runs, operators)
    M, A = operators()
    n = A.shape[0]
    sqrt_m = np.sqrt(M.diagonal())
    t_cholmod = time_ms(runs, lambda: cholesky(A))
    factor = cholesky(A)
    t_cholespy = time_ms(
        runs, lambda: CholeskySolverD(n, A.indptr, A.indices, A.data, MatrixType.CSC)
    )
    solver = CholeskySolverD(n, A.indptr, A.indices, A.data, MatrixType.CSC)

    rng = np.random.default_rng(opts["seed"])

    def cholmod_sample():
        # batch x V standard normals, viewed as a column-major V x batch array
        b = rng.standard_normal((batch, n)).T
        b *= sqrt_m[:, None]
        return factor(b)

    def cholespy_sample():
        b = rng.standard_normal((n, batch))
        b *= sqrt_m[:, None]
        x = np.empty_like(b)
        solver.solve(b, x)
        return x

    b_f = np.asfortranarray(sqrt_m[:, None] * rng.standard_normal((n, batch)))
    b_c = np.ascontiguousarray(b_f)
    x_c = np.empty_like(b_c)

    t_cm_sample = time_ms(runs, cholmod_sample)
    t_cs_sample = time_ms(runs, cholespy_sample)
    t_cm_solve = time_ms(runs, lambda: factor(b_f))
    t_cs_solve = time_ms(runs, lambda: solver.solve(b_c, x_c))

    x_cm = factor(b_f)
    solver.solve(b_c, x_c)
    agreement = float(np.abs(x_cm - x_c).max() / np.abs(x_cm).max())
    timings = {
        "operators": t_ops,
        "cholmod_factor": t_cholmod,
        "cholespy_factor": t_cholespy,
        "cholmod_sample": t_cm_sample,
        "cholespy_sample": t_cs_sample,
        "cholmod_solve": t_cm_solve,
        "cholespy_solve": t_cs_solve,
    }
    return {
        "vertices": int(n),
        "faces": int(f.shape[0]),
        "matrix_nnz": int(A.nnz),
        "peer_max_rel_difference": agreement,
        "median_ms": {k: round(t[0], 4) for k, t in timings.items()},
        "min_ms": {k: round(t[1], 4) for k, t in timings.items()},
    }


def main(argv):
    opts, path = parse_args(argv)
    if opts["out"] is not None:
        os.makedirs(opts["out"], exist_ok=True)
    v, f = igl.read_triangle_mesh(path)
    stem = os.path.splitext(os.path.basename(path))[0]
    results = []
    level = 0
    for target in opts["levels"]:
        if target > level:
            v, f = igl.upsample(v, f, target - level)
            level = target
        v = np.ascontiguousarray(v, dtype=np.float64)
        f = np.ascontiguousarray(f, dtype=np.int64)
        if opts["out"] is not None:
            write_off(os.path.join(opts["out"], "%s_s%d.off" % (stem, level)), v, f)
        print("bench_noise.py: level %d, %d vertices" % (level, v.shape[0]), file=sys.stderr)
        r = time_level(v, f, opts)
        r["mesh"] = os.path.basename(path)
        r["subdiv"] = level
        results.append(r)
    report = {
        "tool": "CHOLMOD via scikit-sparse %s, cholespy %s, libigl %s, numpy %s, scipy %s"
        % (
            version("scikit-sparse"),
            version("cholespy"),
            version("libigl"),
            version("numpy"),
            version("scipy"),
        ),
        "blas": loaded_libraries(["blas", "lapack", "cholmod"]),
        "runs": opts["runs"],
        "batch": opts["batch"],
        "tau": opts["tau"],
        "results": results,
    }
    print(json.dumps(report, indent=2))


if __name__ == "__main__":
    main(sys.argv)
