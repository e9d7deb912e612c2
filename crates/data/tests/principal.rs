//! The principal components of a signal set against their definition: the
//! directions are orthonormal under the weights, the scatter along each is
//! the fitted signals' squared coordinates, the kept directions span every
//! fitted signal's deviation from the mean, a direction is the leading
//! eigenvector of the weighted scatter (checked against power iteration),
//! and bad input is refused.
#![allow(clippy::unwrap_used)]

use mfm_data::principal::{PrincipalComponents, mean_signal};
use mfm_data::{InMemorySignals, SignalSource};
use proptest::prelude::*;

fn inner(w: &[f64], c: usize, a: &[f64], b: &[f64]) -> f64 {
    a.iter()
        .zip(b)
        .enumerate()
        .map(|(j, (x, y))| w[j / c] * x * y)
        .sum()
}

fn set_strategy() -> impl Strategy<Value = (InMemorySignals, Vec<f64>)> {
    (2usize..7, 1usize..6, 1usize..4).prop_flat_map(|(n, v, c)| {
        (
            prop::collection::vec(-2.0f32..2.0, n * v * c),
            prop::collection::vec(0.1f64..3.0, v),
        )
            .prop_map(move |(data, w)| (InMemorySignals::new(data, n, v, c).unwrap(), w))
    })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    #[test]
    fn directions_are_orthonormal_and_span_the_fitted_signals((set, w) in set_strategy()) {
        let n = set.len();
        let c = set.channels();
        let all: Vec<usize> = (0..n).collect();
        let pc = PrincipalComponents::fit(&set, &all, &w, usize::MAX).unwrap();
        let total: f64 = w.iter().sum();
        let wn: Vec<f64> = w.iter().map(|x| x / total).collect();
        prop_assert!(pc.len() <= (n - 1).min(set.num_vertices() * c));
        let mean = mean_signal(&set);
        prop_assert_eq!(pc.mean(), &mean[..]);
        for a in 0..pc.len() {
            for b in 0..pc.len() {
                let d = inner(&wn, c, pc.direction(a), pc.direction(b));
                let expected = if a == b { 1.0 } else { 0.0 };
                prop_assert!((d - expected).abs() < 1e-8, "<u{a}, u{b}> = {d}");
            }
        }
        // scatter = sum of squared coordinates, decreasing, within the total
        for k in 0..pc.len() {
            let sq: f64 = (0..n).map(|i| pc.coordinate(set.signal(i), k).powi(2)).sum();
            prop_assert!((sq - pc.scatter()[k]).abs() <= 1e-8 * pc.total_scatter().max(1e-30));
            if k > 0 {
                prop_assert!(pc.scatter()[k] <= pc.scatter()[k - 1] * (1.0 + 1e-12));
            }
        }
        let kept: f64 = pc.scatter().iter().sum();
        prop_assert!((kept - pc.total_scatter()).abs() <= 1e-8 * pc.total_scatter().max(1e-30));
        // every fitted signal is the mean plus its coordinates along the kept directions
        for i in 0..n {
            let x = set.signal(i);
            let mut r: Vec<f64> = mean.clone();
            for k in 0..pc.len() {
                let a = pc.coordinate(x, k);
                r.iter_mut().zip(pc.direction(k)).for_each(|(y, u)| *y += a * u);
            }
            let err: f64 = r.iter().zip(x).map(|(y, &x)| (y - f64::from(x)).abs()).fold(0.0, f64::max);
            prop_assert!(err < 1e-4, "signal {i} off its reconstruction by {err}");
        }
        // the sign: the first fitted signal sits at a non-negative coordinate
        for k in 0..pc.len() {
            prop_assert!(pc.coordinate(set.signal(0), k) >= -1e-9);
        }
    }
}

