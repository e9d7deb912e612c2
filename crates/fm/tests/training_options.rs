//! The training options beyond the official recipe: the weight average
//! (`train.ema`), the time distribution (`train.time`), the Jacobian weight
//! of the loss (`train.jacobian_weight`), kept snapshots (`train.keep_at`),
//! minibatch optimal transport (`train.coupling`) and the data prior
//! (`noise.prior`): each changes what it
//! says, resumes bit for bit, and is refused when out of range.
#![allow(clippy::unwrap_used)]

use std::collections::BTreeMap;
use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

use mfm_data::InMemorySignals;
use mfm_fm::checkpoint::FlowSpec;
use mfm_fm::config::PriorKind;
use mfm_fm::config::RunConfig;
use mfm_fm::coupling::{Coupling, least_cost_assignment, squared_distances};
use mfm_fm::device::DeviceChoice;
use mfm_fm::path::TimeSampling;
use mfm_fm::prior::{GaussianPrior, PRIOR_FILE};
use mfm_fm::sample::Sampler;
use mfm_fm::train::Trainer;
use mfm_geometry::{TriMesh, procedural};
use mfm_train::LrSchedule;
use mfm_train::checkpoint::{self, EMA_FILE, WEIGHTS_FILE};
use proptest::prelude::*;
use rand::SeedableRng;
use tch::Tensor;

fn signals(mesh: &TriMesh, count: usize) -> Arc<InMemorySignals> {
    let v = mesh.num_vertices();
    let mut data = Vec::with_capacity(count * v);
    for i in 0..count {
        for p in mesh.positions() {
            let a = 1.0 + i as f64;
            data.push((0.5 + 0.4 * (a * p[0]).sin() * p[2] + 0.2 * (a * p[1]).cos()) as f32);
        }
    }
    Arc::new(InMemorySignals::new(data, count, v, 1).unwrap())
}

fn tiny(steps: u64) -> RunConfig {
    let mut c = RunConfig::preset("cpu").unwrap();
    c.model.width = Some(8);
    c.model.blocks = Some(1);
    c.model.vector_layers = Some(2);
    c.train.steps = steps;
    c.train.batch = 3;
    c.train.lr = 1e-2;
    c.train.lr_schedule = LrSchedule::constant();
    c.train.checkpoint_every = 4;
    c.train.log_every = 2;
    c.train.seed = 5;
    c.train.threads = 1;
    c.train.device = DeviceChoice::Cpu;
    // the official loss, uniform times and no average, whatever the
    // preset's defaults
    c.train.ema = 0.0;
    c.train.jacobian_weight = 1.0;
    c.train.time = TimeSampling::Uniform;
    c
}

fn weights(path: &Path) -> BTreeMap<String, Vec<f32>> {
    Tensor::read_safetensors(path)
        .unwrap()
        .into_iter()
        .map(|(k, t)| (k, Vec::<f32>::try_from(t.flatten(0, -1)).unwrap()))
        .collect()
}

fn bits(w: &BTreeMap<String, Vec<f32>>) -> Vec<u32> {
    w.values().flatten().map(|x| x.to_bits()).collect()
}

fn train(dir: &Path, cfg: RunConfig, mesh: &TriMesh, s: Arc<InMemorySignals>, until: u64) {
    Trainer::new(dir, cfg, mesh, s)
        .unwrap()
        .run_until(until, &AtomicBool::new(false), false)
        .unwrap();
}

/// The final weights' bits of a run stopped after step `stop` and resumed
/// to its end.
fn stopped_and_resumed(
    cfg: RunConfig,
    mesh: &TriMesh,
    s: &Arc<InMemorySignals>,
    stop: u64,
) -> Vec<u32> {
    let dir = tempfile::tempdir().unwrap();
    train(dir.path(), cfg, mesh, s.clone(), stop);
    Trainer::resume(dir.path(), mesh, s.clone())
        .unwrap()
        .run(&AtomicBool::new(false), false)
        .unwrap();
    bits(&weights(&dir.path().join(WEIGHTS_FILE)))
}

