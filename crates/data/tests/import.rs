//! `mfm dataset import` as a library: folders of meshes in natural order,
//! the split, the reference mesh and its transfer, signal arrays, PLY
//! properties, the authors' `.pt` files (written by `torch.save` in the
//! project's Python environment), and every refusal and warning; the
//! shared real sequences when `../shared` is there.
#![allow(clippy::unwrap_used)]

use std::path::Path;

use mfm_data::SignalSource;
use mfm_data::dataset::Dataset;
use mfm_data::import::authors::read_authors_dataset;
use mfm_data::import::inputs::list_mesh_files;
use mfm_data::import::sources::{MeshFiles, NpyRows, PairedShapes, ShapesInMemory};
use mfm_data::import::{
    Holdout, ImportExperiment, ImportManifest, ImportSummary, SUMMARY, SignalFiles, TRANSFER,
};
use mfm_data::layout::{HOLDOUT, PREVIEW, REFERENCE, TRAIN};
use mfm_data::pairs::training_pairs;
use mfm_data::transfer::Transfer;
use mfm_geometry::TriMesh;
use mfm_geometry::procedural;
use mfm_geometry::test_support::{python_oracle, shared_data};

/// The rest shape of the tests: a capsule along y.
fn rest() -> TriMesh {
    procedural::capsule(0.3, 0.8, 12, 24).unwrap()
}

/// Shape `k` of a bending family of the rest shape, moved by `k` along x
/// (a sequence that travels, as a captured performance does).
fn shape(rest: &TriMesh, k: usize) -> TriMesh {
    let bend = 0.1 * k as f64;
    let moved: Vec<[f64; 3]> = rest
        .positions()
        .iter()
        .map(|p| {
            let a = bend * p[1];
            [
                p[0] * a.cos() - p[1] * a.sin() + 0.5 * k as f64,
                p[0] * a.sin() + p[1] * a.cos(),
                p[2],
            ]
        })
        .collect();
    rest.with_positions(moved).unwrap()
}

/// Writes shapes `0..n` as `dir/{k+1}.obj` (so that plain string order
/// would put 10 before 2) and a note that is not a mesh.
fn write_sequence(dir: &Path, n: usize) -> TriMesh {
    std::fs::create_dir_all(dir).unwrap();
    let rest = rest();
    for k in 0..n {
        mfm_meshio::write_obj(dir.join(format!("{}.obj", k + 1)), &shape(&rest, k)).unwrap();
    }
    std::fs::write(dir.join("notes.txt"), "not a mesh").unwrap();
    rest
}

fn import(
    source: &dyn SignalFiles,
    template: &TriMesh,
    holdout: Holdout,
    reference: Option<(&TriMesh, &str)>,
    out: &Path,
) -> mfm_data::Result<ImportSummary> {
    ImportExperiment {
        source,
        template,
        template_name: "template",
        holdout,
        reference_mesh: reference,
        seed: 0,
        align: Default::default(),
        pairs: false,
        skipped: 0,
        progress: false,
    }
    .write(out)
}

fn mesh_files(dir: &Path) -> MeshFiles {
    MeshFiles {
        files: list_mesh_files(&[dir.to_path_buf()], false).unwrap().files,
        properties: Vec::new(),
    }
}

