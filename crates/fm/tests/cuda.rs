//! Training and sampling on a CUDA device against the same runs on the CPU.
//! Skips (passes with a note) when libtorch sees no GPU.
//!
//! CUDA's reductions add in another order than the CPU kernels, so the
//! comparisons allow f32 round-off grown over a few Adam steps; a wrong
//! device path (noise, targets or weights on the wrong device, a kernel
//! that reads the wrong memory) gives differences of order one.
#![allow(clippy::unwrap_used)]

use std::collections::BTreeMap;
use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

use mfm_data::InMemorySignals;
use mfm_fm::config::{OdeMethod, RunConfig};
use mfm_fm::device::DeviceChoice;
use mfm_fm::sample::{SampleOptions, Sampler};
use mfm_fm::train::Trainer;
use mfm_geometry::{TriMesh, procedural};
use mfm_train::LrSchedule;
use mfm_train::checkpoint::{LOG_FILE, WEIGHTS_FILE};
use tch::{Device, Tensor};

fn signals(mesh: &TriMesh, count: usize) -> Arc<InMemorySignals> {
    let mut data = Vec::new();
    for i in 0..count {
        for p in mesh.positions() {
            for c in 0..3 {
                let a = 1.0 + i as f64;
                data.push((0.5 * (a * p[c] + 0.3 * c as f64).sin() * p[(c + 1) % 3]) as f32);
            }
        }
    }
    Arc::new(InMemorySignals::new(data, count, mesh.num_vertices(), 3).unwrap())
}

fn config(device: DeviceChoice) -> RunConfig {
    let mut c = RunConfig::preset("cpu").unwrap();
    c.model.width = Some(16);
    c.model.blocks = Some(2);
    c.model.vector_layers = Some(2);
    c.train.steps = 6;
    c.train.batch = 3;
    c.train.lr = 1e-3;
    c.train.lr_schedule = LrSchedule::constant();
    c.train.checkpoint_every = 3;
    c.train.log_every = 1;
    c.train.seed = 5;
    c.train.threads = 1;
    c.train.device = device;
    c.sample.steps = 3;
    c
}

fn losses(run: &Path) -> Vec<f64> {
    std::fs::read_to_string(run.join(LOG_FILE))
        .unwrap()
        .lines()
        .skip(1)
        .map(|l| l.split(',').nth(1).unwrap().parse().unwrap())
        .collect()
}

fn weights(path: &Path) -> BTreeMap<String, Tensor> {
    Tensor::read_safetensors(path)
        .unwrap()
        .into_iter()
        .collect()
}

/// Largest entry-wise difference relative to the largest magnitude of `b`.
fn rel_diff(a: &[f32], b: &[f32]) -> f32 {
    assert_eq!(a.len(), b.len());
    let scale = b.iter().fold(0.0f32, |m, x| m.max(x.abs())).max(1e-12);
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0f32, f32::max)
        / scale
}

fn values(t: &Tensor) -> Vec<f32> {
    Vec::<f32>::try_from(t.to_device(Device::Cpu).flatten(0, -1)).unwrap()
}

