//! As-rigid-as-possible surface deformation (Sorkine & Alexa 2007) with
//! cotangent weights, handle regions as hard (Dirichlet) constraints, and an
//! optional smoothness term on the rotation field (as in smooth-rotation
//! ARAP, Levi & Gotsman 2014) that makes the result consistent across
//! resolutions.
//!
//! ## The energy
//! With rest positions `p`, deformed positions `x`, the cotangent weight
//! `w_ij = (cot a_ij + cot b_ij) / 2 = -L_ij` of each edge (`L` the PSD
//! cotangent Laplacian of [`mfm_geometry::operators::cotangent_laplacian`];
//! a negative weight, from two opposite angles summing to more than 180
//! degrees, is set to 0 and `L`'s diagonal re-summed, since with negative
//! weights the energy below is unbounded and the iteration diverges; a mesh
//! without negative weights uses `L` unchanged) and one rotation `R_i` per
//! vertex,
//!
//! ```text
//! E(x, R) = sum_i sum_{j in N(i)} w_ij |(x_i - x_j) - R_i (p_i - p_j)|^2
//!         + beta sum_i sum_{j in N(i)} w_ij |R_i - R_j|_F^2
//! ```
//!
//! (each edge appears twice, once from each end). The first term is the
//! classic ARAP energy, a discretization of `int |grad x - R|^2 dA`; the
//! second is the Dirichlet energy of the rotation field,
//! `int |grad R|^2 dA`, weighted by `beta = (s d)^2` with `s` =
//! [`ArapOptions::smoothness`] and `d` the bounding-box diagonal of the rest
//! mesh (so `s d` is a length: roughly the shortest wavelength of a bend).
//! Both terms are scale-consistent, so the energy has a limit as the mesh
//! is refined.
//!
//! **Why the smoothness term.** Pure surface ARAP has no bending stiffness:
//! where a pose compresses the surface, the energy is lowered by buckling
//! into folds as narrow as the mesh allows, so converged shapes differ
//! between a mesh and its refinement (on the procedural blob, same
//! parameters: about 14-40% of the largest displacement between 642 and
//! 2562 vertices, with visible creases on the finer mesh). The rotation
//! term penalizes folds narrower than about `s d` and restores agreement
//! across resolutions. `smoothness = 0` gives classic ARAP.
//!
//! [`Arap::energy`] is `E(x, R)` minimized over the rotations (exactly when
//! `beta = 0`, by block coordinate descent otherwise). It is 0 exactly for
//! rigid motions of the rest shape and scales like a squared length.
//!
//! ## The solver
//! Vertices in a handle region are **constrained**: their positions are the
//! handle's rigid motion of their rest positions. The others are **free**.
//! Alternating minimization; no step ever raises the energy:
//! - *global step*: for fixed `R`, the free positions solve
//!   `L_FF x_F = b_F - L_FC x_C` with
//!   `b_i = sum_j w_ij / 2 (R_i + R_j)(p_i - p_j)` (exact minimizer): one
//!   3-column solve with the Cholesky factor of the free-free block `L_FF`,
//!   computed **once** in [`Arap::new`] (mfm-solver's [`CholeskyFactor`]);
//! - *local step* with `beta = 0`: each `R_i` maximizes `<R_i, K_i>_F`,
//!   `K_i = sum_j w_ij (x_i - x_j)(p_i - p_j)^T`
//!   ([`crate::rigid::best_rotation`]: proper rotations only, reflections
//!   handled), in parallel over vertices (exact minimizer);
//! - *local step* with `beta > 0`: the rotations are coupled. Two moves:
//!   (a) a *smoothed candidate*: the per-vertex fits `F_i` above, smoothed
//!   by one implicit diffusion step `(D + 2 beta L) Y = D F` (`D` the rest
//!   stiffness `sum_j w_ij |p_i - p_j|^2 / 3` of each cell; the factor is
//!   built once per `beta`) and projected back onto rotations; it is taken
//!   when it lowers the energy. It spreads rotations over the length
//!   `sqrt(beta)` in one step. (b) Otherwise one *Gauss-Seidel sweep*: each
//!   `R_i` set to the exact minimizer `argmax <R_i, K_i + 2 beta sum_j w_ij R_j>`
//!   with its neighbours fixed, over a greedy vertex coloring (no two
//!   neighbours share a color), each color class in parallel.
//!
//! The positions are accelerated with Anderson acceleration
//! ([`ArapOptions::anderson`] past iterates, Peng et al. 2018), safeguarded:
//! an accelerated iterate is kept only if it lowers the energy, otherwise
//! the plain local/global iterate is taken. So the reported energies never
//! increase.
//!
//! **Initial guess** (a design choice): one global step with per-vertex
//! rotations *blended* from the handle rotations. [`Arap::new`] computes the
//! harmonic weights of the handles once (`L_FF W_F = -L_FC W_C` with `W_C`
//! the indicator of each handle region: a partition of unity over the
//! surface, one multi-column solve), and each free vertex starts with the
//! rotation whose axis-angle vector is the weighted sum of the handles'
//! (the anchor's included). The first global step then spreads both the
//! rotations and the translations of the handles smoothly over the surface.
//! For a common rigid motion of all handles this initial guess is already
//! the exact answer; in general it is a smooth, resolution-independent
//! starting point much closer to the result than the rest shape with only
//! the handles moved.
//!
//! Iteration stops after [`ArapOptions::max_iterations`] global steps, as
//! soon as an iteration does not lower the energy at all (it reached 0, or
//! is stuck at round-off), or when the energy decreased by less than
//! [`ArapOptions::tolerance`] times its magnitude per iteration, on average
//! over the last three iterations (a single accelerated step can stall
//! while the following ones still make progress). The default tolerance,
//! `1e-3`, is loose on purpose: with the smoothness term the energy keeps
//! creeping down by about `1e-4` per iteration for dozens of iterations
//! while the shape barely moves (see the crate's timing example for
//! measurements).
//!
//! Obtuse triangles give negative cotangent weights. Both steps stay exact
//! minimizations (`L` is PSD and [`crate::rigid::best_rotation`] maximizes
//! for any `K`), so the energy still never increases, but a strongly
//! deformed shape on such a mesh can reach a (slightly) negative energy.
//!
//! ## Cost
//! [`Arap::new`]: building `L`, the fill-reducing ordering and the numeric
//! factorization (`O(nnz(factor))` memory), the harmonic weights (one solve
//! with one column per handle) and the coloring; the first deformation with
//! a new smoothness also factors `D + 2 beta L`. Each iteration: one or two
//! local steps (`O(V)` small eigenproblems each, parallel, plus a 9-column
//! solve when `beta > 0`) and one 3-column solve (`~12 nnz(factor)` flops). Results do not depend on the
//! number of threads: no floating-point reduction runs in parallel.
//!
//! # Example
//! ```
//! use mfm_deform::{Arap, ArapOptions, DeformParams, HandleSet, RigidParams};
//! use mfm_geometry::procedural;
//!
//! let mesh = procedural::blob(3).unwrap();
//! let handles = HandleSet::auto(&mesh, 2, 0.1).unwrap();
//! let arap = Arap::new(&mesh, &handles).unwrap();
//! // lift the first moving handle and twist it
//! let mut params = DeformParams::identity(2);
//! params.handles[0] = RigidParams { rotation: [0.0, 0.3, 0.0], translation: [0.0, 0.2, 0.0] };
//! let out = arap.deform(&params, &ArapOptions::default()).unwrap();
//! assert_eq!(out.positions.len(), mesh.num_vertices());
//! // the energy never increases
//! assert!(out.energies.windows(2).all(|e| e[1] <= e[0] * (1.0 + 1e-12)));
//! ```

