//! Sampling: trained runs generate on other triangulations; the ODE
//! integrators match closed forms on a network whose velocity is known.
#![allow(clippy::unwrap_used)]

use std::sync::Arc;
use std::sync::atomic::AtomicBool;

use mfm_data::InMemorySignals;
use mfm_fm::checkpoint::{self, FlowSpec};
use mfm_fm::config::{OdeMethod, RunConfig};
use mfm_fm::device::DeviceChoice;
use mfm_fm::sample::{SampleOptions, Sampler};
use mfm_fm::train::Trainer;
use mfm_geometry::{TriMesh, procedural};
use mfm_net::{HeadKind, PoissonNet, PoissonNetConfig};
use mfm_noise::{NoiseKind, NoiseSampler};
use mfm_train::LrSchedule;
use mfm_train::checkpoint::{self as train_checkpoint, WEIGHTS_FILE};
use tch::{Device, Tensor};

fn signals(mesh: &TriMesh, count: usize, channels: usize) -> Arc<InMemorySignals> {
    let v = mesh.num_vertices();
    let mut data = Vec::new();
    for i in 0..count {
        for p in mesh.positions() {
            for c in 0..channels {
                data.push((p[c % 3] * (1.0 + i as f64) + 0.1 * c as f64) as f32);
            }
        }
    }
    Arc::new(InMemorySignals::new(data, count, v, channels).unwrap())
}

/// Trains a tiny model for a few steps on icosphere(1).
fn tiny_run(dir: &std::path::Path, channels: usize, xyz: bool) -> TriMesh {
    run_of_width(dir, channels, xyz, 8)
}

/// [`tiny_run`] with `width` channels.
/// `preset` shrunk to a W8 K1 network conditioned on xyz, 3 steps of
/// batch 2 on one CPU thread.
fn three_step_xyz_config(preset: &str) -> RunConfig {
    let mut c = RunConfig::preset(preset).unwrap();
    c.model.width = Some(8);
    c.model.blocks = Some(1);
    c.model.condition_on_xyz = true;
    c.train.steps = 3;
    c.train.batch = 2;
    c.train.threads = 1;
    c.train.device = DeviceChoice::Cpu;
    c
}

fn run_of_width(dir: &std::path::Path, channels: usize, xyz: bool, width: usize) -> TriMesh {
    let mesh = procedural::icosphere(1);
    let mut c = RunConfig::preset("cpu").unwrap();
    c.model.width = Some(width);
    c.model.blocks = Some(1);
    c.model.vector_layers = Some(2);
    c.model.condition_on_xyz = xyz;
    c.train.steps = 4;
    c.train.batch = 2;
    c.train.lr_schedule = LrSchedule::constant();
    c.train.checkpoint_every = 2;
    c.train.threads = 1;
    c.train.device = DeviceChoice::Cpu;
    c.sample.steps = 3;
    Trainer::new(dir, c, &mesh, signals(&mesh, 3, channels))
        .unwrap()
        .run(&AtomicBool::new(false), false)
        .unwrap();
    mesh
}

