//! The authors' dataset files (the official code's `dataset.py`): a
//! `torch.save` dict with `src_verts`, `tar_verts` and `faces`, read with
//! [`mfm_torchfile`] (no Python; only tensors and plain containers are
//! built).
//!
//! | key | single source | arbitrary source |
//! |---|---|---|
//! | `src_verts` | `[V, 3]`, the template | `[N, V, 3]`, one source per pair |
//! | `tar_verts` | `[N, V, 3]`, the shapes | `[N, V, 3]`, one target per pair |
//! | `faces` | `[F, 3]` integer vertex indices | the same |

use std::path::Path;

use mfm_geometry::TriMesh;
use mfm_torchfile::{Checkpoint, Dtype, TensorData, Value};

use super::sources::ShapesInMemory;
use crate::error::{DataError, Result};

/// An authors' dataset file, read.
#[derive(Clone, Debug)]
pub struct AuthorsDataset {
    /// The template: `src_verts` (single source) or its first row
    /// (arbitrary source), with `faces`.
    pub template: TriMesh,
    /// The targets, `tar_verts`.
    pub targets: ShapesInMemory,
    /// The sources of an arbitrary-source file, one per target (`None`
    /// for a single-source file).
    pub sources: Option<ShapesInMemory>,
}

/// Reads the authors' dataset file at `path`.
///
/// Cost: the file's tensors in memory once, as `f32` (compared with the
/// memory available before each is read).
///
/// # Errors
/// [`DataError::Files`] (`NoMemory`) for a tensor larger than the memory
/// available;
/// [`DataError::Files`] (`Format`) naming the file and the key: not a
/// `torch.save` dict of tensors, a missing key, a tensor of the wrong rank,
/// dtype or shape, a face index out of range, or a mesh that cannot be
/// built from `src_verts` and `faces`.
pub fn read_authors_dataset(path: &Path) -> Result<AuthorsDataset> {
    let fail = |m: String| DataError::format(path, m);
    let mut file = Checkpoint::open(path).map_err(|e| fail(e.without_path()))?;
    let root = file.root().clone();
    if !matches!(root, Value::Dict(_)) {
        return Err(fail(format!(
            "holds a {}, expected a dict with src_verts, tar_verts and faces (the official \
             dataset.py's format)",
            root.kind()
        )));
    }
    let mut tensor = |key: &str| -> Result<TensorData> {
        match root.get(key) {
            Some(Value::Tensor(t)) => {
                // the record, its dense copy and the f32 values made of it
                mfm_files::space::ensure_memory(
                    &format!("{key} of {}", path.display()),
                    t.storage_numel as u128,
                    3 * t.dtype.size() as u128 + 4,
                )?;
                file.tensor(key, t).map_err(|e| fail(e.without_path()))
            }
            Some(other) => Err(fail(format!(
                "{key} is a {}, expected a tensor",
                other.kind()
            ))),
            None => Err(fail(format!(
                "has no {key:?} (expected src_verts, tar_verts and faces, the official dataset.py's keys)"
            ))),
        }
    };
    let src = tensor("src_verts")?;
    let tar = tensor("tar_verts")?;
    let faces = tensor("faces")?;
    let floats = |t: &TensorData, key: &str| {
        t.to_f32()
            .ok_or_else(|| fail(format!("{key} holds {:?} values, expected floats", t.dtype)))
    };
    let (n, v) = match tar.shape[..] {
        [n, v, 3] => (n, v),
        _ => {
            return Err(fail(format!(
                "tar_verts has shape {:?}, expected [N, V, 3]",
                tar.shape
            )));
        }
    };
    let paired = match src.shape[..] {
        [sv, 3] if sv == v => false,
        [sn, sv, 3] if sn == n && sv == v => true,
        _ => {
            return Err(fail(format!(
                "src_verts has shape {:?}, expected [{v}, 3] (single source) or [{n}, {v}, 3] \
                 (one source per target) to match tar_verts {:?}",
                src.shape, tar.shape
            )));
        }
    };
    let face_list = face_indices(&faces, v).map_err(fail)?;
    let src_values = floats(&src, "src_verts")?;
    let positions: Vec<[f64; 3]> = src_values[..3 * v]
        .chunks_exact(3)
        .map(|p| [p[0].into(), p[1].into(), p[2].into()])
        .collect();
    let template = TriMesh::new(positions, face_list)
        .map_err(|e| fail(format!("src_verts and faces do not make a mesh: {e}")))?;
    let name = |key: &str| format!("{}:{key}", path.display());
    Ok(AuthorsDataset {
        template,
        targets: ShapesInMemory {
            source: name("tar_verts"),
            values: floats(&tar, "tar_verts")?,
            vertices: v,
        },
        sources: paired.then(|| ShapesInMemory {
            source: name("src_verts"),
            values: src_values,
            vertices: v,
        }),
    })
}

/// `faces` as `[F, 3]` vertex indices below `v`.
fn face_indices(faces: &TensorData, v: usize) -> std::result::Result<Vec<[u32; 3]>, String> {
    let [_, 3] = faces.shape[..] else {
        return Err(format!(
            "faces has shape {:?}, expected [F, 3]",
            faces.shape
        ));
    };
    let b = &faces.bytes;
    let values: Vec<i64> = match faces.dtype {
        Dtype::I64 => b
            .chunks_exact(8)
            .map(|c| {
                let mut a = [0u8; 8];
                a.copy_from_slice(c);
                i64::from_le_bytes(a)
            })
            .collect(),
        Dtype::I32 => b
            .chunks_exact(4)
            .map(|c| i64::from(i32::from_le_bytes([c[0], c[1], c[2], c[3]])))
            .collect(),
        other => {
            return Err(format!(
                "faces holds {other:?} values, expected int64 or int32"
            ));
        }
    };
    let mut out = Vec::with_capacity(values.len() / 3);
    for (f, c) in values.chunks_exact(3).enumerate() {
        let mut face = [0u32; 3];
        for k in 0..3 {
            if !(0..v as i64).contains(&c[k]) {
                return Err(format!(
                    "faces[{f}] = {c:?}: index {} is not a vertex (there are {v})",
                    c[k]
                ));
            }
            face[k] = c[k] as u32;
        }
        out.push(face);
    }
    Ok(out)
}
