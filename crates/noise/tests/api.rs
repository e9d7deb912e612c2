//! The sampler against its defining equations (one sample at a time, with
//! independent arithmetic), the parsing and serialization of kinds, the
//! spectral tools on signals with known coefficients, and the
//! error paths.
#![allow(clippy::unwrap_used, clippy::needless_range_loop)]

mod common;

use faer::sparse::SparseColMat;
use mfm_geometry::TriMesh;
use mfm_geometry::operators::Operators;
use mfm_noise::spectrum::{self, SpectralAnalyzer};
use mfm_noise::{
    KindName, KindParameters, NoiseBatch, NoiseError, NoiseKind, NoiseSampler, SpectrumReport,
};
use proptest::prelude::*;

/// `y = L x` from the CSC arrays (both triangles are stored).
fn matvec(l: &SparseColMat<usize, f64>, x: &[f64]) -> Vec<f64> {
    let mut y = vec![0.0; x.len()];
    let (cp, ri, val) = (l.symbolic().col_ptr(), l.symbolic().row_idx(), l.val());
    for j in 0..x.len() {
        for p in cp[j]..cp[j + 1] {
            y[ri[p]] += val[p] * x[j];
        }
    }
    y
}

fn norm(v: &[f64]) -> f64 {
    v.iter().map(|x| x * x).sum::<f64>().sqrt()
}

/// All kinds draw their normals from the same per-(sample, channel)
/// streams, so naive noise *is* the normals `n` each kind starts from.
#[test]
fn every_kind_solves_its_defining_equation() {
    let mesh = common::blob(2);
    let ops = Operators::new(&mesh).unwrap();
    let (l, m) = (&ops.laplacian, &ops.mass);
    let (ns, ch, seed) = (3, 2, 77);
    let naive = NoiseSampler::new(&mesh, NoiseKind::Naive)
        .unwrap()
        .sample(ns, ch, seed)
        .unwrap();
    for s in 0..ns {
        for c in 0..ch {
            let n = naive.signal(s, c);
            // white: M^-1/2 n
            let w = NoiseSampler::new(&mesh, NoiseKind::White)
                .unwrap()
                .sample(ns, ch, seed)
                .unwrap();
            for ((x, n), m) in w.signal(s, c).iter().zip(&n).zip(m) {
                assert!((x * m.sqrt() - n).abs() <= 1e-14 * n.abs().max(1.0));
            }
            // matern: (L + tau M) f = M^1/2 n
            let tau = 7.5;
            let f = NoiseSampler::new(&mesh, NoiseKind::Matern { tau }).unwrap();
            let f = f.sample(ns, ch, seed).unwrap().signal(s, c);
            let lf = matvec(l, &f);
            let r: Vec<f64> = (0..f.len())
                .map(|v| lf[v] + tau * m[v] * f[v] - m[v].sqrt() * n[v])
                .collect();
            let rhs: Vec<f64> = (0..f.len()).map(|v| m[v].sqrt() * n[v]).collect();
            assert!(
                norm(&r) < 1e-12 * norm(&rhs),
                "matern residual {}",
                norm(&r)
            );
            // normalized: g = sqrt(Gamma) f with (L + c Gamma M) f = M^1/2 n
            let cc = 2e-3;
            let ns_ = NoiseSampler::new(&mesh, NoiseKind::MaternNormalized { c: cc }).unwrap();
            let gamma = ns_.gamma();
            assert_eq!(ns_.tau(), Some(cc * gamma));
            assert_eq!(ns_.amplitude(), gamma.sqrt());
            let g = ns_.sample(ns, ch, seed).unwrap().signal(s, c);
            let f: Vec<f64> = g.iter().map(|x| x / gamma.sqrt()).collect();
            let lf = matvec(l, &f);
            let r: Vec<f64> = (0..f.len())
                .map(|v| lf[v] + cc * gamma * m[v] * f[v] - m[v].sqrt() * n[v])
                .collect();
            assert!(
                norm(&r) < 1e-12 * norm(&rhs),
                "normalized residual {}",
                norm(&r)
            );
        }
    }
}

