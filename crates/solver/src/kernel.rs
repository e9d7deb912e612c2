//! Supernodal triangular solves on row-major right-hand-side panels
//! (crate-internal).
//!
//! A panel holds `K` right-hand sides of the permuted system as `n` rows of
//! `K` contiguous values (`panel[i * K + j]` = row `i` of right-hand side `j`,
//! each row aligned to a cache line), so every update of the substitution is
//! a `K`-wide vector operation and the factor is streamed once per panel.
//! Lanes never interact: every column of the result goes through exactly the
//! same sequence of scalar operations whatever `K` is and whatever other
//! columns share the panel, so a column's result is bit-identical however a
//! block is cut into panels.
//!
//! Within a supernode the updates run on register tiles (a few rows or
//! columns of the supernode times two vectors of lanes) accumulated over the
//! whole supernode, so a panel row is loaded and stored once per supernode
//! rather than once per factor column; the tiling keeps the reference order
//! of the scalar operations (see `solve_panel_generic`), so results are the
//! same bits as the plain column-by-column substitution (a test checks it).
//!
//! The kernels are written once, generically, and instantiated inside
//! `#[target_feature]` functions (AVX-512, AVX2+FMA) chosen at run time, so the
//! portable build still runs the wide vector code.

use faer::sparse::linalg::cholesky::supernodal::SymbolicSupernodalCholesky;

use crate::cholesky::Real;

/// Per-supernode data in the layout the kernels read.
pub(crate) struct Supernodes<'a> {
    pub(crate) begin: &'a [usize],
    pub(crate) end: &'a [usize],
    pub(crate) row_ptr: &'a [usize],
    pub(crate) row_idx: &'a [usize],
    pub(crate) val_ptr: &'a [usize],
}

impl<'a> Supernodes<'a> {
    pub(crate) fn new(sn: &'a SymbolicSupernodalCholesky<usize>) -> Self {
        Self {
            begin: sn.supernode_begin(),
            end: sn.supernode_end(),
            row_ptr: sn.col_ptr_for_row_idx(),
            row_idx: sn.row_idx(),
            val_ptr: sn.col_ptr_for_val(),
        }
    }
}

/// `a * b + c`, fused when the instantiation says so.
#[inline(always)]
fn madd<T: Real, const FMA: bool>(a: T, b: T, c: T) -> T {
    if FMA {
        a.fused_mul_add(b, c)
    } else {
        a * b + c
    }
}

/// One row of a panel: `K` right-hand-side values of one unknown, aligned to
/// a cache line so that a lane tile never straddles two lines.
#[derive(Debug, Clone, Copy)]
#[repr(C, align(64))]
pub(crate) struct Row<T, const K: usize>(pub(crate) [T; K]);

/// Rows of a dense (diagonal-block) or pattern tile updated together by the
/// forward kernel, and columns updated together by the backward one.
const TILE: usize = 6;

/// Lanes `t .. t + N` of a row.
#[inline(always)]
fn lanes<T: Real, const K: usize, const N: usize>(row: &Row<T, K>, t: usize) -> [T; N] {
    let mut v = [T::from_f64(0.0); N];
    v.copy_from_slice(&row.0[t..t + N]);
    v
}

/// Writes `v` to lanes `t .. t + N` of a row.
#[inline(always)]
fn set_lanes<T: Real, const K: usize, const N: usize>(row: &mut Row<T, K>, t: usize, v: &[T; N]) {
    row.0[t..t + N].copy_from_slice(v);
}

/// `acc[j] = a * y[j] + acc[j]` for every lane.
#[inline(always)]
fn axpy<T: Real, const N: usize, const FMA: bool>(a: T, y: &[T; N], acc: &mut [T; N]) {
    for j in 0..N {
        acc[j] = madd::<T, FMA>(a, y[j], acc[j]);
    }
}