#[test]
fn training_and_sampling_on_cuda_match_the_cpu() {
    if !tch::Cuda::is_available() {
        eprintln!("SKIPPED: no CUDA device visible to libtorch");
        return;
    }
    let gpu = Device::Cuda(0);
    let mesh = procedural::icosphere(2);
    let data = signals(&mesh, 4);
    let stop = AtomicBool::new(false);

    let cpu_run = tempfile::tempdir().unwrap();
    let mut t = Trainer::new(
        cpu_run.path(),
        config(DeviceChoice::Cpu),
        &mesh,
        data.clone(),
    )
    .unwrap();
    assert_eq!(t.device(), Device::Cpu);
    t.run(&stop, false).unwrap();

    let gpu_run = tempfile::tempdir().unwrap();
    let mut t = Trainer::new(
        gpu_run.path(),
        config(DeviceChoice::Cuda),
        &mesh,
        data.clone(),
    )
    .unwrap();
    assert_eq!(t.device(), gpu);
    assert!(t.run(&stop, false).unwrap().finished);

    // same seed: same minibatches, noise and times, so the same losses and
    // weights up to round-off
    let (lc, lg) = (losses(cpu_run.path()), losses(gpu_run.path()));
    assert_eq!(lc.len(), 6);
    for (step, (c, g)) in lc.iter().zip(&lg).enumerate() {
        let rel = (c - g).abs() / c.abs();
        eprintln!(
            "step {}: loss cpu {c:.6e} cuda {g:.6e} (rel {rel:.1e})",
            step + 1
        );
        assert!(
            rel < 2e-3,
            "step {}: loss {c} on the CPU, {g} on CUDA",
            step + 1
        );
    }
    let (wc, wg) = (
        weights(&cpu_run.path().join(WEIGHTS_FILE)),
        weights(&gpu_run.path().join(WEIGHTS_FILE)),
    );
    assert_eq!(wc.keys().collect::<Vec<_>>(), wg.keys().collect::<Vec<_>>());
    let worst = wc
        .iter()
        .map(|(k, t)| (rel_diff(&values(&wg[k]), &values(t)), k))
        .fold((0.0f32, String::new()), |m, (d, k)| {
            if d > m.0 { (d, k.clone()) } else { m }
        });
    eprintln!(
        "final weights: largest relative difference {:.1e} ({})",
        worst.0, worst.1
    );
    assert!(worst.0 < 1e-2, "weights {} differ by {}", worst.1, worst.0);

    // a run interrupted on the GPU resumes there and ends where the
    // uninterrupted one did (up to CUDA's non-deterministic reductions)
    let stopped_on_gpu_at_3 = || {
        let dir = tempfile::tempdir().unwrap();
        Trainer::new(dir.path(), config(DeviceChoice::Cuda), &mesh, data.clone())
            .unwrap()
            .run_until(3, &stop, false)
            .unwrap();
        dir
    };
    let resumed = stopped_on_gpu_at_3();
    let mut t = Trainer::resume(resumed.path(), &mesh, data.clone()).unwrap();
    assert_eq!((t.resumed().unwrap().step, t.device()), (3, gpu));
    t.run(&stop, false).unwrap();
    let lr = losses(resumed.path());
    for (g, r) in lg.iter().zip(&lr) {
        assert!((g - r).abs() / g.abs() < 1e-4, "resumed loss {r} vs {g}");
    }
    // ... and, moved to the CPU at step 3, also ends there
    let moved = stopped_on_gpu_at_3();
    let mut t = Trainer::resume_on(moved.path(), &mesh, data.clone(), DeviceChoice::Cpu).unwrap();
    assert_eq!(t.device(), Device::Cpu);
    t.run(&stop, false).unwrap();
    for (g, m) in lg.iter().zip(&losses(moved.path())) {
        assert!(
            (g - m).abs() / g.abs() < 1e-4,
            "loss after the move {m} vs {g}"
        );
    }

    // sampling the CPU-trained model on the GPU and on the CPU, on a
    // refinement of the training mesh
    let fine = procedural::icosphere(3);
    let opts = SampleOptions {
        steps: 3,
        method: OdeMethod::Midpoint,
        batch: 2,
    };
    let on_cpu = Sampler::load(cpu_run.path(), Some(Device::Cpu))
        .unwrap()
        .sample(&fine, 3, 9, &opts)
        .unwrap();
    let on_gpu = Sampler::load(cpu_run.path(), Some(gpu))
        .unwrap()
        .sample(&fine, 3, 9, &opts)
        .unwrap();
    let d = rel_diff(&on_gpu.data, &on_cpu.data);
    eprintln!("samples on CUDA vs CPU: relative difference {d:.1e}");
    assert!(on_gpu.data.iter().all(|x| x.is_finite()));
    assert!(d < 1e-4, "samples differ by {d}");
    // a GPU-trained run samples on the CPU (weights come back to the host)
    let from_gpu_run = Sampler::load(gpu_run.path(), Some(Device::Cpu))
        .unwrap()
        .sample(&fine, 3, 9, &opts)
        .unwrap();
    let d = rel_diff(&from_gpu_run.data, &on_cpu.data);
    eprintln!("GPU-trained vs CPU-trained samples: relative difference {d:.1e}");
    assert!(d < 1e-2, "samples of the two runs differ by {d}");
    eprintln!("CUDA training and sampling check passed on {gpu:?}");
}