/// Explicit noise draws `chi` as the first `k` normals of the stream, so its
/// coefficients are `n_i / (lambda_i + tau)` with `n` the naive sample.
#[test]
fn explicit_coefficients_are_scaled_normals() {
    let mesh = common::blob(2);
    let (k, tau) = (12, 3.0);
    let ex = NoiseSampler::new(&mesh, NoiseKind::Explicit { k, tau }).unwrap();
    let naive = NoiseSampler::new(&mesh, NoiseKind::Naive)
        .unwrap()
        .sample(4, 1, 8)
        .unwrap();
    let batch = ex.sample(4, 1, 8).unwrap();
    let pairs = ex.eigenpairs().unwrap();
    for s in 0..4 {
        let c = spectrum::project(pairs, ex.mass(), &batch.signal(s, 0)).unwrap();
        for i in 0..k {
            let want = naive.get(s, i, 0) / (pairs.values[i] + tau);
            assert!(
                (c[i] - want).abs() < 1e-12 * want.abs().max(1e-3),
                "c_{i}: {} vs {want}",
                c[i]
            );
        }
    }
}

/// Signals with known coefficients: the analyzer's variance, mean, energy
/// and correlation are the exact sample statistics of those coefficients.
#[test]
fn analyzer_recovers_known_coefficients() {
    let mesh = common::blob(2);
    let (mass, pairs) = common::eigen(&mesh, 6);
    let v = mesh.num_vertices();
    // 3 samples x 2 channels; signal j has coefficients a[j]
    let a: Vec<[f64; 6]> = (0..6)
        .map(|j| std::array::from_fn(|i| ((j * 7 + i * 3) % 5) as f64 - 2.0 + 0.1 * i as f64))
        .collect();
    let mut data = vec![0.0; 3 * v * 2];
    for (j, coef) in a.iter().enumerate() {
        let (s, c) = (j / 2, j % 2);
        for vv in 0..v {
            data[(s * v + vv) * 2 + c] = (0..6).map(|i| coef[i] * pairs.vectors[(vv, i)]).sum();
        }
    }
    let batch = NoiseBatch::from_vec(data, 3, v, 2).unwrap();
    let mut an = SpectralAnalyzer::new(&pairs, &mass)
        .unwrap()
        .keep(&[1, 4, 99]);
    an.add(&batch).unwrap();
    let r = an.report(None).unwrap();
    assert_eq!(r.num_signals, 6);
    for i in 0..6 {
        let var = a.iter().map(|c| c[i] * c[i]).sum::<f64>() / 6.0;
        let mean = a.iter().map(|c| c[i]).sum::<f64>() / 6.0;
        assert!((r.variance[i] - var).abs() < 1e-10, "var {i}");
        assert!((r.mean[i] - mean).abs() < 1e-10, "mean {i}");
    }
    let energy = a
        .iter()
        .map(|c| c.iter().map(|x| x * x).sum::<f64>())
        .sum::<f64>()
        / 6.0;
    assert!((r.mean_energy - energy).abs() < 1e-10 * energy);
    assert!((r.captured_energy - energy).abs() < 1e-10 * energy);
    let kept: Vec<f64> = a.iter().map(|c| c[4]).collect();
    let got = an.coefficients(4).unwrap();
    assert!(got.iter().zip(&kept).all(|(x, y)| (x - y).abs() < 1e-10));
    assert!(an.coefficients(99).is_none() && an.coefficients(2).is_none());
    // correlation of frequencies 0 and 1 from the definitions
    let (s01, s00, s11) = a.iter().fold((0.0, 0.0, 0.0), |(x, y, z), c| {
        (x + c[0] * c[1], y + c[0] * c[0], z + c[1] * c[1])
    });
    let r01 = (s01 / (s00 * s11).sqrt()).abs();
    assert!(r.independence.max_abs_correlation >= r01 - 1e-12);
    assert_eq!(r.independence.pairs, 15);
    // JSON round trip
    let json = serde_json::to_string(&r).unwrap();
    let back: SpectrumReport = serde_json::from_str(&json).unwrap();
    assert_eq!(back.variance.len(), 6);
    assert!((back.mean_energy - r.mean_energy).abs() <= 1e-15 * r.mean_energy);
}

