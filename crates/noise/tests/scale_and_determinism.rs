//! Acceptance: scale invariance of normalized Matérn noise (paper Alg. 2) and
//! bit-identical sampling whatever the thread count or batch cutting.
#![allow(clippy::unwrap_used)]

mod common;

use mfm_noise::{NoiseBatch, NoiseKind, NoiseSampler};

/// Under `x -> k x`: `L` is unchanged, `M -> k^2 M`, `Gamma -> Gamma / k^2`,
/// so `tau = c Gamma` gives `L + tau M` unchanged, the right-hand side
/// `M^1/2 n` scales by `k`, the solution by `k`, and `sqrt(Gamma)` by `1/k`:
/// the same seed gives the same vertex values up to round-off (the operators
/// are recomputed from the scaled positions, so round-off is all that
/// differs). Fixed-`tau` Matérn noise changes with the scale.
#[test]
fn normalized_matern_is_scale_invariant_fixed_tau_is_not() {
    let mesh = common::blob(3);
    let normalized = NoiseKind::MaternNormalized { c: 1e-3 };
    let fixed = NoiseKind::Matern { tau: 10.0 };
    let reference_n = NoiseSampler::new(&mesh, normalized)
        .unwrap()
        .sample(16, 3, 99)
        .unwrap();
    let reference_f = NoiseSampler::new(&mesh, fixed)
        .unwrap()
        .sample(16, 3, 99)
        .unwrap();
    for k in [0.1, 2.0] {
        let scaled = mesh.transformed(k, [0.3, -1.0, 2.0]);
        let sn = NoiseSampler::new(&scaled, normalized).unwrap();
        let g0 = NoiseSampler::new(&mesh, normalized).unwrap().gamma();
        assert!(
            (sn.gamma() * k * k / g0 - 1.0).abs() < 1e-12,
            "Gamma scales as 1/k^2"
        );
        let d = common::max_rel_diff(reference_n.data(), sn.sample(16, 3, 99).unwrap().data());
        eprintln!("scale {k}: normalized matern relative difference {d:e}");
        assert!(
            d < 1e-12,
            "normalized matern at scale {k}: relative difference {d:e}"
        );
        let sf = NoiseSampler::new(&scaled, fixed)
            .unwrap()
            .sample(16, 3, 99)
            .unwrap();
        let d = common::max_rel_diff(reference_f.data(), sf.data());
        assert!(
            d > 0.2,
            "fixed-tau matern at scale {k} should change, differs by {d:e}"
        );
    }
}

fn in_pool<T: Send>(threads: usize, f: impl FnOnce() -> T + Send) -> T {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap()
        .install(f)
}

fn bits(b: &NoiseBatch) -> Vec<u64> {
    b.data().iter().map(|x| x.to_bits()).collect()
}

/// 1-, 2- and 16-thread pools give the same bits, for batches large enough
/// to be cut into several solver chunks (of widths that depend on the
/// thread count; the sampler's own block cutting is tested in its unit
/// tests); a range
/// drawn on its own equals the same range of a full batch; one channel of a
/// 3-channel batch equals a 1-channel draw.
#[test]
fn samples_are_bit_identical_across_thread_counts_and_batch_cuts() {
    let mesh = common::blob(3);
    let kinds = [
        NoiseKind::Matern { tau: 100.0 },
        NoiseKind::Matern { tau: 0.0 },
        NoiseKind::MaternNormalized { c: 0.01 },
        NoiseKind::White,
        NoiseKind::Naive,
        NoiseKind::Explicit { k: 20, tau: 5.0 },
    ];
    let (n, c, seed) = (150, 3, 0xfeed);
    for kind in kinds {
        let sampler = NoiseSampler::new(&mesh, kind).unwrap();
        let one = in_pool(1, || sampler.sample(n, c, seed).unwrap());
        let two = in_pool(2, || sampler.sample(n, c, seed).unwrap());
        assert_eq!(bits(&one), bits(&two), "{kind}: 1 vs 2 threads");
        // 16 threads make the solver cut each block into 16 narrow chunks
        // instead of 4 wide ones
        let many = in_pool(16, || sampler.sample(n, c, seed).unwrap());
        assert_eq!(bits(&one), bits(&many), "{kind}: 1 vs 16 threads");

        let v = mesh.num_vertices();
        let part = in_pool(2, || sampler.sample_range(61, 47, c, seed).unwrap());
        let whole: Vec<u64> = one.data()[61 * v * c..108 * v * c]
            .iter()
            .map(|x| x.to_bits())
            .collect();
        assert_eq!(bits(&part), whole, "{kind}: sample_range(61, 47)");

        let single = sampler.sample(5, 1, seed).unwrap();
        for s in 0..5 {
            assert_eq!(
                single.signal(s, 0),
                one.signal(s, 0),
                "{kind}: channel 0 alone"
            );
        }
        // a different seed gives different noise
        assert_ne!(
            sampler.sample(1, 1, seed + 1).unwrap().data(),
            single.sample(0)
        );
    }
}

