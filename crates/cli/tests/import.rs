//! `mfm dataset import` and `mfm eval` on imported shapes, driving the real
//! binary: a folder of OBJ frames in, an experiment folder out; the
//! generator-free measures on known answers; refusals and interrupts that
//! leave nothing behind; and (with the network feature) import, train,
//! sample on the reference mesh and evaluate, samples in the user's units.
#![allow(clippy::unwrap_used)]

use std::path::Path;
use std::process::Command;

use mfm_geometry::TriMesh;
use mfm_geometry::procedural;

mod common;
use common::{err, ok, refused};

/// `mfm ARGS` in `dir`, expected to succeed; its standard output.
#[track_caller]
fn stdout_of(dir: &Path, args: &[&str]) -> String {
    common::out(&ok(dir, args))
}

/// Frame `k` of a travelling, bending capsule: far from the unit box, in
/// other units (a scale of 40), so that returning to them is visible.
fn frame(rest: &TriMesh, k: usize) -> TriMesh {
    let bend = 0.08 * k as f64;
    let moved: Vec<[f64; 3]> = rest
        .positions()
        .iter()
        .map(|p| {
            let a = bend * p[1];
            [
                40.0 * (p[0] * a.cos() - p[1] * a.sin()) + 100.0 + 2.0 * k as f64,
                40.0 * (p[0] * a.sin() + p[1] * a.cos()),
                40.0 * p[2] - 50.0,
            ]
        })
        .collect();
    rest.with_positions(moved).unwrap()
}

/// Writes `n` frames as `DIR/frames/frame_{k}.obj` and a README.
fn write_frames(dir: &Path, n: usize) -> TriMesh {
    let frames = dir.join("frames");
    std::fs::create_dir_all(&frames).unwrap();
    let rest = procedural::capsule(0.3, 0.8, 10, 20).unwrap();
    for k in 0..n {
        mfm_meshio::write_obj(frames.join(format!("frame_{k}.obj")), &frame(&rest, k)).unwrap();
    }
    std::fs::write(frames.join("README"), "frames of a test sequence").unwrap();
    rest
}

#[test]
fn imported_frames_evaluate_against_themselves() {
    let d = tempfile::tempdir().unwrap();
    let d = d.path();
    write_frames(d, 24);
    // --out may be an empty folder, as for every `mfm dataset` command
    std::fs::create_dir(d.join("data")).unwrap();
    let out = stdout_of(
        d,
        &[
            "dataset",
            "import",
            "frames",
            "--holdout",
            "every:4",
            "--out",
            "data",
        ],
    );
    assert!(out.contains("18 training, 6 held out"), "{out}");
    for f in [
        "train/signals.npy",
        "holdout/signals.npy",
        "reference/signals.npy",
        "transfer.npy",
        "import.json",
        "preview.png",
    ] {
        assert!(d.join("data").join(f).is_file(), "{f}");
    }
    // the held-out shapes themselves as samples: each is its own nearest
    // real shape (plausibility 0), as far from training as the floor
    // (novelty 1), unflipped, and exactly as rough as itself: every energy
    // is measured on the reference mesh, the real shapes carried there
    std::fs::copy(d.join("data/reference/signals.npy"), d.join("held.npy")).unwrap();
    let out = stdout_of(
        d,
        &[
            "eval",
            "--samples",
            "held.npy",
            "--reference",
            "data",
            "--out",
            "m.json",
            "--png",
            "m.png",
        ],
    );
    assert!(
        out.contains("plausibility 0.00") && out.contains("novelty 1.00"),
        "{out}"
    );
    let m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d.join("m.json")).unwrap()).unwrap();
    let q = &m["shape_quality"];
    assert_eq!(q["plausibility"], 0.0, "{q}");
    assert!((q["novelty"].as_f64().unwrap() - 1.0).abs() < 1e-9, "{q}");
    assert_eq!(q["roughness"], 1.0, "{q}");
    assert_eq!(q["flipped"]["max"], 0.0);
    // the held-out shapes as samples sit where the held-out shapes do in
    // the training shapes' principal plane, drawn beside the picture
    assert!(out.contains("spread "), "{out}");
    assert_eq!(q["plane"]["samples"], q["plane"]["held_out"], "{q}");
    assert!(d.join("m_plane.png").is_file());
    // a file of a companion picture's name is the user's unless the
    // picture itself is there too (an earlier evaluation's)
    std::fs::write(d.join("n_plane.png"), "mine").unwrap();
    let eval_to = |png| {
        [
            "eval",
            "--samples",
            "held.npy",
            "--reference",
            "data",
            "--png",
            png,
        ]
    };
    refused(d, &eval_to("n.png"), "n_plane.png");
    assert_eq!(std::fs::read(d.join("n_plane.png")).unwrap(), b"mine");
    assert!(!d.join("n.png").exists());
    ok(d, &eval_to("m.png"));
    // with the template as the reference mesh, the same shapes are exactly
    // as rough as themselves
    ok(
        d,
        &[
            "dataset",
            "import",
            "frames",
            "--holdout",
            "every:4",
            "--reference-mesh",
            "frames/frame_0.obj",
            "--out",
            "same",
        ],
    );
    std::fs::copy(d.join("same/reference/signals.npy"), d.join("same.npy")).unwrap();
    ok(
        d,
        &[
            "eval",
            "--samples",
            "same.npy",
            "--reference",
            "same",
            "--out",
            "s.json",
        ],
    );
    let s: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d.join("s.json")).unwrap()).unwrap();
    let r = s["shape_quality"]["roughness"].as_f64().unwrap();
    assert!((r - 1.0).abs() < 1e-6, "{s}");
    assert!(d.join("m.png").is_file());
    // samples on the template are judged against the held-out set there
    let out = stdout_of(
        d,
        &[
            "eval",
            "--samples",
            "data/holdout/signals.npy",
            "--reference",
            "data/holdout",
            "--out",
            "h.json",
        ],
    );
    assert!(out.contains("plausibility 0.00"), "{out}");
    let h: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d.join("h.json")).unwrap()).unwrap();
    let r = h["shape_quality"]["roughness"].as_f64().unwrap();
    assert!((r - 1.0).abs() < 1e-6, "{h}");
    // the training shapes on the template are not on the reference mesh
    refused(
        d,
        &[
            "eval",
            "--samples",
            "data/train/signals.npy",
            "--reference",
            "data",
        ],
        "vertices",
    );
}