/// Solves `L Y = X` then `L^T Z = Y` in place on a row-major panel of width
/// `K`, with the factor in faer's supernodal layout (each supernode an
/// `(nc + np) x nc` column-major block: the diagonal block, then the rows of
/// its pattern).
///
/// Every lane goes through this exact sequence of scalar operations (the
/// reference order, which the tiling below preserves):
/// - forward: row `r` of the permuted system takes `x_r = -L_rc * x_c + x_r`
///   (one fused multiply-add) for every stored `L_rc`, `c < r`, in increasing
///   `c`, then `x_r = x_r * (1 / L_rr)`;
/// - backward: column `c` takes `x_c = -L_rc * x_r + x_c` for every stored
///   `L_rc`, `r > c`: first over its supernode's pattern rows in increasing
///   `r` (the rectangular block), then over the later rows of its diagonal
///   block in increasing `r`, then `x_c = x_c * (1 / L_cc)`.
///
/// The tiles only decide which values stay in registers: `LT` lanes (two
/// vector registers) times [`TILE`] rows or columns of accumulators, loaded
/// and stored once per supernode instead of once per factor column; `DT`
/// lanes at a time in the dense backward block, whose columns are strictly
/// sequential. `K` must be a multiple of `LT` and `DT`.
#[inline(always)]
fn solve_panel_generic<
    T: Real,
    const K: usize,
    const LT: usize,
    const DT: usize,
    const FMA: bool,
>(
    sn: &Supernodes<'_>,
    values: &[T],
    x: &mut [Row<T, K>],
) {
    let ns = sn.begin.len();
    for s in 0..ns {
        let (start, nc) = (sn.begin[s], sn.end[s] - sn.begin[s]);
        let pattern = &sn.row_idx[sn.row_ptr[s]..sn.row_ptr[s + 1]];
        let nr = nc + pattern.len();
        let l = &values[sn.val_ptr[s]..sn.val_ptr[s] + nr * nc];
        forward_supernode::<T, K, LT, FMA>(start, nc, nr, pattern, l, x);
    }
    for s in (0..ns).rev() {
        let (start, nc) = (sn.begin[s], sn.end[s] - sn.begin[s]);
        let pattern = &sn.row_idx[sn.row_ptr[s]..sn.row_ptr[s + 1]];
        let nr = nc + pattern.len();
        let l = &values[sn.val_ptr[s]..sn.val_ptr[s] + nr * nc];
        backward_supernode::<T, K, LT, DT, FMA>(start, nc, nr, pattern, l, x);
    }
}

/// Forward substitution through one supernode: its diagonal block (rows in
/// tiles: all earlier columns, then the small triangle inside the tile), then
/// `x[pattern] -= L_bot x[top]`.
#[inline(always)]
fn forward_supernode<T: Real, const K: usize, const LT: usize, const FMA: bool>(
    start: usize,
    nc: usize,
    nr: usize,
    pattern: &[usize],
    l: &[T],
    x: &mut [Row<T, K>],
) {
    let (head, tail) = x.split_at_mut(start + nc);
    let top = &mut head[start..];
    let mut r0 = 0;
    while r0 + TILE <= nc {
        forward_dense_tile::<T, K, LT, TILE, FMA>(r0, nr, l, top);
        r0 += TILE;
    }
    while r0 < nc {
        forward_dense_tile::<T, K, LT, 1, FMA>(r0, nr, l, top);
        r0 += 1;
    }
    // pattern rows all come after the supernode: index them in `tail`
    let off = start + nc;
    let mut p = 0;
    while p + TILE <= pattern.len() {
        let mut rows = [0; TILE];
        for i in 0..TILE {
            rows[i] = pattern[p + i] - off;
        }
        forward_rect_tile::<T, K, LT, TILE, FMA>(top, nr, nc + p, &rows, l, tail);
        p += TILE;
    }
    while p < pattern.len() {
        forward_rect_tile::<T, K, LT, 1, FMA>(top, nr, nc + p, &[pattern[p] - off], l, tail);
        p += 1;
    }
}

/// Rows `r0 .. r0 + R` of a diagonal block (`top` holds the supernode's
/// rows): `x_r -= L_rc x_c` for `c < r0` (already final), then the triangle
/// inside the tile and the scaling.
#[inline(always)]
fn forward_dense_tile<T: Real, const K: usize, const LT: usize, const R: usize, const FMA: bool>(
    r0: usize,
    nr: usize,
    l: &[T],
    top: &mut [Row<T, K>],
) {
    let mut inv = [T::from_f64(1.0); R];
    for i in 0..R {
        inv[i] = T::from_f64(1.0) / l[(r0 + i) * nr + r0 + i];
    }
    for t in (0..K).step_by(LT) {
        let mut acc = [[T::from_f64(0.0); LT]; R];
        for i in 0..R {
            acc[i] = lanes(&top[r0 + i], t);
        }
        for c in 0..r0 {
            let y: [T; LT] = lanes(&top[c], t);
            let col = &l[c * nr + r0..c * nr + r0 + R];
            for i in 0..R {
                axpy::<T, LT, FMA>(-col[i], &y, &mut acc[i]);
            }
        }
        for i in 0..R {
            for c in 0..i {
                let y = acc[c];
                axpy::<T, LT, FMA>(-l[(r0 + c) * nr + r0 + i], &y, &mut acc[i]);
            }
            for v in acc[i].iter_mut() {
                *v *= inv[i];
            }
        }
        for i in 0..R {
            set_lanes(&mut top[r0 + i], t, &acc[i]);
        }
    }
}

