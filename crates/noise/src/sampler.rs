//! [`NoiseSampler`]: per-mesh state for drawing batches of noise, and
//! [`NoiseBatch`], the `[samples, vertices, channels]` array it returns.
//!
//! The sampler is built once per mesh and [`NoiseKind`]: it keeps the lumped
//! mass, `Gamma = ||M^-1 L||_F`, the Cholesky factor of `L + tau M` (Matérn
//! kinds, through [`mfm_solver::ScreenedPoisson`]) or the `k` lowest
//! eigenpairs (explicit kind, through [`mfm_solver::generalized_eigenpairs`]).
//! Each call to [`NoiseSampler::sample`] then draws all right-hand sides of a
//! block and solves them together.
//!
//! ## Randomness and determinism
//! Sample `i`, channel `c` of seed `s` is drawn from its own ChaCha8 stream
//! (key from `s`, stream id `i`, word offset `c * 2^40`), with standard
//! normals from `rand_distr::StandardNormal` (ziggurat), one per vertex in
//! vertex order (one per eigenpair for the explicit kind). The `f32` methods
//! ([`NoiseSampler::sample_f32`]) read the same streams through a 32-bit
//! ziggurat instead (one keystream word per normal), so their values are
//! another draw of the same law, not the `f64` values rounded (except for
//! the explicit kind). Consequences, for both precisions:
//! - the output is bit-identical whatever the rayon thread count and however
//!   the batch is cut into blocks (the solver's block solves are column-wise
//!   bit-identical to single solves); blocks are as wide as memory allows
//!   (up to 1 GiB of right-hand sides), so a batch is usually one block;
//! - [`NoiseSampler::sample_range`] continues a sequence:
//!   `sample_range(first, n, ..)` returns samples `first .. first + n` of the
//!   same seed, so large sets can be drawn in pieces;
//! - channel `c` of a sample does not depend on how many channels are drawn.
//!
//! Results are reproducible on a given machine and instruction set (the
//! solver picks AVX2/AVX-512 kernels at run time).
//!
//! ## Matérn noise without screening (`tau = 0`)
//! `L` is singular: it vanishes exactly on the functions that are constant on
//! each connected component (the zero modes, eigenvalue 0). `tau = 0` samples
//! the pseudo-inverse `f = L^+ P M^1/2 n`, where `P b = b - sum_c M 1_c (1_c^T b) / area_c`
//! removes the zero-mode part of a right-hand side (`1_c` the indicator of
//! component `c`, `area_c = 1_c^T M 1_c`), so that `L f = P M^1/2 n` has
//! solutions; of those, the one with zero mass-weighted mean on every
//! component. Spectrally `c_i = chi_i / lambda_i` for `lambda_i > 0` and `0`
//! for the zero modes. The sampler computes it in three steps per column:
//!
//! 1. **project** the right-hand side `b = M^1/2 n` before the solve:
//!    `b_v -= m_v * (sum_{u in c} b_u) / area_c` for the component `c` of
//!    `v`, which removes exactly its zero-mode component;
//! 2. **solve** `(L + eps M) f = P b` with the Cholesky factor of the
//!    slightly regularized `L + eps M`, `eps = ZERO_TAU_REGULARIZATION * Gamma`
//!    (`1e-10 Gamma`, see [`ZERO_TAU_REGULARIZATION`]);
//! 3. **remove the mean**: `f_v -= (sum_{u in c} m_u f_u) / area_c`, which
//!    discards what round-off (amplified by up to `1 / eps` in the near-null
//!    direction) left in the zero modes.
//!
//! The components come from the sparsity pattern of `L` itself (union-find
//! over its nonzero off-diagonal entries), so
//! [`NoiseSampler::from_operators`] needs no mesh. Each column is projected
//! and centered on its own, in vertex order, so the determinism guarantees
//! above hold unchanged. The `f32` methods compute `tau = 0` in `f64` and
//! round (as for the explicit kind): the `f32` copy of a factor whose
//! condition number is about `1e10` would lose every digit in the solve.

use faer::MatMut;
use faer::sparse::SparseColMat;
use mfm_files::fmt_f64;
use mfm_geometry::TriMesh;
use mfm_geometry::operators::{Operators, try_gamma};
use mfm_solver::{
    EigenOptions, Eigenpairs, ScreenedPoisson, SymbolicAnalysis, generalized_eigenpairs,
};
use rayon::prelude::*;
use std::sync::Arc;

use crate::error::{NoiseError, Result};
use crate::kind::NoiseKind;
use crate::rng::{MAX_CHANNELS, fill_normals, fill_normals_f32, stream};
use crate::spectrum::Theory;

