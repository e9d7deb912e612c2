//! The network on a CUDA device (solves on the CPU) against the CPU run.
//! Skips (passes with a note) when libtorch sees no GPU.
#![allow(clippy::unwrap_used)]

#[path = "../../kernels/tests/common/mod.rs"]
mod common;

use common::rel_max_diff;
use mfm_geometry::procedural;
use mfm_net::loss::flow_matching_loss;
use mfm_net::{HeadKind, MeshTensors, PoissonNet, PoissonNetConfig};
use tch::{Device, Kind, Tensor};

#[test]
fn cuda_forward_and_gradients_match_cpu() {
    if !tch::Cuda::is_available() {
        eprintln!("SKIPPED: no CUDA device visible to libtorch");
        return;
    }
    let gpu = Device::Cuda(0);
    let mesh = procedural::icosphere(2);
    let mt = MeshTensors::new(&mesh).unwrap();
    let cfg = PoissonNetConfig {
        width: 16,
        blocks: 2,
        vector_layers: 3,
        in_channels: 3,
        out_channels: 3,
        cond_channels: 4,
        modulation: true,
        head: HeadKind::Njf,
        global_context: false,
    };
    tch::manual_seed(9);
    let mut cpu_net = PoissonNet::new(&cfg, Device::Cpu).unwrap();
    cpu_net.set_kind(Kind::Double);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("w.safetensors");
    cpu_net.save(&path).unwrap();
    let mut gpu_net = PoissonNet::load(&path, gpu).unwrap();
    gpu_net.set_kind(Kind::Double);
    // the same seed initializes the same network on either device
    tch::manual_seed(9);
    let fresh = PoissonNet::new(&cfg, gpu).unwrap();
    assert_eq!(fresh.device(), gpu);
    let first = cpu_net.var_store().variables();
    for (name, t) in fresh.var_store().variables() {
        assert_eq!(t.device(), gpu, "{name}");
        assert!(
            t.to_device(Device::Cpu)
                .to_kind(Kind::Double)
                .equal(&first[&name]),
            "{name} initialized differently on the GPU"
        );
    }
    let v = mt.num_vertices() as i64;
    let x = Tensor::randn([2, v, 3], (Kind::Double, Device::Cpu));
    let e = Tensor::randn([2, v, 4], (Kind::Double, Device::Cpu));
    let d = Tensor::randn([2, v, 3], (Kind::Double, Device::Cpu));
    let oc = cpu_net.forward(&mt, &x, Some(&e)).unwrap();
    let og = gpu_net
        .forward(&mt, &x.to_device(gpu), Some(&e.to_device(gpu)))
        .unwrap();
    assert_eq!(og.vertex.device(), gpu);
    let err = rel_max_diff(&og.vertex.to_device(Device::Cpu), &oc.vertex);
    assert!(err < 1e-9, "vertex outputs differ by {err}");
    flow_matching_loss(&mt, &oc, &d).unwrap().backward();
    flow_matching_loss(&mt, &og, &d.to_device(gpu))
        .unwrap()
        .backward();
    let gc = cpu_net.var_store().variables();
    for (name, t) in gpu_net.var_store().variables() {
        let err = rel_max_diff(&t.grad().to_device(Device::Cpu), &gc[&name].grad());
        assert!(err < 1e-8, "gradient of {name} differs by {err}");
    }
    // f32 on the GPU runs too
    gpu_net.set_kind(Kind::Float);
    let out = gpu_net
        .forward(
            &mt,
            &x.to_kind(Kind::Float).to_device(gpu),
            Some(&e.to_kind(Kind::Float).to_device(gpu)),
        )
        .unwrap();
    let err = rel_max_diff(
        &out.vertex.to_kind(Kind::Double).to_device(Device::Cpu),
        &oc.vertex,
    );
    assert!(err < 1e-3, "f32 GPU vs f64 CPU: {err}");
    eprintln!("CUDA check passed on {:?}", gpu);
}
