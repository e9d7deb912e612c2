//! The GMM signal generator of the paper's supplementary "GMM datasets"
//! (after Manifold Diffusion Fields): random mixtures of Gaussian bumps on a
//! surface.
//!
//! Each sample is a scalar field (`C = 1`)
//!
//! ```text
//! f(x) = sum_{k=1..K} exp( -d(x, c_k)^2 / (2 sigma^2) )
//! ```
//!
//! with `K` = [`GmmConfig::bumps`] centers `c_k` at mesh vertices and `d` the
//! **geodesic distance computed by the heat method**
//! ([`HeatGeodesics`], `t = h^2`) by default, or the straight-line
//! (Euclidean, through space) distance with [`GmmDistance::Euclidean`].
//!
//! - **Scale-free widths.** `sigma = GmmConfig::sigma * sqrt(total area)`, so
//!   the same configuration gives the same picture on a scaled mesh.
//! - **Centers uniform on the surface.** Each center is drawn with
//!   probability proportional to its vertex's lumped mass (a third of the
//!   area of its faces), so where the triangulation is dense, vertices are
//!   individually less likely: the centers follow area, not vertex count.
//! - **Non-overlapping.** A candidate center closer than
//!   `GmmConfig::min_separation * sigma` (same distance) to an already placed
//!   center of the sample is rejected and redrawn, at most
//!   [`GmmConfig::max_attempts`] times per center. With the default `4 sigma`
//!   another bump contributes at most `exp(-8) ~ 3e-4` at a center, so values
//!   lie in `[0, 1 + (K - 1) exp(-8)]`.
//!
//! ## Determinism
//! Sample `i` of seed `s` draws from its own ChaCha8 stream
//! (`ChaCha8Rng::seed_from_u64(s)` switched to stream `i`, the convention of
//! the noise crate), so it is the same whatever the number of samples
//! requested, the thread count, or the order in which rayon runs them.
//!
//! ## Cost
//! One heat-method distance field (two pairs of sparse triangular solves and
//! two sparse products) per distinct center vertex. Fields are cached per
//! vertex as `f32`, up to a memory budget
//! ([`GmmGenerator::with_cache_limit`], 256 MiB by default); beyond it they
//! are recomputed (bit-identically). When a request draws at least `V / 2`
//! centers and all `V` fields fit in the budget, all fields are first
//! computed in blocks of 64 right-hand sides ([`GmmGenerator::precompute`]),
//! about 4x cheaper per field. Samples are generated in parallel with rayon.
//!
//! # Example
//! ```
//! use mfm_data::gmm::{generate, GmmConfig};
//! use mfm_data::SignalSource;
//! use mfm_geometry::procedural;
//! let mesh = procedural::icosphere(3);
//! let signals = generate(&mesh, &GmmConfig::default(), 4, 42).unwrap();
//! assert_eq!((signals.len(), signals.num_vertices(), signals.channels()), (4, 642, 1));
//! assert!(signals.data().iter().all(|&x| (0.0..=1.01).contains(&x)));
//! ```

use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, OnceLock};

use mfm_geometry::TriMesh;
use mfm_geometry::operators::lumped_mass;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::error::{DataError, Result};
use crate::signals::InMemorySignals;
use mfm_files::fmt_f64;
use mfm_geometry::geodesic::HeatGeodesics;

/// Name of this generator in dataset manifests.
pub const GENERATOR_NAME: &str = "gmm";

/// Default distance-field cache budget of [`GmmGenerator`]: 256 MiB.
pub const DEFAULT_CACHE_BYTES: usize = 256 << 20;

/// A cached distance field: one `f32` per vertex.
type Field = Arc<[f32]>;

/// Right-hand sides per block in [`GmmGenerator::precompute`].
const PRECOMPUTE_BLOCK: usize = 64;

/// Which distance the bumps are functions of.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum GmmDistance {
    /// Geodesic distance along the surface, by the heat method
    /// ([`HeatGeodesics`]). The default.
    #[default]
    Geodesic,
    /// Straight-line distance in space (ignores the surface: bumps leak
    /// across thin parts).
    Euclidean,
}

