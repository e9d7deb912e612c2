//! Which files an import reads: mesh files named one by one or found in
//! folders, in natural sort order.

use std::cmp::Ordering;
use std::path::{Path, PathBuf};

use mfm_meshio::MeshFormat;

use crate::error::{DataError, Result};

/// The mesh files of an import, in order, with what was passed over.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct MeshFileList {
    /// Every mesh file, in input order, each folder's files in natural
    /// sort order of their names ([`natural_cmp`]).
    pub files: Vec<PathBuf>,
    /// Entries of the input folders that are not mesh files (other
    /// extensions, subfolders, hidden files), skipped.
    pub skipped: Vec<PathBuf>,
}

/// Lists the mesh files of `inputs`: a file is taken as it is (it must have
/// a mesh extension, see [`MeshFormat::from_path`]); a folder gives its
/// mesh files (not its subfolders') in natural sort order. With `strict`,
/// a folder entry that is not a mesh file is an error instead of being
/// skipped.
///
/// Cost: one listing per folder, `O(n log n)` comparisons to sort it.
///
/// # Errors
/// [`DataError::Files`] (`Io`) for an input that does not exist or a
/// folder that cannot be listed; (`Format`) for a file that is not a mesh,
/// a folder without mesh files, or, with `strict`, a folder entry that is
/// not one; [`DataError::Config`] for no inputs.
///
/// # Example
/// ```
/// use mfm_data::import::inputs::list_mesh_files;
/// let dir = tempfile::tempdir().unwrap();
/// for name in ["10.obj", "2.obj", "notes.txt"] {
///     std::fs::write(dir.path().join(name), "").unwrap();
/// }
/// let list = list_mesh_files(&[dir.path().to_path_buf()], false).unwrap();
/// let names: Vec<_> = list.files.iter().map(|p| p.file_name().unwrap().to_owned()).collect();
/// assert_eq!(names, ["2.obj", "10.obj"]);
/// assert_eq!(list.skipped.len(), 1);
/// ```
pub fn list_mesh_files(inputs: &[PathBuf], strict: bool) -> Result<MeshFileList> {
    if inputs.is_empty() {
        return Err(DataError::Config(
            "no inputs: give mesh files or folders of them".into(),
        ));
    }
    let mut list = MeshFileList::default();
    for input in inputs {
        let meta = std::fs::metadata(input).map_err(|e| DataError::io(input, e))?;
        if meta.is_dir() {
            list_folder(input, strict, &mut list)?;
        } else if is_mesh_file(input) {
            list.files.push(input.clone());
        } else {
            return Err(DataError::format(
                input,
                "not a mesh file: expected .obj, .off, .ply, .gltf or .glb",
            ));
        }
    }
    Ok(list)
}

/// Whether `path` has a mesh file's extension.
fn is_mesh_file(path: &Path) -> bool {
    MeshFormat::from_path(path).is_some()
}

/// Appends the mesh files of the folder `dir`, naturally sorted.
fn list_folder(dir: &Path, strict: bool, list: &mut MeshFileList) -> Result<()> {
    let mut meshes = Vec::new();
    for entry in std::fs::read_dir(dir).map_err(|e| DataError::io(dir, e))? {
        let entry = entry.map_err(|e| DataError::io(dir, e))?;
        let path = entry.path();
        let hidden = entry.file_name().to_string_lossy().starts_with('.');
        let is_file = entry.file_type().is_ok_and(|t| !t.is_dir());
        if is_file && !hidden && is_mesh_file(&path) {
            meshes.push(path);
        } else if strict {
            return Err(DataError::format(
                &path,
                format!(
                    "not a mesh file in the input folder {} (--strict refuses anything but \
                     .obj, .off, .ply, .gltf and .glb files there)",
                    dir.display()
                ),
            ));
        } else {
            list.skipped.push(path);
        }
    }
    if meshes.is_empty() {
        return Err(DataError::format(
            dir,
            "the folder holds no mesh files (.obj, .off, .ply, .gltf, .glb)",
        ));
    }
    meshes.sort_by(|a, b| {
        let name = |p: &Path| p.file_name().map(|n| n.to_string_lossy().into_owned());
        natural_cmp(&name(a).unwrap_or_default(), &name(b).unwrap_or_default())
    });
    list.files.extend(meshes);
    Ok(())
}

