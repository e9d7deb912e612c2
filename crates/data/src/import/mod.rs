//! A user's own data as an experiment folder (`mfm dataset import`): shapes
//! of one connectivity (mesh files or folders of them), per-vertex signals
//! (a NumPy array on a mesh, PLY vertex properties) or the authors'
//! dataset files, split into training and held-out sets.
//!
//! The folder is laid out as the generated experiments' ([`crate::layout`]):
//!
//! | entry | what |
//! |---|---|
//! | [`TRAIN`] | the training signals on the template (the rest shape; its triangulation is every input's) |
//! | [`HOLDOUT`] | the held-out signals on the template, when a holdout is asked for |
//! | [`REFERENCE`] | the same held-out signals carried to the reference mesh, another triangulation of the template's surface |
//! | [`TRANSFER`] | how the reference mesh's vertices sit on the template: `[V_ref, 6]` float64, per row three template vertex indices then their barycentric weights ([`Transfer`]) |
//! | [`SUMMARY`] | what was imported ([`ImportSummary`]: inputs, split, warnings) |
//! | [`PREVIEW`] | the template and the first training signals |
//!
//! Every dataset's manifest names each of its signals' input (file name or
//! array row) and index ([`ImportManifest`]) and records the template's
//! canonical frame; the signals stay in the user's units and place, so
//! what a model trained on them generates comes back in them.
//!
//! Signals are streamed: each is read, checked (finite values, a bounding
//! box like the template's; a sketch kept for the search for copies and
//! near copies, [`copies`], whose pairs are reported at the end, with the
//! held-out shapes that have a copy among the training ones) and appended to its
//! set's `signals.npy` before the next is read ([`crate::dataset::DatasetWriter`]);
//! memory holds a few signals at a time, whatever their number.

pub mod authors;
pub mod copies;
pub mod inputs;
pub mod sources;

use std::path::Path;
use std::time::Instant;

use indicatif::{ProgressBar, ProgressStyle};
use mfm_geometry::TriMesh;
use mfm_geometry::frame::CanonicalFrame;
use mfm_geometry::validate::{MeshProblem, MeshReport};
use rand::SeedableRng;
use rand::seq::SliceRandom;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::dataset::{Dataset, DatasetWriter, Manifest};
use crate::error::{DataError, Result};
use crate::experiment::{GmmMeshes, HalfDensity};
use crate::layout::{HOLDOUT, PREVIEW, REFERENCE, TRAIN};
use crate::signals::InMemorySignals;
use crate::transfer::Transfer;
use crate::{SignalSource, pictures};
pub use sources::SignalFiles;

/// The generator name recorded in the manifests of an imported dataset.
pub const GENERATOR: &str = "import";
/// The reference mesh's vertices on the template ([`Transfer`]).
pub const TRANSFER: &str = "transfer.npy";
/// The summary of an import ([`ImportSummary`]).
pub const SUMMARY: &str = "import.json";
/// Largest distance of a reference mesh's vertex from the template's
/// surface, as a fraction of the template's bounding-box diagonal.
pub const REFERENCE_TOLERANCE: f64 = 0.01;
/// Bounding-box diagonal ratio (either way) beyond which a shape is said
/// to be in other units than the template.
pub const UNITS_RATIO: f64 = 10.0;
/// Signals read at once (in parallel) while streaming.
const CHUNK: usize = 16;

/// Which inputs are held out (`--holdout`).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Holdout {
    /// No held-out set.
    None,
    /// This many inputs, drawn at random with the seed.
    Count(usize),
    /// This percentage of the inputs (rounded, at least one), drawn at
    /// random with the seed.
    Percent(f64),
    /// Every `k`-th input: inputs `k - 1`, `2k - 1`, ... (0-based), as for
    /// a sequence whose frames are held out at a regular interval.
    Every(usize),
}

impl std::str::FromStr for Holdout {
    type Err = DataError;

