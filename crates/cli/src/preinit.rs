//! What runs before `main` and before every shared library's initializer:
//! the executable's `.preinit_array` (Linux), in this order:
//! 1. [`crate::openmp::respawn_with_default`]: the process may start over
//!    with the OpenMP wait default in its environment;
//! 2. [`crate::output::early_signals::install`]: interrupts during
//!    libtorch's start-up end the process as an interrupt does.
//!
//! The order matters: a handler installed before the respawn would be
//! reset by it, leaving a window where a signal kills the process.

#[cfg(target_os = "linux")]
extern "C" fn before_libraries(
    _argc: libc::c_int,
    argv: *const *const libc::c_char,
    envp: *const *const libc::c_char,
) {
    // SAFETY: glibc calls preinit functions with the process's own
    // argument and environment arrays, before any other thread exists.
    unsafe { crate::openmp::respawn_with_default(argv, envp) };
    crate::output::early_signals::install();
}

#[cfg(target_os = "linux")]
#[used]
#[unsafe(link_section = ".preinit_array")]
static BEFORE_LIBRARIES: extern "C" fn(
    libc::c_int,
    *const *const libc::c_char,
    *const *const libc::c_char,
) = before_libraries;
