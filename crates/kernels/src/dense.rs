//! Dense layers with faer's matrix products on the CPU.
//!
//! [`linear`] computes `y = x W^T + b` like torch's `linear`, but as one
//! autograd node whose forward and backward products run with
//! [faer](https://docs.rs/faer)'s GEMM kernels: on the benchmark machine
//! (AMD EPYC, AVX2) they reach ~77 GFLOPS per core for PoissonNet's
//! `[55728, 256] x [256, 256]` products, against ~55 for the MKL build inside
//! the torch wheel. Rows are split evenly over libtorch's intra-op threads
//! ([`crate::autograd::parallel_for`]), each running a sequential product, so
//! no second thread pool competes with torch's. The weight gradient (a
//! reduction over all rows, where faer's kernels on row-major data are
//! slower for wide layers) stays with torch's `mm` for large weights and
//! runs as fixed-size blocked faer products for small ones (below
//! [`FAER_WEIGHT_GRADIENT_MAX`] entries), where MKL mostly packs.
//!
//! [`complex_linear`] is the complex layers' product `z -> W z` with three
//! real products instead of four (Gauss's form), in the forward pass and in
//! both backward products.
//!
//! Other devices and element types fall back to torch (`linear`,
//! [`complex_linear_reference`]).

use faer::linalg::matmul::matmul;
use faer::{Accum, MatMut, MatRef, Par};
use std::sync::atomic::{AtomicU64, Ordering};
use tch::{Device, Kind, Tensor};

use crate::autograd::{CustomFunction, apply_custom, parallel_for};
use crate::error::{Result, backward_before_forward, shape_error};
use crate::{Scalar, SyncPtr};

/// Names of the dense layers' autograd nodes ([`linear`], [`complex_linear`]),
/// so also of their profile sections `fn:<name>` and `fn:<name>^T`
/// ([`crate::profile`]).
pub const NODE_NAMES: [&str; 2] = [LINEAR_NODE, COMPLEX_LINEAR_NODE];
const LINEAR_NODE: &str = "linear";
const COMPLEX_LINEAR_NODE: &str = "complex_linear";

/// Running total of [`counted_product_flops`].
static PRODUCT_FLOPS: AtomicU64 = AtomicU64::new(0);

/// Floating-point operations (two per multiply-add) of the matrix products
/// that [`linear`] and [`complex_linear`] have run on the CPU in this process
/// so far, forward and backward (a product over `n` rows of a `k -> o` layer
/// counts `2 n k o`; Gauss's three-product form counts its three products).
/// Products that fall back to torch (other devices and kinds) are not
/// counted. For checking cost models such as
/// `mfm_net::PoissonNetConfig::forward_product_flops`: take the difference
/// of two readings around the work, with nothing else running products.
pub fn counted_product_flops() -> u64 {
    PRODUCT_FLOPS.load(Ordering::Relaxed)
}

fn count_products(multiply_adds: usize) {
    PRODUCT_FLOPS.fetch_add(2 * multiply_adds as u64, Ordering::Relaxed);
}

/// Row blocks `[start, end)` of `n` rows, one per intra-op thread (at least
/// 256 rows each).
fn blocks(n: usize) -> Vec<(usize, usize)> {
    let threads = (tch::get_num_threads().max(1) as usize)
        .min(n.div_ceil(256))
        .max(1);
    (0..threads)
        .map(|t| (t * n / threads, (t + 1) * n / threads))
        .collect()
}

/// `C[n, o] = A[n, k] B[k, o]` (row-major, contiguous), `C` overwritten;
/// `b_transposed`: `B` is given as `B^T [o, k]`.
fn gemm_rows<T: Scalar>(
    a: &[T],
    b: &[T],
    c: SyncPtr<T>,
    n: usize,
    k: usize,
    o: usize,
    b_transposed: bool,
) {
    let bl = blocks(n);
    parallel_for(bl.len(), 1, &|begin, end| {
        for &(r0, r1) in &bl[begin..end] {
            let rows = r1 - r0;
            if rows == 0 {
                continue;
            }
            let a_blk = MatRef::from_row_major_slice(&a[r0 * k..r1 * k], rows, k);
            let b_m = if b_transposed {
                MatRef::from_row_major_slice(b, o, k).transpose()
            } else {
                MatRef::from_row_major_slice(b, k, o)
            };
            // SAFETY: each block writes its own rows of C.
            let c_blk = unsafe { std::slice::from_raw_parts_mut(c.get().add(r0 * o), rows * o) };
            let c_m = MatMut::from_row_major_slice_mut(c_blk, rows, o);
            matmul(c_m, Accum::Replace, a_blk, b_m, T::one_impl(), Par::Seq);
        }
    });
}