    /// `N`, `P%` or `every:K`.
    fn from_str(s: &str) -> Result<Self> {
        let bad = || {
            DataError::Config(format!(
                "--holdout {s:?}: expected a count (8), a percentage (12.5%) or every:K (every:8)"
            ))
        };
        if let Some(k) = s.strip_prefix("every:") {
            let k: usize = k.parse().map_err(|_| bad())?;
            if k < 2 {
                return Err(DataError::Config(format!(
                    "--holdout every:{k} would hold out everything; K must be at least 2"
                )));
            }
            return Ok(Self::Every(k));
        }
        if let Some(p) = s.strip_suffix('%') {
            let p: f64 = p.trim().parse().map_err(|_| bad())?;
            if !(p.is_finite() && (0.0..100.0).contains(&p)) {
                return Err(DataError::Config(format!(
                    "--holdout {s}: the percentage must be in [0, 100)"
                )));
            }
            return Ok(if p == 0.0 {
                Self::None
            } else {
                Self::Percent(p)
            });
        }
        let n: usize = s.parse().map_err(|_| bad())?;
        Ok(if n == 0 { Self::None } else { Self::Count(n) })
    }
}

impl Holdout {
    /// Which of `n` inputs are held out, deterministic in `seed`.
    ///
    /// # Errors
    /// [`DataError::Config`] when nothing would be left to train on.
    ///
    /// # Example
    /// ```
    /// use mfm_data::import::Holdout;
    /// let every = Holdout::Every(8).held_out(17, 0).unwrap();
    /// let held: Vec<usize> = (0..17).filter(|&i| every[i]).collect();
    /// assert_eq!(held, [7, 15]);
    /// let drawn = Holdout::Percent(25.0).held_out(8, 3).unwrap();
    /// assert_eq!(drawn.iter().filter(|&&h| h).count(), 2);
    /// assert_eq!(drawn, Holdout::Percent(25.0).held_out(8, 3).unwrap());
    /// ```
    pub fn held_out(&self, n: usize, seed: u64) -> Result<Vec<bool>> {
        let count = match *self {
            Self::None => return Ok(vec![false; n]),
            Self::Every(k) => return Ok((0..n).map(|i| (i + 1) % k.max(1) == 0).collect()),
            Self::Count(k) => k,
            Self::Percent(p) => ((p / 100.0 * n as f64).round() as usize).max(1),
        };
        if count >= n {
            return Err(DataError::Config(format!(
                "--holdout takes {count} of {n} inputs, leaving none to train on"
            )));
        }
        let mut order: Vec<usize> = (0..n).collect();
        order.shuffle(&mut rand_chacha::ChaCha8Rng::seed_from_u64(seed));
        let mut held = vec![false; n];
        for &i in &order[..count] {
            held[i] = true;
        }
        Ok(held)
    }
}

/// Whether imported shapes are turned to face as the template does
/// (`--align`): a sequence that turns about itself (a performer walking
/// around) is a harder distribution to learn than its poses alone.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Align {
    /// Shapes as given.
    #[default]
    None,
    /// Each shape turned about the vertical axis (0 = x, 1 = y, 2 = z)
    /// through its mass-weighted centroid by the angle that best matches
    /// it to the template ([`mfm_deform::align_to_rest`]); its centroid
    /// stays where it was.
    Up(usize),
    /// Each shape turned about its centroid by the rotation that best
    /// matches it to the template (mass-weighted Kabsch,
    /// [`mfm_deform::align_rigid`]); its centroid stays where it was.
    Rigid,
}

impl std::str::FromStr for Align {
    type Err = DataError;

    /// `none`, `up:x|y|z` or `rigid`.
    fn from_str(s: &str) -> Result<Self> {
        match s {
            "none" => Ok(Self::None),
            "rigid" => Ok(Self::Rigid),
            "up:x" => Ok(Self::Up(0)),
            "up:y" => Ok(Self::Up(1)),
            "up:z" => Ok(Self::Up(2)),
            other => Err(DataError::Config(format!(
                "--align {other:?}: expected none, rigid, or up:x, up:y, up:z (the vertical axis)"
            ))),
        }
    }
}

impl Align {
    /// `positions` (`V x 3` values of the template's vertices) turned as
    /// `self` says, their centroid weighted by `mass` (the template's
    /// lumped mass) kept.
    ///
    /// # Errors
    /// [`DataError::Deform`] for shapes the fit cannot take (not finite, a
    /// template without mass).
    pub fn apply(self, template: &TriMesh, mass: &[f64], values: &[f32]) -> Result<Vec<f32>> {
        if self == Self::None {
            return Ok(values.to_vec());
        }
        let p: Vec<[f64; 3]> = values
            .chunks_exact(3)
            .map(|c| [c[0].into(), c[1].into(), c[2].into()])
            .collect();
        let turned = match self {
            Self::Up(axis) => mfm_deform::align_to_rest(template, &p, axis)?,
            _ => mfm_deform::align_rigid(template, &p, template.positions())?,
        };
        // both fits move the centroid onto the template's: put it back
        let from = mfm_deform::rigid::weighted_centroid(&turned, mass);
        let to = mfm_deform::rigid::weighted_centroid(&p, mass);
        Ok(turned
            .iter()
            .flat_map(|q| [0, 1, 2].map(|k| (q[k] - from[k] + to[k]) as f32))
            .collect())
    }
}

