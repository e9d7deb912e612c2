//! Metrics against hand-computed values on tiny examples, and properties.

#![allow(clippy::unwrap_used)]

use mfm_data::{DataError, InMemorySignals};
use mfm_eval::metrics::{
    MassWeighted, Metrics, coverage, evaluate, mass_weighted_distance, mmd, one_nna,
};
use proptest::prelude::*;

fn set(rows: &[&[f32]], vertices: usize, channels: usize) -> InMemorySignals {
    let data: Vec<f32> = rows.iter().flat_map(|r| r.iter().copied()).collect();
    InMemorySignals::new(data, rows.len(), vertices, channels).unwrap()
}

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() < 1e-12
}

/// Three vertices with masses [1, 1, 2] (total 4), one channel.
/// d(a, b)^2 = (D0^2 + D1^2 + 2 D2^2) / 4.
///
/// generated g0 = [0,0,0], g1 = [2,0,0]; reference r0 = [0,0,1], r1 = [2,2,2], r2 = [1,0,0]
///
/// generated x reference:
///   d(g0,r0) = sqrt(2/4) = 0.70711   d(g0,r1) = sqrt(16/4) = 2   d(g0,r2) = sqrt(1/4) = 0.5
///   d(g1,r0) = sqrt(6/4) = 1.22474   d(g1,r1) = sqrt(12/4) = 1.73205   d(g1,r2) = 0.5
/// within sets:
///   d(g0,g1) = sqrt(4/4) = 1
///   d(r0,r1) = sqrt(10/4) = 1.58114   d(r0,r2) = sqrt(3/4) = 0.86603   d(r1,r2) = sqrt(13/4) = 1.80278
///
/// MMD = (min row g0 + min row g1) / 2 = (0.5 + 0.5) / 2 = 0.5
/// COV: both generated samples are closest to r2 -> 1 of 3 references = 1/3
/// 1-NNA (nearest other sample in the union; ties to the lowest index, generated first):
///   g0 -> r2 (0.5) wrong; g1 -> r2 (0.5) wrong; r0 -> g0 (0.707) wrong;
///   r1 -> r0 (1.581) right; r2 -> g0 (0.5, tie with g1) wrong  => 1/5 = 0.2
/// Test error: mean(G) = [1, 0, 0], mean(R) = [1, 2/3, 1],
///   (1*0 + 1*2/3 + 2*1) / 4 = 2/3
fn tiny() -> ([f64; 3], InMemorySignals, InMemorySignals) {
    let mass = [1.0, 1.0, 2.0];
    let g = set(&[&[0.0, 0.0, 0.0], &[2.0, 0.0, 0.0]], 3, 1);
    let r = set(
        &[&[0.0, 0.0, 1.0], &[2.0, 2.0, 2.0], &[1.0, 0.0, 0.0]],
        3,
        1,
    );
    (mass, g, r)
}

#[test]
fn hand_computed_distances() {
    let (mass, g, r) = tiny();
    let m = MassWeighted::new(&mass, 1).unwrap();
    let d = m.pairwise(&g, &r).unwrap();
    let expected = [
        [0.5f64.sqrt(), 2.0, 0.5],
        [1.5f64.sqrt(), 3.0f64.sqrt(), 0.5],
    ];
    for (i, row) in expected.iter().enumerate() {
        for (j, &e) in row.iter().enumerate() {
            assert!(close(d.get(i, j), e), "({i}, {j}): {} vs {e}", d.get(i, j));
        }
    }
    let rr = m.pairwise(&r, &r).unwrap();
    assert!(close(rr.get(0, 1), 2.5f64.sqrt()));
    assert!(close(rr.get(0, 2), 0.75f64.sqrt()));
    assert!(close(rr.get(2, 1), 3.25f64.sqrt()));
    assert_eq!(rr.get(1, 1), 0.0);
}

