//! How well an arbitrary-source model does on held-out body shapes: its
//! targets projected onto each source's own deformation space, their
//! distance from the source against the data's, the pose spread, MMD/COV
//! against the held-out meshes, and the predictor's error.
//!
//! A set is a pairs dataset of held-out shapes (`holdout`: the template's
//! triangulation; `reference`: another triangulation of the same surface).
//! The source of shape `s` is its first pose; the model generates targets
//! over it. Measures (positions in the dataset's units, the normalized
//! frame of `mfm dataset pairs`):
//!
//! - **projection**: mass-weighted MSE of each target to its projection
//!   onto the poses of the source's body shape ([`mfm_deform::project`]
//!   with [`mfm_deform::ShapeFamily::pose_space`]); the floor is the same
//!   number for the set's own meshes. A target of the wrong body shape, a
//!   broken or noisy one, scores far above the floor.
//! - **displacement ratio**: median RMS distance of the targets from their
//!   source over the median RMS distance between two poses of one shape in
//!   the set. A model that copies its source scores 0, one that moves too
//!   much scores above 1.
//! - **pose spread** ([`ParamSpread`]) of the projections' handle motions,
//!   beside the set's own: a collapsed model has none.
//! - **MMD / COV** of the targets against the other poses of the
//!   evaluated shapes (every held-out mesh but the sources; mass weights of
//!   the set's mesh): a model that copies its sources covers nothing.
//! - **predictor error**: per source, the mean over vectors `1..k` of the
//!   mass-weighted relative error of the predicted eigenvectors against the
//!   basis of the set's rest mesh ([`relative_errors`]), and over vectors
//!   `1..=8` alone. Not measured for a predictor imported from the
//!   authors' checkpoint ([`predictor_error_skipped`]): it was trained on
//!   their basis, whose sign and normalization conventions are not mfm's.

use std::path::Path;
use std::time::Instant;

use mfm_data::dataset::Dataset;
use mfm_data::eigenbasis::{Eigenbasis, relative_errors};
use mfm_data::pairs::{self, PairsManifest};
use mfm_data::{InMemorySignals, SignalSource};
use mfm_deform::{Arap, DeformParams, project};
use mfm_eval::metrics::{MassWeighted, coverage, mmd};
use mfm_eval::quality::{ParamSpread, Quartiles};
use mfm_geometry::TriMesh;

use crate::error::{ArbitraryError, Result};
use crate::flow::ArbitrarySampler;

/// The measures of one held-out set (the report's type is mfm-eval's, so
/// that readers of `report.json` need no libtorch); see the
/// [module docs](self).
pub use mfm_eval::arbitrary::SetEvaluation;

/// One source with its generated targets and a true other pose, for
/// pictures.
#[derive(Clone, Debug)]
pub struct Example {
    /// The source mesh.
    pub source: TriMesh,
    /// Generated targets (positions on the source's vertices).
    pub generated: Vec<Vec<[f64; 3]>>,
    /// Another pose of the same shape from the data.
    pub truth: Vec<[f64; 3]>,
}

/// Why the predictor's error against the set's own eigenbasis is not
/// measured for `sampler`, or `None` when it is: a predictor imported from
/// the authors' checkpoint records no eigenvalues
/// ([`crate::predictor::PredictorSpec::has_own_basis`]) and was trained on
/// their basis, so its output need not match mfm's (signs, normalization).
pub fn predictor_error_skipped(sampler: &ArbitrarySampler) -> Option<String> {
    if sampler.predictor().spec().has_own_basis() {
        return None;
    }
    Some(
        "the predictor was imported from the authors' checkpoint: it records no eigenvalues \
         and was trained on their eigenbasis (their signs and normalization), so its error \
         against mfm's basis of each set is not measured"
            .to_owned(),
    )
}

fn flat(p: &[[f64; 3]]) -> Vec<f32> {
    p.iter().flat_map(|x| x.map(|y| y as f32)).collect()
}