#[test]
fn naive_theory_is_phi_m2_phi_and_white_is_one() {
    let mesh = common::blob(2);
    let (mass, pairs) = common::eigen(&mesh, 5);
    let naive = NoiseKind::Naive
        .spectral_variance(&pairs, &mass, 1.0)
        .unwrap();
    for i in 0..5 {
        let want: f64 = (0..mass.len())
            .map(|v| (pairs.vectors[(v, i)] * mass[v]).powi(2))
            .sum();
        assert!((naive[i] - want).abs() < 1e-14 * want);
    }
    let white = NoiseKind::White
        .spectral_variance(&pairs, &mass, 1.0)
        .unwrap();
    assert_eq!(white, vec![1.0; 5]);
    let g = 3.0;
    let nm = NoiseKind::MaternNormalized { c: 0.5 }
        .spectral_variance(&pairs, &mass, g)
        .unwrap();
    assert!((nm[2] - g / (pairs.values[2] + 1.5).powi(2)).abs() < 1e-15);
}

#[test]
fn errors_name_the_problem() {
    let mesh = common::blob(1);
    for (kind, name) in [
        (NoiseKind::Matern { tau: -1.0 }, "tau"),
        (NoiseKind::Matern { tau: f64::NAN }, "tau"),
        (NoiseKind::Matern { tau: f64::INFINITY }, "tau"),
        (NoiseKind::MaternNormalized { c: -1.0 }, "c"),
        (NoiseKind::Explicit { k: 0, tau: 1.0 }, "k"),
        (NoiseKind::Explicit { k: 3, tau: -1.0 }, "tau"),
    ] {
        match NoiseSampler::new(&mesh, kind) {
            Err(NoiseError::InvalidParameter { name: n, .. }) => assert_eq!(n, name),
            other => panic!("{kind:?}: {other:?}"),
        }
    }
    // more eigenpairs than vertices
    let e = NoiseSampler::new(&mesh, NoiseKind::Explicit { k: 1000, tau: 1.0 }).unwrap_err();
    assert!(matches!(e, NoiseError::Solver(_)), "{e}");
    // an unreferenced vertex has zero mass
    let (mut p, f) = mesh.clone().into_parts();
    p.push([5.0, 5.0, 5.0]);
    let lonely = TriMesh::new(p, f).unwrap();
    let e = NoiseSampler::new(&lonely, NoiseKind::White).unwrap_err();
    assert!(
        matches!(e, NoiseError::NonPositiveMass { vertex: 42, .. }),
        "{e}"
    );
    // mass of the wrong length
    let ops = Operators::new(&mesh).unwrap();
    let e =
        NoiseSampler::from_operators(&ops.laplacian, &ops.mass[1..], NoiseKind::White).unwrap_err();
    assert!(matches!(e, NoiseError::SizeMismatch { .. }), "{e}");
    let s = NoiseSampler::from_operators(&ops.laplacian, &ops.mass, NoiseKind::White).unwrap();
    assert!(matches!(
        s.sample(1, 0, 0),
        Err(NoiseError::InvalidParameter {
            name: "channels",
            ..
        })
    ));
    assert_eq!(s.sample(0, 2, 0).unwrap().data().len(), 0);
    assert!(matches!(
        NoiseBatch::from_vec(vec![0.0; 5], 1, 2, 2),
        Err(NoiseError::SizeMismatch { .. })
    ));
    let (mass, pairs) = common::eigen(&mesh, 4);
    assert!(SpectralAnalyzer::new(&pairs, &mass[1..]).is_err());
    assert!(
        SpectralAnalyzer::new(&pairs, &mass)
            .unwrap()
            .report(None)
            .is_err()
    );
    for bad in [
        "",
        "pink",
        "matern:x",
        "matern:1:2",
        "normalized",
        "explicit:-3",
        "explicit:4:0:1",
        "white:3",
    ] {
        assert!(
            matches!(bad.parse::<NoiseKind>(), Err(NoiseError::ParseKind { .. })),
            "{bad:?}"
        );
    }
    for bad in ["matern:-1", "matern:-1e-300", "matern:NaN", "matern:inf"] {
        assert!(
            matches!(
                bad.parse::<NoiseKind>(),
                Err(NoiseError::InvalidParameter { name: "tau", .. })
            ),
            "{bad:?}"
        );
    }
    // tau = 0 (no screening) is allowed
    assert_eq!(
        "matern:0".parse::<NoiseKind>().unwrap(),
        NoiseKind::Matern { tau: 0.0 }
    );
}

