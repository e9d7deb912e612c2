//! Fused CPU kernels for PoissonNet's complex face operations.
//!
//! Written with torch operations, the modulation `g <- g * scale * exp(i
//! phase)` and the magnitude nonlinearity `z <- GELU(|z| + b) z / |z|` each
//! take 8-15 passes over the face features in the forward pass and more in
//! the backward pass, and on the CPU these memory-bound passes cost more than
//! the matrix products around them. Here each is one autograd node
//! ([`crate::autograd::CustomFunction`]) whose forward and backward make
//! one or two passes in Rust; transcendental functions (`cos`, `sin`,
//! `softplus`, `GELU` and its derivative) stay in torch, on the half-size
//! per-channel tensors, where they are vectorized.
//!
//! Layout: face features `g: [B, 2F, C]`, rows `2f` (real) and `2f + 1`
//! (imaginary) of face `f`; per-face-channel values `[B, F, C]`. Inputs on
//! other devices, or of other element types than `f32`/`f64`, use the
//! reference torch implementations ([`modulate_reference`],
//! [`magnitude_gelu_reference`]), which define the functions.

use tch::{Device, Kind, Tensor};

use crate::autograd::{CustomFunction, apply_custom, parallel_for};
use crate::error::{KernelError, Result, backward_before_forward, shape_error};
use crate::{Scalar, SyncPtr};

/// `eps` inside the magnitude of the complex nonlinearity:
/// `|z| = sqrt(re^2 + im^2 + eps)`.
pub const MAGNITUDE_EPS: f64 = 1e-8;
/// Added to the softplus of the modulation scale.
pub const SCALE_EPS: f64 = 1e-8;

/// Rows of faces handled per parallel task.
const GRAIN: usize = 64;

/// A contiguous CPU tensor's data as a slice.
///
/// # Safety
/// `t` must be contiguous, on the CPU, of element type `T`, and outlive the
/// slice; no one may write to it meanwhile.
unsafe fn data<T>(t: &Tensor) -> &[T] {
    // SAFETY: guaranteed by the caller.
    unsafe { std::slice::from_raw_parts(t.data_ptr() as *const T, t.numel()) }
}

fn ptr<T>(t: &Tensor) -> SyncPtr<T> {
    SyncPtr(t.data_ptr() as *mut T)
}

/// Splits `[B, 2F, C]` into (rows = B F, C).
fn face_dims(g: &Tensor, what: &str) -> Result<(usize, usize)> {
    let s = g.size();
    if s.len() != 3 || s[1] % 2 != 0 {
        return Err(shape_error(what, "[B, 2F, C]", g));
    }
    Ok(((s[0] * s[1] / 2) as usize, s[2] as usize))
}

fn fused_ok(g: &Tensor) -> bool {
    g.device() == Device::Cpu && matches!(g.kind(), Kind::Float | Kind::Double)
}

fn first(inputs: &[Tensor], i: usize, op: &str) -> Result<Tensor> {
    inputs
        .get(i)
        .map(Tensor::detach)
        .ok_or_else(|| KernelError::CustomOp {
            op: op.to_owned(),
            message: format!("missing input {i}"),
        })
}

// ---------------------------------------------------------------- modulation

/// Reference (torch) modulation: `g * scale * exp(i phase)` with
/// `phase = ps[..., :C]`, `scale = softplus(ps[..., C:]) + 1e-8`.
pub fn modulate_reference(g: &Tensor, ps: &Tensor) -> Tensor {
    let s = g.size();
    let (b, rows, c) = (s[0], s[1], s[2]);
    let phase = ps.narrow(-1, 0, c);
    let scale = ps.narrow(-1, c, c).softplus() + SCALE_EPS;
    let z = g.reshape([b, rows / 2, 2, c]);
    let (re, im) = (z.select(2, 0), z.select(2, 1));
    let cs = phase.cos() * &scale;
    let sn = phase.sin() * &scale;
    let out_re = &cs * &re - &sn * &im;
    let out_im = &sn * &re + &cs * &im;
    Tensor::stack(&[out_re, out_im], 2).reshape([b, rows, c])
}

struct Modulate {
    saved: Option<ModulateSaved>,
}

struct ModulateSaved {
    g: Tensor,
    /// `cos(phase)`, `sin(phase)`, `softplus(raw scale)` (without the eps),
    /// the raw scale.
    cos: Tensor,
    sin: Tensor,
    softplus: Tensor,
    raw: Tensor,
}