/// Largest weight (`C_out * C_in` entries) whose gradient [`linear`]
/// computes with faer (`weight_gradient`); larger ones use torch's `mm`
/// (MKL). The weight gradient is a long reduction over all rows: for the
/// paper preset's `128 x 384` and `256 x 128` weights MKL was ~4% faster on
/// the whole step (65-70 vs 48 GFLOPS per core), while for the small
/// preset's `64 x 64` and narrower ones MKL spends most of its time packing
/// (`scopy`, `mscale`) and faer's blocked sums made the step ~4% faster
/// (interleaved runs, 2026-11-26).
pub const FAER_WEIGHT_GRADIENT_MAX: usize = 8192;

struct Linear {
    saved: Option<(Tensor, Tensor)>,
    has_bias: bool,
}

/// `(x [.., k] as [n, k], n, k)`.
fn rows_of(x: &Tensor) -> (usize, usize) {
    let s = x.size();
    let k = *s.last().unwrap_or(&1) as usize;
    let n = x.numel().checked_div(k).unwrap_or(0);
    (n, k)
}

/// # Safety
/// `t` must be a contiguous CPU tensor of element type `T`.
unsafe fn slice<T>(t: &Tensor) -> &[T] {
    // SAFETY: guaranteed by the caller.
    unsafe { std::slice::from_raw_parts(t.data_ptr() as *const T, t.numel()) }
}

fn forward_kind<T: Scalar>(x: &Tensor, w: &Tensor, out: &Tensor, n: usize, k: usize, o: usize) {
    // SAFETY: contiguous CPU tensors of type T.
    let (xs, ws) = unsafe { (slice::<T>(x), slice::<T>(w)) };
    gemm_rows(xs, ws, SyncPtr(out.data_ptr() as *mut T), n, k, o, true);
}

/// `(dX = G W, dW = G^T X)` of `Y = X W^T` for contiguous CPU tensors of
/// type `T` (`X: [n, k]`, `W: [o, k]`, `G: [n, o]`).
fn backward_kind<T>(
    x: &Tensor,
    w: &Tensor,
    g: &Tensor,
    n: usize,
    k: usize,
    o: usize,
) -> (Tensor, Tensor)
where
    T: Scalar + tch::kind::Element,
{
    let grad_x = Tensor::empty(x.size().as_slice(), (x.kind(), Device::Cpu));
    // `dX = G W` with `W` handed to faer column-major (`W^T` row-major):
    // faer's kernels read a column-major right-hand side 5-12% faster
    let wt = w.tr().contiguous();
    // SAFETY: contiguous CPU tensors of type T.
    let (xs, wts, gs) = unsafe { (slice::<T>(x), slice::<T>(&wt), slice::<T>(g)) };
    crate::profile::timed("linear.dx", || {
        gemm_rows(gs, wts, SyncPtr(grad_x.data_ptr() as *mut T), n, o, k, true)
    });
    let _s =
        crate::profile::enabled().then(|| crate::profile::section(format!("linear.dw {o}x{k}")));
    let grad_w = if o * k <= FAER_WEIGHT_GRADIENT_MAX {
        Tensor::from_slice(&weight_gradient(xs, gs, n, k, o)).reshape([o as i64, k as i64])
    } else {
        let (ni, oi, ki) = (n as i64, o as i64, k as i64);
        g.reshape([ni, oi]).tr().mm(&x.reshape([ni, ki]))
    };
    (grad_x, grad_w)
}

