//! Embeds an rpath to libtorch's library folder into this crate's tests and
//! passes the folder on to dependent crates as `DEP_MFM_NET_LIBTORCH_LIB`
//! (this crate's `links` key is "mfm_net"). The folder comes from the
//! kernels crate's build script (`DEP_MFM_KERNELS_LIBTORCH_LIB`), which also
//! compiles the C++ autograd shim; see `crates/kernels/build.rs`.

fn main() {
    let lib = mfm_libtorch_link::link_libtorch_of("MFM_KERNELS", "mfm-kernels");
    println!("cargo:libtorch_lib={lib}");
}
