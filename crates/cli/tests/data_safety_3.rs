//! Data safety, third round (issue 39): every writer keeps out of the
//! folders other commands own, implicit companions never replace a file,
//! sizes and values that make no sense are refused up front, and what a
//! killed command left is cleared by the next one. Each check drives the
//! real binary.
#![allow(clippy::unwrap_used)]

use std::fs;
use std::path::Path;

mod common;
use common::{interrupt_when, ok, refused, signals_when};

/// A small GMM experiment `DIR/data` (train and reference sets) and a
/// folder `DIR/run` that holds what marks a training run.
fn owned_folders(d: &Path) {
    ok(
        d,
        &[
            "dataset",
            "gmm",
            "--mesh",
            "builtin:blob:2",
            "--n",
            "3",
            "--reference",
            "2",
            "--sigma",
            "0.1",
            "--min-separation",
            "2",
            "--out",
            "data",
        ],
    );
    fs::create_dir_all(d.join("run/checkpoints/step-000000002")).unwrap();
    fs::write(d.join("run/flow.json"), "{}").unwrap();
    fs::write(d.join("run/model.json"), "{\"the\": \"run's\"}").unwrap();
}

#[test]
fn writers_never_write_into_datasets_experiments_or_runs() {
    let d = tempfile::tempdir().unwrap();
    let d = d.path();
    owned_folders(d);
    let kept = |rel: &str| fs::read(d.join(rel)).unwrap();
    let before: Vec<(&str, Vec<u8>)> = [
        "data/train/signals.npy",
        "data/train/mesh.ply",
        "data/reference/mesh.ply",
        "run/flow.json",
        "run/model.json",
    ]
    .into_iter()
    .map(|f| (f, kept(f)))
    .collect();
    let ico = "builtin:icosphere:1";
    for (args, folder) in [
        (
            vec!["noise", ico, "--out", "data/train/signals.npy"],
            "a dataset folder",
        ),
        (
            vec!["convert", ico, "data/reference/mesh.ply"],
            "a dataset folder",
        ),
        (
            vec![
                "remesh",
                ico,
                "--subdivide",
                "1",
                "--out",
                "data/train/mesh.ply",
            ],
            "a dataset folder",
        ),
        (
            vec!["remesh", ico, "--subdivide", "1", "--out", "data/fine.ply"],
            "an experiment folder",
        ),
        (
            vec![
                "spectrum",
                ico,
                "--samples",
                "4",
                "--k",
                "4",
                "--out",
                "run/flow.json",
            ],
            "a training run folder",
        ),
        // the implicit summary would have replaced the run's model.json
        (
            vec!["noise", ico, "--out", "run/model.npy"],
            "a training run folder",
        ),
        (
            vec!["operators", ico, "--out", "data/train"],
            "a dataset folder",
        ),
        (
            vec!["eigs", ico, "--k", "3", "--out", "run/checkpoints/eigs"],
            "checkpoints folder",
        ),
        (spectrum("4", "data/train", &[]), "a dataset folder"),
    ] {
        let e = refused(d, &args, folder);
        assert!(e.contains("never writes into"), "{args:?}: {e}");
    }
    for (f, bytes) in &before {
        assert_eq!(&kept(f), bytes, "{f} was changed");
    }
    assert!(!d.join("run/model.npy").exists() && !d.join("data/fine.ply").exists());
    assert!(!d.join("run/checkpoints/eigs").exists());
    assert!(!d.join("data/train/L.mtx").exists());
    // a subfolder of a run (samples kept beside it) is the user's
    ok(d, &["noise", ico, "--out", "run/samples/noise.npy"]);
}

#[test]
fn implicit_companions_never_replace_a_file() {
    let d = tempfile::tempdir().unwrap();
    let d = d.path();
    let ico = "builtin:icosphere:1";
    fs::write(d.join("n.json"), "mine").unwrap();
    let e = refused(d, &["noise", ico, "--out", "n.npy"], "n.json exists");
    assert!(e.contains("without being asked"), "{e}");
    assert_eq!(fs::read_to_string(d.join("n.json")).unwrap(), "mine");
    assert!(!d.join("n.npy").exists());
    fs::create_dir(d.join("plots")).unwrap();
    fs::write(d.join("plots/variance.png"), "mine").unwrap();
    refused(d, &spectrum("4", "plots", &[]), "variance.png exists");
    assert_eq!(
        fs::read_to_string(d.join("plots/variance.png")).unwrap(),
        "mine"
    );
    assert!(!d.join("s.json").exists());
    // the same command again over its own earlier result replaces both
    ok(d, &["noise", ico, "--out", "m.npy"]);
    ok(d, &["noise", ico, "--out", "m.npy", "--seed", "3"]);
    // a summary whose output is gone is an earlier result of its own
    fs::remove_file(d.join("m.npy")).unwrap();
    refused(d, &["noise", ico, "--out", "m.npy"], "m.json exists");
}

