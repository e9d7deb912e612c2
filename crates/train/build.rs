//! Embeds an rpath to libtorch's library folder into this crate's binaries and
//! tests, so they run without `LD_LIBRARY_PATH`, and with a CUDA libtorch keeps
//! `libtorch_cuda.so` linked. The folder comes from the net crate's build
//! script (`DEP_MFM_NET_LIBTORCH_LIB`); see `crates/net/build.rs`.

fn main() {
    mfm_libtorch_link::link_libtorch_of("MFM_NET", "mfm-net");
}
