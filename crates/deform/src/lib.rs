#![doc = include_str!("../README.md")]

pub mod align;
mod anderson;
pub mod arap;
pub mod error;
pub mod handles;
pub mod projection;
pub mod rigid;
pub mod shape;
pub mod space;

pub use align::{align_rigid, align_to_rest, normalize_rest};
pub use arap::{Arap, ArapOptions, Deformation};
pub use error::{DeformError, Result};
pub use handles::{DEFAULT_RADIUS_FRACTION, DeformParams, Handle, HandleSet, RigidParams};
pub use projection::{Projection, project};
pub use shape::{ShapeFamily, ShapeParams, ShapeRegion};
pub use space::{DEFAULT_MAX_ANGLE, DEFAULT_MAX_SHIFT, DeformSpace, Shape};