#[test]
fn a_trained_run_samples_on_a_refined_mesh() {
    let run = tempfile::tempdir().unwrap();
    tiny_run(run.path(), 3, true);
    let sampler = Sampler::load(run.path(), Some(Device::Cpu)).unwrap();
    assert!(sampler.flow().condition_on_xyz);
    let fine = procedural::icosphere(2); // a refinement of the training sphere
    let opts = SampleOptions {
        steps: 3,
        method: OdeMethod::Midpoint,
        batch: 2,
    };
    let s = sampler.sample(&fine, 5, 9, &opts).unwrap();
    assert_eq!(
        (s.samples, s.vertices, s.channels),
        (5, fine.num_vertices(), 3)
    );
    assert_eq!(s.data.len(), 5 * fine.num_vertices() * 3);
    assert!(s.data.iter().all(|x| x.is_finite()));
    assert!(s.seconds_per_sample() > 0.0);
    // samples differ from each other and depend on the seed, deterministically
    assert_ne!(s.sample(0), s.sample(1));
    let again = sampler.sample(&fine, 5, 9, &opts).unwrap();
    assert_eq!(again.data, s.data);
    let other = sampler.sample(&fine, 5, 10, &opts).unwrap();
    assert_ne!(other.data, s.data);
    // sample i does not depend on the batch it is generated in (up to the
    // round-off of differently blocked matrix products)
    let one_by_one = sampler
        .sample(&fine, 5, 9, &SampleOptions { batch: 1, ..opts })
        .unwrap();
    let diff = one_by_one
        .data
        .iter()
        .zip(&s.data)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0f32, f32::max);
    assert!(diff < 1e-4, "{diff}");
    // starting noise: the run's kind on the *target* mesh in the training
    // frame, `center(sigma * solve(L + tau M, sqrt(m) n))` (the solve is
    // linear, so sigma before or after it is the same), the centring
    // recomputed here in f64 with the target's own lumped mass
    let flow = sampler.flow();
    assert!(flow.centered && !flow.frame.is_identity());
    assert_eq!(
        flow.frame,
        mfm_geometry::frame::CanonicalFrame::of(&procedural::icosphere(1)).unwrap()
    );
    let target = sampler.prepare(&fine).unwrap();
    let x0 = sampler.noise(&target, 2, 3, 9).unwrap();
    let framed = flow.frame.apply(&fine);
    let direct = NoiseSampler::new(&framed, flow.noise)
        .unwrap()
        .sample_range_f32(2, 3, 3, 9)
        .unwrap();
    let mass = mfm_geometry::operators::lumped_mass(&framed);
    let area: f64 = mass.iter().sum();
    let v = fine.num_vertices();
    let got = values(&x0);
    for i in 0..3 {
        for c in 0..3 {
            let at = |vi: usize| i * v * 3 + vi * 3 + c;
            let raw: Vec<f64> = (0..v)
                .map(|vi| flow.noise_scale * f64::from(direct.data()[at(vi)]))
                .collect();
            let mean = raw.iter().zip(&mass).map(|(x, m)| x * m).sum::<f64>() / area;
            for vi in 0..v {
                let d = (got[at(vi)] - (raw[vi] - mean)).abs();
                assert!(d < 1e-5, "sample {i} channel {c} vertex {vi}: {d}");
            }
            let got_mean = (0..v).map(|vi| got[at(vi)] * mass[vi]).sum::<f64>() / area;
            assert!(got_mean.abs() < 1e-6, "{got_mean}");
        }
    }

    // without the final model, the newest checkpoint is used: same samples
    std::fs::remove_file(run.path().join(WEIGHTS_FILE)).unwrap();
    let from_ckpt = Sampler::load(run.path(), Some(Device::Cpu)).unwrap();
    assert_eq!(from_ckpt.sample(&fine, 5, 9, &opts).unwrap().data, s.data);
    // ... unless it is damaged: then the previous one (another model)
    let last = train_checkpoint::list_checkpoints(run.path())
        .unwrap()
        .pop()
        .unwrap();
    std::fs::write(last.dir.join(checkpoint::FLOW_FILE), "{}").unwrap();
    let older = Sampler::load(run.path(), Some(Device::Cpu)).unwrap();
    assert_ne!(older.sample(&fine, 5, 9, &opts).unwrap().data, s.data);
}

#[test]
fn scalar_runs_sample_with_t_only_conditioning() {
    let run = tempfile::tempdir().unwrap();
    tiny_run(run.path(), 1, false);
    let sampler = Sampler::load(run.path(), None).unwrap();
    let opts = SampleOptions {
        steps: 2,
        method: OdeMethod::Euler,
        batch: 4,
    };
    let fine = procedural::icosphere(3);
    let s = sampler.sample(&fine, 3, 0, &opts).unwrap();
    assert_eq!((s.samples, s.vertices, s.channels), (3, 642, 1));
    assert!(s.data.iter().all(|x| x.is_finite()));
}

/// A network whose velocity is `v(x, t) = alpha x + beta` per vertex: no
/// blocks, `proj_in` picks `x` into the first feature, the linear head reads
/// it back times `alpha` and adds `beta`.
fn affine_velocity_net(alpha: f64, beta: f64) -> PoissonNet {
    let cfg = PoissonNetConfig {
        width: 4,
        blocks: 0,
        vector_layers: 1,
        in_channels: 1,
        out_channels: 1,
        cond_channels: 1,
        modulation: false,
        head: HeadKind::Linear,
        global_context: false,
    };
    let net = PoissonNet::new(&cfg, Device::Cpu).unwrap();
    tch::no_grad(|| {
        for (name, mut t) in net.var_store().variables() {
            let _ = t.zero_();
            match name.as_str() {
                "proj_in.weight" => {
                    let _ = t.get(0).get(0).fill_(1.0);
                }
                "head.linear.weight" => {
                    let _ = t.get(0).get(0).fill_(alpha);
                }
                "head.linear.bias" => {
                    let _ = t.fill_(beta);
                }
                _ => {}
            }
        }
    });
    net
}

