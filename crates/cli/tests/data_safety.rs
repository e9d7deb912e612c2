//! What `mfm` refuses to overwrite, how it survives signals and damaged
//! files, and how it fails on bad input: each check drives the real binary.
#![allow(clippy::unwrap_used)]

use std::fs;
use std::path::Path;
use std::process::Command;

mod common;
#[cfg(feature = "network")]
use common::TINY;
use common::{err, interrupt_when, ok, refused, signals_when};

fn tmp_files(dir: &Path) -> Vec<String> {
    let mut found = Vec::new();
    for e in walk(dir) {
        let name = e.file_name().unwrap().to_string_lossy().into_owned();
        if name.contains(".tmp") {
            found.push(e.display().to_string());
        }
    }
    found
}

fn walk(dir: &Path) -> Vec<std::path::PathBuf> {
    let mut out = Vec::new();
    for e in fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() {
            out.extend(walk(&p));
        }
        out.push(p);
    }
    out
}

#[test]
fn outputs_never_replace_inputs_devices_or_each_other() {
    let d = tempfile::tempdir().unwrap();
    let d = d.path();
    ok(d, &["convert", "builtin:icosphere:1", "ico.ply"]);
    let mesh = fs::read(d.join("ico.ply")).unwrap();
    refused(
        d,
        &["noise", "ico.ply", "--out", "ico.ply"],
        "is also an input",
    );
    refused(
        d,
        &["noise", "ico.ply", "--out", "./ico.ply"],
        "is also an input",
    );
    refused(
        d,
        &["render", "ico.ply", "--out", "ico.ply"],
        "is also an input",
    );
    refused(
        d,
        &["noise", "ico.ply", "--out", "n.npy", "--png", "ico.ply"],
        "is also an input",
    );
    refused(d, &["convert", "ico.ply", "ico.ply"], "is also an input");
    refused(
        d,
        &["noise", "ico.ply", "--out", "x.json"],
        "give --out a .npy name",
    );
    refused(
        d,
        &["noise", "ico.ply", "--out", "n.npy", "--png", "n.npy"],
        "are the same file",
    );
    assert_eq!(fs::read(d.join("ico.ply")).unwrap(), mesh);
    // a device node stays a device node
    refused(
        d,
        &["noise", "ico.ply", "--out", "/dev/null"],
        "is a device",
    );
    use std::os::unix::fs::FileTypeExt;
    assert!(
        fs::metadata("/dev/null")
            .unwrap()
            .file_type()
            .is_char_device()
    );
    // a folder is not replaced by a file
    fs::create_dir(d.join("folder.npy")).unwrap();
    refused(
        d,
        &["noise", "ico.ply", "--out", "folder.npy"],
        "is a folder",
    );
    assert!(d.join("folder.npy").is_dir());
    // a symlink: its target is written, the link stays
    fs::write(d.join("target.npy"), "old").unwrap();
    std::os::unix::fs::symlink("target.npy", d.join("link.npy")).unwrap();
    ok(d, &["noise", "ico.ply", "--out", "link.npy"]);
    assert!(
        fs::symlink_metadata(d.join("link.npy"))
            .unwrap()
            .file_type()
            .is_symlink()
    );
    assert!(
        fs::read(d.join("target.npy"))
            .unwrap()
            .starts_with(b"\x93NUMPY")
    );
    // eval: the samples and the reference dataset are inputs
    ok(
        d,
        &[
            "dataset",
            "gmm",
            "--mesh",
            "builtin:icosphere:2",
            "--out",
            "data",
            "--n",
            "3",
            "--reference",
            "3",
        ],
    );
    let ref_mesh = fs::read(d.join("data/reference/mesh.ply")).unwrap();
    let samples = d.join("data/train/signals.npy").display().to_string();
    refused(
        d,
        &[
            "eval",
            "--samples",
            &samples,
            "--reference",
            "data/reference",
            "--out",
            &samples,
        ],
        "is also an input",
    );
    refused(
        d,
        &[
            "eval",
            "--samples",
            &samples,
            "--reference",
            "data/reference",
            "--png",
            "data/reference/mesh.ply",
        ],
        "inside the input folder",
    );
    assert_eq!(
        fs::read(d.join("data/reference/mesh.ply")).unwrap(),
        ref_mesh
    );
    assert!(tmp_files(d).is_empty(), "{:?}", tmp_files(d));
}