/// One imported signal: its index among the inputs and what the user
/// calls it.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct ImportedSignal {
    /// Index among all inputs (0-based, input order).
    pub index: usize,
    /// The file or array row it came from.
    pub name: String,
}

/// What an imported dataset's manifest records (`generator_params`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ImportManifest {
    /// `template` (train, holdout) or `reference`.
    pub mesh_role: String,
    /// Where the template came from.
    pub template: String,
    /// Whether the signals are vertex positions (shapes).
    pub positions: bool,
    /// The split the set belongs to.
    pub holdout: Holdout,
    /// The split's seed.
    pub seed: u64,
    /// How the shapes were turned to face as the template does.
    #[serde(default)]
    pub align: Align,
    /// Whether the shapes are (source, target) pairs for the
    /// arbitrary-source model (the authors' arbitrary-source file): shape
    /// `2 i` is the source of pair `i`, shape `2 i + 1` its target
    /// ([`crate::pairs::training_pairs`]).
    #[serde(default)]
    pub pairs: bool,
    /// Every signal of the set, in order.
    pub signals: Vec<ImportedSignal>,
}

impl ImportManifest {
    /// The import record of a dataset (`None` when it was not imported).
    ///
    /// # Errors
    /// [`DataError::Files`] (`Format`) naming the manifest when the record
    /// does not parse.
    pub fn of(dataset: &Dataset) -> Result<Option<Self>> {
        dataset.generator_params(GENERATOR)
    }
}

/// What [`ImportExperiment::write`] did, also written as [`SUMMARY`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ImportSummary {
    /// Where the template came from.
    pub template: String,
    /// Template vertices and faces.
    pub template_size: [usize; 2],
    /// Reference mesh vertices and faces (`None` without a holdout).
    pub reference_size: Option<[usize; 2]>,
    /// Where the reference mesh came from.
    pub reference_mesh: Option<String>,
    /// Largest distance of a reference vertex from the template's surface,
    /// over the template's bounding-box diagonal.
    pub reference_max_distance: Option<f64>,
    /// Signals read.
    pub inputs: usize,
    /// Channels per vertex.
    pub channels: usize,
    /// Whether the signals are positions.
    pub positions: bool,
    /// Training signals.
    pub train: usize,
    /// Held-out signals.
    pub held_out: usize,
    /// Whether the signals are (source, target) pairs, two signals each
    /// ([`ImportManifest::pairs`]).
    #[serde(default)]
    pub pairs: bool,
    /// Input folder entries skipped as not mesh files.
    pub skipped: usize,
    /// Warnings about data that is still usable.
    pub warnings: Vec<String>,
    /// Wall-clock seconds.
    pub seconds: f64,
}

/// An import: the signals, their template, the split and the reference
/// mesh; see the [module docs](self).
#[derive(Clone, Copy)]
pub struct ImportExperiment<'a> {
    /// The signals.
    pub source: &'a dyn SignalFiles,
    /// The template mesh (the rest shape): every signal lives on its
    /// vertices.
    pub template: &'a TriMesh,
    /// Where the template came from, for the manifests.
    pub template_name: &'a str,
    /// Which signals are held out.
    pub holdout: Holdout,
    /// The reference mesh, another triangulation of the template's
    /// surface; `None`: the template with its `x < centroid` half refined
    /// twice (as `mfm dataset deform` makes its evaluation mesh).
    pub reference_mesh: Option<(&'a TriMesh, &'a str)>,
    /// The split's seed.
    pub seed: u64,
    /// Whether shapes are turned to face as the template does (only
    /// position signals; [`Align::None`] for others).
    pub align: Align,
    /// Whether the signals are (source, target) pairs, source first
    /// ([`sources::PairedShapes`]): the split holds out whole pairs and
    /// repeated sources are not copies.
    pub pairs: bool,
    /// Input folder entries skipped before the import (for the summary).
    pub skipped: usize,
    /// Whether to show a progress bar.
    pub progress: bool,
}