fn any_kind() -> impl Strategy<Value = NoiseKind> {
    prop_oneof![
        Just(NoiseKind::Naive),
        Just(NoiseKind::White),
        prop_oneof![Just(0.0), 1e-6f64..1e6].prop_map(|tau| NoiseKind::Matern { tau }),
        (1e-9f64..1e3).prop_map(|c| NoiseKind::MaternNormalized { c }),
        (1e-6f64..1e6, 2u32..=4).prop_map(|(tau, order)| NoiseKind::MaternSmooth { tau, order }),
        (1usize..5000, prop_oneof![Just(0.0), 1e-6f64..1e6])
            .prop_map(|(k, tau)| NoiseKind::Explicit { k, tau }),
    ]
}

fn parts(tau: Option<f64>, c: Option<f64>, k: Option<usize>, order: Option<u32>) -> KindParameters {
    KindParameters { tau, c, k, order }
}

proptest! {
    #[test]
    fn kinds_round_trip_through_text_and_json(kind in any_kind()) {
        prop_assert_eq!(kind.to_string().parse::<NoiseKind>().unwrap(), kind);
        let json = serde_json::to_string(&kind).unwrap();
        prop_assert_eq!(serde_json::from_str::<NoiseKind>(&json).unwrap(), kind);
        let tag = format!("\"kind\":\"{}\"", kind.name().replace('-', "_"));
        prop_assert!(json.contains(&tag), "{} lacks {}", json, tag);
    }

    #[test]
    fn the_long_form_gives_the_same_kind(kind in any_kind()) {
        // every parameter spelled out
        let (tau, c, k, order) = match kind {
            NoiseKind::Naive | NoiseKind::White => (None, None, None, None),
            NoiseKind::Matern { tau } => (Some(tau), None, None, None),
            NoiseKind::MaternNormalized { c } => (None, Some(c), None, None),
            NoiseKind::MaternSmooth { tau, order } => (Some(tau), None, None, Some(order)),
            NoiseKind::Explicit { k, tau } => (Some(tau), None, Some(k), None),
        };
        prop_assert_eq!(NoiseKind::from_parts(kind.kind_name(), parts(tau, c, k, order)).unwrap(), kind);
        // and every parameter the kind does not take refused by name
        let given = [
            ("tau", tau.is_some()),
            ("c", c.is_some()),
            ("k", k.is_some()),
            ("order", order.is_some()),
        ];
        for (p, given) in given {
            if given {
                continue;
            }
            let e = match p {
                "tau" => NoiseKind::from_parts(kind.kind_name(), parts(Some(1.0), c, k, order)),
                "c" => NoiseKind::from_parts(kind.kind_name(), parts(tau, Some(1.0), k, order)),
                "k" => NoiseKind::from_parts(kind.kind_name(), parts(tau, c, Some(3), order)),
                _ => NoiseKind::from_parts(kind.kind_name(), parts(tau, c, k, Some(3))),
            };
            let accepted = match (p, kind.kind_name()) {
                // parameters left at their defaults are accepted when given
                ("tau", KindName::Matern | KindName::Explicit | KindName::MaternSmooth) => true,
                ("c", KindName::MaternNormalized) => true,
                ("k", KindName::Explicit) => true,
                ("order", KindName::MaternSmooth) => true,
                _ => false,
            };
            prop_assert_eq!(e.is_ok(), accepted, "{} given to {}", p, kind);
            if let Err(e) = e {
                prop_assert!(
                    matches!(e, NoiseError::UnusedParameter { parameter, .. } if parameter == p),
                    "{}", e
                );
            }
        }
    }
}

