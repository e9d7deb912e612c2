//! What `mfm eval` measures, as report types: the distribution metrics of
//! generated samples against a reference set, the sample-quality fit of
//! the data's own family (GMM bumps, or the deformation space's
//! projection), and the same projection error alone when only a
//! deformation space is at hand.
//!
//! [`evaluate`] runs the whole protocol on a reference dataset and returns
//! an [`Evaluation`]: the serializable [`EvalReport`] (the `--out` JSON,
//! field names stable) with what pictures of it need. The report's
//! [`EvalReport::summary`] is the text `mfm eval` prints.
//!
//! Cost: the metrics are `O(N_gen N_ref V)`; the GMM fit factors the mesh's
//! heat-method operators once; the projection solves one ARAP fit per shape.

use serde::{Deserialize, Serialize};

use mfm_deform::DeformSpace;
use mfm_geometry::TriMesh;
use mfm_geometry::operators::Operators;

use mfm_data::dataset::Dataset;
use mfm_data::deformations::DeformManifest;
use mfm_data::gmm::{self, GmmConfig, GmmGenerator};
use mfm_data::import::{self, ImportManifest};
use mfm_data::transfer::Transfer;
use mfm_data::{DataError, InMemorySignals, Result, SignalSource};

use crate::metrics::Metrics;
use crate::pictures;
use crate::plausibility::{self, Plausibility};
use crate::quality::{GmmQualityReport, ParamSpread, Quartiles};
use crate::shape_quality::{self, ShapeQuality, ShapeSets};
use std::path::Path;

/// Generated shapes whose projections [`evaluate`] keeps for pictures.
pub const PROJECTIONS_KEPT: usize = 4;

/// The report of [`evaluate`] (`mfm eval --out`): the metrics' fields at the
/// top level, then the quality fit of the data's family.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EvalReport {
    /// MMD, COV, 1-NNA, test error and the set sizes.
    #[serde(flatten)]
    pub metrics: Metrics,
    /// The bump fit (scalar GMM reference sets only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub quality: Option<GmmQualityReport>,
    /// The projection onto the deformation space (deformation reference
    /// sets only), its fields at the top level.
    #[serde(flatten, default, skip_serializing_if = "Option::is_none")]
    pub shapes: Option<ShapeReport>,
    /// The generator-free measures of shapes (imported shape sets, which
    /// have no generator): plausibility, coverage, roughness, novelty and
    /// flipped faces against the training and held-out shapes.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub shape_quality: Option<ShapeQuality>,
}

/// How far generated shapes are from the deformation space, and how much
/// their projections' parameters vary, next to the reference set's.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ShapeReport {
    /// Mean projection MSE of the generated shapes (plausibility).
    pub projection_mse: f64,
    /// Its median.
    pub projection_mse_median: f64,
    /// Its quartiles.
    pub projection_mse_quartiles: Quartiles,
    /// Mean projection MSE of the reference shapes (the data's floor).
    pub reference_projection_mse: f64,
    /// Spread of the generated projections' handle parameters.
    pub param_spread: ParamSpread,
    /// The same for the reference set.
    pub reference_param_spread: ParamSpread,
    /// `param_spread / reference_param_spread`, per kind (1 = the data's
    /// variety, 0 = collapsed).
    pub spread_ratio: SpreadRatio,
}

/// Generated over reference parameter spread.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct SpreadRatio {
    /// Of the handle rotations.
    pub rotation: f64,
    /// Of the handle translations.
    pub translation: f64,
}

impl EvalReport {
    /// The lines `mfm eval` prints: the quality fit, the projection, then the
    /// metrics.
    pub fn summary(&self) -> String {
        let mut lines = Vec::new();
        if let Some(q) = &self.quality {
            lines.push(q.summary());
        }
        if let Some(q) = &self.shape_quality {
            lines.push(q.summary());
        }
        if let Some(s) = &self.shapes {
            let q = s.projection_mse_quartiles;
            lines.push(format!(
                "projection MSE (plausibility): generated median {:.3e} [{:.3e}, {:.3e}], mean {:.3e}; reference mean {:.3e}",
                q.median, q.q1, q.q3, s.projection_mse, s.reference_projection_mse
            ));
            let (g, r) = (s.param_spread, s.reference_param_spread);
            lines.push(format!(
                "handle-parameter spread of the projections: rotation {:.3} rad (data {:.3}), translation {:.4} (data {:.4})",
                g.rotation, r.rotation, g.translation, r.translation
            ));
        }
        let m = &self.metrics;
        lines.push(format!(
            "MMD {:.5}  COV {:.3}  1-NNA {:.3}  test error {:.5}  ({} generated, {} reference)",
            m.mmd, m.cov, m.one_nna, m.test_error, m.num_generated, m.num_reference
        ));
        lines.join("\n")
    }
}

