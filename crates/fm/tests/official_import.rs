//! Importing a checkpoint of the official code (fixtures/official-tiny,
//! written by `official_fixture.py` in the official Lightning layout) and
//! exporting mfm weights under the official names.
//!
//! The parity oracle: `expected.npy` is the official network's output on
//! `x_t.npy`, `t.npy`, computed in float64 by the fixture script with a
//! forward pass written from the official PoissonNet (block order: vector
//! MLP on the gradients with modulation, Poisson solve, vertex MLPs on
//! `[x, u, conditioning]` with the skips; NJF head with the input-gradient
//! residual), on operators it builds itself.
#![allow(clippy::unwrap_used)]

use std::path::{Path, PathBuf};
use std::process::Command;

use mfm_fm::official::{IMPORTED_FILES, OfficialConfig, export_official, import_official};
use mfm_fm::sample::{SampleOptions, Sampler, StartNoise};
use mfm_geometry::test_support::{python_oracle, workspace_root};
use mfm_net::{MeshTensors, PoissonNet};
use tch::{Device, Kind, Tensor};

fn fixture(name: &str) -> PathBuf {
    workspace_root().join("fixtures/official-tiny").join(name)
}

fn npy_f64(path: &Path) -> (Vec<usize>, Vec<f64>) {
    let a = mfm_files::npy::read::<f64>(path).unwrap();
    (a.shape, a.values)
}

fn import(out: &Path) -> mfm_fm::official::ImportRecord {
    let mesh = mfm_meshio::read_mesh(fixture("template.obj")).unwrap();
    import_official(
        &fixture("tiny.ckpt"),
        &fixture("config.yaml"),
        &mesh,
        &fixture("template.obj"),
        out,
    )
    .unwrap()
}

#[test]
fn the_imported_network_computes_the_official_forward_pass() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    let record = import(&run);
    assert_eq!(record.parameters, 2368);
    assert_eq!(record.global_step, Some(1234));
    for k in [
        "epoch",
        "optimizer_states",
        "lr_schedulers",
        "callbacks",
        "loops",
    ] {
        assert!(record.ignored_entries.iter().any(|e| e == k), "{k}");
    }
    for f in IMPORTED_FILES {
        assert!(run.join(f).is_file(), "{f}");
    }

    let mesh = mfm_meshio::read_mesh(fixture("template.obj")).unwrap();
    let mut net = PoissonNet::load(run.join("model.safetensors"), Device::Cpu).unwrap();
    net.set_kind(Kind::Double);
    let mt = MeshTensors::new(&mesh).unwrap();
    let (shape, x) = npy_f64(&fixture("x_t.npy"));
    let (_, t) = npy_f64(&fixture("t.npy"));
    let (_, expected) = npy_f64(&fixture("expected.npy"));
    let (b, v) = (shape[0] as i64, shape[1] as i64);
    let x = Tensor::from_slice(&x).reshape([b, v, 3]);
    let xyz: Vec<f64> = mesh.positions().iter().flatten().copied().collect();
    let xyz = Tensor::from_slice(&xyz)
        .reshape([1, v, 3])
        .expand([b, v, 3], false);
    let tt = Tensor::from_slice(&t)
        .reshape([b, 1, 1])
        .expand([b, v, 1], false);
    let cond = Tensor::cat(&[xyz, tt], 2);
    let out = net.forward(&mt, &x, Some(&cond)).unwrap();
    let got = Vec::<f64>::try_from(&out.vertex.contiguous().view([-1])).unwrap();
    let scale = expected.iter().fold(0.0f64, |m, e| m.max(e.abs()));
    let err = got
        .iter()
        .zip(&expected)
        .fold(0.0f64, |m, (g, e)| m.max((g - e).abs()));
    assert!(
        scale > 1e-3,
        "the oracle's output is not trivially small: {scale}"
    );
    assert!(
        err <= 1e-6 * scale,
        "mfm's forward pass differs from the official one by {err} (output scale {scale})"
    );
}

#[test]
fn an_imported_run_samples_and_a_given_start_reproduces_the_drawn_noise() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    import(&run);
    let mesh = mfm_meshio::read_mesh(fixture("template.obj")).unwrap();
    let sampler = Sampler::load(&run, Some(Device::Cpu)).unwrap();
    assert!(sampler.surface_warnings(&mesh).is_empty());
    let opts = SampleOptions {
        steps: 4,
        ..SampleOptions::default()
    };
    let drawn = sampler.sample(&mesh, 3, 5, &opts).unwrap();
    assert!(drawn.data.iter().all(|x| x.is_finite()));
    let target = sampler.prepare(&mesh).unwrap();
    let x0 = sampler.noise(&target, 0, 3, 5).unwrap();
    let values = Vec::<f32>::try_from(&x0.contiguous().view([-1])).unwrap();
    let v = mesh.num_vertices();
    let given = sampler
        .with_start_noise(StartNoise {
            values,
            shape: [3, v, 3],
        })
        .unwrap();
    let again = given.sample(&mesh, 3, 999, &opts).unwrap();
    assert_eq!(
        again.data, drawn.data,
        "the seed is unused with a given start"
    );
    let e = given.sample(&mesh, 4, 0, &opts).unwrap_err().to_string();
    assert!(e.contains("[3, 18, 3]") && e.contains("[4, 18, 3]"), "{e}");
}

