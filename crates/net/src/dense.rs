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
//! slower) stays with torch's `mm`.
//!
//! Other devices and element types fall back to torch's `linear`.

use faer::linalg::matmul::matmul;
use faer::{Accum, MatMut, MatRef, Par};
use tch::{Device, Kind, Tensor};

use crate::autograd::{CustomFunction, apply_custom, parallel_for};
use crate::error::{NetError, Result, shape_error};

#[derive(Clone, Copy)]
struct Ptr<T>(*mut T);

impl<T> Ptr<T> {
    /// The pointer (a method, so closures capture the `Sync` wrapper).
    fn get(self) -> *mut T {
        self.0
    }
}
// SAFETY: workers write disjoint row blocks (or their own partial buffers).
unsafe impl<T> Send for Ptr<T> {}
// SAFETY: as above.
unsafe impl<T> Sync for Ptr<T> {}

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
fn gemm_rows<T: faer::traits::ComplexField<Canonical = T> + Copy + Send + Sync + 'static>(
    a: &[T],
    b: &[T],
    c: Ptr<T>,
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

fn forward_kind<T: faer::traits::ComplexField<Canonical = T> + Copy + Send + Sync + 'static>(
    x: &Tensor,
    w: &Tensor,
    out: &Tensor,
    n: usize,
    k: usize,
    o: usize,
) {
    // SAFETY: contiguous CPU tensors of type T.
    let (xs, ws) = unsafe { (slice::<T>(x), slice::<T>(w)) };
    gemm_rows(xs, ws, Ptr(out.data_ptr() as *mut T), n, k, o, true);
}

impl CustomFunction for Linear {
    fn name(&self) -> &str {
        "linear"
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
            }
        }
        let out = if self.has_bias {
            out + &inputs[2].detach()
        } else {
            out
        };
        self.saved = Some((x, w));
        Ok(vec![out])
    }

    fn backward(&mut self, grad_outputs: &[Tensor]) -> Result<Vec<Option<Tensor>>> {
        let (x, w) = self.saved.as_ref().ok_or_else(|| NetError::CustomOp {
            op: "linear".into(),
            message: "backward before forward".into(),
        })?;
        let g = grad_outputs[0].contiguous();
        let (n, k) = rows_of(x);
        let o = w.size()[0] as usize;
        let grad_x = Tensor::empty(x.size().as_slice(), (x.kind(), Device::Cpu));
        match x.kind() {
            Kind::Double => {
                // SAFETY: contiguous CPU tensors of type f64.
                let (gs, ws) = unsafe { (slice::<f64>(&g), slice::<f64>(w)) };
                gemm_rows(gs, ws, Ptr(grad_x.data_ptr() as *mut f64), n, o, k, false);
            }
            _ => {
                // SAFETY: contiguous CPU tensors of type f32.
                let (gs, ws) = unsafe { (slice::<f32>(&g), slice::<f32>(w)) };
                gemm_rows(gs, ws, Ptr(grad_x.data_ptr() as *mut f32), n, o, k, false);
            }
        }
        // the weight gradient is a long reduction (k = rows): MKL does it
        // faster than faer's row-major kernels (measured 65-70 vs 48 GFLOPS)
        let (ni, oi, ki) = (n as i64, o as i64, k as i64);
        let grad_w = g.reshape([ni, oi]).tr().mm(&x.reshape([ni, ki]));
        let mut grads = vec![Some(grad_x), Some(grad_w)];
        if self.has_bias {
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