#[test]
fn a_folder_of_meshes_becomes_an_experiment() {
    let tmp = tempfile::tempdir().unwrap();
    let input = tmp.path().join("frames");
    let rest = write_sequence(&input, 12);
    let list = list_mesh_files(std::slice::from_ref(&input), false).unwrap();
    assert_eq!(list.skipped.len(), 1, "notes.txt is skipped");
    let names: Vec<String> = list
        .files
        .iter()
        .map(|p| p.file_name().unwrap().to_string_lossy().into_owned())
        .collect();
    assert_eq!(names[..3], ["1.obj", "2.obj", "3.obj"]);
    assert_eq!(names[11], "12.obj");
    let err = list_mesh_files(std::slice::from_ref(&input), true).unwrap_err();
    assert!(err.to_string().contains("notes.txt"), "{err}");

    let source = mesh_files(&input);
    let template = mfm_meshio::read_mesh(&list.files[0]).unwrap();
    let out = tmp.path().join("data");
    let summary = import(&source, &template, Holdout::Every(4), None, &out).unwrap();
    assert_eq!((summary.train, summary.held_out), (9, 3));
    assert!(summary.warnings.is_empty(), "{:?}", summary.warnings);
    for entry in [TRAIN, HOLDOUT, REFERENCE, TRANSFER, SUMMARY, PREVIEW] {
        assert!(out.join(entry).exists(), "{entry}");
    }

    let train = Dataset::open(out.join(TRAIN)).unwrap();
    let holdout = Dataset::open(out.join(HOLDOUT)).unwrap();
    let reference = Dataset::open(out.join(REFERENCE)).unwrap();
    assert_eq!((train.len(), train.channels()), (9, 3));
    assert_eq!(train.mesh().faces(), rest.faces());
    // every 4th frame held out: inputs 3, 7, 11 (files 4.obj, 8.obj, 12.obj)
    let m = ImportManifest::of(&holdout).unwrap().unwrap();
    let held: Vec<usize> = m.signals.iter().map(|s| s.index).collect();
    assert_eq!(held, [3, 7, 11]);
    assert!(m.signals[2].name.ends_with("12.obj"), "{:?}", m.signals[2]);
    let t = ImportManifest::of(&train).unwrap().unwrap();
    assert_eq!(t.signals.len(), 9);
    assert!(t.positions);
    assert!(train.manifest().frame.is_some());

    // the user's units and place: shape 7 exactly as its file, moved by 3.5 along x
    let all = holdout.load_all().unwrap();
    let file = shape(&rest, 7);
    for (a, b) in all.positions(1).iter().zip(file.positions()) {
        for k in 0..3 {
            assert_eq!(a[k], b[k] as f32 as f64);
        }
    }
    // the reference set is the held-out set carried by the transfer
    assert!(reference.num_vertices() > 2 * train.num_vertices());
    let transfer = Transfer::read(&out.join(TRANSFER), train.num_vertices()).unwrap();
    assert_eq!(transfer.target_vertices(), reference.num_vertices());
    let carried = transfer.apply_set(&all).unwrap();
    assert_eq!(carried.data(), reference.load_all().unwrap().data());
    // the refinement keeps the coarse surface: a carried shape is that
    // shape's surface (area of the moved reference mesh = moved template's)
    let moved_ref = reference
        .mesh()
        .with_positions(reference.load_all().unwrap().positions(1))
        .unwrap();
    let moved = train.mesh().with_positions(all.positions(1)).unwrap();
    assert!((moved_ref.total_area() - moved.total_area()).abs() < 1e-4 * moved.total_area());

    let text = std::fs::read_to_string(out.join(SUMMARY)).unwrap();
    let read: ImportSummary = serde_json::from_str(&text).unwrap();
    assert_eq!(read.inputs, 12);
}

#[test]
fn a_given_reference_mesh_must_lie_on_the_template() {
    let tmp = tempfile::tempdir().unwrap();
    let input = tmp.path().join("frames");
    let rest = write_sequence(&input, 6);
    let source = mesh_files(&input);
    let fine = mfm_geometry::subdivide::midpoint(&rest).unwrap();
    let out = tmp.path().join("ok");
    let s = import(
        &source,
        &rest,
        Holdout::Count(2),
        Some((&fine, "fine")),
        &out,
    )
    .unwrap();
    assert_eq!(
        s.reference_size,
        Some([fine.num_vertices(), fine.num_faces()])
    );
    assert!(s.reference_max_distance.unwrap() < 1e-9);

    let far = fine.transformed(1.0, [0.0, 0.0, 0.05 * rest.bounding_box_diagonal()]);
    let out = tmp.path().join("far");
    let err = import(
        &source,
        &rest,
        Holdout::Count(2),
        Some((&far, "far.ply")),
        &out,
    )
    .unwrap_err();
    let text = err.to_string();
    assert!(
        text.contains("far.ply") && text.contains("% of its bounding-box diagonal"),
        "{text}"
    );
    assert!(!out.exists(), "nothing is left behind");
}