impl CustomFunction for Linear {
    fn name(&self) -> &str {
        LINEAR_NODE
    }

    fn forward(&mut self, inputs: &[Tensor]) -> Result<Vec<Tensor>> {
        let x = inputs[0].detach().contiguous();
        let w = inputs[1].detach().contiguous();
        let (n, k) = rows_of(&x);
        let o = w.size()[0] as usize;
        let mut shape = x.size();
        if let Some(last) = shape.last_mut() {
            *last = o as i64;
        }
        let out = Tensor::empty(shape.as_slice(), (x.kind(), Device::Cpu));
        if n > 0 && o > 0 {
            if k == 0 {
                let _ = out.shallow_clone().zero_();
            } else {
                match x.kind() {
                    Kind::Double => forward_kind::<f64>(&x, &w, &out, n, k, o),
                    _ => forward_kind::<f32>(&x, &w, &out, n, k, o),
                }
                count_products(n * k * o);
            }
        }
        let out = if self.has_bias {
            let _s = crate::profile::section("linear.bias");
            out + &inputs[2].detach()
        } else {
            out
        };
        self.saved = Some((x, w));
        Ok(vec![out])
    }

    fn backward(&mut self, grad_outputs: &[Tensor]) -> Result<Vec<Option<Tensor>>> {
        let (x, w) = self
            .saved
            .as_ref()
            .ok_or_else(|| backward_before_forward(LINEAR_NODE))?;
        let g = grad_outputs[0].contiguous();
        let (n, k) = rows_of(x);
        let o = w.size()[0] as usize;
        let (grad_x, grad_w) = match x.kind() {
            Kind::Double => backward_kind::<f64>(x, w, &g, n, k, o),
            _ => backward_kind::<f32>(x, w, &g, n, k, o),
        };
        count_products(2 * n * k * o);
        let mut grads = vec![Some(grad_x), Some(grad_w)];
        if self.has_bias {
            let _s = crate::profile::section("linear.db");
            let gb =
                g.reshape([n as i64, o as i64])
                    .sum_dim_intlist([0i64].as_slice(), false, g.kind());
            grads.push(Some(gb));
        }
        Ok(grads)
    }
}

/// `y = x W^T + b` for `x: [..., k]`, `W: [o, k]`, `b: [o]`, differentiable in
/// all three; faer products on the CPU for `f32`/`f64` (see the
/// [module docs](self)), torch's `linear` elsewhere. First derivatives only.
///
/// The backward pass uses the weight as it was in the forward pass; do not
/// update parameters in place between a forward pass and its backward pass.
pub fn linear(x: &Tensor, weight: &Tensor, bias: Option<&Tensor>) -> Result<Tensor> {
    let (_, k) = rows_of(x);
    let ws = weight.size();
    if ws.len() != 2 || ws[1] as usize != k || x.dim() == 0 {
        return Err(shape_error(
            "linear weight",
            format!("[out, {k}] for inputs [..., {k}]"),
            weight,
        ));
    }
    if let Some(b) = bias {
        if b.size() != [ws[0]] {
            return Err(shape_error("linear bias", format!("[{}]", ws[0]), b));
        }
    }
    let cpu = x.device() == Device::Cpu && weight.device() == Device::Cpu;
    let kinds = matches!(x.kind(), Kind::Float | Kind::Double)
        && weight.kind() == x.kind()
        && bias.is_none_or(|b| b.kind() == x.kind() && b.device() == Device::Cpu);
    if !(cpu && kinds) {
        return Ok(x.linear(weight, bias));
    }
    let node = Linear {
        saved: None,
        has_bias: bias.is_some(),
    };
    let mut out = match bias {
        Some(b) => apply_custom(node, &[x, weight, b])?,
        None => apply_custom(node, &[x, weight])?,
    };
    Ok(out.remove(0))
}

