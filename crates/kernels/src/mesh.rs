//! Mesh operators as differentiable tensor operations.
//!
//! [`MeshTensors`] holds everything PoissonNet needs from one triangle mesh:
//! the intrinsic gradient `G` as per-face coefficients, the interleaved face
//! areas `A2`, the lumped mass `M`, the connected components, and the cached
//! Cholesky factor of `L + eps I` (shared through an `Arc` by every solve on
//! this mesh, in every batch and every autograd node).
//!
//! ## Conventions
//! - Vertex signals are tensors `[..., V, C]` (any leading batch dimensions,
//!   one channel per column); face-vector signals are `[..., 2F, C]`, rows
//!   `2f, 2f + 1` the two components in face `f`'s tangent frame (the frame of
//!   `mfm_geometry::operators`, built from edge lengths). Reading rows
//!   `2f, 2f + 1` as the real and imaginary parts of a complex number gives
//!   PoissonNet's complex face features; rotating face `f`'s frame by `theta`
//!   multiplies them by `exp(-i theta)`.
//! - `L = G^T diag(A2) G` is the positive semi-definite cotangent Laplacian.
//! - Elements are `f32` or `f64`; every operation keeps the input's type.
//!
//! ## Operations (all differentiable, see [`crate::autograd`])
//! | method | maps | cost |
//! |---|---|---|
//! | [`MeshTensors::gradient`] | `x -> G x`, `[.., V, C] -> [.., 2F, C]` | `O(F C)` per batch item |
//! | [`MeshTensors::gradient_adjoint`] | `y -> G^T y` | `O(F C)` |
//! | [`MeshTensors::divergence`] | `y -> G^T (A2 * y)` | `O(F C)` |
//! | [`MeshTensors::rotated_divergence`] | `y -> G^T (A2 * (i y))` | `O(F C)` |
//! | [`MeshTensors::paired_divergence`] | both side by side, `[.., V, 2C]`, one pass | `O(F C)` |
//! | [`MeshTensors::face_mean`] | mean over each face's vertices, `[.., F, C]` | `O(F C)` |
//! | [`MeshTensors::solve`] | `(L + eps I)^-1 b` | `~4 nnz(factor)` flops per column |
//! | [`MeshTensors::mass_weighted_mean`] / [`MeshTensors::remove_mass_mean`] | per component and channel | `O(V C)` |
//!
//! `G`, `G^T` and the face means run as Rust kernels on the CPU (one gather
//! per face vertex, and the adjoint as a gather over each vertex's faces, so
//! no atomics and no torch sparse kernels); on other devices, or with
//! [`Backend::Torch`], they use torch's `index_select` / `index_add`. The
//! solve always runs on the CPU with the `f64` factor (or its `f32` copy for
//! `f32` tensors); tensors on a GPU are moved to the CPU and back.
//!
//! ## Example
//! ```
//! use mfm_geometry::procedural;
//! use mfm_kernels::mesh::MeshTensors;
//! use tch::{Kind, Tensor};
//!
//! let mesh = procedural::icosphere(2);
//! let mt = MeshTensors::new(&mesh).unwrap();
//! let (v, f) = (mt.num_vertices() as i64, mt.num_faces() as i64);
//! // a Poisson round trip: u -> G^T A2 G u = L u -> solve -> u (up to the
//! // mean, and up to the relative O(eps / lambda_1) ~ 3e-5 of the shift)
//! let u = Tensor::randn([2, v, 3], (Kind::Double, tch::Device::Cpu));
//! let u = mt.remove_mass_mean(&u).unwrap();
//! let lu = mt.divergence(&mt.gradient(&u).unwrap()).unwrap();
//! assert_eq!(mt.gradient(&u).unwrap().size(), vec![2, 2 * f, 3]);
//! let back = mt.remove_mass_mean(&mt.solve(&lu).unwrap()).unwrap();
//! let err = (&back - &u).abs().max().double_value(&[]);
//! assert!(err < 1e-4, "{err}");
//! ```

use std::sync::{Arc, Mutex};

use faer::MatMut;
use mfm_geometry::operators::Operators;
use mfm_geometry::{Topology, TriMesh};
use mfm_solver::{LaplacianSolver, SOLVE_CHUNK, ShiftOptions};
use tch::{Device, Kind, Tensor};

use crate::autograd::{LinearOperator, apply_linear, parallel_for};
use crate::error::{KernelError, Result, shape_error};
use crate::gather::{GatherKernel, GatherMode, Incidence};
use crate::{Scalar, SyncPtr};

/// How the face/vertex operators (`G`, `G^T`, face means) are computed.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Backend {
    /// Rust kernels for CPU tensors, torch operations on other devices.
    #[default]
    Native,
    /// Torch operations (`index_select`, batched `matmul`, `index_add`)
    /// everywhere; slower on the CPU, used as an independent reference
    /// (selected with `MeshTensors::with_backend`, a test-only method: the
    /// crate's `reference` feature).
    Torch,
}

