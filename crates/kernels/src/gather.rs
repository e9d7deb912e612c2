//! Gather kernels of the mesh operators: a face-from-vertex operator `A`
//! (`G`, face means) applied as `A x` over face items or `A^T y` over vertex
//! items, each output row written by exactly one item (no atomics, no
//! scatter), with the vertex-to-face incidence in compressed form. The loops
//! are compiled twice, portable and for AVX2 + FMA, and chosen at run time.
//! The operators that own the coefficients are in [`crate::mesh`].

use crate::{Scalar, SyncPtr};

/// Vertex -> incident (face, corner) lists, compressed.
#[derive(Debug)]
pub(crate) struct Incidence {
    pub(crate) ptr: Vec<usize>,
    pub(crate) face: Vec<u32>,
    pub(crate) corner: Vec<u8>,
}

impl Incidence {
    pub(crate) fn new(num_vertices: usize, faces: &[[u32; 3]]) -> Self {
        let mut count = vec![0usize; num_vertices + 1];
        for t in faces {
            for &v in t {
                count[v as usize + 1] += 1;
            }
        }
        for i in 0..num_vertices {
            count[i + 1] += count[i];
        }
        let ptr = count.clone();
        let mut next = count;
        let mut face = vec![0u32; faces.len() * 3];
        let mut corner = vec![0u8; faces.len() * 3];
        for (f, t) in faces.iter().enumerate() {
            for (j, &v) in t.iter().enumerate() {
                let k = next[v as usize];
                face[k] = f as u32;
                corner[k] = j as u8;
                next[v as usize] += 1;
            }
        }
        Self { ptr, face, corner }
    }
}

/// Hints the CPU to load the first `min(len, 4 cache lines)` of `data`
/// into the cache (no effect off x86-64).
#[inline(always)]
fn prefetch<T>(data: &[T], len: usize) {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::{_MM_HINT_T0, _mm_prefetch};
        let bytes = (len.min(data.len()) * std::mem::size_of::<T>()).min(256);
        let base = data.as_ptr().cast::<i8>();
        let mut off = 0;
        while off < bytes {
            // SAFETY: prefetching is a hint and never faults; the address is
            // inside `data`.
            unsafe { _mm_prefetch::<_MM_HINT_T0>(base.add(off)) };
            off += 64;
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = (data, len);
}

/// Which map a [`GatherKernel`] run computes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum GatherMode {
    /// `A x`, face items.
    Forward,
    /// `A^T y`, vertex items.
    Adjoint,
    /// [`GatherKernel::forward_pair_rows`] (vertex rows of `2c` values).
    PairedForward,
    /// [`GatherKernel::adjoint_pair_rows`] (vertex rows of `2c` values).
    PairedAdjoint,
}

impl GatherMode {
    pub(crate) fn adjoint(self) -> bool {
        matches!(self, Self::Adjoint | Self::PairedAdjoint)
    }
}

/// One run of the face operators' CPU kernel (`crate::mesh`): `A x` over face items
/// `b F + f` or, with `adjoint`, `A^T y` over vertex items `b V + v`,
/// written to `out`. Its loops over a range of items are compiled twice
/// (portable, and for AVX2 + FMA chosen at run time).
pub(crate) struct GatherKernel<'a, T> {
    pub(crate) faces: &'a [[u32; 3]],
    pub(crate) incidence: &'a Incidence,
    pub(crate) rows: usize,
    pub(crate) num_vertices: usize,
    pub(crate) c: usize,
    /// The paired modes are the paired divergence's (`rows == 2`): vertex
    /// rows hold `2c` values, `[p | q]`.
    pub(crate) mode: GatherMode,
    pub(crate) input: &'a [T],
    /// Per-face coefficients (forward) or per-incidence ones (adjoint).
    pub(crate) coef: &'a [T],
    pub(crate) out: SyncPtr<T>,
}

