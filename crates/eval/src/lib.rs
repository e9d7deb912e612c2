#![doc = include_str!("../README.md")]

pub mod arbitrary;
pub mod evaluation;
pub mod gaussian_baseline;
pub mod metrics;
pub mod pictures;
pub mod plausibility;
pub mod principal_plane;
pub mod quality;
pub mod shape_quality;