/// Sparse face-from-vertex operator `A`: `(A x)[R f + r] = sum_j c[f, r, j]
/// x[faces[f][j]]` for `R` rows per face, and its adjoint.
struct FaceOperator {
    name: &'static str,
    rows: usize,
    num_vertices: usize,
    faces: Arc<Vec<[u32; 3]>>,
    incidence: Arc<Incidence>,
    /// `c[f, r, j]` at `(f R + r) 3 + j`.
    coef64: Vec<f64>,
    coef32: Vec<f32>,
    /// Per incidence `k` (vertex-major), the `R` coefficients of that corner.
    adj64: Vec<f64>,
    adj32: Vec<f32>,
    backend: Backend,
    /// Face indices and coefficients on non-CPU devices, made on first use.
    device_cache: Mutex<Vec<(Device, Kind, Tensor, Tensor)>>,
}

impl std::fmt::Debug for FaceOperator {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("FaceOperator")
            .field("name", &self.name)
            .field("rows", &self.rows)
            .field("num_vertices", &self.num_vertices)
            .field("num_faces", &self.faces.len())
            .finish()
    }
}

impl FaceOperator {
    fn new(
        name: &'static str,
        rows: usize,
        num_vertices: usize,
        faces: Arc<Vec<[u32; 3]>>,
        incidence: Arc<Incidence>,
        coef64: Vec<f64>,
        backend: Backend,
    ) -> Self {
        let nnz = incidence.face.len();
        let mut adj64 = vec![0.0; nnz * rows];
        for k in 0..nnz {
            let f = incidence.face[k] as usize;
            let j = incidence.corner[k] as usize;
            for r in 0..rows {
                adj64[k * rows + r] = coef64[(f * rows + r) * 3 + j];
            }
        }
        Self {
            name,
            rows,
            num_vertices,
            coef32: coef64.iter().map(|&c| c as f32).collect(),
            adj32: adj64.iter().map(|&c| c as f32).collect(),
            faces,
            incidence,
            coef64,
            adj64,
            backend,
            device_cache: Mutex::new(Vec::new()),
        }
    }

    #[cfg(feature = "reference")]
    fn with_backend(&self, backend: Backend) -> Self {
        Self {
            name: self.name,
            rows: self.rows,
            num_vertices: self.num_vertices,
            faces: Arc::clone(&self.faces),
            incidence: Arc::clone(&self.incidence),
            coef64: self.coef64.clone(),
            coef32: self.coef32.clone(),
            adj64: self.adj64.clone(),
            adj32: self.adj32.clone(),
            backend,
            device_cache: Mutex::new(Vec::new()),
        }
    }

    fn num_faces(&self) -> usize {
        self.faces.len()
    }

    /// Splits `[..., n, C]` into (leading dims, batch count, C).
    fn split(
        &self,
        x: &Tensor,
        n: usize,
        what: &str,
        expected: &str,
    ) -> Result<(Vec<i64>, i64, i64)> {
        let s = x.size();
        if s.len() < 2 || s[s.len() - 2] != n as i64 {
            return Err(shape_error(format!("{} {what}", self.name), expected, x));
        }
        let lead = s[..s.len() - 2].to_vec();
        let nb = lead.iter().product::<i64>();
        Ok((lead, nb, s[s.len() - 1]))
    }

    fn use_kernels(&self, x: &Tensor) -> bool {
        self.backend == Backend::Native && x.device() == Device::Cpu
    }

    /// Face indices (`[3F]`, i64) and coefficients (`[F, R, 3]`) as tensors on
    /// `device` with element type `kind`.
    fn torch_tables(&self, device: Device, kind: Kind) -> Result<(Tensor, Tensor)> {
        let mut cache = self
            .device_cache
            .lock()
            .map_err(|_| KernelError::CustomOp {
                op: self.name.to_owned(),
                message: "operator cache poisoned by an earlier panic".into(),
            })?;
        if let Some((_, _, i, c)) = cache.iter().find(|(d, k, _, _)| *d == device && *k == kind) {
            return Ok((i.shallow_clone(), c.shallow_clone()));
        }
        let flat: Vec<i64> = self.faces.iter().flat_map(|t| t.map(i64::from)).collect();
        let idx = Tensor::from_slice(&flat).to_device(device);
        let coef = Tensor::from_slice(&self.coef64)
            .reshape([self.num_faces() as i64, self.rows as i64, 3])
            .to_kind(kind)
            .to_device(device);
        cache.push((device, kind, idx.shallow_clone(), coef.shallow_clone()));
        Ok((idx, coef))
    }

    fn forward_torch(&self, x: &Tensor, lead: &[i64], nb: i64, c: i64) -> Result<Tensor> {
        let (idx, coef) = self.torch_tables(x.device(), x.kind())?;
        let (v, f, r) = (
            self.num_vertices as i64,
            self.num_faces() as i64,
            self.rows as i64,
        );
        let xg = x
            .reshape([nb, v, c])
            .index_select(1, &idx)
            .reshape([nb, f, 3, c]);
        let out = coef.matmul(&xg); // [nb, F, R, C]
        let mut shape = lead.to_vec();
        shape.extend([f * r, c]);
        Ok(out.reshape(shape.as_slice()))
    }

