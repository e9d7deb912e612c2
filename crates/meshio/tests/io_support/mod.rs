//! Helpers shared by the `io_*` and `validate` test suites.
#![allow(dead_code)]

use mfm_geometry::TriMesh;
use proptest::prelude::*;
use std::path::PathBuf;

/// A file of `fixtures/bad` (hand-made defective meshes, one per error).
pub fn bad_fixture(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../fixtures/bad")
        .join(name)
}

/// A binary glTF container: 12-byte header, JSON chunk (space padded), and a
/// BIN chunk (zero padded) when `bin` is not empty.
pub fn glb(json: &str, bin: &[u8]) -> Vec<u8> {
    let mut j = json.as_bytes().to_vec();
    while j.len() % 4 != 0 {
        j.push(b' ');
    }
    let mut b = bin.to_vec();
    while b.len() % 4 != 0 {
        b.push(0);
    }
    let total = 12 + 8 + j.len() + if b.is_empty() { 0 } else { 8 + b.len() };
    let mut out = Vec::with_capacity(total);
    out.extend_from_slice(b"glTF");
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&(total as u32).to_le_bytes());
    out.extend_from_slice(&(j.len() as u32).to_le_bytes());
    out.extend_from_slice(b"JSON");
    out.extend_from_slice(&j);
    if !b.is_empty() {
        out.extend_from_slice(&(b.len() as u32).to_le_bytes());
        out.extend_from_slice(b"BIN\0");
        out.extend_from_slice(&b);
    }
    out
}

/// Little-endian `f32` bytes of points.
pub fn f32_bytes(points: &[[f32; 3]]) -> Vec<u8> {
    points
        .iter()
        .flat_map(|p| p.iter().flat_map(|c| c.to_le_bytes()))
        .collect()
}

/// Standard base64 (for glTF data URIs), written independently of the reader.
pub fn base64(bytes: &[u8]) -> String {
    const A: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut s = String::new();
    for chunk in bytes.chunks(3) {
        let n = chunk.len();
        let v = (u32::from(chunk[0]) << 16)
            | (u32::from(*chunk.get(1).unwrap_or(&0)) << 8)
            | u32::from(*chunk.get(2).unwrap_or(&0));
        for k in 0..4 {
            if k <= n {
                s.push(A[((v >> (18 - 6 * k)) & 63) as usize] as char);
            } else {
                s.push('=');
            }
        }
    }
    s
}

/// Coordinates including awkward values (signed zero, subnormals, extremes).
pub fn coordinate() -> impl Strategy<Value = f64> {
    prop_oneof![
        4 => -1e3..1e3f64,
        1 => prop::sample::select(vec![
            0.0,
            -0.0,
            5e-324,
            -2.2250738585072014e-308,
            1e-300,
            0.1,
            1.0 / 3.0,
            123456789.12345679,
            -1.7976931348623157e308,
            f64::MAX,
        ]),
        1 => any::<f64>().prop_filter("finite", |x| x.is_finite()),
    ]
}

/// Three distinct indices below `v` (`v >= 3`).
pub fn triangle(v: u32) -> impl Strategy<Value = [u32; 3]> {
    (0..v, 1..v, 0..v - 2).prop_map(move |(a, db, k)| {
        let b = (a + db) % v;
        let c = (0..v)
            .filter(|&x| x != a && x != b)
            .nth(k as usize)
            .unwrap_or(0);
        [a, b, c]
    })
}

/// Random valid `TriMesh`es (any connectivity, awkward coordinates), small.
pub fn any_mesh() -> impl Strategy<Value = TriMesh> {
    (3u32..30).prop_flat_map(|v| {
        (
            prop::collection::vec([coordinate(), coordinate(), coordinate()], v as usize),
            prop::collection::vec(triangle(v), 1..40),
        )
            .prop_map(|(p, f)| TriMesh::new(p, f).expect("generated meshes are valid"))
    })
}