/// The leading direction is the leading eigenvector of the weighted scatter
/// operator `S y = sum_i (x_i - mu) <x_i - mu, y>`, found here by power
/// iteration without any Gram matrix.
#[test]
fn the_leading_direction_is_the_scatters_leading_eigenvector() {
    let (n, v, c) = (9, 7, 2);
    let data: Vec<f32> = (0..n * v * c)
        .map(|j| ((j as f32 * 0.37).sin() * (1.0 + (j % 5) as f32)) + 0.3 * (j / (v * c)) as f32)
        .collect();
    let set = InMemorySignals::new(data, n, v, c).unwrap();
    let w: Vec<f64> = (0..v).map(|i| 0.5 + i as f64 * 0.25).collect();
    let pc = PrincipalComponents::fit(&set, &(0..n).collect::<Vec<_>>(), &w, 3).unwrap();
    assert_eq!(pc.len(), 3);
    let total: f64 = w.iter().sum();
    let wn: Vec<f64> = w.iter().map(|x| x / total).collect();
    let mean = mean_signal(&set);
    let dev: Vec<Vec<f64>> = (0..n)
        .map(|i| {
            set.signal(i)
                .iter()
                .zip(&mean)
                .map(|(&x, m)| f64::from(x) - m)
                .collect()
        })
        .collect();
    let mut y: Vec<f64> = (0..v * c).map(|j| 1.0 + j as f64 * 0.01).collect();
    let mut lambda = 0.0;
    for _ in 0..2000 {
        let mut s = vec![0.0; v * c];
        for d in &dev {
            let a = inner(&wn, c, d, &y);
            s.iter_mut().zip(d).for_each(|(sj, dj)| *sj += a * dj);
        }
        lambda = inner(&wn, c, &s, &y) / inner(&wn, c, &y, &y);
        let norm = inner(&wn, c, &s, &s).sqrt();
        y = s.iter().map(|x| x / norm).collect();
    }
    assert!(
        (lambda - pc.scatter()[0]).abs() < 1e-9 * lambda,
        "{lambda} vs {}",
        pc.scatter()[0]
    );
    let cos = inner(&wn, c, &y, pc.direction(0)).abs();
    assert!((cos - 1.0).abs() < 1e-9, "cosine {cos}");
}

#[test]
fn a_subset_is_fitted_about_the_whole_sets_mean_and_bad_input_is_refused() {
    let set = InMemorySignals::new(vec![0.0, 1.0, 5.0, 3.0], 4, 1, 1).unwrap();
    let pc = PrincipalComponents::fit(&set, &[0, 1], &[2.0], 4).unwrap();
    assert_eq!(pc.mean(), &[2.25]);
    assert_eq!(pc.fitted_on(), 2);
    // one direction in one dimension; scatter (0 - 2.25)^2 + (1 - 2.25)^2
    assert_eq!(pc.len(), 1);
    assert!((pc.scatter()[0] - (2.25f64.powi(2) + 1.25f64.powi(2))).abs() < 1e-12);
    // identical signals: no direction
    let flat = InMemorySignals::new(vec![1.5; 6], 3, 2, 1).unwrap();
    assert!(
        PrincipalComponents::fit(&flat, &[0, 1, 2], &[1.0, 1.0], 4)
            .unwrap()
            .is_empty()
    );
    // at most the directions asked for
    let pc = PrincipalComponents::fit(&set, &[0, 1, 2, 3], &[1.0], 0).unwrap();
    assert!(pc.is_empty());
    for (fitted, w, needle) in [
        (vec![], vec![1.0], "at least one signal"),
        (vec![4], vec![1.0], "beyond"),
        (vec![0], vec![1.0, 1.0], "vertex weights"),
        (vec![0], vec![0.0], "finite positive sum"),
        (vec![0], vec![-1.0], "finite positive sum"),
    ] {
        let e = PrincipalComponents::fit(&set, &fitted, &w, 2)
            .unwrap_err()
            .to_string();
        assert!(e.contains(needle), "{e}");
    }
}