#[test]
fn the_weight_average_follows_its_recursion_and_resumes_bit_for_bit() {
    let mesh = procedural::icosphere(1);
    let s = signals(&mesh, 4);
    let mut cfg = tiny(12);
    cfg.train.ema = 0.9;

    // full run; the final model is the average, the checkpoint has both
    let full = tempfile::tempdir().unwrap();
    train(full.path(), cfg.clone(), &mesh, s.clone(), 12);
    let last = checkpoint::checkpoint_dir(full.path(), 12);
    let avg = weights(&last.join(EMA_FILE));
    let trained = weights(&last.join(WEIGHTS_FILE));
    assert_eq!(bits(&weights(&full.path().join(WEIGHTS_FILE))), bits(&avg));
    assert_ne!(
        bits(&avg),
        bits(&trained),
        "the average is not the trained weights"
    );

    // the recursion, replayed from the checkpoint of step 8: four more
    // steps of w <- d w + (1 - d) p with d = min(0.9, (1 + k) / (10 + k));
    // the trained weights of steps 9..12 come from a run that keeps them all
    let mut every = cfg.clone();
    every.train.checkpoint_every = 1;
    every.train.keep_checkpoints = 20;
    let dense = tempfile::tempdir().unwrap();
    train(dense.path(), every, &mesh, s.clone(), 12);
    let at = |k: u64, f: &str| weights(&checkpoint::checkpoint_dir(dense.path(), k).join(f));
    let mut w = at(8, EMA_FILE);
    for k in 9..=12u64 {
        let d = 0.9f64.min((1.0 + k as f64) / (10.0 + k as f64));
        let p = at(k, WEIGHTS_FILE);
        for (name, v) in w.iter_mut() {
            for (x, y) in v.iter_mut().zip(&p[name]) {
                *x = (f64::from(*x) * d + f64::from(*y) * (1.0 - d)) as f32;
            }
        }
    }
    for (name, v) in &avg {
        for (a, b) in v.iter().zip(&w[name]) {
            assert!(
                (a - b).abs() <= 1e-6 * (1.0 + b.abs()),
                "{name}: {a} vs {b}"
            );
        }
    }
    // checkpointing every step changed nothing else
    assert_eq!(bits(&at(12, EMA_FILE)), bits(&avg));

    // stopped at step 6 (off the checkpoint grid) and resumed: bit for bit
    assert_eq!(stopped_and_resumed(cfg.clone(), &mesh, &s, 6), bits(&avg));

    // the training itself does not depend on the average
    let mut plain = cfg.clone();
    plain.train.ema = 0.0;
    let p = tempfile::tempdir().unwrap();
    train(p.path(), plain, &mesh, s.clone(), 12);
    assert_eq!(bits(&weights(&p.path().join(WEIGHTS_FILE))), bits(&trained));
    assert!(
        !checkpoint::checkpoint_dir(p.path(), 12)
            .join(EMA_FILE)
            .exists()
    );

    // sampling a checkpoint uses the average unless asked otherwise
    let a = Sampler::load_checkpoint(&last, None).unwrap();
    let r = Sampler::load_checkpoint_weights(&last, None, false).unwrap();
    let first = |s: &Sampler| {
        let vars = s.net().var_store().variables();
        let (_, t) = vars.iter().min_by_key(|(k, _)| k.as_str()).unwrap();
        Vec::<f32>::try_from(t.flatten(0, -1)).unwrap()
    };
    assert_eq!(first(&a), avg.values().next().unwrap().clone());
    assert_eq!(first(&r), trained.values().next().unwrap().clone());

    // a checkpoint without an average cannot resume a run that has one
    let mut edited = cfg;
    edited.train.steps = 30;
    let broken = tempfile::tempdir().unwrap();
    train(broken.path(), edited, &mesh, s.clone(), 4);
    let ck = checkpoint::checkpoint_dir(broken.path(), 4);
    std::fs::remove_file(ck.join(EMA_FILE)).unwrap();
    let err = Trainer::resume(broken.path(), &mesh, s).unwrap_err();
    assert!(err.to_string().contains("ema.safetensors"), "{err}");
}

