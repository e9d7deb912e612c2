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

/// The bytes every writer leaves free beside its output on a file system
/// with `available` bytes free: 1% of them, at least 16 MiB (so that the
/// system and other programs can still write).
pub fn margin(available: u64) -> u64 {
    (available / 100).max(16 << 20)
}

/// Refuses an output of `needed` bytes at `path` when its file system has
/// less free than `needed` plus [`margin`]: the one rule of every writer.
///
/// # Errors
/// [`FileError::NoSpace`] with the three numbers.
pub fn ensure_space(path: &Path, needed: u64) -> Result<(), FileError> {
    if let Some(available) = available_bytes(path)? {
        let margin = margin(available);
        if needed.saturating_add(margin) > available {
            return Err(FileError::NoSpace {
                path: path.to_path_buf(),
                needed,
                margin,
                available,
            });
        }
    }
    Ok(())
}

/// Bytes of memory the kernel says are available to a new allocation
/// (`MemAvailable` of `/proc/meminfo`), or `None` where it cannot tell.
pub fn available_memory() -> Option<u64> {
    let text = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = text.lines().find(|l| l.starts_with("MemAvailable:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    kib.checked_mul(1024)
}

/// Refuses a request for `count` items of `bytes_each` bytes (`what`, in
/// words, for the message) held in memory at once, when that exceeds the
/// available memory ([`available_memory`]) or the address space, before
/// anything is allocated. The product is taken in `u128`, so no size
/// overflows.
///
/// # Errors
/// [`FileError::NoMemory`] with both numbers.
pub fn ensure_memory(what: &str, count: u128, bytes_each: u128) -> Result<(), FileError> {
    let needed = count.saturating_mul(bytes_each);
    let addressable = isize::MAX as u128;
    let available = available_memory().map_or(addressable, |a| u128::from(a).min(addressable));
    if needed > available {
        return Err(FileError::NoMemory {
            what: what.to_owned(),
            needed: u64::try_from(needed).unwrap_or(u64::MAX),
            available: u64::try_from(available).unwrap_or(u64::MAX),
        });
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
#[allow(clippy::unwrap_used)]
mod tests {
    #[test]
    fn human_sizes() {
        assert_eq!(super::human_bytes(12), "12 B");
        assert_eq!(super::human_bytes(1_500_000), "1.50 MB");
        assert_eq!(super::human_bytes(999_499), "999 kB");
        assert_eq!(super::human_bytes(2_654_000_000_000_000), "2.65 PB");
    }

    #[test]
    fn the_free_space_rule_is_stated_with_its_margin() {
        let dir = tempfile::tempdir().unwrap();
        let Some(available) = super::available_bytes(dir.path()).unwrap() else {
            return;
        };
        let margin = super::margin(available);
        assert!(margin >= 16 << 20 && margin >= available / 100);
        // fits with the margin (and room for other writers meanwhile), and
        // all the free space does not: the margin is the rule
        let fits = available
            .saturating_sub(2 * margin)
            .saturating_sub(256 << 20);
        if fits > 0 {
            super::ensure_space(dir.path(), fits).unwrap();
        }
        let e = super::ensure_space(dir.path(), available).unwrap_err();
        let text = e.to_string();
        assert!(
            text.contains("disk full")
                && text.contains("1% of the free space, at least 16 MiB")
                && text.contains(&super::human_bytes(margin)),
            "{text}"
        );
    }

    #[test]
    fn memory_beyond_the_machine_is_refused() {
        super::ensure_memory("a few bytes", 16, 8).unwrap();
        let e = super::ensure_memory("10^15 values", 10u128.pow(15), 8).unwrap_err();
        let text = e.to_string();
        assert!(
            text.starts_with("10^15 values: needs 8.00 PB of memory"),
            "{text}"
        );
        assert!(text.contains("ask for fewer"), "{text}");
    }
}