#[test]
fn bad_files_and_values_are_refused_by_name() {
    let d = tempfile::tempdir().unwrap();
    let d = d.path();
    // huge values are written with the shared formatter, not 300 digits
    let e = refused(
        d,
        &[
            "dataset",
            "gmm",
            "--mesh",
            "builtin:icosphere:2",
            "--out",
            "g",
            "--n",
            "2",
            "--sigma",
            "1e300",
        ],
        "e300",
    );
    assert!(e.len() < 400, "{e}");
    // the advice names the flag of the command: --regions, not handles
    let e = refused(
        d,
        &[
            "dataset",
            "pairs",
            "--mesh",
            "builtin:capsule",
            "--out",
            "p",
            "--regions",
            "400",
        ],
        "use fewer regions (--regions)",
    );
    assert!(!e.contains("fewer handles"), "{e}");
    assert!(!d.join("g").exists() && !d.join("p").exists());
    // header counts are enforced
    fs::write(
        d.join("extra.off"),
        "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n3 0 2 1\n",
    )
    .unwrap();
    refused(
        d,
        &["info", "extra.off"],
        "extra.off`: line 7: found `3` after the 3 vertices and 1 faces",
    );
    let ply = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n\
property float z\nelement face 2\nproperty list uchar int vertex_indices\nend_header\n\
0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n3 0 2 1\n3 0 1 2\n3 1 2 0\n";
    fs::write(d.join("four.ply"), ply).unwrap();
    refused(
        d,
        &["info", "four.ply"],
        "after the last element the header declares",
    );
    let garbage: Vec<u8> = (0..4000u32)
        .map(|i| (i.wrapping_mul(2654435761) >> 13) as u8)
        .collect();
    fs::write(d.join("garbage.obj"), garbage).unwrap();
    refused(d, &["info", "garbage.obj"], "not an OBJ file");
    // control bytes from a file are shown escaped, never sent to the terminal
    fs::write(
        d.join("esc.off"),
        b"OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 \x1b[2J\x07\n",
    )
    .unwrap();
    let e = refused(d, &["info", "esc.off"], "esc.off");
    assert!(!e.chars().any(|c| c.is_control() && c != '\n'), "{e:?}");
    assert!(e.contains("\\u{1b}[2J"), "{e}");
    // duplicate faces: `info` flags them and every computing command refuses
    fs::write(
        d.join("dup.off"),
        "OFF\n4 3 0\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 1 2\n3 0 2 3\n3 2 1 0\n",
    )
    .unwrap();
    let info = ok(d, &["info", "dup.off"]);
    assert!(String::from_utf8_lossy(&info.stdout).contains("duplicate face"));
    for args in [
        &["noise", "dup.off", "--out", "n.npy"][..],
        &["operators", "dup.off", "--out", "ops"],
        &["eigs", "dup.off", "--k", "2", "--out", "eigs"],
    ] {
        refused(d, args, "dup.off: 1 duplicate face");
    }
    assert!(!d.join("ops").exists() && !d.join("eigs").exists() && !d.join("n.npy").exists());
    // non-manifold edges: a warning, the same one from every command
    fs::write(
        d.join("fin.off"),
        "OFF\n5 3 0\n0 0 0\n1 0 0\n0 1 0\n0 -1 0\n0 0 1\n3 0 1 2\n3 1 0 3\n3 0 1 4\n",
    )
    .unwrap();
    for args in [
        &["noise", "fin.off", "--out", "f.npy"][..],
        &["operators", "fin.off", "--out", "fops"],
    ] {
        let o = ok(d, args);
        assert!(
            err(&o).contains("warning: fin.off: 1 non-manifold edge"),
            "{}",
            err(&o)
        );
    }
    // numbers: negative values reach the command, which names the flag
    ok(d, &["convert", "builtin:icosphere:1", "ico.ply"]);
    refused(
        d,
        &["noise", "ico.ply", "--tau", "-1", "--out", "t.npy"],
        "invalid parameter tau",
    );
    refused(
        d,
        &["noise", "ico.ply", "--tau", "1e-15", "--out", "t.npy"],
        "at least 1e-10 x Gamma",
    );
    refused(
        d,
        &[
            "noise",
            "ico.ply",
            "--kind",
            "matern-normalized",
            "--c",
            "1e-20",
            "--out",
            "t.npy",
        ],
        "invalid parameter c: expected at least 1e-10",
    );
    ok(d, &["noise", "ico.ply", "--tau", "0", "--out", "t0.npy"]);
    let o = ok(d, &["noise", "ico.ply", "--tau", "1e10", "--out", "t.npy"]);
    let line = String::from_utf8_lossy(&o.stdout).into_owned();
    assert!(
        line.contains("matern:10000000000") && line.len() < 400,
        "{line}"
    );
    // beyond it the noise vanishes (1e300: all zeros, every sample alike)
    refused(
        d,
        &["noise", "ico.ply", "--tau", "1e300", "--out", "t300.npy"],
        "in [0, 1e10]",
    );
    // npy files: truncated and wrong shapes name the file
    let bytes = fs::read(d.join("t.npy")).unwrap();
    fs::write(d.join("trunc.npy"), &bytes[..bytes.len() - 3]).unwrap();
    refused(
        d,
        &[
            "render",
            "ico.ply",
            "--scalars",
            "trunc.npy",
            "--out",
            "r.png",
        ],
        "trunc.npy: truncated",
    );
    assert!(!d.join("r.png").exists());
    // a dataset with a NaN is refused, naming file, signal and vertex
    ok(
        d,
        &[
            "dataset",
            "gmm",
            "--mesh",
            "builtin:icosphere:2",
            "--out",
            "data",
            "--n",
            "3",
            "--reference",
            "2",
        ],
    );
    let signals = d.join("data/train/signals.npy");
    let mut raw = fs::read(&signals).unwrap();
    let at = raw.len() - 4 * 7;
    raw[at..at + 4].copy_from_slice(&f32::NAN.to_le_bytes());
    fs::write(&signals, &raw).unwrap();
    if cfg!(feature = "network") {
        refused(
            d,
            &[
                "train",
                "--preset",
                "cpu",
                "--dataset",
                "data/train",
                "--out",
                "run",
                "--steps",
                "2",
                "--quiet",
            ],
            "signal 2, vertex",
        );
        // ...and the failed start leaves no run folder behind
        assert!(!d.join("run").exists());
    }
    // an eval of NaN samples is an error naming the file and the sample
    refused(
        d,
        &[
            "eval",
            "--samples",
            "data/train/signals.npy",
            "--reference",
            "data/reference",
        ],
        "signals.npy: sample 2 is not finite",
    );
    // samples with other channels than the reference name both
    ok(
        d,
        &[
            "noise",
            "data/reference/mesh.ply",
            "--channels",
            "2",
            "--out",
            "two.npy",
        ],
    );
    refused(
        d,
        &[
            "eval",
            "--samples",
            "two.npy",
            "--reference",
            "data/reference",
        ],
        "two.npy: samples have 2 channels but the reference set data/reference has 1",
    );
    // an output larger than the disk is refused before anything is written
    refused(
        d,
        &[
            "noise",
            "ico.ply",
            "--samples",
            "100000000000",
            "--out",
            "big.npy",
        ],
        "free there",
    );
    assert!(!d.join("big.npy").exists() && !d.join("big.json").exists());
    // messages for paths that are not what they should be
    if cfg!(feature = "network") {
        refused(
            d,
            &[
                "sample", "--run", "nowhere", "--mesh", "ico.ply", "--out", "s",
            ],
            "nowhere: no such run folder",
        );
        refused(
            d,
            &[
                "train",
                "--preset",
                "cpu",
                "--dataset",
                "t.npy",
                "--out",
                "run2",
            ],
            "is a file, not a dataset folder",
        );
    } else {
        refused(
            d,
            &[
                "sample", "--run", "nowhere", "--mesh", "ico.ply", "--out", "s",
            ],
            "`network` feature",
        );
    }
    refused(
        d,
        &["eval", "--samples", "t.npy", "--reference", "t.npy"],
        "is a file, not a dataset folder",
    );
    assert!(!d.join("s").exists() && !d.join("run2").exists());
    assert!(tmp_files(d).is_empty(), "{:?}", tmp_files(d));
}