#[test]
fn kept_snapshots_survive_pruning_and_are_written_off_the_grid() {
    let mesh = procedural::icosphere(1);
    let s = signals(&mesh, 4);
    let mut cfg = tiny(16);
    cfg.train.keep_checkpoints = 1;
    cfg.train.keep_at = vec![3, 8];
    let dir = tempfile::tempdir().unwrap();
    train(dir.path(), cfg, &mesh, s, 16);
    let steps: Vec<u64> = checkpoint::list_checkpoints(dir.path())
        .unwrap()
        .iter()
        .map(|c| c.step)
        .collect();
    // 3 is off the every-4 grid; 8 is on it; 16 is the newest
    assert_eq!(steps, [3, 8, 16]);
}

#[test]
fn time_sampling_and_jacobian_weight_change_the_run_and_resume_bit_for_bit() {
    let mesh = procedural::icosphere(1);
    let s = signals(&mesh, 4);
    let base = tiny(8);
    let reference = tempfile::tempdir().unwrap();
    train(reference.path(), base.clone(), &mesh, s.clone(), 8);
    let reference = bits(&weights(&reference.path().join(WEIGHTS_FILE)));
    let variants: Vec<(&str, RunConfig)> = vec![
        ("logit-normal", {
            let mut c = base.clone();
            c.train.time = TimeSampling::LogitNormal {
                mean: 0.0,
                std: 1.0,
            };
            c
        }),
        ("late", {
            let mut c = base.clone();
            c.train.time = TimeSampling::Late { power: 2.0 };
            c
        }),
        ("jacobian 0", {
            let mut c = base.clone();
            c.train.jacobian_weight = 0.0;
            c
        }),
        ("jacobian 0.1", {
            let mut c = base.clone();
            c.train.jacobian_weight = 0.1;
            c
        }),
        ("minibatch optimal transport", {
            let mut c = base.clone();
            c.train.coupling = Coupling::MinibatchOt { pool: 4 };
            c
        }),
    ];
    for (name, cfg) in variants {
        let full = tempfile::tempdir().unwrap();
        train(full.path(), cfg.clone(), &mesh, s.clone(), 8);
        let w = bits(&weights(&full.path().join(WEIGHTS_FILE)));
        assert_ne!(
            w, reference,
            "{name} trained the same weights as the default"
        );
        assert_eq!(
            stopped_and_resumed(cfg, &mesh, &s, 5),
            w,
            "{name} resumed differently"
        );
    }
    // weight 1 is the official loss exactly
    let mut one = base;
    one.train.jacobian_weight = 1.0;
    let d = tempfile::tempdir().unwrap();
    train(d.path(), one, &mesh, s, 8);
    assert_eq!(bits(&weights(&d.path().join(WEIGHTS_FILE))), reference);
}