#[test]
fn bad_imports_are_refused_naming_the_input_and_leave_nothing() {
    let d = tempfile::tempdir().unwrap();
    let d = d.path();
    let rest = write_frames(d, 3);
    std::fs::create_dir_all(d.join("empty")).unwrap();
    refused(
        d,
        &["dataset", "import", "empty", "--out", "a"],
        "holds no mesh files",
    );
    refused(
        d,
        &["dataset", "import", "frames", "--strict", "--out", "a"],
        "README",
    );
    // one frame of another mesh
    mfm_meshio::write_obj(d.join("frames/frame_1.obj"), &procedural::icosphere(1)).unwrap();
    refused(
        d,
        &["dataset", "import", "frames", "--out", "a"],
        "frame_1.obj",
    );
    mfm_meshio::write_obj(d.join("frames/frame_1.obj"), &frame(&rest, 1)).unwrap();
    // a NaN coordinate names the file and the vertex
    let text = std::fs::read_to_string(d.join("frames/frame_2.obj")).unwrap();
    let mut lines: Vec<String> = text.lines().map(str::to_owned).collect();
    let first_v = lines.iter().position(|l| l.starts_with("v ")).unwrap();
    lines[first_v] = "v nan 0 0".into();
    std::fs::write(d.join("frames/frame_2.obj"), lines.join("\n")).unwrap();
    let e = refused(
        d,
        &["dataset", "import", "frames", "--out", "a"],
        "frame_2.obj",
    );
    assert!(e.to_lowercase().contains("vertex 0"), "{e}");
    // too few shapes and holdouts that leave nothing
    refused(
        d,
        &["dataset", "import", "frames/frame_0.obj", "--out", "a"],
        "at least 2",
    );
    refused(
        d,
        &[
            "dataset",
            "import",
            "frames/frame_0.obj",
            "frames/frame_1.obj",
            "--holdout",
            "2",
            "--out",
            "a",
        ],
        "leaving none to train on",
    );
    refused(
        d,
        &[
            "dataset",
            "import",
            "frames",
            "--holdout",
            "ten",
            "--out",
            "a",
        ],
        "--holdout",
    );
    assert!(!d.join("a").exists() && !d.join(".a.mfm-lock").exists());
    // the output may not be an input
    refused(
        d,
        &["dataset", "import", "frames", "--out", "frames"],
        "frames",
    );
}