use faer::Mat;
use faer::sparse::{SparseColMat, Triplet};
use mfm_geometry::{TriMesh, operators};
use mfm_solver::CholeskyFactor;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use std::sync::{Arc, Mutex};

use crate::anderson::Anderson;
use crate::error::{DeformError, Result};
use crate::handles::{DeformParams, HandleSet, RigidParams};
use crate::rigid::{Mat3, RigidTransform, axis_angle_to_matrix, best_rotation, mat_vec};

/// Vertices per parallel task in the local step and the right-hand side.
const VERTEX_CHUNK: usize = 512;

/// Iterations over which [`ArapOptions::tolerance`] is averaged.
const STOP_WINDOW: usize = 3;

/// Marks a vertex that belongs to no handle.
const FREE: u32 = u32::MAX;

/// Local steps [`Arap::energy`] runs at most to minimize over rotations.
pub const ENERGY_STEPS: usize = 100;

/// Solver options of [`Arap::deform`]: stopping rule, acceleration and the
/// weight of the rotation smoothness term.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ArapOptions {
    /// Largest number of local/global iterations (global solves after the
    /// initial guess). Default 50.
    pub max_iterations: usize,
    /// Stop when the energy decreases by less than `tolerance` times its
    /// magnitude per iteration, averaged over the last three iterations.
    /// Default `1e-3` (see the [module docs](self)).
    pub tolerance: f64,
    /// Window of the Anderson acceleration (number of past iterates used);
    /// 0 gives plain local/global iterations. Default 5.
    #[serde(default = "default_anderson")]
    pub anderson: usize,
    /// Length scale `s` of the rotation smoothness term, as a fraction of
    /// the bounding-box diagonal of the rest mesh: `beta = (s d)^2` (see the
    /// [module docs](self)). 0 gives classic ARAP. Default 0.05.
    #[serde(default = "default_smoothness")]
    pub smoothness: f64,
}

fn default_anderson() -> usize {
    5
}

fn default_smoothness() -> f64 {
    0.05
}

impl Default for ArapOptions {
    fn default() -> Self {
        Self {
            max_iterations: 50,
            tolerance: 1e-3,
            anderson: default_anderson(),
            smoothness: default_smoothness(),
        }
    }
}

impl ArapOptions {
    fn validate(&self) -> Result<()> {
        if !(self.tolerance.is_finite() && self.tolerance >= 0.0) {
            return Err(DeformError::InvalidParameter {
                name: "tolerance",
                expected: "a finite relative energy change >= 0",
                found: self.tolerance.to_string(),
            });
        }
        if !(self.smoothness.is_finite() && self.smoothness >= 0.0) {
            return Err(DeformError::InvalidParameter {
                name: "smoothness",
                expected: "a finite fraction >= 0 of the bounding-box diagonal",
                found: self.smoothness.to_string(),
            });
        }
        Ok(())
    }
}

