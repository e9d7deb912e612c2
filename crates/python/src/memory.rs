//! Refusing results that cannot fit in memory before allocating them: an
//! allocation failure would abort the interpreter instead of raising.

use pyo3::PyResult;
use pyo3::exceptions::PyMemoryError;

/// The memory the kernel says is available (`MemAvailable` of
/// `/proc/meminfo`), in bytes; `None` where it cannot be read.
fn available_bytes() -> Option<u64> {
    let text = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = text.lines().find(|l| l.starts_with("MemAvailable:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    kib.checked_mul(1024)
}

/// `MemoryError` when `count` values of `bytes_each` bytes (`what`, in
/// words) exceed the addressable size or the available memory.
pub fn require_memory(what: &str, count: u128, bytes_each: u128) -> PyResult<()> {
    let need = count.saturating_mul(bytes_each);
    let too_large = need > isize::MAX as u128;
    let available = available_bytes();
    if too_large || available.is_some_and(|a| need > a as u128) {
        let have = available.map_or("an unknown amount".to_owned(), |a| {
            format!("{:.1} GiB", a as f64 / (1u64 << 30) as f64)
        });
        return Err(PyMemoryError::new_err(format!(
            "{what} need {:.1} GiB; this machine has {have} available (ask for fewer)",
            need as f64 / (1u64 << 30) as f64
        )));
    }
    Ok(())
}
