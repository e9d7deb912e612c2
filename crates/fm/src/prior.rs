//! The **data prior**: a start distribution that already holds the
//! training data's mean and covariance (`noise.prior = "gaussian"`).
//!
//! The flow then starts each sample from a draw of the Gaussian fitted to
//! the training signals plus the run's noise, and only has to learn what
//! that Gaussian gets wrong. On a motion sequence the flow from noise
//! alone decides a sample's pose in the first half of the path and blends
//! poses toward the mean shape there (docs/BENCHMARKS.md, "What the samples
//! are"); a Gaussian draw starts it near a plausible shape already.
//!
//! ## The fit
//! With the training signals `x_1 .. x_n` in the run's frame (at most
//! [`PRIOR_FIT_SIGNALS`] evenly spaced ones), their mean `mu` and their
//! principal directions `u_k` under the training mesh's lumped mass
//! ([`mfm_data::principal`]) with scatter `g_k`, a draw is
//!
//! ```text
//! g = mu + sum_{k < r} e_k sqrt(g_k / (n - 1)) u_k,     e ~ N(0, I)
//! ```
//!
//! with `r` at most `noise.prior_directions`: the Gaussian with the signals'
//! mean and sample covariance, truncated to its `r` leading directions
//! (exact when `r >= n - 1`). The start of a sample is then `x0 = g +
//! sigma n` (`n` the run's noise), centred as the noise alone would be.
//!
//! ## On any mesh
//! The fit lives on the training mesh. On another triangulation of the
//! same surface a draw is made on the training mesh and carried to the
//! target's vertices by closest point and barycentric weights
//! ([`mfm_data::transfer::Transfer`]), as [`crate::sample::Sampler::carried_noise`]
//! carries noise: it holds no frequency the training mesh cannot, so the
//! network meets no start it has not seen. A target farther from the
//! training surface than [`crate::sample::CARRY_TOLERANCE`] of its diagonal
//! is refused.
//!
//! ## Determinism
//! Draw `i` of seed `s` takes its `r` normals from stream `i` of a key
//! derived from `(s, "prior")`: training step `t` adds draws `t B .. t B +
//! B` to its noise samples of the same indices, sample `i` adds draw `i`,
//! whatever the batch or thread count.
//!
//! ## The file
//! `prior.safetensors` in the run folder ([`PRIOR_FILE`]), written once when
//! training starts: `mean` `[V, C]` and `components` `[r, V, C]` (the
//! `sqrt(g_k / (n - 1)) u_k`) in `f32`, and the training mesh in the frame,
//! `vertices` `[V, 3]` `f64` and `faces` `[F, 3]` `u32`. `flow.json` records
//! its size and CRC-32 ([`PriorSpec`]); a file that does not match is
//! refused by name.
//!
//! # Example
//! ```
//! use mfm_data::InMemorySignals;
//! use mfm_fm::prior::GaussianPrior;
//!
//! let mesh = mfm_geometry::procedural::icosphere(1);
//! let v = mesh.num_vertices();
//! // two constant fields, 0 and 2: the fit's draws are constant fields about 1
//! let mut values = vec![0.0f32; v];
//! values.extend(vec![2.0f32; v]);
//! let signals = InMemorySignals::new(values, 2, v, 1).unwrap();
//! let prior = GaussianPrior::fit(&mesh, &signals, 8).unwrap();
//! assert_eq!(prior.directions(), 1);
//! let mut x = vec![0.0f32; 3 * v];
//! prior.add_draws(&mut x, 0, 3, 7, None).unwrap();
//! assert!(x.chunks(v).all(|s| s.iter().all(|&y| (y - s[0]).abs() < 1e-5)));
//! ```

use std::collections::HashMap;
use std::path::Path;

use mfm_data::transfer::Transfer;
use mfm_data::{InMemorySignals, SignalSource};
use mfm_files::run_folder::FileRecord;
use mfm_geometry::TriMesh;
use mfm_train::seeding::derived_rng;
use rand::Rng;
use rand_distr::StandardNormal;
use rayon::prelude::*;
use safetensors::tensor::{Dtype, TensorView};
use serde::{Deserialize, Serialize};

use crate::error::{FmError, Result};

/// The prior's file in a run folder.
pub const PRIOR_FILE: &str = mfm_files::owned::RUN_PRIOR;

/// Most training signals the prior is fitted on (evenly spaced over the
/// dataset beyond); fewer when they would hold more than
/// [`PRIOR_FIT_VALUES`] values.
pub const PRIOR_FIT_SIGNALS: usize = 512;

/// Most values (signals times vertices times channels) the fit reads.
pub const PRIOR_FIT_VALUES: usize = 1 << 25;

/// The purpose of the prior's derived random keys (the training's are
/// 1-4).
const PURPOSE_PRIOR: u64 = 5;