impl<T: Scalar> GatherKernel<'_, T> {
    /// Items `begin..end`, with the AVX2 + FMA loops when the CPU has them.
    pub(crate) fn dispatch(&self, begin: usize, end: usize) {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma")
        {
            // SAFETY: the CPU supports AVX2 and FMA (checked above).
            unsafe { self.run_avx2(begin, end) };
            return;
        }
        self.run(begin, end);
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn run_avx2(&self, begin: usize, end: usize) {
        self.run(begin, end);
    }

    #[inline(always)]
    fn run(&self, begin: usize, end: usize) {
        match self.mode {
            GatherMode::Forward => self.forward_rows(begin, end),
            GatherMode::Adjoint => self.adjoint_rows(begin, end),
            GatherMode::PairedForward => self.forward_pair_rows(begin, end),
            GatherMode::PairedAdjoint => self.adjoint_pair_rows(begin, end),
        }
    }

    /// Paired forward: vertex rows `[p | q]` (`2c` values) to the face rows
    /// `(A p + A_rot q)`, where `A_rot` turns each face's coefficient rows
    /// `(a0, a1)` into `(a1, -a0)`: row 0 gets `a0 p + a1 q`, row 1
    /// `a1 p - a0 q`. The adjoint of [`GatherKernel::adjoint_pair_rows`].
    #[inline(always)]
    fn forward_pair_rows(&self, begin: usize, end: usize) {
        let (v, f, c) = (self.num_vertices, self.faces.len(), self.c);
        let (x, coef, out) = (self.input, self.coef, self.out);
        let w = 2 * c;
        for idx in begin..end {
            let (b, fi) = (idx / f, idx % f);
            let xb = &x[b * v * w..(b + 1) * v * w];
            let [i0, i1, i2] = self.faces[fi].map(|i| i as usize);
            let (p0, q0) = xb[i0 * w..i0 * w + w].split_at(c);
            let (p1, q1) = xb[i1 * w..i1 * w + w].split_at(c);
            let (p2, q2) = xb[i2 * w..i2 * w + w].split_at(c);
            let a = &coef[fi * 6..fi * 6 + 3];
            let d = &coef[fi * 6 + 3..fi * 6 + 6];
            // SAFETY: rows 2 idx and 2 idx + 1 belong to this range only and
            // are inside the output (nb F 2 rows of c).
            let (o0, o1) = unsafe {
                std::slice::from_raw_parts_mut(out.get().add(idx * 2 * c), 2 * c).split_at_mut(c)
            };
            let (a0, a1, a2) = (a[0], a[1], a[2]);
            let (d0, d1, d2) = (d[0], d[1], d[2]);
            let ps = p0.iter().zip(p1).zip(p2);
            let qs = q0.iter().zip(q1).zip(q2);
            for (((o0, o1), ((&pa, &pb), &pc)), ((&qa, &qb), &qc)) in
                o0.iter_mut().zip(o1.iter_mut()).zip(ps).zip(qs)
            {
                *o0 = a0 * pa + a1 * pb + a2 * pc + (d0 * qa + d1 * qb + d2 * qc);
                *o1 = d0 * pa + d1 * pb + d2 * pc - (a0 * qa + a1 * qb + a2 * qc);
            }
        }
    }

    /// In the adjoint kernels, before vertex `vi`'s sum: the faces of the
    /// next vertex are scattered over the input `yb` (one batch item, `block`
    /// values per face), so ask for their first cache lines now (the rest of
    /// each face's rows follow sequentially).
    #[inline(always)]
    fn prefetch_next_vertex(&self, yb: &[T], vi: usize, block: usize) {
        let inc = self.incidence;
        if vi + 1 < self.num_vertices {
            for k in inc.ptr[vi + 1]..inc.ptr[vi + 2] {
                prefetch(&yb[inc.face[k] as usize * block..], block);
            }
        }
    }

    /// Paired adjoint: face rows `(y0, y1)` to vertex rows `[p | q]` with
    /// `p = A^T y` and `q = A_rot^T y` (per incidence with coefficients
    /// `(w0, w1)`: `p += w0 y0 + w1 y1`, `q += w1 y0 - w0 y1`), reading each
    /// face row once.
    #[inline(always)]
    fn adjoint_pair_rows(&self, begin: usize, end: usize) {
        let (v, f, c) = (self.num_vertices, self.faces.len(), self.c);
        let (y, adj, out) = (self.input, self.coef, self.out);
        let inc = self.incidence;
        let block = 2 * c;
        for idx in begin..end {
            let (b, vi) = (idx / v, idx % v);
            let yb = &y[b * f * block..(b + 1) * f * block];
            self.prefetch_next_vertex(yb, vi, block);
            // SAFETY: row idx (2c values) belongs to this range only.
            let (op, oq) = unsafe {
                std::slice::from_raw_parts_mut(out.get().add(idx * 2 * c), 2 * c).split_at_mut(c)
            };
            op.fill(T::default());
            oq.fill(T::default());
            for k in inc.ptr[vi]..inc.ptr[vi + 1] {
                let fi = inc.face[k] as usize;
                let (w0, w1) = (adj[k * 2], adj[k * 2 + 1]);
                let (y0, y1) = yb[fi * block..(fi + 1) * block].split_at(c);
                for (((p, q), &a), &d) in op.iter_mut().zip(oq.iter_mut()).zip(y0).zip(y1) {
                    *p = *p + w0 * a + w1 * d;
                    *q = *q + w1 * a - w0 * d;
                }
            }
        }
    }

    #[inline(always)]
    fn forward_rows(&self, begin: usize, end: usize) {
        let (v, f, rows, c) = (self.num_vertices, self.faces.len(), self.rows, self.c);
        let (x, coef, out) = (self.input, self.coef, self.out);
        for idx in begin..end {
            let (b, fi) = (idx / f, idx % f);
            let xb = &x[b * v * c..(b + 1) * v * c];
            let [i0, i1, i2] = self.faces[fi].map(|i| i as usize);
            let (x0, x1, x2) = (
                &xb[i0 * c..i0 * c + c],
                &xb[i1 * c..i1 * c + c],
                &xb[i2 * c..i2 * c + c],
            );
            for r in 0..rows {
                let k = &coef[(fi * rows + r) * 3..(fi * rows + r) * 3 + 3];
                let (k0, k1, k2) = (k[0], k[1], k[2]);
                // SAFETY: row (idx R + r) belongs to this range only and is
                // inside the output (nb F R rows of c).
                let o = unsafe {
                    std::slice::from_raw_parts_mut(out.get().add((idx * rows + r) * c), c)
                };
                for (((o, &a), &b), &d) in o.iter_mut().zip(x0).zip(x1).zip(x2) {
                    *o = k0 * a + k1 * b + k2 * d;
                }
            }
        }
    }

    #[inline(always)]
    fn adjoint_rows(&self, begin: usize, end: usize) {
        let (v, f, rows, c) = (self.num_vertices, self.faces.len(), self.rows, self.c);
        let (y, adj, out) = (self.input, self.coef, self.out);
        let inc = self.incidence;
        let block = rows * c;
        for idx in begin..end {
            let (b, vi) = (idx / v, idx % v);
            let yb = &y[b * f * block..(b + 1) * f * block];
            self.prefetch_next_vertex(yb, vi, block);
            // SAFETY: row idx belongs to this range only.
            let o = unsafe { std::slice::from_raw_parts_mut(out.get().add(idx * c), c) };
            o.fill(T::default());
            for k in inc.ptr[vi]..inc.ptr[vi + 1] {
                let fi = inc.face[k] as usize;
                for r in 0..rows {
                    let w = adj[k * rows + r];
                    let yr = &yb[(fi * rows + r) * c..(fi * rows + r + 1) * c];
                    for (o, &y) in o.iter_mut().zip(yr) {
                        *o += w * y;
                    }
                }
            }
        }
    }
}
