//! Wavefront OBJ reader and writer.
//!
//! Read: `v x y z [w | r g b]` lines (extra numbers ignored) and
//! `f c_1 c_2 ... c_n` lines whose corners are `i`, `i/t`, `i//n` or `i/t/n`;
//! only the position index `i` is used: 1-based, or negative for "relative to
//! the last vertex so far" (`-1` is the last one). Every other statement
//! (`vt`, `vn`, `g`, `o`, `s`, `usemtl`, `mtllib`, `l`, `p`, ...) is skipped.
//! `#` starts a comment and a trailing `\` continues a statement on the next
//! line. Vertices keep their file order, including those no face uses.

use super::text::{lines, parse_token, show, strip_comment, tokens};
use super::{Parsed, ReadErrorKind, fmt_f64, push_fan};
use crate::mesh::{MeshError, TriMesh};
use std::io::Write;

pub(crate) fn parse(bytes: &[u8]) -> Result<Parsed, ReadErrorKind> {
    let mut out = Parsed::default();
    let mut corners: Vec<u32> = Vec::new();
    let mut face_count = 0usize;
    // first face index that does not fit in u32: (triangle number, index)
    let mut too_large: Option<(usize, u64)> = None;
    // a statement continued over several lines with a trailing backslash
    let mut pending: Vec<u8> = Vec::new();
    let mut pending_line = 0usize;

    for (l, raw) in lines(bytes) {
        let text = strip_comment(raw).trim_ascii_end();
        if let Some(head) = text.strip_suffix(b"\\") {
            if pending.is_empty() {
                pending_line = l;
            }
            pending.extend_from_slice(head);
            pending.push(b' ');
            continue;
        }
        let (line, statement): (usize, &[u8]) = if pending.is_empty() {
            (l, text)
        } else {
            pending.extend_from_slice(text);
            (pending_line, &pending)
        };
        let mut t = tokens(statement);
        let keyword = t.next();
        match keyword {
            Some(b"v") => {
                let vertex = out.positions.len();
                let mut p = [0.0; 3];
                for (k, c) in p.iter_mut().enumerate() {
                    *c = parse_token(
                        t.next(),
                        &format!("coordinate {k} of vertex {vertex}"),
                        line,
                    )?;
                }
                out.positions.push(p);
            }
            Some(b"f") => {
                corners.clear();
                for token in t.by_ref() {
                    let index = corner_index(token, out.positions.len(), face_count, line)?;
                    let index = match u32::try_from(index) {
                        Ok(i) => i,
                        Err(_) => {
                            too_large.get_or_insert((out.faces.len(), index));
                            u32::MAX
                        }
                    };
                    corners.push(index);
                }
                if corners.len() < 3 {
                    return Err(ReadErrorKind::FaceArity {
                        face: face_count,
                        arity: corners.len(),
                        line: Some(line),
                    });
                }
                push_fan(&mut out.faces, &corners);
                face_count += 1;
            }
            _ => {}
        }
        drop(t);
        pending.clear();
    }
    if !pending.is_empty() {
        return Err(ReadErrorKind::Syntax {
            line: pending_line,
            message: "the file ends inside a statement continued with `\\`".into(),
        });
    }
    if let Some((face, index)) = too_large {
        return Err(ReadErrorKind::Mesh(MeshError::IndexOutOfRange {
            face,
            index,
            num_vertices: out.positions.len(),
        }));
    }
    Ok(out)
}

/// 0-based vertex index of one face corner (`i`, `i/t`, `i//n`, `i/t/n`).
fn corner_index(
    token: &[u8],
    defined: usize,
    face: usize,
    line: usize,
) -> Result<u64, ReadErrorKind> {
    let first = token.split(|&b| b == b'/').next().unwrap_or_default();
    let what = format!("a vertex index of face {face} (1-based, or negative to count back)");
    let raw: i64 = parse_token(Some(first), &what, line).map_err(|_| ReadErrorKind::Syntax {
        line,
        message: format!("expected {what}, found {}", show(token)),
    })?;
    if raw > 0 {
        Ok(raw as u64 - 1)
    } else if raw < 0 && raw.unsigned_abs() <= defined as u64 {
        Ok(defined as u64 - raw.unsigned_abs())
    } else if raw == 0 {
        Err(ReadErrorKind::Syntax {
            line,
            message: format!("face {face} uses vertex index 0; OBJ indices start at 1"),
        })
    } else {
        Err(ReadErrorKind::Syntax {
            line,
            message: format!(
                "face {face} uses relative index {raw}, but only {defined} vertices are defined before it"
            ),
        })
    }
}

pub(crate) fn write(w: &mut impl Write, mesh: &TriMesh) -> std::io::Result<()> {
    writeln!(
        w,
        "# written by mfm-geometry: {} vertices, {} faces",
        mesh.num_vertices(),
        mesh.num_faces()
    )?;
    for p in mesh.positions() {
        writeln!(w, "v {} {} {}", fmt_f64(p[0]), fmt_f64(p[1]), fmt_f64(p[2]))?;
    }
    for f in mesh.faces() {
        writeln!(
            w,
            "f {} {} {}",
            f[0] as u64 + 1,
            f[1] as u64 + 1,
            f[2] as u64 + 1
        )?;
    }
    Ok(())
}
