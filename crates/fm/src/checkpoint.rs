//! Atomic checkpoints.