fn flow(noise: NoiseKind, offset: f64) -> FlowSpec {
    FlowSpec {
        channels: 1,
        noise,
        noise_scale: 3.0,
        condition_on_xyz: false,
        velocity_offset: vec![offset],
        frame: mfm_geometry::frame::CanonicalFrame::identity(),
        positions: false,
        centered: false,
        training_surface: None,
        prediction: Default::default(),
        displacements: false,
        prior: None,
    }
}

fn values(t: &Tensor) -> Vec<f64> {
    Vec::<f32>::try_from(t.flatten(0, -1))
        .unwrap()
        .into_iter()
        .map(f64::from)
        .collect()
}

#[test]
fn zero_velocity_returns_the_noise() {
    let mesh = procedural::icosphere(2);
    let sampler = Sampler::new(affine_velocity_net(0.0, 0.0), flow(NoiseKind::White, 0.0)).unwrap();
    let target = sampler.prepare(&mesh).unwrap();
    let x0 = sampler.noise(&target, 0, 3, 4).unwrap();
    for method in [OdeMethod::Euler, OdeMethod::Midpoint] {
        let opts = SampleOptions {
            steps: 5,
            method,
            batch: 2,
        };
        let s = sampler.sample_on(&target, 0, 3, 4, &opts).unwrap();
        assert_eq!(s.data, Vec::<f32>::try_from(x0.flatten(0, -1)).unwrap());
    }
}

#[test]
fn every_ode_step_of_every_batch_is_reported_and_changes_nothing() {
    let mesh = procedural::icosphere(1);
    let sampler = Sampler::new(
        affine_velocity_net(0.8, 0.25),
        flow(NoiseKind::Matern { tau: 10.0 }, 0.15),
    )
    .unwrap();
    let target = sampler.prepare(&mesh).unwrap();
    for method in [OdeMethod::Euler, OdeMethod::Midpoint] {
        let opts = SampleOptions {
            steps: 4,
            method,
            batch: 2,
        };
        let reports = std::sync::Mutex::new(Vec::new());
        let seen = sampler
            .sample_on_reporting(&target, 1, 5, 7, &opts, &|b| {
                reports.lock().unwrap().push(b)
            })
            .unwrap();
        // batches of 2, 2, 1 samples, each reported once per ODE step
        let want: Vec<usize> = [2, 2, 1].iter().flat_map(|&b| [b; 4]).collect();
        assert_eq!(reports.into_inner().unwrap(), want);
        assert_eq!(
            seen.data,
            sampler.sample_on(&target, 1, 5, 7, &opts).unwrap().data
        );
    }
}

/// A sampler whose velocity is `a x + bias` plus the flow's `offset`, on a
/// matern noise of `tau = 10`.
fn affine_sampler(a: f64, bias: f64, offset: f64) -> Sampler {
    Sampler::new(
        affine_velocity_net(a, bias),
        flow(NoiseKind::Matern { tau: 10.0 }, offset),
    )
    .unwrap()
}

/// `steps` steps of length `h` of `method` on `dx/dt = a x + b` from
/// `start`, in f64.
fn affine_steps(
    start: &[f64],
    a: f64,
    b: f64,
    h: f64,
    steps: usize,
    method: OdeMethod,
) -> Vec<f64> {
    let (gain, shift) = match method {
        OdeMethod::Euler => (1.0 + a * h, b * h),
        OdeMethod::Midpoint => (
            1.0 + a * h + a * a * h * h / 2.0,
            b * h * (1.0 + a * h / 2.0),
        ),
    };
    let mut x = start.to_vec();
    for _ in 0..steps {
        x.iter_mut().for_each(|v| *v = gain * *v + shift);
    }
    x
}

fn max_err(got: &[f64], want: &[f64]) -> f64 {
    got.iter()
        .zip(want)
        .map(|(g, w)| (g - w).abs())
        .fold(0.0, f64::max)
}

