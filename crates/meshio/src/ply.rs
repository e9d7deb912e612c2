//! Stanford PLY reader and writer (ASCII, binary little and big endian).
//!
//! Read: the `vertex` element must have scalar properties `x`, `y`, `z` (any
//! numeric type); its other scalar properties are returned as per-vertex
//! scalars. The `face` element must have an integer list property named
//! `vertex_indices` (or `vertex_index`); polygons are fan-triangulated. Other
//! properties and elements (edges, materials, ...) are read and discarded, so
//! they may appear in any order. Type names are the classic ones (`char`,
//! `uchar`, `short`, `ushort`, `int`, `uint`, `float`, `double`) or the sized
//! ones (`int8`, ..., `float64`).

use super::text::{lines, show, tokens};
use super::{Parsed, ReadErrorKind, WriteErrorKind, fmt_f64, push_fan};
use mfm_geometry::mesh::TriMesh;
use std::io::Write;

/// How [`crate::write_ply_with`] encodes the body of a PLY file.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum PlyEncoding {
    /// Human-readable text; numbers in shortest round-trip decimal form.
    Ascii,
    /// Binary, little endian (the default: compact, exact, widely read).
    #[default]
    BinaryLittleEndian,
    /// Binary, big endian.
    BinaryBigEndian,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl Scalar {
    fn from_name(name: &[u8]) -> Option<Self> {
        Some(match name {
            b"char" | b"int8" => Self::I8,
            b"uchar" | b"uint8" => Self::U8,
            b"short" | b"int16" => Self::I16,
            b"ushort" | b"uint16" => Self::U16,
            b"int" | b"int32" => Self::I32,
            b"uint" | b"uint32" => Self::U32,
            b"float" | b"float32" => Self::F32,
            b"double" | b"float64" => Self::F64,
            _ => return None,
        })
    }

    fn size(self) -> usize {
        match self {
            Self::I8 | Self::U8 => 1,
            Self::I16 | Self::U16 => 2,
            Self::I32 | Self::U32 | Self::F32 => 4,
            Self::F64 => 8,
        }
    }

    fn is_integer(self) -> bool {
        !matches!(self, Self::F32 | Self::F64)
    }

    /// Inclusive range of an integer type.
    fn range(self) -> (i64, i64) {
        match self {
            Self::I8 => (i8::MIN.into(), i8::MAX.into()),
            Self::U8 => (0, u8::MAX.into()),
            Self::I16 => (i16::MIN.into(), i16::MAX.into()),
            Self::U16 => (0, u16::MAX.into()),
            Self::I32 => (i32::MIN.into(), i32::MAX.into()),
            Self::U32 => (0, u32::MAX.into()),
            Self::F32 | Self::F64 => (i64::MIN, i64::MAX),
        }
    }
}

#[derive(Clone, Copy, Debug)]
enum Kind {
    Scalar(Scalar),
    List { count: Scalar, item: Scalar },
}

#[derive(Debug)]
struct Property {
    name: String,
    kind: Kind,
    /// Header line declaring it.
    line: usize,
}