#[test]
fn an_interrupted_import_leaves_nothing() {
    let d = tempfile::tempdir().unwrap();
    let d = d.path();
    let mesh = procedural::icosphere(5);
    let v = mesh.num_vertices();
    mfm_meshio::write_ply(d.join("mesh.ply"), &mesh, &[]).unwrap();
    let n = 600;
    let values: Vec<f32> = (0..n * v * 3).map(|i| (i % 1000) as f32 * 1e-3).collect();
    mfm_files::npy::write(d.join("big.npy"), &values, &[n as u64, v as u64, 3]).unwrap();
    let o = common::interrupt_when(
        d,
        &[
            "dataset",
            "import",
            "--signals",
            "big.npy",
            "--mesh",
            "mesh.ply",
            "--holdout",
            "10%",
            "--out",
            "data",
        ],
        || d.join("data").exists(),
        "-INT",
    );
    if o.status.success() {
        eprintln!("the import finished before the signal; nothing to check");
        return;
    }
    assert_eq!(o.status.code(), Some(130), "{}", err(&o));
    let mut left: Vec<String> = std::fs::read_dir(d)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    left.sort();
    assert_eq!(left, ["big.npy", "mesh.ply"], "what the import left");
}

#[test]
#[cfg(feature = "network")]
fn imported_shapes_train_sample_and_come_back_in_the_users_units() {
    let d = tempfile::tempdir().unwrap();
    let d = d.path();
    write_frames(d, 16);
    ok(
        d,
        &[
            "dataset",
            "import",
            "frames",
            "--holdout",
            "every:4",
            "--out",
            "data",
        ],
    );
    let config = "[model]\npreset = \"small\"\nwidth = 8\nblocks = 1\nvector_layers = 1\n\
                  condition_on_xyz = true\n\
                  [train]\nsteps = 4\nbatch = 2\ncheckpoint_every = 2\nlog_every = 1\n\
                  [sample]\nsteps = 2\n";
    std::fs::write(d.join("run.toml"), config).unwrap();
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
            "--out",
            "samples",
        ],
    );
    // in the frames' units and place: centred near x = 115, z = -50
    let in_place = |file: &str| {
        let a = mfm_files::npy::read::<f32>(&d.join(file)).unwrap();
        let n = a.values.len() / 3;
        let mean = |k: usize| -> f64 {
            a.values
                .chunks_exact(3)
                .map(|p| f64::from(p[k]))
                .sum::<f64>()
                / n as f64
        };
        let (x, z) = (mean(0), mean(2));
        assert!(
            (x - 115.0).abs() < 10.0 && (z + 50.0).abs() < 10.0,
            "{file}: {x} {z}"
        );
    };
    in_place("samples/samples.npy");
    // with the data prior (and another noise amplitude): fitted on the 12
    // training frames, stored with the run, carried to the reference mesh
    let out = stdout_of(
        d,
        &[
            "train",
            "--config",
            "run.toml",
            "--dataset",
            "data/train",
            "--prior",
            "gaussian",
            "--noise-scale",
            "0.5",
            "--out",
            "run_prior",
            "--quiet",
        ],
    );
    assert!(
        out.contains("prior: a Gaussian fit of 12 training signals"),
        "{out}"
    );
    let written = std::fs::read_to_string(d.join("run_prior/config.toml")).unwrap();
    assert!(
        written.contains("prior = \"gaussian\"") && written.contains("scale = 0.5"),
        "{written}"
    );
    ok(
        d,
        &[
            "sample",
            "--run",
            "run_prior",
            "--mesh",
            "data/reference/mesh.ply",
            "--n",
            "3",
            "--out",
            "samples_prior",
        ],
    );
    in_place("samples_prior/samples.npy");
    let out = stdout_of(
        d,
        &[
            "eval",
            "--samples",
            "samples/samples.npy",
            "--reference",
            "data",
        ],
    );
    assert!(
        out.contains("plausibility") && out.contains("roughness"),
        "{out}"
    );
}

