//! Datasets on disk, the GMM generator and the GMM experiment's meshes.

#![allow(clippy::unwrap_used)]

use std::fs::OpenOptions;
use std::path::Path;

use mfm_data::dataset::{Dataset, MANIFEST_FILE, MESH_FILE, Manifest, SIGNALS_FILE, WriteOptions};
use mfm_data::experiment::{GmmMeshes, HalfDensity, split_x};
use mfm_data::gmm::{GENERATOR_NAME, GmmConfig, GmmDistance, GmmGenerator, generate};
use mfm_data::{DataError, InMemorySignals, SignalSource};
use mfm_files::FileError;
use mfm_geometry::geodesic::HeatGeodesics;
use mfm_geometry::operators::lumped_mass;
use mfm_geometry::{TriMesh, procedural};
use mfm_processing::refine::{RefineCriterion, refine_region};
use npyz::WriterBuilder;

// ---------------------------------------------------------------- datasets

fn ramp(n: usize, v: usize, c: usize) -> InMemorySignals {
    let data = (0..n * v * c).map(|i| i as f32 * 0.25 - 3.0).collect();
    InMemorySignals::new(data, n, v, c).unwrap()
}

fn write_npy(path: &Path, dtype: &str, shape: &[u64], values: usize) {
    let file = std::fs::File::create(path).unwrap();
    let dtype = npyz::DType::Plain(dtype.parse().unwrap());
    if dtype.num_bytes() == Some(8) {
        let mut w = npyz::WriteOptions::<f64>::new()
            .dtype(dtype)
            .shape(shape)
            .writer(std::io::BufWriter::new(file))
            .begin_nd()
            .unwrap();
        w.extend((0..values).map(|i| i as f64)).unwrap();
        w.finish().unwrap();
    } else {
        let mut w = npyz::WriteOptions::<f32>::new()
            .dtype(dtype)
            .shape(shape)
            .writer(std::io::BufWriter::new(file))
            .begin_nd()
            .unwrap();
        w.extend((0..values).map(|i| i as f32)).unwrap();
        w.finish().unwrap();
    }
}

fn format_error(err: DataError) -> (std::path::PathBuf, String) {
    match err {
        DataError::Files(FileError::Format { path, message }) => (path, message),
        other => panic!("expected a format error, got {other:?}"),
    }
}

#[test]
fn dataset_round_trip_and_subsets() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("nested").join("ds");
    let mesh = procedural::icosphere(1);
    let signals = ramp(6, mesh.num_vertices(), 2);
    let manifest = Manifest::new("ramp", serde_json::json!({ "step": 0.25 }))
        .with_seed(11)
        .with_provenance("unit test");
    let ds = Dataset::write(&dir, &mesh, &signals, manifest).unwrap();
    assert_eq!((ds.len(), ds.num_vertices(), ds.channels()), (6, 42, 2));

    let ds = Dataset::open(&dir).unwrap();
    assert_eq!(ds.mesh(), &mesh);
    let m = ds.manifest();
    assert_eq!(
        (m.num_signals, m.num_vertices, m.channels, m.seed),
        (6, 42, 2, Some(11))
    );
    assert_eq!(m.generator, "ramp");
    assert_eq!(m.generator_params["step"], 0.25);
    assert_eq!(m.provenance, "unit test");
    assert!(m.tool_version.starts_with("mfm-fm "));
    assert_eq!(ds.load_all().unwrap(), signals);

    // any subset, in any order, with repeats, equals the slices
    let n = 42 * 2;
    for idx in [vec![3usize], vec![5, 0, 1, 2], vec![4, 4, 1], vec![]] {
        let mut out = vec![0.0f32; idx.len() * n];
        ds.read_into(&idx, &mut out).unwrap();
        let mut want = vec![0.0f32; idx.len() * n];
        signals.read_into(&idx, &mut want).unwrap();
        assert_eq!(out, want, "indices {idx:?}");
    }
    let mut out = vec![0.0f32; n];
    assert!(matches!(
        ds.read_into(&[6], &mut out),
        Err(DataError::SizeMismatch { .. })
    ));
    assert!(ds.read_into(&[0, 1], &mut out).is_err());

    // no temporary folders are left next to it
    let siblings: Vec<_> = std::fs::read_dir(dir.parent().unwrap()).unwrap().collect();
    assert_eq!(siblings.len(), 1);
}

