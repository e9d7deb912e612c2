//! A seeded family of body shapes of one template mesh: smooth,
//! region-wise anisotropic scalings (thicker legs, a longer trunk, a wider
//! torso) on top of a global anisotropic scaling.
//!
//! A [`ShapeFamily`] plays the role SMPL's shape space plays in the paper's
//! arbitrary-source experiment: every member has the template's
//! connectivity, and [`ShapeFamily::pose_space`] poses a member with the
//! deformation space of the template (the same handle regions, by vertex,
//! turning about the moved centres).
//!
//! ## The map
//! For log-scales `s_k` (per region, per axis) and `g` (global, per axis),
//! a template point `p` goes to
//!
//! ```text
//! q = p + sum_k w_k(p) (exp(s_k) - 1) * (p - c_k),   w_k(p) = exp(-|p - c_k|^2 / (2 r_k^2))
//! shape(p) = c + exp(g) * (q - c)      (computed as q + (exp(g) - 1) * (q - c))
//! ```
//!
//! with `*` and `exp` per axis (x, y, z of the template's frame), `c_k`,
//! `r_k` the regions' centres and radii and `c` the family's centre. The
//! map is smooth; [`ShapeFamily::realize`] refuses parameters that turn a
//! face over.
//!
//! ## Sampling
//! The parameters of member `index` under `seed` are a pure function of
//! `(seed, index)`: a ChaCha8 stream keyed by `seed`, on stream number
//! `index`, reads three uniforms in `[-1, 1]` for the global scaling (times
//! [`ShapeFamily::max_global`]), then three per region (times
//! [`ShapeFamily::max_region`]).

use mfm_geometry::TriMesh;
use mfm_geometry::mesh::{cross, dot, sub};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::error::{DeformError, Result};
use crate::handles::{Handle, HandleSet};
use crate::space::DeformSpace;

/// Default largest log-scale of a region along an axis (`exp(0.25)` is
/// about 1.28).
pub const DEFAULT_MAX_REGION: f64 = 0.25;

/// Default largest log-scale of the global scaling along an axis.
pub const DEFAULT_MAX_GLOBAL: f64 = 0.12;

/// Default influence radius of a region, as a fraction of the template's
/// bounding-box diagonal.
pub const DEFAULT_REGION_RADIUS: f64 = 0.18;

/// One region of a [`ShapeFamily`]: a Gaussian bump of influence.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ShapeRegion {
    /// The centre the region's scaling is about (template coordinates).
    pub center: [f64; 3],
    /// The standard deviation of the influence (same units).
    pub radius: f64,
}

/// The parameters of one member of a [`ShapeFamily`]: natural-log scale
/// factors per axis.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ShapeParams {
    /// Global log-scales (x, y, z).
    pub global: [f64; 3],
    /// Log-scales of each region, in region order.
    pub regions: Vec<[f64; 3]>,
}

impl ShapeParams {
    /// The template itself (every scale 1) for a family of `regions`
    /// regions.
    pub fn identity(regions: usize) -> Self {
        Self {
            global: [0.0; 3],
            regions: vec![[0.0; 3]; regions],
        }
    }
}

/// A family of shapes of one template; see the [module docs](self).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ShapeFamily {
    /// The regions scaled independently.
    pub regions: Vec<ShapeRegion>,
    /// The centre of the global scaling (the template's area centroid for
    /// [`ShapeFamily::auto`]).
    pub center: [f64; 3],
    /// Largest absolute log-scale of a region along an axis.
    pub max_region: f64,
    /// Largest absolute log-scale of the global scaling along an axis.
    pub max_global: f64,
}

