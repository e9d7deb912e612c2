//! Training-step and inference timings on synthetic flow-matching inputs
//! (what `mfm net bench` reports).
//!
//! A step is: build `x_t = (1 - t) f_0 + t f_1` for a batch (`f_0` Gaussian
//! noise, `f_1` a smooth deformation of the mesh's normalized positions, `t`
//! uniform per item), run the network with the source positions and `t` as
//! conditioning, compute [`crate::loss::flow_matching_loss`] against
//! `f_1 - f_0`, backpropagate, and take an Adam step. Inputs are made before
//! the timer starts. Inference is one forward pass with batch 1 under
//! `no_grad`.

use std::time::Instant;

use mfm_geometry::TriMesh;
use tch::nn::OptimizerConfig;
use tch::{Device, Kind, Tensor, nn};

use crate::config::PoissonNetConfig;
use crate::error::{NetError, Result};
use crate::loss::flow_matching_loss;
use crate::model::PoissonNet;
use mfm_kernels::mesh::MeshTensors;
use mfm_kernels::profile;

/// Options of [`bench_training_step`].
#[derive(Clone, Debug, PartialEq)]
pub struct BenchOptions {
    /// Batch size of the training steps.
    pub batch: usize,
    /// Timed training steps (the median is reported).
    pub steps: usize,
    /// Untimed steps first (allocator and thread-pool warm-up).
    pub warmup: usize,
    /// Timed batch-1 forward passes (the median is reported); 0 skips them.
    pub inference_runs: usize,
    /// libtorch intra-op threads (`None`: leave libtorch's setting).
    pub threads: Option<i32>,
    /// Where the network and tensors live (solves always run on the CPU).
    pub device: Device,
    /// Adam learning rate.
    pub learning_rate: f64,
    /// Seed of the weights and the synthetic inputs.
    pub seed: i64,
    /// Also collect per-section times ([`mfm_kernels::profile`]).
    pub profile: bool,
    /// Call [`mfm_kernels::runtime::tune_allocator`] first (recommended).
    pub tune_allocator: bool,
}

impl Default for BenchOptions {
    fn default() -> Self {
        Self {
            batch: 8,
            steps: 5,
            warmup: 1,
            inference_runs: 5,
            threads: None,
            device: Device::Cpu,
            learning_rate: 1e-4,
            seed: 0,
            profile: false,
            tune_allocator: true,
        }
    }
}

/// One row of [`BenchReport::sections`] (per timed step).
#[derive(Clone, Debug, PartialEq)]
pub struct SectionRow {
    /// Section name (see [`mfm_kernels::profile`]).
    pub name: String,
    /// Wall seconds per step.
    pub wall: f64,
    /// Process CPU seconds per step.
    pub cpu: f64,
    /// Calls per step.
    pub calls: f64,
}

/// Timings of [`bench_training_step`], in seconds.
#[derive(Clone, Debug, PartialEq)]
pub struct BenchReport {
    /// Vertices of the mesh.
    pub num_vertices: usize,
    /// Faces of the mesh.
    pub num_faces: usize,
    /// Trainable parameters of the network.
    pub num_parameters: usize,
    /// Dense-product work of one forward pass of one batch item
    /// ([`crate::PoissonNetConfig::forward_product_flops`]); a training step
    /// does `3 * batch` times this.
    pub forward_product_flops: u64,
    /// Batch size of the training steps.
    pub batch: usize,
    /// libtorch intra-op threads during the run.
    pub threads: i32,
    /// Building the mesh tensors and factoring `L + eps I`.
    pub setup_seconds: f64,
    /// Each timed training step (forward, backward, Adam).
    pub step_seconds: Vec<f64>,
    /// Forward part of each timed step.
    pub forward_seconds: Vec<f64>,
    /// Backward part of each timed step.
    pub backward_seconds: Vec<f64>,
    /// Adam part of each timed step.
    pub optimizer_seconds: Vec<f64>,
    /// Process CPU time (all threads) of each timed step; with `T` threads
    /// `cpu / (T * wall)` is the parallel efficiency, and on a loaded machine
    /// it is a steadier measure of the work than the wall time.
    pub step_cpu_seconds: Vec<f64>,
    /// Each timed batch-1 inference.
    pub inference_seconds: Vec<f64>,
    /// With [`BenchOptions::profile`]: per section, the wall and CPU seconds
    /// and calls per timed step, sorted by CPU time.
    pub sections: Vec<SectionRow>,
}