#[test]
fn dataset_refuses_to_overwrite_unless_asked() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("ds");
    let mesh = procedural::icosphere(0);
    let a = ramp(2, 12, 1);
    Dataset::write(&dir, &mesh, &a, Manifest::new("a", serde_json::Value::Null)).unwrap();
    let b = InMemorySignals::new(vec![1.0; 36], 3, 12, 1).unwrap();
    let err =
        Dataset::write(&dir, &mesh, &b, Manifest::new("b", serde_json::Value::Null)).unwrap_err();
    assert!(
        matches!(&err, DataError::Files(FileError::Io { path, .. }) if path == &dir),
        "{err}"
    );
    // untouched
    assert_eq!(Dataset::open(&dir).unwrap().load_all().unwrap(), a);
    let ds = Dataset::write_with(
        &dir,
        &mesh,
        &b,
        Manifest::new("b", serde_json::Value::Null),
        WriteOptions { overwrite: true },
    )
    .unwrap();
    assert_eq!(ds.load_all().unwrap(), b);
    assert_eq!(ds.manifest().generator, "b");
    // an existing empty folder is fine
    let empty = tmp.path().join("empty");
    std::fs::create_dir(&empty).unwrap();
    Dataset::write(
        &empty,
        &mesh,
        &a,
        Manifest::new("a", serde_json::Value::Null),
    )
    .unwrap();
    // signals on another mesh are refused before anything is written
    let other = tmp.path().join("other");
    assert!(matches!(
        Dataset::write(
            &other,
            &procedural::icosphere(1),
            &a,
            Manifest::new("a", serde_json::Value::Null)
        ),
        Err(DataError::SizeMismatch { .. })
    ));
    assert!(!other.exists());
}

fn small_dataset(dir: &Path) -> (TriMesh, InMemorySignals) {
    let mesh = procedural::icosphere(1);
    let signals = ramp(5, 42, 1);
    Dataset::write(
        dir,
        &mesh,
        &signals,
        Manifest::new("ramp", serde_json::Value::Null),
    )
    .unwrap();
    (mesh, signals)
}

#[test]
fn truncated_signals_give_a_clear_error() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("ds");
    small_dataset(&dir);
    let npy = dir.join(SIGNALS_FILE);
    let len = std::fs::metadata(&npy).unwrap().len();
    OpenOptions::new()
        .write(true)
        .open(&npy)
        .unwrap()
        .set_len(len - 10)
        .unwrap();
    let (path, message) = format_error(Dataset::open(&dir).unwrap_err());
    assert_eq!(path, npy);
    assert!(message.contains("truncated"), "{message}");

    // a header cut in the middle
    OpenOptions::new()
        .write(true)
        .open(&npy)
        .unwrap()
        .set_len(20)
        .unwrap();
    let (path, message) = format_error(Dataset::open(&dir).unwrap_err());
    assert_eq!(path, npy);
    assert!(message.contains(".npy"), "{message}");
}

#[test]
fn rows_are_read_on_demand() {
    // truncating the file after opening breaks only the rows that are gone:
    // the dataset reads rows from disk, not from a copy made at open
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("ds");
    let (_, signals) = small_dataset(&dir);
    let ds = Dataset::open(&dir).unwrap();
    let npy = dir.join(SIGNALS_FILE);
    let len = std::fs::metadata(&npy).unwrap().len();
    OpenOptions::new()
        .write(true)
        .open(&npy)
        .unwrap()
        .set_len(len - 4 * 42)
        .unwrap();
    let mut out = vec![0.0f32; 2 * 42];
    ds.read_into(&[1, 3], &mut out).unwrap();
    assert_eq!(&out[..42], signals.signal(1));
    assert_eq!(&out[42..], signals.signal(3));
    let err = ds.read_into(&[4, 0], &mut out).unwrap_err();
    let (path, _) = format_error(err);
    assert_eq!(path, npy);
}

