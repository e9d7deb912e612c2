//! End-to-end tests that drive the real `mfm` binary.
#![allow(clippy::unwrap_used)]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn mfm(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_mfm"))
        .args(args)
        .output()
        .expect("the mfm binary runs")
}

#[cfg(feature = "network")]
/// Writes `config` to `DIR/run.toml` and runs `mfm train --config
/// DIR/run.toml --dataset DIR/data/train --out DIR/run --quiet`.
fn train_with_config(dir: &Path, config: &str) -> Output {
    let p = |s: &str| dir.join(s).to_string_lossy().into_owned();
    std::fs::write(dir.join("run.toml"), config).unwrap();
    mfm(&[
        "train",
        "--config",
        &p("run.toml"),
        "--dataset",
        &p("data/train"),
        "--out",
        &p("run"),
        "--quiet",
    ])
}

#[cfg(feature = "network")]
/// `mfm dataset gmm` of `n` training and `reference` reference signals on
/// the small built-in blob into `DIR/data` (wide bumps, so they fit).
fn small_gmm_dataset(dir: &Path, n: usize, reference: usize) -> Output {
    let out = dir.join("data").to_string_lossy().into_owned();
    let (n, reference) = (n.to_string(), reference.to_string());
    mfm(&[
        "dataset",
        "gmm",
        "--mesh",
        "builtin:blob:2",
        "--out",
        &out,
        "--n",
        &n,
        "--reference",
        &reference,
        "--sigma",
        "0.1",
        "--min-separation",
        "2",
    ])
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

fn fixtures() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fixtures")
}

