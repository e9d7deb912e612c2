//! Embeds an rpath to libtorch's library folder into this crate's binaries and
//! tests, and passes the folder on to dependent crates.
//!
//! torch-sys reports the folder it linked against as `DEP_TCH_LIBTORCH_LIB`
//! (its `links` key is "tch"). Link arguments printed by a build script only
//! reach that package's own targets, so every crate with binaries or tests that
//! link libtorch has a build script doing the same; this one re-exports the
//! folder as `DEP_MFM_NET_LIBTORCH_LIB` for them.

fn main() {
    println!("cargo:rerun-if-env-changed=DEP_TCH_LIBTORCH_LIB");
    let Ok(lib) = std::env::var("DEP_TCH_LIBTORCH_LIB") else {
        panic!(
            "torch-sys did not report its libtorch folder (DEP_TCH_LIBTORCH_LIB); \
             set LIBTORCH to the torch install (see `cargo xtask setup`)"
        );
    };
    println!("cargo:rustc-link-arg=-Wl,-rpath,{lib}");
    println!("cargo:libtorch_lib={lib}");
}
