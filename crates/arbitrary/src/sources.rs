//! Many source meshes of one connectivity: one symbolic analysis of the
//! Laplacian's pattern, numeric factorizations per source, and a cache of
//! the per-source contexts for a dataset that fits in memory.

use std::collections::HashMap;
use std::sync::{Arc, Mutex};

use mfm_geometry::TriMesh;
use mfm_geometry::operators::cotangent_laplacian;
use mfm_noise::NoiseKind;
use mfm_solver::{ScreenedPoisson, SymbolicAnalysis};

use crate::error::{ArbitraryError, Result};
use mfm_fm::context::MeshContext;

/// Per-source [`MeshContext`]s of shapes of one template (same faces).
///
/// The symbolic analysis (fill-reducing ordering, supernodes) of the
/// template's Laplacian pattern is computed once and every source's
/// factorizations (the noise's `L + tau M`, the network's `L + eps I`) reuse
/// it. [`SourceSet::cached`] keeps the contexts of sources met by index (a
/// dataset's meshes, when training without augmentation), up to a number of
/// vertices in total; [`SourceSet::build`] makes one for any positions.
#[derive(Debug)]
pub struct SourceSet {
    template: TriMesh,
    noise: NoiseKind,
    symbolic: Arc<SymbolicAnalysis>,
    cache: Mutex<HashMap<usize, Arc<MeshContext>>>,
    cache_vertices: usize,
}

/// Vertices (summed over cached sources) [`SourceSet`] keeps by default:
/// with the network's tensors and two factors per source, about 2 GB for
/// meshes of a few thousand vertices.
pub const DEFAULT_CACHE_VERTICES: usize = 2_000_000;

impl SourceSet {
    /// Analyses the pattern of `template`'s Laplacian; `noise` is the kind
    /// each context's sampler draws.
    ///
    /// # Errors
    /// An invalid noise kind; the analysis failing.
    pub fn new(template: &TriMesh, noise: NoiseKind) -> Result<Self> {
        noise.validate()?;
        let symbolic = ScreenedPoisson::analyse(&cotangent_laplacian(template))?;
        Ok(Self {
            template: template.clone(),
            noise,
            symbolic,
            cache: Mutex::new(HashMap::new()),
            cache_vertices: DEFAULT_CACHE_VERTICES,
        })
    }

    /// The shared analysis.
    pub fn symbolic(&self) -> &Arc<SymbolicAnalysis> {
        &self.symbolic
    }

    /// The template (its faces are every source's).
    pub fn template(&self) -> &TriMesh {
        &self.template
    }

    /// The context of the template's faces at `positions` (numeric
    /// factorizations only).
    ///
    /// # Errors
    /// [`ArbitraryError::Source`] for a wrong vertex count or non-finite positions;
    /// a degenerate face; a factorization failure.
    pub fn build(&self, positions: Vec<[f64; 3]>) -> Result<MeshContext> {
        let mesh = self.template.with_positions(positions).map_err(|e| {
            ArbitraryError::Source(format!(
                "a source of the template ({} vertices): {e}",
                self.template.num_vertices()
            ))
        })?;
        Ok(MeshContext::sharing(
            &mesh,
            self.noise,
            Some(&self.symbolic),
        )?)
    }

    /// The context of source `index` at `positions`, from the cache when it
    /// was built before (the caller promises that an index always comes
    /// with the same positions).
    ///
    /// # Errors
    /// As [`SourceSet::build`].
    pub fn cached(&self, index: usize, positions: Vec<[f64; 3]>) -> Result<Arc<MeshContext>> {
        if let Some(c) = self.lock().get(&index) {
            return Ok(Arc::clone(c));
        }
        let context = Arc::new(self.build(positions)?);
        let mut cache = self.lock();
        if (cache.len() + 1) * self.template.num_vertices() <= self.cache_vertices {
            cache.insert(index, Arc::clone(&context));
        }
        Ok(context)
    }

    /// Number of cached contexts.
    pub fn cached_len(&self) -> usize {
        self.lock().len()
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, HashMap<usize, Arc<MeshContext>>> {
        self.cache.lock().unwrap_or_else(|p| p.into_inner())
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use mfm_geometry::procedural;
    use tch::{Kind, Tensor};

    #[test]
    fn sources_share_the_analysis_and_solve_like_fresh_contexts() {
        let mesh = procedural::blob(2).unwrap();
        let kind = NoiseKind::Matern { tau: 100.0 };
        let set = SourceSet::new(&mesh, kind).unwrap();
        // a second shape of the same connectivity
        let posed: Vec<[f64; 3]> = mesh
            .positions()
            .iter()
            .map(|p| [1.3 * p[0], p[1] + 0.2 * p[0] * p[0], 0.8 * p[2]])
            .collect();
        let shared = set.cached(1, posed.clone()).unwrap();
        assert!(Arc::ptr_eq(
            shared.tensors.solver().symbolic(),
            set.symbolic()
        ));
        assert!(Arc::ptr_eq(
            shared.noise.screened_poisson().unwrap().symbolic(),
            set.symbolic()
        ));
        let fresh = MeshContext::new(&mesh.with_positions(posed.clone()).unwrap(), kind).unwrap();
        let v = mesh.num_vertices() as i64;
        // deterministic values: libtorch's global generator belongs to the
        // tests that seed it (adam's twin networks)
        let vals: Vec<f64> = (0..v * 3).map(|i| (0.37 * i as f64).sin()).collect();
        let b = Tensor::from_slice(&vals).reshape([1, v, 3]);
        let b = &b - b.mean_dim([1i64].as_slice(), true, Kind::Double);
        let d = shared.tensors.solve(&b).unwrap() - fresh.tensors.solve(&b).unwrap();
        assert_eq!(f64::try_from(d.abs().max()).unwrap(), 0.0);
        assert_eq!(
            shared.noise.sample(2, 3, 5).unwrap(),
            fresh.noise.sample(2, 3, 5).unwrap()
        );
        // the cache hands back the same context
        let again = set.cached(1, posed).unwrap();
        assert!(Arc::ptr_eq(&again, &shared));
        assert_eq!(set.cached_len(), 1);
        // a wrong vertex count is refused with the template's size
        let e = set.build(vec![[0.0; 3]; 3]).unwrap_err();
        assert!(e.to_string().contains("vertices"), "{e}");
    }
}
