//! PoissonNet: parameter counts, gradients (finite differences in f64),
//! saving and loading.
#![allow(clippy::unwrap_used)]

#[path = "../../kernels/tests/common/mod.rs"]
mod common;

use common::{check_directional, check_parameters, randn, rel_max_diff};
use mfm_geometry::procedural;
use mfm_net::layers::{PoissonBlock, VectorMlp};
use mfm_net::{HeadKind, MeshTensors, NetError, PoissonNet, PoissonNetConfig};
use tch::{Device, Kind, Tensor, nn};

#[test]
fn parameter_counts_match_the_reference_implementation() {
    let cases = [
        (PoissonNetConfig::paper(), 1_369_600),
        (PoissonNetConfig::small(), 56_000),
        (PoissonNetConfig::medium(), 282_688),
        (PoissonNetConfig::preset("paper").unwrap(), 1_369_600),
    ];
    for (cfg, expected) in cases {
        assert_eq!(cfg.num_parameters(), expected, "{cfg:?} (formula)");
        let net = PoissonNet::new(&cfg, Device::Cpu).unwrap();
        assert_eq!(net.num_parameters(), expected, "{cfg:?} (built)");
        let summary = net.summary();
        assert_eq!(summary.total, expected);
        assert_eq!(
            summary.rows.iter().map(|r| r.params).sum::<usize>(),
            expected
        );
    }
    // the paper preset's breakdown: proj 512 + cond 17152 + 5 x 247168 + head 116096
    let paper = PoissonNetConfig::paper();
    assert_eq!(paper.block_parameters(), 247_168);
    let net = PoissonNet::new(&paper, Device::Cpu).unwrap();
    let s = net.summary();
    let sum_prefix = |p: &str| {
        s.rows
            .iter()
            .filter(|r| r.name.starts_with(p))
            .map(|r| r.params)
            .sum::<usize>()
    };
    assert_eq!(sum_prefix("proj_in."), 512);
    assert_eq!(sum_prefix("cond."), 17_152);
    assert_eq!(sum_prefix("blocks.4."), 247_168);
    assert_eq!(sum_prefix("head."), 116_096);
    // natural order: blocks.0 .. blocks.4 in sequence, the table prints a total
    let first_block_rows: Vec<&str> = s
        .rows
        .iter()
        .filter(|r| r.name.starts_with("blocks."))
        .map(|r| r.name.as_str())
        .collect();
    assert!(first_block_rows[0].starts_with("blocks.0."));
    let text = s.to_string();
    assert!(text.lines().last().unwrap().contains("1369600"), "{text}");
    // the linear head
    let lin = PoissonNetConfig {
        head: HeadKind::Linear,
        ..PoissonNetConfig::small()
    };
    let net = PoissonNet::new(&lin, Device::Cpu).unwrap();
    assert_eq!(net.num_parameters(), lin.num_parameters());
    assert!(
        PoissonNetConfig::preset("huge")
            .unwrap_err()
            .to_string()
            .contains("paper, medium, small")
    );
}

fn tiny(width: usize, blocks: usize, head: HeadKind) -> PoissonNetConfig {
    PoissonNetConfig {
        width,
        blocks,
        vector_layers: 3,
        in_channels: 3,
        out_channels: 3,
        cond_channels: 2,
        modulation: true,
        head,
        global_context: false,
    }
}

