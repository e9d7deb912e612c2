//! The cost model `PoissonNetConfig::forward_product_flops` against the
//! products the network actually runs, counted by the dense layers
//! (`mfm_kernels::dense::counted_product_flops`). One test in its own binary: the
//! counter is process-wide, so no other test may run products meanwhile.
#![allow(clippy::unwrap_used)]

#[path = "../../kernels/tests/common/mod.rs"]
mod common;

use common::randn;
use mfm_geometry::procedural;
use mfm_kernels::dense::counted_product_flops;
use mfm_net::{HeadKind, MeshTensors, PoissonNet, PoissonNetConfig};
use tch::{Device, Kind};

#[test]
fn counted_products_equal_the_cost_model_forward_and_backward() {
    tch::manual_seed(9);
    let mesh = procedural::icosphere(2);
    let mt = MeshTensors::new(&mesh).unwrap();
    let (v, f) = (mt.num_vertices(), mt.num_faces());
    let base = PoissonNetConfig::deformation(8, 2);
    let configs = [
        base.clone(),
        // three-product complex layers in the blocks (width >= 64), four in
        // the head's last layer
        PoissonNetConfig {
            width: 64,
            blocks: 1,
            ..base.clone()
        },
        // a head wide enough for the three-product form
        PoissonNetConfig {
            width: 64,
            blocks: 1,
            vector_layers: 2,
            in_channels: 64,
            out_channels: 64,
            ..base.clone()
        },
        PoissonNetConfig {
            cond_channels: 0,
            modulation: false,
            vector_layers: 1,
            ..base.clone()
        },
        PoissonNetConfig {
            head: HeadKind::Linear,
            out_channels: 2,
            ..base.clone()
        },
    ];
    for (i, cfg) in configs.iter().enumerate() {
        let net = PoissonNet::new(cfg, Device::Cpu).unwrap();
        let batch = 2;
        let x = randn(&[batch, v as i64, cfg.in_channels as i64]).to_kind(Kind::Float);
        let e = (cfg.cond_channels > 0)
            .then(|| randn(&[batch, v as i64, cfg.cond_channels as i64]).to_kind(Kind::Float));
        let model = batch as u64 * cfg.forward_product_flops(v, f);
        let c0 = counted_product_flops();
        let out = net.forward(&mt, &x, e.as_ref()).unwrap();
        let c1 = counted_product_flops();
        assert_eq!(c1 - c0, model, "config {i}: forward products");
        let mut loss = out.vertex.square().sum(Kind::Float);
        if let Some(j) = &out.jacobian {
            loss += j.square().sum(Kind::Float);
        }
        loss.backward();
        let c2 = counted_product_flops();
        assert_eq!(c2 - c1, 2 * model, "config {i}: backward products");
    }
    // the paper preset on bunny's sizes, the number the docs quote
    let paper = PoissonNetConfig::paper().forward_product_flops(3485, 6966) as f64 * 1e-9;
    assert!((paper - 15.78).abs() < 0.005, "paper preset: {paper} GFLOP");
}