#[test]
fn wrong_shape_dtype_and_manifest_are_named() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("ds");
    small_dataset(&dir);
    let npy = dir.join(SIGNALS_FILE);

    // one vertex too many
    write_npy(&npy, "<f4", &[5, 43, 1], 5 * 43);
    let (path, message) = format_error(Dataset::open(&dir).unwrap_err());
    assert_eq!(path, npy);
    assert!(
        message.contains(MESH_FILE) && message.contains("42"),
        "{message}"
    );

    // rank 2
    write_npy(&npy, "<f4", &[5, 42], 5 * 42);
    let (_, message) = format_error(Dataset::open(&dir).unwrap_err());
    assert!(message.contains("3 axes"), "{message}");

    // float64
    write_npy(&npy, "<f8", &[5, 42, 1], 5 * 42);
    let (_, message) = format_error(Dataset::open(&dir).unwrap_err());
    assert!(message.contains("dtype"), "{message}");

    // right vertices, but the manifest says 5 signals
    write_npy(&npy, "<f4", &[4, 42, 1], 4 * 42);
    let (_, message) = format_error(Dataset::open(&dir).unwrap_err());
    assert!(message.contains(MANIFEST_FILE), "{message}");

    // a corrupt manifest
    write_npy(&npy, "<f4", &[5, 42, 1], 5 * 42);
    assert!(Dataset::open(&dir).is_ok());
    let manifest = dir.join(MANIFEST_FILE);
    std::fs::write(&manifest, b"{ \"format_version\": 1, ").unwrap();
    let (path, _) = format_error(Dataset::open(&dir).unwrap_err());
    assert_eq!(path, manifest);

    // a future format version
    let mut m = Manifest::new("ramp", serde_json::Value::Null);
    m.format_version = 99;
    m.num_signals = 5;
    m.num_vertices = 42;
    m.channels = 1;
    std::fs::write(&manifest, serde_json::to_vec(&m).unwrap()).unwrap();
    let (path, message) = format_error(Dataset::open(&dir).unwrap_err());
    assert_eq!(path, manifest);
    assert!(message.contains("99"), "{message}");

    // missing files name themselves
    std::fs::remove_file(&manifest).unwrap();
    assert!(
        matches!(Dataset::open(&dir), Err(DataError::Files(FileError::Io { path, .. })) if path == manifest)
    );
    assert!(matches!(
        Dataset::open(tmp.path().join("nope")),
        Err(DataError::Files(FileError::Io { .. }))
    ));
}

// ---------------------------------------------------------------- GMM

#[test]
fn gmm_bumps_peak_at_separated_centers() {
    let mesh = procedural::icosphere(3);
    let config = GmmConfig::default();
    let generator = GmmGenerator::new(&mesh, &config).unwrap();
    let sigma = 0.06 * (mesh.total_area()).sqrt();
    assert!((generator.sigma() - sigma).abs() < 1e-12);
    let geo = HeatGeodesics::new(&mesh).unwrap();
    for index in 0..6 {
        let (centers, values) = generator.sample(5, index).unwrap();
        assert_eq!(centers.len(), 3);
        let fields: Vec<Vec<f64>> = centers.iter().map(|&c| geo.distance(c).unwrap()).collect();
        // separation, measured as the generator does (from the earlier center)
        for (i, field) in fields.iter().enumerate() {
            for (j, &later) in centers.iter().enumerate().skip(i + 1) {
                assert!(
                    field[later] >= 4.0 * sigma,
                    "centers {i} and {j} are {} apart",
                    field[later]
                );
            }
        }
        // the values are the sum of Gaussians of the heat-method distance
        for (v, &x) in values.iter().enumerate() {
            let want: f64 = fields
                .iter()
                .map(|f| (-f[v] * f[v] / (2.0 * sigma * sigma)).exp())
                .sum();
            assert!(
                (f64::from(x) - want).abs() < 1e-5,
                "vertex {v}: {x} vs {want}"
            );
            assert!((0.0..=1.0 + 2.0 * (-8.0f32).exp() + 1e-6).contains(&x));
        }
        for &c in &centers {
            assert!(values[c] >= 1.0 - 1e-6);
        }
        let argmax = (0..values.len())
            .max_by(|&a, &b| values[a].total_cmp(&values[b]))
            .unwrap();
        assert!(centers.contains(&argmax));
    }
}