#[test]
fn last_complex_layer_after_the_divergence_equals_the_face_form() {
    // a block only needs the divergence of its vector MLP's output, and
    // computes the last complex layer after it, on vertices; the value and
    // every gradient must be those of the face form
    tch::manual_seed(4);
    let mesh = procedural::icosphere(2);
    let mt = MeshTensors::new(&mesh).unwrap();
    let (v, f2) = (mt.num_vertices() as i64, 2 * mt.num_faces() as i64);
    for (width, out, layers) in [(6, 6, 3), (5, 3, 1), (64, 64, 2)] {
        let mut vs = nn::VarStore::new(Device::Cpu);
        let mlp = VectorMlp::new(vs.root(), width, layers, out, true);
        vs.double();
        let g = randn(&[2, f2, width as i64]).set_requires_grad(true);
        let x = randn(&[2, v, width as i64]).set_requires_grad(true);
        let r = randn(&[2, v, out as i64]);
        let run = |vertex_form: bool| {
            for mut t in vs
                .trainable_variables()
                .into_iter()
                .chain([g.shallow_clone(), x.shallow_clone()])
            {
                t.zero_grad();
            }
            let y = if vertex_form {
                mlp.forward_divergence(&g, &x, &mt).unwrap()
            } else {
                mt.divergence(&mlp.forward(&g, &x, &mt).unwrap()).unwrap()
            };
            (&y * &r).sum(Kind::Double).backward();
            let grads: Vec<Tensor> = vs
                .trainable_variables()
                .iter()
                .chain([&g, &x])
                .map(|t| t.grad().copy())
                .collect();
            (y.detach(), grads)
        };
        let (face, face_grads) = run(false);
        let (vertex, vertex_grads) = run(true);
        assert_eq!(vertex.size(), vec![2, v, out as i64]);
        let err = rel_max_diff(&vertex, &face);
        assert!(err < 1e-12, "W{width} nl{layers}: values differ by {err}");
        for (i, (a, b)) in vertex_grads.iter().zip(&face_grads).enumerate() {
            let err = rel_max_diff(a, b);
            assert!(
                err < 1e-11,
                "W{width} nl{layers}: gradient {i} differs by {err}"
            );
        }
    }
}

#[test]
fn a_block_equals_its_specification_with_the_solve_output_formed() {
    // the block folds the columns of MLP1's first weight that read `u` into
    // the last complex layer before the solve (model docs); value and every
    // gradient must equal the block as docs/network.md writes it: u = solve(div)
    // with the mean removed, h = [x, u, e], x + gamma1 MLP1(h), ...
    tch::manual_seed(5);
    let mesh = procedural::icosphere(2);
    let mt = MeshTensors::new(&mesh).unwrap();
    let v = mt.num_vertices() as i64;
    for (w, conditioned, global) in [
        (6usize, true, false),
        (5, false, false),
        (64, true, false),
        (6, true, true),
        (5, false, true),
    ] {
        let wi = w as i64;
        let mut vs = nn::VarStore::new(Device::Cpu);
        let block = PoissonBlock::new(vs.root(), w, 3, true, conditioned, global);
        vs.double();
        if global {
            // the global map starts at zero: give it weights that matter
            let mut g = vs.variables()["global.weight"].shallow_clone();
            tch::no_grad(|| g.copy_(&randn(&[wi, wi])));
        }
        let mut spec_vs = nn::VarStore::new(Device::Cpu);
        let vector = VectorMlp::new(spec_vs.root() / "vector", w, 3, w, true);
        spec_vs.double();
        spec_vs.copy(&vs).unwrap();
        let x = randn(&[2, v, wi]).set_requires_grad(true);
        let e = randn(&[2, v, wi]).set_requires_grad(true);
        let cond = conditioned.then_some(&e);
        let r = randn(&[2, v, wi]);
        let vars = vs.variables();
        let lin = |t: &Tensor, name: &str| {
            t.linear(
                &vars[&format!("{name}.weight")],
                Some(&vars[&format!("{name}.bias")]),
            )
        };
        let spec = || {
            let g = mt.gradient(&x).unwrap();
            let div = vector.forward_divergence(&g, &x, &mt).unwrap();
            let u = mt.remove_mass_mean(&mt.solve(&div).unwrap()).unwrap();
            let h = match cond {
                Some(e) => Tensor::cat(&[&x, &u, e], -1),
                None => Tensor::cat(&[&x, &u], -1),
            };
            let hidden = lin(&h, "mlp1.0").gelu("none");
            let out = lin(&hidden, "mlp1.1");
            let out = if global {
                // the surface integral of the hidden features over the area
                let m = mt.mass().view([1, v, 1]);
                let mean =
                    (&hidden * &m).sum_dim_intlist(1, true, Kind::Double) / m.sum(Kind::Double);
                out + mean.matmul(&vars["global.weight"].tr())
            } else {
                out
            };
            let x1 = &x + &vars["gamma1"] * out;
            &x1 + &vars["gamma2"] * lin(&lin(&x1, "mlp2.0").gelu("none"), "mlp2.1")
        };
        let all = || {
            vs.trainable_variables()
                .into_iter()
                .chain(spec_vs.trainable_variables())
                .chain([x.shallow_clone(), e.shallow_clone()])
        };
        let run = |as_built: bool| {
            for mut t in all() {
                t.zero_grad();
            }
            let y = if as_built {
                block.forward(&x, cond, &mt).unwrap()
            } else {
                spec()
            };
            (&y * &r).sum(Kind::Double).backward();
            // gradients by name: the block's vector MLP lives in `vs`, the
            // specification's in `spec_vs`, under the same names
            let mut grads: Vec<(String, Tensor)> = Vec::new();
            for (name, t) in vs.variables() {
                let owner = if !as_built && name.starts_with("vector.") {
                    spec_vs.variables()[&name].shallow_clone()
                } else {
                    t
                };
                grads.push((name, owner.grad().copy()));
            }
            grads.push(("x".into(), x.grad().copy()));
            if conditioned {
                grads.push(("e".into(), e.grad().copy()));
            }
            grads.sort_by(|a, b| a.0.cmp(&b.0));
            (y.detach(), grads)
        };
        let (built, built_grads) = run(true);
        let (specified, spec_grads) = run(false);
        let err = rel_max_diff(&built, &specified);
        assert!(err < 1e-12, "W{w}: values differ by {err}");
        assert_eq!(
            built_grads.iter().any(|(n, _)| n == "global.weight"),
            global
        );
        assert!(built_grads.len() > 15);
        for ((name, a), (_, b)) in built_grads.iter().zip(&spec_grads) {
            let err = rel_max_diff(a, b);
            assert!(err < 1e-10, "W{w}: gradient of {name} differs by {err}");
        }
    }
}