#[test]
fn shapes_of_another_connectivity_are_named() {
    let tmp = tempfile::tempdir().unwrap();
    let input = tmp.path().join("frames");
    let rest = write_sequence(&input, 4);
    // 3.obj: the same vertices, one face turned
    let mut faces = rest.faces().to_vec();
    faces[5] = [faces[5][1], faces[5][2], faces[5][0]];
    let turned = TriMesh::new(rest.positions().to_vec(), faces).unwrap();
    mfm_meshio::write_obj(input.join("3.obj"), &turned).unwrap();
    let out = tmp.path().join("data");
    let err = import(&mesh_files(&input), &rest, Holdout::None, None, &out).unwrap_err();
    let text = err.to_string();
    assert!(text.contains("3.obj") && text.contains("face 5"), "{text}");
    assert!(!out.exists());
    // fewer vertices
    let other = procedural::icosphere(1);
    mfm_meshio::write_obj(input.join("3.obj"), &other).unwrap();
    let err = import(&mesh_files(&input), &rest, Holdout::None, None, &out).unwrap_err();
    assert!(err.to_string().contains("42 vertices"), "{err}");
}

#[test]
fn bad_values_and_too_little_data_are_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let rest = rest();
    let v = rest.num_vertices();
    // an array with a NaN at signal 2, vertex 5, y
    let mut values = vec![0.25f32; 4 * v * 3];
    values[2 * v * 3 + 5 * 3 + 1] = f32::NAN;
    let path = tmp.path().join("x.npy");
    mfm_files::npy::write(&path, &values, &[4, v as u64, 3]).unwrap();
    let rows = NpyRows::open(&path, true).unwrap();
    let out = tmp.path().join("data");
    let err = import(&rows, &rest, Holdout::None, None, &out).unwrap_err();
    let text = err.to_string();
    assert!(
        text.contains("x.npy[2]") && text.contains("vertex 5, coordinate y"),
        "{text}"
    );
    assert!(!out.exists());

    let one = tmp.path().join("one.npy");
    mfm_files::npy::write(&one, &vec![0.0f32; v], &[1, v as u64]).unwrap();
    let err = import(
        &NpyRows::open(&one, false).unwrap(),
        &rest,
        Holdout::None,
        None,
        &out,
    )
    .unwrap_err();
    assert!(err.to_string().contains("at least 2"), "{err}");

    // a degenerate template face
    let mut p = rest.positions().to_vec();
    let f = rest.faces()[0];
    p[f[2] as usize] = p[f[0] as usize];
    let flat = TriMesh::new(p, rest.faces().to_vec()).unwrap();
    let rows = NpyRows::open(&path, true).unwrap();
    let err = import(&rows, &flat, Holdout::None, None, &out).unwrap_err();
    assert!(err.to_string().contains("degenerate"), "{err}");
}

#[test]
fn copies_and_other_units_are_warned_about() {
    let tmp = tempfile::tempdir().unwrap();
    let input = tmp.path().join("frames");
    let rest = write_sequence(&input, 5);
    std::fs::copy(input.join("2.obj"), input.join("6.obj")).unwrap();
    let big = shape(&rest, 2).transformed(100.0, [0.0; 3]);
    mfm_meshio::write_obj(input.join("7.obj"), &big).unwrap();
    let s = import(
        &mesh_files(&input),
        &rest,
        Holdout::None,
        None,
        &tmp.path().join("d"),
    )
    .unwrap();
    assert_eq!(s.warnings.len(), 2, "{:?}", s.warnings);
    assert!(
        s.warnings[0].contains("input 5 repeats input 1"),
        "{:?}",
        s.warnings
    );
    assert!(s.warnings[1].contains("7.obj") && s.warnings[1].contains("mixed units"));
}

