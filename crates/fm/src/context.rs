//! One mesh's shared set-up for training and sampling: the intrinsic
//! operators are built once and both the noise sampler and the network's
//! mesh tensors are made from them; for Matérn noise the network's factor
//! of `L + eps I` reuses the symbolic analysis (ordering and supernodes) of
//! the noise's `L + tau M`, so only its numeric factorization runs.
//!
//! Cost: the operators (`O(V + F)`), the noise sampler's factorization (of
//! `L + tau M` for Matérn noise) and the numeric factorization of the
//! network's `L + eps I` (with its own symbolic analysis when the noise
//! has no factor). The results are the same bits as building the sampler
//! and the tensors each from the mesh.

use std::sync::Arc;

use mfm_geometry::TriMesh;
use mfm_geometry::operators::Operators;
use mfm_net::MeshTensors;
use mfm_noise::{NoiseKind, NoiseSampler};
use mfm_solver::{LaplacianSolver, ShiftOptions, SymbolicAnalysis};

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
    /// mesh tensors (default shift of `L + eps I`, sharing the noise
    /// factor's symbolic analysis when there is one).
    ///
    /// # Errors
    /// An invalid noise kind, a degenerate face, a factorization failure.
    pub fn new(mesh: &TriMesh, noise: NoiseKind) -> Result<Self> {
        Self::sharing(mesh, noise, None)
    }

    /// [`MeshContext::new`] with every factorization on `symbolic`, a
    /// symbolic analysis of the Laplacian's pattern shared by many shapes of
    /// one connectivity (the arbitrary-source model's sources): only
    /// numeric factorizations run, with the bits of fresh analyses. `None`
    /// is [`MeshContext::new`].
    ///
    /// # Errors
    /// As [`MeshContext::new`], plus a pattern mismatch for an analysis of
    /// another connectivity.
    pub fn sharing(
        mesh: &TriMesh,
        noise: NoiseKind,
        symbolic: Option<&Arc<SymbolicAnalysis>>,
    ) -> Result<Self> {
        let (tensors, sampler) = build(mesh, Some(noise), symbolic, Factors::Both)?;
        match sampler {
            Some(noise) => Ok(Self { noise, tensors }),
            None => unreachable!("a noise kind was given, so a sampler was built"),
        }
    }
}

/// What a sampler needs of one mesh: the network's tensors, and the noise
/// sampler of `noise` (`None`: the caller brings its own starting noise and
/// no noise factor is made). Sampling solves and draws in `f32` only, so
/// both factors keep only their `f32` copies: on a mesh of a million
/// vertices each `f64` factor would hold about 0.45 GB more, unused. The
/// samples are the same bits as with [`MeshContext::new`]'s parts.
///
/// # Errors
/// As [`MeshContext::new`].
pub(crate) fn sampling_parts(
    mesh: &TriMesh,
    noise: Option<NoiseKind>,
) -> Result<(MeshTensors, Option<NoiseSampler>)> {
    build(mesh, noise, None, Factors::F32Only)
}

/// Which precisions the factors of a [`build`] keep.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Factors {
    /// `f64`, with the `f32` copies made on first use (training, any caller).
    Both,
    /// The `f32` copies only (`f32` sampling).
    F32Only,
}

/// Builds the operators of `mesh` once, then the noise sampler (for a
/// given kind) and the mesh tensors (default shift of `L + eps I`, sharing
/// `symbolic` or the noise factor's symbolic analysis when there is one).
fn build(
    mesh: &TriMesh,
    noise: Option<NoiseKind>,
    symbolic: Option<&Arc<SymbolicAnalysis>>,
    factors: Factors,
) -> Result<(MeshTensors, Option<NoiseSampler>)> {
    if let Some(kind) = noise {
        kind.validate()?;
    }
    let ops = Operators::new(mesh)?;
    let mut sampler = noise
        .map(|kind| NoiseSampler::from_operators_sharing(&ops.laplacian, &ops.mass, kind, symbolic))
        .transpose()?;
    // L + eps I has the pattern of the noise's L + tau M: one symbolic
    // analysis serves both factorizations
    let shift = ShiftOptions::default();
    let noise_symbolic = sampler
        .as_ref()
        .and_then(|s| s.screened_poisson())
        .map(|p| p.symbolic());
    let mut solver = match symbolic.or(noise_symbolic) {
        Some(s) => LaplacianSolver::with_symbolic(s, &ops.laplacian, &shift)?,
        None => LaplacianSolver::with_options(&ops.laplacian, &shift)?,
    };
    if factors == Factors::F32Only {
        solver.release_f64_factor();
        if let Some(s) = sampler.as_mut() {
            s.release_f64_factor();
        }
    }
    let tensors = MeshTensors::from_operators(mesh.faces(), &ops, Arc::new(solver))?;
    Ok((tensors, sampler))
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use mfm_geometry::procedural;
    use tch::{Kind, Tensor};

    #[test]
    fn one_build_gives_what_separate_builds_give() {
        let mesh = procedural::icosphere(2);
        let kind = NoiseKind::Matern { tau: 100.0 };
        let ctx = MeshContext::new(&mesh, kind).unwrap();
        // the network's factor reuses the noise factor's symbolic analysis
        let noise_symbolic = ctx.noise.screened_poisson().unwrap().symbolic();
        assert!(Arc::ptr_eq(ctx.tensors.solver().symbolic(), noise_symbolic));
        // and both halves are the same bits as when built on their own
        let separate = MeshTensors::new(&mesh).unwrap();
        let v = mesh.num_vertices() as i64;
        // deterministic values: libtorch's global generator belongs to the
        // tests that seed it (adam's twin networks)
        let vals: Vec<f64> = (0..2 * v * 3).map(|i| (0.37 * i as f64).sin()).collect();
        let b = Tensor::from_slice(&vals).reshape([2, v, 3]);
        let b = &b - b.mean_dim([1i64].as_slice(), true, Kind::Double);
        let (x, y) = (ctx.tensors.solve(&b).unwrap(), separate.solve(&b).unwrap());
        assert_eq!(f64::try_from((x - y).abs().max()).unwrap(), 0.0);
        let alone = NoiseSampler::new(&mesh, kind).unwrap();
        assert_eq!(
            ctx.noise.sample(3, 1, 9).unwrap(),
            alone.sample(3, 1, 9).unwrap()
        );
        // noise kinds without a factor build their own analysis
        let white = MeshContext::new(&mesh, NoiseKind::White).unwrap();
        assert!(white.noise.screened_poisson().is_none());
        let w = white.tensors.solve(&b).unwrap();
        let y = separate.solve(&b).unwrap();
        assert_eq!(f64::try_from((w - y).abs().max()).unwrap(), 0.0);
    }
}