/// An [`EvalReport`] with what pictures of it need.
#[derive(Debug)]
pub struct Evaluation {
    /// The report.
    pub report: EvalReport,
    /// The reference set's mesh (the mesh the samples live on).
    pub mesh: TriMesh,
    /// The reference signals.
    pub reference: InMemorySignals,
    /// The generated shapes' projections (the first [`PROJECTIONS_KEPT`]
    /// kept), for deformation reference sets.
    pub projections: Option<Plausibility>,
    /// For imported shape sets: the training shapes carried to the
    /// reference mesh, with the template's diagonal and the split's seed
    /// (what [`ShapeSets`] needs besides the reference and the samples).
    pub imported: Option<ImportedShapes>,
}

/// The real shapes of an imported experiment on its reference mesh,
/// besides the held-out ones.
#[derive(Debug)]
pub struct ImportedShapes {
    /// The training shapes carried to the reference mesh.
    pub train: InMemorySignals,
    /// The template's bounding-box diagonal (the unit of distances).
    pub diagonal: f64,
    /// The split's seed.
    pub seed: u64,
}

impl ImportedShapes {
    /// The [`ShapeSets`] of these real shapes, the held-out ones on `mesh`
    /// and `samples`.
    pub fn sets<'a>(
        &'a self,
        mesh: &'a TriMesh,
        held_out: &'a InMemorySignals,
        samples: &'a InMemorySignals,
    ) -> ShapeSets<'a> {
        ShapeSets {
            mesh,
            train: &self.train,
            held_out,
            samples,
            diagonal: self.diagonal,
            seed: self.seed,
        }
    }
}

impl Evaluation {
    /// The [`ShapeSets`] of an imported shape set and `samples` (`None`
    /// for other sets).
    pub fn shape_sets<'a>(&'a self, samples: &'a InMemorySignals) -> Option<ShapeSets<'a>> {
        self.imported
            .as_ref()
            .map(|i| i.sets(&self.mesh, &self.reference, samples))
    }
}

/// Evaluates `generated` (on the reference set's mesh, with its channels)
/// against `reference`: [`Metrics`] always; the bump fit for a scalar GMM
/// set; the projection onto the deformation space for a deformation set.
///
/// # Errors
/// [`DataError::SizeMismatch`] when the samples' vertices or channels are
/// not the reference's; [`DataError::Files`] (`Format`) for unreadable generator
/// parameters; the metrics', fits' and projection's errors.
pub fn evaluate(reference: &Dataset, generated: &InMemorySignals) -> Result<Evaluation> {
    for (what, found, expected) in [
        (
            "vertices of the samples",
            generated.num_vertices(),
            reference.num_vertices(),
        ),
        (
            "channels of the samples",
            generated.channels(),
            reference.channels(),
        ),
    ] {
        if found != expected {
            return Err(DataError::SizeMismatch {
                what: what.into(),
                expected,
                found,
            });
        }
    }
    let mesh = reference.mesh().clone();
    let deform = DeformManifest::of(reference)?;
    let gmm = (reference.manifest().generator == gmm::GENERATOR_NAME)
        .then(|| GmmConfig::from_manifest_params(&reference.manifest().generator_params))
        .transpose()?;
    let mass = Operators::new(&mesh)?.mass;
    let reference_signals = reference.load_all()?;
    let metrics = Metrics::evaluate(&mass, generated, &reference_signals)?;
    let quality = match (&gmm, generated.channels()) {
        (Some(config), 1) => {
            let generator = GmmGenerator::new(&mesh, config)?;
            Some(GmmQualityReport::of(
                &generator,
                &mesh,
                &mass,
                generated,
                &reference_signals,
            )?)
        }
        _ => None,
    };
    let (shape_quality, imported) = match ImportManifest::of(reference)? {
        Some(m) if m.positions && generated.channels() == 3 => {
            let imported = imported_shapes(reference, &m)?;
            let sets = imported.sets(&mesh, &reference_signals, generated);
            (Some(shape_quality::shape_quality(&sets)?), Some(imported))
        }
        _ => (None, None),
    };
    let (shapes, projections) = match &deform {
        Some(d) => {
            let p = plausibility::plausibility(&d.space, &mesh, generated, PROJECTIONS_KEPT)?;
            let r = plausibility::plausibility(&d.space, &mesh, &reference_signals, 0)?;
            let (g, rs) = (ParamSpread::of(&p.params), ParamSpread::of(&r.params));
            let report = ShapeReport {
                projection_mse: p.mean,
                projection_mse_median: p.median,
                projection_mse_quartiles: Quartiles::of(&p.mse),
                reference_projection_mse: r.mean,
                param_spread: g,
                reference_param_spread: rs,
                spread_ratio: SpreadRatio {
                    rotation: g.rotation / rs.rotation,
                    translation: g.translation / rs.translation,
                },
            };
            (Some(report), Some(p))
        }
        None => (None, None),
    };
    Ok(Evaluation {
        report: EvalReport {
            metrics,
            quality,
            shapes,
            shape_quality,
        },
        mesh,
        reference: reference_signals,
        projections,
        imported,
    })
}