/// A frame written again with its coordinates rounded differently is a
/// near copy; a held-out shape whose copy is in the training set is
/// named, since the evaluation would read a memorized shape as data-like.
#[test]
fn near_copies_and_held_out_copies_are_warned_about() {
    let tmp = tempfile::tempdir().unwrap();
    let input = tmp.path().join("frames");
    let rest = write_sequence(&input, 6);
    // input 6: shape 1 moved by 1e-6 of the diagonal (not the same bits)
    let nudge = 1e-6 * rest.bounding_box_diagonal();
    let again = shape(&rest, 1).transformed(1.0, [nudge, 0.0, 0.0]);
    mfm_meshio::write_obj(input.join("7.obj"), &again).unwrap();
    // input 7: shape 4 moved by 1e-2 of the diagonal, a distinct shape
    let apart = shape(&rest, 4).transformed(1.0, [1e-2 * rest.bounding_box_diagonal(), 0.0, 0.0]);
    mfm_meshio::write_obj(input.join("8.obj"), &apart).unwrap();
    // every:2 holds out inputs 1, 3, 5, 7: input 1 held out, its copy 6 not
    let s = import(
        &mesh_files(&input),
        &rest,
        Holdout::Every(2),
        None,
        &tmp.path().join("d"),
    )
    .unwrap();
    assert_eq!(s.warnings.len(), 2, "{:?}", s.warnings);
    assert!(
        s.warnings[0].starts_with("1 signal is a copy or near copy")
            && s.warnings[0].contains("input 6 repeats input 1"),
        "{:?}",
        s.warnings
    );
    assert!(
        s.warnings[1].starts_with("1 held-out signal has a copy among the training signals")
            && s.warnings[1].contains("held-out input 1 repeats training input 6"),
        "{:?}",
        s.warnings
    );
    // without a holdout only the copy is told
    let s = import(
        &mesh_files(&input),
        &rest,
        Holdout::None,
        None,
        &tmp.path().join("e"),
    )
    .unwrap();
    assert_eq!(s.warnings.len(), 1, "{:?}", s.warnings);
}

#[test]
fn signal_arrays_and_ply_properties_import_as_channels() {
    let tmp = tempfile::tempdir().unwrap();
    let rest = rest();
    let v = rest.num_vertices();
    // [N, V] float64
    let values: Vec<f64> = (0..5 * v).map(|i| (i as f64 * 0.01).sin()).collect();
    let path = tmp.path().join("scalars.npy");
    mfm_files::npy::write(&path, &values, &[5, v as u64]).unwrap();
    let rows = NpyRows::open(&path, false).unwrap();
    let out = tmp.path().join("scalars");
    let s = import(&rows, &rest, Holdout::Count(1), None, &out).unwrap();
    assert_eq!((s.channels, s.positions, s.train), (1, false, 4));
    let train = Dataset::open(out.join(TRAIN)).unwrap();
    let m = ImportManifest::of(&train).unwrap().unwrap();
    let first = m.signals[0].index;
    assert_eq!(
        train.load_all().unwrap().signal(0)[7],
        values[first * v + 7] as f32
    );

    // PLY files with two vertex properties
    let dir = tmp.path().join("ply");
    std::fs::create_dir_all(&dir).unwrap();
    for k in 0..3 {
        let a: Vec<f64> = (0..v).map(|i| (i + k) as f64).collect();
        let b: Vec<f64> = (0..v).map(|i| -((i * k) as f64)).collect();
        mfm_meshio::write_ply(
            dir.join(format!("s{k}.ply")),
            &rest,
            &[("heat", &a), ("cold", &b)],
        )
        .unwrap();
    }
    let files = MeshFiles {
        files: list_mesh_files(std::slice::from_ref(&dir), true)
            .unwrap()
            .files,
        properties: vec!["cold".into(), "heat".into()],
    };
    let out = tmp.path().join("props");
    let s = import(&files, &rest, Holdout::None, None, &out).unwrap();
    assert_eq!((s.channels, s.positions), (2, false));
    let all = Dataset::open(out.join(TRAIN)).unwrap().load_all().unwrap();
    assert_eq!(all.signal(2)[2 * 10..2 * 10 + 2], [-20.0, 12.0]);
    let missing = MeshFiles {
        files: files.files.clone(),
        properties: vec!["warm".into()],
    };
    let err = import(&missing, &rest, Holdout::None, None, &tmp.path().join("m")).unwrap_err();
    assert!(
        err.to_string().contains("\"warm\"") && err.to_string().contains("heat"),
        "{err}"
    );
}

