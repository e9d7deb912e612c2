//! Readers: every error from a file in `fixtures/bad`, format details on
//! hand-written inputs, the shared meshes, and libigl as an independent oracle.

mod io_support;

use io_support::{bad_fixture, base64, f32_bytes, glb};
use mfm_geometry::{MeshError, TriMesh, test_support};
use mfm_meshio::{MeshFormat, ReadError, ReadErrorKind};
use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

fn read_bad(name: &str) -> ReadError {
    let path = bad_fixture(name);
    let err = match mfm_meshio::read_mesh(&path) {
        Ok(m) => panic!("{name} should not read, got {} faces", m.num_faces()),
        Err(e) => e,
    };
    assert_eq!(err.path(), path, "the error names the file");
    let text = err.to_string();
    assert!(text.contains(name), "message `{text}` should name {name}");
    err
}

fn parse(bytes: &[u8], format: MeshFormat) -> Result<TriMesh, ReadErrorKind> {
    mfm_meshio::read_mesh_from_bytes(bytes, format).map_err(ReadError::into_kind)
}

fn parse_ok(bytes: &[u8], format: MeshFormat) -> TriMesh {
    match parse(bytes, format) {
        Ok(m) => m,
        Err(e) => panic!("should parse: {e}"),
    }
}

/// The fixtures checked here (read errors) and in `validate.rs` (problems).
const READ_ERROR_FIXTURES: &[&str] = &[
    "unknown_format.stl",
    "syntax_error.off",
    "syntax_error.obj",
    "syntax_error.ply",
    "truncated_binary.ply",
    "count_too_large.off",
    "count_too_large.ply",
    "face_arity.off",
    "unsupported_mode.gltf",
    "invalid_gltf.gltf",
    "empty_mesh.obj",
    "index_out_of_range.off",
    "non_finite.off",
    "repeated_vertex.off",
];
const PROBLEM_FIXTURES: &[&str] = &[
    "degenerate_faces.off",
    "unreferenced_vertices.off",
    "non_manifold_edges.off",
    "non_manifold_vertices.off",
    "inconsistent_orientation.off",
    "duplicate_faces.off",
];

#[test]
fn every_fixture_is_covered() {
    let dir = bad_fixture("");
    let on_disk: BTreeSet<String> = std::fs::read_dir(&dir)
        .expect("fixtures/bad exists")
        .map(|e| {
            e.expect("readable entry")
                .file_name()
                .to_string_lossy()
                .into_owned()
        })
        .filter(|n| n != "README.md")
        .collect();
    let listed: BTreeSet<String> = READ_ERROR_FIXTURES
        .iter()
        .chain(PROBLEM_FIXTURES)
        .map(|s| s.to_string())
        .collect();
    assert_eq!(on_disk, listed);
    // the problem fixtures are valid files: they read, and only validation objects
    for name in PROBLEM_FIXTURES {
        mfm_meshio::read_mesh(bad_fixture(name)).expect("problem fixtures read");
    }
}

/// The errors can travel through `anyhow` and across threads.
#[test]
fn errors_are_send_sync_static() {
    fn check<E: std::error::Error + Send + Sync + 'static>() {}
    check::<ReadError>();
    check::<mfm_meshio::WriteError>();
    check::<mfm_geometry::validate::ValidationError>();
}

#[test]
fn unknown_extension_and_missing_file() {
    let e = read_bad("unknown_format.stl");
    assert!(
        matches!(e.kind(), ReadErrorKind::UnknownFormat { found } if found == "`.stl`"),
        "{e}"
    );
    let missing = bad_fixture("does_not_exist.off");
    let e = mfm_meshio::read_mesh(&missing).expect_err("missing file");
    assert!(matches!(e.kind(), ReadErrorKind::Io(io) if io.kind() == std::io::ErrorKind::NotFound));
    assert!(e.to_string().contains("does_not_exist.off"));
    let dir = tempfile::tempdir().expect("tempdir");
    let folder = dir.path().join("folder.off");
    std::fs::create_dir(&folder).expect("mkdir");
    let e = mfm_meshio::read_mesh(&folder).expect_err("a directory");
    assert!(
        matches!(e.kind(), ReadErrorKind::NotRegular { kind: "a folder" }),
        "{e}"
    );
    // a device (read until memory runs out) or a FIFO (read forever) is
    // refused before anything is read, also behind a link with a mesh name
    #[cfg(unix)]
    {
        let zero = dir.path().join("zero.obj");
        std::os::unix::fs::symlink("/dev/zero", &zero).expect("link");
        let e = mfm_meshio::read_mesh(&zero).expect_err("a device");
        assert!(
            matches!(e.kind(), ReadErrorKind::NotRegular { kind: "a device" }),
            "{e}"
        );
        let fifo = dir.path().join("fifo.off");
        let made = std::process::Command::new("mkfifo").arg(&fifo).status();
        if made.is_ok_and(|s| s.success()) {
            let e = mfm_meshio::read_mesh(&fifo).expect_err("a FIFO");
            assert!(e.to_string().contains("a FIFO"), "{e}");
        }
    }
    let e = mfm_meshio::read_mesh(bad_fixture("no_extension")).expect_err("no extension");
    assert!(matches!(e.kind(), ReadErrorKind::UnknownFormat { found } if found == "(none)"));
}

#[test]
fn syntax_errors_give_line_numbers() {
    let e = read_bad("syntax_error.off");
    match e.kind() {
        ReadErrorKind::Syntax { line, message } => {
            assert_eq!(*line, 4);
            assert!(
                message.contains("`zero`") && message.contains("vertex 1"),
                "{message}"
            );
        }
        k => panic!("expected Syntax, got {k:?}"),
    }
    assert!(e.to_string().contains("line 4"));
    let e = read_bad("syntax_error.obj");
    assert!(
        matches!(e.kind(), ReadErrorKind::Syntax { line: 5, message } if message.contains("start at 1")),
        "{e}"
    );
    let e = read_bad("syntax_error.ply");
    assert!(
        matches!(e.kind(), ReadErrorKind::Syntax { line: 12, message } if message.contains("`1.5.2`")),
        "{e}"
    );
}