/// `R` pattern rows (block rows `p .. p + R` of the supernode, at `rows` in
/// `tail`): `x_g -= L_gc x_c` for every column `c` of the supernode, in order.
#[inline(always)]
fn forward_rect_tile<T: Real, const K: usize, const LT: usize, const R: usize, const FMA: bool>(
    top: &[Row<T, K>],
    nr: usize,
    p: usize,
    rows: &[usize; R],
    l: &[T],
    tail: &mut [Row<T, K>],
) {
    for t in (0..K).step_by(LT) {
        let mut acc = [[T::from_f64(0.0); LT]; R];
        for i in 0..R {
            acc[i] = lanes(&tail[rows[i]], t);
        }
        for (c, yc) in top.iter().enumerate() {
            let y: [T; LT] = lanes(yc, t);
            let col = &l[c * nr + p..c * nr + p + R];
            for i in 0..R {
                axpy::<T, LT, FMA>(-col[i], &y, &mut acc[i]);
            }
        }
        for i in 0..R {
            set_lanes(&mut tail[rows[i]], t, &acc[i]);
        }
    }
}

/// Backward substitution through one supernode: `x[top] -= L_bot^T
/// x[pattern]` (columns in tiles), then the dense `L_top^T` block, one
/// column at a time from the last.
#[inline(always)]
fn backward_supernode<
    T: Real,
    const K: usize,
    const LT: usize,
    const DT: usize,
    const FMA: bool,
>(
    start: usize,
    nc: usize,
    nr: usize,
    pattern: &[usize],
    l: &[T],
    x: &mut [Row<T, K>],
) {
    let (head, tail) = x.split_at_mut(start + nc);
    let top = &mut head[start..];
    let off = start + nc;
    let mut c0 = 0;
    while c0 + TILE <= nc {
        backward_rect_tile::<T, K, LT, TILE, FMA>(c0, nr, nc, pattern, off, l, tail, top);
        c0 += TILE;
    }
    while c0 < nc {
        backward_rect_tile::<T, K, LT, 1, FMA>(c0, nr, nc, pattern, off, l, tail, top);
        c0 += 1;
    }
    for c in (0..nc).rev() {
        let col = &l[c * nr..c * nr + nc];
        let inv = T::from_f64(1.0) / col[c];
        let (done, rest) = top.split_at_mut(c + 1);
        let xc = &mut done[c];
        for t in (0..K).step_by(DT) {
            let mut acc: [T; DT] = lanes(xc, t);
            for (r, xr) in rest.iter().enumerate() {
                let y: [T; DT] = lanes(xr, t);
                axpy::<T, DT, FMA>(-col[c + 1 + r], &y, &mut acc);
            }
            for v in acc.iter_mut() {
                *v *= inv;
            }
            set_lanes(xc, t, &acc);
        }
    }
}