/// Writes `f(re, im)` of each of the `rows` complex rows of `src` (rows
/// `[re (k) | im (k)]`) to `dst` (rows of `k`).
fn combine_parts<T: Copy>(src: &[T], k: usize, dst: &mut [T], f: impl Fn(T, T) -> T) {
    for (row, out) in src.chunks_exact(2 * k).zip(dst.chunks_exact_mut(k)) {
        let (re, im) = row.split_at(k);
        for ((s, &a), &b) in out.iter_mut().zip(re).zip(im) {
            *s = f(a, b);
        }
    }
}

/// Complex rows per chunk in [`complex_rows_product`] and
/// [`complex_weight_gradient`] for `width = max(C_in, C_out)`: about 64 Ki
/// values per temporary (256 KiB in `f32`, `512 x 128`), so a chunk's
/// temporaries stay in L2.
fn complex_chunk(width: usize) -> usize {
    ((64 * 1024) / width.max(1)).clamp(256, 4096)
}

/// Narrowest `min(C_in, C_out)` for which [`complex_linear`] uses the
/// three-product form. Below it the three small products and the extra
/// passes cost more than the product saved: at width 32 (the `small` preset)
/// torch's one four-product GEMM gave 6% faster training steps and 15-20%
/// faster inference than the three-product form, and the same product
/// through [`linear`]'s faer kernels another ~7% on the training step; at
/// width 64 the three-product form was 3-9% faster.
pub const GAUSS_MIN_WIDTH: i64 = 64;

/// The three real matrices of a complex matrix `M = A + iB` (`[k, o]` each)
/// that Gauss's three-product form needs: `A`, `B` and `A + B`.
struct ComplexFactors<'a, T> {
    re: MatRef<'a, T>,
    im: MatRef<'a, T>,
    sum: MatRef<'a, T>,
}

