//! Embeds an rpath to libtorch's library folder into this crate's binaries and
//! tests, so they run without `LD_LIBRARY_PATH`, and with a CUDA libtorch keeps
//! `libtorch_cuda.so` linked. The folder comes from the net crate's build
//! script (`DEP_MFM_NET_LIBTORCH_LIB`); see `crates/net/build.rs`.

fn main() {
    // declared in every build, so that one without the network does not
    // rerun this script on every source change
    println!("cargo:rerun-if-env-changed=DEP_MFM_NET_LIBTORCH_LIB");
    if std::env::var_os("CARGO_FEATURE_NETWORK").is_none() {
        // built without the network: nothing links libtorch
        return;
    }
    mfm_libtorch_link::link_libtorch_of("MFM_NET", "mfm-net");
}