/// Parameters of the GMM generator (see the [module docs](self)).
///
/// Every field has a default; unknown fields are an error when
/// deserializing.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct GmmConfig {
    /// Number of bumps per sample. Default 3.
    pub bumps: usize,
    /// Bump width relative to the square root of the surface area:
    /// `sigma_abs = sigma * sqrt(total area)`. Default 0.06 (on a unit
    /// sphere, `sigma_abs ~ 0.21`).
    pub sigma: f64,
    /// Smallest distance between two centers of one sample, in multiples of
    /// `sigma_abs`. Default 4.
    pub min_separation: f64,
    /// Draws allowed per center before giving up with an error. Default 1000.
    pub max_attempts: usize,
    /// The distance used for bumps and separation. Default geodesic.
    pub distance: GmmDistance,
    /// Heat-method time step as a multiple of the squared mean edge length
    /// (geodesic distance only). Default 1.
    pub heat_time_factor: f64,
}

impl Default for GmmConfig {
    fn default() -> Self {
        Self {
            bumps: 3,
            sigma: 0.06,
            min_separation: 4.0,
            max_attempts: 1000,
            distance: GmmDistance::Geodesic,
            heat_time_factor: 1.0,
        }
    }
}

/// The narrowest bump [`GmmConfig::sigma`] may ask for (relative to the
/// square root of the area): narrower ones underflow to a single vertex
/// (and `0 / 0` at their centre).
pub const MIN_SIGMA: f64 = 1e-6;

impl GmmConfig {
    /// Checks every field.
    ///
    /// # Errors
    /// [`DataError::Config`] naming the field: `bumps` or `max_attempts` zero,
    /// `sigma` not finite or below [`MIN_SIGMA`], `heat_time_factor` not
    /// finite and positive,
    /// `min_separation` negative or not finite.
    pub fn validate(&self) -> Result<()> {
        let bad = |field: &str, requirement: &str, found: String| {
            Err(DataError::Config(format!(
                "gmm.{field} must be {requirement}, found {found}"
            )))
        };
        if self.bumps == 0 {
            return bad("bumps", "at least 1", "0".into());
        }
        if self.max_attempts == 0 {
            return bad("max_attempts", "at least 1", "0".into());
        }
        if !(self.sigma.is_finite() && self.sigma >= MIN_SIGMA) {
            return bad(
                "sigma",
                &format!(
                    "finite and at least {MIN_SIGMA} (relative to the square root of the area; \
                     0.02 to 0.3 make visible bumps)"
                ),
                self.sigma.to_string(),
            );
        }
        if !(self.min_separation.is_finite() && self.min_separation >= 0.0) {
            return bad(
                "min_separation",
                "finite and >= 0",
                self.min_separation.to_string(),
            );
        }
        if !(self.heat_time_factor.is_finite() && self.heat_time_factor > 0.0) {
            return bad(
                "heat_time_factor",
                "finite and > 0",
                self.heat_time_factor.to_string(),
            );
        }
        Ok(())
    }

    /// The parameters as JSON, for [`Manifest::generator_params`]
    /// (every field, so the dataset can be regenerated;
    /// [`GmmConfig::from_manifest_params`] reads it back).
    ///
    /// [`Manifest::generator_params`]: crate::dataset::Manifest::generator_params
    pub fn manifest_params(&self) -> serde_json::Value {
        serde_json::json!({
            "bumps": self.bumps,
            "sigma": self.sigma,
            "min_separation": self.min_separation,
            "max_attempts": self.max_attempts,
            "distance": self.distance,
            "heat_time_factor": self.heat_time_factor,
        })
    }

    /// Parses [`GmmConfig::manifest_params`] output (missing fields take
    /// their defaults).
    ///
    /// # Errors
    /// [`DataError::Config`] for unknown fields or wrong types.
    pub fn from_manifest_params(params: &serde_json::Value) -> Result<Self> {
        serde_json::from_value(params.clone())
            .map_err(|e| DataError::Config(format!("gmm generator parameters: {e}")))
    }
}

/// Options of [`GmmGenerator::generate_with`].
#[derive(Clone, Copy, Default)]
pub struct GenerateOptions<'a> {
    /// Show an `indicatif` progress bar on stderr. Default `false`.
    pub progress_bar: bool,
    /// Called with `(samples done, total)` after each sample, from worker
    /// threads, in no particular order. Default `None`.
    pub on_progress: Option<&'a (dyn Fn(usize, usize) + Sync)>,
}

impl std::fmt::Debug for GenerateOptions<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("GenerateOptions")
            .field("progress_bar", &self.progress_bar)
            .field("on_progress", &self.on_progress.map(|_| "callback"))
            .finish()
    }
}