#[derive(Debug)]
struct Element {
    name: String,
    count: u64,
    properties: Vec<Property>,
    /// Header line declaring it.
    line: usize,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Format {
    Ascii,
    Binary { big_endian: bool },
}

struct Header {
    format: Format,
    elements: Vec<Element>,
    /// Byte offset of the body.
    body: usize,
    /// Line number of the first body line (ASCII).
    body_line: usize,
}

fn syntax(line: usize, message: impl Into<String>) -> ReadErrorKind {
    ReadErrorKind::Syntax {
        line,
        message: message.into(),
    }
}

fn parse_header(bytes: &[u8]) -> Result<Header, ReadErrorKind> {
    let mut format = None;
    let mut elements: Vec<Element> = Vec::new();
    let mut offset = 0usize;
    for (line, raw) in bytes
        .split(|&b| b == b'\n')
        .enumerate()
        .map(|(i, l)| (i + 1, l))
    {
        let full_len = raw.len() + 1;
        let text = raw.strip_suffix(b"\r").unwrap_or(raw);
        let mut t = tokens(text);
        let keyword = t.next();
        if line == 1 {
            if text.trim_ascii() != b"ply" {
                return Err(syntax(
                    line,
                    format!("expected the `ply` magic line, found {}", show(text)),
                ));
            }
            offset += full_len;
            continue;
        }
        match keyword {
            None | Some(b"comment") | Some(b"obj_info") => {}
            Some(b"format") => {
                let f = match t.next() {
                    Some(b"ascii") => Format::Ascii,
                    Some(b"binary_little_endian") => Format::Binary { big_endian: false },
                    Some(b"binary_big_endian") => Format::Binary { big_endian: true },
                    other => {
                        return Err(syntax(
                            line,
                            format!(
                                "expected the format `ascii`, `binary_little_endian` or `binary_big_endian`, found {}",
                                show(other.unwrap_or_default())
                            ),
                        ));
                    }
                };
                if format.replace(f).is_some() {
                    return Err(syntax(line, "a second `format` line"));
                }
            }
            Some(b"element") => {
                let name = t
                    .next()
                    .ok_or_else(|| syntax(line, "expected an element name after `element`"))?;
                let name = String::from_utf8_lossy(name).into_owned();
                let count = t
                    .next()
                    .and_then(|c| std::str::from_utf8(c).ok())
                    .and_then(|c| c.parse::<u64>().ok())
                    .ok_or_else(|| {
                        syntax(
                            line,
                            format!("expected the count of element `{name}` (an integer >= 0)"),
                        )
                    })?;
                if elements.iter().any(|e| e.name == name) && (name == "vertex" || name == "face") {
                    return Err(syntax(line, format!("a second `{name}` element")));
                }
                elements.push(Element {
                    name,
                    count,
                    properties: Vec::new(),
                    line,
                });
            }
            Some(b"property") => {
                let Some(element) = elements.last_mut() else {
                    return Err(syntax(line, "a `property` line before any `element` line"));
                };
                let type_name = t.next().unwrap_or_default();
                let type_of = |name: Option<&[u8]>| {
                    let name = name.unwrap_or_default();
                    Scalar::from_name(name).ok_or_else(|| {
                        syntax(
                            line,
                            format!(
                                "expected a property type (char, uchar, short, ushort, int, uint, float, double, int8, ..., float64), found {}",
                                show(name)
                            ),
                        )
                    })
                };
                let kind = if type_name == b"list" {
                    let count = type_of(t.next())?;
                    let item = type_of(t.next())?;
                    if !count.is_integer() {
                        return Err(syntax(
                            line,
                            "the count type of a list property must be an integer type",
                        ));
                    }
                    Kind::List { count, item }
                } else {
                    Kind::Scalar(type_of(Some(type_name))?)
                };
                let name = t
                    .next()
                    .ok_or_else(|| syntax(line, "expected a property name"))?;
                element.properties.push(Property {
                    name: String::from_utf8_lossy(name).into_owned(),
                    kind,
                    line,
                });
            }
            Some(b"end_header") => {
                let format =
                    format.ok_or_else(|| syntax(line, "`end_header` before any `format` line"))?;
                return Ok(Header {
                    format,
                    elements,
                    body: (offset + full_len).min(bytes.len()),
                    body_line: line + 1,
                });
            }
            Some(other) => {
                return Err(syntax(
                    line,
                    format!(
                        "expected a header line (format, element, property, comment, end_header), found {}",
                        show(other)
                    ),
                ));
            }
        }
        offset += full_len;
    }
    let last = bytes.split(|&b| b == b'\n').count();
    Err(syntax(last, "the file ends before `end_header`"))
}

/// Where values come from: text tokens or binary bytes.
trait Source {
    /// Reads one value of type `ty` as `f64`.
    fn real(&mut self, ty: Scalar, what: &dyn Fn() -> String) -> Result<f64, ReadErrorKind>;
    /// Reads one integer value of type `ty`.
    fn integer(&mut self, ty: Scalar, what: &dyn Fn() -> String) -> Result<i64, ReadErrorKind>;
    /// Skips `n` values of type `ty`.
    fn skip(&mut self, ty: Scalar, n: u64, what: &dyn Fn() -> String) -> Result<(), ReadErrorKind>;
    /// An error at the current position.
    fn error(&self, message: String) -> ReadErrorKind;
    /// What follows the last element, if anything but whitespace: the error
    /// to report.
    fn leftover(&mut self) -> Option<ReadErrorKind>;
}

struct Ascii<'a> {
    tokens: Box<dyn Iterator<Item = (usize, &'a [u8])> + 'a>,
    line: usize,
}

impl<'a> Ascii<'a> {
    fn new(body: &'a [u8], first_line: usize) -> Self {
        let tokens = lines(body)
            .flat_map(move |(l, text)| tokens(text).map(move |t| (l + first_line - 1, t)));
        Self {
            tokens: Box::new(tokens),
            line: first_line,
        }
    }

