//! Sample-quality measures: the generator's own signals score near their
//! floor; flat, noise-only and single-mode sets score far from it.
#![allow(clippy::unwrap_used)]

use mfm_data::gmm::{GmmConfig, GmmGenerator};
use mfm_data::{InMemorySignals, SignalSource};
use mfm_eval::quality::{GmmQualityReport, Quartiles, diversity, fit_bumps};
use mfm_geometry::operators::lumped_mass;
use mfm_geometry::{TriMesh, procedural};
use mfm_noise::{NoiseKind, NoiseSampler};

struct Setup {
    mesh: TriMesh,
    mass: Vec<f64>,
    generator: GmmGenerator,
    reference: InMemorySignals,
}

fn setup() -> Setup {
    let mesh = procedural::icosphere(3); // 642 vertices
    let mass = lumped_mass(&mesh);
    let generator = GmmGenerator::new(&mesh, &GmmConfig::default()).unwrap();
    let reference = generator.generate(24, 1).unwrap();
    Setup {
        mesh,
        mass,
        generator,
        reference,
    }
}

fn report(s: &Setup, generated: &InMemorySignals) -> GmmQualityReport {
    GmmQualityReport::of(&s.generator, &s.mesh, &s.mass, generated, &s.reference).unwrap()
}

#[test]
fn the_generators_own_signals_sit_at_the_floor() {
    let s = setup();
    let own = s.generator.generate(24, 2).unwrap();
    let r = report(&s, &own);
    eprintln!("{}", r.summary());
    assert!(r.floor < 0.1, "floor {}", r.floor);
    let g = &r.generated;
    assert!(g.residual.median < 0.1, "{:?}", g.residual);
    assert!(g.peak.median > 0.95 && g.peak.median < 1.05, "{:?}", g.peak);
    assert!(g.bumps_above_half > 2.7, "{}", g.bumps_above_half);
    assert!(r.within_twice_floor > 0.7, "{}", r.within_twice_floor);
    assert!(r.diversity > 0.8 && r.diversity < 1.25, "{}", r.diversity);
    // the fit finds the generator's centres (or a neighbouring vertex)
    let (centers, _) = s.generator.sample(2, 0).unwrap();
    let found = &g.fits[0].centers;
    let p = s.mesh.positions();
    for c in centers {
        let near = found.iter().any(|&f| {
            let d: f64 = (0..3).map(|k| (p[f][k] - p[c][k]).powi(2)).sum();
            d.sqrt() < 0.5 * s.generator.sigma()
        });
        assert!(near, "centre {c} not found among {found:?}");
    }
}

