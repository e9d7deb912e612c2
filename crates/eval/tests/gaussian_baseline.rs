//! `mfm_eval::gaussian_baseline::gaussian_shapes`: draws in the training
//! shapes' affine span, with their mean and covariance, reproducible.

#![allow(clippy::unwrap_used)]

use mfm_data::{InMemorySignals, SignalSource};
use mfm_eval::gaussian_baseline::gaussian_shapes;
use proptest::prelude::*;

/// `n` random "shapes" of `values` values each.
fn shapes(n: usize, values: usize) -> impl Strategy<Value = InMemorySignals> {
    prop::collection::vec(-2.0f32..2.0, n * values)
        .prop_map(move |data| InMemorySignals::new(data, n, values / 3, 3).unwrap())
}

fn as_f64(x: &[f32]) -> Vec<f64> {
    x.iter().map(|&v| f64::from(v)).collect()
}

/// Distance of `x` to the affine span of the shapes, by least squares on
/// their differences to the first (modified Gram-Schmidt).
fn distance_to_span(train: &InMemorySignals, x: &[f32]) -> f64 {
    let t0 = as_f64(train.signal(0));
    let mut basis: Vec<Vec<f64>> = Vec::new();
    for i in 1..train.len() {
        let mut d: Vec<f64> = as_f64(train.signal(i))
            .iter()
            .zip(&t0)
            .map(|(a, b)| a - b)
            .collect();
        for b in &basis {
            let p: f64 = d.iter().zip(b).map(|(x, y)| x * y).sum();
            d.iter_mut().zip(b).for_each(|(x, y)| *x -= p * y);
        }
        let norm = d.iter().map(|x| x * x).sum::<f64>().sqrt();
        if norm > 1e-9 {
            basis.push(d.iter().map(|x| x / norm).collect());
        }
    }
    let mut r: Vec<f64> = as_f64(x).iter().zip(&t0).map(|(a, b)| a - b).collect();
    for b in &basis {
        let p: f64 = r.iter().zip(b).map(|(x, y)| x * y).sum();
        r.iter_mut().zip(b).for_each(|(x, y)| *x -= p * y);
    }
    r.iter().map(|x| x * x).sum::<f64>().sqrt()
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]

    #[test]
    fn draws_lie_in_the_span_and_follow_the_seed(
        train in (2usize..6).prop_flat_map(|n| shapes(n, 12)),
        count in 1usize..6,
        seed in 0u64..1000,
    ) {
        let g = gaussian_shapes(&train, count, seed).unwrap();
        prop_assert_eq!((g.len(), g.num_vertices(), g.channels()), (count, 4, 3));
        for k in 0..count {
            let off = distance_to_span(&train, g.signal(k));
            prop_assert!(off < 1e-4, "draw {} is {} off the span", k, off);
        }
        let again = gaussian_shapes(&train, count, seed).unwrap();
        prop_assert_eq!(g.data(), again.data());
        let other = gaussian_shapes(&train, count, seed + 1).unwrap();
        prop_assert_ne!(g.data(), other.data());
        // a longer run starts with the same draws
        let more = gaussian_shapes(&train, count + 2, seed).unwrap();
        prop_assert_eq!(g.data(), &more.data()[..g.data().len()]);
    }
}

/// Over many draws, the sample mean and covariance are the training
/// shapes' (within the sampling error of 20,000 draws).
#[test]
fn many_draws_have_the_training_mean_and_covariance() {
    let train = InMemorySignals::new(
        vec![
            0.0, 1.0, -1.0, 0.5, 0.0, 2.0, //
            1.0, 0.0, 0.5, -0.5, 1.0, 0.0, //
            2.0, 2.0, 0.0, 0.0, -1.0, 1.0, //
            -1.0, 0.5, 1.5, 1.0, 0.0, -1.0,
        ],
        4,
        2,
        3,
    )
    .unwrap();
    let (n, p, count) = (4, 6, 20_000);
    let mean = |f: &dyn Fn(usize) -> Vec<f64>, m: usize| -> Vec<f64> {
        let mut s = vec![0.0; p];
        for k in 0..m {
            s.iter_mut().zip(f(k)).for_each(|(a, b)| *a += b / m as f64);
        }
        s
    };
    let covariance = |f: &dyn Fn(usize) -> Vec<f64>, m: usize, mu: &[f64]| -> Vec<f64> {
        let mut c = vec![0.0; p * p];
        for k in 0..m {
            let x = f(k);
            for i in 0..p {
                for j in 0..p {
                    c[i * p + j] += (x[i] - mu[i]) * (x[j] - mu[j]) / (m - 1) as f64;
                }
            }
        }
        c
    };
    let t = |k: usize| as_f64(train.signal(k));
    let mu_t = mean(&t, n);
    let cov_t = covariance(&t, n, &mu_t);
    let g = gaussian_shapes(&train, count, 11).unwrap();
    let d = |k: usize| as_f64(g.signal(k));
    let mu_g = mean(&d, count);
    let cov_g = covariance(&d, count, &mu_g);
    let scale = cov_t.iter().fold(0.0f64, |a, &b| a.max(b.abs()));
    for i in 0..p {
        assert!(
            (mu_g[i] - mu_t[i]).abs() < 0.05 * scale.sqrt(),
            "mean {i}: {mu_g:?} vs {mu_t:?}"
        );
    }
    for (a, b) in cov_g.iter().zip(&cov_t) {
        assert!((a - b).abs() < 0.05 * scale, "covariance {a} vs {b}");
    }
}

#[test]
fn too_few_shapes_or_no_draws_are_refused() {
    let one = InMemorySignals::new(vec![0.0; 6], 1, 2, 3).unwrap();
    let e = gaussian_shapes(&one, 4, 0).unwrap_err().to_string();
    assert!(e.contains("at least 2 training shapes"), "{e}");
    let two = InMemorySignals::new(vec![0.0; 12], 2, 2, 3).unwrap();
    assert!(gaussian_shapes(&two, 0, 0).is_err());
}
