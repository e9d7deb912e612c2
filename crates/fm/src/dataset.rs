//! On-disk datasets of signals over one mesh.
