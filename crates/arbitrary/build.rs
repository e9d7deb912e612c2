//! Embeds an rpath to libtorch's library folder into this crate's tests, so
//! they run without `LD_LIBRARY_PATH` (see `crates/fm/build.rs`).

fn main() {
    mfm_libtorch_link::link_libtorch_of("MFM_NET", "mfm-net");
}