/// Regularization of Matérn noise without screening (`tau = 0`), relative
/// to `Gamma = ||M^-1 L||_F`: the sampler factors `L + eps M` with
/// `eps = ZERO_TAU_REGULARIZATION * Gamma` (see the [module docs](self)).
///
/// Why `1e-10`:
/// - **large enough** for a stable `f64` Cholesky factorization. Every
///   eigenvalue `lambda_i` of `M^-1 L` is at most `Gamma` (a Frobenius norm
///   bounds the spectral radius), so the mass-scaled
///   `M^-1/2 (L + eps M) M^-1/2` has condition number at most about
///   `Gamma / eps = 1e10`, well below `1 / 2^-53 ~ 1e16`: the pivots stay
///   positive (the round-off in the assembled `L`, which may make its zero
///   eigenvalues slightly negative, is about `1e-16 Gamma`, a millionth of
///   `eps`), and the solution is accurate to about `1e-6` relative in the
///   near-null direction — which the mean removal discards — and to the usual
///   `1e-16 lambda_max / lambda_1` elsewhere;
/// - **small enough** that the bias is negligible: with the zero modes
///   projected out, mode `i` is divided by `lambda_i + eps` instead of
///   `lambda_i`, a relative bias of at most `eps / lambda_1 = 1e-10 Gamma / lambda_1`
///   (`2 eps / lambda_1` on `Var(c_1)`, less on the higher modes).
///   `Gamma / lambda_1` is scale-free and grows like `V^1.5`; measured
///   `eps / lambda_1`: `2.5e-7` on `icosphere(3)` (642 vertices), `1.6e-5`
///   on `icosphere(5)` (10242), `1.3e-4` on `icosphere(6)` (40962), `1.9e-5`
///   on the 3485-vertex Stanford bunny — far below the sampling error of any
///   spectral estimate — extrapolating to about `1e-2` at a million vertices.
pub const ZERO_TAU_REGULARIZATION: f64 = 1e-10;

/// Largest block of right-hand sides [`NoiseSampler`] draws and solves at
/// once, in bytes (the solver's panels take about as much again).
const BLOCK_BYTES: usize = 1 << 30;

/// A batch of noise signals: `samples x vertices x channels` values stored
/// row-major (`data[(s * vertices + v) * channels + c]`), so each sample is a
/// contiguous `vertices x channels` block (vertex-major, like a `V x 3`
/// position array when `channels == 3`).
///
/// # Example
/// ```
/// use mfm_noise::NoiseBatch;
/// let b = NoiseBatch::from_vec(vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0], 1, 3, 2).unwrap();
/// assert_eq!(b.get(0, 2, 1), 6.0);
/// assert_eq!(b.signal(0, 0), vec![1.0, 3.0, 5.0]);
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct NoiseBatch<T = f64> {
    data: Vec<T>,
    samples: usize,
    vertices: usize,
    channels: usize,
}

impl<T: Copy> NoiseBatch<T> {
    /// Wraps `data` (row-major `[samples, vertices, channels]`), e.g. signals
    /// produced elsewhere that should go through the spectral diagnostics.
    ///
    /// # Errors
    /// [`NoiseError::SizeMismatch`] if `data.len() != samples * vertices * channels`;
    /// [`NoiseError::TooLarge`] if that product overflows.
    pub fn from_vec(
        data: Vec<T>,
        samples: usize,
        vertices: usize,
        channels: usize,
    ) -> Result<Self> {
        let len = checked_len(samples, vertices, channels)?;
        if data.len() != len {
            return Err(NoiseError::SizeMismatch {
                what: "batch data length",
                expected: len,
                found: data.len(),
            });
        }
        Ok(Self {
            data,
            samples,
            vertices,
            channels,
        })
    }

    /// Number of samples `N`.
    pub fn samples(&self) -> usize {
        self.samples
    }

    /// Number of vertices `V`.
    pub fn vertices(&self) -> usize {
        self.vertices
    }

    /// Number of channels `C`.
    pub fn channels(&self) -> usize {
        self.channels
    }

    /// All values, row-major `[N, V, C]`.
    pub fn data(&self) -> &[T] {
        &self.data
    }

    /// The values, row-major `[N, V, C]`, by value.
    pub fn into_data(self) -> Vec<T> {
        self.data
    }

    /// Sample `s` as a `V x C` vertex-major slice.
    ///
    /// # Panics
    /// If `s >= samples()`.
    pub fn sample(&self, s: usize) -> &[T] {
        let w = self.vertices * self.channels;
        &self.data[s * w..(s + 1) * w]
    }

    /// Value of sample `s`, vertex `v`, channel `c`.
    ///
    /// # Panics
    /// If an index is out of range.
    pub fn get(&self, s: usize, v: usize, c: usize) -> T {
        assert!(c < self.channels && v < self.vertices, "index out of range");
        self.data[(s * self.vertices + v) * self.channels + c]
    }

    /// Channel `c` of sample `s` as one value per vertex (a copy).
    ///
    /// # Panics
    /// If an index is out of range.
    pub fn signal(&self, s: usize, c: usize) -> Vec<T> {
        assert!(c < self.channels, "channel out of range");
        self.sample(s)
            .iter()
            .skip(c)
            .step_by(self.channels)
            .copied()
            .collect()
    }
}

impl NoiseBatch<f64> {
    /// The batch rounded to `f32`.
    pub fn to_f32(&self) -> NoiseBatch<f32> {
        NoiseBatch {
            data: self.data.iter().map(|&x| x as f32).collect(),
            samples: self.samples,
            vertices: self.vertices,
            channels: self.channels,
        }
    }
}

fn checked_len(samples: usize, vertices: usize, channels: usize) -> Result<usize> {
    samples
        .checked_mul(vertices)
        .and_then(|x| x.checked_mul(channels))
        .ok_or(NoiseError::TooLarge {
            samples,
            vertices,
            channels,
        })
}