#[test]
fn info_on_builtin_reports_counts_and_topology() {
    let o = mfm(&["info", "builtin:icosphere:2", "--json"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).expect("json");
    assert_eq!(v["num_vertices"], 162);
    assert_eq!(v["num_faces"], 320);
    assert_eq!(v["euler_characteristic"], 2);
    assert_eq!(v["genus"], 0);
    let text = mfm(&["info", "builtin:torus"]);
    assert!(text.status.success());
    assert!(String::from_utf8_lossy(&text.stdout).contains("genus"));
}

#[test]
fn bad_input_exits_non_zero_with_one_line_naming_the_file() {
    let missing = mfm(&["info", "/nonexistent/mesh.off"]);
    assert!(!missing.status.success());
    let e = stderr(&missing);
    assert_eq!(e.trim_end().lines().count(), 1, "one line: {e}");
    assert!(e.contains("/nonexistent/mesh.off"), "{e}");

    let unknown = mfm(&["info", "builtin:dodecahedron"]);
    assert!(!unknown.status.success());
    assert!(stderr(&unknown).contains("unknown built-in mesh"));

    // every bad fixture that fails to load gives one line naming it
    let dir = fixtures().join("bad");
    let mut seen = 0;
    for entry in std::fs::read_dir(&dir).expect("fixtures/bad exists") {
        let path = entry.expect("entry").path();
        let o = mfm(&["info", path.to_str().expect("utf8 path")]);
        if !o.status.success() {
            let e = stderr(&o);
            assert_eq!(e.trim_end().lines().count(), 1, "{}: {e}", path.display());
            let name = path
                .file_name()
                .expect("name")
                .to_string_lossy()
                .into_owned();
            assert!(e.contains(&name), "{e}");
            seen += 1;
        }
    }
    assert!(seen > 0);
}

#[test]
fn operators_are_written_and_consistent() {
    let dir = tempfile::tempdir().expect("tempdir");
    let out = dir.path().join("ops");
    let o = mfm(&[
        "operators",
        "builtin:icosphere:2",
        "--out",
        out.to_str().expect("utf8"),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    // L.mtx: header, size line, and L 1 = 0 (rows sum to zero)
    let text = std::fs::read_to_string(out.join("L.mtx")).expect("L.mtx");
    let mut lines = text.lines().filter(|l| !l.starts_with('%'));
    let dims: Vec<usize> = lines
        .next()
        .expect("size line")
        .split_whitespace()
        .map(|t| t.parse().expect("int"))
        .collect();
    assert_eq!(&dims[..2], &[162, 162]);
    let mut row_sum = vec![0.0f64; 162];
    let mut count = 0;
    for l in lines {
        let t: Vec<&str> = l.split_whitespace().collect();
        let i: usize = t[0].parse().expect("row");
        let v: f64 = t[2].parse().expect("value");
        row_sum[i - 1] += v;
        count += 1;
    }
    assert_eq!(count, dims[2]);
    assert!(row_sum.iter().all(|s| s.abs() < 1e-12));
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).expect("summary"))
            .expect("json");
    let gamma = summary["gamma"].as_f64().expect("gamma");
    assert!(gamma.is_finite() && gamma > 0.0);
    // the mass file sums to the surface area
    let bytes = std::fs::read(out.join("mass.npy")).expect("mass.npy");
    let mass: Vec<f64> = npyz::NpyFile::new(&bytes[..])
        .expect("npy")
        .into_vec()
        .expect("f64");
    let area = summary["total_area"].as_f64().expect("area");
    assert!((mass.iter().sum::<f64>() - area).abs() < 1e-12 * area);
}

#[test]
fn operators_files_are_readable_by_scipy() {
    let Some(python) = mfm_geometry::test_support::python_oracle() else {
        return;
    };
    let dir = tempfile::tempdir().expect("tempdir");
    let out = dir.path().join("ops");
    let o = mfm(&[
        "operators",
        "builtin:torus",
        "--out",
        out.to_str().expect("utf8"),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let script = r#"
import sys, json, numpy as np, scipy.io
d = sys.argv[1]
L = scipy.io.mmread(d + "/L.mtx").tocsr()
G = scipy.io.mmread(d + "/G.mtx").tocsr()
m = np.load(d + "/mass.npy"); a = np.load(d + "/face_areas.npy")
a2 = np.repeat(a, 2)
r = abs(G.T @ (a2[:, None] * G.toarray()) - L.toarray()).max() / abs(L).max()
print(json.dumps({"n": L.shape[0], "gtag": float(r), "sym": float(abs(L - L.T).max()), "m": float(m.sum()), "a": float(a.sum())}))
"#;
    let res = Command::new(python)
        .args(["-c", script, out.to_str().expect("utf8")])
        .output()
        .expect("python runs");
    assert!(
        res.status.success(),
        "{}",
        String::from_utf8_lossy(&res.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&res.stdout).expect("json");
    assert!(v["gtag"].as_f64().expect("f") < 1e-12, "{v}");
    assert_eq!(v["sym"].as_f64(), Some(0.0));
    assert!((v["m"].as_f64().expect("m") - v["a"].as_f64().expect("a")).abs() < 1e-10);
}

#[test]
fn convert_and_render_write_files() {
    let dir = tempfile::tempdir().expect("tempdir");
    let ply = dir.path().join("t.ply");
    let o = mfm(&["convert", "builtin:capsule", ply.to_str().expect("utf8")]);
    assert!(o.status.success(), "{}", stderr(&o));
    let back = mfm(&["info", ply.to_str().expect("utf8"), "--json"]);
    assert!(back.status.success(), "{}", stderr(&back));
    let png = dir.path().join("t.png");
    let r = mfm(&[
        "render",
        ply.to_str().expect("utf8"),
        "--scalar",
        "z",
        "--size",
        "64",
        "--out",
        png.to_str().expect("utf8"),
    ]);
    assert!(r.status.success(), "{}", stderr(&r));
    let bytes = std::fs::read(&png).expect("png written");
    assert_eq!(&bytes[1..4], b"PNG");
    let bad = mfm(&[
        "convert",
        "builtin:capsule",
        dir.path().join("t.stl").to_str().expect("utf8"),
    ]);
    assert!(!bad.status.success());
    assert!(stderr(&bad).contains(".obj or .ply"));
}

fn read_npy(path: &Path) -> Vec<f64> {
    let bytes = std::fs::read(path).expect("npy file");
    npyz::NpyFile::new(&bytes[..])
        .expect("npy")
        .into_vec()
        .expect("f64")
}

#[test]
fn eigs_match_the_sphere_spectrum_and_are_mass_orthonormal() {
    let dir = tempfile::tempdir().expect("tempdir");
    let out = dir.path().join("eigs");
    let ops = dir.path().join("ops");
    let mesh = "builtin:icosphere:3";
    let o = mfm(&[
        "eigs",
        mesh,
        "--k",
        "9",
        "--out",
        out.to_str().expect("utf8"),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let o = mfm(&["operators", mesh, "--out", ops.to_str().expect("utf8")]);
    assert!(o.status.success(), "{}", stderr(&o));
    let values = read_npy(&out.join("eigenvalues.npy"));
    let vectors = read_npy(&out.join("eigenvectors.npy"));
    let mass = read_npy(&ops.join("mass.npy"));
    let (n, k) = (mass.len(), 9);
    assert_eq!(values.len(), k);
    assert_eq!(vectors.len(), n * k);
    // unit sphere: l(l+1) with multiplicity 2l+1 -> 0, 2 x3, 6 x5
    assert!(values[0].abs() < 1e-8, "{values:?}");
    for (i, &lambda) in values.iter().enumerate().skip(1) {
        let exact = if i < 4 { 2.0 } else { 6.0 };
        assert!(
            (lambda - exact).abs() < 0.03 * exact,
            "lambda_{i} = {lambda}"
        );
    }
    for a in 0..k {
        for b in 0..k {
            let dot: f64 = (0..n)
                .map(|v| vectors[v * k + a] * mass[v] * vectors[v * k + b])
                .sum();
            let expected = if a == b { 1.0 } else { 0.0 };
            assert!((dot - expected).abs() < 1e-8, "({a},{b}) -> {dot}");
        }
    }
    let bad = mfm(&[
        "eigs",
        mesh,
        "--k",
        "0",
        "--out",
        out.to_str().expect("utf8"),
    ]);
    assert!(!bad.status.success());
    assert!(stderr(&bad).contains("--k"));
}

#[test]
fn noise_writes_npy_json_png_and_is_deterministic() {
    let dir = tempfile::tempdir().expect("tempdir");
    let a = dir.path().join("a.npy");
    let b = dir.path().join("b.npy");
    let png = dir.path().join("a.png");
    let args = |out: &Path| {
        vec![
            "noise".to_owned(),
            "builtin:icosphere:2".to_owned(),
            "--kind".to_owned(),
            "matern".to_owned(),
            "--tau".to_owned(),
            "10".to_owned(),
            "--samples".to_owned(),
            "3".to_owned(),
            "--channels".to_owned(),
            "2".to_owned(),
            "--seed".to_owned(),
            "5".to_owned(),
            "--out".to_owned(),
            out.to_str().expect("utf8").to_owned(),
        ]
    };
    let mut first = args(&a);
    first.extend(["--png".to_owned(), png.to_str().expect("utf8").to_owned()]);
    let first: Vec<&str> = first.iter().map(String::as_str).collect();
    let o = mfm(&first);
    assert!(o.status.success(), "{}", stderr(&o));
    let second = args(&b);
    let second: Vec<&str> = second.iter().map(String::as_str).collect();
    assert!(mfm(&second).status.success());
    let bytes = std::fs::read(&a).expect("npy");
    let npy = npyz::NpyFile::new(&bytes[..]).expect("npy");
    assert_eq!(npy.shape(), &[3, 162, 2]);
    let values: Vec<f64> = npy.into_vec().expect("f64");
    assert!(values.iter().all(|x| x.is_finite()));
    assert!(values.iter().any(|&x| x != 0.0));
    // same seed, same bits
    assert_eq!(values, read_npy(&b));
    // `--noise matern:10`, the grammar of `mfm train --noise`, is the same noise
    let c = dir.path().join("c.npy");
    let o = mfm(&[
        "noise",
        "builtin:icosphere:2",
        "--noise",
        "matern:10",
        "--samples",
        "3",
        "--channels",
        "2",
        "--seed",
        "5",
        "--out",
        c.to_str().expect("utf8"),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(values, read_npy(&c));
    let o = mfm(&[
        "noise",
        "builtin:icosphere:1",
        "--noise",
        "white",
        "--tau",
        "3",
        "--out",
        c.to_str().expect("utf8"),
    ]);
    assert!(
        !o.status.success() && stderr(&o).contains("--tau"),
        "{}",
        stderr(&o)
    );
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(a.with_extension("json")).expect("json"))
            .expect("json");
    assert_eq!(summary["kind"]["kind"], "matern");
    assert_eq!(summary["tau"], 10.0);
    let img = std::fs::read(&png).expect("png");
    assert_eq!(&img[1..4], b"PNG");
    // a flag the kind does not use is an error, not silently ignored
    let o = mfm(&[
        "noise",
        "builtin:icosphere:1",
        "--kind",
        "white",
        "--tau",
        "3",
        "--out",
        a.to_str().expect("utf8"),
    ]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("--tau"), "{}", stderr(&o));
}

#[test]
fn spectrum_reports_matern_variance_near_theory_and_compares_meshes() {
    let dir = tempfile::tempdir().expect("tempdir");
    let out = dir.path().join("spec.json");
    let plots = dir.path().join("plots");
    let o = mfm(&[
        "spectrum",
        "builtin:icosphere:2",
        "builtin:icosphere:3",
        "--tau",
        "20",
        "--samples",
        "1500",
        "--k",
        "16",
        "--out",
        out.to_str().expect("utf8"),
        "--plots",
        plots.to_str().expect("utf8"),
        "--coefficients",
        "1,9",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&out).expect("report")).expect("json");
    let meshes = v["meshes"].as_array().expect("meshes");
    assert_eq!(meshes.len(), 2);
    for m in meshes {
        // relative sd of a variance from 1500 samples is sqrt(2/1500) = 3.7%;
        // 16 frequencies stay within 5 sigma
        let err = m["report"]["max_relative_error"].as_f64().expect("error");
        assert!(err < 0.185, "{err}");
    }
    assert_eq!(v["comparisons"].as_array().expect("comparisons").len(), 1);
    let rel = v["comparisons"][0]["max_relative_std_difference"]
        .as_f64()
        .expect("std diff");
    assert!(rel < 0.2, "{rel}");
    for f in ["variance.png", "coefficients.png"] {
        assert!(plots.join(f).is_file(), "{f}");
    }
}

#[test]
#[cfg(feature = "network")]
fn net_summary_counts_match_the_reference_implementation() {
    for (preset, expected) in [
        ("paper", 1_369_600u64),
        ("medium", 282_688),
        ("small", 56_000),
    ] {
        let o = mfm(&["net", "summary", "--preset", preset, "--json"]);
        assert!(o.status.success(), "{}", stderr(&o));
        let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        assert_eq!(v["parameters"].as_u64(), Some(expected), "{preset}");
        assert!(v["config"]["width"].as_u64().is_some());
    }
    // The table lists every variable and ends with the total.
    let o = mfm(&["net", "summary", "--preset", "small"]);
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(text.contains("proj_in.weight"), "{text}");
    let last = text.lines().last().unwrap_or_default();
    assert!(
        last.starts_with("total") && last.trim_end().ends_with("56000"),
        "{last}"
    );
    let o = mfm(&["net", "summary", "--preset", "huge"]);
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("paper, medium, small"),
        "{}",
        stderr(&o)
    );
}

#[test]
#[cfg(feature = "network")]
fn net_bench_prints_step_and_inference_medians() {
    let o = mfm(&[
        "net",
        "bench",
        "builtin:icosphere:2",
        "--preset",
        "small",
        "--batch",
        "2",
        "--steps",
        "1",
        "--warmup",
        "0",
        "--inference",
        "1",
        "--threads",
        "1",
        "--profile",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(text.contains("56000 parameters"), "{text}");
    // the profile finds the dense layers' sections (`fn:linear`, `fn:linear^T`)
    assert!(text.contains("s per step in the dense layers"), "{text}");
    assert!(text.contains("fn:linear^T"), "{text}");
    assert!(text.contains("training step (median of 1)"), "{text}");
    assert!(text.contains("inference, batch 1 (median of 1)"), "{text}");
    // a step does the products of 3 x batch forward passes
    let sizes: Vec<usize> = text
        .lines()
        .find_map(|l| l.strip_prefix("mesh: "))
        .unwrap()
        .split(' ')
        .take(3)
        .filter_map(|w| w.parse().ok())
        .collect();
    let forward = mfm_net::PoissonNetConfig::small().forward_product_flops(sizes[0], sizes[1]);
    let step = 3.0 * 2.0 * forward as f64 * 1e-9;
    let line = format!(
        "dense products: {} GFLOP per step",
        mfm_net::bench::three_digits(step)
    );
    assert!(text.contains(&line), "expected {line:?} in {text}");
    let o = mfm(&["net", "bench", "builtin:icosphere:2", "--batch", "0"]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("--batch"), "{}", stderr(&o));
}

#[cfg(feature = "network")]
fn read_npy_f32(path: &Path) -> (Vec<u64>, Vec<f32>) {
    let bytes = std::fs::read(path).unwrap();
    let npy = npyz::NpyFile::new(&bytes[..]).unwrap();
    let shape = npy.shape().to_vec();
    (shape, npy.into_vec::<f32>().unwrap())
}

/// The flow-matching workflow from the command line on a small mesh:
/// dataset -> train (with a TOML config) -> sample on another
/// triangulation -> eval, plus the errors a user meets on the way.
#[test]
#[cfg(feature = "network")]
fn gmm_dataset_train_sample_eval_end_to_end() {
    let dir = tempfile::tempdir().unwrap();
    let p = |s: &str| dir.path().join(s).to_string_lossy().into_owned();
    let o = small_gmm_dataset(dir.path(), 12, 6);
    assert!(o.status.success(), "{}", stderr(&o));
    for f in [
        "train/signals.npy",
        "train/manifest.json",
        "reference/signals.npy",
        "preview.png",
    ] {
        assert!(dir.path().join("data").join(f).is_file(), "{f} missing");
    }
    let (shape, values) = read_npy_f32(&dir.path().join("data/train/signals.npy"));
    assert_eq!(shape.len(), 3);
    assert_eq!((shape[0], shape[2]), (12, 1));
    let max = values.iter().copied().fold(f32::MIN, f32::max);
    assert!(max > 0.5 && max < 1.5, "bump peaks near 1, found {max}");
    // A second run into the same folder refuses and keeps the data.
    let o = mfm(&[
        "dataset",
        "gmm",
        "--mesh",
        "builtin:blob:2",
        "--out",
        &p("data"),
        "--n",
        "2",
    ]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("not empty"), "{}", stderr(&o));
    assert_eq!(
        read_npy_f32(&dir.path().join("data/train/signals.npy")).1,
        values
    );

    // A config with a typo names the field.
    std::fs::write(dir.path().join("bad.toml"), "[train]\nstepz = 3\n").unwrap();
    let o = mfm(&[
        "train",
        "--config",
        &p("bad.toml"),
        "--dataset",
        &p("data/train"),
        "--out",
        &p("run"),
    ]);
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("stepz") && stderr(&o).contains("bad.toml"),
        "{}",
        stderr(&o)
    );

    let config = "[model]\npreset = \"small\"\nwidth = 8\nblocks = 1\nvector_layers = 1\n\
                  [train]\nsteps = 4\nbatch = 2\ncheckpoint_every = 2\nlog_every = 1\n\
                  [sample]\nsteps = 2\n";
    let o = train_with_config(dir.path(), config);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(dir.path().join("run/model.safetensors").is_file());
    // the run says which frame it trains in, and records it with the
    // dataset's own
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(
        out.contains("largest extent 1") && out.contains("centred"),
        "{out}"
    );
    let flow: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("run/flow.json")).unwrap())
            .unwrap();
    let manifest: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(dir.path().join("data/train/manifest.json")).unwrap(),
    )
    .unwrap();
    assert_eq!(flow["frame"], manifest["frame"], "{flow} {manifest}");
    assert_eq!(flow["centered"], true);
    let log = std::fs::read_to_string(dir.path().join("run/train_log.csv")).unwrap();
    assert_eq!(log.lines().count(), 5, "header + 4 rows:\n{log}");
    // Training again into a finished run folder is refused.
    let o = train_with_config(dir.path(), config);
    assert!(!o.status.success());

    // Sample on the reference's (non-uniform, finer) mesh.
    let test_mesh = p("data/reference/mesh.ply");
    // five samples of the run on the test mesh into `out`, with `extra` flags
    let sample_into = |out: &str, extra: &[&str]| {
        let (run, out) = (p("run"), p(out));
        let mut args = vec!["sample", "--run", &run, "--mesh", &test_mesh];
        args.extend(["--n", "5", "--out", &out]);
        args.extend(extra);
        mfm(&args)
    };
    let o = sample_into("samples", &["--ply", "2"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let (shape, samples) = read_npy_f32(&dir.path().join("samples/samples.npy"));
    let test_v = mfm_meshio::read_mesh(&test_mesh).unwrap().num_vertices() as u64;
    assert_eq!(shape, vec![5, test_v, 1]);
    assert!(samples.iter().all(|x| x.is_finite()));
    assert!(dir.path().join("samples/sample_001.ply").is_file());
    assert!(!dir.path().join("samples/sample_002.ply").exists());
    assert!(dir.path().join("samples/samples.png").is_file());
    // --device: cpu gives the same samples here; a bad name and a missing
    // GPU are clear errors
    let sample_on = |device: &str, out: &str| sample_into(out, &["--device", device]);
    let o = sample_on("cpu", "samples_cpu");
    assert!(o.status.success(), "{}", stderr(&o));
    // (equal here; with a GPU the first run used it: equal up to round-off)
    let on_cpu = read_npy_f32(&dir.path().join("samples_cpu/samples.npy")).1;
    let diff = on_cpu
        .iter()
        .zip(&samples)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0f32, f32::max);
    assert!(on_cpu.len() == samples.len() && diff < 1e-4, "{diff}");
    let o = sample_on("tpu", "samples_tpu");
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("expected auto, cpu or cuda"),
        "{}",
        stderr(&o)
    );
    let o = sample_on("cuda", "samples_cuda");
    if !o.status.success() {
        assert!(stderr(&o).contains("no CUDA device"), "{}", stderr(&o));
    }
    // a finished run resumed on the CPU has nothing left to do; on a GPU
    // that libtorch does not see it is a clear error
    let o = mfm(&["train", "--out", &p("run"), "--resume", "--device", "cpu"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        String::from_utf8_lossy(&o.stdout).contains("step 4"),
        "{}",
        String::from_utf8_lossy(&o.stdout)
    );
    let o = mfm(&["train", "--out", &p("run"), "--resume", "--device", "cuda"]);
    if !o.status.success() {
        assert!(stderr(&o).contains("no CUDA device"), "{}", stderr(&o));
    }

    let o = mfm(&[
        "eval",
        "--samples",
        &p("samples/samples.npy"),
        "--reference",
        &p("data/reference"),
        "--out",
        &p("metrics.json"),
        "--png",
        &p("means.png"),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("metrics.json")).unwrap())
            .unwrap();
    assert_eq!(m["num_generated"], 5);
    assert_eq!(m["num_reference"], 6);
    let cov = m["cov"].as_f64().unwrap();
    assert!(
        (0.0..=1.0).contains(&cov) && m["mmd"].as_f64().unwrap() > 0.0,
        "{m}"
    );
    assert!(dir.path().join("means.png").is_file());
    // the sample-quality fit: printed, in the JSON, and data beside samples
    assert!(
        String::from_utf8_lossy(&o.stdout).contains("bump fit: residual median"),
        "{}",
        String::from_utf8_lossy(&o.stdout)
    );
    let q = &m["quality"];
    assert_eq!(q["generated"]["fits"].as_array().unwrap().len(), 5);
    assert_eq!(q["reference"]["fits"].as_array().unwrap().len(), 6);
    // the reference set is exactly in the generator's family
    assert!(q["floor"].as_f64().unwrap() < 1e-3, "{q}");
    assert!(
        q["generated"]["residual"]["median"].as_f64().unwrap() > 0.1,
        "{q}"
    );
    assert!(dir.path().join("means_samples.png").is_file());
    // a sampling mesh of another size is flagged, naming both sizes
    let scaled = p("scaled.ply");
    let big = mfm_meshio::read_mesh(&test_mesh)
        .unwrap()
        .transformed(3.0, [0.0; 3]);
    mfm_meshio::write_ply(&scaled, &big, &[]).unwrap();
    let o = mfm(&[
        "sample",
        "--run",
        &p("run"),
        "--mesh",
        &scaled,
        "--n",
        "1",
        "--out",
        &p("s_big"),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("warning")
            && stderr(&o).contains("differs from the training surface's"),
        "{}",
        stderr(&o)
    );
    assert!(
        !stderr(&mfm(&[
            "sample",
            "--run",
            &p("run"),
            "--mesh",
            &test_mesh,
            "--n",
            "1",
            "--out",
            &p("s_same"),
        ]))
        .contains("warning")
    );
    // Samples from another mesh do not fit the reference.
    let o = mfm(&[
        "eval",
        "--samples",
        &p("data/train/signals.npy"),
        "--reference",
        &p("data/reference"),
    ]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("vertices"), "{}", stderr(&o));
}

#[test]
#[cfg(feature = "network")]
fn deformation_dataset_trains_on_coarse_and_samples_on_finer_meshes() {
    let dir = tempfile::tempdir().unwrap();
    let p = |s: &str| dir.path().join(s).to_string_lossy().into_owned();
    // builtin:capsule, decimated to 300 faces for training
    let o = mfm(&[
        "dataset",
        "deform",
        "--mesh",
        "builtin:capsule",
        "--out",
        &p("data"),
        "--n",
        "6",
        "--reference",
        "3",
        "--handles",
        "2",
        "--radius",
        "0.15",
        "--coarse-faces",
        "300",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    for f in [
        "train/signals.npy",
        "train/params.json",
        "reference/signals.npy",
        "holdout/signals.npy",
        "original.ply",
        "coarse.ply",
        "eval.ply",
        "space.json",
        "preview.png",
    ] {
        assert!(dir.path().join("data").join(f).is_file(), "{f} missing");
    }
    let (shape, _) = read_npy_f32(&dir.path().join("data/train/signals.npy"));
    assert_eq!((shape[0], shape[2]), (6, 3));
    let params: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(dir.path().join("data/train/params.json")).unwrap(),
    )
    .unwrap();
    assert_eq!(params.as_array().unwrap().len(), 6);

    // a tiny conditioned, augmented run on the coarse mesh
    let config = "[model]\npreset = \"small\"\nwidth = 8\nblocks = 1\nvector_layers = 1\ncondition_on_xyz = true\n\
                  [train]\nsteps = 3\nbatch = 2\ncheckpoint_every = 3\nlog_every = 1\n\
                  [train.augment]\nscale = 0.1\nshift = 0.05\n[sample]\nsteps = 2\n";
    let o = train_with_config(dir.path(), config);
    assert!(o.status.success(), "{}", stderr(&o));

    // resolution transfer: the original mesh and a 4x refinement of it
    let o = mfm(&[
        "remesh",
        &p("data/original.ply"),
        "--subdivide",
        "1",
        "--out",
        &p("fine.ply"),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    for mesh in ["data/original.ply", "fine.ply"] {
        let out = p(&format!("samples_{}", mesh.replace(['/', '.'], "_")));
        let o = mfm(&[
            "sample",
            "--run",
            &p("run"),
            "--mesh",
            &p(mesh),
            "--n",
            "2",
            "--out",
            &out,
        ]);
        assert!(o.status.success(), "{mesh}: {}", stderr(&o));
        let (shape, values) = read_npy_f32(&Path::new(&out).join("samples.npy"));
        assert_eq!((shape[0], shape[2]), (2, 3), "{mesh}");
        assert!(values.iter().all(|x| x.is_finite()), "{mesh}");
        // plausibility without a reference set
        let o = mfm(&[
            "eval",
            "--samples",
            &format!("{out}/samples.npy"),
            "--space",
            &p("data/space.json"),
            "--mesh",
            &p(mesh),
            "--out",
            &format!("{out}/projection.json"),
        ]);
        assert!(o.status.success(), "{mesh}: {}", stderr(&o));
        let m: serde_json::Value = serde_json::from_str(
            &std::fs::read_to_string(format!("{out}/projection.json")).unwrap(),
        )
        .unwrap();
        assert!(m["projection_mse"].as_f64().unwrap() > 0.0, "{m}");
    }

    // held-out shapes score against the reference set with the projection metric
    let o = mfm(&[
        "sample",
        "--run",
        &p("run"),
        "--mesh",
        &p("data/eval.ply"),
        "--n",
        "3",
        "--out",
        &p("s_eval"),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let o = mfm(&[
        "eval",
        "--samples",
        &p("s_eval/samples.npy"),
        "--reference",
        &p("data/reference"),
        "--out",
        &p("m.json"),
        "--png",
        &p("shapes.png"),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("m.json")).unwrap()).unwrap();
    let (generated, reference) = (
        m["projection_mse"].as_f64().unwrap(),
        m["reference_projection_mse"].as_f64().unwrap(),
    );
    // an untrained model's shapes are far from the space; dataset shapes lie in it
    assert!(reference < 1e-3 * generated, "{m}");
    // the spread of the projections' handle parameters, against the data's
    for k in ["param_spread", "reference_param_spread"] {
        assert!(m[k]["rotation"].as_f64().unwrap() >= 0.0, "{m}");
    }
    assert!(
        m["reference_param_spread"]["rotation"].as_f64().unwrap() > 0.0,
        "{m}"
    );
    assert!(
        m["projection_mse_quartiles"]["median"].as_f64().unwrap() > 0.0,
        "{m}"
    );
    assert!(dir.path().join("shapes.png").is_file());

    // damage keeps the handles: holes and flips give meshes the model samples on
    let o = mfm(&[
        "remesh",
        &p("data/eval.ply"),
        "--damage",
        "medium-holes",
        "--space",
        &p("data/space.json"),
        "--out",
        &p("holes.ply"),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let o = mfm(&[
        "remesh",
        &p("data/eval.ply"),
        "--damage",
        "dents",
        "--space",
        &p("data/space.json"),
        "--out",
        &p("x.ply"),
    ]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("small-holes"), "{}", stderr(&o));
    // another surface's mesh with this space: refused, nothing written
    let o = mfm(&[
        "remesh",
        "builtin:torus",
        "--damage",
        "small-holes",
        "--space",
        &p("data/space.json"),
        "--out",
        &p("torus.ply"),
    ]);
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("not the space's surface"),
        "{}",
        stderr(&o)
    );
    assert!(!dir.path().join("torus.ply").exists());
}

#[cfg(feature = "network")]
#[test]
fn pairs_dataset_predictor_and_arbitrary_source_flow_end_to_end() {
    let dir = tempfile::tempdir().unwrap();
    let p = |s: &str| dir.path().join(s).to_string_lossy().into_owned();
    let pairs = |extra: &[&str]| {
        let mut a = vec!["dataset", "pairs", "--mesh", "builtin:capsule", "--out"];
        a.extend_from_slice(extra);
        mfm(&a)
    };
    // a pair needs two poses of one shape; nothing is written
    let o = pairs(&[&p("bad"), "--poses", "1"]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("--poses"), "{}", stderr(&o));
    assert!(!dir.path().join("bad").exists());
    let o = pairs(&[
        &p("data"),
        "--shapes",
        "2",
        "--poses",
        "2",
        "--reference",
        "1",
        "--handles",
        "2",
        "--radius",
        "0.15",
        "--regions",
        "3",
        "--coarse-faces",
        "300",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    for f in [
        "train/signals.npy",
        "train/params.json",
        "holdout/signals.npy",
        "reference/signals.npy",
        "pair_space.json",
        "eval.ply",
        "preview.png",
    ] {
        assert!(dir.path().join("data").join(f).is_file(), "{f} missing");
    }
    let (shape, _) = read_npy_f32(&dir.path().join("data/train/signals.npy"));
    assert_eq!((shape[0], shape[2]), (4, 3));
    // the flow mode's options are refused in the other modes, and back
    let o = mfm(&[
        "train",
        "--mode",
        "predictor",
        "--noise",
        "white",
        "--dataset",
        &p("data/train"),
        "--out",
        &p("x"),
    ]);
    assert!(stderr(&o).contains("--mode flow"), "{}", stderr(&o));
    let o = mfm(&[
        "train",
        "--mode",
        "predictor",
        "--dataset",
        &p("data/train"),
        "--out",
        &p("pred"),
        "--steps",
        "2",
        "--quiet",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(dir.path().join("pred/model.safetensors").is_file());
    let o = mfm(&[
        "train",
        "--mode",
        "arbitrary",
        "--dataset",
        &p("data/train"),
        "--predictor",
        &p("pred"),
        "--out",
        &p("arb"),
        "--steps",
        "2",
        "--quiet",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    // a fresh run that fails before its first checkpoint leaves nothing
    let o = mfm(&[
        "train",
        "--mode",
        "arbitrary",
        "--dataset",
        &p("data/train"),
        "--predictor",
        &p("nowhere"),
        "--out",
        &p("failed"),
        "--quiet",
    ]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("nowhere"), "{}", stderr(&o));
    assert!(!dir.path().join("failed").exists());
    // a finished run resumes to nothing new
    let o = mfm(&[
        "train",
        "--mode",
        "arbitrary",
        "--resume",
        "--out",
        &p("arb"),
        "--quiet",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(String::from_utf8_lossy(&o.stdout).contains("steps 2..2 of 2"));
    // a source of another triangulation than the template's
    let o = mfm(&[
        "sample",
        "--run",
        &p("arb"),
        "--source",
        &p("data/eval.ply"),
        "--n",
        "2",
        "--ply",
        "1",
        "--out",
        &p("targets"),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let (shape, values) = read_npy_f32(&dir.path().join("targets/samples.npy"));
    let eval_vertices = shape[1];
    assert_eq!((shape[0], shape[2]), (2, 3));
    assert!(values.iter().all(|x| x.is_finite()));
    for f in [
        "source.ply",
        "sample_000.ply",
        "samples.png",
        "eigenvectors.png",
    ] {
        assert!(dir.path().join("targets").join(f).is_file(), "{f} missing");
    }
    let o = mfm(&[
        "eval-arbitrary",
        "--run",
        &p("arb"),
        "--experiment",
        &p("data"),
        "--sources",
        "1",
        "--per-source",
        "1",
        "--out",
        &p("eval"),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let report: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(dir.path().join("eval/report.json")).unwrap(),
    )
    .unwrap();
    let sets = report.as_array().unwrap();
    assert_eq!(sets.len(), 2);
    assert_eq!(sets[1]["vertices"].as_u64(), Some(eval_vertices));
    // the data's own shapes are in their space: the floor is round-off
    assert!(sets[0]["projection_floor"]["median"].as_f64().unwrap() < 1e-10);
    assert!(dir.path().join("eval/reference.png").is_file());
    // a one-mesh run is sampled with --mesh, not --source
    let o = mfm(&[
        "sample",
        "--run",
        &p("pred"),
        "--source",
        &p("data/eval.ply"),
        "--out",
        &p("y"),
    ]);
    assert!(!o.status.success());
}

#[test]
#[cfg(feature = "network")]
fn kept_snapshots_sample_by_step_with_or_without_the_weight_average() {
    let dir = tempfile::tempdir().unwrap();
    let p = |s: &str| dir.path().join(s).to_string_lossy().into_owned();
    let o = small_gmm_dataset(dir.path(), 8, 4);
    assert!(o.status.success(), "{}", stderr(&o));
    // clean-signal prediction, a weight average and a kept snapshot off the
    // checkpoint grid
    let config = "[model]\npreset = \"small\"\nwidth = 8\nblocks = 1\nvector_layers = 1\n\
                  prediction = \"clean\"\n\
                  [train]\nsteps = 6\nbatch = 2\ncheckpoint_every = 3\nkeep_checkpoints = 1\n\
                  log_every = 1\nema = 0.5\nkeep_at = [1]\njacobian_weight = 0.5\n\
                  time = \"late:2\"\n[sample]\nsteps = 2\n";
    let o = train_with_config(dir.path(), config);
    assert!(o.status.success(), "{}", stderr(&o));
    let flow = std::fs::read_to_string(dir.path().join("run/flow.json")).unwrap();
    assert!(flow.contains("\"prediction\": \"clean\""), "{flow}");
    let mesh = p("data/reference/mesh.ply");
    let run = p("run");
    let sample = |out: &str, extra: &[&str]| {
        let out = p(out);
        let mut args = vec![
            "sample", "--run", &run, "--mesh", &mesh, "--n", "2", "--out", &out, "--ply", "0",
        ];
        args.extend_from_slice(extra);
        mfm(&args)
    };
    let avg = sample("s_avg", &["--step", "1"]);
    assert!(avg.status.success(), "{}", stderr(&avg));
    let raw = sample("s_raw", &["--step", "1", "--raw-weights"]);
    assert!(raw.status.success(), "{}", stderr(&raw));
    let (_, a) = read_npy_f32(&dir.path().join("s_avg/samples.npy"));
    let (_, r) = read_npy_f32(&dir.path().join("s_raw/samples.npy"));
    assert!(a.iter().all(|x| x.is_finite()) && r.iter().all(|x| x.is_finite()));
    assert_ne!(a, r, "the average and the trained weights sample alike");
    let fin = sample("s_final", &[]);
    assert!(fin.status.success(), "{}", stderr(&fin));
    // a step without a checkpoint names the ones there are
    let missing = sample("s_missing", &["--step", "4"]);
    assert!(!missing.status.success());
    let e = stderr(&missing);
    assert!(e.contains("--step 4") && e.contains("1, 6"), "{e}");
    assert!(!dir.path().join("s_missing").exists());
    // --raw-weights needs --step
    let bare = sample("s_bare", &["--raw-weights"]);
    assert!(!bare.status.success());
    assert!(stderr(&bare).contains("--step"), "{}", stderr(&bare));
}

#[test]
#[cfg(feature = "network")]
fn the_shipped_pretrained_model_loads_and_samples() {
    // fixtures/pretrained/gmm-blob is what `cargo xtask demo` samples first:
    // its checksums hold and it samples the built-in blob it was trained on
    let run = fixtures().join("pretrained/gmm-blob");
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("s");
    let o = mfm(&[
        "sample",
        "--run",
        &run.to_string_lossy(),
        "--mesh",
        "builtin:blob",
        "--n",
        "2",
        "--steps",
        "4",
        "--out",
        &out.to_string_lossy(),
        "--ply",
        "0",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let (shape, values) = read_npy_f32(&out.join("samples.npy"));
    assert_eq!((shape[0], shape[2]), (2, 1));
    assert!(values.iter().all(|x| x.is_finite()));
    // a bump field: values between about 0 and about 1
    let max = values.iter().copied().fold(f32::MIN, f32::max);
    assert!(max > 0.3 && max < 2.0, "peak {max}");
    let flow = std::fs::read_to_string(run.join("flow.json")).unwrap();
    assert!(flow.contains("\"centered\": true"), "{flow}");
}

/// libtorch's OpenMP workers spin briefly by default (`GOMP_SPINCOUNT`
/// set before libtorch loads), and a user's own setting wins.
#[test]
#[cfg(all(feature = "network", target_os = "linux"))]
fn openmp_workers_spin_briefly_unless_the_user_chose() {
    let bench = |env: &[(&str, &str)]| {
        let mut c = Command::new(env!("CARGO_BIN_EXE_mfm"));
        c.args([
            "net",
            "bench",
            "builtin:icosphere:1",
            "--steps",
            "1",
            "--warmup",
            "0",
            "--inference",
            "0",
            "--threads",
            "1",
        ])
        .env_remove("GOMP_SPINCOUNT")
        .env_remove("OMP_WAIT_POLICY");
        for (k, v) in env {
            c.env(k, v);
        }
        let o = c.output().unwrap();
        assert!(o.status.success(), "{}", stderr(&o));
        String::from_utf8_lossy(&o.stdout).into_owned()
    };
    let text = bench(&[]);
    assert!(
        text.contains("OpenMP workers wait with GOMP_SPINCOUNT=1000 (mfm's default)"),
        "{text}"
    );
    let text = bench(&[("GOMP_SPINCOUNT", "50000")]);
    assert!(text.contains("wait with GOMP_SPINCOUNT=50000\n"), "{text}");
    let text = bench(&[("OMP_WAIT_POLICY", "ACTIVE")]);
    assert!(
        text.contains("wait with OMP_WAIT_POLICY=ACTIVE\n"),
        "{text}"
    );
}

/// fixtures/pretrained/elephant (`cargo xtask pretrain elephant`): at most
/// 1 MB, and, where the shared elephant mesh is there to make its training
/// mesh, it samples poses of the elephant's size on that mesh.
#[test]
#[cfg(feature = "network")]
fn the_shipped_shape_model_is_small_and_samples_elephants() {
    let run = fixtures().join("pretrained/elephant");
    let bytes: u64 = std::fs::read_dir(&run)
        .unwrap()
        .map(|e| e.unwrap().metadata().unwrap().len())
        .sum();
    assert!(bytes <= 1 << 20, "{bytes} bytes");
    let flow = std::fs::read_to_string(run.join("flow.json")).unwrap();
    assert!(flow.contains("matern-smooth:100:2"), "{flow}");
    let elephant =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/meshes/elephant.obj");
    if !elephant.is_file() {
        eprintln!(
            "skipped sampling the shape model: {} not found",
            elephant.display()
        );
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let p = |s: &str| dir.path().join(s).to_string_lossy().into_owned();
    let o = mfm(&[
        "dataset",
        "deform",
        "--mesh",
        &elephant.to_string_lossy(),
        "--n",
        "2",
        "--reference",
        "1",
        "--out",
        &p("data"),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let o = mfm(&[
        "sample",
        "--run",
        &run.to_string_lossy(),
        "--mesh",
        &p("data/coarse.ply"),
        "--n",
        "2",
        "--ply",
        "0",
        "--out",
        &p("s"),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let (shape, values) = read_npy_f32(&dir.path().join("s/samples.npy"));
    assert_eq!((shape[0], shape[2]), (2, 3));
    assert!(values.iter().all(|x| x.is_finite()));
    // poses of the training shape: its size (unit bounding-box diagonal)
    for s in 0..2 {
        let n = shape[1] as usize;
        let pts = &values[s * n * 3..(s + 1) * n * 3];
        let (mut lo, mut hi) = ([f32::MAX; 3], [f32::MIN; 3]);
        for p in pts.chunks(3) {
            for k in 0..3 {
                lo[k] = lo[k].min(p[k]);
                hi[k] = hi[k].max(p[k]);
            }
        }
        let diagonal = (0..3).map(|k| (hi[k] - lo[k]).powi(2)).sum::<f32>().sqrt();
        assert!(
            (0.8..1.25).contains(&diagonal),
            "sample {s}: diagonal {diagonal}"
        );
    }
}

/// `mfm remesh --refine-half R`: one half of the surface refined (the GMM
/// test mesh's recipe), after any subdivision; nothing moves, and more
/// than 4 rounds are refused.
#[test]
fn remesh_refines_one_half_of_the_surface() {
    let dir = tempfile::tempdir().unwrap();
    let p = |s: &str| dir.path().join(s).to_string_lossy().into_owned();
    let o = mfm(&[
        "remesh",
        "builtin:icosphere:2",
        "--subdivide",
        "1",
        "--refine-half",
        "2",
        "--out",
        &p("half.ply"),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = String::from_utf8_lossy(&o.stdout);
    // 320 faces, 1280 after one subdivision; two rounds of bisection on
    // half of them: between 1.5x and 4x as many
    let faces: usize = text
        .split(", ")
        .find_map(|w| w.strip_suffix(" faces (from 162 vertices"))
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("{text}"));
    assert!((1920..5120).contains(&faces), "{faces}: {text}");
    let o = mfm(&["info", &p("half.ply")]);
    assert!(o.status.success(), "{}", stderr(&o));
    let o = mfm(&[
        "remesh",
        "builtin:icosphere:2",
        "--refine-half",
        "5",
        "--out",
        &p("x.ply"),
    ]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("at most 4 rounds"), "{}", stderr(&o));
}