#[test]
fn euler_and_midpoint_match_their_recurrences_and_converge_at_their_orders() {
    // dx/dt = a x + b (b = head bias + velocity offset), x(1) = (x0 + b/a) e^a - b/a
    let (a, bias, offset) = (0.8, 0.25, 0.15);
    let b = bias + offset;
    let mesh = procedural::icosphere(1);
    let sampler = affine_sampler(a, bias, offset);
    let target = sampler.prepare(&mesh).unwrap();
    let x0 = sampler.noise(&target, 0, 2, 1).unwrap();
    let start = values(&x0);
    let exact: Vec<f64> = start
        .iter()
        .map(|x| (x + b / a) * a.exp() - b / a)
        .collect();
    let mut errors = Vec::new();
    for method in [OdeMethod::Euler, OdeMethod::Midpoint] {
        let mut per_steps = Vec::new();
        for steps in [8usize, 16] {
            let want = affine_steps(&start, a, b, 1.0 / steps as f64, steps, method);
            let opts = SampleOptions {
                steps,
                method,
                batch: 2,
            };
            let got = values(&sampler.integrate(&target, &x0, &opts).unwrap());
            assert!(
                max_err(&got, &want) < 1e-5,
                "{method:?} {steps}: {}",
                max_err(&got, &want)
            );
            per_steps.push(max_err(&got, &exact));
        }
        errors.push(per_steps);
    }
    let (euler, midpoint) = (&errors[0], &errors[1]);
    eprintln!("errors vs exact: euler {euler:?}, midpoint {midpoint:?}");
    // first order: halving h halves the error; second order: quarters it
    assert!((euler[0] / euler[1] - 2.0).abs() < 0.3, "{euler:?}");
    assert!(
        (midpoint[0] / midpoint[1] - 4.0).abs() < 0.6,
        "{midpoint:?}"
    );
    assert!(midpoint[1] < euler[1] / 10.0);
}

/// `integrate_from(x, t0)` integrates the rest of the path: from `t0 = 0`
/// it is `integrate` bit for bit, from `t0 = 0.5` its steps are `0.5 /
/// steps` long (the midpoint recurrence on the affine field, and the exact
/// solution `(x + b/a) e^{a (1 - t0)} - b/a` as the steps grow), and a
/// start at `t = 1` or beyond is refused.
#[test]
fn integrating_from_part_of_the_way_takes_the_rest_of_the_path() {
    let (a, bias, offset) = (0.8, 0.25, 0.15);
    let b = bias + offset;
    let mesh = procedural::icosphere(1);
    let sampler = affine_sampler(a, bias, offset);
    let target = sampler.prepare(&mesh).unwrap();
    let x = sampler.noise(&target, 0, 2, 3).unwrap();
    let opts = |steps| SampleOptions {
        steps,
        method: OdeMethod::Midpoint,
        batch: 2,
    };
    assert_eq!(
        values(&sampler.integrate_from(&target, &x, 0.0, &opts(4)).unwrap()),
        values(&sampler.integrate(&target, &x, &opts(4)).unwrap())
    );
    let t0 = 0.5;
    let start = values(&x);
    for steps in [4usize, 64] {
        let h = (1.0 - t0) / steps as f64;
        let want = affine_steps(&start, a, b, h, steps, OdeMethod::Midpoint);
        let got = values(
            &sampler
                .integrate_from(&target, &x, t0, &opts(steps))
                .unwrap(),
        );
        let err = max_err(&got, &want);
        assert!(err < 1e-5, "{steps} steps: {err}");
    }
    let exact: Vec<f64> = start
        .iter()
        .map(|v| (v + b / a) * (a * (1.0 - t0)).exp() - b / a)
        .collect();
    let got = values(&sampler.integrate_from(&target, &x, t0, &opts(64)).unwrap());
    let err = max_err(&got, &exact);
    assert!(err < 1e-4, "against the exact solution: {err}");
    for bad in [1.0, 1.5, -0.1] {
        let e = sampler
            .integrate_from(&target, &x, bad, &opts(4))
            .unwrap_err()
            .to_string();
        assert!(e.contains("[0, 1)"), "{e}");
    }
}

#[test]
fn mismatched_networks_are_rejected() {
    let net = affine_velocity_net(1.0, 0.0);
    let mut f = flow(NoiseKind::White, 0.0);
    f.channels = 3;
    f.velocity_offset = vec![0.0; 3];
    assert!(Sampler::new(net, f).is_err());
    let mut f = flow(NoiseKind::White, 0.0);
    f.condition_on_xyz = true;
    assert!(Sampler::new(affine_velocity_net(1.0, 0.0), f).is_err());
}

#[test]
fn runs_with_non_finite_weights_are_refused_at_load() {
    let run = tempfile::tempdir().unwrap();
    tiny_run(run.path(), 1, false);
    let weights = run.path().join(WEIGHTS_FILE);
    let net = PoissonNet::load(&weights, Device::Cpu).unwrap();
    let (name, mut v) = net.var_store().variables().into_iter().next().unwrap();
    tch::no_grad(|| {
        let _ = v.fill_(f64::NAN);
    });
    net.save(&weights).unwrap();
    // as the trainer does after saving (a diverged run's record matches its
    // NaN weights)
    mfm_train::checkpoint::write_final_record(run.path()).unwrap();
    let err = Sampler::load(run.path(), Some(Device::Cpu)).unwrap_err();
    assert!(matches!(err, mfm_fm::FmError::Diverged(_)), "{err}");
    let msg = err.to_string();
    assert!(msg.contains(&name) && msg.contains(WEIGHTS_FILE), "{msg}");
}

