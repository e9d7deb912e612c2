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
/// to be cut into several sample blocks and several solver chunks (of
/// widths that depend on the thread count); a range
/// drawn on its own equals the same range of a full batch; one channel of a
/// 3-channel batch equals a 1-channel draw.
#[test]
fn samples_are_bit_identical_across_thread_counts_and_batch_cuts() {
    let mesh = common::blob(3);
    let kinds = [
        NoiseKind::Matern { tau: 100.0 },
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

/// f32 sampling uses the same draws: it matches the f64 samples to f32
/// accuracy (the Matérn solve runs with the f32 factor).
#[test]
fn f32_samples_match_f64() {
    let mesh = common::blob(3);
    for kind in [NoiseKind::Matern { tau: 10.0 }, NoiseKind::White] {
        let s = NoiseSampler::new(&mesh, kind).unwrap();
        let a = s.sample(40, 2, 3).unwrap();
        let b = s.sample_f32(40, 2, 3).unwrap();
        let b64: Vec<f64> = b.data().iter().map(|&x| f64::from(x)).collect();
        let d = common::max_rel_diff(a.data(), &b64);
        assert!(d < 1e-5, "{kind}: f32 vs f64 relative difference {d:e}");
        assert_eq!(
            (b.samples(), b.vertices(), b.channels()),
            (40, mesh.num_vertices(), 2)
        );
    }
}