#[test]
fn the_long_form_fills_in_defaults_and_validates() {
    let d = |name| NoiseKind::from_parts(name, KindParameters::default()).unwrap();
    assert_eq!(d(KindName::Matern), "matern".parse().unwrap());
    assert_eq!(d(KindName::Explicit), "explicit:64".parse().unwrap());
    assert_eq!(
        d(KindName::MaternNormalized),
        NoiseKind::MaternNormalized { c: 1e-4 }
    );
    assert_eq!(
        d(KindName::MaternSmooth),
        NoiseKind::MaternSmooth {
            tau: 100.0,
            order: 2
        }
    );
    assert_eq!(d(KindName::MaternSmooth), "matern-smooth".parse().unwrap());
    assert_eq!(
        d(KindName::MaternSmooth),
        "matern-smooth:100".parse().unwrap()
    );
    let e =
        NoiseKind::from_parts(KindName::Matern, parts(Some(-1.0), None, None, None)).unwrap_err();
    assert!(
        matches!(e, NoiseError::InvalidParameter { name: "tau", .. }),
        "{e}"
    );
    let e = NoiseKind::from_parts(
        KindName::MaternNormalized,
        parts(Some(5.0), None, None, None),
    )
    .unwrap_err();
    assert!(e.to_string().contains("give c"), "{e}");
    let e = NoiseKind::from_parts(KindName::Matern, parts(None, None, None, Some(2))).unwrap_err();
    assert!(e.to_string().contains("matern-smooth"), "{e}");
    // smooth Matérn needs screening and an order in 2..=4
    for bad in [
        "matern-smooth:0",
        "matern-smooth:100:1",
        "matern-smooth:100:5",
        "matern-smooth:1:2:3",
    ] {
        let e = bad.parse::<NoiseKind>().unwrap_err();
        assert!(
            e.to_string().contains("tau")
                || e.to_string().contains("order")
                || e.to_string().contains("parameters"),
            "{bad}: {e}"
        );
    }
    let e = "matern-smooth:100:1".parse::<NoiseKind>().unwrap_err();
    assert!(
        matches!(e, NoiseError::InvalidParameter { name: "order", .. }),
        "{e}"
    );
    let e = "matern-smooth:0".parse::<NoiseKind>().unwrap_err();
    assert!(
        matches!(e, NoiseError::InvalidParameter { name: "tau", .. }),
        "{e}"
    );
}

#[test]
fn kind_names_parse_as_the_short_form_writes_them() {
    for name in KindName::ALL {
        assert_eq!(name.as_str().parse::<KindName>().unwrap(), name);
        let kind = NoiseKind::from_parts(name, KindParameters::default()).unwrap();
        assert_eq!(kind.kind_name(), name);
    }
    let e = "Matern".parse::<KindName>().unwrap_err();
    assert!(e.to_string().contains("matern-normalized"), "{e}");
}

#[test]
fn the_summary_beside_a_noise_file_describes_it() {
    let dir = tempfile::tempdir().unwrap();
    let mesh = common::blob(2);
    let sampler = NoiseSampler::new(&mesh, NoiseKind::Matern { tau: 10.0 }).unwrap();
    let (npy, json) = (dir.path().join("n.npy"), dir.path().join("n.json"));
    let mut seen = Vec::new();
    let files = mfm_noise::stream::NoiseFiles {
        mesh: "blob",
        npy: &npy,
        json: &json,
        samples: 3,
        channels: 2,
        seed: 9,
    };
    let (summary, written) = files.write(&sampler, |done| seen.push(done)).unwrap();
    assert_eq!(seen, vec![3]);
    let a = mfm_files::npy::read::<f64>(&npy).unwrap();
    assert_eq!(a.shape, vec![3, mesh.num_vertices(), 2]);
    let batch = sampler.sample_range(0, 3, 2, 9).unwrap();
    assert_eq!(a.values, batch.data());
    let stored: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    assert_eq!(stored["mesh"], "blob");
    assert_eq!(stored["samples"], 3);
    assert_eq!(stored["tau"], 10.0);
    assert_eq!(stored["mean_energy"], summary.mean_energy);
    assert_eq!(written.first_signal, batch.signal(0, 0));
}

