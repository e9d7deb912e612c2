//! Training: the loss goes down, interrupted runs resume bit for bit,
//! damaged checkpoints are reported and skipped, configurations parse
//! strictly.
#![allow(clippy::unwrap_used)]

use std::collections::BTreeMap;
use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

use mfm_data::{InMemorySignals, SignalSource};
use mfm_fm::FmError;
use mfm_fm::checkpoint;
use mfm_fm::config::{NoiseScale, RunConfig};
use mfm_fm::device::DeviceChoice;
use mfm_fm::train::Trainer;
use mfm_geometry::{TriMesh, procedural};
use mfm_train::LOG_HEADER;
use mfm_train::LrSchedule;
use mfm_train::checkpoint::{
    self as train_checkpoint, LOG_FILE, OPTIMIZER_FILE, STATE_FILE, WEIGHTS_FILE,
};
use tch::Tensor;

/// `count` smooth fields on the unit sphere `mesh`, each a different blend
/// of low-order harmonics around a common mean of 0.5.
fn smooth_signals(mesh: &TriMesh, count: usize, channels: usize) -> Arc<InMemorySignals> {
    let v = mesh.num_vertices();
    let mut data = Vec::with_capacity(count * v * channels);
    for i in 0..count {
        let a = 1.0 + i as f64;
        for p in mesh.positions() {
            for c in 0..channels {
                let phase = 0.7 * c as f64 + 0.3 * i as f64;
                let x = 0.5 + 0.4 * (a * p[0] + phase).sin() * p[2] + 0.2 * (p[1] * a).cos();
                data.push(x as f32);
            }
        }
    }
    Arc::new(InMemorySignals::new(data, count, v, channels).unwrap())
}

/// A tiny network and run: width 8, one block, two complex layers.
/// A run of `cfg` trained to its last step in a fresh temporary folder.
fn trained_run(cfg: RunConfig, mesh: &TriMesh, signals: Arc<InMemorySignals>) -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    Trainer::new(dir.path(), cfg, mesh, signals)
        .unwrap()
        .run(&no_stop(), false)
        .unwrap();
    dir
}

fn tiny_config(steps: u64) -> RunConfig {
    let mut c = RunConfig::preset("cpu").unwrap();
    c.model.width = Some(8);
    c.model.blocks = Some(1);
    c.model.vector_layers = Some(2);
    c.train.steps = steps;
    c.train.batch = 3;
    c.train.lr = 1e-2;
    c.train.lr_schedule = LrSchedule::Milestones(vec![(steps / 2, 5e-3)]);
    c.train.checkpoint_every = 5;
    c.train.log_every = 3;
    c.train.seed = 11;
    c.train.threads = 1;
    c.train.device = DeviceChoice::Cpu;
    c
}

/// Log rows without the wall-clock column.
fn log_rows(run: &Path) -> Vec<String> {
    let text = std::fs::read_to_string(run.join(LOG_FILE)).unwrap();
    let mut lines = text.lines();
    assert_eq!(lines.next(), Some(LOG_HEADER));
    lines
        .map(|l| l.rsplit_once(',').unwrap().0.to_owned())
        .collect()
}

fn weights(path: &Path) -> BTreeMap<String, Tensor> {
    Tensor::read_safetensors(path)
        .unwrap()
        .into_iter()
        .collect()
}

/// Some variable of `a` differs from its namesake in `b`.
fn assert_weights_differ(a: &Path, b: &Path) {
    let (wa, wb) = (weights(a), weights(b));
    assert!(
        wa.iter().any(|(k, t)| !t.equal(&wb[k])),
        "{} and {} hold the same weights",
        a.display(),
        b.display()
    );
}

