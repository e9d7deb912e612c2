"""Oracle for mfm-solver's generalized eigensolver: the k smallest eigenvalues of
L phi = lambda M phi computed by scipy's shift-invert ARPACK (eigsh).

Usage:
  scipy_eigs.py --mesh MESH OUTDIR K [--sigma S]
      Reads MESH with igl.read_triangle_mesh, builds L = -igl.cotmatrix (the
      positive semi-definite cotangent Laplacian) and the barycentric lumped
      mass, and writes into OUTDIR:
        L.txt     triplets "i j value" of L (0-based, 17 significant digits)
        M.txt     the diagonal of M, one value per line
        eigs.txt  the K smallest eigenvalues, ascending, one per line
  scipy_eigs.py --operators DIR K [--sigma S]
      Reads DIR/L.mtx (Matrix Market) or DIR/L.txt (triplets) and DIR/M.txt
      (or DIR/M.npy), writes DIR/eigs.txt.

The eigenvalues come from
  scipy.sparse.linalg.eigsh(L, k=K, M=M, sigma=S, which="LM", tol=0)
(tol=0: ARPACK iterates to machine precision). S defaults to -1e-8 times
trace(L) / trace(M), a shift just below the zero eigenvalue of a closed mesh.
"""

import os
import sys

import numpy as np
import scipy.io
import scipy.sparse as sp
import scipy.sparse.linalg as spla


def write_triplets(path, mat):
    coo = sp.coo_matrix(mat)
    coo.sum_duplicates()
    data = np.column_stack([coo.row, coo.col, coo.data])
    np.savetxt(path, data, fmt=["%d", "%d", "%.17g"])


def read_operators(folder):
    mtx = os.path.join(folder, "L.mtx")
    if os.path.exists(mtx):
        lap = sp.csc_matrix(scipy.io.mmread(mtx))
    else:
        t = np.loadtxt(os.path.join(folder, "L.txt"), ndmin=2)
        n = int(t[:, :2].max()) + 1
        lap = sp.csc_matrix((t[:, 2], (t[:, 0].astype(int), t[:, 1].astype(int))), shape=(n, n))
    npy = os.path.join(folder, "M.npy")
    mass = np.load(npy) if os.path.exists(npy) else np.loadtxt(os.path.join(folder, "M.txt"))
    return lap, np.asarray(mass, dtype=np.float64).ravel()


def mesh_operators(mesh, out):
    import igl

    v, f = igl.read_triangle_mesh(mesh)
    v = np.ascontiguousarray(v, dtype=np.float64)
    f = np.ascontiguousarray(f, dtype=np.int64)
    lap = sp.csc_matrix(-igl.cotmatrix(v, f))
    mass = igl.massmatrix(v, f, igl.MASSMATRIX_TYPE_BARYCENTRIC).diagonal()
    write_triplets(os.path.join(out, "L.txt"), lap)
    np.savetxt(os.path.join(out, "M.txt"), mass, fmt="%.17g")
    return lap, mass


def main(argv):
    args = list(argv[1:])
    sigma = None
    if "--sigma" in args:
        i = args.index("--sigma")
        sigma = float(args[i + 1])
        del args[i : i + 2]
    if len(args) == 4 and args[0] == "--mesh":
        _, mesh, out, k = args
        os.makedirs(out, exist_ok=True)
        lap, mass = mesh_operators(mesh, out)
    elif len(args) == 3 and args[0] == "--operators":
        _, out, k = args
        lap, mass = read_operators(out)
    else:
        sys.exit(__doc__)
    k = int(k)
    if sigma is None:
        sigma = -1e-8 * lap.diagonal().sum() / mass.sum()
    m = sp.diags(mass).tocsc()
    vals = spla.eigsh(lap, k=k, M=m, sigma=sigma, which="LM", tol=0, return_eigenvectors=False)
    np.savetxt(os.path.join(out, "eigs.txt"), np.sort(vals), fmt="%.17g")


if __name__ == "__main__":
    main(sys.argv)
