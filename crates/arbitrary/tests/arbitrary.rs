//! The arbitrary-source model end to end at toy size: a pairs dataset of a
//! capsule, the eigenvector predictor, the flow, sampling on a held-out
//! shape of the template and on a held-out shape of another triangulation,
//! and an interrupted run resumed to the same weights.
#![allow(clippy::unwrap_used)]

use std::path::Path;
use std::sync::atomic::AtomicBool;

use mfm_arbitrary::flow::{self, ArbitrarySampler, FlowConfig};
use mfm_arbitrary::predictor::{self, EigenPredictor, PredictorConfig};
use mfm_data::dataset::Dataset;
use mfm_data::deformations::{self, DeformMeshes};
use mfm_data::pairs::{self, PairSpace};
use mfm_deform::ShapeFamily;
use mfm_geometry::procedural;

struct Toy {
    meshes: DeformMeshes,
    space: PairSpace,
}

fn toy() -> Toy {
    let capsule = procedural::capsule(0.5, 0.75, 10, 24).unwrap();
    let meshes = DeformMeshes::from_mesh(&capsule, 300).unwrap();
    let poses = deformations::space_for(&meshes.original, 2, 0.15, 0.4, 0.08).unwrap();
    let family = ShapeFamily::auto(&meshes.original, 3).unwrap();
    Toy {
        meshes,
        space: PairSpace {
            family,
            poses,
            poses_per_shape: 2,
        },
    }
}

fn write(t: &Toy, dir: &Path, mesh: &mfm_geometry::TriMesh, seed: u64, shapes: usize) -> Dataset {
    pairs::write_dataset(
        dir,
        mesh,
        &t.space,
        seed,
        0..shapes,
        t.meshes.normalization,
        t.meshes.frame,
        "test",
        "test",
        false,
    )
    .unwrap()
}

fn tiny_predictor() -> PredictorConfig {
    let mut c = PredictorConfig::cpu();
    c.eigenvectors = 6;
    c.width = 8;
    c.blocks = 1;
    c.schedule.steps = 6;
    c.schedule.batch = 2;
    c.schedule.checkpoint_every = 3;
    c.schedule.milestones = vec![];
    c
}

fn tiny_flow() -> FlowConfig {
    let mut c = FlowConfig::cpu();
    c.width = 8;
    c.blocks = 1;
    c.ode_steps = 3;
    c.schedule.steps = 6;
    c.schedule.batch = 2;
    c.schedule.checkpoint_every = 3;
    c.schedule.milestones = vec![];
    c
}