/// `y = L x` from the CSC arrays (both triangles are stored).
fn matvec(l: &faer::sparse::SparseColMat<usize, f64>, x: &[f64]) -> Vec<f64> {
    let mut y = vec![0.0; x.len()];
    let (cp, ri, val) = (l.symbolic().col_ptr(), l.symbolic().row_idx(), l.val());
    for (j, xj) in x.iter().enumerate() {
        for p in cp[j]..cp[j + 1] {
            y[ri[p]] += val[p] * xj;
        }
    }
    y
}

/// f32 sampling draws its own `f32` normals `n` (naive `f32` noise is
/// exactly them): white noise is `M^-1/2 n` rounded, Matérn noise solves
/// `(L + tau M) f = M^1/2 n` to f32 accuracy (checked in f64 against the
/// operators), normalized Matérn carries `sqrt(Gamma)`, and the explicit
/// kind is its f64 sample rounded.
#[test]
fn f32_samples_solve_their_equations_with_f32_normals() {
    let mesh = common::blob(3);
    let ops = mfm_geometry::operators::Operators::new(&mesh).unwrap();
    let (l, m) = (&ops.laplacian, &ops.mass);
    let (ns, ch, seed) = (40, 2, 3);
    let naive = NoiseSampler::new(&mesh, NoiseKind::Naive)
        .unwrap()
        .sample_f32(ns, ch, seed)
        .unwrap();
    let moments = naive.data().iter().fold((0.0, 0.0), |(a, b), &x| {
        (a + f64::from(x), b + f64::from(x) * f64::from(x))
    });
    let count = naive.data().len() as f64;
    assert!((moments.0 / count).abs() < 5.0 / count.sqrt());
    assert!((moments.1 / count - 1.0).abs() < 8.0 * (2.0 / count).sqrt());
    let white = NoiseSampler::new(&mesh, NoiseKind::White)
        .unwrap()
        .sample_f32(ns, ch, seed)
        .unwrap();
    for (i, (&w, &n)) in white.data().iter().zip(naive.data()).enumerate() {
        let v = (i / ch) % mesh.num_vertices();
        assert_eq!(w, n * (1.0 / m[v].sqrt()) as f32);
    }
    let tau = 10.0;
    let matern = NoiseSampler::new(&mesh, NoiseKind::Matern { tau }).unwrap();
    let normalized = NoiseSampler::new(&mesh, NoiseKind::MaternNormalized { c: 0.01 }).unwrap();
    let (a, b) = (
        matern.sample_f32(ns, ch, seed).unwrap(),
        normalized.sample_f32(ns, ch, seed).unwrap(),
    );
    let (gamma, tau_n) = (normalized.gamma(), normalized.tau().unwrap());
    for s in 0..ns {
        for c in 0..ch {
            let n: Vec<f64> = naive.signal(s, c).iter().map(|&x| f64::from(x)).collect();
            let rhs: Vec<f64> = n.iter().zip(m).map(|(n, m)| m.sqrt() * n).collect();
            let rn = rhs.iter().map(|x| x * x).sum::<f64>().sqrt();
            for (sample, t, amp) in [(&a, tau, 1.0), (&b, tau_n, gamma.sqrt())] {
                let f: Vec<f64> = sample
                    .signal(s, c)
                    .iter()
                    .map(|&x| f64::from(x) / amp)
                    .collect();
                let lf = matvec(l, &f);
                let r = (0..f.len())
                    .map(|v| (lf[v] + t * m[v] * f[v] - rhs[v]).powi(2))
                    .sum::<f64>()
                    .sqrt();
                assert!(r < 1e-5 * rn, "tau {t}: relative residual {}", r / rn);
            }
        }
    }
    // smooth Matérn of order 2 is one more solve of the Matérn sample of
    // the same normals: (L + tau M) f_2 = tau M f_1, in f32 and in f64
    let smooth = NoiseSampler::new(&mesh, NoiseKind::MaternSmooth { tau, order: 2 }).unwrap();
    let matern64 = matern.sample(ns, ch, seed).unwrap();
    let smooth64 = smooth.sample(ns, ch, seed).unwrap();
    let smooth32 = smooth.sample_f32(ns, ch, seed).unwrap();
    for s in 0..ns {
        for c in 0..ch {
            let to64 = |x: &[f32]| x.iter().map(|&x| f64::from(x)).collect::<Vec<f64>>();
            let cases = [
                (to64(&smooth32.signal(s, c)), to64(&a.signal(s, c)), 1e-5),
                (smooth64.signal(s, c), matern64.signal(s, c), 1e-11),
            ];
            for (f2, f1, tolerance) in cases {
                let rhs: Vec<f64> = f1.iter().zip(m).map(|(f, m)| tau * m * f).collect();
                let rn = rhs.iter().map(|x| x * x).sum::<f64>().sqrt();
                let lf = matvec(l, &f2);
                let r = (0..f2.len())
                    .map(|v| (lf[v] + tau * m[v] * f2[v] - rhs[v]).powi(2))
                    .sum::<f64>()
                    .sqrt();
                assert!(r < tolerance * rn, "smooth: relative residual {}", r / rn);
            }
        }
    }
    let explicit = NoiseSampler::new(&mesh, NoiseKind::Explicit { k: 10, tau: 2.0 }).unwrap();
    assert_eq!(
        explicit.sample_f32(5, 2, 8).unwrap(),
        explicit.sample(5, 2, 8).unwrap().to_f32()
    );
    assert_eq!(
        (a.samples(), a.vertices(), a.channels()),
        (ns, mesh.num_vertices(), ch)
    );
}