#[test]
fn samples_do_not_depend_on_the_thread_count() {
    // width 64 takes the three-product complex layers; icosphere(3) has
    // enough faces (1280) for the row blocks to split over two threads
    let run = tempfile::tempdir().unwrap();
    run_of_width(run.path(), 3, true, 64);
    let sampler = Sampler::load(run.path(), Some(Device::Cpu)).unwrap();
    let fine = procedural::icosphere(3);
    let opts = SampleOptions {
        steps: 2,
        method: OdeMethod::Midpoint,
        batch: 2,
    };
    let by_threads: Vec<Vec<f32>> = [1, 2]
        .iter()
        .map(|&t| {
            tch::set_num_threads(t);
            sampler.sample(&fine, 2, 4, &opts).unwrap().data
        })
        .collect();
    tch::set_num_threads(1);
    assert!(by_threads[0].iter().all(|x| x.is_finite()));
    assert_eq!(by_threads[0], by_threads[1]);
}

/// A dataset of shapes in odd units (a sphere 40 across, far from the
/// origin), trained on in the canonical frame and sampled on a finer
/// triangulation in the same units: the samples come back in the user's
/// units, the frame is the training mesh's, and a mesh of another size is
/// flagged.
#[test]
fn position_samples_come_back_in_the_datasets_units() {
    use mfm_geometry::frame::CanonicalFrame;
    let (scale, shift) = (20.0, [100.0, -20.0, 5.0]);
    let mesh = procedural::icosphere(1).transformed(scale, shift);
    let v = mesh.num_vertices();
    // shapes: the sphere stretched along x by 1 + i/10, about its centre
    let mut data = Vec::new();
    for i in 0..4 {
        for p in mesh.positions() {
            let x = shift[0] + (p[0] - shift[0]) * (1.0 + 0.1 * i as f64);
            data.extend([x as f32, p[1] as f32, p[2] as f32]);
        }
    }
    let signals = Arc::new(InMemorySignals::new(data, 4, v, 3).unwrap());
    let run = tempfile::tempdir().unwrap();
    let c = three_step_xyz_config("cpu");
    let trainer = Trainer::new(run.path(), c, &mesh, signals).unwrap();
    let flow = trainer.flow().clone();
    assert_eq!(flow.frame, CanonicalFrame::of(&mesh).unwrap());
    assert!((flow.frame.scale - 1.0 / (2.0 * scale)).abs() < 1e-9);
    assert!(flow.positions && flow.centered);
    // the offset is the data's mean in the frame: near the origin
    assert!(
        flow.velocity_offset.iter().all(|o| o.abs() < 0.05),
        "{flow:?}"
    );
    let mut trainer = trainer;
    trainer.run(&AtomicBool::new(false), false).unwrap();

    let sampler = Sampler::load(run.path(), Some(Device::Cpu)).unwrap();
    assert_eq!(sampler.flow(), &flow);
    // midpoint subdivision: the same surface, 4x the faces
    let fine = mfm_geometry::subdivide::midpoint(&mesh).unwrap();
    assert!(sampler.surface_warnings(&fine).is_empty());
    let opts = SampleOptions {
        steps: 2,
        method: OdeMethod::Midpoint,
        batch: 2,
    };
    let s = sampler.sample(&fine, 2, 3, &opts).unwrap();
    // the flow carries no mean, so each sample's mass-weighted centroid is
    // the data's mean centroid, mapped back to the dataset's units
    let mass = mfm_geometry::operators::lumped_mass(&fine);
    let area: f64 = mass.iter().sum();
    let want = flow.frame.from_canonical([
        flow.velocity_offset[0],
        flow.velocity_offset[1],
        flow.velocity_offset[2],
    ]);
    for i in 0..2 {
        let x = s.sample(i);
        for k in 0..3 {
            let c: f64 = (0..fine.num_vertices())
                .map(|vi| mass[vi] * f64::from(x[3 * vi + k]))
                .sum::<f64>()
                / area;
            assert!(
                (c - want[k]).abs() < 1e-3 * scale,
                "sample {i} axis {k}: {c} vs {want:?}"
            );
            assert!(
                (c - shift[k]).abs() < 0.05 * scale,
                "sample {i} axis {k}: {c}"
            );
        }
    }
    // a mesh in other units is flagged, naming both sizes
    let w = sampler.surface_warnings(&fine.transformed(0.05, [0.0; 3]));
    assert_eq!(w.len(), 2, "{w:?}");
    assert!(
        w[0].starts_with("largest bounding-box extent 2 ")
            && w[0].contains("training surface's 40 by 95%"),
        "{w:?}"
    );
    assert!(w[1].contains("area"), "{w:?}");
}