fn modulate_forward<T: Scalar>(g: &Tensor, s: &ModulateSaved, out: &Tensor, n: usize, c: usize) {
    // SAFETY: contiguous CPU tensors of type T made by the caller; `out` is
    // only written through disjoint rows.
    let (gs, cs, sn, sp) = unsafe {
        (
            data::<T>(g),
            data::<T>(&s.cos),
            data::<T>(&s.sin),
            data::<T>(&s.softplus),
        )
    };
    let eps = T::from_f64(SCALE_EPS);
    let o = ptr::<T>(out);
    parallel_for(n, GRAIN, &|begin, end| {
        for i in begin..end {
            let (lo, mid, hi) = (2 * i * c, (2 * i + 1) * c, (2 * i + 2) * c);
            let (re, im) = (&gs[lo..mid], &gs[mid..hi]);
            let (co, si, sc) = (
                &cs[i * c..(i + 1) * c],
                &sn[i * c..(i + 1) * c],
                &sp[i * c..(i + 1) * c],
            );
            // SAFETY: rows 2i, 2i + 1 belong to this chunk.
            let (or, oi) = unsafe { (o.row(2 * i, c), o.row(2 * i + 1, c)) };
            for k in 0..c {
                let scale = sc[k] + eps;
                let (ar, ai) = (scale * co[k], scale * si[k]);
                or[k] = ar * re[k] - ai * im[k];
                oi[k] = ai * re[k] + ar * im[k];
            }
        }
    });
}

fn modulate_backward<T: Scalar>(
    grad: &Tensor,
    s: &ModulateSaved,
    sig: &Tensor,
    grad_g: &Tensor,
    grad_ps: &Tensor,
    n: usize,
    c: usize,
) {
    // SAFETY: contiguous CPU tensors of type T; outputs written by disjoint rows.
    let (gr, gs, cs, sn, sp, sg) = unsafe {
        (
            data::<T>(grad),
            data::<T>(&s.g),
            data::<T>(&s.cos),
            data::<T>(&s.sin),
            data::<T>(&s.softplus),
            data::<T>(sig),
        )
    };
    let eps = T::from_f64(SCALE_EPS);
    let (og, op) = (ptr::<T>(grad_g), ptr::<T>(grad_ps));
    parallel_for(n, GRAIN, &|begin, end| {
        for i in begin..end {
            let (lo, mid, hi) = (2 * i * c, (2 * i + 1) * c, (2 * i + 2) * c);
            let (dre, dim) = (&gr[lo..mid], &gr[mid..hi]);
            let (re, im) = (&gs[lo..mid], &gs[mid..hi]);
            let row = i * c..(i + 1) * c;
            let (co, si, sc, sgm) = (
                &cs[row.clone()],
                &sn[row.clone()],
                &sp[row.clone()],
                &sg[row],
            );
            // SAFETY: rows 2i, 2i + 1 of grad_g and row i of grad_ps (2c wide)
            // belong to this chunk.
            let (ogr, ogi, ops) =
                unsafe { (og.row(2 * i, c), og.row(2 * i + 1, c), op.row(i, 2 * c)) };
            let (dphase, dscale) = ops.split_at_mut(c);
            for k in 0..c {
                let scale = sc[k] + eps;
                let (ar, ai) = (scale * co[k], scale * si[k]);
                // out = m g: dg = conj(m) dout, dm = dout conj(g)
                ogr[k] = ar * dre[k] + ai * dim[k];
                ogi[k] = ar * dim[k] - ai * dre[k];
                let dmr = dre[k] * re[k] + dim[k] * im[k];
                let dmi = dim[k] * re[k] - dre[k] * im[k];
                // m = scale (cos + i sin), scale = softplus(raw) + eps
                dphase[k] = dmi * ar - dmr * ai;
                dscale[k] = (dmr * co[k] + dmi * si[k]) * sgm[k];
            }
        }
    });
}

impl CustomFunction for Modulate {
    fn name(&self) -> &str {
        "modulate"
    }