    fn adjoint_torch(&self, y: &Tensor, lead: &[i64], nb: i64, c: i64) -> Result<Tensor> {
        let (idx, coef) = self.torch_tables(y.device(), y.kind())?;
        let (v, f, r) = (
            self.num_vertices as i64,
            self.num_faces() as i64,
            self.rows as i64,
        );
        let y4 = y.reshape([nb, f, r, c]);
        let contrib = coef.transpose(1, 2).matmul(&y4).reshape([nb, 3 * f, c]);
        let out = Tensor::zeros([nb, v, c], (y.kind(), y.device())).index_add(1, &idx, &contrib);
        let mut shape = lead.to_vec();
        shape.extend([v, c]);
        Ok(out.reshape(shape.as_slice()))
    }

    /// `A x` (or with `adjoint`, `A^T x`) for `nb` items of `c` channels;
    /// `coef` the per-face (per-incidence) coefficients.
    fn gather<T: Scalar>(
        &self,
        mode: GatherMode,
        input: &[T],
        out: &mut [T],
        nb: usize,
        c: usize,
        coef: &[T],
    ) {
        let k = GatherKernel {
            faces: &self.faces[..],
            incidence: &self.incidence,
            rows: self.rows,
            num_vertices: self.num_vertices,
            c,
            mode,
            input,
            coef,
            out: SyncPtr(out.as_mut_ptr()),
        };
        let (items, grain) = if mode.adjoint() {
            (nb * self.num_vertices, 128)
        } else {
            (nb * self.faces.len(), 256)
        };
        parallel_for(items, grain, &|begin, end| k.dispatch(begin, end));
    }

    /// Runs a kernel on a CPU copy of `x` (`nb` items of `c` channels, or
    /// in the paired mode `c` channels per face row and `2c` per vertex
    /// row) into a new tensor of shape `out_shape`.
    fn run_kernel(
        &self,
        x: &Tensor,
        out_shape: Vec<i64>,
        nb: i64,
        c: i64,
        mode: GatherMode,
    ) -> Result<Tensor> {
        let kind = x.kind();
        let x = x.contiguous();
        let out = Tensor::empty(out_shape.as_slice(), (kind, Device::Cpu));
        let n_in = x.numel();
        let n_out = out.numel();
        match kind {
            Kind::Double => {
                // SAFETY: contiguous CPU tensors of the stated sizes and kind.
                let (xs, os) = unsafe {
                    (
                        std::slice::from_raw_parts(x.data_ptr() as *const f64, n_in),
                        std::slice::from_raw_parts_mut(out.data_ptr() as *mut f64, n_out),
                    )
                };
                let coef = if mode.adjoint() {
                    &self.adj64
                } else {
                    &self.coef64
                };
                self.gather(mode, xs, os, nb as usize, c as usize, coef);
            }
            Kind::Float => {
                // SAFETY: as above.
                let (xs, os) = unsafe {
                    (
                        std::slice::from_raw_parts(x.data_ptr() as *const f32, n_in),
                        std::slice::from_raw_parts_mut(out.data_ptr() as *mut f32, n_out),
                    )
                };
                let coef = if mode.adjoint() {
                    &self.adj32
                } else {
                    &self.coef32
                };
                self.gather(mode, xs, os, nb as usize, c as usize, coef);
            }
            k => {
                return Err(KernelError::Kind {
                    what: self.name.to_owned(),
                    kind: k,
                });
            }
        }
        Ok(out)
    }
}

impl LinearOperator for FaceOperator {
    fn name(&self) -> &str {
        self.name
    }

    fn apply(&self, x: &Tensor) -> Result<Tensor> {
        let (lead, nb, c) = self.split(x, self.num_vertices, "input", "[..., V, C]")?;
        if !self.use_kernels(x) {
            return self.forward_torch(x, &lead, nb, c);
        }
        let rows = self.num_faces() * self.rows;
        let mut shape = lead.clone();
        shape.extend([rows as i64, c]);
        self.run_kernel(x, shape, nb, c, GatherMode::Forward)
    }

    fn apply_adjoint(&self, y: &Tensor) -> Result<Tensor> {
        let n = self.num_faces() * self.rows;
        let (lead, nb, c) = self.split(y, n, "adjoint input", "[..., R F, C]")?;
        if !self.use_kernels(y) {
            return self.adjoint_torch(y, &lead, nb, c);
        }
        let mut shape = lead.clone();
        shape.extend([self.num_vertices as i64, c]);
        self.run_kernel(y, shape, nb, c, GatherMode::Adjoint)
    }
}

/// The weak divergence and the rotated weak divergence side by side, as the
/// adjoint of a linear operator: `A^T y = [G^T A2 y | G^T A2 (i y)]`,
/// `[..., 2F, C] -> [..., V, 2C]`, and `A [p | q] = A2 G p + (A2 G)_rot q`,
/// `[..., V, 2C] -> [..., 2F, C]`. On the CPU one kernel reads every face row
/// once (instead of two gathers and a concatenation); elsewhere it is the two
/// operators below.
struct PairedDivergenceOp {
    /// `A2 G` (its adjoint is [`MeshTensors::divergence`]).
    weighted: Arc<FaceOperator>,
    /// The same rows turned by a quarter turn (adjoint:
    /// [`MeshTensors::rotated_divergence`]).
    rotated: Arc<FaceOperator>,
}