    fn token(&mut self, what: &dyn Fn() -> String) -> Result<&'a [u8], ReadErrorKind> {
        match self.tokens.next() {
            Some((l, t)) => {
                self.line = l;
                Ok(t)
            }
            None => Err(syntax(
                self.line,
                format!("expected {}, found the end of the file", what()),
            )),
        }
    }
}

impl Source for Ascii<'_> {
    fn real(&mut self, ty: Scalar, what: &dyn Fn() -> String) -> Result<f64, ReadErrorKind> {
        if ty.is_integer() {
            return self.integer(ty, what).map(|v| v as f64);
        }
        let t = self.token(what)?;
        std::str::from_utf8(t)
            .ok()
            .and_then(|s| s.parse::<f64>().ok())
            .ok_or_else(|| {
                syntax(
                    self.line,
                    format!("expected {} (a number), found {}", what(), show(t)),
                )
            })
    }

    fn integer(&mut self, ty: Scalar, what: &dyn Fn() -> String) -> Result<i64, ReadErrorKind> {
        let t = self.token(what)?;
        let (lo, hi) = ty.range();
        std::str::from_utf8(t)
            .ok()
            .and_then(|s| s.parse::<i64>().ok())
            .filter(|v| (lo..=hi).contains(v))
            .ok_or_else(|| {
                syntax(
                    self.line,
                    format!(
                        "expected {} (an integer in {lo}..={hi}), found {}",
                        what(),
                        show(t)
                    ),
                )
            })
    }

    fn skip(&mut self, ty: Scalar, n: u64, what: &dyn Fn() -> String) -> Result<(), ReadErrorKind> {
        for _ in 0..n {
            self.real(ty, what)?;
        }
        Ok(())
    }

    fn error(&self, message: String) -> ReadErrorKind {
        syntax(self.line, message)
    }

    fn leftover(&mut self) -> Option<ReadErrorKind> {
        let (line, token) = self.tokens.next()?;
        Some(syntax(
            line,
            format!(
                "found {} after the last element the header declares (wrong counts in the header?)",
                show(token)
            ),
        ))
    }
}

struct Binary<'a> {
    bytes: &'a [u8],
    pos: usize,
    big_endian: bool,
}