/// A GMM generator bound to one mesh: the distance operators, the center
/// distribution and the distance-field cache. `Send + Sync`.
pub struct GmmGenerator {
    config: GmmConfig,
    positions: Vec<[f64; 3]>,
    geodesics: Option<HeatGeodesics>,
    /// Running sums of the vertex masses (last entry: total area).
    cumulative_mass: Vec<f64>,
    sigma: f64,
    separation: f64,
    cache: Vec<OnceLock<Field>>,
    cache_slots: usize,
    cached: AtomicUsize,
}

impl std::fmt::Debug for GmmGenerator {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("GmmGenerator")
            .field("config", &self.config)
            .field("num_vertices", &self.positions.len())
            .field("sigma", &self.sigma)
            .field("separation", &self.separation)
            .field("cached_fields", &self.cached.load(Ordering::Relaxed))
            .finish()
    }
}

impl GmmGenerator {
    /// Validates `config`, builds the lumped mass and (for geodesic
    /// distance) factors the heat-method operators of `mesh`.
    ///
    /// # Errors
    /// [`GmmConfig::validate`]'s errors; [`DataError::Geodesic`] from
    /// [`HeatGeodesics::with_time_factor`];
    /// [`DataError::Config`] if the mesh has no area, or fewer vertices
    /// than `config.bumps` (each bump is centred at its own vertex).
    pub fn new(mesh: &TriMesh, config: &GmmConfig) -> Result<Self> {
        config.validate()?;
        if config.bumps > mesh.num_vertices() {
            return Err(DataError::Config(format!(
                "gmm.bumps must be at most the mesh's {} vertices (each bump is centred at its own \
                 vertex), found {}",
                mesh.num_vertices(),
                config.bumps
            )));
        }
        let mass = lumped_mass(mesh);
        let mut total = 0.0;
        let cumulative_mass: Vec<f64> = mass
            .iter()
            .map(|m| {
                total += m;
                total
            })
            .collect();
        if !(total.is_finite() && total > 0.0) {
            return Err(DataError::Config(format!(
                "the mesh must have a finite, positive area to place bumps, found {total}"
            )));
        }
        let geodesics = match config.distance {
            GmmDistance::Geodesic => Some(HeatGeodesics::with_time_factor(
                mesh,
                config.heat_time_factor,
            )?),
            GmmDistance::Euclidean => None,
        };
        let sigma = config.sigma * total.sqrt();
        let n = mesh.num_vertices();
        let mut generator = Self {
            config: config.clone(),
            positions: mesh.positions().to_vec(),
            geodesics,
            cumulative_mass,
            sigma,
            separation: config.min_separation * sigma,
            cache: (0..n).map(|_| OnceLock::new()).collect(),
            cache_slots: 0,
            cached: AtomicUsize::new(0),
        };
        generator.set_cache_limit(DEFAULT_CACHE_BYTES);
        Ok(generator)
    }

    /// Sets the distance-field cache budget in bytes (each field takes
    /// `4 V` bytes; 0 disables caching). Results do not depend on it.
    #[must_use]
    pub fn with_cache_limit(mut self, bytes: usize) -> Self {
        self.set_cache_limit(bytes);
        self
    }

    fn set_cache_limit(&mut self, bytes: usize) {
        let field = 4 * self.positions.len().max(1);
        self.cache_slots = bytes / field;
    }

    /// The configuration.
    pub fn config(&self) -> &GmmConfig {
        &self.config
    }

    /// Number of vertices of the mesh.
    pub fn num_vertices(&self) -> usize {
        self.positions.len()
    }

    /// The absolute bump width `sigma * sqrt(area)`.
    pub fn sigma(&self) -> f64 {
        self.sigma
    }

    /// The absolute minimum center separation `min_separation * sigma_abs`.
    pub fn separation(&self) -> f64 {
        self.separation
    }

