//! No parser panics, whatever the bytes: random bytes, random bytes after a
//! plausible header, random mutations of valid files of every format, and
//! glTF documents with random accessor layouts. (A panic fails the test.)

mod io_support;

use io_support::{any_mesh, base64, f32_bytes, glb};
use mfm_meshio::{MeshFormat, PlyEncoding};
use proptest::prelude::*;

const FORMATS: [MeshFormat; 4] = [
    MeshFormat::Obj,
    MeshFormat::Off,
    MeshFormat::Ply,
    MeshFormat::Gltf,
];

/// Parses with every reader; when one succeeds, the mesh is consistent.
fn parse_all(bytes: &[u8]) {
    for format in FORMATS {
        if let Ok((mesh, scalars)) = mfm_meshio::read_mesh_with_scalars_from_bytes(bytes, format) {
            let n = mesh.num_vertices();
            assert!(mesh.faces().iter().flatten().all(|&i| (i as usize) < n));
            // every element costs at least a byte of input: nothing was
            // allocated from a count the file could not back
            assert!(
                n <= bytes.len() && mesh.num_faces() <= bytes.len(),
                "{format}"
            );
            assert!(scalars.iter().all(|(_, s)| s.len() == n));
        }
    }
}

/// Text made of the characters the text formats care about.
fn texty() -> impl Strategy<Value = Vec<u8>> {
    prop::collection::vec(
        prop::sample::select(b"0123456789 -+.eE\n\r\t#/\\vfnaiOFplyx".to_vec()),
        0..400,
    )
}

#[derive(Clone, Debug)]
enum Mutation {
    Flip(usize, u8),
    Insert(usize, Vec<u8>),
    Delete(usize, usize),
    Truncate(usize),
    /// Overwrite 4 bytes with a chosen little-endian u32 (counts, lengths).
    Word(usize, u32),
    /// Replace a digit by a long run of nines (huge numbers in text).
    Nines(usize),
}

fn mutation() -> impl Strategy<Value = Mutation> {
    // positions favour the first bytes, where headers and counts live
    let pos = prop_oneof![0usize..40, any::<usize>()];
    let word = prop_oneof![
        Just(0u32),
        Just(1),
        Just(3),
        Just(u32::MAX),
        Just(0x7fff_ffff),
        any::<u32>()
    ];
    prop_oneof![
        (pos.clone(), any::<u8>()).prop_map(|(p, b)| Mutation::Flip(p, b)),
        (pos.clone(), prop::collection::vec(any::<u8>(), 1..8))
            .prop_map(|(p, b)| Mutation::Insert(p, b)),
        (pos.clone(), 1usize..16).prop_map(|(p, n)| Mutation::Delete(p, n)),
        pos.clone().prop_map(Mutation::Truncate),
        (pos.clone(), word).prop_map(|(p, w)| Mutation::Word(p, w)),
        pos.prop_map(Mutation::Nines),
    ]
}

fn apply(bytes: &mut Vec<u8>, m: &Mutation) {
    if bytes.is_empty() {
        return;
    }
    let at = |p: usize, len: usize| p % len;
    match m {
        Mutation::Flip(p, b) => {
            let i = at(*p, bytes.len());
            bytes[i] ^= b | 1;
        }
        Mutation::Insert(p, b) => {
            let i = at(*p, bytes.len() + 1);
            bytes.splice(i..i, b.iter().copied());
        }
        Mutation::Delete(p, n) => {
            let i = at(*p, bytes.len());
            let j = (i + n).min(bytes.len());
            bytes.drain(i..j);
        }
        Mutation::Truncate(p) => {
            let i = at(*p, bytes.len());
            bytes.truncate(i);
        }
        Mutation::Word(p, w) => {
            if bytes.len() >= 4 {
                let i = at(*p, bytes.len() - 3);
                bytes[i..i + 4].copy_from_slice(&w.to_le_bytes());
            }
        }
        Mutation::Nines(p) => {
            if let Some(i) = (0..bytes.len())
                .map(|k| (at(*p, bytes.len()) + k) % bytes.len())
                .find(|&k| bytes[k].is_ascii_digit())
            {
                bytes.splice(i..i + 1, std::iter::repeat_n(b'9', 25));
            }
        }
    }
}

