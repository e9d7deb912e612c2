//! glTF 2.0 reader (`.gltf` JSON and `.glb` binary), on top of the `gltf`
//! crate's document parsing and validation.
//!
//! Buffer loading and accessor reading are done here rather than through
//! `gltf::import` / `Reader`, with every offset and length checked, because
//! those paths of the crate can panic on malformed input (non-UTF-8
//! percent-escapes in URIs, zero-count or mistyped accessors). Images are never
//! decoded. See [`crate`] for what is read (triangle primitives of all
//! meshes, node transforms not applied).

use super::{Parsed, ReadErrorKind};
use ::gltf::accessor::{DataType, Dimensions};
use ::gltf::mesh::{Mode, Semantic};
use std::path::Path;

fn invalid(message: impl Into<String>) -> ReadErrorKind {
    ReadErrorKind::Gltf(message.into())
}

pub(crate) fn parse(bytes: &[u8], base: Option<&Path>) -> Result<Parsed, ReadErrorKind> {
    check_glb_header(bytes)?;
    let gltf =
        ::gltf::Gltf::from_slice_without_validation(bytes).map_err(|e| invalid(e.to_string()))?;
    validate(gltf.document.as_json())?;
    let buffers = load_buffers(&gltf, base)?;
    let mut out = Parsed::default();
    for mesh in gltf.document.meshes() {
        for prim in mesh.primitives() {
            let at = || format!("mesh {} primitive {}", mesh.index(), prim.index());
            let mode = prim.mode();
            if !matches!(
                mode,
                Mode::Triangles | Mode::TriangleStrip | Mode::TriangleFan
            ) {
                return Err(ReadErrorKind::Unsupported(format!(
                    "{} has mode {mode:?}; only triangle primitives are read",
                    at()
                )));
            }
            let Some(pos) = prim.get(&Semantic::Positions) else {
                return Err(invalid(format!("{} has no POSITION attribute", at())));
            };
            if pos.dimensions() != Dimensions::Vec3 {
                return Err(invalid(format!(
                    "{}: POSITION accessor {} has type {:?}, expected VEC3",
                    at(),
                    pos.index(),
                    pos.dimensions()
                )));
            }
            let first = out.positions.len();
            let view = AccessorView::new(&pos, &buffers)?;
            out.positions.reserve(view.count);
            for i in 0..view.count {
                let mut p = [0.0; 3];
                for (k, c) in p.iter_mut().enumerate() {
                    *c = view.component(i, k);
                }
                out.positions.push(p);
            }
            let n = view.count;
            let indices: Vec<u64> = match prim.indices() {
                Some(acc) => {
                    if acc.dimensions() != Dimensions::Scalar
                        || !matches!(
                            acc.data_type(),
                            DataType::U8 | DataType::U16 | DataType::U32
                        )
                    {
                        return Err(invalid(format!(
                            "{}: index accessor {} must be SCALAR of unsigned integers, found {:?} of {:?}",
                            at(),
                            acc.index(),
                            acc.dimensions(),
                            acc.data_type()
                        )));
                    }
                    let v = AccessorView::new(&acc, &buffers)?;
                    (0..v.count)
                        .map(|i| v.raw(i, 0).map_or(u64::MAX, |(x, _)| x as u64))
                        .collect()
                }
                None => (0..n as u64).collect(),
            };
            if let Some(&bad) = indices.iter().find(|&&i| i >= n as u64) {
                return Err(invalid(format!(
                    "{} uses vertex index {bad}, but the primitive has {n} vertices",
                    at()
                )));
            }
            let base_index = first as u64;
            let global = |i: u64| {
                u32::try_from(base_index + i).map_err(|_| invalid("more than 2^32 - 1 vertices"))
            };
            match mode {
                Mode::Triangles => {
                    if indices.len() % 3 != 0 {
                        return Err(invalid(format!(
                            "{} has {} indices, not a multiple of 3",
                            at(),
                            indices.len()
                        )));
                    }
                    for t in indices.chunks_exact(3) {
                        out.faces
                            .push([global(t[0])?, global(t[1])?, global(t[2])?]);
                    }
                }
                Mode::TriangleStrip => {
                    for (i, w) in indices.windows(3).enumerate() {
                        // odd triangles swap their first two corners to keep the winding;
                        // triangles with a repeated index only join strips: skipped
                        let t = if i % 2 == 0 {
                            [w[0], w[1], w[2]]
                        } else {
                            [w[1], w[0], w[2]]
                        };
                        if t[0] != t[1] && t[1] != t[2] && t[0] != t[2] {
                            out.faces
                                .push([global(t[0])?, global(t[1])?, global(t[2])?]);
                        }
                    }
                }
                _ => {
                    if let Some((&c, rest)) = indices.split_first() {
                        for w in rest.windows(2) {
                            if c != w[0] && w[0] != w[1] && c != w[1] {
                                out.faces.push([global(c)?, global(w[0])?, global(w[1])?]);
                            }
                        }
                    }
                }
            }
        }
    }
    Ok(out)
}

