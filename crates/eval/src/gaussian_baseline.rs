//! The Gaussian baseline of shape quality: shapes drawn from the Gaussian
//! with the training shapes' mean and covariance, the simplest model of a
//! shape collection that has learned more than its mean.
//!
//! With the (centred) training shapes `t_1 .. t_n` (`n >= 2`), their mean
//! `mu` and a seeded standard normal vector `e` per draw, a draw is
//!
//! ```text
//! g = mu + sum_i e_i (t_i - mu) / sqrt(n - 1)
//! ```
//!
//! whose distribution has mean `mu` and the training shapes' sample
//! covariance (every draw lies in their affine span). A generative model
//! that is worth its training should produce samples nearer the real
//! shapes than these: [`crate::shape_quality`] reports their plausibility,
//! coverage and spread (measured exactly as the samples') beside the
//! samples'. On a motion cycle the draws cut across the cycle the way
//! blends of poses do, so they read a spread below 1 and a plausibility
//! above the floor; samples worse than them have not learned even the
//! data's covariance.
//!
//! # Example
//! ```
//! use mfm_data::{InMemorySignals, SignalSource};
//! use mfm_eval::gaussian_baseline::gaussian_shapes;
//!
//! // two "shapes" of one vertex: draws lie on the line through them
//! let train = InMemorySignals::new(vec![0.0, 0.0, 0.0, 2.0, 0.0, 0.0], 2, 1, 3).unwrap();
//! let g = gaussian_shapes(&train, 5, 7).unwrap();
//! assert_eq!(g.len(), 5);
//! assert!((0..5).all(|k| g.signal(k)[1] == 0.0 && g.signal(k)[2] == 0.0));
//! ```

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use mfm_data::principal::mean_signal;
use mfm_data::{DataError, InMemorySignals, Result, SignalSource};

/// The Gaussian baseline's measures, each defined as the samples' are
/// ([`crate::shape_quality`] module docs), for as many draws as samples.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct GaussianBaseline {
    /// Median distance of a draw to the nearest real shape, over the floor.
    pub plausibility: f64,
    /// Median distance of a held-out shape to the nearest draw, over the
    /// same for the coverage baseline's random training shapes.
    pub coverage: f64,
    /// Median distance of a draw to the training shapes' mean over the
    /// same for the real shapes.
    pub spread: f64,
    /// Number of draws.
    pub draws: usize,
}

/// `count` draws of the Gaussian with the mean and sample covariance of
/// the shapes `train` (`[n, V, C]`, `n >= 2`; see the module docs), as
/// `f32` signals of `train`'s size, from stream 1 of
/// `ChaCha8Rng::seed_from_u64(seed)` (stream 0 draws the coverage
/// baseline's training shapes; the `n` normals of draw `k` are the `k`-th
/// `n` of the stream). The same seed gives the same draws at any thread
/// count.
///
/// # Errors
/// [`DataError::Config`] for fewer than 2 training shapes (no covariance)
/// or no draws.
pub fn gaussian_shapes(
    train: &InMemorySignals,
    count: usize,
    seed: u64,
) -> Result<InMemorySignals> {
    let n = train.len();
    if n < 2 || count == 0 {
        return Err(DataError::Config(format!(
            "a Gaussian fit needs at least 2 training shapes and draws at least 1, found {n} \
             and {count}"
        )));
    }
    let mean = mean_signal(train);
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    rng.set_stream(1);
    let scale = 1.0 / ((n - 1) as f64).sqrt();
    let weights: Vec<Vec<f64>> = (0..count)
        .map(|_| {
            (0..n)
                .map(|_| rng.sample::<f64, _>(StandardNormal) * scale)
                .collect()
        })
        .collect();
    let draws: Vec<Vec<f32>> = weights
        .par_iter()
        .map(|e| {
            let mut g = mean.clone();
            for (i, &w) in e.iter().enumerate() {
                for ((gv, &x), &m) in g.iter_mut().zip(train.signal(i)).zip(&mean) {
                    *gv += w * (f64::from(x) - m);
                }
            }
            g.into_iter().map(|v| v as f32).collect()
        })
        .collect();
    InMemorySignals::new(
        draws.concat(),
        count,
        train.num_vertices(),
        train.channels(),
    )
}