/// Result of [`Arap::deform`].
#[derive(Clone, Debug, PartialEq)]
pub struct Deformation {
    /// Deformed vertex positions (`V`).
    pub positions: Vec<[f64; 3]>,
    /// Energy `E(x, R)` of the initial guess, then after each iteration:
    /// `iterations + 1` values, non-increasing up to round-off.
    pub energies: Vec<f64>,
    /// Number of iterations done (global solves after the initial guess).
    pub iterations: usize,
}

/// An ARAP solver for one rest mesh and one handle set: the cotangent
/// weights, the handle regions and the Cholesky factor of the free-free
/// block of `L`, ready for any number of [`Arap::deform`] calls (from any
/// number of threads: `Arap` is `Send + Sync`). See the [module docs](self).
#[derive(Debug)]
pub struct Arap {
    rest: TriMesh,
    handles: HandleSet,
    regions: Vec<Vec<usize>>,
    mass: Vec<f64>,
    diagonal: f64,
    /// `handle_of[v]`: index (anchor first) of the handle holding `v`, or `FREE`.
    handle_of: Vec<u32>,
    /// Free vertices, ascending (free index -> vertex).
    free: Vec<usize>,
    /// `free_slot[v]`: free index of `v`, or `usize::MAX` if constrained.
    free_slot: Vec<usize>,
    /// One-ring in CSR form, diagonal excluded: neighbours, weights `w_ij`
    /// and rest edge vectors `p_i - p_j`.
    ring_ptr: Vec<usize>,
    ring: Vec<u32>,
    weight: Vec<f64>,
    rest_edge: Vec<[f64; 3]>,
    /// Vertex classes with no two neighbours in one class.
    colors: Vec<Vec<u32>>,
    factor: CholeskyFactor,
    /// Harmonic weights of the handles at the free vertices, row-major
    /// (`free index * handles + handle`).
    harmonic: Vec<f64>,
    /// Rest stiffness of each vertex's cell, `sum_j w_ij |p_i - p_j|^2 / 3`
    /// (clamped positive): the diagonal `D` of the rotation smoother.
    stiffness: Vec<f64>,
    /// The full Laplacian, lower triangle (for the rotation smoother).
    laplacian: SparseColMat<usize, f64>,
    /// Factors of `D + 2 beta L`, one per `beta` used so far.
    smoothers: Mutex<Vec<(u64, Arc<CholeskyFactor>)>>,
}

impl Arap {
    /// Builds the solver: cotangent Laplacian and lumped mass of `rest`,
    /// handle regions, the Cholesky factorization of `L_FF`, the harmonic
    /// weights of the handles and a vertex coloring.
    ///
    /// # Errors
    /// [`DeformError::EmptyHandle`] / [`DeformError::OverlappingHandles`]
    /// from [`HandleSet::regions`]; [`DeformError::UnconstrainedVertex`]
    /// when a free vertex has no path to a handle (a component without a
    /// handle, an unreferenced vertex); [`DeformError::Solver`] if the
    /// factorization fails anyway (e.g. a badly degenerate mesh).
    pub fn new(rest: &TriMesh, handles: &HandleSet) -> Result<Self> {
        let regions = handles.regions(rest)?;
        Self::with_regions(rest, handles, regions)
    }

