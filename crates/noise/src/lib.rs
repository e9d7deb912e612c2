//! # mfm-noise
//!
//! Matérn noise on meshes and its baselines, with spectral diagnostics.
//! Not implemented yet: the samplers land with the noise issue. The crate
//! exists so the workspace layout is complete; it exports nothing.