impl ImportExperiment<'_> {
    /// Checks the template and the sizes, then streams every signal into
    /// `out` (missing or empty; everything it wrote is removed on failure
    /// or interrupt), and writes the transfer, the summary and the
    /// preview.
    ///
    /// Cost: one read of every input; a closest-point search per reference
    /// vertex; `O(V C)` memory per signal in flight.
    ///
    /// # Errors
    /// [`DataError::Config`] for fewer than 2 signals, a holdout that
    /// leaves nothing to train on, or a template unfit for training
    /// (degenerate, duplicate or non-manifold faces, naming the file and
    /// the first faces); [`DataError::Files`] naming the input that cannot
    /// be read, does not have the template's connectivity or holds a value
    /// that is not finite (with its vertex); a reference mesh farther from
    /// the template than [`REFERENCE_TOLERANCE`]; memory and disk refusals;
    /// the writers' errors.
    pub fn write(&self, out: &Path) -> Result<ImportSummary> {
        let started = Instant::now();
        let source = self.source;
        let n = source.len();
        if self.align != Align::None && !(source.positions() && source.channels() == 3) {
            return Err(DataError::Config(
                "--align turns shapes; these signals are not vertex positions".into(),
            ));
        }
        if self.pairs && !(source.positions() && source.channels() == 3 && n % 2 == 0) {
            return Err(DataError::Config(
                "pairs are (source, target) shapes, two position signals each".into(),
            ));
        }
        if n < 2 {
            return Err(DataError::Config(format!(
                "{n} signal{} to import: a generative model needs at least 2",
                if n == 1 { "" } else { "s" }
            )));
        }
        let mut warnings = check_template(self.template, self.template_name)?;
        let held = if self.pairs {
            // whole pairs: both shapes of a held-out pair are held out
            let pairs = self.holdout.held_out(n / 2, self.seed)?;
            (0..n).map(|i| pairs[i / 2]).collect()
        } else {
            self.holdout.held_out(n, self.seed)?
        };
        let num_held = held.iter().filter(|&&h| h).count();
        let c = source.channels();
        let v = self.template.num_vertices();
        let reference = if num_held > 0 {
            Some(self.reference()?)
        } else {
            None
        };
        let v_ref = reference.as_ref().map_or(0, |r| r.0.num_vertices());
        let values =
            |count: usize, vertices: usize| (count as u128) * (vertices as u128) * c as u128;
        let bytes =
            4 * (values(n - num_held, v) + values(num_held, v + v_ref)) + 48 * v_ref as u128 + 1024;
        mfm_files::space::ensure_memory(
            &format!("{CHUNK} signals of {v} vertices x {c} channels in flight"),
            values(CHUNK, v),
            8,
        )?;
        let frame = CanonicalFrame::of(self.template).map_err(|e| DataError::MeshProcessing {
            what: format!(
                "placing the template {} in the canonical frame",
                self.template_name
            ),
            source: Box::new(e),
        })?;
        let undo = mfm_files::Undo::empty_folder(out)?;
        mfm_files::space::ensure_space(out, u64::try_from(bytes).unwrap_or(u64::MAX))?;
        let manifest = |role: &str, pick: bool| {
            let signals = (0..n)
                .filter(|&i| held[i] == pick)
                .map(|index| ImportedSignal {
                    index,
                    name: source.name(index),
                })
                .collect();
            let params = ImportManifest {
                mesh_role: role.into(),
                template: self.template_name.into(),
                positions: source.positions(),
                holdout: self.holdout,
                seed: self.seed,
                align: self.align,
                pairs: self.pairs,
                signals,
            };
            serde_json::to_value(&params)
                .map(|p| {
                    Manifest::new(GENERATOR, p)
                        .with_seed(self.seed)
                        .with_frame(frame)
                        .with_provenance(format!(
                            "mfm dataset import: {} signals of {}",
                            if pick { "held-out" } else { "training" },
                            self.template_name
                        ))
                })
                .map_err(|e| DataError::Config(e.to_string()))
        };
        let mut train = DatasetWriter::create(
            out.join(TRAIN),
            self.template,
            manifest("template", false)?,
            n - num_held,
            c,
        )?;
        let mut sets = None;
        if let Some((mesh, transfer, _, _)) = &reference {
            transfer.write(&out.join(TRANSFER))?;
            let holdout = DatasetWriter::create(
                out.join(HOLDOUT),
                self.template,
                manifest("template", true)?,
                num_held,
                c,
            )?;
            let mut reference_manifest = manifest("reference", true)?;
            reference_manifest.provenance = format!(
                "mfm dataset import: held-out signals of {} carried to the reference mesh",
                self.template_name
            );
            let on_reference =
                DatasetWriter::create(out.join(REFERENCE), mesh, reference_manifest, num_held, c)?;
            sets = Some((holdout, on_reference));
        }
        let mass = if self.align == Align::None {
            Vec::new()
        } else {
            mfm_geometry::operators::lumped_mass(self.template)
        };
        let bar = progress_bar(self.progress, n, v);
        let mut checks = SignalChecks::new(self.template, source.positions(), c);
        for first in (0..n).step_by(CHUNK) {
            let indices: Vec<usize> = (first..(first + CHUNK).min(n)).collect();
            // a source repeated over its pairs is not a copy
            let copies = |i: usize| !(self.pairs && i % 2 == 0);
            let read: Vec<Result<(Vec<f32>, _)>> = indices
                .par_iter()
                .map(|&i| {
                    let signal = source.read(i, self.template)?;
                    let sketch = copies(i).then(|| checks.copies.sketch(&signal));
                    Ok((signal, sketch))
                })
                .collect();
            for (&i, read) in indices.iter().zip(read) {
                let (signal, sketch) = read?;
                checks.check(&signal, i, &source.name(i), c, sketch)?;
                let signal = self.align.apply(self.template, &mass, &signal)?;
                if held[i] {
                    if let (Some((holdout, on_reference)), Some((_, transfer, _, _))) =
                        (sets.as_mut(), reference.as_ref())
                    {
                        holdout.append(&signal)?;
                        on_reference.append(&transfer.apply(&signal, c)?)?;
                    }
                } else {
                    train.append(&signal)?;
                }
                bar.inc(1);
            }
        }
        bar.finish_and_clear();
        warnings.extend(checks.warnings(&held));
        let train = train.finish()?;
        if let Some((holdout, on_reference)) = sets {
            holdout.finish()?;
            on_reference.finish()?;
        }
        preview(
            self.template,
            &train,
            source.positions(),
            &out.join(PREVIEW),
        )?;
        let summary = ImportSummary {
            template: self.template_name.into(),
            template_size: [v, self.template.num_faces()],
            reference_size: reference
                .as_ref()
                .map(|r| [r.0.num_vertices(), r.0.num_faces()]),
            reference_mesh: reference.as_ref().map(|r| r.2.clone()),
            reference_max_distance: reference.as_ref().map(|r| r.3),
            inputs: n,
            channels: c,
            positions: source.positions(),
            train: n - num_held,
            held_out: num_held,
            pairs: self.pairs,
            skipped: self.skipped,
            warnings,
            seconds: started.elapsed().as_secs_f64(),
        };
        mfm_files::write_json(out.join(SUMMARY), &summary)?;
        undo.keep();
        Ok(summary)
    }

    /// The reference mesh, its transfer, where it came from and its
    /// largest distance from the template (over the diagonal).
    fn reference(&self) -> Result<(TriMesh, Transfer, String, f64)> {
        let (mesh, name) = match self.reference_mesh {
            Some((mesh, name)) => (mesh.clone(), name.to_owned()),
            None => {
                let meshes = GmmMeshes::from_base(self.template.clone(), HalfDensity::default())?;
                (
                    meshes.test,
                    "the template with its x < centroid half refined twice".to_owned(),
                )
            }
        };
        let transfer = Transfer::locate(self.template, &mesh).map_err(|e| match e {
            DataError::Config(m) => DataError::Config(format!("reference mesh {name}: {m}")),
            other => other,
        })?;
        let diagonal = self.template.bounding_box_diagonal();
        let distance = transfer.max_distance() / diagonal;
        if distance.is_nan() || distance > REFERENCE_TOLERANCE {
            let (vertex, d) = transfer.farthest();
            return Err(DataError::Config(format!(
                "reference mesh {name}: vertex {vertex} lies {} from the template's surface, {:.1}% \
                 of its bounding-box diagonal (at most {}% is taken for another triangulation of \
                 the same surface; is it in the template's units and place?)",
                mfm_files::fmt_f64(d),
                100.0 * d / diagonal,
                100.0 * REFERENCE_TOLERANCE
            )));
        }
        Ok((mesh, transfer, name, distance))
    }
}

