//! What `mfm eval-arbitrary` reports per held-out set (`report.json`, a
//! list of [`SetEvaluation`]): the arbitrary-source model's targets
//! against each source's own deformation space and the set's poses.
//! `mfm_arbitrary::evaluate` measures it (with libtorch); the report is
//! defined here so that its readers need none.

use serde::{Deserialize, Serialize};

use crate::quality::{ParamSpread, Quartiles};

/// The measures of one held-out set of the arbitrary-source model (see
/// `mfm_arbitrary::evaluate` for how each is measured).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SetEvaluation {
    /// The set's folder name.
    pub set: String,
    /// Vertices of its mesh.
    pub vertices: usize,
    /// Sources evaluated (one per held-out shape, at most the requested
    /// number).
    pub sources: usize,
    /// Targets generated per source.
    pub samples_per_source: usize,
    /// Projection error of the generated targets.
    pub projection: Quartiles,
    /// Projection error of the set's own meshes (the floor).
    pub projection_floor: Quartiles,
    /// Median target-to-source distance over the data's.
    pub displacement_ratio: f64,
    /// Pose spread of the generated targets' projections.
    pub pose_spread: ParamSpread,
    /// Pose spread of the set's own meshes' projections.
    pub reference_pose_spread: ParamSpread,
    /// Minimum matching distance to the other poses of the evaluated
    /// shapes.
    pub mmd: f64,
    /// Coverage of those poses.
    pub cov: f64,
    /// The predictor's mean relative error per source (vectors `1..k`);
    /// `None` when not measured (an imported predictor).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub predictor_error: Option<Quartiles>,
    /// The same over the first eight non-constant vectors (`1..=8`), the
    /// coarse layout of the body; `None` when not measured.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub predictor_error_low: Option<Quartiles>,
    /// Seconds per generated target.
    pub seconds_per_sample: f64,
}

impl SetEvaluation {
    /// The measures on one line, spreads as ratios to the data's (what
    /// `mfm eval-arbitrary` prints).
    pub fn summary(&self) -> String {
        let ratio = |a: f64, b: f64| a / b.max(f64::MIN_POSITIVE);
        let predictor = match (&self.predictor_error, &self.predictor_error_low) {
            (Some(all), Some(low)) => format!(
                "predictor error {:.3} (vectors 1-8: {:.3})",
                all.median, low.median
            ),
            _ => "predictor error not measured (imported predictor)".to_owned(),
        };
        format!(
            "{:>9} ({} vertices, {} sources x {}): projection {:.2e} [{:.2e}, {:.2e}] (floor {:.2e}), \
             displacement ratio {:.2}, pose spread {:.2}/{:.2} of the data's, MMD {:.4}, COV {:.2}, \
             {predictor}",
            self.set,
            self.vertices,
            self.sources,
            self.samples_per_source,
            self.projection.median,
            self.projection.q1,
            self.projection.q3,
            self.projection_floor.median,
            self.displacement_ratio,
            ratio(
                self.pose_spread.rotation,
                self.reference_pose_spread.rotation
            ),
            ratio(
                self.pose_spread.translation,
                self.reference_pose_spread.translation
            ),
            self.mmd,
            self.cov,
        )
    }
}
