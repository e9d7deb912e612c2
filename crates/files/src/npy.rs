//! NumPy `.npy` arrays of floats: reading without trusting the header, and
//! writing at once or in streamed batches.
//!
//! Read: little- or big-endian `float32`/`float64` in C order (the layout
//! NumPy writes by default). Before any value is allocated the header's
//! shape is checked against the file's length, so a corrupt or hostile
//! header cannot make the reader allocate more than the file holds, and a
//! truncated file or one with bytes after the data is an error that says
//! how many bytes were expected.
//!
//! Write: little-endian C-order arrays through [`crate::AtomicFile`].
//! [`NpyStream`] writes the header first (the shape is known up front) and
//! then appends batches, so an output larger than memory is written with
//! the memory of one batch.

use crate::atomic::AtomicFile;
use crate::error::FileError;
use npyz::WriterBuilder;
use std::io::Write;
use std::path::Path;

/// A float array read from a `.npy` file.
#[derive(Clone, Debug, PartialEq)]
pub struct Array<T> {
    /// The shape, C order (last index fastest).
    pub shape: Vec<usize>,
    /// `shape.iter().product()` values, C order.
    pub values: Vec<T>,
}

/// A float type an array can be read as.
pub trait Float: Copy + npyz::Deserialize {
    /// From an `f32` value.
    fn from_f32(x: f32) -> Self;
    /// From an `f64` value (rounded for `f32`).
    fn from_f64(x: f64) -> Self;
}

impl Float for f32 {
    fn from_f32(x: f32) -> Self {
        x
    }
    fn from_f64(x: f64) -> Self {
        x as f32
    }
}

impl Float for f64 {
    fn from_f32(x: f32) -> Self {
        f64::from(x)
    }
    fn from_f64(x: f64) -> Self {
        x
    }
}

/// Reads the `.npy` file at `path` as `T`, converting `float32`/`float64`.
///
/// # Errors
/// [`FileError::Io`] when the file cannot be read; [`FileError::Format`],
/// naming the file, for anything that is not a C-order float array whose
/// data length matches its shape.
pub fn read<T: Float>(path: &Path) -> Result<Array<T>, FileError> {
    let bytes = crate::read_regular(path)?;
    from_bytes(&bytes).map_err(|message| FileError::format(path, message))
}

/// [`read`] on bytes in memory; the error is the message without the path.
///
/// # Errors
/// A message saying what is wrong.
pub fn from_bytes<T: Float>(bytes: &[u8]) -> Result<Array<T>, String> {
    let npy = npyz::NpyFile::new(bytes).map_err(|e| format!("not a .npy file ({e})"))?;
    if npy.order() == npyz::Order::Fortran {
        return Err(
            "the array is in Fortran order; save it in C order (numpy.ascontiguousarray)".into(),
        );
    }
    let size = match npy.dtype() {
        npyz::DType::Plain(t) if t.type_char() == npyz::TypeChar::Float => t.size_field(),
        other => {
            return Err(format!(
                "expected float32 or float64 values, found dtype {}",
                other.descr()
            ));
        }
    };
    if size != 4 && size != 8 {
        return Err(format!(
            "expected float32 or float64 values, found float{}",
            8 * size
        ));
    }
    let shape: Vec<u64> = npy.shape().to_vec();
    let count = shape
        .iter()
        .try_fold(1u64, |a, &s| a.checked_mul(s))
        .filter(|&c| c.checked_mul(size as u64).is_some())
        .ok_or_else(|| format!("the shape {shape:?} is too large to be an array"))?;
    let needed = count * size as u64;
    let inner: &[u8] = npy.into_inner();
    let have = inner.len() as u64;
    if have < needed {
        return Err(format!(
            "truncated: the shape {shape:?} of float{} needs {needed} data bytes, the file has {have}",
            8 * size
        ));
    }
    if have > needed {
        return Err(format!(
            "{} bytes after the {needed} data bytes the shape {shape:?} declares",
            have - needed
        ));
    }
    // The header again, now that its claims are checked against the length.
    let npy = npyz::NpyFile::new(bytes).map_err(|e| format!("not a .npy file ({e})"))?;
    let values: Vec<T> = if size == 4 {
        npy.into_vec::<f32>()
            .map_err(|e| format!("cannot read the values ({e})"))?
            .into_iter()
            .map(T::from_f32)
            .collect()
    } else {
        npy.into_vec::<f64>()
            .map_err(|e| format!("cannot read the values ({e})"))?
            .into_iter()
            .map(T::from_f64)
            .collect()
    };
    let shape = shape
        .iter()
        .map(|&s| {
            usize::try_from(s).map_err(|_| format!("the shape {shape:?} does not fit memory"))
        })
        .collect::<Result<_, _>>()?;
    Ok(Array { shape, values })
}