/// The experiment folder an imported dataset belongs to (its parent).
fn experiment_of(dataset: &Dataset) -> Result<&Path> {
    dataset.dir().parent().ok_or_else(|| {
        DataError::format(
            dataset.dir(),
            "an imported reference set must sit in its experiment folder (beside train/ and transfer.npy)",
        )
    })
}

/// The real shapes of the imported experiment `reference` belongs to (`m`
/// its import record): the
/// training set carried to the reference mesh by the experiment's
/// transfer (as it is for the held-out set on the template) and the
/// template's diagonal.
fn imported_shapes(reference: &Dataset, m: &ImportManifest) -> Result<ImportedShapes> {
    let dir = experiment_of(reference)?;
    let train = Dataset::open(dir.join(mfm_data::layout::TRAIN))?;
    let holdout = Dataset::open(dir.join(mfm_data::layout::HOLDOUT))?;
    // the held-out set on the template needs no transfer
    let transfer = if m.mesh_role == "template" {
        None
    } else {
        let transfer = Transfer::read(&dir.join(import::TRANSFER), train.num_vertices())?;
        if transfer.target_vertices() != reference.num_vertices() {
            return Err(DataError::format(
                dir.join(import::TRANSFER),
                format!(
                    "carries the template to {} vertices, but the reference mesh has {}",
                    transfer.target_vertices(),
                    reference.num_vertices()
                ),
            ));
        }
        Some(transfer)
    };
    if holdout.len() != reference.len() {
        return Err(DataError::format(
            holdout.dir(),
            format!(
                "holds {} shapes, the reference set {}: not the same held-out shapes",
                holdout.len(),
                reference.len()
            ),
        ));
    }
    mfm_files::space::ensure_memory(
        "the training shapes on the reference mesh",
        (train.len() as u128)
            * (reference.num_vertices() as u128 + train.num_vertices() as u128)
            * 3,
        4,
    )?;
    let on_template_shapes = train.load_all()?;
    let diagonal = train.mesh().bounding_box_diagonal();
    let train = match &transfer {
        Some(t) => t.apply_set(&on_template_shapes)?,
        None => on_template_shapes,
    };
    Ok(ImportedShapes {
        train,
        diagonal,
        seed: m.seed,
    })
}

/// The projection error of shapes on `mesh` when there is no reference set,
/// only a deformation space (`mfm eval --space`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PlausibilityReport {
    /// Mean projection MSE.
    pub projection_mse: f64,
    /// Its median.
    pub projection_mse_median: f64,
    /// Number of shapes.
    pub num_generated: usize,
    /// Vertices of the mesh.
    pub vertices: usize,
}

