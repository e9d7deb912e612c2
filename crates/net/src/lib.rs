//! # mfm-net
//!
//! PoissonNet (the paper's denoiser, DESIGN.md section 5) on libtorch
//! through `tch`: the layers, the network with its NJF and linear heads,
//! its configuration and presets, safetensors checkpoints, the losses and
//! a training-step benchmark. The tensor operations under it (the
//! differentiable Poisson solve, the mesh operators, the dense and fused
//! kernels, the autograd bridge with its C++ shim) are the
//! [`mfm_kernels`] crate; the items the network's users need from it are
//! re-exported here ([`MeshTensors`], [`runtime`]); [`NetError`] holds
//! their [`KernelError`] beside the network's own errors.
//!
//! This crate links the libtorch 2.13 shared libraries of the project's
//! Python environment (see `cargo xtask setup`); its build script embeds an
//! rpath so binaries run without `LD_LIBRARY_PATH`.
//!
//! ## Modules
//! - [`layers`]: one file per layer kind (complex linear, vector MLP,
//!   vertex MLP, Poisson block); [`model`]: [`PoissonNet`] assembling them;
//!   [`config`]: [`PoissonNetConfig`] with the presets `paper`, `medium`,
//!   `small`.
//! - [`loss`]: mass- and area-weighted MSE, the flow-matching loss.
//! - [`official`]: the official PoissonNet's parameter names and the map
//!   between them and this crate's variables (`mfm import`, `mfm export-weights`).
//! - `bench` (with the `bench` feature, which also builds the kernels'
//!   section timers): `bench::bench_training_step`, what `mfm net bench`
//!   runs. Training and sampling do not need it.
//!
//! ## Devices and element types
//! Everything runs on the CPU; with a CUDA libtorch and a GPU the network and
//! its tensors can live on the GPU ([`runtime::TorchRuntime::preferred_device`])
//! while the sparse solves stay on the CPU (tensors move for each solve).
//! [`PoissonNet::new`] draws the parameters on the CPU and then moves them,
//! so a seed gives the same network on either device. Binaries and tests of
//! this workspace keep a CUDA libtorch's `libtorch_cuda.so` linked (see
//! `crates/kernels/libtorch_link.rs`); a crate of your own that links this one
//! needs the same link argument in its build script, or libtorch will not see
//! the GPU.
//! Parameters are `f32` by default; [`PoissonNet::set_kind`] switches to `f64`
//! (solves then use the `f64` factor).
//!
//! ## CPU performance
//! A training step is dominated by dense products (the complex layers are
//! ~68% of the ~537 GFLOP that a paper-preset step at batch 8 on the
//! 3.5k-vertex bunny takes with four real products per complex product),
//! then by elementwise work on the face features, then by the sparse solves.
//! What this crate does about it:
//! - complex layers at least 64 channels wide take three real products
//!   instead of four (Gauss's form, [`mfm_kernels::dense::complex_linear`]), forward and
//!   in both backward products: the paper step's dense work drops to ~444
//!   GFLOP;
//! - a block's last complex layer runs after the divergence, on vertices:
//!   `div(W g) = div(g) Wr^T + div(i g) Wi^T`
//!   ([`layers::ComplexLinear::forward_divergence`], with both divergences in
//!   one pass, [`MeshTensors::paired_divergence`]): one `[V, 2W] x [2W, W]`
//!   product instead of three `[F, W] x [W, W]` ones, ~392 GFLOP per paper
//!   step;
//! - the solve output `u` is never formed: the columns of the first vertex
//!   MLP's weight that read it are folded into that last complex layer
//!   before the solve (exact, see [`model`]), ~379 GFLOP per paper step
//!   ([`PoissonNetConfig::forward_product_flops`] is the cost model; a test
//!   checks it against the products the layers run,
//!   [`mfm_kernels::dense::counted_product_flops`]);
//! - dense layers use faer's GEMM ([`mfm_kernels::dense`]), ~15-25% faster per core than
//!   the MKL inside the torch wheel on the AMD benchmark machine;
//! - the modulation and the magnitude nonlinearity are single-pass fused
//!   kernels in `f32` ([`mfm_kernels::fused`]), 2-3x less time than the torch graph;
//! - `G`, `G^T A2`, face means are gather kernels ([`mfm_kernels::mesh`]); the first
//!   modulation layer runs on vertices (exact rewrite, see [`model`]);
//! - Rust kernels run on libtorch's own intra-op threads
//!   ([`mfm_kernels::autograd::parallel_for`]; the shim is compiled with OpenMP and linked
//!   against the `libgomp` that ships with libtorch, so there is one pool).
//!
//! Two process settings matter a lot and are the caller's choice:
//! - [`runtime::tune_allocator`]: without it glibc returns every large
//!   activation to the kernel and each step pays page faults for all of them
//!   (measured: 7x slower elementwise products). The benchmark
//!   (`bench::bench_training_step`) calls it; training binaries should
//!   too, once at start-up.
//! - libtorch's OpenMP workers busy-wait between parallel regions (the
//!   default policy). On an otherwise idle machine that is the fast choice:
//!   the small preset's batch-1 inference took 25-27 ms with it and 35-52 ms
//!   with `OMP_WAIT_POLICY=PASSIVE`, which puts the workers to sleep after
//!   each region. On a machine shared with other busy processes the spinning
//!   makes multi-threaded runs several times slower; start such runs with
//!   `OMP_WAIT_POLICY=PASSIVE` in the environment (it is read when libtorch
//!   loads, so it cannot be set from inside the process), or use one thread
//!   (`tch::set_num_threads(1)`), as the tests do for tiny meshes.
//!
//! ## Example
//! ```
//! use mfm_geometry::procedural;
//! use mfm_net::{MeshTensors, PoissonNet, PoissonNetConfig, loss};
//! use tch::{Device, Kind, Tensor};
//!
//! let mesh = procedural::icosphere(2);
//! let mt = MeshTensors::new(&mesh).unwrap();
//! let cfg = PoissonNetConfig { width: 8, blocks: 1, ..PoissonNetConfig::small() };
//! let net = PoissonNet::new(&cfg, Device::Cpu).unwrap();
//! let v = mt.num_vertices() as i64;
//! let x = Tensor::randn([4, v, 3], (Kind::Float, Device::Cpu));
//! let cond = Tensor::randn([4, v, 4], (Kind::Float, Device::Cpu));
//! let out = net.forward(&mt, &x, Some(&cond)).unwrap();
//! let target = Tensor::zeros([4, v, 3], (Kind::Float, Device::Cpu));
//! let l = loss::flow_matching_loss(&mt, &out, &target).unwrap();
//! l.backward(); // through both Poisson solves of the forward pass
//! ```

#[cfg(feature = "bench")]
pub mod bench;
pub mod config;
pub mod error;
pub mod layers;
pub mod loss;
pub mod model;
pub mod official;

pub use config::{HeadKind, PRESETS, PoissonNetConfig};
pub use error::{KernelError, NetError, Result};
pub use mfm_kernels::{Backend, MeshTensors, mesh, runtime};
pub use model::{LayerRow, PoissonNet, PoissonNetOutput, Summary};
