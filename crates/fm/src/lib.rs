//! # mfm-fm
//!
//! Flow matching on meshes: datasets, training, sampling and metrics.
//! Not implemented yet: it lands with the flow-matching issue. The crate
//! exists so the workspace layout is complete; it exports nothing.
