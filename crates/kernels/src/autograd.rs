//! Autograd operations implemented in Rust.
//!
//! tch exposes no way to define a custom autograd `Function` in Rust. This
//! crate compiles a small C++ shim (`csrc/mfm_autograd.cpp`, built by the
//! crate's build script against the headers of the linked libtorch) that
//! defines one `torch::autograd::Function` whose forward and backward call
//! back into Rust through function pointers. The per-call Rust state (any
//! [`CustomFunction`]) is owned by the autograd node and dropped with it.
//!
//! ## Why a shim rather than splitting the graph
//! The alternative, cutting the graph at every solve and chaining the backward
//! pass segment by segment by hand, needs a driver that knows the whole graph:
//! it breaks as soon as a solve sits inside a user's loss, a second network, a
//! `torch::autograd::grad` call or a graph with several solves feeding each
//! other. With a real autograd node the solve is an ordinary operation: any
//! graph, any number of solves per forward pass, batches sharing one factor,
//! different meshes in one loss, `retain_graph`, and second derivatives (the
//! backward of a [`LinearOperator`] is again a [`LinearOperator`] node) work
//! without special cases. The cost is one small C++ file compiled once
//! (30-50 s on the 2-core machine, only when the file changes) against the
//! headers libtorch ships anyway.
//!
//! ## Pieces
//! - [`CustomFunction`] + [`apply_custom`]: any forward/backward pair.
//! - [`LinearOperator`] + [`apply_linear`]: a linear map `A` whose backward is
//!   the adjoint `A^T` (the Poisson solve, `G`, `G^T`, face means). Its
//!   backward is recorded again, so gradients of gradients work.
//! - [`parallel_for`]: runs a Rust closure on libtorch's intra-op thread pool,
//!   so Rust kernels between torch operations do not compete with torch's
//!   spinning OpenMP workers for the cores.

use std::ffi::{c_char, c_void};
use std::mem::ManuallyDrop;
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::sync::Arc;

use tch::Tensor;
use torch_sys::C_tensor;

use crate::error::{KernelError, Result};

type ForwardFn = unsafe extern "C" fn(
    state: *mut c_void,
    inputs: *const *mut C_tensor,
    num_inputs: i64,
    outputs: *mut *mut C_tensor,
    max_outputs: i64,
    num_outputs: *mut i64,
    err: *mut c_char,
    err_len: i64,
) -> i32;

type BackwardFn = unsafe extern "C" fn(
    state: *mut c_void,
    grad_outputs: *const *mut C_tensor,
    num_grad_outputs: i64,
    grad_inputs: *mut *mut C_tensor,
    num_inputs: i64,
    err: *mut c_char,
    err_len: i64,
) -> i32;

type DropFn = unsafe extern "C" fn(state: *mut c_void);
type RangeFn = unsafe extern "C" fn(ctx: *mut c_void, begin: i64, end: i64);

unsafe extern "C" {
    fn mfm_custom_apply(
        state: *mut c_void,
        forward: ForwardFn,
        backward: BackwardFn,
        drop: DropFn,
        inputs: *const *mut C_tensor,
        num_inputs: i64,
        outputs: *mut *mut C_tensor,
        max_outputs: i64,
        num_outputs: *mut i64,
        err: *mut c_char,
        err_len: i64,
    ) -> i32;
    fn mfm_parallel_for(begin: i64, end: i64, grain: i64, f: RangeFn, ctx: *mut c_void);
    fn mfm_in_parallel_region() -> i32;
}

/// Largest number of outputs a [`CustomFunction`] may return.
pub const MAX_OUTPUTS: usize = 16;
const ERR_LEN: usize = 2048;

/// A differentiable operation written in Rust, applied with [`apply_custom`].
///
/// One value is created per call; it receives the forward inputs, may keep
/// whatever it needs for the backward pass (detached tensors, factors), and
/// is dropped when the autograd node is released. Forward runs with gradient
/// recording off; backward runs with recording on only when the caller asked
/// for a graph of the backward pass (`create_graph`), so a backward written
/// with differentiable operations supports second derivatives.
///
/// Do not keep the forward *outputs* in the state: the node owns the state
/// and the outputs point to the node, which would make a reference cycle.
pub trait CustomFunction: Send + 'static {
    /// A short name used in error messages.
    fn name(&self) -> &str;

    /// Computes the outputs (at least one, at most [`MAX_OUTPUTS`]).
    fn forward(&mut self, inputs: &[Tensor]) -> Result<Vec<Tensor>>;

    /// Given one gradient per output (zeros for unused outputs), returns one
    /// gradient per input, `None` for inputs that get none.
    fn backward(&mut self, grad_outputs: &[Tensor]) -> Result<Vec<Option<Tensor>>>;
}