#[test]
fn the_new_fields_parse_default_and_refuse_bad_values() {
    let c = RunConfig::default();
    assert_eq!(c.train.ema, 0.0);
    assert_eq!(c.train.time, TimeSampling::Uniform);
    assert_eq!(c.train.jacobian_weight, 1.0);
    assert!(c.train.keep_at.is_empty());
    assert_eq!(c.train.coupling, Coupling::Independent);
    // the default is not written: configurations and checkpoints of runs
    // without it read as before
    assert!(!c.to_toml_string().unwrap().contains("coupling"));
    let text = "[train]\nema = 0.999\ntime = \"logit-normal:-0.5:0.8\"\njacobian_weight = 0.0\nkeep_at = [100, 1000]\ncoupling = \"ot:64\"\n";
    let c = RunConfig::from_toml_str(text, "t.toml").unwrap();
    assert_eq!(c.train.ema, 0.999);
    assert_eq!(
        c.train.time,
        TimeSampling::LogitNormal {
            mean: -0.5,
            std: 0.8
        }
    );
    assert_eq!(c.train.jacobian_weight, 0.0);
    assert_eq!(c.train.keep_at, [100, 1000]);
    assert_eq!(c.train.coupling, Coupling::MinibatchOt { pool: 64 });
    // written and read back
    let again = RunConfig::from_toml_str(&c.to_toml_string().unwrap(), "t.toml").unwrap();
    assert_eq!(again, c);
    for (bad, field) in [
        ("[train]\nema = 1.0\n", "train.ema"),
        ("[train]\nema = -0.1\n", "train.ema"),
        ("[train]\njacobian_weight = -1.0\n", "train.jacobian_weight"),
        ("[train]\ntime = \"logit-normal:0:0\"\n", "std > 0"),
        ("[train]\ntime = \"late:-2\"\n", "power > 0"),
        ("[train]\ntime = \"gaussian\"\n", "unknown time sampling"),
        ("[train]\ntime = \"late:x\"\n", "not a number"),
        (
            "[train]\nbatch = 8\ncoupling = \"ot:4\"\n",
            "train.coupling",
        ),
        ("[train]\ncoupling = \"ot:5000\"\n", "at most 1024"),
        ("[train]\ncoupling = \"ot:x\"\n", "whole number"),
        ("[train]\ncoupling = \"sinkhorn\"\n", "unknown coupling"),
    ] {
        let e = RunConfig::from_toml_str(bad, "bad.toml")
            .unwrap_err()
            .to_string();
        assert!(e.contains(field) && e.contains("bad.toml"), "{bad:?}: {e}");
    }
    // keep_at may change on resume; ema may not
    assert!(mfm_fm::train::RESUMABLE_FIELDS.contains(&"train.keep_at"));
    assert!(!mfm_fm::train::RESUMABLE_FIELDS.contains(&"train.ema"));
}

/// All permutations of `0..n`.
fn permutations(n: usize) -> Vec<Vec<usize>> {
    if n == 0 {
        return vec![Vec::new()];
    }
    let mut all = Vec::new();
    for p in permutations(n - 1) {
        for at in 0..n {
            let mut q = p.clone();
            q.insert(at, n - 1);
            all.push(q);
        }
    }
    all
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    /// The assignment is a permutation whose total cost no other
    /// permutation beats (all of them tried).
    #[test]
    fn the_assignment_is_a_least_cost_permutation(
        n in 1usize..7,
        costs in prop::collection::vec(-5.0f64..5.0, 36),
    ) {
        let costs = &costs[..n * n];
        let a = least_cost_assignment(costs, n).unwrap();
        let mut seen = a.clone();
        seen.sort_unstable();
        prop_assert_eq!(seen, (0..n).collect::<Vec<_>>());
        let total = |p: &[usize]| -> f64 { p.iter().enumerate().map(|(i, &j)| costs[i * n + j]).sum() };
        let best = permutations(n).iter().map(|p| total(p)).fold(f64::INFINITY, f64::min);
        prop_assert!(total(&a) <= best + 1e-9, "{} > {}", total(&a), best);
    }

    /// The cost matrix is the squared mass-weighted distance: zero between
    /// a set and itself on the diagonal, transposed when the sets swap, and
    /// each entry the sum written out.
    #[test]
    fn the_pairing_costs_are_squared_mass_weighted_distances(
        n in 1usize..5,
        a in prop::collection::vec(-2.0f32..2.0, 4 * 5 * 2),
        b in prop::collection::vec(-2.0f32..2.0, 4 * 5 * 2),
        mass in prop::collection::vec(0.1f64..2.0, 5),
    ) {
        let (a, b) = (&a[..n * 10], &b[..n * 10]);
        let ab = squared_distances(a, b, n, &mass, 2).unwrap();
        let ba = squared_distances(b, a, n, &mass, 2).unwrap();
        let aa = squared_distances(a, a, n, &mass, 2).unwrap();
        for i in 0..n {
            prop_assert_eq!(aa[i * n + i], 0.0);
            for j in 0..n {
                prop_assert_eq!(ab[i * n + j], ba[j * n + i]);
                let mut direct = 0.0;
                for v in 0..5 {
                    for k in 0..2 {
                        let d = f64::from(a[i * 10 + v * 2 + k]) - f64::from(b[j * 10 + v * 2 + k]);
                        direct += mass[v] * d * d;
                    }
                }
                prop_assert!((ab[i * n + j] - direct).abs() <= 1e-9 * direct.max(1.0));
            }
        }
        prop_assert!(squared_distances(a, &b[..b.len() - 1], n, &mass, 2).is_err());
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]

    /// Every distribution stays in [0, 1]; `late:P` with P > 1 has its mean
    /// above 1/2 (1 - 1/(P+1)), logit-normal with mean m has its median at
    /// sigmoid(m).
    #[test]
    fn time_draws_stay_in_the_unit_interval_with_the_right_centre(
        seed in 0u64..1000,
        power in 1.5f64..4.0,
        m in -1.0f64..1.0,
    ) {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let n = 4000;
        let late: Vec<f64> = (0..n)
            .map(|_| f64::from(TimeSampling::Late { power }.draw(&mut rng)))
            .collect();
        prop_assert!(late.iter().all(|t| (0.0..=1.0).contains(t)));
        let mean = late.iter().sum::<f64>() / n as f64;
        let expected = 1.0 - 1.0 / (power + 1.0);
        prop_assert!((mean - expected).abs() < 0.02, "late:{power} mean {mean} vs {expected}");
        let mut ln: Vec<f64> = (0..n)
            .map(|_| f64::from(TimeSampling::LogitNormal { mean: m, std: 1.0 }.draw(&mut rng)))
            .collect();
        prop_assert!(ln.iter().all(|t| (0.0..=1.0).contains(t)));
        ln.sort_by(f64::total_cmp);
        let median = ln[n / 2];
        let expected = 1.0 / (1.0 + (-m).exp());
        prop_assert!((median - expected).abs() < 0.03, "median {median} vs {expected}");
    }
}