/// The `gltf` crate's schema validation, preceded by the one check it needs
/// to not panic itself (its `POSITION` min/max check indexes the accessor list
/// unchecked). Only after this do the document accessors not panic.
fn validate(root: &::gltf::json::Root) -> Result<(), ReadErrorKind> {
    use ::gltf::json::validation::Validate;
    for (m, mesh) in root.meshes.iter().enumerate() {
        for (p, prim) in mesh.primitives.iter().enumerate() {
            for index in prim.attributes.values() {
                if index.value() >= root.accessors.len() {
                    return Err(invalid(format!(
                        "mesh {m} primitive {p}: an attribute refers to accessor {}, but there are {}",
                        index.value(),
                        root.accessors.len()
                    )));
                }
            }
        }
    }
    let mut errors = Vec::new();
    root.validate(root, ::gltf::json::Path::new, &mut |path, error| {
        errors.push(format!("{}: {error}", path().as_str()));
    });
    if errors.is_empty() {
        Ok(())
    } else {
        let n = errors.len();
        errors.truncate(3);
        Err(invalid(format!(
            "{n} schema error(s): {}",
            errors.join("; ")
        )))
    }
}

/// The GLB header length field is used unchecked by the `gltf` crate; check
/// it here.
fn check_glb_header(bytes: &[u8]) -> Result<(), ReadErrorKind> {
    if !bytes.starts_with(b"glTF") {
        return Ok(());
    }
    let Some(len) = bytes.get(8..12) else {
        return Err(ReadErrorKind::Binary {
            offset: bytes.len(),
            message: "the GLB header is truncated (12 bytes expected)".into(),
        });
    };
    let len = u32::from_le_bytes([len[0], len[1], len[2], len[3]]) as usize;
    if len < 12 || len > bytes.len() {
        return Err(ReadErrorKind::Binary {
            offset: 8,
            message: format!(
                "the GLB header declares a length of {len} bytes; the file has {}",
                bytes.len()
            ),
        });
    }
    Ok(())
}

fn load_buffers(gltf: &::gltf::Gltf, base: Option<&Path>) -> Result<Vec<Vec<u8>>, ReadErrorKind> {
    let mut out = Vec::new();
    for buffer in gltf.document.buffers() {
        let data = match buffer.source() {
            ::gltf::buffer::Source::Bin => gltf.blob.clone().ok_or_else(|| {
                invalid(format!(
                    "buffer {} refers to a missing GLB binary chunk",
                    buffer.index()
                ))
            })?,
            ::gltf::buffer::Source::Uri(uri) => {
                read_uri(uri, base, buffer.index(), buffer.length())?
            }
        };
        if data.len() < buffer.length() {
            return Err(invalid(format!(
                "buffer {} declares {} bytes but holds {}",
                buffer.index(),
                buffer.length(),
                data.len()
            )));
        }
        out.push(data);
    }
    Ok(out)
}