    /// [`Arap::new`] with the handles' vertex regions given instead of
    /// selected by the balls on `rest`. This is how a changed body shape of
    /// a template is posed: the regions are chosen once on the template and
    /// keep their vertices when the shape moves them (see
    /// [`crate::shape`]); `handles` supplies the centres the rigid motions
    /// turn about.
    ///
    /// # Errors
    /// [`DeformError::SizeMismatch`] unless there is one region per handle;
    /// [`DeformError::InvalidParameter`] for an empty region, a vertex
    /// outside the mesh or in two regions; otherwise as [`Arap::new`].
    pub fn with_regions(
        rest: &TriMesh,
        handles: &HandleSet,
        regions: Vec<Vec<usize>>,
    ) -> Result<Self> {
        let n = rest.num_vertices();
        check_regions(n, handles, &regions)?;
        let mut handle_of = vec![FREE; n];
        for (h, region) in regions.iter().enumerate() {
            for &v in region {
                handle_of[v] = h as u32;
            }
        }
        let l = nonnegative_weights(operators::cotangent_laplacian(rest))?;
        let mass = operators::lumped_mass(rest);

        // one-rings from the columns of L (both triangles are stored)
        let col_ptr = l.symbolic().col_ptr();
        let row_idx = l.symbolic().row_idx();
        let val = l.val();
        let pos = rest.positions();
        let mut ring_ptr = Vec::with_capacity(n + 1);
        let mut ring = Vec::with_capacity(col_ptr[n]);
        let mut weight = Vec::with_capacity(col_ptr[n]);
        let mut rest_edge = Vec::with_capacity(col_ptr[n]);
        ring_ptr.push(0);
        for i in 0..n {
            for k in col_ptr[i]..col_ptr[i + 1] {
                let j = row_idx[k];
                if j != i {
                    ring.push(j as u32);
                    weight.push(-val[k]);
                    rest_edge.push(sub3(pos[i], pos[j]));
                }
            }
            ring_ptr.push(ring.len());
        }

        check_connected(n, &handle_of, &ring_ptr, &ring, &weight)?;

        // free numbering keeps vertex order, so "lower in the free block"
        // is "lower in L"
        let free: Vec<usize> = (0..n).filter(|&v| handle_of[v] == FREE).collect();
        let mut free_slot = vec![usize::MAX; n];
        for (f, &v) in free.iter().enumerate() {
            free_slot[v] = f;
        }
        let mut triplets = Vec::new();
        for (fc, &c) in free.iter().enumerate() {
            for k in col_ptr[c]..col_ptr[c + 1] {
                let r = row_idx[k];
                if r >= c && handle_of[r] == FREE {
                    triplets.push(Triplet::new(free_slot[r], fc, val[k]));
                }
            }
        }
        let nf = free.len();
        let lff =
            SparseColMat::<usize, f64>::try_new_from_triplets(nf, nf, &triplets).map_err(|e| {
                DeformError::InvalidParameter {
                    name: "free-free block of L",
                    expected: "a sparse matrix faer can assemble",
                    found: format!("{e:?}"),
                }
            })?;
        let factor = CholeskyFactor::new(lff.as_ref()).map_err(|source| DeformError::Solver {
            context: "factorization of the free-free block of the cotangent Laplacian",
            source,
        })?;
        let colors = greedy_coloring(n, &ring_ptr, &ring);
        let mut stiffness: Vec<f64> = (0..n)
            .map(|i| {
                (ring_ptr[i]..ring_ptr[i + 1])
                    .map(|k| {
                        let e = rest_edge[k];
                        weight[k] * (e[0] * e[0] + e[1] * e[1] + e[2] * e[2])
                    })
                    .sum::<f64>()
                    / 3.0
            })
            .collect();
        let mean = stiffness.iter().map(|s| s.abs()).sum::<f64>() / n as f64;
        for s in stiffness.iter_mut() {
            *s = s.max(1e-3 * mean).max(f64::MIN_POSITIVE);
        }
        let mut arap = Self {
            rest: rest.clone(),
            handles: handles.clone(),
            regions,
            mass,
            diagonal: rest.bounding_box_diagonal(),
            handle_of,
            free,
            free_slot,
            ring_ptr,
            ring,
            weight,
            rest_edge,
            colors,
            factor,
            harmonic: Vec::new(),
            stiffness,
            laplacian: l,
            smoothers: Mutex::new(Vec::new()),
        };
        arap.harmonic = arap.harmonic_weights()?;
        Ok(arap)
    }

    /// The rest mesh.
    pub fn rest(&self) -> &TriMesh {
        &self.rest
    }

    /// The handle set.
    pub fn handles(&self) -> &HandleSet {
        &self.handles
    }

    /// The vertex region of each handle on the rest mesh (anchor first).
    pub fn regions(&self) -> &[Vec<usize>] {
        &self.regions
    }

    /// Lumped mass of the rest mesh (one value per vertex).
    pub fn mass(&self) -> &[f64] {
        &self.mass
    }

    /// Number of free (unconstrained) vertices, the dimension of `L_FF`.
    pub fn num_free(&self) -> usize {
        self.free.len()
    }

    /// Number of vertices in handle regions.
    pub fn num_constrained(&self) -> usize {
        self.rest.num_vertices() - self.free.len()
    }

    /// Number of color classes of the local sweep.
    pub fn num_colors(&self) -> usize {
        self.colors.len()
    }

    /// Deforms the rest shape with the anchor fixed and moving handle `k`
    /// moved by `params.handles[k]`; see the [module docs](self).
    ///
    /// # Errors
    /// [`DeformError::HandleCountMismatch`] unless there is one transform per
    /// moving handle; [`DeformError::NonFinite`] for a non-finite parameter;
    /// [`DeformError::InvalidParameter`] for invalid options.
    pub fn deform(&self, params: &DeformParams, opts: &ArapOptions) -> Result<Deformation> {
        self.deform_with_anchor(&RigidParams::identity(), params, opts)
    }

