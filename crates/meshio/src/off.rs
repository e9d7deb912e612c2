//! OFF reader (Geomview "Object File Format", text).
//!
//! Layout: the keyword `OFF` (prefixes `ST`, `C`, `N` are accepted and their
//! extra per-vertex numbers ignored), the counts `V F [E]` (on the keyword line
//! or the next one), `V` vertex lines whose first three numbers are `x y z`,
//! then `F` face lines `n i_1 ... i_n [color...]` with 0-based indices.
//! `#` starts a comment; blank lines are skipped. Each vertex and each face
//! must be on one line; anything after the declared faces is an error (the
//! counts would be wrong). 4D/nD and binary OFF are rejected.

use super::text::{lines, parse_token, show, strip_comment, tokens};
use super::{Parsed, ReadErrorKind, push_fan};
use mfm_geometry::mesh::MeshError;

pub(crate) fn parse(bytes: &[u8]) -> Result<Parsed, ReadErrorKind> {
    let mut last_line = 1;
    let mut content = lines(bytes)
        .map(|(n, l)| (n, strip_comment(l)))
        .filter(|(_, l)| tokens(l).next().is_some());

    // header keyword
    let Some((line, header)) = content.next() else {
        return Err(ReadErrorKind::Syntax {
            line: last_line,
            message: "expected the `OFF` keyword, found an empty file".into(),
        });
    };
    last_line = line;
    let mut toks = tokens(header);
    let keyword = toks.next().unwrap_or_default();
    check_keyword(keyword, line)?;
    if let Some(t) = toks.clone().next() {
        if t.eq_ignore_ascii_case(b"BINARY") {
            return Err(ReadErrorKind::Unsupported("binary OFF".into()));
        }
    }

    // counts, on the keyword line or the next content line
    let (count_line, count_text, mut count_toks) = if toks.clone().next().is_some() {
        (line, header, toks)
    } else {
        let Some((l, text)) = content.next() else {
            return Err(ReadErrorKind::Syntax {
                line: last_line,
                message: "expected the counts `V F E`, found the end of the file".into(),
            });
        };
        last_line = l;
        (l, text, tokens(text))
    };
    let nv: u64 = parse_token(count_toks.next(), "the vertex count", count_line)?;
    let nf: u64 = parse_token(count_toks.next(), "the face count", count_line)?;

    // every vertex needs 3 numbers and every face 4, each at least one byte
    // plus a separator (except the very last): refuse impossible counts
    // before allocating anything
    let available = bytes.len().saturating_sub(end_offset(bytes, count_text));
    let avail = available as u128 + 1;
    if 6 * nv as u128 > avail {
        return Err(ReadErrorKind::CountTooLarge {
            element: "vertices".into(),
            declared: nv,
            max_possible: (avail / 6) as u64,
            available_bytes: available,
        });
    }
    if 6 * nv as u128 + 8 * nf as u128 > avail {
        return Err(ReadErrorKind::CountTooLarge {
            element: "faces".into(),
            declared: nf,
            max_possible: ((avail - 6 * nv as u128) / 8) as u64,
            available_bytes: available,
        });
    }
    let (nv, nf) = (nv as usize, nf as usize);

    let mut out = Parsed {
        positions: Vec::with_capacity(nv),
        faces: Vec::with_capacity(nf),
        scalars: Vec::new(),
    };
    for i in 0..nv {
        let Some((l, text)) = content.next() else {
            return Err(ReadErrorKind::Syntax {
                line: last_line,
                message: format!("the file ends after {i} of {nv} vertices"),
            });
        };
        last_line = l;
        let mut t = tokens(text);
        let mut p = [0.0; 3];
        for (k, c) in p.iter_mut().enumerate() {
            *c = parse_token(t.next(), &format!("coordinate {k} of vertex {i}"), l)?;
        }
        out.positions.push(p);
    }
    let mut corners: Vec<u32> = Vec::new();
    for face in 0..nf {
        let Some((l, text)) = content.next() else {
            return Err(ReadErrorKind::Syntax {
                line: last_line,
                message: format!("the file ends after {face} of {nf} faces"),
            });
        };
        last_line = l;
        let mut t = tokens(text);
        let n: usize = parse_token(t.next(), &format!("the corner count of face {face}"), l)?;
        if n < 3 {
            return Err(ReadErrorKind::FaceArity {
                face,
                arity: n,
                line: Some(l),
            });
        }
        corners.clear();
        for k in 0..n {
            let index: u64 = parse_token(
                t.next(),
                &format!("corner {k} of face {face} (a vertex index >= 0)"),
                l,
            )?;
            let index = u32::try_from(index).map_err(|_| {
                ReadErrorKind::Mesh(MeshError::IndexOutOfRange {
                    face: out.faces.len(),
                    index,
                    num_vertices: nv,
                })
            })?;
            corners.push(index);
        }
        push_fan(&mut out.faces, &corners);
    }
    if let Some((l, text)) = content.next() {
        return Err(ReadErrorKind::Syntax {
            line: l,
            message: format!(
                "found {} after the {nv} vertices and {nf} faces the header declares (wrong counts in the header?)",
                show(tokens(text).next().unwrap_or_default())
            ),
        });
    }
    Ok(out)
}

/// Accepts `OFF` with optional `ST`, `C`, `N` prefixes; rejects 4D / nD.
fn check_keyword(keyword: &[u8], line: usize) -> Result<(), ReadErrorKind> {
    let Some(prefix) = keyword.strip_suffix(b"OFF") else {
        return Err(ReadErrorKind::Syntax {
            line,
            message: format!(
                "expected the `OFF` keyword at the start of the file, found {}",
                show(keyword)
            ),
        });
    };
    if prefix.contains(&b'4') || prefix.contains(&b'n') {
        return Err(ReadErrorKind::Unsupported(format!(
            "{} (4D or nD OFF); only 3D OFF is read",
            show(keyword)
        )));
    }
    let mut rest = prefix;
    for p in [&b"ST"[..], b"C", b"N"] {
        rest = rest.strip_prefix(p).unwrap_or(rest);
    }
    if !rest.is_empty() {
        return Err(ReadErrorKind::Syntax {
            line,
            message: format!("expected the `OFF` keyword, found {}", show(keyword)),
        });
    }
    Ok(())
}

/// Byte offset just after `line`, a sub-slice of `bytes`.
fn end_offset(bytes: &[u8], line: &[u8]) -> usize {
    let start = (line.as_ptr() as usize).saturating_sub(bytes.as_ptr() as usize);
    start.saturating_add(line.len()).min(bytes.len())
}