#[test]
fn hand_computed_metrics() {
    let (mass, g, r) = tiny();
    let m = evaluate(&mass, &g, &r).unwrap();
    assert!(close(m.mmd, 0.5), "mmd {}", m.mmd);
    assert!(close(m.cov, 1.0 / 3.0), "cov {}", m.cov);
    assert!(close(m.one_nna, 0.2), "1-nna {}", m.one_nna);
    assert!(
        close(m.test_error, 2.0 / 3.0),
        "test error {}",
        m.test_error
    );
    assert_eq!((m.num_generated, m.num_reference), (2, 3));
    // the same through the building blocks
    let w = MassWeighted::new(&mass, 1).unwrap();
    let gr = w.pairwise(&g, &r).unwrap();
    assert!(close(mmd(&gr).unwrap(), 0.5));
    assert!(close(coverage(&gr).unwrap(), 1.0 / 3.0));
    let nna = one_nna(
        &w.pairwise(&g, &g).unwrap(),
        &gr,
        &w.pairwise(&r, &r).unwrap(),
    )
    .unwrap();
    assert!(close(nna, 0.2));
    // swapping roles: MMD becomes the mean over references of the closest generated
    // rows r0: 0.70711, r1: 1.73205, r2: 0.5
    let swapped = evaluate(&mass, &r, &g).unwrap();
    let want = (0.5f64.sqrt() + 3.0f64.sqrt() + 0.5) / 3.0;
    assert!(close(swapped.mmd, want), "{} vs {want}", swapped.mmd);
    // r0 -> g0, r1 -> g1, r2 -> g0 (tie with g1, lowest index): both generated covered
    assert!(close(swapped.cov, 1.0));
}

#[test]
fn channels_use_the_euclidean_norm() {
    // mass [1, 3] (total 4), two channels: a = [(0,0), (3,4)], b = 0
    // d^2 = (1*0 + 3*25) / 4 = 18.75
    let mass = [1.0, 3.0];
    let d = mass_weighted_distance(&mass, 2, &[0.0, 0.0, 3.0, 4.0], &[0.0; 4]).unwrap();
    assert!(close(d, 18.75f64.sqrt()));
    // test error: |mean difference| per vertex is 5 at vertex 1: (3 * 5) / 4
    let a = set(&[&[0.0, 0.0, 3.0, 4.0]], 2, 2);
    let b = set(&[&[0.0, 0.0, 0.0, 0.0]], 2, 2);
    let m = evaluate(&mass, &a, &b).unwrap();
    assert!(close(m.test_error, 3.75));
    assert!(close(m.mmd, 18.75f64.sqrt()));
    // one generated, one reference: each one's only neighbour is in the other set
    assert!(close(m.one_nna, 0.0));
}

#[test]
fn identical_sets() {
    let mass = [0.5, 1.0, 1.5, 2.0];
    let rows: Vec<Vec<f32>> = (0..6)
        .map(|i| {
            (0..4)
                .map(|v| ((i * 7 + v * 3) % 5) as f32 - 1.5 * i as f32)
                .collect()
        })
        .collect();
    let refs: Vec<&[f32]> = rows.iter().map(|r| r.as_slice()).collect();
    let s = set(&refs, 4, 1);
    let m = evaluate(&mass, &s, &s).unwrap();
    assert_eq!(m.mmd, 0.0);
    assert_eq!(m.cov, 1.0);
    assert_eq!(m.test_error, 0.0);
    // every sample's nearest other is its twin in the other set: all misclassified
    assert_eq!(m.one_nna, 0.0);
}

#[test]
fn separated_sets_are_told_apart_and_collapse_lowers_coverage() {
    let mass = [1.0, 1.0];
    let g = set(&[&[0.0, 0.0], &[0.1, 0.0], &[0.0, 0.1]], 2, 1);
    let r = set(
        &[&[10.0, 10.0], &[10.1, 10.0], &[10.0, 10.2], &[10.3, 10.0]],
        2,
        1,
    );
    let m = evaluate(&mass, &g, &r).unwrap();
    assert_eq!(m.one_nna, 1.0);
    // all generated samples are nearest to r0 = (10, 10): 1 of 4
    assert!(close(m.cov, 0.25));
    // mean(G) = (1/30, 1/30), mean(R) = (10.1, 10.05): weights 1/2 each
    let want = 0.5 * ((10.1 - 0.1 / 3.0) + (10.05 - 0.1 / 3.0));
    assert!(
        (m.test_error - want).abs() < 1e-4,
        "{} vs {want}",
        m.test_error
    );
    // the struct serializes and reads back
    let json = serde_json::to_string(&m).unwrap();
    let back: Metrics = serde_json::from_str(&json).unwrap();
    assert_eq!(back, m);
}