    /// [`Arap::deform`] with the anchor moved too (by `anchor`, about its
    /// center). Moving every handle by the same rigid motion gives that
    /// motion of the rest shape.
    ///
    /// # Errors
    /// As [`Arap::deform`].
    pub fn deform_with_anchor(
        &self,
        anchor: &RigidParams,
        params: &DeformParams,
        opts: &ArapOptions,
    ) -> Result<Deformation> {
        opts.validate()?;
        if params.handles.len() != self.handles.num_moving() {
            return Err(DeformError::HandleCountMismatch {
                expected: self.handles.num_moving(),
                found: params.handles.len(),
            });
        }
        let all: Vec<&RigidParams> = std::iter::once(anchor).chain(&params.handles).collect();
        for (i, p) in all.iter().enumerate() {
            if !p.is_finite() {
                let bad = if p.rotation.iter().all(|x| x.is_finite()) {
                    p.translation
                } else {
                    p.rotation
                };
                return Err(DeformError::NonFinite {
                    what: "handle motion (index 0 is the anchor)",
                    index: i,
                    value: bad,
                });
            }
        }
        let transforms: Vec<RigidTransform> = all
            .iter()
            .zip(self.handles.iter())
            .map(|(p, h)| p.to_transform(h.center))
            .collect();
        let beta = (opts.smoothness * self.diagonal).powi(2);

        // constrained vertices follow their handle
        let pos = self.rest.positions();
        let mut x: Vec<[f64; 3]> = pos.to_vec();
        for (v, xv) in x.iter_mut().enumerate() {
            let h = self.handle_of[v];
            if h != FREE {
                *xv = transforms[h as usize].apply(pos[v]);
            }
        }
        // initial guess: one global step with blended handle rotations
        let nh = self.handles.len();
        let mut rotations: Vec<Mat3> = (0..x.len())
            .into_par_iter()
            .with_min_len(VERTEX_CHUNK)
            .map(|v| {
                let h = self.handle_of[v];
                if h != FREE {
                    return transforms[h as usize].rotation;
                }
                let f = self.free_slot[v];
                let w = &self.harmonic[f * nh..(f + 1) * nh];
                let mut axis = [0.0; 3];
                for (wk, p) in w.iter().zip(&all) {
                    for (a, r) in axis.iter_mut().zip(p.rotation) {
                        *a += wk * r;
                    }
                }
                axis_angle_to_matrix(axis)
            })
            .collect();
        let first = self.global_step(&rotations, &x)?;
        self.set_free(&mut x, &first);

        let mut energy = self.local_step(&x, &mut rotations, beta)?;
        let mut energies = vec![energy];
        let mut iterations = 0;
        let mut anderson = Anderson::new(opts.anderson);
        while iterations < opts.max_iterations {
            let plain = self.global_step(&rotations, &x)?;
            let previous = energy;
            let current: Vec<f64> = self.free.iter().flat_map(|&v| x[v]).collect();
            let image: Vec<f64> = plain.iter().flatten().copied().collect();
            let mut accepted = false;
            if let Some(candidate) = anderson.step(&current, &image) {
                let trial: Vec<[f64; 3]> = candidate
                    .chunks_exact(3)
                    .map(|c| [c[0], c[1], c[2]])
                    .collect();
                let mut y = x.clone();
                self.set_free(&mut y, &trial);
                let mut r = rotations.clone();
                let e = self.local_step(&y, &mut r, beta)?;
                if e < previous {
                    (x, rotations, energy) = (y, r, e);
                    accepted = true;
                } else {
                    anderson.reset();
                }
            }
            if !accepted {
                self.set_free(&mut x, &plain);
                energy = self.local_step(&x, &mut rotations, beta)?;
            }
            energies.push(energy);
            iterations += 1;
            // stop when stuck, or when the mean relative decrease over the
            // last STOP_WINDOW iterations is below the tolerance (one step
            // alone can stall while the next ones still make progress)
            let stalled = previous - energy <= 0.0;
            let slow = iterations >= STOP_WINDOW && {
                let old = energies[iterations - STOP_WINDOW];
                old - energy <= opts.tolerance * STOP_WINDOW as f64 * old.abs()
            };
            if stalled || slow {
                break;
            }
        }
        Ok(Deformation {
            positions: x,
            energies,
            iterations,
        })
    }

    /// The energy of a shape with the smoothness of `opts`, minimized over
    /// the rotations: exactly (one per-vertex fit) when the smoothness is 0;
    /// otherwise by local steps from the per-vertex fits until the energy
    /// changes by less than `1e-9` relatively (at most [`ENERGY_STEPS`]), an
    /// upper bound of the minimum. Cost: up to that many local steps.
    ///
    /// # Errors
    /// [`DeformError::SizeMismatch`] unless there is one position per vertex;
    /// [`DeformError::InvalidParameter`] for invalid options.
    pub fn energy(&self, positions: &[[f64; 3]], opts: &ArapOptions) -> Result<f64> {
        opts.validate()?;
        if positions.len() != self.rest.num_vertices() {
            return Err(DeformError::SizeMismatch {
                what: "positions",
                expected: self.rest.num_vertices(),
                found: positions.len(),
            });
        }
        let beta = (opts.smoothness * self.diagonal).powi(2);
        let mut rotations = vec![[[0.0; 3]; 3]; positions.len()];
        self.local_sweep(positions, &mut rotations, 0.0);
        let mut energy = self.energy_with(positions, &rotations, beta);
        if beta > 0.0 {
            for _ in 0..ENERGY_STEPS {
                let e = self.local_step(positions, &mut rotations, beta)?;
                let done = energy - e <= 1e-9 * energy.abs();
                energy = e;
                if done {
                    break;
                }
            }
        }
        Ok(energy)
    }

    /// Harmonic extension of the indicator of each handle region to the free
    /// vertices (row-major, one row per free vertex): one solve with one
    /// column per handle.
    fn harmonic_weights(&self) -> Result<Vec<f64>> {
        let h = self.handles.len();
        let nf = self.free.len();
        let b = Mat::<f64>::from_fn(nf, h, |f, col| {
            let i = self.free[f];
            (self.ring_ptr[i]..self.ring_ptr[i + 1])
                .filter(|&k| self.handle_of[self.ring[k] as usize] == col as u32)
                .map(|k| self.weight[k])
                .sum()
        });
        let w = self
            .factor
            .solve_many(b.as_ref())
            .map_err(|source| DeformError::Solver {
                context: "harmonic handle weights",
                source,
            })?;
        Ok((0..nf * h).map(|t| w[(t / h, t % h)]).collect())
    }

