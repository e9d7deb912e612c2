#![doc = include_str!("../README.md")]

use std::path::Path;

/// Prints the link arguments for binaries and tests linking the libtorch in
/// `lib` (its library folder):
///
/// - an rpath to `lib`, so they run without `LD_LIBRARY_PATH`;
/// - with a CUDA build of libtorch (`libtorch_cuda.so` in `lib`), that
///   library as a needed entry even though no symbol of it is referenced.
///   Rust links with `--as-needed`, which would drop it; libtorch then never
///   registers its CUDA backend and `tch::Cuda::is_available()` is false on a
///   machine with a GPU. `--push-state`/`--pop-state` keep the setting to this
///   one library.
pub fn emit_link_args(lib: &str) {
    println!("cargo:rustc-link-arg=-Wl,-rpath,{lib}");
    let cuda = Path::new(lib).join("libtorch_cuda.so");
    if cuda.is_file() {
        println!(
            "cargo:rustc-link-arg=-Wl,--push-state,--no-as-needed,{},--pop-state",
            cuda.display()
        );
    }
}

/// The libtorch folder a dependency's build script reported as
/// `DEP_<LINKS>_LIBTORCH_LIB` (`links` is that dependency's `links` key in
/// upper case: `TCH` for torch-sys, `MFM_KERNELS`, `MFM_NET`), with
/// [`emit_link_args`] already printed for it and the reruns declared.
///
/// Panics, naming `dependency` and the variable, when the variable is
/// missing (libtorch was not found; `LIBTORCH` unset).
pub fn link_libtorch_of(links: &str, dependency: &str) -> String {
    let var = format!("DEP_{links}_LIBTORCH_LIB");
    println!("cargo:rerun-if-env-changed={var}");
    let Ok(lib) = std::env::var(&var) else {
        panic!(
            "{dependency} did not report its libtorch folder ({var}); \
             set LIBTORCH to the torch install (see `cargo xtask setup`)"
        );
    };
    emit_link_args(&lib);
    lib
}