pub use mfm_kernels::profile::process_cpu_seconds;

/// Median of a sample (0 for an empty one).
pub fn median(xs: &[f64]) -> f64 {
    if xs.is_empty() {
        return 0.0;
    }
    let mut v = xs.to_vec();
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

impl BenchReport {
    /// Median training-step time.
    pub fn median_step(&self) -> f64 {
        median(&self.step_seconds)
    }

    /// Median batch-1 inference time.
    pub fn median_inference(&self) -> f64 {
        median(&self.inference_seconds)
    }

    /// With [`BenchOptions::profile`]: wall seconds per step spent inside the
    /// dense layers' autograd nodes, forward and backward ([`mfm_kernels::dense`]'s
    /// `linear` and `complex_linear` sections: the products and the bias
    /// and sum passes around them); `None` without a profile or when no
    /// dense layer ran on the CPU.
    pub fn profiled_product_seconds(&self) -> Option<f64> {
        let dense_node = |section: &str| {
            section.strip_prefix("fn:").is_some_and(|node| {
                mfm_kernels::dense::NODE_NAMES.contains(&node.strip_suffix("^T").unwrap_or(node))
            })
        };
        let total: f64 = self
            .sections
            .iter()
            .filter(|r| dense_node(&r.name))
            .map(|r| r.wall)
            .sum();
        (total > 0.0).then_some(total)
    }

    /// Dense-product work of one training step: `3 * batch *
    /// forward_product_flops` (forward, then input and weight gradients).
    pub fn step_product_flops(&self) -> u64 {
        3 * self.batch as u64 * self.forward_product_flops
    }
}

impl std::fmt::Display for BenchReport {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        writeln!(
            f,
            "mesh: {} vertices, {} faces; {} parameters; batch {}; {} threads",
            self.num_vertices, self.num_faces, self.num_parameters, self.batch, self.threads
        )?;
        writeln!(
            f,
            "setup (operators + factor): {:.1} ms",
            self.setup_seconds * 1e3
        )?;
        writeln!(
            f,
            "training step (median of {}): {:.3} s  [forward {:.3} s, backward {:.3} s, adam {:.3} s; cpu {:.3} s]",
            self.step_seconds.len(),
            self.median_step(),
            median(&self.forward_seconds),
            median(&self.backward_seconds),
            median(&self.optimizer_seconds),
            median(&self.step_cpu_seconds)
        )?;
        if !self.inference_seconds.is_empty() {
            writeln!(
                f,
                "inference, batch 1 (median of {}): {:.1} ms",
                self.inference_seconds.len(),
                self.median_inference() * 1e3
            )?;
        }
        let step_flops = self.step_product_flops() as f64;
        if step_flops > 0.0 && !self.step_seconds.is_empty() {
            write!(
                f,
                "dense products: {} GFLOP per step ({:.0} GFLOP/s over the whole step)",
                three_digits(step_flops * 1e-9),
                step_flops * 1e-9 / self.median_step()
            )?;
            if !self.inference_seconds.is_empty() {
                let inference_flops = self.forward_product_flops as f64;
                write!(
                    f,
                    ", {} per inference ({:.0} GFLOP/s)",
                    three_digits(inference_flops * 1e-9),
                    inference_flops * 1e-9 / self.median_inference()
                )?;
            }
            writeln!(f)?;
        }
        if let Some(products) = self.profiled_product_seconds() {
            let step = self.median_step();
            writeln!(
                f,
                "profiled: {:.3} s per step in the dense layers ({:.0} GFLOP/s), {:.3} s in everything else",
                products,
                self.step_product_flops() as f64 * 1e-9 / products,
                (step - products).max(0.0)
            )?;
        }
        if !self.sections.is_empty() {
            writeln!(
                f,
                "{:<42} {:>9} {:>9} {:>7}",
                "sections (per step)", "wall s", "cpu s", "calls"
            )?;
            for r in &self.sections {
                writeln!(
                    f,
                    "  {:<40} {:>9.4} {:>9.4} {:>7.1}",
                    r.name, r.wall, r.cpu, r.calls
                )?;
            }
        }
        Ok(())
    }
}