#[test]
fn trains_and_samples_on_unseen_sources_of_any_triangulation() {
    let t = toy();
    let dir = tempfile::tempdir().unwrap();
    let train = write(&t, &dir.path().join("train"), &t.meshes.coarse, 1, 3);
    let stop = AtomicBool::new(false);
    let p_dir = dir.path().join("predictor");
    let report = predictor::train(&p_dir, train.dir(), &tiny_predictor(), &stop, false).unwrap();
    assert!(report.finished && report.model.is_some());
    let eigen = EigenPredictor::load(&p_dir).unwrap();
    assert_eq!(eigen.spec().eigenvalues.len(), 6);

    // the flow refuses a dataset that is not pairs and an unfinished predictor
    let gmm_like = deformations::write_dataset(
        &dir.path().join("deform"),
        &t.meshes.coarse,
        &t.space.poses,
        1,
        0..2,
        t.meshes.normalization,
        t.meshes.frame,
        "coarse",
        "test",
        false,
    )
    .unwrap();
    let e = flow::train(
        &dir.path().join("bad"),
        gmm_like.dir(),
        &p_dir,
        &tiny_flow(),
        &stop,
        false,
    )
    .unwrap_err();
    assert!(e.to_string().contains("not a pairs dataset"), "{e}");
    let e = flow::train(
        &dir.path().join("bad2"),
        train.dir(),
        &dir.path().join("nowhere"),
        &tiny_flow(),
        &stop,
        false,
    )
    .unwrap_err();
    assert!(e.to_string().contains("nowhere"), "{e}");

    let f_dir = dir.path().join("flow");
    let report = flow::train(&f_dir, train.dir(), &p_dir, &tiny_flow(), &stop, false).unwrap();
    assert!(report.finished);
    assert!(report.last_loss.unwrap().is_finite());
    let sampler = ArbitrarySampler::load(&f_dir).unwrap();
    // the ablation without the positional encoding trains and samples too,
    // and gives other targets from the same noise
    let mut plain = tiny_flow();
    plain.eigenvectors = false;
    let n_dir = dir.path().join("plain");
    flow::train(&n_dir, train.dir(), &p_dir, &plain, &stop, false).unwrap();
    let ablated = ArbitrarySampler::load(&n_dir).unwrap();
    assert!(!ablated.spec().config.eigenvectors);
    let probe = train
        .mesh()
        .with_positions(train.load_all().unwrap().positions(0))
        .unwrap();
    let (a, b) = (
        ablated.sample(&probe, 0, 1, 7).unwrap(),
        sampler.sample(&probe, 0, 1, 7).unwrap(),
    );
    assert!(a[0].iter().flatten().all(|x| x.is_finite()));
    assert_ne!(a, b);

    // unseen shapes: the same connectivity, and another triangulation
    let held = write(&t, &dir.path().join("held"), &t.meshes.coarse, 99, 1);
    let remeshed = write(&t, &dir.path().join("remeshed"), &t.meshes.eval, 99, 1);
    for set in [&held, &remeshed] {
        let mesh = set.mesh();
        let source = mesh
            .with_positions(set.load_all().unwrap().positions(0))
            .unwrap();
        let out = sampler.sample(&source, 0, 2, 7).unwrap();
        assert_eq!(out.len(), 2);
        assert!(out.iter().all(|s| s.len() == mesh.num_vertices()));
        assert!(out.iter().flatten().flatten().all(|x| x.is_finite()));
        // the same seed and index give the same sample; another index another
        let again = sampler.sample(&source, 1, 1, 7).unwrap();
        assert_eq!(again[0], out[1]);
        assert_ne!(out[0], out[1]);
        // generated targets sit where the source is, at its size
        let (lo, hi) = source.bounding_box();
        let centre: Vec<f64> = (0..3).map(|a| 0.5 * (lo[a] + hi[a])).collect();
        let n = out[0].len() as f64;
        for a in 0..3 {
            let mean = out[0].iter().map(|p| p[a]).sum::<f64>() / n;
            assert!(
                (mean - centre[a]).abs() < 0.5,
                "axis {a}: {mean} vs {}",
                centre[a]
            );
        }
        let eigen = sampler.eigenvectors_on(&source).unwrap();
        assert_eq!(eigen.len(), mesh.num_vertices() * 6);
    }
}

#[test]
fn an_interrupted_run_resumes_to_the_same_weights() {
    let t = toy();
    let dir = tempfile::tempdir().unwrap();
    let train = write(&t, &dir.path().join("train"), &t.meshes.coarse, 1, 2);
    let stop = AtomicBool::new(false);
    let whole = dir.path().join("whole");
    predictor::train(&whole, train.dir(), &tiny_predictor(), &stop, false).unwrap();
    // a copy of the run as it was after the first checkpoint (step 3)
    let cut = dir.path().join("cut");
    std::fs::create_dir(&cut).unwrap();
    for name in ["predictor.json", "targets.npy", "train_log.csv"] {
        std::fs::copy(whole.join(name), cut.join(name)).unwrap();
    }
    let ck = mfm_train::checkpoint::checkpoint_dir(&whole, 3);
    let dest = mfm_train::checkpoint::checkpoint_dir(&cut, 3);
    std::fs::create_dir_all(&dest).unwrap();
    for e in std::fs::read_dir(&ck).unwrap() {
        let e = e.unwrap();
        std::fs::copy(e.path(), dest.join(e.file_name())).unwrap();
    }
    let report = predictor::train(&cut, train.dir(), &tiny_predictor(), &stop, false).unwrap();
    assert_eq!((report.start_step, report.end_step), (3, 6));
    assert_eq!(
        std::fs::read(whole.join("model.safetensors")).unwrap(),
        std::fs::read(cut.join("model.safetensors")).unwrap()
    );
    // the log has one row per 10 steps or the last: the same rows, their
    // averages over steps before and after the interruption included (the
    // row in progress is kept in the checkpoint); only the clock differs
    let rows = |run: &std::path::Path| -> Vec<String> {
        std::fs::read_to_string(run.join("train_log.csv"))
            .unwrap()
            .lines()
            .map(|l| {
                l.rsplit_once(',')
                    .map_or(l, |(row, _seconds)| row)
                    .to_owned()
            })
            .collect()
    };
    assert_eq!(rows(&whole), rows(&cut));
    assert_eq!(rows(&cut).len(), 2);
    // another configuration in the same folder is refused
    let mut other = tiny_predictor();
    other.width = 16;
    let e = predictor::train(&cut, train.dir(), &other, &stop, false).unwrap_err();
    assert!(e.to_string().contains("another configuration"), "{e}");
}