fn write_error(msg: &str, err: *mut c_char, err_len: i64) {
    if err.is_null() || err_len <= 0 {
        return;
    }
    let bytes = msg.as_bytes();
    let n = bytes.len().min(err_len as usize - 1);
    // SAFETY: the caller passes a buffer of `err_len` bytes.
    unsafe {
        std::ptr::copy_nonoverlapping(bytes.as_ptr(), err.cast::<u8>(), n);
        *err.add(n) = 0;
    }
}

fn panic_message(p: &(dyn std::any::Any + Send)) -> String {
    if let Some(s) = p.downcast_ref::<&str>() {
        (*s).to_owned()
    } else if let Some(s) = p.downcast_ref::<String>() {
        s.clone()
    } else {
        "panic".to_owned()
    }
}

/// Shallow copies of the tensors behind `ptrs` (they share storage and
/// autograd identity with the C++ tensors).
///
/// # Safety
/// `ptrs` must hold `n` valid `at::Tensor*`.
unsafe fn borrow_tensors(ptrs: *const *mut C_tensor, n: i64) -> Vec<Tensor> {
    (0..n.max(0) as usize)
        // SAFETY: guaranteed by the caller.
        .map(|i| unsafe { Tensor::clone_from_ptr(*ptrs.add(i)) })
        .collect()
}

/// Hands a tensor to C++, which takes ownership of the `at::Tensor*`.
fn release(t: Tensor) -> *mut C_tensor {
    let mut t = ManuallyDrop::new(t);
    t.as_mut_ptr()
}

unsafe extern "C" fn forward_trampoline<F: CustomFunction>(
    state: *mut c_void,
    inputs: *const *mut C_tensor,
    num_inputs: i64,
    outputs: *mut *mut C_tensor,
    max_outputs: i64,
    num_outputs: *mut i64,
    err: *mut c_char,
    err_len: i64,
) -> i32 {
    let result = catch_unwind(AssertUnwindSafe(|| {
        // SAFETY: `state` is the `Box<F>` made by `apply_custom`, alive until `drop`.
        let f = unsafe { &mut *state.cast::<F>() };
        // SAFETY: the shim passes `num_inputs` valid tensors.
        let ins = unsafe { borrow_tensors(inputs, num_inputs) };
        let _s =
            crate::profile::enabled().then(|| crate::profile::section(format!("fn:{}", f.name())));
        let outs = f.forward(&ins)?;
        if outs.is_empty() || outs.len() > max_outputs as usize {
            return Err(KernelError::CustomOp {
                op: f.name().to_owned(),
                message: format!(
                    "forward returned {} outputs (1..={max_outputs} allowed)",
                    outs.len()
                ),
            });
        }
        Ok(outs)
    }));
    match result {
        Ok(Ok(outs)) => {
            // SAFETY: the shim passes room for `max_outputs` pointers.
            unsafe {
                *num_outputs = outs.len() as i64;
                for (i, t) in outs.into_iter().enumerate() {
                    *outputs.add(i) = release(t);
                }
            }
            0
        }
        Ok(Err(e)) => {
            write_error(&e.to_string(), err, err_len);
            1
        }
        Err(p) => {
            write_error(
                &format!("panic in forward: {}", panic_message(&*p)),
                err,
                err_len,
            );
            1
        }
    }
}

unsafe extern "C" fn backward_trampoline<F: CustomFunction>(
    state: *mut c_void,
    grad_outputs: *const *mut C_tensor,
    num_grad_outputs: i64,
    grad_inputs: *mut *mut C_tensor,
    num_inputs: i64,
    err: *mut c_char,
    err_len: i64,
) -> i32 {
    let result = catch_unwind(AssertUnwindSafe(|| {
        // SAFETY: as in `forward_trampoline`.
        let f = unsafe { &mut *state.cast::<F>() };
        // SAFETY: the shim passes `num_grad_outputs` valid tensors.
        let grads = unsafe { borrow_tensors(grad_outputs, num_grad_outputs) };
        let _s = crate::profile::enabled()
            .then(|| crate::profile::section(format!("fn:{}^T", f.name())));
        let gi = f.backward(&grads)?;
        if gi.len() != num_inputs as usize {
            return Err(KernelError::CustomOp {
                op: f.name().to_owned(),
                message: format!(
                    "backward returned {} gradients for {num_inputs} inputs",
                    gi.len()
                ),
            });
        }
        Ok(gi)
    }));
    match result {
        Ok(Ok(gi)) => {
            for (i, g) in gi.into_iter().enumerate() {
                if let Some(g) = g {
                    // SAFETY: the shim passes room for `num_inputs` pointers.
                    unsafe { *grad_inputs.add(i) = release(g) };
                }
            }
            0
        }
        Ok(Err(e)) => {
            write_error(&e.to_string(), err, err_len);
            1
        }
        Err(p) => {
            write_error(
                &format!("panic in backward: {}", panic_message(&*p)),
                err,
                err_len,
            );
            1
        }
    }
}

