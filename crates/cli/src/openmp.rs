//! How libtorch's OpenMP workers wait between parallel regions, chosen
//! before libtorch starts them.
//!
//! libgomp (the OpenMP runtime that ships with libtorch) lets a worker that
//! finished its part of a region spin for `GOMP_SPINCOUNT` iterations
//! before it sleeps, 300,000 by default (about a millisecond). On an idle
//! machine that only burns a core that has nothing else to do; beside
//! another busy process (a second `mfm train`, a cluster neighbour) the
//! spinning workers take the cores the other threads need: measured on 2
//! cores, a training step beside a second training took 3.1-3.6x its idle
//! time, a sample 2.9x. With 1,000 spins (libgomp's own choice when it
//! knows a machine is oversubscribed) the same took 1.8-2.0x and 1.7-1.9x
//! (two equal jobs on two cores cannot do better than 2x), while idle runs
//! stayed within their run-to-run spread (docs/BENCHMARKS.md, "Sharing the
//! machine").
//!
//! libgomp reads its settings once, in its own initializer, from the
//! environment the process started with (glibc resets the environment to
//! that array after the executable's `.preinit_array` has run, so a
//! variable set there is gone before libgomp looks). So when neither
//! `GOMP_SPINCOUNT` nor `OMP_WAIT_POLICY` is set, [`respawn_with_default`]
//! executes the program again from [`crate::preinit`] with
//! `GOMP_SPINCOUNT=1000` and [`MARKER`] added: same process id, same
//! arguments, before any library initializer or any of mfm's code has run
//! (it costs the dynamic loader's work once more, about 3 ms). A user's own
//! `GOMP_SPINCOUNT` or `OMP_WAIT_POLICY` is left as it is
//! (`GOMP_SPINCOUNT=300000` restores libgomp's default); child processes
//! inherit the setting.

/// `GOMP_SPINCOUNT=` the default spin count, as put in the environment.
const DEFAULT_ENTRY: &std::ffi::CStr = c"GOMP_SPINCOUNT=1000";

/// Marks an environment whose `GOMP_SPINCOUNT` mfm chose (and stops a
/// second respawn whatever happens).
pub(crate) const MARKER: &str = "MFM_OPENMP_DEFAULT";

/// `MARKER=1`.
const MARKER_ENTRY: &std::ffi::CStr = c"MFM_OPENMP_DEFAULT=1";

/// Where the wait policy of this process came from, for reports: the
/// user's `OMP_WAIT_POLICY` / `GOMP_SPINCOUNT` or mfm's default.
#[cfg_attr(not(feature = "network"), allow(dead_code))]
pub(crate) fn describe() -> String {
    let policy = std::env::var("OMP_WAIT_POLICY").ok();
    let spin = std::env::var("GOMP_SPINCOUNT").ok();
    let ours = std::env::var_os(MARKER).is_some();
    match (policy, spin) {
        (Some(p), Some(s)) => format!("OMP_WAIT_POLICY={p}, GOMP_SPINCOUNT={s}"),
        (Some(p), None) => format!("OMP_WAIT_POLICY={p}"),
        (None, Some(s)) if ours => format!("GOMP_SPINCOUNT={s} (mfm's default)"),
        (None, Some(s)) => format!("GOMP_SPINCOUNT={s}"),
        (None, None) => "libgomp's default".to_owned(),
    }
}

/// Executes `/proc/self/exe` again with [`DEFAULT_ENTRY`] and
/// [`MARKER_ENTRY`] added to `envp` when it has none of `GOMP_SPINCOUNT`,
/// `OMP_WAIT_POLICY` and [`MARKER`]; returns (and the process runs on with
/// libgomp's default) when it has one, or when the exec fails.
///
/// # Safety
/// `argv` and `envp` are the NUL-terminated arrays of NUL-terminated
/// strings the process started with (or null), and no other thread runs.
#[cfg(target_os = "linux")]
pub(crate) unsafe fn respawn_with_default(
    argv: *const *const libc::c_char,
    envp: *const *const libc::c_char,
) {
    if argv.is_null() || envp.is_null() {
        return;
    }
    let mut entries: Vec<*const libc::c_char> = Vec::new();
    let mut i = 0;
    loop {
        // SAFETY: envp is NUL-terminated (the caller's contract)
        let entry = unsafe { *envp.add(i) };
        if entry.is_null() {
            break;
        }
        // SAFETY: each entry is a NUL-terminated string
        let bytes = unsafe { std::ffi::CStr::from_ptr(entry) }.to_bytes();
        let named = |name: &[u8]| {
            bytes.len() > name.len() && bytes.starts_with(name) && bytes[name.len()] == b'='
        };
        if named(b"GOMP_SPINCOUNT") || named(b"OMP_WAIT_POLICY") || named(MARKER.as_bytes()) {
            return;
        }
        entries.push(entry);
        i += 1;
    }
    entries.extend([
        DEFAULT_ENTRY.as_ptr(),
        MARKER_ENTRY.as_ptr(),
        std::ptr::null(),
    ]);
    // SAFETY: both arrays are NUL-terminated arrays of C strings; execve
    // only returns on failure, leaving the process as it was
    unsafe {
        libc::execve(c"/proc/self/exe".as_ptr(), argv, entries.as_ptr());
    }
}

#[cfg(test)]
mod tests {
    /// The test binary carries the preinit function too: without a user
    /// setting, it runs with the default.
    #[test]
    #[cfg(target_os = "linux")]
    fn the_default_is_in_place_before_main() {
        let user = std::env::var_os("OMP_WAIT_POLICY").is_some()
            || (std::env::var_os("GOMP_SPINCOUNT").is_some()
                && std::env::var_os(super::MARKER).is_none());
        if !user {
            assert_eq!(
                std::env::var("GOMP_SPINCOUNT").ok().as_deref(),
                Some("1000")
            );
            assert!(super::describe().contains("(mfm's default)"));
        }
    }
}