/// The bytes of buffer `index`, `declared` long, from its URI: a base64
/// data URI, or a file in the glTF file's folder `base` (or below it; a
/// path that leads elsewhere is refused), a regular file of the declared
/// length (up to 3 bytes of alignment padding more), of which only the
/// declared bytes are read.
fn read_uri(
    uri: &str,
    base: Option<&Path>,
    index: usize,
    declared: usize,
) -> Result<Vec<u8>, ReadErrorKind> {
    if let Some(rest) = uri.strip_prefix("data:") {
        let payload = rest.split_once(";base64,").map(|(_, p)| p).ok_or_else(|| {
            ReadErrorKind::Unsupported(format!("buffer {index}: only base64 data URIs are read"))
        })?;
        return decode_base64(payload)
            .ok_or_else(|| invalid(format!("buffer {index}: the data URI is not valid base64")));
    }
    let relative = if let Some(p) = uri
        .strip_prefix("file://")
        .or_else(|| uri.strip_prefix("file:"))
    {
        p.to_owned()
    } else if uri.contains(':') {
        return Err(ReadErrorKind::Unsupported(format!(
            "buffer {index}: URI scheme of `{uri}`"
        )));
    } else {
        percent_decode(uri)
            .ok_or_else(|| invalid(format!("buffer {index}: bad percent-escape in `{uri}`")))?
    };
    let Some(base) = base else {
        return Err(ReadErrorKind::Unsupported(format!(
            "buffer {index} refers to the external file `{relative}`, which an in-memory read cannot load"
        )));
    };
    let path = base.join(&relative);
    let cannot = |e: &dyn std::fmt::Display| {
        invalid(format!(
            "buffer {index}: cannot read `{}`: {e}",
            path.display()
        ))
    };
    // judged by the URI's own path (`..` resolved as written): a link the
    // user put in the folder is theirs to follow
    let folder = lexical(base);
    let resolved = lexical(&path);
    if Path::new(&relative).is_absolute() || !resolved.starts_with(&folder) {
        return Err(invalid(format!(
            "buffer {index}: `{relative}` lies outside the glTF file's folder {}; buffers are \
             read from that folder (or below it) only",
            folder.display()
        )));
    }
    let file = mfm_files::open_regular(&resolved).map_err(|e| cannot(&e))?;
    let size = file.metadata().map_err(|e| cannot(&e))?.len();
    if size < declared as u64 || size > declared as u64 + 3 {
        return Err(invalid(format!(
            "buffer {index}: `{relative}` holds {size} bytes but the buffer declares {declared}"
        )));
    }
    let mut bytes = Vec::with_capacity(declared);
    std::io::Read::read_to_end(&mut std::io::Read::take(file, declared as u64), &mut bytes)
        .map_err(|e| cannot(&e))?;
    Ok(bytes)
}

/// `path` with `.` and `..` removed as written (no link followed), made
/// absolute against the working folder.
fn lexical(path: &Path) -> std::path::PathBuf {
    use std::path::Component;
    let absolute = std::env::current_dir()
        .map(|d| d.join(path))
        .unwrap_or_else(|_| path.to_path_buf());
    let mut out = std::path::PathBuf::new();
    for part in absolute.components() {
        match part {
            Component::CurDir => {}
            Component::ParentDir => {
                out.pop();
            }
            other => out.push(other),
        }
    }
    out
}

/// Decodes `%XX` escapes; `None` on a malformed escape or non-UTF-8 result.
fn percent_decode(s: &str) -> Option<String> {
    let b = s.as_bytes();
    let mut out = Vec::with_capacity(b.len());
    let mut i = 0;
    while i < b.len() {
        if b[i] == b'%' {
            let hex = b.get(i + 1..i + 3)?;
            let hex = std::str::from_utf8(hex).ok()?;
            out.push(u8::from_str_radix(hex, 16).ok()?);
            i += 3;
        } else {
            out.push(b[i]);
            i += 1;
        }
    }
    String::from_utf8(out).ok()
}

/// Standard base64 (RFC 4648 alphabet, optional `=` padding).
fn decode_base64(s: &str) -> Option<Vec<u8>> {
    let s = s.trim_end_matches('=');
    let mut out = Vec::with_capacity(s.len() / 4 * 3 + 3);
    let (mut acc, mut bits) = (0u32, 0u32);
    for c in s.bytes() {
        let v = match c {
            b'A'..=b'Z' => c - b'A',
            b'a'..=b'z' => c - b'a' + 26,
            b'0'..=b'9' => c - b'0' + 52,
            b'+' => 62,
            b'/' => 63,
            _ => return None,
        };
        acc = (acc << 6) | u32::from(v);
        bits += 6;
        if bits >= 8 {
            bits -= 8;
            out.push((acc >> bits) as u8);
            acc &= (1 << bits) - 1;
        }
    }
    Some(out)
}

