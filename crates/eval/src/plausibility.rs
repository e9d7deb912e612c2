//! How far generated shapes are from a deformation space: each shape is
//! projected onto the space (handle transforms fitted by Kabsch, then the
//! ARAP solve, see [`mfm_deform::project`]) and the mass-weighted mean
//! squared distance to its projection is reported. This is the stand-in for
//! the paper's SMPL-regression MSE (0 for a shape the space can produce).

use mfm_data::{DataError, InMemorySignals, Result, SignalSource};
use mfm_deform::{Arap, DeformParams, DeformSpace, project};
use mfm_geometry::TriMesh;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// Projection errors of a set of shapes; see [`plausibility`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Plausibility {
    /// Mass-weighted mean squared distance of each shape to its projection
    /// onto the deformation space (squared units of the normalized mesh,
    /// whose bounding-box diagonal is 1).
    pub mse: Vec<f64>,
    /// Mean of `mse`.
    pub mean: f64,
    /// Median of `mse`.
    pub median: f64,
    /// The projections of the first `keep` shapes (see [`plausibility`]).
    #[serde(skip)]
    pub projections: Vec<Vec<[f64; 3]>>,
    /// The fitted parameters of every shape's projection, in order (their
    /// spread: [`crate::quality::ParamSpread`]).
    #[serde(skip)]
    pub params: Vec<DeformParams>,
}

/// Projects every signal of `shapes` (3 channels: positions on `mesh`) onto
/// `space` and reports the projection errors, keeping the projected
/// positions of the first `keep` shapes (for pictures). `mesh` may be any
/// triangulation of the surface the space was made for (the handles select
/// its regions by position).
///
/// Cost: one ARAP factorization of `mesh`, then per shape one Kabsch fit per
/// handle and one ARAP solve (parallel over shapes).
///
/// # Errors
/// [`DataError::SizeMismatch`] when the shapes are not 3-channel signals on
/// `mesh`; [`DataError::Deform`] (a handle region is empty on `mesh`, the ARAP
/// solve failed).
pub fn plausibility(
    space: &DeformSpace,
    mesh: &TriMesh,
    shapes: &InMemorySignals,
    keep: usize,
) -> Result<Plausibility> {
    if shapes.channels() != 3 || shapes.num_vertices() != mesh.num_vertices() {
        return Err(DataError::SizeMismatch {
            what: "shapes for the plausibility metric (vertices x channels)".into(),
            expected: mesh.num_vertices() * 3,
            found: shapes.num_vertices() * shapes.channels(),
        });
    }
    let arap = Arap::new(mesh, &space.handles)?;
    let results = (0..shapes.len())
        .into_par_iter()
        .map(|i| {
            let p = project(&arap, space, &shapes.positions(i))?;
            Ok((p.mse, (i < keep).then_some(p.positions), p.params))
        })
        .collect::<Result<Vec<_>>>()?;
    let mut mse = Vec::with_capacity(results.len());
    let mut kept = Vec::with_capacity(results.len());
    let mut params = Vec::with_capacity(results.len());
    for (m, k, p) in results {
        mse.push(m);
        kept.push(k);
        params.push(p);
    }
    let projections = kept.into_iter().flatten().collect();
    let mean = mse.iter().sum::<f64>() / mse.len().max(1) as f64;
    let median = crate::quality::Quartiles::of(&mse).median;
    Ok(Plausibility {
        mse,
        mean,
        median,
        projections,
        params,
    })
}