impl PairedDivergenceOp {
    /// The pair made of [`MeshTensors`]' `face_ops[1]` (`A2 G`) and
    /// `face_ops[3]` (its rotated rows).
    fn of(face_ops: &[Arc<FaceOperator>; 4]) -> Arc<dyn LinearOperator> {
        Arc::new(Self {
            weighted: Arc::clone(&face_ops[1]),
            rotated: Arc::clone(&face_ops[3]),
        })
    }
}

impl LinearOperator for PairedDivergenceOp {
    fn name(&self) -> &str {
        "paired_area_weighted_gradient"
    }

    fn apply(&self, x: &Tensor) -> Result<Tensor> {
        let op = &self.weighted;
        let (lead, nb, c2) = op.split(x, op.num_vertices, "paired input", "[..., V, 2C]")?;
        if c2 % 2 != 0 {
            return Err(shape_error(
                self.name(),
                "[..., V, 2C] (an even channel count)",
                x,
            ));
        }
        let c = c2 / 2;
        if !op.use_kernels(x) {
            let p = x.narrow(-1, 0, c);
            let q = x.narrow(-1, c, c);
            return Ok(op.apply(&p)? + self.rotated.apply(&q)?);
        }
        let mut shape = lead;
        shape.extend([2 * op.num_faces() as i64, c]);
        op.run_kernel(x, shape, nb, c, GatherMode::PairedForward)
    }

    fn apply_adjoint(&self, y: &Tensor) -> Result<Tensor> {
        let op = &self.weighted;
        let n = 2 * op.num_faces();
        let (lead, nb, c) = op.split(y, n, "paired adjoint input", "[..., 2F, C]")?;
        if !op.use_kernels(y) {
            return Ok(Tensor::cat(
                &[op.apply_adjoint(y)?, self.rotated.apply_adjoint(y)?],
                -1,
            ));
        }
        let mut shape = lead;
        shape.extend([op.num_vertices as i64, 2 * c]);
        op.run_kernel(y, shape, nb, c, GatherMode::PairedAdjoint)
    }
}

/// `(L + eps I)^-1` as a self-adjoint linear operator on `[..., V, C]`.
/// Solves the row-major block `[items, rows, width]` at `data` in place with
/// `factor`, one right-hand side per (item, channel): chunks of up to
/// [`SOLVE_CHUNK`] channels of one item are solved on libtorch's threads
/// ([`parallel_for`]), each read and written one contiguous row at a time
/// (no transposes). A non-finite entry is reported with `col = item * width
/// + channel`.
fn solve_channels<T: mfm_solver::Real>(
    factor: &mfm_solver::CholeskyFactor<T>,
    data: SyncPtr<T>,
    items: usize,
    rows: usize,
    width: usize,
) -> Result<()> {
    let per_item = width.div_ceil(SOLVE_CHUNK);
    let failure: Mutex<Option<mfm_solver::SolverError>> = Mutex::new(None);
    if rows == 0 {
        return Ok(());
    }
    parallel_for(items * per_item, 1, &|t0, t1| {
        for t in t0..t1 {
            let (item, chunk) = (t / per_item, t % per_item);
            let c0 = chunk * SOLVE_CHUNK;
            let k = SOLVE_CHUNK.min(width - c0);
            // SAFETY: task t owns columns c0..c0 + k of item `item`,
            // disjoint from every other task's; the block holds
            // items * rows * width elements.
            let m = unsafe {
                MatMut::from_raw_parts_mut(
                    data.get().add(item * rows * width + c0),
                    rows,
                    k,
                    width as isize,
                    1,
                )
            };
            if let Err(mut e) = factor.solve_in_place_sequential(m) {
                if let mfm_solver::SolverError::NonFinite { col, .. } = &mut e {
                    *col += item * width + c0;
                }
                if let Ok(mut slot) = failure.lock() {
                    slot.get_or_insert(e);
                }
            }
        }
    });
    match failure.into_inner().ok().flatten() {
        Some(e) => Err(e.into()),
        None => Ok(()),
    }
}

struct PoissonSolveOp {
    solver: Arc<LaplacianSolver>,
}

impl PoissonSolveOp {
    fn solve(&self, b: &Tensor) -> Result<Tensor> {
        let v = self.solver.dim() as i64;
        let s = b.size();
        if s.len() < 2 || s[s.len() - 2] != v {
            return Err(shape_error(
                "Poisson solve right-hand side",
                format!("[..., V={v}, C]"),
                b,
            ));
        }
        let c = s[s.len() - 1];
        let nb = s[..s.len() - 2].iter().product::<i64>();
        let (device, kind) = (b.device(), b.kind());
        let work = match kind {
            Kind::Double => Kind::Double,
            Kind::Float | Kind::Half | Kind::BFloat16 => Kind::Float,
            k => {
                return Err(KernelError::Kind {
                    what: "Poisson solve".into(),
                    kind: k,
                });
            }
        };
        // a [nb, V, C] copy, solved in place (see `solve_channels`)
        let mut buf = Tensor::empty([nb, v, c], (work, Device::Cpu));
        buf.copy_(&b.reshape([nb, v, c]));
        let (items, rows, width) = (nb as usize, v as usize, c as usize);
        if work == Kind::Double {
            let data = SyncPtr(buf.data_ptr() as *mut f64);
            solve_channels(self.solver.factor()?, data, items, rows, width)?;
        } else {
            let data = SyncPtr(buf.data_ptr() as *mut f32);
            solve_channels(self.solver.factor_f32(), data, items, rows, width)?;
        }
        let out = buf.reshape(s.as_slice());
        Ok(if kind != work || device != Device::Cpu {
            out.to_kind(kind).to_device(device)
        } else {
            out
        })
    }
}

