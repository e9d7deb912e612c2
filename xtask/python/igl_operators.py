"""Dump a mesh and its libigl operators as plain text, for mfm's oracle tests.

Usage: igl_operators.py MESH OUTDIR [--mesh-only]

MESH is read with igl.read_triangle_mesh (OFF, OBJ, PLY, ...). OUTDIR receives,
every number printed with 17 significant digits (a lossless round trip):
  V.txt  one vertex per line: x y z
  F.txt  one face per line: i j k (0-based)
and, unless --mesh-only:
  L.txt  triplets "i j value" of -igl.cotmatrix (the positive semi-definite L)
  M.txt  the diagonal of igl.massmatrix(..., MASSMATRIX_TYPE_BARYCENTRIC)
  A.txt  face areas, igl.doublearea / 2
  G.txt  triplets "i j value" of igl.grad (3F x V: rows d*F + f, d = x, y, z)
"""

import os
import sys

import igl
import numpy as np
import scipy.sparse as sp


def write_triplets(path, mat):
    coo = sp.coo_matrix(mat)
    coo.sum_duplicates()
    data = np.column_stack([coo.row, coo.col, coo.data])
    np.savetxt(path, data, fmt=["%d", "%d", "%.17g"])


def main(argv):
    args = [a for a in argv[1:] if not a.startswith("--")]
    if len(args) != 2:
        sys.exit("usage: igl_operators.py MESH OUTDIR [--mesh-only]")
    mesh, out = args
    os.makedirs(out, exist_ok=True)
    v, f = igl.read_triangle_mesh(mesh)
    v = np.ascontiguousarray(v, dtype=np.float64)
    f = np.ascontiguousarray(f, dtype=np.int64)
    np.savetxt(os.path.join(out, "V.txt"), v, fmt="%.17g")
    np.savetxt(os.path.join(out, "F.txt"), f, fmt="%d")
    if "--mesh-only" in argv:
        return
    write_triplets(os.path.join(out, "L.txt"), -igl.cotmatrix(v, f))
    m = igl.massmatrix(v, f, igl.MASSMATRIX_TYPE_BARYCENTRIC)
    np.savetxt(os.path.join(out, "M.txt"), m.diagonal(), fmt="%.17g")
    np.savetxt(os.path.join(out, "A.txt"), igl.doublearea(v, f) / 2.0, fmt="%.17g")
    write_triplets(os.path.join(out, "G.txt"), igl.grad(v, f))


if __name__ == "__main__":
    main(sys.argv)