impl<'a> Binary<'a> {
    fn take(&mut self, n: usize, what: &dyn Fn() -> String) -> Result<&'a [u8], ReadErrorKind> {
        let end = self.pos.checked_add(n).filter(|&e| e <= self.bytes.len());
        match end {
            Some(end) => {
                let s = &self.bytes[self.pos..end];
                self.pos = end;
                Ok(s)
            }
            None => Err(ReadErrorKind::Binary {
                offset: self.pos,
                message: format!(
                    "the file ends while reading {} ({n} bytes needed, {} left)",
                    what(),
                    self.bytes.len() - self.pos
                ),
            }),
        }
    }

    fn array<const N: usize>(
        &mut self,
        what: &dyn Fn() -> String,
    ) -> Result<[u8; N], ReadErrorKind> {
        let s = self.take(N, what)?;
        let mut a = [0u8; N];
        a.copy_from_slice(s);
        if self.big_endian {
            a.reverse();
        }
        Ok(a)
    }

    fn value(&mut self, ty: Scalar, what: &dyn Fn() -> String) -> Result<Value, ReadErrorKind> {
        Ok(match ty {
            Scalar::I8 => Value::Int(i8::from_le_bytes(self.array(what)?).into()),
            Scalar::U8 => Value::Int(u8::from_le_bytes(self.array(what)?).into()),
            Scalar::I16 => Value::Int(i16::from_le_bytes(self.array(what)?).into()),
            Scalar::U16 => Value::Int(u16::from_le_bytes(self.array(what)?).into()),
            Scalar::I32 => Value::Int(i32::from_le_bytes(self.array(what)?).into()),
            Scalar::U32 => Value::Int(u32::from_le_bytes(self.array(what)?).into()),
            Scalar::F32 => Value::Real(f32::from_le_bytes(self.array(what)?).into()),
            Scalar::F64 => Value::Real(f64::from_le_bytes(self.array(what)?)),
        })
    }
}

enum Value {
    Int(i64),
    Real(f64),
}

impl Source for Binary<'_> {
    fn real(&mut self, ty: Scalar, what: &dyn Fn() -> String) -> Result<f64, ReadErrorKind> {
        Ok(match self.value(ty, what)? {
            Value::Int(v) => v as f64,
            Value::Real(v) => v,
        })
    }

    fn integer(&mut self, ty: Scalar, what: &dyn Fn() -> String) -> Result<i64, ReadErrorKind> {
        let start = self.pos;
        match self.value(ty, what)? {
            Value::Int(v) => Ok(v),
            Value::Real(_) => Err(ReadErrorKind::Binary {
                offset: start,
                message: format!("expected {} to have an integer type", what()),
            }),
        }
    }

    fn skip(&mut self, ty: Scalar, n: u64, what: &dyn Fn() -> String) -> Result<(), ReadErrorKind> {
        let n = usize::try_from(n)
            .ok()
            .and_then(|n| n.checked_mul(ty.size()))
            .unwrap_or(usize::MAX);
        self.take(n, what).map(|_| ())
    }

    fn error(&self, message: String) -> ReadErrorKind {
        ReadErrorKind::Binary {
            offset: self.pos,
            message,
        }
    }

    fn leftover(&mut self) -> Option<ReadErrorKind> {
        let rest = self.bytes.get(self.pos..).unwrap_or_default();
        // a trailing newline some writers add is not data
        if rest.iter().all(u8::is_ascii_whitespace) {
            return None;
        }
        Some(self.error(format!(
            "{} bytes after the last element the header declares (wrong counts in the header?)",
            rest.len()
        )))
    }
}

/// Which property of `element` is `name` (scalar), if any.
fn scalar_property(element: &Element, name: &str) -> Option<usize> {
    element
        .properties
        .iter()
        .position(|p| p.name == name && matches!(p.kind, Kind::Scalar(_)))
}

pub(crate) fn parse(bytes: &[u8]) -> Result<Parsed, ReadErrorKind> {
    let header = parse_header(bytes)?;
    let body = &bytes[header.body..];
    match header.format {
        Format::Ascii => {
            let mut src = Ascii::new(body, header.body_line);
            read_body(&header, body.len(), &mut src)
        }
        Format::Binary { big_endian } => {
            let mut src = Binary {
                bytes,
                pos: header.body,
                big_endian,
            };
            read_body(&header, body.len(), &mut src)
        }
    }
}