impl LinearOperator for PoissonSolveOp {
    fn name(&self) -> &str {
        "poisson_solve"
    }

    fn apply(&self, x: &Tensor) -> Result<Tensor> {
        self.solve(x)
    }

    fn apply_adjoint(&self, y: &Tensor) -> Result<Tensor> {
        // L + eps I is symmetric
        self.solve(y)
    }
}

/// Mass-weighted projection onto zero mean per connected component.
#[derive(Debug)]
struct MeanRemoval {
    /// Number of vertex components `K`.
    components: usize,
    /// `[K, V]` row-major: `m_v / M_k` for `v` in component `k`.
    weights: Vec<f64>,
    /// `[V, K]` row-major indicator; unused when `K == 1`.
    indicator: Vec<f64>,
}

impl MeanRemoval {
    fn weights(&self, nv: usize, like: &Tensor) -> Tensor {
        Tensor::from_slice(&self.weights)
            .reshape([self.components as i64, nv as i64])
            .to_kind(like.kind())
            .to_device(like.device())
    }

    fn indicator(&self, nv: usize, like: &Tensor) -> Tensor {
        Tensor::from_slice(&self.indicator)
            .reshape([nv as i64, self.components as i64])
            .to_kind(like.kind())
            .to_device(like.device())
    }
}

/// Vertex positions as the `f32` tensor `[1, V, 3]` on `device` that a
/// network takes them as (a shape's signal, a source's conditioning).
pub fn positions_tensor(positions: &[[f64; 3]], device: Device) -> Tensor {
    let flat: Vec<f32> = positions.iter().flat_map(|p| p.map(|x| x as f32)).collect();
    Tensor::from_slice(&flat)
        .reshape([1, positions.len() as i64, 3])
        .to_device(device)
}

/// Everything PoissonNet needs from one triangle mesh, as tensors and
/// differentiable operators. See the [module docs](self).
///
/// Cheap to clone (operators and the factor are shared); `Send + Sync`.
pub struct MeshTensors {
    num_vertices: usize,
    num_faces: usize,
    gradient: Arc<dyn LinearOperator>,
    weighted_gradient: Arc<dyn LinearOperator>,
    rotated_weighted_gradient: Arc<dyn LinearOperator>,
    paired_weighted_gradient: Arc<dyn LinearOperator>,
    face_mean: Arc<dyn LinearOperator>,
    solve: Arc<dyn LinearOperator>,
    face_ops: [Arc<FaceOperator>; 4],
    solver: Arc<LaplacianSolver>,
    mass: Arc<Vec<f64>>,
    face_areas_interleaved: Arc<Vec<f64>>,
    faces: Arc<Vec<[u32; 3]>>,
    mean: Arc<MeanRemoval>,
    backend: Backend,
}

impl Clone for MeshTensors {
    fn clone(&self) -> Self {
        Self {
            gradient: Arc::clone(&self.gradient),
            weighted_gradient: Arc::clone(&self.weighted_gradient),
            rotated_weighted_gradient: Arc::clone(&self.rotated_weighted_gradient),
            paired_weighted_gradient: Arc::clone(&self.paired_weighted_gradient),
            face_mean: Arc::clone(&self.face_mean),
            face_ops: self.face_ops.clone(),
            mass: Arc::clone(&self.mass),
            face_areas_interleaved: Arc::clone(&self.face_areas_interleaved),
            faces: Arc::clone(&self.faces),
            solve: Arc::clone(&self.solve),
            solver: Arc::clone(&self.solver),
            mean: Arc::clone(&self.mean),
            ..*self
        }
    }
}

impl std::fmt::Debug for MeshTensors {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("MeshTensors")
            .field("num_vertices", &self.num_vertices)
            .field("num_faces", &self.num_faces)
            .field("components", &self.mean.components)
            .field("eps", &self.solver.eps())
            .field("backend", &self.backend)
            .finish()
    }
}

impl MeshTensors {
    /// Builds the operators of `mesh` and factors `L + eps I` (`eps = 1e-6`,
    /// grown x10 until the factorization succeeds).
    ///
    /// Cost: the operators (`O(V + F)`) plus one sparse Cholesky factorization.
    ///
    /// Errors: [`KernelError::Operators`] for a degenerate face,
    /// [`KernelError::Solver`] if no shift gives a factorization.
    pub fn new(mesh: &TriMesh) -> Result<Self> {
        Self::with_shift(mesh, &ShiftOptions::default())
    }

