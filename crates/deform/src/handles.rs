//! Handle regions and the rigid motions that drive them.
//!
//! A [`Handle`] is a ball in ambient space: its region on a mesh is the set
//! of vertices whose **rest** position lies within `radius` of `center`
//! (inclusive). Because it is defined in space and not by vertex indices, one
//! [`HandleSet`] applies to every triangulation of the same surface: a coarse
//! decimation, midpoint refinements, the original mesh, a copy with holes.
//!
//! A [`HandleSet`] is one `anchor` (held fixed by the deformation space: its
//! motion is the identity) and a list of `moving` handles. Handles are
//! numbered anchor first: index 0 is the anchor (named `"anchor"`), index
//! `k + 1` is `moving[k]` (named `"handle k"`); errors use these names.
//!
//! A handle moves by a [`RigidParams`]: rotation by an axis-angle vector
//! **about the handle's center**, then a translation, i.e.
//! `x -> c + R (x - c) + t`. [`DeformParams`] holds one per moving handle.
//!
//! [`HandleSet::auto`] places the anchor on the torso (the vertex nearest
//! the mass-weighted centroid) and the moving handles at extremities, by
//! farthest-point sampling of the edge-path (approximate geodesic) distance
//! from the anchor.
//!
//! # Example
//! ```
//! use mfm_deform::HandleSet;
//! use mfm_geometry::procedural;
//! let mesh = procedural::blob(3).unwrap();
//! let handles = HandleSet::auto(&mesh, 3, 0.08).unwrap();
//! assert_eq!(handles.len(), 4); // anchor + 3
//! let regions = handles.regions(&mesh).unwrap();
//! assert!(regions.iter().all(|r| !r.is_empty()));
//! ```

use mfm_geometry::mesh::{norm, sub};
use mfm_geometry::{TriMesh, operators};
use mfm_processing::holes::edge_path_distances;
use serde::{Deserialize, Serialize};

use crate::error::{DeformError, Result};
use crate::rigid::{
    RigidTransform, axis_angle_to_matrix, mat_vec, matrix_to_axis_angle, weighted_centroid,
};

/// Mean length of the face edges of `mesh` (interior edges counted twice).
fn mean_edge(mesh: &TriMesh) -> f64 {
    let pos = mesh.positions();
    let total: f64 = mesh
        .faces()
        .iter()
        .flat_map(|f| {
            [(f[0], f[1]), (f[1], f[2]), (f[2], f[0])]
                .map(|(a, b)| norm(sub(pos[a as usize], pos[b as usize])))
        })
        .sum();
    total / (3 * mesh.num_faces()) as f64
}

/// Default handle radius of [`HandleSet::auto`], as a fraction of the
/// bounding-box diagonal of the mesh.
pub const DEFAULT_RADIUS_FRACTION: f64 = 0.08;

/// A ball in space; its region on a mesh is the vertices whose rest position
/// is within `radius` of `center` (inclusive).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Handle {
    /// Center of the ball (rest-space coordinates).
    pub center: [f64; 3],
    /// Radius of the ball (same units as the mesh).
    pub radius: f64,
}

impl Handle {
    /// Whether `p` is in the ball (`|p - center| <= radius`).
    #[inline]
    pub fn contains(&self, p: [f64; 3]) -> bool {
        let d = sub(p, self.center);
        d[0] * d[0] + d[1] * d[1] + d[2] * d[2] <= self.radius * self.radius
    }

    /// The vertices of `mesh` in the ball, ascending. Cost: `O(V)`.
    pub fn vertices(&self, mesh: &TriMesh) -> Vec<usize> {
        mesh.positions()
            .iter()
            .enumerate()
            .filter(|(_, p)| self.contains(**p))
            .map(|(i, _)| i)
            .collect()
    }

    fn validate(&self, name: &str) -> Result<()> {
        if !self.center.iter().all(|c| c.is_finite()) {
            return Err(DeformError::InvalidParameter {
                name: "handle center",
                expected: "finite coordinates",
                found: format!("{name}: {:?}", self.center),
            });
        }
        if !(self.radius.is_finite() && self.radius > 0.0) {
            return Err(DeformError::InvalidParameter {
                name: "handle radius",
                expected: "a finite radius > 0",
                found: format!("{name}: {}", self.radius),
            });
        }
        Ok(())
    }
}

/// An anchor handle plus the moving handles; see the [module docs](self)
/// for the numbering and names.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct HandleSet {
    /// The fixed handle (identity motion in a [`crate::DeformSpace`]).
    pub anchor: Handle,
    /// The handles whose motions are the deformation parameters.
    pub moving: Vec<Handle>,
}

impl HandleSet {
    /// A handle set from explicit balls. Errors if a center is not finite or
    /// a radius is not positive. Whether the regions are non-empty and
    /// disjoint depends on the mesh: see [`HandleSet::regions`].
    pub fn new(anchor: Handle, moving: Vec<Handle>) -> Result<Self> {
        let set = Self { anchor, moving };
        for (i, h) in set.iter().enumerate() {
            h.validate(&set.name(i))?;
        }
        Ok(set)
    }