fn bits32(b: &NoiseBatch<f32>) -> Vec<u32> {
    b.data().iter().map(|x| x.to_bits()).collect()
}

/// The f32 path has the f64 path's guarantees: 1, 2 and 16 threads give the
/// same bits, a range equals the same slice of a bigger batch, and a channel
/// does not depend on how many are drawn.
#[test]
fn f32_samples_are_bit_identical_across_thread_counts_and_batch_cuts() {
    let mesh = common::blob(3);
    let (n, c, seed) = (150, 3, 0xbeef);
    for kind in [
        NoiseKind::Matern { tau: 100.0 },
        NoiseKind::Matern { tau: 0.0 },
        NoiseKind::MaternNormalized { c: 0.01 },
        NoiseKind::MaternSmooth {
            tau: 100.0,
            order: 3,
        },
        NoiseKind::White,
        NoiseKind::Naive,
    ] {
        let sampler = NoiseSampler::new(&mesh, kind).unwrap();
        let one = in_pool(1, || sampler.sample_f32(n, c, seed).unwrap());
        let two = in_pool(2, || sampler.sample_f32(n, c, seed).unwrap());
        assert_eq!(bits32(&one), bits32(&two), "{kind}: 1 vs 2 threads");
        let many = in_pool(16, || sampler.sample_f32(n, c, seed).unwrap());
        assert_eq!(bits32(&one), bits32(&many), "{kind}: 1 vs 16 threads");
        let v = mesh.num_vertices();
        let part = in_pool(2, || sampler.sample_range_f32(61, 47, c, seed).unwrap());
        assert_eq!(
            part.data(),
            &one.data()[61 * v * c..108 * v * c],
            "{kind}: range"
        );
        let single = sampler.sample_f32(5, 1, seed).unwrap();
        for s in 0..5 {
            assert_eq!(
                single.signal(s, 0),
                one.signal(s, 0),
                "{kind}: channel 0 alone"
            );
        }
        assert_ne!(
            sampler.sample_f32(1, 1, seed + 1).unwrap().data(),
            single.sample(0)
        );
    }
}

/// A sampler that keeps only the `f32` factor (a sampler on a very fine
/// mesh) draws the same `f32` bits; the kinds whose `f32` draws need the
/// `f64` factor keep it, and a released one refuses `f64` draws.
#[test]
fn releasing_the_f64_factor_keeps_f32_draws_bit_for_bit() {
    let mesh = common::blob(2);
    let (n, c, seed) = (7, 3, 0x5eed);
    for (kind, releases) in [
        (NoiseKind::Matern { tau: 100.0 }, true),
        (NoiseKind::MaternNormalized { c: 0.01 }, true),
        (
            NoiseKind::MaternSmooth {
                tau: 100.0,
                order: 2,
            },
            true,
        ),
        (NoiseKind::Matern { tau: 0.0 }, false),
        (NoiseKind::White, false),
        (NoiseKind::Naive, false),
    ] {
        let kept = NoiseSampler::new(&mesh, kind).unwrap();
        let mut released = NoiseSampler::new(&mesh, kind).unwrap();
        assert_eq!(released.release_f64_factor(), releases, "{kind}");
        assert_eq!(
            bits32(&released.sample_f32(n, c, seed).unwrap()),
            bits32(&kept.sample_f32(n, c, seed).unwrap()),
            "{kind}: f32 draws after the release"
        );
        let f64_draw = released.sample(n, c, seed);
        if releases {
            let e = f64_draw.unwrap_err().to_string();
            assert!(e.contains("only f32 solves remain"), "{kind}: {e}");
            assert!(
                !released.screened_poisson().unwrap().holds_f64_factor(),
                "{kind}"
            );
        } else {
            assert_eq!(
                bits(&f64_draw.unwrap()),
                bits(&kept.sample(n, c, seed).unwrap()),
                "{kind}: nothing released"
            );
        }
    }
}