    /// [`MeshTensors::new`] with explicit options for the shift of `L + eps I`.
    pub fn with_shift(mesh: &TriMesh, shift: &ShiftOptions) -> Result<Self> {
        let ops = Operators::new(mesh)?;
        let solver = Arc::new(LaplacianSolver::with_options(&ops.laplacian, shift)?);
        Self::from_operators(mesh.faces(), &ops, solver)
    }

    /// Assembles the tensors from prebuilt operators and a factor of
    /// `L + eps I` for the same mesh (e.g. shared with other users of the
    /// factor). `G` is read face by face from
    /// [`Operators::face_gradients`] (so a `G` in other face frames is given
    /// by rotating that table's rows); the sparse [`Operators::gradient`] is
    /// not used.
    ///
    /// Cost: `O(V + F)` copies plus the connected components.
    ///
    /// Errors: [`KernelError::Shape`] when the sizes of `faces`, the operators and
    /// the factor disagree.
    pub fn from_operators(
        faces: &[[u32; 3]],
        ops: &Operators,
        solver: Arc<LaplacianSolver>,
    ) -> Result<Self> {
        let nf = faces.len();
        let nv = ops.mass.len();
        let bad = |what: &str, expected: String, found: Vec<i64>| KernelError::Shape {
            what: what.into(),
            expected,
            found,
        };
        if ops.face_gradients.len() != nf {
            return Err(bad(
                "per-face gradient rows of G",
                format!("[F={nf}, 2, 3]"),
                vec![ops.face_gradients.len() as i64, 2, 3],
            ));
        }
        if ops.face_areas_interleaved.len() != 2 * nf {
            return Err(bad(
                "interleaved face areas A2",
                format!("[2F={}]", 2 * nf),
                vec![ops.face_areas_interleaved.len() as i64],
            ));
        }
        if solver.dim() != nv {
            return Err(bad(
                "factor of L + eps I",
                format!("[V={nv}, V]"),
                vec![solver.dim() as i64],
            ));
        }
        if let Some(t) = faces.iter().find(|t| t.iter().any(|&i| i as usize >= nv)) {
            return Err(bad(
                "face vertex index",
                format!("indices < V={nv}"),
                t.iter().map(|&i| i64::from(i)).collect(),
            ));
        }
        // G's coefficients per face corner, as geometry built them
        let g: Vec<f64> = ops
            .face_gradients
            .iter()
            .flatten()
            .flatten()
            .copied()
            .collect();
        let a2 = &ops.face_areas_interleaved;
        let gw: Vec<f64> = g.iter().enumerate().map(|(i, &c)| c * a2[i / 3]).collect();
        // the same rows turned by a quarter turn in each face's frame:
        // (x, y) coefficient rows -> (y, -x), so that its adjoint applied to
        // (re, im) rows gives the divergence of i y
        let mut gw_rot = vec![0.0f64; nf * 2 * 3];
        for f in 0..nf {
            for j in 0..3 {
                gw_rot[(2 * f) * 3 + j] = gw[(2 * f + 1) * 3 + j];
                gw_rot[(2 * f + 1) * 3 + j] = -gw[(2 * f) * 3 + j];
            }
        }
        let mean: Vec<f64> = vec![1.0 / 3.0; nf * 3];
        let faces_arc = Arc::new(faces.to_vec());
        let inc = Arc::new(Incidence::new(nv, faces));
        let backend = Backend::Native;
        let mk = |name, rows, coef| {
            Arc::new(FaceOperator::new(
                name,
                rows,
                nv,
                Arc::clone(&faces_arc),
                Arc::clone(&inc),
                coef,
                backend,
            ))
        };
        let face_ops = [
            mk("gradient", 2, g),
            mk("area_weighted_gradient", 2, gw),
            mk("face_mean", 1, mean),
            mk("rotated_area_weighted_gradient", 2, gw_rot),
        ];
        let mean = Arc::new(Self::mean_removal(nv, faces, &ops.mass));
        let solve: Arc<dyn LinearOperator> = Arc::new(PoissonSolveOp {
            solver: Arc::clone(&solver),
        });
        Ok(Self {
            num_vertices: nv,
            num_faces: nf,
            gradient: face_ops[0].clone(),
            weighted_gradient: face_ops[1].clone(),
            face_mean: face_ops[2].clone(),
            rotated_weighted_gradient: face_ops[3].clone(),
            paired_weighted_gradient: PairedDivergenceOp::of(&face_ops),
            solve,
            face_ops,
            solver,
            mass: Arc::new(ops.mass.clone()),
            face_areas_interleaved: Arc::new(a2.clone()),
            faces: faces_arc,
            mean,
            backend,
        })
    }

