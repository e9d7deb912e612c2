//! Embeds an rpath to libtorch's library folder into this crate's tests, so
//! they run without `LD_LIBRARY_PATH` (see `crates/fm/build.rs`).

#[path = "../kernels/libtorch_link.rs"]
mod libtorch_link;

fn main() {
    println!("cargo:rerun-if-env-changed=DEP_MFM_NET_LIBTORCH_LIB");
    println!("cargo:rerun-if-changed=../kernels/libtorch_link.rs");
    match std::env::var("DEP_MFM_NET_LIBTORCH_LIB") {
        Ok(lib) => libtorch_link::emit_link_args(&lib),
        Err(_) => panic!(
            "mfm-net did not report its libtorch folder (DEP_MFM_NET_LIBTORCH_LIB); \
             set LIBTORCH to the torch install (see `cargo xtask setup`)"
        ),
    }
}
