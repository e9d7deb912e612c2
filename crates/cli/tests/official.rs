//! `mfm import`, `mfm sample --x0` and `mfm export-weights` end to end on
//! the official-layout checkpoint of fixtures/official-tiny (the smoke test
//! of running an authors' model: import, then sample from it).
#![cfg(feature = "network")]
#![allow(clippy::unwrap_used)]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn mfm(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_mfm"))
        .args(args)
        .output()
        .expect("the mfm binary runs")
}

fn tiny(name: &str) -> String {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../fixtures/official-tiny")
        .join(name)
        .to_string_lossy()
        .into_owned()
}

fn text(o: &Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

fn import(out: &Path) -> Output {
    mfm(&[
        "import",
        "--checkpoint",
        &tiny("tiny.ckpt"),
        "--config",
        &tiny("config.yaml"),
        "--mesh",
        &tiny("template.obj"),
        "--out",
        out.to_str().unwrap(),
    ])
}

/// Writes `[n, v, c]` float64 values to an `.npy` file (numpy's header).
fn write_npy(path: &Path, shape: [usize; 3], values: &[f64]) {
    let header = format!(
        "{{'descr': '<f8', 'fortran_order': False, 'shape': ({}, {}, {}), }}",
        shape[0], shape[1], shape[2]
    );
    let mut h = header.into_bytes();
    while (10 + h.len() + 1) % 64 != 0 {
        h.push(b' ');
    }
    h.push(b'\n');
    let mut bytes = b"\x93NUMPY\x01\x00".to_vec();
    bytes.extend_from_slice(&(h.len() as u16).to_le_bytes());
    bytes.extend_from_slice(&h);
    for v in values {
        bytes.extend_from_slice(&v.to_le_bytes());
    }
    std::fs::write(path, bytes).unwrap();
}

fn read_samples(path: &Path) -> (Vec<u64>, Vec<f32>) {
    let bytes = std::fs::read(path).unwrap();
    let npy = npyz::NpyFile::new(&bytes[..]).unwrap();
    let shape = npy.shape().to_vec();
    (shape, npy.into_vec::<f32>().unwrap())
}

#[test]
fn import_then_sample_from_drawn_and_given_noise() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    let o = import(&run);
    assert!(o.status.success(), "{}", text(&o));
    let said = text(&o);
    assert!(
        said.contains("imported 2368 parameters (step 1234)"),
        "{said}"
    );
    assert!(said.contains("optimizer_states"), "{said}");

    // a second import into the same folder is refused; nothing is replaced
    let before = std::fs::read(run.join("model.safetensors")).unwrap();
    let o = import(&run);
    assert!(!o.status.success());
    assert!(text(&o).contains("not empty"), "{}", text(&o));
    assert_eq!(
        std::fs::read(run.join("model.safetensors")).unwrap(),
        before
    );

    let samples = dir.path().join("samples");
    let p = |x: &Path| x.to_string_lossy().into_owned();
    let o = mfm(&[
        "sample",
        "--run",
        &p(&run),
        "--mesh",
        &tiny("template.obj"),
        "--n",
        "2",
        "--steps",
        "3",
        "--out",
        &p(&samples),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let (shape, drawn) = read_samples(&samples.join("samples.npy"));
    assert_eq!(shape, vec![2, 18, 3]);
    assert!(drawn.iter().all(|x| x.is_finite()));

    // --x0: three given starts give three samples; the same file gives the
    // same samples again, and another file other ones
    let x0: Vec<f64> = (0..3 * 18 * 3)
        .map(|i| ((i * 7919) % 101) as f64 / 500.0 - 0.1)
        .collect();
    let x0_path = dir.path().join("x0.npy");
    write_npy(&x0_path, [3, 18, 3], &x0);
    let given = |out: &Path, x0: &Path| {
        mfm(&[
            "sample",
            "--run",
            &p(&run),
            "--mesh",
            &tiny("template.obj"),
            "--steps",
            "3",
            "--x0",
            &p(x0),
            "--out",
            &p(out),
        ])
    };
    let (a, b) = (dir.path().join("a"), dir.path().join("b"));
    let o = given(&a, &x0_path);
    assert!(o.status.success(), "{}", text(&o));
    assert!(given(&b, &x0_path).status.success());
    let (shape, sa) = read_samples(&a.join("samples.npy"));
    assert_eq!(shape, vec![3, 18, 3]);
    assert_eq!(sa, read_samples(&b.join("samples.npy")).1);
    let shifted: Vec<f64> = x0.iter().map(|v| v + 0.01).collect();
    let x1_path = dir.path().join("x1.npy");
    write_npy(&x1_path, [3, 18, 3], &shifted);
    let c = dir.path().join("c");
    assert!(given(&c, &x1_path).status.success());
    assert_ne!(sa, read_samples(&c.join("samples.npy")).1);

    // a start of the wrong shape is refused naming both shapes; --n and
    // --x0 do not go together
    let bad = dir.path().join("bad.npy");
    write_npy(&bad, [2, 17, 3], &vec![0.0; 2 * 17 * 3]);
    let o = given(&dir.path().join("d"), &bad);
    assert!(!o.status.success());
    let e = text(&o);
    assert!(
        e.contains("[2, 17, 3]") && e.contains("[2, 18, 3]") && e.contains("bad.npy"),
        "{e}"
    );
    let o = mfm(&[
        "sample",
        "--run",
        &p(&run),
        "--mesh",
        &tiny("template.obj"),
        "--x0",
        &p(&x0_path),
        "--n",
        "3",
        "--out",
        &p(&dir.path().join("e")),
    ]);
    assert!(!o.status.success());
    assert!(text(&o).contains("--n"), "{}", text(&o));
}

#[test]
fn export_weights_writes_a_checkpoint_that_imports_to_the_same_model() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    assert!(import(&run).status.success());
    let ckpt = dir.path().join("model.ckpt");
    let p = |x: &Path| x.to_string_lossy().into_owned();
    let o = mfm(&["export-weights", "--run", &p(&run), "--out", &p(&ckpt)]);
    assert!(o.status.success(), "{}", text(&o));
    assert!(text(&o).contains("53 tensors"), "{}", text(&o));

    let o = mfm(&["export-weights", "--run", &p(&run), "--out", &p(&ckpt)]);
    assert!(!o.status.success());
    assert!(text(&o).contains("--force"), "{}", text(&o));
    let o = mfm(&[
        "export-weights",
        "--run",
        &p(&run),
        "--out",
        &p(&ckpt),
        "--force",
    ]);
    assert!(o.status.success(), "{}", text(&o));
    // the run's own files are inputs: never written over
    let o = mfm(&[
        "export-weights",
        "--run",
        &p(&run),
        "--out",
        &p(&run.join("model.safetensors")),
        "--force",
    ]);
    assert!(!o.status.success(), "{}", text(&o));

    let again: PathBuf = dir.path().join("again");
    let o = mfm(&[
        "import",
        "--checkpoint",
        &p(&ckpt),
        "--config",
        &tiny("config.yaml"),
        "--mesh",
        &tiny("template.obj"),
        "--out",
        &p(&again),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    assert_eq!(
        std::fs::read(run.join("model.safetensors")).unwrap(),
        std::fs::read(again.join("model.safetensors")).unwrap()
    );
}

#[test]
fn import_errors_name_the_file_at_fault() {
    let dir = tempfile::tempdir().unwrap();
    let p = |x: &Path| x.to_string_lossy().into_owned();
    let notes = dir.path().join("notes.ckpt");
    std::fs::write(&notes, "not a checkpoint").unwrap();
    let o = mfm(&[
        "import",
        "--checkpoint",
        &p(&notes),
        "--config",
        &tiny("config.yaml"),
        "--mesh",
        &tiny("template.obj"),
        "--out",
        &p(&dir.path().join("r1")),
    ]);
    assert!(!o.status.success());
    let e = text(&o);
    assert!(e.contains("notes.ckpt") && e.contains("torch.save"), "{e}");
    assert!(!e.contains("panicked"), "{e}");
    assert!(!dir.path().join("r1").exists());

    let yaml = dir.path().join("norm.yaml");
    std::fs::write(
        &yaml,
        std::fs::read_to_string(tiny("config.yaml"))
            .unwrap()
            .replace("mlp_norm: False", "mlp_norm: True"),
    )
    .unwrap();
    let o = mfm(&[
        "import",
        "--checkpoint",
        &tiny("tiny.ckpt"),
        "--config",
        &p(&yaml),
        "--mesh",
        &tiny("template.obj"),
        "--out",
        &p(&dir.path().join("r2")),
    ]);
    assert!(!o.status.success());
    let e = text(&o);
    assert!(e.contains("norm.yaml") && e.contains("mlp_norm"), "{e}");
}

fn arbitrary(name: &str) -> String {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../fixtures/official-arbitrary")
        .join(name)
        .to_string_lossy()
        .into_owned()
}

#[test]
fn import_of_an_arbitrary_source_model_then_sample_over_a_source() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    let p = |x: &Path| x.to_string_lossy().into_owned();
    let o = mfm(&[
        "import",
        "--checkpoint",
        &arbitrary("arbitrary.ckpt"),
        "--config",
        &arbitrary("config.yaml"),
        "--predictor-checkpoint",
        &arbitrary("predictor.ckpt"),
        "--out",
        &p(&run),
    ]);
    let said = text(&o);
    assert!(o.status.success(), "{said}");
    assert!(
        said.contains("arbitrary-source flow") && said.contains("(step 1234)"),
        "{said}"
    );
    assert!(said.contains("same weights"), "{said}");

    let samples = dir.path().join("samples");
    let o = mfm(&[
        "sample",
        "--run",
        &p(&run),
        "--source",
        &arbitrary("template.obj"),
        "--n",
        "2",
        "--steps",
        "3",
        "--out",
        &p(&samples),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let (shape, drawn) = read_samples(&samples.join("samples.npy"));
    assert_eq!(shape, vec![2, 18, 3]);
    assert!(drawn.iter().all(|x| x.is_finite()));

    // an imported run has no training state to continue
    for mode in [None, Some("arbitrary"), Some("predictor")] {
        let mut args = vec!["train", "--resume", "--out", run.to_str().unwrap()];
        if let Some(m) = mode {
            args.extend(["--mode", m]);
        }
        let o = mfm(&args);
        assert!(!o.status.success(), "{mode:?}");
        let said = text(&o);
        assert!(
            said.contains("imported") && said.contains("resume"),
            "{mode:?}: {said}"
        );
    }

    // a predictor that is not the flow's is refused naming both files,
    // and nothing is written
    let other = dir.path().join("other");
    let o = mfm(&[
        "import",
        "--checkpoint",
        &arbitrary("arbitrary.ckpt"),
        "--config",
        &arbitrary("config.yaml"),
        "--predictor-checkpoint",
        &tiny("tiny.ckpt"),
        "--out",
        &p(&other),
    ]);
    let said = text(&o);
    assert!(!o.status.success(), "{said}");
    assert!(
        said.contains("tiny.ckpt") && said.contains("nothing was written"),
        "{said}"
    );
    assert!(!other.join("arbitrary.json").exists());

    // the predictor's own configuration is not a model to import
    let predictor_yaml = dir.path().join("predictor.yaml");
    std::fs::write(
        &predictor_yaml,
        "model:\n  type: eigenvecs_predictor\n  model_type: PoissonNet\n",
    )
    .unwrap();
    let o = mfm(&[
        "import",
        "--checkpoint",
        &arbitrary("predictor.ckpt"),
        "--config",
        &p(&predictor_yaml),
        "--out",
        &p(&other),
    ]);
    assert!(!o.status.success());
    assert!(
        text(&o).contains("--predictor-checkpoint") && text(&o).contains("predictor.yaml"),
        "{}",
        text(&o)
    );

    // a single-source model still needs its template
    let o = mfm(&[
        "import",
        "--checkpoint",
        &tiny("tiny.ckpt"),
        "--config",
        &tiny("config.yaml"),
        "--out",
        &p(&other),
    ]);
    assert!(!o.status.success());
    assert!(text(&o).contains("--mesh"), "{}", text(&o));
}