    fn mean_removal(nv: usize, faces: &[[u32; 3]], mass: &[f64]) -> MeanRemoval {
        let (label, k) = Topology::new(nv, faces).vertex_components();
        let k = k.max(1);
        let mut totals = vec![0.0f64; k];
        for (v, &l) in label.iter().enumerate() {
            if l != u32::MAX {
                totals[l as usize] += mass[v];
            }
        }
        let mut w = vec![0.0f64; k * nv];
        let mut ind = vec![0.0f64; nv * k];
        for (v, &l) in label.iter().enumerate() {
            if l != u32::MAX && totals[l as usize] > 0.0 {
                let l = l as usize;
                w[l * nv + v] = mass[v] / totals[l];
                ind[v * k + l] = 1.0;
            }
        }
        MeanRemoval {
            components: k,
            weights: w,
            indicator: ind,
        }
    }

    /// The same mesh with another [`Backend`] for `G`, `G^T` and face means
    /// (the factor and tables are shared): with [`Backend::Torch`], the
    /// independent torch path that the tests compare the Rust kernels
    /// against. Only with the crate's `reference` feature (the crate's own
    /// tests turn it on).
    #[cfg(feature = "reference")]
    pub fn with_backend(&self, backend: Backend) -> Self {
        let ops = self
            .face_ops
            .clone()
            .map(|op| Arc::new(op.with_backend(backend)));
        Self {
            gradient: ops[0].clone(),
            weighted_gradient: ops[1].clone(),
            face_mean: ops[2].clone(),
            rotated_weighted_gradient: ops[3].clone(),
            paired_weighted_gradient: PairedDivergenceOp::of(&ops),
            face_ops: ops,
            backend,
            mass: Arc::clone(&self.mass),
            face_areas_interleaved: Arc::clone(&self.face_areas_interleaved),
            faces: Arc::clone(&self.faces),
            solve: Arc::clone(&self.solve),
            solver: Arc::clone(&self.solver),
            mean: Arc::clone(&self.mean),
            ..*self
        }
    }

    /// The backend of the face/vertex operators.
    pub fn backend(&self) -> Backend {
        self.backend
    }

    /// Number of vertices `V`.
    pub fn num_vertices(&self) -> usize {
        self.num_vertices
    }

    /// Number of faces `F`.
    pub fn num_faces(&self) -> usize {
        self.num_faces
    }

    /// Number of connected components (of referenced vertices; at least 1).
    pub fn num_components(&self) -> usize {
        self.mean.components
    }

    /// The mesh's faces cut into blocks of at most `max_faces` consecutive
    /// faces, each a [`MeshTensors`] over all `V` vertices and its own faces
    /// only: its [`MeshTensors::gradient`], [`MeshTensors::face_mean`] and
    /// face-to-vertex maps ([`MeshTensors::divergence`],
    /// [`MeshTensors::paired_divergence`]) are the whole mesh's restricted
    /// to those faces, so a per-face computation run block by block and its
    /// divergences summed gives the whole mesh's (up to the order of the
    /// sums). The factor, the mass and the mean removal are shared with
    /// `self`. Inference on a very fine mesh uses them to hold the
    /// activations of one block of faces at a time instead of all of them.
    ///
    /// Cost: the face tables once more, in pieces; the factor is not copied.
    pub fn face_blocks(&self, max_faces: usize) -> Vec<MeshTensors> {
        let max_faces = max_faces.max(1);
        let nv = self.num_vertices;
        (0..self.num_faces)
            .step_by(max_faces)
            .map(|start| {
                let end = (start + max_faces).min(self.num_faces);
                let faces = Arc::new(self.faces[start..end].to_vec());
                let inc = Arc::new(Incidence::new(nv, &faces));
                let face_ops = self.face_ops.clone().map(|op| {
                    let per_face = op.rows * 3;
                    Arc::new(FaceOperator::new(
                        op.name,
                        op.rows,
                        nv,
                        Arc::clone(&faces),
                        Arc::clone(&inc),
                        op.coef64[start * per_face..end * per_face].to_vec(),
                        op.backend,
                    ))
                });
                MeshTensors {
                    num_vertices: nv,
                    num_faces: end - start,
                    gradient: face_ops[0].clone(),
                    weighted_gradient: face_ops[1].clone(),
                    face_mean: face_ops[2].clone(),
                    rotated_weighted_gradient: face_ops[3].clone(),
                    paired_weighted_gradient: PairedDivergenceOp::of(&face_ops),
                    solve: Arc::clone(&self.solve),
                    face_ops,
                    solver: Arc::clone(&self.solver),
                    mass: Arc::clone(&self.mass),
                    face_areas_interleaved: Arc::new(
                        self.face_areas_interleaved[2 * start..2 * end].to_vec(),
                    ),
                    faces,
                    mean: Arc::clone(&self.mean),
                    backend: self.backend,
                }
            })
            .collect()
    }

    /// The factor of `L + eps I` every solve on this mesh uses.
    pub fn solver(&self) -> &Arc<LaplacianSolver> {
        &self.solver
    }

    /// Lumped mass as a new `[V]` `f64` CPU tensor.
    pub fn mass(&self) -> Tensor {
        Tensor::from_slice(&self.mass)
    }

    /// Total surface area (the sum of the lumped mass).
    pub fn total_area(&self) -> f64 {
        self.mass.iter().sum()
    }

    /// Interleaved face areas `A2` as a new `[2F]` `f64` CPU tensor.
    pub fn face_areas_interleaved(&self) -> Tensor {
        Tensor::from_slice(&self.face_areas_interleaved)
    }