/// The header of a little-endian C-order array of `dtype` (`"<f4"`,
/// `"<f8"`) and `shape`.
fn header(dtype: &str, shape: &[u64]) -> std::io::Result<Vec<u8>> {
    let dtype = npyz::DType::parse(&format!("'{dtype}'"))?;
    let mut bytes = Vec::new();
    npyz::WriteOptions::new_header_only()
        .dtype(dtype)
        .shape(shape)
        .writer(&mut bytes)
        .write_header_only()?;
    Ok(bytes)
}

/// Bytes of a `.npy` file of `count` values of `value_bytes` each with
/// `shape` (header included).
pub fn file_bytes(shape: &[u64], value_bytes: u64) -> u64 {
    let count = shape.iter().fold(1u64, |a, &s| a.saturating_mul(s));
    let header =
        header(if value_bytes == 4 { "<f4" } else { "<f8" }, shape).map_or(128, |h| h.len() as u64);
    header.saturating_add(count.saturating_mul(value_bytes))
}

/// A value type [`NpyStream`] writes.
pub trait Element: Copy {
    /// The little-endian dtype string.
    const DTYPE: &'static str;
    /// The value's little-endian bytes, appended to `out`.
    fn put(self, out: &mut Vec<u8>);
}

impl Element for f32 {
    const DTYPE: &'static str = "<f4";
    fn put(self, out: &mut Vec<u8>) {
        out.extend_from_slice(&self.to_le_bytes());
    }
}

impl Element for f64 {
    const DTYPE: &'static str = "<f8";
    fn put(self, out: &mut Vec<u8>) {
        out.extend_from_slice(&self.to_le_bytes());
    }
}

/// A `.npy` file written in batches; it appears at its path, complete, on
/// [`NpyStream::finish`], and not at all when dropped before.
///
/// # Example
/// ```
/// let dir = tempfile::tempdir().unwrap();
/// let path = dir.path().join("a.npy");
/// let mut s = mfm_files::npy::NpyStream::<f32>::create(&path, &[2, 3]).unwrap();
/// s.append(&[1.0, 2.0, 3.0]).unwrap();
/// s.append(&[4.0, 5.0, 6.0]).unwrap();
/// s.finish().unwrap();
/// let a = mfm_files::npy::read::<f32>(&path).unwrap();
/// assert_eq!(a.shape, [2, 3]);
/// assert_eq!(a.values, [1.0, 2.0, 3.0, 4.0, 5.0, 6.0]);
/// ```
#[derive(Debug)]
pub struct NpyStream<T: Element> {
    file: AtomicFile,
    expected: u64,
    written: u64,
    buf: Vec<u8>,
    _marker: std::marker::PhantomData<T>,
}

impl<T: Element> NpyStream<T> {
    /// Starts the file with the header of `shape`.
    ///
    /// # Errors
    /// As [`AtomicFile::create`].
    pub fn create(path: impl AsRef<Path>, shape: &[u64]) -> Result<Self, FileError> {
        let path = path.as_ref();
        let mut file = AtomicFile::create(path)?;
        let head = header(T::DTYPE, shape).map_err(|e| FileError::io(path, e))?;
        file.write_all(&head).map_err(|e| FileError::io(path, e))?;
        Ok(Self {
            file,
            expected: shape.iter().fold(1u64, |a, &s| a.saturating_mul(s)),
            written: 0,
            buf: Vec::new(),
            _marker: std::marker::PhantomData,
        })
    }

    /// Appends values (C order).
    ///
    /// # Errors
    /// [`FileError::Format`] when more values arrive than the shape holds;
    /// [`FileError::Io`] for a failed write (a full disk).
    pub fn append(&mut self, values: &[T]) -> Result<(), FileError> {
        let n = values.len() as u64;
        if self.written + n > self.expected {
            return Err(FileError::format(
                self.file.path(),
                format!(
                    "internal error: {} values written to an array of {}",
                    self.written + n,
                    self.expected
                ),
            ));
        }
        self.buf.clear();
        for &v in values {
            v.put(&mut self.buf);
        }
        let path = self.file.path().to_path_buf();
        self.file
            .write_all(&self.buf)
            .map_err(|e| FileError::io(path, e))?;
        self.written += n;
        Ok(())
    }

    /// Values appended so far.
    pub fn written(&self) -> u64 {
        self.written
    }

    /// Commits the file.
    ///
    /// # Errors
    /// [`FileError::Format`] when fewer values were appended than the shape
    /// holds (the file is not written); as [`AtomicFile::commit`].
    pub fn finish(self) -> Result<(), FileError> {
        if self.written != self.expected {
            return Err(FileError::format(
                self.file.path(),
                format!(
                    "internal error: {} values written to an array of {}",
                    self.written, self.expected
                ),
            ));
        }
        self.file.commit()
    }
}

/// Writes `values` with `shape` at once.
///
/// # Errors
/// [`FileError::Format`] when the counts disagree; as [`NpyStream`].
pub fn write<T: Element>(
    path: impl AsRef<Path>,
    values: &[T],
    shape: &[u64],
) -> Result<(), FileError> {
    let mut s = NpyStream::<T>::create(path, shape)?;
    s.append(values)?;
    s.finish()
}