    /// Automatic placement on `mesh`: an anchor at the vertex nearest the
    /// mass-weighted centroid (lumped mass: the area centroid of the
    /// surface), then `count` moving handles by farthest-point sampling of
    /// the edge-path distance (see [`edge_path_distances`]), starting from
    /// the anchor vertex: each new center is the vertex farthest, along the
    /// mesh, from every center chosen so far. All radii are
    /// `radius_fraction` times the bounding-box diagonal.
    ///
    /// A vertex is only a candidate if no vertex of `mesh` is within
    /// `radius + mean edge length` of both it and a center already chosen:
    /// then the regions are disjoint on `mesh`, with a margin that keeps them
    /// disjoint on finer triangulations of the surface in practice (each
    /// [`crate::Arap::new`] checks its own mesh again). Ties go to the
    /// lowest vertex index. Cost: `O(count (V + E) log V)` plus `O(V)` per
    /// rejected candidate.
    ///
    /// # Errors
    /// [`DeformError::InvalidParameter`] for a `radius_fraction` that is not
    /// finite and positive; [`DeformError::HandlePlacement`] when fewer than
    /// `count` candidates remain (try a smaller radius or count);
    /// [`DeformError::Geometry`] should not happen.
    pub fn auto(mesh: &TriMesh, count: usize, radius_fraction: f64) -> Result<Self> {
        if !(radius_fraction.is_finite() && radius_fraction > 0.0) {
            return Err(DeformError::InvalidParameter {
                name: "radius_fraction",
                expected: "a finite fraction > 0 of the bounding-box diagonal",
                found: radius_fraction.to_string(),
            });
        }
        let radius = radius_fraction * mesh.bounding_box_diagonal();
        let placement_error = |reason: String| DeformError::HandlePlacement {
            requested: count.saturating_add(1),
            reason,
        };
        if count >= mesh.num_vertices() {
            return Err(placement_error(format!(
                "the mesh has {} vertices, and each handle (the anchor too) needs its own",
                mesh.num_vertices()
            )));
        }
        if !(radius.is_finite() && radius > 0.0) {
            return Err(placement_error(format!(
                "the mesh has a zero bounding box, so the radius would be {radius}"
            )));
        }
        let mass = operators::lumped_mass(mesh);
        let pos = mesh.positions();
        if mass.iter().sum::<f64>() <= 0.0 {
            return Err(placement_error("the mesh has zero area".to_string()));
        }
        let centroid = weighted_centroid(pos, &mass);
        let anchor_vertex = (0..pos.len())
            .filter(|&v| mass[v] > 0.0)
            .min_by(|&a, &b| {
                norm(sub(pos[a], centroid))
                    .total_cmp(&norm(sub(pos[b], centroid)))
                    .then(a.cmp(&b))
            })
            .ok_or_else(|| placement_error("no vertex is used by a face".to_string()))?;
        // a candidate conflicts with a chosen center when some vertex is
        // within `reach` of both: the two balls would share a vertex on this
        // mesh, or likely on a finer triangulation of the surface
        let reach = radius + mean_edge(mesh);
        let mut near = vec![false; pos.len()];
        let mark = |c: usize, near: &mut Vec<bool>| {
            for (u, p) in pos.iter().enumerate() {
                if norm(sub(*p, pos[c])) <= reach {
                    near[u] = true;
                }
            }
        };
        mark(anchor_vertex, &mut near);
        let mut centers = vec![anchor_vertex];
        let mut dist = edge_path_distances(mesh, &[anchor_vertex])?;
        for k in 0..count {
            let mut order: Vec<usize> = (0..pos.len())
                .filter(|&v| dist[v].is_finite() && dist[v] > 0.0)
                .collect();
            order.sort_by(|&a, &b| dist[b].total_cmp(&dist[a]).then(a.cmp(&b)));
            let free_of_conflict = |v: usize| {
                !pos.iter()
                    .zip(&near)
                    .any(|(p, &n)| n && norm(sub(*p, pos[v])) <= reach)
            };
            let Some(v) = order.into_iter().find(|&v| free_of_conflict(v)) else {
                return Err(placement_error(format!(
                    "only {k} moving handles fit: every other vertex connected to the anchor \
                     has a vertex within {reach:e} (radius plus mean edge length) of it and of \
                     a center chosen so far"
                )));
            };
            mark(v, &mut near);
            centers.push(v);
            let dv = edge_path_distances(mesh, &[v])?;
            for (d, e) in dist.iter_mut().zip(dv) {
                *d = d.min(e);
            }
        }
        let ball = |v: usize| Handle {
            center: pos[v],
            radius,
        };
        let set = Self::new(
            ball(anchor_vertex),
            centers[1..].iter().map(|&v| ball(v)).collect(),
        )?;
        set.regions(mesh)?;
        Ok(set)
    }

