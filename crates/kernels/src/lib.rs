//! # mfm-kernels
//!
//! The tensor operations under PoissonNet (`mfm-net`), on libtorch through
//! `tch`: Rust kernels that run as autograd nodes, and one mesh's
//! operators as differentiable tensor operations. The network's layers
//! live in `mfm-net` and call into this crate, so a reader finds the math
//! of a layer there and the machinery that makes it fast here.
//!
//! ## Modules
//! - [`autograd`]: custom autograd operations in Rust
//!   ([`autograd::apply_custom`], [`autograd::apply_linear`]) through a
//!   small C++ shim compiled by this crate's build script, and
//!   [`autograd::parallel_for`] on libtorch's intra-op threads.
//! - [`mesh`]: [`MeshTensors`], one mesh's `G`, `G^T`, face means, mass
//!   means and the cached Cholesky factor of `L + eps I` as differentiable
//!   operations.
//! - [`dense`]: `linear` and the complex layers' products on faer's GEMM
//!   (three real products per complex one from 64 channels), as autograd
//!   nodes, with the product counter the cost model is tested against.
//! - [`fused`]: single-pass modulation and magnitude-nonlinearity kernels
//!   (and the torch graphs they replace, as references and as the path on
//!   other devices).
//! - `gather` (private): the mesh operators' gather kernels (`G`,
//!   `G^T A2`, face means, the paired divergence), AVX2 + FMA dispatch and
//!   prefetch; `fastmath` (private): the vectorizable `f32`
//!   approximations the fused kernels use.
//! - [`profile`]: per-section timers; [`runtime`]: what the linked
//!   libtorch offers (threads, CUDA, the allocator setting);
//!   [`error`]: [`KernelError`], the one error type of this crate
//!   (`mfm-net`'s `NetError` wraps it).
//!
//! All kernels write disjoint output rows from libtorch's intra-op threads
//! through the one pointer wrapper `SyncPtr`, and are generic over the one
//! element trait `Scalar` (`f32`, `f64`). Results do not depend on the
//! number of threads.
//!
//! This crate links the libtorch 2.13 shared libraries of the project's
//! Python environment (see `cargo xtask setup`); its build script embeds an
//! rpath so binaries run without `LD_LIBRARY_PATH` and passes the library
//! folder on to dependent crates (`DEP_MFM_KERNELS_LIBTORCH_LIB`).

pub mod autograd;
pub mod dense;
pub mod error;
mod fastmath;
pub mod fused;
mod gather;
pub mod mesh;
pub mod profile;
pub mod runtime;

pub use error::{KernelError, Result};
pub use mesh::{Backend, MeshTensors};

/// The element types the kernels run on: `f32` and `f64`.
pub(crate) trait Scalar:
    faer::traits::ComplexField<Canonical = Self>
    + Copy
    + Send
    + Sync
    + Default
    + std::ops::Mul<Output = Self>
    + std::ops::Add<Output = Self>
    + std::ops::Sub<Output = Self>
    + std::ops::Div<Output = Self>
    + std::ops::Neg<Output = Self>
    + std::ops::AddAssign
    + 'static
{
    /// `x` rounded to this type.
    fn from_f64(x: f64) -> Self;
    /// The square root.
    fn square_root(self) -> Self;
}

impl Scalar for f32 {
    fn from_f64(x: f64) -> Self {
        x as f32
    }
    fn square_root(self) -> Self {
        f32::sqrt(self)
    }
}

impl Scalar for f64 {
    fn from_f64(x: f64) -> Self {
        x
    }
    fn square_root(self) -> Self {
        f64::sqrt(self)
    }
}

/// A raw pointer to a kernel's output that may cross threads: each parallel
/// chunk writes only its own rows (or its own partial buffer).
#[derive(Clone, Copy)]
pub(crate) struct SyncPtr<T>(pub(crate) *mut T);

// SAFETY: kernels only write disjoint index ranges from `parallel_for` chunks.
unsafe impl<T> Send for SyncPtr<T> {}
// SAFETY: as above.
unsafe impl<T> Sync for SyncPtr<T> {}

impl<T> SyncPtr<T> {
    /// The pointer (a method, so closures capture the `Sync` wrapper).
    pub(crate) fn get(self) -> *mut T {
        self.0
    }

    /// Row `i` of width `w`.
    ///
    /// # Safety
    /// The row must be in bounds and not aliased by another live slice.
    #[allow(clippy::mut_from_ref)]
    pub(crate) unsafe fn row(&self, i: usize, w: usize) -> &mut [T] {
        // SAFETY: guaranteed by the caller.
        unsafe { std::slice::from_raw_parts_mut(self.0.add(i * w), w) }
    }
}