/// Projects 3-channel `shapes` on `mesh` onto `space` (the first
/// [`PROJECTIONS_KEPT`] projections kept) and reports the error.
///
/// # Errors
/// [`DataError::SizeMismatch`] unless the shapes are positions of `mesh`'s
/// vertices; the projection's errors.
pub fn plausibility_only(
    space: &DeformSpace,
    mesh: &TriMesh,
    shapes: &InMemorySignals,
) -> Result<(PlausibilityReport, Plausibility)> {
    if shapes.channels() != 3 {
        return Err(DataError::SizeMismatch {
            what: "channels of the shapes (positions)".into(),
            expected: 3,
            found: shapes.channels(),
        });
    }
    if shapes.num_vertices() != mesh.num_vertices() {
        return Err(DataError::SizeMismatch {
            what: "vertices of the shapes".into(),
            expected: mesh.num_vertices(),
            found: shapes.num_vertices(),
        });
    }
    let p = plausibility::plausibility(space, mesh, shapes, PROJECTIONS_KEPT)?;
    let report = PlausibilityReport {
        projection_mse: p.mean,
        projection_mse_median: p.median,
        num_generated: shapes.len(),
        vertices: mesh.num_vertices(),
    };
    Ok((report, p))
}

/// The files of `mfm eval` against a reference set: what it reads and
/// what it writes.
#[derive(Clone, Copy, Debug)]
pub struct EvalFiles<'a> {
    /// Generated samples, `.npy` `[N, V, C]` ([`InMemorySignals::read_npy`]).
    pub samples: &'a Path,
    /// The reference dataset folder (its mesh is the samples' mesh), or
    /// an experiment folder whose `reference/` set is meant.
    pub reference: &'a Path,
    /// Where to write the [`EvalReport`] as JSON.
    pub json: Option<&'a Path>,
    /// Where to draw the pictures: for a deformation set the generated
    /// shapes beside their projections ([`pictures::projections`]); else the
    /// point-wise means ([`pictures::means`]) with `STEM_difference.png`
    /// beside it, and for a GMM set also `STEM_samples.png`
    /// ([`pictures::data_and_samples`]); for an imported shape set, the
    /// first samples beside their nearest real shapes
    /// ([`pictures::nearest_real`]) and `STEM_plane.png`, every shape in
    /// the training shapes' principal plane ([`pictures::principal_plane`]).
    pub png: Option<&'a Path>,
}

impl EvalFiles<'_> {
    /// Checks the outputs ([`mfm_files::Outputs`]), reads the samples
    /// (which must be finite) and the reference set, [`evaluate`]s, and
    /// writes the report and pictures; nothing is left behind on failure.
    ///
    /// # Errors
    /// [`DataError::Files`] (`Format`) for no samples or non-finite ones,
    /// [`DataError::SizeMismatch`] for samples not on the reference's mesh, and those of the readers,
    /// [`evaluate`] and the writers.
    pub fn run(&self) -> Result<Evaluation> {
        let undo = guard(&[self.samples, self.reference], self.json, self.png)?;
        let generated = read_finite(self.samples)?;
        let reference_dir = reference_set_of(self.reference);
        let reference = Dataset::open(&reference_dir)?;
        let dir = reference_dir.display();
        if generated.num_vertices() != reference.num_vertices() {
            return Err(DataError::format(
                self.samples,
                format!(
                    "samples have {} vertices but the reference mesh ({dir}) has {}; \
                     sample on the reference's mesh",
                    generated.num_vertices(),
                    reference.num_vertices()
                ),
            ));
        }
        if generated.channels() != reference.channels() {
            return Err(DataError::format(
                self.samples,
                format!(
                    "samples have {} channels but the reference set {dir} has {}",
                    generated.channels(),
                    reference.channels()
                ),
            ));
        }
        let e = evaluate(&reference, &generated)?;
        if let Some(json) = self.json {
            mfm_files::write_json(json, &e.report)?;
        }
        if let Some(png) = self.png {
            if let Some(q) = &e.report.quality {
                let samples = pictures::sibling_png(png, "samples");
                pictures::data_and_samples(&e.mesh, &e.reference, &generated, q, &samples)?;
            }
            match (
                &e.projections,
                &e.report.shape_quality,
                e.shape_sets(&generated),
            ) {
                (Some(p), _, _) => pictures::projections(&e.mesh, &generated, p, png)?,
                (None, Some(q), Some(sets)) => {
                    pictures::nearest_real(&sets, q, png)?;
                    pictures::principal_plane(q, &pictures::sibling_png(png, "plane"))?;
                }
                _ => pictures::means(
                    &e.mesh,
                    &generated,
                    &e.reference,
                    e.report.metrics.test_error,
                    png,
                    &pictures::sibling_png(png, "difference"),
                )?,
            }
        }
        undo.keep();
        Ok(e)
    }
}