fn read_body(
    header: &Header,
    available: usize,
    src: &mut dyn Source,
) -> Result<Parsed, ReadErrorKind> {
    let Some(vertex) = header.elements.iter().find(|e| e.name == "vertex") else {
        return Err(syntax(
            header.body_line.saturating_sub(1),
            "the header has no `vertex` element",
        ));
    };
    let mut xyz = [0usize; 3];
    for (k, name) in ["x", "y", "z"].into_iter().enumerate() {
        xyz[k] = scalar_property(vertex, name).ok_or_else(|| {
            syntax(
                vertex.line,
                format!("the `vertex` element has no scalar property `{name}`"),
            )
        })?;
    }
    let face_list = header
        .elements
        .iter()
        .find(|e| e.name == "face")
        .map(|face| {
            face.properties
                .iter()
                .position(|p| p.name == "vertex_indices" || p.name == "vertex_index")
                .ok_or_else(|| {
                    syntax(
                        face.line,
                        "the `face` element has no `vertex_indices` (or `vertex_index`) property",
                    )
                })
                .and_then(|i| match face.properties[i].kind {
                    Kind::List { item, .. } if item.is_integer() => Ok(i),
                    _ => Err(syntax(
                        face.properties[i].line,
                        "the face property `vertex_indices` must be a list of integers",
                    )),
                })
        })
        .transpose()?;

    // refuse counts the remaining bytes cannot hold, before allocating
    let ascii = matches!(header.format, Format::Ascii);
    let mut need: u128 = 0;
    for e in &header.elements {
        let per: u128 = if ascii {
            // each value is a token of at least one byte plus a separator
            2 * e.properties.len() as u128
        } else {
            e.properties
                .iter()
                .map(|p| match p.kind {
                    Kind::Scalar(s) => s.size() as u128,
                    Kind::List { count, .. } => count.size() as u128,
                })
                .sum()
        };
        let before = need;
        need += per * e.count as u128;
        if need > available as u128 + 1 {
            let room = (available as u128 + 1).saturating_sub(before);
            return Err(ReadErrorKind::CountTooLarge {
                element: format!("elements `{}`", e.name),
                declared: e.count,
                max_possible: (room / per.max(1)) as u64,
                available_bytes: available,
            });
        }
    }

    let mut out = Parsed::default();
    let mut corners: Vec<u32> = Vec::new();
    for e in &header.elements {
        if e.properties.is_empty() {
            continue;
        }
        // bounded by the check above
        let count = e.count as usize;
        let is_vertex = e.name == "vertex";
        let is_face = e.name == "face";
        if is_vertex {
            out.positions.reserve_exact(count);
            for (k, p) in e.properties.iter().enumerate() {
                if matches!(p.kind, Kind::Scalar(_)) && !xyz.contains(&k) {
                    out.scalars
                        .push((p.name.clone(), Vec::with_capacity(count)));
                }
            }
        }
        if is_face {
            out.faces.reserve(count);
        }
        for i in 0..count {
            let mut p = [0.0; 3];
            let mut scalar_slot = 0;
            for (k, prop) in e.properties.iter().enumerate() {
                let what = || format!("property `{}` of {} {i}", prop.name, e.name);
                match prop.kind {
                    Kind::Scalar(ty) => {
                        if is_vertex {
                            let v = src.real(ty, &what)?;
                            if let Some(axis) = xyz.iter().position(|&a| a == k) {
                                p[axis] = v;
                            } else {
                                out.scalars[scalar_slot].1.push(v);
                                scalar_slot += 1;
                            }
                        } else {
                            src.skip(ty, 1, &what)?;
                        }
                    }
                    Kind::List { count: cty, item } => {
                        let n = src.integer(cty, &|| format!("the length of {}", what()))?;
                        let n = u64::try_from(n).map_err(|_| {
                            src.error(format!("{} has negative length {n}", what()))
                        })?;
                        if is_face && face_list == Some(k) {
                            if n < 3 {
                                return Err(ReadErrorKind::FaceArity {
                                    face: i,
                                    arity: n as usize,
                                    line: None,
                                });
                            }
                            corners.clear();
                            for c in 0..n {
                                let what = || format!("corner {c} of face {i}");
                                let v = src.integer(item, &what)?;
                                let v = u32::try_from(v).map_err(|_| {
                                    src.error(format!(
                                        "{} is {v}; vertex indices must be >= 0",
                                        what()
                                    ))
                                })?;
                                corners.push(v);
                            }
                            push_fan(&mut out.faces, &corners);
                        } else {
                            src.skip(item, n, &what)?;
                        }
                    }
                }
            }
            if is_vertex {
                out.positions.push(p);
            }
        }
    }
    if let Some(e) = src.leftover() {
        return Err(e);
    }
    Ok(out)
}

