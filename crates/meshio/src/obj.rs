//! Wavefront OBJ reader (parsing by the `tobj` crate) and writer.
//!
//! # What is read
//! `v x y z ...` statements (numbers after the third are ignored: no `w`
//! division, no vertex colors) and `f c_1 c_2 ... c_n` statements whose
//! corners are `i`, `i/t`, `i//n` or `i/t/n`; only the position index `i` is
//! used: 1-based, or negative for "relative to the last vertex so far" (`-1`
//! is the last one). Every other statement (`vt`, `vn`, `g`, `o`, `s`,
//! `usemtl`, `mtllib`, `l`, `p`, ...) is skipped. `#` starts a comment and a
//! trailing `\` continues a statement on the next line. Vertices keep their
//! file order, including those no face uses; all objects and groups end up in
//! one mesh.
//!
//! # How `tobj` is used
//! `tobj` parses the numbers (as `f64`, feature `use_f64`) and the face
//! corners, resolves relative indices, fan-triangulates polygons and checks
//! the indices. Left to itself it would also split the file into one model per
//! `o`/`g`/`usemtl`, renumber the vertices of each model in order of first use
//! and drop the vertices no face uses. So this module hands it a prepared
//! text:
//!
//! 1. Comments, `\` continuations and invalid UTF-8 (replaced by U+FFFD) are
//!    dealt with here, line by line, keeping each statement's line number.
//! 2. Only `v` statements (cut to `v x y z`, so that colors or a `w` given for
//!    some vertices only cannot misalign `tobj`'s color array) and `f`
//!    statements are passed on, so `tobj` builds a single model. Faces with
//!    fewer than three corners are refused here (`tobj` would turn them into
//!    zero-area triangles). Keeping `vt`/`vn` out also keeps `tobj` away
//!    from texture and normal indices, which it does not bound-check before
//!    doing arithmetic on them (`vt 0 0` then `f 1/-4 2 3` overflows in
//!    `tobj` 4.0.5).
//! 3. The text starts with one point face `f k` per vertex, `k = 1..V`, which
//!    `tobj` (with `single_index: false`) numbers first, in file order: vertex
//!    `k` of the model *is* vertex `k` of the file, every vertex is kept, and
//!    the faces that follow keep the file's numbering. (Positive indices are
//!    resolved when the model is finished, so these faces may come before the
//!    vertices.) The `V` degenerate triangles these points become are checked
//!    and removed from the output.
//!
//! `tobj` errors carry no position. A parse error is placed by counting the
//! lines `tobj` has consumed; an index error (found only after the whole file
//! is read) is explained by a scan of the face statements, which reports the
//! first bad corner with its line, as the hand-written parser used to.

use super::text::{lines, show, strip_comment};
use super::{Parsed, ReadErrorKind, fmt_f64};
use mfm_geometry::mesh::TriMesh;
use std::io::{BufRead, Read, Write};
use std::ops::Range;

/// Bytes looked at to decide whether a file is OBJ text at all.
const SNIFF_BYTES: usize = 1 << 20;

/// Statement keywords of OBJ (geometry, grouping, display and free-form).
const KEYWORDS: &[&[u8]] = &[
    b"v",
    b"vt",
    b"vn",
    b"vp",
    b"f",
    b"l",
    b"p",
    b"o",
    b"g",
    b"s",
    b"mg",
    b"usemtl",
    b"mtllib",
    b"usemap",
    b"maplib",
    b"cstype",
    b"deg",
    b"bmat",
    b"step",
    b"curv",
    b"curv2",
    b"surf",
    b"parm",
    b"trim",
    b"hole",
    b"scrv",
    b"sp",
    b"end",
    b"con",
    b"lod",
    b"bevel",
    b"c_interp",
    b"d_interp",
    b"shadow_obj",
    b"trace_obj",
    b"ctech",
    b"stech",
    b"call",
    b"csh",
];