/// Valid files of every format and encoding for `mesh`.
fn valid_files(mesh: &mfm_geometry::TriMesh) -> Vec<(MeshFormat, Vec<u8>)> {
    let dir = tempfile::tempdir().expect("tempdir");
    let s: Vec<f64> = mesh.positions().iter().map(|p| p[0]).collect();
    let mut out = Vec::new();
    for (k, enc) in [
        PlyEncoding::BinaryLittleEndian,
        PlyEncoding::BinaryBigEndian,
        PlyEncoding::Ascii,
    ]
    .into_iter()
    .enumerate()
    {
        let p = dir.path().join(format!("{k}.ply"));
        mfm_meshio::write_ply_with(&p, mesh, &[("s", &s)], enc).expect("write ply");
        out.push((MeshFormat::Ply, std::fs::read(&p).expect("read")));
    }
    let p = dir.path().join("m.obj");
    mfm_meshio::write_obj(&p, mesh).expect("write obj");
    out.push((MeshFormat::Obj, std::fs::read(&p).expect("read")));
    let mut off = format!(
        "OFF\n# comment\n{} {} 0\n",
        mesh.num_vertices(),
        mesh.num_faces()
    );
    for p in mesh.positions() {
        off += &format!("{} {} {}\n", p[0], p[1], p[2]);
    }
    for f in mesh.faces() {
        off += &format!("3 {} {} {}\n", f[0], f[1], f[2]);
    }
    out.push((MeshFormat::Off, off.into_bytes()));
    // glTF: f32 positions, u32 indices, as GLB and as JSON with a data URI
    let pts: Vec<[f32; 3]> = mesh
        .positions()
        .iter()
        .map(|p| {
            p.map(|c| {
                if (c as f32).is_finite() {
                    c as f32
                } else {
                    0.0
                }
            })
        })
        .collect();
    let mut bin = f32_bytes(&pts);
    let pos_len = bin.len();
    for &i in mesh.faces().iter().flatten() {
        bin.extend(i.to_le_bytes());
    }
    let json = |uri: &str| {
        format!(
            r#"{{"asset":{{"version":"2.0"}},"buffers":[{{"byteLength":{}{uri}}}],"bufferViews":[{{"buffer":0,"byteLength":{pos_len}}},{{"buffer":0,"byteOffset":{pos_len},"byteLength":{}}}],"accessors":[{{"bufferView":0,"componentType":5126,"count":{},"type":"VEC3","min":[0,0,0],"max":[1,1,1]}},{{"bufferView":1,"componentType":5125,"count":{},"type":"SCALAR"}}],"meshes":[{{"primitives":[{{"attributes":{{"POSITION":0}},"indices":1}}]}}]}}"#,
            bin.len(),
            bin.len() - pos_len,
            pts.len(),
            3 * mesh.num_faces()
        )
    };
    out.push((MeshFormat::Gltf, glb(&json(""), &bin)));
    let uri = format!(
        r#","uri":"data:application/octet-stream;base64,{}""#,
        base64(&bin)
    );
    out.push((MeshFormat::Gltf, json(&uri).into_bytes()));
    out
}