    /// Faces as a new `[F, 3]` `i64` CPU tensor.
    pub fn faces(&self) -> Tensor {
        let flat: Vec<i64> = self.faces.iter().flat_map(|t| t.map(i64::from)).collect();
        Tensor::from_slice(&flat).reshape([self.num_faces as i64, 3])
    }

    /// `G x`: `[..., V, C] -> [..., 2F, C]`.
    pub fn gradient(&self, x: &Tensor) -> Result<Tensor> {
        apply_linear(&self.gradient, x, false)
    }

    /// `G^T y`: `[..., 2F, C] -> [..., V, C]`.
    pub fn gradient_adjoint(&self, y: &Tensor) -> Result<Tensor> {
        apply_linear(&self.gradient, y, true)
    }

    /// `G^T (A2 * y)` (the weak divergence; `divergence(gradient(u)) = L u`):
    /// `[..., 2F, C] -> [..., V, C]`.
    pub fn divergence(&self, y: &Tensor) -> Result<Tensor> {
        apply_linear(&self.weighted_gradient, y, true)
    }

    /// The weak divergence of the field turned by a quarter turn in every
    /// face, `G^T (A2 * (i y))` with `i y = (-y_im, y_re)` per face and
    /// channel: `[..., 2F, C] -> [..., V, C]`. Up to sign, the weak curl of `y`.
    ///
    /// With [`MeshTensors::divergence`] it lets a complex linear map `W`
    /// followed by the divergence act on vertices instead of faces:
    /// `divergence(W y) = divergence(y) Wr^T + rotated_divergence(y) Wi^T`
    /// (`W = Wr + i Wi` acting on channels), since `W` mixes channels and
    /// the divergence mixes faces.
    pub fn rotated_divergence(&self, y: &Tensor) -> Result<Tensor> {
        apply_linear(&self.rotated_weighted_gradient, y, true)
    }

    /// `[divergence(y) | rotated_divergence(y)]`, `[..., 2F, C] -> [..., V,
    /// 2C]`, in one pass over `y` on the CPU (and one pass in its backward).
    pub fn paired_divergence(&self, y: &Tensor) -> Result<Tensor> {
        apply_linear(&self.paired_weighted_gradient, y, true)
    }

    /// Mean of `x` over each face's three vertices: `[..., V, C] -> [..., F, C]`.
    pub fn face_mean(&self, x: &Tensor) -> Result<Tensor> {
        apply_linear(&self.face_mean, x, false)
    }

    /// Adjoint of [`MeshTensors::face_mean`]: each face spreads a third of its
    /// value to each of its vertices, `[..., F, C] -> [..., V, C]`.
    pub fn face_mean_adjoint(&self, y: &Tensor) -> Result<Tensor> {
        apply_linear(&self.face_mean, y, true)
    }

    /// `(L + eps I)^-1 b` for `b: [..., V, C]` (every batch item and channel is
    /// one right-hand side of a single multi-column solve). The backward pass
    /// solves the incoming gradient with the same factor.
    ///
    /// Right-hand sides with zero sum per component (such as anything from
    /// [`MeshTensors::divergence`]) give the Poisson solution up to an `O(eps)`
    /// perturbation; other components are amplified by `1/eps`.
    pub fn solve(&self, b: &Tensor) -> Result<Tensor> {
        apply_linear(&self.solve, b, false)
    }

    fn check_vertex(&self, u: &Tensor, what: &str) -> Result<()> {
        let s = u.size();
        if s.len() < 2 || s[s.len() - 2] != self.num_vertices as i64 {
            return Err(shape_error(
                what,
                format!("[..., V={}, C]", self.num_vertices),
                u,
            ));
        }
        Ok(())
    }

    /// Mass-weighted mean of each channel over each connected component,
    /// `[..., V, C] -> [..., K, C]` (`K` components; `K = 1` for a connected
    /// mesh).
    pub fn mass_weighted_mean(&self, u: &Tensor) -> Result<Tensor> {
        self.check_vertex(u, "mass-weighted mean")?;
        Ok(self.mean.weights(self.num_vertices, u).matmul(u))
    }

    /// `u` minus its mass-weighted mean, per channel and connected component.
    pub fn remove_mass_mean(&self, u: &Tensor) -> Result<Tensor> {
        let mean = self.mass_weighted_mean(u)?;
        if self.mean.components == 1 {
            Ok(u - mean)
        } else {
            Ok(u - self.mean.indicator(self.num_vertices, u).matmul(&mean))
        }
    }

    /// Mass-weighted sum over vertices of `a * b` summed over channels, per
    /// batch item: `sum_v m_v sum_c a[.., v, c] b[.., v, c]`, shape `[...]`.
    pub fn mass_inner(&self, a: &Tensor, b: &Tensor) -> Result<Tensor> {
        self.check_vertex(a, "mass inner product")?;
        let m = self
            .mass()
            .to_kind(a.kind())
            .to_device(a.device())
            .unsqueeze(-1);
        Ok((a * b * m).sum_dim_intlist([-2i64, -1].as_slice(), false, a.kind()))
    }
}