fn assert_bit_identical(a: &Path, b: &Path) {
    let (wa, wb) = (weights(a), weights(b));
    assert_eq!(wa.keys().collect::<Vec<_>>(), wb.keys().collect::<Vec<_>>());
    for (k, ta) in &wa {
        let tb = &wb[k];
        // bitwise: compare the raw values as integers
        let ia = Vec::<f32>::try_from(ta.flatten(0, -1)).unwrap();
        let ib = Vec::<f32>::try_from(tb.flatten(0, -1)).unwrap();
        let ba: Vec<u32> = ia.iter().map(|x| x.to_bits()).collect();
        let bb: Vec<u32> = ib.iter().map(|x| x.to_bits()).collect();
        assert_eq!(
            ba,
            bb,
            "variable {k} differs between {} and {}",
            a.display(),
            b.display()
        );
    }
}

fn no_stop() -> AtomicBool {
    AtomicBool::new(false)
}

#[test]
fn loss_decreases_on_a_few_fixed_signals() {
    let mesh = procedural::icosphere(2);
    let signals = smooth_signals(&mesh, 4, 1);
    let mut cfg = tiny_config(80);
    cfg.train.log_every = 1;
    cfg.train.checkpoint_every = 1000;
    cfg.model.width = Some(16);
    cfg.model.blocks = Some(2);
    // noise of unit magnitude: the network first has to learn to undo the
    // noise's large gradients on this coarse mesh, which it does quickly
    cfg.noise.scale = NoiseScale::Unit;
    let dir = tempfile::tempdir().unwrap();
    let mut t = Trainer::new(dir.path(), cfg, &mesh, signals).unwrap();
    let s = t.run(&no_stop(), false).unwrap();
    assert!(s.finished && !s.stopped);
    let losses: Vec<f64> = log_rows(dir.path())
        .iter()
        .map(|r| r.split(',').nth(1).unwrap().parse().unwrap())
        .collect();
    assert_eq!(losses.len(), 80);
    let n = losses.len();
    let first: f64 = losses[..10].iter().sum::<f64>() / 10.0;
    let last: f64 = losses[n - 10..].iter().sum::<f64>() / 10.0;
    eprintln!("mean loss: first 10 steps {first:.4e}, last 10 {last:.4e}");
    assert!(
        last < 0.5 * first,
        "loss went from {first:.4e} to {last:.4e}"
    );
    // the final model and a checkpoint of the last step exist
    assert!(dir.path().join(WEIGHTS_FILE).is_file());
    let cps = train_checkpoint::list_checkpoints(dir.path()).unwrap();
    assert_eq!(cps.last().unwrap().step, 80);
}

#[test]
fn interrupted_and_resumed_runs_equal_the_uninterrupted_run() {
    let mesh = procedural::icosphere(1);
    let signals = smooth_signals(&mesh, 5, 2);
    let cfg = tiny_config(20);

    let full = trained_run(cfg.clone(), &mesh, signals.clone());

    // stopped cleanly at step 7 (between checkpoints and log rows), resumed
    let stopped = tempfile::tempdir().unwrap();
    let s = Trainer::new(stopped.path(), cfg.clone(), &mesh, signals.clone())
        .unwrap()
        .run_until(7, &no_stop(), false)
        .unwrap();
    assert_eq!((s.end_step, s.finished), (7, false));
    let mut t = Trainer::resume(stopped.path(), &mesh, signals.clone()).unwrap();
    assert_eq!(t.resumed().unwrap().step, 7);
    assert!(t.run(&no_stop(), false).unwrap().finished);

    // killed after step 8 before its checkpoint reached the disk: the
    // newest checkpoint is step 5, and the log already has the row of step 6
    let killed = tempfile::tempdir().unwrap();
    Trainer::new(killed.path(), cfg.clone(), &mesh, signals.clone())
        .unwrap()
        .run_until(8, &no_stop(), false)
        .unwrap();
    std::fs::remove_dir_all(train_checkpoint::checkpoint_dir(killed.path(), 8)).unwrap();
    assert!(log_rows(killed.path()).iter().any(|r| r.starts_with("6,")));
    let mut t = Trainer::resume(killed.path(), &mesh, signals.clone()).unwrap();
    assert_eq!(t.resumed().unwrap().step, 5);
    t.run(&no_stop(), false).unwrap();

    // a stop flag set before any step: a checkpoint at step 0, then resume
    let flagged = tempfile::tempdir().unwrap();
    let s = Trainer::new(flagged.path(), cfg.clone(), &mesh, signals.clone())
        .unwrap()
        .run(&AtomicBool::new(true), false)
        .unwrap();
    assert!(s.stopped && s.end_step == 0 && s.checkpoint.is_some());
    Trainer::resume(flagged.path(), &mesh, signals.clone())
        .unwrap()
        .run(&no_stop(), false)
        .unwrap();

    let reference = log_rows(full.path());
    let steps: Vec<&str> = reference
        .iter()
        .map(|r| r.split(',').next().unwrap())
        .collect();
    assert_eq!(steps, ["3", "6", "9", "12", "15", "18", "20"]);
    for other in [stopped.path(), killed.path(), flagged.path()] {
        assert_bit_identical(&full.path().join(WEIGHTS_FILE), &other.join(WEIGHTS_FILE));
        assert_eq!(log_rows(other), reference, "log of {}", other.display());
        let last = |p: &Path| train_checkpoint::checkpoint_dir(p, 20).join(OPTIMIZER_FILE);
        assert_eq!(
            std::fs::read(last(full.path())).unwrap(),
            std::fs::read(last(other)).unwrap(),
            "optimizer state of {}",
            other.display()
        );
    }
    // the run really moved: different seeds give different weights
    let mut other_seed = cfg.clone();
    other_seed.train.seed = 12;
    let d = trained_run(other_seed, &mesh, signals);
    assert_weights_differ(
        &full.path().join(WEIGHTS_FILE),
        &d.path().join(WEIGHTS_FILE),
    );
}