#[test]
fn euclidean_bumps_match_an_independent_formula() {
    let mesh = procedural::icosphere(2);
    let config = GmmConfig {
        distance: GmmDistance::Euclidean,
        bumps: 2,
        sigma: 0.1,
        min_separation: 3.0,
        ..GmmConfig::default()
    };
    let generator = GmmGenerator::new(&mesh, &config).unwrap();
    let sigma = 0.1 * mesh.total_area().sqrt();
    let p = mesh.positions();
    let dist = |a: usize, b: usize| {
        let d = [p[a][0] - p[b][0], p[a][1] - p[b][1], p[a][2] - p[b][2]];
        (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt()
    };
    for index in 0..10 {
        let (c, values) = generator.sample(1, index).unwrap();
        assert!(dist(c[0], c[1]) >= 3.0 * sigma - 1e-6);
        for (v, &x) in values.iter().enumerate() {
            let want: f64 = c
                .iter()
                .map(|&k| (-dist(v, k).powi(2) / (2.0 * sigma * sigma)).exp())
                .sum();
            assert!((f64::from(x) - want).abs() < 1e-5);
        }
    }
}

/// A 2 x 2 square whose left half is refined 4 times: the left half holds
/// most vertices but only half of the area.
fn lopsided_grid() -> TriMesh {
    let grid = procedural::plane_grid(8, 8, 2.0, 2.0).unwrap();
    refine_region(&grid, |c| c[0] < 0.0, RefineCriterion::Rounds(4)).unwrap()
}

#[test]
fn centers_follow_area_not_vertex_count() {
    let mesh = lopsided_grid();
    let p = mesh.positions();
    let mass = lumped_mass(&mesh);
    let total: f64 = mass.iter().sum();
    let quadrant = |v: usize| usize::from(p[v][0] < 0.0) * 2 + usize::from(p[v][1] < 0.0);
    let mut area = [0.0f64; 4];
    let mut vertices = [0usize; 4];
    for v in 0..p.len() {
        area[quadrant(v)] += mass[v] / total;
        vertices[quadrant(v)] += 1;
    }
    let left_area = area[2] + area[3];
    let left_vertices = (vertices[2] + vertices[3]) as f64 / p.len() as f64;
    assert!(left_vertices > 0.8 && (0.4..0.5).contains(&left_area));

    let config = GmmConfig {
        bumps: 1,
        ..GmmConfig::default()
    };
    let generator = GmmGenerator::new(&mesh, &config).unwrap();
    let draws = 4000;
    let mut counts = [0usize; 4];
    for i in 0..draws {
        let c = generator.centers(3, i).unwrap();
        counts[quadrant(c[0])] += 1;
    }
    // Pearson chi-square against the mass fractions, 3 degrees of freedom:
    // P(chi2 > 16.27) = 0.001
    let chi2: f64 = (0..4)
        .map(|q| {
            let e = area[q] * draws as f64;
            (counts[q] as f64 - e).powi(2) / e
        })
        .sum();
    assert!(
        chi2 < 16.27,
        "chi2 {chi2}, counts {counts:?}, area {area:?}"
    );
    let left = (counts[2] + counts[3]) as f64 / draws as f64;
    assert!(
        (left - left_area).abs() < 0.03,
        "{left} vs area {left_area}"
    );
    assert!((left - left_vertices).abs() > 0.3);
}

#[test]
fn generation_is_deterministic_for_any_thread_count() {
    let mesh = procedural::icosphere(2);
    let config = GmmConfig::default();
    let run = |threads: usize, n: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| generate(&mesh, &config, n, 99).unwrap())
    };
    let one = run(1, 12);
    let three = run(3, 12);
    assert_eq!(one, three);
    // sample i does not depend on how many are requested
    let fewer = run(2, 5);
    assert_eq!(fewer.data(), &one.data()[..5 * mesh.num_vertices()]);
    // nor on the cache
    let uncached = GmmGenerator::new(&mesh, &config)
        .unwrap()
        .with_cache_limit(0)
        .generate(12, 99)
        .unwrap();
    assert_eq!(uncached, one);
    // nor on whether the fields were precomputed in blocks (60 samples x 3
    // bumps >= V / 2 triggers it) or solved one at a time
    let blocked = run(2, 60);
    let single = GmmGenerator::new(&mesh, &config)
        .unwrap()
        .with_cache_limit(0)
        .generate(60, 99)
        .unwrap();
    assert_eq!(blocked, single);
    // another seed differs
    assert_ne!(generate(&mesh, &config, 12, 100).unwrap(), one);
}