/// What each column of a block goes through after the normals are drawn.
#[derive(Debug)]
enum Engine {
    /// `x = scale_v * n_v` per vertex (naive: 1, white: `M^-1/2`).
    Diagonal(Option<Vec<f64>>),
    /// `x = (L + tau M)^-1 M^1/2 n`, times an amplitude. With `tau = 0`,
    /// `L + eps M` is factored and `null_space` holds the components whose
    /// constants are projected out before and after the solve. Each of the
    /// `repeats` further solves (smooth Matérn) first multiplies `x` by
    /// `tau M`: `x <- (L + tau M)^-1 tau M x`.
    Poisson {
        poisson: ScreenedPoisson,
        sqrt_mass: Vec<f64>,
        null_space: Option<Components>,
        repeats: u32,
    },
    /// `x = sum_i weight_i chi_i phi_i`.
    Explicit {
        pairs: Eigenpairs,
        weights: Vec<f64>,
    },
}

/// The connected components of the graph of `L`'s nonzero off-diagonal
/// entries, whose indicator vectors span the null space of `L` (the zero
/// modes removed by Matérn noise without screening).
#[derive(Debug)]
struct Components {
    /// Component of each vertex, numbered in the order of their first vertex.
    of: Vec<u32>,
    /// `1 / area_c` with `area_c = sum_{v in c} m_v`, per component.
    inv_area: Vec<f64>,
}

impl Components {
    /// Union-find over the nonzero off-diagonal entries of `l` (either
    /// triangle, or both), then the area of each component. `O(nnz(L))`.
    fn new(l: &SparseColMat<usize, f64>, mass: &[f64]) -> Self {
        fn root(parent: &mut [usize], mut v: usize) -> usize {
            while parent[v] != v {
                parent[v] = parent[parent[v]];
                v = parent[v];
            }
            v
        }
        let n = mass.len();
        let mut parent: Vec<usize> = (0..n).collect();
        let l = l.as_ref();
        for j in 0..n {
            for (i, &x) in l.row_idx_of_col(j).zip(l.val_of_col(j)) {
                if i != j && x != 0.0 {
                    let (a, b) = (root(&mut parent, i), root(&mut parent, j));
                    // the smaller index becomes the root: deterministic
                    if a < b {
                        parent[b] = a;
                    } else if b < a {
                        parent[a] = b;
                    }
                }
            }
        }
        let mut id = vec![u32::MAX; n];
        let mut of = Vec::with_capacity(n);
        let mut area: Vec<f64> = Vec::new();
        for (v, &m) in mass.iter().enumerate() {
            let r = root(&mut parent, v);
            if id[r] == u32::MAX {
                id[r] = area.len() as u32;
                area.push(0.0);
            }
            of.push(id[r]);
            area[id[r] as usize] += m;
        }
        Self {
            of,
            inv_area: area.iter().map(|a| 1.0 / a).collect(),
        }
    }

    /// Number of connected components.
    fn len(&self) -> usize {
        self.inv_area.len()
    }

    /// Per-component `(sum_{v in c} w_v x_v) / area_c` (`w = 1` when `None`).
    fn means(&self, x: &[f64], weights: Option<&[f64]>) -> Vec<f64> {
        let mut sums = vec![0.0; self.len()];
        match weights {
            Some(w) => {
                for ((&c, &x), &w) in self.of.iter().zip(x).zip(w) {
                    sums[c as usize] += w * x;
                }
            }
            None => {
                for (&c, &x) in self.of.iter().zip(x) {
                    sums[c as usize] += x;
                }
            }
        }
        sums.iter_mut()
            .zip(&self.inv_area)
            .for_each(|(s, a)| *s *= a);
        sums
    }

    /// `b -= M 1_c (1_c^T b) / area_c` for every component `c`: removes the
    /// zero-mode part of a right-hand side (afterwards `1_c^T b = 0`).
    fn project_rhs(&self, b: &mut [f64], mass: &[f64]) {
        let s = self.means(b, None);
        for ((x, &c), &m) in b.iter_mut().zip(&self.of).zip(mass) {
            *x -= m * s[c as usize];
        }
    }

    /// `f -= 1_c (1_c^T M f) / area_c` for every component `c`: zero
    /// mass-weighted mean per component.
    fn remove_mean(&self, f: &mut [f64], mass: &[f64]) {
        let s = self.means(f, Some(mass));
        for (x, &c) in f.iter_mut().zip(&self.of) {
            *x -= s[c as usize];
        }
    }
}