#[test]
fn a_run_resumed_on_another_device_choice_goes_on_there() {
    let mesh = procedural::icosphere(1);
    let signals = smooth_signals(&mesh, 4, 2);
    let cfg = tiny_config(10);
    let full = trained_run(cfg.clone(), &mesh, signals.clone());
    let moved = tempfile::tempdir().unwrap();
    Trainer::new(moved.path(), cfg, &mesh, signals.clone())
        .unwrap()
        .run_until(5, &no_stop(), false)
        .unwrap();
    // `auto`: the CPU here (bit for bit the same run), a GPU where there is one
    let mut t =
        Trainer::resume_on(moved.path(), &mesh, signals.clone(), DeviceChoice::Auto).unwrap();
    assert_eq!(t.resumed().unwrap().step, 5);
    assert_eq!(t.device(), DeviceChoice::Auto.resolve().unwrap());
    t.run(&no_stop(), false).unwrap();
    let last = train_checkpoint::checkpoint_dir(moved.path(), 10);
    let stored = RunConfig::from_toml_file(last.join(checkpoint::CONFIG_FILE)).unwrap();
    assert_eq!(
        stored.train.device,
        DeviceChoice::Auto,
        "the new choice is kept"
    );
    if t.device() == tch::Device::Cpu {
        assert_bit_identical(
            &full.path().join(WEIGHTS_FILE),
            &moved.path().join(WEIGHTS_FILE),
        );
        assert_eq!(log_rows(moved.path()), log_rows(full.path()));
    }
    // a GPU that libtorch does not see is a clear error
    if !tch::Cuda::is_available() {
        let e = Trainer::resume_on(moved.path(), &mesh, signals, DeviceChoice::Cuda).unwrap_err();
        assert!(e.to_string().contains("no CUDA device"), "{e}");
    }
}