#[test]
#[cfg(feature = "network")]
fn a_run_is_never_written_inside_the_dataset_it_reads() {
    let d = tempfile::tempdir().unwrap();
    let d = d.path();
    owned_folders(d);
    let e = refused(
        d,
        &[
            "train",
            "--preset",
            "cpu",
            "--dataset",
            "data/train",
            "--out",
            "data/train/run",
        ],
        "inside the input folder",
    );
    assert!(e.contains("data/train"), "{e}");
    assert!(!d.join("data/train/run").exists());
    refused(
        d,
        &[
            "train",
            "--preset",
            "cpu",
            "--dataset",
            "data/train",
            "--out",
            "run/checkpoints/run2",
        ],
        "checkpoints folder",
    );
    assert!(!d.join("run/checkpoints/run2").exists());
}

/// `owned_folders` and a real run `DIR/tiny` trained on `DIR/data/train`,
/// sampled into `DIR/out`.
#[cfg(feature = "network")]
fn tiny_run(d: &Path) {
    owned_folders(d);
    fs::write(d.join("tiny.toml"), common::TINY).unwrap();
    ok(
        d,
        &[
            "train",
            "--config",
            "tiny.toml",
            "--dataset",
            "data/train",
            "--out",
            "tiny",
            "--quiet",
        ],
    );
    ok(
        d,
        &[
            "sample",
            "--run",
            "tiny",
            "--mesh",
            "data/train/mesh.ply",
            "--n",
            "2",
            "--out",
            "out",
        ],
    );
}

#[test]
#[cfg(feature = "network")]
fn sampling_keeps_its_starting_noise_and_reads_its_run_configuration() {
    let d = tempfile::tempdir().unwrap();
    let d = d.path();
    tiny_run(d);
    let samples = fs::read(d.join("out/samples.npy")).unwrap();
    let sample = |extra: &[&str]| -> Vec<String> {
        [
            "sample",
            "--run",
            "tiny",
            "--mesh",
            "data/train/mesh.ply",
            "--out",
            "out2",
        ]
        .iter()
        .chain(extra)
        .map(|s| s.to_string())
        .collect()
    };
    // --x0 is an input: --force never replaces it with the samples
    let e = refused(
        d,
        &[
            "sample",
            "--run",
            "tiny",
            "--mesh",
            "data/train/mesh.ply",
            "--x0",
            "out/samples.npy",
            "--out",
            "out",
            "--force",
        ],
        "is also an input",
    );
    assert!(e.contains("samples.npy"), "{e}");
    assert_eq!(fs::read(d.join("out/samples.npy")).unwrap(), samples);
    // a damaged configuration is refused by name, not replaced by defaults
    let config = fs::read_to_string(d.join("tiny/config.toml")).unwrap();
    fs::write(d.join("tiny/config.toml"), "[sample\nsteps = ").unwrap();
    let args = sample(&[]);
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    refused(d, &args, "config.toml");
    assert!(!d.join("out2").exists());
    // a missing one is said, with the defaults assumed
    fs::remove_file(d.join("tiny/config.toml")).unwrap();
    let o = ok(d, &args);
    let e = common::err(&o);
    assert!(
        e.contains("has no config.toml") && e.contains("20 midpoint steps"),
        "{e}"
    );
    fs::write(d.join("tiny/config.toml"), config).unwrap();
}