#[test]
fn gmm_is_scale_free_and_reports_progress() {
    let mesh = procedural::icosphere(2);
    let big = mesh.transformed(5.0, [1.0, 2.0, 3.0]);
    let config = GmmConfig::default();
    let a = generate(&mesh, &config, 4, 7).unwrap();
    let b = generate(&big, &config, 4, 7).unwrap();
    for (x, y) in a.data().iter().zip(b.data()) {
        assert!((x - y).abs() < 1e-4, "{x} vs {y}");
    }
    let calls = std::sync::atomic::AtomicUsize::new(0);
    let callback = |done: usize, total: usize| {
        assert!(done >= 1 && done <= total && total == 6);
        calls.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    };
    let options = mfm_data::gmm::GenerateOptions {
        on_progress: Some(&callback),
        ..Default::default()
    };
    GmmGenerator::new(&mesh, &config)
        .unwrap()
        .generate_with(6, 7, &options)
        .unwrap();
    assert_eq!(calls.load(std::sync::atomic::Ordering::Relaxed), 6);
}

#[test]
fn gmm_config_checks_and_records_itself() {
    let mesh = procedural::icosphere(1);
    for bad in [
        GmmConfig {
            bumps: 0,
            ..GmmConfig::default()
        },
        GmmConfig {
            sigma: -1.0,
            ..GmmConfig::default()
        },
        GmmConfig {
            min_separation: f64::NAN,
            ..GmmConfig::default()
        },
        GmmConfig {
            heat_time_factor: 0.0,
            ..GmmConfig::default()
        },
    ] {
        assert!(matches!(
            GmmGenerator::new(&mesh, &bad),
            Err(DataError::Config(_))
        ));
    }
    // impossible separation: a clear error, not a hang
    let crowded = GmmConfig {
        bumps: 3,
        min_separation: 100.0,
        max_attempts: 50,
        ..GmmConfig::default()
    };
    let err = generate(&mesh, &crowded, 1, 0).unwrap_err();
    assert!(err.to_string().contains("min_separation"), "{err}");

    // manifest parameters round trip, through a written dataset
    let config = GmmConfig {
        sigma: 0.08,
        ..GmmConfig::default()
    };
    let signals = generate(&mesh, &config, 3, 1).unwrap();
    let tmp = tempfile::tempdir().unwrap();
    let manifest = Manifest::new(GENERATOR_NAME, config.manifest_params()).with_seed(1);
    let ds = Dataset::write(tmp.path().join("gmm"), &mesh, &signals, manifest).unwrap();
    let back = GmmConfig::from_manifest_params(&ds.manifest().generator_params).unwrap();
    assert_eq!(back, config);
    assert_eq!(ds.load_all().unwrap(), signals);
    assert!(GmmConfig::from_manifest_params(&serde_json::json!({ "bumpz": 2 })).is_err());
    let partial: GmmConfig = toml::from_str("bumps = 2").unwrap();
    assert_eq!(
        partial,
        GmmConfig {
            bumps: 2,
            ..GmmConfig::default()
        }
    );
}

