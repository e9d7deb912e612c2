//! Importing the authors' arbitrary-source model (fixtures/official-arbitrary,
//! written by `official_arbitrary_fixture.py` in the official Lightning
//! layout: the flow under `base_model.*`, the eigenvector predictor under
//! `eigenvecs_predictor.*`) as an mfm arbitrary-source run.
//!
//! The parity oracle: `expected_eigenvectors.npy` is the official
//! predictor's output on the template's positions and `expected.npy` the
//! official flow's on `x_t.npy`, `t.npy` with the conditioning `[template
//! xyz, t, expected eigenvectors]`, both computed in float64 by the fixture
//! script with the forward pass of `crates/fm/tests/official_fixture.py`.
#![allow(clippy::unwrap_used)]

use std::path::{Path, PathBuf};
use std::process::Command;

use mfm_arbitrary::SourceFrame;
use mfm_arbitrary::evaluate::predictor_error_skipped;
use mfm_arbitrary::flow::{ArbitrarySampler, FlowConfig};
use mfm_arbitrary::folders::{SampleFolder, TrainingRun, write_sample_folder};
use mfm_arbitrary::markers::{FolderKind, RunKind};
use mfm_arbitrary::official::{
    ArbitraryImportRecord, IMPORTED_FILES, OfficialArbitraryConfig, import_official_arbitrary,
    official_model_type,
};
use mfm_arbitrary::predictor::PredictorConfig;
use mfm_geometry::TriMesh;
use mfm_geometry::test_support::{python_oracle, workspace_root};
use mfm_net::{MeshTensors, PoissonNet};
use mfm_torchfile::{Checkpoint, TensorData};
use tch::{Device, Kind, Tensor};

fn fixture(name: &str) -> PathBuf {
    workspace_root()
        .join("fixtures/official-arbitrary")
        .join(name)
}

fn template() -> TriMesh {
    mfm_meshio::read_mesh(fixture("template.obj")).unwrap()
}

fn npy_f64(path: &Path) -> (Vec<usize>, Vec<f64>) {
    let a = mfm_files::npy::read::<f64>(path).unwrap();
    (a.shape, a.values)
}

fn import_with(
    checkpoint: &Path,
    config: &Path,
    predictor: Option<&Path>,
    out: &Path,
) -> mfm_arbitrary::Result<ArbitraryImportRecord> {
    let mesh = template();
    let path = fixture("template.obj");
    import_official_arbitrary(
        checkpoint,
        config,
        predictor,
        Some((&mesh, path.as_path())),
        out,
    )
}

fn import(out: &Path) -> ArbitraryImportRecord {
    import_with(
        &fixture("arbitrary.ckpt"),
        &fixture("config.yaml"),
        Some(&fixture("predictor.ckpt")),
        out,
    )
    .unwrap()
}

/// The largest difference of `got` from `expected`, and the output's scale.
fn worst(got: &Tensor, expected: &[f64]) -> (f64, f64) {
    let got = Vec::<f64>::try_from(&got.to_kind(Kind::Double).contiguous().view([-1])).unwrap();
    assert_eq!(got.len(), expected.len());
    let scale = expected.iter().fold(0.0f64, |m, e| m.max(e.abs()));
    let err = got
        .iter()
        .zip(expected)
        .fold(0.0f64, |m, (g, e)| m.max((g - e).abs()));
    (err, scale)
}