    /// Number of handles, anchor included (`1 + moving.len()`).
    pub fn len(&self) -> usize {
        1 + self.moving.len()
    }

    /// Always `false`: there is at least the anchor.
    pub fn is_empty(&self) -> bool {
        false
    }

    /// Number of moving handles (the length of [`DeformParams::handles`]).
    pub fn num_moving(&self) -> usize {
        self.moving.len()
    }

    /// Handle `i` in the anchor-first numbering, or `None` past the end.
    pub fn get(&self, i: usize) -> Option<&Handle> {
        if i == 0 {
            Some(&self.anchor)
        } else {
            self.moving.get(i - 1)
        }
    }

    /// All handles, anchor first.
    pub fn iter(&self) -> impl Iterator<Item = &Handle> {
        std::iter::once(&self.anchor).chain(self.moving.iter())
    }

    /// Name of handle `i` in the anchor-first numbering: `"anchor"` for 0,
    /// `"handle k"` for `moving[k]`.
    pub fn name(&self, i: usize) -> String {
        if i == 0 {
            "anchor".to_string()
        } else {
            format!("handle {}", i - 1)
        }
    }

    /// The vertex regions of every handle on `mesh` (anchor first, each
    /// ascending). Cost: `O(V · len)`.
    ///
    /// # Errors
    /// [`DeformError::EmptyHandle`] if a ball holds no vertex,
    /// [`DeformError::OverlappingHandles`] if two regions share a vertex
    /// (naming both handles and the vertex).
    pub fn regions(&self, mesh: &TriMesh) -> Result<Vec<Vec<usize>>> {
        let pos = mesh.positions();
        let mut owner: Vec<Option<usize>> = vec![None; pos.len()];
        let mut regions = Vec::with_capacity(self.len());
        for (i, h) in self.iter().enumerate() {
            h.validate(&self.name(i))?;
            let region = h.vertices(mesh);
            if region.is_empty() {
                let nearest = pos
                    .iter()
                    .map(|p| norm(sub(*p, h.center)))
                    .fold(f64::INFINITY, f64::min);
                return Err(DeformError::EmptyHandle {
                    handle: self.name(i),
                    center: h.center,
                    radius: h.radius,
                    num_vertices: pos.len(),
                    nearest,
                });
            }
            for &v in &region {
                if let Some(j) = owner[v] {
                    return Err(DeformError::OverlappingHandles {
                        first: self.name(j),
                        second: self.name(i),
                        vertex: v,
                    });
                }
                owner[v] = Some(i);
            }
            regions.push(region);
        }
        Ok(regions)
    }
}

/// The rigid motion of one handle: rotate by the axis-angle vector
/// `rotation` (radians) about the handle's center `c`, then translate by
/// `translation`: `x -> c + R (x - c) + t`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct RigidParams {
    /// Axis-angle rotation vector (axis times angle in radians).
    pub rotation: [f64; 3],
    /// Translation applied after the rotation.
    pub translation: [f64; 3],
}

impl RigidParams {
    /// No motion.
    pub fn identity() -> Self {
        Self::default()
    }

    /// The motion as `x -> R x + (c - R c + t)` for the handle center `c`.
    pub fn to_transform(&self, center: [f64; 3]) -> RigidTransform {
        let rotation = axis_angle_to_matrix(self.rotation);
        let rc = mat_vec(&rotation, center);
        RigidTransform {
            rotation,
            translation: [
                center[0] - rc[0] + self.translation[0],
                center[1] - rc[1] + self.translation[1],
                center[2] - rc[2] + self.translation[2],
            ],
        }
    }

    /// The parameters of the motion `transform` for a handle centered at
    /// `center` (inverse of [`RigidParams::to_transform`]; the angle comes
    /// back in `[0, pi]`).
    pub fn from_transform(transform: &RigidTransform, center: [f64; 3]) -> Self {
        let rc = mat_vec(&transform.rotation, center);
        Self {
            rotation: matrix_to_axis_angle(&transform.rotation),
            translation: [
                transform.translation[0] - center[0] + rc[0],
                transform.translation[1] - center[1] + rc[1],
                transform.translation[2] - center[2] + rc[2],
            ],
        }
    }

    /// Whether all six numbers are finite.
    pub fn is_finite(&self) -> bool {
        self.rotation
            .iter()
            .chain(&self.translation)
            .all(|x| x.is_finite())
    }
}

/// Parameters of one deformation: one [`RigidParams`] per **moving** handle,
/// in the order of [`HandleSet::moving`] (the anchor is not listed; a
/// [`crate::DeformSpace`] holds it fixed).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct DeformParams {
    /// Motion of each moving handle.
    pub handles: Vec<RigidParams>,
}

impl DeformParams {
    /// `count` identity motions (the rest shape).
    pub fn identity(count: usize) -> Self {
        Self {
            handles: vec![RigidParams::identity(); count],
        }
    }
}