/// Columns `c0 .. c0 + C` of a supernode: `x_c -= L_gc x_g` over the
/// pattern rows `g` (at `g - off` in `tail`), in order.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn backward_rect_tile<T: Real, const K: usize, const LT: usize, const C: usize, const FMA: bool>(
    c0: usize,
    nr: usize,
    nc: usize,
    pattern: &[usize],
    off: usize,
    l: &[T],
    tail: &[Row<T, K>],
    top: &mut [Row<T, K>],
) {
    let np = pattern.len();
    let mut cols: [&[T]; C] = [&[]; C];
    for i in 0..C {
        cols[i] = &l[(c0 + i) * nr + nc..(c0 + i) * nr + nc + np];
    }
    for t in (0..K).step_by(LT) {
        let mut acc = [[T::from_f64(0.0); LT]; C];
        for i in 0..C {
            acc[i] = lanes(&top[c0 + i], t);
        }
        for (p, &g) in pattern.iter().enumerate() {
            let y: [T; LT] = lanes(&tail[g - off], t);
            for i in 0..C {
                axpy::<T, LT, FMA>(-cols[i][p], &y, &mut acc[i]);
            }
        }
        for i in 0..C {
            set_lanes(&mut top[c0 + i], t, &acc[i]);
        }
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx2,fma")]
unsafe fn solve_panel_avx512<T: Real, const K: usize, const LT: usize, const DT: usize>(
    sn: &Supernodes<'_>,
    values: &[T],
    x: &mut [Row<T, K>],
) {
    solve_panel_generic::<T, K, LT, DT, true>(sn, values, x)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn solve_panel_avx2<T: Real, const K: usize, const LT: usize, const DT: usize>(
    sn: &Supernodes<'_>,
    values: &[T],
    x: &mut [Row<T, K>],
) {
    solve_panel_generic::<T, K, LT, DT, true>(sn, values, x)
}

/// Instruction set the kernels run with on this machine.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Isa {
    #[cfg(target_arch = "x86_64")]
    Avx512,
    #[cfg(target_arch = "x86_64")]
    Avx2,
    Portable,
}

pub(crate) fn detect_isa() -> Isa {
    #[cfg(target_arch = "x86_64")]
    {
        if std::arch::is_x86_feature_detected!("avx512f")
            && std::arch::is_x86_feature_detected!("avx2")
            && std::arch::is_x86_feature_detected!("fma")
        {
            return Isa::Avx512;
        }
        if std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma")
        {
            return Isa::Avx2;
        }
    }
    Isa::Portable
}

/// Runs the forward and backward substitutions on a panel of width `K`,
/// with register tiles of `LT` lanes (rectangular blocks, forward dense
/// block) and `DT` lanes (backward dense block); both divide `K`.
pub(crate) fn solve_panel<T: Real, const K: usize, const LT: usize, const DT: usize>(
    isa: Isa,
    sn: &Supernodes<'_>,
    values: &[T],
    x: &mut [Row<T, K>],
) {
    debug_assert!(K % LT == 0 && K % DT == 0);
    match isa {
        // SAFETY: `detect_isa` returned these variants only after checking at
        // run time that the CPU supports the enabled features.
        #[cfg(target_arch = "x86_64")]
        Isa::Avx512 => unsafe { solve_panel_avx512::<T, K, LT, DT>(sn, values, x) },
        #[cfg(target_arch = "x86_64")]
        Isa::Avx2 => unsafe { solve_panel_avx2::<T, K, LT, DT>(sn, values, x) },
        Isa::Portable => solve_panel_generic::<T, K, LT, DT, false>(sn, values, x),
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::needless_range_loop)]
mod tests {
    use super::*;
    use crate::CholeskyFactor;
    use faer::sparse::{SparseColMat, Triplet};

    /// The straightforward supernodal substitution (one factor column at a
    /// time, every update read and written through the panel): the operation
    /// order the tiled kernel must reproduce bit for bit.
    #[allow(clippy::needless_range_loop)]
    fn reference_panel<T: Real, const K: usize, const FMA: bool>(
        sn: &Supernodes<'_>,
        values: &[T],
        x: &mut [[T; K]],
    ) {
        let ns = sn.begin.len();
        // forward substitution, supernodes in order
        for s in 0..ns {
            let start = sn.begin[s];
            let nc = sn.end[s] - start;
            let pattern = &sn.row_idx[sn.row_ptr[s]..sn.row_ptr[s + 1]];
            let nr = nc + pattern.len();
            let l = &values[sn.val_ptr[s]..sn.val_ptr[s] + nr * nc];
            // dense lower-triangular block
            for c in 0..nc {
                let col = &l[c * nr..(c + 1) * nr];
                let inv = T::from_f64(1.0) / col[c];
                let mut xc = x[start + c];
                for v in xc.iter_mut() {
                    *v *= inv;
                }
                x[start + c] = xc;
                for r in c + 1..nc {
                    let lr = -col[r];
                    let xr = &mut x[start + r];
                    for j in 0..K {
                        xr[j] = madd::<T, FMA>(lr, xc[j], xr[j]);
                    }
                }
            }
            // rectangular block below: x[pattern] -= L_bot * x[top], four
            // columns at a time
            let mut c = 0;
            while c + 4 <= nc {
                let x0 = x[start + c];
                let x1 = x[start + c + 1];
                let x2 = x[start + c + 2];
                let x3 = x[start + c + 3];
                let (c0, c1, c2, c3) = (
                    &l[c * nr + nc..(c + 1) * nr],
                    &l[(c + 1) * nr + nc..(c + 2) * nr],
                    &l[(c + 2) * nr + nc..(c + 3) * nr],
                    &l[(c + 3) * nr + nc..(c + 4) * nr],
                );
                for (p, &g) in pattern.iter().enumerate() {
                    let (a0, a1, a2, a3) = (-c0[p], -c1[p], -c2[p], -c3[p]);
                    let mut acc = x[g];
                    for j in 0..K {
                        let mut v = madd::<T, FMA>(a0, x0[j], acc[j]);
                        v = madd::<T, FMA>(a1, x1[j], v);
                        v = madd::<T, FMA>(a2, x2[j], v);
                        acc[j] = madd::<T, FMA>(a3, x3[j], v);
                    }
                    x[g] = acc;
                }
                c += 4;
            }
            while c < nc {
                let x0 = x[start + c];
                let c0 = &l[c * nr + nc..(c + 1) * nr];
                for (p, &g) in pattern.iter().enumerate() {
                    let a0 = -c0[p];
                    let acc = &mut x[g];
                    for j in 0..K {
                        acc[j] = madd::<T, FMA>(a0, x0[j], acc[j]);
                    }
                }
                c += 1;
            }
        }
        // backward substitution with L^T, supernodes in reverse order
        for s in (0..ns).rev() {
            let start = sn.begin[s];
            let nc = sn.end[s] - start;
            let pattern = &sn.row_idx[sn.row_ptr[s]..sn.row_ptr[s + 1]];
            let nr = nc + pattern.len();
            let l = &values[sn.val_ptr[s]..sn.val_ptr[s] + nr * nc];
            // x[top] -= L_bot^T x[pattern], four columns at a time
            let mut c = 0;
            while c + 4 <= nc {
                let (c0, c1, c2, c3) = (
                    &l[c * nr + nc..(c + 1) * nr],
                    &l[(c + 1) * nr + nc..(c + 2) * nr],
                    &l[(c + 2) * nr + nc..(c + 3) * nr],
                    &l[(c + 3) * nr + nc..(c + 4) * nr],
                );
                let mut acc0 = x[start + c];
                let mut acc1 = x[start + c + 1];
                let mut acc2 = x[start + c + 2];
                let mut acc3 = x[start + c + 3];
                for (p, &g) in pattern.iter().enumerate() {
                    let xp = x[g];
                    let (a0, a1, a2, a3) = (-c0[p], -c1[p], -c2[p], -c3[p]);
                    for j in 0..K {
                        acc0[j] = madd::<T, FMA>(a0, xp[j], acc0[j]);
                        acc1[j] = madd::<T, FMA>(a1, xp[j], acc1[j]);
                        acc2[j] = madd::<T, FMA>(a2, xp[j], acc2[j]);
                        acc3[j] = madd::<T, FMA>(a3, xp[j], acc3[j]);
                    }
                }
                x[start + c] = acc0;
                x[start + c + 1] = acc1;
                x[start + c + 2] = acc2;
                x[start + c + 3] = acc3;
                c += 4;
            }
            while c < nc {
                let c0 = &l[c * nr + nc..(c + 1) * nr];
                let mut acc0 = x[start + c];
                for (p, &g) in pattern.iter().enumerate() {
                    let xp = x[g];
                    let a0 = -c0[p];
                    for j in 0..K {
                        acc0[j] = madd::<T, FMA>(a0, xp[j], acc0[j]);
                    }
                }
                x[start + c] = acc0;
                c += 1;
            }
            // dense upper-triangular block L_top^T
            for c in (0..nc).rev() {
                let col = &l[c * nr..(c + 1) * nr];
                let mut acc = x[start + c];
                for r in c + 1..nc {
                    let a = -col[r];
                    let xr = x[start + r];
                    for j in 0..K {
                        acc[j] = madd::<T, FMA>(a, xr[j], acc[j]);
                    }
                }
                let inv = T::from_f64(1.0) / col[c];
                for v in acc.iter_mut() {
                    *v *= inv;
                }
                x[start + c] = acc;
            }
        }
    }

    /// A weighted `nx x ny` grid Laplacian (4-neighbours and one diagonal,
    /// pseudo-random weights) plus a positive diagonal: supernodes from one
    /// column to a few dozen, with pattern rows past every tile boundary.
    fn grid(nx: usize, ny: usize, seed: u64) -> SparseColMat<usize, f64> {
        let mut state = seed;
        let mut rnd = move || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            0.5 + (state >> 11) as f64 / (1u64 << 53) as f64
        };
        let id = |i: usize, j: usize| i * ny + j;
        let n = nx * ny;
        let mut diag = vec![0.0; n];
        let mut t = Vec::new();
        for i in 0..nx {
            for j in 0..ny {
                for (di, dj) in [(1, 0), (0, 1), (1, 1)] {
                    if i + di < nx && j + dj < ny {
                        let (a, b, w) = (id(i, j), id(i + di, j + dj), rnd());
                        t.push(Triplet::new(b, a, -w));
                        diag[a] += w;
                        diag[b] += w;
                    }
                }
            }
        }
        for (i, d) in diag.iter().enumerate() {
            t.push(Triplet::new(i, i, d + 0.01 * rnd()));
        }
        SparseColMat::try_new_from_triplets(n, n, &t).unwrap()
    }

    fn check<T: Real, const K: usize, const LT: usize, const DT: usize>(
        factor: &CholeskyFactor<T>,
        cols: usize,
    ) {
        let n = factor.dim();
        let sym = factor.symbolic();
        let sn = Supernodes::new(sym.supernodal());
        let zero = T::from_f64(0.0);
        let mut panel = vec![Row([zero; K]); n];
        let mut plain = vec![[zero; K]; n];
        for i in 0..n {
            for j in 0..cols {
                let v = T::from_f64(((i * 31 + j * 17) % 23) as f64 - 11.5);
                panel[i].0[j] = v;
                plain[i][j] = v;
            }
        }
        let isa = detect_isa();
        solve_panel::<T, K, LT, DT>(isa, &sn, factor.values(), &mut panel);
        if isa == Isa::Portable {
            reference_panel::<T, K, false>(&sn, factor.values(), &mut plain);
        } else {
            reference_panel::<T, K, true>(&sn, factor.values(), &mut plain);
        }
        for i in 0..n {
            for j in 0..K {
                let (a, b): (f64, f64) = (panel[i].0[j].into(), plain[i][j].into());
                assert_eq!(a.to_bits(), b.to_bits(), "row {i} lane {j} (K = {K})");
            }
        }
        // the portable instantiation follows the same order without FMA
        let mut panel = vec![Row([zero; K]); n];
        for i in 0..n {
            panel[i].0 = plain[i];
        }
        let mut plain2 = plain.clone();
        solve_panel::<T, K, LT, DT>(Isa::Portable, &sn, factor.values(), &mut panel);
        reference_panel::<T, K, false>(&sn, factor.values(), &mut plain2);
        for i in 0..n {
            for j in 0..K {
                let (a, b): (f64, f64) = (panel[i].0[j].into(), plain2[i][j].into());
                assert_eq!(
                    a.to_bits(),
                    b.to_bits(),
                    "portable: row {i} lane {j} (K = {K})"
                );
            }
        }
    }

    #[test]
    fn tiled_kernel_matches_the_reference_order_bit_for_bit() {
        for (nx, ny, seed) in [(1, 1, 1), (3, 2, 2), (17, 13, 3), (40, 37, 4)] {
            let a = grid(nx, ny, seed);
            let f = CholeskyFactor::new(a.as_ref()).unwrap();
            let f32 = f.to_f32();
            if nx == 40 {
                // big enough for supernodes wider than a tile
                assert!(
                    f.symbolic()
                        .supernodal()
                        .supernode_end()
                        .iter()
                        .zip(f.symbolic().supernodal().supernode_begin())
                        .any(|(e, b)| e - b > 2 * TILE)
                );
            }
            check::<f64, 8, 8, 8>(&f, 5);
            check::<f64, 16, 8, 16>(&f, 16);
            check::<f64, 32, 8, 32>(&f, 27);
            check::<f32, 8, 8, 8>(&f32, 8);
            check::<f32, 16, 16, 16>(&f32, 9);
            check::<f32, 32, 16, 32>(&f32, 32);
        }
    }
}