    fn forward(&mut self, inputs: &[Tensor]) -> Result<Vec<Tensor>> {
        let g = first(inputs, 0, "modulate")?.contiguous();
        let ps = first(inputs, 1, "modulate")?;
        let (n, c) = face_dims(&g, "modulate")?;
        let ci = c as i64;
        // contiguous halves first: torch's transcendental kernels are several
        // times slower on strided views
        let phase = ps.narrow(-1, 0, ci).contiguous();
        let raw = ps.narrow(-1, ci, ci).contiguous();
        let saved = ModulateSaved {
            cos: phase.cos(),
            sin: phase.sin(),
            softplus: raw.softplus(),
            raw,
            g,
        };
        let out = Tensor::empty(saved.g.size().as_slice(), (saved.g.kind(), Device::Cpu));
        match saved.g.kind() {
            Kind::Double => modulate_forward::<f64>(&saved.g, &saved, &out, n, c),
            _ => modulate_forward::<f32>(&saved.g, &saved, &out, n, c),
        }
        self.saved = Some(saved);
        Ok(vec![out])
    }

    fn backward(&mut self, grad_outputs: &[Tensor]) -> Result<Vec<Option<Tensor>>> {
        let s = self
            .saved
            .as_ref()
            .ok_or_else(|| backward_before_forward("modulate"))?;
        let grad = first(grad_outputs, 0, "modulate")?.contiguous();
        let (n, c) = face_dims(&s.g, "modulate")?;
        let gs = s.g.size();
        let opts = (s.g.kind(), Device::Cpu);
        let sig = s.raw.sigmoid();
        let grad_g = Tensor::empty(gs.as_slice(), opts);
        let grad_ps = Tensor::empty([gs[0], gs[1] / 2, 2 * c as i64], opts);
        match s.g.kind() {
            Kind::Double => modulate_backward::<f64>(&grad, s, &sig, &grad_g, &grad_ps, n, c),
            _ => modulate_backward::<f32>(&grad, s, &sig, &grad_g, &grad_ps, n, c),
        }
        Ok(vec![Some(grad_g), Some(grad_ps)])
    }
}

/// Modulation `g <- g * scale * exp(i phase)` per face and channel, with
/// `phase = ps[..., :C]` and `scale = softplus(ps[..., C:]) + 1e-8`.
///
/// `g: [B, 2F, C]`, `ps: [B, F, 2C]`; returns `[B, 2F, C]`. Fused on the CPU
/// (one pass over `g` forward and one backward); first derivatives only.
pub fn modulate(g: &Tensor, ps: &Tensor) -> Result<Tensor> {
    let (n, c) = face_dims(g, "modulate")?;
    let s = ps.size();
    if s.len() != 3 || (s[0] * s[1]) as usize != n || s[2] != 2 * c as i64 || ps.kind() != g.kind()
    {
        return Err(shape_error(
            "modulation parameters",
            format!("[B, F, 2C={}] like g", 2 * c),
            ps,
        ));
    }
    if !fused_ok(g) || ps.device() != g.device() {
        return Ok(modulate_reference(g, ps));
    }
    let mut out = if g.kind() == Kind::Float {
        apply_custom(Modulate32 { saved: None }, &[g, ps])?
    } else {
        apply_custom(Modulate { saved: None }, &[g, ps])?
    };
    Ok(out.remove(0))
}

// ----------------------------------------------------- magnitude nonlinearity

/// Reference (torch) magnitude nonlinearity `z -> GELU(|z| + b) z / |z|`,
/// `|z| = sqrt(re^2 + im^2 + 1e-8)`, on `[B, 2F, C]`; `bias` is `[C]`.
pub fn magnitude_gelu_reference(g: &Tensor, bias: &Tensor) -> Tensor {
    let s = g.size();
    let (b, rows, c) = (s[0], s[1], s[2]);
    let z = g.reshape([b, rows / 2, 2, c]);
    let mag = (z
        .square()
        .sum_dim_intlist([2i64].as_slice(), true, z.kind())
        + MAGNITUDE_EPS)
        .sqrt();
    let a = (&mag + bias).gelu("none");
    (z * (a / mag)).reshape([b, rows, c])
}

struct MagnitudeGelu {
    saved: Option<MagnitudeSaved>,
}

struct MagnitudeSaved {
    g: Tensor,
    mag: Tensor,
    /// `|z| + b`, the GELU's argument.
    pre: Tensor,
    /// `GELU(|z| + b) / |z|`.
    ratio: Tensor,
}