/// Writes `DIR/pairs.pt`, the authors' arbitrary-source format, with
/// `torch.save` in the project's Python environment: pair `i` goes from
/// frame `i` of [`frame`] to frame `i + 3`, on the capsule's faces
/// (`None` without the environment).
fn write_authors_pairs(dir: &Path, pairs: usize) -> Option<()> {
    let python = mfm_geometry::test_support::python_oracle()?;
    let rest = procedural::capsule(0.3, 0.8, 10, 20).unwrap();
    let coordinates = |k: usize| -> Vec<u8> {
        frame(&rest, k)
            .positions()
            .iter()
            .flat_map(|p| p.iter().flat_map(|&x| (x as f32).to_le_bytes()))
            .collect()
    };
    let src: Vec<u8> = (0..pairs).flat_map(coordinates).collect();
    let tar: Vec<u8> = (0..pairs).flat_map(|i| coordinates(i + 3)).collect();
    let faces: Vec<u8> = rest
        .faces()
        .iter()
        .flat_map(|f| f.iter().flat_map(|&i| i64::from(i).to_le_bytes()))
        .collect();
    std::fs::write(dir.join("src.bin"), src).unwrap();
    std::fs::write(dir.join("tar.bin"), tar).unwrap();
    std::fs::write(dir.join("faces.bin"), faces).unwrap();
    let script = format!(
        "import numpy as np, torch\n\
         v = {v}\n\
         src = torch.from_numpy(np.fromfile('src.bin', np.float32).reshape({pairs}, v, 3))\n\
         tar = torch.from_numpy(np.fromfile('tar.bin', np.float32).reshape({pairs}, v, 3))\n\
         faces = torch.from_numpy(np.fromfile('faces.bin', np.int64).reshape(-1, 3))\n\
         torch.save({{'src_verts': src, 'tar_verts': tar, 'faces': faces}}, 'pairs.pt')\n",
        v = rest.num_vertices()
    );
    let o = Command::new(python)
        .current_dir(dir)
        .args(["-c", &script])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", err(&o));
    Some(())
}

#[test]
#[cfg(feature = "network")]
fn the_authors_arbitrary_source_pairs_train_the_arbitrary_source_model() {
    let d = tempfile::tempdir().unwrap();
    let d = d.path();
    if write_authors_pairs(d, 8).is_none() {
        eprintln!("skipped: no Python environment with torch (cargo xtask setup)");
        return;
    }
    let out = stdout_of(
        d,
        &[
            "dataset",
            "import",
            "pairs.pt",
            "--holdout",
            "2",
            "--out",
            "data",
        ],
    );
    assert!(out.contains("8 (source, target) pairs"), "{out}");
    assert!(out.contains("6 training pairs, 2 held out"), "{out}");
    assert!(out.contains("--mode arbitrary"), "{out}");
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d.join("data/import.json")).unwrap())
            .unwrap();
    assert_eq!(summary["pairs"], true);
    assert_eq!(summary["train"], 12);
    let quick = ["--steps", "2", "--quiet"];
    ok(
        d,
        &[
            &["train", "--mode", "predictor", "--dataset", "data/train"][..],
            &["--out", "pred"],
            &quick,
        ]
        .concat(),
    );
    ok(
        d,
        &[
            &["train", "--mode", "arbitrary", "--dataset", "data/train"][..],
            &["--predictor", "pred", "--out", "arb"],
            &quick,
        ]
        .concat(),
    );
    // a predictor run generates nothing, with --mesh or --source
    for flag in ["--mesh", "--source"] {
        refused(
            d,
            &[
                "sample",
                "--run",
                "pred",
                flag,
                "data/holdout/mesh.ply",
                "--out",
                "p",
            ],
            "is an eigenvector predictor run",
        );
    }
    // the template (the first pair's source) as a source gives a target
    ok(
        d,
        &[
            "sample",
            "--run",
            "arb",
            "--source",
            "data/holdout/mesh.ply",
            "--n",
            "1",
            "--out",
            "targets",
        ],
    );
    assert!(d.join("targets/samples.npy").is_file());
    // a source beyond f64's range for the operators is refused by name,
    // not measured as "area NaN differs by NaN%"
    std::fs::write(
        d.join("huge.off"),
        "OFF\n3 1 0\n0 0 0\n1e300 0 0\n0 1e300 0\n3 0 1 2\n",
    )
    .unwrap();
    let e = refused(
        d,
        &[
            "sample", "--run", "arb", "--source", "huge.off", "--n", "1", "--out", "huge",
        ],
        "too small or too large",
    );
    assert!(!e.contains("NaN"), "{e}");
    // a set of single shapes is not a pairs set: named as such
    write_frames(d, 6);
    ok(d, &["dataset", "import", "frames", "--out", "single"]);
    let e = refused(
        d,
        &[
            &["train", "--mode", "arbitrary", "--dataset", "single/train"][..],
            &["--predictor", "pred", "--out", "arb2"],
            &quick,
        ]
        .concat(),
        "is not a pairs dataset",
    );
    assert!(e.contains("arbitrary-source file"), "{e}");
}