/// Noise sampler for one mesh and one [`NoiseKind`]; see the
/// [module docs](self) for the randomness and determinism guarantees.
///
/// Matérn noise with `tau = 0` is the pseudo-inverse `L^+ P M^1/2 n`
/// computed through `L + eps M`, `eps = 1e-10 Gamma`, with the zero modes
/// projected out before and after the solve (see the
/// [module docs](self) and
/// [`ZERO_TAU_REGULARIZATION`]); it costs the same as `tau > 0` plus `O(V)`
/// per column, in `f64` for both precisions.
///
/// Conventions: `L` PSD cotangent Laplacian, `M` lumped mass (positive at
/// every vertex), `Gamma = ||M^-1 L||_F` (docs/conventions.md, "Spectra").
///
/// Cost of construction: operators `O(V + F)`; Matérn kinds one sparse
/// Cholesky factorization of `L + tau M`; explicit kind one eigensolve for
/// `k` pairs. Cost per sample and channel: Matérn one forward/backward
/// substitution (`~4 nnz(factor)` flops, batched), explicit `O(V k)`,
/// naive/white `O(V)`, plus `V` normals. `Send + Sync`.
///
/// # Example
/// ```
/// use mfm_geometry::procedural;
/// use mfm_noise::{NoiseKind, NoiseSampler};
/// let mesh = procedural::icosphere(3);
/// let sampler = NoiseSampler::new(&mesh, NoiseKind::Matern { tau: 100.0 }).unwrap();
/// let batch = sampler.sample(8, 3, 42).unwrap(); // 8 samples of xyz noise
/// assert_eq!((batch.samples(), batch.vertices(), batch.channels()), (8, mesh.num_vertices(), 3));
/// // the same seed gives the same bits; sample_range continues the sequence
/// assert_eq!(sampler.sample_range(5, 3, 3, 42).unwrap().data(), &batch.data()[5 * 642 * 3..]);
/// ```
#[derive(Debug)]
pub struct NoiseSampler {
    kind: NoiseKind,
    mass: Vec<f64>,
    gamma: f64,
    tau: Option<f64>,
    amplitude: f64,
    engine: Engine,
}

impl NoiseSampler {
    /// Builds the operators of `mesh` and the sampler for `kind`.
    ///
    /// # Errors
    /// [`NoiseError::InvalidParameter`] (see [`NoiseKind::validate`]),
    /// [`NoiseError::Operators`] (a degenerate face),
    /// [`NoiseError::NonPositiveMass`] (an unreferenced vertex), and those of
    /// [`NoiseSampler::from_operators`].
    pub fn new(mesh: &TriMesh, kind: NoiseKind) -> Result<Self> {
        kind.validate()?;
        let ops = Operators::new(mesh)?;
        Self::from_operators(&ops.laplacian, &ops.mass, kind)
    }

    /// Builds the sampler from a PSD Laplacian `l` (`V x V`, lower triangle
    /// read) and the lumped mass diagonal `mass`, e.g. operators the caller
    /// already has.
    ///
    /// # Errors
    /// [`NoiseError::InvalidParameter`] (also for Matérn with
    /// `0 < tau < ZERO_TAU_REGULARIZATION * Gamma`: below the regularization
    /// that `tau = 0` itself gets, `L + tau M` cannot be factored reliably),
    /// [`NoiseError::SizeMismatch`],
    /// [`NoiseError::NonPositiveMass`], [`NoiseError::Operators`] (a
    /// non-square `l`), [`NoiseError::Solver`] (the factorization or the
    /// eigensolve failed, e.g. `k > V` or `L` not PSD).
    pub fn from_operators(
        l: &SparseColMat<usize, f64>,
        mass: &[f64],
        kind: NoiseKind,
    ) -> Result<Self> {
        Self::from_operators_sharing(l, mass, kind, None)
    }