fn magnitude<T: Scalar>(g: &Tensor, mag: &Tensor, n: usize, c: usize) {
    // SAFETY: contiguous CPU tensors of type T; `mag` written by disjoint rows.
    let gs = unsafe { data::<T>(g) };
    let m = ptr::<T>(mag);
    let eps = T::from_f64(MAGNITUDE_EPS);
    parallel_for(n, GRAIN, &|begin, end| {
        for i in begin..end {
            let (re, im) = (
                &gs[2 * i * c..(2 * i + 1) * c],
                &gs[(2 * i + 1) * c..(2 * i + 2) * c],
            );
            // SAFETY: row i belongs to this chunk.
            let out = unsafe { m.row(i, c) };
            for k in 0..c {
                out[k] = (re[k] * re[k] + im[k] * im[k] + eps).square_root();
            }
        }
    });
}

/// `out = g * ratio` (ratio broadcast over the two components).
fn scale_rows<T: Scalar>(g: &Tensor, ratio: &Tensor, out: &Tensor, n: usize, c: usize) {
    // SAFETY: as in `magnitude`.
    let (gs, rs) = unsafe { (data::<T>(g), data::<T>(ratio)) };
    let o = ptr::<T>(out);
    parallel_for(n, GRAIN, &|begin, end| {
        for i in begin..end {
            let r = &rs[i * c..(i + 1) * c];
            for row in [2 * i, 2 * i + 1] {
                let x = &gs[row * c..(row + 1) * c];
                // SAFETY: rows 2i, 2i + 1 belong to this chunk.
                let y = unsafe { o.row(row, c) };
                for k in 0..c {
                    y[k] = x[k] * r[k];
                }
            }
        }
    });
}

/// First backward pass: `s = (dout . z) / |z|` per face and channel (the
/// derivative with respect to `a = GELU(|z| + b)`).
fn project<T: Scalar>(grad: &Tensor, s: &MagnitudeSaved, out: &Tensor, n: usize, c: usize) {
    // SAFETY: as in `magnitude`.
    let (gr, gs, ms) = unsafe { (data::<T>(grad), data::<T>(&s.g), data::<T>(&s.mag)) };
    let o = ptr::<T>(out);
    parallel_for(n, GRAIN, &|begin, end| {
        for i in begin..end {
            let (dre, dim) = (
                &gr[2 * i * c..(2 * i + 1) * c],
                &gr[(2 * i + 1) * c..(2 * i + 2) * c],
            );
            let (re, im) = (
                &gs[2 * i * c..(2 * i + 1) * c],
                &gs[(2 * i + 1) * c..(2 * i + 2) * c],
            );
            let m = &ms[i * c..(i + 1) * c];
            // SAFETY: row i belongs to this chunk.
            let y = unsafe { o.row(i, c) };
            for k in 0..c {
                y[k] = (dre[k] * re[k] + dim[k] * im[k]) / m[k];
            }
        }
    });
}

/// Second backward pass: `dz = dout * ratio + (dpre - s * ratio) z / |z|`,
/// where `dpre` is the gradient reaching `|z|` through the GELU.
fn combine<T: Scalar>(
    grad: &Tensor,
    s: &MagnitudeSaved,
    sproj: &Tensor,
    dpre: &Tensor,
    out: &Tensor,
    n: usize,
    c: usize,
) {
    // SAFETY: as in `magnitude`.
    let (gr, gs, ms, rs, ss, ds) = unsafe {
        (
            data::<T>(grad),
            data::<T>(&s.g),
            data::<T>(&s.mag),
            data::<T>(&s.ratio),
            data::<T>(sproj),
            data::<T>(dpre),
        )
    };
    let o = ptr::<T>(out);
    parallel_for(n, GRAIN, &|begin, end| {
        for i in begin..end {
            let (m, r, sp, dp) = (
                &ms[i * c..(i + 1) * c],
                &rs[i * c..(i + 1) * c],
                &ss[i * c..(i + 1) * c],
                &ds[i * c..(i + 1) * c],
            );
            for row in [2 * i, 2 * i + 1] {
                let (d, z) = (&gr[row * c..(row + 1) * c], &gs[row * c..(row + 1) * c]);
                // SAFETY: rows 2i, 2i + 1 belong to this chunk.
                let y = unsafe { o.row(row, c) };
                for k in 0..c {
                    // d|z|/dz = z / |z|; the ratio a/|z| contributes -s a/|z|^2 = -s ratio/|z|
                    y[k] = d[k] * r[k] + (dp[k] - sp[k] * r[k]) * z[k] / m[k];
                }
            }
        }
    });
}

