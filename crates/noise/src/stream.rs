//! Many samples without holding them all: samples `0..N` of a seed are
//! drawn in chunks ([`CHUNK`] samples unless asked otherwise) and handed,
//! in order, to a
//! consumer (a [`SpectralAnalyzer`](crate::SpectralAnalyzer), a statistic,
//! or with the `cli-output` feature an `.npy` file: `write_npy`). Memory stays at one chunk, `chunk x V x C` values, whatever
//! `N` is, and the values are the same bits as one [`NoiseSampler::sample`]
//! call (samples are indexed, not drawn in sequence). Statistics summed per
//! chunk depend on the chunk size in their last bits.
//!
//! # Example
//! ```
//! use mfm_geometry::procedural;
//! use mfm_noise::{NoiseKind, NoiseSampler, stream};
//! let sampler = NoiseSampler::new(&procedural::icosphere(2), NoiseKind::White).unwrap();
//! let mut seen = 0;
//! stream::for_each_chunk(&sampler, 600, 1, 7, stream::CHUNK, |batch, first| {
//!     assert_eq!(first, seen);
//!     seen += batch.samples();
//!     Ok(())
//! })
//! .unwrap();
//! assert_eq!(seen, 600);
//! ```

#[cfg(feature = "cli-output")]
use std::path::Path;

#[cfg(feature = "cli-output")]
use crate::error::NoiseError;
use crate::error::Result;
use crate::sampler::{NoiseBatch, NoiseSampler};

/// Samples per chunk of the sampling streams (`write_npy`, the spectra of
/// `mfm spectrum`).
pub const CHUNK: usize = 256;

/// Calls `each(batch, first)` for `[count, V, channels]` batches that cover
/// samples `0..samples` of `seed` in order (`first` is the batch's first
/// sample index, `count <= chunk`); stops at the first error.
///
/// # Errors
/// The sampler's errors and those `each` returns.
pub fn for_each_chunk(
    sampler: &NoiseSampler,
    samples: usize,
    channels: usize,
    seed: u64,
    chunk: usize,
    mut each: impl FnMut(&NoiseBatch, usize) -> Result<()>,
) -> Result<()> {
    let chunk = chunk.max(1);
    let mut first = 0;
    while first < samples {
        let count = chunk.min(samples - first);
        let batch = sampler.sample_range(first, count, channels, seed)?;
        each(&batch, first)?;
        first += count;
    }
    Ok(())
}

#[cfg(feature = "cli-output")]
/// What [`write_npy`] measured on the way.
#[derive(Clone, Debug, PartialEq)]
pub struct WrittenNoise {
    /// Mean over samples and channels of the energy `f^T M f`.
    pub mean_energy: f64,
    /// Channel 0 of sample 0 (for a picture).
    pub first_signal: Vec<f64>,
}

#[cfg(feature = "cli-output")]
/// Writes samples `0..samples` of `seed` (`channels` each) to the `.npy`
/// file `path`, `[samples, V, channels]` row-major `f64`, atomically;
/// `progress(done)` is called after each chunk.
///
/// # Errors
/// [`NoiseError::InvalidParameter`] for no samples; the sampler's errors;
/// [`NoiseError::File`] naming the file.
pub fn write_npy(
    sampler: &NoiseSampler,
    path: &Path,
    samples: usize,
    channels: usize,
    seed: u64,
    mut progress: impl FnMut(usize),
) -> Result<WrittenNoise> {
    if samples == 0 {
        return Err(NoiseError::InvalidParameter {
            name: "samples",
            expected: ">= 1",
            found: "0".into(),
        });
    }
    let shape = [
        samples as u64,
        sampler.num_vertices() as u64,
        channels as u64,
    ];
    let mut file = mfm_files::npy::NpyStream::<f64>::create(path, &shape)?;
    let mass = sampler.mass();
    let mut energy = 0.0;
    let mut first_signal = Vec::new();
    for_each_chunk(sampler, samples, channels, seed, CHUNK, |batch, first| {
        for s in 0..batch.samples() {
            for c in 0..channels {
                let f = batch.signal(s, c);
                energy += f.iter().zip(mass).map(|(x, m)| m * x * x).sum::<f64>();
            }
        }
        if first == 0 {
            first_signal = batch.signal(0, 0);
        }
        file.append(batch.data())?;
        progress(first + batch.samples());
        Ok(())
    })?;
    file.finish()?;
    Ok(WrittenNoise {
        mean_energy: energy / (samples * channels) as f64,
        first_signal,
    })
}

#[cfg(feature = "cli-output")]
/// The JSON [`NoiseFiles::write`] writes beside the samples.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct NoiseSummary {
    /// The mesh as the user named it.
    pub mesh: String,
    /// The noise kind.
    pub kind: crate::NoiseKind,
    /// Samples written.
    pub samples: usize,
    /// Vertices of the mesh.
    pub vertices: usize,
    /// Channels per sample.
    pub channels: usize,
    /// The seed.
    pub seed: u64,
    /// `Gamma = ||M^-1 L||_F` of the mesh.
    pub gamma: f64,
    /// The screening weight used (`None` for kinds without one).
    pub tau: Option<f64>,
    /// The array layout of the `.npy`, in words.
    pub layout: &'static str,
    /// Mean energy `f^T M f` over samples and channels.
    pub mean_energy: f64,
}

#[cfg(feature = "cli-output")]
/// A noise file and its summary: what `mfm noise` writes.
#[derive(Clone, Copy, Debug)]
pub struct NoiseFiles<'a> {
    /// The mesh as the user named it (recorded in the summary).
    pub mesh: &'a str,
    /// The `.npy` file of the samples.
    pub npy: &'a Path,
    /// The JSON file of the [`NoiseSummary`].
    pub json: &'a Path,
    /// Samples `0..samples` of the seed.
    pub samples: usize,
    /// Channels per sample.
    pub channels: usize,
    /// The seed.
    pub seed: u64,
}

#[cfg(feature = "cli-output")]
impl NoiseFiles<'_> {
    /// [`write_npy`], then the [`NoiseSummary`] of the file as pretty JSON,
    /// atomically.
    ///
    /// # Errors
    /// Those of [`write_npy`]; [`NoiseError::File`] for the summary.
    pub fn write(
        &self,
        sampler: &NoiseSampler,
        progress: impl FnMut(usize),
    ) -> Result<(NoiseSummary, WrittenNoise)> {
        let (samples, channels, seed) = (self.samples, self.channels, self.seed);
        let written = write_npy(sampler, self.npy, samples, channels, seed, progress)?;
        let summary = NoiseSummary {
            mesh: self.mesh.to_owned(),
            kind: sampler.kind(),
            samples,
            vertices: sampler.num_vertices(),
            channels,
            seed,
            gamma: sampler.gamma(),
            tau: sampler.tau(),
            layout: "[samples, vertices, channels], row-major f64",
            mean_energy: written.mean_energy,
        };
        mfm_files::write_json(self.json, &summary)?;
        Ok((summary, written))
    }
}