#[test]
fn one_block_passes_finite_difference_checks() {
    tch::manual_seed(1);
    let mesh = procedural::icosphere(1);
    let mt = MeshTensors::new(&mesh).unwrap();
    let v = mt.num_vertices() as i64;
    let w = 5;
    let mut vs = nn::VarStore::new(Device::Cpu);
    let block = PoissonBlock::new(vs.root(), w, 3, true, true, true);
    vs.double();
    let mut g = vs.variables()["global.weight"].shallow_clone();
    tch::no_grad(|| g.copy_(&randn(&[w as i64, w as i64])));
    let r = randn(&[2, v, w as i64]);
    let x = randn(&[2, v, w as i64]);
    let e = randn(&[2, v, w as i64]);
    // inputs
    let f =
        |xs: &[Tensor]| (block.forward(&xs[0], Some(&xs[1]), &mt).unwrap() * &r).sum(Kind::Double);
    let err = check_directional(&[x.shallow_clone(), e.shallow_clone()], &f, 3, 1e-6);
    assert!(err < 1e-6, "block inputs: relative FD error {err}");
    // parameters
    let params = vs.trainable_variables();
    assert!(params.len() > 10);
    let g = || (block.forward(&x, Some(&e), &mt).unwrap() * &r).sum(Kind::Double);
    let err = check_parameters(&params, &g, 3, 1e-6);
    assert!(err < 1e-6, "block parameters: relative FD error {err}");
}