/// Refuses a file that is not OBJ text: one whose first [`SNIFF_BYTES`]
/// hold no `v` or `f` statement and either a NUL byte or a line that starts
/// with something other than an OBJ keyword or a comment.
fn sniff(bytes: &[u8]) -> Result<(), ReadErrorKind> {
    let head = &bytes[..bytes.len().min(SNIFF_BYTES)];
    let mut foreign = None;
    for (n, line) in head.split(|&b| b == b'\n').enumerate() {
        let first = line
            .split(|b| b.is_ascii_whitespace())
            .find(|t| !t.is_empty())
            .unwrap_or_default();
        if first == b"v" || first == b"f" {
            return Ok(());
        }
        if foreign.is_none()
            && !first.is_empty()
            && !first.starts_with(b"#")
            && !first.starts_with(b"\\")
            && !KEYWORDS.contains(&first)
        {
            foreign = Some(n + 1);
        }
    }
    let binary = head.contains(&0);
    match (binary, foreign) {
        (false, None) => Ok(()),
        (true, _) => Err(ReadErrorKind::Syntax {
            line: 1,
            message: format!(
                "not an OBJ file: binary data and no `v` or `f` statement in the first {} bytes",
                head.len()
            ),
        }),
        (false, Some(line)) => Err(ReadErrorKind::Syntax {
            line,
            message: format!(
                "not an OBJ file: no `v` or `f` statement in the first {} bytes, and this line starts with no OBJ keyword",
                head.len()
            ),
        }),
    }
}

pub(crate) fn parse(bytes: &[u8]) -> Result<Parsed, ReadErrorKind> {
    sniff(bytes)?;
    let prepared = Prepared::new(bytes)?;
    let text = prepared.tobj_text();
    let mut reader = CountingReader {
        rest: text.as_bytes(),
        newlines: 0,
    };
    let options = tobj::LoadOptions {
        // one index per corner, keyed by the position alone: `single_index`
        // would key vertices by (position, texcoord, normal) and split them
        single_index: false,
        triangulate: true,
        // the leading point faces must reach the model
        ignore_points: false,
        ignore_lines: false,
    };
    // no `mtllib` statement reaches tobj, so this loader is never called
    let no_materials = |_: &std::path::Path| Ok((Vec::new(), Default::default()));
    match tobj::load_obj_buf(&mut reader, &options, no_materials) {
        Ok((models, _)) => prepared.collect(models),
        Err(e) => Err(prepared.explain(e, reader.newlines)),
    }
}

/// One `v` or `f` statement passed on to `tobj`.
struct Statement {
    /// 1-based line of the file where it starts.
    line: usize,
    /// Its text in [`Prepared::body`] (without the newline).
    range: Range<usize>,
    /// Number of `v` statements before it.
    vertices_before: usize,
    /// For a face: its 0-based number among the faces.
    face: Option<usize>,
}

/// The `v` and `f` statements of a file, normalized for `tobj`.
struct Prepared {
    /// The statements, one per line, each ending in `\n`.
    body: String,
    statements: Vec<Statement>,
    num_vertices: usize,
}