    /// [`NoiseSampler::from_operators`] whose factor of `L + tau M` (for the
    /// Matérn kinds) reuses `symbolic`, a symbolic analysis of `L`'s pattern
    /// ([`ScreenedPoisson::analyse`], or [`ScreenedPoisson::symbolic`] of a
    /// sampler on another shape of the same connectivity): only the numeric
    /// factorization runs, with the same bits as a fresh analysis. `None`
    /// analyses the pattern itself. Kinds without a factor ignore it.
    ///
    /// # Errors
    /// As [`NoiseSampler::from_operators`], plus
    /// [`mfm_solver::SolverError::PatternMismatch`] (inside
    /// [`NoiseError::Solver`]) for an analysis of another pattern.
    pub fn from_operators_sharing(
        l: &SparseColMat<usize, f64>,
        mass: &[f64],
        kind: NoiseKind,
        symbolic: Option<&Arc<SymbolicAnalysis>>,
    ) -> Result<Self> {
        let screened = |tau: f64| -> Result<ScreenedPoisson> {
            Ok(match symbolic {
                Some(s) => ScreenedPoisson::with_symbolic(s, l, mass, tau)?,
                None => ScreenedPoisson::new(l, mass, tau)?,
            })
        };
        kind.validate()?;
        if l.nrows() == l.ncols() && mass.len() != l.nrows() {
            return Err(NoiseError::SizeMismatch {
                what: "mass vector length",
                expected: l.nrows(),
                found: mass.len(),
            });
        }
        if let Some((vertex, &m)) = mass
            .iter()
            .enumerate()
            .find(|(_, m)| !(m.is_finite() && **m > 0.0))
        {
            return Err(NoiseError::NonPositiveMass { vertex, mass: m });
        }
        let gamma = try_gamma(l, mass)?;
        let sqrt_mass = || mass.iter().map(|m| m.sqrt()).collect::<Vec<_>>();
        let (tau, amplitude, engine) = match kind {
            NoiseKind::Naive => (None, 1.0, Engine::Diagonal(None)),
            NoiseKind::White => (
                None,
                1.0,
                Engine::Diagonal(Some(mass.iter().map(|m| 1.0 / m.sqrt()).collect())),
            ),
            NoiseKind::Matern { tau: 0.0 } => {
                let eps = ZERO_TAU_REGULARIZATION * gamma;
                if !(eps.is_finite() && eps > 0.0) {
                    return Err(NoiseError::InvalidParameter {
                        name: "tau",
                        expected: "tau > 0 on a mesh whose Laplacian is zero (tau = 0 needs Gamma > 0)",
                        found: format!("tau = 0, Gamma = {gamma}"),
                    });
                }
                (
                    Some(0.0),
                    1.0,
                    Engine::Poisson {
                        poisson: screened(eps)?,
                        sqrt_mass: sqrt_mass(),
                        null_space: Some(Components::new(l, mass)),
                        repeats: 0,
                    },
                )
            }
            NoiseKind::Matern { tau } | NoiseKind::MaternSmooth { tau, .. }
                if tau < ZERO_TAU_REGULARIZATION * gamma =>
            {
                return Err(NoiseError::InvalidParameter {
                    name: "tau",
                    expected: "0 (no screening) or at least 1e-10 x Gamma, the smallest \
                               screening whose factorization is reliable",
                    found: format!(
                        "{}, below 1e-10 x Gamma = {} on this mesh (Gamma = {})",
                        fmt_f64(tau),
                        fmt_f64(ZERO_TAU_REGULARIZATION * gamma),
                        fmt_f64(gamma)
                    ),
                });
            }
            NoiseKind::Matern { tau } | NoiseKind::MaternSmooth { tau, .. } => (
                Some(tau),
                1.0,
                Engine::Poisson {
                    poisson: screened(tau)?,
                    sqrt_mass: sqrt_mass(),
                    null_space: None,
                    // smooth Matérn: one solve per order
                    repeats: match kind {
                        NoiseKind::MaternSmooth { order, .. } => order - 1,
                        _ => 0,
                    },
                },
            ),
            NoiseKind::MaternNormalized { c } => {
                let tau = c * gamma;
                if !(tau.is_finite() && tau > 0.0) {
                    return Err(NoiseError::InvalidParameter {
                        name: "c",
                        expected: "c * Gamma finite and > 0 (a mesh with a nonzero Laplacian)",
                        found: format!("c = {c}, Gamma = {gamma}"),
                    });
                }
                if c < ZERO_TAU_REGULARIZATION {
                    return Err(NoiseError::InvalidParameter {
                        name: "c",
                        expected: "at least 1e-10 (tau = c x Gamma; a smaller screening has \
                                   no reliable factorization)",
                        found: format!("{}, below 1e-10 (tau = {})", fmt_f64(c), fmt_f64(tau)),
                    });
                }
                (
                    Some(tau),
                    gamma.sqrt(),
                    Engine::Poisson {
                        poisson: screened(tau)?,
                        sqrt_mass: sqrt_mass(),
                        null_space: None,
                        repeats: 0,
                    },
                )
            }
            NoiseKind::Explicit { k, tau } => {
                let pairs = generalized_eigenpairs(l, mass, k, &EigenOptions::default())?;
                let weights = explicit_weights(&pairs.values, tau);
                (Some(tau), 1.0, Engine::Explicit { pairs, weights })
            }
        };
        Ok(Self {
            kind,
            mass: mass.to_vec(),
            gamma,
            tau,
            amplitude,
            engine,
        })
    }

    /// The kind this sampler draws.
    pub fn kind(&self) -> NoiseKind {
        self.kind
    }

    /// Number of vertices `V`.
    pub fn num_vertices(&self) -> usize {
        self.mass.len()
    }

    /// The lumped mass (diagonal of `M`).
    pub fn mass(&self) -> &[f64] {
        &self.mass
    }

    /// `Gamma = ||M^-1 L||_F` of the mesh (computed for every kind).
    pub fn gamma(&self) -> f64 {
        self.gamma
    }

    /// The screening weight in use: `tau` for Matérn (`0` without
    /// screening, not the regularization) and explicit, `c * Gamma` for
    /// normalized Matérn, `None` for naive and white.
    pub fn tau(&self) -> Option<f64> {
        self.tau
    }

    /// Factor applied to every sample: `sqrt(Gamma)` for normalized Matérn,
    /// `1` otherwise.
    pub fn amplitude(&self) -> f64 {
        self.amplitude
    }

    /// The eigenpairs of the explicit kind (`None` for the others).
    pub fn eigenpairs(&self) -> Option<&Eigenpairs> {
        match &self.engine {
            Engine::Explicit { pairs, .. } => Some(pairs),
            _ => None,
        }
    }

    /// The factored `L + tau M` of the Matérn kinds (`None` for the others);
    /// reuse it for other screened Poisson solves on the mesh. For `tau = 0`
    /// it is `L + eps M` with `eps = `[`ZERO_TAU_REGULARIZATION`]` * Gamma`
    /// (its [`ScreenedPoisson::tau`] is `eps`).
    pub fn screened_poisson(&self) -> Option<&ScreenedPoisson> {
        match &self.engine {
            Engine::Poisson { poisson, .. } => Some(poisson),
            _ => None,
        }
    }