    /// One global step: the free positions (in free order) minimizing the
    /// energy for the given per-vertex rotations (constrained positions are
    /// read from `x`).
    fn global_step(&self, rotations: &[Mat3], x: &[[f64; 3]]) -> Result<Vec<[f64; 3]>> {
        let nf = self.free.len();
        let b: Vec<[f64; 3]> = self
            .free
            .par_iter()
            .with_min_len(VERTEX_CHUNK)
            .map(|&i| {
                let mut b = [0.0; 3];
                let ri = &rotations[i];
                for k in self.ring_ptr[i]..self.ring_ptr[i + 1] {
                    let j = self.ring[k] as usize;
                    let e = self.rest_edge[k];
                    let a = mat_vec(ri, e);
                    let c = mat_vec(&rotations[j], e);
                    let w = self.weight[k];
                    let hw = 0.5 * w;
                    for d in 0..3 {
                        b[d] += hw * (a[d] + c[d]);
                    }
                    // known columns -L_FC x_C move to the right-hand side
                    if self.handle_of[j] != FREE {
                        for d in 0..3 {
                            b[d] += w * x[j][d];
                        }
                    }
                }
                b
            })
            .collect();
        let mut m = Mat::<f64>::from_fn(nf, 3, |i, d| b[i][d]);
        self.factor
            .solve_in_place(m.as_mut())
            .map_err(|source| DeformError::Solver {
                context: "global step solve",
                source,
            })?;
        Ok((0..nf).map(|i| [m[(i, 0)], m[(i, 1)], m[(i, 2)]]).collect())
    }

    /// Writes the free positions (in free order) into a full shape.
    fn set_free(&self, x: &mut [[f64; 3]], free_positions: &[[f64; 3]]) {
        for (&v, p) in self.free.iter().zip(free_positions) {
            x[v] = *p;
        }
    }

    /// `K_i = sum_j w_ij (x_i - x_j)(p_i - p_j)^T`.
    #[inline]
    fn covariance(&self, x: &[[f64; 3]], i: usize) -> Mat3 {
        let mut k = [[0.0; 3]; 3];
        for t in self.ring_ptr[i]..self.ring_ptr[i + 1] {
            let j = self.ring[t] as usize;
            let de = sub3(x[i], x[j]);
            let e = self.rest_edge[t];
            let w = self.weight[t];
            for r in 0..3 {
                for c in 0..3 {
                    k[r][c] += w * de[r] * e[c];
                }
            }
        }
        k
    }

    /// The local step: new rotations for the shape `x`, never raising
    /// `E(x, R)`, and the energy with them (see the [module docs](self)).
    ///
    /// With `beta = 0`, the per-vertex best rotations (exact). Otherwise the
    /// smoothed candidate of [`Arap::smoothed_fits`] if it lowers the energy
    /// below that of the current rotations, else one Gauss-Seidel sweep.
    fn local_step(&self, x: &[[f64; 3]], rotations: &mut [Mat3], beta: f64) -> Result<f64> {
        if beta == 0.0 {
            self.local_sweep(x, rotations, 0.0);
            return Ok(self.energy_with(x, rotations, 0.0));
        }
        let current = self.energy_with(x, rotations, beta);
        let candidate = self.smoothed_fits(x, beta)?;
        let e = self.energy_with(x, &candidate, beta);
        if e < current {
            rotations.copy_from_slice(&candidate);
            return Ok(e);
        }
        self.local_sweep(x, rotations, beta);
        Ok(self.energy_with(x, rotations, beta))
    }

    /// The factor of `D + 2 beta L` (built on first use, then cached).
    fn smoother(&self, beta: f64) -> Result<Arc<CholeskyFactor>> {
        let key = beta.to_bits();
        let mut cache = self.smoothers.lock().unwrap_or_else(|e| e.into_inner());
        if let Some((_, f)) = cache.iter().find(|(k, _)| *k == key) {
            return Ok(Arc::clone(f));
        }
        let n = self.rest.num_vertices();
        let cp = self.laplacian.symbolic().col_ptr();
        let ri = self.laplacian.symbolic().row_idx();
        let val = self.laplacian.val();
        let mut t = Vec::with_capacity(cp[n]);
        for c in 0..n {
            for k in cp[c]..cp[c + 1] {
                let r = ri[k];
                if r >= c {
                    let d = if r == c { self.stiffness[c] } else { 0.0 };
                    t.push(Triplet::new(r, c, d + 2.0 * beta * val[k]));
                }
            }
        }
        let a = SparseColMat::<usize, f64>::try_new_from_triplets(n, n, &t).map_err(|e| {
            DeformError::InvalidParameter {
                name: "rotation smoother",
                expected: "a sparse matrix faer can assemble",
                found: format!("{e:?}"),
            }
        })?;
        let f =
            Arc::new(
                CholeskyFactor::new(a.as_ref()).map_err(|source| DeformError::Solver {
                    context: "factorization of the rotation smoother",
                    source,
                })?,
            );
        cache.push((key, Arc::clone(&f)));
        Ok(f)
    }