/// Refuses a template that training cannot use and returns warnings about
/// what it can.
fn check_template(template: &TriMesh, name: &str) -> Result<Vec<String>> {
    let report = MeshReport::new(template);
    let mut warnings = Vec::new();
    for problem in &report.problems {
        let fatal = matches!(
            problem,
            MeshProblem::DegenerateFaces { .. }
                | MeshProblem::DuplicateFaces { .. }
                | MeshProblem::NonManifoldEdges { .. }
                | MeshProblem::NonManifoldVertices { .. }
        );
        if fatal {
            return Err(DataError::Config(format!(
                "the template {name}: {problem}; the operators every model computes need a \
                 manifold mesh whose faces have an area (`mfm info {name}` shows the full report)"
            )));
        }
        warnings.push(format!("the template {name}: {problem}"));
    }
    Ok(warnings)
}

/// What the import notices about the signals as they stream by.
struct SignalChecks {
    positions: bool,
    diagonal: f64,
    copies: copies::CopyFinder,
    other_units: Vec<(String, f64)>,
}

impl SignalChecks {
    fn new(template: &TriMesh, positions: bool, channels: usize) -> Self {
        let diagonal = template.bounding_box_diagonal();
        Self {
            positions,
            diagonal,
            copies: copies::CopyFinder::new(
                template.num_vertices(),
                channels,
                positions.then_some(diagonal),
            ),
            other_units: Vec::new(),
        }
    }

