//! Embeds an rpath to libtorch's library folder into this crate's tests and
//! passes the folder on to dependent crates as `DEP_MFM_NET_LIBTORCH_LIB`
//! (this crate's `links` key is "mfm_net"). The folder comes from the
//! kernels crate's build script (`DEP_MFM_KERNELS_LIBTORCH_LIB`), which also
//! compiles the C++ autograd shim; see `crates/kernels/build.rs`.

#[path = "../kernels/libtorch_link.rs"]
mod libtorch_link;

fn main() {
    println!("cargo:rerun-if-env-changed=DEP_MFM_KERNELS_LIBTORCH_LIB");
    println!("cargo:rerun-if-changed=../kernels/libtorch_link.rs");
    match std::env::var("DEP_MFM_KERNELS_LIBTORCH_LIB") {
        Ok(lib) => {
            libtorch_link::emit_link_args(&lib);
            println!("cargo:libtorch_lib={lib}");
        }
        Err(_) => panic!(
            "mfm-kernels did not report its libtorch folder (DEP_MFM_KERNELS_LIBTORCH_LIB); \
             set LIBTORCH to the torch install (see `cargo xtask setup`)"
        ),
    }
}
