//! Writing tensors in the format of `torch.save`, so that
//! `torch.load(path, weights_only=True)` reads them.
//!
//! [`state_dict_archive`] builds the archive in memory (the caller writes
//! it atomically): `archive/data.pkl` is a protocol-2 pickle of an
//! `OrderedDict` of tensors, optionally inside a dict under one key (a
//! Lightning-style `{"state_dict": ...}` checkpoint); `archive/data/<i>`
//! holds tensor `i`'s little-endian elements (uncompressed, 64-byte
//! aligned, as PyTorch writes them); `archive/byteorder` and
//! `archive/version` are PyTorch's.

use std::io::{Cursor, Write};

use crate::tensor::TensorData;

/// The archive's top folder (PyTorch uses the file's stem; any name reads).
pub const ARCHIVE_FOLDER: &str = "archive";

/// The serialization format version PyTorch 2 writes.
pub const FORMAT_VERSION: &str = "3";

/// A `torch.save` archive of `tensors` (an `OrderedDict` in the given
/// order), wrapped as `{wrap: OrderedDict}` when `wrap` is given.
///
/// # Errors
/// The zip writer's error as text (it writes to memory, so only on
/// impossible sizes).
///
/// # Example
/// ```
/// use mfm_torchfile::{Checkpoint, TensorData, state_dict_archive};
/// let t = TensorData::from_f32(vec![2, 2], &[1.0, 2.0, 3.0, 4.0]);
/// let bytes = state_dict_archive(&[("w".into(), t.clone())], Some("state_dict")).unwrap();
/// let dir = tempfile::tempdir().unwrap();
/// let path = dir.path().join("m.ckpt");
/// std::fs::write(&path, bytes).unwrap();
/// let mut ckpt = Checkpoint::open(&path).unwrap();
/// assert_eq!(ckpt.state_dict("state_dict").unwrap(), vec![("w".to_string(), t)]);
/// ```
pub fn state_dict_archive(
    tensors: &[(String, TensorData)],
    wrap: Option<&str>,
) -> Result<Vec<u8>, String> {
    let mut p = Pickler::default();
    p.bytes.extend_from_slice(&[0x80, 2]);
    if let Some(key) = wrap {
        p.bytes.push(b'}');
        p.unicode(key);
    }
    p.ordered_dict();
    if !tensors.is_empty() {
        p.bytes.push(b'(');
        for (i, (name, t)) in tensors.iter().enumerate() {
            p.unicode(name);
            p.tensor(&i.to_string(), t);
        }
        p.bytes.push(b'u');
    }
    if wrap.is_some() {
        p.bytes.push(b's');
    }
    p.bytes.push(b'.');

    let mut zip = zip::ZipWriter::new(Cursor::new(Vec::new()));
    let stored = zip::write::FileOptions::default()
        .compression_method(zip::CompressionMethod::Stored)
        .last_modified_time(zip::DateTime::default());
    let mut put = |name: String, data: &[u8]| -> Result<(), String> {
        zip.start_file_aligned(name.clone(), stored, 64)
            .map_err(|e| format!("{name}: {e}"))?;
        zip.write_all(data).map_err(|e| format!("{name}: {e}"))
    };
    put(format!("{ARCHIVE_FOLDER}/data.pkl"), &p.bytes)?;
    put(format!("{ARCHIVE_FOLDER}/byteorder"), b"little")?;
    for (i, (_, t)) in tensors.iter().enumerate() {
        put(format!("{ARCHIVE_FOLDER}/data/{i}"), &t.bytes)?;
    }
    put(
        format!("{ARCHIVE_FOLDER}/version"),
        format!("{FORMAT_VERSION}\n").as_bytes(),
    )?;
    let cursor = zip.finish().map_err(|e| format!("zip: {e}"))?;
    Ok(cursor.into_inner())
}

/// A protocol-2 pickle writer for the few things a state dict needs.
#[derive(Default)]
struct Pickler {
    bytes: Vec<u8>,
}

impl Pickler {
    fn unicode(&mut self, s: &str) {
        self.bytes.push(b'X');
        self.bytes
            .extend_from_slice(&(s.len() as u32).to_le_bytes());
        self.bytes.extend_from_slice(s.as_bytes());
    }

    fn global(&mut self, module: &str, name: &str) {
        self.bytes.push(b'c');
        self.bytes.extend_from_slice(module.as_bytes());
        self.bytes.push(b'\n');
        self.bytes.extend_from_slice(name.as_bytes());
        self.bytes.push(b'\n');
    }

    fn int(&mut self, v: usize) {
        match i32::try_from(v) {
            Ok(small) => {
                self.bytes.push(b'J');
                self.bytes.extend_from_slice(&small.to_le_bytes());
            }
            Err(_) => {
                // LONG1 with 8 bytes and a zero byte for the sign.
                self.bytes.extend_from_slice(&[0x8a, 9]);
                self.bytes.extend_from_slice(&(v as u64).to_le_bytes());
                self.bytes.push(0);
            }
        }
    }

    fn int_tuple(&mut self, values: &[usize]) {
        self.bytes.push(b'(');
        for &v in values {
            self.int(v);
        }
        self.bytes.push(b't');
    }

    fn ordered_dict(&mut self) {
        self.global("collections", "OrderedDict");
        self.bytes.push(b')');
        self.bytes.push(b'R');
    }

    /// `torch._utils._rebuild_tensor_v2(storage, 0, shape, stride, False,
    /// OrderedDict())` with storage `key`.
    fn tensor(&mut self, key: &str, t: &TensorData) {
        self.global("torch._utils", "_rebuild_tensor_v2");
        self.bytes.push(b'(');
        // the storage's persistent id
        self.bytes.push(b'(');
        self.unicode("storage");
        self.global("torch", t.dtype.storage_class());
        self.unicode(key);
        self.unicode("cpu");
        self.int(t.numel());
        self.bytes.push(b't');
        self.bytes.push(b'Q');
        self.int(0);
        self.int_tuple(&t.shape);
        let mut stride = vec![1usize; t.shape.len()];
        for d in (0..t.shape.len().saturating_sub(1)).rev() {
            stride[d] = stride[d + 1] * t.shape[d + 1];
        }
        self.int_tuple(&stride);
        self.bytes.push(0x89);
        self.ordered_dict();
        self.bytes.push(b't');
        self.bytes.push(b'R');
    }
}
