//! The evaluation protocol of `mfm eval` on an experiment's layout: the
//! reference set against itself is perfect, flat samples are not, and the
//! report keeps its JSON field names.
#![allow(clippy::unwrap_used)]

use mfm_data::dataset::Dataset;
use mfm_data::experiment::{GmmMeshes, HalfDensity};
use mfm_data::gmm::{GmmConfig, GmmDistance};
use mfm_data::{DataError, InMemorySignals, SignalSource};
use mfm_eval::evaluation::{self, EvalReport};
use mfm_geometry::procedural;

/// The layout written by `GmmExperiment`, evaluated by
/// `evaluation::evaluate`: the reference set against itself is perfect,
/// flat samples are not, and the report's JSON keeps its field names and
/// reads back.
#[test]
fn gmm_experiment_evaluation() {
    use mfm_data::gmm::GenerateOptions;
    use mfm_data::layout::{self, GmmExperiment};
    let meshes = GmmMeshes::from_base(procedural::icosphere(2), HalfDensity::default()).unwrap();
    let config = GmmConfig {
        distance: GmmDistance::Euclidean,
        ..GmmConfig::default()
    };
    let dir = tempfile::tempdir().unwrap();
    let experiment = GmmExperiment {
        config: &config,
        train_mesh: &meshes.train,
        test_mesh: &meshes.test,
        source: "icosphere(2)",
        train: 6,
        reference: 12,
        seed: 3,
    };
    experiment
        .write(dir.path(), &GenerateOptions::default())
        .unwrap();
    let reference = Dataset::open(dir.path().join(layout::REFERENCE)).unwrap();

    let itself = reference.load_all().unwrap();
    let e = evaluation::evaluate(&reference, &itself).unwrap();
    assert_eq!(e.report.metrics.mmd, 0.0);
    assert_eq!(e.report.metrics.num_generated, 12);
    let q = e
        .report
        .quality
        .as_ref()
        .expect("a GMM set gets the bump fit");
    assert!(q.generated.residual.median < 0.05, "{}", q.summary());
    assert!(e.report.shapes.is_none() && e.projections.is_none());
    let flat = InMemorySignals::new(
        vec![0.0; 12 * itself.num_vertices()],
        12,
        itself.num_vertices(),
        1,
    )
    .unwrap();
    let f = evaluation::evaluate(&reference, &flat).unwrap();
    assert!(f.report.metrics.mmd > 0.0);
    assert!(f.report.quality.as_ref().unwrap().generated.residual.median > 0.5);
    // the metrics' fields sit at the top level, as `mfm eval --out` wrote them
    let json = serde_json::to_value(&f.report).unwrap();
    for key in ["mmd", "cov", "one_nna", "test_error", "quality"] {
        assert!(json.get(key).is_some(), "{key} in {json}");
    }
    assert!(json.get("projection_mse").is_none());
    let back: EvalReport = serde_json::from_value(json).unwrap();
    assert_eq!(back, f.report);
    // samples on another mesh are refused by size
    let wrong = InMemorySignals::new(vec![0.0; 4], 1, 4, 1).unwrap();
    assert!(matches!(
        evaluation::evaluate(&reference, &wrong),
        Err(DataError::SizeMismatch { .. })
    ));
}