#[test]
fn the_imported_networks_compute_the_official_forward_passes() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    let record = import(&run);
    assert_eq!(record.global_step, Some(1234));
    assert_eq!(record.model_type, "Matern_FM_arbitrary_source");
    assert!(record.predictor_checkpoint.is_some());
    for k in ["epoch", "optimizer_states", "lr_schedulers", "loops"] {
        assert!(record.ignored_entries.iter().any(|e| e == k), "{k}");
    }
    for f in IMPORTED_FILES {
        assert!(run.join(f).is_file(), "{f}");
    }
    assert_eq!(FolderKind::of(&run), FolderKind::ArbitraryRun);

    let mesh = template();
    let mt = MeshTensors::new(&mesh).unwrap();
    let v = mesh.num_vertices() as i64;
    let xyz: Vec<f64> = mesh.positions().iter().flatten().copied().collect();
    let xyz = Tensor::from_slice(&xyz).reshape([1, v, 3]);

    // the predictor on the template's positions, as they are
    let mut predictor = PoissonNet::load(run.join("predictor.safetensors"), Device::Cpu).unwrap();
    assert_eq!(predictor.num_parameters(), record.predictor_parameters);
    predictor.set_kind(Kind::Double);
    let (eshape, eigen) = npy_f64(&fixture("expected_eigenvectors.npy"));
    let k = eshape[2] as i64;
    let out = predictor.forward(&mt, &xyz, None).unwrap();
    let (err, scale) = worst(&out.vertex, &eigen);
    assert!(scale > 1e-2, "the oracle's output is not trivial: {scale}");
    assert!(
        err <= 1e-6 * scale,
        "the predictor differs from the official one by {err} (scale {scale})"
    );

    // the flow with the conditioning [xyz, t, eigenvectors]
    let mut flow = PoissonNet::load(run.join("model.safetensors"), Device::Cpu).unwrap();
    assert_eq!(flow.num_parameters(), record.flow_parameters);
    assert_eq!(flow.config().cond_channels as i64, 4 + k);
    flow.set_kind(Kind::Double);
    let (shape, x) = npy_f64(&fixture("x_t.npy"));
    let (_, t) = npy_f64(&fixture("t.npy"));
    let (_, expected) = npy_f64(&fixture("expected.npy"));
    let b = shape[0] as i64;
    let x = Tensor::from_slice(&x).reshape([b, v, 3]);
    let tt = Tensor::from_slice(&t)
        .reshape([b, 1, 1])
        .expand([b, v, 1], false);
    let e = Tensor::from_slice(&eigen)
        .reshape([1, v, k])
        .expand([b, v, k], false);
    let cond = Tensor::cat(&[xyz.expand([b, v, 3], false), tt, e], 2);
    let out = flow.forward(&mt, &x, Some(&cond)).unwrap();
    let (err, scale) = worst(&out.vertex, &expected);
    assert!(scale > 1e-2, "the oracle's output is not trivial: {scale}");
    assert!(
        err <= 1e-6 * scale,
        "the flow differs from the official one by {err} (scale {scale})"
    );

    // the run's own predictor (float32, as the sampler runs it) on the
    // source as it is
    let sampler = ArbitrarySampler::load(&run).unwrap();
    assert_eq!(sampler.spec().config.frame, SourceFrame::AsIs);
    let predicted = sampler.eigenvectors_on(&mesh).unwrap();
    let predicted = Tensor::from_slice(&predicted);
    let (err, scale) = worst(&predicted, &eigen);
    assert!(err <= 1e-5 * scale, "{err} of {scale}");
}

#[test]
fn an_imported_run_samples_as_is_with_mass_mean_zero_targets() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    import(&run);
    let mesh = template();
    let mut sampler = ArbitrarySampler::load(&run).unwrap();
    assert!(sampler.source_warnings(&mesh).is_empty());
    sampler.set_ode_steps(4);
    let a = sampler.sample(&mesh, 0, 2, 7).unwrap();
    assert_eq!(sampler.sample(&mesh, 0, 2, 7).unwrap(), a, "seeded");
    let mass = mfm_geometry::operators::lumped_mass(&mesh);
    let total: f64 = mass.iter().sum();
    for target in &a {
        assert!(target.iter().flatten().all(|x| x.is_finite()));
        let spread = target.iter().flatten().fold(0.0f64, |m, x| m.max(x.abs()));
        assert!(spread > 1e-3, "a target is not collapsed: {spread}");
        for c in 0..3 {
            let mean: f64 = target.iter().zip(&mass).map(|(p, m)| p[c] * m).sum::<f64>() / total;
            assert!(
                mean.abs() < 1e-5 * spread,
                "coordinate {c}: mass-weighted mean {mean} (spread {spread})"
            );
        }
    }
    // as-is: the same source moved elsewhere conditions the network on other
    // positions, so the targets change (the own frame would cancel a shift)
    let shifted = mesh
        .with_positions(
            mesh.positions()
                .iter()
                .map(|p| [p[0] + 0.5, p[1], p[2]])
                .collect(),
        )
        .unwrap();
    assert_ne!(sampler.sample(&shifted, 0, 2, 7).unwrap(), a);

    // what `mfm sample --run RUN --source MESH` writes
    let out = dir.path().join("samples");
    let folder = SampleFolder {
        run: &run,
        source_name: "template.obj",
        source_file: None,
        out: &out,
        count: 2,
        seed: 7,
        ply: 1,
    };
    write_sample_folder(&sampler, &mesh, &folder).unwrap();
    for f in [
        "samples.npy",
        "source.ply",
        "samples.png",
        "eigenvectors.png",
    ] {
        assert!(out.join(f).is_file(), "{f}");
    }
}

#[test]
fn an_imported_run_is_not_resumed_and_its_predictor_is_not_scored() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    import(&run);
    for kind in [RunKind::Flow, RunKind::Predictor] {
        let e = TrainingRun::prepare(kind, &run, None)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("imported") && e.contains("resume") && e.contains("import.json"),
            "{kind:?}: {e}"
        );
    }
    let sampler = ArbitrarySampler::load(&run).unwrap();
    let why = predictor_error_skipped(&sampler).unwrap();
    assert!(why.contains("imported"), "{why}");
}