/// `model.displacements`: a run resumes bit for bit, trains other weights
/// than the same run on positions, and is refused with augmentation or on
/// signals that are not positions.
#[test]
fn displacement_runs_resume_bit_for_bit_and_refuse_what_is_no_shape() {
    let mesh = procedural::icosphere(1);
    let v = mesh.num_vertices();
    let mut data = Vec::with_capacity(4 * v * 3);
    for i in 0..4 {
        let a = 0.1 * (1.0 + i as f64);
        for p in mesh.positions() {
            data.extend([p[0], p[1] * (1.0 + a), p[2] + a * p[0] * p[0]].map(|x| x as f32));
        }
    }
    let s = Arc::new(InMemorySignals::new(data, 4, v, 3).unwrap());
    let mut cfg = tiny(8);
    cfg.model.condition_on_xyz = true;
    let positions = tempfile::tempdir().unwrap();
    train(positions.path(), cfg.clone(), &mesh, s.clone(), 8);
    cfg.model.displacements = true;
    let full = tempfile::tempdir().unwrap();
    train(full.path(), cfg.clone(), &mesh, s.clone(), 8);
    let w = bits(&weights(&full.path().join(WEIGHTS_FILE)));
    assert_ne!(w, bits(&weights(&positions.path().join(WEIGHTS_FILE))));
    assert_eq!(stopped_and_resumed(cfg.clone(), &mesh, &s, 5), w);
    assert!(!mfm_fm::train::RESUMABLE_FIELDS.contains(&"model.displacements"));

    let mut augmented = cfg.clone();
    augmented.train.augment.scale = 0.1;
    let e = augmented.validate().unwrap_err().to_string();
    assert!(
        e.contains("model.displacements") && e.contains("train.augment"),
        "{e}"
    );
    let mut values = cfg.clone();
    values.dataset.positions = Some(false);
    let e = values.validate().unwrap_err().to_string();
    assert!(e.contains("position signals"), "{e}");
    // one channel of values is no shape either
    let d = tempfile::tempdir().unwrap();
    let e = Trainer::new(d.path(), cfg, &mesh, signals(&mesh, 3))
        .err()
        .unwrap()
        .to_string();
    assert!(
        e.contains("model.displacements") && e.contains("1 channel"),
        "{e}"
    );
    // the field reads from TOML and is written only when set
    let c = RunConfig::from_toml_str("[model]\ndisplacements = true\n", "t.toml").unwrap();
    assert!(c.model.displacements);
    assert!(c.to_toml_string().unwrap().contains("displacements = true"));
    assert!(
        !RunConfig::default()
            .to_toml_string()
            .unwrap()
            .contains("displacements")
    );
}