#[test]
fn full_network_with_njf_head_passes_finite_difference_checks() {
    tch::manual_seed(2);
    let mesh = procedural::icosphere(1);
    let mt = MeshTensors::new(&mesh).unwrap();
    let v = mt.num_vertices() as i64;
    let f2 = 2 * mt.num_faces() as i64;
    let mut net = PoissonNet::new(&tiny(4, 2, HeadKind::Njf), Device::Cpu).unwrap();
    net.set_kind(Kind::Double);
    let ru = randn(&[2, v, 3]);
    let rg = randn(&[2, f2, 3]);
    let loss = |x: &Tensor, e: &Tensor| {
        let out = net.forward(&mt, x, Some(e)).unwrap();
        (&out.vertex * &ru).sum(Kind::Double) + (out.jacobian.unwrap() * &rg).sum(Kind::Double)
    };
    let x = randn(&[2, v, 3]);
    let e = randn(&[2, v, 2]);
    let err = check_directional(
        &[x.shallow_clone(), e.shallow_clone()],
        &|xs| loss(&xs[0], &xs[1]),
        3,
        1e-6,
    );
    assert!(err < 1e-6, "network inputs: relative FD error {err}");
    let params = net.var_store().trainable_variables();
    let err = check_parameters(&params, &|| loss(&x, &e), 3, 1e-6);
    assert!(err < 1e-6, "network parameters: relative FD error {err}");
}

#[test]
fn linear_head_and_unconditioned_network_run_and_differentiate() {
    let mesh = procedural::icosphere(1);
    let mt = MeshTensors::new(&mesh).unwrap();
    let v = mt.num_vertices() as i64;
    let cfg = PoissonNetConfig {
        cond_channels: 0,
        in_channels: 2,
        out_channels: 5,
        ..tiny(4, 1, HeadKind::Linear)
    };
    let mut net = PoissonNet::new(&cfg, Device::Cpu).unwrap();
    net.set_kind(Kind::Double);
    let r = randn(&[1, v, 5]);
    let f = |xs: &[Tensor]| (net.forward(&mt, &xs[0], None).unwrap().vertex * &r).sum(Kind::Double);
    let err = check_directional(&[randn(&[v, 2])], &f, 2, 1e-6);
    assert!(err < 1e-6, "{err}");
    let out = net.forward(&mt, &randn(&[v, 2]), None).unwrap();
    assert!(out.jacobian.is_none());
    assert_eq!(out.vertex.size(), vec![1, v, 5]);
    // conditioning passed to an unconditioned network is an error, not a panic
    assert!(
        net.forward(&mt, &randn(&[v, 2]), Some(&randn(&[v, 1])))
            .is_err()
    );
    // NJF needs C_in == C_out
    let bad = PoissonNetConfig {
        out_channels: 4,
        ..tiny(4, 1, HeadKind::Njf)
    };
    assert!(matches!(
        PoissonNet::new(&bad, Device::Cpu),
        Err(NetError::Config(_))
    ));
}

#[test]
fn the_njf_head_without_the_input_gradient_is_the_njf_head_minus_g_x_in() {
    tch::manual_seed(5);
    let mesh = procedural::icosphere(1);
    let mt = MeshTensors::new(&mesh).unwrap();
    let v = mt.num_vertices() as i64;
    let mut with = PoissonNet::new(&tiny(4, 2, HeadKind::Njf), Device::Cpu).unwrap();
    let cfg = tiny(4, 2, HeadKind::NjfNoInputGradient);
    assert_eq!(cfg.num_parameters(), with.config().num_parameters());
    let mut without = PoissonNet::new(&cfg, Device::Cpu).unwrap();
    with.set_kind(Kind::Double);
    without.set_kind(Kind::Double);
    without.var_store_mut().copy(with.var_store()).unwrap();
    let x = randn(&[2, v, 3]);
    let e = randn(&[2, v, 2]);
    let a = with.forward(&mt, &x, Some(&e)).unwrap();
    let b = without.forward(&mt, &x, Some(&e)).unwrap();
    let ga = a.jacobian.unwrap();
    let gb = b.jacobian.unwrap();
    assert!(rel_max_diff(&(&ga - mt.gradient(&x).unwrap()), &gb) < 1e-12);
    // the vertex output is the solve of the Jacobian's divergence, mean removed
    let ub = mt
        .remove_mass_mean(&mt.solve(&mt.divergence(&gb).unwrap()).unwrap())
        .unwrap();
    assert!(rel_max_diff(&b.vertex, &ub) < 1e-10);
    assert!(
        rel_max_diff(&a.vertex, &b.vertex) > 1e-3,
        "the residual matters"
    );
    // without the residual, C_in and C_out may differ
    let other = PoissonNetConfig {
        out_channels: 5,
        ..tiny(4, 1, HeadKind::NjfNoInputGradient)
    };
    let net = PoissonNet::new(&other, Device::Cpu).unwrap();
    let out = net
        .forward(
            &mt,
            &randn(&[1, v, 3]).to_kind(Kind::Float),
            Some(&randn(&[1, v, 2]).to_kind(Kind::Float)),
        )
        .unwrap();
    assert_eq!(out.vertex.size(), vec![1, v, 5]);
}