/// `x` with three significant digits, or more where it has more integer
/// digits.
///
/// ```
/// use mfm_net::bench::three_digits;
/// assert_eq!(three_digits(378.73), "379");
/// assert_eq!(three_digits(15.78), "15.8");
/// assert_eq!(three_digits(0.17094), "0.171");
/// assert_eq!(three_digits(1234.4), "1234");
/// assert_eq!(three_digits(0.0), "0");
/// ```
pub fn three_digits(x: f64) -> String {
    let decimals = if x > 0.0 && x.is_finite() {
        (2 - x.log10().floor() as i64).clamp(0, 9) as usize
    } else {
        0
    };
    format!("{x:.decimals$}")
}

/// Waits for queued GPU work so that timers measure it.
fn sync(device: Device) {
    if let Device::Cuda(i) = device {
        tch::Cuda::synchronize(i as i64);
    }
}

/// Synthetic flow-matching batch on `mesh`: `(x_t [B,V,3], cond [B,V,4],
/// delta [B,V,3])` with positions centred and scaled to unit bounding-box
/// diagonal.
pub fn synthetic_batch(
    mesh: &TriMesh,
    batch: usize,
    kind: Kind,
    device: Device,
) -> (Tensor, Tensor, Tensor) {
    let (lo, hi) = mesh.bounding_box();
    let diag = mesh.bounding_box_diagonal().max(f64::MIN_POSITIVE);
    let centre = [
        0.5 * (lo[0] + hi[0]),
        0.5 * (lo[1] + hi[1]),
        0.5 * (lo[2] + hi[2]),
    ];
    let flat: Vec<f64> = mesh
        .positions()
        .iter()
        .flat_map(|p| (0..3).map(move |i| (p[i] - centre[i]) / diag))
        .collect();
    let v = mesh.num_vertices() as i64;
    let b = batch as i64;
    let opts = (kind, device);
    let src = Tensor::from_slice(&flat)
        .reshape([1, v, 3])
        .to_kind(kind)
        .to_device(device);
    // a smooth deformation: bend and twist
    let x = src.select(2, 0);
    let y = src.select(2, 1);
    let z = src.select(2, 2);
    let target = Tensor::stack(
        &[
            &x + (&y * 3.0).sin() * 0.05,
            &y * 1.1,
            &z + (&x * 4.0).cos() * 0.05,
        ],
        2,
    );
    let f1 = target.expand([b, v, 3], false);
    let f0 = Tensor::randn([b, v, 3], opts) * 0.1;
    let t = Tensor::rand([b, 1, 1], opts);
    let xt = (Tensor::ones_like(&t) - &t) * &f0 + &t * &f1;
    let cond = Tensor::cat(
        &[src.expand([b, v, 3], false), t.expand([b, v, 1], false)],
        2,
    );
    let delta = f1 - f0;
    (xt, cond, delta)
}