#[test]
fn invalid_inputs_are_errors() {
    let (mass, g, r) = tiny();
    assert!(matches!(
        evaluate(&mass[..2], &g, &r),
        Err(DataError::SizeMismatch { .. })
    ));
    assert!(matches!(
        evaluate(&[1.0, -1.0, 2.0], &g, &r),
        Err(DataError::Config(_))
    ));
    assert!(matches!(
        evaluate(&[0.0, 0.0, 0.0], &g, &r),
        Err(DataError::Config(_))
    ));
    let empty = InMemorySignals::new(Vec::new(), 0, 3, 1).unwrap();
    assert!(matches!(
        evaluate(&mass, &empty, &r),
        Err(DataError::Config(_))
    ));
    let two_channels = set(&[&[0.0; 6]], 3, 2);
    assert!(evaluate(&mass, &g, &two_channels).is_err());
    assert!(mass_weighted_distance(&mass, 1, &[0.0; 3], &[0.0; 2]).is_err());
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    #[test]
    fn distance_is_a_symmetric_scale_free_metric(
        mass in prop::collection::vec(0.01f64..10.0, 5),
        a in prop::collection::vec(-5.0f32..5.0, 10),
        b in prop::collection::vec(-5.0f32..5.0, 10),
        c in prop::collection::vec(-5.0f32..5.0, 10),
        k in 0.1f64..100.0,
    ) {
        let m = MassWeighted::new(&mass, 2).unwrap();
        let dab = m.distance(&a, &b).unwrap();
        prop_assert_eq!(dab, m.distance(&b, &a).unwrap());
        prop_assert_eq!(m.distance(&a, &a).unwrap(), 0.0);
        let dbc = m.distance(&b, &c).unwrap();
        let dac = m.distance(&a, &c).unwrap();
        prop_assert!(dac <= dab + dbc + 1e-9);
        // only relative masses matter
        let scaled: Vec<f64> = mass.iter().map(|x| x * k).collect();
        let ds = MassWeighted::new(&scaled, 2).unwrap().distance(&a, &b).unwrap();
        prop_assert!((ds - dab).abs() <= 1e-12 * (1.0 + dab));
        // a constant offset of s in every value moves the signal by sqrt(C) |s|
        let shifted: Vec<f32> = a.iter().map(|x| x + 0.5).collect();
        let dshift = m.distance(&a, &shifted).unwrap();
        prop_assert!((dshift - 0.5 * 2f64.sqrt()).abs() < 1e-5);
    }

    #[test]
    fn pairwise_is_transposed_by_swapping(
        x in prop::collection::vec(-3.0f32..3.0, 12),
        y in prop::collection::vec(-3.0f32..3.0, 9),
    ) {
        let mass = [1.0, 2.0, 3.0];
        let xs = InMemorySignals::new(x, 4, 3, 1).unwrap();
        let ys = InMemorySignals::new(y, 3, 3, 1).unwrap();
        let m = MassWeighted::new(&mass, 1).unwrap();
        let xy = m.pairwise(&xs, &ys).unwrap();
        let yx = m.pairwise(&ys, &xs).unwrap();
        for i in 0..4 {
            for j in 0..3 {
                prop_assert_eq!(xy.get(i, j), yx.get(j, i));
            }
        }
        let metrics = evaluate(&mass, &xs, &ys).unwrap();
        prop_assert!((0.0..=1.0).contains(&metrics.cov));
        prop_assert!((0.0..=1.0).contains(&metrics.one_nna));
        prop_assert!(metrics.mmd >= 0.0 && metrics.test_error >= 0.0);
    }
}