#[test]
fn batches_shrink_on_meshes_whose_activations_would_not_fit() {
    use mfm_fm::sample::{SAMPLE_BATCH_BYTES, SAMPLE_BYTES_PER_FACE_CHANNEL, batch_within_memory};
    // the horse template (16.8k faces) keeps the run's batch of 8
    assert_eq!(batch_within_memory(16_843, 32, 8), 8);
    // its 16x refinement: 269k faces x 32 channels x 128 bytes = 1.1 GB a sample
    let fit = SAMPLE_BATCH_BYTES / (269_488 * 32 * SAMPLE_BYTES_PER_FACE_CHANNEL);
    assert_eq!(fit, 2);
    assert_eq!(batch_within_memory(269_488, 32, 8), fit);
    // a million faces: one at a time, never zero
    assert_eq!(batch_within_memory(1_077_952, 32, 8), 1);
    assert_eq!(batch_within_memory(usize::MAX, usize::MAX, 8), 1);
    assert_eq!(batch_within_memory(0, 0, 3), 3);
    // the sampler uses it: a fine mesh is integrated one sample at a time
    let mesh = procedural::icosphere(1);
    let sampler = Sampler::new(
        affine_velocity_net(0.8, 0.25),
        flow(NoiseKind::Matern { tau: 10.0 }, 0.15),
    )
    .unwrap();
    let target = sampler.prepare(&mesh).unwrap();
    assert_eq!(sampler.batch_on(&target, 4), 4);
}

#[test]
fn noise_carried_to_a_refinement_is_the_coarse_noise_interpolated() {
    let coarse = procedural::icosphere(1);
    let fine = mfm_geometry::subdivide::midpoint(&coarse).unwrap();
    let mut spec = flow(NoiseKind::Matern { tau: 10.0 }, 0.15);
    spec.centered = true;
    let sampler = Sampler::new(affine_velocity_net(0.8, 0.25), spec).unwrap();
    let (n, seed) = (3, 11);
    let c = sampler.flow().channels;
    // onto the same mesh: the sampler's own noise (centring again changes
    // nothing but round-off)
    let own = sampler
        .noise(&sampler.prepare(&coarse).unwrap(), 0, n, seed)
        .unwrap();
    let own = Vec::<f32>::try_from(&own.contiguous().view([-1])).unwrap();
    let same = sampler.carried_noise(&coarse, &coarse, n, seed).unwrap();
    assert_eq!(same.shape, [n, coarse.num_vertices(), c]);
    let worst = own
        .iter()
        .zip(&same.values)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0f32, f32::max);
    assert!(worst < 1e-5, "{worst}");
    // onto the midpoint subdivision: the coarse vertices keep their values
    // (the first vertices of the subdivision, up to one constant per
    // channel from centring with the fine mass) and every new vertex is
    // the mean of an edge's ends, so the fine noise is piecewise linear
    let carried = sampler.carried_noise(&coarse, &fine, n, seed).unwrap();
    let (vc, vf) = (coarse.num_vertices(), fine.num_vertices());
    assert_eq!(carried.shape, [n, vf, c]);
    let key = |p: [f64; 3]| p.map(|x| (x * 1e9).round() as i64);
    let mut edge_of_midpoint = std::collections::HashMap::new();
    for f in coarse.faces() {
        for (a, b) in [(f[0], f[1]), (f[1], f[2]), (f[2], f[0])] {
            let (pa, pb) = (
                coarse.positions()[a as usize],
                coarse.positions()[b as usize],
            );
            let m = [0, 1, 2].map(|i| 0.5 * (pa[i] + pb[i]));
            edge_of_midpoint.insert(key(m), (a as usize, b as usize));
        }
    }
    for s in 0..n {
        for k in 0..c {
            let at = |v: usize| carried.values[(s * vf + v) * c + k];
            let was = |v: usize| own[(s * vc + v) * c + k];
            let shift = at(0) - was(0);
            for v in 0..vc {
                assert!(
                    (at(v) - was(v) - shift).abs() < 1e-5,
                    "sample {s} vertex {v}"
                );
            }
            for v in vc..vf {
                let (a, b) = edge_of_midpoint[&key(fine.positions()[v])];
                let mean = 0.5 * (was(a) + was(b));
                assert!((at(v) - mean - shift).abs() < 1e-5, "sample {s} vertex {v}");
            }
        }
    }
    // and its mass-weighted mean is zero on the fine mesh (a centred run)
    let mass = mfm_geometry::operators::lumped_mass(&fine);
    for k in 0..c {
        let mean: f64 = (0..vf)
            .map(|v| f64::from(carried.values[v * c + k]) * mass[v])
            .sum::<f64>()
            / mass.iter().sum::<f64>();
        assert!(mean.abs() < 1e-6, "{mean}");
    }
    // a mesh off the surface (another scale) is refused, naming why
    let bigger = fine.transformed(2.0, [0.0; 3]);
    let e = sampler
        .carried_noise(&coarse, &bigger, n, seed)
        .unwrap_err();
    assert!(e.to_string().contains("same surface"), "{e}");
}

