//! Writers: exact round trips (property tests), the PLY header layout other
//! tools rely on, argument checks, and atomicity.

mod io_support;

use io_support::any_mesh;
use mfm_geometry::{TriMesh, procedural};
use mfm_meshio::{PlyEncoding, WriteErrorKind};
use proptest::prelude::*;
use std::path::Path;

fn bits(mesh: &TriMesh) -> Vec<u64> {
    mesh.positions()
        .iter()
        .flatten()
        .map(|x| x.to_bits())
        .collect()
}

/// Files in `dir` (names), sorted.
fn listing(dir: &Path) -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .expect("readable dir")
        .map(|e| e.expect("entry").file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    names
}

fn scalar_values() -> impl Strategy<Value = f64> {
    prop_oneof![
        3 => any::<f64>(),
        1 => prop::sample::select(vec![f64::NAN, f64::INFINITY, f64::NEG_INFINITY, -0.0, 5e-324]),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    /// write then read gives the same vertices (bit for bit), faces and scalars
    /// for every encoding; binary keeps even NaN payloads.
    #[test]
    fn ply_round_trip_is_exact(
        mesh in any_mesh(),
        seeds in prop::collection::vec(scalar_values(), 0..3 * 30),
        nfields in 0usize..3,
    ) {
        let dir = tempfile::tempdir().expect("tempdir");
        let n = mesh.num_vertices();
        let fields: Vec<Vec<f64>> = (0..nfields)
            .map(|k| (0..n).map(|v| seeds.get(k * n + v).copied().unwrap_or(v as f64)).collect())
            .collect();
        let names = ["u", "field_2", "temperature.K"];
        let scalars: Vec<(&str, &[f64])> =
            fields.iter().enumerate().map(|(k, f)| (names[k], f.as_slice())).collect();
        for encoding in [PlyEncoding::BinaryLittleEndian, PlyEncoding::BinaryBigEndian, PlyEncoding::Ascii] {
            let path = dir.path().join("m.ply");
            mfm_meshio::write_ply_with(&path, &mesh, &scalars, encoding).expect("write");
            let (back, read) = mfm_meshio::read_mesh_with_scalars(&path).expect("read back");
            prop_assert_eq!(bits(&back), bits(&mesh));
            prop_assert_eq!(back.faces(), mesh.faces());
            prop_assert_eq!(read.len(), fields.len());
            for ((name, values), (want_name, want)) in read.iter().zip(&scalars) {
                prop_assert_eq!(name.as_str(), *want_name);
                for (a, b) in values.iter().zip(want.iter()) {
                    if encoding == PlyEncoding::Ascii && b.is_nan() {
                        prop_assert!(a.is_nan());
                    } else {
                        prop_assert_eq!(a.to_bits(), b.to_bits(), "{:?}", encoding);
                    }
                }
            }
        }
        prop_assert_eq!(listing(dir.path()), vec!["m.ply".to_string()]);
    }

    /// OBJ keeps every vertex (used or not) and the exact coordinates.
    #[test]
    fn obj_round_trip_is_exact(mesh in any_mesh()) {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("m.obj");
        mfm_meshio::write_obj(&path, &mesh).expect("write");
        let back = mfm_meshio::read_mesh(&path).expect("read back");
        prop_assert_eq!(bits(&back), bits(&mesh));
        prop_assert_eq!(back.faces(), mesh.faces());
    }
}

#[test]
fn ply_header_is_what_viewers_expect() {
    let mesh = procedural::icosphere(0);
    let a: &[f64] = &(0..mesh.num_vertices())
        .map(|v| v as f64)
        .collect::<Vec<_>>();
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("ico.ply");
    mfm_meshio::write_ply(&path, &mesh, &[("geodesic_distance", a), ("noise-1", a)])
        .expect("write");
    let bytes = std::fs::read(&path).expect("read");
    let header = "ply\nformat binary_little_endian 1.0\ncomment written by mfm-geometry\n\
        element vertex 12\nproperty double x\nproperty double y\nproperty double z\n\
        property double geodesic_distance\nproperty double noise-1\n\
        element face 20\nproperty list uchar uint vertex_indices\nend_header\n";
    assert!(bytes.starts_with(header.as_bytes()));
    // 12 vertices of 5 doubles, 20 faces of 1 + 3 * 4 bytes
    assert_eq!(bytes.len(), header.len() + 12 * 5 * 8 + 20 * 13);
    // first vertex, little endian
    let x0 = f64::from_le_bytes(bytes[header.len()..header.len() + 8].try_into().expect("8"));
    assert_eq!(x0.to_bits(), mesh.positions()[0][0].to_bits());
}

#[test]
fn ascii_files_are_readable_text() {
    let mesh = TriMesh::new(
        vec![[0.0, 0.0, 0.0], [1e-300, 0.5, -0.0], [0.1, 1.0, 2.5e20]],
        vec![[0, 1, 2]],
    )
    .expect("mesh");
    let dir = tempfile::tempdir().expect("tempdir");
    let obj = dir.path().join("t.obj");
    mfm_meshio::write_obj(&obj, &mesh).expect("obj");
    let text = std::fs::read_to_string(&obj).expect("utf-8");
    assert_eq!(
        text,
        "# written by mfm-geometry: 3 vertices, 1 faces\nv 0 0 0\nv 1e-300 0.5 -0\nv 0.1 1 2.5e20\nf 1 2 3\n"
    );
    let ply = dir.path().join("t.ply");
    mfm_meshio::write_ply_with(
        &ply,
        &mesh,
        &[("s", &[1.0, f64::INFINITY, -2.5][..])],
        PlyEncoding::Ascii,
    )
    .expect("ply");
    let text = std::fs::read_to_string(&ply).expect("utf-8");
    assert!(
        text.ends_with("end_header\n0 0 0 1\n1e-300 0.5 -0 inf\n0.1 1 2.5e20 -2.5\n3 0 1 2\n"),
        "{text}"
    );
}

#[test]
fn bad_scalars_are_refused_before_touching_the_file() {
    let mesh = procedural::icosphere(0);
    let ok: &[f64] = &vec![0.0; mesh.num_vertices()];
    let short: &[f64] = &[0.0; 3];
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("keep.ply");
    std::fs::write(&path, b"precious").expect("write");
    // (scalars, a phrase the error message must contain)
    type Case<'a> = (Vec<(&'a str, &'a [f64])>, &'a str);
    let cases: Vec<Case> = vec![
        (vec![("", ok)], "empty"),
        (vec![("has space", ok)], "only ASCII"),
        (vec![("1st", ok)], "start with"),
        (vec![("é", ok)], "start with"),
        (vec![("y", ok)], "coordinates"),
        (vec![("a", ok), ("a", ok)], "twice"),
        (vec![("a", ok), ("b", short)], "3 values"),
    ];
    for (scalars, needle) in cases {
        let err = mfm_meshio::write_ply(&path, &mesh, &scalars).expect_err("invalid scalars");
        assert_eq!(err.path(), path);
        let text = err.to_string();
        assert!(
            text.contains(needle) && text.contains("keep.ply"),
            "`{text}` lacks `{needle}`"
        );
        match err.kind() {
            WriteErrorKind::InvalidScalarName { .. } => assert_ne!(needle, "3 values"),
            WriteErrorKind::ScalarLength {
                expected: 12,
                found: 3,
                name,
            } => assert_eq!(name, "b"),
            k => panic!("unexpected {k:?}"),
        }
        assert_eq!(std::fs::read(&path).expect("still there"), b"precious");
    }
    assert_eq!(listing(dir.path()), vec!["keep.ply".to_string()]);
}