impl Prepared {
    fn new(bytes: &[u8]) -> Result<Self, ReadErrorKind> {
        let mut out = Self {
            body: String::new(),
            statements: Vec::new(),
            num_vertices: 0,
        };
        let mut num_faces = 0usize;
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
            let (line, statement) = if pending.is_empty() {
                (l, String::from_utf8_lossy(text))
            } else {
                pending.extend_from_slice(text);
                (pending_line, String::from_utf8_lossy(&pending))
            };
            let mut words = statement.split_whitespace();
            let keyword = words.next();
            let start = out.body.len();
            let face = match keyword {
                Some("v") => {
                    out.body.push('v');
                    for w in words.take(3) {
                        out.body.push(' ');
                        out.body.push_str(w);
                    }
                    None
                }
                Some("f") => {
                    let corners: Vec<&str> = words.collect();
                    if corners.len() < 3 {
                        return Err(ReadErrorKind::FaceArity {
                            face: num_faces,
                            arity: corners.len(),
                            line: Some(line),
                        });
                    }
                    out.body.push('f');
                    for c in corners {
                        out.body.push(' ');
                        out.body.push_str(c);
                    }
                    num_faces += 1;
                    Some(num_faces - 1)
                }
                _ => {
                    pending.clear();
                    continue;
                }
            };
            out.statements.push(Statement {
                line,
                range: start..out.body.len(),
                vertices_before: out.num_vertices,
                face,
            });
            out.body.push('\n');
            if face.is_none() {
                out.num_vertices += 1;
            }
            pending.clear();
        }
        if !pending.is_empty() {
            return Err(ReadErrorKind::Syntax {
                line: pending_line,
                message: "the file ends inside a statement continued with `\\`".into(),
            });
        }
        Ok(out)
    }

    /// The text for `tobj`: one point face per vertex, then the statements.
    fn tobj_text(&self) -> String {
        use std::fmt::Write as _;
        let mut text = String::with_capacity(self.body.len() + 10 * self.num_vertices);
        for k in 1..=self.num_vertices {
            // writing to a String cannot fail
            let _ = writeln!(text, "f {k}");
        }
        text.push_str(&self.body);
        text
    }

    fn text(&self, s: &Statement) -> &str {
        self.body.get(s.range.clone()).unwrap_or_default()
    }

    /// Turns `tobj`'s single model back into file-numbered positions and
    /// triangles, checking the layout described in the module docs.
    fn collect(&self, models: Vec<tobj::Model>) -> Result<Parsed, ReadErrorKind> {
        let n = self.num_vertices;
        let unexpected = |what: &str| {
            ReadErrorKind::Unsupported(format!(
                "the OBJ parser (tobj) returned an unexpected layout: {what}"
            ))
        };
        let [model] = <[tobj::Model; 1]>::try_from(models)
            .map_err(|m| unexpected(&format!("{} models instead of 1", m.len())))?;
        let mesh = model.mesh;
        if mesh.positions.len() != 3 * n {
            return Err(unexpected(&format!(
                "{} coordinates for {n} vertices",
                mesh.positions.len()
            )));
        }
        if mesh.indices.len() % 3 != 0 || mesh.indices.len() < 3 * n {
            return Err(unexpected("an incomplete triangle list"));
        }
        let (points, triangles) = mesh.indices.split_at(3 * n);
        let in_order = points
            .chunks_exact(3)
            .zip(0u32..)
            .all(|(p, k)| p.iter().all(|&i| i == k));
        if !in_order {
            return Err(unexpected("vertices out of file order"));
        }
        Ok(Parsed {
            positions: mesh
                .positions
                .chunks_exact(3)
                .map(|p| [p[0], p[1], p[2]])
                .collect(),
            faces: triangles
                .chunks_exact(3)
                .map(|t| [t[0], t[1], t[2]])
                .collect(),
            scalars: Vec::new(),
        })
    }

    /// A precise error for a `tobj` failure, after `newlines` lines of its
    /// input were consumed.
    fn explain(&self, error: tobj::LoadError, newlines: usize) -> ReadErrorKind {
        // A parse error stops tobj right after it consumed the failing line;
        // an index error is only found once the whole text is read.
        let failing = newlines
            .checked_sub(1 + self.num_vertices)
            .and_then(|i| self.statements.get(i));
        match (error, failing) {
            (tobj::LoadError::FaceVertexOutOfBounds, _) => self
                .bad_index()
                .unwrap_or_else(|| self.fallback(error, self.statements.last())),
            (tobj::LoadError::PositionParseError, Some(s)) if s.face.is_none() => {
                let vertex = s.vertices_before;
                ReadErrorKind::Syntax {
                    line: s.line,
                    message: format!(
                        "expected three numbers x y z for vertex {vertex}, found {}",
                        show(self.text(s).as_bytes())
                    ),
                }
            }
            (tobj::LoadError::FaceParseError, Some(s)) => match s.face {
                Some(face) => self.bad_corner(s, face),
                None => self.fallback(error, Some(s)),
            },
            (_, s) => self.fallback(error, s),
        }
    }

    /// The corner of a face statement that `tobj` could not parse.
    fn bad_corner(&self, s: &Statement, face: usize) -> ReadErrorKind {
        let corner_ok = |c: &str| {
            c.split('/').count() <= 3
                && c.split('/')
                    .all(|p| p.is_empty() || p.parse::<isize>().is_ok())
        };
        let text = self.text(s);
        match text.split_whitespace().skip(1).find(|c| !corner_ok(c)) {
            Some(corner) => ReadErrorKind::Syntax {
                line: s.line,
                message: format!(
                    "expected a corner `i`, `i/t`, `i//n` or `i/t/n` of face {face} (integer indices), found {}",
                    show(corner.as_bytes())
                ),
            },
            None => self.fallback(tobj::LoadError::FaceParseError, Some(s)),
        }
    }

    /// The first face corner whose position index does not name a vertex.
    fn bad_index(&self) -> Option<ReadErrorKind> {
        let n = self.num_vertices;
        for s in &self.statements {
            let Some(face) = s.face else { continue };
            let corners = self.text(s).split_whitespace().skip(1);
            for (c, corner) in corners.enumerate() {
                let first = corner.split('/').next().unwrap_or_default();
                let syntax = |message: String| {
                    Some(ReadErrorKind::Syntax {
                        line: s.line,
                        message,
                    })
                };
                let Ok(raw) = first.parse::<i64>() else {
                    return syntax(format!(
                        "face {face} has a corner without a vertex index: {}",
                        show(corner.as_bytes())
                    ));
                };
                let defined = s.vertices_before as u64;
                if raw == 0 {
                    return syntax(format!(
                        "face {face} uses vertex index 0; OBJ indices start at 1"
                    ));
                } else if raw < 0 && raw.unsigned_abs() > defined {
                    return syntax(format!(
                        "face {face} uses relative index {raw}, but only {defined} vertices are defined before it"
                    ));
                } else if raw > 0 && raw.unsigned_abs() > n as u64 {
                    // the index as written (1-based), where the file has it
                    return syntax(format!(
                        "face {face} (corner {}) uses vertex index {raw}, but the file has only \
                         {n} vertices (OBJ indices are 1 to {n})",
                        c + 1
                    ));
                }
            }
        }
        None
    }

    /// `tobj`'s own message, at the statement it most likely concerns.
    fn fallback(&self, error: tobj::LoadError, s: Option<&Statement>) -> ReadErrorKind {
        match s {
            Some(s) => ReadErrorKind::Syntax {
                line: s.line,
                message: format!("{error} in {}", show(self.text(s).as_bytes())),
            },
            None => ReadErrorKind::Unsupported(format!("the OBJ parser (tobj) failed: {error}")),
        }
    }
}

/// A [`BufRead`] over a byte slice that counts the newlines consumed, so that
/// the line `tobj` failed on can be found.
struct CountingReader<'a> {
    rest: &'a [u8],
    newlines: usize,
}

impl Read for CountingReader<'_> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let n = buf.len().min(self.rest.len());
        buf[..n].copy_from_slice(&self.rest[..n]);
        self.consume(n);
        Ok(n)
    }
}

impl BufRead for CountingReader<'_> {
    fn fill_buf(&mut self) -> std::io::Result<&[u8]> {
        Ok(self.rest)
    }

    fn consume(&mut self, amt: usize) {
        let (done, rest) = self.rest.split_at(amt.min(self.rest.len()));
        self.newlines += done.iter().filter(|&&b| b == b'\n').count();
        self.rest = rest;
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