/// The distribution a flow's start adds to its noise (`noise.prior`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum PriorKind {
    /// None: the start is the noise alone (the paper's).
    #[default]
    None,
    /// The Gaussian fit of the training signals ([module docs](self)).
    Gaussian,
}

impl PriorKind {
    /// `true` for [`PriorKind::None`].
    pub fn is_none(&self) -> bool {
        *self == Self::None
    }
}

impl std::fmt::Display for PriorKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::None => "none",
            Self::Gaussian => "gaussian",
        })
    }
}

impl std::str::FromStr for PriorKind {
    type Err = String;

    /// `none` or `gaussian` (the command-line and TOML forms).
    fn from_str(s: &str) -> std::result::Result<Self, Self::Err> {
        match s {
            "none" => Ok(Self::None),
            "gaussian" => Ok(Self::Gaussian),
            other => Err(format!(
                "unknown prior {other:?}; expected \"none\" or \"gaussian\""
            )),
        }
    }
}

/// What `flow.json` records of a run's prior.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PriorSpec {
    /// The prior's kind (never [`PriorKind::None`]).
    pub kind: PriorKind,
    /// Directions `r` kept.
    pub directions: usize,
    /// Training signals fitted on.
    pub fitted_on: usize,
    /// Size and CRC-32 of [`PRIOR_FILE`].
    pub file: FileRecord,
}

/// The Gaussian fit of a run's training signals on its training mesh (see
/// the [module docs](self)).
#[derive(Clone, Debug, PartialEq)]
pub struct GaussianPrior {
    mesh: TriMesh,
    channels: usize,
    /// `mu`, `V x C`.
    mean: Vec<f32>,
    /// `r` rows of `V x C`: `sqrt(g_k / (n - 1)) u_k`.
    components: Vec<f32>,
    fitted_on: usize,
}

impl GaussianPrior {
    /// Fits the prior to `signals` on `mesh` (both in the run's frame)
    /// with at most `max_directions` directions: reads at most
    /// [`PRIOR_FIT_SIGNALS`] evenly spaced signals (fewer for very large
    /// meshes, [`PRIOR_FIT_VALUES`]).
    ///
    /// # Errors
    /// [`FmError::SizeMismatch`] for signals of another vertex count;
    /// [`FmError::Config`] for no signals; read errors of the dataset.
    pub fn fit(mesh: &TriMesh, signals: &dyn SignalSource, max_directions: usize) -> Result<Self> {
        let (n, v, c) = (signals.len(), signals.num_vertices(), signals.channels());
        if v != mesh.num_vertices() {
            return Err(FmError::SizeMismatch {
                what: "vertices per signal of the prior's fit (the training mesh's)".into(),
                expected: mesh.num_vertices(),
                found: v,
            });
        }
        if n == 0 || c == 0 {
            return Err(FmError::Config(
                "noise.prior needs training signals with at least one channel".into(),
            ));
        }
        let k = n
            .min(PRIOR_FIT_SIGNALS)
            .min((PRIOR_FIT_VALUES / (v * c)).max(2));
        let indices: Vec<usize> = (0..k).map(|i| i * n / k).collect();
        let mut values = vec![0.0f32; k * v * c];
        signals.read_into(&indices, &mut values)?;
        let set = InMemorySignals::new(values, k, v, c)?;
        let mass = mfm_geometry::operators::lumped_mass(mesh);
        let all: Vec<usize> = (0..k).collect();
        let pc = mfm_data::principal::PrincipalComponents::fit(&set, &all, &mass, max_directions)?;
        let mut components = Vec::with_capacity(pc.len() * v * c);
        for (d, g) in pc.scatter().iter().enumerate() {
            let sd = (g / (k - 1) as f64).sqrt();
            components.extend(pc.direction(d).iter().map(|u| (sd * u) as f32));
        }
        Ok(Self {
            mesh: mesh.clone(),
            channels: c,
            mean: pc.mean().iter().map(|&m| m as f32).collect(),
            components,
            fitted_on: k,
        })
    }

    /// Directions `r` of the fit.
    pub fn directions(&self) -> usize {
        self.components.len() / self.mean.len().max(1)
    }

    /// Channels `C` per vertex.
    pub fn channels(&self) -> usize {
        self.channels
    }

    /// Training signals the fit read.
    pub fn fitted_on(&self) -> usize {
        self.fitted_on
    }

    /// The training mesh in the run's frame (where the fit lives).
    pub fn mesh(&self) -> &TriMesh {
        &self.mesh
    }

    /// The mean `mu`, `V x C` values of the training mesh.
    pub fn mean(&self) -> &[f32] {
        &self.mean
    }

    /// Component `k` (`sqrt(g_k / (n - 1)) u_k`, `V x C` values; `k <
    /// directions()`, panics otherwise).
    pub fn component(&self, k: usize) -> &[f32] {
        let size = self.mean.len();
        &self.components[k * size..(k + 1) * size]
    }

