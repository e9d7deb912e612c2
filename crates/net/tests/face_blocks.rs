//! The network run face block by face block (`PoissonNet::forward_blocks`
//! on `MeshTensors::face_blocks`) is the whole mesh's network: the same
//! vertex output and Jacobian, up to the order of the sums over faces, for
//! every block size, with and without modulation, for both heads.
#![allow(clippy::unwrap_used)]

#[path = "../../kernels/tests/common/mod.rs"]
mod common;

use common::rel_max_diff;
use mfm_geometry::procedural;
use mfm_net::{HeadKind, MeshTensors, PoissonNet, PoissonNetConfig};
use tch::{Device, Kind, Tensor};

#[test]
fn face_blocks_give_the_whole_mesh_network() {
    let mesh = procedural::icosphere(3);
    let mt = MeshTensors::new(&mesh).unwrap();
    let (v, f) = (mt.num_vertices() as i64, mt.num_faces());
    for (head, modulation) in [
        (HeadKind::Njf, true),
        (HeadKind::Njf, false),
        (HeadKind::Linear, true),
    ] {
        let cfg = PoissonNetConfig {
            width: 16,
            blocks: 2,
            vector_layers: 3,
            in_channels: 3,
            out_channels: 3,
            cond_channels: 4,
            modulation,
            head,
            global_context: false,
        };
        tch::manual_seed(3);
        let mut net = PoissonNet::new(&cfg, Device::Cpu).unwrap();
        net.set_kind(Kind::Double);
        let x = Tensor::randn([2, v, 3], (Kind::Double, Device::Cpu));
        let e = Tensor::randn([2, v, 4], (Kind::Double, Device::Cpu));
        let whole = tch::no_grad(|| net.forward(&mt, &x, Some(&e))).unwrap();
        // one block, blocks that do not divide the faces, one face each
        for size in [f, 100, 333, 1] {
            let blocks = mt.face_blocks(size);
            assert_eq!(blocks.len(), f.div_ceil(size));
            assert_eq!(blocks.iter().map(MeshTensors::num_faces).sum::<usize>(), f);
            let parts = tch::no_grad(|| net.forward_blocks(&mt, &blocks, &x, Some(&e))).unwrap();
            let d = rel_max_diff(&parts.vertex, &whole.vertex);
            assert!(
                d < 1e-10,
                "{head:?} modulation {modulation}, blocks of {size}: vertex {d:e}"
            );
            match (&parts.jacobian, &whole.jacobian) {
                (Some(a), Some(b)) => {
                    assert_eq!(a.size(), b.size());
                    let d = rel_max_diff(a, b);
                    assert!(d < 1e-10, "blocks of {size}: jacobian {d:e}");
                }
                (None, None) => {}
                _ => panic!("{head:?}: one of the two has a Jacobian"),
            }
        }
    }
    let e = net_without_blocks();
    assert!(e.to_string().contains("no face blocks"), "{e}");
}

fn net_without_blocks() -> mfm_net::NetError {
    let mesh = procedural::icosphere(1);
    let mt = MeshTensors::new(&mesh).unwrap();
    let cfg = PoissonNetConfig {
        width: 8,
        blocks: 1,
        vector_layers: 1,
        in_channels: 1,
        out_channels: 1,
        cond_channels: 0,
        modulation: true,
        head: HeadKind::Njf,
        global_context: false,
    };
    let net = PoissonNet::new(&cfg, Device::Cpu).unwrap();
    let x = Tensor::zeros([1, mt.num_vertices() as i64, 1], (Kind::Float, Device::Cpu));
    net.forward_blocks(&mt, &[], &x, None).unwrap_err()
}