#[test]
fn input_errors_name_the_expected_shape() {
    let mesh = procedural::icosphere(1);
    let mt = MeshTensors::new(&mesh).unwrap();
    let net = PoissonNet::new(&tiny(4, 1, HeadKind::Njf), Device::Cpu).unwrap();
    let v = mt.num_vertices() as i64;
    let x = Tensor::zeros([2, v + 1, 3], (Kind::Float, Device::Cpu));
    let e = Tensor::zeros([2, v, 2], (Kind::Float, Device::Cpu));
    let msg = net.forward(&mt, &x, Some(&e)).unwrap_err().to_string();
    assert!(msg.contains("V=42"), "{msg}");
    let x = Tensor::zeros([2, v, 3], (Kind::Double, Device::Cpu));
    let msg = net.forward(&mt, &x, Some(&e)).unwrap_err().to_string();
    assert!(msg.contains("Double"), "{msg}");
    let x = Tensor::zeros([2, v, 3], (Kind::Float, Device::Cpu));
    assert!(net.forward(&mt, &x, None).is_err());
}

#[test]
fn batch_items_are_independent_and_many_meshes_work() {
    tch::manual_seed(3);
    let a = MeshTensors::new(&procedural::icosphere(1)).unwrap();
    let b = MeshTensors::new(&procedural::icosphere(2)).unwrap();
    let mut net = PoissonNet::new(&tiny(6, 2, HeadKind::Njf), Device::Cpu).unwrap();
    net.set_kind(Kind::Double);
    let (va, vb) = (a.num_vertices() as i64, b.num_vertices() as i64);
    let xa = randn(&[3, va, 3]);
    let ea = randn(&[3, va, 2]);
    let batched = net.forward(&a, &xa, Some(&ea)).unwrap();
    for i in 0..3 {
        let one = net.forward(&a, &xa.get(i), Some(&ea.get(i))).unwrap();
        assert!(rel_max_diff(&one.vertex.get(0), &batched.vertex.get(i)) < 1e-10);
    }
    let xb = randn(&[2, vb, 3]);
    let eb = randn(&[1, vb, 2]); // shared conditioning
    let outs = net
        .forward_many(&[(&a, &xa, Some(&ea)), (&b, &xb, Some(&eb))])
        .unwrap();
    assert_eq!(outs[1].vertex.size(), vec![2, vb, 3]);
    assert!(rel_max_diff(&outs[0].vertex, &batched.vertex) < 1e-12);
    let loss =
        outs[0].vertex.square().sum(Kind::Double) + outs[1].vertex.square().sum(Kind::Double);
    loss.backward();
    let grads: f64 = net
        .var_store()
        .trainable_variables()
        .iter()
        .map(|p| p.grad().abs().sum(Kind::Double).double_value(&[]))
        .sum();
    assert!(grads > 0.0 && grads.is_finite());
}