/// A bounds-checked window on an accessor's elements.
struct AccessorView<'a> {
    data: &'a [u8],
    stride: usize,
    component: DataType,
    normalized: bool,
    count: usize,
}

impl<'a> AccessorView<'a> {
    fn new(acc: &::gltf::Accessor<'_>, buffers: &'a [Vec<u8>]) -> Result<Self, ReadErrorKind> {
        let id = acc.index();
        if acc.sparse().is_some() {
            return Err(ReadErrorKind::Unsupported(format!(
                "accessor {id} is sparse"
            )));
        }
        let Some(view) = acc.view() else {
            return Err(ReadErrorKind::Unsupported(format!(
                "accessor {id} has no buffer view"
            )));
        };
        let buffer = buffers
            .get(view.buffer().index())
            .ok_or_else(|| invalid(format!("accessor {id}: missing buffer")))?;
        let view_bytes = view
            .offset()
            .checked_add(view.length())
            .and_then(|end| buffer.get(view.offset()..end))
            .ok_or_else(|| {
                invalid(format!(
                    "buffer view {} spans bytes {}..+{} of a {}-byte buffer",
                    view.index(),
                    view.offset(),
                    view.length(),
                    buffer.len()
                ))
            })?;
        let component = acc.data_type();
        let size = component.size() * acc.dimensions().multiplicity();
        let stride = view.stride().unwrap_or(size);
        if stride < size {
            return Err(invalid(format!(
                "accessor {id}: byte stride {stride} is smaller than its element size {size}"
            )));
        }
        let count = acc.count();
        let span = if count == 0 {
            Some(0)
        } else {
            stride
                .checked_mul(count - 1)
                .and_then(|s| s.checked_add(size))
        };
        let data = span
            .and_then(|span| acc.offset().checked_add(span))
            .and_then(|end| view_bytes.get(acc.offset()..end))
            .ok_or_else(|| {
                invalid(format!(
                    "accessor {id}: {count} elements of {size} bytes (stride {stride}) from offset {} do not fit in buffer view {} ({} bytes)",
                    acc.offset(),
                    view.index(),
                    view_bytes.len()
                ))
            })?;
        Ok(Self {
            data,
            stride,
            component,
            normalized: acc.normalized(),
            count,
        })
    }

    /// Component `k` of element `i`, normalized if the accessor says so
    /// (NaN, caught later as a non-finite coordinate, if out of bounds, which
    /// the constructor rules out).
    fn component(&self, i: usize, k: usize) -> f64 {
        self.raw(i, k).map_or(f64::NAN, |(value, scale)| {
            if self.normalized && self.component != DataType::F32 {
                (value / scale).max(-1.0)
            } else {
                value
            }
        })
    }

    /// Component `k` of element `i` as stored, with its normalization scale.
    fn raw(&self, i: usize, k: usize) -> Option<(f64, f64)> {
        let size = self.component.size();
        let at = i.checked_mul(self.stride)?.checked_add(k * size)?;
        let b = self.data.get(at..at + size)?;
        Some(match self.component {
            DataType::I8 => (f64::from(b[0] as i8), 127.0),
            DataType::U8 => (f64::from(b[0]), 255.0),
            DataType::I16 => (f64::from(i16::from_le_bytes([b[0], b[1]])), 32767.0),
            DataType::U16 => (f64::from(u16::from_le_bytes([b[0], b[1]])), 65535.0),
            DataType::U32 => (
                f64::from(u32::from_le_bytes([b[0], b[1], b[2], b[3]])),
                4294967295.0,
            ),
            DataType::F32 => (f64::from(f32::from_le_bytes([b[0], b[1], b[2], b[3]])), 1.0),
        })
    }
}