/// `model.global_context`: the run builds blocks with the global map, trains
/// other weights than the same run without it, resumes bit for bit, reads
/// from TOML, is written only when set, and is refused by the official
/// export (the authors' network has no such layer).
#[test]
fn global_context_runs_resume_bit_for_bit_and_are_not_exported_as_official() {
    let mesh = procedural::icosphere(1);
    let s = signals(&mesh, 4);
    let mut cfg = tiny(8);
    let plain = tempfile::tempdir().unwrap();
    train(plain.path(), cfg.clone(), &mesh, s.clone(), 8);
    cfg.model.global_context = true;
    let global = tempfile::tempdir().unwrap();
    train(global.path(), cfg.clone(), &mesh, s.clone(), 8);
    let wg = weights(&global.path().join(WEIGHTS_FILE));
    assert!(wg.contains_key("blocks.0.global.weight"));
    let learned = wg["blocks.0.global.weight"].iter().any(|&x| x != 0.0);
    assert!(learned, "the global map never left zero");
    let w = bits(&wg);
    assert_ne!(w, bits(&weights(&plain.path().join(WEIGHTS_FILE))));
    assert_eq!(stopped_and_resumed(cfg.clone(), &mesh, &s, 5), w);
    assert!(!mfm_fm::train::RESUMABLE_FIELDS.contains(&"model.global_context"));
    let out = global.path().join("official.ckpt");
    let e = mfm_fm::official::export_official(global.path(), &out)
        .unwrap_err()
        .to_string();
    assert!(e.contains("model.global_context"), "{e}");
    assert!(!out.exists());
    let c = RunConfig::from_toml_str("[model]\nglobal_context = true\n", "t.toml").unwrap();
    assert!(c.model.global_context);
    assert!(c.model.net_config(3).unwrap().global_context);
    assert!(
        c.to_toml_string()
            .unwrap()
            .contains("global_context = true")
    );
    assert!(
        !RunConfig::default()
            .to_toml_string()
            .unwrap()
            .contains("global_context")
    );
}

/// `noise.prior = "gaussian"`: the run fits the prior on its training
/// signals in its frame, writes it once beside `flow.json` (which records
/// its size and checksum), trains other weights than the plain run,
/// resumes bit for bit, is refused by the official export, and a changed
/// prior file is refused by name when sampling. Runs without a prior
/// write neither the file nor the field.
#[test]
fn gaussian_prior_runs_store_their_fit_and_resume_bit_for_bit() {
    let mesh = procedural::icosphere(1);
    let s = signals(&mesh, 5);
    let mut cfg = tiny(8);
    let plain = tempfile::tempdir().unwrap();
    train(plain.path(), cfg.clone(), &mesh, s.clone(), 8);
    assert!(!plain.path().join(PRIOR_FILE).exists());
    let text = std::fs::read_to_string(plain.path().join("flow.json")).unwrap();
    assert!(!text.contains("prior"), "{text}");

    cfg.noise.prior = PriorKind::Gaussian;
    let with = tempfile::tempdir().unwrap();
    train(with.path(), cfg.clone(), &mesh, s.clone(), 8);
    let flow = FlowSpec::read(with.path().join("flow.json")).unwrap();
    let spec = flow.prior.unwrap();
    assert_eq!(
        (spec.kind, spec.fitted_on, spec.directions),
        (PriorKind::Gaussian, 5, 4)
    );
    // the file is the fit of the signals on the framed training mesh
    let framed = flow.frame.apply(&mesh);
    let stored = GaussianPrior::read(&with.path().join(PRIOR_FILE), &spec, 1).unwrap();
    assert_eq!(stored, GaussianPrior::fit(&framed, s.as_ref(), 64).unwrap());
    let w = bits(&weights(&with.path().join(WEIGHTS_FILE)));
    assert_ne!(w, bits(&weights(&plain.path().join(WEIGHTS_FILE))));
    assert_eq!(stopped_and_resumed(cfg.clone(), &mesh, &s, 5), w);
    assert!(!mfm_fm::train::RESUMABLE_FIELDS.contains(&"noise.prior"));
    // fewer directions asked for, fewer kept
    let mut three = cfg.clone();
    three.noise.prior_directions = 3;
    let d = tempfile::tempdir().unwrap();
    train(d.path(), three, &mesh, s.clone(), 1);
    let spec3 = FlowSpec::read(d.path().join("flow.json"))
        .unwrap()
        .prior
        .unwrap();
    assert_eq!(spec3.directions, 3);

    let out = with.path().join("official.ckpt");
    let e = mfm_fm::official::export_official(with.path(), &out)
        .unwrap_err()
        .to_string();
    assert!(e.contains("noise.prior"), "{e}");
    assert!(!out.exists());

    Sampler::load(with.path(), Some(tch::Device::Cpu)).unwrap();
    let path = with.path().join(PRIOR_FILE);
    let mut bytes = std::fs::read(&path).unwrap();
    let last = bytes.len() - 1;
    bytes[last] ^= 1;
    std::fs::write(&path, &bytes).unwrap();
    let e = Sampler::load(with.path(), Some(tch::Device::Cpu))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("prior.safetensors") && e.contains("CRC-32"),
        "{e}"
    );
    std::fs::remove_file(&path).unwrap();
    let e = Sampler::load(with.path(), Some(tch::Device::Cpu))
        .unwrap_err()
        .to_string();
    assert!(e.contains("prior.safetensors"), "{e}");
}