    /// Distance from vertex `center` to every vertex (`f32`, cached).
    ///
    /// # Errors
    /// [`DataError::SizeMismatch`] for a bad vertex, [`DataError::Solver`].
    pub fn distance_field(&self, center: usize) -> Result<Arc<[f32]>> {
        let slot = self
            .cache
            .get(center)
            .ok_or_else(|| DataError::SizeMismatch {
                what: "bump center vertex index".into(),
                expected: self.positions.len(),
                found: center,
            })?;
        if let Some(field) = slot.get() {
            return Ok(Arc::clone(field));
        }
        let field: Field = match &self.geodesics {
            Some(geo) => geo.distance(center)?.iter().map(|&d| d as f32).collect(),
            None => {
                let c = self.positions[center];
                self.positions
                    .iter()
                    .map(|p| {
                        let d = [p[0] - c[0], p[1] - c[1], p[2] - c[2]];
                        (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt() as f32
                    })
                    .collect()
            }
        };
        self.store(slot, Arc::clone(&field));
        Ok(field)
    }

    /// Caches `field` in `slot` if the budget allows and the slot is empty
    /// (another thread may have stored the same, bit-identical field).
    fn store(&self, slot: &OnceLock<Field>, field: Field) {
        let stored = self.cached.fetch_add(1, Ordering::Relaxed) < self.cache_slots
            && slot.set(field).is_ok();
        if !stored {
            self.cached.fetch_sub(1, Ordering::Relaxed);
        }
    }

    /// Computes the distance fields of `vertices` as blocks of right-hand
    /// sides (about 4x cheaper per field than one at a time; blocks run in
    /// parallel) and caches them, within the cache budget. The fields are
    /// bit-identical to those computed on demand, so results do not change.
    ///
    /// # Errors
    /// [`DataError::SizeMismatch`] for a bad vertex, [`DataError::Solver`].
    pub fn precompute(&self, vertices: &[usize]) -> Result<()> {
        if let Some(&bad) = vertices.iter().find(|&&v| v >= self.positions.len()) {
            return Err(DataError::SizeMismatch {
                what: "bump center vertex index".into(),
                expected: self.positions.len(),
                found: bad,
            });
        }
        let Some(geo) = &self.geodesics else {
            return Ok(()); // Euclidean fields are cheap: computed on demand
        };
        let room = self
            .cache_slots
            .saturating_sub(self.cached.load(Ordering::Relaxed));
        let todo: Vec<usize> = vertices
            .iter()
            .copied()
            .filter(|&v| self.cache.get(v).is_some_and(|slot| slot.get().is_none()))
            .take(room)
            .collect();
        todo.par_chunks(PRECOMPUTE_BLOCK)
            .try_for_each(|block| -> Result<()> {
                for (&v, field) in block.iter().zip(geo.distances(block)?) {
                    let field: Field = field.iter().map(|&d| d as f32).collect();
                    self.store(&self.cache[v], field);
                }
                Ok(())
            })
    }

    /// A vertex drawn with probability proportional to its mass.
    fn draw_vertex(&self, rng: &mut ChaCha8Rng) -> usize {
        let total = self.cumulative_mass.last().copied().unwrap_or(0.0);
        let u = rng.random::<f64>() * total;
        self.cumulative_mass
            .partition_point(|&c| c <= u)
            .min(self.cumulative_mass.len() - 1)
    }

    /// The centers of sample `index` of `seed` and their distance fields
    /// (the last center's field only if `last_field`: placing centers does
    /// not need it).
    fn centers_and_fields(
        &self,
        seed: u64,
        index: u64,
        last_field: bool,
    ) -> Result<(Vec<usize>, Vec<Field>)> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        rng.set_stream(index);
        let k = self.config.bumps;
        let mut centers = Vec::with_capacity(k);
        let mut fields: Vec<Field> = Vec::with_capacity(k);
        for bump in 0..k {
            let mut placed = false;
            for _ in 0..self.config.max_attempts {
                let v = self.draw_vertex(&mut rng);
                if fields.iter().all(|f| f64::from(f[v]) >= self.separation) {
                    centers.push(v);
                    if last_field || bump + 1 < k {
                        fields.push(self.distance_field(v)?);
                    }
                    placed = true;
                    break;
                }
            }
            if !placed {
                return Err(DataError::Config(format!(
                    "could not place bump {} of {k} at least {} (min_separation {} x sigma {}) \
                     from the others in {} draws; lower gmm.min_separation or gmm.sigma",
                    bump + 1,
                    fmt_f64(self.separation),
                    fmt_f64(self.config.min_separation),
                    fmt_f64(self.sigma),
                    self.config.max_attempts
                )));
            }
        }
        Ok((centers, fields))
    }

    /// One bump of the generator's family centred at vertex `center`:
    /// `exp(-d(x, c)^2 / (2 sigma^2))` at every vertex (the distance field
    /// is cached like the generator's own).
    ///
    /// # Errors
    /// As [`GmmGenerator::distance_field`].
    pub fn bump(&self, center: usize) -> Result<Vec<f64>> {
        let field = self.distance_field(center)?;
        let inv = 1.0 / (2.0 * self.sigma * self.sigma);
        Ok(field
            .iter()
            .map(|&d| {
                let d = f64::from(d);
                (-d * d * inv).exp()
            })
            .collect())
    }