impl ShapeFamily {
    /// A family on `template` with `count` regions placed like automatic
    /// handles ([`HandleSet::auto`]: one at the area centroid, the others
    /// at extremities by farthest-point sampling), each of influence radius
    /// [`DEFAULT_REGION_RADIUS`] times the bounding-box diagonal, and the
    /// default ranges. Cost: that of [`HandleSet::auto`].
    ///
    /// # Errors
    /// [`DeformError::InvalidParameter`] for `count == 0`; the errors of
    /// [`HandleSet::auto`].
    pub fn auto(template: &TriMesh, count: usize) -> Result<Self> {
        if count == 0 {
            return Err(DeformError::InvalidParameter {
                name: "shape regions",
                expected: "at least 1",
                found: "0".into(),
            });
        }
        let placed = HandleSet::auto(template, count - 1, 0.05).map_err(|e| match e {
            DeformError::HandlePlacement { reason, .. } => DeformError::RegionPlacement {
                requested: count,
                reason: reason.replace("moving handles", "regions besides the centre one"),
            },
            other => other,
        })?;
        let radius = DEFAULT_REGION_RADIUS * template.bounding_box_diagonal();
        Ok(Self {
            regions: placed
                .iter()
                .map(|h| ShapeRegion {
                    center: h.center,
                    radius,
                })
                .collect(),
            center: placed.anchor.center,
            max_region: DEFAULT_MAX_REGION,
            max_global: DEFAULT_MAX_GLOBAL,
        })
    }

