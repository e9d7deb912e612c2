//! End-to-end training: a tiny PoissonNet overfits one target deformation.
#![allow(clippy::unwrap_used)]

use mfm_geometry::procedural;
use mfm_net::loss::flow_matching_loss;
use mfm_net::{HeadKind, MeshTensors, PoissonNet, PoissonNetConfig};
use tch::nn::OptimizerConfig;
use tch::{Device, Kind, Tensor, nn};

#[test]
fn tiny_network_overfits_one_deformation() {
    // one intra-op thread: the problem is tiny, and on a shared machine
    // OpenMP's spinning workers make multi-threaded tiny ops much slower
    tch::set_num_threads(1);
    tch::manual_seed(5);
    let mesh = procedural::icosphere(2);
    let mt = MeshTensors::new(&mesh).unwrap();
    let v = mesh.num_vertices() as i64;
    let xyz: Vec<f64> = mesh.positions().iter().flatten().copied().collect();
    let xyz = Tensor::from_slice(&xyz)
        .reshape([1, v, 3])
        .to_kind(Kind::Float);
    // target velocity: a smooth bend, mass-mean free (the NJF output is)
    let (x, y, z) = (xyz.select(2, 0), xyz.select(2, 1), xyz.select(2, 2));
    let delta = Tensor::stack(
        &[
            (&y * 3.0).sin() * 0.3,
            &z * &x * 0.5,
            (&x * 2.0).cos() * 0.2,
        ],
        2,
    );
    let delta = mt.remove_mass_mean(&delta).unwrap();
    let t = Tensor::full([1, v, 1], 0.5, (Kind::Float, Device::Cpu));
    let cond = Tensor::cat(&[&xyz, &t], 2);
    let cfg = PoissonNetConfig {
        width: 16,
        blocks: 2,
        vector_layers: 2,
        in_channels: 3,
        out_channels: 3,
        cond_channels: 4,
        modulation: true,
        head: HeadKind::Njf,
        global_context: false,
    };
    let net = PoissonNet::new(&cfg, Device::Cpu).unwrap();
    let mut opt = nn::Adam::default().build(net.var_store(), 1e-2).unwrap();
    let mut first = None;
    let mut last = f64::INFINITY;
    for _ in 0..400 {
        let out = net.forward(&mt, &xyz, Some(&cond)).unwrap();
        let loss = flow_matching_loss(&mt, &out, &delta).unwrap();
        let l = loss.double_value(&[]);
        first.get_or_insert(l);
        last = last.min(l);
        opt.backward_step(&loss);
    }
    let first = first.unwrap();
    eprintln!("loss {first:.3e} -> {last:.3e}");
    assert!(
        last < first / 100.0,
        "loss only went from {first:.3e} to {last:.3e}"
    );
}
