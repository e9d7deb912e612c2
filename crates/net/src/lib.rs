//! # mfm-net
//!
//! PoissonNet on libtorch through `tch` (the network itself lands with the
//! PoissonNet issue). This crate links the libtorch 2.13 shared libraries of
//! the project's Python environment (see `cargo xtask setup`); its build
//! script embeds an rpath so binaries run without `LD_LIBRARY_PATH`.
//! [`runtime`] reports what the linked libtorch provides.

pub mod runtime;