#[test]
fn binary_errors_give_byte_offsets() {
    let e = read_bad("truncated_binary.ply");
    let len = std::fs::metadata(bad_fixture("truncated_binary.ply"))
        .expect("fixture")
        .len() as usize;
    match e.kind() {
        ReadErrorKind::Binary { offset, message } => {
            // the face list is cut after its first index: reading the second fails at the end
            assert_eq!(*offset, len);
            assert!(message.contains("corner 1 of face 0"), "{message}");
        }
        k => panic!("expected Binary, got {k:?}"),
    }
}

#[test]
fn huge_declared_counts_are_refused_before_allocating() {
    let e = read_bad("count_too_large.off");
    assert!(
        matches!(e.kind(), ReadErrorKind::CountTooLarge { declared: 1_000_000_000_000, element, max_possible, .. }
            if element == "vertices" && *max_possible < 100),
        "{e}"
    );
    let e = read_bad("count_too_large.ply");
    assert!(
        matches!(e.kind(), ReadErrorKind::CountTooLarge { declared: 4_000_000_000, max_possible, .. }
            if *max_possible < 10),
        "{e}"
    );
    // the largest count a header can state, for every element kind and format
    let big = u64::MAX;
    let cases = [
        format!("OFF\n{big} 1 0\n0 0 0\n"),
        format!("OFF\n3 {big} 0\n0 0 0\n1 0 0\n0 1 0\n"),
        format!(
            "ply\nformat ascii 1.0\nelement vertex {big}\nproperty float x\nproperty float y\nproperty float z\nend_header\n0 0 0\n"
        ),
        format!(
            "ply\nformat binary_big_endian 1.0\nelement edge {big}\nproperty int a\nelement vertex 0\nproperty float x\nproperty float y\nproperty float z\nend_header\n"
        ),
    ];
    for (i, text) in cases.iter().enumerate() {
        let format = if i < 2 {
            MeshFormat::Off
        } else {
            MeshFormat::Ply
        };
        let kind = parse(text.as_bytes(), format).expect_err("impossible count");
        assert!(
            matches!(kind, ReadErrorKind::CountTooLarge { declared, .. } if declared == big),
            "{kind}"
        );
    }
}

#[test]
fn faces_need_three_corners() {
    let e = read_bad("face_arity.off");
    assert!(
        matches!(
            e.kind(),
            ReadErrorKind::FaceArity {
                face: 1,
                arity: 2,
                line: Some(7)
            }
        ),
        "{e}"
    );
    let obj = b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 2\n";
    assert!(matches!(
        parse(obj, MeshFormat::Obj),
        Err(ReadErrorKind::FaceArity {
            face: 1,
            arity: 2,
            line: Some(5)
        })
    ));
    let ply = b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n1 0\n";
    assert!(matches!(
        parse(ply, MeshFormat::Ply),
        Err(ReadErrorKind::FaceArity {
            face: 0,
            arity: 1,
            line: None
        })
    ));
}