#[test]
fn failed_writes_leave_nothing_behind() {
    let mesh = procedural::icosphere(0);
    let dir = tempfile::tempdir().expect("tempdir");
    // the destination is a non-empty directory: refused before writing
    let target = dir.path().join("occupied.ply");
    std::fs::create_dir(&target).expect("mkdir");
    std::fs::write(target.join("inside.txt"), b"keep me").expect("write");
    let err = mfm_meshio::write_ply(&target, &mesh, &[]).expect_err("cannot replace a directory");
    assert!(matches!(err.kind(), WriteErrorKind::Refused(_)), "{err}");
    assert!(err.to_string().contains("is a folder"), "{err}");
    let err = mfm_meshio::write_obj(&target, &mesh).expect_err("cannot replace a directory");
    assert!(matches!(err.kind(), WriteErrorKind::Refused(_)), "{err}");
    assert_eq!(
        std::fs::read(target.join("inside.txt")).expect("kept"),
        b"keep me"
    );
    // no temporary file is left next to it
    assert_eq!(listing(dir.path()), vec!["occupied.ply".to_string()]);
    // a missing parent folder is an I/O error naming the path
    let nowhere = dir.path().join("missing/sub/m.obj");
    let err = mfm_meshio::write_obj(&nowhere, &mesh).expect_err("no such folder");
    assert!(err.to_string().contains("missing/sub/m.obj"));
    // an existing file is replaced whole
    let path = dir.path().join("m.obj");
    std::fs::write(&path, "x".repeat(100_000)).expect("write");
    mfm_meshio::write_obj(&path, &mesh).expect("replace");
    assert_eq!(mfm_meshio::read_mesh(&path).expect("reads"), mesh);
    assert_eq!(
        listing(dir.path()),
        vec!["m.obj".to_string(), "occupied.ply".to_string()]
    );
}

#[test]
fn write_mesh_picks_the_format_by_extension_and_refuses_others() {
    let dir = tempfile::tempdir().expect("tempdir");
    let mesh = procedural::icosphere(1);
    for name in ["a.obj", "b.PLY"] {
        let p = dir.path().join(name);
        mfm_meshio::write_mesh(&p, &mesh).expect("written");
        let back = mfm_meshio::read_mesh(&p).expect("readable");
        assert_eq!(bits(&back), bits(&mesh), "{name}");
        assert_eq!(back.faces(), mesh.faces(), "{name}");
    }
    // the OBJ writer's text, not PLY's binary
    let obj = std::fs::read(dir.path().join("a.obj")).expect("obj");
    assert!(obj.iter().all(u8::is_ascii));
    for name in ["c.off", "noext"] {
        let Err(e) = mfm_meshio::write_mesh(dir.path().join(name), &mesh) else {
            panic!("{name} was written");
        };
        assert!(
            matches!(e.kind(), WriteErrorKind::UnsupportedExtension { .. }),
            "{e}"
        );
        assert!(e.to_string().contains(name), "{e}");
    }
    assert_eq!(listing(dir.path()), ["a.obj", "b.PLY"]);
}