    /// The per-vertex best rotations `F_i` (without smoothness), smoothed
    /// by one implicit diffusion step and projected back onto rotations:
    /// `proj_SO3(Y_i)` with `(D + 2 beta L) Y = D F` (nine columns, factor
    /// cached per `beta`), `D` the rest stiffness of each cell. This spreads
    /// the rotations over the length `sqrt(beta)` in one step, where
    /// Gauss-Seidel sweeps would need about `beta / h^2` steps on a mesh of
    /// edge length `h`.
    fn smoothed_fits(&self, x: &[[f64; 3]], beta: f64) -> Result<Vec<Mat3>> {
        let n = x.len();
        let smoother = self.smoother(beta)?;
        let fits: Vec<Mat3> = (0..n)
            .into_par_iter()
            .with_min_len(VERTEX_CHUNK)
            .map(|i| best_rotation(&self.covariance(x, i)))
            .collect();
        let mut y = Mat::<f64>::from_fn(n, 9, |i, c| self.stiffness[i] * fits[i][c / 3][c % 3]);
        smoother
            .solve_in_place(y.as_mut())
            .map_err(|source| DeformError::Solver {
                context: "rotation smoothing",
                source,
            })?;
        Ok((0..n)
            .into_par_iter()
            .with_min_len(VERTEX_CHUNK)
            .map(|i| {
                let m: Mat3 = std::array::from_fn(|r| std::array::from_fn(|c| y[(i, 3 * r + c)]));
                best_rotation(&m)
            })
            .collect())
    }

    /// One Gauss-Seidel sweep: every `R_i` set to the exact minimizer of
    /// the energy with everything else fixed, color class by color class
    /// (parallel within a class). With `beta = 0` this is the classic
    /// per-vertex local step and does not depend on the input rotations.
    fn local_sweep(&self, x: &[[f64; 3]], rotations: &mut [Mat3], beta: f64) {
        if beta == 0.0 {
            rotations
                .par_iter_mut()
                .with_min_len(VERTEX_CHUNK)
                .enumerate()
                .for_each(|(i, r)| *r = best_rotation(&self.covariance(x, i)));
            return;
        }
        for class in &self.colors {
            let updated: Vec<Mat3> = class
                .par_iter()
                .with_min_len(VERTEX_CHUNK)
                .map(|&i| {
                    let i = i as usize;
                    let mut k = self.covariance(x, i);
                    for t in self.ring_ptr[i]..self.ring_ptr[i + 1] {
                        let rj = &rotations[self.ring[t] as usize];
                        let c = 2.0 * beta * self.weight[t];
                        for r in 0..3 {
                            for col in 0..3 {
                                k[r][col] += c * rj[r][col];
                            }
                        }
                    }
                    best_rotation(&k)
                })
                .collect();
            for (&i, r) in class.iter().zip(updated) {
                rotations[i as usize] = r;
            }
        }
    }

    /// `E(x, R)` (summed sequentially, so it does not depend on the thread
    /// count).
    fn energy_with(&self, x: &[[f64; 3]], rotations: &[Mat3], beta: f64) -> f64 {
        let per_vertex: Vec<f64> = (0..x.len())
            .into_par_iter()
            .with_min_len(VERTEX_CHUNK)
            .map(|i| {
                let ri = &rotations[i];
                let mut energy = 0.0;
                for t in self.ring_ptr[i]..self.ring_ptr[i + 1] {
                    let j = self.ring[t] as usize;
                    let w = self.weight[t];
                    let r = sub3(sub3(x[i], x[j]), mat_vec(ri, self.rest_edge[t]));
                    energy += w * (r[0] * r[0] + r[1] * r[1] + r[2] * r[2]);
                    if beta > 0.0 {
                        let rj = &rotations[j];
                        let mut d2 = 0.0;
                        for a in 0..3 {
                            for b in 0..3 {
                                d2 += (ri[a][b] - rj[a][b]).powi(2);
                            }
                        }
                        energy += beta * w * d2;
                    }
                }
                energy
            })
            .collect();
        per_vertex.iter().sum()
    }
}

/// Greedy coloring of the vertex graph in vertex order: each vertex gets the
/// smallest color none of its earlier neighbours has. Returns the classes.
fn greedy_coloring(n: usize, ring_ptr: &[usize], ring: &[u32]) -> Vec<Vec<u32>> {
    let mut color = vec![u32::MAX; n];
    let mut classes: Vec<Vec<u32>> = Vec::new();
    let mut taken: Vec<bool> = Vec::new();
    for v in 0..n {
        taken.iter_mut().for_each(|t| *t = false);
        for &j in &ring[ring_ptr[v]..ring_ptr[v + 1]] {
            let c = color[j as usize];
            if c != u32::MAX {
                taken[c as usize] = true;
            }
        }
        let c = taken.iter().position(|t| !t).unwrap_or(taken.len());
        if c == classes.len() {
            classes.push(Vec::new());
            taken.push(false);
        }
        color[v] = c as u32;
        classes[c].push(v as u32);
    }
    classes
}

/// The cotangent Laplacian with every negative edge weight set to 0 (its
/// diagonal re-summed), or `l` itself, untouched, when no weight is
/// negative. With a negative weight (an edge opposite two angles summing
/// to more than 180 degrees, common where a refinement meets coarse faces)
/// the ARAP energy is unbounded below: the local step's "best rotation"
/// rewards stretching that edge and the iteration runs away.
fn nonnegative_weights(l: SparseColMat<usize, f64>) -> Result<SparseColMat<usize, f64>> {
    let n = l.ncols();
    let (cp, ri, val) = (l.symbolic().col_ptr(), l.symbolic().row_idx(), l.val());
    let negative = (0..n).any(|c| (cp[c]..cp[c + 1]).any(|k| ri[k] != c && val[k] > 0.0));
    if !negative {
        return Ok(l);
    }
    let mut triplets = Vec::with_capacity(val.len());
    for c in 0..n {
        let mut diagonal = 0.0;
        for k in cp[c]..cp[c + 1] {
            let r = ri[k];
            if r != c {
                let v = val[k].min(0.0);
                diagonal -= v;
                triplets.push(Triplet::new(r, c, v));
            }
        }
        triplets.push(Triplet::new(c, c, diagonal));
    }
    SparseColMat::<usize, f64>::try_new_from_triplets(n, n, &triplets).map_err(|e| {
        DeformError::InvalidParameter {
            name: "cotangent Laplacian with clamped weights",
            expected: "a sparse matrix faer can assemble",
            found: format!("{e:?}"),
        }
    })
}

