//! # mfm-eval
//!
//! What is measured and shown of a set of generated signals against its
//! data, without libtorch (DESIGN.md section 7):
//!
//! - [`metrics`]: the distribution metrics (MMD, COV, 1-NNA, test error)
//!   under the mass-weighted distance of the mesh;
//! - [`quality`]: measures that a flat, noisy or collapsed sample set
//!   cannot pass, which the metrics can: the fit of the GMM data's own
//!   family (bumps of the dataset's width), the residual against the data's
//!   floor, diversity, and the spread of deformation parameters;
//! - [`plausibility`]: the distance of generated shapes to the deformation
//!   space of their data;
//! - [`shape_quality`]: generated shapes against real ones on one mesh,
//!   without a generator: plausibility, coverage, novelty and roughness
//!   over the data's own floor, flipped faces;
//! - [`evaluation`]: the protocol of `mfm eval` on a reference dataset, its
//!   serializable report and the files it reads and writes;
//! - [`arbitrary`]: the report of `mfm eval-arbitrary` per held-out set;
//! - [`pictures`]: the evaluation's pictures (data above samples, shapes
//!   beside their projections, point-wise means).
//!
//! Datasets, generators and their errors are [`mfm_data`]'s; this crate
//! reports [`mfm_data::DataError`].
//!
//! ## Example
//! ```
//! use mfm_data::InMemorySignals;
//! use mfm_eval::metrics;
//!
//! // two signals on a 3-vertex mesh with unit masses
//! let reference = InMemorySignals::new(vec![0.0, 0.0, 0.0, 1.0, 1.0, 1.0], 2, 3, 1).unwrap();
//! let flat = InMemorySignals::new(vec![0.5; 6], 2, 3, 1).unwrap();
//! let m = metrics::evaluate(&[1.0; 3], &reference, &reference).unwrap();
//! assert_eq!((m.mmd, m.cov), (0.0, 1.0)); // a set against itself
//! let m = metrics::evaluate(&[1.0; 3], &flat, &reference).unwrap();
//! assert!(m.mmd > 0.0 && m.cov == 0.5); // both flat samples match one reference
//! ```

pub mod arbitrary;
pub mod evaluation;
pub mod metrics;
pub mod pictures;
pub mod plausibility;
pub mod quality;
pub mod shape_quality;