/// Checks scalar names and lengths for [`write`].
pub(crate) fn check_scalars(
    mesh: &TriMesh,
    scalars: &[(&str, &[f64])],
) -> Result<(), WriteErrorKind> {
    for (i, (name, values)) in scalars.iter().enumerate() {
        let bad = |reason| {
            Err(WriteErrorKind::InvalidScalarName {
                name: (*name).to_owned(),
                reason,
            })
        };
        let mut chars = name.chars();
        match chars.next() {
            None => return bad("it is empty"),
            Some(c) if !(c.is_ascii_alphabetic() || c == '_') => {
                return bad("it must start with an ASCII letter or `_`");
            }
            _ => {}
        }
        if !chars.all(|c| c.is_ascii_alphanumeric() || matches!(c, '_' | '-' | '.')) {
            return bad("only ASCII letters, digits, `_`, `-` and `.` are allowed");
        }
        if matches!(*name, "x" | "y" | "z") {
            return bad("`x`, `y` and `z` are the vertex coordinates");
        }
        if scalars[..i].iter().any(|(n, _)| n == name) {
            return bad("it appears twice");
        }
        if values.len() != mesh.num_vertices() {
            return Err(WriteErrorKind::ScalarLength {
                name: (*name).to_owned(),
                expected: mesh.num_vertices(),
                found: values.len(),
            });
        }
    }
    Ok(())
}

/// Writes a PLY file; `scalars` must have passed [`check_scalars`].
pub(crate) fn write(
    w: &mut impl Write,
    mesh: &TriMesh,
    scalars: &[(&str, &[f64])],
    encoding: PlyEncoding,
) -> std::io::Result<()> {
    let format = match encoding {
        PlyEncoding::Ascii => "ascii",
        PlyEncoding::BinaryLittleEndian => "binary_little_endian",
        PlyEncoding::BinaryBigEndian => "binary_big_endian",
    };
    writeln!(
        w,
        "ply\nformat {format} 1.0\ncomment written by mfm-geometry"
    )?;
    writeln!(w, "element vertex {}", mesh.num_vertices())?;
    for axis in ["x", "y", "z"] {
        writeln!(w, "property double {axis}")?;
    }
    for (name, _) in scalars {
        writeln!(w, "property double {name}")?;
    }
    writeln!(w, "element face {}", mesh.num_faces())?;
    writeln!(w, "property list uchar uint vertex_indices\nend_header")?;
    let big = encoding == PlyEncoding::BinaryBigEndian;
    let put = |w: &mut dyn Write, x: f64| -> std::io::Result<()> {
        match encoding {
            PlyEncoding::Ascii => write!(w, "{}", fmt_f64(x)),
            _ if big => w.write_all(&x.to_be_bytes()),
            _ => w.write_all(&x.to_le_bytes()),
        }
    };
    for (v, p) in mesh.positions().iter().enumerate() {
        let values = p.iter().copied().chain(scalars.iter().map(|(_, s)| s[v]));
        for (k, x) in values.enumerate() {
            if encoding == PlyEncoding::Ascii && k > 0 {
                w.write_all(b" ")?;
            }
            put(w, x)?;
        }
        if encoding == PlyEncoding::Ascii {
            w.write_all(b"\n")?;
        }
    }
    for f in mesh.faces() {
        match encoding {
            PlyEncoding::Ascii => writeln!(w, "3 {} {} {}", f[0], f[1], f[2])?,
            _ => {
                w.write_all(&[3u8])?;
                for &i in f {
                    w.write_all(&if big {
                        i.to_be_bytes()
                    } else {
                        i.to_le_bytes()
                    })?;
                }
            }
        }
    }
    Ok(())
}