/// A sampler of a prior run starts sample `i` from the plain run's noise
/// plus draw `i` of the prior, carried from the training mesh to the
/// target (here its midpoint refinement) and centred with the target's
/// mass; draws do not depend on the batch; a target that is not the
/// training surface is refused.
#[test]
fn a_prior_runs_start_is_its_noise_plus_the_carried_draw() {
    let mesh = procedural::icosphere(1);
    let s = signals(&mesh, 5);
    let mut cfg = tiny(2);
    cfg.noise.prior = PriorKind::Gaussian;
    let dir = tempfile::tempdir().unwrap();
    train(dir.path(), cfg, &mesh, s, 2);
    let cpu = Some(tch::Device::Cpu);
    let with = Sampler::load(dir.path(), cpu).unwrap();
    let prior = with.prior().unwrap().clone();
    let mut flow = with.flow().clone();
    flow.prior = None;
    let net = mfm_net::PoissonNet::load(dir.path().join(WEIGHTS_FILE), tch::Device::Cpu).unwrap();
    let without = Sampler::new(net, flow.clone()).unwrap();

    let fine = mfm_geometry::subdivide::midpoint(&mesh).unwrap();
    let (tw, to) = (
        with.prepare(&fine).unwrap(),
        without.prepare(&fine).unwrap(),
    );
    let seed = 11;
    let xw = Vec::<f32>::try_from(with.noise(&tw, 0, 3, seed).unwrap().flatten(0, -1)).unwrap();
    let xo = Vec::<f32>::try_from(without.noise(&to, 0, 3, seed).unwrap().flatten(0, -1)).unwrap();
    let framed = flow.frame.apply(&fine);
    let transfer = mfm_data::transfer::Transfer::locate(prior.mesh(), &framed).unwrap();
    let mass = mfm_geometry::operators::lumped_mass(&framed);
    let total: f64 = mass.iter().sum();
    let v = fine.num_vertices();
    for i in 0..3 {
        let g = transfer.apply(&prior.draw(i as u64, seed), 1).unwrap();
        let mean: f64 = g
            .iter()
            .zip(&mass)
            .map(|(&x, m)| f64::from(x) * m)
            .sum::<f64>()
            / total;
        for j in 0..v {
            let expected = f64::from(g[j]) - mean;
            let found = f64::from(xw[i * v + j]) - f64::from(xo[i * v + j]);
            assert!(
                (expected - found).abs() < 1e-5,
                "sample {i} vertex {j}: {found} vs {expected}"
            );
        }
    }
    // a draw does not depend on the batch it is drawn in
    let part = Vec::<f32>::try_from(with.noise(&tw, 1, 2, seed).unwrap().flatten(0, -1)).unwrap();
    assert_eq!(part, xw[v..]);
    // a target prepared without the prior is refused, and so is another surface
    let e = with.noise(&to, 0, 1, seed).unwrap_err().to_string();
    assert!(e.contains("without the run's prior"), "{e}");
    let big = TriMesh::new(
        mesh.positions()
            .iter()
            .map(|p| p.map(|x| 1.5 * x))
            .collect(),
        mesh.faces().to_vec(),
    )
    .unwrap();
    let e = with.prepare(&big).unwrap_err().to_string();
    assert!(e.contains("the prior is fitted on"), "{e}");
}

