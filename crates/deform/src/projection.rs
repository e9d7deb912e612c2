//! The plausibility metric: how far a shape is from the deformation space.
//!
//! [`project`] maps a shape (new positions for the vertices of the mesh an
//! [`Arap`] was built on) to the closest-looking member of a
//! [`DeformSpace`], in four steps:
//! 1. fit a rigid motion to each handle region (mass-weighted Kabsch from
//!    the rest positions of the region to the shape's);
//! 2. express every moving handle's motion relative to the fitted anchor
//!    motion (`T_a^-1 T_k`), so the anchor is back at the identity, as in
//!    the space; these are the fitted [`DeformParams`];
//! 3. ARAP-deform the rest shape with those parameters
//!    ([`DeformSpace::arap`] options);
//! 4. rigidly align the result to the shape (mass-weighted Kabsch,
//!    rotation and translation), which undoes the anchor motion and any
//!    global alignment of the shape.
//!
//! The metric is the mass-weighted mean squared distance to the projection,
//! `mse = sum_v m_v |shape_v - proj_v|^2 / sum_v m_v` (`m` the lumped mass of
//! the rest mesh), in squared length units: divide by `diagonal^2` for a
//! scale-free number. A shape of the space (up to a rigid motion) projects
//! onto itself (mse at round-off level); a shape whose free vertices moved
//! away from the ARAP solution does not. It works on any triangulation: build
//! the `Arap` on that mesh with the same handle set.
//!
//! # Example
//! ```
//! use mfm_deform::{project, Arap, DeformSpace, HandleSet};
//! use mfm_geometry::procedural;
//!
//! let mesh = procedural::blob(2).unwrap();
//! let space = DeformSpace::new(&mesh, HandleSet::auto(&mesh, 3, 0.1).unwrap());
//! let arap = Arap::new(&mesh, &space.handles).unwrap();
//! let shape = space.realize(&arap, &space.sample_params(7, 0)).unwrap();
//! let p = project(&arap, &space, &shape).unwrap();
//! assert!(p.mse < 1e-12 * space.diagonal * space.diagonal);
//! ```

use serde::{Deserialize, Serialize};

use crate::align::align_rigid;
use crate::arap::Arap;
use crate::error::{DeformError, Result};
use crate::handles::{DeformParams, RigidParams};
use crate::rigid::{RigidTransform, fit_rigid};
use crate::space::DeformSpace;

/// Result of [`project`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Projection {
    /// The fitted parameters (one motion per moving handle, relative to the
    /// fitted anchor motion).
    pub params: DeformParams,
    /// The ARAP shape of `params`, rigidly aligned to the input shape.
    pub positions: Vec<[f64; 3]>,
    /// Mass-weighted mean squared distance from the shape to `positions`.
    pub mse: f64,
}

/// Projects `shape` onto the deformation space; see the [module docs](self).
///
/// Cost: one ARAP deformation plus `O(V)`.
///
/// # Errors
/// [`DeformError::InvalidParameter`] if `arap` was built with another handle
/// set than `space`; [`DeformError::SizeMismatch`] /
/// [`DeformError::NonFinite`] for a bad shape; errors of [`Arap::deform`].
pub fn project(arap: &Arap, space: &DeformSpace, shape: &[[f64; 3]]) -> Result<Projection> {
    if arap.handles() != &space.handles {
        return Err(DeformError::InvalidParameter {
            name: "arap",
            expected: "a solver built with the space's handle set",
            found: "a solver with another handle set".to_string(),
        });
    }
    let rest = arap.rest();
    let n = rest.num_vertices();
    crate::align::check_shape(n, shape)?;
    let mass = arap.mass();
    let fitted: Vec<RigidTransform> = arap
        .regions()
        .iter()
        .map(|region| {
            let src: Vec<[f64; 3]> = region.iter().map(|&v| rest.positions()[v]).collect();
            let dst: Vec<[f64; 3]> = region.iter().map(|&v| shape[v]).collect();
            let mut w: Vec<f64> = region.iter().map(|&v| mass[v]).collect();
            let total: f64 = w.iter().sum();
            if total.is_nan() || total <= 0.0 {
                // a region of unreferenced vertices only: weigh them equally
                w.iter_mut().for_each(|x| *x = 1.0);
            }
            fit_rigid(&src, &dst, &w).unwrap_or_default()
        })
        .collect();
    let anchor_inv = fitted[0].inverse();
    let params = DeformParams {
        handles: fitted[1..]
            .iter()
            .zip(&space.handles.moving)
            .map(|(t, h)| RigidParams::from_transform(&anchor_inv.after(t), h.center))
            .collect(),
    };
    let deformed = arap.deform(&params, &space.arap)?;
    let positions = align_rigid(rest, &deformed.positions, shape)?;
    let total: f64 = mass.iter().sum();
    let weighted: f64 = shape
        .iter()
        .zip(&positions)
        .zip(mass)
        .map(|((a, b), m)| {
            let d = [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
            m * (d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
        })
        .sum();
    Ok(Projection {
        params,
        positions,
        mse: weighted / total,
    })
}