    /// Keeps only the `f32` copy of the Matérn factor, for a caller that
    /// draws with [`NoiseSampler::sample_range_f32`] only (e.g. a sampler on
    /// a mesh of millions of vertices, where the `f64` factor takes hundreds
    /// of MB). Returns whether a factor was released: `false` for the kinds
    /// whose `f32` draws are computed in `f64` (the explicit kind, Matérn
    /// noise without screening) and for those without a factor, which keep
    /// what they hold. After a release, the `f64` draws
    /// ([`NoiseSampler::sample_range`]) fail with a solver error; the `f32`
    /// draws are the same bits as before.
    pub fn release_f64_factor(&mut self) -> bool {
        match &mut self.engine {
            Engine::Poisson {
                poisson,
                null_space: None,
                ..
            } => {
                poisson.release_f64_factor();
                true
            }
            _ => false,
        }
    }

    /// The closed-form statistics of this sampler's noise on its mesh, for
    /// eigenpairs `pairs` of the same mesh ([`Theory::new`] with the
    /// sampler's mass and `Gamma`; its variances are
    /// [`NoiseKind::spectral_variance`]).
    ///
    /// # Errors
    /// [`NoiseError::SizeMismatch`] if `pairs` has another vertex count.
    pub fn theory(&self, pairs: &Eigenpairs) -> Result<Theory> {
        Theory::new(self.kind, pairs, &self.mass, self.gamma)
    }

    /// Draws `samples` samples of `channels` independent channels each, from
    /// `seed`: the same as [`NoiseSampler::sample_range`]`(0, samples, channels, seed)`.
    ///
    /// # Errors
    /// See [`NoiseSampler::sample_range`].
    pub fn sample(&self, samples: usize, channels: usize, seed: u64) -> Result<NoiseBatch> {
        self.sample_range(0, samples, channels, seed)
    }

    /// Draws samples `first .. first + count` of the sequence of `seed`
    /// (`channels` independent channels each) as a `[count, V, channels]`
    /// batch. Blocks of samples are solved together; the rayon pool runs the
    /// random draws, the solves and the scatter in parallel.
    ///
    /// # Errors
    /// [`NoiseError::InvalidParameter`] (`channels == 0` or `>= 2^28`),
    /// [`NoiseError::TooLarge`], [`NoiseError::Solver`].
    pub fn sample_range(
        &self,
        first: usize,
        count: usize,
        channels: usize,
        seed: u64,
    ) -> Result<NoiseBatch> {
        let per_block = self.block_samples(channels, std::mem::size_of::<f64>());
        self.sample_range_blocked(first, count, channels, seed, per_block)
    }

    /// [`NoiseSampler::sample_range`] with blocks of `per_block` samples.
    fn sample_range_blocked(
        &self,
        first: usize,
        count: usize,
        channels: usize,
        seed: u64,
        per_block: usize,
    ) -> Result<NoiseBatch> {
        self.check_channels(channels)?;
        let v = self.num_vertices();
        let mut data = vec![0.0; checked_len(count, v, channels)?];
        if data.is_empty() {
            return NoiseBatch::from_vec(data, count, v, channels);
        }
        let per_block = per_block.clamp(1, count);
        let mut scratch = scratch_block(per_block, v, channels);
        for (b, out) in data.chunks_mut(per_block * v * channels).enumerate() {
            let start = first + b * per_block;
            let cols = out.len() / v;
            if channels == 1 {
                self.draw_into(out, start, 1, seed);
                self.solve_block(out, cols)?;
                let amp = self.amplitude;
                if amp != 1.0 {
                    out.par_iter_mut().for_each(|x| *x *= amp);
                }
            } else {
                let block = &mut scratch[..out.len()];
                self.draw_into(block, start, channels, seed);
                self.solve_block(block, cols)?;
                scatter(block, out, v, channels, self.amplitude);
            }
        }
        NoiseBatch::from_vec(data, count, v, channels)
    }

    /// [`NoiseSampler::sample`] in `f32`.
    ///
    /// The normals are drawn in `f32` (a 32-bit ziggurat on the same
    /// per-(seed, sample, channel) streams, see the [module docs](self)), so
    /// the values follow the same law as [`NoiseSampler::sample`]'s but are
    /// not its rounding; they have the same determinism guarantees. Matérn
    /// kinds scale the normals by `amplitude * M^1/2` in `f32` and solve with
    /// the solver's `f32` factor (relative accuracy about
    /// `cond(L + tau M) * 6e-8`, typically `< 1e-5`); naive and white noise
    /// are computed in `f32`. The explicit kind and Matérn noise without
    /// screening (`tau = 0`) are computed in `f64` and rounded (they are
    /// [`NoiseSampler::sample`] rounded): the `f32` factor of `L + eps M`,
    /// condition number about `1e10`, would not be accurate at all.
    ///
    /// # Errors
    /// See [`NoiseSampler::sample_range`].
    pub fn sample_f32(
        &self,
        samples: usize,
        channels: usize,
        seed: u64,
    ) -> Result<NoiseBatch<f32>> {
        self.sample_range_f32(0, samples, channels, seed)
    }

    /// [`NoiseSampler::sample_range`] in `f32` (see [`NoiseSampler::sample_f32`]):
    /// samples `first .. first + count` of the `f32` sequence of `seed`.
    ///
    /// # Errors
    /// See [`NoiseSampler::sample_range`].
    pub fn sample_range_f32(
        &self,
        first: usize,
        count: usize,
        channels: usize,
        seed: u64,
    ) -> Result<NoiseBatch<f32>> {
        let per_block = self.block_samples(channels, std::mem::size_of::<f32>());
        self.sample_range_f32_blocked(first, count, channels, seed, per_block)
    }