    /// Draw `index` of `seed` on the training mesh (`V x C` values).
    pub fn draw(&self, index: u64, seed: u64) -> Vec<f32> {
        let mut rng = derived_rng(seed, PURPOSE_PRIOR, index);
        let e: Vec<f64> = (0..self.directions())
            .map(|_| rng.sample::<f64, _>(StandardNormal))
            .collect();
        let mut g: Vec<f64> = self.mean.iter().map(|&m| f64::from(m)).collect();
        for (k, &ek) in e.iter().enumerate() {
            for (gj, &cj) in g.iter_mut().zip(self.component(k)) {
                *gj += ek * f64::from(cj);
            }
        }
        g.into_iter().map(|x| x as f32).collect()
    }

    /// Adds draws `first .. first + count` of `seed` to `values` (`count`
    /// signals, one after the other): on the training mesh when `transfer`
    /// is `None`, else carried by it to its target's vertices.
    ///
    /// # Errors
    /// [`FmError::SizeMismatch`] when `values` is not `count` signals of
    /// the mesh's (or the transfer target's) vertices.
    pub fn add_draws(
        &self,
        values: &mut [f32],
        first: usize,
        count: usize,
        seed: u64,
        transfer: Option<&Transfer>,
    ) -> Result<()> {
        let c = self.channels;
        let vertices = transfer.map_or(self.mesh.num_vertices(), Transfer::target_vertices);
        let size = vertices * c;
        if values.len() != count * size {
            return Err(FmError::SizeMismatch {
                what: "values the prior's draws are added to".into(),
                expected: count * size,
                found: values.len(),
            });
        }
        values
            .par_chunks_mut(size.max(1))
            .enumerate()
            .try_for_each(|(k, out)| -> Result<()> {
                let g = self.draw((first + k) as u64, seed);
                let g = match transfer {
                    Some(t) => t.apply(&g, c)?,
                    None => g,
                };
                out.iter_mut().zip(&g).for_each(|(x, y)| *x += y);
                Ok(())
            })
    }

    /// Writes the prior to `path` atomically ([module docs](self), "The
    /// file") and returns what `flow.json` records of it.
    ///
    /// # Errors
    /// I/O errors naming the file.
    pub fn write(&self, path: &Path) -> Result<PriorSpec> {
        let (v, c, r) = (self.mesh.num_vertices(), self.channels, self.directions());
        let vertices: Vec<u8> = self
            .mesh
            .positions()
            .iter()
            .flat_map(|p| p.iter().flat_map(|x| x.to_le_bytes()))
            .collect();
        let faces: Vec<u8> = self
            .mesh
            .faces()
            .iter()
            .flat_map(|f| f.iter().flat_map(|i| i.to_le_bytes()))
            .collect();
        let f32_bytes = |x: &[f32]| -> Vec<u8> { x.iter().flat_map(|y| y.to_le_bytes()).collect() };
        let (mean, components) = (f32_bytes(&self.mean), f32_bytes(&self.components));
        let tensors = vec![
            ("mean", tensor_view(path, Dtype::F32, vec![v, c], &mean)?),
            (
                "components",
                tensor_view(path, Dtype::F32, vec![r, v, c], &components)?,
            ),
            (
                "vertices",
                tensor_view(path, Dtype::F64, vec![v, 3], &vertices)?,
            ),
            (
                "faces",
                tensor_view(path, Dtype::U32, vec![self.mesh.num_faces(), 3], &faces)?,
            ),
        ];
        let metadata = Some(HashMap::from([
            ("kind".to_owned(), "gaussian".to_owned()),
            ("fitted_on".to_owned(), self.fitted_on.to_string()),
        ]));
        let bytes = safetensors::serialize(tensors, &metadata)
            .map_err(|e| FmError::format(path, format!("cannot serialize the prior: {e:?}")))?;
        mfm_files::write_atomic(path, |w| w.write_all(&bytes))?;
        let mut h = crc32fast::Hasher::new();
        h.update(&bytes);
        Ok(PriorSpec {
            kind: PriorKind::Gaussian,
            directions: r,
            fitted_on: self.fitted_on,
            file: FileRecord {
                bytes: bytes.len() as u64,
                crc32: h.finalize(),
            },
        })
    }

