#![doc = include_str!("../README.md")]

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
