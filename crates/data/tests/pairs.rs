//! Pairs datasets for the arbitrary-source model: the stored parameters
//! reproduce the stored shapes, pairs share a body shape, generation does
//! not depend on the thread count, and the same parameters give
//! corresponding shapes on another triangulation.
#![allow(clippy::unwrap_used)]

use mfm_data::SignalSource;
use mfm_data::dataset::Dataset;
use mfm_data::deformations::{self, DeformMeshes};
use mfm_data::pairs::{self, PairSpace, PairsManifest};
use mfm_deform::ShapeFamily;
use mfm_geometry::procedural;

fn setup() -> (DeformMeshes, PairSpace) {
    let capsule = procedural::capsule(0.5, 0.75, 16, 48).unwrap();
    let m = DeformMeshes::from_mesh(&capsule, 600).unwrap();
    let poses = deformations::space_for(&m.original, 2, 0.15, 0.4, 0.08).unwrap();
    let family = ShapeFamily::auto(&m.original, 3).unwrap();
    (
        m,
        PairSpace {
            family,
            poses,
            poses_per_shape: 3,
        },
    )
}

fn max_distance(a: &[[f64; 3]], b: &[[f64; 3]]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(p, q)| mfm_geometry::mesh::norm(mfm_geometry::mesh::sub(*p, *q)))
        .fold(0.0, f64::max)
}

#[test]
fn stored_parameters_reproduce_the_stored_shapes() {
    let (m, space) = setup();
    let dir = tempfile::tempdir().unwrap();
    let data = pairs::write_dataset(
        &dir.path().join("p"),
        &m.coarse,
        &space,
        11,
        2..5,
        m.normalization,
        m.frame,
        "coarse",
        "test",
        false,
    )
    .unwrap();
    let opened = Dataset::open(data.dir()).unwrap();
    let manifest = PairsManifest::of(&opened).unwrap().unwrap();
    assert_eq!(manifest.space, space);
    assert_eq!((manifest.first_shape, opened.len()), (2, 9));
    assert_eq!(opened.manifest().frame, Some(m.frame));
    let params = pairs::read_params(&opened).unwrap();
    assert_eq!((params.shapes.len(), params.poses.len()), (3, 9));
    assert_eq!(params.shapes[0], space.family.sample_params(11, 2));
    let stored = opened.load_all().unwrap();
    for s in 0..3 {
        let poses = &params.poses[3 * s..3 * s + 3];
        let again = space.realize(&m.coarse, &params.shapes[s], poses).unwrap();
        for (a, shape) in again.iter().enumerate() {
            let err = max_distance(shape, &stored.positions(3 * s + a));
            assert!(err < 1e-6, "shape {s} pose {a}: {err}");
        }
    }
    // every ordered pair of two poses of one shape
    let list = space.pairs(opened.len());
    assert_eq!(list.len(), 3 * 3 * 2);
    assert!(list.iter().all(|&(i, j)| i != j && i / 3 == j / 3));
    // poses of one shape differ, and so do the shapes' rest members
    let (a, b) = (stored.positions(0), stored.positions(1));
    assert!(max_distance(&a, &b) > 1e-3);
    let r0 = space.family.realize(&m.coarse, &params.shapes[0]).unwrap();
    let r1 = space.family.realize(&m.coarse, &params.shapes[1]).unwrap();
    assert!(max_distance(r0.positions(), r1.positions()) > 1e-3);
    // another generator's dataset is not a pairs dataset
    let other = deformations::write_dataset(
        &dir.path().join("d"),
        &m.coarse,
        &space.poses,
        1,
        0..1,
        m.normalization,
        m.frame,
        "coarse",
        "test",
        false,
    )
    .unwrap();
    assert!(PairsManifest::of(&other).unwrap().is_none());
    assert!(
        pairs::write_dataset(
            &dir.path().join("e"),
            &m.coarse,
            &space,
            1,
            0..0,
            m.normalization,
            m.frame,
            "coarse",
            "test",
            false
        )
        .is_err()
    );
}

#[test]
fn generation_is_the_same_for_any_thread_count_and_needs_two_poses() {
    let (m, space) = setup();
    let run = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| space.generate(&m.coarse, 5, 0..3, |_| {}).unwrap())
    };
    assert_eq!(run(1), run(3));
    let mut one = space.clone();
    one.poses_per_shape = 1;
    assert!(one.generate(&m.coarse, 5, 0..1, |_| {}).is_err());
}

#[test]
fn the_same_parameters_give_corresponding_shapes_on_a_remeshing() {
    let (m, space) = setup();
    let (shape, poses) = space.params(3, 0);
    let coarse = space.realize(&m.coarse, &shape, &poses[..1]).unwrap();
    let fine = space.realize(&m.eval, &shape, &poses[..1]).unwrap();
    // the evaluation mesh keeps the coarse vertices first
    let n = m.coarse.num_vertices();
    assert_eq!(&m.eval.positions()[..n], m.coarse.positions());
    let moved: f64 = coarse[0]
        .iter()
        .zip(m.coarse.positions())
        .map(|(p, q)| mfm_geometry::mesh::norm(mfm_geometry::mesh::sub(*p, *q)))
        .sum::<f64>()
        / n as f64;
    let apart: f64 = coarse[0]
        .iter()
        .zip(&fine[0][..n])
        .map(|(p, q)| mfm_geometry::mesh::norm(mfm_geometry::mesh::sub(*p, *q)))
        .sum::<f64>()
        / n as f64;
    assert!(moved > 1e-3, "the shape moved by {moved}");
    assert!(
        apart < 0.2 * moved,
        "triangulations differ by {apart}, shapes moved {moved}"
    );
}

#[test]
fn an_experiment_writes_its_space_and_both_held_out_sets() {
    use mfm_data::layout::{self, PairsExperiment};
    let (m, space) = setup();
    let dir = tempfile::tempdir().unwrap();
    let train = PairsExperiment {
        meshes: &m,
        space: &space,
        source: "capsule",
        train: 2,
        reference: 1,
        seed: 4,
        progress: false,
    }
    .write(dir.path())
    .unwrap();
    assert_eq!(train.len(), 6);
    let read = layout::read_pair_space(&dir.path().join(layout::PAIR_SPACE)).unwrap();
    assert_eq!(read, space);
    // the held-out shapes are the same parameters on both triangulations
    let hold = Dataset::open(dir.path().join(layout::HOLDOUT)).unwrap();
    let refs = Dataset::open(dir.path().join(layout::REFERENCE)).unwrap();
    assert_eq!(
        pairs::read_params(&hold).unwrap(),
        pairs::read_params(&refs).unwrap()
    );
    assert_eq!(refs.mesh().num_vertices(), m.eval.num_vertices());
    assert_ne!(
        pairs::read_params(&hold).unwrap().shapes[0],
        pairs::read_params(&train).unwrap().shapes[0]
    );
    // a deformation space is not a pair space
    let other = dir.path().join("space.json");
    layout::write_space(&other, &space.poses).unwrap();
    let e = layout::read_pair_space(&other).unwrap_err();
    assert!(e.to_string().contains("not a pair space"), "{e}");
}