#[test]
fn augmented_position_runs_resume_bit_for_bit_and_differ_from_plain_ones() {
    let mesh = procedural::icosphere(1);
    let signals = smooth_signals(&mesh, 4, 3);
    let mut cfg = tiny_config(8);
    cfg.model.condition_on_xyz = true;
    cfg.train.augment.scale = 0.2;
    cfg.train.augment.shift = 0.1;

    let full = trained_run(cfg.clone(), &mesh, signals.clone());
    let stopped = tempfile::tempdir().unwrap();
    Trainer::new(stopped.path(), cfg.clone(), &mesh, signals.clone())
        .unwrap()
        .run_until(3, &no_stop(), false)
        .unwrap();
    Trainer::resume(stopped.path(), &mesh, signals.clone())
        .unwrap()
        .run(&no_stop(), false)
        .unwrap();
    assert_bit_identical(
        &full.path().join(WEIGHTS_FILE),
        &stopped.path().join(WEIGHTS_FILE),
    );

    // the augmentation is really applied: without it the weights differ
    let mut plain = cfg.clone();
    plain.train.augment = Default::default();
    let d = trained_run(plain, &mesh, signals);
    assert_weights_differ(
        &full.path().join(WEIGHTS_FILE),
        &d.path().join(WEIGHTS_FILE),
    );

    // scalar signals cannot be augmented as positions
    let scalar = smooth_signals(&mesh, 4, 1);
    let d = tempfile::tempdir().unwrap();
    let err = Trainer::new(d.path(), cfg, &mesh, scalar).unwrap_err();
    assert!(err.to_string().contains("train.augment"), "{err}");
}

#[test]
fn damaged_checkpoints_are_named_and_skipped() {
    let mesh = procedural::icosphere(1);
    let signals = smooth_signals(&mesh, 3, 1);
    let cfg = tiny_config(10);
    let run = trained_run(cfg.clone(), &mesh, signals.clone());
    let c5 = train_checkpoint::checkpoint_dir(run.path(), 5);
    let c10 = train_checkpoint::checkpoint_dir(run.path(), 10);
    let weights10 = c10.join(WEIGHTS_FILE);
    let intact = std::fs::read(&weights10).unwrap();

    // truncated
    std::fs::write(&weights10, &intact[..intact.len() / 2]).unwrap();
    let err = checkpoint::verify_checkpoint(&c10).unwrap_err();
    let msg = err.to_string();
    assert!(
        matches!(err, FmError::Files(mfm_files::FileError::Format { .. })),
        "{msg}"
    );
    assert!(
        msg.contains(&weights10.display().to_string()) && msg.contains("bytes"),
        "{msg}"
    );

    // same length, one byte flipped in the middle of the weights
    let mut flipped = intact.clone();
    let mid = flipped.len() - 10;
    flipped[mid] ^= 0x40;
    std::fs::write(&weights10, &flipped).unwrap();
    let msg = checkpoint::verify_checkpoint(&c10).unwrap_err().to_string();
    assert!(
        msg.contains("model.safetensors") && msg.contains("CRC-32"),
        "{msg}"
    );

    // resume falls back to step 5 and says why; step 5 is intact
    let mut t = Trainer::resume(run.path(), &mesh, signals.clone()).unwrap();
    let info = t.resumed().unwrap();
    assert_eq!(info.step, 5);
    assert_eq!(info.checkpoint.as_deref(), Some(c5.as_path()));
    assert_eq!(info.skipped.len(), 1);
    assert!(info.skipped[0].1.to_string().contains("model.safetensors"));
    assert_eq!(checkpoint::verify_checkpoint(&c5).unwrap().step, 5);
    // finishing again replaces the damaged checkpoint with the same weights
    t.run(&no_stop(), false).unwrap();
    assert_eq!(checkpoint::verify_checkpoint(&c10).unwrap().step, 10);
    assert_eq!(std::fs::read(&weights10).unwrap(), intact);

    // a garbled state file is named too
    std::fs::write(c10.join(STATE_FILE), "{ \"format\": 1, \"st").unwrap();
    let msg = checkpoint::verify_checkpoint(&c10).unwrap_err().to_string();
    assert!(msg.contains("state.json"), "{msg}");

    // with every checkpoint damaged, resuming fails with the newest's error
    std::fs::write(c5.join(OPTIMIZER_FILE), b"junk").unwrap();
    let msg = Trainer::resume(run.path(), &mesh, signals.clone())
        .unwrap_err()
        .to_string();
    assert!(msg.contains("state.json"), "{msg}");

    // a new run refuses to overwrite the folder
    let msg = Trainer::new(run.path(), cfg, &mesh, signals)
        .unwrap_err()
        .to_string();
    assert!(msg.contains("resume"), "{msg}");
}