    /// Checks the ranges (finite, `>= 0`), the radii (finite, `> 0`) and
    /// the centres (finite).
    ///
    /// # Errors
    /// [`DeformError::InvalidParameter`] naming the field.
    pub fn validate(&self) -> Result<()> {
        let bad = |name: &'static str, expected: &'static str, found: String| {
            Err(DeformError::InvalidParameter {
                name,
                expected,
                found,
            })
        };
        for (name, v) in [
            ("max_region", self.max_region),
            ("max_global", self.max_global),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return bad(name, "a finite log-scale >= 0", v.to_string());
            }
        }
        if !self.center.iter().all(|x| x.is_finite()) {
            return bad("center", "finite coordinates", format!("{:?}", self.center));
        }
        for r in &self.regions {
            if !(r.radius.is_finite() && r.radius > 0.0 && r.center.iter().all(|x| x.is_finite())) {
                return bad(
                    "shape region",
                    "a finite centre and a finite radius > 0",
                    format!("{r:?}"),
                );
            }
        }
        Ok(())
    }

    /// The parameters of member `index` under `seed` (see the [module
    /// docs](self)). Cost: `O(regions)`.
    pub fn sample_params(&self, seed: u64, index: usize) -> ShapeParams {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        rng.set_stream(index as u64);
        let mut axes = |max: f64| -> [f64; 3] {
            std::array::from_fn(|_| max * (2.0 * rng.random::<f64>() - 1.0))
        };
        let global = axes(self.max_global);
        let regions = (0..self.regions.len())
            .map(|_| axes(self.max_region))
            .collect();
        ShapeParams { global, regions }
    }

    /// The image of one template point under `params` (the map of the
    /// [module docs](self)). `params` must have one entry per region.
    pub fn apply(&self, params: &ShapeParams, p: [f64; 3]) -> [f64; 3] {
        let mut q = p;
        for (region, s) in self.regions.iter().zip(&params.regions) {
            let d = sub(p, region.center);
            let w = (-dot(d, d) / (2.0 * region.radius * region.radius)).exp();
            for a in 0..3 {
                q[a] += w * s[a].exp_m1() * d[a];
            }
        }
        // written as q + (e^g - 1)(q - c) so that zero log-scales give p exactly
        std::array::from_fn(|a| q[a] + params.global[a].exp_m1() * (q[a] - self.center[a]))
    }

    fn check_params(&self, params: &ShapeParams) -> Result<()> {
        if params.regions.len() != self.regions.len() {
            return Err(DeformError::SizeMismatch {
                what: "shape parameters (one per region)",
                expected: self.regions.len(),
                found: params.regions.len(),
            });
        }
        let all = std::iter::once(&params.global).chain(&params.regions);
        for (i, s) in all.enumerate() {
            if !s.iter().all(|x| x.is_finite()) {
                return Err(DeformError::NonFinite {
                    what: "shape log-scales (index 0 is the global one)",
                    index: i,
                    value: *s,
                });
            }
        }
        Ok(())
    }

    /// The member `params` of the family on `template` (any triangulation
    /// of the surface the family was made for): its vertices mapped, the
    /// connectivity kept. Cost: `O(V · regions + F)`.
    ///
    /// # Errors
    /// [`DeformError::SizeMismatch`] / [`DeformError::NonFinite`] for
    /// parameters that do not fit the family; [`DeformError::FoldedShape`]
    /// when a face's normal turns by more than 90 degrees.
    pub fn realize(&self, template: &TriMesh, params: &ShapeParams) -> Result<TriMesh> {
        self.validate()?;
        self.check_params(params)?;
        let moved: Vec<[f64; 3]> = template
            .positions()
            .iter()
            .map(|&p| self.apply(params, p))
            .collect();
        let before = template.positions();
        for (f, tri) in template.faces().iter().enumerate() {
            let normal = |pos: &[[f64; 3]]| {
                let [a, b, c] = tri.map(|i| pos[i as usize]);
                cross(sub(b, a), sub(c, a))
            };
            let (n0, n1) = (normal(before), normal(&moved));
            if dot(n0, n0) > 0.0 && dot(n0, n1) <= 0.0 {
                return Err(DeformError::FoldedShape { face: f });
            }
        }
        template
            .with_positions(moved)
            .map_err(|e| DeformError::InvalidParameter {
                name: "shape parameters",
                expected: "a map to finite positions",
                found: e.to_string(),
            })
    }

    /// The deformation space that poses the member `params`: `template`'s
    /// `space` with every handle centre moved by the shape map (radii
    /// scaled by the global scaling's geometric mean), and the handles'
    /// vertex regions on the template, which the member keeps by vertex.
    /// Build the member's solver with [`crate::Arap::with_regions`] on
    /// these regions, then [`DeformSpace::realize`] poses it.
    ///
    /// # Errors
    /// As [`HandleSet::regions`] on `template`, and for parameters that do
    /// not fit the family.
    pub fn pose_space(
        &self,
        template: &TriMesh,
        space: &DeformSpace,
        params: &ShapeParams,
    ) -> Result<(DeformSpace, Vec<Vec<usize>>)> {
        self.check_params(params)?;
        let regions = space.handles.regions(template)?;
        let scale = (params.global.iter().sum::<f64>() / 3.0).exp();
        let moved = |h: &Handle| Handle {
            center: self.apply(params, h.center),
            radius: h.radius * scale,
        };
        let handles = HandleSet::new(
            moved(&space.handles.anchor),
            space.handles.moving.iter().map(moved).collect(),
        )?;
        Ok((
            DeformSpace {
                handles,
                ..space.clone()
            },
            regions,
        ))
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use crate::arap::Arap;
    use mfm_geometry::procedural;

    #[test]
    fn identity_parameters_leave_the_template_and_samples_are_pure() {
        let mesh = procedural::blob(2).unwrap();
        let family = ShapeFamily::auto(&mesh, 4).unwrap();
        assert_eq!(family.regions.len(), 4);
        let same = family.realize(&mesh, &ShapeParams::identity(4)).unwrap();
        assert_eq!(same.positions(), mesh.positions());
        let a = family.sample_params(7, 3);
        assert_eq!(a, family.sample_params(7, 3));
        assert_ne!(a, family.sample_params(7, 4));
        assert_ne!(a, family.sample_params(8, 3));
        for s in std::iter::once(&a.global).chain(&a.regions) {
            assert!(s.iter().all(|x| x.abs() <= DEFAULT_MAX_REGION));
        }
        assert!(a.global.iter().all(|x| x.abs() <= DEFAULT_MAX_GLOBAL));
    }

    #[test]
    fn a_region_scales_what_is_near_it_and_leaves_what_is_far() {
        let family = ShapeFamily {
            regions: vec![ShapeRegion {
                center: [0.0; 3],
                radius: 0.1,
            }],
            center: [0.0; 3],
            max_region: 0.3,
            max_global: 0.0,
        };
        let params = ShapeParams {
            global: [0.0; 3],
            regions: vec![[0.2, 0.0, -0.2]],
        };
        // near the centre the map is the scaling itself (w ~ 1)
        let p = [1e-3, 1e-3, 1e-3];
        let q = family.apply(&params, p);
        assert!((q[0] / p[0] - 0.2f64.exp()).abs() < 1e-4);
        assert!((q[1] / p[1] - 1.0).abs() < 1e-12);
        assert!((q[2] / p[2] - (-0.2f64).exp()).abs() < 1e-4);
        // ten radii away it does not move
        let far = [1.0, 0.0, 0.0];
        let moved = family.apply(&params, far);
        assert!((moved[0] - 1.0).abs() < 1e-15);
    }

    #[test]
    fn too_large_scales_are_refused_and_wrong_sizes_named() {
        let mesh = procedural::blob(2).unwrap();
        let family = ShapeFamily::auto(&mesh, 3).unwrap();
        let e = family
            .realize(&mesh, &ShapeParams::identity(2))
            .unwrap_err();
        assert!(matches!(
            e,
            DeformError::SizeMismatch {
                expected: 3,
                found: 2,
                ..
            }
        ));
        // a region squashed to a hundredth along x folds the surface near it
        let mut params = ShapeParams::identity(3);
        params.regions[1] = [-6.0, 0.0, 0.0];
        params.regions[2] = [3.0, 3.0, 3.0];
        let e = family.realize(&mesh, &params).unwrap_err();
        assert!(matches!(e, DeformError::FoldedShape { .. }), "{e}");
        let mut params = ShapeParams::identity(3);
        params.global[1] = f64::NAN;
        assert!(matches!(
            family.realize(&mesh, &params).unwrap_err(),
            DeformError::NonFinite { index: 0, .. }
        ));
    }

    #[test]
    fn a_member_is_posed_with_the_template_regions() {
        let mesh = procedural::blob(2).unwrap();
        let handles = HandleSet::auto(&mesh, 3, 0.1).unwrap();
        let space = DeformSpace::new(&mesh, handles);
        let family = ShapeFamily::auto(&mesh, 5).unwrap();
        let params = family.sample_params(3, 0);
        let member = family.realize(&mesh, &params).unwrap();
        let (posing, regions) = family.pose_space(&mesh, &space, &params).unwrap();
        assert_eq!(regions, space.handles.regions(&mesh).unwrap());
        let arap = Arap::with_regions(&member, &posing.handles, regions).unwrap();
        // the identity pose is the member itself
        let rest = posing
            .realize(&arap, &crate::DeformParams::identity(3))
            .unwrap();
        let err = rest
            .iter()
            .zip(member.positions())
            .map(|(a, b)| mfm_geometry::mesh::norm(sub(*a, *b)))
            .fold(0.0, f64::max);
        assert!(err < 1e-6 * member.bounding_box_diagonal(), "{err}");
        // a random pose moves it, and the identity-shape family member posed
        // the same way is the template posed by the template's own space
        let pose = space.sample_params(5, 1);
        let posed = posing.realize(&arap, &pose).unwrap();
        assert!(posed != rest);
        let (plain, plain_regions) = family
            .pose_space(&mesh, &space, &ShapeParams::identity(5))
            .unwrap();
        assert_eq!(plain, space);
        let a = Arap::with_regions(&mesh, &plain.handles, plain_regions).unwrap();
        let b = Arap::new(&mesh, &space.handles).unwrap();
        assert_eq!(
            plain.realize(&a, &pose).unwrap(),
            space.realize(&b, &pose).unwrap()
        );
    }

    #[test]
    fn regions_given_by_hand_are_checked() {
        let mesh = procedural::blob(2).unwrap();
        let handles = HandleSet::auto(&mesh, 2, 0.1).unwrap();
        let mut regions = handles.regions(&mesh).unwrap();
        let e = Arap::with_regions(&mesh, &handles, regions[..2].to_vec()).unwrap_err();
        assert!(matches!(e, DeformError::SizeMismatch { .. }));
        let first = regions[0][0];
        regions[1].push(first);
        let e = Arap::with_regions(&mesh, &handles, regions.clone()).unwrap_err();
        assert!(e.to_string().contains(&format!("vertex {first}")), "{e}");
        regions[1].pop();
        regions[2].clear();
        assert!(Arap::with_regions(&mesh, &handles, regions).is_err());
    }
}