/// Times training steps and batch-1 inference of a network with `config`
/// on `mesh` (see the [module docs](self)).
///
/// Errors: mesh operator / factorization errors, or [`NetError::Config`] for
/// an unusable configuration (the synthetic inputs need `C_in = C_out = 3`
/// and `C_e = 4`).
///
/// # Example
/// ```
/// use mfm_geometry::procedural;
/// use mfm_net::PoissonNetConfig;
/// use mfm_net::bench::{BenchOptions, bench_training_step};
///
/// let cfg = PoissonNetConfig { width: 8, blocks: 1, ..PoissonNetConfig::small() };
/// let opts = BenchOptions { batch: 2, steps: 1, warmup: 0, inference_runs: 1, ..Default::default() };
/// let report = bench_training_step(&procedural::icosphere(1), &cfg, &opts).unwrap();
/// assert_eq!(report.step_seconds.len(), 1);
/// println!("{report}");
/// ```
pub fn bench_training_step(
    mesh: &TriMesh,
    config: &PoissonNetConfig,
    opts: &BenchOptions,
) -> Result<BenchReport> {
    if config.in_channels != 3 || config.out_channels != 3 || config.cond_channels != 4 {
        return Err(NetError::Config(format!(
            "the benchmark feeds xyz in and out with (source xyz, t) as conditioning: it needs \
             in_channels = out_channels = 3 and cond_channels = 4, found {}, {} and {}",
            config.in_channels, config.out_channels, config.cond_channels
        )));
    }
    if opts.batch == 0 {
        return Err(NetError::Config("batch must be at least 1".into()));
    }
    if opts.tune_allocator {
        mfm_kernels::runtime::tune_allocator();
    }
    if let Some(t) = opts.threads {
        tch::set_num_threads(t.max(1));
    }
    tch::manual_seed(opts.seed);
    let t0 = Instant::now();
    let mt = MeshTensors::new(mesh)?;
    let setup_seconds = t0.elapsed().as_secs_f64();
    let net = PoissonNet::new(config, opts.device)?;
    let mut adam = nn::Adam::default().build(net.var_store(), opts.learning_rate)?;
    let (xt, cond, delta) = synthetic_batch(mesh, opts.batch, Kind::Float, opts.device);

    let mut report = BenchReport {
        num_vertices: mt.num_vertices(),
        num_faces: mt.num_faces(),
        num_parameters: net.num_parameters(),
        forward_product_flops: config.forward_product_flops(mt.num_vertices(), mt.num_faces()),
        batch: opts.batch,
        threads: tch::get_num_threads(),
        setup_seconds,
        step_seconds: Vec::new(),
        forward_seconds: Vec::new(),
        backward_seconds: Vec::new(),
        optimizer_seconds: Vec::new(),
        step_cpu_seconds: Vec::new(),
        inference_seconds: Vec::new(),
        sections: Vec::new(),
    };
    let was_profiling = profile::enabled();
    for step in 0..opts.warmup + opts.steps {
        let timed = step >= opts.warmup;
        if timed && step == opts.warmup && opts.profile {
            profile::reset();
            profile::set_enabled(true);
        }
        let c0 = process_cpu_seconds();
        let t0 = Instant::now();
        let out = net.forward(&mt, &xt, Some(&cond))?;
        let loss = flow_matching_loss(&mt, &out, &delta)?;
        sync(opts.device);
        let t1 = Instant::now();
        adam.zero_grad();
        {
            let _s = profile::section("backward");
            loss.f_backward()?;
            sync(opts.device);
        }
        let t2 = Instant::now();
        adam.step();
        sync(opts.device);
        let t3 = Instant::now();
        if timed {
            report.forward_seconds.push((t1 - t0).as_secs_f64());
            report.backward_seconds.push((t2 - t1).as_secs_f64());
            report.optimizer_seconds.push((t3 - t2).as_secs_f64());
            report.step_seconds.push((t3 - t0).as_secs_f64());
            report.step_cpu_seconds.push(process_cpu_seconds() - c0);
        }
    }
    if opts.profile && opts.steps > 0 {
        let steps = opts.steps as f64;
        let mut sections: Vec<SectionRow> = profile::totals()
            .into_iter()
            .map(|(name, t)| SectionRow {
                name,
                wall: t.wall / steps,
                cpu: t.cpu / steps,
                calls: t.calls as f64 / steps,
            })
            .collect();
        sections.sort_by(|a, b| b.cpu.total_cmp(&a.cpu));
        report.sections = sections;
    }
    profile::set_enabled(was_profiling);

    if opts.inference_runs > 0 {
        let x1 = xt.narrow(0, 0, 1);
        let c1 = cond.narrow(0, 0, 1);
        tch::no_grad(|| -> Result<()> {
            // one untimed run
            net.forward(&mt, &x1, Some(&c1))?;
            for _ in 0..opts.inference_runs {
                let t0 = Instant::now();
                let out = net.forward(&mt, &x1, Some(&c1))?;
                sync(opts.device);
                drop(out);
                report.inference_seconds.push(t0.elapsed().as_secs_f64());
            }
            Ok(())
        })?;
    }
    Ok(report)
}