/// `Y = X M` for `n` complex rows: `x` holds rows `[re (k) | im (k)]`, `y`
/// gets rows `[re (o) | im (o)]` (overwritten). Uses Gauss's form with three
/// real products instead of four, `t1 = Xr A`, `t2 = Xi B`,
/// `t3 = (Xr + Xi)(A + B)`, `Yr = t1 - t2`, `Yi = t3 - t1 - t2`, chunk by chunk so the
/// temporaries stay in cache; rows are split over libtorch's intra-op threads.
fn complex_rows_product<T>(x: &[T], m: &ComplexFactors<'_, T>, y: SyncPtr<T>, n: usize)
where
    T: Scalar,
{
    let (k, o) = (m.re.nrows(), m.re.ncols());
    let bl = blocks(n);
    let chunk = complex_chunk(k.max(o));
    parallel_for(bl.len(), 1, &|begin, end| {
        let mut xs = vec![T::zero_impl(); chunk * k];
        let mut t2 = vec![T::zero_impl(); chunk * o];
        for &(r0, r1) in &bl[begin..end] {
            let mut c0 = r0;
            while c0 < r1 {
                let c1 = (c0 + chunk).min(r1);
                let rows = c1 - c0;
                let xc = &x[c0 * 2 * k..c1 * 2 * k];
                let xr = MatRef::from_row_major_slice_with_stride(xc, rows, k, 2 * k);
                let xi = MatRef::from_row_major_slice_with_stride(&xc[k..], rows, k, 2 * k);
                combine_parts(xc, k, &mut xs, |a, b| a + b);
                let xs_m = MatRef::from_row_major_slice(&xs[..rows * k], rows, k);
                // SAFETY: this task owns rows c0..c1 of y; the real and
                // imaginary views interleave without overlapping.
                let (yr, yi) = unsafe {
                    let base = y.get().add(c0 * 2 * o);
                    (
                        MatMut::from_raw_parts_mut(base, rows, o, 2 * o as isize, 1),
                        MatMut::from_raw_parts_mut(base.add(o), rows, o, 2 * o as isize, 1),
                    )
                };
                let t2_m = MatMut::from_row_major_slice_mut(&mut t2[..rows * o], rows, o);
                let one = T::one_impl();
                matmul(yr, Accum::Replace, xr, m.re, one, Par::Seq);
                matmul(t2_m, Accum::Replace, xi, m.im, one, Par::Seq);
                matmul(yi, Accum::Replace, xs_m, m.sum, one, Par::Seq);
                // SAFETY: as above, rows c0..c1 of y belong to this task.
                let yc = unsafe {
                    std::slice::from_raw_parts_mut(y.get().add(c0 * 2 * o), rows * 2 * o)
                };
                for (row, t2r) in yc.chunks_exact_mut(2 * o).zip(t2.chunks_exact(o)) {
                    let (re, im) = row.split_at_mut(o);
                    for ((a, b), &t2v) in re.iter_mut().zip(im.iter_mut()).zip(t2r) {
                        let t1 = *a;
                        *a = t1 - t2v;
                        *b = *b - t1 - t2v;
                    }
                }
                c0 = c1;
            }
        }
    });
}

/// Rows per partial sum of [`complex_weight_gradient`]: fixed, so the
/// order of the sum, and the rounding of the result, does not depend on the
/// thread count.
const WEIGHT_GRADIENT_BLOCK: usize = 4096;

/// Weight gradient of the complex product `Y = X W^T`: with `Gy` the
/// gradient of `Y`, `dW = Gy^T conj(X)`, i.e. `dWr = Gyr^T Xr + Gyi^T Xi`,
/// `dWi = Gyi^T Xr - Gyr^T Xi`, also in Gauss's form: `p1 = Gyr^T Xr`,
/// `p2 = Gyi^T Xi`, `p3 = (Gyr + Gyi)^T (Xr - Xi)`, `dWr = p1 + p2`,
/// `dWi = p3 - p1 + p2`. Each block of [`WEIGHT_GRADIENT_BLOCK`] rows accumulates its own
/// `p1, p2, p3` (blocks run in parallel); the blocks' sums are added in
/// order at the end. Returns `[2, o, k]` row-major.
fn complex_weight_gradient<T>(x: &[T], gy: &[T], n: usize, k: usize, o: usize) -> Vec<T>
where
    T: Scalar,
{
    let blocks = n.div_ceil(WEIGHT_GRADIENT_BLOCK);
    let chunk = complex_chunk(k.max(o));
    let mut partials = vec![T::zero_impl(); blocks * 3 * o * k];
    let pp = SyncPtr(partials.as_mut_ptr());
    parallel_for(blocks, 1, &|begin, end| {
        let mut xd = vec![T::zero_impl(); chunk * k];
        let mut gs = vec![T::zero_impl(); chunk * o];
        for b in begin..end {
            // SAFETY: block b owns its 3 o k partial values.
            let p =
                unsafe { std::slice::from_raw_parts_mut(pp.get().add(b * 3 * o * k), 3 * o * k) };
            let (p1, rest) = p.split_at_mut(o * k);
            let (p2, p3) = rest.split_at_mut(o * k);
            let (r0, r1) = (
                b * WEIGHT_GRADIENT_BLOCK,
                ((b + 1) * WEIGHT_GRADIENT_BLOCK).min(n),
            );
            let mut c0 = r0;
            while c0 < r1 {
                let c1 = (c0 + chunk).min(r1);
                let rows = c1 - c0;
                let xc = &x[c0 * 2 * k..c1 * 2 * k];
                let gc = &gy[c0 * 2 * o..c1 * 2 * o];
                combine_parts(xc, k, &mut xd, |a, b| a - b);
                combine_parts(gc, o, &mut gs, |a, b| a + b);
                let xr = MatRef::from_row_major_slice_with_stride(xc, rows, k, 2 * k);
                let xi = MatRef::from_row_major_slice_with_stride(&xc[k..], rows, k, 2 * k);
                let gr = MatRef::from_row_major_slice_with_stride(gc, rows, o, 2 * o).transpose();
                let gi =
                    MatRef::from_row_major_slice_with_stride(&gc[o..], rows, o, 2 * o).transpose();
                let xd_m = MatRef::from_row_major_slice(&xd[..rows * k], rows, k);
                let gs_m = MatRef::from_row_major_slice(&gs[..rows * o], rows, o).transpose();
                let one = T::one_impl();
                let acc = |dst: &mut [T], lhs: MatRef<'_, T>, rhs: MatRef<'_, T>| {
                    let d = MatMut::from_row_major_slice_mut(dst, o, k);
                    matmul(d, Accum::Add, lhs, rhs, one, Par::Seq);
                };
                acc(p1, gr, xr);
                acc(p2, gi, xi);
                acc(p3, gs_m, xd_m);
                c0 = c1;
            }
        }
    });
    let mut grad = vec![T::zero_impl(); 2 * o * k];
    for p in partials.chunks_exact(3 * o * k) {
        let (p1, rest) = p.split_at(o * k);
        let (p2, p3) = rest.split_at(o * k);
        let (gr, gi) = grad.split_at_mut(o * k);
        for i in 0..o * k {
            gr[i] = gr[i] + p1[i] + p2[i];
            gi[i] = gi[i] + p3[i] - p1[i] + p2[i];
        }
    }
    grad
}

/// Weight gradient `dW = Gy^T X` (`[o, k]` row-major) of `Y = X W^T` for `n`
/// rows, summed over fixed blocks of [`WEIGHT_GRADIENT_BLOCK`] rows (in
/// parallel, then added in order, so the result does not depend on the
/// thread count).
fn weight_gradient<T: Scalar>(x: &[T], gy: &[T], n: usize, k: usize, o: usize) -> Vec<T> {
    let blocks = n.div_ceil(WEIGHT_GRADIENT_BLOCK);
    let mut partials = vec![T::zero_impl(); blocks * o * k];
    let pp = SyncPtr(partials.as_mut_ptr());
    parallel_for(blocks, 1, &|begin, end| {
        for b in begin..end {
            // SAFETY: block b owns its o k partial values.
            let p = unsafe { std::slice::from_raw_parts_mut(pp.get().add(b * o * k), o * k) };
            let (r0, r1) = (
                b * WEIGHT_GRADIENT_BLOCK,
                ((b + 1) * WEIGHT_GRADIENT_BLOCK).min(n),
            );
            let rows = r1 - r0;
            let xm = MatRef::from_row_major_slice(&x[r0 * k..r1 * k], rows, k);
            let gm = MatRef::from_row_major_slice(&gy[r0 * o..r1 * o], rows, o).transpose();
            let d = MatMut::from_row_major_slice_mut(p, o, k);
            matmul(d, Accum::Replace, gm, xm, T::one_impl(), Par::Seq);
        }
    });
    let mut grad = vec![T::zero_impl(); o * k];
    for p in partials.chunks_exact(o * k) {
        for (g, &v) in grad.iter_mut().zip(p) {
            *g += v;
        }
    }
    grad
}

struct ComplexLinearOp {
    saved: Option<(Tensor, Tensor)>,
}

/// `(complex rows, C_in, C_out)` of `z: [..., 2R, C_in]` and `w: [2, C_out, C_in]`.
fn complex_dims(z: &Tensor, w: &Tensor) -> (usize, usize, usize) {
    let s = w.size();
    let (o, k) = (s[1] as usize, s[2] as usize);
    let n = z.numel().checked_div(2 * k).unwrap_or(0);
    (n, k, o)
}

fn complex_forward_kind<T>(z: &Tensor, w: &Tensor, out: &Tensor, n: usize, k: usize, o: usize)
where
    T: Scalar,
{
    // `y = z W^T`: A = Wr^T, B = Wi^T, A + B = (Wr + Wi)^T, all [k, o]
    let sum = (w.get(0) + w.get(1)).contiguous();
    // SAFETY: contiguous CPU tensors of type T.
    let (zs, ws, ss) = unsafe { (slice::<T>(z), slice::<T>(w), slice::<T>(&sum)) };
    let m = ComplexFactors {
        re: MatRef::from_row_major_slice(&ws[..o * k], o, k).transpose(),
        im: MatRef::from_row_major_slice(&ws[o * k..], o, k).transpose(),
        sum: MatRef::from_row_major_slice(ss, o, k).transpose(),
    };
    complex_rows_product(zs, &m, SyncPtr(out.data_ptr() as *mut T), n);
}

fn complex_backward_kind<T>(
    z: &Tensor,
    w: &Tensor,
    g: &Tensor,
    n: usize,
    k: usize,
    o: usize,
) -> (Tensor, Tensor)
where
    T: Scalar + tch::kind::Element,
{
    // `dz = dy conj(W)`: A = Wr, B = -Wi, A + B = Wr - Wi, all [o, k], each
    // handed to faer column-major (stored transposed, row-major), which its
    // kernels read 5-12% faster than a row-major right-hand side
    let (wr, wi) = (w.get(0), w.get(1));
    let re_t = wr.tr().contiguous();
    let neg_im_t = (-&wi).tr().contiguous();
    let diff_t = (&wr - &wi).tr().contiguous();
    let grad_z = Tensor::empty(z.size().as_slice(), (z.kind(), Device::Cpu));
    // SAFETY: contiguous CPU tensors of type T.
    let (zs, gs, rs, ns, ds) = unsafe {
        (
            slice::<T>(z),
            slice::<T>(g),
            slice::<T>(&re_t),
            slice::<T>(&neg_im_t),
            slice::<T>(&diff_t),
        )
    };
    let m = ComplexFactors {
        re: MatRef::from_row_major_slice(rs, k, o).transpose(),
        im: MatRef::from_row_major_slice(ns, k, o).transpose(),
        sum: MatRef::from_row_major_slice(ds, k, o).transpose(),
    };
    crate::profile::timed("complex.dz", || {
        complex_rows_product(gs, &m, SyncPtr(grad_z.data_ptr() as *mut T), n)
    });
    let gw = crate::profile::timed("complex.dw", || complex_weight_gradient(zs, gs, n, k, o));
    let grad_w = Tensor::from_slice(&gw).reshape([2, o as i64, k as i64]);
    (grad_z, grad_w)
}

impl CustomFunction for ComplexLinearOp {
    fn name(&self) -> &str {
        COMPLEX_LINEAR_NODE
    }

    fn forward(&mut self, inputs: &[Tensor]) -> Result<Vec<Tensor>> {
        let z = inputs[0].detach().contiguous();
        let w = inputs[1].detach().contiguous();
        let (n, k, o) = complex_dims(&z, &w);
        let mut shape = z.size();
        if let Some(last) = shape.last_mut() {
            *last = o as i64;
        }
        let opts = (z.kind(), Device::Cpu);
        let out = if n > 0 && k > 0 && o > 0 {
            // every row is written by the kernel
            let out = Tensor::empty(shape.as_slice(), opts);
            match z.kind() {
                Kind::Double => complex_forward_kind::<f64>(&z, &w, &out, n, k, o),
                _ => complex_forward_kind::<f32>(&z, &w, &out, n, k, o),
            }
            count_products(3 * n * k * o);
            out
        } else {
            Tensor::zeros(shape.as_slice(), opts)
        };
        self.saved = Some((z, w));
        Ok(vec![out])
    }

    fn backward(&mut self, grad_outputs: &[Tensor]) -> Result<Vec<Option<Tensor>>> {
        let (z, w) = self
            .saved
            .as_ref()
            .ok_or_else(|| backward_before_forward(COMPLEX_LINEAR_NODE))?;
        let g = grad_outputs[0].contiguous();
        let (n, k, o) = complex_dims(z, w);
        if n == 0 || k == 0 || o == 0 {
            return Ok(vec![Some(z.zeros_like()), Some(w.zeros_like())]);
        }
        let (gz, gw) = match z.kind() {
            Kind::Double => complex_backward_kind::<f64>(z, w, &g, n, k, o),
            _ => complex_backward_kind::<f32>(z, w, &g, n, k, o),
        };
        count_products(6 * n * k * o);
        Ok(vec![Some(gz), Some(gw)])
    }
}

/// The complex linear map `z -> W z` on complex feature rows, `W = Wr + i Wi`
/// given as `weight: [2, C_out, C_in]`, for `z: [..., 2R, C_in]` whose rows
/// `2r, 2r + 1` are the real and imaginary parts of complex row `r`; returns
/// `[..., 2R, C_out]`. Differentiable in `z` and `weight` (first derivatives).
///
/// This is `torch`'s `[R, 2 C_in] x [2 C_in, 2 C_out]` real product in
/// disguise, but computed with three real products of size `C_in x C_out`
/// (Gauss's trick) instead of four, in the forward pass and in both backward
/// products, with faer kernels on the CPU for `f32`/`f64` (see the
/// [module docs](self)). Layers narrower than [`GAUSS_MIN_WIDTH`] use the
/// four-product real form as one [`linear`] product; other devices and other
/// kinds use it through torch ([`complex_linear_reference`]). The
/// three-product form rounds differently from the four-product one
/// (relative differences of a few ulps times `C_in`).
///
/// Complexity: `6 R C_in C_out` multiply-adds forward, twice that backward.
pub fn complex_linear(z: &Tensor, weight: &Tensor) -> Result<Tensor> {
    let ws = weight.size();
    let s = z.size();
    let rows: i64 = s[..s.len().saturating_sub(1)].iter().product();
    if ws.len() != 3 || ws[0] != 2 {
        return Err(shape_error(
            "complex_linear weight",
            "[2, C_out, C_in]",
            weight,
        ));
    }
    if s.len() < 2 || s.last() != Some(&ws[2]) || rows % 2 != 0 {
        return Err(shape_error(
            "complex_linear input",
            format!("[..., 2R, {}] (real and imaginary rows)", ws[2]),
            z,
        ));
    }
    let cpu = z.device() == Device::Cpu && weight.device() == Device::Cpu;
    let kinds = matches!(z.kind(), Kind::Float | Kind::Double) && weight.kind() == z.kind();
    if !(cpu && kinds) {
        return Ok(complex_linear_reference(z, weight));
    }
    if ws[1].min(ws[2]) < GAUSS_MIN_WIDTH {
        // one faer product with the real matrix (its weight gradient flows
        // back through `real_matrix`'s concatenations)
        return as_real_product(z, weight, |rows, real| linear(rows, &real.tr(), None));
    }
    let mut out = apply_custom(ComplexLinearOp { saved: None }, &[z, weight])?;
    Ok(out.remove(0))
}

/// The real `[2 C_in, 2 C_out]` matrix `[[Wr^T, Wi^T], [-Wi^T, Wr^T]]` of
/// the complex weight `[2, C_out, C_in]`, acting on rows `[re | im]`.
fn real_matrix(weight: &Tensor) -> Tensor {
    let wr = weight.get(0).tr();
    let wi = weight.get(1).tr();
    let top = Tensor::cat(&[&wr, &wi], 1);
    let bottom = Tensor::cat(&[&(-&wi), &wr], 1);
    Tensor::cat(&[top, bottom], 0)
}

/// The same map as [`complex_linear`] with torch operations only: one real
/// `[R, 2 C_in] x [2 C_in, 2 C_out]` product with the real matrix
/// `[[Wr^T, Wi^T], [-Wi^T, Wr^T]]` acting on rows `[re | im]`.
pub fn complex_linear_reference(z: &Tensor, weight: &Tensor) -> Tensor {
    as_real_product(z, weight, |rows, real| {
        Ok::<_, std::convert::Infallible>(rows.mm(real))
    })
    .unwrap_or_else(|e| match e {})
}

/// `product([R, 2 C_in] rows, [2 C_in, 2 C_out] real matrix)` reshaped back
/// to `[..., 2R, C_out]`: the four-product form of [`complex_linear`].
fn as_real_product<E>(
    z: &Tensor,
    weight: &Tensor,
    product: impl FnOnce(&Tensor, &Tensor) -> std::result::Result<Tensor, E>,
) -> std::result::Result<Tensor, E> {
    let s = z.size();
    let (o, k) = (weight.size()[1], weight.size()[2]);
    let rows: i64 = s[..s.len() - 1].iter().product();
    let mut out_shape = s.clone();
    if let Some(last) = out_shape.last_mut() {
        *last = o;
    }
    let y = product(&z.reshape([rows / 2, 2 * k]), &real_matrix(weight))?;
    Ok(y.reshape(out_shape.as_slice()))
}