unsafe extern "C" fn drop_trampoline<F: CustomFunction>(state: *mut c_void) {
    // SAFETY: `state` came from `Box::into_raw` in `apply_custom` and the shim
    // drops it exactly once. A panicking `Drop` must not unwind into C++.
    let _ = catch_unwind(AssertUnwindSafe(|| {
        drop(unsafe { Box::from_raw(state.cast::<F>()) })
    }));
}

/// Applies a [`CustomFunction`] to `inputs` as one autograd node.
///
/// The outputs require gradients when gradient recording is on and some input
/// requires them; the node's backward then calls [`CustomFunction::backward`].
///
/// Errors: whatever the forward returns, wrapped by libtorch into a message
/// naming the operation.
///
/// # Example
/// ```
/// use mfm_kernels::autograd::{CustomFunction, apply_custom};
/// use tch::Tensor;
///
/// /// y = 3 x, written by hand.
/// struct Triple;
/// impl CustomFunction for Triple {
///     fn name(&self) -> &str { "triple" }
///     fn forward(&mut self, x: &[Tensor]) -> mfm_kernels::Result<Vec<Tensor>> {
///         Ok(vec![&x[0] * 3.0])
///     }
///     fn backward(&mut self, g: &[Tensor]) -> mfm_kernels::Result<Vec<Option<Tensor>>> {
///         Ok(vec![Some(&g[0] * 3.0)])
///     }
/// }
/// let x = Tensor::from_slice(&[1.0f64, 2.0]).set_requires_grad(true);
/// let y = apply_custom(Triple, &[&x]).unwrap().remove(0);
/// y.sum(tch::Kind::Double).backward();
/// assert_eq!(Vec::<f64>::try_from(x.grad()).unwrap(), vec![3.0, 3.0]);
/// ```
pub fn apply_custom<F: CustomFunction>(f: F, inputs: &[&Tensor]) -> Result<Vec<Tensor>> {
    let name = f.name().to_owned();
    let state = Box::into_raw(Box::new(f)).cast::<c_void>();
    let ptrs: Vec<*mut C_tensor> = inputs.iter().map(|t| t.as_ptr().cast_mut()).collect();
    let mut outs = [std::ptr::null_mut::<C_tensor>(); MAX_OUTPUTS];
    let mut n_out = 0i64;
    let mut err = vec![0 as c_char; ERR_LEN];
    // SAFETY: the pointers are valid for the call; the shim takes ownership of
    // `state` (releasing it through `drop_trampoline`) and hands back
    // `n_out` fresh tensors.
    let rc = unsafe {
        mfm_custom_apply(
            state,
            forward_trampoline::<F>,
            backward_trampoline::<F>,
            drop_trampoline::<F>,
            ptrs.as_ptr(),
            ptrs.len() as i64,
            outs.as_mut_ptr(),
            MAX_OUTPUTS as i64,
            &mut n_out,
            err.as_mut_ptr(),
            ERR_LEN as i64,
        )
    };
    if rc != 0 {
        // SAFETY: the shim NUL-terminates the buffer.
        let msg = unsafe { std::ffi::CStr::from_ptr(err.as_ptr()) }
            .to_string_lossy()
            .into_owned();
        return Err(KernelError::CustomOp {
            op: name,
            message: msg,
        });
    }
    Ok(outs[..n_out.clamp(0, MAX_OUTPUTS as i64) as usize]
        .iter()
        // SAFETY: fresh tensors owned by us from here on.
        .map(|&p| unsafe { Tensor::from_ptr(p) })
        .collect())
}

/// A linear map `A` together with its adjoint `A^T`, used as an autograd node
/// by [`apply_linear`]: the backward of `y = A x` is `dx = A^T dy`.
///
/// Implementations decide which shapes they accept and may move data to the
/// CPU and back; they must return a tensor on the input's device.
pub trait LinearOperator: Send + Sync + 'static {
    /// A short name used in error messages.
    fn name(&self) -> &str;

    /// `A x`.
    fn apply(&self, x: &Tensor) -> Result<Tensor>;

    /// `A^T y`.
    fn apply_adjoint(&self, y: &Tensor) -> Result<Tensor>;
}

struct LinearNode {
    op: Arc<dyn LinearOperator>,
    adjoint: bool,
    name: String,
}

impl CustomFunction for LinearNode {
    fn name(&self) -> &str {
        &self.name
    }