/// The reference set a `--reference` path names: the path itself, or for
/// an experiment folder (one with `reference/` and no manifest of its
/// own), its `reference/` set.
fn reference_set_of(path: &Path) -> std::path::PathBuf {
    let set = path.join(mfm_data::layout::REFERENCE);
    if !path.join(mfm_data::dataset::MANIFEST_FILE).exists()
        && set.join(mfm_data::dataset::MANIFEST_FILE).is_file()
    {
        set
    } else {
        path.to_path_buf()
    }
}

/// The files of `mfm eval --space`: shapes judged against a deformation
/// space alone.
#[derive(Clone, Copy, Debug)]
pub struct PlausibilityFiles<'a> {
    /// Generated shapes, `.npy` `[N, V, 3]`.
    pub samples: &'a Path,
    /// `space.json` of a deformation experiment.
    pub space: &'a Path,
    /// The mesh the shapes move.
    pub mesh: &'a TriMesh,
    /// The mesh's file, `None` for a built-in mesh.
    pub mesh_file: Option<&'a Path>,
    /// Where to write the [`PlausibilityReport`] as JSON.
    pub json: Option<&'a Path>,
    /// Where to draw the first shapes beside their projections.
    pub png: Option<&'a Path>,
}

impl PlausibilityFiles<'_> {
    /// Checks the outputs, reads the shapes and the space, runs
    /// [`plausibility_only`] and writes the report and picture.
    ///
    /// # Errors
    /// As [`EvalFiles::run`], with [`plausibility_only`]'s.
    pub fn run(&self) -> Result<PlausibilityReport> {
        let mut inputs = vec![self.samples, self.space];
        inputs.extend(self.mesh_file);
        let undo = guard(&inputs, self.json, self.png)?;
        let generated = read_finite(self.samples)?;
        let v = self.mesh.num_vertices();
        if generated.num_vertices() != v || generated.channels() != 3 {
            return Err(DataError::format(
                self.samples,
                format!(
                    "samples are [{}, {}, {}] but the mesh has {v} vertices (positions need 3 channels)",
                    generated.len(),
                    generated.num_vertices(),
                    generated.channels()
                ),
            ));
        }
        let space = mfm_data::layout::read_space(self.space)?;
        let (report, p) = plausibility_only(&space, self.mesh, &generated)?;
        if let Some(json) = self.json {
            mfm_files::write_json(json, &report)?;
        }
        if let Some(png) = self.png {
            pictures::projections(self.mesh, &generated, &p, png)?;
        }
        undo.keep();
        Ok(report)
    }
}

/// The output guard of an evaluation: the JSON, the picture and the
/// pictures beside it, which are its implicit companions
/// ([`mfm_files::Outputs::implicit`]): one of their names may be replaced
/// only when the picture itself exists too (an earlier evaluation's), never
/// a file of that name that is someone else's.
fn guard(inputs: &[&Path], json: Option<&Path>, png: Option<&Path>) -> Result<mfm_files::Undo> {
    let mut outputs = mfm_files::Outputs::new()
        .inputs(inputs)
        .outputs(json)
        .outputs(png);
    if let Some(png) = png {
        for suffix in ["samples", "difference", "plane"] {
            outputs = outputs.implicit(pictures::sibling_png(png, suffix), png);
        }
    }
    Ok(outputs.prepare()?)
}

/// [`InMemorySignals::read_npy`], refusing a value that is not finite.
fn read_finite(path: &Path) -> Result<InMemorySignals> {
    let generated = InMemorySignals::read_npy(path)?;
    if generated.is_empty() {
        return Err(DataError::format(
            path,
            format!(
                "holds no samples (shape [0, {}, {}]); metrics need at least one",
                generated.num_vertices(),
                generated.channels()
            ),
        ));
    }
    if let Some((i, vertex, channel, x)) = generated.first_non_finite() {
        return Err(DataError::format(
            path,
            format!(
                "sample {i} is not finite ({x} at vertex {vertex}, channel {channel}); \
                 metrics need finite samples"
            ),
        ));
    }
    Ok(generated)
}