#[test]
fn a_measured_spectrum_keeps_the_asked_coefficients_and_compares_meshes() {
    let (coarse, fine) = (common::blob(2), common::blob(3));
    let request = spectrum::SpectrumRequest {
        samples: 64,
        k: 12,
        seed: 3,
        keep: vec![2, 40, 5],
    };
    let mut measured = Vec::new();
    for (name, mesh) in [("coarse", &coarse), ("fine", &fine)] {
        let ops = Operators::new(mesh).unwrap();
        let kind = NoiseKind::Matern { tau: 10.0 };
        let sampler = NoiseSampler::from_operators(&ops.laplacian, &ops.mass, kind).unwrap();
        let mut last = 0;
        let (m, kept) =
            spectrum::MeshSpectrum::measure(name, &ops, &sampler, &request, |d| last = d).unwrap();
        assert_eq!(last, 64);
        // 40 is not below k: left out; the others in the order asked
        assert_eq!(
            kept.iter().map(|(i, c)| (*i, c.len())).collect::<Vec<_>>(),
            vec![(2, 64), (5, 64)]
        );
        assert_eq!(m.report.variance.len(), 12);
        measured.push(m);
    }
    let file = spectrum::SpectrumFile::new(NoiseKind::Matern { tau: 10.0 }, 64, 12, 3, measured);
    assert_eq!(file.comparisons.len(), 1);
    let too_many = spectrum::SpectrumRequest {
        k: coarse.num_vertices() + 1,
        ..request
    };
    let ops = Operators::new(&coarse).unwrap();
    let sampler =
        NoiseSampler::from_operators(&ops.laplacian, &ops.mass, NoiseKind::White).unwrap();
    let e = spectrum::MeshSpectrum::measure("c", &ops, &sampler, &too_many, |_| {}).unwrap_err();
    assert!(matches!(e, NoiseError::InvalidParameter { .. }), "{e}");
}

#[test]
fn a_spectrum_on_given_eigenpairs_is_the_measured_one_and_shows_every_chunk() {
    let mesh = common::blob(2);
    let ops = Operators::new(&mesh).unwrap();
    let sampler =
        NoiseSampler::from_operators(&ops.laplacian, &ops.mass, NoiseKind::Matern { tau: 10.0 })
            .unwrap();
    let request = spectrum::SpectrumRequest {
        samples: 300,
        k: 10,
        seed: 5,
        keep: vec![3],
    };
    let (measured, kept) =
        spectrum::MeshSpectrum::measure("m", &ops, &sampler, &request, |_| {}).unwrap();
    let pairs = spectrum::eigenpairs(&ops.laplacian, &ops.mass, 10).unwrap();
    let mut seen = Vec::new();
    let on = spectrum::MeshSpectrum::measure_on(
        "m",
        &ops,
        &pairs,
        &sampler,
        &request,
        mfm_noise::stream::CHUNK,
        |batch, first| {
            seen.push((first, batch.samples()));
            Ok(())
        },
    )
    .unwrap();
    // the same chunks, so the same bits
    assert_eq!(on.spectrum, measured);
    assert_eq!(on.kept, kept);
    assert_eq!(seen, vec![(0, 256), (256, 44)]);
    assert!(on.sample_seconds >= 0.0 && on.analysis_seconds >= 0.0);
    // k must be the pairs'
    let other = spectrum::SpectrumRequest { k: 9, ..request };
    let e =
        spectrum::MeshSpectrum::measure_on("m", &ops, &pairs, &sampler, &other, 64, |_, _| Ok(()))
            .unwrap_err();
    assert!(matches!(e, NoiseError::InvalidParameter { .. }), "{e}");
}

#[test]
fn tau_below_the_zero_tau_regularization_is_refused_by_name() {
    let mesh = mfm_geometry::procedural::icosphere(2);
    let ops = Operators::new(&mesh).unwrap();
    let gamma = mfm_geometry::operators::gamma(&ops.laplacian, &ops.mass);
    let bound = mfm_noise::sampler::ZERO_TAU_REGULARIZATION * gamma;
    match NoiseSampler::new(&mesh, NoiseKind::Matern { tau: 1e-15 }) {
        Err(NoiseError::InvalidParameter { name, found, .. }) => {
            assert_eq!(name, "tau");
            assert!(found.starts_with("1e-15, below 1e-10 x Gamma"), "{found}");
        }
        other => panic!("expected a refusal, got {other:?}"),
    }
    // the bound itself, and tau = 0, sample finite values
    for tau in [bound, 0.0] {
        let s = NoiseSampler::new(&mesh, NoiseKind::Matern { tau }).unwrap();
        let b = s.sample_range(0, 2, 1, 3).unwrap();
        assert!(b.data().iter().all(|x| x.is_finite()), "tau = {tau}");
    }
    // extreme values print in scientific notation
    assert_eq!(NoiseKind::Matern { tau: 1e300 }.to_string(), "matern:1e300");
}