#[test]
fn save_and_load_round_trip_and_mismatch_is_reported() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("model.safetensors");
    let cfg = tiny(6, 2, HeadKind::Njf);
    let net = PoissonNet::new(&cfg, Device::Cpu).unwrap();
    net.save(&path).unwrap();
    assert!(PoissonNet::config_path(&path).is_file());
    assert_eq!(PoissonNet::read_config(&path).unwrap(), cfg);
    let loaded = PoissonNet::load(&path, Device::Cpu).unwrap();
    let mesh = procedural::icosphere(1);
    let mt = MeshTensors::new(&mesh).unwrap();
    let v = mt.num_vertices() as i64;
    let x = Tensor::randn([1, v, 3], (Kind::Float, Device::Cpu));
    let e = Tensor::randn([1, v, 2], (Kind::Float, Device::Cpu));
    let a = net.forward(&mt, &x, Some(&e)).unwrap().vertex;
    let b = loaded.forward(&mt, &x, Some(&e)).unwrap().vertex;
    assert_eq!(rel_max_diff(&a, &b), 0.0);

    // a different configuration: the message names the file and the field
    let mut other = PoissonNet::new(&tiny(8, 2, HeadKind::Njf), Device::Cpu).unwrap();
    let msg = other.load_weights(&path).unwrap_err().to_string();
    assert!(msg.contains("model.safetensors"), "{msg}");
    assert!(
        msg.contains("width = 6 in the file's configuration, 8 in the network's"),
        "{msg}"
    );
    // without the configuration file, shapes and names are compared
    std::fs::remove_file(PoissonNet::config_path(&path)).unwrap();
    let msg = other.load_weights(&path).unwrap_err().to_string();
    assert!(
        msg.contains("model.safetensors") && msg.contains("shape differences"),
        "{msg}"
    );
    let mut deeper = PoissonNet::new(&tiny(6, 3, HeadKind::Njf), Device::Cpu).unwrap();
    let msg = deeper.load_weights(&path).unwrap_err().to_string();
    assert!(msg.contains("missing in the file: blocks.2."), "{msg}");
    // wrong extension
    assert!(net.save(dir.path().join("model.pt")).is_err());
}

#[test]
fn a_global_context_starts_as_the_plain_network_and_is_saved_only_when_on() {
    let plain = tiny(6, 2, HeadKind::Njf);
    let global = PoissonNetConfig {
        global_context: true,
        ..plain.clone()
    };
    // one W x W map per block, counted by the formula and the built network
    assert_eq!(global.num_parameters(), plain.num_parameters() + 2 * 36);
    tch::manual_seed(4);
    let a = PoissonNet::new(&plain, Device::Cpu).unwrap();
    tch::manual_seed(4);
    let b = PoissonNet::new(&global, Device::Cpu).unwrap();
    assert_eq!(b.num_parameters(), global.num_parameters());
    assert_eq!(b.summary().total, global.num_parameters());
    // the maps start at zero and draw no random numbers: same function
    let mesh = procedural::icosphere(1);
    let mt = MeshTensors::new(&mesh).unwrap();
    let v = mt.num_vertices() as i64;
    let x = Tensor::randn([2, v, 3], (Kind::Float, Device::Cpu));
    let e = Tensor::randn([2, v, 2], (Kind::Float, Device::Cpu));
    let ya = a.forward(&mt, &x, Some(&e)).unwrap().vertex;
    let yb = b.forward(&mt, &x, Some(&e)).unwrap().vertex;
    assert_eq!(rel_max_diff(&ya, &yb), 0.0);
    // ... but they learn: the loss reaches them
    (yb * Tensor::randn([2, v, 3], (Kind::Float, Device::Cpu)))
        .sum(Kind::Float)
        .backward();
    let vars = b.var_store().variables();
    for k in 0..2 {
        let g = vars[&format!("blocks.{k}.global.weight")].grad();
        assert!(
            g.abs().sum(Kind::Double).double_value(&[]) > 0.0,
            "block {k}"
        );
    }
    // the plain configuration's JSON has no such key (earlier files read
    // and write unchanged); the global one round-trips
    let json = serde_json::to_string(&plain).unwrap();
    assert!(!json.contains("global_context"), "{json}");
    let json = serde_json::to_string(&global).unwrap();
    assert_eq!(
        serde_json::from_str::<PoissonNetConfig>(&json).unwrap(),
        global
    );
    // loading a global model's file into a plain network names the field
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("model.safetensors");
    b.save(&path).unwrap();
    assert_eq!(PoissonNet::read_config(&path).unwrap(), global);
    let mut other = PoissonNet::new(&plain, Device::Cpu).unwrap();
    let msg = other.load_weights(&path).unwrap_err().to_string();
    assert!(
        msg.contains(
            "global_context = true in the file's configuration, its default in the network's"
        ),
        "{msg}"
    );
}