#[test]
fn sizes_and_values_that_make_no_sense_are_refused_up_front() {
    let d = tempfile::tempdir().unwrap();
    let d = d.path();
    let check = |args: &[&str], needle: &str| {
        let e = refused(d, args, needle);
        assert!(!e.contains("panicked") && !e.contains("NaN"), "{e}");
    };
    let gmm = [
        "dataset",
        "gmm",
        "--mesh",
        "builtin:icosphere:1",
        "--n",
        "2",
    ];
    let deform = [
        "dataset",
        "deform",
        "--mesh",
        "builtin:capsule",
        "--out",
        "dd",
    ];
    // a bump count beyond the mesh: no overflow, no 32 GB allocation
    for bumps in ["18446744073709551615", "4000000000"] {
        check(
            &[&gmm[..], &["--bumps", bumps, "--out", "g"]].concat(),
            "at most the mesh's 42 vertices",
        );
    }
    // a bump width that underflows
    check(
        &[&gmm[..], &["--sigma", "1e-300", "--out", "g"]].concat(),
        "gmm.sigma",
    );
    assert!(!d.join("g").exists() && !d.join(".g.mfm-lock").exists());
    // a handle count that wraps around
    check(
        &[&deform[..], &["--handles", "18446744073709551615"]].concat(),
        "cannot place 18446744073709551615 handles",
    );
    // a translation that tears the shape apart
    check(
        &[&deform[..], &["--max-shift", "1e20"]].concat(),
        "max_shift",
    );
    assert!(!d.join("dd").exists());
    // screening so strong the noise vanishes
    check(
        &[
            "noise",
            "builtin:icosphere:1",
            "--kind",
            "matern",
            "--tau",
            "1e300",
            "--out",
            "n.npy",
        ],
        "[0, 1e10]",
    );
    // built-in meshes beyond their cap are refused before they are built
    check(&["info", "builtin:grid:100000"], "at most 1024");
    // a plotted frequency that is not measured
    check(
        &spectrum("8", "p", &["--coefficients", "2,999"]),
        "--coefficients 999",
    );
    assert!(!d.join("s.json").exists());
    // a folder's path that holds a file
    fs::write(d.join("taken"), "mine").unwrap();
    check(&[&gmm[..], &["--out", "taken"]].concat(), "is not a folder");
    assert_eq!(fs::read_to_string(d.join("taken")).unwrap(), "mine");
}

/// `mfm spectrum` of `builtin:icosphere:1` with 4 samples and `k`
/// frequencies into `s.json`, plots into `plots`, then `extra`.
fn spectrum<'a>(k: &'a str, plots: &'a str, extra: &[&'a str]) -> Vec<&'a str> {
    let base = [
        "spectrum",
        "builtin:icosphere:1",
        "--samples",
        "4",
        "--k",
        k,
        "--out",
        "s.json",
        "--plots",
        plots,
    ];
    [&base[..], extra].concat()
}

#[test]
fn obj_index_errors_count_as_the_file_does() {
    let d = tempfile::tempdir().unwrap();
    let d = d.path();
    fs::write(
        d.join("bad.obj"),
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\nf 1 2 5\n",
    )
    .unwrap();
    let e = refused(d, &["info", "bad.obj"], "vertex index 5");
    assert!(e.contains("line 6") && e.contains("1 to 4"), "{e}");
}

/// (A network build: its start-up in libtorch is the window this checks.)
#[test]
#[cfg(all(target_os = "linux", feature = "network"))]
fn a_signal_while_starting_is_an_interrupt_too() {
    let d = tempfile::tempdir().unwrap();
    let d = d.path();
    for signal in ["-TERM", "-HUP", "-INT"] {
        // as soon as the process catches the three signals: past the
        // dynamic loader (no code of any kind runs before it), in the
        // libraries' start-up or later (then the command's own handler
        // answers the same)
        let caught = |pid: u32| {
            let status = fs::read_to_string(format!("/proc/{pid}/status")).unwrap_or_default();
            status
                .lines()
                .find_map(|l| l.strip_prefix("SigCgt:"))
                .and_then(|m| u64::from_str_radix(m.trim(), 16).ok())
                .is_some_and(|m| m & 0x4003 == 0x4003)
        };
        let o = signals_when(
            d,
            &[
                "dataset",
                "gmm",
                "--mesh",
                "builtin:icosphere:1",
                "--out",
                "g",
            ],
            caught,
            &[signal],
        );
        assert_eq!(o.status.code(), Some(130), "{signal}: {}", common::err(&o));
        // the handler was there before the libraries finished starting
        // (a network build spends ~0.15 s there; polling takes 1 ms)
        assert!(
            common::err(&o).contains("while starting"),
            "{signal}: {}",
            common::err(&o)
        );
        let left: Vec<_> = fs::read_dir(d).unwrap().collect();
        assert!(left.is_empty(), "{signal}: {left:?}");
    }
}