const WRITE_AUTHORS_DATASETS: &str = r#"
import sys, torch
d = sys.argv[1]
g = torch.Generator().manual_seed(0)
v = torch.tensor([[0., 0., 0.], [1., 0., 0.], [0., 1., 0.], [0., 0., 1.]])
faces = torch.tensor([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
tar = v + 0.05 * torch.randn(6, 4, 3, generator=g)
torch.save({"src_verts": v, "tar_verts": tar, "faces": faces}, d + "/single.pt")
torch.save({"src_verts": tar.flip(0), "tar_verts": tar, "faces": faces}, d + "/pairs.pt")
torch.save({"src_verts": v, "faces": faces}, d + "/missing.pt")
tar.numpy().astype("float32").tofile(d + "/tar.bin")
"#;

#[test]
fn the_authors_dataset_files_read_as_shapes() {
    let Some(python) = python_oracle() else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let out = std::process::Command::new(&python)
        .arg("-c")
        .arg(WRITE_AUTHORS_DATASETS)
        .arg(tmp.path())
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let expect: Vec<f32> = std::fs::read(tmp.path().join("tar.bin"))
        .unwrap()
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect();
    let single = read_authors_dataset(&tmp.path().join("single.pt")).unwrap();
    assert!(single.sources.is_none());
    assert_eq!(single.template.num_vertices(), 4);
    assert_eq!(single.template.faces()[0], [0, 2, 1]);
    assert_eq!(single.targets.values, expect);
    let data = tmp.path().join("data");
    let s = import(
        &single.targets,
        &single.template,
        Holdout::Count(2),
        None,
        &data,
    )
    .unwrap();
    assert_eq!((s.train, s.held_out), (4, 2));

    // one source per target: (source, target) pairs, held out whole
    let pairs = read_authors_dataset(&tmp.path().join("pairs.pt")).unwrap();
    let sources = pairs.sources.clone().unwrap();
    assert_eq!(sources.values[..12], expect[5 * 12..]);
    let paired = PairedShapes::new(sources, pairs.targets.clone()).unwrap();
    assert_eq!(paired.len(), 12);
    let data = tmp.path().join("pairs");
    let s = ImportExperiment {
        source: &paired,
        template: &pairs.template,
        template_name: "pairs.pt",
        holdout: Holdout::Count(2),
        reference_mesh: None,
        seed: 0,
        align: Default::default(),
        pairs: true,
        skipped: 0,
        progress: false,
    }
    .write(&data)
    .unwrap();
    assert_eq!((s.train, s.held_out, s.pairs), (8, 4, true));
    // the sources repeat the targets (flipped): not copies
    assert!(s.warnings.is_empty(), "{:?}", s.warnings);
    for (set, count) in [(TRAIN, 4), (HOLDOUT, 2)] {
        let d = Dataset::open(data.join(set)).unwrap();
        let record = ImportManifest::of(&d).unwrap().unwrap();
        assert!(record.pairs);
        let want: Vec<(usize, usize)> = (0..count).map(|i| (2 * i, 2 * i + 1)).collect();
        assert_eq!(training_pairs(&d).unwrap().unwrap(), want);
        let all = d.load_all().unwrap();
        for (k, signal) in record.signals.iter().enumerate() {
            // mesh 2i is pair i's source (row N-1-i of tar_verts), 2i+1 its target
            assert_eq!(signal.index % 2, k % 2);
            let pair = signal.index / 2;
            let row = if k % 2 == 0 { 5 - pair } else { pair };
            let side = if k % 2 == 0 { "src_verts" } else { "tar_verts" };
            assert!(
                signal.name.ends_with(&format!("{side}[{pair}]")),
                "{}",
                signal.name
            );
            assert_eq!(
                all.signal(k),
                &expect[12 * row..12 * (row + 1)],
                "{set} mesh {k}"
            );
        }
    }
    // a set of single shapes has no pairs
    let single = Dataset::open(tmp.path().join("data").join(TRAIN)).unwrap();
    assert_eq!(training_pairs(&single).unwrap(), None);
    let odd = ShapesInMemory {
        source: "odd".into(),
        values: vec![0.0; 12],
        vertices: 4,
    };
    let err = PairedShapes::new(odd, pairs.targets).unwrap_err();
    assert!(err.to_string().contains("one source per target"), "{err}");
    let err = read_authors_dataset(&tmp.path().join("missing.pt")).unwrap_err();
    assert!(err.to_string().contains("\"tar_verts\""), "{err}");
}

/// Writes every 4th frame of the shared sequence `name` as an OBJ folder,
/// imports it with every 4th of those held out, and checks every
/// training row against its frame; returns the import's warnings (`None`
/// without `../shared`).
fn real_sequence_imports_frame_for_frame(name: &str) -> Option<Vec<String>> {
    let dir = shared_data(name)?;
    let template = mfm_meshio::read_mesh(dir.join("template.obj")).unwrap();
    let frames = mfm_files::npy::read::<f32>(&dir.join("frames.npy")).unwrap();
    let [n, v, 3] = frames.shape[..] else {
        panic!("{:?}", frames.shape)
    };
    assert_eq!(v, template.num_vertices());
    let tmp = tempfile::tempdir().unwrap();
    let objs = tmp.path().join("objs");
    std::fs::create_dir_all(&objs).unwrap();
    let picked: Vec<usize> = (0..n).step_by(4).collect();
    for (k, &i) in picked.iter().enumerate() {
        let p: Vec<[f64; 3]> = frames.values[i * v * 3..(i + 1) * v * 3]
            .chunks_exact(3)
            .map(|c| [c[0].into(), c[1].into(), c[2].into()])
            .collect();
        mfm_meshio::write_obj(
            objs.join(format!("frame{k}.obj")),
            &template.with_positions(p).unwrap(),
        )
        .unwrap();
    }
    let out = tmp.path().join("data");
    let s = import(&mesh_files(&objs), &template, Holdout::Every(4), None, &out).unwrap();
    assert_eq!(s.train + s.held_out, picked.len());
    let train = Dataset::open(out.join(TRAIN)).unwrap();
    let m = ImportManifest::of(&train).unwrap().unwrap();
    let train = train.load_all().unwrap();
    for (row, signal) in m.signals.iter().enumerate() {
        let frame = picked[signal.index];
        assert_eq!(
            train.signal(row),
            &frames.values[frame * v * 3..(frame + 1) * v * 3],
            "{}",
            signal.name
        );
    }
    Some(s.warnings)
}

#[test]
fn the_horse_gallop_written_as_obj_files_imports_frame_for_frame() {
    // the gallop's 48 frames are its 24-frame cycle twice (frame k + 24
    // is frame k to 1e-5 of the diagonal, bit for bit in 5 of them): of
    // frames 0, 4, ..., 44 the last 6 repeat the first 6, and 3 of the
    // held-out ones (12, 28, 44) repeat training frames (36, 4, 20)
    let Some(warnings) = real_sequence_imports_frame_for_frame("horse-gallop") else {
        return;
    };
    assert_eq!(warnings.len(), 2, "{warnings:?}");
    assert!(
        warnings[0].starts_with("6 signals are a copy or near copy")
            && warnings[0].contains("input 6 repeats input 0"),
        "{warnings:?}"
    );
    assert!(
        warnings[1].starts_with("3 held-out signals have a copy among the training signals")
            && warnings[1].contains("held-out input 3 repeats training input 9"),
        "{warnings:?}"
    );
}

#[test]
fn the_crane_performance_written_as_obj_files_imports_frame_for_frame() {
    // a performance without repeats: its closest frames are 1e-3 of the
    // diagonal apart, ten times the copies' tolerance
    if let Some(warnings) = real_sequence_imports_frame_for_frame("crane") {
        assert!(warnings.is_empty(), "{warnings:?}");
    }
}

#[test]
fn a_transfer_round_trips_and_bad_files_are_named() {
    let coarse = procedural::icosphere(2);
    let fine = mfm_geometry::subdivide::midpoint(&coarse).unwrap();
    let t = Transfer::locate(&coarse, &fine).unwrap();
    assert!(t.max_distance() < 1e-12);
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("t.npy");
    t.write(&path).unwrap();
    let back = Transfer::read(&path, coarse.num_vertices()).unwrap();
    let xyz: Vec<f32> = coarse
        .positions()
        .iter()
        .flat_map(|p| p.map(|x| x as f32))
        .collect();
    assert_eq!(back.apply(&xyz, 3).unwrap(), t.apply(&xyz, 3).unwrap());
    // every fine vertex is reproduced by its weights
    for (a, p) in t
        .apply(&xyz, 3)
        .unwrap()
        .chunks_exact(3)
        .zip(fine.positions())
    {
        for k in 0..3 {
            assert!((f64::from(a[k]) - p[k]).abs() < 1e-6);
        }
    }
    assert!(t.apply(&xyz[..9], 3).is_err());
    // a template with fewer vertices than the indices
    let err = Transfer::read(&path, 10).unwrap_err();
    assert!(
        err.to_string().contains("not a vertex of the template"),
        "{err}"
    );
    // another shape, and weights that are not barycentric
    let bad = tmp.path().join("bad.npy");
    mfm_files::npy::write(&bad, &[0.0f64; 10], &[2, 5]).unwrap();
    let err = Transfer::read(&bad, 100).unwrap_err();
    assert!(err.to_string().contains("[V_reference, 6]"), "{err}");
    mfm_files::npy::write(&bad, &[0.0, 1.0, 2.0, 0.5, 0.7, 0.1], &[1, 6]).unwrap();
    let err = Transfer::read(&bad, 100).unwrap_err();
    assert!(err.to_string().contains("not barycentric"), "{err}");
}

#[test]
fn shapes_turned_about_the_vertical_are_turned_back() {
    let tmp = tempfile::tempdir().unwrap();
    let rest = rest();
    // shape k: the rest shape turned by 0.3 k about y, moved along x
    let v = rest.num_vertices();
    let mut values = Vec::new();
    for k in 0..4 {
        let a = 0.3 * k as f64;
        for p in rest.positions() {
            values.extend([
                (a.cos() * p[0] + a.sin() * p[2] + k as f64) as f32,
                p[1] as f32,
                (-a.sin() * p[0] + a.cos() * p[2]) as f32,
            ]);
        }
    }
    let path = tmp.path().join("turning.npy");
    mfm_files::npy::write(&path, &values, &[4, v as u64, 3]).unwrap();
    let rows = NpyRows::open(&path, true).unwrap();
    let out = tmp.path().join("data");
    ImportExperiment {
        source: &rows,
        template: &rest,
        template_name: "rest",
        holdout: Holdout::None,
        reference_mesh: None,
        seed: 0,
        align: "up:y".parse().unwrap(),
        pairs: false,
        skipped: 0,
        progress: false,
    }
    .write(&out)
    .unwrap();
    let train = Dataset::open(out.join(TRAIN)).unwrap();
    assert_eq!(
        ImportManifest::of(&train).unwrap().unwrap().align,
        mfm_data::import::Align::Up(1)
    );
    let all = train.load_all().unwrap();
    for k in 0..4 {
        // the rest shape again, moved by k along x (its place kept)
        for (q, p) in all.positions(k).iter().zip(rest.positions()) {
            assert!((q[0] - p[0] - k as f64).abs() < 1e-5, "{k}: {q:?} {p:?}");
            assert!((q[1] - p[1]).abs() < 1e-5 && (q[2] - p[2]).abs() < 1e-5);
        }
    }
    assert!("sideways".parse::<mfm_data::import::Align>().is_err());
}