// ---------------------------------------------------------------- meshes

/// Vertices per unit area on each side of `cut` (area from the lumped mass).
fn densities(mesh: &TriMesh, cut: f64) -> (f64, f64) {
    let mass = lumped_mass(mesh);
    let (mut nl, mut al, mut nr, mut ar) = (0.0, 0.0, 0.0, 0.0);
    for (p, m) in mesh.positions().iter().zip(&mass) {
        if p[0] < cut {
            nl += 1.0;
            al += m;
        } else {
            nr += 1.0;
            ar += m;
        }
    }
    (nl / al, nr / ar)
}

#[test]
fn builtin_meshes_are_one_surface_two_triangulations() {
    let meshes = GmmMeshes::builtin().unwrap();
    let (train, test) = (&meshes.train, &meshes.test);
    assert!((1000..=3000).contains(&train.num_vertices()));
    let (a, b) = (train.total_area(), test.total_area());
    assert!((a - b).abs() < 1e-9 * a, "areas {a} vs {b}");
    // every training vertex is still there, unmoved
    assert_eq!(&test.positions()[..train.num_vertices()], train.positions());
    let cut = split_x(train);
    assert!((split_x(test) - cut).abs() < 1e-9);
    let (train_l, train_r) = densities(train, cut);
    let (test_l, test_r) = densities(test, cut);
    assert!(
        (train_l / train_r - 1.0).abs() < 0.1,
        "train {train_l} / {train_r}"
    );
    assert!(test_l / test_r > 3.0, "test {test_l} / {test_r}");
    assert!((test_r / train_r - 1.0).abs() < 0.15);
    mfm_geometry::validate::validate(test).unwrap();
}

#[test]
fn coarsened_half_keeps_the_surface_close() {
    let base = procedural::blob(3).unwrap();
    let meshes = GmmMeshes::from_base(base, HalfDensity::Coarsen { factor: 4.0 }).unwrap();
    let (a, b) = (meshes.train.total_area(), meshes.test.total_area());
    assert!((a - b).abs() < 0.03 * a, "areas {a} vs {b}");
    let cut = split_x(&meshes.train);
    let (l, r) = densities(&meshes.test, cut);
    assert!(r / l > 2.0, "test densities {l} / {r}");
    mfm_geometry::validate::validate(&meshes.test).unwrap();
    assert!(
        GmmMeshes::from_base(procedural::icosphere(1), HalfDensity::Refine { rounds: 0 }).is_err()
    );
    assert!(
        GmmMeshes::from_base(
            procedural::icosphere(1),
            HalfDensity::Coarsen { factor: 1.0 }
        )
        .is_err()
    );
}

/// The experiment layout written by `GmmExperiment`: the train set is
/// returned, the reference set is held out (its own seed, on the test mesh)
/// and the test mesh itself is not written.
#[test]
fn gmm_experiment_layout() {
    use mfm_data::gmm::GenerateOptions;
    use mfm_data::layout::{self, GmmExperiment};
    let meshes = GmmMeshes::from_base(procedural::icosphere(2), HalfDensity::default()).unwrap();
    let config = GmmConfig {
        distance: GmmDistance::Euclidean,
        ..GmmConfig::default()
    };
    let dir = tempfile::tempdir().unwrap();
    let experiment = GmmExperiment {
        config: &config,
        train_mesh: &meshes.train,
        test_mesh: &meshes.test,
        source: "icosphere(2)",
        train: 6,
        reference: 12,
        seed: 3,
    };
    let train = experiment
        .write(dir.path(), &GenerateOptions::default())
        .unwrap();
    assert_eq!(train.len(), 6);
    let reference = Dataset::open(dir.path().join(layout::REFERENCE)).unwrap();
    assert_eq!(reference.manifest().seed, Some(layout::held_out_seed(3)));
    assert_eq!(reference.num_vertices(), meshes.test.num_vertices());
    assert!(!dir.path().join(layout::TEST_MESH).exists());
}
