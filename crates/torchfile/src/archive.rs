//! Reading a `torch.save` file: a zip archive with one top folder holding
//! `data.pkl` (the pickled object), `data/<key>` (one record of raw
//! little-endian elements per storage), `byteorder` and `version`.
//!
//! [`Checkpoint::open`] reads the pickle with the restricted reader
//! ([`crate::pickle`]) and refuses a file in which anything but plain
//! values, containers and tensors appears, naming the entry: the same rule
//! as `torch.load(weights_only=True)`. Tensor elements are read on demand
//! ([`Checkpoint::tensor`]), each storage checked against the size its
//! record declares.

use std::fs::File;
use std::io::Read;
use std::path::{Path, PathBuf};

use crate::error::{Result, TorchFileError};
use crate::pickle::{TensorRef, Value, unpickle};
use crate::tensor::TensorData;

/// Largest `data.pkl` accepted (the pickle of a checkpoint holds structure,
/// not elements).
pub const MAX_PICKLE_BYTES: u64 = 256 << 20;

/// An opened `torch.save` file.
pub struct Checkpoint {
    path: PathBuf,
    prefix: String,
    root: Value,
    zip: zip::ZipArchive<File>,
}

impl std::fmt::Debug for Checkpoint {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Checkpoint")
            .field("path", &self.path)
            .field("prefix", &self.prefix)
            .finish_non_exhaustive()
    }
}

impl Checkpoint {
    /// Opens `path` and reads its pickle.
    ///
    /// # Errors
    /// [`TorchFileError::Io`] if the file cannot be opened;
    /// [`TorchFileError::Archive`] if it is not a zip archive with one
    /// `<folder>/data.pkl`, or declares a big-endian byte order (a
    /// pre-1.6 `torch.save` file, not a zip, says so);
    /// [`TorchFileError::Pickle`] for a malformed pickle;
    /// [`TorchFileError::Entry`] naming the first entry holding an object
    /// the reader does not build.
    pub fn open(path: impl AsRef<Path>) -> Result<Self> {
        let path = path.as_ref().to_path_buf();
        let io = |source| TorchFileError::Io {
            path: path.clone(),
            source,
        };
        // a device or FIFO would be read forever: regular files only
        let meta = std::fs::metadata(&path).map_err(io)?;
        if !meta.is_file() {
            return Err(io(std::io::Error::other(
                "not a regular file (a device, FIFO, socket or folder); checkpoints are read \
                 from regular files only",
            )));
        }
        let file = File::open(&path).map_err(io)?;
        let archive_error = |message: String| TorchFileError::Archive {
            path: path.clone(),
            message,
        };
        let mut zip = zip::ZipArchive::new(file).map_err(|e| {
            archive_error(format!(
                "not a torch.save zip archive ({e}); files written by PyTorch before 1.6 \
                 (or with _use_new_zipfile_serialization=False) must be re-saved with a newer torch"
            ))
        })?;
        let pickles: Vec<String> = zip
            .file_names()
            .filter(|n| {
                n.strip_suffix("data.pkl")
                    .and_then(|p| p.strip_suffix('/'))
                    .is_some_and(|p| !p.is_empty() && !p.contains('/'))
            })
            .map(str::to_string)
            .collect();
        let pkl = match pickles.as_slice() {
            [one] => one.clone(),
            [] => {
                return Err(archive_error(
                    "no <folder>/data.pkl record: not a torch.save file".into(),
                ));
            }
            _ => {
                return Err(archive_error(format!(
                    "{} data.pkl records ({}): not one torch.save object",
                    pickles.len(),
                    pickles.join(", ")
                )));
            }
        };
        let prefix = pkl.trim_end_matches("data.pkl").to_string();
        if let Some(order) =
            read_record(&mut zip, &format!("{prefix}byteorder"), 64).map_err(&archive_error)?
        {
            let order = String::from_utf8_lossy(&order).trim().to_string();
            if order != "little" {
                return Err(archive_error(format!(
                    "byte order {order:?}: only little-endian checkpoints are read"
                )));
            }
        }
        let bytes = read_record(&mut zip, &pkl, MAX_PICKLE_BYTES)
            .map_err(&archive_error)?
            .ok_or_else(|| archive_error(format!("{pkl} cannot be read")))?;
        let root = unpickle(&bytes)?;
        if let Some((entry, class)) = root.first_object("") {
            return Err(TorchFileError::Entry {
                path,
                entry: if entry.is_empty() {
                    "<the whole object>".into()
                } else {
                    entry
                },
                message: format!(
                    "holds {class}, which is not a tensor or plain container; \
                     this reader never builds arbitrary pickled objects"
                ),
            });
        }
        Ok(Self {
            path,
            prefix,
            root,
            zip,
        })
    }

    /// The file's path.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The unpickled object (tensors as [`TensorRef`]s).
    pub fn root(&self) -> &Value {
        &self.root
    }

