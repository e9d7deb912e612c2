//! mfm's PLY files, opened in pyvista (through the Python oracle environment).
//!
//! A mesh with two per-vertex scalar fields is written in every PLY encoding
//! by `mfm_meshio::write_ply_with`, then read in one Python process:
//! - `pyvista.read` (VTK's PLY reader, what pyvista and ParaView use): vertex
//!   count, face count, the triangles in order and the coordinates (VTK keeps
//!   them as `float32`).
//! - `load_ply` of `xtask/python/visual_check.py` (what `cargo xtask
//!   visual-check` renders): pyvista's mesh with the scalar fields attached.
//!   VTK's reader keeps only the vertex properties it knows (normals, colors,
//!   texture coordinates) and drops `property double NAME`, so `load_ply`
//!   reads those with numpy; the test checks their names, order and values
//!   bit for bit (mfm writes doubles that round-trip exactly).
//!
//! Only reading: no OpenGL context, so no display is needed. Skips with a
//! printed reason without the environment (fails under `MFM_REQUIRE_ORACLES=1`).

use std::process::Command;

use mfm_geometry::procedural;
use mfm_geometry::test_support::{python_oracle, workspace_root};
use mfm_meshio::PlyEncoding;
use serde_json::Value;

const SCRIPT: &str = r#"
import json, sys
import numpy as np
import pyvista as pv
sys.path.insert(0, sys.argv[1])
from visual_check import load_ply

out = []
for path in sys.argv[2:]:
    raw = pv.read(path)
    mesh = load_ply(path)
    bits = lambda a: np.ascontiguousarray(a, dtype=np.float64).view(np.uint64).tolist()
    out.append({
        "n_points": int(raw.n_points),
        "n_cells": int(raw.n_cells),
        "all_triangles": bool(raw.is_all_triangles),
        "faces": raw.faces.reshape(-1, 4)[:, 1:].tolist() if raw.n_cells else [],
        "points": np.asarray(raw.points, dtype=np.float64).ravel().tolist(),
        "vtk_arrays": list(raw.point_data.keys()),
        "vtk_bits": {n: bits(raw.point_data[n]) for n in raw.point_data.keys()
                     if raw.point_data[n].ndim == 1},
        "arrays": list(mesh.point_data.keys()),
        "bits": {n: bits(mesh.point_data[n]) for n in mesh.point_data.keys()},
        "point_bits": bits(np.asarray(mesh.points).ravel()),
    })
print(json.dumps(out))
"#;

fn bits(v: &Value) -> Vec<u64> {
    v.as_array()
        .expect("array of bits")
        .iter()
        .map(|b| b.as_u64().expect("u64 bits"))
        .collect()
}

/// Asserts that `got` holds the bit patterns of `want`, naming the first
/// differing entry (rather than printing both arrays).
fn assert_same_bits(got: &[u64], want: &[f64], what: &str) {
    assert_eq!(got.len(), want.len(), "{what}: number of values");
    let differ: Vec<usize> = (0..want.len())
        .filter(|&k| got[k] != want[k].to_bits())
        .collect();
    if let Some(&k) = differ.first() {
        panic!(
            "{what}: entry {k} is {:e}, expected {:e} ({} of {} entries differ)",
            f64::from_bits(got[k]),
            want[k],
            differ.len(),
            want.len()
        );
    }
}

#[test]
fn pyvista_reads_mfm_ply_geometry_and_scalars_in_every_encoding() {
    let Some(python) = python_oracle() else {
        return;
    };
    let mesh = procedural::icosphere(2);
    let v = mesh.num_vertices();
    // values that float32 would round, negative, tiny and huge ones
    let signal: Vec<f64> = mesh
        .positions()
        .iter()
        .enumerate()
        .map(|(i, p)| (3.0 * p[2]).sin() * 0.1 + 1e-9 * i as f64 - 0.3)
        .collect();
    let density: Vec<f64> = (0..v)
        .map(|i| match i % 3 {
            0 => 1.0 / (i as f64 + 3.0),
            1 => -1e300 / (i as f64 + 1.0),
            _ => 5e-324 * (i as f64),
        })
        .collect();
    let fields: [(&str, &[f64]); 2] = [("signal", &signal), ("gmm-density.v1", &density)];

    let dir = tempfile::tempdir().expect("temporary folder");
    let encodings = [
        ("ascii", PlyEncoding::Ascii),
        ("binary_le", PlyEncoding::BinaryLittleEndian),
        ("binary_be", PlyEncoding::BinaryBigEndian),
    ];
    let mut paths = Vec::new();
    for (name, encoding) in encodings {
        let path = dir.path().join(format!("sphere_{name}.ply"));
        mfm_meshio::write_ply_with(&path, &mesh, &fields, encoding).expect("write PLY");
        paths.push(path);
    }
    // the default writer is one of the above (binary little endian): check it too
    let default = dir.path().join("sphere_default.ply");
    mfm_meshio::write_ply(&default, &mesh, &fields).expect("write PLY");
    paths.push(default);

    let out = Command::new(&python)
        .arg("-c")
        .arg(SCRIPT)
        .arg(workspace_root().join("xtask/python"))
        .args(&paths)
        .output()
        .expect("run the oracle python");
    assert!(
        out.status.success(),
        "python failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let results: Vec<Value> = serde_json::from_slice(&out.stdout).expect("JSON from python");
    assert_eq!(results.len(), paths.len());

    for (path, r) in paths.iter().zip(&results) {
        let file = path.file_name().expect("file name").to_string_lossy();
        assert_eq!(
            r["n_points"].as_u64(),
            Some(v as u64),
            "{file}: vertex count"
        );
        assert_eq!(
            r["n_cells"].as_u64(),
            Some(mesh.num_faces() as u64),
            "{file}: face count"
        );
        assert_eq!(r["all_triangles"], Value::Bool(true), "{file}");
        let faces: Vec<[u32; 3]> = serde_json::from_value(r["faces"].clone()).expect("faces");
        assert_eq!(faces, mesh.faces(), "{file}: triangles in file order");
        let points: Vec<f64> = serde_json::from_value(r["points"].clone()).expect("points");
        for (k, (got, want)) in points
            .iter()
            .zip(mesh.positions().iter().flatten())
            .enumerate()
        {
            // VTK stores the coordinates as float32
            assert!(
                (got - want).abs() <= 1e-7 * want.abs().max(1.0),
                "{file}: coordinate {k}: {got} vs {want}"
            );
        }
        let exact: Vec<f64> = mesh.positions().iter().flatten().copied().collect();
        assert_same_bits(
            &bits(&r["point_bits"]),
            &exact,
            &format!("{file}: load_ply coordinates"),
        );

        let arrays: Vec<&str> = r["arrays"]
            .as_array()
            .expect("array names")
            .iter()
            .map(|a| a.as_str().expect("array name"))
            .collect();
        assert_eq!(arrays, ["signal", "gmm-density.v1"], "{file}: scalar names");
        for (name, values) in fields {
            assert_same_bits(
                &bits(&r["bits"][name]),
                values,
                &format!("{file}: values of `{name}`"),
            );
            // VTK's reader drops unknown vertex properties today; if a later
            // VTK keeps them, they must be the same numbers (up to float32)
            if let Some(vtk) = r["vtk_bits"].get(name) {
                let got: Vec<f64> = bits(vtk).into_iter().map(f64::from_bits).collect();
                assert_eq!(got.len(), v, "{file}: VTK's `{name}`");
                for (g, w) in got.iter().zip(values) {
                    assert_eq!(*g as f32, *w as f32, "{file}: VTK's `{name}`");
                }
            }
        }
    }
}
