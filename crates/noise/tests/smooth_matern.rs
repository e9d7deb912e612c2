//! Acceptance: smooth Matérn noise (`matern-smooth`, order `p >= 2`) keeps
//! a bounded bending energy under refinement, where plain Matérn noise's
//! grows with the vertex count (issue 41: the texture of samples drawn on
//! meshes much finer than the training mesh).
//!
//! The bending energy of a signal is `f^T L M^-1 L f = sum_i lambda_i^2
//! c_i^2`. In expectation: `sum_i lambda_i^2 / (lambda_i + tau)^2` for
//! Matérn noise, which gains almost one unit per new high frequency (about
//! `V`), and `sum_i tau^2 lambda_i^2 / (lambda_i + tau)^4` for order 2,
//! whose terms fall as `tau^2 / lambda_i^2` and, with Weyl's law
//! (`lambda_k ~ 4 pi k / area`), sum to a finite limit.
//!
//! Refinement by midpoint subdivision (the same piecewise-flat surface), two
//! levels (16x the faces). Estimates are Monte Carlo means over `N = 200`
//! samples; the energy is a sum over many frequencies around `tau` of
//! independent chi-square terms, so its relative standard error is a few
//! percent (printed), far inside the bounds: plain Matérn must grow by more
//! than 3x, smooth Matérn must not grow by more than 15%. It may fall a
//! little: the coarse mesh's lowest eigenvalues, which carry most of a
//! smooth sample's bending, are a little off their limits (measured: order
//! 2 x0.91, order 3 x0.82 on the blob below; the bound below is 0.7).
#![allow(clippy::unwrap_used)]

mod common;

use mfm_geometry::operators::Operators;
use mfm_geometry::{TriMesh, subdivide};
use mfm_noise::{NoiseKind, NoiseSampler};

const SAMPLES: usize = 200;

/// Mean and standard error of the bending energy of `kind`'s samples.
fn bending(mesh: &TriMesh, kind: NoiseKind) -> (f64, f64) {
    let ops = Operators::new(mesh).unwrap();
    let (l, m) = (&ops.laplacian, &ops.mass);
    let batch = NoiseSampler::new(mesh, kind)
        .unwrap()
        .sample(SAMPLES, 1, 7)
        .unwrap();
    let (cp, ri, val) = (l.symbolic().col_ptr(), l.symbolic().row_idx(), l.val());
    let energies: Vec<f64> = (0..SAMPLES)
        .map(|s| {
            let f = batch.signal(s, 0);
            let mut lf = vec![0.0; f.len()];
            for (j, fj) in f.iter().enumerate() {
                for p in cp[j]..cp[j + 1] {
                    lf[ri[p]] += val[p] * fj;
                }
            }
            lf.iter().zip(m).map(|(x, m)| x * x / m).sum()
        })
        .collect();
    let n = energies.len() as f64;
    let mean = energies.iter().sum::<f64>() / n;
    let var = energies.iter().map(|e| (e - mean).powi(2)).sum::<f64>() / (n - 1.0);
    (mean, (var / n).sqrt())
}

#[test]
fn smooth_matern_bending_energy_is_bounded_under_refinement() {
    let coarse = common::blob(3);
    let fine = subdivide::midpoint(&subdivide::midpoint(&coarse).unwrap()).unwrap();
    let tau = 30.0;
    for (kind, grows) in [
        (NoiseKind::Matern { tau }, true),
        (NoiseKind::MaternSmooth { tau, order: 2 }, false),
        (NoiseKind::MaternSmooth { tau, order: 3 }, false),
    ] {
        let (a, sa) = bending(&coarse, kind);
        let (b, sb) = bending(&fine, kind);
        eprintln!(
            "{kind}: bending energy {a:.4e} ± {:.1}% ({} vertices) -> {b:.4e} ± {:.1}% ({} vertices): x{:.3}",
            100.0 * sa / a,
            coarse.num_vertices(),
            100.0 * sb / b,
            fine.num_vertices(),
            b / a
        );
        assert!(sa < 0.05 * a && sb < 0.05 * b, "{kind}: estimate too noisy");
        if grows {
            assert!(
                b > 3.0 * a,
                "{kind}: bending energy grew only x{:.3}",
                b / a
            );
        } else {
            assert!(
                (0.7..1.15).contains(&(b / a)),
                "{kind}: bending energy changed x{:.3} under refinement",
                b / a
            );
        }
    }
}
