//! The plausibility metric separates the shapes of a deformation dataset
//! (which lie in its space) from smoothly perturbed ones.
#![allow(clippy::unwrap_used)]

use mfm_data::dataset::Dataset;
use mfm_data::deformations::{self, DeformMeshes};
use mfm_data::{InMemorySignals, SignalSource};
use mfm_eval::plausibility::plausibility;
use mfm_geometry::procedural;

#[test]
fn dataset_shapes_project_onto_their_space() {
    let capsule = procedural::capsule(0.5, 0.75, 16, 48).unwrap();
    let m = DeformMeshes::from_mesh(&capsule, 600).unwrap();
    let space = deformations::space_for(&m.original, 2, 0.15, 0.4, 0.08).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let data = deformations::write_dataset(
        &dir.path().join("d"),
        &m.coarse,
        &space,
        7,
        3..7,
        m.normalization,
        m.frame,
        "coarse",
        "test",
        false,
    )
    .unwrap();
    let opened = Dataset::open(data.dir()).unwrap();

    // dataset shapes lie in the space; a smooth perturbation does not
    let shapes = opened.load_all().unwrap();
    let p = plausibility(&space, &m.coarse, &shapes, 1).unwrap();
    assert_eq!((p.mse.len(), p.projections.len()), (4, 1));
    let mut bent = shapes.data().to_vec();
    for (k, x) in bent.iter_mut().enumerate() {
        let v = (k / 3) as f32;
        *x += 0.01 * (0.37 * v).sin();
    }
    let bent = InMemorySignals::new(bent, 4, shapes.num_vertices(), 3).unwrap();
    let q = plausibility(&space, &m.coarse, &bent, 0).unwrap();
    assert!(p.mean < 1e-8, "dataset shapes project with {:e}", p.mean);
    assert!(
        q.mean > 100.0 * p.mean.max(1e-10),
        "{:e} vs {:e}",
        q.mean,
        p.mean
    );
    // wrong channel count is an error
    let scalar = InMemorySignals::new(
        vec![0.0; m.coarse.num_vertices()],
        1,
        m.coarse.num_vertices(),
        1,
    )
    .unwrap();
    assert!(plausibility(&space, &m.coarse, &scalar, 0).is_err());
}