impl CustomFunction for MagnitudeGelu {
    fn name(&self) -> &str {
        "magnitude_gelu"
    }

    fn forward(&mut self, inputs: &[Tensor]) -> Result<Vec<Tensor>> {
        let g = first(inputs, 0, "magnitude_gelu")?.contiguous();
        let bias = first(inputs, 1, "magnitude_gelu")?;
        let (n, c) = face_dims(&g, "magnitude_gelu")?;
        let gsz = g.size();
        let opts = (g.kind(), Device::Cpu);
        let mag = Tensor::empty([gsz[0], gsz[1] / 2, gsz[2]], opts);
        match g.kind() {
            Kind::Double => magnitude::<f64>(&g, &mag, n, c),
            _ => magnitude::<f32>(&g, &mag, n, c),
        }
        let pre = &mag + &bias;
        let ratio = (pre.gelu("none") / &mag).contiguous();
        let out = Tensor::empty(gsz.as_slice(), opts);
        match g.kind() {
            Kind::Double => scale_rows::<f64>(&g, &ratio, &out, n, c),
            _ => scale_rows::<f32>(&g, &ratio, &out, n, c),
        }
        self.saved = Some(MagnitudeSaved { g, mag, pre, ratio });
        Ok(vec![out])
    }

    fn backward(&mut self, grad_outputs: &[Tensor]) -> Result<Vec<Option<Tensor>>> {
        let s = self
            .saved
            .as_ref()
            .ok_or_else(|| backward_before_forward("magnitude_gelu"))?;
        let grad = first(grad_outputs, 0, "magnitude_gelu")?.contiguous();
        let (n, c) = face_dims(&s.g, "magnitude_gelu")?;
        let opts = (s.g.kind(), Device::Cpu);
        let sproj = Tensor::empty(s.mag.size().as_slice(), opts);
        match s.g.kind() {
            Kind::Double => project::<f64>(&grad, s, &sproj, n, c),
            _ => project::<f32>(&grad, s, &sproj, n, c),
        }
        // through the GELU: d(pre) = GELU'(pre) * s
        let dpre = s.pre.gelu_backward(&sproj, "none").contiguous();
        let grad_bias = dpre.sum_dim_intlist([0i64, 1].as_slice(), false, dpre.kind());
        let grad_g = Tensor::empty(s.g.size().as_slice(), opts);
        match s.g.kind() {
            Kind::Double => combine::<f64>(&grad, s, &sproj, &dpre, &grad_g, n, c),
            _ => combine::<f32>(&grad, s, &sproj, &dpre, &grad_g, n, c),
        }
        Ok(vec![Some(grad_g), Some(grad_bias)])
    }
}

/// Magnitude nonlinearity `z -> GELU(|z| + b) z / |z|` per face and channel,
/// `|z| = sqrt(re^2 + im^2 + 1e-8)`, on `g: [B, 2F, C]` with `bias: [C]`.
/// Fused on the CPU (two passes over `g` forward, two backward); first
/// derivatives only.
pub fn magnitude_gelu(g: &Tensor, bias: &Tensor) -> Result<Tensor> {
    let (_, c) = face_dims(g, "magnitude nonlinearity")?;
    if bias.size() != [c as i64] || bias.kind() != g.kind() {
        return Err(shape_error(
            "magnitude nonlinearity bias",
            format!("[C={c}] like g"),
            bias,
        ));
    }
    if !fused_ok(g) || bias.device() != g.device() {
        return Ok(magnitude_gelu_reference(g, bias));
    }
    let mut out = if g.kind() == Kind::Float {
        apply_custom(Magnitude32 { saved: None }, &[g, bias])?
    } else {
        apply_custom(MagnitudeGelu { saved: None }, &[g, bias])?
    };
    Ok(out.remove(0))
}

// ------------------------------------------------------- single-pass f32 path
//
// For f32 (the training type) each operation is one pass forward and one
// backward, with the transcendental functions evaluated in the kernel by the
// vectorizable approximations of `crate::fastmath` (the loops compile twice,
// with and without AVX2, chosen at run time). Nothing but the inputs is saved
// for the backward pass, which recomputes the rest.