    /// Refuses a value that is not finite; notes the signal's sketch (when
    /// it is searched for copies) and other units.
    fn check(
        &mut self,
        signal: &[f32],
        index: usize,
        name: &str,
        channels: usize,
        sketch: Option<([f64; copies::SKETCH], f64)>,
    ) -> Result<()> {
        let v = signal.len() / channels.max(1);
        if let Some((_, vertex, channel, x)) = crate::signals::first_non_finite(signal, v, channels)
        {
            return Err(DataError::format(
                name,
                format!(
                    "vertex {vertex}{} is {x}: every value must be finite",
                    if self.positions {
                        format!(", coordinate {}", ["x", "y", "z"][channel.min(2)])
                    } else {
                        format!(", channel {channel}")
                    }
                ),
            ));
        }
        if let Some(sketch) = sketch {
            self.copies.push(index, sketch);
        }
        if self.positions && channels == 3 {
            let points: Vec<[f64; 3]> = signal
                .chunks_exact(3)
                .map(|p| [p[0].into(), p[1].into(), p[2].into()])
                .collect();
            let (lo, hi) = mfm_geometry::mesh::bounding_box(&points);
            let d = mfm_geometry::mesh::norm(mfm_geometry::mesh::sub(hi, lo));
            let ratio = d / self.diagonal;
            if !(1.0 / UNITS_RATIO..=UNITS_RATIO).contains(&ratio) {
                self.other_units.push((name.to_owned(), ratio));
            }
        }
        Ok(())
    }

    /// The warnings, `held[i]` telling whether input `i` is held out.
    fn warnings(&self, held: &[bool]) -> Vec<String> {
        let mut out = Vec::new();
        let pairs = self.copies.pairs();
        let scale = if self.positions {
            "of the template's bounding-box diagonal"
        } else {
            "of the signals' RMS value"
        };
        let mut later: Vec<usize> = pairs.iter().map(|&(i, _)| i).collect();
        later.dedup();
        if let Some(&(i, j)) = pairs.first() {
            out.push(format!(
                "{} signal{} a copy or near copy of an earlier one (RMS vertex distance at most {} \
                 {scale}; first: input {i} repeats input {j}); copies weigh more in training",
                later.len(),
                if later.len() == 1 { " is" } else { "s are" },
                copies::COPY_TOLERANCE,
            ));
        }
        let is_held = |i: usize| held.get(i).copied().unwrap_or(false);
        let mut leaks: Vec<(usize, usize)> = pairs
            .iter()
            .filter(|&&(i, j)| is_held(i) != is_held(j))
            .map(|&(i, j)| if is_held(i) { (i, j) } else { (j, i) })
            .collect();
        leaks.sort_unstable();
        if let Some(&(h, t)) = leaks.first() {
            let mut count: Vec<usize> = leaks.iter().map(|&(h, _)| h).collect();
            count.dedup();
            out.push(format!(
                "{} held-out signal{} a copy among the training signals (first: held-out input {h} \
                 repeats training input {t}): the evaluation reads a model that reproduces it as \
                 data-like and its floor is 0 there; choose a holdout that keeps copies on one side \
                 (for a repeated cycle, hold out within one repetition) or remove the copies",
                count.len(),
                if count.len() == 1 { " has" } else { "s have" },
            ));
        }
        if let Some((name, ratio)) = self.other_units.first() {
            out.push(format!(
                "{} shape{} a bounding box more than {UNITS_RATIO}x larger or smaller than the \
                 template's (first: {name}, {}x): mixed units?",
                self.other_units.len(),
                if self.other_units.len() == 1 {
                    " has"
                } else {
                    "s have"
                },
                mfm_files::fmt_f64((ratio * 100.0).round() / 100.0)
            ));
        }
        out
    }
}