/// A sampler that starts from given noise prepares its targets without a
/// noise sampler (the noise factor would go unused on a fine mesh) and
/// gives exactly the samples of one that draws that same noise.
#[test]
fn starting_noise_prepares_no_noise_sampler_and_gives_the_same_samples() {
    let mesh = procedural::icosphere(2);
    let spec = flow(NoiseKind::Matern { tau: 10.0 }, 0.15);
    let drawing = Sampler::new(affine_velocity_net(0.8, 0.25), spec.clone()).unwrap();
    let opts = SampleOptions {
        steps: 3,
        method: OdeMethod::Midpoint,
        batch: 2,
    };
    let (n, seed) = (3, 4);
    let target = drawing.prepare(&mesh).unwrap();
    assert!(target.noise_sampler().is_some());
    // sampling solves and draws in f32: neither factor keeps its f64 values
    assert!(!target.mesh_tensors().solver().holds_f64_factor());
    let noise_factor = target.noise_sampler().unwrap().screened_poisson();
    assert!(!noise_factor.unwrap().holds_f64_factor());
    let drawn = drawing.sample_on(&target, 0, n, seed, &opts).unwrap();
    let noise = drawing.noise(&target, 0, n, seed).unwrap();
    let values = Vec::<f32>::try_from(&noise.contiguous().view([-1])).unwrap();
    let start = mfm_fm::sample::StartNoise {
        values,
        shape: [n, mesh.num_vertices(), drawing.flow().channels],
    };
    let given = Sampler::new(affine_velocity_net(0.8, 0.25), spec)
        .unwrap()
        .with_start_noise(start)
        .unwrap();
    let bare = given.prepare(&mesh).unwrap();
    assert!(bare.noise_sampler().is_none());
    assert!(!bare.mesh_tensors().solver().holds_f64_factor());
    let from_start = given.sample_on(&bare, 0, n, seed, &opts).unwrap();
    assert_eq!(from_start.data, drawn.data);
    // a target prepared without noise cannot draw it
    let e = drawing.noise(&bare, 0, n, seed).unwrap_err().to_string();
    assert!(e.contains("prepare it again"), "{e}");
}

#[test]
fn face_blocks_give_the_same_samples() {
    let mesh = procedural::icosphere(2);
    let sampler = Sampler::new(
        affine_velocity_net(0.8, 0.25),
        flow(NoiseKind::Matern { tau: 10.0 }, 0.15),
    )
    .unwrap();
    let opts = SampleOptions {
        steps: 3,
        method: OdeMethod::Midpoint,
        batch: 2,
    };
    let whole = sampler.prepare(&mesh).unwrap();
    // a small mesh is one block: the network runs on it whole
    assert_eq!(whole.face_block_count(), 1);
    let a = sampler.sample_on(&whole, 0, 3, 5, &opts).unwrap();
    let blocked = sampler.prepare(&mesh).unwrap().with_face_blocks(Some(77));
    assert_eq!(blocked.face_block_count(), mesh.num_faces().div_ceil(77));
    let b = sampler.sample_on(&blocked, 0, 3, 5, &opts).unwrap();
    let worst = a
        .data
        .iter()
        .zip(&b.data)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0f32, f32::max);
    assert!(worst < 1e-5, "{worst}");
    assert_eq!(mfm_fm::sample::faces_per_block(32), 262_144);
}

