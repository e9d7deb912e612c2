//! Free space on a file system.

use crate::error::FileError;
use std::path::Path;

/// Bytes available to this user on the file system holding `path` (its
/// nearest existing ancestor when `path` does not exist yet), or `None`
/// where the platform cannot tell.
///
/// # Errors
/// [`FileError::Io`] when no ancestor of `path` can be queried.
pub fn available_bytes(path: &Path) -> Result<Option<u64>, FileError> {
    let absolute = std::path::absolute(path).map_err(|e| FileError::io(path, e))?;
    let mut p = absolute.as_path();
    while !p.exists() {
        match p.parent() {
            Some(q) => p = q,
            None => break,
        }
    }
    statvfs_available(p).map_err(|e| FileError::io(p, e))
}

#[cfg(unix)]
fn statvfs_available(p: &Path) -> std::io::Result<Option<u64>> {
    use std::os::unix::ffi::OsStrExt;
    let c = std::ffi::CString::new(p.as_os_str().as_bytes())
        .map_err(|_| std::io::Error::other("the path holds a NUL byte"))?;
    let mut st = std::mem::MaybeUninit::<libc::statvfs>::zeroed();
    // SAFETY: `c` is a NUL-terminated path and `st` is valid for writes of
    // one `statvfs`; it is read only after the call reports success.
    let rc = unsafe { libc::statvfs(c.as_ptr(), st.as_mut_ptr()) };
    if rc != 0 {
        return Err(std::io::Error::last_os_error());
    }
    // SAFETY: statvfs returned 0, so it filled the struct.
    let st = unsafe { st.assume_init() };
    #[allow(clippy::unnecessary_cast)] // the field types differ by platform
    Ok(Some(
        (st.f_bavail as u64).saturating_mul(st.f_frsize as u64),
    ))
}

#[cfg(not(unix))]
fn statvfs_available(_: &Path) -> std::io::Result<Option<u64>> {
    Ok(None)
}

/// Refuses an output of `needed` bytes at `path` when its file system has
/// less free (with 1% and 16 MiB to spare).
///
/// # Errors
/// [`FileError::NoSpace`] with both numbers.
pub fn ensure_space(path: &Path, needed: u64) -> Result<(), FileError> {
    if let Some(available) = available_bytes(path)? {
        let margin = (available / 100).max(16 << 20);
        if needed.saturating_add(margin) > available {
            return Err(FileError::NoSpace {
                path: path.to_path_buf(),
                needed,
                available,
            });
        }
    }
    Ok(())
}

/// `1.5 GB`-style sizes (powers of 1000, three significant digits).
pub fn human_bytes(n: u64) -> String {
    const UNITS: [&str; 7] = ["B", "kB", "MB", "GB", "TB", "PB", "EB"];
    let mut x = n as f64;
    let mut unit = 0;
    while x >= 1000.0 && unit + 1 < UNITS.len() {
        x /= 1000.0;
        unit += 1;
    }
    match (unit, x) {
        (0, _) => format!("{n} B"),
        (_, x) if x >= 100.0 => format!("{x:.0} {}", UNITS[unit]),
        (_, x) if x >= 10.0 => format!("{x:.1} {}", UNITS[unit]),
        _ => format!("{x:.2} {}", UNITS[unit]),
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn human_sizes() {
        assert_eq!(super::human_bytes(12), "12 B");
        assert_eq!(super::human_bytes(1_500_000), "1.50 MB");
        assert_eq!(super::human_bytes(999_499), "999 kB");
        assert_eq!(super::human_bytes(2_654_000_000_000_000), "2.65 PB");
    }
}