    /// [`NoiseSampler::sample_range_f32`] with blocks of `per_block` samples.
    fn sample_range_f32_blocked(
        &self,
        first: usize,
        count: usize,
        channels: usize,
        seed: u64,
        per_block: usize,
    ) -> Result<NoiseBatch<f32>> {
        // per-vertex factor applied to the normals (none for naive noise)
        let scale: Option<Vec<f32>> = match &self.engine {
            Engine::Explicit { .. }
            | Engine::Poisson {
                null_space: Some(_),
                ..
            } => {
                // computed in f64: blocks within the f64 budget
                let per_block = per_block.min(self.block_samples(channels, 8));
                return Ok(self
                    .sample_range_blocked(first, count, channels, seed, per_block)?
                    .to_f32());
            }
            Engine::Diagonal(scale) => scale
                .as_ref()
                .map(|s| s.iter().map(|&x| x as f32).collect()),
            Engine::Poisson { sqrt_mass, .. } => Some(
                sqrt_mass
                    .iter()
                    .map(|&x| (x * self.amplitude) as f32)
                    .collect(),
            ),
        };
        self.check_channels(channels)?;
        let v = self.num_vertices();
        let mut data = vec![0.0f32; checked_len(count, v, channels)?];
        if data.is_empty() {
            return NoiseBatch::from_vec(data, count, v, channels);
        }
        let per_block = per_block.clamp(1, count);
        let mut scratch = scratch_block(per_block, v, channels);
        for (b, out) in data.chunks_mut(per_block * v * channels).enumerate() {
            let start = first + b * per_block;
            let cols = out.len() / v;
            let block = if channels == 1 {
                &mut *out
            } else {
                &mut scratch[..out.len()]
            };
            block.par_chunks_mut(v).enumerate().for_each(|(j, col)| {
                let sample = (start + j / channels) as u64;
                fill_normals_f32(seed, sample, (j % channels) as u64, col);
                if let Some(s) = &scale {
                    col.iter_mut().zip(s).for_each(|(x, s)| *x *= s);
                }
            });
            if let Engine::Poisson {
                poisson, repeats, ..
            } = &self.engine
            {
                poisson
                    .solve_many_f32_in_place(MatMut::from_column_major_slice_mut(block, v, cols))?;
                if *repeats > 0 {
                    let tau_mass: Vec<f32> = self
                        .mass
                        .iter()
                        .map(|m| (poisson.tau() * m) as f32)
                        .collect();
                    for _ in 0..*repeats {
                        block.par_chunks_mut(v).for_each(|col| {
                            col.iter_mut().zip(&tau_mass).for_each(|(x, s)| *x *= s)
                        });
                        poisson.solve_many_f32_in_place(MatMut::from_column_major_slice_mut(
                            block, v, cols,
                        ))?;
                    }
                }
            }
            if channels > 1 {
                scatter(&scratch[..out.len()], out, v, channels, 1.0);
            }
        }
        NoiseBatch::from_vec(data, count, v, channels)
    }

    fn check_channels(&self, channels: usize) -> Result<()> {
        if channels == 0 || channels >= MAX_CHANNELS {
            return Err(NoiseError::InvalidParameter {
                name: "channels",
                expected: "between 1 and 2^28 - 1",
                found: channels.to_string(),
            });
        }
        Ok(())
    }

    /// Samples per block: as many as fit [`BLOCK_BYTES`] of right-hand
    /// sides (values of `bytes` bytes), so that a whole batch is usually
    /// solved in one pass over the factor (the solve streams the factor once
    /// per block and thread, and the output is as large anyway); at least 8
    /// right-hand sides. Callers clamp it to the batch.
    fn block_samples(&self, channels: usize, bytes: usize) -> usize {
        let v = self.num_vertices().max(1);
        let cols = (BLOCK_BYTES / (v * bytes)).max(8);
        (cols / channels.max(1)).max(1)
    }

    /// Solves the Matérn system in place for a column-major `V x cols` block
    /// (nothing for the other kinds); without screening, then removes each
    /// column's mass-weighted mean per component.
    fn solve_block(&self, block: &mut [f64], cols: usize) -> Result<()> {
        if let Engine::Poisson {
            poisson,
            null_space,
            repeats,
            ..
        } = &self.engine
        {
            let v = self.num_vertices();
            poisson.solve_many_in_place(MatMut::from_column_major_slice_mut(block, v, cols))?;
            for _ in 0..*repeats {
                let tau = poisson.tau();
                block.par_chunks_mut(v).for_each(|col| {
                    col.iter_mut()
                        .zip(&self.mass)
                        .for_each(|(x, m)| *x *= tau * m)
                });
                poisson.solve_many_in_place(MatMut::from_column_major_slice_mut(block, v, cols))?;
            }
            if let (Some(components), true) = (null_space, v > 0) {
                block
                    .par_chunks_mut(v)
                    .for_each(|col| components.remove_mean(col, &self.mass));
            }
        }
        Ok(())
    }