    /// The elements of tensor `t` (found at `entry`, for messages), dense
    /// and row-major.
    ///
    /// # Errors
    /// [`TorchFileError::Entry`] naming `entry` if its storage record is
    /// missing, of the wrong size, or the view reaches beyond it.
    pub fn tensor(&mut self, entry: &str, t: &TensorRef) -> Result<TensorData> {
        let fail = |message: String| TorchFileError::Entry {
            path: self.path.clone(),
            entry: entry.to_string(),
            message,
        };
        let esize = t.dtype.size();
        let expected = t
            .storage_numel
            .checked_mul(esize)
            .ok_or_else(|| fail(format!("a storage of {} elements", t.storage_numel)))?;
        let name = format!("{}data/{}", self.prefix, t.storage);
        let raw = read_record(&mut self.zip, &name, expected as u64 + 1)
            .map_err(fail)?
            .ok_or_else(|| fail(format!("its storage record {name} is missing")))?;
        if raw.len() != expected {
            return Err(fail(format!(
                "storage record {name} has {} bytes where {} {} elements need {expected}",
                raw.len(),
                t.storage_numel,
                t.dtype
            )));
        }
        let numel = t
            .shape
            .iter()
            .try_fold(1usize, |a, &d| a.checked_mul(d))
            .ok_or_else(|| fail(format!("shape {:?} overflows", t.shape)))?;
        if numel > 0 {
            let last = t
                .shape
                .iter()
                .zip(&t.stride)
                .try_fold(t.offset, |a, (&d, &s)| {
                    a.checked_add((d - 1).checked_mul(s)?)
                })
                .ok_or_else(|| fail("its strides overflow".into()))?;
            if last >= t.storage_numel {
                return Err(fail(format!(
                    "shape {:?} with strides {:?} at offset {} reaches element {last} of a storage of {}",
                    t.shape, t.stride, t.offset, t.storage_numel
                )));
            }
        }
        let mut bytes = Vec::with_capacity(numel * esize);
        let mut index = vec![0usize; t.shape.len()];
        for _ in 0..numel {
            let at = t.offset
                + index
                    .iter()
                    .zip(&t.stride)
                    .map(|(i, s)| i * s)
                    .sum::<usize>();
            bytes.extend_from_slice(&raw[at * esize..(at + 1) * esize]);
            for d in (0..index.len()).rev() {
                index[d] += 1;
                if index[d] < t.shape[d] {
                    break;
                }
                index[d] = 0;
            }
        }
        Ok(TensorData {
            dtype: t.dtype,
            shape: t.shape.clone(),
            bytes,
        })
    }

    /// The tensors of the dict at `entry` (`""`: the whole object;
    /// `"state_dict"`: a Lightning checkpoint's weights), in file order.
    ///
    /// # Errors
    /// [`TorchFileError::Entry`] if `entry` is missing or not a dict, or a
    /// key is not a string, or a value is not a tensor (naming it); the
    /// errors of [`Checkpoint::tensor`].
    pub fn state_dict(&mut self, entry: &str) -> Result<Vec<(String, TensorData)>> {
        let file = self.path.clone();
        let fail = |e: &str, message: String| TorchFileError::Entry {
            path: file.clone(),
            entry: e.to_string(),
            message,
        };
        let dict = if entry.is_empty() {
            self.root.clone()
        } else {
            self.root.get(entry).cloned().ok_or_else(|| {
                fail(
                    entry,
                    format!(
                        "missing (the checkpoint holds {})",
                        top_level_keys(&self.root)
                    ),
                )
            })?
        };
        let Value::Dict(items) = dict else {
            return Err(fail(
                entry,
                format!("is a {}, not a dict of tensors", dict.kind()),
            ));
        };
        let mut out = Vec::with_capacity(items.len());
        for (k, v) in items {
            let Value::Str(name) = k else {
                return Err(fail(
                    entry,
                    format!("has a {} key, not a parameter name", k.kind()),
                ));
            };
            let path = if entry.is_empty() {
                name.clone()
            } else {
                format!("{entry}.{name}")
            };
            let Value::Tensor(t) = v else {
                return Err(fail(&path, format!("is a {}, not a tensor", v.kind())));
            };
            let data = self.tensor(&path, &t)?;
            out.push((name, data));
        }
        Ok(out)
    }
}

/// The keys of a dict, for messages.
fn top_level_keys(v: &Value) -> String {
    match v {
        Value::Dict(items) => {
            let keys: Vec<String> = items
                .iter()
                .map(|(k, _)| match k {
                    Value::Str(s) => s.clone(),
                    other => format!("<{}>", other.kind()),
                })
                .collect();
            if keys.is_empty() {
                "no entries".into()
            } else {
                keys.join(", ")
            }
        }
        other => format!("a {}", other.kind()),
    }
}

/// Reads record `name` (`None` if absent), refusing more than `limit`
/// bytes.
fn read_record(
    zip: &mut zip::ZipArchive<File>,
    name: &str,
    limit: u64,
) -> std::result::Result<Option<Vec<u8>>, String> {
    let file = match zip.by_name(name) {
        Ok(f) => f,
        Err(zip::result::ZipError::FileNotFound) => return Ok(None),
        Err(e) => return Err(format!("record {name}: {e}")),
    };
    if file.size() > limit {
        return Err(format!(
            "record {name} has {} bytes, more than the {limit} it may hold",
            file.size()
        ));
    }
    let mut bytes = Vec::with_capacity(file.size() as usize);
    file.take(limit)
        .read_to_end(&mut bytes)
        .map_err(|e| format!("record {name}: {e}"))?;
    Ok(Some(bytes))
}