    /// The bump centers (vertex indices) of sample `index` of `seed`, in the
    /// order they were placed.
    ///
    /// # Errors
    /// [`DataError::Config`] if a center cannot be placed in
    /// [`GmmConfig::max_attempts`] draws; solver errors.
    pub fn centers(&self, seed: u64, index: u64) -> Result<Vec<usize>> {
        self.centers_and_fields(seed, index, false).map(|(c, _)| c)
    }

    /// Sample `index` of `seed`: the centers and the `V` values.
    ///
    /// # Errors
    /// As [`GmmGenerator::centers`].
    pub fn sample(&self, seed: u64, index: u64) -> Result<(Vec<usize>, Vec<f32>)> {
        let (centers, fields) = self.centers_and_fields(seed, index, true)?;
        let mut out = vec![0.0f32; self.num_vertices()];
        self.fill(&fields, &mut out);
        Ok((centers, out))
    }

    /// `out = sum_k exp(-d_k^2 / (2 sigma^2))`.
    fn fill(&self, fields: &[Field], out: &mut [f32]) {
        let inv = 1.0 / (2.0 * self.sigma * self.sigma);
        for (v, o) in out.iter_mut().enumerate() {
            let s: f64 = fields
                .iter()
                .map(|f| {
                    let d = f64::from(f[v]);
                    (-d * d * inv).exp()
                })
                .sum();
            *o = s as f32;
        }
    }

    /// Samples `0..n` of `seed` as an `[n, V, 1]` signal set (parallel).
    ///
    /// # Errors
    /// As [`GmmGenerator::centers`].
    pub fn generate(&self, n: usize, seed: u64) -> Result<InMemorySignals> {
        self.generate_with(n, seed, &GenerateOptions::default())
    }

    /// [`GmmGenerator::generate`] with progress reporting.
    ///
    /// # Errors
    /// As [`GmmGenerator::centers`].
    pub fn generate_with(
        &self,
        n: usize,
        seed: u64,
        options: &GenerateOptions<'_>,
    ) -> Result<InMemorySignals> {
        let v = self.num_vertices();
        let total = n
            .checked_mul(v)
            .ok_or_else(|| DataError::Config(format!("{n} samples of {v} vertices overflow")))?;
        let mut data = vec![0.0f32; total];
        let bar = options.progress_bar.then(|| {
            let bar = indicatif::ProgressBar::new(n as u64);
            if let Ok(style) = indicatif::ProgressStyle::with_template(
                "gmm {bar:40} {pos}/{len} samples [{elapsed_precise} < {eta}]",
            ) {
                bar.set_style(style);
            }
            bar
        });
        // when most vertices will be centers anyway and all fields fit in the
        // cache, computing them in blocks up front is cheaper
        if v > 0 && n.saturating_mul(self.config.bumps) >= v / 2 && self.cache_slots >= v {
            let all: Vec<usize> = (0..v).collect();
            self.precompute(&all)?;
        }
        let done = AtomicUsize::new(0);
        if v > 0 {
            data.par_chunks_mut(v)
                .enumerate()
                .try_for_each(|(i, out)| -> Result<()> {
                    let (_, fields) = self.centers_and_fields(seed, i as u64, true)?;
                    self.fill(&fields, out);
                    let finished = done.fetch_add(1, Ordering::Relaxed) + 1;
                    if let Some(bar) = &bar {
                        bar.inc(1);
                    }
                    if let Some(callback) = options.on_progress {
                        callback(finished, n);
                    }
                    Ok(())
                })?;
        }
        if let Some(bar) = bar {
            bar.finish_and_clear();
        }
        InMemorySignals::new(data, n, v, 1)
    }
}

/// Generates `n` GMM samples on `mesh` with `seed` (see the
/// [module docs](self)): an `[n, V, 1]` signal set.
///
/// # Errors
/// As [`GmmGenerator::new`] and [`GmmGenerator::generate`].
pub fn generate(
    mesh: &TriMesh,
    config: &GmmConfig,
    n: usize,
    seed: u64,
) -> Result<InMemorySignals> {
    GmmGenerator::new(mesh, config)?.generate(n, seed)
}