#[test]
fn config_files_are_strict_and_defaults_roundtrip() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("run.toml");

    std::fs::write(&path, "[train]\nsteps = 10\nbatchsize = 4\n").unwrap();
    let msg = RunConfig::from_toml_file(&path).unwrap_err().to_string();
    assert!(
        msg.contains("batchsize") && msg.contains("run.toml"),
        "{msg}"
    );

    std::fs::write(&path, "[modle]\nwidth = 4\n").unwrap();
    let msg = RunConfig::from_toml_file(&path).unwrap_err().to_string();
    assert!(msg.contains("modle"), "{msg}");

    std::fs::write(&path, "[train]\nbatch = \"four\"\n").unwrap();
    let msg = RunConfig::from_toml_file(&path).unwrap_err().to_string();
    assert!(msg.contains("batch") && msg.contains("run.toml"), "{msg}");

    std::fs::write(&path, "[train]\nbatch = 0\n").unwrap();
    let msg = RunConfig::from_toml_file(&path).unwrap_err().to_string();
    assert!(
        msg.contains("train.batch") && msg.contains("run.toml"),
        "{msg}"
    );

    std::fs::write(&path, "[train.augment]\nscale = 1.5\n").unwrap();
    let msg = RunConfig::from_toml_file(&path).unwrap_err().to_string();
    assert!(msg.contains("train.augment.scale"), "{msg}");

    std::fs::write(&path, "[noise]\nkind = \"matern:-1\"\n").unwrap();
    let msg = RunConfig::from_toml_file(&path).unwrap_err().to_string();
    assert!(msg.contains("tau"), "{msg}");

    std::fs::write(
        &path,
        "[train]\nlr_schedule = { milestones = [[10, 1e-3]], decay = 0.5 }\n",
    )
    .unwrap();
    let msg = RunConfig::from_toml_file(&path).unwrap_err().to_string();
    assert!(msg.contains("lr_schedule"), "{msg}");

    // an empty file is the default; the default written out reads back equal
    std::fs::write(&path, "").unwrap();
    assert_eq!(
        RunConfig::from_toml_file(&path).unwrap(),
        RunConfig::default()
    );
    RunConfig::default().write_toml_file(&path).unwrap();
    assert_eq!(
        RunConfig::from_toml_file(&path).unwrap(),
        RunConfig::default()
    );

    // every kind of value survives a round trip
    let mut c = RunConfig::preset("cpu").unwrap();
    c.dataset.path = Some("data/x".into());
    c.noise.kind = "explicit:16:50".parse().unwrap();
    c.noise.scale = NoiseScale::Unit;
    c.train.lr_schedule = LrSchedule::Decay {
        factor: 0.2,
        at: vec![10, 30],
    };
    c.sample.method = "euler".parse().unwrap();
    c.write_toml_file(&path).unwrap();
    assert_eq!(RunConfig::from_toml_file(&path).unwrap(), c);
    c.noise.scale = NoiseScale::Factor(2.5);
    assert_eq!(
        RunConfig::from_toml_str(&c.to_toml_string().unwrap(), "x").unwrap(),
        c
    );

    // a hand-written file in the documented form
    let text = r#"
        [dataset]
        path = "data/gmm"
        [model]
        preset = "small"
        width = 24
        condition_on_xyz = true
        [noise]
        kind = "matern-normalized:0.5"
        scale = "data"
        [train]
        lr_schedule = { decay = 0.2, at = [40000, 160000] }
        [sample]
        method = "euler"
    "#;
    let c = RunConfig::from_toml_str(text, "inline").unwrap();
    let net = c.model.net_config(3).unwrap();
    assert_eq!(
        (net.width, net.blocks, net.cond_channels, net.in_channels),
        (24, 3, 4, 3)
    );
    assert_eq!(c.noise.scale, NoiseScale::Data);
    assert!((c.train.lr_at(50_000) - 1e-4).abs() < 1e-18);
}