#[test]
fn the_default_frame_of_runs_is_unchanged() {
    for c in [FlowConfig::paper(), FlowConfig::cpu()] {
        assert_eq!(c.frame, SourceFrame::Own);
        let json = serde_json::to_value(&c).unwrap();
        assert!(json.get("frame").is_none(), "{json}");
        let back: FlowConfig = serde_json::from_value(json).unwrap();
        assert_eq!(back, c, "a description without `frame` is the own frame");
    }
    let p = PredictorConfig::paper();
    assert_eq!(p.frame, SourceFrame::Own);
    let json = serde_json::to_value(&p).unwrap();
    assert!(json.get("frame").is_none(), "{json}");
    let mut as_is = FlowConfig::cpu();
    as_is.frame = SourceFrame::AsIs;
    let json = serde_json::to_value(&as_is).unwrap();
    assert_eq!(json["frame"], "as-is");
    assert_eq!(serde_json::from_value::<FlowConfig>(json).unwrap(), as_is);
}

/// A change to a checkpoint's state dict.
type Edit = Box<dyn FnOnce(&mut Vec<(String, TensorData)>)>;

/// Writes the fixture's checkpoint with `edit` applied to its state dict.
fn edited_checkpoint(dir: &Path, edit: impl FnOnce(&mut Vec<(String, TensorData)>)) -> PathBuf {
    let mut sd = Checkpoint::open(fixture("arbitrary.ckpt"))
        .unwrap()
        .state_dict("state_dict")
        .unwrap();
    edit(&mut sd);
    let path = dir.join("edited.ckpt");
    std::fs::write(
        &path,
        mfm_torchfile::state_dict_archive(&sd, Some("state_dict")).unwrap(),
    )
    .unwrap();
    path
}

#[test]
fn missing_extra_and_mis_shaped_tensors_are_refused_by_name_and_nothing_is_written() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("run");
    let config = fixture("config.yaml");
    let cases: Vec<(Edit, &str)> = vec![
        (
            Box::new(|sd| sd.retain(|(n, _)| n != "eigenvecs_predictor.head.bias")),
            "eigenvecs_predictor.head.bias",
        ),
        (
            Box::new(|sd| sd.retain(|(n, _)| n != "base_model.blocks.1.vert_mlp.ls2")),
            "base_model.blocks.1.vert_mlp.ls2",
        ),
        (
            Box::new(|sd| {
                sd.push((
                    "eigenvecs_predictor.blocks.0.vert_mlp.norm_pde.weight".into(),
                    TensorData::from_f32(vec![8], &[1.0; 8]),
                ))
            }),
            "eigenvecs_predictor.blocks.0.vert_mlp.norm_pde.weight",
        ),
        (
            Box::new(|sd| sd.push(("ema.weight".into(), TensorData::from_f32(vec![1], &[1.0])))),
            "ema.weight",
        ),
        (
            Box::new(|sd| {
                for (n, t) in sd.iter_mut() {
                    if n == "base_model.extra_feat_mlp.0.weight" {
                        // conditioning of 4 + 5 channels instead of 4 + 4
                        *t = TensorData::from_f32(vec![8, 9], &[0.0; 72]);
                    }
                }
            }),
            "base_model.extra_feat_mlp.0.weight",
        ),
    ];
    for (edit, named) in cases {
        let ckpt = edited_checkpoint(dir.path(), edit);
        let e = import_with(&ckpt, &config, None, &out)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains(named) && e.contains("edited.ckpt"),
            "{named}: {e}"
        );
        assert!(!out.exists(), "{named}: nothing is written");
    }

    // the predictor's own checkpoint must hold the flow checkpoint's copy
    let ckpt = edited_checkpoint(dir.path(), |sd| {
        sd.retain(|(n, _)| n.starts_with("eigenvecs_predictor."));
        for (n, t) in sd.iter_mut() {
            let rest = n["eigenvecs_predictor.".len()..].to_owned();
            if rest == "proj_in.bias" {
                t.bytes[0] ^= 1;
            }
            *n = format!("base_model.{rest}");
        }
    });
    let other = dir.path().join("other_predictor.ckpt");
    std::fs::rename(&ckpt, &other).unwrap();
    let e = import_with(&fixture("arbitrary.ckpt"), &config, Some(&other), &out)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("other_predictor.ckpt") && e.contains("base_model.proj_in.bias"),
        "{e}"
    );
    assert!(!out.exists(), "nothing is written");
}