/// The import's progress bar (hidden unless `show`).
fn progress_bar(show: bool, n: usize, v: usize) -> ProgressBar {
    if !show {
        return ProgressBar::hidden();
    }
    let bar = ProgressBar::new(n as u64);
    bar.set_style(
        ProgressStyle::with_template("{prefix} [{bar:30}] {pos}/{len} ({per_sec}, {eta} left)")
            .unwrap_or_else(|_| ProgressStyle::default_bar())
            .progress_chars("=> "),
    );
    bar.set_prefix(format!("importing signals on {v} vertices"));
    bar
}

/// The preview: the template and up to [`pictures::SHOWN`] training
/// signals spread evenly over the set (the first, the last and between:
/// consecutive frames of a sequence look alike), read alone, not the whole
/// set.
fn preview(template: &TriMesh, train: &Dataset, positions: bool, path: &Path) -> Result<()> {
    let n = train.len();
    let shown = n.min(pictures::SHOWN);
    let indices: Vec<usize> = (0..shown)
        .map(|k| {
            if shown > 1 {
                k * (n - 1) / (shown - 1)
            } else {
                0
            }
        })
        .collect();
    let row = train.num_vertices() * train.channels();
    let mut data = vec![0.0f32; shown * row];
    train.read_into(&indices, &mut data)?;
    let picked = InMemorySignals::new(data, shown, train.num_vertices(), train.channels())?;
    let captions: Vec<String> = indices.iter().map(|i| format!("training {i}")).collect();
    if positions && train.channels() == 3 {
        let mut items = vec![pictures::Shown::Shape(template.clone(), "template".into())];
        for (k, caption) in captions.into_iter().enumerate() {
            items.push(pictures::Shown::of(template, &picked, k, caption)?);
        }
        pictures::save(template, &items, 3, "imported training shapes", path)
    } else {
        let items = captions
            .into_iter()
            .enumerate()
            .map(|(k, c)| pictures::Shown::of(template, &picked, k, c))
            .collect::<Result<Vec<_>>>()?;
        pictures::save(
            template,
            &items,
            4,
            "imported training signals (channel 0)",
            path,
        )
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::Holdout;

    #[test]
    fn holdout_forms_parse() {
        assert_eq!("8".parse::<Holdout>().unwrap(), Holdout::Count(8));
        assert_eq!("0".parse::<Holdout>().unwrap(), Holdout::None);
        assert_eq!("12.5%".parse::<Holdout>().unwrap(), Holdout::Percent(12.5));
        assert_eq!("every:8".parse::<Holdout>().unwrap(), Holdout::Every(8));
        for bad in ["", "x", "-1", "100%", "every:1", "every:x", "nan%"] {
            assert!(bad.parse::<Holdout>().is_err(), "{bad}");
        }
    }

    #[test]
    fn a_holdout_leaves_something_to_train_on() {
        assert!(Holdout::Count(5).held_out(5, 0).is_err());
        assert!(Holdout::Percent(99.0).held_out(10, 0).is_err());
        let h = Holdout::Count(3).held_out(10, 1).unwrap();
        assert_eq!(h.iter().filter(|&&x| x).count(), 3);
        assert_ne!(h, Holdout::Count(3).held_out(10, 2).unwrap());
    }
}