/// A run that generates displacements (`model.displacements`) trains on
/// each shape minus the training mesh, and its samples are the generated
/// field plus the vertices of whatever mesh they are sampled on: the end of
/// an ODE that stays at zero is that mesh itself, in the dataset's units,
/// on the training mesh and on a refinement alike.
#[test]
fn displacement_runs_train_on_shape_minus_mesh_and_sample_around_the_sampled_mesh() {
    let (scale, shift) = (20.0, [100.0, -20.0, 5.0]);
    let mesh = procedural::icosphere(1).transformed(scale, shift);
    let v = mesh.num_vertices();
    // shape i: the sphere with its upper half lifted by i (dataset units)
    let lift = |i: usize, p: &[f64; 3]| if p[2] > shift[2] { i as f64 } else { 0.0 };
    let mut data = Vec::new();
    for i in 0..4 {
        for p in mesh.positions() {
            data.extend([p[0] as f32, p[1] as f32, (p[2] + lift(i, p)) as f32]);
        }
    }
    let signals = Arc::new(InMemorySignals::new(data, 4, v, 3).unwrap());
    let mut c = three_step_xyz_config("cpu-deform");
    c.model.displacements = true;
    let run = tempfile::tempdir().unwrap();
    let mut trainer = Trainer::new(run.path(), c.clone(), &mesh, signals.clone()).unwrap();
    let flow = trainer.flow().clone();
    assert!(flow.displacements && flow.positions && flow.centered);
    // the offset is the mean displacement in the frame: the upper half's
    // share of the area times the mean lift (1.5), scaled into the frame
    let mass = mfm_geometry::operators::lumped_mass(&mesh);
    let area: f64 = mass.iter().sum();
    let upper: f64 = mesh
        .positions()
        .iter()
        .zip(&mass)
        .filter(|(p, _)| p[2] > shift[2])
        .map(|(_, m)| m)
        .sum();
    let want = 1.5 * upper / area * flow.frame.scale;
    assert!(flow.velocity_offset[0].abs() < 1e-6, "{flow:?}");
    assert!(flow.velocity_offset[1].abs() < 1e-6, "{flow:?}");
    assert!(
        (flow.velocity_offset[2] - want).abs() < 1e-6,
        "{} vs {want}",
        flow.velocity_offset[2]
    );
    // the flag is written only when set: flow.json of other runs is unchanged
    let text = std::fs::read_to_string(run.path().join(checkpoint::FLOW_FILE)).unwrap();
    assert!(text.contains("\"displacements\": true"), "{text}");
    trainer.run(&AtomicBool::new(false), false).unwrap();
    let positions_run = tempfile::tempdir().unwrap();
    let mut p = c.clone();
    p.model.displacements = false;
    p.train.steps = 1;
    Trainer::new(positions_run.path(), p, &mesh, signals.clone())
        .unwrap()
        .run(&AtomicBool::new(false), false)
        .unwrap();
    let text = std::fs::read_to_string(positions_run.path().join(checkpoint::FLOW_FILE)).unwrap();
    assert!(!text.contains("displacements"), "{text}");

    // the ODE's end as samples: zero -> the sampled mesh; d -> mesh + d / s
    let sampler = Sampler::load(run.path(), Some(Device::Cpu)).unwrap();
    assert!(sampler.flow().displacements);
    let fine = mfm_geometry::subdivide::midpoint(&mesh).unwrap();
    for m in [&mesh, &fine] {
        let target = sampler.prepare(m).unwrap();
        let n = m.num_vertices() as i64;
        let offset: Vec<f32> = flow.velocity_offset.iter().map(|&x| x as f32).collect();
        let offset = Tensor::from_slice(&offset).reshape([1, 1, 3]);
        let ends = [
            Tensor::zeros([1, n, 3], (tch::Kind::Float, Device::Cpu)) - &offset,
            Tensor::full([1, n, 3], 0.25, (tch::Kind::Float, Device::Cpu)) - &offset,
        ];
        for (end, d) in ends.iter().zip([0.0, 0.25]) {
            let x = values(&sampler.finish(&target, end));
            for (vi, p) in m.positions().iter().enumerate() {
                for k in 0..3 {
                    let want = p[k] + d / flow.frame.scale;
                    assert!(
                        (x[3 * vi + k] - want).abs() < 1e-4 * scale,
                        "vertex {vi} axis {k}: {} vs {want}",
                        x[3 * vi + k]
                    );
                }
            }
        }
    }
    // and it samples on the refinement
    let opts = SampleOptions {
        steps: 2,
        method: OdeMethod::Midpoint,
        batch: 2,
    };
    let s = sampler.sample(&fine, 2, 3, &opts).unwrap();
    assert_eq!(s.data.len(), 2 * fine.num_vertices() * 3);
    assert!(s.data.iter().all(|x| x.is_finite()));
}
