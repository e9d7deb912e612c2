//! Embeds an rpath to libtorch's library folder into this crate's binaries and
//! tests, so they run without `LD_LIBRARY_PATH`. The folder comes from the net
//! crate's build script (`DEP_MFM_NET_LIBTORCH_LIB`); see `crates/net/build.rs`.

fn main() {
    println!("cargo:rerun-if-env-changed=DEP_MFM_NET_LIBTORCH_LIB");
    match std::env::var("DEP_MFM_NET_LIBTORCH_LIB") {
        Ok(lib) => println!("cargo:rustc-link-arg=-Wl,-rpath,{lib}"),
        Err(_) => panic!(
            "mfm-net did not report its libtorch folder (DEP_MFM_NET_LIBTORCH_LIB); \
             set LIBTORCH to the torch install (see `cargo xtask setup`)"
        ),
    }
}