#[test]
#[cfg(feature = "network")]
fn runs_survive_signals_edits_moves_and_damage() {
    let root = tempfile::tempdir().unwrap();
    let d = &root.path().join("project");
    fs::create_dir(d).unwrap();
    ok(
        d,
        &[
            "dataset",
            "gmm",
            "--mesh",
            "builtin:icosphere:2",
            "--out",
            "data",
            "--n",
            "6",
            "--reference",
            "4",
        ],
    );
    fs::write(d.join("run.toml"), TINY).unwrap();
    ok(
        d,
        &[
            "train",
            "--config",
            "run.toml",
            "--dataset",
            "data/train",
            "--out",
            "run",
            "--quiet",
        ],
    );
    // the dataset path is stored absolute
    let config = fs::read_to_string(d.join("run/config.toml")).unwrap();
    let stored = d.join("data/train").canonicalize().unwrap();
    assert!(
        config.contains(&format!("path = \"{}\"", stored.display())),
        "{config}"
    );

    // sample: a non-empty folder is refused; --force replaces only what
    // sample writes, stale PLYs of an earlier run included
    ok(
        d,
        &[
            "sample",
            "--run",
            "run",
            "--mesh",
            "data/reference/mesh.ply",
            "--n",
            "3",
            "--ply",
            "3",
            "--out",
            "s",
        ],
    );
    fs::write(d.join("s/notes.txt"), "mine").unwrap();
    let before = fs::read(d.join("s/samples.npy")).unwrap();
    refused(
        d,
        &[
            "sample",
            "--run",
            "run",
            "--mesh",
            "data/reference/mesh.ply",
            "--n",
            "2",
            "--ply",
            "1",
            "--out",
            "s",
        ],
        "--force",
    );
    assert_eq!(fs::read(d.join("s/samples.npy")).unwrap(), before);
    ok(
        d,
        &[
            "sample",
            "--run",
            "run",
            "--mesh",
            "data/reference/mesh.ply",
            "--n",
            "2",
            "--ply",
            "1",
            "--out",
            "s",
            "--force",
        ],
    );
    assert!(d.join("s/sample_000.ply").is_file());
    assert!(!d.join("s/sample_001.ply").exists() && !d.join("s/sample_002.ply").exists());
    assert_eq!(fs::read_to_string(d.join("s/notes.txt")).unwrap(), "mine");
    // more samples than the disk holds: refused up front, nothing written
    refused(
        d,
        &[
            "sample",
            "--run",
            "run",
            "--mesh",
            "data/reference/mesh.ply",
            "--n",
            "100000000000",
            "--out",
            "huge",
        ],
        "free there",
    );
    assert!(!d.join("huge").exists());
    // a sample into the run folder's own files is refused
    refused(
        d,
        &[
            "sample",
            "--run",
            "run",
            "--mesh",
            "data/reference/mesh.ply",
            "--out",
            "run/checkpoints",
            "--force",
        ],
        "inside the input folder",
    );
    // --force never writes into a dataset or run folder
    let mesh = fs::read(d.join("data/reference/mesh.ply")).unwrap();
    for out in ["data/reference", "run"] {
        refused(
            d,
            &[
                "sample",
                "--run",
                "run",
                "--mesh",
                "data/reference/mesh.ply",
                "--out",
                out,
                "--force",
            ],
            "--force never writes into",
        );
    }
    assert_eq!(fs::read(d.join("data/reference/mesh.ply")).unwrap(), mesh);

    // the final model is checksummed: a flipped byte is named
    let weights = d.join("run/model.safetensors");
    let good = fs::read(&weights).unwrap();
    let mut bad = good.clone();
    let k = bad.len() - 10;
    bad[k] ^= 0x40;
    fs::write(&weights, &bad).unwrap();
    refused(
        d,
        &[
            "sample",
            "--run",
            "run",
            "--mesh",
            "data/reference/mesh.ply",
            "--out",
            "s2",
        ],
        "model.safetensors: the final model file is corrupted",
    );
    assert!(!d.join("s2").exists());
    fs::write(&weights, &good).unwrap();

    // an edited config.toml: a model change is refused by name, a longer run accepted
    let original = fs::read_to_string(d.join("run/config.toml")).unwrap();
    fs::write(
        d.join("run/config.toml"),
        original.replace("width = 8", "width = 16"),
    )
    .unwrap();
    refused(
        d,
        &["train", "--out", "run", "--resume", "--quiet"],
        "model.width 8 -> 16",
    );
    assert!(
        fs::read_to_string(d.join("run/config.toml"))
            .unwrap()
            .contains("width = 16"),
        "the edit is kept"
    );
    fs::write(
        d.join("run/config.toml"),
        original.replace("steps = 4", "steps = 6"),
    )
    .unwrap();
    let o = ok(d, &["train", "--out", "run", "--resume", "--quiet"]);
    assert!(
        String::from_utf8_lossy(&o.stdout).contains("steps 4..6"),
        "{}",
        String::from_utf8_lossy(&o.stdout)
    );

    // moved: the project copied elsewhere resumes from any directory
    let moved = root.path().join("moved");
    fs::rename(d, &moved).unwrap();
    let o = ok(
        root.path(),
        &[
            "train",
            "--out",
            "moved/run",
            "--resume",
            "--steps",
            "8",
            "--quiet",
        ],
    );
    assert!(
        err(&o).contains("using") && err(&o).contains("moved/data/train"),
        "{}",
        err(&o)
    );
    // a finished run without its checkpoints is not retrained over its model
    let finished = moved.join("run");
    let model = fs::read(finished.join("model.safetensors")).unwrap();
    fs::remove_dir_all(finished.join("checkpoints")).unwrap();
    refused(
        &moved,
        &["train", "--out", "run", "--resume", "--quiet"],
        "no valid checkpoint",
    );
    assert_eq!(fs::read(finished.join("model.safetensors")).unwrap(), model);

    // SIGTERM (kill, timeout, Slurm, docker stop) checkpoints like Ctrl-C
    let long = TINY
        .replace("steps = 4", "steps = 1000000")
        .replace("checkpoint_every = 2", "checkpoint_every = 100000");
    fs::write(moved.join("long.toml"), long).unwrap();
    let child = Command::new(env!("CARGO_BIN_EXE_mfm"))
        .current_dir(&moved)
        .args([
            "train",
            "--config",
            "long.toml",
            "--dataset",
            "data/train",
            "--out",
            "long",
            "--quiet",
        ])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let log = moved.join("long/train_log.csv");
    let t0 = std::time::Instant::now();
    while fs::read_to_string(&log).map_or(0, |l| l.lines().count()) < 3 {
        assert!(t0.elapsed().as_secs() < 120, "training did not start");
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
    // one writer per run folder: a second one is refused naming the first
    let e = refused(
        &moved,
        &["train", "--out", "long", "--resume", "--quiet"],
        &format!("long is in use by PID {}", child.id()),
    );
    assert!(e.contains("--config long.toml"), "{e}");
    let status = Command::new("kill")
        .args(["-TERM", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(status.success());
    let o = child.wait_with_output().unwrap();
    assert_eq!(o.status.code(), Some(130), "{}", err(&o));
    let checkpoints: Vec<_> = fs::read_dir(moved.join("long/checkpoints"))
        .unwrap()
        .collect();
    assert_eq!(checkpoints.len(), 1, "one checkpoint written on SIGTERM");
    assert!(
        !moved.join(".long.mfm-lock").exists(),
        "the lock goes with its holder"
    );

    // a second signal ends it at once: no temporaries (a checkpoint or model
    // half written) or lock are left, and the run's checkpoints stay
    let lines = fs::read_to_string(&log).unwrap().lines().count();
    let o = signals_when(
        &moved,
        &["train", "--out", "long", "--resume", "--quiet"],
        |_| fs::read_to_string(&log).map_or(0, |l| l.lines().count()) > lines + 2,
        &["-TERM", "-TERM"],
    );
    assert_eq!(o.status.code(), Some(130), "{}", err(&o));
    let hidden: Vec<_> = walk(&moved)
        .into_iter()
        .filter(|p| {
            p.file_name()
                .and_then(|n| n.to_str())
                .is_some_and(|n| n.starts_with('.'))
        })
        .collect();
    assert!(hidden.is_empty(), "left behind: {hidden:?}");
    let kept: Vec<_> = fs::read_dir(moved.join("long/checkpoints"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    assert!(!kept.is_empty(), "the checkpoints were removed");
    for c in &kept {
        assert!(c.join("state.json").is_file(), "{} is torn", c.display());
    }
}

/// Borrowed arguments of owned ones.
#[cfg(feature = "network")]
fn run(a: &[String]) -> Vec<&str> {
    a.iter().map(String::as_str).collect()
}

/// Flips one byte near the end of `path`; returns the original bytes.
#[cfg(feature = "network")]
fn damage(path: &Path) -> Vec<u8> {
    let good = fs::read(path).unwrap();
    let mut bad = good.clone();
    let k = bad.len() - 10;
    bad[k] ^= 0x40;
    fs::write(path, &bad).unwrap();
    good
}

#[test]
#[cfg(feature = "network")]
fn arbitrary_runs_check_their_models_and_keep_reports() {
    let root = tempfile::tempdir().unwrap();
    let d = root.path();
    ok(
        d,
        &[
            "dataset",
            "pairs",
            "--mesh",
            "builtin:capsule",
            "--out",
            "data",
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
        ],
    );
    let train = |extra: &[&str]| {
        let mut a = vec![
            "train",
            "--dataset",
            "data/train",
            "--steps",
            "2",
            "--quiet",
        ];
        a.extend_from_slice(extra);
        a.into_iter().map(str::to_owned).collect::<Vec<_>>()
    };
    let args = train(&["--mode", "predictor", "--out", "pred"]);
    ok(d, &args.iter().map(String::as_str).collect::<Vec<_>>());
    // --config: the run description's `config` object, here with two of
    // the training loop's settings the presets leave at their defaults
    let spec: serde_json::Value =
        serde_json::from_str(&fs::read_to_string(d.join("pred/predictor.json")).unwrap()).unwrap();
    let mut config = spec["config"].clone();
    config["schedule"]["ema"] = serde_json::json!(0.5);
    config["schedule"]["log_every"] = serde_json::json!(1);
    fs::write(d.join("pred.json"), config.to_string()).unwrap();
    let args = train(&[
        "--mode",
        "predictor",
        "--config",
        "pred.json",
        "--out",
        "pred2",
    ]);
    ok(d, &args.iter().map(String::as_str).collect::<Vec<_>>());
    let written = fs::read_to_string(d.join("pred2/predictor.json")).unwrap();
    assert!(written.contains("\"ema\": 0.5"), "{written}");
    let rows = fs::read_to_string(d.join("pred2/train_log.csv")).unwrap();
    assert_eq!(rows.lines().count(), 3, "a row per step: {rows}");
    let e = refused(
        d,
        &[
            "train",
            "--resume",
            "--mode",
            "predictor",
            "--config",
            "pred.json",
            "--out",
            "pred2",
        ],
        "drop --config",
    );
    assert!(e.contains("predictor.json"), "{e}");
    let args = train(&["--mode", "arbitrary", "--predictor", "pred", "--out", "arb"]);
    ok(d, &args.iter().map(String::as_str).collect::<Vec<_>>());
    let sample = |out: &str| {
        [
            "sample",
            "--run",
            "arb",
            "--source",
            "data/eval.ply",
            "--n",
            "1",
            "--ply",
            "0",
            "--out",
            out,
        ]
        .map(str::to_owned)
    };
    ok(d, &run(&sample("t")));

    // damaged or unchecked models are refused by name, nothing written
    for (file, needle) in [
        (
            "arb/model.safetensors",
            "model.safetensors: the final model file is corrupted",
        ),
        (
            "arb/predictor.safetensors",
            "predictor.safetensors: the final model file is corrupted",
        ),
    ] {
        let good = damage(&d.join(file));
        refused(d, &run(&sample("t2")), needle);
        assert!(!d.join("t2").exists());
        fs::write(d.join(file), good).unwrap();
    }
    let good = damage(&d.join("pred/model.safetensors"));
    let args = train(&[
        "--mode",
        "arbitrary",
        "--predictor",
        "pred",
        "--out",
        "arb2",
    ]);
    refused(
        d,
        &run(&args),
        "model.safetensors: the final model file is corrupted",
    );
    assert!(!d.join("arb2").exists());
    fs::write(d.join("pred/model.safetensors"), good).unwrap();
    let record = d.join("arb/model.state.json");
    let kept = fs::read(&record).unwrap();
    fs::remove_file(&record).unwrap();
    refused(d, &run(&sample("t2")), "model.state.json: missing");
    fs::write(&record, kept).unwrap();

    // a source unlike the template is warned about: topology and area
    let o = ok(d, &run(&sample("t5")));
    assert!(!err(&o).contains("warning"), "{}", err(&o));
    fs::write(
        d.join("tet.off"),
        "OFF\n4 4 0\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 2 1\n3 0 1 3\n3 1 2 3\n3 0 3 2\n",
    )
    .unwrap();
    for (source, needle) in [
        (
            "builtin:torus",
            "warning: builtin:torus: Euler characteristic 0 differs from the template's 2",
        ),
        (
            "tet.off",
            "warning: tet.off: area 2.366 differs from the template's",
        ),
    ] {
        let mut a = sample("t6").to_vec();
        a[4] = source.into();
        let o = ok(d, &run(&a));
        assert!(err(&o).contains(needle), "{source}: {}", err(&o));
        fs::remove_dir_all(d.join("t6")).unwrap();
    }

    // more targets than any machine holds: refused before sampling
    let mut a = sample("t4").to_vec();
    a[6] = "100000000000000000".into();
    too_big(
        d,
        &run(&a),
        "100000000000000000 targets x 722 vertices x 3 coordinates: needs",
        "t4",
    );
    too_big(
        d,
        &[
            "eval-arbitrary",
            "--run",
            "arb",
            "--experiment",
            "data",
            "--sources",
            "1",
            "--per-source",
            "100000000000000000",
            "--out",
            "ev4",
        ],
        "1 sources x 100000000000000000 targets",
        "ev4",
    );

    // a predictor run is not sampled; the message says what to do instead
    refused(
        d,
        &[
            "sample",
            "--run",
            "pred",
            "--source",
            "data/eval.ply",
            "--out",
            "t3",
        ],
        "--mode arbitrary --predictor",
    );

    // --force never writes into a dataset, experiment or run folder
    let mesh = fs::read(d.join("data/reference/mesh.ply")).unwrap();
    for out in ["data/reference", "data", "arb", "pred"] {
        let mut a = sample(out).to_vec();
        a.push("--force".into());
        refused(d, &run(&a), "--force never writes into");
    }
    assert_eq!(fs::read(d.join("data/reference/mesh.ply")).unwrap(), mesh);

    // eval-arbitrary: no empty evaluation; an earlier report is kept without --force
    let eval = |extra: &[&str]| {
        let mut a = vec![
            "eval-arbitrary",
            "--run",
            "arb",
            "--experiment",
            "data",
            "--out",
            "ev",
        ];
        a.extend_from_slice(extra);
        a.into_iter().map(str::to_owned).collect::<Vec<_>>()
    };
    refused(
        d,
        &run(&eval(&["--sources", "0"])),
        "--sources must be at least 1",
    );
    refused(
        d,
        &run(&eval(&["--per-source", "0"])),
        "--per-source must be at least 1",
    );
    assert!(!d.join("ev").exists());
    ok(d, &run(&eval(&["--sources", "1", "--per-source", "1"])));
    let report = fs::read(d.join("ev/report.json")).unwrap();
    refused(
        d,
        &run(&eval(&[
            "--sources",
            "1",
            "--per-source",
            "1",
            "--seed",
            "3",
        ])),
        "--force",
    );
    assert_eq!(fs::read(d.join("ev/report.json")).unwrap(), report);
    let args = eval(&[
        "--sources",
        "1",
        "--per-source",
        "1",
        "--seed",
        "3",
        "--force",
    ]);
    ok(d, &run(&args));

    // an edited run description: a model or optimisation change is refused
    // by name and kept, a longer run accepted
    for (spec, mode, model_dir) in [
        ("pred/predictor.json", "predictor", "pred"),
        ("arb/arbitrary.json", "arbitrary", "arb"),
    ] {
        let original = fs::read_to_string(d.join(spec)).unwrap();
        assert!(original.contains("\"lr\": 0.001,"), "{original}");
        let edited = original.replace("\"lr\": 0.001,", "\"lr\": 1000000.0,");
        fs::write(d.join(spec), &edited).unwrap();
        let resume = [
            "train", "--resume", "--mode", mode, "--out", model_dir, "--quiet",
        ];
        let e = refused(
            d,
            &resume,
            &format!(
                "{spec} was edited after the checkpoint at step 2: config.schedule.lr 0.001 -> 1000000.0"
            ),
        );
        assert!(e.contains("undo the edit"), "{e}");
        assert_eq!(
            fs::read_to_string(d.join(spec)).unwrap(),
            edited,
            "the edit is kept"
        );
        fs::write(
            d.join(spec),
            original.replace("\"steps\": 2,", "\"steps\": 3,"),
        )
        .unwrap();
        let o = ok(d, &resume);
        assert!(
            String::from_utf8_lossy(&o.stdout).contains("steps 2..3 of 3"),
            "{}",
            String::from_utf8_lossy(&o.stdout)
        );
    }

    // a finished run without its checkpoints is not retrained over its model
    let model = fs::read(d.join("arb/model.safetensors")).unwrap();
    fs::remove_dir_all(d.join("arb/checkpoints")).unwrap();
    refused(
        d,
        &[
            "train",
            "--mode",
            "arbitrary",
            "--resume",
            "--out",
            "arb",
            "--quiet",
        ],
        "no valid checkpoint",
    );
    assert_eq!(fs::read(d.join("arb/model.safetensors")).unwrap(), model);
}

/// Writes `values` as a 1-D little-endian `f64` `.npy` file.
fn write_npy(path: &Path, values: &[f64]) {
    write_npy_shaped(path, &[values.len()], values);
}

/// Writes `values` as a little-endian `f64` `.npy` file of `shape`.
fn write_npy_shaped(path: &Path, shape: &[usize], values: &[f64]) {
    let dims: String = shape.iter().map(|n| format!("{n},")).collect();
    let dict = format!("{{'descr': '<f8', 'fortran_order': False, 'shape': ({dims}), }}");
    // magic (6) + version (2) + header length (2) + dict + newline: a multiple of 64
    let pad = (64 - (10 + dict.len() + 1) % 64) % 64;
    let header = format!("{dict}{}\n", " ".repeat(pad));
    let mut bytes = b"\x93NUMPY\x01\x00".to_vec();
    bytes.extend_from_slice(&u16::try_from(header.len()).unwrap().to_le_bytes());
    bytes.extend_from_slice(header.as_bytes());
    for v in values {
        bytes.extend_from_slice(&v.to_le_bytes());
    }
    fs::write(path, bytes).unwrap();
}

#[test]
fn render_says_when_scalars_are_not_finite() {
    let d = tempfile::tempdir().unwrap();
    let d = d.path();
    // builtin:icosphere:1 has 42 vertices
    write_npy(&d.join("nan.npy"), &[f64::NAN; 42]);
    let mut mixed: Vec<f64> = (0..42).map(f64::from).collect();
    mixed[3] = f64::NAN;
    mixed[7] = f64::INFINITY;
    write_npy(&d.join("mixed.npy"), &mixed);
    fn render<'a>(scalars: &'a str, out: &'a str) -> [&'a str; 8] {
        [
            "render",
            "builtin:icosphere:1",
            "--scalars",
            scalars,
            "--size",
            "64",
            "--out",
            out,
        ]
    }
    refused(
        d,
        &render("nan.npy", "nan.png"),
        "nan.npy: all 42 values are non-finite (NaN or inf)",
    );
    assert!(!d.join("nan.png").exists());
    let o = ok(d, &render("mixed.npy", "mixed.png"));
    assert!(
        err(&o).contains("warning: mixed.npy: 2 of 42 values are non-finite"),
        "{}",
        err(&o)
    );
    assert!(d.join("mixed.png").is_file());
    let o = ok(d, &render("mixed.npy", "again.png"));
    assert_eq!(err(&o).matches("warning").count(), 1, "{}", err(&o));
}

#[test]
#[cfg(feature = "network")]
fn training_divergence_names_the_step_and_the_rate() {
    let d = tempfile::tempdir().unwrap();
    let d = d.path();
    ok(
        d,
        &[
            "dataset",
            "gmm",
            "--mesh",
            "builtin:icosphere:2",
            "--out",
            "data",
            "--n",
            "4",
            "--reference",
            "2",
        ],
    );
    fs::write(
        d.join("lr.toml"),
        TINY.replace("log_every = 1\n", "log_every = 1\nlr = 1e6\n"),
    )
    .unwrap();
    let e = refused(
        d,
        &[
            "train",
            "--config",
            "lr.toml",
            "--dataset",
            "data/train",
            "--out",
            "run",
            "--quiet",
        ],
        "training diverged at step 1",
    );
    assert!(e.contains("lower train.lr"), "{e}");
    assert!(
        !d.join("run").exists(),
        "no run folder without a checkpoint"
    );
}

#[test]
fn errors_name_the_file_and_the_flag() {
    let d = tempfile::tempdir().unwrap();
    let d = d.path();
    // a degenerate (zero-area) face in --test-mesh names the flag and the file
    // (vertex 3 on the edge 1-2: face 2 has no area)
    let off = "OFF\n4 4 0\n0 0 1\n1 0 0\n0 1 0\n0.5 0.5 0\n3 0 2 1\n3 0 1 3\n3 1 2 3\n3 2 0 3\n";
    fs::write(d.join("flat.off"), off).unwrap();
    let e = refused(
        d,
        &[
            "dataset",
            "gmm",
            "--mesh",
            "builtin:icosphere:2",
            "--test-mesh",
            "flat.off",
            "--out",
            "g",
            "--n",
            "2",
            "--reference",
            "1",
        ],
        "--test-mesh flat.off: 1 degenerate face (zero area), e.g. face 2",
    );
    assert!(!e.contains("geodesics"), "{e}");
    assert!(!d.join("g").exists());
    // an empty samples file names the file
    ok(
        d,
        &[
            "dataset",
            "gmm",
            "--mesh",
            "builtin:icosphere:1",
            "--out",
            "data",
            "--n",
            "2",
            "--reference",
            "2",
        ],
    );
    write_npy_shaped(&d.join("none.npy"), &[0, 42, 1], &[]);
    refused(
        d,
        &[
            "eval",
            "--samples",
            "none.npy",
            "--reference",
            "data/reference",
        ],
        "none.npy: holds no samples (shape [0, 42, 1])",
    );
}

#[test]
#[cfg(feature = "network")]
fn wrong_folder_kinds_say_what_they_are() {
    let d = tempfile::tempdir().unwrap();
    let d = d.path();
    // a flow run, and a pairs experiment with a predictor and an arbitrary run
    ok(
        d,
        &[
            "dataset",
            "gmm",
            "--mesh",
            "builtin:icosphere:2",
            "--out",
            "gmm",
            "--n",
            "4",
            "--reference",
            "0",
        ],
    );
    fs::write(d.join("run.toml"), TINY).unwrap();
    ok(
        d,
        &[
            "train",
            "--config",
            "run.toml",
            "--dataset",
            "gmm/train",
            "--out",
            "flow",
            "--quiet",
        ],
    );
    ok(
        d,
        &[
            "dataset",
            "pairs",
            "--mesh",
            "builtin:capsule",
            "--out",
            "pairs",
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
        ],
    );
    let train = |extra: &[&str]| {
        let mut a = vec!["train", "--steps", "2", "--quiet"];
        a.extend_from_slice(extra);
        a.into_iter().map(str::to_owned).collect::<Vec<_>>()
    };
    let pred = train(&[
        "--mode",
        "predictor",
        "--dataset",
        "pairs/train",
        "--out",
        "pred",
    ]);
    ok(d, &run(&pred));
    let arb = train(&[
        "--mode",
        "arbitrary",
        "--dataset",
        "pairs/train",
        "--predictor",
        "pred",
        "--out",
        "arb",
    ]);
    ok(d, &run(&arb));

    // --predictor: a flow run, an arbitrary run, nothing
    for (given, what) in [
        ("flow", "is a flow run (mfm train)"),
        (
            "arb",
            "is an arbitrary-source run (mfm train --mode arbitrary)",
        ),
        ("nowhere", "does not exist"),
    ] {
        let args = train(&[
            "--mode",
            "arbitrary",
            "--dataset",
            "pairs/train",
            "--predictor",
            given,
            "--out",
            "x",
        ]);
        let e = refused(d, &run(&args), &format!("--predictor {given}: {what}"));
        assert!(e.contains("mfm train --mode predictor"), "{e}");
    }
    // --resume with the wrong --mode, or without one
    refused(
        d,
        &["train", "--resume", "--out", "pred", "--quiet"],
        "--out pred: is an eigenvector predictor run (mfm train --mode predictor), not a flow \
         run: continue it with --resume --mode predictor",
    );
    refused(
        d,
        &["train", "--resume", "--out", "arb", "--quiet"],
        "continue it with --resume --mode arbitrary",
    );
    refused(
        d,
        &[
            "train",
            "--resume",
            "--mode",
            "predictor",
            "--out",
            "flow",
            "--quiet",
        ],
        "--out flow: is a flow run (mfm train), not an eigenvector predictor run",
    );
    // --dataset an experiment folder: its sets are named
    for mode in ["predictor", "flow"] {
        let args = train(&[
            "--mode",
            mode,
            "--preset",
            "cpu",
            "--dataset",
            "pairs",
            "--out",
            "x",
        ]);
        let e = refused(
            d,
            &run(&args),
            "this is an experiment folder, not a dataset folder",
        );
        assert!(e.contains("pairs/train"), "{e}");
    }
    // eval-arbitrary: a missing experiment, a set for an experiment, runs of other kinds
    let eval = |run_dir: &str, experiment: &str| {
        [
            "eval-arbitrary",
            "--run",
            run_dir,
            "--experiment",
            experiment,
            "--out",
            "ev",
        ]
        .map(str::to_owned)
    };
    refused(
        d,
        &run(&eval("arb", "nowhere")),
        "nowhere: no such folder (expected the experiment folder of mfm dataset pairs)",
    );
    refused(
        d,
        &run(&eval("arb", "pairs/train")),
        "pairs/train: is a dataset folder (one set of an experiment), not an experiment folder",
    );
    refused(
        d,
        &run(&eval("pred", "pairs")),
        "pred: is an eigenvector predictor run (mfm train --mode predictor), not an \
         arbitrary-source run",
    );
    refused(
        d,
        &run(&eval("flow", "pairs")),
        "flow: is a flow run (mfm train), not an arbitrary-source run",
    );
    assert!(!d.join("ev").exists() && !d.join("x").exists());

    // another template of as many vertices (one vertex moved): its predictor
    // is refused for a flow, and a run is not evaluated on its experiment
    ok(d, &["convert", "builtin:capsule", "capsule.ply"]);
    let mut capsule = mfm_meshio::read_mesh(d.join("capsule.ply")).unwrap();
    let mut moved = capsule.positions().to_vec();
    moved[0][0] += 0.05;
    capsule = capsule.with_positions(moved).unwrap();
    mfm_meshio::write_ply(d.join("other.ply"), &capsule, &[]).unwrap();
    ok(
        d,
        &[
            "dataset",
            "pairs",
            "--mesh",
            "other.ply",
            "--out",
            "other",
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
        ],
    );
    let args = train(&[
        "--mode",
        "arbitrary",
        "--dataset",
        "other/train",
        "--predictor",
        "pred",
        "--out",
        "x",
    ]);
    let e = refused(d, &run(&args), "was trained on another template");
    assert!(
        e.contains("pairs/train") && e.contains("other/train"),
        "{e}"
    );
    let e = refused(
        d,
        &run(&eval("arb", "other")),
        "other is an experiment of another template",
    );
    assert!(e.contains("pairs/train"), "{e}");
    assert!(!d.join("ev").exists() && !d.join("x").exists());

    // a template with fewer vertices than the predictor's eigenvectors names the flags
    ok(
        d,
        &[
            "dataset",
            "pairs",
            "--mesh",
            "builtin:icosphere:1",
            "--out",
            "p42",
            "--shapes",
            "2",
            "--poses",
            "2",
            "--reference",
            "1",
            "--handles",
            "2",
            "--regions",
            "3",
        ],
    );
    let args = train(&[
        "--mode",
        "predictor",
        "--dataset",
        "p42/train",
        "--out",
        "x",
    ]);
    let e = refused(
        d,
        &run(&args),
        "the template has 42 vertices, fewer than the 64 eigenvectors the predictor learns",
    );
    assert!(e.contains("--coarse-faces") && e.contains("--mesh"), "{e}");

    // a TOML error on one line, without the parser's drawing
    fs::write(d.join("bad.toml"), "[model]\nwidth = \"x\"\n").unwrap();
    let e = refused(
        d,
        &[
            "train",
            "--config",
            "bad.toml",
            "--dataset",
            "gmm/train",
            "--out",
            "x",
        ],
        "bad.toml: invalid run configuration: line 2, column 9: invalid type: string \"x\", \
         expected usize (`width = \"x\"`)",
    );
    assert!(!e.contains("\\n") && e.lines().count() == 1, "{e}");

    // resuming on a dataset of other channels names both
    ok(
        d,
        &[
            "dataset",
            "deform",
            "--mesh",
            "builtin:icosphere:2",
            "--out",
            "shapes",
            "--n",
            "3",
            "--reference",
            "0",
            "--handles",
            "2",
            "--coarse-faces",
            "320",
        ],
    );
    let e = refused(
        d,
        &[
            "train",
            "--resume",
            "--out",
            "flow",
            "--steps",
            "6",
            "--dataset",
            "shapes/train",
            "--quiet",
        ],
        "the dataset shapes/train has 3-channel signals, but the run flow was trained on \
         1-channel ones",
    );
    assert!(e.contains("gmm/train"), "{e}");
    assert!(!d.join("x").exists());
}

/// Runs and expects a refusal naming the memory it needs, with no panic or
/// backtrace and nothing written at `out`.
#[track_caller]
fn too_big(dir: &Path, args: &[&str], needle: &str, out: &str) {
    let e = refused(dir, args, needle);
    assert!(e.contains("of memory, but this machine has"), "{e}");
    assert!(
        !e.contains("panicked") && !e.contains("backtrace") && e.lines().count() <= 4,
        "{e}"
    );
    assert!(!dir.join(out).exists(), "{out} was left behind");
}

#[test]
fn sizes_beyond_the_machine_are_refused_up_front() {
    let d = tempfile::tempdir().unwrap();
    let d = d.path();
    // beyond any machine's memory and address space (isize::MAX bytes)
    let huge = "100000000000000000";
    too_big(
        d,
        &[
            "dataset",
            "gmm",
            "--mesh",
            "builtin:icosphere:2",
            "--out",
            "g",
            "--n",
            huge,
            "--reference",
            "1",
        ],
        &format!("the train set's {huge} signals x 162 vertices x 1 channel: needs"),
        "g",
    );
    let pairs = |shapes: &str, poses: &str| {
        [
            "dataset",
            "pairs",
            "--mesh",
            "builtin:capsule",
            "--out",
            "p",
            "--shapes",
            shapes,
            "--poses",
            poses,
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
        ]
        .map(str::to_owned)
    };
    let a = pairs(huge, "2");
    too_big(
        d,
        &run_args(&a),
        "the train set's 200000000000000000 signals",
        "p",
    );
    let a = pairs("2", "10000000000000000");
    too_big(
        d,
        &run_args(&a),
        "the train set's 20000000000000000 signals",
        "p",
    );
    too_big(
        d,
        &[
            "dataset",
            "deform",
            "--mesh",
            "builtin:icosphere:2",
            "--out",
            "f",
            "--n",
            huge,
            "--handles",
            "2",
            "--coarse-faces",
            "320",
        ],
        "the train set's",
        "f",
    );
    too_big(
        d,
        &[
            "spectrum",
            "builtin:icosphere:2",
            "--samples",
            "1000000000000000000",
            "--out",
            "sp.json",
        ],
        "--samples 1000000000000000000 x 3 kept coefficients (--coefficients)",
        "sp.json",
    );
}

/// Borrowed arguments of owned ones (any feature set).
fn run_args(a: &[String]) -> Vec<&str> {
    a.iter().map(String::as_str).collect()
}

#[test]
#[cfg(feature = "network")]
fn networks_beyond_the_machine_are_refused_up_front() {
    let d = tempfile::tempdir().unwrap();
    let d = d.path();
    ok(
        d,
        &[
            "dataset",
            "gmm",
            "--mesh",
            "builtin:icosphere:1",
            "--out",
            "data",
            "--n",
            "2",
            "--reference",
            "0",
        ],
    );
    fs::write(
        d.join("wide.toml"),
        TINY.replace("width = 8", "width = 100000"),
    )
    .unwrap();
    let e = refused(
        d,
        &[
            "train",
            "--config",
            "wide.toml",
            "--dataset",
            "data/train",
            "--out",
            "run",
            "--quiet",
        ],
        "a network of width 100000 with 1 blocks",
    );
    assert!(
        e.contains("lower model.width or model.blocks") && !e.contains("panicked"),
        "{e}"
    );
    assert!(!d.join("run").exists());
}

#[test]
fn one_writer_per_folder_and_stale_locks_are_taken_over() {
    let d = tempfile::tempdir().unwrap();
    let d = d.path();
    let gmm = |out: &str| {
        [
            "dataset",
            "gmm",
            "--mesh",
            "builtin:icosphere:1",
            "--out",
            out,
            "--n",
            "2",
            "--reference",
            "0",
        ]
        .map(str::to_owned)
    };
    // a writer of `busy` in this process: every dataset command is refused naming it
    let held = mfm_files::FolderLock::acquire(&d.join("busy"), "the test's writer").unwrap();
    let holder = format!(
        "busy is in use by PID {} (the test's writer)",
        std::process::id()
    );
    let pairs = [
        "dataset",
        "pairs",
        "--mesh",
        "builtin:capsule",
        "--out",
        "busy",
        "--shapes",
        "1",
        "--poses",
        "2",
        "--reference",
        "0",
    ];
    let deform = [
        "dataset",
        "deform",
        "--mesh",
        "builtin:icosphere:2",
        "--out",
        "busy",
        "--n",
        "1",
        "--reference",
        "0",
        "--handles",
        "2",
    ];
    for args in [run_args(&gmm("busy")), pairs.to_vec(), deform.to_vec()] {
        refused(d, &args, &holder);
        assert!(
            !d.join("busy").exists(),
            "{args:?} wrote into a locked folder"
        );
    }
    if cfg!(feature = "network") {
        ok(d, &run_args(&gmm("data")));
        fs::write(
            d.join("run.toml"),
            "[model]\npreset = \"small\"\nwidth = 8\nblocks = 1\n\
vector_layers = 1\n[train]\nsteps = 2\nbatch = 2\n[sample]\nsteps = 2\n",
        )
        .unwrap();
        ok(
            d,
            &[
                "train",
                "--config",
                "run.toml",
                "--dataset",
                "data/train",
                "--out",
                "run",
                "--quiet",
            ],
        );
        let sample = [
            "sample",
            "--run",
            "run",
            "--mesh",
            "builtin:icosphere:1",
            "--n",
            "1",
            "--out",
            "busy",
        ];
        refused(d, &sample, &holder);
        assert!(!d.join("busy").exists());
        drop(held);
        ok(d, &sample);
    } else {
        drop(held);
    }
    // a lock file left by a process that is gone is stale: taken over, and
    // removed when the new writer ends
    let lock = d.join(".stale.mfm-lock");
    fs::write(&lock, "PID 999999999 (mfm dataset gmm --out stale)\n").unwrap();
    ok(d, &run_args(&gmm("stale")));
    assert!(d.join("stale/train/manifest.json").is_file());
    assert!(!lock.exists(), "the lock goes with its holder");
}

#[test]
#[cfg(feature = "network")]
fn a_sampling_mesh_of_another_topology_is_warned_about() {
    let d = tempfile::tempdir().unwrap();
    let d = d.path();
    ok(
        d,
        &[
            "dataset",
            "gmm",
            "--mesh",
            "builtin:icosphere:2",
            "--out",
            "data",
            "--n",
            "2",
            "--reference",
            "0",
        ],
    );
    fs::write(d.join("run.toml"), TINY.replace("steps = 4", "steps = 1")).unwrap();
    ok(
        d,
        &[
            "train",
            "--config",
            "run.toml",
            "--dataset",
            "data/train",
            "--out",
            "run",
            "--quiet",
        ],
    );
    let sample = |mesh: &str, out: &str| {
        [
            "sample", "--run", "run", "--mesh", mesh, "--n", "1", "--ply", "0", "--out", out,
        ]
        .map(str::to_owned)
    };
    let o = ok(d, &run(&sample("builtin:icosphere:3", "a")));
    assert!(!err(&o).contains("warning"), "{}", err(&o));
    let o = ok(d, &run(&sample("builtin:torus", "b")));
    assert!(
        err(&o).contains(
            "warning: builtin:torus: Euler characteristic 0 differs from the training surface's 2"
        ),
        "{}",
        err(&o)
    );
}

#[test]
fn interrupted_commands_remove_what_they_wrote_and_exit_130() {
    let d = tempfile::tempdir().unwrap();
    let d = d.path();
    fs::write(d.join("mine.txt"), "the user's").unwrap();
    // SIGTERM while noise streams its .npy: the temporary goes
    let o = interrupt_when(
        d,
        &[
            "noise",
            "builtin:icosphere:5",
            "--samples",
            "3000",
            "--out",
            "big.npy",
        ],
        || !tmp_files(d).is_empty(),
        "-TERM",
    );
    assert_eq!(o.status.code(), Some(130), "{}", err(&o));
    assert!(err(&o).contains("interrupted; removed what this command had written"));
    assert!(tmp_files(d).is_empty(), "{:?}", tmp_files(d));
    assert!(!d.join("big.npy").exists() && !d.join("big.json").exists());
    // SIGHUP while a pairs experiment is half written: the folder goes whole
    let o = interrupt_when(
        d,
        &[
            "dataset",
            "pairs",
            "--mesh",
            "builtin:capsule",
            "--out",
            "pairs",
            "--shapes",
            "400",
            "--poses",
            "4",
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
        ],
        || d.join("pairs/pair_space.json").exists(),
        "-HUP",
    );
    assert_eq!(o.status.code(), Some(130), "{}", err(&o));
    assert!(
        !d.join("pairs").exists(),
        "a half-written experiment was left"
    );
    assert!(!d.join(".pairs.mfm-lock").exists(), "the lock was left");
    // SIGINT (Ctrl-C) while a GMM dataset is generated
    let o = interrupt_when(
        d,
        &[
            "dataset",
            "gmm",
            "--mesh",
            "builtin:icosphere:4",
            "--out",
            "gmm",
            "--n",
            "20000",
            "--reference",
            "0",
        ],
        || d.join("gmm").exists(),
        "-INT",
    );
    assert_eq!(o.status.code(), Some(130), "{}", err(&o));
    assert!(!d.join("gmm").exists());
    let left: Vec<_> = fs::read_dir(d)
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(left, vec![std::ffi::OsString::from("mine.txt")], "{left:?}");

    // SIGKILL cannot be handled: the next writer of the same names removes
    // what the killed one left (its PID is gone), and a rerun is not refused
    let noise = [
        "noise",
        "builtin:icosphere:5",
        "--samples",
        "3000",
        "--out",
        "big.npy",
    ];
    let o = interrupt_when(d, &noise, || !tmp_files(d).is_empty(), "-KILL");
    assert_eq!(o.status.code(), None);
    assert_eq!(tmp_files(d).len(), 1, "{:?}", tmp_files(d));
    ok(d, &["noise", "builtin:icosphere:1", "--out", "big.npy"]);
    assert!(tmp_files(d).is_empty(), "{:?}", tmp_files(d));
    let gmm = [
        "dataset",
        "gmm",
        "--mesh",
        "builtin:icosphere:4",
        "--out",
        "gmm",
        "--n",
        "20000",
        "--reference",
        "0",
    ];
    let in_progress = || {
        fs::read_dir(d.join("gmm")).is_ok_and(|mut l| {
            l.any(|e| {
                e.unwrap()
                    .file_name()
                    .to_string_lossy()
                    .starts_with(".train.tmp-")
            })
        })
    };
    let o = interrupt_when(d, &gmm, in_progress, "-KILL");
    assert_eq!(o.status.code(), None);
    let mut rerun = gmm;
    rerun[7] = "2";
    ok(d, &rerun);
    let inside: Vec<_> = fs::read_dir(d.join("gmm"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert!(!inside.iter().any(|n| n.starts_with('.')), "{inside:?}");
}
