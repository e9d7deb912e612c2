//! The principal plane (`mfm_eval::principal_plane`) against what a plane
//! must do: shapes that differ only within a plane keep their distances in
//! it exactly, whatever the plane's rotation or signs; the projection never
//! lengthens a distance; the shares of the variance add up; the seeded
//! subset beyond 512 shapes finds the same plane.

#![allow(clippy::unwrap_used)]

use mfm_data::{DataError, InMemorySignals, SignalSource};
use mfm_eval::principal_plane::{PLANE_FIT_SHAPES, PlaneProjector};
use mfm_eval::shape_quality::CentredDistance;
use mfm_geometry::operators::lumped_mass;
use mfm_geometry::procedural;
use proptest::prelude::*;

/// Vertices of the icosahedron the shapes live on.
const V: usize = 12;

/// Shapes `base + a_i p + b_i q` (a two-dimensional affine family),
/// centred as `mfm eval` centres them, with the icosahedron's masses and
/// diagonal.
fn planar_family(
    base: &[f32],
    p: &[f32],
    q: &[f32],
    coefficients: &[(f32, f32)],
) -> (InMemorySignals, CentredDistance, Vec<f64>, f64) {
    let mesh = procedural::icosahedron();
    let mass = lumped_mass(&mesh);
    let diagonal = mesh.bounding_box_diagonal();
    let data: Vec<f32> = coefficients
        .iter()
        .flat_map(|&(a, b)| (0..3 * V).map(move |j| base[j] + a * p[j] + b * q[j]))
        .collect();
    let set = InMemorySignals::new(data, coefficients.len(), V, 3).unwrap();
    let d = CentredDistance::new(&mass, diagonal).unwrap();
    (d.centre(&set).unwrap(), d, mass, diagonal)
}

fn field() -> impl Strategy<Value = Vec<f32>> {
    prop::collection::vec(-1.0f32..1.0, 3 * V)
}

fn planar_distance(a: [f64; 2], b: [f64; 2]) -> f64 {
    (a[0] - b[0]).hypot(a[1] - b[1])
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    #[test]
    fn shapes_of_a_planar_family_keep_their_distances_in_the_plane(
        base in field(), p in field(), q in field(),
        coefficients in prop::collection::vec((-1.0f32..1.0, -1.0f32..1.0), 3..12),
    ) {
        let (set, d, mass, diagonal) = planar_family(&base, &p, &q, &coefficients);
        let plane = PlaneProjector::fit(&set, &mass, diagonal, 0).unwrap();
        let c: Vec<[f64; 2]> = (0..set.len()).map(|i| plane.coordinates(set.signal(i))).collect();
        let e = plane.explained();
        prop_assert!(e[0] >= e[1] && e[1] >= 0.0, "{:?}", e);
        // all the variance is in the plane, unless the family is flatter
        // still (coefficients on a line), and then the first holds it all
        prop_assert!((e[0] + e[1] - 1.0).abs() < 1e-6, "{:?}", e);
        for i in 0..set.len() {
            for j in 0..i {
                let full = d.distance(set.signal(i), set.signal(j)).unwrap();
                let flat = planar_distance(c[i], c[j]);
                // f32 shapes: a relative error of a few ulps of the shapes' size
                prop_assert!((full - flat).abs() <= 1e-5 * (1.0 + full), "{} {}", full, flat);
            }
        }
        // the signs: the first shape fitted on sits on the positive side
        prop_assert!(c[0][0] >= -1e-9 && c[0][1] >= -1e-9, "{:?}", c[0]);
    }

    #[test]
    fn the_projection_never_lengthens_a_distance(
        shapes in prop::collection::vec(field(), 2..9),
        others in prop::collection::vec(field(), 1..4),
    ) {
        let mesh = procedural::icosahedron();
        let mass = lumped_mass(&mesh);
        let diagonal = mesh.bounding_box_diagonal();
        let d = CentredDistance::new(&mass, diagonal).unwrap();
        let set = |s: &Vec<Vec<f32>>| {
            d.centre(&InMemorySignals::new(s.concat(), s.len(), V, 3).unwrap()).unwrap()
        };
        let (train, others) = (set(&shapes), set(&others));
        let plane = PlaneProjector::fit(&train, &mass, diagonal, 0).unwrap();
        let mut variance = [0.0; 2];
        let mut total = 0.0;
        for i in 0..train.len() {
            let c = plane.coordinates(train.signal(i));
            let r = plane.distance_to_mean(train.signal(i));
            prop_assert!(c[0].hypot(c[1]) <= r * (1.0 + 1e-9) + 1e-12);
            variance[0] += c[0] * c[0];
            variance[1] += c[1] * c[1];
            total += r * r;
        }
        // each direction's share of the variance is what `explained` says
        let e = plane.explained();
        for k in 0..2 {
            prop_assert!((variance[k] / total - e[k]).abs() < 1e-6, "{:?} {:?}", variance, e);
        }
        for i in 0..others.len() {
            for j in 0..train.len() {
                let full = d.distance(others.signal(i), train.signal(j)).unwrap();
                let (a, b) = (plane.coordinates(others.signal(i)), plane.coordinates(train.signal(j)));
                prop_assert!(planar_distance(a, b) <= full * (1.0 + 1e-6) + 1e-9);
            }
        }
    }
}