/// One region per handle, each non-empty, inside the mesh and disjoint.
fn check_regions(n: usize, handles: &HandleSet, regions: &[Vec<usize>]) -> Result<()> {
    if regions.len() != handles.len() {
        return Err(DeformError::SizeMismatch {
            what: "handle regions",
            expected: handles.len(),
            found: regions.len(),
        });
    }
    let mut owner = vec![usize::MAX; n];
    for (h, region) in regions.iter().enumerate() {
        let bad = |found: String| DeformError::InvalidParameter {
            name: "handle regions",
            expected: "non-empty, disjoint sets of vertices of the mesh",
            found,
        };
        if region.is_empty() {
            return Err(bad(format!("{} is empty", handles.name(h))));
        }
        for &v in region {
            if v >= n {
                return Err(bad(format!(
                    "{} holds vertex {v} of a mesh with {n} vertices",
                    handles.name(h)
                )));
            }
            if owner[v] != usize::MAX {
                return Err(bad(format!(
                    "vertex {v} is in {} and {}",
                    handles.name(owner[v]),
                    handles.name(h)
                )));
            }
            owner[v] = h;
        }
    }
    Ok(())
}

/// Every free vertex must reach a constrained one through edges with a
/// non-zero weight, or `L_FF` is singular.
fn check_connected(
    n: usize,
    handle_of: &[u32],
    ring_ptr: &[usize],
    ring: &[u32],
    weight: &[f64],
) -> Result<()> {
    let mut reached: Vec<bool> = handle_of.iter().map(|&h| h != FREE).collect();
    let mut stack: Vec<usize> = (0..n).filter(|&v| reached[v]).collect();
    while let Some(v) = stack.pop() {
        for k in ring_ptr[v]..ring_ptr[v + 1] {
            let j = ring[k] as usize;
            if weight[k] != 0.0 && !reached[j] {
                reached[j] = true;
                stack.push(j);
            }
        }
    }
    let missing: Vec<usize> = (0..n).filter(|&v| !reached[v]).collect();
    match missing.first() {
        Some(&vertex) => Err(DeformError::UnconstrainedVertex {
            vertex,
            count: missing.len(),
        }),
        None => Ok(()),
    }
}

#[inline]
fn sub3(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn coloring_separates_neighbours_and_covers_all_vertices() {
        let mesh = mfm_geometry::procedural::blob(2).unwrap();
        let handles = HandleSet::auto(&mesh, 2, 0.1).unwrap();
        let arap = Arap::new(&mesh, &handles).unwrap();
        let mut color = vec![usize::MAX; mesh.num_vertices()];
        for (c, class) in arap.colors.iter().enumerate() {
            for &v in class {
                assert_eq!(color[v as usize], usize::MAX, "vertex in two classes");
                color[v as usize] = c;
            }
        }
        assert!(color.iter().all(|&c| c != usize::MAX));
        for i in 0..mesh.num_vertices() {
            for &j in &arap.ring[arap.ring_ptr[i]..arap.ring_ptr[i + 1]] {
                assert_ne!(color[i], color[j as usize]);
            }
        }
        assert!(arap.num_colors() <= 8, "{} colors", arap.num_colors());
    }

    #[test]
    fn local_sweep_minimizes_each_rotation() {
        // after a sweep, no single-vertex rotation perturbation lowers E
        let mesh = mfm_geometry::procedural::blob(2).unwrap();
        let handles = HandleSet::auto(&mesh, 2, 0.1).unwrap();
        let arap = Arap::new(&mesh, &handles).unwrap();
        let x: Vec<[f64; 3]> = mesh
            .positions()
            .iter()
            .map(|p| {
                [
                    p[0] + 0.1 * (3.0 * p[1]).sin(),
                    p[1] * 1.1,
                    p[2] - 0.05 * p[0] * p[0],
                ]
            })
            .collect();
        let beta = 0.01;
        let mut rot = vec![crate::rigid::IDENTITY; x.len()];
        arap.local_sweep(&x, &mut rot, 0.0);
        arap.local_sweep(&x, &mut rot, beta);
        // the last color class was updated last: its rotations are exact
        // minimizers given everything else
        let last = arap.colors.last().unwrap();
        let e0 = arap.energy_with(&x, &rot, beta);
        for &v in last.iter().take(20) {
            for axis in [[1e-3, 0.0, 0.0], [0.0, -1e-3, 0.0], [0.0, 0.0, 1e-3]] {
                let mut r = rot.clone();
                r[v as usize] =
                    crate::rigid::mat_mul(&axis_angle_to_matrix(axis), &rot[v as usize]);
                assert!(arap.energy_with(&x, &r, beta) >= e0 - 1e-13 * e0.abs());
            }
        }
    }
}
