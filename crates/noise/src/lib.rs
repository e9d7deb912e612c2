//! # mfm-noise
//!
//! Triangulation-agnostic noise on triangle meshes (paper §3, DESIGN.md §4):
//! Matérn noise sampled by one screened Poisson solve (also without
//! screening, `tau = 0`, as a pseudo-inverse), its scale-normalized
//! variant, discrete white noise, naive per-vertex noise and an explicit
//! truncated-spectrum sampler, plus spectral diagnostics that measure the
//! paper's three properties (their plots are drawn by `mfm_render::plots`).
//!
//! - [`NoiseKind`]: which noise (serde, and a short `matern:100` text form).
//! - [`NoiseSampler`]: built once per mesh (operators, Cholesky factor of
//!   `L + tau M` — of `L + 1e-10 Gamma M` with the zero modes projected out
//!   when `tau = 0` — or eigenpairs), then [`NoiseSampler::sample`] draws a
//!   [`NoiseBatch`] `[samples, vertices, channels]` from a seed, bit-identically
//!   for any thread count.
//! - [`stream`]: any number of samples in bounded memory, chunk by chunk,
//!   to a consumer or straight into an `.npy` file.
//! - [`spectrum`]: coefficients `c_i = phi_i^T M f`, empirical against
//!   theoretical `Var(c_i)`, independence, per-frequency W2 between meshes,
//!   energy; a serializable [`SpectrumReport`].
//!
//! ## Conventions
//! - `L` is the PSD cotangent Laplacian, `M` the lumped mass (positive at
//!   every vertex), both from [`mfm_geometry::operators`].
//! - Eigenpairs `L phi = lambda M phi`, ascending, `phi^T M phi = 1`;
//!   `Gamma = ||M^-1 L||_F`. Under a global scale by `k`: `lambda -> lambda / k^2`,
//!   `Gamma -> Gamma / k^2`, and normalized Matérn samples are unchanged.
//! - `n ~ N(0, I)` is one standard normal per vertex; `tau` has the units of
//!   an eigenvalue (1 / length²), `c` is dimensionless.
//!
//! This crate depends on neither libtorch nor Python.
//!
//! ## Example
//! ```
//! use mfm_geometry::procedural;
//! use mfm_noise::{NoiseKind, NoiseSampler};
//!
//! let mesh = procedural::icosphere(3);
//! // factor L + tau M once ...
//! let sampler = NoiseSampler::new(&mesh, NoiseKind::Matern { tau: 100.0 }).unwrap();
//! // ... then draw 16 scalar samples at once
//! let batch = sampler.sample(16, 1, 7).unwrap();
//! assert_eq!(batch.data().len(), 16 * mesh.num_vertices());
//! // the same seed on any number of threads gives the same bits
//! assert_eq!(batch, sampler.sample(16, 1, 7).unwrap());
//! ```

pub mod error;
pub mod kind;
mod rng;
pub mod sampler;
pub mod spectrum;
pub mod stream;

pub use error::{NoiseError, Result};
pub use kind::{DEFAULT_TAU, KindName, KindParameters, NoiseKind};
pub use sampler::{NoiseBatch, NoiseSampler};
pub use spectrum::{SpectralAnalyzer, SpectrumComparison, SpectrumReport, Theory};