    /// Reads the prior `spec` describes from `path`, after checking its size
    /// and CRC-32.
    ///
    /// # Errors
    /// [`FmError::Files`] naming the file when it is missing, does not
    /// match the record, or its tensors are not a prior of `channels`
    /// channels (names, types, shapes, a mesh that does not build).
    pub fn read(path: &Path, spec: &PriorSpec, channels: usize) -> Result<Self> {
        let bytes = std::fs::read(path).map_err(|e| FmError::io(path, e))?;
        let mut h = crc32fast::Hasher::new();
        h.update(&bytes);
        let found = FileRecord {
            bytes: bytes.len() as u64,
            crc32: h.finalize(),
        };
        if found != spec.file {
            return Err(FmError::format(
                path,
                format!(
                    "the prior file has {} bytes and CRC-32 {:08x}, the run's flow.json records {} \
                     bytes and {:08x}: it was changed or truncated since training started",
                    found.bytes, found.crc32, spec.file.bytes, spec.file.crc32
                ),
            ));
        }
        let bad = |what: String| FmError::format(path, what);
        let file = safetensors::SafeTensors::deserialize(&bytes)
            .map_err(|e| bad(format!("not a safetensors file: {e:?}")))?;
        let tensor = |name: &str, dtype: Dtype| -> Result<(Vec<usize>, &[u8])> {
            let t = file
                .tensor(name)
                .map_err(|e| bad(format!("no tensor `{name}`: {e:?}")))?;
            if t.dtype() != dtype {
                return Err(bad(format!(
                    "tensor `{name}` is {:?}, expected {dtype:?}",
                    t.dtype()
                )));
            }
            Ok((t.shape().to_vec(), t.data()))
        };
        let (mshape, mean) = tensor("mean", Dtype::F32)?;
        let (cshape, components) = tensor("components", Dtype::F32)?;
        let (vshape, vertices) = tensor("vertices", Dtype::F64)?;
        let (fshape, faces) = tensor("faces", Dtype::U32)?;
        let v = vshape.first().copied().unwrap_or(0);
        let shapes_fit = mshape == [v, channels]
            && cshape.len() == 3
            && cshape[0] == spec.directions
            && cshape[1..] == [v, channels]
            && vshape == [v, 3]
            && fshape.len() == 2
            && fshape[1] == 3;
        if !shapes_fit {
            return Err(bad(format!(
                "tensor shapes mean {mshape:?}, components {cshape:?}, vertices {vshape:?}, \
                 faces {fshape:?} are not a prior of {} directions and {channels} channels",
                spec.directions
            )));
        }
        let f32s = |b: &[u8]| -> Vec<f32> {
            b.chunks_exact(4)
                .map(|x| f32::from_le_bytes([x[0], x[1], x[2], x[3]]))
                .collect()
        };
        let positions: Vec<[f64; 3]> = vertices
            .chunks_exact(24)
            .map(|p| {
                std::array::from_fn(|d| {
                    let mut b = [0u8; 8];
                    b.copy_from_slice(&p[8 * d..8 * d + 8]);
                    f64::from_le_bytes(b)
                })
            })
            .collect();
        let faces: Vec<[u32; 3]> = faces
            .chunks_exact(12)
            .map(|f| {
                std::array::from_fn(|d| {
                    u32::from_le_bytes([f[4 * d], f[4 * d + 1], f[4 * d + 2], f[4 * d + 3]])
                })
            })
            .collect();
        let mesh = TriMesh::new(positions, faces)
            .map_err(|e| bad(format!("the prior's training mesh does not build: {e}")))?;
        Ok(Self {
            mesh,
            channels,
            mean: f32s(mean),
            components: f32s(components),
            fitted_on: spec.fitted_on,
        })
    }
}

/// A tensor of the prior's file.
fn tensor_view<'a>(
    path: &Path,
    dtype: Dtype,
    shape: Vec<usize>,
    data: &'a [u8],
) -> Result<TensorView<'a>> {
    TensorView::new(dtype, shape, data).map_err(|e| {
        FmError::format(
            path,
            format!("internal: a prior tensor is inconsistent: {e:?}"),
        )
    })
}

/// The prior of the flow `flow` read from `flow_path` (`None` when it has
/// none), found by [`prior_path`] and checked against its record.
///
/// # Errors
/// As [`GaussianPrior::read`].
pub fn read_prior(
    flow_path: &Path,
    flow: &crate::checkpoint::FlowSpec,
) -> Result<Option<GaussianPrior>> {
    flow.prior
        .as_ref()
        .map(|spec| GaussianPrior::read(&prior_path(flow_path), spec, flow.channels))
        .transpose()
}

/// Where the prior of the run whose `flow.json` is `flow_path` lies: next
/// to it (a run folder), else in the run folder of the checkpoint holding it
/// (`run/checkpoints/step-N/flow.json`: `run/prior.safetensors`).
pub fn prior_path(flow_path: &Path) -> std::path::PathBuf {
    let dir = flow_path.parent().unwrap_or(Path::new("."));
    let beside = dir.join(PRIOR_FILE);
    if beside.exists() {
        return beside;
    }
    match dir.parent().and_then(Path::parent) {
        Some(run) if run.join(PRIOR_FILE).exists() => run.join(PRIOR_FILE),
        _ => beside,
    }
}