use crate::fastmath::{self, Fused, MulAdd, Separate};

/// Defines `$name::<M>` (the kernel, generic over how the polynomials
/// multiply-add) and `$avx`, the kernel compiled for AVX2 and FMA with fused
/// multiply-adds.
macro_rules! simd_kernel {
    ($name:ident, $avx:ident, ($($arg:ident: $ty:ty),*), $body:block) => {
        #[inline(always)]
        #[allow(clippy::too_many_arguments)]
        fn $name<M: MulAdd>($($arg: $ty),*) $body

        #[cfg(target_arch = "x86_64")]
        #[target_feature(enable = "avx2,fma")]
        #[allow(clippy::too_many_arguments)]
        unsafe fn $avx($($arg: $ty),*) {
            $name::<Fused>($($arg),*)
        }
    };
}

/// Calls the AVX2 + FMA variant when the CPU has both, the portable one
/// (separate multiplications and additions) otherwise.
macro_rules! simd_call {
    ($name:ident, $avx:ident, ($($arg:expr),*)) => {{
        #[cfg(target_arch = "x86_64")]
        {
            if std::arch::is_x86_feature_detected!("avx2")
                && std::arch::is_x86_feature_detected!("fma")
            {
                // SAFETY: the CPU supports AVX2 and FMA (checked above).
                unsafe { $avx($($arg),*) }
            } else {
                $name::<Separate>($($arg),*)
            }
        }
        #[cfg(not(target_arch = "x86_64"))]
        {
            $name::<Separate>($($arg),*)
        }
    }};
}

simd_kernel!(mod32_fwd_rows, mod32_fwd_rows_avx2, (gs: &[f32], pss: &[f32], o: SyncPtr<f32>, begin: usize, end: usize, c: usize), {
    let eps = SCALE_EPS as f32;
    for i in begin..end {
        let (re, im) = (&gs[2 * i * c..(2 * i + 1) * c], &gs[(2 * i + 1) * c..(2 * i + 2) * c]);
        let (ph, raw) = (&pss[2 * i * c..(2 * i + 1) * c], &pss[(2 * i + 1) * c..(2 * i + 2) * c]);
        // SAFETY: rows 2i, 2i + 1 belong to the caller's chunk.
        let (or, oi) = unsafe { (o.row(2 * i, c), o.row(2 * i + 1, c)) };
        // zipped iterators: no bounds checks, so the loop vectorizes whole
        let ins = re.iter().zip(im).zip(ph.iter().zip(raw));
        for (((&r, &m), (&p, &q)), (o_r, o_i)) in ins.zip(or.iter_mut().zip(oi.iter_mut())) {
            let (s, co) = fastmath::sincos::<M>(p);
            let scale = fastmath::softplus::<M>(q) + eps;
            let (ar, ai) = (scale * co, scale * s);
            *o_r = ar * r - ai * m;
            *o_i = ai * r + ar * m;
        }
    }
});

simd_kernel!(mod32_bwd_rows, mod32_bwd_rows_avx2, (gr: &[f32], gs: &[f32], pss: &[f32], og: SyncPtr<f32>, op: SyncPtr<f32>, begin: usize, end: usize, c: usize), {
    let eps = SCALE_EPS as f32;
    for i in begin..end {
        let (lo, mid, hi) = (2 * i * c, (2 * i + 1) * c, (2 * i + 2) * c);
        let (dre, dim) = (&gr[lo..mid], &gr[mid..hi]);
        let (re, im) = (&gs[lo..mid], &gs[mid..hi]);
        let (ph, raw) = (&pss[lo..mid], &pss[mid..hi]);
        // SAFETY: rows 2i, 2i + 1 of grad_g and row i of grad_ps (2c wide)
        // belong to the caller's chunk.
        let (ogr, ogi, ops) = unsafe { (og.row(2 * i, c), og.row(2 * i + 1, c), op.row(i, 2 * c)) };
        let (dphase, dscale) = ops.split_at_mut(c);
        let ins = (dre.iter().zip(dim)).zip(re.iter().zip(im)).zip(ph.iter().zip(raw));
        let outs = (ogr.iter_mut().zip(ogi.iter_mut())).zip(dphase.iter_mut().zip(dscale.iter_mut()));
        for ((((&dr, &di), (&r, &m)), (&p, &q)), ((o_r, o_i), (o_p, o_s))) in ins.zip(outs) {
            let (s, co) = fastmath::sincos::<M>(p);
            let scale = fastmath::softplus::<M>(q) + eps;
            let (ar, ai) = (scale * co, scale * s);
            *o_r = ar * dr + ai * di;
            *o_i = ar * di - ai * dr;
            let dmr = dr * r + di * m;
            let dmi = di * r - dr * m;
            *o_p = dmi * ar - dmr * ai;
            *o_s = (dmr * co + dmi * s) * fastmath::sigmoid::<M>(q);
        }
    }
});