#[test]
#[cfg(unix)]
fn devices_and_fifos_are_refused_as_inputs() {
    let d = tempfile::tempdir().unwrap();
    let d = d.path();
    std::os::unix::fs::symlink("/dev/zero", d.join("zero.obj")).unwrap();
    std::os::unix::fs::symlink("/dev/urandom", d.join("random.npy")).unwrap();
    let fifo = d.join("fifo.npy");
    assert!(
        std::process::Command::new("mkfifo")
            .arg(&fifo)
            .status()
            .unwrap()
            .success()
    );
    let started = std::time::Instant::now();
    refused(d, &["info", "zero.obj"], "a device, not a regular file");
    refused(
        d,
        &["noise", "zero.obj", "--out", "n.npy"],
        "not a regular file",
    );
    ok(d, &["convert", "builtin:icosphere:1", "ico.ply"]);
    for samples in ["random.npy", "fifo.npy"] {
        refused(
            d,
            &[
                "eval",
                "--samples",
                samples,
                "--space",
                "space.json",
                "--mesh",
                "ico.ply",
            ],
            "not a regular file",
        );
    }
    // refused at once: nothing was read until memory ran out, nothing blocked
    assert!(started.elapsed().as_secs() < 60);
}

#[test]
fn what_a_killed_dataset_command_left_is_cleared_by_the_next_one() {
    let d = tempfile::tempdir().unwrap();
    let d = d.path();
    let deform = [
        "dataset",
        "deform",
        "--mesh",
        "builtin:capsule",
        "--n",
        "40",
        "--reference",
        "4",
        "--coarse-faces",
        "600",
        "--out",
        "dd",
    ];
    // killed after its meshes and space, before its sets
    let o = interrupt_when(d, &deform, || d.join("dd/space.json").exists(), "-KILL");
    assert_eq!(o.status.code(), None, "killed before it finished");
    assert!(d.join("dd").exists() && d.join(".dd.mfm-lock").exists());
    let o = ok(d, &deform);
    assert!(
        common::err(&o).contains("what a killed command left"),
        "{}",
        common::err(&o)
    );
    assert!(d.join("dd/train/signals.npy").is_file());
    // a folder with anything else in it is never cleared
    fs::create_dir(d.join("mine")).unwrap();
    fs::write(d.join("mine/notes.txt"), "mine").unwrap();
    fs::write(d.join("mine/space.json"), "{}").unwrap();
    fs::write(
        d.join(".mine.mfm-lock"),
        "PID 999999999 (mfm dataset deform)\n",
    )
    .unwrap();
    let mut again = deform.to_vec();
    *again.last_mut().unwrap() = "mine";
    refused(d, &again, "not empty");
    assert_eq!(
        fs::read_to_string(d.join("mine/notes.txt")).unwrap(),
        "mine"
    );
}

#[test]
#[cfg(feature = "network")]
fn a_killed_sample_leaves_nothing_that_stops_the_rerun() {
    let d = tempfile::tempdir().unwrap();
    let d = d.path();
    tiny_run(d);
    let args = [
        "sample",
        "--run",
        "tiny",
        "--mesh",
        "builtin:icosphere:5",
        "--n",
        "64",
        "--out",
        "s",
    ];
    let temporary = || {
        fs::read_dir(d.join("s")).is_ok_and(|e| {
            e.flatten()
                .any(|e| e.file_name().to_string_lossy().ends_with(".tmp"))
        })
    };
    let o = interrupt_when(d, &args, temporary, "-KILL");
    assert_eq!(o.status.code(), None, "killed before it finished");
    assert!(temporary(), "the kill left its temporary");
    ok(d, &args);
    assert!(d.join("s/samples.npy").is_file());
    assert!(!temporary());
}

#[test]
fn info_and_the_commands_that_compute_agree_on_a_mesh_out_of_range() {
    let d = tempfile::tempdir().unwrap();
    let d = d.path();
    for (name, scale) in [("tiny.off", "1e-320"), ("huge.off", "1e300")] {
        fs::write(
            d.join(name),
            format!("OFF\n3 1 0\n0 0 0\n{scale} 0 0\n0 {scale} 0\n3 0 1 2\n"),
        )
        .unwrap();
        let o = ok(d, &["info", name]);
        let report = common::out(&o);
        assert!(
            report.contains("too small or too large"),
            "{name}: {report}"
        );
        let e = refused(
            d,
            &["noise", name, "--out", "n.npy"],
            "too small or too large",
        );
        assert!(!e.contains("NaN"), "{e}");
        refused(
            d,
            &["remesh", name, "--subdivide", "1", "--out", "r.ply"],
            "too small or too large",
        );
    }
}

