"""Time libigl's operators on mesh files, printing JSON like mfm's
`operator_timings` example (crates/geometry/examples/operator_timings.rs).

Usage: bench_operators.py [--subdiv 0,2,3,4] [--runs 9] [--write-off DIR] MESH [MESH ...]

Each mesh is read with igl.read_triangle_mesh and refined with igl.upsample
(1-to-4 midpoint subdivision: V' = V + E, F' = 4F, the same counts as
mfm_geometry::subdivide::midpoint). Per (mesh, level), the median wall time of
--runs runs (after one warm-up run) is printed per operator, in milliseconds,
with the fastest run (min_ms):
  face_areas          igl.doublearea / 2
  lumped_mass         igl.massmatrix(V, F, MASSMATRIX_TYPE_BARYCENTRIC)
  cotangent_laplacian igl.cotmatrix
  intrinsic_gradient  igl.grad (3F x V, extrinsic)
  laplacian_and_mass  cotmatrix + massmatrix
  operators_new       all four
Times include the bindings' conversion to scipy matrices, as a Python user
pays it. With --write-off DIR, every timed mesh is also written to
DIR/<name>_s<level>.off (17 significant digits), so that the Rust example can
time exactly the same vertex and face arrays (vertex order affects memory
locality, hence timings):

  cargo run --release -p mfm-geometry --example operator_timings -- DIR/*.off
"""

import json
import os
import sys

import igl
import numpy as np

from bench_timing import time_ms  # sibling module; scripts run by path


def parse_args(argv):
    levels, runs, out, paths = [0], 9, None, []
    it = iter(argv[1:])
    for a in it:
        if a == "--subdiv":
            levels = sorted(int(x) for x in next(it).split(","))
        elif a == "--runs":
            runs = max(1, int(next(it)))
        elif a == "--write-off":
            out = next(it)
        else:
            paths.append(a)
    if not paths:
        sys.exit("usage: bench_operators.py [--subdiv 0,2,3,4] [--runs 9] [--write-off DIR] MESH...")
    return levels, runs, out, paths


def write_off(path, v, f):
    with open(path, "w") as out:
        out.write("OFF\n%d %d 0\n" % (v.shape[0], f.shape[0]))
        np.savetxt(out, v, fmt="%.17g")
        np.savetxt(out, np.column_stack([np.full(f.shape[0], 3), f]), fmt="%d")


def main(argv):
    levels, runs, out, paths = parse_args(argv)
    if out is not None:
        os.makedirs(out, exist_ok=True)
    bary = igl.MASSMATRIX_TYPE_BARYCENTRIC
    results = []
    for path in paths:
        v, f = igl.read_triangle_mesh(path)
        level = 0
        for target in levels:
            if target > level:
                v, f = igl.upsample(v, f, target - level)
                level = target
            v = np.ascontiguousarray(v, dtype=np.float64)
            f = np.ascontiguousarray(f, dtype=np.int64)
            if out is not None:
                stem = os.path.splitext(os.path.basename(path))[0]
                write_off(os.path.join(out, "%s_s%d.off" % (stem, level)), v, f)

            def everything():
                igl.cotmatrix(v, f)
                igl.massmatrix(v, f, bary)
                igl.grad(v, f)
                igl.doublearea(v, f) / 2.0

            def l_and_m():
                igl.cotmatrix(v, f)
                igl.massmatrix(v, f, bary)

            timings = {
                "face_areas": time_ms(runs, lambda: igl.doublearea(v, f) / 2.0),
                "lumped_mass": time_ms(runs, lambda: igl.massmatrix(v, f, bary)),
                "cotangent_laplacian": time_ms(runs, lambda: igl.cotmatrix(v, f)),
                "intrinsic_gradient": time_ms(runs, lambda: igl.grad(v, f)),
                "laplacian_and_mass": time_ms(runs, l_and_m),
                "operators_new": time_ms(runs, everything),
            }
            results.append(
                {
                    "mesh": os.path.basename(path),
                    "subdiv": level,
                    "vertices": int(v.shape[0]),
                    "faces": int(f.shape[0]),
                    "median_ms": {k: round(t[0], 3) for k, t in timings.items()},
                    "min_ms": {k: round(t[1], 3) for k, t in timings.items()},
                }
            )
    print(json.dumps({"tool": "libigl " + getattr(igl, "__version__", "(python)"), "runs": runs,
                      "results": results}, indent=2))


if __name__ == "__main__":
    main(sys.argv)