struct Modulate32 {
    saved: Option<(Tensor, Tensor)>,
}

impl CustomFunction for Modulate32 {
    fn name(&self) -> &str {
        "modulate"
    }

    fn forward(&mut self, inputs: &[Tensor]) -> Result<Vec<Tensor>> {
        let g = first(inputs, 0, "modulate")?.contiguous();
        let ps = first(inputs, 1, "modulate")?.contiguous();
        let (n, c) = face_dims(&g, "modulate")?;
        let out = Tensor::empty(g.size().as_slice(), (Kind::Float, Device::Cpu));
        // SAFETY: contiguous CPU f32 tensors; `out` written by disjoint rows.
        let (gs, pss) = unsafe { (data::<f32>(&g), data::<f32>(&ps)) };
        let o = ptr::<f32>(&out);
        parallel_for(n, GRAIN, &|begin, end| {
            simd_call!(
                mod32_fwd_rows,
                mod32_fwd_rows_avx2,
                (gs, pss, o, begin, end, c)
            )
        });
        self.saved = Some((g, ps));
        Ok(vec![out])
    }

    fn backward(&mut self, grad_outputs: &[Tensor]) -> Result<Vec<Option<Tensor>>> {
        let (g, ps) = self
            .saved
            .as_ref()
            .ok_or_else(|| backward_before_forward("modulate"))?;
        let grad = first(grad_outputs, 0, "modulate")?.contiguous();
        let (n, c) = face_dims(g, "modulate")?;
        let opts = (Kind::Float, Device::Cpu);
        let grad_g = Tensor::empty(g.size().as_slice(), opts);
        let grad_ps = Tensor::empty(ps.size().as_slice(), opts);
        // SAFETY: contiguous CPU f32 tensors; outputs written by disjoint rows.
        let (gr, gs, pss) = unsafe { (data::<f32>(&grad), data::<f32>(g), data::<f32>(ps)) };
        let (og, op) = (ptr::<f32>(&grad_g), ptr::<f32>(&grad_ps));
        parallel_for(n, GRAIN, &|begin, end| {
            simd_call!(
                mod32_bwd_rows,
                mod32_bwd_rows_avx2,
                (gr, gs, pss, og, op, begin, end, c)
            )
        });
        Ok(vec![Some(grad_g), Some(grad_ps)])
    }
}

simd_kernel!(mag32_fwd_rows, mag32_fwd_rows_avx2, (gs: &[f32], bias: &[f32], o: SyncPtr<f32>, begin: usize, end: usize, c: usize), {
    let eps = MAGNITUDE_EPS as f32;
    for i in begin..end {
        let (re, im) = (&gs[2 * i * c..(2 * i + 1) * c], &gs[(2 * i + 1) * c..(2 * i + 2) * c]);
        // SAFETY: rows 2i, 2i + 1 belong to the caller's chunk.
        let (or, oi) = unsafe { (o.row(2 * i, c), o.row(2 * i + 1, c)) };
        let ins = re.iter().zip(im).zip(bias);
        for (((&x, &y), &b), (o_r, o_i)) in ins.zip(or.iter_mut().zip(oi.iter_mut())) {
            let m = (x * x + y * y + eps).sqrt();
            let r = fastmath::gelu::<M>(m + b) / m;
            *o_r = x * r;
            *o_i = y * r;
        }
    }
});