#[test]
fn beyond_the_fitting_limit_a_seeded_subset_finds_the_same_plane() {
    let base: Vec<f32> = (0..3 * V).map(|j| (j as f32 * 0.37).sin()).collect();
    let p: Vec<f32> = (0..3 * V).map(|j| (j as f32 * 1.3).cos()).collect();
    let q: Vec<f32> = (0..3 * V).map(|j| ((j * j) as f32 * 0.11).sin()).collect();
    let n = PLANE_FIT_SHAPES + 88;
    // a ring: the motion-cycle shape of a periodic sequence
    let coefficients: Vec<(f32, f32)> = (0..n)
        .map(|k| {
            let a = k as f32 * std::f32::consts::TAU / n as f32;
            (a.cos(), a.sin())
        })
        .collect();
    let (set, d, mass, diagonal) = planar_family(&base, &p, &q, &coefficients);
    let plane = PlaneProjector::fit(&set, &mass, diagonal, 5).unwrap();
    assert_eq!(plane.fitted_on(), PLANE_FIT_SHAPES);
    let again = PlaneProjector::fit(&set, &mass, diagonal, 5).unwrap();
    for i in (0..n).step_by(37) {
        let c = plane.coordinates(set.signal(i));
        assert_eq!(
            c,
            again.coordinates(set.signal(i)),
            "seeded: the same subset"
        );
        for j in (0..i).step_by(53) {
            let full = d.distance(set.signal(i), set.signal(j)).unwrap();
            let flat = planar_distance(c, plane.coordinates(set.signal(j)));
            assert!((full - flat).abs() <= 1e-5 * (1.0 + full), "{full} {flat}");
        }
    }
}

#[test]
fn one_shape_has_no_direction_and_sits_at_the_origin() {
    let base: Vec<f32> = (0..3 * V).map(|j| j as f32 * 0.1).collect();
    let (set, _, mass, diagonal) = planar_family(&base, &base, &base, &[(0.0, 0.0)]);
    let plane = PlaneProjector::fit(&set, &mass, diagonal, 0).unwrap();
    assert_eq!(plane.explained(), [0.0, 0.0]);
    assert_eq!(plane.coordinates(set.signal(0)), [0.0, 0.0]);
    let other: Vec<f32> = base.iter().map(|x| -x).collect();
    assert_eq!(plane.coordinates(&other), [0.0, 0.0]);
    assert_eq!(plane.distance_to_mean(set.signal(0)), 0.0);
}

#[test]
fn bad_inputs_are_refused_with_the_reason() {
    let mesh = procedural::icosahedron();
    let mass = lumped_mass(&mesh);
    let empty = InMemorySignals::new(Vec::new(), 0, V, 3).unwrap();
    let e = PlaneProjector::fit(&empty, &mass, 1.0, 0).unwrap_err();
    assert!(
        matches!(&e, DataError::Config(m) if m.contains("at least one")),
        "{e}"
    );
    let scalars = InMemorySignals::new(vec![0.0; 2 * V], 2, V, 1).unwrap();
    let e = PlaneProjector::fit(&scalars, &mass, 1.0, 0).unwrap_err();
    assert!(matches!(e, DataError::SizeMismatch { .. }), "{e}");
    let shapes = InMemorySignals::new(vec![0.5; 6 * V], 2, V, 3).unwrap();
    let e = PlaneProjector::fit(&shapes, &mass, f64::NAN, 0).unwrap_err();
    assert!(e.to_string().contains("diagonal"), "{e}");
    let e = PlaneProjector::fit(&shapes, &[0.0; V], 1.0, 0).unwrap_err();
    assert!(e.to_string().contains("masses"), "{e}");
}
