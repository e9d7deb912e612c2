//! Embeds an rpath to libtorch's library folder into this crate's binaries and
//! tests (and, with a CUDA libtorch, keeps `libtorch_cuda.so` linked; see
//! `mfm-libtorch-link`), passes the folder on to dependent crates, and compiles the C++ shim
//! (`csrc/mfm_autograd.cpp`) that lets autograd call operations written in Rust.
//!
//! torch-sys reports the folder it linked against as `DEP_TCH_LIBTORCH_LIB`
//! (its `links` key is "tch"). Link arguments printed by a build script only
//! reach that package's own targets, so every crate with binaries or tests that
//! link libtorch (kernels, net, fm, arbitrary, cli) has a build script calling
//! the same logic; this one re-exports the folder as
//! `DEP_MFM_KERNELS_LIBTORCH_LIB` for net, whose build script passes it on as
//! `DEP_MFM_NET_LIBTORCH_LIB` to the crates above.
//!
//! The shim is compiled against the headers of the same libtorch
//! (`<lib>/../include` and `<lib>/../include/torch/csrc/api/include`), with the
//! C++11 ABI flag torch-sys uses (`LIBTORCH_CXX11_ABI`, default `1`, which is
//! what the pip wheels of torch 2.x are built with).

use std::path::PathBuf;

fn main() {
    println!("cargo:rerun-if-env-changed=LIBTORCH_CXX11_ABI");
    println!("cargo:rerun-if-changed=csrc/mfm_autograd.cpp");
    let lib = mfm_libtorch_link::link_libtorch_of("TCH", "torch-sys");
    println!("cargo:libtorch_lib={lib}");

    let root = PathBuf::from(&lib).join("..");
    let include = root.join("include");
    let api_include = include.join("torch/csrc/api/include");
    let abi = std::env::var("LIBTORCH_CXX11_ABI").unwrap_or_else(|_| "1".to_owned());
    cc::Build::new()
        .cpp(true)
        .pic(true)
        .warnings(false)
        .include(&include)
        .include(&api_include)
        .flag("-std=c++17")
        .flag(format!("-D_GLIBCXX_USE_CXX11_ABI={abi}"))
        .flag("-DGLOG_USE_GLOG_EXPORT")
        // ATen's `parallel_for` is an inline template over `#pragma omp
        // parallel` in OpenMP builds of torch: without `-fopenmp` it quietly
        // runs the whole range on the calling thread.
        .flag("-fopenmp")
        .opt_level(2)
        .file("csrc/mfm_autograd.cpp")
        .compile("mfm_autograd");
    // The OpenMP runtime is the one libtorch itself loads (the wheel ships
    // `libgomp.so.1` beside `libtorch_cpu.so`), so Rust kernels and torch's
    // own share one thread pool.
    println!("cargo:rustc-link-search=native={lib}");
    println!("cargo:rustc-link-lib=dylib:+verbatim=libgomp.so.1");
}