simd_kernel!(mag32_bwd_rows, mag32_bwd_rows_avx2, (gr: &[f32], gs: &[f32], bias: &[f32], og: SyncPtr<f32>, gb: &mut [f32], begin: usize, end: usize, c: usize), {
    let eps = MAGNITUDE_EPS as f32;
    for i in begin..end {
        let (lo, mid, hi) = (2 * i * c, (2 * i + 1) * c, (2 * i + 2) * c);
        let (dre, dim) = (&gr[lo..mid], &gr[mid..hi]);
        let (re, im) = (&gs[lo..mid], &gs[mid..hi]);
        // SAFETY: rows 2i, 2i + 1 belong to the caller's chunk.
        let (ogr, ogi) = unsafe { (og.row(2 * i, c), og.row(2 * i + 1, c)) };
        let ins = (dre.iter().zip(dim)).zip(re.iter().zip(im)).zip(bias);
        let outs = ogr.iter_mut().zip(ogi.iter_mut()).zip(gb.iter_mut());
        for ((((&dr, &di), (&x, &y)), &b), ((o_r, o_i), g_b)) in ins.zip(outs) {
            let m = (x * x + y * y + eps).sqrt();
            let inv_m = 1.0 / m;
            let (a, da) = fastmath::gelu_with_grad::<M>(m + b);
            let r = a * inv_m;
            // s = dL/da, dpre = dL/d(|z| + b), dm = total dL/d|z|
            let s = (dr * x + di * y) * inv_m;
            let dpre = da * s;
            let dm = (dpre - s * r) * inv_m;
            *o_r = dr * r + dm * x;
            *o_i = di * r + dm * y;
            *g_b += dpre;
        }
    }
});

/// Rows per block of the bias-gradient reduction (fixed, so the sum's order
/// does not depend on the thread count).
const BIAS_BLOCK: usize = 512;

struct Magnitude32 {
    saved: Option<(Tensor, Tensor)>,
}

impl CustomFunction for Magnitude32 {
    fn name(&self) -> &str {
        "magnitude_gelu"
    }

    fn forward(&mut self, inputs: &[Tensor]) -> Result<Vec<Tensor>> {
        let g = first(inputs, 0, "magnitude_gelu")?.contiguous();
        let bias = first(inputs, 1, "magnitude_gelu")?.contiguous();
        let (n, c) = face_dims(&g, "magnitude_gelu")?;
        let out = Tensor::empty(g.size().as_slice(), (Kind::Float, Device::Cpu));
        // SAFETY: contiguous CPU f32 tensors; `out` written by disjoint rows.
        let (gs, bs) = unsafe { (data::<f32>(&g), data::<f32>(&bias)) };
        let o = ptr::<f32>(&out);
        parallel_for(n, GRAIN, &|begin, end| {
            simd_call!(
                mag32_fwd_rows,
                mag32_fwd_rows_avx2,
                (gs, bs, o, begin, end, c)
            )
        });
        self.saved = Some((g, bias));
        Ok(vec![out])
    }

    fn backward(&mut self, grad_outputs: &[Tensor]) -> Result<Vec<Option<Tensor>>> {
        let (g, bias) = self
            .saved
            .as_ref()
            .ok_or_else(|| backward_before_forward("magnitude_gelu"))?;
        let grad = first(grad_outputs, 0, "magnitude_gelu")?.contiguous();
        let (n, c) = face_dims(g, "magnitude_gelu")?;
        let grad_g = Tensor::empty(g.size().as_slice(), (Kind::Float, Device::Cpu));
        // SAFETY: contiguous CPU f32 tensors; outputs written by disjoint rows.
        let (gr, gs, bs) = unsafe { (data::<f32>(&grad), data::<f32>(g), data::<f32>(bias)) };
        let og = ptr::<f32>(&grad_g);
        let blocks = n.div_ceil(BIAS_BLOCK);
        let mut partial = vec![0.0f32; blocks * c];
        let pp = SyncPtr(partial.as_mut_ptr());
        parallel_for(blocks, 1, &|b0, b1| {
            for blk in b0..b1 {
                // SAFETY: block `blk` owns its partial row.
                let gb = unsafe { pp.row(blk, c) };
                let (begin, end) = (blk * BIAS_BLOCK, ((blk + 1) * BIAS_BLOCK).min(n));
                simd_call!(
                    mag32_bwd_rows,
                    mag32_bwd_rows_avx2,
                    (gr, gs, bs, og, gb, begin, end, c)
                );
            }
        });
        let mut gb = vec![0.0f32; c];
        for row in partial.chunks(c.max(1)) {
            for (x, &y) in gb.iter_mut().zip(row) {
                *x += y;
            }
        }
        Ok(vec![Some(grad_g), Some(Tensor::from_slice(&gb))])
    }
}