#[test]
fn run_folder_records_config_and_resolved_flow() {
    let mesh = procedural::icosphere(3);
    let signals = smooth_signals(&mesh, 6, 1);
    let mut cfg = tiny_config(1);
    cfg.noise.scale = NoiseScale::Unit;
    let run = tempfile::tempdir().unwrap();
    let t = Trainer::new(run.path(), cfg.clone(), &mesh, signals.clone()).unwrap();
    // the config written into the run folder reads back equal
    let written = RunConfig::from_toml_file(run.path().join(checkpoint::CONFIG_FILE)).unwrap();
    assert_eq!(written, cfg);
    let flow = checkpoint::FlowSpec::read(run.path().join(checkpoint::FLOW_FILE)).unwrap();
    assert_eq!(&flow, t.flow());

    // the run trains in the training mesh's canonical frame
    assert_eq!(
        flow.frame,
        mfm_geometry::frame::CanonicalFrame::of(&mesh).unwrap()
    );
    assert!(flow.centered && !flow.positions);
    // "unit": fresh noise (on the mesh in the frame) times the scale has RMS
    // ~1 over the surface
    let framed = flow.frame.apply(&mesh);
    let sampler = mfm_noise::NoiseSampler::new(&framed, cfg.noise.kind).unwrap();
    let batch = sampler.sample(64, 1, 12345).unwrap();
    let area: f64 = sampler.mass().iter().sum();
    let ms: f64 = (0..64)
        .map(|s| {
            batch
                .sample(s)
                .iter()
                .zip(sampler.mass())
                .map(|(x, m)| m * (x * flow.noise_scale).powi(2))
                .sum::<f64>()
        })
        .sum::<f64>()
        / (64.0 * area);
    assert!((ms.sqrt() - 1.0).abs() < 0.1, "rms {}", ms.sqrt());

    // the offset is the mass-weighted mean of the data (0.5 + zero-mean parts)
    let mut mean = 0.0;
    let v = mesh.num_vertices();
    for i in 0..signals.len() {
        let s = signals.signal(i);
        mean += (0..v)
            .map(|j| sampler.mass()[j] * f64::from(s[j]))
            .sum::<f64>()
            / area;
    }
    mean /= signals.len() as f64;
    assert!((flow.velocity_offset[0] - mean).abs() < 1e-6);
    assert!(
        (flow.velocity_offset[0] - 0.5).abs() < 0.05,
        "{:?}",
        flow.velocity_offset
    );
}

/// Step time of the `cpu` preset on a ~2.5k-vertex sphere (2562 vertices)
/// with xyz-like 3-channel signals: `cargo test -p mfm-fm --release --test
/// training -- --ignored --nocapture cpu_preset`.
#[test]
#[ignore = "timing, not a check; run by hand"]
fn cpu_preset_step_time() {
    let mesh = procedural::icosphere(4);
    let signals = smooth_signals(&mesh, 64, 3);
    let mut cfg = RunConfig::preset("cpu").unwrap();
    cfg.train.steps = 40;
    cfg.train.device = DeviceChoice::Cpu;
    let run = tempfile::tempdir().unwrap();
    let mut t = Trainer::new(run.path(), cfg, &mesh, signals).unwrap();
    mfm_kernels::profile::set_enabled(true);
    let cpu0 = mfm_kernels::profile::process_cpu_seconds();
    let s = t.run(&no_stop(), false).unwrap();
    let cpu = mfm_kernels::profile::process_cpu_seconds() - cpu0;
    mfm_kernels::profile::set_enabled(false);
    for (name, total) in mfm_kernels::profile::totals() {
        eprintln!(
            "{name:<32} cpu {:8.1} ms/step  wall {:8.1} ms/step",
            1e3 * total.cpu / s.end_step as f64,
            1e3 * total.wall / s.end_step as f64
        );
    }
    eprintln!(
        "cpu preset: {} vertices, {} threads, {:.1} ms/step wall, {:.1} ms/step CPU time ({} steps, {:.2} s)",
        mesh.num_vertices(),
        tch::get_num_threads(),
        1e3 * s.seconds_per_step,
        1e3 * cpu / s.end_step as f64,
        s.end_step,
        s.seconds
    );
}
