//! Supernodal triangular solves on row-major right-hand-side panels
//! (crate-internal).
//!
//! A panel holds `K` right-hand sides of the permuted system as `n` rows of
//! `K` contiguous values (`panel[i * K + j]` = row `i` of right-hand side `j`),
//! so every update of the substitution is a `K`-wide vector operation and the
//! factor is streamed once per panel. Lanes never interact: every column of the
//! result goes through exactly the same sequence of scalar operations whatever
//! `K` is and whatever other columns share the panel, so a column's result is
//! bit-identical however a block is cut into panels.
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

/// Solves `L Y = X` then `L^T Z = Y` in place on a row-major panel of width
/// `K`, with the factor in faer's supernodal layout (each supernode an
/// `(nc + np) x nc` column-major block: the diagonal block, then the rows of
/// its pattern).
#[inline(always)]
fn solve_panel_generic<T: Real, const K: usize, const FMA: bool>(
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

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx2,fma")]
unsafe fn solve_panel_avx512<T: Real, const K: usize>(
    sn: &Supernodes<'_>,
    values: &[T],
    x: &mut [[T; K]],
) {
    solve_panel_generic::<T, K, true>(sn, values, x)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn solve_panel_avx2<T: Real, const K: usize>(
    sn: &Supernodes<'_>,
    values: &[T],
    x: &mut [[T; K]],
) {
    solve_panel_generic::<T, K, true>(sn, values, x)
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

/// Runs the forward and backward substitutions on a panel of width `K`.
pub(crate) fn solve_panel<T: Real, const K: usize>(
    isa: Isa,
    sn: &Supernodes<'_>,
    values: &[T],
    x: &mut [[T; K]],
) {
    match isa {
        // SAFETY: `detect_isa` returned these variants only after checking at
        // run time that the CPU supports the enabled features.
        #[cfg(target_arch = "x86_64")]
        Isa::Avx512 => unsafe { solve_panel_avx512::<T, K>(sn, values, x) },
        #[cfg(target_arch = "x86_64")]
        Isa::Avx2 => unsafe { solve_panel_avx2::<T, K>(sn, values, x) },
        Isa::Portable => solve_panel_generic::<T, K, false>(sn, values, x),
    }
}