#[test]
fn gltf_errors() {
    let e = read_bad("unsupported_mode.gltf");
    assert!(
        matches!(e.kind(), ReadErrorKind::Unsupported(m) if m.contains("Lines") && m.contains("mesh 0 primitive 0")),
        "{e}"
    );
    let e = read_bad("invalid_gltf.gltf");
    assert!(
        matches!(e.kind(), ReadErrorKind::Gltf(m) if m.contains("accessor 0") && m.contains("do not fit")),
        "{e}"
    );
    // errors of the gltf crate itself (JSON syntax) land in the same variant
    assert!(matches!(
        parse(b"{ not json", MeshFormat::Gltf),
        Err(ReadErrorKind::Gltf(_))
    ));
    // a POSITION accessor that does not exist (the gltf crate's own validation
    // would index out of bounds), and a schema error (POSITION without min/max)
    let pts = base64(&f32_bytes(&[
        [0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
    ]));
    let doc = |accessor: &str, position: usize| {
        gltf_json(
            accessor,
            &format!(r#"{{"attributes":{{"POSITION":{position}}}}}"#),
            &format!(r#","uri":"data:application/octet-stream;base64,{pts}""#),
            36,
            r#"{"buffer":0,"byteLength":36}"#,
        )
    };
    let good = r#"{"bufferView":0,"componentType":5126,"count":3,"type":"VEC3","min":[0,0,0],"max":[1,1,0]}"#;
    assert_eq!(
        parse_ok(doc(good, 0).as_bytes(), MeshFormat::Gltf).num_faces(),
        1
    );
    let err = parse(doc(good, 7).as_bytes(), MeshFormat::Gltf).expect_err("no accessor 7");
    assert!(
        matches!(&err, ReadErrorKind::Gltf(m) if m.contains("accessor 7")),
        "{err}"
    );
    let no_min = r#"{"bufferView":0,"componentType":5126,"count":3,"type":"VEC3"}"#;
    let err = parse(doc(no_min, 0).as_bytes(), MeshFormat::Gltf).expect_err("no min/max");
    assert!(
        matches!(&err, ReadErrorKind::Gltf(m) if m.contains("schema") && m.contains("min")),
        "{err}"
    );
    // a GLB header with a length smaller than the header itself
    let mut bytes = glb("{}", &[]);
    bytes[8..12].copy_from_slice(&3u32.to_le_bytes());
    assert!(matches!(
        parse(&bytes, MeshFormat::Gltf),
        Err(ReadErrorKind::Binary { offset: 8, .. })
    ));
}

#[test]
fn mesh_errors_from_files() {
    let e = read_bad("empty_mesh.obj");
    assert!(matches!(
        e.kind(),
        ReadErrorKind::Mesh(MeshError::Empty {
            vertices: 3,
            faces: 0
        })
    ));
    let e = read_bad("index_out_of_range.off");
    assert!(matches!(
        e.kind(),
        ReadErrorKind::Mesh(MeshError::IndexOutOfRange {
            face: 0,
            index: 3,
            num_vertices: 3
        })
    ));
    let e = read_bad("non_finite.off");
    assert!(
        matches!(e.kind(), ReadErrorKind::Mesh(MeshError::NonFinite { vertex: 1, coords }) if coords[1].is_nan())
    );
    let e = read_bad("repeated_vertex.off");
    assert!(matches!(
        e.kind(),
        ReadErrorKind::Mesh(MeshError::RepeatedVertex {
            face: 0,
            indices: [0, 1, 1]
        })
    ));
    // an index too large for u32 is reported as out of range, not truncated
    let off = b"OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 4294967296\n";
    assert!(matches!(
        parse(off, MeshFormat::Off),
        Err(ReadErrorKind::Mesh(MeshError::IndexOutOfRange {
            index: 4294967296,
            ..
        }))
    ));
    let obj = b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4294967297\n";
    let (line, message) = obj_syntax_error(obj);
    assert_eq!(line, 4);
    assert!(
        message.contains("vertex index 4294967297") && message.contains("only 3 vertices"),
        "{message}"
    );
}

#[test]
fn extension_dispatch_is_case_insensitive() {
    assert_eq!(MeshFormat::from_extension("OBJ"), Some(MeshFormat::Obj));
    assert_eq!(MeshFormat::from_extension("Off"), Some(MeshFormat::Off));
    assert_eq!(MeshFormat::from_extension("pLy"), Some(MeshFormat::Ply));
    assert_eq!(MeshFormat::from_extension("GLB"), Some(MeshFormat::Gltf));
    assert_eq!(MeshFormat::from_extension("gltf"), Some(MeshFormat::Gltf));
    assert_eq!(MeshFormat::from_extension("stl"), None);
    let dir = tempfile::tempdir().expect("tempdir");
    let src = bad_fixture("inconsistent_orientation.off");
    let upper = dir.path().join("MESH.OFF");
    std::fs::copy(&src, &upper).expect("copy");
    assert_eq!(
        mfm_meshio::read_mesh(&upper).expect("upper case extension"),
        mfm_meshio::read_mesh(&src).expect("fixture")
    );
}

#[test]
fn off_details() {
    // counts on the keyword line, comments, CRLF, COFF colors, a quad and a pentagon
    let text = b"COFF 6 2 0 # header\r\n\
        # a comment line\r\n\
        0 0 0 255 0 0 255\r\n1 0 0 0 255 0 255\r\n1 1 0 0 0 255 255\r\n0 1 0 1 1 1 1\r\n\
        \r\n2 2 0 1 1 1 1\r\n3 1 0 1 1 1 1\r\n\
        4 0 1 2 3 0.5 0.5 0.5\r\n5 1 4 5 3 2\r\n";
    let m = parse_ok(text, MeshFormat::Off);
    assert_eq!(m.num_vertices(), 6);
    assert_eq!(m.positions()[4], [2.0, 2.0, 0.0]);
    assert_eq!(
        m.faces(),
        &[[0, 1, 2], [0, 2, 3], [1, 4, 5], [1, 5, 3], [1, 3, 2]]
    );
    // 4D OFF and binary OFF are refused, not misread
    assert!(matches!(
        parse(b"4OFF\n1 1 0\n", MeshFormat::Off),
        Err(ReadErrorKind::Unsupported(_))
    ));
    assert!(matches!(
        parse(b"OFF BINARY\n", MeshFormat::Off),
        Err(ReadErrorKind::Unsupported(_))
    ));
    assert!(matches!(
        parse(b"OBJ\n", MeshFormat::Off),
        Err(ReadErrorKind::Syntax { line: 1, .. })
    ));
    assert!(matches!(
        parse(b"", MeshFormat::Off),
        Err(ReadErrorKind::Syntax { line: 1, .. })
    ));
    // (padded with a comment so that the byte-count guard does not fire first)
    let short = b"OFF\n3 1 0\n0 0 0 # padding padding\n1 0 0\n0 1 0\n";
    assert!(matches!(
        parse(short, MeshFormat::Off),
        Err(ReadErrorKind::Syntax { line: 5, message }) if message.contains("0 of 1 faces")
    ));
}

#[test]
fn obj_details() {
    let text = b"# comment\n\
        mtllib nothing.mtl\n\
        o first\n\
        v 0 0 0\nv 1 0 0 1.0\nv 1 1 0 0.1 0.2 0.3\nvt 0 0\nvn 0 0 1\n\
        g a\n\
        f 1/1/1 2/1/1 3//1\n\
        g b\n\
        usemtl stone\n\
        v 0 1 0\n\
        v 9 9 9\n\
        f -4 -2 \\\n  -3\n\
        l 1 2\n\
        f 1 3 4 2\n";
    let m = parse_ok(text, MeshFormat::Obj);
    // vertices in file order, the unused one (9 9 9) kept, groups not split
    assert_eq!(
        m.positions(),
        &[
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [1.0, 1.0, 0.0],
            [0.0, 1.0, 0.0],
            [9.0, 9.0, 9.0]
        ]
    );
    assert_eq!(m.faces(), &[[0, 1, 2], [1, 3, 2], [0, 2, 3], [0, 3, 1]]);
    // a relative index reaching before the first vertex
    assert!(matches!(
        parse(b"v 0 0 0\nf -1 -2 -3\n", MeshFormat::Obj),
        Err(ReadErrorKind::Syntax { line: 2, message }) if message.contains("-2")
    ));
    assert!(matches!(
        parse(b"v 0 0\n", MeshFormat::Obj),
        Err(ReadErrorKind::Syntax { line: 1, .. })
    ));
    assert!(matches!(
        parse(b"v 0 0 0 \\", MeshFormat::Obj),
        Err(ReadErrorKind::Syntax { line: 1, .. })
    ));
}

/// An OBJ error as `(line, message)`, checking that the message is one line.
fn obj_syntax_error(text: &[u8]) -> (usize, String) {
    match parse(text, MeshFormat::Obj) {
        Err(ReadErrorKind::Syntax { line, message }) => {
            assert!(!message.contains('\n'), "one line: {message}");
            (line, message)
        }
        other => panic!("expected a syntax error, got {other:?}"),
    }
}

#[test]
fn a_byte_order_mark_before_a_text_header_is_skipped() {
    let bom = "\u{feff}";
    let off = format!("{bom}OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n");
    let obj = format!("{bom}v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
    let ply = format!(
        "{bom}ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n\
         property float z\nelement face 1\nproperty list uchar int vertex_indices\n\
         end_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n"
    );
    for (text, format) in [
        (off, MeshFormat::Off),
        (obj, MeshFormat::Obj),
        (ply, MeshFormat::Ply),
    ] {
        let m = parse_ok(text.as_bytes(), format);
        assert_eq!(m.faces(), &[[0, 1, 2]], "{format:?}");
    }
}

#[test]
fn obj_errors_name_the_line_and_what_is_wrong() {
    let tri = "v 0 0 0\nv 1 0 0\nv 0 1 0\n";
    // a coordinate that is not a number: the vertex and the statement
    let (line, message) = obj_syntax_error(b"v 0 0 0\n# two\nv 1 zero 0\n");
    assert_eq!(line, 3);
    assert!(
        message.contains("vertex 1") && message.contains("`v 1 zero 0`"),
        "{message}"
    );
    // a corner that is not `i`, `i/t`, `i//n` or `i/t/n`
    for (corner, face) in [("2/x", 1), ("2/1/1/1", 1), ("two", 1)] {
        let text = format!("{tri}f 1 2 3\n\nf 1 {corner} 3\n");
        let (line, message) = obj_syntax_error(text.as_bytes());
        assert_eq!(line, 6, "{corner}");
        assert!(
            message.contains(&format!("`{corner}`")) && message.contains(&format!("face {face}")),
            "{message}"
        );
    }
    // a corner with texture and normal indices but no position index
    let (line, message) = obj_syntax_error(format!("{tri}f 1 //1 3\n").as_bytes());
    assert_eq!(line, 4);
    assert!(message.contains("`//1`"), "{message}");
    // a relative index too large for any integer type
    let (line, _) = obj_syntax_error(format!("{tri}f 1 2 -99999999999999999999\n").as_bytes());
    assert_eq!(line, 4);
    // the line of a continued statement is the line it starts on
    let (line, message) = obj_syntax_error(format!("{tri}f 1 \\\n 2 \\\n 0\n").as_bytes());
    assert_eq!(line, 4);
    assert!(message.contains("start at 1"), "{message}");
    // an index past the last vertex: its line, and the index as written
    // (OBJ counts from 1), not the 0-based one of the mesh
    let text = format!("{tri}v 1 1 0\nv 2 2 0\nf 1 2 3\nf 1 2 3 9 4\n");
    let (line, message) = obj_syntax_error(text.as_bytes());
    assert_eq!(line, 7);
    assert!(
        message.contains("face 1 (corner 4) uses vertex index 9")
            && message.contains("only 5 vertices"),
        "{message}"
    );
    let (_, message) = obj_syntax_error(format!("{tri}f 1 2 5\n").as_bytes());
    assert!(
        message.contains("vertex index 5") && message.contains("1 to 3"),
        "{message}"
    );
    // faces of zero, one and two corners
    for (corners, arity) in [("", 0), (" 1", 1), (" 1 2", 2)] {
        let text = format!("{tri}f{corners}\n");
        assert!(
            matches!(
                parse(text.as_bytes(), MeshFormat::Obj),
                Err(ReadErrorKind::FaceArity { face: 0, arity: a, line: Some(4) }) if a == arity
            ),
            "{corners:?}"
        );
    }
}

#[test]
fn obj_leniency() {
    // inline comments, CRLF, tabs, a non-UTF-8 comment, a forward reference,
    // statements tobj would refuse but that carry nothing we read (a
    // one-component `vt`, `usemtl` without a name, five numbers on a `v`)
    let mut text = b"v 0 0 0 # origin\r\nf 1 2 3\r\n# caf\xe9\r\nvt 0.5\r\nusemtl\r\n".to_vec();
    text.extend_from_slice(b"v\t1 0 0 7 8\r\nv 0 1 0 0\r\n");
    let m = parse_ok(&text, MeshFormat::Obj);
    assert_eq!(
        m.positions(),
        &[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]
    );
    assert_eq!(m.faces(), &[[0, 1, 2]]);
    // texture indices are not followed (tobj 4.0.5 alone overflows on this
    // relative `vt` index reaching before the first one)
    let m = parse_ok(
        b"v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1/-4 2 3\n",
        MeshFormat::Obj,
    );
    assert_eq!(m.faces(), &[[0, 1, 2]]);
    // coordinates are parsed as f64, not f32
    let m = parse_ok(
        b"v 0.1 1e-300 123456789.12345679\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
        MeshFormat::Obj,
    );
    assert_eq!(m.positions()[0], [0.1, 1e-300, 123456789.12345679]);
}

/// The OBJ text of `mesh` written the awkward ways the reader must undo:
/// faces spread between the vertices (forward references included), random
/// relative indices and `/t`, `//n`, `/t/n` corners, groups, objects and
/// materials between faces, `vt`/`vn`/`l`/`s` statements, `w` and colors on
/// some vertices, comments, CRLF and `\` continuations.
fn awkward_obj(mesh: &TriMesh, seed: u64) -> String {
    use rand::{Rng, SeedableRng};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let nv = mesh.num_vertices();
    // the number of vertices defined before each face, non-decreasing
    let mut defined: Vec<usize> = (0..mesh.num_faces())
        .map(|_| rng.random_range(0..=nv))
        .collect();
    defined.sort_unstable();
    let mut out = String::new();
    let eol = |rng: &mut rand_chacha::ChaCha8Rng, out: &mut String| {
        out.push_str(if rng.random_bool(0.3) { "\r\n" } else { "\n" });
    };
    let mut next_face = 0;
    for v in 0..=nv {
        while next_face < defined.len() && defined[next_face] == v {
            for _ in 0..rng.random_range(0..3) {
                let filler = [
                    "g part",
                    "o thing",
                    "usemtl stone",
                    "s 1",
                    "vt 0.25 0.75",
                    "vn 0 0 1",
                    "l 1 2",
                    "# note",
                    "",
                    "mtllib none.mtl",
                ];
                out.push_str(filler[rng.random_range(0..filler.len())]);
                eol(&mut rng, &mut out);
            }
            out.push('f');
            for &i in &mesh.faces()[next_face] {
                let i = i as usize;
                let index = if i < v && rng.random_bool(0.5) {
                    format!("-{}", v - i)
                } else {
                    format!("{}", i + 1)
                };
                let suffix = ["", "/1", "//1", "/1/1"][rng.random_range(0..4)];
                out.push_str(if rng.random_bool(0.1) { " \\\n " } else { " " });
                out.push_str(&index);
                out.push_str(suffix);
            }
            eol(&mut rng, &mut out);
            next_face += 1;
        }
        if let Some(p) = mesh.positions().get(v) {
            out.push_str(&format!("v {:?} {:?} {:?}", p[0], p[1], p[2]));
            out.push_str(match rng.random_range(0..5) {
                0 => " 2.5",
                1 => " 0.1 0.2 0.3",
                2 => " # a vertex",
                _ => "",
            });
            eol(&mut rng, &mut out);
        }
    }
    out
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig::with_cases(128))]

    /// Whatever the layout of the file, the mesh read is the one written:
    /// same vertices in the same order (bit for bit), same triangles.
    #[test]
    fn obj_reads_back_in_file_numbering(
        mesh in io_support::any_mesh(),
        seed in proptest::prelude::any::<u64>(),
    ) {
        let text = awkward_obj(&mesh, seed);
        let back = match parse(text.as_bytes(), MeshFormat::Obj) {
            Ok(m) => m,
            Err(e) => panic!("{e}\n{text}"),
        };
        let bits = |m: &TriMesh| -> Vec<u64> {
            m.positions().iter().flatten().map(|x| x.to_bits()).collect()
        };
        proptest::prop_assert_eq!(bits(&back), bits(&mesh));
        proptest::prop_assert_eq!(back.faces(), mesh.faces());
    }
}

fn ply_header(format: &str, vertex_props: &str, nv: usize, face_props: &str, nf: usize) -> String {
    format!(
        "ply\nformat {format} 1.0\ncomment test\nobj_info x\nelement vertex {nv}\n{vertex_props}element face {nf}\n{face_props}end_header\n"
    )
}

#[test]
fn ply_ascii_with_extra_properties_and_elements() {
    let header = "ply\nformat ascii 1.0\n\
        element vertex 4\nproperty float32 x\nproperty uchar red\nproperty double y\nproperty int z\nproperty list uchar float tex\nproperty short temp\n\
        element edge 2\nproperty int vertex1\nproperty int vertex2\n\
        element face 2\nproperty uchar flags\nproperty list uint8 uint32 vertex_index\nproperty list uchar float uv\n\
        end_header\n";
    let body = "0 255 0 0 2 0.5 0.5 -3\n1 0 0 0 0 7\n1 1 1 0 1 0.25 12\n0 2 1 0 0 -32768\n\
        0 1\n1 2\n\
        9 4 0 1 2 3 0\n9 3 0 2 1 2 0.5 0.5\n";
    let bytes = format!("{header}{body}");
    let (mesh, scalars) =
        mfm_meshio::read_mesh_with_scalars_from_bytes(bytes.as_bytes(), MeshFormat::Ply)
            .expect("valid ascii ply");
    assert_eq!(
        mesh.positions(),
        &[
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [1.0, 1.0, 0.0],
            [0.0, 1.0, 0.0]
        ]
    );
    assert_eq!(mesh.faces(), &[[0, 1, 2], [0, 2, 3], [0, 2, 1]]);
    assert_eq!(scalars.len(), 2);
    assert_eq!(scalars[0], ("red".to_string(), vec![255.0, 0.0, 1.0, 2.0]));
    assert_eq!(
        scalars[1],
        ("temp".to_string(), vec![-3.0, 7.0, 12.0, -32768.0])
    );
    // a value out of range for its declared type is an error, not wrapped
    let bad = bytes.replace("0 255 0 0", "0 256 0 0");
    assert!(matches!(
        parse(bad.as_bytes(), MeshFormat::Ply),
        Err(ReadErrorKind::Syntax { line: 18, message }) if message.contains("0..=255")
    ));
}

#[test]
fn ply_binary_both_endians_all_types() {
    // x as int8, y as uint16, z as float, an ignored double, faces with int16 counts and uint8 indices
    for big in [false, true] {
        let fmt = if big {
            "binary_big_endian"
        } else {
            "binary_little_endian"
        };
        let header = ply_header(
            fmt,
            "property char x\nproperty ushort y\nproperty float z\nproperty float64 w\n",
            4,
            "property list short uchar vertex_indices\nproperty int id\n",
            1,
        );
        let mut body = Vec::new();
        let vertices: [(i8, u16, f32, f64); 4] = [
            (-1, 0, 0.5, 1.0),
            (1, 0, 0.5, 2.0),
            (1, 65535, 0.5, 3.0),
            (-128, 2, -0.25, 4.0),
        ];
        for (x, y, z, w) in vertices {
            body.push(x as u8);
            body.extend(if big {
                y.to_be_bytes()
            } else {
                y.to_le_bytes()
            });
            body.extend(if big {
                z.to_be_bytes()
            } else {
                z.to_le_bytes()
            });
            body.extend(if big {
                w.to_be_bytes()
            } else {
                w.to_le_bytes()
            });
        }
        body.extend(if big {
            4i16.to_be_bytes()
        } else {
            4i16.to_le_bytes()
        });
        body.extend([0u8, 1, 2, 3]);
        body.extend(if big {
            77i32.to_be_bytes()
        } else {
            77i32.to_le_bytes()
        });
        let bytes = [header.as_bytes(), &body].concat();
        let (mesh, scalars) =
            mfm_meshio::read_mesh_with_scalars_from_bytes(&bytes, MeshFormat::Ply)
                .expect("valid binary ply");
        assert_eq!(
            mesh.positions(),
            &[
                [-1.0, 0.0, 0.5],
                [1.0, 0.0, 0.5],
                [1.0, 65535.0, 0.5],
                [-128.0, 2.0, -0.25]
            ],
            "{fmt}"
        );
        assert_eq!(mesh.faces(), &[[0, 1, 2], [0, 2, 3]]);
        assert_eq!(scalars, vec![("w".to_string(), vec![1.0, 2.0, 3.0, 4.0])]);
        // every strict prefix of a binary file is an error (never a shorter mesh)
        for cut in 0..bytes.len() {
            assert!(
                parse(&bytes[..cut], MeshFormat::Ply).is_err(),
                "{fmt} prefix {cut}"
            );
        }
    }
}

#[test]
fn ply_header_errors() {
    let v = "property float x\nproperty float y\nproperty float z\n";
    let f = "property list uchar int vertex_indices\n";
    let cases: Vec<(String, usize, &str)> = vec![
        ("PLY\n".into(), 1, "`ply`"),
        (
            "ply\nformat ascii 1.0\nelement vertex 1\n".into(),
            4,
            "end_header",
        ),
        (ply_header("binary_middle_endian", v, 3, f, 1), 2, "format"),
        (
            "ply\nformat ascii 1.0\nproperty float x\nend_header\n".into(),
            3,
            "before any `element`",
        ),
        (
            ply_header("ascii", "property float x\nproperty float y\n", 3, f, 1),
            5,
            "no scalar property `z`",
        ),
        (
            ply_header(
                "ascii",
                v,
                3,
                "property list uchar float vertex_indices\n",
                1,
            ),
            10,
            "list of integers",
        ),
        (
            ply_header("ascii", v, 3, "property list float int vertex_indices\n", 1),
            10,
            "count type",
        ),
        (
            ply_header("ascii", v, 3, "property int vertex_indices_typo\n", 1),
            9,
            "no `vertex_indices`",
        ),
        (
            ply_header("ascii", "property decimal x\n", 3, f, 1),
            6,
            "`decimal`",
        ),
        (
            "ply\nformat ascii 1.0\nelement vertex -3\n".into(),
            3,
            "count of element `vertex`",
        ),
        ("ply\nformat ascii 1.0\nnonsense\n".into(), 3, "`nonsense`"),
        ("ply\nend_header\n".into(), 2, "`format`"),
        (
            "ply\nformat ascii 1.0\nelement face 0\nend_header\n".into(),
            4,
            "no `vertex` element",
        ),
    ];
    for (text, line, needle) in cases {
        match parse(text.as_bytes(), MeshFormat::Ply) {
            Err(ReadErrorKind::Syntax { line: l, message }) => {
                assert_eq!(l, line, "{text:?}: {message}");
                assert!(
                    message.contains(needle),
                    "{text:?}: `{message}` lacks `{needle}`"
                );
            }
            other => panic!("{text:?}: expected a syntax error, got {other:?}"),
        }
    }
}

fn gltf_json(
    accessors: &str,
    primitives: &str,
    buffer: &str,
    buffer_len: usize,
    views: &str,
) -> String {
    format!(
        r#"{{"asset":{{"version":"2.0"}},"buffers":[{{"byteLength":{buffer_len}{buffer}}}],"bufferViews":[{views}],"accessors":[{accessors}],"meshes":[{{"primitives":[{primitives}]}}]}}"#
    )
}

#[test]
fn glb_with_two_primitives_strip_and_u16_indices() {
    // positions: 4 points (48 bytes), then u16 indices 0 1 2 3 (8 bytes), packed in one BIN chunk
    let pts = [
        [0.0f32, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [1.0, 1.0, 0.5],
    ];
    let mut bin = f32_bytes(&pts);
    for i in [0u16, 1, 2, 3] {
        bin.extend(i.to_le_bytes());
    }
    let json = gltf_json(
        r#"{"bufferView":0,"componentType":5126,"count":4,"type":"VEC3","min":[0,0,0],"max":[1,1,1]},{"bufferView":1,"componentType":5123,"count":4,"type":"SCALAR"}"#,
        r#"{"attributes":{"POSITION":0},"indices":1,"mode":5},{"attributes":{"POSITION":0},"indices":1,"mode":4}"#,
        "",
        56,
        r#"{"buffer":0,"byteLength":48},{"buffer":0,"byteOffset":48,"byteLength":8}"#,
    );
    // second primitive: mode 4 with 4 indices is not a multiple of 3 -> error
    let err = parse(&glb(&json, &bin), MeshFormat::Gltf).expect_err("4 indices");
    assert!(
        matches!(&err, ReadErrorKind::Gltf(m) if m.contains("multiple of 3")),
        "{err}"
    );
    // with 3 indices in the second primitive it reads: a strip of 2 triangles, then a triangle
    let json = json.replacen(r#""count":4,"type":"SCALAR""#, r#""count":4,"type":"SCALAR"},{"bufferView":1,"componentType":5123,"count":3,"type":"SCALAR""#, 1)
        .replacen(r#""indices":1,"mode":4"#, r#""indices":2,"mode":4"#, 1);
    let m = parse_ok(&glb(&json, &bin), MeshFormat::Gltf);
    assert_eq!(
        m.num_vertices(),
        8,
        "each primitive brings its own vertices"
    );
    assert_eq!(m.positions()[7], [1.0, 1.0, 0.5]);
    // strip 0 1 2 3 -> (0 1 2), (2 1 3) keeping the winding; then (4 5 6)
    assert_eq!(m.faces(), &[[0, 1, 2], [2, 1, 3], [4, 5, 6]]);
}

#[test]
fn gltf_data_uri_fan_and_external_buffers() {
    let pts = [
        [0.0f32, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [1.0, 1.0, 0.0],
        [0.0, 1.0, 0.0],
    ];
    let bin = f32_bytes(&pts);
    let accessor = r#"{"bufferView":0,"componentType":5126,"count":4,"type":"VEC3","min":[0,0,0],"max":[1,1,1]}"#;
    let fan = r#"{"attributes":{"POSITION":0},"mode":6}"#;
    let views = r#"{"buffer":0,"byteLength":48}"#;
    let uri = format!(
        r#","uri":"data:application/octet-stream;base64,{}""#,
        base64(&bin)
    );
    let json = gltf_json(accessor, fan, &uri, 48, views);
    let m = parse_ok(json.as_bytes(), MeshFormat::Gltf);
    assert_eq!(m.faces(), &[[0, 1, 2], [0, 2, 3]]);
    assert_eq!(m.positions()[2], [1.0, 1.0, 0.0]);

    // an external buffer file: fine from disk, refused in memory
    let dir = tempfile::tempdir().expect("tempdir");
    std::fs::write(dir.path().join("my data.bin"), &bin).expect("write bin");
    let json = gltf_json(accessor, fan, r#","uri":"my%20data.bin""#, 48, views);
    let path = dir.path().join("mesh.gltf");
    std::fs::write(&path, &json).expect("write gltf");
    assert_eq!(mfm_meshio::read_mesh(&path).expect("external buffer"), m);
    assert!(matches!(
        parse(json.as_bytes(), MeshFormat::Gltf),
        Err(ReadErrorKind::Unsupported(msg)) if msg.contains("my data.bin")
    ));
    // a buffer file is read from the glTF file's folder only, never past
    // its declared length, and only from a regular file
    let outside = tempfile::tempdir().expect("tempdir");
    std::fs::write(outside.path().join("secret.bin"), &bin).expect("write");
    let escaping = format!(
        r#","uri":"../{}/secret.bin""#,
        outside
            .path()
            .file_name()
            .expect("a temporary folder has a name")
            .to_string_lossy()
    );
    let sub = dir.path().join("sub");
    std::fs::create_dir(&sub).expect("mkdir");
    std::fs::write(sub.join("data.bin"), &bin).expect("write bin");
    for (uri, needle) in [
        (escaping.as_str(), "outside the glTF file's folder"),
        (
            r#","uri":"file:///etc/passwd""#,
            "outside the glTF file's folder",
        ),
        (r#","uri":"sub/data.bin""#, ""),
    ] {
        let json = gltf_json(accessor, fan, uri, 48, views);
        std::fs::write(&path, &json).expect("write gltf");
        let read = mfm_meshio::read_mesh(&path);
        if needle.is_empty() {
            assert_eq!(read.expect("a buffer in a subfolder"), m);
        } else {
            let e = read.expect_err(uri);
            assert!(e.to_string().contains(needle), "{uri}: {e}");
        }
    }
    std::fs::write(
        dir.path().join("long.bin"),
        [bin.clone(), vec![0u8; 64]].concat(),
    )
    .expect("write bin");
    let json = gltf_json(accessor, fan, r#","uri":"long.bin""#, 48, views);
    std::fs::write(&path, &json).expect("write gltf");
    let e = mfm_meshio::read_mesh(&path).expect_err("longer than declared");
    assert!(
        e.to_string()
            .contains("holds 112 bytes but the buffer declares 48"),
        "{e}"
    );
    #[cfg(unix)]
    {
        std::os::unix::fs::symlink("/dev/zero", dir.path().join("zero.bin")).expect("link");
        let json = gltf_json(accessor, fan, r#","uri":"zero.bin""#, 48, views);
        std::fs::write(&path, &json).expect("write gltf");
        let e = mfm_meshio::read_mesh(&path).expect_err("a device");
        assert!(e.to_string().contains("a device"), "{e}");
    }
    // a malformed percent escape is an error, not a panic
    let json = gltf_json(accessor, fan, r#","uri":"%FF%FE.bin""#, 48, views);
    std::fs::write(&path, &json).expect("write gltf");
    assert!(matches!(
        mfm_meshio::read_mesh(&path).map_err(ReadError::into_kind),
        Err(ReadErrorKind::Gltf(_))
    ));
    // a normalized u8 accessor reads as [0, 1]
    let json = gltf_json(
        r#"{"bufferView":0,"componentType":5121,"normalized":true,"count":3,"type":"VEC3","min":[0,0,0],"max":[1,1,1]}"#,
        r#"{"attributes":{"POSITION":0}}"#,
        &format!(
            r#","uri":"data:application/octet-stream;base64,{}""#,
            base64(&[0, 0, 0, 255, 0, 0, 0, 51, 0])
        ),
        9,
        r#"{"buffer":0,"byteLength":9}"#,
    );
    let m = parse_ok(json.as_bytes(), MeshFormat::Gltf);
    assert_eq!(
        m.positions(),
        &[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.2, 0.0]]
    );
}

fn shared(name: &str) -> Option<PathBuf> {
    test_support::shared_mesh(name)
}

#[test]
fn shared_meshes_have_the_documented_sizes() {
    for (name, v, f) in [
        ("bunny.off", 3485, 6966),
        ("camel_b.obj", 2032, 3576),
        ("3holes.off", 3596, 7200),
        ("fertility.off", 4494, 9000),
        ("elephant.obj", 6034, 12064),
    ] {
        let Some(path) = shared(name) else { continue };
        let m = mfm_meshio::read_mesh(&path).expect("shared mesh reads");
        assert_eq!((m.num_vertices(), m.num_faces()), (v, f), "{name}");
    }
}

/// Reads files with libigl (`igl.read_triangle_mesh`) and returns, per file,
/// its positions and faces as written by numpy (`<f8`, `<i8`).
fn igl_read(python: &Path, files: &[PathBuf], out: &Path) -> Vec<(Vec<f64>, Vec<i64>)> {
    let script = r#"
import sys, igl, numpy as np
out = sys.argv[1]
for i, p in enumerate(sys.argv[2:]):
    v, f = igl.read_triangle_mesh(p)
    np.ascontiguousarray(v, dtype='<f8').tofile(f"{out}/{i}.v")
    np.ascontiguousarray(f, dtype='<i8').tofile(f"{out}/{i}.f")
"#;
    let status = std::process::Command::new(python)
        .arg("-c")
        .arg(script)
        .arg(out)
        .args(files)
        .status()
        .expect("python runs");
    assert!(status.success(), "the libigl oracle failed");
    (0..files.len())
        .map(|i| {
            let v = std::fs::read(out.join(format!("{i}.v"))).expect("v");
            let f = std::fs::read(out.join(format!("{i}.f"))).expect("f");
            (
                v.chunks_exact(8)
                    .map(|c| f64::from_le_bytes(c.try_into().expect("8 bytes")))
                    .collect(),
                f.chunks_exact(8)
                    .map(|c| i64::from_le_bytes(c.try_into().expect("8 bytes")))
                    .collect(),
            )
        })
        .collect()
}

#[test]
fn readers_and_ply_writer_agree_with_libigl() {
    let Some(python) = test_support::python_oracle() else {
        return;
    };
    let names = ["bunny.off", "camel_b.obj", "elephant.obj", "fertility.off"];
    let mut files: Vec<PathBuf> = Vec::new();
    for name in names {
        match shared(name) {
            Some(p) => files.push(p),
            None => return,
        }
    }
    let dir = tempfile::tempdir().expect("tempdir");
    // our own PLY output (binary and ascii) must read back identically in libigl
    let bunny = mfm_meshio::read_mesh(&files[0]).expect("bunny");
    let field: Vec<f64> = bunny.positions().iter().map(|p| p[0] * p[1]).collect();
    let bin = dir.path().join("bunny_bin.ply");
    let asc = dir.path().join("bunny_ascii.ply");
    mfm_meshio::write_ply(&bin, &bunny, &[("field", &field)]).expect("write binary");
    mfm_meshio::write_ply_with(
        &asc,
        &bunny,
        &[("field", &field)],
        mfm_meshio::PlyEncoding::Ascii,
    )
    .expect("write ascii");
    files.push(bin);
    files.push(asc);
    let oracle = igl_read(&python, &files, dir.path());
    for (path, (v, f)) in files.iter().zip(oracle) {
        let m = mfm_meshio::read_mesh(path).expect("reads");
        let ours_v: Vec<u64> = m
            .positions()
            .iter()
            .flatten()
            .map(|x| x.to_bits())
            .collect();
        let igl_v: Vec<u64> = v.iter().map(|x| x.to_bits()).collect();
        assert_eq!(ours_v.len(), igl_v.len(), "{}", path.display());
        assert!(
            ours_v == igl_v,
            "{}: positions differ from libigl",
            path.display()
        );
        let ours_f: Vec<i64> = m.faces().iter().flatten().map(|&i| i64::from(i)).collect();
        assert!(ours_f == f, "{}: faces differ from libigl", path.display());
    }
}

#[test]
#[allow(clippy::unwrap_used)]
fn data_after_the_declared_elements_is_an_error() {
    let mesh = mfm_geometry::procedural::icosphere(0);
    for encoding in [
        mfm_meshio::PlyEncoding::Ascii,
        mfm_meshio::PlyEncoding::BinaryLittleEndian,
        mfm_meshio::PlyEncoding::BinaryBigEndian,
    ] {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("t.ply");
        mfm_meshio::write_ply_with(&path, &mesh, &[], encoding).unwrap();
        let bytes = std::fs::read(&path).unwrap();
        // a trailing newline is not data
        let mut newline = bytes.clone();
        newline.extend_from_slice(b"\n");
        assert_eq!(
            mfm_meshio::read_mesh_from_bytes(&newline, MeshFormat::Ply).unwrap(),
            mesh
        );
        // an extra face (the header says 4) is
        let mut extra = bytes.clone();
        extra.extend_from_slice(match encoding {
            mfm_meshio::PlyEncoding::Ascii => b"3 0 1 2\n".as_slice(),
            _ => &[3, 0, 0, 0, 0, 0, 0, 0, 1, 0, 0, 0, 2],
        });
        let e = mfm_meshio::read_mesh_from_bytes(&extra, MeshFormat::Ply).unwrap_err();
        assert!(
            e.to_string()
                .contains("after the last element the header declares"),
            "{encoding:?}: {e}"
        );
    }
    let off = b"OFF\n4 4 0\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 1 2\n3 0 3 1\n3 0 2 3\n3 1 3 2\n";
    assert!(mfm_meshio::read_mesh_from_bytes(off, MeshFormat::Off).is_ok());
    let mut extra = off.to_vec();
    extra.extend_from_slice(b"# a comment is fine\n3 0 1 3\n");
    let e = mfm_meshio::read_mesh_from_bytes(&extra, MeshFormat::Off).unwrap_err();
    assert!(
        e.to_string()
            .contains("line 12: found `3` after the 4 vertices and 4 faces"),
        "{e}"
    );
}

#[test]
#[allow(clippy::unwrap_used)]
fn an_obj_that_is_not_text_says_so() {
    let noise: Vec<u8> = (0..5000u32)
        .map(|i| (i.wrapping_mul(2654435761) >> 11) as u8)
        .collect();
    let e = mfm_meshio::read_mesh_from_bytes(&noise, MeshFormat::Obj).unwrap_err();
    assert!(e.to_string().contains("not an OBJ file"), "{e}");
    let e = mfm_meshio::read_mesh_from_bytes(b"hello world\nthis is prose\n", MeshFormat::Obj)
        .unwrap_err();
    assert!(e.to_string().contains("line 1: not an OBJ file"), "{e}");
    // comments and groups before the first vertex are OBJ
    let ok = b"# made by hand\nmtllib a.mtl\no thing\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n";
    assert_eq!(
        mfm_meshio::read_mesh_from_bytes(ok, MeshFormat::Obj)
            .unwrap()
            .num_faces(),
        1
    );
}