/// The prior's draws have the fitted signals' mean and sample covariance
/// (20,000 draws, every entry within 3% of the largest variance), and the
/// config fields read from TOML, are written only when set and refuse
/// what they cannot do.
#[test]
fn gaussian_prior_draws_have_the_datas_mean_and_covariance() {
    let mesh = procedural::icosphere(1);
    let v = mesh.num_vertices();
    let s = signals(&mesh, 6);
    let prior = GaussianPrior::fit(&mesh, s.as_ref(), 64).unwrap();
    assert_eq!(prior.directions(), 5);
    let n = 20_000;
    let mut x = vec![0.0f32; n * v];
    prior.add_draws(&mut x, 0, n, 3, None).unwrap();
    let mean = |rows: &[&[f32]], j: usize| -> f64 {
        rows.iter().map(|r| f64::from(r[j])).sum::<f64>() / rows.len() as f64
    };
    let cov = |rows: &[&[f32]], a: usize, b: usize, ddof: usize| -> f64 {
        let (ma, mb) = (mean(rows, a), mean(rows, b));
        rows.iter()
            .map(|r| (f64::from(r[a]) - ma) * (f64::from(r[b]) - mb))
            .sum::<f64>()
            / (rows.len() - ddof) as f64
    };
    let data: Vec<&[f32]> = (0..6).map(|i| s.signal(i)).collect();
    let draws: Vec<&[f32]> = x.chunks(v).collect();
    let largest = (0..v).map(|j| cov(&data, j, j, 1)).fold(0.0, f64::max);
    assert!(largest > 1e-3);
    for a in 0..v {
        assert!((mean(&draws, a) - mean(&data, a)).abs() < 0.03 * largest.sqrt());
        for b in 0..v {
            let (d, g) = (cov(&data, a, b, 1), cov(&draws, a, b, 1));
            assert!((d - g).abs() < 0.03 * largest, "cov[{a}, {b}]: {g} vs {d}");
        }
    }

    let c = RunConfig::from_toml_str(
        "[noise]\nprior = \"gaussian\"\nprior_directions = 8\n",
        "t.toml",
    )
    .unwrap();
    assert_eq!(
        (c.noise.prior, c.noise.prior_directions),
        (PriorKind::Gaussian, 8)
    );
    let text = c.to_toml_string().unwrap();
    assert!(text.contains("prior = \"gaussian\"") && text.contains("prior_directions = 8"));
    assert!(
        !RunConfig::default()
            .to_toml_string()
            .unwrap()
            .contains("prior")
    );
    let e = RunConfig::from_toml_str("[noise]\nprior = \"laplace\"\n", "t.toml")
        .unwrap_err()
        .to_string();
    assert!(e.contains("laplace") && e.contains("gaussian"), "{e}");
    let mut zero = c.clone();
    zero.noise.prior_directions = 0;
    let e = zero.validate().unwrap_err().to_string();
    assert!(e.contains("noise.prior_directions"), "{e}");
    let mut augmented = c;
    augmented.train.augment.shift = 0.1;
    let e = augmented.validate().unwrap_err().to_string();
    assert!(
        e.contains("noise.prior") && e.contains("train.augment"),
        "{e}"
    );
}