#[test]
fn unsupported_options_are_refused_by_name_and_nothing_is_written() {
    let dir = tempfile::tempdir().unwrap();
    let text = std::fs::read_to_string(fixture("config.yaml")).unwrap();
    let out = dir.path().join("run");
    for (from, to, named) in [
        (
            "use_predicted_eigenvecs: True",
            "use_predicted_eigenvecs: False",
            "use_predicted_eigenvecs",
        ),
        ("method: 'midpoint'", "method: 'euler'", "ode_solver.method"),
        ("step_size: 0.05", "step_size: 0.03", "step_size"),
        ("  head_type: njf", "  head_type: linear", "model.head_type"),
        (
            "head_type: 'linear'",
            "head_type: 'njf'",
            "eigenvecs_predictor.head_type",
        ),
        (
            "    cmlp_nlayers: 3\n    cmlp_dropout",
            "    cmlp_nlayers: 2\n    cmlp_dropout",
            "model.extra_configs.cmlp_nlayers",
        ),
        (
            "      cmlp_nlayers: 3",
            "      cmlp_nlayers: 4",
            "eigenvecs_predictor.extra_configs.cmlp_nlayers",
        ),
        (
            "    cmlp_modulate: True\n    cmlp_nlayers",
            "    cmlp_modulate: False\n    cmlp_nlayers",
            "cmlp_modulate",
        ),
        (
            "    mlp_norm: False\n    inner",
            "    mlp_norm: True\n    inner",
            "mlp_norm",
        ),
        (
            "      inner_prod_features: False",
            "      inner_prod_features: True",
            "inner_prod_features",
        ),
        ("['v_source', 't']", "['t']", "extra_features"),
        (
            "  outputs_at: vertices",
            "  outputs_at: faces",
            "outputs_at",
        ),
        (
            "center_target_data: True",
            "center_target_data: False",
            "center_target_data",
        ),
        (
            "  use_predicted_eigenvecs: True",
            "  use_predicted_eigenvecs: True\n  layer_scale: 2",
            "layer_scale",
        ),
        (
            "    out_dim: 4",
            "    out_dim: 5",
            "base_model.extra_feat_mlp.0.weight",
        ),
        ("  hidden_dim: 8", "  hidden_dim: 16", "base_model."),
    ] {
        assert!(text.contains(from), "{from}");
        let cfg = dir.path().join("edited.yaml");
        std::fs::write(&cfg, text.replacen(from, to, 1)).unwrap();
        let e = import_with(&fixture("arbitrary.ckpt"), &cfg, None, &out)
            .unwrap_err()
            .to_string();
        assert!(e.contains(named), "{to}: {e}");
        assert!(!out.exists(), "{to}: nothing is written");
    }
    assert!(OfficialArbitraryConfig::read(&fixture("config.yaml")).is_ok());
    assert_eq!(
        official_model_type(&fixture("config.yaml")).unwrap(),
        "Matern_FM_arbitrary_source"
    );
    // the single-source reader points at this importer
    let e = mfm_fm::official::OfficialConfig::read(fixture("config.yaml"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("arbitrary-source"), "{e}");
}

#[test]
fn the_fixture_is_what_its_script_writes() {
    let Some(python) = python_oracle() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let script = workspace_root().join("crates/arbitrary/tests/official_arbitrary_fixture.py");
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
    // inputs byte for byte; the float64 outputs to round-off (torch's
    // summation order depends on the CPU's vector width)
    for f in ["config.yaml", "template.obj", "x_t.npy", "t.npy"] {
        assert_eq!(
            std::fs::read(dir.path().join(f)).unwrap(),
            std::fs::read(fixture(f)).unwrap(),
            "{f} differs from what the script writes"
        );
    }
    for f in ["expected.npy", "expected_eigenvectors.npy"] {
        let (shape, written) = npy_f64(&dir.path().join(f));
        let (fixture_shape, stored) = npy_f64(&fixture(f));
        assert_eq!(shape, fixture_shape, "{f} shape");
        let worst = written
            .iter()
            .zip(&stored)
            .map(|(a, b)| (a - b).abs() / b.abs().max(1.0))
            .fold(0.0_f64, f64::max);
        assert!(
            worst < 1e-12,
            "{f} differs from what the script writes by {worst:e} (relative)"
        );
    }
    for f in ["arbitrary.ckpt", "predictor.ckpt"] {
        let tensors = |p: &Path| {
            Checkpoint::open(p)
                .unwrap()
                .state_dict("state_dict")
                .unwrap()
        };
        assert_eq!(
            tensors(&dir.path().join(f)),
            tensors(&fixture(f)),
            "{f} differs from what the script writes"
        );
    }
}