    /// Fills the column-major `V x cols` `block`: column `j` is sample
    /// `start + j / channels`, channel `j % channels`, before any solve
    /// (Matérn: the right-hand sides, projected when `tau = 0`).
    fn draw_into(&self, block: &mut [f64], start: usize, channels: usize, seed: u64) {
        let v = self.num_vertices();
        if v == 0 {
            return;
        }
        block.par_chunks_mut(v).enumerate().for_each(|(j, col)| {
            let sample = (start + j / channels) as u64;
            let mut rng = stream(seed, sample, (j % channels) as u64);
            match &self.engine {
                Engine::Diagonal(scale) => {
                    fill_normals(&mut rng, col);
                    if let Some(s) = scale {
                        col.iter_mut().zip(s).for_each(|(x, s)| *x *= s);
                    }
                }
                Engine::Poisson {
                    sqrt_mass,
                    null_space,
                    ..
                } => {
                    fill_normals(&mut rng, col);
                    col.iter_mut().zip(sqrt_mass).for_each(|(x, s)| *x *= s);
                    if let Some(components) = null_space {
                        components.project_rhs(col, &self.mass);
                    }
                }
                Engine::Explicit { pairs, weights } => {
                    col.fill(0.0);
                    let mut chi = vec![0.0; weights.len()];
                    fill_normals(&mut rng, &mut chi);
                    for (i, (&w, &z)) in weights.iter().zip(&chi).enumerate() {
                        let a = w * z;
                        if a != 0.0 {
                            let phi = pairs.vectors.col(i);
                            col.iter_mut()
                                .zip(phi.iter())
                                .for_each(|(x, p)| *x += a * p);
                        }
                    }
                }
            }
        });
    }
}

/// `1 / (lambda_i + tau)`, with the zero modes left out when `tau == 0`.
pub(crate) fn explicit_weights(values: &[f64], tau: f64) -> Vec<f64> {
    let zero = zero_mode_tolerance(values);
    values
        .iter()
        .map(|&l| {
            if tau == 0.0 && l <= zero {
                0.0
            } else {
                1.0 / (l + tau)
            }
        })
        .collect()
}

/// Eigenvalues at or below this count as zero modes (constants per
/// connected component): `1e-8` times the largest computed eigenvalue.
pub(crate) fn zero_mode_tolerance(values: &[f64]) -> f64 {
    1e-8 * values.iter().copied().fold(0.0, f64::max)
}

/// Column-major scratch block for `per_block` samples of `channels`
/// channels. One channel needs none: `[N, V, 1]` is the column-major block
/// itself, so draws, solves and scaling happen in the output.
fn scratch_block<T: Clone + Default>(per_block: usize, v: usize, channels: usize) -> Vec<T> {
    let len = if channels > 1 {
        per_block * v * channels
    } else {
        0
    };
    vec![T::default(); len]
}

/// Writes the column-major block (column `s * channels + c`) into the
/// row-major `[n, V, C]` output, multiplied by `amp`.
fn scatter<T: Copy + Send + Sync + std::ops::Mul<Output = T>>(
    block: &[T],
    out: &mut [T],
    v: usize,
    channels: usize,
    amp: T,
) {
    if v == 0 {
        return;
    }
    out.par_chunks_mut(v * channels)
        .enumerate()
        .for_each(|(s, dst)| {
            for c in 0..channels {
                let col = &block[(s * channels + c) * v..][..v];
                for (i, &x) in col.iter().enumerate() {
                    dst[i * channels + c] = x * amp;
                }
            }
        });
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use mfm_geometry::procedural;

    /// The block size changes neither bit of a batch, in `f64` nor `f32`,
    /// for one channel (drawn and solved in the output) or several (through
    /// the scratch block), nor for a range that starts mid-block.
    #[test]
    fn batches_do_not_depend_on_the_block_size() {
        let mesh = procedural::icosphere(2);
        for kind in [
            NoiseKind::MaternNormalized { c: 0.05 },
            NoiseKind::Matern { tau: 0.0 },
            NoiseKind::White,
            NoiseKind::Explicit { k: 12, tau: 1.0 },
        ] {
            let s = NoiseSampler::new(&mesh, kind).unwrap();
            for channels in [1, 3] {
                let whole = s.sample_range_blocked(3, 23, channels, 5, 23).unwrap();
                let whole32 = s.sample_range_f32_blocked(3, 23, channels, 5, 23).unwrap();
                for per_block in [1, 4, 9, 1000] {
                    let b = s
                        .sample_range_blocked(3, 23, channels, 5, per_block)
                        .unwrap();
                    assert_eq!(
                        b, whole,
                        "{kind}, {channels} channels, blocks of {per_block}"
                    );
                    let b = s
                        .sample_range_f32_blocked(3, 23, channels, 5, per_block)
                        .unwrap();
                    assert_eq!(
                        b, whole32,
                        "{kind} f32, {channels} channels, blocks of {per_block}"
                    );
                }
                // and the public entry points agree with them
                assert_eq!(s.sample_range(3, 23, channels, 5).unwrap(), whole);
                assert_eq!(s.sample_range_f32(3, 23, channels, 5).unwrap(), whole32);
            }
        }
    }

    #[test]
    fn blocks_hold_the_whole_batch_within_the_budget() {
        let s = NoiseSampler::new(&procedural::icosphere(1), NoiseKind::White).unwrap();
        // 42 vertices: the budget allows millions of samples per block
        assert!(s.block_samples(1, 8) > 1_000_000);
        assert_eq!(s.block_samples(3, 8), s.block_samples(1, 8) / 3);
        assert_eq!(s.block_samples(1, 4), 2 * s.block_samples(1, 8));
    }
}
