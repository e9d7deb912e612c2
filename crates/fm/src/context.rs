//! One mesh's shared set-up for training and sampling: the intrinsic
//! operators are built once and both the noise sampler and the network's
//! mesh tensors are made from them.
//!
//! Cost: the operators (`O(V + F)`), the noise sampler's factorization (of
//! `L + tau M` for Matérn noise) and the network's factor of `L + eps I`.
//! The results are the same bits as building the sampler and the tensors
//! each from the mesh.

use std::sync::Arc;

use mfm_geometry::TriMesh;
use mfm_geometry::operators::Operators;
use mfm_net::MeshTensors;
use mfm_noise::{NoiseKind, NoiseSampler};
use mfm_solver::{LaplacianSolver, ShiftOptions};

use crate::error::Result;

/// The noise sampler and the network's tensors of one mesh, from one build
/// of its operators.
#[derive(Debug)]
pub struct MeshContext {
    /// The noise of the flow's source distribution on this mesh.
    pub noise: NoiseSampler,
    /// The network's view of the mesh (`G`, `G^T A2`, face means, the
    /// factor of `L + eps I`).
    pub tensors: MeshTensors,
}

impl MeshContext {
    /// Builds the operators of `mesh` once, then the `noise` sampler and the
    /// mesh tensors (default shift of `L + eps I`).
    ///
    /// # Errors
    /// An invalid noise kind, a degenerate face, a factorization failure.
    pub fn new(mesh: &TriMesh, noise: NoiseKind) -> Result<Self> {
        noise.validate()?;
        let ops = Operators::new(mesh)?;
        let sampler = NoiseSampler::from_operators(&ops.laplacian, &ops.mass, noise)?;
        let solver = LaplacianSolver::with_options(&ops.laplacian, &ShiftOptions::default())?;
        let tensors = MeshTensors::from_operators(mesh.faces(), &ops, Arc::new(solver))?;
        Ok(Self {
            noise: sampler,
            tensors,
        })
    }
}