#[test]
fn a_file_is_named_once_in_an_error() {
    let d = tempfile::tempdir().unwrap();
    let d = d.path();
    let once = |e: &str, name: &str| {
        assert_eq!(e.matches(name).count(), 1, "{name} in: {e}");
    };
    let e = refused(
        d,
        &["dataset", "import", "gone.pt", "--out", "x"],
        "gone.pt",
    );
    once(&e, "gone.pt");
    fs::write(d.join("garbage.pt"), "not a zip").unwrap();
    let e = refused(
        d,
        &["dataset", "import", "garbage.pt", "--out", "x"],
        "garbage.pt",
    );
    once(&e, "garbage.pt");
    #[cfg(feature = "network")]
    {
        let e = refused(
            d,
            &[
                "import",
                "--checkpoint",
                "gone.ckpt",
                "--config",
                "gone.yaml",
                "--out",
                "r",
            ],
            "gone.yaml",
        );
        once(&e, "gone.yaml");
    }
}

#[test]
#[cfg(unix)]
fn mesh_files_may_have_names_that_are_not_utf8() {
    use std::os::unix::ffi::OsStringExt;
    let d = tempfile::tempdir().unwrap();
    let d = d.path();
    let name = std::ffi::OsString::from_vec(b"caf\xe9.off".to_vec());
    fs::write(
        d.join(&name),
        "OFF\n4 4 0\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 2 1\n3 0 1 3\n3 0 3 2\n3 1 2 3\n",
    )
    .unwrap();
    let run = |args: &[&std::ffi::OsStr]| {
        std::process::Command::new(env!("CARGO_BIN_EXE_mfm"))
            .current_dir(d)
            .args(args)
            .output()
            .unwrap()
    };
    let o = run(&["info".as_ref(), name.as_os_str()]);
    assert!(o.status.success(), "{}", common::err(&o));
    assert!(
        common::out(&o).contains("vertices        4"),
        "{}",
        common::out(&o)
    );
    let o = run(&[
        "noise".as_ref(),
        name.as_os_str(),
        "--out".as_ref(),
        "n.npy".as_ref(),
    ]);
    assert!(o.status.success(), "{}", common::err(&o));
    assert!(d.join("n.npy").is_file());
    // named in messages with a replacement character
    let missing = std::ffi::OsString::from_vec(b"gon\xe9.off".to_vec());
    let o = run(&["info".as_ref(), missing.as_os_str()]);
    assert!(!o.status.success());
    assert!(
        common::err(&o).contains("gon\u{fffd}.off"),
        "{}",
        common::err(&o)
    );
}

/// `sample --noise-from`: the noise of the training mesh carried to a
/// refinement; onto the training mesh itself it is the noise `sample`
/// draws there, so the samples are the plain ones.
#[test]
#[cfg(feature = "network")]
fn sampling_a_refinement_from_the_noise_of_the_training_mesh() {
    let d = tempfile::tempdir().unwrap();
    let d = d.path();
    tiny_run(d);
    let read = |p: &str| {
        let bytes = fs::read(d.join(p)).unwrap();
        let npy = npyz::NpyFile::new(&bytes[..]).unwrap();
        let shape = npy.shape().to_vec();
        (shape, npy.into_vec::<f32>().unwrap())
    };
    let (plain_shape, plain) = read("out/samples.npy");
    let sample = |mesh: &str, out: &str| {
        ok(
            d,
            &[
                "sample",
                "--run",
                "tiny",
                "--mesh",
                mesh,
                "--noise-from",
                "data/train/mesh.ply",
                "--n",
                "2",
                "--out",
                out,
            ],
        );
    };
    sample("data/train/mesh.ply", "same");
    let (shape, same) = read("same/samples.npy");
    assert_eq!(shape, plain_shape);
    let worst = same
        .iter()
        .zip(&plain)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0f32, f32::max);
    assert!(worst < 1e-4, "{worst}");
    ok(
        d,
        &[
            "remesh",
            "data/train/mesh.ply",
            "--subdivide",
            "1",
            "--out",
            "fine.ply",
        ],
    );
    sample("fine.ply", "fine");
    let (shape, fine) = read("fine/samples.npy");
    assert_eq!(shape[0], 2);
    assert!(shape[1] > plain_shape[1]);
    assert!(fine.iter().all(|x| x.is_finite()));
    // --noise-from and --x0 both start the ODE: one at a time
    refused(
        d,
        &[
            "sample",
            "--run",
            "tiny",
            "--mesh",
            "fine.ply",
            "--noise-from",
            "data/train/mesh.ply",
            "--x0",
            "out/samples.npy",
            "--out",
            "x",
        ],
        "cannot be used with",
    );
}