#[test]
fn flat_noise_and_single_mode_sets_are_far_from_the_floor() {
    let s = setup();
    let v = s.mesh.num_vertices();
    let n = 24;
    // flat: zeros and a constant
    let zeros = InMemorySignals::new(vec![0.0; n * v], n, v, 1).unwrap();
    let r = report(&s, &zeros);
    assert_eq!(r.generated.residual.median, 1.0);
    assert_eq!(r.generated.bumps_above_half, 0.0);
    assert_eq!(r.within_twice_floor, 0.0);
    let constant = InMemorySignals::new(vec![0.3; n * v], n, v, 1).unwrap();
    let r = report(&s, &constant);
    // (bumps can fit part of a constant with any height: only the residual
    // and the peak tell)
    assert!(
        r.generated.residual.median > 0.5,
        "{:?}",
        r.generated.residual
    );
    assert!((r.generated.peak.median - 0.3).abs() < 1e-6);
    assert_eq!(r.within_twice_floor, 0.0);
    // noise with the data's root-mean-square value
    let noise = NoiseSampler::new(&s.mesh, NoiseKind::Matern { tau: 100.0 })
        .unwrap()
        .sample_f32(n, 1, 5)
        .unwrap();
    let raw = noise.data();
    let rms =
        |x: &[f32]| (x.iter().map(|a| f64::from(*a).powi(2)).sum::<f64>() / x.len() as f64).sqrt();
    let k = (rms(s.reference.data()) / rms(raw)) as f32;
    let noisy = InMemorySignals::new(raw.iter().map(|x| x * k).collect(), n, v, 1).unwrap();
    let r = report(&s, &noisy);
    eprintln!("noise: {}", r.summary());
    assert!(
        r.generated.residual.median > 0.5,
        "{:?}",
        r.generated.residual
    );
    assert!(r.generated.bumps_above_half < 1.0);
    assert_eq!(r.within_twice_floor, 0.0);
    // a smeared mean of many signals: low bumps everywhere
    let mut mean = vec![0.0f32; v];
    for i in 0..s.reference.len() {
        mean.iter_mut()
            .zip(s.reference.signal(i))
            .for_each(|(m, x)| *m += x / s.reference.len() as f32);
    }
    let smeared = InMemorySignals::new(mean.repeat(n), n, v, 1).unwrap();
    let r = report(&s, &smeared);
    assert!(
        r.generated.residual.median > 0.3,
        "{:?}",
        r.generated.residual
    );
    assert!(r.generated.peak.median < 0.8, "{:?}", r.generated.peak);
    // single mode: copies of one data signal pass per sample, not as a set
    let one = s.reference.signal(3).to_vec();
    let copies = InMemorySignals::new(one.repeat(n), n, v, 1).unwrap();
    let r = report(&s, &copies);
    assert!(r.generated.residual.median < 0.1);
    assert!(r.diversity < 1e-6, "{}", r.diversity);
    assert!(diversity(&s.mass, &s.reference, &s.reference).unwrap() == 1.0);
    // a single sample is scored, without a diversity
    let single = InMemorySignals::new(one.clone(), 1, v, 1).unwrap();
    let r = report(&s, &single);
    assert!(r.generated.residual.median < 0.1 && r.diversity.is_nan());
    let line = r.summary();
    assert!(
        !line.contains("NaN") && line.contains("needs at least 2 samples"),
        "{line}"
    );
    assert!(diversity(&s.mass, &single, &s.reference).is_err());
}

#[test]
fn one_fit_recovers_heights_of_a_mixture() {
    let s = setup();
    let v = s.mesh.num_vertices();
    // two bumps of heights 0.7 and 1.2 at far-apart vertices
    let p = s.mesh.positions();
    let a = 0;
    let b = (0..v)
        .max_by(|&i, &j| {
            let d = |k: usize| (0..3).map(|c| (p[k][c] - p[a][c]).powi(2)).sum::<f64>();
            d(i).total_cmp(&d(j))
        })
        .unwrap();
    let (ba, bb) = (s.generator.bump(a).unwrap(), s.generator.bump(b).unwrap());
    let signal: Vec<f64> = (0..v).map(|i| 0.7 * ba[i] + 1.2 * bb[i]).collect();
    let fit = fit_bumps(&s.generator, &s.mesh, &s.mass, &signal).unwrap();
    assert!(fit.residual < 1e-6, "{fit:?}");
    let mut pairs: Vec<(usize, f64)> = fit
        .centers
        .iter()
        .copied()
        .zip(fit.heights.iter().copied())
        .filter(|(_, h)| h.abs() > 1e-6)
        .collect();
    pairs.sort_by_key(|p| p.0);
    assert_eq!(pairs.len(), 2, "{fit:?}");
    assert_eq!((pairs[0].0, pairs[1].0), (a.min(b), a.max(b)));
    let height = |c: usize| pairs.iter().find(|p| p.0 == c).unwrap().1;
    assert!(
        (height(a) - 0.7).abs() < 1e-6 && (height(b) - 1.2).abs() < 1e-6,
        "{pairs:?}"
    );
    assert_eq!(fit.bumps_above_half, 2);
    assert_eq!(fit.peak, signal.iter().copied().fold(f64::MIN, f64::max));
    assert!(Quartiles::of(&signal).median < fit.peak);
    // wrong sizes are errors
    assert!(fit_bumps(&s.generator, &s.mesh, &s.mass, &signal[1..]).is_err());
}