/// Evaluates `sampler` on the held-out pairs dataset `set` (see the
/// [module docs](self)): `per_source` targets over each of the first
/// `sources` shapes' first poses, noise `seed`. Returns the measures and
/// the examples.
///
/// # Errors
/// [`ArbitraryError::Dataset`] for a set that is not a pairs dataset; data, shape,
/// sampling errors.
pub fn evaluate_set(
    sampler: &ArbitrarySampler,
    set: &Path,
    sources: usize,
    per_source: usize,
    seed: u64,
) -> Result<(SetEvaluation, Vec<Example>)> {
    let data = Dataset::open(set)?;
    let Some(manifest) = PairsManifest::of(&data)? else {
        return Err(ArbitraryError::Dataset(format!(
            "{} is not a pairs dataset made by `mfm dataset pairs`: this evaluation measures \
             targets against the pose space that made them (imported pairs have none; judge \
             their samples with `mfm eval --reference`)",
            set.display()
        )));
    };
    let params = pairs::read_params(&data)?;
    let space = &manifest.space;
    let p = space.poses_per_shape;
    let rest = data.mesh().clone();
    let meshes = data.load_all()?;
    let shapes = (meshes.len() / p).min(sources.max(1));
    // the generated targets of every source are kept (f32), each source's
    // as f64 while it is measured
    mfm_files::space::ensure_memory(
        &format!(
            "{shapes} sources x {per_source} targets x {} vertices x 3 coordinates",
            rest.num_vertices()
        ),
        (shapes as u128)
            .saturating_mul(per_source as u128)
            .saturating_mul(rest.num_vertices() as u128 * 3),
        12,
    )?;
    let mass = mfm_geometry::operators::lumped_mass(&rest);
    let metric = MassWeighted::new(&mass, 3)?;
    let k = sampler.predictor().eigenvectors();
    let measure_predictor = predictor_error_skipped(sampler).is_none();
    let basis = if measure_predictor {
        Some(Eigenbasis::of(&rest, k)?)
    } else {
        None
    };
    let (mut projection, mut floor, mut moved, mut data_moved) = (vec![], vec![], vec![], vec![]);
    let (mut gen_params, mut ref_params) = (vec![], vec![]);
    let (mut predictor_error, mut predictor_error_low) = (vec![], vec![]);
    let mut generated_all: Vec<f32> = Vec::new();
    let mut others: Vec<f32> = Vec::new();
    let mut examples = Vec::new();
    let mut seconds = 0.0;
    for s in 0..shapes {
        let shape = &params.shapes[s];
        let member = space.family.realize(&rest, shape)?;
        let (posing, regions) = space.family.pose_space(&rest, &space.poses, shape)?;
        let arap = Arap::with_regions(&member, &posing.handles, regions)?;
        let poses: Vec<Vec<[f64; 3]>> = (0..p).map(|a| meshes.positions(s * p + a)).collect();
        for q in &poses {
            let pr = project(&arap, &posing, q)?;
            floor.push(pr.mse);
            ref_params.push(pr.params);
        }
        let source_values = flat(&poses[0]);
        for q in &poses[1..] {
            let q = flat(q);
            data_moved.push(metric.distance(&q, &source_values)?);
            others.extend(q);
        }
        let source = rest
            .with_positions(poses[0].clone())
            .map_err(|e| ArbitraryError::Source(e.to_string()))?;
        let t0 = Instant::now();
        let out = sampler.sample(&source, s * per_source, per_source, seed)?;
        seconds += t0.elapsed().as_secs_f64();
        for g in &out {
            let pr = project(&arap, &posing, g)?;
            projection.push(pr.mse);
            gen_params.push(pr.params);
            let g = flat(g);
            moved.push(metric.distance(&g, &source_values)?);
            generated_all.extend(g);
        }
        if let Some(basis) = &basis {
            let predicted = sampler.eigenvectors_on(&source)?;
            let errors = relative_errors(&rest, basis, &predicted)?;
            let mean = |e: &[f64]| e.iter().sum::<f64>() / e.len().max(1) as f64;
            predictor_error.push(mean(&errors[1..]));
            predictor_error_low.push(mean(&errors[1..k.min(9)]));
        }
        examples.push(Example {
            source,
            generated: out,
            truth: poses[1].clone(),
        });
    }
    let n_gen = shapes * per_source;
    let generated = InMemorySignals::new(generated_all, n_gen, rest.num_vertices(), 3)?;
    let reference = InMemorySignals::new(others, shapes * (p - 1), rest.num_vertices(), 3)?;
    let d = metric.pairwise(&generated, &reference)?;
    let median = |v: &[f64]| Quartiles::of(v).median;
    let spread = |v: &[DeformParams]| ParamSpread::of(v);
    Ok((
        SetEvaluation {
            set: set
                .file_name()
                .map_or_else(String::new, |n| n.to_string_lossy().into_owned()),
            vertices: rest.num_vertices(),
            sources: shapes,
            samples_per_source: per_source,
            projection: Quartiles::of(&projection),
            projection_floor: Quartiles::of(&floor),
            displacement_ratio: median(&moved) / median(&data_moved).max(f64::MIN_POSITIVE),
            pose_spread: spread(&gen_params),
            reference_pose_spread: spread(&ref_params),
            mmd: mmd(&d)?,
            cov: coverage(&d)?,
            predictor_error: measure_predictor.then(|| Quartiles::of(&predictor_error)),
            predictor_error_low: measure_predictor.then(|| Quartiles::of(&predictor_error_low)),
            seconds_per_sample: seconds / n_gen.max(1) as f64,
        },
        examples,
    ))
}