/// The arbitrary-source trainings run on the training loop every flow run
/// uses, so they have its features: a warm-up and cosine rate, no
/// clipping, a weight average that the finished model is, snapshots kept
/// at chosen steps, a log row per step; and an interrupted run with all of
/// them on resumes to the same weights, average and log.
#[test]
fn a_predictor_run_has_every_feature_of_the_training_loop() {
    let t = toy();
    let dir = tempfile::tempdir().unwrap();
    let train = write(&t, &dir.path().join("train"), &t.meshes.coarse, 1, 2);
    let stop = AtomicBool::new(false);
    let mut c = tiny_predictor();
    c.schedule.gamma = 1.0;
    c.schedule.lr_schedule = Some(mfm_train::LrSchedule::CosineOverRun {
        warmup_fraction: 0.34,
        floor: 1e-5,
    });
    c.schedule.grad_clip = 0.0;
    c.schedule.ema = 0.5;
    c.schedule.keep_checkpoints = 1;
    c.schedule.keep_at = vec![2];
    c.schedule.log_every = 1;
    let whole = dir.path().join("whole");
    let report = predictor::train(&whole, train.dir(), &c, &stop, false).unwrap();
    assert!(report.finished);
    let steps: Vec<u64> = mfm_train::checkpoint::list_checkpoints(&whole)
        .unwrap()
        .iter()
        .map(|c| c.step)
        .collect();
    assert_eq!(steps, [2, 6], "the newest, and the snapshot at step 2");
    let log = std::fs::read_to_string(whole.join("train_log.csv")).unwrap();
    let rates: Vec<f64> = log
        .lines()
        .skip(1)
        .map(|l| l.split(',').nth(2).unwrap().parse().unwrap())
        .collect();
    let expected: Vec<f64> = (0..6).map(|s| c.schedule.lr_at(s)).collect();
    assert_eq!(rates, expected, "a row per step at the cosine's rates");
    assert!(rates[1] > rates[0] && rates[5] < rates[2], "{rates:?}");
    // the finished model is the average: in the last checkpoint beside the
    // trained weights, and not equal to them
    let last = mfm_train::checkpoint::checkpoint_dir(&whole, 6);
    let average = std::fs::read(last.join(mfm_train::checkpoint::EMA_FILE)).unwrap();
    assert_eq!(
        std::fs::read(whole.join("model.safetensors")).unwrap(),
        average
    );
    assert_ne!(
        std::fs::read(last.join("model.safetensors")).unwrap(),
        average
    );
    // interrupted after the snapshot at step 2: the same model and log
    let cut = dir.path().join("cut");
    std::fs::create_dir(&cut).unwrap();
    for name in ["predictor.json", "targets.npy", "train_log.csv"] {
        std::fs::copy(whole.join(name), cut.join(name)).unwrap();
    }
    let dest = mfm_train::checkpoint::checkpoint_dir(&cut, 2);
    std::fs::create_dir_all(&dest).unwrap();
    let ck = mfm_train::checkpoint::checkpoint_dir(&whole, 2);
    for e in std::fs::read_dir(&ck).unwrap() {
        let e = e.unwrap();
        std::fs::copy(e.path(), dest.join(e.file_name())).unwrap();
    }
    let resumed = predictor::train(&cut, train.dir(), &c, &stop, false).unwrap();
    assert_eq!((resumed.start_step, resumed.end_step), (2, 6));
    assert_eq!(
        std::fs::read(whole.join("model.safetensors")).unwrap(),
        std::fs::read(cut.join("model.safetensors")).unwrap()
    );
    let rows = |run: &Path| -> Vec<String> {
        std::fs::read_to_string(run.join("train_log.csv"))
            .unwrap()
            .lines()
            .map(|l| l.rsplit_once(',').map_or(l, |(row, _)| row).to_owned())
            .collect()
    };
    assert_eq!(rows(&whole), rows(&cut));
    // the description of a run with the loop's settings names them; one
    // at their defaults is written as before they existed
    let spec = std::fs::read_to_string(whole.join("predictor.json")).unwrap();
    assert!(
        spec.contains("\"ema\": 0.5") && spec.contains("\"keep_at\""),
        "{spec}"
    );
    let plain = serde_json::to_string(&tiny_predictor()).unwrap();
    for field in [
        "lr_schedule",
        "adam_beta1",
        "ema",
        "keep_checkpoints",
        "keep_at",
        "log_every",
    ] {
        assert!(!plain.contains(field), "{field} in {plain}");
    }
    // and a schedule that mixes a step decay with another rate schedule is
    // refused, naming the fields
    let mut both = c.clone();
    both.schedule.milestones = vec![3];
    let e = predictor::train(&dir.path().join("both"), train.dir(), &both, &stop, false)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("lr_schedule replaces milestones and gamma"),
        "{e}"
    );
}

