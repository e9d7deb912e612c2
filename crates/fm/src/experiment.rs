//! Train/test meshes for experiments.