#[test]
fn export_then_import_gives_the_same_weights_file() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    import(&run);
    let exported = dir.path().join("exported.ckpt");
    assert_eq!(export_official(&run, &exported).unwrap(), 53);
    let mesh = mfm_meshio::read_mesh(fixture("template.obj")).unwrap();
    let again = dir.path().join("again");
    import_official(
        &exported,
        &fixture("config.yaml"),
        &mesh,
        &fixture("template.obj"),
        &again,
    )
    .unwrap();
    assert_eq!(
        std::fs::read(run.join("model.safetensors")).unwrap(),
        std::fs::read(again.join("model.safetensors")).unwrap()
    );
    assert_eq!(
        std::fs::read(run.join("model.json")).unwrap(),
        std::fs::read(again.join("model.json")).unwrap()
    );

    // the authors' loader: torch.load(weights_only=True)["state_dict"] has
    // the official names and the checkpoint's values exactly
    let Some(python) = python_oracle() else {
        return;
    };
    let out = Command::new(python)
        .arg("-c")
        .arg(
            r#"
import sys, torch
a = torch.load(sys.argv[1], weights_only=True)["state_dict"]
b = torch.load(sys.argv[2], weights_only=True)["state_dict"]
assert sorted(a) == sorted(b), (sorted(set(a) ^ set(b)))
for k in a:
    assert a[k].dtype == b[k].dtype and a[k].shape == b[k].shape and torch.equal(a[k], b[k]), k
print(len(a))
"#,
        )
        .arg(fixture("tiny.ckpt"))
        .arg(&exported)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(String::from_utf8_lossy(&out.stdout).trim(), "53");
}

#[test]
fn a_configuration_that_does_not_fit_the_checkpoint_is_refused_naming_the_parameter() {
    let dir = tempfile::tempdir().unwrap();
    let text = std::fs::read_to_string(fixture("config.yaml"))
        .unwrap()
        .replace("hidden_dim: 8", "hidden_dim: 16");
    let cfg = dir.path().join("wide.yaml");
    std::fs::write(&cfg, text).unwrap();
    let mesh = mfm_meshio::read_mesh(fixture("template.obj")).unwrap();
    let out = dir.path().join("run");
    let e = import_official(
        &fixture("tiny.ckpt"),
        &cfg,
        &mesh,
        &fixture("template.obj"),
        &out,
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("base_model.") && e.contains("shape") && e.contains("tiny.ckpt"),
        "{e}"
    );
    assert!(!out.exists(), "nothing is written");

    let text = std::fs::read_to_string(fixture("config.yaml"))
        .unwrap()
        .replace("cmlp_nlayers: 2", "cmlp_nlayers: 3");
    std::fs::write(&cfg, text).unwrap();
    let e = import_official(
        &fixture("tiny.ckpt"),
        &cfg,
        &mesh,
        &fixture("template.obj"),
        &out,
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("grad_mlp.layers.1.mag_bias") && e.contains("missing"),
        "{e}"
    );
    assert!(OfficialConfig::read(fixture("config.yaml")).is_ok());
}

#[test]
fn the_fixture_is_what_its_script_writes() {
    let Some(python) = python_oracle() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let script = workspace_root().join("crates/fm/tests/official_fixture.py");
    let status = Command::new(python)
        .arg(&script)
        .arg(dir.path())
        .output()
        .unwrap();
    assert!(
        status.status.success(),
        "{}",
        String::from_utf8_lossy(&status.stderr)
    );
    // Inputs are drawn from a seeded generator and written as they are: byte for
    // byte. The network's output is a float64 forward pass whose summation order
    // depends on the CPU's vector width in torch's kernels, so it is compared to
    // round-off (a few ulps observed between machines), not to the byte.
    for f in ["config.yaml", "template.obj", "x_t.npy", "t.npy"] {
        assert_eq!(
            std::fs::read(dir.path().join(f)).unwrap(),
            std::fs::read(fixture(f)).unwrap(),
            "{f} differs from what the script writes"
        );
    }
    let (shape, written) = npy_f64(&dir.path().join("expected.npy"));
    let (fixture_shape, stored) = npy_f64(&fixture("expected.npy"));
    assert_eq!(shape, fixture_shape, "expected.npy shape");
    let worst = written
        .iter()
        .zip(&stored)
        .map(|(a, b)| (a - b).abs() / b.abs().max(1.0))
        .fold(0.0_f64, f64::max);
    assert!(
        worst < 1e-12,
        "expected.npy differs from what the script writes by {worst:e} (relative)"
    );
    let tensors = |p: &Path| {
        mfm_torchfile::Checkpoint::open(p)
            .unwrap()
            .state_dict("state_dict")
            .unwrap()
    };
    assert_eq!(
        tensors(&dir.path().join("tiny.ckpt")),
        tensors(&fixture("tiny.ckpt"))
    );
}