    fn forward(&mut self, inputs: &[Tensor]) -> Result<Vec<Tensor>> {
        let x = inputs.first().ok_or_else(|| KernelError::CustomOp {
            op: self.name.clone(),
            message: "no input".into(),
        })?;
        let _timer =
            crate::profile::enabled().then(|| crate::profile::section(format!("op:{}", self.name)));
        let y = if self.adjoint {
            self.op.apply_adjoint(x)?
        } else {
            self.op.apply(x)?
        };
        Ok(vec![y])
    }

    fn backward(&mut self, grad_outputs: &[Tensor]) -> Result<Vec<Option<Tensor>>> {
        let g = grad_outputs.first().ok_or_else(|| KernelError::CustomOp {
            op: self.name.clone(),
            message: "no output gradient".into(),
        })?;
        // recorded again (when create_graph is on), so the backward is itself
        // differentiable
        Ok(vec![Some(apply_linear(&self.op, g, !self.adjoint)?)])
    }
}

/// Applies `A` (or `A^T` when `adjoint`) to `x` as an autograd node whose
/// backward applies the other one.
///
/// # Example
/// ```
/// use std::sync::Arc;
/// use mfm_kernels::autograd::{LinearOperator, apply_linear};
/// use tch::{Kind, Tensor};
///
/// /// Cumulative sum (A) and reversed cumulative sum (A^T).
/// struct CumSum;
/// impl LinearOperator for CumSum {
///     fn name(&self) -> &str { "cumsum" }
///     fn apply(&self, x: &Tensor) -> mfm_kernels::Result<Tensor> { Ok(x.cumsum(0, x.kind())) }
///     fn apply_adjoint(&self, y: &Tensor) -> mfm_kernels::Result<Tensor> {
///         Ok(y.flip([0]).cumsum(0, y.kind()).flip([0]))
///     }
/// }
/// let op: Arc<dyn LinearOperator> = Arc::new(CumSum);
/// let x = Tensor::from_slice(&[1.0f64, 2.0, 3.0]).set_requires_grad(true);
/// let y = apply_linear(&op, &x, false).unwrap();
/// assert_eq!(Vec::<f64>::try_from(&y).unwrap(), vec![1.0, 3.0, 6.0]);
/// y.sum(Kind::Double).backward();
/// assert_eq!(Vec::<f64>::try_from(x.grad()).unwrap(), vec![3.0, 2.0, 1.0]);
/// ```
pub fn apply_linear(op: &Arc<dyn LinearOperator>, x: &Tensor, adjoint: bool) -> Result<Tensor> {
    let name = if adjoint {
        format!("{}^T", op.name())
    } else {
        op.name().to_owned()
    };
    let node = LinearNode {
        op: Arc::clone(op),
        adjoint,
        name,
    };
    let mut out = apply_custom(node, &[x])?;
    out.pop().ok_or_else(|| KernelError::CustomOp {
        op: op.name().to_owned(),
        message: "no output".into(),
    })
}

struct RangeCtx<'a> {
    f: &'a (dyn Fn(usize, usize) + Sync),
    panic: std::sync::Mutex<Option<String>>,
}

unsafe extern "C" fn range_trampoline(ctx: *mut c_void, begin: i64, end: i64) {
    // SAFETY: `ctx` is the `RangeCtx` of the enclosing `parallel_for` call.
    let ctx = unsafe { &*ctx.cast::<RangeCtx<'_>>() };
    let r = catch_unwind(AssertUnwindSafe(|| (ctx.f)(begin as usize, end as usize)));
    if let Err(p) = r {
        if let Ok(mut slot) = ctx.panic.lock() {
            slot.get_or_insert_with(|| panic_message(&*p));
        }
    }
}

/// Runs `f(begin, end)` over disjoint chunks covering `0..n` on libtorch's
/// intra-op thread pool (`tch::set_num_threads`), chunks of at least `grain`
/// items. Runs inline when called from inside such a region.
///
/// Panics in `f` are caught on the worker and re-raised here.
pub fn parallel_for(n: usize, grain: usize, f: &(dyn Fn(usize, usize) + Sync)) {
    if n == 0 {
        return;
    }
    // SAFETY: plain query of the shim.
    if n <= grain || unsafe { mfm_in_parallel_region() } != 0 {
        f(0, n);
        return;
    }
    let ctx = RangeCtx {
        f,
        panic: std::sync::Mutex::new(None),
    };
    // SAFETY: `ctx` outlives the call; the trampoline never unwinds.
    unsafe {
        mfm_parallel_for(
            0,
            n as i64,
            grain.max(1) as i64,
            range_trampoline,
            (&ctx as *const RangeCtx<'_>).cast_mut().cast::<c_void>(),
        );
    }
    if let Some(msg) = ctx.panic.into_inner().ok().flatten() {
        panic!("{msg}");
    }
}