/// Both arbitrary-source trainings on a CUDA device against the same runs
/// on the CPU: the per-step losses agree up to f32 round-off grown over a
/// few Adam steps (a wrong device path gives differences of order one).
/// Skips, with a note, when libtorch sees no GPU.
#[test]
fn both_trainings_run_on_a_gpu_as_on_the_cpu() {
    use mfm_fm::device::DeviceChoice;
    if !tch::Cuda::is_available() {
        eprintln!("skipped: libtorch sees no CUDA device");
        return;
    }
    let t = toy();
    let dir = tempfile::tempdir().unwrap();
    let train = write(&t, &dir.path().join("train"), &t.meshes.coarse, 1, 2);
    let stop = AtomicBool::new(false);
    let losses = |run: &Path| -> Vec<f64> {
        std::fs::read_to_string(run.join("train_log.csv"))
            .unwrap()
            .lines()
            .skip(1)
            .map(|l| l.split(',').nth(1).unwrap().parse().unwrap())
            .collect()
    };
    let close = |a: &[f64], b: &[f64], what: &str| {
        assert_eq!(a.len(), b.len(), "{what}");
        for (x, y) in a.iter().zip(b) {
            assert!(
                (x - y).abs() <= 1e-3 * y.abs().max(1e-6),
                "{what}: {a:?} vs {b:?}"
            );
        }
    };
    let mut runs = Vec::new();
    for device in [DeviceChoice::Cpu, DeviceChoice::Cuda] {
        let mut p = tiny_predictor();
        p.schedule.log_every = 1;
        p.schedule.device = device;
        let pred = dir.path().join(format!("pred-{device:?}"));
        predictor::train(&pred, train.dir(), &p, &stop, false).unwrap();
        let mut f = tiny_flow();
        f.schedule.log_every = 1;
        f.schedule.device = device;
        let arb = dir.path().join(format!("arb-{device:?}"));
        flow::train(&arb, train.dir(), &pred, &f, &stop, false).unwrap();
        runs.push((pred, arb));
    }
    close(&losses(&runs[1].0), &losses(&runs[0].0), "predictor");
    close(&losses(&runs[1].1), &losses(&runs[0].1), "flow");
}

/// The schedule's device is part of a run's description only when it is
/// not the default (`auto`), and a CPU run says so.
#[test]
fn a_run_on_the_cpu_records_its_device() {
    let mut c = tiny_predictor();
    assert!(!serde_json::to_string(&c).unwrap().contains("device"));
    c.schedule.device = mfm_fm::device::DeviceChoice::Cpu;
    let json = serde_json::to_string(&c).unwrap();
    assert!(json.contains("\"device\":\"cpu\""), "{json}");
    let back: PredictorConfig = serde_json::from_str(&json).unwrap();
    assert_eq!(back, c);
}