/// OBJ statements built to reach the corners of `tobj`'s parser: numbers at
/// the limits of `isize`, zero and relative indices, corners with up to four
/// `/` parts, `vt`/`vn` data that faces point into, colors and `w` on
/// vertices, `l` lines, empty `usemtl`, continuations. Most statements are
/// valid, so that whole files parse often enough to reach index resolution
/// (which `tobj` only does at the end of the file).
fn obj_statement() -> impl Strategy<Value = String> {
    let number = prop_oneof![
        12 => prop::sample::select(vec!["1", "2", "3", "-1", "-2", "0.5"]),
        2 => prop::sample::select(vec![
            "0",
            "+2",
            "-4",
            "9223372036854775807",
            "-9223372036854775808",
            "4294967297",
        ]),
        1 => prop::sample::select(vec!["", "x", "nan", "1e999", "1.5", "99999999999999999999"]),
    ];
    let corner = prop_oneof![
        2 => number.clone().prop_map(str::to_owned),
        3 => prop::collection::vec(number.clone(), 2..4).prop_map(|parts| parts.join("/")),
        1 => prop::collection::vec(number.clone(), 1..5).prop_map(|parts| parts.join("/")),
    ];
    let keyword = prop::sample::select(vec![
        "v", "v", "v", "f", "f", "f", "vt", "vn", "l", "p", "g", "o", "usemtl", "mtllib", "s", "#",
    ]);
    (
        keyword,
        prop_oneof![4 => 3usize..4, 1 => 0usize..8],
        prop::collection::vec(corner, 8),
        prop::collection::vec(number, 8),
        prop::sample::select(vec!["\n", "\n", "\r\n", " \\\n", " # c\n"]),
    )
        .prop_map(|(k, n, corners, numbers, end)| {
            let body = if k == "f" || k == "l" {
                corners[..n].join(" ")
            } else {
                numbers[..n].join(" ")
            };
            format!("{k} {body}{end}")
        })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    #[test]
    fn random_bytes_never_panic(bytes in prop::collection::vec(any::<u8>(), 0..600)) {
        parse_all(&bytes);
    }

    #[test]
    fn random_text_after_headers_never_panics(body in texty(), which in 0usize..6) {
        let head: &[u8] = match which {
            0 => b"OFF\n",
            1 => b"v 0 0 0\nv 1 0 0\nv 0 1 0\n",
            2 => b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n",
            3 => b"ply\nformat binary_little_endian 1.0\nelement vertex 2\nproperty double x\nproperty double y\nproperty double z\nproperty uchar c\nelement face 1\nproperty list uint uint vertex_indices\nend_header\n",
            4 => b"ply\nformat binary_big_endian 1.0\nelement junk 2\nproperty list int short stuff\nelement vertex 1\nproperty short x\nproperty short y\nproperty short z\nend_header\n",
            _ => b"glTF\x02\x00\x00\x00",
        };
        parse_all(&[head, &body].concat());
    }

    #[test]
    fn obj_statements_never_panic(
        head in any::<bool>(),
        statements in prop::collection::vec(obj_statement(), 0..16),
    ) {
        // a valid start, with texture coordinates and normals for faces to
        // point into (tobj 4.0.5 overflows on `f 1/-4 2 3` after one `vt`)
        let head = if head { "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvn 0 0 1\n" } else { "" };
        parse_all(format!("{head}{}", statements.concat()).as_bytes());
    }

    /// glTF with arbitrary accessor and view numbers: every combination must be
    /// read or refused, never read out of bounds.
    #[test]
    fn gltf_with_random_layouts_never_panics(
        count in prop_oneof![Just(0u64), 1u64..8, Just(u32::MAX as u64), Just(u64::MAX / 2)],
        acc_offset in prop_oneof![0u64..40, Just(u32::MAX as u64)],
        view_offset in 0u64..48,
        view_len in 0u64..64,
        stride in prop_oneof![Just(None), (0u64..40).prop_map(Some)],
        component in prop::sample::select(vec![5120u32, 5121, 5122, 5123, 5125, 5126, 5130, 1]),
        kind in prop::sample::select(vec!["SCALAR", "VEC2", "VEC3", "VEC4", "MAT4", "BOGUS"]),
        index_component in prop::sample::select(vec![5121u32, 5123, 5125, 5126]),
        mode in 0u32..8,
        normalized in any::<bool>(),
        bytes in prop::collection::vec(any::<u8>(), 0..64),
    ) {
        let stride = stride.map(|s| format!(r#","byteStride":{s}"#)).unwrap_or_default();
        let json = format!(
            r#"{{"asset":{{"version":"2.0"}},"buffers":[{{"byteLength":{}}}],"bufferViews":[{{"buffer":0,"byteOffset":{view_offset},"byteLength":{view_len}{stride}}}],"accessors":[{{"bufferView":0,"byteOffset":{acc_offset},"componentType":{component},"normalized":{normalized},"count":{count},"type":"{kind}","min":[0,0,0],"max":[1,1,1]}},{{"bufferView":0,"componentType":{index_component},"count":{count},"type":"SCALAR"}}],"meshes":[{{"primitives":[{{"attributes":{{"POSITION":0}},"indices":1,"mode":{mode}}}]}}]}}"#,
            bytes.len()
        );
        let file = glb(&json, &bytes);
        let _ = mfm_meshio::read_mesh_from_bytes(&file, MeshFormat::Gltf);
    }
}

proptest! {
    // 40 meshes x 7 files x 12 mutation sequences
    #![proptest_config(ProptestConfig::with_cases(40))]

    #[test]
    fn mutated_valid_files_never_panic(
        mesh in any_mesh(),
        sequences in prop::collection::vec(prop::collection::vec(mutation(), 1..4), 12),
    ) {
        // writing the files dominates the cost: mutate each one many ways
        for (format, bytes) in valid_files(&mesh) {
            // the unmutated file reads (the generator is right)
            prop_assert!(mfm_meshio::read_mesh_from_bytes(&bytes, format).is_ok(), "{format} unmutated");
            for sequence in &sequences {
                let mut bytes = bytes.clone();
                for m in sequence {
                    apply(&mut bytes, m);
                }
                parse_all(&bytes);
            }
        }
    }
}