/// Natural order of names: runs of ASCII digits compare as numbers
/// (`2 < 10`, leading zeros ignored, then the shorter run first), other
/// characters as they are; equal names by this rule fall back to plain
/// string order, so the order is total.
///
/// # Example
/// ```
/// use mfm_data::import::inputs::natural_cmp;
/// let mut names = vec!["frame10.obj", "frame2.obj", "frame02.obj", "Frame1.obj"];
/// names.sort_by(|a, b| natural_cmp(a, b));
/// assert_eq!(names, ["Frame1.obj", "frame2.obj", "frame02.obj", "frame10.obj"]);
/// ```
pub fn natural_cmp(a: &str, b: &str) -> Ordering {
    let (mut x, mut y) = (a.as_bytes(), b.as_bytes());
    loop {
        match (x.first(), y.first()) {
            (None, None) => return a.cmp(b),
            (None, Some(_)) => return Ordering::Less,
            (Some(_), None) => return Ordering::Greater,
            (Some(p), Some(q)) if p.is_ascii_digit() && q.is_ascii_digit() => {
                let (nx, rx) = digit_run(x);
                let (ny, ry) = digit_run(y);
                let (tx, ty) = (trim_zeros(nx), trim_zeros(ny));
                let by_value = tx.len().cmp(&ty.len()).then_with(|| tx.cmp(ty));
                let by_width = nx.len().cmp(&ny.len());
                match by_value.then(by_width) {
                    Ordering::Equal => (x, y) = (rx, ry),
                    other => return other,
                }
            }
            (Some(p), Some(q)) => {
                let order = p.to_ascii_lowercase().cmp(&q.to_ascii_lowercase());
                if order != Ordering::Equal {
                    return order;
                }
                (x, y) = (&x[1..], &y[1..]);
            }
        }
    }
}

/// The leading run of ASCII digits of `s`, and the rest.
fn digit_run(s: &[u8]) -> (&[u8], &[u8]) {
    let n = s.iter().take_while(|c| c.is_ascii_digit()).count();
    s.split_at(n)
}

/// `digits` without its leading zeros.
fn trim_zeros(digits: &[u8]) -> &[u8] {
    let n = digits.iter().take_while(|&&c| c == b'0').count();
    &digits[n..]
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::natural_cmp;
    use proptest::prelude::*;
    use std::cmp::Ordering;

    #[test]
    fn numbers_compare_by_value() {
        assert_eq!(natural_cmp("2.obj", "10.obj"), Ordering::Less);
        assert_eq!(natural_cmp("a9b", "a10a"), Ordering::Less);
        assert_eq!(natural_cmp("x", "x1"), Ordering::Less);
        assert_eq!(natural_cmp("frame_0099", "frame_100"), Ordering::Less);
        assert_eq!(natural_cmp("same", "same"), Ordering::Equal);
    }

    proptest! {
        #[test]
        fn natural_order_is_a_total_order(a in "[a-c0-9]{0,6}", b in "[a-c0-9]{0,6}", c in "[a-c0-9]{0,6}") {
            prop_assert_eq!(natural_cmp(&a, &b), natural_cmp(&b, &a).reverse());
            prop_assert_eq!(natural_cmp(&a, &b) == Ordering::Equal, a == b);
            if natural_cmp(&a, &b) != Ordering::Greater && natural_cmp(&b, &c) != Ordering::Greater {
                prop_assert_ne!(natural_cmp(&a, &c), Ordering::Greater);
            }
        }

        #[test]
        fn numbered_names_sort_by_number(i in 0u32..100_000, j in 0u32..100_000) {
            let (a, b) = (format!("shape{i}.obj"), format!("shape{j}.obj"));
            prop_assert_eq!(natural_cmp(&a, &b), i.cmp(&j));
        }
    }
}
